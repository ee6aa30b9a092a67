//! Property tests of the codec: encode -> decode is the identity for every message; any
//! byte stream, in any chunking, decodes to packets or errors (never a panic), and every
//! packet it yields re-encodes to the bytes it came from; changing any one byte of an
//! encoded packet is detected (no packet comes out).
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use fes_sciencemode::{
    AckResult, ChannelListInit, ChannelListUpdate, ChannelPulse, Decoder, MAX_PACKET_LEN, Message,
    Packet, PhaseResult, PulseMode, SinglePulse, StimulationError, StimulationMode,
};
use proptest::prelude::*;

fn ack() -> impl Strategy<Value = AckResult> {
    any::<i8>().prop_map(AckResult::from_code)
}

fn channel_pulse() -> impl Strategy<Value = ChannelPulse> {
    (
        proptest::sample::select(PulseMode::ALL),
        any::<u16>(),
        any::<u8>(),
    )
        .prop_map(|(mode, pulse_width_us, current_ma)| ChannelPulse {
            mode,
            pulse_width_us,
            current_ma,
        })
}

pub fn message() -> impl Strategy<Value = Message> {
    prop_oneof![
        any::<u8>().prop_map(|version| Message::Init { version }),
        ack().prop_map(|result| Message::InitAck { result }),
        any::<u8>().prop_map(|command| Message::UnknownCommand { command }),
        Just(Message::Watchdog),
        Just(Message::GetStimulationMode),
        // §4.2: an error acknowledgement may carry the result only; a successful one
        // always carries the mode.
        (
            ack(),
            proptest::option::of(proptest::sample::select(StimulationMode::ALL))
        )
            .prop_map(|(result, mode)| Message::GetStimulationModeAck {
                result,
                mode: if result.is_ok() {
                    Some(mode.unwrap_or(StimulationMode::Start))
                } else {
                    mode
                },
            }),
        (
            any::<u8>(),
            any::<u8>(),
            any::<u8>(),
            any::<u8>(),
            any::<u16>(),
            any::<u8>()
        )
            .prop_map(
                |(a, b, c, d, e, f)| Message::InitChannelListMode(ChannelListInit {
                    low_frequency_factor: a,
                    active_channels: b,
                    low_frequency_channels: c,
                    inter_pulse_interval_code: d,
                    main_interval_code: e,
                    channel_execution: f,
                })
            ),
        ack().prop_map(|result| Message::InitChannelListModeAck { result }),
        proptest::collection::vec(channel_pulse(), 1..=8).prop_map(|entries| {
            Message::StartChannelListMode(ChannelListUpdate::new(&entries).unwrap())
        }),
        ack().prop_map(|result| Message::StartChannelListModeAck { result }),
        Just(Message::StopChannelListMode),
        ack().prop_map(|result| Message::StopChannelListModeAck { result }),
        (any::<u8>(), any::<u16>(), any::<u8>()).prop_map(|(channel, w, c)| {
            Message::SinglePulse(SinglePulse {
                channel,
                pulse_width_us: w,
                current_ma: c,
            })
        }),
        ack().prop_map(|result| Message::SinglePulseAck { result }),
        any::<i8>().prop_map(|c| Message::StimulationError {
            error: StimulationError::from_code(c)
        }),
        proptest::collection::vec(any::<u8>(), 16).prop_map(|b| {
            let w = |i: usize| u16::from_be_bytes([b[i], b[i + 1]]);
            Message::PhaseResult(PhaseResult {
                phase_counter: b[0],
                passive_distance_10m: w(1),
                active_distance_10m: w(3),
                average_power_w: b[5],
                maximum_power_w: b[6],
                phase_duration_s: w(7),
                active_phase_duration_s: w(9),
                phase_work_j: w(11),
                success_percent: b[13],
                symmetry_left_percent: b[14],
                average_muscle_tone_dnm: b[15],
            })
        }),
        (any::<u16>(), any::<i16>(), any::<i16>()).prop_map(|(a, s, t)| {
            Message::ActualValues {
                angle_deg: a,
                speed_rpm: s,
                torque_dnm: t,
            }
        }),
        ack().prop_map(|result| Message::MotomedCommandDone { result }),
        any::<i8>().prop_map(|code| Message::MotomedError { code }),
    ]
}

fn packet() -> impl Strategy<Value = Packet> {
    (any::<u8>(), message()).prop_map(|(n, m)| Packet::new(n, m))
}

/// The encoding, or `None` when the stuffed packet exceeds 69 bytes (a channel list full
/// of special bytes).
fn encode(p: &Packet) -> Option<Vec<u8>> {
    let mut buf = [0u8; MAX_PACKET_LEN];
    match p.encode(&mut buf) {
        Ok(n) => Some(buf[..n].to_vec()),
        Err(fes_sciencemode::EncodeError::TooLong { .. }) => None,
        Err(e) => panic!("{p:?}: {e}"),
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn encode_then_decode_is_the_identity(p in packet(), noise in proptest::collection::vec(any::<u8>(), 0..8)) {
        let Some(wire) = encode(&p) else { return Ok(()); };
        prop_assert!(wire.len() <= MAX_PACKET_LEN);
        // After noise that holds no start byte, the packet decodes to itself.
        let mut stream: Vec<u8> = noise.into_iter().filter(|&b| b != 0xF0).collect();
        stream.extend_from_slice(&wire);
        let out: Vec<_> = Decoder::new().feed(&stream).collect();
        prop_assert_eq!(out, vec![Ok(p)]);
    }

    #[test]
    fn packets_back_to_back_decode_in_order(ps in proptest::collection::vec(packet(), 1..6), chunk in 1usize..20) {
        let mut stream = Vec::new();
        let mut expected = Vec::new();
        for p in &ps {
            if let Some(w) = encode(p) {
                stream.extend_from_slice(&w);
                expected.push(Ok(*p));
            }
        }
        let mut d = Decoder::new();
        let mut out = Vec::new();
        for c in stream.chunks(chunk) {
            out.extend(d.feed(c));
        }
        prop_assert_eq!(out, expected);
    }

    #[test]
    fn any_byte_stream_decodes_without_panic_and_packets_reencode(bytes in proptest::collection::vec(any::<u8>(), 0..300)) {
        let mut d = Decoder::new();
        // Every packet decoded re-encodes (in the description's stuffing, which may differ
        // from the bytes it came from: the decoder un-stuffs any byte after 0x81) to bytes
        // that decode to the same packet.
        for &b in &bytes {
            if let Some(Ok(p)) = d.push(b) {
                let wire = encode(&p).expect("a decoded packet fits a packet");
                let again: Vec<_> = Decoder::new().feed(&wire).collect();
                prop_assert_eq!(again, vec![Ok(p)], "{:?} re-encodes to {:02X?}", p, wire);
            }
        }
    }

    #[test]
    fn the_encoder_escapes_only_the_table_6_constants(p in packet()) {
        // §2.2: 0xF0, 0x0F and 0x81 are escaped, the stuffing key 0x55 (and 0x0A) are not:
        // after the header, a byte is 0x81 only as an escape, and the stuffed data is the
        // unstuffed data plus one byte per 0xF0, 0x0F or 0x81 in it.
        let Some(wire) = encode(&p) else { return Ok(()); };
        let (data, len) = p.data();
        let specials = data[..len].iter().filter(|&&b| matches!(b, 0xF0 | 0x0F | 0x81)).count();
        prop_assert_eq!(wire.len(), 5 + len + specials + 1);
    }

    #[test]
    fn any_single_byte_change_is_detected(p in packet(), pos in any::<prop::sample::Index>(), value in any::<u8>()) {
        let Some(mut wire) = encode(&p) else { return Ok(()); };
        let i = pos.index(wire.len());
        prop_assume!(wire[i] != value);
        wire[i] = value;
        let out: Vec<_> = Decoder::new().feed(&wire).collect();
        prop_assert!(out.iter().all(Result::is_err), "{wire:02X?} decoded to {out:?}");
    }
}

#[test]
fn codes_keep_one_meaning() {
    for c in i8::MIN..=i8::MAX {
        assert_eq!(AckResult::from_code(c).code(), c);
        assert_eq!(StimulationError::from_code(c).code(), c);
    }
    assert!(AckResult::from_code(0).is_ok());
    assert!(!AckResult::from_code(-8).is_ok());
    assert_eq!(AckResult::from_code(-8), AckResult::BusyError);
}
