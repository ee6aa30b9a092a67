//! Unused bytes and bits must be zero in every message and CONFIG page: a frame with a
//! reserved bit set is refused with `DecodeError::ReservedNonZero` naming the byte, so an
//! accepted frame has one meaning and re-encodes to exactly the bytes received.

use fes_can::table::MESSAGES;
use fes_can::{
    Config, ConfigPage, DecodeError, Emcy, ErrorCode, Force, Heartbeat, Message, MessageKind, Nmt,
    NmtCommand, NmtState, Pulse, Status, StimState, decode,
};

const OUTPUT: ConfigPage = ConfigPage::OutputLimits {
    max_amplitude_100ua: 1000,
    max_width_us: 500,
    min_ipi_ms: 1,
};
const RATE: ConfigPage = ConfigPage::RateAndWatchdog {
    max_pulses: 100,
    rate_window_ms: 1000,
    watchdog_ms: 100,
};
const CHARGE: ConfigPage = ConfigPage::Charge {
    max_charge_10nc: 263,
};

/// One valid message of every kind and CONFIG page.
fn one_of_each() -> Vec<Message> {
    let mut all = vec![
        Message::Nmt(Nmt {
            command: NmtCommand::Start,
            node: 0x10,
        }),
        Message::Emcy(Emcy::new(ErrorCode::BadCrc, StimState::Fault, 7, 0x1234)),
        Message::Pulse(Pulse {
            seq: 1,
            alive_counter: 2,
            channel: 3,
            amplitude_100ua: 200,
            width_us: 300,
        }),
        Message::Force(Force {
            seq: 9,
            force_mn: -5,
            sample_time_us: 77,
        }),
        Message::Status(Status {
            state: StimState::PreOperational,
            counter: 4,
            last_error: ErrorCode::NoError,
            pulses_delivered: 12,
            rejected: 1,
            config_id: 16,
        }),
        Message::HostHeartbeat(Heartbeat {
            state: NmtState::Operational,
        }),
        Message::StimHeartbeat(Heartbeat {
            state: NmtState::PreOperational,
        }),
    ];
    for page in [OUTPUT, RATE, CHARGE] {
        let c = Config {
            config_id: 16,
            page,
        };
        all.push(Message::Config(c));
        all.push(Message::ConfigApplied(c));
    }
    all
}

/// The page a message's reserved bits depend on.
fn page_of(m: &Message) -> Option<u8> {
    match m {
        Message::Config(c) | Message::ConfigApplied(c) => Some(c.page.id().raw()),
        _ => None,
    }
}

/// The frame of `m` with `byte` set to `value`.
fn with_byte(m: Message, byte: usize, value: u8) -> (u32, Vec<u8>) {
    let f = m.encode().unwrap();
    let mut data = f.payload().to_vec();
    data[byte] = value;
    (u32::from(f.id), data)
}

/// The input `scripts/fuzz` found (fuzz/regressions/can_frame/): a CONFIG_APPLIED charge
/// page with bytes 5 and 6 set re-encoded to `[2, 16, 7, 1, 0, 0, 0, 0]`.
#[test]
fn the_fuzzed_config_applied_charge_page_with_unused_bytes_set_is_refused() {
    assert_eq!(
        decode(0x390, &[0x02, 0x10, 0x07, 0x01, 0x00, 0x07, 0xff, 0x00]),
        Err(DecodeError::ReservedNonZero {
            message: "CONFIG_APPLIED",
            byte: 5,
            value: 0x07
        })
    );
    // The same page with its unused bytes zero is accepted.
    assert_eq!(
        decode(0x390, &[0x02, 0x10, 0x07, 0x01, 0x00, 0x00, 0x00, 0x00]),
        Ok(Message::ConfigApplied(Config {
            config_id: 16,
            page: CHARGE
        }))
    );
}

/// The charge page uses bytes 0-3 (page, config_id, max_charge); 4-7 are reserved.
fn charge_page_refuses_each_reserved_byte(m: Message, name: &'static str) {
    for byte in 4..8 {
        for value in [0x01, 0x80, 0xff] {
            let (id, data) = with_byte(m, byte, value);
            assert_eq!(
                decode(id, &data),
                Err(DecodeError::ReservedNonZero {
                    message: name,
                    byte,
                    value
                }),
                "{name} charge page, byte {byte} = {value:#04x}"
            );
        }
    }
}

#[test]
fn a_config_charge_page_with_a_non_zero_reserved_byte_is_refused() {
    let c = Config {
        config_id: 16,
        page: CHARGE,
    };
    charge_page_refuses_each_reserved_byte(Message::Config(c), "CONFIG");
}

#[test]
fn a_config_applied_charge_page_with_a_non_zero_reserved_byte_is_refused() {
    let c = Config {
        config_id: 16,
        page: CHARGE,
    };
    charge_page_refuses_each_reserved_byte(Message::ConfigApplied(c), "CONFIG_APPLIED");
}

/// Which bits are reserved, per message and page: only the charge page has any (bytes
/// 4-7); every other message and page fills its DLC with signals, so a reserved bit can
/// only appear there. Changing a layout must update this test (and the DBC, which
/// `dbc_consistency` compares with the table).
#[test]
fn only_the_charge_page_has_reserved_bits() {
    for m in one_of_each() {
        let desc = m.kind().desc();
        let dlc_bits = if desc.dlc == 8 {
            u64::MAX
        } else {
            (1u64 << (8 * desc.dlc)) - 1
        };
        let expected_reserved = match page_of(&m) {
            Some(2) => 0xFFFF_FFFF_0000_0000,
            _ => 0,
        };
        assert_eq!(
            dlc_bits & !desc.used_bits(page_of(&m)),
            expected_reserved,
            "{m:?}"
        );
    }
    assert_eq!(MESSAGES.len(), MessageKind::ALL.len());
}

/// Every reserved bit of every message kind and page, set alone in a valid frame, is
/// refused naming its byte (whatever layout the table has).
#[test]
fn any_reserved_bit_of_any_message_or_page_is_refused_naming_its_byte() {
    let mut checked = 0;
    for m in one_of_each() {
        let f = m.encode().unwrap();
        let desc = m.kind().desc();
        let used = desc.used_bits(page_of(&m));
        for bit in 0..8 * usize::from(desc.dlc) {
            if used >> bit & 1 == 1 {
                continue;
            }
            let mut data = f.payload().to_vec();
            data[bit / 8] |= 1 << (bit % 8);
            assert_eq!(
                decode(u32::from(f.id), &data),
                Err(DecodeError::ReservedNonZero {
                    message: desc.name,
                    byte: bit / 8,
                    value: data[bit / 8]
                }),
                "{m:?}, bit {bit}"
            );
            checked += 1;
        }
        // The frame itself, reserved bits zero, is accepted and canonical.
        assert_eq!(decode(u32::from(f.id), f.payload()), Ok(m));
    }
    // Two charge pages (CONFIG, CONFIG_APPLIED) x 32 reserved bits.
    assert_eq!(checked, 64);
}

#[test]
fn a_reserved_bit_is_a_value_out_of_range_emergency() {
    let e = DecodeError::ReservedNonZero {
        message: "CONFIG",
        byte: 4,
        value: 1,
    };
    assert_eq!(e.error_code(), ErrorCode::ValueOutOfRange);
    assert_eq!(e.to_string(), "CONFIG: reserved byte 4 is 0x01, must be 0");
}
