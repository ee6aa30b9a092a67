//! The ScienceMode transmit side against the virtual RehaStim 2: the driver's PULSE and
//! heartbeat frames, written through [`ScienceModeTx`] to a serial port opened with
//! [`open_serial`], reach the device (`fes_virtual_stimulator`'s pty device) as single
//! pulses with the same channel, current and width, keep its watchdog fed, and a pulse
//! outside the device's range never reaches the line.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use std::io::{Read as _, Write as _};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use fes_can::{Heartbeat, Message as CanMessage, NmtState, Nodes, Pulse};
use fes_sciencemode::{AckResult, Decoder, MAX_PACKET_LEN, Message, Packet};
use fes_virtual_stimulator::rehastim2_pty::{Rehastim2Args, run_rehastim2_until};
use fes_virtual_stimulator::test_plant::ChargeIntegrator;
use stim_driver::serial_tx::{ScienceModeTx, open_serial};
use stim_driver::tx::{CanTx, RetryPolicy, TxError};

/// Reads the port until `count` packets matching `want` have arrived (others are skipped).
fn read_packets(
    what: &str,
    count: usize,
    port: &mut std::fs::File,
    decoder: &mut Decoder,
    want: impl Fn(&Packet) -> bool,
) -> Vec<Packet> {
    let deadline = Instant::now() + Duration::from_secs(5);
    let mut buf = [0u8; 64];
    let mut found = Vec::new();
    loop {
        assert!(
            Instant::now() < deadline,
            "{} of {count} {what} from the device: {found:?}",
            found.len()
        );
        match port.read(&mut buf) {
            Ok(n) => {
                for r in decoder.feed(&buf[..n]) {
                    let p = r.unwrap();
                    if want(&p) {
                        found.push(p);
                    }
                }
                if found.len() >= count {
                    return found;
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(1));
            }
            Err(e) => panic!("reading the port: {e}"),
        }
    }
}

#[test]
fn driver_frames_reach_the_virtual_rehastim2_as_single_pulses() {
    let dir = fes_testkit::Scratch::new("stim-driver-serial");
    let args = Rehastim2Args {
        pty_link: dir.join("ttyUSB0"),
        pulse_log: Some(dir.join("pulses.csv")),
        watchdog_ms: 200,
        init_period_ms: 20,
        muscle_channel: 1,
        duration_s: Some(60.0),
        test_fault: None,
        latency_ms: 0,
        motomed: false,
        processing_ms: 0,
        force_prefix: None,
        force_max_n: None,
    };
    let stop = AtomicBool::new(false);
    let nodes = Nodes::DEFAULT;
    let frame = |m: CanMessage| m.encode_for(&nodes).unwrap();
    let pulse = |seq: u16, channel: u8, amplitude_100ua: u16, width_us: u16| {
        frame(CanMessage::Pulse(Pulse {
            seq,
            alive_counter: (seq % 16) as u8,
            channel,
            amplitude_100ua,
            width_us,
        }))
    };
    let heartbeat = frame(CanMessage::HostHeartbeat(Heartbeat {
        state: NmtState::Operational,
    }));
    /// Stops the device when the test body ends, panicking or not (else the scope would
    /// wait for the device's whole duration).
    struct StopOnDrop<'a>(&'a AtomicBool);
    impl Drop for StopOnDrop<'_> {
        fn drop(&mut self) {
            self.0.store(true, Ordering::Relaxed);
        }
    }
    let summary = std::thread::scope(|s| {
        let device = s.spawn(|| {
            let mut plant = ChargeIntegrator::new();
            let summary = run_rehastim2_until(&args, &mut plant, &stop).unwrap();
            (summary, plant.pulses())
        });
        let stop_device = StopOnDrop(&stop);
        let deadline = Instant::now() + Duration::from_secs(5);
        while !args.pty_link.exists() {
            assert!(Instant::now() < deadline, "no pty link");
            std::thread::sleep(Duration::from_millis(2));
        }
        let mut port = open_serial(&args.pty_link).unwrap();
        // The handshake (the receive side's job, not yet in the driver): Init -> InitAck.
        let mut decoder = Decoder::new();
        let init = read_packets("Init", 1, &mut port, &mut decoder, |p| {
            matches!(p.message, Message::Init { .. })
        })[0];
        let mut buf = [0u8; MAX_PACKET_LEN];
        let n = Packet::new(
            init.number,
            Message::InitAck {
                result: AckResult::Ok,
            },
        )
        .encode(&mut buf)
        .unwrap();
        port.write_all(&buf[..n]).unwrap();
        let retry = RetryPolicy {
            budget_ns: 2_000_000,
            interval_ns: 100_000,
        };
        let mut tx = ScienceModeTx::new(port.try_clone().unwrap(), nodes, retry);
        // Heartbeats for 400 ms (twice the device's watchdog) with pulses every 50 ms.
        let mut seq = 0;
        for k in 0..40u32 {
            tx.send(&heartbeat).unwrap();
            if k.is_multiple_of(5) {
                seq += 1;
                // 22, 24, ... mA: even, the device's steps being 2 mA.
                tx.send(&pulse(seq, 0, 200 + 20 * seq, 250)).unwrap();
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        // One the device cannot carry (20.5 mA): refused before the line.
        assert_eq!(
            tx.send(&pulse(99, 0, 205, 250)),
            Err(TxError::Failed {
                errno: libc::EINVAL
            })
        );
        // Every pulse acknowledged: the eight, numbered as the transmit side numbered them
        // (a Watchdog before each: 1, 7, 13, ...).
        let acks = read_packets("SinglePulseAck", 8, &mut port, &mut decoder, |p| {
            matches!(p.message, Message::SinglePulseAck { .. })
        });
        let numbers: Vec<u8> = acks.iter().map(|p| p.number).collect();
        assert_eq!(numbers, [1, 7, 13, 19, 25, 31, 37, 43]);
        assert!(
            acks.iter()
                .all(|p| p.message.ack_result() == Some(AckResult::Ok))
        );
        std::thread::sleep(Duration::from_millis(20));
        drop(stop_device);
        device.join().unwrap()
    });
    let (summary, plant_pulses) = summary;
    assert_eq!(summary.bad_packets, 0);
    assert_eq!(summary.pulses, 8);
    assert_eq!(plant_pulses, 8);
    let log = std::fs::read_to_string(dir.join("pulses.csv")).unwrap();
    let rows: Vec<&str> = log.lines().skip(1).collect();
    assert_eq!(rows.len(), 8, "{log}");
    for (i, row) in rows.iter().enumerate() {
        let current = 20 + 2 * (i + 1);
        assert!(
            row.ends_with(&format!(",pulse,1,250,{current},single,1,")),
            "row {i}: {row}\n{log}"
        );
    }
    assert!(!log.contains("watchdog"), "{log}");
}
