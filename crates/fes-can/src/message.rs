//! Typed messages and the frame codec.
//!
//! `encode` turns a typed message into a [`Frame`] (identifier, DLC, 8 data bytes);
//! `decode` turns an identifier and payload back into a [`Message`] or a
//! [`DecodeError`]: wrong length, wrong CRC, a value outside its range, an undefined
//! enumerated value or a non-zero reserved (unused) bit are all errors, never panics; an
//! accepted frame re-encodes to exactly the bytes received. Both work on stack arrays only (no heap
//! allocation), so the driver can call them on its real-time path. Field values are raw
//! bus integers; the field name carries the unit (e.g. `amplitude_100ua` = 0.1 mA steps).
//!
//! Alive-counter and sequence-number validation need history and live in
//! [`crate::counter`].

use crate::crc::frame_crc;
use crate::desc::SignalDesc;
use crate::error::{DecodeError, EncodeError};
use crate::ids::{MessageKind, Nodes};
use crate::table::{config, emcy, force, heartbeat, nmt, pulse, status};
use crate::values::{ConfigPageId, ErrorCode, NmtCommand, NmtState, StimState};

/// A classic CAN frame with a standard (11-bit) identifier.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Frame {
    /// Standard identifier (COB-ID).
    pub id: u16,
    /// Data length code, 0..=8.
    pub dlc: u8,
    /// Data bytes; bytes at and after `dlc` are zero.
    pub data: [u8; 8],
}

impl Frame {
    /// The payload (`data[..dlc]`).
    pub fn payload(&self) -> &[u8] {
        &self.data[..usize::from(self.dlc.min(8))]
    }
}

/// `cansend` syntax: `110#0102030405060708`.
impl core::fmt::Display for Frame {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{:03X}#", self.id)?;
        for b in self.payload() {
            write!(f, "{b:02X}")?;
        }
        Ok(())
    }
}

/// NMT node control.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Nmt {
    /// The command.
    pub command: NmtCommand,
    /// The addressed node, 0 for all nodes.
    pub node: u8,
}

/// Emergency: a rejected frame or a fault.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Emcy {
    /// CANopen error code.
    pub code: ErrorCode,
    /// CANopen error register.
    pub register: u8,
    /// Stimulator state when raised.
    pub state: StimState,
    /// Sequence number of the offending PULSE, else 0.
    pub seq: u16,
    /// Code-specific detail (see `docs/can-protocol.md`).
    pub detail: u16,
}

impl Emcy {
    /// An emergency with the error register that belongs to `code`.
    pub const fn new(code: ErrorCode, state: StimState, seq: u16, detail: u16) -> Self {
        Self {
            code,
            register: code.error_register(),
            state,
            seq,
            detail,
        }
    }
}

/// One stimulation pulse. The CRC is computed by `encode` and checked by `decode`.
///
/// One PULSE is one charge-balanced biphasic pulse: a cathodic phase of `width_us` at
/// `amplitude_100ua`, an interphase gap of [`INTERPHASE_GAP_US`], then an anodic phase of the
/// same amplitude and width (symmetric, so no net charge). The charge per phase is
/// amplitude x width ([`Pulse::charge_nc`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Pulse {
    /// Pulse sequence number.
    pub seq: u16,
    /// Alive counter, 0..=15.
    pub alive_counter: u8,
    /// Output channel, 0..=15.
    pub channel: u8,
    /// Amplitude in 0.1 mA steps, 0..=1500 (0-150 mA).
    pub amplitude_100ua: u16,
    /// Width in us, 0..=1000.
    pub width_us: u16,
}

/// The interphase gap of every PULSE, us: fixed by the protocol (docs/can-protocol.md,
/// "What one PULSE is"), not configurable.
pub const INTERPHASE_GAP_US: u16 = 100;

impl Pulse {
    /// Charge per phase in nC (amplitude x width; 0.1 mA x 1 us = 0.1 nC per raw unit).
    pub fn charge_nc(&self) -> u32 {
        u32::from(self.amplitude_100ua) * u32::from(self.width_us) / 10
    }

    /// Amplitude in mA.
    pub fn amplitude_ma(&self) -> f64 {
        pulse::AMPLITUDE.physical(i64::from(self.amplitude_100ua))
    }
}

/// A force sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Force {
    /// Frame counter (+1 per FORCE frame).
    pub seq: u16,
    /// Force in mN, -8_388_608..=8_388_607.
    pub force_mn: i32,
    /// Sample time in us modulo 2^24.
    pub sample_time_us: u32,
}

impl Force {
    /// Force in newtons.
    pub fn force_n(&self) -> f64 {
        force::FORCE.physical(i64::from(self.force_mn))
    }

    /// The raw force (mN) nearest to `newtons`, or `None` when outside the signal's range
    /// (or not finite).
    pub fn raw_force(newtons: f64) -> Option<i32> {
        if !newtons.is_finite() {
            return None;
        }
        let raw = ((newtons - force::FORCE.offset) / force::FORCE.factor).round();
        if raw < force::FORCE.raw_min() as f64 || raw > force::FORCE.raw_max() as f64 {
            return None;
        }
        Some(raw as i32)
    }
}

/// Stimulator status.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Status {
    /// Stimulator state.
    pub state: StimState,
    /// Status counter, 0..=15.
    pub counter: u8,
    /// Most recent emergency code since reset.
    pub last_error: ErrorCode,
    /// Pulses applied since reset, modulo 2^24.
    pub pulses_delivered: u32,
    /// Frames rejected since reset, modulo 2^8.
    pub rejected: u8,
    /// Active configuration id (0: defaults).
    pub config_id: u8,
}

/// The contents of one CONFIG page.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ConfigPage {
    /// Page 0.
    OutputLimits {
        /// Amplitude ceiling in 0.1 mA steps, 0..=1500.
        max_amplitude_100ua: u16,
        /// Width ceiling in us, 0..=1000.
        max_width_us: u16,
        /// Minimum inter-pulse interval in ms, 1..=1000.
        min_ipi_ms: u16,
    },
    /// Page 1.
    RateAndWatchdog {
        /// Most pulses in any rate window, 1..=1000.
        max_pulses: u16,
        /// Rate window in ms, 1..=60000.
        rate_window_ms: u16,
        /// Host heartbeat timeout in ms, 20..=5000.
        watchdog_ms: u16,
    },
    /// Page 2.
    Charge {
        /// Charge-per-phase ceiling in 10 nC (0.01 uC) steps, 0..=15000 (0-150 uC).
        max_charge_10nc: u16,
    },
}

impl ConfigPage {
    /// The page number (multiplexor value).
    pub const fn id(&self) -> ConfigPageId {
        match self {
            ConfigPage::OutputLimits { .. } => ConfigPageId::OutputLimits,
            ConfigPage::RateAndWatchdog { .. } => ConfigPageId::RateAndWatchdog,
            ConfigPage::Charge { .. } => ConfigPageId::Charge,
        }
    }
}

/// One CONFIG frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Config {
    /// Configuration id, 1..=255.
    pub config_id: u8,
    /// The page.
    pub page: ConfigPage,
}

/// A heartbeat (either node's).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Heartbeat {
    /// The sender's NMT state.
    pub state: NmtState,
}

/// Any message of the protocol.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Message {
    /// NMT node control.
    Nmt(Nmt),
    /// Emergency.
    Emcy(Emcy),
    /// Stimulation pulse.
    Pulse(Pulse),
    /// Force sample.
    Force(Force),
    /// Stimulator status.
    Status(Status),
    /// One page of run limits.
    Config(Config),
    /// One page of the limits the stimulator applied (its answer to a complete CONFIG).
    ConfigApplied(Config),
    /// Host heartbeat.
    HostHeartbeat(Heartbeat),
    /// Stimulator heartbeat.
    StimHeartbeat(Heartbeat),
}

impl Message {
    /// Which message this is.
    pub const fn kind(&self) -> MessageKind {
        match self {
            Message::Nmt(_) => MessageKind::Nmt,
            Message::Emcy(_) => MessageKind::Emcy,
            Message::Pulse(_) => MessageKind::Pulse,
            Message::Force(_) => MessageKind::Force,
            Message::Status(_) => MessageKind::Status,
            Message::Config(_) => MessageKind::Config,
            Message::ConfigApplied(_) => MessageKind::ConfigApplied,
            Message::HostHeartbeat(_) => MessageKind::HostHeartbeat,
            Message::StimHeartbeat(_) => MessageKind::StimHeartbeat,
        }
    }

    /// Encodes for the default nodes ([`Nodes::DEFAULT`]).
    pub fn encode(&self) -> Result<Frame, EncodeError> {
        self.encode_for(&Nodes::DEFAULT)
    }

    /// Encodes for `nodes`. A field outside its signal's range is an error (never clamped).
    pub fn encode_for(&self, nodes: &Nodes) -> Result<Frame, EncodeError> {
        let kind = self.kind();
        let id = nodes.id_of(kind);
        let mut d = [0u8; 8];
        let put = |s: &SignalDesc, d: &mut [u8; 8], v: i64| s.encode(kind, d, v);
        match *self {
            Message::Nmt(m) => {
                put(&nmt::COMMAND, &mut d, i64::from(m.command.raw()))?;
                put(&nmt::NODE, &mut d, i64::from(m.node))?;
            }
            Message::Emcy(m) => {
                put(&emcy::ERROR_CODE, &mut d, i64::from(m.code.raw()))?;
                put(&emcy::ERROR_REGISTER, &mut d, i64::from(m.register))?;
                put(&emcy::STATE, &mut d, i64::from(m.state.raw()))?;
                put(&emcy::SEQ, &mut d, i64::from(m.seq))?;
                put(&emcy::DETAIL, &mut d, i64::from(m.detail))?;
            }
            Message::Pulse(m) => {
                put(&pulse::SEQ, &mut d, i64::from(m.seq))?;
                put(&pulse::ALIVE_COUNTER, &mut d, i64::from(m.alive_counter))?;
                put(&pulse::CHANNEL, &mut d, i64::from(m.channel))?;
                put(&pulse::AMPLITUDE, &mut d, i64::from(m.amplitude_100ua))?;
                put(&pulse::WIDTH, &mut d, i64::from(m.width_us))?;
                let crc = frame_crc(id, &crc_input(&d));
                put(&pulse::CRC, &mut d, i64::from(crc))?;
            }
            Message::Force(m) => {
                put(&force::SEQ, &mut d, i64::from(m.seq))?;
                put(&force::FORCE, &mut d, i64::from(m.force_mn))?;
                put(&force::SAMPLE_TIME, &mut d, i64::from(m.sample_time_us))?;
            }
            Message::Status(m) => {
                put(&status::STATE, &mut d, i64::from(m.state.raw()))?;
                put(&status::COUNTER, &mut d, i64::from(m.counter))?;
                put(&status::LAST_ERROR, &mut d, i64::from(m.last_error.raw()))?;
                put(
                    &status::PULSES_DELIVERED,
                    &mut d,
                    i64::from(m.pulses_delivered),
                )?;
                put(&status::REJECTED, &mut d, i64::from(m.rejected))?;
                put(&status::CONFIG_ID, &mut d, i64::from(m.config_id))?;
            }
            Message::Config(m) | Message::ConfigApplied(m) => {
                put(&config::PAGE, &mut d, i64::from(m.page.id().raw()))?;
                put(&config::CONFIG_ID, &mut d, i64::from(m.config_id))?;
                match m.page {
                    ConfigPage::OutputLimits {
                        max_amplitude_100ua,
                        max_width_us,
                        min_ipi_ms,
                    } => {
                        put(
                            &config::MAX_AMPLITUDE,
                            &mut d,
                            i64::from(max_amplitude_100ua),
                        )?;
                        put(&config::MAX_WIDTH, &mut d, i64::from(max_width_us))?;
                        put(&config::MIN_IPI, &mut d, i64::from(min_ipi_ms))?;
                    }
                    ConfigPage::RateAndWatchdog {
                        max_pulses,
                        rate_window_ms,
                        watchdog_ms,
                    } => {
                        put(&config::MAX_PULSES, &mut d, i64::from(max_pulses))?;
                        put(&config::RATE_WINDOW, &mut d, i64::from(rate_window_ms))?;
                        put(&config::WATCHDOG, &mut d, i64::from(watchdog_ms))?;
                    }
                    ConfigPage::Charge { max_charge_10nc } => {
                        put(&config::MAX_CHARGE, &mut d, i64::from(max_charge_10nc))?;
                    }
                }
            }
            Message::HostHeartbeat(m) | Message::StimHeartbeat(m) => {
                put(&heartbeat::STATE, &mut d, i64::from(m.state.raw()))?;
            }
        }
        Ok(Frame {
            id,
            dlc: kind.desc().dlc,
            data: d,
        })
    }
}

/// Bytes 0-6, the CRC's input after the identifier.
fn crc_input(d: &[u8; 8]) -> [u8; 7] {
    [d[0], d[1], d[2], d[3], d[4], d[5], d[6]]
}

/// Decodes a frame for the default nodes ([`Nodes::DEFAULT`]).
pub fn decode(id: u32, data: &[u8]) -> Result<Message, DecodeError> {
    Nodes::DEFAULT.decode(id, data)
}

/// Reads a signal that must fit `T` (guaranteed by its range, which `decode` checked).
fn field<T: TryFrom<i64>>(
    kind: MessageKind,
    s: &SignalDesc,
    d: &[u8; 8],
) -> Result<T, DecodeError> {
    let raw = s.decode(kind, d)?;
    T::try_from(raw).map_err(|_| DecodeError::OutOfRange {
        message: kind.name(),
        signal: s.name,
        raw,
    })
}

/// Reads an enumerated signal through `from_raw`.
fn enumerated<T>(
    kind: MessageKind,
    s: &SignalDesc,
    d: &[u8; 8],
    from_raw: fn(u64) -> Option<T>,
) -> Result<T, DecodeError> {
    let raw = s.decode(kind, d)?;
    u64::try_from(raw)
        .ok()
        .and_then(from_raw)
        .ok_or(DecodeError::UnknownValue {
            message: kind.name(),
            signal: s.name,
            raw,
        })
}

impl Nodes {
    /// Decodes a frame (standard identifier `id`, payload `data`) for these nodes.
    pub fn decode(&self, id: u32, data: &[u8]) -> Result<Message, DecodeError> {
        let kind = self.kind_of(id).ok_or(DecodeError::UnknownId { id })?;
        let desc = kind.desc();
        if data.len() != usize::from(desc.dlc) {
            return Err(DecodeError::WrongLength {
                message: desc.name,
                expected: desc.dlc,
                actual: data.len(),
            });
        }
        let mut d = [0u8; 8];
        d[..data.len()].copy_from_slice(data);
        let k = kind;
        let m = match kind {
            MessageKind::Nmt => Message::Nmt(Nmt {
                command: enumerated(k, &nmt::COMMAND, &d, NmtCommand::from_raw)?,
                node: field(k, &nmt::NODE, &d)?,
            }),
            MessageKind::Emcy => Message::Emcy(Emcy {
                code: enumerated(k, &emcy::ERROR_CODE, &d, ErrorCode::from_raw)?,
                register: field(k, &emcy::ERROR_REGISTER, &d)?,
                state: enumerated(k, &emcy::STATE, &d, StimState::from_raw)?,
                seq: field(k, &emcy::SEQ, &d)?,
                detail: field(k, &emcy::DETAIL, &d)?,
            }),
            MessageKind::Pulse => {
                let received: u8 = field(k, &pulse::CRC, &d)?;
                // The identifier fits u16: kind_of accepted it as a standard COB-ID.
                let computed = frame_crc(id as u16, &crc_input(&d));
                if received != computed {
                    return Err(DecodeError::BadCrc { received, computed });
                }
                Message::Pulse(Pulse {
                    seq: field(k, &pulse::SEQ, &d)?,
                    alive_counter: field(k, &pulse::ALIVE_COUNTER, &d)?,
                    channel: field(k, &pulse::CHANNEL, &d)?,
                    amplitude_100ua: field(k, &pulse::AMPLITUDE, &d)?,
                    width_us: field(k, &pulse::WIDTH, &d)?,
                })
            }
            MessageKind::Force => Message::Force(Force {
                seq: field(k, &force::SEQ, &d)?,
                force_mn: field(k, &force::FORCE, &d)?,
                sample_time_us: field(k, &force::SAMPLE_TIME, &d)?,
            }),
            MessageKind::Status => Message::Status(Status {
                state: enumerated(k, &status::STATE, &d, StimState::from_raw)?,
                counter: field(k, &status::COUNTER, &d)?,
                last_error: enumerated(k, &status::LAST_ERROR, &d, ErrorCode::from_raw)?,
                pulses_delivered: field(k, &status::PULSES_DELIVERED, &d)?,
                rejected: field(k, &status::REJECTED, &d)?,
                config_id: field(k, &status::CONFIG_ID, &d)?,
            }),
            MessageKind::Config | MessageKind::ConfigApplied => {
                let page = enumerated(k, &config::PAGE, &d, ConfigPageId::from_raw)?;
                let config_id = field(k, &config::CONFIG_ID, &d)?;
                let page = match page {
                    ConfigPageId::OutputLimits => ConfigPage::OutputLimits {
                        max_amplitude_100ua: field(k, &config::MAX_AMPLITUDE, &d)?,
                        max_width_us: field(k, &config::MAX_WIDTH, &d)?,
                        min_ipi_ms: field(k, &config::MIN_IPI, &d)?,
                    },
                    ConfigPageId::RateAndWatchdog => ConfigPage::RateAndWatchdog {
                        max_pulses: field(k, &config::MAX_PULSES, &d)?,
                        rate_window_ms: field(k, &config::RATE_WINDOW, &d)?,
                        watchdog_ms: field(k, &config::WATCHDOG, &d)?,
                    },
                    ConfigPageId::Charge => ConfigPage::Charge {
                        max_charge_10nc: field(k, &config::MAX_CHARGE, &d)?,
                    },
                };
                let c = Config { config_id, page };
                if kind == MessageKind::Config {
                    Message::Config(c)
                } else {
                    Message::ConfigApplied(c)
                }
            }
            MessageKind::HostHeartbeat => Message::HostHeartbeat(Heartbeat {
                state: enumerated(k, &heartbeat::STATE, &d, NmtState::from_raw)?,
            }),
            MessageKind::StimHeartbeat => Message::StimHeartbeat(Heartbeat {
                state: enumerated(k, &heartbeat::STATE, &d, NmtState::from_raw)?,
            }),
        };
        // Unused bytes and bits must be zero: otherwise two frames would carry one message
        // and an accepted frame would not re-encode to the bytes received.
        let page = match m {
            Message::Config(c) | Message::ConfigApplied(c) => Some(c.page.id().raw()),
            _ => None,
        };
        desc.check_reserved(page, &d)?;
        Ok(m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nmt_start_all_is_the_canopen_frame() {
        let f = Message::Nmt(Nmt {
            command: NmtCommand::Start,
            node: 0,
        })
        .encode()
        .unwrap();
        assert_eq!((f.id, f.payload()), (0x000, &[0x01, 0x00][..]));
        assert_eq!(f.to_string(), "000#0100");
    }

    #[test]
    fn boot_up_is_the_canopen_frame() {
        let f = Message::StimHeartbeat(Heartbeat {
            state: NmtState::BootUp,
        })
        .encode()
        .unwrap();
        assert_eq!((f.id, f.payload()), (0x710, &[0x00][..]));
    }

    #[test]
    fn pulse_layout_by_hand() {
        let p = Pulse {
            seq: 0x1234,
            alive_counter: 0x5,
            channel: 0x2,
            amplitude_100ua: 200,
            width_us: 300,
        };
        let f = Message::Pulse(p).encode().unwrap();
        // seq LE, counter low nibble / channel high nibble, 200 = 0x00C8, 300 = 0x012C.
        let body = [0x34, 0x12, 0x25, 0xC8, 0x00, 0x2C, 0x01];
        assert_eq!(&f.data[..7], &body);
        let mut with_id = vec![0x10, 0x01];
        with_id.extend_from_slice(&body);
        assert_eq!(f.data[7], crate::crc::crc8(&with_id));
        assert_eq!(decode(0x110, f.payload()), Ok(Message::Pulse(p)));
    }

    #[test]
    fn force_is_signed_24_bit() {
        let m = Message::Force(Force {
            seq: 1,
            force_mn: -2,
            sample_time_us: 0xFF_FFFF,
        });
        let f = m.encode().unwrap();
        assert_eq!(&f.data, &[0x01, 0x00, 0xFE, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF]);
        assert_eq!(decode(0x190, f.payload()), Ok(m));
        assert_eq!(Force::raw_force(-0.0024), Some(-2));
        assert_eq!(Force::raw_force(9000.0), None);
        assert_eq!(Force::raw_force(f64::NAN), None);
    }

    #[test]
    fn corrupted_pulse_fails_crc() {
        let p = Pulse {
            seq: 7,
            alive_counter: 1,
            channel: 0,
            amplitude_100ua: 100,
            width_us: 200,
        };
        let mut f = Message::Pulse(p).encode().unwrap();
        f.data[3] ^= 0x01;
        assert!(matches!(
            decode(0x110, f.payload()),
            Err(DecodeError::BadCrc { .. })
        ));
    }

    #[test]
    fn pulse_moved_to_another_node_fails_crc() {
        let p = Pulse {
            seq: 7,
            alive_counter: 1,
            channel: 0,
            amplitude_100ua: 100,
            width_us: 200,
        };
        let f = Message::Pulse(p).encode().unwrap();
        let other = Nodes::new(0x01, 0x11).unwrap();
        assert!(matches!(
            other.decode(0x111, f.payload()),
            Err(DecodeError::BadCrc { .. })
        ));
    }

    #[test]
    fn out_of_range_is_refused_both_ways() {
        let p = Pulse {
            seq: 0,
            alive_counter: 16,
            channel: 0,
            amplitude_100ua: 0,
            width_us: 0,
        };
        assert!(matches!(
            Message::Pulse(p).encode(),
            Err(EncodeError::OutOfRange {
                signal: "alive_counter",
                ..
            })
        ));
        let p = Pulse {
            seq: 0,
            alive_counter: 0,
            channel: 0,
            amplitude_100ua: 1501,
            width_us: 0,
        };
        assert!(matches!(
            Message::Pulse(p).encode(),
            Err(EncodeError::OutOfRange {
                signal: "amplitude",
                ..
            })
        ));
        // A width of 1001 us with a valid CRC is still refused by decode.
        let mut d = [0u8; 8];
        d[5..7].copy_from_slice(&1001u16.to_le_bytes());
        d[7] = crate::crc::frame_crc(0x110, &crc_input(&d));
        assert_eq!(
            decode(0x110, &d),
            Err(DecodeError::OutOfRange {
                message: "PULSE",
                signal: "width",
                raw: 1001
            })
        );
    }

    #[test]
    fn undefined_enum_values_are_errors() {
        assert_eq!(
            decode(0x000, &[0x03, 0x00]),
            Err(DecodeError::UnknownValue {
                message: "NMT",
                signal: "command",
                raw: 3
            })
        );
        assert_eq!(
            decode(0x701, &[0x01]),
            Err(DecodeError::UnknownValue {
                message: "HOST_HEARTBEAT",
                signal: "state",
                raw: 1
            })
        );
        // Page 3 is the first undefined page (0-2 are output limits, rate, charge).
        assert!(matches!(
            decode(0x310, &[3, 1, 0, 0, 0, 0, 1, 0]),
            Err(DecodeError::OutOfRange { signal: "page", .. })
        ));
        assert!(matches!(
            decode(0x390, &[3, 1, 0, 0, 0, 0, 1, 0]),
            Err(DecodeError::OutOfRange { signal: "page", .. })
        ));
    }

    #[test]
    fn wrong_length_and_unknown_id() {
        assert_eq!(
            decode(0x701, &[0x05, 0x00]),
            Err(DecodeError::WrongLength {
                message: "HOST_HEARTBEAT",
                expected: 1,
                actual: 2
            })
        );
        assert_eq!(
            decode(0x123, &[]),
            Err(DecodeError::UnknownId { id: 0x123 })
        );
    }

    #[test]
    fn config_id_zero_is_reserved() {
        let c = Config {
            config_id: 0,
            page: ConfigPage::RateAndWatchdog {
                max_pulses: 1,
                rate_window_ms: 1,
                watchdog_ms: 20,
            },
        };
        assert!(Message::Config(c).encode().is_err());
    }
}
