//! Packet framing (§2.2 of the protocol description).
//!
//! ```text
//! 0xF0  0x81  checksum^0x55  0x81  length^0x55  packet data (stuffed) ...  0x0F
//! start stuff checksum       stuff length       number command data       stop
//! ```
//!
//! * Byte stuffing: "every constant from Table 6, except the stuffing key, is escaped with
//!   the stuffing byte" (§2.2): in the packet data each of the three special bytes 0xF0
//!   (start), 0x0F (stop) and 0x81 (stuffing byte) is sent as the stuffing byte 0x81
//!   followed by the byte XOR the stuffing key 0x55. The stuffing key 0x55 itself, and 0x0A,
//!   go out as they are. The checksum and the length are always sent that way, whatever
//!   their value, so their positions are fixed.
//! * The decoder un-stuffs generically: 0x81 followed by any byte is that byte XOR 0x55, so
//!   it reads both the device's form and the one pyScienceMode 1.1.5 sends (which also
//!   stuffs 0x55 and 0x0A); every other byte, 0x55 and 0x0A included, is data as it is.
//! * The checksum is the CRC-8 (polynomial 0x07, initial value 0, no reflection, no final
//!   XOR) of the packet data as sent (stuffed); the length is the number of packet data
//!   bytes as sent.
//! * A packet is at most 69 bytes long, so the stuffed packet data is at most 63 bytes.
//!
//! A stop byte never occurs inside the stuffed packet data, and a start byte never occurs
//! after the header, so the [`Decoder`] finds packet boundaries without the length field
//! and uses it as a check. (The checksum position may hold any byte, 0xF0 and 0x0F
//! included: the decoder reads it by position.)

use crc::{CRC_8_SMBUS, Crc};

use crate::error::{DecodeError, EncodeError};
use crate::message::{Message, Packet};

/// Start of a packet.
pub const START_BYTE: u8 = 0xF0;
/// End of a packet.
pub const STOP_BYTE: u8 = 0x0F;
/// Precedes a stuffed byte.
pub const STUFFING_BYTE: u8 = 0x81;
/// A stuffed byte is the original XOR this key.
pub const STUFFING_KEY: u8 = 0x55;
/// The most bytes of one packet, framing included.
pub const MAX_PACKET_LEN: usize = 69;
/// Start byte, stuffing byte, checksum, stuffing byte, length.
pub const HEADER_LEN: usize = 5;
/// The most stuffed packet data bytes of one packet.
pub const MAX_DATA_LEN: usize = MAX_PACKET_LEN - HEADER_LEN - 1;

/// Whether `b` must be stuffed in packet data: the constants of Table 6 except the
/// stuffing key (§2.2), i.e. 0xF0, 0x0F and 0x81.
pub const fn is_special(b: u8) -> bool {
    matches!(b, START_BYTE | STOP_BYTE | STUFFING_BYTE)
}

/// The checksum's engine: CRC-8/SMBUS from the `crc` crate's catalogue (polynomial 0x07,
/// initial value 0, no reflection, no final XOR; check value 0xF4), its lookup table built
/// at compile time.
static SMBUS: Crc<u8> = Crc::<u8>::new(&CRC_8_SMBUS);

// The parameters §2.2's checksum needs, as the module doc states them.
const _: () = assert!(
    CRC_8_SMBUS.poly == 0x07
        && CRC_8_SMBUS.init == 0
        && !CRC_8_SMBUS.refin
        && !CRC_8_SMBUS.refout
        && CRC_8_SMBUS.xorout == 0
        && CRC_8_SMBUS.check == 0xF4
);

/// CRC-8 (polynomial 0x07, initial value 0, no reflection, no final XOR; CRC-8/SMBUS,
/// check value 0xF4) of `bytes`.
pub fn crc8(bytes: &[u8]) -> u8 {
    SMBUS.checksum(bytes)
}

/// The length of `data` after byte stuffing.
pub fn stuffed_len(data: &[u8]) -> usize {
    data.iter().map(|&b| 1 + usize::from(is_special(b))).sum()
}

/// Frames unstuffed packet data (number, command, command data) into `out`.
pub(crate) fn encode_data(data: &[u8], out: &mut [u8]) -> Result<usize, EncodeError> {
    let stuffed = stuffed_len(data);
    if stuffed > MAX_DATA_LEN {
        return Err(EncodeError::TooLong {
            len: stuffed,
            max: MAX_DATA_LEN,
        });
    }
    let needed = HEADER_LEN + stuffed + 1;
    if out.len() < needed {
        return Err(EncodeError::BufferTooSmall {
            needed,
            available: out.len(),
        });
    }
    let mut n = HEADER_LEN;
    for &b in data {
        if is_special(b) {
            out[n] = STUFFING_BYTE;
            out[n + 1] = b ^ STUFFING_KEY;
            n += 2;
        } else {
            out[n] = b;
            n += 1;
        }
    }
    let checksum = crc8(&out[HEADER_LEN..n]);
    out[0] = START_BYTE;
    out[1] = STUFFING_BYTE;
    out[2] = checksum ^ STUFFING_KEY;
    out[3] = STUFFING_BYTE;
    // stuffed <= MAX_DATA_LEN (63) fits a byte.
    out[4] = (stuffed as u8) ^ STUFFING_KEY;
    out[n] = STOP_BYTE;
    Ok(n + 1)
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    /// Waiting for a start byte; other bytes are skipped.
    Idle,
    /// After the start byte: the stuffing byte before the checksum.
    HeaderStuff1,
    Checksum,
    HeaderStuff2,
    Length,
    Data,
}

/// The streaming decoder: bytes in, one at a time or in chunks; packets or typed errors
/// out. Allocation-free (a fixed 63-byte buffer) and never panics on any input.
///
/// Bytes outside a packet are skipped and counted ([`Decoder::skipped`]). Every error
/// drops the packet being received; a start byte always begins a new one.
#[derive(Debug, Clone)]
pub struct Decoder {
    state: State,
    buf: [u8; MAX_DATA_LEN],
    len: usize,
    checksum: u8,
    declared: u8,
    skipped: u64,
}

impl Default for Decoder {
    fn default() -> Self {
        Decoder::new()
    }
}

impl Decoder {
    /// A decoder waiting for a start byte.
    pub const fn new() -> Decoder {
        Decoder {
            state: State::Idle,
            buf: [0; MAX_DATA_LEN],
            len: 0,
            checksum: 0,
            declared: 0,
            skipped: 0,
        }
    }

    /// Bytes skipped outside packets so far (line noise, or the tail of a dropped packet).
    pub const fn skipped(&self) -> u64 {
        self.skipped
    }

    /// Whether the decoder is inside a packet (a partial packet is buffered).
    pub fn in_packet(&self) -> bool {
        self.state != State::Idle
    }

    /// Forgets any partial packet.
    pub fn reset(&mut self) {
        self.state = State::Idle;
        self.len = 0;
    }

    fn begin(&mut self) {
        self.state = State::HeaderStuff1;
        self.len = 0;
    }

    /// Takes one byte; returns a packet or an error when `byte` completes or breaks one.
    pub fn push(&mut self, byte: u8) -> Option<Result<Packet, DecodeError>> {
        match self.state {
            State::Idle => {
                if byte == START_BYTE {
                    self.begin();
                } else {
                    self.skipped += 1;
                }
                None
            }
            State::HeaderStuff1 | State::HeaderStuff2 => {
                let position = if self.state == State::HeaderStuff1 {
                    1
                } else {
                    3
                };
                if byte == STUFFING_BYTE {
                    self.state = if self.state == State::HeaderStuff1 {
                        State::Checksum
                    } else {
                        State::Length
                    };
                    None
                } else {
                    if byte == START_BYTE {
                        self.begin();
                    } else {
                        self.state = State::Idle;
                    }
                    Some(Err(DecodeError::BadHeader { position, byte }))
                }
            }
            State::Checksum => {
                self.checksum = byte ^ STUFFING_KEY;
                self.state = State::HeaderStuff2;
                None
            }
            State::Length => {
                self.declared = byte ^ STUFFING_KEY;
                self.state = State::Data;
                None
            }
            State::Data => match byte {
                STOP_BYTE => {
                    self.state = State::Idle;
                    Some(self.finish())
                }
                START_BYTE => {
                    let received = self.len as u8;
                    self.begin();
                    Some(Err(DecodeError::Truncated { received }))
                }
                _ => {
                    if self.len == MAX_DATA_LEN {
                        self.state = State::Idle;
                        return Some(Err(DecodeError::TooLong {
                            max: MAX_DATA_LEN as u8,
                        }));
                    }
                    self.buf[self.len] = byte;
                    self.len += 1;
                    None
                }
            },
        }
    }

    /// Decodes `bytes`, yielding every packet or error they complete, in order.
    pub fn feed<'d, 'b>(&'d mut self, bytes: &'b [u8]) -> Feed<'d, 'b> {
        Feed {
            decoder: self,
            bytes: bytes.iter(),
        }
    }

    fn finish(&self) -> Result<Packet, DecodeError> {
        let stuffed = &self.buf[..self.len];
        let actual = self.len as u8;
        if self.declared != actual {
            return Err(DecodeError::BadLength {
                declared: self.declared,
                actual,
            });
        }
        let computed = crc8(stuffed);
        if computed != self.checksum {
            return Err(DecodeError::BadChecksum {
                received: self.checksum,
                computed,
            });
        }
        let mut data = [0u8; MAX_DATA_LEN];
        let mut n = 0;
        let mut i = 0;
        while i < stuffed.len() {
            let b = stuffed[i];
            let position = i as u8;
            let value = if b == STUFFING_BYTE {
                // §2.2: the stuffing byte escapes the next byte, which is sent XOR the key.
                // Any byte is un-stuffed (the device escapes only 0xF0, 0x0F and 0x81; a
                // host such as pyScienceMode also escapes 0x55 and 0x0A).
                let next = stuffed
                    .get(i + 1)
                    .copied()
                    .ok_or(DecodeError::BadStuffing { position, byte: b })?;
                i += 2;
                next ^ STUFFING_KEY
            } else {
                i += 1;
                b
            };
            data[n] = value;
            n += 1;
        }
        let data = &data[..n];
        let [number, command, rest @ ..] = data else {
            return Err(DecodeError::Empty { len: n as u8 });
        };
        Ok(Packet {
            number: *number,
            message: Message::decode(*command, rest).map_err(|e| match e {
                DecodeError::UnknownCommand { command, .. } => DecodeError::UnknownCommand {
                    number: *number,
                    command,
                },
                other => other,
            })?,
        })
    }
}

/// The packets and errors a chunk of bytes completes ([`Decoder::feed`]).
#[derive(Debug)]
pub struct Feed<'d, 'b> {
    decoder: &'d mut Decoder,
    bytes: core::slice::Iter<'b, u8>,
}

impl Iterator for Feed<'_, '_> {
    type Item = Result<Packet, DecodeError>;

    fn next(&mut self) -> Option<Self::Item> {
        for &b in self.bytes.by_ref() {
            if let Some(r) = self.decoder.push(b) {
                return Some(r);
            }
        }
        None
    }
}
