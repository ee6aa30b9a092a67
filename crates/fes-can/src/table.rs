//! The descriptor table: the codec's statement of `dbc/fes.dbc`.
//!
//! `tests/it/dbc_consistency.rs` parses the DBC and compares every message (COB-ID, DLC,
//! cycle time, sender) and every signal (start bit, length, byte order, signedness,
//! factor, offset, min, max, unit, multiplexing, value table) with this table.

use crate::desc::{MessageDesc, SignalDesc};
use crate::ids::{MessageKind, Role};
use crate::values::{ConfigPageId, ErrorCode, NmtCommand, NmtState, StimState};

/// NMT (COB-ID 0x000): CANopen node control.
pub mod nmt {
    use super::*;
    /// NMT command.
    pub const COMMAND: SignalDesc = SignalDesc::new("command", 0, 8)
        .range(1.0, 130.0)
        .values(NmtCommand::VALUES);
    /// Addressed node (0 = all).
    pub const NODE: SignalDesc = SignalDesc::new("node", 8, 8).range(0.0, 127.0);
    /// All signals in DBC order.
    pub const SIGNALS: &[SignalDesc] = &[COMMAND, NODE];
}

/// EMCY (COB-ID 0x080 + stimulator).
pub mod emcy {
    use super::*;
    /// CANopen error code.
    pub const ERROR_CODE: SignalDesc =
        SignalDesc::new("error_code", 0, 16).values(ErrorCode::VALUES);
    /// CANopen error register.
    pub const ERROR_REGISTER: SignalDesc = SignalDesc::new("error_register", 16, 8);
    /// Stimulator state at the time.
    pub const STATE: SignalDesc = SignalDesc::new("state", 24, 8)
        .range(0.0, 5.0)
        .values(StimState::VALUES);
    /// Sequence number of the offending PULSE (else 0).
    pub const SEQ: SignalDesc = SignalDesc::new("seq", 32, 16);
    /// Code-specific detail.
    pub const DETAIL: SignalDesc = SignalDesc::new("detail", 48, 16);
    /// All signals in DBC order.
    pub const SIGNALS: &[SignalDesc] = &[ERROR_CODE, ERROR_REGISTER, STATE, SEQ, DETAIL];
}

/// PULSE (COB-ID 0x100 + stimulator).
pub mod pulse {
    use super::*;
    /// Pulse sequence number.
    pub const SEQ: SignalDesc = SignalDesc::new("seq", 0, 16);
    /// Alive counter (mod 16).
    pub const ALIVE_COUNTER: SignalDesc = SignalDesc::new("alive_counter", 16, 4);
    /// Output channel.
    pub const CHANNEL: SignalDesc = SignalDesc::new("channel", 20, 4);
    /// Amplitude, 0.1 mA per bit.
    pub const AMPLITUDE: SignalDesc = SignalDesc::new("amplitude", 24, 16)
        .scale(0.1, 0.0)
        .range(0.0, 150.0)
        .unit("mA");
    /// Width, 1 us per bit.
    pub const WIDTH: SignalDesc = SignalDesc::new("width", 40, 16)
        .range(0.0, 1000.0)
        .unit("us");
    /// CRC-8/SAE-J1850 over COB-ID and bytes 0-6.
    pub const CRC: SignalDesc = SignalDesc::new("crc", 56, 8);
    /// All signals in DBC order.
    pub const SIGNALS: &[SignalDesc] = &[SEQ, ALIVE_COUNTER, CHANNEL, AMPLITUDE, WIDTH, CRC];
    const _: () = assert!(
        CRC.start_bit == 56 && CRC.length == 8,
        "the CRC must be the last byte"
    );
}

/// FORCE (COB-ID 0x180 + stimulator), every 1 ms.
pub mod force {
    use super::*;
    /// Frame counter.
    pub const SEQ: SignalDesc = SignalDesc::new("seq", 0, 16);
    /// Force, 1 mN per bit, signed 24 bits.
    pub const FORCE: SignalDesc = SignalDesc::new("force", 16, 24)
        .signed()
        .scale(0.001, 0.0)
        .range(-8388.608, 8388.607)
        .unit("N");
    /// Sample time, us modulo 2^24.
    pub const SAMPLE_TIME: SignalDesc = SignalDesc::new("sample_time", 40, 24).unit("us");
    /// All signals in DBC order.
    pub const SIGNALS: &[SignalDesc] = &[SEQ, FORCE, SAMPLE_TIME];
}

/// STATUS (COB-ID 0x280 + stimulator), every 10 ms.
pub mod status {
    use super::*;
    /// Stimulator state.
    pub const STATE: SignalDesc = SignalDesc::new("state", 0, 4)
        .range(0.0, 5.0)
        .values(StimState::VALUES);
    /// Status counter (mod 16).
    pub const COUNTER: SignalDesc = SignalDesc::new("counter", 4, 4);
    /// Most recent emergency code.
    pub const LAST_ERROR: SignalDesc =
        SignalDesc::new("last_error", 8, 16).values(ErrorCode::VALUES);
    /// Pulses applied, modulo 2^24.
    pub const PULSES_DELIVERED: SignalDesc =
        SignalDesc::new("pulses_delivered", 24, 24).unit("pulses");
    /// Frames rejected, modulo 2^8.
    pub const REJECTED: SignalDesc = SignalDesc::new("rejected", 48, 8).unit("frames");
    /// Active configuration id.
    pub const CONFIG_ID: SignalDesc = SignalDesc::new("config_id", 56, 8);
    /// All signals in DBC order.
    pub const SIGNALS: &[SignalDesc] = &[
        STATE,
        COUNTER,
        LAST_ERROR,
        PULSES_DELIVERED,
        REJECTED,
        CONFIG_ID,
    ];
}

/// CONFIG (COB-ID 0x300 + stimulator), multiplexed by `page`; CONFIG_APPLIED (COB-ID
/// 0x380 + stimulator) has the same layout.
pub mod config {
    use super::*;
    /// Page multiplexor.
    pub const PAGE: SignalDesc = SignalDesc::new("page", 0, 8)
        .multiplexor()
        .range(0.0, 2.0)
        .values(ConfigPageId::VALUES);
    /// Configuration id (0 is reserved for the stimulator's defaults).
    pub const CONFIG_ID: SignalDesc = SignalDesc::new("config_id", 8, 8).range(1.0, 255.0);
    /// Page 0: amplitude ceiling, 0.1 mA per bit.
    pub const MAX_AMPLITUDE: SignalDesc = SignalDesc::new("max_amplitude", 16, 16)
        .page(0)
        .scale(0.1, 0.0)
        .range(0.0, 150.0)
        .unit("mA");
    /// Page 0: width ceiling.
    pub const MAX_WIDTH: SignalDesc = SignalDesc::new("max_width", 32, 16)
        .page(0)
        .range(0.0, 1000.0)
        .unit("us");
    /// Page 0: minimum inter-pulse interval.
    pub const MIN_IPI: SignalDesc = SignalDesc::new("min_ipi", 48, 16)
        .page(0)
        .range(1.0, 1000.0)
        .unit("ms");
    /// Page 1: most pulses in one rate window.
    pub const MAX_PULSES: SignalDesc = SignalDesc::new("max_pulses", 16, 16)
        .page(1)
        .range(1.0, 1000.0)
        .unit("pulses");
    /// Page 1: rate window.
    pub const RATE_WINDOW: SignalDesc = SignalDesc::new("rate_window", 32, 16)
        .page(1)
        .range(1.0, 60000.0)
        .unit("ms");
    /// Page 1: host heartbeat timeout.
    pub const WATCHDOG: SignalDesc = SignalDesc::new("watchdog", 48, 16)
        .page(1)
        .range(20.0, 5000.0)
        .unit("ms");
    /// Page 2: charge-per-phase ceiling, 0.01 uC (10 nC) per bit.
    pub const MAX_CHARGE: SignalDesc = SignalDesc::new("max_charge", 16, 16)
        .page(2)
        .scale(0.01, 0.0)
        .range(0.0, 150.0)
        .unit("uC");
    /// All signals in DBC order.
    pub const SIGNALS: &[SignalDesc] = &[
        PAGE,
        CONFIG_ID,
        MAX_AMPLITUDE,
        MAX_WIDTH,
        MIN_IPI,
        MAX_PULSES,
        RATE_WINDOW,
        WATCHDOG,
        MAX_CHARGE,
    ];
}

/// HOST_HEARTBEAT / STIM_HEARTBEAT (COB-ID 0x700 + sender).
pub mod heartbeat {
    use super::*;
    /// NMT state of the sender.
    pub const STATE: SignalDesc = SignalDesc::new("state", 0, 8)
        .range(0.0, 127.0)
        .values(NmtState::VALUES);
    /// All signals in DBC order.
    pub const SIGNALS: &[SignalDesc] = &[STATE];
}

/// Every message, indexed by `MessageKind as usize`.
pub const MESSAGES: [MessageDesc; 9] = [
    MessageDesc {
        kind: MessageKind::Nmt,
        name: "NMT",
        function_code: 0x000,
        id_node: None,
        dlc: 2,
        cycle_time_ms: None,
        sender: Role::Host,
        receiver: Role::Stim,
        signals: nmt::SIGNALS,
    },
    MessageDesc {
        kind: MessageKind::Emcy,
        name: "EMCY",
        function_code: 0x080,
        id_node: Some(Role::Stim),
        dlc: 8,
        cycle_time_ms: None,
        sender: Role::Stim,
        receiver: Role::Host,
        signals: emcy::SIGNALS,
    },
    MessageDesc {
        kind: MessageKind::Pulse,
        name: "PULSE",
        function_code: 0x100,
        id_node: Some(Role::Stim),
        dlc: 8,
        cycle_time_ms: None,
        sender: Role::Host,
        receiver: Role::Stim,
        signals: pulse::SIGNALS,
    },
    MessageDesc {
        kind: MessageKind::Force,
        name: "FORCE",
        function_code: 0x180,
        id_node: Some(Role::Stim),
        dlc: 8,
        cycle_time_ms: Some(1),
        sender: Role::Stim,
        receiver: Role::Host,
        signals: force::SIGNALS,
    },
    MessageDesc {
        kind: MessageKind::Status,
        name: "STATUS",
        function_code: 0x280,
        id_node: Some(Role::Stim),
        dlc: 8,
        cycle_time_ms: Some(10),
        sender: Role::Stim,
        receiver: Role::Host,
        signals: status::SIGNALS,
    },
    MessageDesc {
        kind: MessageKind::Config,
        name: "CONFIG",
        function_code: 0x300,
        id_node: Some(Role::Stim),
        dlc: 8,
        cycle_time_ms: None,
        sender: Role::Host,
        receiver: Role::Stim,
        signals: config::SIGNALS,
    },
    MessageDesc {
        kind: MessageKind::ConfigApplied,
        name: "CONFIG_APPLIED",
        function_code: 0x380,
        id_node: Some(Role::Stim),
        dlc: 8,
        cycle_time_ms: None,
        sender: Role::Stim,
        receiver: Role::Host,
        signals: config::SIGNALS,
    },
    MessageDesc {
        kind: MessageKind::HostHeartbeat,
        name: "HOST_HEARTBEAT",
        function_code: 0x700,
        id_node: Some(Role::Host),
        dlc: 1,
        cycle_time_ms: Some(10),
        sender: Role::Host,
        receiver: Role::Stim,
        signals: heartbeat::SIGNALS,
    },
    MessageDesc {
        kind: MessageKind::StimHeartbeat,
        name: "STIM_HEARTBEAT",
        function_code: 0x700,
        id_node: Some(Role::Stim),
        dlc: 1,
        cycle_time_ms: Some(100),
        sender: Role::Stim,
        receiver: Role::Host,
        signals: heartbeat::SIGNALS,
    },
];

#[cfg(test)]
mod tests {
    use super::*;
    use crate::desc::ByteOrder;

    #[test]
    fn signals_fit_their_frame_and_do_not_overlap() {
        for m in &MESSAGES {
            // Each multiplexor page (and the plain signals) must be overlap-free.
            for page in [None, Some(0u8), Some(1u8), Some(2u8)] {
                let mut used = 0u64;
                for s in m.signals {
                    let present = match s.mux {
                        crate::desc::Mux::Page(p) => Some(p) == page,
                        _ => true,
                    };
                    if !present {
                        continue;
                    }
                    assert_eq!(s.byte_order, ByteOrder::LittleEndian);
                    assert!(
                        u32::from(s.start_bit) + u32::from(s.length) <= 8 * u32::from(m.dlc),
                        "{}.{}",
                        m.name,
                        s.name
                    );
                    let bits = ((1u128 << s.length) - 1) as u64;
                    let bits = bits << s.start_bit;
                    assert_eq!(used & bits, 0, "{}.{} overlaps", m.name, s.name);
                    used |= bits;
                }
            }
        }
    }

    #[test]
    fn raw_ranges_fit_the_bit_width() {
        for m in &MESSAGES {
            for s in m.signals {
                let (lo, hi) = if s.signed {
                    (-(1i128 << (s.length - 1)), (1i128 << (s.length - 1)) - 1)
                } else {
                    (0, (1i128 << s.length) - 1)
                };
                assert!(
                    i128::from(s.raw_min()) >= lo && i128::from(s.raw_max()) <= hi,
                    "{}.{}",
                    m.name,
                    s.name
                );
                assert!(s.raw_min() <= s.raw_max());
                // The physical bounds are exactly representable raw values.
                assert!((s.physical(s.raw_min()) - s.min).abs() < 1e-9 * s.min.abs().max(1.0));
                assert!((s.physical(s.raw_max()) - s.max).abs() < 1e-9 * s.max.abs().max(1.0));
            }
        }
    }
}
