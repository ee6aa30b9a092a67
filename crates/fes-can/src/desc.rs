//! Signal and message descriptors, and the bit packing they drive.
//!
//! The descriptor table ([`crate::table`]) is the codec's copy of `dbc/fes.dbc`: every
//! typed message is packed and unpacked through its descriptors, and a test compares
//! the table with the DBC, so the codec cannot drift from the file. Only Intel (little
//! endian) byte order is used on this bus.

use crate::error::{DecodeError, EncodeError};
use crate::ids::{MessageKind, Role};

/// Byte order of a signal (DBC `@1` little endian / Intel, `@0` big endian / Motorola).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ByteOrder {
    /// Intel: the start bit is the least significant bit.
    LittleEndian,
    /// Motorola: not used by this protocol (the packer refuses it at compile time).
    BigEndian,
}

/// Multiplexing role of a signal.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mux {
    /// Present in every frame of the message.
    Plain,
    /// The multiplexor switch (DBC `M`).
    Multiplexor,
    /// Present only when the multiplexor equals the value (DBC `m<value>`).
    Page(u8),
}

/// One signal: where its bits are, how raw maps to physical, its range and unit.
///
/// Physical value = raw * `factor` + `offset`; valid frames have `min <= physical <= max`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SignalDesc {
    /// DBC signal name.
    pub name: &'static str,
    /// Multiplexing role.
    pub mux: Mux,
    /// Start bit (least significant bit, Intel numbering).
    pub start_bit: u8,
    /// Length in bits (1..=64).
    pub length: u8,
    /// Byte order.
    pub byte_order: ByteOrder,
    /// Two's-complement signed raw value.
    pub signed: bool,
    /// Scale factor from raw to physical.
    pub factor: f64,
    /// Offset from raw to physical.
    pub offset: f64,
    /// Smallest valid physical value.
    pub min: f64,
    /// Largest valid physical value.
    pub max: f64,
    /// Physical unit ("" when dimensionless).
    pub unit: &'static str,
    /// Value table (`VAL_`), empty when the signal is numeric.
    pub values: &'static [(u64, &'static str)],
}

impl SignalDesc {
    /// An unsigned, unscaled, plain signal spanning its full raw range; adjust with the
    /// other `const fn` builders.
    pub const fn new(name: &'static str, start_bit: u8, length: u8) -> Self {
        assert!(length >= 1 && length <= 64 && start_bit as u32 + length as u32 <= 64);
        Self {
            name,
            mux: Mux::Plain,
            start_bit,
            length,
            byte_order: ByteOrder::LittleEndian,
            signed: false,
            factor: 1.0,
            offset: 0.0,
            min: 0.0,
            max: if length == 64 {
                u64::MAX as f64
            } else {
                ((1u64 << length) - 1) as f64
            },
            unit: "",
            values: &[],
        }
    }

    /// Sets the scale (factor, offset).
    pub const fn scale(mut self, factor: f64, offset: f64) -> Self {
        self.factor = factor;
        self.offset = offset;
        self
    }

    /// Sets the physical range.
    pub const fn range(mut self, min: f64, max: f64) -> Self {
        self.min = min;
        self.max = max;
        self
    }

    /// Sets the unit.
    pub const fn unit(mut self, unit: &'static str) -> Self {
        self.unit = unit;
        self
    }

    /// Marks the raw value as two's-complement signed.
    pub const fn signed(mut self) -> Self {
        self.signed = true;
        self
    }

    /// Sets the value table.
    pub const fn values(mut self, values: &'static [(u64, &'static str)]) -> Self {
        self.values = values;
        self
    }

    /// Makes the signal the multiplexor.
    pub const fn multiplexor(mut self) -> Self {
        self.mux = Mux::Multiplexor;
        self
    }

    /// Makes the signal present only on multiplexor page `page`.
    pub const fn page(mut self, page: u8) -> Self {
        self.mux = Mux::Page(page);
        self
    }

    fn mask(&self) -> u64 {
        if self.length == 64 {
            u64::MAX
        } else {
            (1u64 << self.length) - 1
        }
    }

    /// The smallest valid raw value (from the physical `min`).
    pub fn raw_min(&self) -> i64 {
        ((self.min - self.offset) / self.factor).round() as i64
    }

    /// The largest valid raw value (from the physical `max`).
    pub fn raw_max(&self) -> i64 {
        ((self.max - self.offset) / self.factor).round() as i64
    }

    /// Physical value of a raw value.
    pub fn physical(&self, raw: i64) -> f64 {
        raw as f64 * self.factor + self.offset
    }

    /// Writes `raw` into `data` (no range check; two's complement when signed).
    fn insert(&self, data: &mut [u8; 8], raw: i64) {
        let mask = self.mask();
        let mut word = u64::from_le_bytes(*data);
        word &= !(mask << self.start_bit);
        word |= ((raw as u64) & mask) << self.start_bit;
        *data = word.to_le_bytes();
    }

    /// Reads the raw value from `data` (sign-extended when signed; no range check).
    pub fn extract(&self, data: &[u8; 8]) -> i64 {
        let raw = (u64::from_le_bytes(*data) >> self.start_bit) & self.mask();
        if self.signed && self.length < 64 && ((raw >> (self.length - 1)) & 1) == 1 {
            (raw | !self.mask()) as i64
        } else {
            raw as i64
        }
    }

    /// Range-checks `raw` and writes it into `data`.
    pub fn encode(
        &self,
        kind: MessageKind,
        data: &mut [u8; 8],
        raw: i64,
    ) -> Result<(), EncodeError> {
        if raw < self.raw_min() || raw > self.raw_max() {
            return Err(EncodeError::OutOfRange {
                message: kind.name(),
                signal: self.name,
                value: raw,
            });
        }
        self.insert(data, raw);
        Ok(())
    }

    /// Reads the raw value from `data` and range-checks it.
    pub fn decode(&self, kind: MessageKind, data: &[u8; 8]) -> Result<i64, DecodeError> {
        let raw = self.extract(data);
        if raw < self.raw_min() || raw > self.raw_max() {
            return Err(DecodeError::OutOfRange {
                message: kind.name(),
                signal: self.name,
                raw,
            });
        }
        Ok(raw)
    }
}

/// One message: identifier rule, length, timing, sender and signals.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MessageDesc {
    /// Which message.
    pub kind: MessageKind,
    /// DBC message name.
    pub name: &'static str,
    /// CANopen function code: the COB-ID without the node id.
    pub function_code: u16,
    /// Whose node id is added to the function code (`None`: the COB-ID is fixed).
    pub id_node: Option<Role>,
    /// Data length code (payload bytes).
    pub dlc: u8,
    /// Cycle time in ms for periodic messages (DBC `GenMsgCycleTime`), `None` if on event.
    pub cycle_time_ms: Option<u16>,
    /// Transmitting node.
    pub sender: Role,
    /// Receiving node.
    pub receiver: Role,
    /// Signals, in DBC order.
    pub signals: &'static [SignalDesc],
}

impl MessageDesc {
    /// The signal named `name`, if any.
    pub fn signal(&self, name: &str) -> Option<&'static SignalDesc> {
        self.signals.iter().find(|s| s.name == name)
    }

    /// The payload bits (bit `i` of the little-endian 64-bit word is payload bit `i`) that
    /// a signal occupies on multiplexor page `page` (`None`: a message without pages).
    /// Every other bit is reserved and must be zero.
    pub fn used_bits(&self, page: Option<u8>) -> u64 {
        self.signals
            .iter()
            .filter(|s| match s.mux {
                Mux::Plain | Mux::Multiplexor => true,
                Mux::Page(p) => Some(p) == page,
            })
            .fold(0, |used, s| used | (s.mask() << s.start_bit))
    }

    /// Refuses a payload with a reserved bit set, naming the first byte that has one.
    pub fn check_reserved(&self, page: Option<u8>, data: &[u8; 8]) -> Result<(), DecodeError> {
        let reserved = u64::from_le_bytes(*data) & !self.used_bits(page);
        if reserved == 0 {
            return Ok(());
        }
        let byte = (reserved.trailing_zeros() / 8) as usize;
        Err(DecodeError::ReservedNonZero {
            message: self.name,
            byte,
            value: data[byte],
        })
    }
}
