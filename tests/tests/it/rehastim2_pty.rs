//! The virtual RehaStim 2 (`fes_virtual_stimulator::rehastim2_pty`) driven through its
//! pseudo-terminal by pyScienceMode's own `Rehastim2` client (`tests/python/rehastim2_client.py`,
//! pyScienceMode pinned and installed as in [`crate::sciencemode_peer`]): the device's pulse
//! log must show exactly the session the client ran, and the muscle (a charge integrator
//! under channel 1) must have received channel 1's pulses.
//!
//! * `session`: connect, channel list on channels 1 and 2 at 50 ms, pause, update, stop,
//!   three single pulses, disconnect;
//! * `killed`: the client dies (SIGKILL) while the device stimulates; the device's watchdog
//!   must stop the stimulation about a second later (the serial twin of the CAN stimulator's
//!   "driver killed" case).
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use std::os::unix::process::ExitStatusExt as _;
use std::path::Path;
use std::process::{Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use fes_sciencemode::{AckResult, Decoder, Message, Packet};
use fes_virtual_stimulator::rehastim2_pty::{Rehastim2Args, run_rehastim2_until};
use fes_virtual_stimulator::test_plant::ChargeIntegrator;

use crate::sciencemode_peer::{peer_python, python_script};

/// One row of the device's pulse log.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Row {
    t_ms: u64,
    event: String,
    channel: u8,
    width_us: u16,
    current_ma: u8,
    source: String,
    applied: bool,
    detail: String,
}

fn read_log(path: &Path) -> Vec<Row> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some("t_ms,event,channel,width_us,current_ma,source,applied,detail")
    );
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            assert_eq!(f.len(), 8, "{l}");
            Row {
                t_ms: f[0].parse().unwrap(),
                event: f[1].into(),
                channel: f[2].parse().unwrap_or(0),
                width_us: f[3].parse().unwrap_or(0),
                current_ma: f[4].parse().unwrap_or(0),
                source: f[5].into(),
                applied: f[6] == "1",
                detail: f[7].into(),
            }
        })
        .collect()
}

struct Run {
    client: ExitStatus,
    stdout: String,
    rows: Vec<Row>,
    plant: ChargeIntegrator,
    bad_packets: u64,
}

/// Runs the device on a pty (in this process) and the pyScienceMode client `mode` on it;
/// after the client ends, lets the device run `after` more, stops it and reads its log.
fn run(name: &str, mode: &str, after: Duration) -> Run {
    let python = peer_python();
    let dir = fes_testkit::Scratch::new_in(
        Path::new(env!("CARGO_TARGET_TMPDIR")),
        &format!("rehastim2-{name}"),
    );
    let args = Rehastim2Args {
        pty_link: dir.join("ttyRehaStim2"),
        pulse_log: Some(dir.join("pulses.csv")),
        watchdog_ms: 1000,
        init_period_ms: 100,
        muscle_channel: 1,
        duration_s: Some(120.0),
        test_fault: None,
        latency_ms: 0,
        motomed: false,
        processing_ms: 0,
        force_prefix: None,
        force_max_n: None,
    };
    let stop = AtomicBool::new(false);
    let (client, stdout, plant, summary) = std::thread::scope(|s| {
        let device = s.spawn(|| {
            let mut plant = ChargeIntegrator::new();
            let summary = run_rehastim2_until(&args, &mut plant, &stop);
            (plant, summary)
        });
        let deadline = Instant::now() + Duration::from_secs(10);
        while !args.pty_link.exists() {
            assert!(
                Instant::now() < deadline,
                "the device did not publish its pty"
            );
            std::thread::sleep(Duration::from_millis(5));
        }
        let mut child = Command::new(&python)
            .arg(python_script("rehastim2_client.py"))
            .arg(&args.pty_link)
            .arg(mode)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("start the pyScienceMode client");
        let deadline = Instant::now() + Duration::from_secs(60);
        let status = loop {
            if let Some(s) = child.try_wait().unwrap() {
                break s;
            }
            if Instant::now() > deadline {
                let _ = child.kill();
                stop.store(true, Ordering::Relaxed);
                panic!("the pyScienceMode client did not finish within 60 s");
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        let mut stdout = String::new();
        std::io::Read::read_to_string(&mut child.stdout.take().unwrap(), &mut stdout).unwrap();
        std::thread::sleep(after);
        stop.store(true, Ordering::Relaxed);
        let (plant, summary) = device.join().unwrap();
        (status, stdout, plant, summary.unwrap())
    });
    let rows = read_log(&args.pulse_log.unwrap());
    assert_eq!(
        summary.pulses,
        rows.iter().filter(|r| r.event == "pulse").count() as u64
    );
    Run {
        client,
        stdout,
        rows,
        plant,
        bad_packets: summary.bad_packets,
    }
}

/// Checks the channel list pulses: channel 1 every 50 ms (in multiples: a paused cycle has
/// no pulse), each followed by channel 2's doublet 2 ms and 4 ms later (the last cycle's
/// may be cut short by the stop or the watchdog); channel 1's 200 us, applied to the
/// muscle, channel 2's 100 us at 10 mA, logged only. Returns channel 1's currents.
fn check_channel_list(rows: &[&Row]) -> Vec<u8> {
    let ch1: Vec<&&Row> = rows.iter().filter(|r| r.channel == 1).collect();
    assert!(!ch1.is_empty(), "no channel 1 pulse: {rows:#?}");
    for w in ch1.windows(2) {
        let gap = w[1].t_ms - w[0].t_ms;
        assert!(
            gap > 0 && gap % 50 == 0,
            "channel 1 at {} and {}",
            w[0].t_ms,
            w[1].t_ms
        );
    }
    let doublet_pulse = |r: &Row, dt: u64| {
        rows.iter().any(|q| {
            q.channel == 2 && q.t_ms == r.t_ms + dt && q.width_us == 100 && q.current_ma == 10
        })
    };
    for (i, r) in ch1.iter().enumerate() {
        assert_eq!((r.width_us, r.applied), (200, true), "{r:?}");
        let last = i + 1 == ch1.len();
        let first = doublet_pulse(r, 2);
        let second = doublet_pulse(r, 4);
        let whole_or_cut = match (first, second) {
            (true, true) => true,
            // The stop or the watchdog came during the last cycle: a prefix of the doublet.
            (true, false) | (false, false) => last,
            (false, true) => false,
        };
        assert!(
            whole_or_cut,
            "channel 2's doublet after {r:?}: {first} {second}"
        );
    }
    let ch2: Vec<&&Row> = rows.iter().filter(|r| r.channel == 2).collect();
    assert!(ch2.iter().all(|r| !r.applied), "{ch2:#?}");
    assert!(
        ch2.len() <= 2 * ch1.len() && ch2.len() >= 2 * ch1.len() - 2,
        "{rows:#?}"
    );
    ch1.iter().map(|r| r.current_ma).collect()
}

#[test]
fn pysciencemode_drives_the_virtual_rehastim2_through_its_pty() {
    let run = run("session", "session", Duration::from_millis(100));
    assert!(
        run.client.success(),
        "client: {}\n{}",
        run.client,
        run.stdout
    );
    // pyScienceMode prints "thread started" (no newline) from its ack thread, which may
    // land in front of a step's line.
    let steps: Vec<serde_json::Value> = run
        .stdout
        .lines()
        .filter_map(|l| l.find('{').map(|i| &l[i..]))
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let names: Vec<&str> = steps.iter().map(|v| v["what"].as_str().unwrap()).collect();
    assert_eq!(
        names,
        [
            "connected",
            "init_channel",
            "start_then_pause",
            "update",
            "stop",
            "single_pulse",
            "single_pulse",
            "single_pulse",
            "disconnected"
        ],
        "{}",
        run.stdout
    );
    // The single pulses' acknowledgements, as pyScienceMode read them off the port.
    for (i, v) in steps
        .iter()
        .filter(|v| v["what"] == "single_pulse")
        .enumerate()
    {
        let hex = v["ack"].as_str().unwrap();
        let bytes: Vec<u8> = (0..hex.len() / 2)
            .map(|k| u8::from_str_radix(&hex[2 * k..2 * k + 2], 16).unwrap())
            .collect();
        let packets: Vec<_> = Decoder::new().feed(&bytes).collect();
        assert_eq!(
            packets,
            [Ok(Packet::new(
                i as u8,
                Message::SinglePulseAck {
                    result: AckResult::Ok
                }
            ))]
        );
    }
    assert_eq!(run.bad_packets, 0);
    assert!(
        run.rows.iter().all(|r| r.event == "pulse"),
        "{:#?}",
        run.rows
    );
    let list: Vec<&Row> = run
        .rows
        .iter()
        .filter(|r| r.source == "channel_list")
        .collect();
    let singles: Vec<&Row> = run.rows.iter().filter(|r| r.source == "single").collect();
    // 0.5 s at 20 mA, the pause (0 mA: no pulse), 0.3 s at 30 mA: every 20 mA pulse
    // before every 30 mA one.
    let currents = check_channel_list(&list);
    let n20 = currents.iter().filter(|&&c| c == 20).count();
    let n30 = currents.iter().filter(|&&c| c == 30).count();
    assert_eq!(n20 + n30, currents.len(), "{currents:?}");
    // (At least a few of each: the device's ticks may fall behind a loaded host's clock.)
    assert!(n20 >= 3 && n30 >= 2, "{currents:?}");
    assert!(currents.is_sorted(), "{currents:?}");
    // Then stop: the three single pulses come after the last channel list pulse.
    assert_eq!(singles.len(), 3, "{singles:#?}");
    let last_list = list.iter().map(|r| r.t_ms).max().unwrap();
    for s in &singles {
        assert_eq!(
            (s.channel, s.width_us, s.current_ma, s.applied),
            (1, 250, 40, true),
            "{s:?}"
        );
        assert!(s.t_ms > last_list, "{s:?} before the stop");
    }
    // The muscle received channel 1's pulses: the list's and the single ones.
    assert_eq!(run.plant.pulses(), (currents.len() + 3) as u64);
}

#[test]
fn the_device_watchdog_stops_stimulation_when_the_pysciencemode_host_dies() {
    let run = run("killed", "killed", Duration::from_millis(2000));
    assert_eq!(
        run.client.signal(),
        Some(9),
        "the client should have killed itself: {}\n{}",
        run.client,
        run.stdout
    );
    assert!(run.stdout.contains("\"started\""), "{}", run.stdout);
    let watchdog: Vec<&Row> = run.rows.iter().filter(|r| r.event == "watchdog").collect();
    assert_eq!(watchdog.len(), 1, "{:#?}", run.rows);
    let silent_ms: u64 = watchdog[0].detail.parse().unwrap();
    assert!(silent_ms > 1000 && silent_ms < 1100, "{silent_ms}");
    let pulses: Vec<&Row> = run.rows.iter().filter(|r| r.event == "pulse").collect();
    // It stimulated (at 20 mA) until the watchdog, and not after.
    let currents = check_channel_list(&pulses);
    assert!(
        currents.iter().all(|&c| c == 20) && currents.len() >= 3,
        "{currents:?}"
    );
    let last = pulses.iter().map(|r| r.t_ms).max().unwrap();
    assert!(
        last < watchdog[0].t_ms,
        "pulse at {last} ms after the watchdog"
    );
    // Channel list mode ran on through the silence, right up to the watchdog: the last
    // pulse is at most one 50 ms interval before it.
    assert!(
        watchdog[0].t_ms - last <= 50,
        "{last} .. {}",
        watchdog[0].t_ms
    );
}
