//! `can.log` of a run on the host bus: the whole stack runs armed for two
//! seconds while [`CanLog`] records the tap; the log is a `candump -L` file that cantools
//! decodes with the project's DBC, every frame, and python-can's log reader reads frame
//! for frame, with the PULSE frames of the run among them.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use std::process::Command;
use std::time::Duration;

use fes_bench::bench::ChainTiming;
use fes_bench::canlog::{CanLog, HOSTBUS_CHANNEL};
use fes_tests::stack::stack_binaries;

use crate::stack_support;

#[test]
fn a_runs_can_log_decodes_with_cantools_and_python_can() {
    let _one = stack_support::one_stack_at_a_time();
    let dir = fes_testkit::Scratch::new("canlog");
    let iface = format!("hostbus:{}", dir.join("bus").display());
    let log = dir.join("can.log");
    let canlog = CanLog::start(&iface, &log).expect("start can.log");
    let stack = stack_support::start_armed(
        "can.log",
        &dir,
        &stack_binaries(),
        iface,
        ChainTiming::Tolerant,
        format!("canlog{}", std::process::id()),
        Vec::new(),
    );
    std::thread::sleep(Duration::from_secs(2));
    let root = dir.join("recording");
    let _ = stack.stop(Duration::from_secs(5));
    let frames = canlog.finish().expect("finish can.log");
    let text = std::fs::read_to_string(&log).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len() as u64, frames);
    assert!(
        frames > 1000,
        "two armed seconds carry FORCE every ms: {frames}"
    );
    let pulse_id = 0x110; // PULSE of the default stimulator node (fes.dbc)
    let pulses = lines
        .iter()
        .filter(|l| l.contains(&format!(" {HOSTBUS_CHANNEL} {pulse_id:03X}#")))
        .count();
    assert!(pulses > 10, "{pulses} PULSE frames");

    // The recording's ledger: every pulse the driver sent is on the bus, and the virtual
    // stimulator applied every one it accounted for (STATUS counts them in order); at most
    // the last STATUS period's pulses may be unaccounted when the recording ended.
    let run = fes_bench::bench::recordings_in(&root)
        .pop()
        .expect("the run's recording");
    let ledger = fes_bench::summary::PulseLedger::read(&run.join("pulses.csv"))
        .expect("read pulses.csv")
        .expect("the recording has pulses.csv");
    assert!(
        ledger.sent <= pulses as u64,
        "{ledger:?}, {pulses} on the bus"
    );
    assert!(
        ledger.applied + 2 >= ledger.sent && ledger.applied > 10,
        "{ledger:?}"
    );

    // cantools: one decoded line per frame, every one a message of the DBC.
    let decoded = fes_tests::cantools::decode_log(&log);
    assert_eq!(decoded.len(), lines.len(), "one decoded line per frame");
    assert_eq!(
        decoded.iter().filter(|l| l.contains(":: PULSE(")).count(),
        pulses
    );

    // python-can: the same frames, in order, with their ids.
    let script = r#"
import sys, can
ids = [m.arbitration_id for m in can.LogReader(sys.argv[1])]
print(len(ids), sum(1 for i in ids if i == int(sys.argv[2], 16)))
"#;
    let out = Command::new("python3")
        .args(["-c", script])
        .arg(&log)
        .arg(format!("{pulse_id:X}"))
        .output()
        .expect("run python3");
    assert!(
        out.status.success(),
        "python-can (scripts/setup installs it): {}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        String::from_utf8_lossy(&out.stdout).trim(),
        format!("{frames} {pulses}")
    );
}
