//! Fault injection on the whole stack: the four processes on the host bus
//! (fes_hostbus: the CAN frames over Unix datagrams, at the host's real-time
//! latencies), a 120 beats/min cardiac profile, and then
//!
//! * SIGSTOP of each process at a seeded random moment for a seeded random time, SIGCONT;
//! * injected on the bus through the tap station: a bus-off error frame, an EMCY storm in
//!   the stimulator's name, forged PULSE frames, random frames and datagrams, and *valid*
//!   host frames (NMT start, a host heartbeat, a PULSE with the right CRC, alive counter
//!   and sequence number) from a sender that is not the driver.
//!
//! Each case asserts on what the stimulator did (its per-tick record) and what the
//! supervisor reports: every applied pulse within the stimulator's limits and with the
//! generator's parameters (never a forged one); once the stimulator has left operation it
//! applies no pulse again (nobody re-arms); a fault beyond the chain's reaction threshold
//! ends with the stimulator out of operation and the supervisor in `fault`; the recording
//! reads back as a data set. Each process's exit is clean at the end, or it was a victim.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use fes_bench::bench::{ChainTiming, PROCESSES, Stack, process_logs};
use fes_can::{Emcy, ErrorCode, Message, Nodes, StimState};
use fes_dataset::DataSet;
use fes_hostbus::{HostBus, RawFrame, Station};
use fes_rt::rt::clock::monotonic_ns;
use fes_testkit::Scratch;
use fes_tests::stack::{StimRow, stack_binaries, stimulator_rows};
use nix::sys::signal::Signal;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use supervisor::profile::{CardiacSpec, ProfileSpec};
use supervisor::protocol::Status;

use crate::stack_support;

/// The stimulator's limits on the bench (its defaults).
const LIMITS: fes_can::StimLimits = fes_can::StimLimits::DEFAULT;

/// The chain's timeouts in these cases: above the host's own stalls (what is judged is
/// what the chain does, not how fast).
const TIMING: ChainTiming = ChainTiming::Tolerant;

struct Bench {
    stack: Stack,
    dir: Scratch,
    _serial: std::sync::MutexGuard<'static, ()>,
}

impl Bench {
    /// Starts the stack on the host bus, arms and starts the cardiac profile.
    fn start(tag: &str) -> Self {
        Self::start_with(tag, |_| {})
    }

    /// As [`Self::start`], with `prepare` run on the (new, empty) stack directory first.
    fn start_with(tag: &str, prepare: impl FnOnce(&Path)) -> Self {
        Self::start_env(tag, prepare, Vec::new())
    }

    /// As [`Self::start_with`], with extra environment per process (test-only switches).
    fn start_env(
        tag: &str,
        prepare: impl FnOnce(&Path),
        env: Vec<(&'static str, String, String)>,
    ) -> Self {
        let serial = stack_support::one_stack_at_a_time();
        let dir = Scratch::new(&format!("fi-{tag}"));
        prepare(&dir);
        let stack = stack_support::start_armed(
            tag,
            &dir,
            &stack_binaries(),
            format!("hostbus:{}", dir.join("bus").display()),
            TIMING,
            format!("fi{}{tag}", std::process::id()),
            env,
        );
        Self {
            stack,
            dir,
            _serial: serial,
        }
    }

    fn bus(&self) -> PathBuf {
        self.dir.join("bus")
    }

    fn logs(&self) -> String {
        process_logs(&self.dir)
    }

    fn status(&self) -> Status {
        self.stack
            .status()
            .unwrap_or_else(|e| panic!("the supervisor does not answer: {e}\n{}", self.logs()))
    }

    /// Polls the supervisor until it reports a fault or `timeout` passes.
    fn wait_fault(&self, timeout: Duration) -> Status {
        let deadline = Instant::now() + timeout;
        loop {
            let s = self.status();
            if s.state == "fault" || Instant::now() > deadline {
                return s;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// The stack, when it is still stimulating just before a case injects its fault; `Err`
    /// (the stack stopped, the safety invariants checked) when a host stall has already
    /// tripped the chain ([`stack_support::is_timing_trip`]): the attempt is void.
    fn ready_for_injection(self, case: &str) -> Result<Self, String> {
        let s = self.status();
        let timing = stack_support::is_timing_trip(&s);
        let Some(trip) = s.fault.filter(|_| timing) else {
            return Ok(self);
        };
        let done = self.finish();
        done.check_safety(&format!("{case} (void attempt)"), 0);
        Err(format!("{trip}; driver: {}", done.driver_trips))
    }

    /// Stops the stack and returns the stimulator's record, the recording's sample count
    /// and the exit codes.
    fn finish(self) -> Finished {
        let recordings = self.stack.recordings();
        let dir = self.dir;
        let exits = self.stack.stop(Duration::from_secs(5));
        let rows = stimulator_rows(&dir.join("stimulator.csv"));
        let run = recordings.last().expect("a recording run");
        let ds = DataSet::read(run).unwrap_or_else(|e| panic!("{}: {e}", run.display()));
        // Every recording names the prescription it was made under.
        let meta = std::fs::read_to_string(run.join("dataset.json")).unwrap_or_default();
        let meta: serde_json::Value = serde_json::from_str(&meta).unwrap_or_default();
        assert_eq!(
            meta["prescription_sha256"].as_str(),
            Some(fes_prescription::sha256_hex(fes_bench::bench::PRESCRIPTION.as_bytes()).as_str()),
            "{}: dataset.json prescription_sha256",
            run.display()
        );
        let decided_ns = stack_support::raw_ticks(run)
            .iter()
            .filter(|t| t.pulse)
            .map(|t| t.t_ns)
            .collect();
        let samples = ds.records.iter().map(|r| r.len()).sum();
        let logs = process_logs(&dir);
        let driver_trips = stack_support::driver_trips(&dir);
        let rt_core_log = std::fs::read_to_string(dir.join("rt-core.log")).unwrap_or_default();
        // Everything the checks need is read: the directory goes now.
        drop(dir);
        Finished {
            rows,
            samples,
            exits,
            logs,
            driver_trips,
            rt_core_log,
            decided_ns,
        }
    }
}

struct Finished {
    rows: Vec<StimRow>,
    samples: usize,
    exits: Vec<(&'static str, Option<i32>)>,
    logs: String,
    /// The driver's `SAFE STATE` lines ([`stack_support::driver_trips`]).
    driver_trips: String,
    /// rt-core's whole log.
    rt_core_log: String,
    /// Grid times of the pulses rt-core decided (the recording's raw tick stream), ns.
    decided_ns: Vec<u64>,
}

const OPERATING: [&str; 2] = ["stimulating", "armed"];

impl Finished {
    /// The invariants of every case: applied pulses within the limits and identical in
    /// amplitude and width to the generator's first; no pulse once the stimulator left
    /// operation after `from_ns`; a readable recording. Returns when the stimulator left
    /// operation after `from_ns`, if it did.
    fn check(&self, case: &str, from_ns: u64) -> Option<u64> {
        // Stimulation was under way: rt-core decided pulses and the stimulator applied
        // some (how many decisions arrive in time is the host's: the driver refuses a
        // pulse it would send late, rightly).
        let applied = self
            .rows
            .iter()
            .filter(|r| r.pulse.is_some() && r.t_ns < from_ns)
            .count();
        let decided = self.decided_ns.iter().filter(|&&t| t < from_ns).count();
        assert!(
            applied >= 1 && decided > 5,
            "{case}: no stimulation before the fault ({decided} pulses decided, {applied} applied)\n{}",
            self.logs
        );
        let left = self.check_safety(case, from_ns);
        assert!(
            self.samples >= 500,
            "{case}: only {} samples recorded",
            self.samples
        );
        left
    }

    /// The safety invariants alone (those of [`Self::check`] that hold however early a
    /// fault came): applied pulses within the limits, with the generator's parameters and
    /// the minimum IPI, and none once the stimulator left operation after `from_ns`.
    fn check_safety(&self, case: &str, from_ns: u64) -> Option<u64> {
        let pulses: Vec<&StimRow> = self.rows.iter().filter(|r| r.pulse.is_some()).collect();
        let (_, amp0, width0) = pulses.first().and_then(|r| r.pulse)?;
        let mut prev: Option<u64> = None;
        let mut ticks_sorted: Vec<u64> = pulses.iter().map(|r| r.tick).collect();
        ticks_sorted.sort_unstable();
        for (r, &tick) in pulses.iter().zip(&ticks_sorted) {
            let (_, amp, width) = r.pulse.unwrap();
            assert!(
                amp == amp0 && width == width0,
                "{case}: a pulse of {amp} mA / {width} us at tick {} (the generator's are {amp0} / {width0})",
                r.tick
            );
            assert!(
                amp * 10.0 <= f64::from(LIMITS.max_amplitude_100ua) + 1e-9
                    && width <= f64::from(LIMITS.max_width_us),
                "{case}: pulse beyond the limits at tick {}",
                r.tick
            );
            if let Some(p) = prev {
                assert!(
                    tick - p >= u64::from(LIMITS.min_ipi_ms),
                    "{case}: pulses at ticks {p} and {tick}, closer than the minimum IPI"
                );
            }
            prev = Some(tick);
        }
        // Leaving operation counts only once the stimulator was operating: before the arm
        // it is pre-operational (a void attempt checks from 0).
        let operating_since = self
            .rows
            .iter()
            .find(|r| OPERATING.contains(&r.state.as_str()))
            .map(|r| r.t_ns);
        let left = operating_since.and_then(|since| {
            self.rows
                .iter()
                .find(|r| r.t_ns > from_ns.max(since) && !OPERATING.contains(&r.state.as_str()))
                .map(|r| r.t_ns)
        });
        if let Some(t) = left {
            let after: Vec<u64> = pulses
                .iter()
                .filter(|r| r.t_ns > t)
                .map(|r| (r.t_ns - t) / 1_000_000)
                .collect();
            let around: Vec<String> = self
                .rows
                .iter()
                .filter(|r| r.t_ns + 5_000_000 >= t && (r.state != "fault" || r.pulse.is_some()))
                .take(40)
                .map(|r| format!("{} {} {} {:?}", r.tick, r.t_ns, r.state, r.pulse))
                .collect();
            assert!(
                after.is_empty(),
                "{case}: pulses {after:?} ms after the stimulator left operation (re-armed by itself?)\n{}",
                around.join("\n")
            );
        }
        left
    }

    /// The stimulator's last recorded state.
    fn last_state(&self) -> &str {
        self.rows.last().map_or("", |r| r.state.as_str())
    }

    /// Every process but `victim` exited on SIGTERM; rt-core's hot path allocated nothing
    /// (a peer connecting late is counted apart).
    fn clean_exits_except(&self, case: &str, victim: Option<&str>) {
        self.clean_exits(case, victim, true);
    }

    /// As [`Self::clean_exits_except`]; `no_alloc`: also require rt-core's 0 hot-path
    /// allocations. (A CI run saw 1 in a SIGSTOP case; the SIGSTOP cases report the count
    /// instead, see docs/safety.md.)
    fn clean_exits(&self, case: &str, victim: Option<&str>, no_alloc: bool) {
        for (name, code) in &self.exits {
            if Some(*name) != victim {
                assert!(
                    code.is_some(),
                    "{case}: {name} had to be killed at the end\n{}",
                    self.logs
                );
            }
        }
        if victim != Some("rt-core") && no_alloc {
            assert_eq!(
                self.rt_core_allocations(),
                Some(0),
                "{case}: rt-core allocated on its hot path; {}\n{}",
                self.rt_core_allocation_trace(),
                self.logs
            );
        }
    }

    /// rt-core's hot-path allocations, from its final log line.
    fn rt_core_allocations(&self) -> Option<u64> {
        let log = &self.rt_core_log;
        let i = log.rfind(" hot-path heap allocations")?;
        log[..i].rsplit(' ').next()?.parse().ok()
    }

    /// Where rt-core's first hot-path heap allocation came from (its exit log:
    /// `[telemetry] trace_allocations`), or a note that it logged none.
    fn rt_core_allocation_trace(&self) -> String {
        self.rt_core_log
            .find("first heap allocation on a tracked thread")
            .map_or("no allocation trace in rt-core's log".into(), |i| {
                self.rt_core_log[i..].chars().take(6000).collect()
            })
    }
}

/// Runs `attempt` (given its number) until it is not void, three attempts at most. An
/// attempt is void when a host stall tripped the chain before the case could inject its
/// fault ([`Bench::ready_for_injection`]); CI saw such trips about once in a few minutes of
/// stack time. Every void attempt is printed.
fn repeat_void(case: &str, mut attempt: impl FnMut(u32) -> Result<(), String>) {
    for n in 1..=3 {
        match attempt(n) {
            Ok(()) => return,
            Err(why) => eprintln!("{case}: attempt {n} void ({why}); again"),
        }
    }
    panic!("{case}: three attempts in a row were voided by host stalls");
}

/// The stall beyond which the chain must have stopped stimulation, per victim, ms: the
/// driver's StimTick watchdog for rt-core, the stimulator's heartbeat watchdog for the
/// driver, the driver's stimulator timeout for the stimulator, the supervisor's self-stall
/// limit for the supervisor; each with 100 ms (the supervisor 200 ms) of margin.
fn must_stop_after_ms(victim: &str) -> u64 {
    let t = TIMING.timeouts();
    match victim {
        "supervisor" => t.self_stall_ms + 200,
        "rt-core" => u64::from(t.driver_tick_ticks) + 100,
        _ => u64::from(t.stimulator_watchdog_ms) + 100,
    }
}

/// The range of stall times drawn for a victim, ms: both sides of its threshold.
fn stall_range_ms(victim: &str) -> std::ops::Range<u64> {
    match victim {
        "supervisor" => 20..2500,
        _ => 20..900,
    }
}

/// SIGSTOP of each process at a seeded moment (0.3-1.5 s into the profile) for a seeded
/// time (20-900 ms; the supervisor 20-2500 ms), then SIGCONT. Three seeds per process.
#[test]
fn seeded_sigstop_of_each_process_fails_safe_and_never_rearms() {
    let mut summary = Vec::new();
    for (index, victim) in PROCESSES.into_iter().enumerate() {
        for seed in 1..=3u64 {
            let mut rng = ChaCha8Rng::seed_from_u64(seed * 7919 + index as u64);
            let at_ms: u64 = rng.random_range(300..1500);
            let stall_ms: u64 = rng.random_range(stall_range_ms(victim));
            let case = format!("SIGSTOP {victim} seed {seed} ({stall_ms} ms at {at_ms} ms)");
            repeat_void(&case, |n| {
                let bench = Bench::start(&format!("stop{}{seed}{n}", &victim[..3]));
                std::thread::sleep(Duration::from_millis(700 + at_ms));
                let bench = bench.ready_for_injection(&case)?;
                let stopped_ns = monotonic_ns();
                bench
                    .stack
                    .signal(victim, Signal::SIGSTOP)
                    .expect("SIGSTOP");
                std::thread::sleep(Duration::from_millis(stall_ms));
                bench
                    .stack
                    .signal(victim, Signal::SIGCONT)
                    .expect("SIGCONT");
                let must_stop = stall_ms >= must_stop_after_ms(victim);
                let status = if must_stop {
                    bench.wait_fault(Duration::from_secs(3))
                } else {
                    std::thread::sleep(Duration::from_millis(1000));
                    bench.status()
                };
                std::thread::sleep(Duration::from_millis(500));
                let done = bench.finish();
                let left = done.check(&case, stopped_ns);
                done.clean_exits(&case, None, false);
                if must_stop {
                    assert_eq!(status.state, "fault", "{case}: {status:?}\n{}", done.logs);
                    let fault = status.fault.clone().unwrap_or_default();
                    assert!(
                        fault.starts_with(victim),
                        "{case}: the supervisor blames another process: {fault}"
                    );
                    assert!(
                        left.is_some() && !OPERATING.contains(&done.last_state()),
                        "{case}: the stimulator is still {}\n{}",
                        done.last_state(),
                        done.logs
                    );
                }
                summary.push(format!(
                "{case}: supervisor {} {:?}; stimulator {} (left operation {}); rt-core hot-path allocations {:?}",
                status.state,
                status.fault.unwrap_or_default(),
                done.last_state(),
                left.map_or("never".into(), |t| format!(
                    "{:.1} ms after SIGSTOP",
                    (t - stopped_ns) as f64 / 1e6
                )),
                done.rt_core_allocations()
            ));
                if done.rt_core_allocations().is_some_and(|n| n > 0) {
                    summary.push(format!("  {}", done.rt_core_allocation_trace()));
                }
                Ok(())
            });
        }
    }
    for s in &summary {
        eprintln!("{s}");
    }
}

fn tap(bench: &Bench) -> HostBus {
    HostBus::open(&bench.bus(), Station::Tap, None).expect("the tap station")
}

/// Runs an injection case: `inject` sends through the tap; `must_stop`: the chain must
/// end stopped with the supervisor in fault; otherwise it must keep stimulating.
fn injection_case(case: &str, must_stop: bool, inject: impl Fn(&HostBus, &Path)) {
    repeat_void(case, |n| injection_attempt(case, n, must_stop, &inject));
}

/// One attempt of [`injection_case`].
fn injection_attempt(
    case: &str,
    attempt: u32,
    must_stop: bool,
    inject: &impl Fn(&HostBus, &Path),
) -> Result<(), String> {
    let bench = Bench::start(&format!("{case}{attempt}"));
    let tap = tap(&bench);
    std::thread::sleep(Duration::from_millis(1500));
    let bench = bench.ready_for_injection(case)?;
    let from_ns = monotonic_ns();
    inject(&tap, &bench.bus());
    let status = if must_stop {
        bench.wait_fault(Duration::from_secs(3))
    } else {
        std::thread::sleep(Duration::from_millis(1500));
        bench.status()
    };
    let checked_ns = monotonic_ns();
    std::thread::sleep(Duration::from_millis(300));
    drop(tap);
    let done = bench.finish();
    let left = done.check(case, from_ns);
    done.clean_exits_except(case, None);
    if !must_stop && stack_support::is_timing_trip(&status) {
        // A host stall tripped the chain after the injection: the safety invariants held
        // (checked above), but whether it would have gone on stimulating is not known.
        return Err(format!(
            "after the injection: {}; driver: {}",
            status.fault.unwrap_or_default(),
            done.driver_trips
        ));
    }
    if must_stop {
        assert_eq!(status.state, "fault", "{case}: {status:?}\n{}", done.logs);
        assert!(
            left.is_some() && !OPERATING.contains(&done.last_state()),
            "{case}: the stimulator is still {}",
            done.last_state()
        );
    } else {
        assert_eq!(status.state, "armed", "{case}: {status:?}\n{}", done.logs);
        let pulses_after = done
            .rows
            .iter()
            .filter(|r| r.t_ns > from_ns && r.pulse.is_some())
            .count();
        assert!(
            pulses_after > 10 && left.is_none_or(|t| t > checked_ns),
            "{case}: stimulation stopped ({pulses_after} pulses after)\n{}",
            done.logs
        );
    }
    eprintln!(
        "{case}: supervisor {} {:?}; stimulator {}",
        status.state,
        status.fault.unwrap_or_default(),
        done.last_state()
    );
    Ok(())
}

/// A bus-off error frame reaches the driver and the stimulator: the driver trips, the
/// stimulator reports a communication error, stimulation ends.
#[test]
fn an_injected_bus_off_stops_stimulation() {
    injection_case("bus-off", true, |tap, _| {
        // CAN_ERR_BUSOFF (linux/can/error.h).
        tap.send(&RawFrame::error(0x40, &[])).expect("inject");
    });
}

/// `supervisor watch`, waiting while stimulation runs, tells a planned stop from an
/// unplanned one by its exit status: the operator's stop (`supervisor stop`, which exits 0
/// only once the driver acknowledged it) ends it with 0; a fault (an injected bus-off)
/// with 4 and the alarm, naming the fault, on stderr.
#[test]
fn a_waiting_watch_alarms_on_an_unplanned_stop_only() {
    use std::process::{Command, Stdio};
    repeat_void("watch", |attempt| {
        let bench = Bench::start(&format!("watch{attempt}"));
        let tap = tap(&bench);
        std::thread::sleep(Duration::from_millis(1000));
        let bench = bench.ready_for_injection("watch")?;
        let socket = bench.dir.join("supervisor.sock");
        let watch = || {
            Command::new(stack_binaries().join("supervisor"))
                .args(["watch", "--socket"])
                .arg(&socket)
                .stdout(Stdio::piped())
                .stderr(Stdio::piped())
                .spawn()
                .expect("supervisor watch")
        };
        let finish = |child: std::process::Child| {
            let deadline = Instant::now() + Duration::from_secs(5);
            let mut child = child;
            while child.try_wait().expect("wait").is_none() {
                if Instant::now() > deadline {
                    let _ = child.kill();
                    panic!("supervisor watch did not end within 5 s of the stop");
                }
                std::thread::sleep(Duration::from_millis(20));
            }
            child.wait_with_output().expect("output")
        };
        // Planned: the operator's stop.
        let planned = watch();
        std::thread::sleep(Duration::from_millis(500));
        // The operator's `supervisor stop`: it ends only once stim-driver acknowledged the
        // stop, and says so.
        let asked = Instant::now();
        let stop = Command::new(stack_binaries().join("supervisor"))
            .args(["stop", "--socket"])
            .arg(&socket)
            .output()
            .expect("supervisor stop");
        let stop_ms = asked.elapsed().as_secs_f64() * 1e3;
        let stop_out = String::from_utf8_lossy(&stop.stdout).into_owned();
        assert_eq!(
            stop.status.code(),
            Some(0),
            "supervisor stop: {stop_out}{}",
            String::from_utf8_lossy(&stop.stderr)
        );
        assert!(
            stop_out.contains("stim-driver acknowledged the stop"),
            "{stop_out}"
        );
        eprintln!("supervisor stop: acknowledged, {stop_ms:.0} ms after it was run");
        let out = finish(planned);
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        assert_eq!(
            out.status.code(),
            Some(0),
            "after the operator's stop: {stderr}"
        );
        assert!(!stderr.contains("ALARM"), "{stderr}");
        // Unplanned: re-armed, then a bus-off.
        bench
            .stack
            .arm_with(ProfileSpec::Cardiac(CardiacSpec {
                bpm: 120.0,
                duty: 0.4,
                amplitude: 0.3,
                edge_rate_per_s: None,
                outer_loop: None,
                start_rest_ms: None,
            }))
            .expect("re-arm");
        std::thread::sleep(Duration::from_millis(500));
        let unplanned = watch();
        std::thread::sleep(Duration::from_millis(500));
        let before = bench.status();
        if stack_support::is_timing_trip(&before) {
            let _ = finish(unplanned);
            let done = bench.finish();
            done.check_safety("watch (void attempt)", 0);
            return Err(format!(
                "before the bus-off: {}",
                before.fault.unwrap_or_default()
            ));
        }
        tap.send(&RawFrame::error(0x40, &[])).expect("inject");
        let out = finish(unplanned);
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        let status = bench.status();
        drop(tap);
        let done = bench.finish();
        assert_eq!(
            out.status.code(),
            Some(4),
            "after a bus-off: {stderr}\n{}",
            done.logs
        );
        let fault = status.fault.unwrap_or_default();
        assert!(
            stderr.contains("ALARM: unplanned stop")
                && !fault.is_empty()
                && stderr.contains(&fault),
            "the alarm names the fault ({fault}): {stderr}"
        );
        Ok(())
    });
}

/// A thread of the driver panics while it stimulates (its report thread, by the test-only
/// switch `FES_TEST_PANIC_REPORT_AFTER_MS`): the panic hook sends NMT stop and aborts the
/// process, so the stimulator leaves operation at once, well within its
/// own watchdog, and the supervisor names the driver dead. Before the hook, the forward
/// thread went on sending pulses with the report thread (DriverStatus, liveness checks)
/// dead, until the supervisor's 1 s DriverStatus timeout stopped it.
#[test]
fn a_panicking_driver_thread_stops_the_stimulator_within_its_watchdog() {
    repeat_void("driver panic", |attempt| {
        let bench = Bench::start_env(
            &format!("panic{attempt}"),
            |_| {},
            vec![(
                "stim-driver",
                "FES_TEST_PANIC_REPORT_AFTER_MS".to_owned(),
                "4000".to_owned(),
            )],
        );
        std::thread::sleep(Duration::from_millis(1000));
        let bench = bench.ready_for_injection("driver panic")?;
        let from_ns = monotonic_ns();
        let status = bench.wait_fault(Duration::from_secs(8));
        std::thread::sleep(Duration::from_millis(500));
        let log = std::fs::read_to_string(bench.dir.join("stim-driver.log")).unwrap_or_default();
        let done = bench.finish();
        let panicked_ns: u64 = log
            .lines()
            .find_map(|l| {
                let rest = l.split_once("panicked at CLOCK_MONOTONIC ")?.1;
                rest.split_whitespace().next()?.parse().ok()
            })
            .unwrap_or_else(|| panic!("no panic in the driver's log\n{}", done.logs));
        assert!(
            panicked_ns > from_ns,
            "the switch fired before the stack was stimulating: raise it"
        );
        let left = done.check("driver panic", from_ns);
        let left =
            left.unwrap_or_else(|| panic!("the stimulator never left operation\n{}", done.logs));
        let ms = left.saturating_sub(panicked_ns) as f64 / 1e6;
        let watchdog = f64::from(TIMING.timeouts().stimulator_watchdog_ms);
        eprintln!(
            "driver panic: the stimulator left operation {ms:.1} ms after it (watchdog {watchdog} ms)"
        );
        assert!(
            ms <= watchdog,
            "the stimulator left operation {ms:.1} ms after the driver's panic, later than its own watchdog ({watchdog} ms)\n{}",
            done.logs
        );
        assert!(
            log.contains("NMT stop written"),
            "the panic hook's NMT stop is not in the driver's log\n{log}"
        );
        assert_eq!(status.state, "fault", "{status:?}");
        assert!(
            status
                .fault
                .as_deref()
                .is_some_and(|f| f.starts_with("stim-driver")),
            "the supervisor blames another process: {status:?}"
        );
        done.clean_exits_except("driver panic", Some("stim-driver"));
        Ok(())
    });
}

/// 2000 EMCY frames in the stimulator's name within about 200 ms: the driver trips on the
/// first and survives the storm (its event queues are bounded), stimulation ends.
#[test]
fn an_emcy_storm_stops_stimulation_and_crashes_nothing() {
    injection_case("emcy-storm", true, |tap, _| {
        let nodes = Nodes::DEFAULT;
        for i in 0..2000u32 {
            let f = Message::Emcy(Emcy::new(
                ErrorCode::Generic,
                StimState::Fault,
                i as u16,
                0xBEEF,
            ))
            .encode_for(&nodes)
            .expect("EMCY encodes");
            tap.send(&RawFrame::data(f.id, f.payload()).unwrap())
                .expect("inject");
            if i % 10 == 0 {
                std::thread::sleep(Duration::from_millis(1));
            }
        }
    });
}

/// Forged PULSE frames (random payloads, so bad CRCs and counters, and an amplitude the
/// generator never uses) at the stimulator's PULSE identifier: it applies none of them
/// (the invariant check: every applied pulse has the generator's amplitude and width) and
/// stimulation stops (the driver sees a PULSE it did not send: an intrusion; valid forged
/// frames are `valid_frames_from_a_foreign_sender_trip_the_driver_and_stop_the_stimulator`).
#[test]
fn forged_pulse_frames_are_never_applied() {
    injection_case("forged-pulse", true, |tap, _| {
        let id = Nodes::DEFAULT.id_of(fes_can::MessageKind::Pulse);
        let mut rng = ChaCha8Rng::seed_from_u64(42);
        for _ in 0..200 {
            let r: [u8; 8] = rng.random();
            tap.send(&RawFrame::data(id, &r).unwrap()).expect("inject");
            std::thread::sleep(Duration::from_micros(500));
        }
    });
}

/// How long after a valid foreign frame reaches the bus the stimulator must have left
/// operation, ms: the driver's receive thread wakes on the frame, its forward thread acts
/// at its next wake-up (at most one 1 ms tick) and writes NMT stop, which the stimulator
/// obeys at its next 1 ms tick. About 2 ms on a quiet host (docs/safety.md gives the
/// measured values); the rest is margin for the shared host's scheduling.
const INTRUSION_STOP_BOUND_MS: f64 = 50.0;

/// A valid frame in the host's name from a foreign sender.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Foreign {
    /// NMT start to the stimulator (while armed it is a no-op for the stimulator: only
    /// the driver can tell it is not its own).
    NmtStart,
    /// A host heartbeat showing operational (it would feed the stimulator's watchdog).
    Heartbeat,
    /// The PULSE the driver would send next: the last one seen on the bus with the
    /// sequence number and alive counter advanced by one and a correct CRC, sent 3 ms
    /// after it (past the stimulator's minimum interval): the stimulator accepts it.
    Pulse,
    /// The stimulator's last FORCE frame sent again (a replay: the force the closed loop
    /// would act on, from another sender).
    Force,
    /// The stimulator's last STATUS frame sent again three times (a second STATUS sender).
    Status,
}

/// The last frame of `kind` the stimulator sent, from the tap (waits for one; the tap's
/// backlog is drained first).
fn last_stimulator_frame(tap: &HostBus, kind: fes_can::MessageKind) -> fes_can::Frame {
    while let Ok(Some(_)) = tap.recv() {}
    let id = Nodes::DEFAULT.id_of(kind);
    let deadline = Instant::now() + Duration::from_secs(3);
    loop {
        assert!(
            Instant::now() < deadline,
            "no {kind:?} from the stimulator in 3 s"
        );
        match tap.recv() {
            Ok(Some(r)) if r.frame.standard_id() == Some(id) => {
                let m = fes_can::decode(u32::from(id), r.frame.payload())
                    .unwrap_or_else(|e| panic!("the stimulator's {kind:?} does not decode: {e}"));
                return m.encode().expect("re-encodes");
            }
            Ok(_) => std::thread::sleep(Duration::from_micros(100)),
            Err(e) => panic!("tap: {e}"),
        }
    }
}

/// The next PULSE frame the driver would send, from the last one the tap sees (waits for
/// one; the tap's backlog is drained first).
fn next_driver_pulse(tap: &HostBus) -> fes_can::Frame {
    while let Ok(Some(_)) = tap.recv() {}
    let pulse_id = Nodes::DEFAULT.id_of(fes_can::MessageKind::Pulse);
    let deadline = Instant::now() + Duration::from_secs(3);
    loop {
        assert!(Instant::now() < deadline, "no PULSE from the driver in 3 s");
        match tap.recv() {
            Ok(Some(r)) if r.frame.standard_id() == Some(pulse_id) => {
                let Ok(Message::Pulse(p)) = fes_can::decode(u32::from(pulse_id), r.frame.payload())
                else {
                    panic!("the driver's PULSE does not decode: {:?}", r.frame);
                };
                let next = fes_can::Pulse {
                    seq: p.seq.wrapping_add(1),
                    alive_counter: (p.alive_counter + 1) % fes_can::counter::ALIVE_MODULUS,
                    ..p
                };
                return Message::Pulse(next).encode().expect("a valid PULSE");
            }
            Ok(_) => std::thread::sleep(Duration::from_micros(100)),
            Err(e) => panic!("tap: {e}"),
        }
    }
}

/// One attempt of [`valid_frames_from_a_foreign_sender_trip_the_driver_and_stop_the_stimulator`]:
/// the stimulator's time from the injection to leaving operation, ms.
fn foreign_frame_attempt(kind: Foreign, attempt: u32) -> Result<f64, String> {
    let case = format!("foreign-{kind:?}").to_lowercase();
    let bench = Bench::start(&format!("{case}{attempt}"));
    let tap = tap(&bench);
    std::thread::sleep(Duration::from_millis(1500));
    let bench = bench.ready_for_injection(&case)?;
    let frame = match kind {
        Foreign::NmtStart => Message::Nmt(fes_can::Nmt {
            command: fes_can::NmtCommand::Start,
            node: Nodes::DEFAULT.stim(),
        })
        .encode()
        .unwrap(),
        Foreign::Heartbeat => Message::HostHeartbeat(fes_can::Heartbeat {
            state: fes_can::NmtState::Operational,
        })
        .encode()
        .unwrap(),
        Foreign::Pulse => {
            let f = next_driver_pulse(&tap);
            std::thread::sleep(Duration::from_millis(3));
            f
        }
        Foreign::Force => last_stimulator_frame(&tap, fes_can::MessageKind::Force),
        Foreign::Status => last_stimulator_frame(&tap, fes_can::MessageKind::Status),
    };
    let from_ns = monotonic_ns();
    let copies = if kind == Foreign::Status { 3 } else { 1 };
    for _ in 0..copies {
        tap.send(&RawFrame::data(frame.id, frame.payload()).unwrap())
            .expect("inject");
    }
    let status = bench.wait_fault(Duration::from_secs(3));
    std::thread::sleep(Duration::from_millis(300));
    drop(tap);
    let done = bench.finish();
    let left = done.check(&case, from_ns);
    done.clean_exits_except(&case, None);
    if stack_support::is_timing_trip(&status) {
        // A host stall tripped the chain first: the safety invariants held (checked
        // above), the detection was not what stopped it.
        return Err(format!(
            "after the injection: {}; driver: {}",
            status.fault.unwrap_or_default(),
            done.driver_trips
        ));
    }
    assert_eq!(
        status.state, "fault",
        "{case}: {status:?}
{}",
        done.logs
    );
    let fault = status.fault.clone().unwrap_or_default();
    assert!(
        fault.contains("0xFF30 intrusion"),
        "{case}: the supervisor names {fault:?}, not the intrusion
{}",
        done.logs
    );
    let cob = format!("COB-ID {:#05x}", frame.id);
    assert!(
        done.driver_trips.contains("intrusion") && done.driver_trips.contains(&cob),
        "{case}: the driver's trip does not name the intrusion at {cob}: {}",
        done.driver_trips
    );
    let left = left.unwrap_or_else(|| panic!("{case}: the stimulator never left operation"));
    assert!(
        !OPERATING.contains(&done.last_state()),
        "{case}: the stimulator is still {}",
        done.last_state()
    );
    let stop_ms = (left - from_ns) as f64 / 1e6;
    assert!(
        stop_ms <= INTRUSION_STOP_BOUND_MS,
        "{case}: the stimulator left operation {stop_ms:.1} ms after the injection (bound {INTRUSION_STOP_BOUND_MS} ms)"
    );
    let forged_applied = match kind {
        Foreign::Pulse => {
            let seq = u64::from(
                fes_can::decode(u32::from(frame.id), frame.payload())
                    .ok()
                    .and_then(|m| match m {
                        Message::Pulse(p) => Some(p.seq),
                        _ => None,
                    })
                    .unwrap_or(0),
            );
            done.rows
                .iter()
                .any(|r| r.pulse.is_some_and(|(s, _, _)| s == seq))
        }
        _ => false,
    };
    eprintln!(
        "{case}: supervisor {fault:?}; stimulator left operation {stop_ms:.2} ms after the injection, ends {}{}",
        done.last_state(),
        if forged_applied {
            "; the forged PULSE was applied before the stop (detection, not prevention)"
        } else {
            ""
        }
    );
    Ok(stop_ms)
}

/// Valid host frames from a sender that is not the driver: NMT start,
/// a host heartbeat and the next PULSE, each with what the real driver would send (the
/// codec's encoders; the PULSE's CRC, alive counter and sequence number as the driver's
/// next). The stimulator cannot tell them from the driver's; the driver, which receives
/// frames on its own identifiers, trips on each (0xFF30, naming the COB-ID), and the
/// stimulator leaves operation within [`INTRUSION_STOP_BOUND_MS`] of the injection and
/// applies no pulse after. Without the detection the NMT start and the heartbeat change
/// nothing (stimulation goes on) and the PULSE trips on the sequence error or the STATUS
/// reconciliation instead, so this test fails. Likewise the stimulator's own FORCE and
/// STATUS frames from a second sender (a replay: its numbering repeats): without the
/// numbering check the FORCE feeds the loop and the STATUS changes nothing.
#[test]
fn valid_frames_from_a_foreign_sender_trip_the_driver_and_stop_the_stimulator() {
    let mut measured = Vec::new();
    for kind in [
        Foreign::NmtStart,
        Foreign::Heartbeat,
        Foreign::Pulse,
        Foreign::Force,
        Foreign::Status,
    ] {
        let case = format!("foreign-{kind:?}");
        repeat_void(&case, |attempt| {
            measured.push((kind, foreign_frame_attempt(kind, attempt)?));
            Ok(())
        });
    }
    eprintln!("stimulator out of operation after a foreign frame, ms: {measured:?}");
}

/// Noise on the bus that is nobody's: datagrams that are not CAN frames, extended and
/// remote frames, and standard frames at identifiers outside the protocol (random
/// payloads). Filtered or dropped as malformed; stimulation goes on.
#[test]
fn foreign_frames_and_garbage_datagrams_are_ignored() {
    injection_case("noise", false, |tap, bus| {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let raw = std::os::unix::net::UnixDatagram::unbound().unwrap();
        for i in 0..500u32 {
            let r: [u8; 8] = rng.random();
            match i % 4 {
                0 => {
                    for s in [Station::Driver, Station::Stimulator] {
                        let len = rng.random_range(0..40usize);
                        let _ = raw.send_to(&[0xA5; 40][..len], bus.join(s.file_name()));
                    }
                }
                1 => {
                    let f = RawFrame {
                        can_id: fes_hostbus::EFF_FLAG | rng.random_range(0..=libc::CAN_EFF_MASK),
                        len: 8,
                        data: r,
                    };
                    tap.send(&f).unwrap();
                }
                2 => {
                    let f = RawFrame {
                        can_id: fes_hostbus::RTR_FLAG | 0x110,
                        len: 0,
                        data: [0; 8],
                    };
                    tap.send(&f).unwrap();
                }
                _ => {
                    // Identifiers the protocol does not use (a frame of the wrong length
                    // at one it uses, e.g. a host heartbeat at 0x701, is a protocol
                    // error: the forged-frame case).
                    let id = loop {
                        let id = rng.random_range(0x200..0x800u16);
                        if Nodes::DEFAULT.kind_of(u32::from(id)).is_none() {
                            break id;
                        }
                    };
                    tap.send(&RawFrame::data(id, &r).unwrap()).unwrap();
                }
            }
            // About 4 frames per millisecond: what a 1 Mbit/s CAN bus carries besides
            // the protocol's own traffic (at most about 8 frames per millisecond).
            if i % 4 == 0 {
                std::thread::sleep(Duration::from_millis(1));
            }
        }
    });
}

/// Unmounts a filesystem on drop.
struct Mounted(PathBuf);

impl Drop for Mounted {
    fn drop(&mut self) {
        let _ = std::process::Command::new("umount").arg(&self.0).status();
    }
}

/// The recording's disk fills up mid-run (a 512 KiB tmpfs mounted at the recording
/// directory, full after about 2 s): the supervisor stops stimulation and says why, the
/// stimulator ends stopped, and what was written before reads back as a data set. Needs
/// root (mount); without it the case says so and passes vacuously. An attempt that a
/// host stall ends first (a timing trip, see [`stack_support::is_timing_trip`]) is checked for safety
/// and repeated, three attempts at most.
#[test]
fn a_full_recording_disk_stops_stimulation_and_keeps_what_was_written() {
    repeat_void("disk full", full_disk_attempt);
}

/// One attempt of [`a_full_recording_disk_stops_stimulation_and_keeps_what_was_written`]:
/// `Err` with the fault when a timing trip came first (after checking the invariants).
fn full_disk_attempt(attempt: u32) -> Result<(), String> {
    let mut mounted = None;
    let bench = Bench::start_with(&format!("diskfull{attempt}"), |dir| {
        let rec = dir.join("recording");
        std::fs::create_dir_all(&rec).unwrap();
        let ok = std::process::Command::new("mount")
            .args(["-t", "tmpfs", "-o", "size=512k,mode=0750", "tmpfs"])
            .arg(&rec)
            .status()
            .is_ok_and(|s| s.success());
        if ok {
            mounted = Some(Mounted(rec));
        }
    });
    let Some(mounted) = mounted else {
        eprintln!("SKIPPED: cannot mount a tmpfs here (not root?)");
        return Ok(());
    };
    let status = bench.wait_fault(Duration::from_secs(30));
    // The fault was raised at most one poll (50 ms) before it was seen.
    let from_ns = monotonic_ns() - 100_000_000;
    let fault = status.fault.clone().unwrap_or_default();
    std::thread::sleep(Duration::from_millis(300));
    let done = bench.finish();
    // The stack's scratch directory, which `finish` could not remove with the tmpfs
    // mounted in it.
    let dir = mounted.0.parent().map(Path::to_path_buf);
    let cleanup = move || {
        drop(mounted);
        if let Some(d) = dir {
            let _ = std::fs::remove_dir_all(d);
        }
    };
    assert_eq!(status.state, "fault", "{status:?}\n{}", done.logs);
    assert!(
        !OPERATING.contains(&done.last_state()),
        "the stimulator is still {}",
        done.last_state()
    );
    if stack_support::is_timing_trip(&status) {
        done.check_safety("disk full (void attempt)", from_ns);
        cleanup();
        return Err(format!("{fault}; driver: {}", done.driver_trips));
    }
    done.check("disk full", from_ns);
    assert!(
        fault.contains("no recording means no evidence") && fault.contains("No space left"),
        "{fault}\n{}",
        done.logs
    );
    done.clean_exits_except("disk full", None);
    eprintln!(
        "disk full: supervisor {fault:?}; stimulator {}; {} samples readable",
        done.last_state(),
        done.samples
    );
    cleanup();
    Ok(())
}

/// A step of CLOCK_REALTIME by `applied_ns` (signed), stepped back when dropped (also when
/// the case fails).
struct ClockStep {
    applied_ns: i64,
}

/// Moves CLOCK_REALTIME by `delta_ns`.
fn shift_realtime(delta_ns: i64) -> nix::Result<()> {
    use nix::time::{ClockId, clock_gettime, clock_settime};
    let now = clock_gettime(ClockId::CLOCK_REALTIME)?;
    let t =
        i128::from(now.tv_sec()) * 1_000_000_000 + i128::from(now.tv_nsec()) + i128::from(delta_ns);
    let ts = nix::sys::time::TimeSpec::new(
        (t.div_euclid(1_000_000_000)) as i64,
        (t.rem_euclid(1_000_000_000)) as i64,
    );
    clock_settime(ClockId::CLOCK_REALTIME, ts)
}

impl ClockStep {
    fn step(delta_ns: i64) -> nix::Result<Self> {
        shift_realtime(delta_ns)?;
        Ok(Self {
            applied_ns: delta_ns,
        })
    }
}

impl Drop for ClockStep {
    fn drop(&mut self) {
        let _ = shift_realtime(-self.applied_ns);
    }
}

/// CLOCK_REALTIME steps forward by 10 s, back to the true time a second later, 10 s behind
/// it and back again a second after that: the stack does not notice. Every loop, timeout
/// and watchdog runs on CLOCK_MONOTONIC; the kernel receive timestamps (CLOCK_REALTIME)
/// are mapped onto it and bounded (`socket_loop::arrival_ns`).
/// Stimulation goes on, the stimulator never leaves operation, pulses keep their spacing.
/// Needs CAP_SYS_TIME; without it the case says so and passes vacuously. The system clock
/// is put back (to within the time the two steps take) even if the case fails.
#[test]
fn clock_realtime_steps_change_nothing() {
    repeat_void("clock steps", clock_steps_attempt);
}

/// One attempt of [`clock_realtime_steps_change_nothing`].
fn clock_steps_attempt(attempt: u32) -> Result<(), String> {
    let bench = Bench::start(&format!("clock{attempt}"));
    std::thread::sleep(Duration::from_millis(1500));
    let bench = bench.ready_for_injection("clock steps")?;
    let from_ns = monotonic_ns();
    let forward = match ClockStep::step(10_000_000_000) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("SKIPPED: cannot set CLOCK_REALTIME here ({e})");
            return Ok(());
        }
    };
    std::thread::sleep(Duration::from_millis(1000));
    drop(forward); // steps it back
    let back = ClockStep::step(-10_000_000_000).expect("second step");
    std::thread::sleep(Duration::from_millis(1000));
    drop(back);
    std::thread::sleep(Duration::from_millis(500));
    let status = bench.status();
    let checked_ns = monotonic_ns();
    let done = bench.finish();
    if stack_support::is_timing_trip(&status) {
        done.check_safety("clock steps (void attempt)", from_ns);
        return Err(format!(
            "during the steps: {}; driver: {}",
            status.fault.unwrap_or_default(),
            done.driver_trips
        ));
    }
    assert_eq!(status.state, "armed", "{status:?}\n{}", done.logs);
    let left = done.check("clock steps", from_ns);
    assert!(
        left.is_none_or(|t| t > checked_ns),
        "the stimulator left operation during the clock steps\n{}",
        done.logs
    );
    let during = done
        .rows
        .iter()
        .filter(|r| r.t_ns > from_ns && r.t_ns < checked_ns && r.pulse.is_some())
        .count();
    // 2.5 s at 120 beats/min: 5 beats of about 6 pulses.
    assert!(
        during >= 20,
        "only {during} pulses during the steps\n{}",
        done.logs
    );
    done.clean_exits_except("clock steps", None);
    eprintln!(
        "clock steps: supervisor {}; {during} pulses during the steps",
        status.state
    );
    Ok(())
}

/// Every file and directory under `root` whose name starts with `prefix` (recursively).
fn files_under(root: &Path, prefix: &str, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(root) else {
        return;
    };
    for e in entries.flatten() {
        let p = e.path();
        let name = e.file_name().to_string_lossy().into_owned();
        if p.is_dir() {
            out.push(p.clone());
            files_under(&p, "", out);
        } else if name.starts_with(prefix) {
            out.push(p);
        }
    }
}

/// While the stack runs, the iceoryx2 shared memory and its management
/// files (`/dev/shm/iox2_*`, `/tmp/iceoryx2/...`) and the host bus directory are private to
/// the owner: no write access for the group, no access for others. (iceoryx2's one global
/// 16-byte management segment, `*.global_mgmt`, is shared by design: it is how any user's
/// process finds the node registry; it holds no message data.)
#[test]
fn shared_memory_and_bus_paths_are_private() {
    use std::os::unix::fs::PermissionsExt;
    let bench = Bench::start("perm");
    std::thread::sleep(Duration::from_millis(1000));
    let mut paths = Vec::new();
    files_under(Path::new("/dev/shm"), "iox2_", &mut paths);
    files_under(Path::new("/tmp/iceoryx2"), "", &mut paths);
    paths.push(bench.bus());
    files_under(&bench.bus(), "", &mut paths);
    let data = paths
        .iter()
        .filter(|p| p.to_string_lossy().ends_with(".data"))
        .count();
    let mut open = Vec::new();
    for p in &paths {
        if p.to_string_lossy().ends_with(".global_mgmt") {
            continue;
        }
        let Ok(meta) = std::fs::symlink_metadata(p) else {
            continue; // removed meanwhile (another test's node)
        };
        let mode = meta.permissions().mode() & 0o777;
        if mode & 0o027 != 0 {
            open.push(format!("{:o} {}", mode, p.display()));
        }
    }
    let done = bench.finish();
    assert!(data > 0, "no iceoryx2 data segment seen: {paths:?}");
    assert!(
        open.is_empty(),
        "paths open to others:\n{}",
        open.join("\n")
    );
    done.clean_exits_except("permissions", None);
    eprintln!(
        "permissions: {} paths checked ({data} data segments), all private",
        paths.len()
    );
}

/// Starts the stack in a fresh directory without arming; the stack (if it came up) and the
/// directory.
fn start_unarmed(
    tag: &str,
    pulse_amplitude_ua: Option<u32>,
    env: Vec<(&'static str, String, String)>,
) -> (Result<Stack, fes_bench::bench::BenchError>, Scratch) {
    let dir = Scratch::new(&format!("fi-{tag}"));
    let stack = Stack::start(fes_bench::bench::StackOptions {
        dir: dir.to_path_buf(),
        bin_dir: stack_binaries(),
        controller: fes_tests::stack::workspace_root().join("models/fast.lcn.json"),
        iface: format!("hostbus:{}", dir.join("bus").display()),
        timing: TIMING,
        preset: sim_muscle::preset::Preset::Fast,
        fatigue: false,
        outer_loop: true,
        outer_gain: None,
        prefix: format!("fi{}{tag}", std::process::id()),
        env,
        pulse_amplitude_ua,
        stimulator: fes_bench::bench::StimulatorKind::Can,
        rehastim2: fes_bench::bench::Rehastim2Options::default(),
    });
    (stack, dir)
}

/// A 5x amplitude slip in rt-core's file (100 mA for the prescription's
/// 20 mA) is refused before any pulse: rt-core exits at start naming the prescription, so
/// the stack never comes up, nothing is armed, and the stimulator applies no pulse.
#[test]
fn a_5x_amplitude_slip_in_rt_core_is_refused_before_any_pulse() {
    let _serial = stack_support::one_stack_at_a_time();
    let (stack, dir) = start_unarmed("slip", Some(100_000), Vec::new());
    let logs = process_logs(&dir);
    let err = match stack {
        Ok(stack) => {
            // Without the start check: try to stimulate, and show what reaches the muscle.
            let armed = stack.arm_with(ProfileSpec::Cardiac(CardiacSpec {
                bpm: 120.0,
                duty: 0.4,
                amplitude: 0.3,
                edge_rate_per_s: None,
                outer_loop: None,
                start_rest_ms: None,
            }));
            std::thread::sleep(Duration::from_millis(1500));
            let _ = stack.stop(Duration::from_secs(5));
            let rows = stimulator_rows(&dir.join("stimulator.csv"));
            let pulses = rows.iter().filter(|r| r.pulse.is_some()).count();
            panic!(
                "the stack started with a 100 mA pulse (arm: {armed:?}; {pulses} pulses applied)\n{}",
                process_logs(&dir)
            );
        }
        Err(e) => e.to_string(),
    };
    let rt_log = std::fs::read_to_string(dir.join("rt-core.log")).unwrap_or_default();
    assert!(
        rt_log.contains("amplitude = 100000 uA exceeds the prescription's 20000 uA"),
        "rt-core must name the prescription: {err}\n{logs}"
    );
    let rows = stimulator_rows(&dir.join("stimulator.csv"));
    assert!(
        rows.iter()
            .all(|r| r.pulse.is_none() && !OPERATING.contains(&r.state.as_str())),
        "the stimulator was operated or applied a pulse\n{logs}"
    );
}

/// A stimulator that applies a looser limit than the CONFIG asked for (the
/// virtual stimulator's test fault: it keeps its own 100 mA amplitude ceiling and reports
/// it in CONFIG_APPLIED) is refused at arm: the driver names the differing limit, the
/// stimulator is never started, no pulse is applied.
#[test]
fn a_stimulator_that_applies_a_looser_limit_is_refused_at_arm() {
    let _serial = stack_support::one_stack_at_a_time();
    let env = vec![(
        "sim-muscle",
        "FES_TEST_FAULT_LOOSE_CONFIG".to_string(),
        "1".to_string(),
    )];
    let (stack, dir) = start_unarmed("loose", None, env);
    let stack = stack.unwrap_or_else(|e| panic!("the stack did not start: {e}"));
    std::thread::sleep(Duration::from_millis(2000));
    let armed = stack.arm_with(ProfileSpec::Cardiac(CardiacSpec {
        bpm: 120.0,
        duty: 0.4,
        amplitude: 0.3,
        edge_rate_per_s: None,
        outer_loop: None,
        start_rest_ms: None,
    }));
    std::thread::sleep(Duration::from_millis(500));
    let _ = stack.stop(Duration::from_secs(5));
    let logs = process_logs(&dir);
    assert!(armed.is_err(), "armed with a looser stimulator\n{logs}");
    let driver_log = std::fs::read_to_string(dir.join("stim-driver.log")).unwrap_or_default();
    assert!(
        driver_log.contains("differs: Some(\"max_amplitude\")"),
        "the driver must name the differing limit\n{logs}"
    );
    let rows = stimulator_rows(&dir.join("stimulator.csv"));
    assert!(!rows.is_empty(), "no stimulator record\n{logs}");
    assert!(
        rows.iter()
            .all(|r| r.pulse.is_none() && !OPERATING.contains(&r.state.as_str())),
        "the stimulator was operated or applied a pulse\n{logs}"
    );
}
