//! The whole stack for the tests that run it (the kill test in `runtime_recording.rs`, the
//! fault-injection suite): started, armed and stimulating.

use std::path::Path;
use std::time::Duration;

use fes_bench::bench::{ChainTiming, Stack, StackOptions, process_logs};
use fes_tests::stack::workspace_root;
use supervisor::core::FaultCause;
use supervisor::profile::{CardiacSpec, ProfileSpec};
use supervisor::protocol::Status;

/// One whole stack at a time in this test binary: the cases share two cores and run their
/// loops at SCHED_FIFO, and two stacks at once stall each other into timing trips.
static STACKS: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Holds the one-stack-at-a-time lock for as long as a case runs its stack.
pub fn one_stack_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    STACKS.lock().unwrap_or_else(|e| e.into_inner())
}

/// Starts the four processes in `dir` from `bins` on `iface` with the default controller
/// and `timing`'s timeouts, waits until the supervisor has heard from every
/// process, arms, and starts a 120 beats/min cardiac profile (duty 0.4, amplitude 0.3).
/// `env`: extra environment per process (test-only switches). Panics naming `what`, with
/// the processes' logs.
pub fn start_armed(
    what: &str,
    dir: &Path,
    bins: &Path,
    iface: String,
    timing: ChainTiming,
    prefix: String,
    env: Vec<(&'static str, String, String)>,
) -> Stack {
    let stack = Stack::start(StackOptions {
        dir: dir.to_path_buf(),
        bin_dir: bins.to_path_buf(),
        controller: workspace_root().join("models/fast.lcn.json"),
        iface,
        timing,
        preset: sim_muscle::preset::Preset::Fast,
        fatigue: false,
        outer_loop: true,
        outer_gain: None,
        prefix,
        env,
        pulse_amplitude_ua: None,
        stimulator: fes_bench::bench::StimulatorKind::Can,
        rehastim2: fes_bench::bench::Rehastim2Options::default(),
    })
    .unwrap_or_else(|e| panic!("{what}: the stack did not start: {e}"));
    let healthy_s = if timing == ChainTiming::Uml { 90 } else { 20 };
    if let Err(e) = stack.wait_healthy(Duration::from_secs(healthy_s)) {
        panic!("{what}: {e}\n{}", process_logs(dir));
    }
    stack
        .arm_with(ProfileSpec::Cardiac(CardiacSpec {
            bpm: 120.0,
            duty: 0.4,
            amplitude: 0.3,
            edge_rate_per_s: None,
            outer_loop: None,
            start_rest_ms: None,
        }))
        .unwrap_or_else(|e| panic!("{what}: arm and cardiac profile: {e}"));
    stack
}

/// Whether a fault is one of the chain's own timing trips (a watchdog or a staleness
/// limit) rather than the fault a case injected: on a shared 2-core VM a host stall of
/// longer than even [`ChainTiming::Tolerant`]'s watchdogs can happen (CI saw 20 ms stalls
/// trip the bench's), and the chain rightly stops stimulation for it. A case checks the safety invariants on
/// such a run all the same; only its own cause was not exercised, so it runs again.
/// Judged by the status's typed cause (`fault_cause`), not by its words.
pub fn is_timing_trip(status: &Status) -> bool {
    status.state == "fault" && status.fault_cause.is_some_and(FaultCause::is_timing)
}

/// The driver's `SAFE STATE` log lines in the stack directory `dir` (what tripped, e.g.
/// "watchdog: StimTick 23.4 ms old on arrival"), for the message of a void attempt.
pub fn driver_trips(dir: &Path) -> String {
    std::fs::read_to_string(dir.join("stim-driver.log"))
        .unwrap_or_default()
        .lines()
        .filter(|l| l.contains("SAFE STATE"))
        .take(3)
        .collect::<Vec<_>>()
        .join(" | ")
}

/// One row of a recording's `ticks.csv` (the raw StimTick stream).
pub struct RawTick {
    /// StimTick sequence number.
    pub seq: u64,
    /// Its grid time, ns.
    pub t_ns: u64,
    /// It fired a pulse.
    pub pulse: bool,
}

/// The recording `run`'s `ticks.csv`, its complete lines: a line the recorder could not
/// finish (a full disk, a killed supervisor) has no newline and is left out.
pub fn raw_ticks(run: &Path) -> Vec<RawTick> {
    let text = std::fs::read_to_string(run.join("ticks.csv")).unwrap_or_default();
    let complete = text.rfind('\n').map_or("", |end| &text[..=end]);
    let mut lines = complete.lines();
    let header: Vec<&str> = lines.next().unwrap_or_default().split(',').collect();
    let col = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .unwrap_or_else(|| panic!("ticks.csv has no column {name}: {header:?}"))
    };
    let (seq, t_ns, pulse) = (col("seq"), col("t_ns"), col("pulse"));
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            RawTick {
                seq: f[seq].parse().expect("seq"),
                t_ns: f[t_ns].parse().expect("t_ns"),
                pulse: f[pulse] != "0",
            }
        })
        .collect()
}
