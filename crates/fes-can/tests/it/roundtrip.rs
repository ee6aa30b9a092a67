//! Property tests of the codec: encode -> decode is the identity on every message's valid
//! range; any payload of any length on any identifier decodes to a value or an error
//! (never a panic), and whatever decodes re-encodes to the very same bytes; any
//! single-bit error in a PULSE frame is caught.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use fes_can::{
    Config, ConfigPage, DecodeError, Emcy, ErrorCode, Force, Heartbeat, Message, Nmt, NmtCommand,
    NmtState, Nodes, Pulse, Status, StimState, decode,
};
use proptest::prelude::*;

fn pick<T: Copy + core::fmt::Debug + 'static>(all: &'static [T]) -> impl Strategy<Value = T> {
    proptest::sample::select(all)
}

fn nmt() -> impl Strategy<Value = Message> {
    (pick(NmtCommand::ALL), 0u8..=127)
        .prop_map(|(command, node)| Message::Nmt(Nmt { command, node }))
}

fn emcy() -> impl Strategy<Value = Message> {
    (
        pick(ErrorCode::ALL),
        any::<u8>(),
        pick(StimState::ALL),
        any::<u16>(),
        any::<u16>(),
    )
        .prop_map(|(code, register, state, seq, detail)| {
            Message::Emcy(Emcy {
                code,
                register,
                state,
                seq,
                detail,
            })
        })
}

fn pulse() -> impl Strategy<Value = Message> {
    (any::<u16>(), 0u8..16, 0u8..16, 0u16..=1500, 0u16..=1000).prop_map(
        |(seq, alive_counter, channel, amplitude_100ua, width_us)| {
            Message::Pulse(Pulse {
                seq,
                alive_counter,
                channel,
                amplitude_100ua,
                width_us,
            })
        },
    )
}

fn force() -> impl Strategy<Value = Message> {
    (any::<u16>(), -8_388_608i32..=8_388_607, 0u32..(1 << 24)).prop_map(
        |(seq, force_mn, sample_time_us)| {
            Message::Force(Force {
                seq,
                force_mn,
                sample_time_us,
            })
        },
    )
}

fn status() -> impl Strategy<Value = Message> {
    (
        pick(StimState::ALL),
        0u8..16,
        pick(ErrorCode::ALL),
        0u32..(1 << 24),
        any::<u8>(),
        any::<u8>(),
    )
        .prop_map(
            |(state, counter, last_error, pulses_delivered, rejected, config_id)| {
                Message::Status(Status {
                    state,
                    counter,
                    last_error,
                    pulses_delivered,
                    rejected,
                    config_id,
                })
            },
        )
}

fn config() -> impl Strategy<Value = Message> {
    let output =
        (0u16..=1500, 0u16..=1000, 1u16..=1000).prop_map(|(a, w, i)| ConfigPage::OutputLimits {
            max_amplitude_100ua: a,
            max_width_us: w,
            min_ipi_ms: i,
        });
    let rate = (1u16..=1000, 1u16..=60000, 20u16..=5000).prop_map(|(p, r, w)| {
        ConfigPage::RateAndWatchdog {
            max_pulses: p,
            rate_window_ms: r,
            watchdog_ms: w,
        }
    });
    let charge = (0u16..=15000).prop_map(|c| ConfigPage::Charge { max_charge_10nc: c });
    (1u8..=255, prop_oneof![output, rate, charge], any::<bool>()).prop_map(
        |(config_id, page, applied)| {
            let c = Config { config_id, page };
            if applied {
                Message::ConfigApplied(c)
            } else {
                Message::Config(c)
            }
        },
    )
}

fn heartbeat() -> impl Strategy<Value = Message> {
    (pick(NmtState::ALL), any::<bool>()).prop_map(|(state, host)| {
        if host {
            Message::HostHeartbeat(Heartbeat { state })
        } else {
            Message::StimHeartbeat(Heartbeat { state })
        }
    })
}

fn any_message() -> impl Strategy<Value = Message> {
    prop_oneof![
        nmt(),
        emcy(),
        pulse(),
        force(),
        status(),
        config(),
        heartbeat()
    ]
}

fn any_nodes() -> impl Strategy<Value = Nodes> {
    (1u8..=127, 1u8..=127).prop_filter_map("distinct nodes", |(h, s)| Nodes::new(h, s).ok())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(4000))]

    #[test]
    fn encode_then_decode_is_identity(m in any_message()) {
        let f = m.encode().expect("valid range encodes");
        prop_assert_eq!(f.payload().len(), usize::from(m.kind().desc().dlc));
        prop_assert_eq!(decode(u32::from(f.id), f.payload()), Ok(m));
    }

    #[test]
    fn identity_holds_for_any_node_ids(m in any_message(), nodes in any_nodes()) {
        let f = m.encode_for(&nodes).expect("valid range encodes");
        prop_assert_eq!(nodes.decode(u32::from(f.id), f.payload()), Ok(m));
    }

    #[test]
    fn random_frames_never_panic_and_accepted_frames_are_canonical(
        id in prop_oneof![0u32..0x800, any::<u32>()],
        data in proptest::collection::vec(any::<u8>(), 0..=16),
    ) {
        if let Ok(m) = decode(id, &data) {
            let f = m.encode().expect("a decoded message re-encodes");
            prop_assert_eq!(u32::from(f.id), id);
            prop_assert_eq!(f.payload(), &data[..]);
        }
    }

    #[test]
    fn random_payloads_on_protocol_ids_never_panic(
        kind in 0usize..8,
        data in proptest::collection::vec(any::<u8>(), 0..=8),
    ) {
        let id = Nodes::DEFAULT.id_of(fes_can::MessageKind::ALL[kind]);
        let _ = decode(u32::from(id), &data);
    }

    #[test]
    fn every_single_bit_error_in_a_pulse_is_detected(m in pulse(), bit in 0usize..64) {
        let f = m.encode().expect("valid pulse");
        let mut data = f.data;
        data[bit / 8] ^= 1 << (bit % 8);
        let caught = matches!(decode(u32::from(f.id), &data), Err(DecodeError::BadCrc { .. }));
        prop_assert!(caught, "bit {} flipped in {:?} went undetected", bit, f.data);
    }
}
