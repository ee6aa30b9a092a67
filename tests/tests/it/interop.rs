//! Interoperability with standard tools on the same bus: frames the Rust side sends are
//! seen by `candump`; frames injected with `cansend` (typed by hand, or printed by the
//! codec) are understood by the stimulator; the `candump -L` log of the run decodes with
//! `python3 -m cantools decode crates/fes-can/dbc/fes.dbc` with no unknown frame, and cantools
//! reads the same values as the Rust decoder.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use crate::common;

use std::fs::File;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::*;
use fes_can::{ErrorCode, Message, MessageKind, Nodes, StimState};
use fes_testkit::bus::{HeartbeatSender, HostPort, Tap};
use fes_testkit::vcan::{CanEnv, with_vcan};

#[test]
fn can_utils_and_cantools_interoperate() {
    with_vcan(interop);
}

fn require_in_path(program: &str, hint: &str) {
    let found = std::env::var_os("PATH")
        .is_some_and(|p| std::env::split_paths(&p).any(|d| d.join(program).is_file()));
    assert!(found, "{program} not found in PATH: {hint}");
}

fn cansend(iface: &str, frame: &str) {
    let s = Command::new("cansend")
        .args([iface, frame])
        .status()
        .expect("run cansend");
    assert!(s.success(), "cansend {iface} {frame}: {s}");
}

/// `(id, data)` of each `(time) iface ID#DATA` line of a `candump -L` log.
fn parse_log(text: &str) -> Vec<(u32, Vec<u8>)> {
    text.lines()
        .filter_map(|l| l.split_whitespace().nth(2))
        .map(|f| {
            let (id, data) = f
                .split_once('#')
                .unwrap_or_else(|| panic!("not a candump -L frame: {f}"));
            let id = u32::from_str_radix(id, 16).unwrap_or_else(|e| panic!("identifier {id}: {e}"));
            let data = (0..data.len() / 2)
                .map(|i| {
                    u8::from_str_radix(&data[2 * i..2 * i + 2], 16)
                        .unwrap_or_else(|e| panic!("{data}: {e}"))
                })
                .collect();
            (id, data)
        })
        .collect()
}

fn wait_for_file(path: &Path, needle: &str, timeout: Duration) -> bool {
    let deadline = Instant::now() + timeout;
    while Instant::now() < deadline {
        if std::fs::read_to_string(path).is_ok_and(|t| t.contains(needle)) {
            return true;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    false
}

fn interop(can: &CanEnv) {
    let t0 = Instant::now();
    let phase = |what: &str| println!("[{:6.2} s] {what}", t0.elapsed().as_secs_f64());
    require_in_path("candump", "install can-utils (scripts/setup)");
    require_in_path("cansend", "install can-utils (scripts/setup)");
    let dir = fes_testkit::Scratch::new("interop");
    let log = dir.join("candump.log");

    // candump records the whole run; a first host frame proves it is listening.
    let mut candump = Command::new("candump")
        .args(["-L", &can.iface])
        .stdout(File::create(&log).unwrap())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("start candump");
    let mut host = HostPort::open(&can.iface).unwrap();
    let probe = host
        .send(&Message::HostHeartbeat(fes_can::Heartbeat {
            state: fes_can::NmtState::PreOperational,
        }))
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(5);
    while !wait_for_file(&log, "701#7F", Duration::from_millis(100)) {
        assert!(
            Instant::now() < deadline,
            "candump did not record the probe frame"
        );
        host.send_frame(&probe).unwrap();
    }

    phase("candump recording");
    let tap = Tap::open(&can.iface).unwrap();
    let stim = StimProcess::spawn(&can.iface, &[]);
    tap.wait_msg(0, Duration::from_secs(10), boot_up)
        .expect("boot-up message");
    phase("stimulator booted");
    let hb = HeartbeatSender::start(&can.iface, Duration::from_millis(10)).unwrap();

    // cansend, typed by hand: NMT start to node 0x10.
    cansend(&can.iface, "000#0110");
    wait_status(&tap, 0, PROMPT, "armed (NMT start from cansend)", |s| {
        s.state == StimState::Armed
    });

    // cansend, printed by the codec: a PULSE of 20 mA x 200 us = 4 uC.
    let p = host.next_pulse(200, 200);
    let frame = Message::Pulse(p).encode().unwrap();
    cansend(&can.iface, &frame.to_string());
    wait_status(&tap, 0, PROMPT, "the cansend pulse delivered", |s| {
        s.pulses_delivered == 1
    });
    let i = tap.len();
    tap.wait_msg(i, PROMPT, |m| force(m).filter(|f| f.force_mn == 4000))
        .expect("FORCE shows 4 uC = 4.000 N");

    // cansend, a corrupted PULSE: EMCY bad CRC.
    let (_, mut bad) = host.corrupt_pulse_frame(100, 100, 0).unwrap();
    bad.data[7] ^= 0x01;
    let i = tap.len();
    cansend(&can.iface, &bad.to_string());
    wait_emcy(&tap, i, ErrorCode::BadCrc);

    // The Rust host's own pulses.
    let mut rust_sent = vec![(u32::from(probe.id), probe.payload().to_vec())];
    for n in 2..=4 {
        // Each waits for the previous one to be applied, so a stalled guest cannot
        // squeeze two into one tick.
        let (_, f) = host.pulse(150, 100).unwrap();
        rust_sent.push((u32::from(f.id), f.payload().to_vec()));
        wait_status(&tap, 0, PROMPT, "the Rust pulse delivered", |s| {
            s.pulses_delivered == n
        });
        std::thread::sleep(Duration::from_millis(5));
    }

    let exit = stim.terminate();
    assert!(exit.success(), "test-stimulator exit status {exit}");
    drop(hb);
    std::thread::sleep(Duration::from_millis(100));
    // SAFETY: kill(2) on the pid of the candump child we started and have not reaped.
    unsafe {
        libc::kill(i32::try_from(candump.id()).unwrap(), libc::SIGINT);
    }
    let _ = candump.wait();
    let tapped: Vec<(u32, Vec<u8>)> = tap.frames().into_iter().map(|f| (f.id, f.data)).collect();
    drop(tap);

    // candump saw exactly what the tap saw, in the same order, Rust frames included.
    let text = std::fs::read_to_string(&log).unwrap();
    let logged = parse_log(&text);
    let start = logged
        .iter()
        .position(|f| Some(f) == tapped.first())
        .expect("the tap's first frame is in the log");
    assert_eq!(
        &logged[start..],
        &tapped[..],
        "candump and the Rust tap disagree"
    );
    for f in &rust_sent {
        assert!(
            logged.contains(f),
            "candump did not see the Rust frame {f:02X?}"
        );
    }
    let stim_id = |k| u32::from(Nodes::DEFAULT.id_of(k));
    let kinds = [
        MessageKind::Force,
        MessageKind::Status,
        MessageKind::StimHeartbeat,
        MessageKind::Emcy,
    ];
    for k in kinds {
        assert!(
            logged.iter().any(|(id, _)| *id == stim_id(k)),
            "no {} frame in the candump log",
            k.name()
        );
    }
    println!(
        "candump: {} frames, identical to the Rust tap's {} from the first tapped frame on",
        logged.len(),
        tapped.len()
    );

    phase("candump log checked");
    // cantools decodes every logged frame with the project's DBC.
    let lines = fes_tests::cantools::decode_log(&log);
    phase("cantools finished");
    assert_eq!(lines.len(), logged.len(), "one decoded line per frame");
    // And reads the same values as the Rust decoder (the last STATUS of the run).
    let last = lines
        .iter()
        .rev()
        .find(|l| l.contains(":: STATUS("))
        .expect("a STATUS line");
    let (i, _) = logged
        .iter()
        .enumerate()
        .rev()
        .find(|(_, (id, _))| *id == stim_id(MessageKind::Status))
        .unwrap();
    let ours = match fes_can::decode(logged[i].0, &logged[i].1) {
        Ok(Message::Status(s)) => s,
        other => panic!("Rust decoder: {other:?}"),
    };
    assert!(
        last.contains(&format!("state: {}", ours.state)),
        "{last} vs {ours:?}"
    );
    assert!(
        last.contains(&format!(
            "pulses_delivered: {} pulses",
            ours.pulses_delivered
        )),
        "{last} vs {ours:?}"
    );
    assert!(
        last.contains(&format!("last_error: {}", ours.last_error)),
        "{last} vs {ours:?}"
    );
    assert_eq!((ours.state, ours.pulses_delivered), (StimState::Stopped, 4));
    println!(
        "cantools decoded all {} frames; last STATUS: {last}",
        lines.len()
    );
}
