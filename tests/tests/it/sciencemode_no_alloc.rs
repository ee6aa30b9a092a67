//! The driver's ScienceMode 2 sides allocate nothing per packet (both transports are
//! allocation-free on the hot path): the receive side's decoding and event mapping
//! (`stim_driver::serial_rx::Receiver` behind a `fes_sciencemode::Decoder`, as the receive
//! thread runs them) and the transmit side with its receive-side link
//! (`ScienceModeTx::with_link`: InitAck, the liveness query, pulses), under the counting
//! global allocator of this binary (`stimulator_no_alloc.rs`).

use std::sync::Arc;

use fes_can::{Heartbeat, Message as CanMessage, Nmt, NmtCommand, NmtState, Nodes, Pulse};
use fes_rt::rt::alloc;
use fes_sciencemode::{
    AckResult, Decoder, MAX_PACKET_LEN, Message, Packet, StimulationError, StimulationMode,
};
use stim_driver::event::BusEvent;
use stim_driver::serial_rx::{Receiver, SerialLink};
use stim_driver::serial_tx::ScienceModeTx;
use stim_driver::tx::{CanTx, RetryPolicy};

#[test]
fn the_serial_sides_allocate_nothing_per_packet() {
    // What a device sends in a session: Init, mode answers, pulse acknowledgements,
    // errors, and a packet with a broken checksum.
    let device = [
        Message::Init { version: 1 },
        Message::GetStimulationModeAck {
            result: AckResult::Ok,
            mode: Some(StimulationMode::Start),
        },
        Message::SinglePulseAck {
            result: AckResult::Ok,
        },
        Message::SinglePulseAck {
            result: AckResult::ParameterError,
        },
        Message::SinglePulseAck {
            result: AckResult::BusyError,
        },
        Message::UnknownCommand { command: 50 },
        Message::ActualValues {
            angle_deg: 90,
            speed_rpm: -30,
            torque_dnm: 15,
        },
        Message::StimulationError {
            error: StimulationError::Electrode,
        },
    ];
    let mut stream = Vec::new();
    let mut buf = [0u8; MAX_PACKET_LEN];
    for (i, m) in device.iter().enumerate() {
        let n = Packet::new(i as u8, *m).encode(&mut buf).unwrap();
        stream.extend_from_slice(&buf[..n]);
    }
    let n = Packet::new(9, device[2]).encode(&mut buf).unwrap();
    buf[2] ^= 0x01; // the checksum
    stream.extend_from_slice(&buf[..n]);
    let nodes = Nodes::DEFAULT;
    let frames = [
        CanMessage::HostHeartbeat(Heartbeat {
            state: NmtState::Operational,
        }),
        CanMessage::Nmt(Nmt {
            command: NmtCommand::Start,
            node: nodes.stim(),
        }),
        CanMessage::Pulse(Pulse {
            seq: 1,
            alive_counter: 0,
            channel: 0,
            amplitude_100ua: 200,
            width_us: 200,
        }),
    ]
    .map(|m| m.encode_for(&nodes).unwrap());
    let link = Arc::new(SerialLink::new());
    let mut receiver = Receiver::new(fes_can::StimLimits::DEFAULT);
    let mut decoder = Decoder::new();
    let retry = RetryPolicy {
        budget_ns: 0,
        interval_ns: 0,
    };
    let mut tx = ScienceModeTx::with_link(std::io::sink(), nodes, retry, link.clone(), 0);
    let (mut events, mut emcys, mut packets, mut busy) = (0u64, 0u64, 0u64, 0u64);

    alloc::track_current_thread(true);
    let before = alloc::current_thread_allocations();
    for _ in 0..2_000 {
        for r in decoder.feed(&stream) {
            let mut push = |e: BusEvent| {
                events += 1;
                emcys += u64::from(matches!(e, BusEvent::Emcy(_)));
                busy += u64::from(matches!(e, BusEvent::DeviceBusy { .. }));
            };
            match r {
                Ok(p) => {
                    packets += 1;
                    receiver.on_packet(&p, &link, &mut push);
                }
                Err(_) => receiver.on_line_fault(&mut push),
            }
        }
        for f in &frames {
            tx.send(f).unwrap();
            // The device's answer to what was just written (stop-and-wait).
            link.answer_received(tx.next_number().wrapping_sub(1));
        }
    }
    let after = alloc::current_thread_allocations();
    alloc::track_current_thread(false);
    assert_eq!(
        (after.allocations - before.allocations)
            + (after.pool_allocations - before.pool_allocations),
        0,
        "allocations in the ScienceMode receive and transmit paths"
    );
    // The paths measured were the real ones: every packet decoded and mapped, every error
    // an EMCY, the handshake done by the transmit side.
    assert_eq!(packets, 2_000 * device.len() as u64);
    assert_eq!(emcys, 2_000 * 3);
    assert_eq!(busy, 2_000);
    assert!(events > emcys);
    assert!(link.handshake_done());
    assert_eq!(receiver.delivered(), 2_000);
}
