//! Known byte vectors: each was produced by pyScienceMode 1.1.5's own packet builder
//! (`pysciencemode.utils.packet_construction(number, command, data)`, run in Python and
//! pasted here; the call is in each comment). Our encoder must produce the same bytes and
//! our decoder must read them back to the same fields.
//!
//! pyScienceMode 1.1.5 also stuffs 0x55 and 0x0A, which the protocol description sends as
//! they are (§2.2: "every constant from Table 6, except the stuffing key, is escaped"); for
//! packets holding those our encoder sends the description's form and our decoder reads
//! pyScienceMode's form too (`stuffed_command_data`).
//!
//! pyScienceMode XORs a packet number or command byte that is a special byte in place,
//! without the 0x81 stuffing byte before it (only the command data is stuffed properly).
//! Packets where that happens are not decodable as the protocol defines them; the last
//! tests pin how ours treats them.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use fes_sciencemode::{
    AckResult, ChannelListInit, ChannelListUpdate, ChannelPulse, DecodeError, Decoder, Message,
    Packet, PulseMode, SinglePulse, StimulationError, StimulationMode, crc8,
};

use super::support::{check, decode_all, encode, wrap};

#[test]
fn crc8_is_the_smbus_crc() {
    // The CRC-8 check value (polynomial 0x07, init 0): "123456789" -> 0xF4.
    assert_eq!(crc8(b"123456789"), 0xF4);
    assert_eq!(crc8(&[]), 0);
}

#[test]
fn watchdog() {
    // packet_construction(0, "Watchdog")
    check(
        Packet::new(0, Message::Watchdog),
        &[0xF0, 0x81, 0x49, 0x81, 0x57, 0x00, 0x04, 0x0F],
    );
    // packet_construction(7, "Watchdog")
    check(
        Packet::new(7, Message::Watchdog),
        &[0xF0, 0x81, 0x22, 0x81, 0x57, 0x07, 0x04, 0x0F],
    );
}

#[test]
fn init_and_init_ack() {
    // packet_construction(0, "Init", [1]) (the device's greeting)
    check(
        Packet::new(0, Message::Init { version: 1 }),
        &[0xF0, 0x81, 0x47, 0x81, 0x56, 0x00, 0x01, 0x01, 0x0F],
    );
    // packet_construction(3, "InitAck", [0])
    check(
        Packet::new(
            3,
            Message::InitAck {
                result: AckResult::Ok,
            },
        ),
        &[0xF0, 0x81, 0xC2, 0x81, 0x56, 0x03, 0x02, 0x00, 0x0F],
    );
}

#[test]
fn get_stimulation_mode_ack() {
    // packet_construction(2, "GetStimulationModeAck", [0, 1])
    check(
        Packet::new(
            2,
            Message::GetStimulationModeAck {
                result: AckResult::Ok,
                mode: Some(StimulationMode::Initialised),
            },
        ),
        &[0xF0, 0x81, 0x92, 0x81, 0x51, 0x02, 0x0B, 0x00, 0x01, 0x0F],
    );
}

#[test]
fn init_channel_list_mode() {
    // packet_construction(4, "InitChannelListMode", [0, 3, 0, 1, 0, 48, 0]): channels 1
    // and 2, inter-pulse interval 2 ms, main interval 25 ms.
    let init = ChannelListInit {
        low_frequency_factor: 0,
        active_channels: 0b11,
        low_frequency_channels: 0,
        inter_pulse_interval_code: 1,
        main_interval_code: 48,
        channel_execution: 0,
    };
    assert_eq!(init.main_interval_us(), 25_000);
    assert_eq!(init.inter_pulse_interval_us(), 2_000);
    check(
        Packet::new(4, Message::InitChannelListMode(init)),
        &[
            0xF0, 0x81, 0xE7, 0x81, 0x5C, 0x04, 0x1E, 0x00, 0x03, 0x00, 0x01, 0x00, 0x30, 0x00,
            0x0F,
        ],
    );
}

#[test]
fn stuffed_command_data() {
    let packet = Packet::new(
        5,
        Message::InitChannelListMode(ChannelListInit {
            low_frequency_factor: 2,
            active_channels: 0x0F,
            low_frequency_channels: 0x0A,
            inter_pulse_interval_code: 0x55,
            main_interval_code: 0x0181,
            channel_execution: 0,
        }),
    );
    // packet_construction(5, "InitChannelListMode", [2, 0x0F, 0x0A, 0x55, 1, 0x81, 0]):
    // pyScienceMode stuffs 0x0F, 0x0A, 0x55 and 0x81, each as 0x81, byte ^ 0x55. Our
    // decoder reads it (§2.2 un-stuffing applies to any byte after 0x81).
    let theirs = [
        0xF0, 0x81, 0x93, 0x81, 0x58, 0x05, 0x1E, 0x02, 0x81, 0x5A, 0x81, 0x5F, 0x81, 0x00, 0x01,
        0x81, 0xD4, 0x00, 0x0F,
    ];
    assert_eq!(decode_all(&theirs), [Ok(packet)]);
    // The description's form (§2.2, Table 6: only 0xF0, 0x0F and 0x81 are escaped; the
    // stuffing key 0x55 and 0x0A go as they are), which our encoder sends; the checksum
    // covers the stuffed bytes and the length counts them. Bytes computed by a separate
    // Python implementation of §2.2.
    check(
        packet,
        &[
            0xF0, 0x81, 0x93, 0x81, 0x5E, 0x05, 0x1E, 0x02, 0x81, 0x5A, 0x0A, 0x55, 0x01, 0x81,
            0xD4, 0x00, 0x0F,
        ],
    );
}

#[test]
fn start_channel_list_mode() {
    // packet_construction(6, "StartChannelListMode", [0, 0, 200, 20, 1, 1, 0xF4, 30]):
    // channel A single 200 us 20 mA, channel B doublet 500 us 30 mA. The length (10) is
    // itself a special byte and goes out as 0x5F like any length.
    let list = ChannelListUpdate::new(&[
        ChannelPulse {
            mode: PulseMode::Single,
            pulse_width_us: 200,
            current_ma: 20,
        },
        ChannelPulse {
            mode: PulseMode::Doublet,
            pulse_width_us: 500,
            current_ma: 30,
        },
    ])
    .unwrap();
    check(
        Packet::new(6, Message::StartChannelListMode(list)),
        &[
            0xF0, 0x81, 0x20, 0x81, 0x5F, 0x06, 0x20, 0x00, 0x00, 0xC8, 0x14, 0x01, 0x01, 0xF4,
            0x1E, 0x0F,
        ],
    );
}

#[test]
fn stop_channel_list_mode_and_acks() {
    // packet_construction(8, "StopChannelListMode")
    check(
        Packet::new(8, Message::StopChannelListMode),
        &[0xF0, 0x81, 0x13, 0x81, 0x57, 0x08, 0x22, 0x0F],
    );
    // packet_construction(9, "StartChannelListModeAck", [-2 & 0xFF]): parameter error
    check(
        Packet::new(
            9,
            Message::StartChannelListModeAck {
                result: AckResult::ParameterError,
            },
        ),
        &[0xF0, 0x81, 0x20, 0x81, 0x56, 0x09, 0x21, 0xFE, 0x0F],
    );
    // packet_construction(12, "StimulationError", [-2 & 0xFF]): electrode error
    check(
        Packet::new(
            12,
            Message::StimulationError {
                error: StimulationError::Electrode,
            },
        ),
        &[0xF0, 0x81, 0x8B, 0x81, 0x56, 0x0C, 0x26, 0xFE, 0x0F],
    );
}

#[test]
fn single_pulse() {
    // packet_construction(11, "SinglePulse", [0, 0, 250, 40]): channel 1 (0), 250 us, 40 mA
    check(
        Packet::new(
            11,
            Message::SinglePulse(SinglePulse {
                channel: 0,
                pulse_width_us: 250,
                current_ma: 40,
            }),
        ),
        &[
            0xF0, 0x81, 0xC4, 0x81, 0x53, 0x0B, 0x24, 0x00, 0x00, 0xFA, 0x28, 0x0F,
        ],
    );
}

#[test]
fn pyscience_modes_in_place_xor_of_a_special_command_is_not_our_packet() {
    // packet_construction(1, "GetStimulationMode"): the command 10 (0x0A) is special and
    // pyScienceMode sends 0x5F in its place, without the stuffing byte. Read as the
    // protocol defines it, that is command 95, which does not exist.
    let theirs = [0xF0, 0x81, 0xDA, 0x81, 0x57, 0x01, 0x5F, 0x0F];
    assert_eq!(
        decode_all(&theirs),
        [Err(DecodeError::UnknownCommand {
            number: 1,
            command: 0x5F
        })]
    );
    // Ours sends it as it is (§2.2: 0x0A is not a Table 6 constant).
    assert_eq!(
        encode(&Packet::new(1, Message::GetStimulationMode)),
        [0xF0, 0x81, 0x76, 0x81, 0x57, 0x01, 0x0A, 0x0F]
    );
    // And reads it stuffed as well: 0x81 0x5F is 0x0A.
    let stuffed = wrap(&[0x01, 0x81, 0x5F]);
    assert_eq!(
        decode_all(&stuffed),
        [Ok(Packet::new(1, Message::GetStimulationMode))]
    );
    // packet_construction(10, "Watchdog"): packet number 10 goes out as 0x5F; the packet
    // decodes, with number 0x5F (a number is only echoed, never interpreted).
    let theirs = [0xF0, 0x81, 0x86, 0x81, 0x57, 0x5F, 0x04, 0x0F];
    assert_eq!(
        decode_all(&theirs),
        [Ok(Packet::new(0x5F, Message::Watchdog))]
    );
}

#[test]
fn errors_are_typed() {
    let good = encode(&Packet::new(
        3,
        Message::InitAck {
            result: AckResult::Ok,
        },
    ));
    // Checksum byte changed.
    let mut bad = good.clone();
    bad[2] ^= 0x01;
    assert!(matches!(
        decode_all(&bad)[..],
        [Err(DecodeError::BadChecksum { .. })]
    ));
    // Length byte changed.
    let mut bad = good.clone();
    bad[4] ^= 0x01;
    assert_eq!(
        decode_all(&bad),
        [Err(DecodeError::BadLength {
            declared: 2,
            actual: 3
        })]
    );
    // Header stuffing byte missing.
    let mut bad = good.clone();
    bad[1] = 0x00;
    assert_eq!(
        decode_all(&bad),
        [Err(DecodeError::BadHeader {
            position: 1,
            byte: 0
        })]
    );
    // A new start byte inside a packet.
    let mut cut = good[..6].to_vec();
    cut.extend_from_slice(&good);
    assert_eq!(
        decode_all(&cut),
        [
            Err(DecodeError::Truncated { received: 1 }),
            Ok(Packet::new(
                3,
                Message::InitAck {
                    result: AckResult::Ok
                }
            ))
        ]
    );
    // A stuffing byte at the end of the packet data: nothing to un-stuff.
    let forged = wrap(&[0x03, 0x02, 0x81]);
    assert_eq!(
        decode_all(&forged),
        [Err(DecodeError::BadStuffing {
            position: 2,
            byte: 0x81
        })]
    );
    // An unknown command (a MOTOmed command), and a known one with the wrong data length.
    let forged = wrap(&[0x03, 50]);
    assert_eq!(
        decode_all(&forged),
        [Err(DecodeError::UnknownCommand {
            number: 3,
            command: 50
        })]
    );
    let forged = wrap(&[0x03, 0x04, 0x00]);
    assert!(matches!(
        decode_all(&forged)[..],
        [Err(DecodeError::WrongDataLength {
            expected: 0,
            actual: 1,
            ..
        })]
    ));
    // Noise outside packets is skipped and counted.
    let mut d = Decoder::new();
    let mut noisy = vec![0x00, 0x13, 0x0F];
    noisy.extend_from_slice(&good);
    assert_eq!(d.feed(&noisy).count(), 1);
    assert_eq!(d.skipped(), 3);
}

#[test]
fn a_channel_list_holds_one_to_eight_entries_and_fits_a_packet() {
    assert!(ChannelListUpdate::new(&[]).is_err());
    assert!(ChannelListUpdate::new(&[ChannelPulse::default(); 9]).is_err());
    // Eight entries fit a packet, even when every byte that can be special is: a mode is
    // never special, so an entry stuffs to at most 7 bytes and the packet to 65 (the
    // packet number 0x81 stuffed too).
    let plain = ChannelPulse {
        mode: PulseMode::Single,
        pulse_width_us: 300,
        current_ma: 50,
    };
    let list = ChannelListUpdate::new(&[plain; 8]).unwrap();
    let wire = encode(&Packet::new(1, Message::StartChannelListMode(list)));
    assert_eq!(wire.len(), 5 + 2 + 32 + 1);
    let special = ChannelPulse {
        mode: PulseMode::Single,
        pulse_width_us: 0xF00F,
        current_ma: 0x81,
    };
    let list = ChannelListUpdate::new(&[special; 8]).unwrap();
    let packet = Packet::new(0x81, Message::StartChannelListMode(list));
    let wire = encode(&packet);
    assert_eq!(wire.len(), 5 + 2 + 1 + 8 * 7 + 1);
    assert_eq!(decode_all(&wire), [Ok(packet)]);
    // A buffer too small is an error, not a panic.
    let mut small = [0u8; 4];
    assert!(matches!(
        Packet::new(1, Message::Watchdog).encode(&mut small),
        Err(fes_sciencemode::EncodeError::BufferTooSmall {
            needed: 8,
            available: 4
        })
    ));
}
