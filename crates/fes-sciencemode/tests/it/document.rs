//! Vectors built from "ScienceMode2 – Description and Protocol" v1.24 (HASOMED, 2012-12-12)
//! itself: each packet's bytes follow the section and table cited in its comment. The
//! checksums were computed by a separate Python implementation of §2.2 (CRC-8, polynomial
//! 0x07, over the stuffed packet data) and pasted here.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use fes_sciencemode::{AckResult, DecodeError, Message, Packet, PhaseResult, StimulationMode};

use super::support::{check, decode_all, encode, wrap};

/// Frames unstuffed packet data as §2.2 / Table 6 say (test side, independent of the
/// codec's encoder): 0xF0, 0x0F and 0x81 escaped as 0x81, byte ^ 0x55.
fn frame(data: &[u8]) -> Vec<u8> {
    let mut stuffed = Vec::new();
    for &b in data {
        if matches!(b, 0xF0 | 0x0F | 0x81) {
            stuffed.extend([0x81, b ^ 0x55]);
        } else {
            stuffed.push(b);
        }
    }
    wrap(&stuffed)
}

fn single_pulse_ack(number: u8) -> Packet {
    Packet::new(
        number,
        Message::SinglePulseAck {
            result: AckResult::Ok,
        },
    )
}

#[test]
fn acks_to_packet_numbers_0x0a_and_0x55_are_sent_and_read_as_they_are() {
    // §2.2: the device echoes the host's packet number in each response; 0x0A and the
    // stuffing key 0x55 are not Table 6 constants that get escaped, so SinglePulseAck
    // (§4.3: echo number, 37, result) to packets 10 and 85 carries them raw.
    check(
        single_pulse_ack(0x0A),
        &[0xF0, 0x81, 0x3D, 0x81, 0x56, 0x0A, 0x25, 0x00, 0x0F],
    );
    check(
        single_pulse_ack(0x55),
        &[0xF0, 0x81, 0x5E, 0x81, 0x56, 0x55, 0x25, 0x00, 0x0F],
    );
    // Every packet number decodes, whatever the form it arrives in.
    for n in 0..=255u8 {
        let data = [n, 0x25, 0x00];
        assert_eq!(decode_all(&frame(&data)), [Ok(single_pulse_ack(n))], "{n}");
        assert_eq!(encode(&single_pulse_ack(n)), frame(&data), "{n}");
    }
}

#[test]
fn acks_to_packet_numbers_0x0f_0xf0_0x81_are_escaped() {
    // §2.2 / Table 6: stop byte, start byte and stuffing byte are escaped as 0x81 then
    // the byte XOR the stuffing key 0x55 (the description's example: 0xF0 -> 0x81, 0xA5).
    check(
        single_pulse_ack(0x0F),
        &[0xF0, 0x81, 0x3E, 0x81, 0x51, 0x81, 0x5A, 0x25, 0x00, 0x0F],
    );
    check(
        single_pulse_ack(0xF0),
        &[0xF0, 0x81, 0x15, 0x81, 0x51, 0x81, 0xA5, 0x25, 0x00, 0x0F],
    );
    check(
        single_pulse_ack(0x81),
        &[0xF0, 0x81, 0x19, 0x81, 0x51, 0x81, 0xD4, 0x25, 0x00, 0x0F],
    );
}

#[test]
fn a_host_that_also_escapes_0x55_and_0x0a_is_read() {
    // pyScienceMode 1.1.5 escapes 0x55 and 0x0A too; 0x81 followed by any byte un-stuffs
    // to that byte XOR 0x55 (§2.2), so the decoder reads that form as well.
    for (n, escaped) in [(0x0Au8, 0x5Fu8), (0x55, 0x00)] {
        let wire = wrap(&[0x81, escaped, 0x25, 0x00]);
        assert_eq!(decode_all(&wire), [Ok(single_pulse_ack(n))]);
    }
}

#[test]
fn get_stimulation_mode_ack_carries_the_mode_only_when_successful() {
    // §4.2 GetStimulationModeAck: byte 7 result; "if Result != 0, then byte 8 = stop
    // byte"; otherwise byte 8 the mode (0 start, 1 initialised, 2 started).
    check(
        Packet::new(
            7,
            Message::GetStimulationModeAck {
                result: AckResult::BusyError,
                mode: None,
            },
        ),
        &[0xF0, 0x81, 0x32, 0x81, 0x56, 0x07, 0x0B, 0xF8, 0x0F],
    );
    assert_eq!(
        decode_all(&frame(&[0x08, 0x0B, 0xFF])),
        [Ok(Packet::new(
            8,
            Message::GetStimulationModeAck {
                result: AckResult::TransferError,
                mode: None,
            }
        ))]
    );
    assert_eq!(
        decode_all(&frame(&[0x09, 0x0B, 0x00, 0x02])),
        [Ok(Packet::new(
            9,
            Message::GetStimulationModeAck {
                result: AckResult::Ok,
                mode: Some(StimulationMode::Started),
            }
        ))]
    );
    // A successful acknowledgement without its mode is malformed.
    assert!(matches!(
        decode_all(&frame(&[0x09, 0x0B, 0x00]))[..],
        [Err(DecodeError::WrongDataLength {
            expected: 2,
            actual: 1,
            ..
        })]
    ));
}

#[test]
fn unknown_command_echoes_the_number_and_the_command() {
    // §4.1 UnknownCommand: byte 5 echo packet number, byte 6 command 3, byte 7 "echo
    // command byte: echoes the received command value".
    check(
        Packet::new(7, Message::UnknownCommand { command: 50 }),
        &[0xF0, 0x81, 0xE2, 0x81, 0x56, 0x07, 0x03, 0x32, 0x0F],
    );
}

#[test]
fn motomed_information_packets_decode() {
    // §4.4 ActualValues (60): angle MSB/LSB (deg), speed MSB/LSB (rpm, signed), torque
    // MSB/LSB (dNm, signed). Angle 90, speed -30, torque 15 (0x0F, escaped).
    let actual = Packet::new(
        0,
        Message::ActualValues {
            angle_deg: 90,
            speed_rpm: -30,
            torque_dnm: 15,
        },
    );
    check(
        actual,
        &[
            0xF0, 0x81, 0x7E, 0x81, 0x5C, 0x00, 0x3C, 0x00, 0x5A, 0xFF, 0xE2, 0x00, 0x81, 0x5A,
            0x0F,
        ],
    );
    assert!(actual.message.is_motomed_information());
    // §4.4 MotomedCommandDone (89): result 0.
    assert_eq!(
        decode_all(&frame(&[0x01, 89, 0x00])),
        [Ok(Packet::new(
            1,
            Message::MotomedCommandDone {
                result: AckResult::Ok
            }
        ))]
    );
    // §4.4 MotomedError (90): -4 MOTOmed connection error.
    assert_eq!(
        decode_all(&frame(&[0x02, 90, 0xFC])),
        [Ok(Packet::new(2, Message::MotomedError { code: -4 }))]
    );
    // §4.4 PhaseResult (58): phase counter, passive and active distance (10 m, 2 bytes
    // each), average and maximum power (W), phase and active phase duration (s, 2 bytes
    // each), phase work (J, 2 bytes), success (%), symmetry left (%), muscle tone (dNm).
    let data = [
        0x03, 58, 4, 0x01, 0x02, 0x00, 0x30, 50, 120, 0x01, 0x2C, 0x00, 0xF0, 0x27, 0x10, 80, 48,
        12,
    ];
    assert_eq!(
        decode_all(&frame(&data)),
        [Ok(Packet::new(
            3,
            Message::PhaseResult(PhaseResult {
                phase_counter: 4,
                passive_distance_10m: 0x0102,
                active_distance_10m: 0x30,
                average_power_w: 50,
                maximum_power_w: 120,
                phase_duration_s: 300,
                active_phase_duration_s: 0xF0,
                phase_work_j: 10_000,
                success_percent: 80,
                symmetry_left_percent: 48,
                average_muscle_tone_dnm: 12,
            })
        ))]
    );
    for m in [
        Message::StimulationError {
            error: fes_sciencemode::StimulationError::Electrode,
        },
        Message::SinglePulseAck {
            result: AckResult::Ok,
        },
    ] {
        assert!(!m.is_motomed_information());
    }
}

#[test]
fn every_host_command_but_watchdog_and_init_ack_is_answered() {
    // §2.3 and §5.1: the device answers each command with a response packet carrying the
    // command's packet number (an acknowledgement, §4.2-4.3, or UnknownCommand, §4.1);
    // Watchdog (§4.2) and InitAck (§4.1, itself the host's answer to Init) have none.
    // The host's stop-and-wait rests on this table.
    let ack = AckResult::Ok;
    let pulse = fes_sciencemode::SinglePulse {
        channel: 0,
        pulse_width_us: 200,
        current_ma: 20,
    };
    let init = fes_sciencemode::ChannelListInit {
        low_frequency_factor: 0,
        active_channels: 1,
        low_frequency_channels: 0,
        inter_pulse_interval_code: 0,
        main_interval_code: 0,
        channel_execution: 0,
    };
    let update = fes_sciencemode::ChannelListUpdate::new(&[fes_sciencemode::ChannelPulse {
        mode: fes_sciencemode::PulseMode::Single,
        pulse_width_us: 200,
        current_ma: 20,
    }])
    .unwrap();
    let table: [(Message, Option<Message>); 7] = [
        (Message::Watchdog, None),
        (Message::InitAck { result: ack }, None),
        (
            Message::GetStimulationMode,
            Some(Message::GetStimulationModeAck {
                result: ack,
                mode: Some(StimulationMode::Start),
            }),
        ),
        (
            Message::InitChannelListMode(init),
            Some(Message::InitChannelListModeAck { result: ack }),
        ),
        (
            Message::StartChannelListMode(update),
            Some(Message::StartChannelListModeAck { result: ack }),
        ),
        (
            Message::StopChannelListMode,
            Some(Message::StopChannelListModeAck { result: ack }),
        ),
        (
            Message::SinglePulse(pulse),
            Some(Message::SinglePulseAck { result: ack }),
        ),
    ];
    for (command, answer) in table {
        assert_eq!(command.expects_answer(), answer.is_some(), "{command:?}");
        assert!(!command.is_answer(), "{command:?}");
        if let Some(a) = answer {
            assert!(a.is_answer() && !a.expects_answer(), "{a:?}");
            // The acknowledgement's command id follows the command's (§4, Table 7).
            assert_eq!(a.command().id(), command.command().id() + 1, "{a:?}");
        }
    }
    assert!(Message::UnknownCommand { command: 50 }.is_answer());
    // What the device sends unasked answers nothing: Init (§4.1), StimulationError
    // (§4.3), the MOTOmed information packets (§4.4).
    for unasked in [
        Message::Init { version: 1 },
        Message::StimulationError {
            error: fes_sciencemode::StimulationError::Electrode,
        },
        Message::ActualValues {
            angle_deg: 0,
            speed_rpm: 0,
            torque_dnm: 0,
        },
        Message::MotomedError { code: -4 },
    ] {
        assert!(
            !unasked.is_answer() && !unasked.expects_answer(),
            "{unasked:?}"
        );
    }
}
