//! The recorder: a run becomes a readable `fes-dataset/1` data set plus message streams;
//! a crash leaves a readable data set; a full disk is an error, never a panic.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::Command;

use fes_dataset::DataSet;
use fes_rt::msg::{ForceSample, PulseFate, PulseOutcome, Reference, StimTick};
use supervisor::core::FaultCause;
use supervisor::health::Cause;
use supervisor::recording::{Recorder, RecorderSettings};

const MS: u64 = 1_000_000;
const T0: u64 = 10_000 * MS;

/// The checksum the recorder is given (any 64 hex digits).
const PRESCRIPTION_SHA256: &str =
    "8d4c6a25f5f8e3b1f8b6e2c6b4a3a1d9e0f1a2b3c4d5e6f708192a3b4c5d6e7f";

fn settings() -> RecorderSettings {
    RecorderSettings {
        flush_period_ns: 1_000 * MS,
        max_record_ticks: 1000,
        scale_n: 1.0,
        offset_n: 0.0,
        source: "test".into(),
        protocol: serde_json::json!({"test": true}),
        prescription_sha256: Some(PRESCRIPTION_SHA256.into()),
    }
}

fn tick(k: u64) -> StimTick {
    let t = T0 + k * MS;
    let pulse = k % 25 == 3;
    StimTick {
        seq: k + 1,
        t_ns: t,
        t_wake_ns: t + 20_000,
        t_publish_ns: t + 30_000,
        ref_seq: 1,
        reference: 0.3,
        u_cont: 0.1,
        energy: 0.2,
        model_force: 0.25,
        predicted_force: 0.3,
        phi: 0.4,
        amplitude_ua: if pulse { 20_000 } else { 0 },
        missed_periods: 0,
        width_us: if pulse { 200 } else { 0 },
        flags: 0,
        pulse: u8::from(pulse),
        channel: 0,
        min_gap_ticks: 0,
    }
}

/// Force of sample k: a smooth, distinct value per sample.
fn force(k: u64) -> f64 {
    0.3 + 0.2 * ((k as f64) * 0.01).sin()
}

fn sample(k: u64) -> ForceSample {
    let f = force(k);
    ForceSample {
        seq: k + 1,
        // The stimulator's sample time is 0.3 ms off the tick grid.
        t_ns: T0 + k * MS + 300_000,
        stim_seq: k,
        force_n: 364.0 * f + 2.0,
        force: f,
    }
}

/// The driver refused the pulse of tick k (one in four of the pulses, k = 53, 153, ...).
fn refused(k: u64) -> bool {
    k % 100 == 53
}

/// The stimulator did not apply the pulse of tick k although it was sent (k = 103, 303, ...).
fn not_applied(k: u64) -> bool {
    k % 200 == 103
}

/// The stimulator's account of tick k's pulse (sent, not refused), 10 ms after its tick.
fn account(k: u64, n: &mut u64) -> PulseOutcome {
    *n += 1;
    let fate = if not_applied(k) {
        PulseFate::NotApplied
    } else {
        PulseFate::Applied
    };
    PulseOutcome::new(*n, T0 + (k + 10) * MS, k + 1, T0 + k * MS, fate)
}

/// The driver's outcome of tick k's pulse.
fn outcome(k: u64, n: &mut u64) -> PulseOutcome {
    *n += 1;
    let fate = if refused(k) {
        PulseFate::Refused
    } else {
        PulseFate::Sent
    };
    PulseOutcome::new(*n, T0 + k * MS + 400_000, k + 1, T0 + k * MS, fate)
}

fn tempdir(tag: &str) -> fes_testkit::Scratch {
    fes_testkit::Scratch::new(tag)
}

/// Feeds `n` ms of a run: ticks first, the driver's outcome of each pulse with it (the
/// outcome of the tick before: it may also overtake its tick), the stimulator's account of
/// each pulse sent 10 ms later (as the next STATUS), their force 2 ms later (as over CAN),
/// a beat boundary every 800 ms, a reference every 10 ms.
fn feed(r: &mut Recorder, n: u64) {
    feed_with(r, n, |_| true, |_| true);
}

/// [`feed`], with the driver's outcome of tick k's pulse sent only when `reported(k)`, and
/// the stimulator's account of it only when `accounted(k)` too.
fn feed_with(
    r: &mut Recorder,
    n: u64,
    reported: impl Fn(u64) -> bool,
    accounted: impl Fn(u64) -> bool,
) {
    let mut outcomes = 0;
    for k in 0..n {
        let now = T0 + k * MS + 500_000;
        if let Some(j) = k.checked_sub(10)
            && tick(j).fires()
            && !refused(j)
            && reported(j)
            && accounted(j)
        {
            r.on_outcome(&account(j, &mut outcomes), now).unwrap();
        }
        if k % 800 == 0 {
            r.boundary(T0 + k * MS, format!("beat {}", k / 800));
        }
        let t = tick(k);
        // The even pulses' outcomes arrive before their ticks, the odd ones' after.
        let early = (k / 25) % 2 == 0;
        if t.fires() && reported(k) && early {
            r.on_outcome(&outcome(k, &mut outcomes), now).unwrap();
        }
        r.on_stim_tick(&t, now).unwrap();
        if t.fires() && reported(k) && !early {
            r.on_outcome(&outcome(k, &mut outcomes), now).unwrap();
        }
        if k >= 2 {
            r.on_force(&sample(k - 2), now).unwrap();
        }
        if k % 10 == 0 {
            r.on_reference(&Reference::new(k / 10 + 1, now, 0.3))
                .unwrap();
        }
        r.maybe_flush(now).unwrap();
    }
}

#[test]
fn a_run_reads_back_as_a_data_set_with_the_fed_samples() {
    let root = tempdir("ok");
    let mut r = Recorder::create(&root, "run1", settings(), T0).unwrap();
    feed(&mut r, 3000);
    // The last force samples arrive, then the run ends.
    r.on_force(&sample(2998), T0 + 3000 * MS).unwrap();
    r.on_force(&sample(2999), T0 + 3000 * MS).unwrap();
    r.on_event(T0 + 3000 * MS, "stop").unwrap();
    let s = r.finish(T0 + 3001 * MS).unwrap();
    assert_eq!(s.ticks, 3000);
    // 120 decided, 30 refused by the driver, 15 of the 90 sent not applied.
    assert_eq!(
        (s.pulses_decided, s.pulses_sent, s.pulses_applied),
        (120, 90, 75)
    );
    let dir = root.join("run1");
    assert_eq!(
        std::fs::metadata(&dir).unwrap().permissions().mode() & 0o777,
        0o750
    );
    for f in [
        "dataset.json",
        "ticks.csv",
        "force.csv",
        "events.jsonl",
        "outcomes.csv",
        "pulses.csv",
        "record_00000.csv",
    ] {
        let m = std::fs::metadata(dir.join(f)).unwrap().permissions().mode() & 0o777;
        assert_eq!(m, 0o640, "{f}: {m:o}");
    }
    let ds = DataSet::read(&dir).unwrap();
    // The recording names the prescription it was made under.
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("dataset.json")).unwrap()).unwrap();
    assert_eq!(meta["prescription_sha256"], PRESCRIPTION_SHA256);
    // Beats of 800 ms: records 800, 800, 800, 600 samples.
    let lens: Vec<usize> = ds.records.iter().map(|r| r.len()).collect();
    assert_eq!(lens, vec![800, 800, 800, 600]);
    assert_eq!(s.records, 4);
    let mut k = 0u64;
    for rec in &ds.records {
        assert!(rec.kind.starts_with("beat"), "{}", rec.kind);
        let decided = rec
            .decided
            .as_ref()
            .expect("a recording has the decided column");
        for (i, (&p, &f)) in rec.pulse.iter().zip(&rec.force).enumerate() {
            assert_eq!(rec.t_ms[i], i as f64);
            assert_eq!(decided[i], k % 25 == 3, "decided at {k}");
            assert_eq!(
                p,
                k % 25 == 3 && !refused(k) && !not_applied(k),
                "applied at {k}"
            );
            assert_eq!(f, force(k), "force at {k}");
            k += 1;
        }
    }
    // force_n = 364 force + 2: the scale is fitted from the stream.
    assert!(
        (ds.header.scale_n - 364.0).abs() < 1e-6,
        "{}",
        ds.header.scale_n
    );
    assert!(
        (ds.header.offset_n - 2.0).abs() < 1e-6,
        "{}",
        ds.header.offset_n
    );
    // The refused pulses are told apart, and identification refuses such data by default.
    assert_eq!(ds.undelivered(), (45, 0));
    let ticks = std::fs::read_to_string(dir.join("ticks.csv")).unwrap();
    assert_eq!(ticks.lines().count(), 3001);
    let outcomes = std::fs::read_to_string(dir.join("outcomes.csv")).unwrap();
    // A decision per pulse, an account per pulse sent.
    assert_eq!(outcomes.lines().count(), 1 + 120 + 90);
    assert!(
        outcomes.contains(",104,10103000000,not_applied"),
        "{outcomes}"
    );
    let pulses = std::fs::read_to_string(dir.join("pulses.csv")).unwrap();
    assert_eq!(pulses.lines().count(), 121);
    for line in [
        "tick_seq,t_ns,decided,sent,applied,fate",
        "4,10003000000,1,1,1,sent",
        "54,10053000000,1,0,0,refused",
        "104,10103000000,1,1,0,sent",
    ] {
        assert!(pulses.lines().any(|l| l == line), "{line}: {pulses}");
    }
    assert!(outcomes.contains(",54,10053000000,refused"), "{outcomes}");
    let refs = std::fs::read_to_string(dir.join("references.csv")).unwrap();
    assert_eq!(refs.lines().count(), 301);
    let _ = std::fs::remove_dir_all(&root);
}

/// A pulse decision the driver never reported on (its outcome lost, or the driver gone)
/// is recorded as decided, not as delivered, once the outcome wait is over; the rows
/// after it are not held up for longer than that. A pulse sent whose account never came
/// is recorded as sent, not applied, once the account of a later pulse is in.
#[test]
fn a_pulse_the_driver_never_reported_is_not_recorded_as_delivered() {
    let root = tempdir("unreported");
    let mut r = Recorder::create(&root, "run", settings(), T0).unwrap();
    // The outcomes of ticks 503 and 1603 are lost; from 2000 on the driver is silent; the
    // stimulator's account of 803 is lost.
    let reported = |k: u64| k != 503 && k != 1603 && k < 2000;
    feed_with(&mut r, 2400, reported, |k| k != 803);
    let end = T0 + 2400 * MS + supervisor::recording::OUTCOME_WAIT_NS;
    r.on_force(&sample(2398), end).unwrap();
    r.on_force(&sample(2399), end).unwrap();
    let s = r.finish(end).unwrap();
    assert_eq!(s.ticks, 2400);
    let ds = DataSet::read(root.join("run")).unwrap();
    let lens: Vec<usize> = ds.records.iter().map(|r| r.len()).collect();
    assert_eq!(lens, vec![800, 800, 800]);
    let mut k = 0u64;
    for rec in &ds.records {
        let decided = rec.decided.as_ref().unwrap();
        for (i, &p) in rec.pulse.iter().enumerate() {
            let fires = k % 25 == 3;
            assert_eq!(decided[i], fires, "decided at {k}");
            let applied = fires && !refused(k) && reported(k) && !not_applied(k) && k != 803;
            assert_eq!(p, applied, "applied at {k}");
            k += 1;
        }
    }
    // 96 decided; 20 refused, 2 lost, 16 after the driver fell silent (2003..2378); of
    // the 58 sent, 9 not applied (103, 303, ... but 503) and one unaccounted (803).
    assert_eq!(
        (s.pulses_decided, s.pulses_sent, s.pulses_applied),
        (96, 96 - 20 - 2 - 16, 58 - 9 - 1)
    );
    assert_eq!(ds.undelivered(), (48, 0));
    let pulses = std::fs::read_to_string(root.join("run").join("pulses.csv")).unwrap();
    for line in [
        "504,10503000000,1,0,0,unreported",
        "804,10803000000,1,1,0,sent",
    ] {
        assert!(pulses.lines().any(|l| l == line), "{line}");
    }
}

/// A crash (the recorder dropped without `finish`) loses at most the record being
/// written: the data set lists every completed record and reads back; the streams hold
/// at least everything up to the last flush.
#[test]
fn a_crash_leaves_a_readable_data_set() {
    let root = tempdir("crash");
    let mut r = Recorder::create(&root, "run", settings(), T0).unwrap();
    feed(&mut r, 2500);
    std::mem::forget(r); // as a SIGKILL: no destructor, no flush
    let dir = root.join("run");
    let ds = DataSet::read(&dir).unwrap();
    let total: usize = ds.records.iter().map(|r| r.len()).sum();
    assert_eq!(total, 2400, "the three completed beats");
    assert!(2500 - total <= 1000, "lost more than one record");
    let flushed = std::fs::read_to_string(dir.join("ticks.csv")).unwrap();
    assert!(
        flushed.lines().count() > 2000,
        "ticks flushed: {}",
        flushed.lines().count()
    );
    let _ = std::fs::remove_dir_all(&root);
}

/// A force sample outside the data-set range (-0.1..1.1) or a gap in the tick sequence
/// ends the record; the data set stays valid.
#[test]
fn gaps_and_unrecordable_force_split_records() {
    let root = tempdir("gap");
    let mut r = Recorder::create(&root, "run", settings(), T0).unwrap();
    for k in 0..600u64 {
        if (200..210).contains(&k) {
            continue; // ticks lost
        }
        let now = T0 + k * MS + 500_000;
        r.on_stim_tick(&tick(k), now).unwrap();
        let mut s = sample(k);
        if k == 400 {
            s.force = 1.5;
            s.force_n = 364.0 * 1.5 + 2.0;
        }
        r.on_force(&s, now).unwrap();
    }
    r.finish(T0 + 700 * MS).unwrap();
    let ds = DataSet::read(root.join("run")).unwrap();
    let lens: Vec<usize> = ds.records.iter().map(|r| r.len()).collect();
    assert_eq!(lens, vec![200, 190, 199]);
    let _ = std::fs::remove_dir_all(&root);
}

/// A full disk is a reported error naming the file and the cause, never a panic; the
/// recorder refuses further writes.
#[test]
fn disk_full_is_an_error_not_a_panic() {
    let root = tempdir("full");
    std::fs::create_dir_all(&root).unwrap();
    let ok = Command::new("mount")
        .args(["-t", "tmpfs", "-o", "size=96k", "tmpfs"])
        .arg(root.path())
        .status()
        .map(|s| s.success())
        .unwrap_or(false);
    assert!(
        ok,
        "this test mounts a 96 KiB tmpfs to fill it: it needs root (CAP_SYS_ADMIN)"
    );
    struct Unmount(PathBuf);
    impl Drop for Unmount {
        fn drop(&mut self) {
            let _ = Command::new("umount").arg(&self.0).status();
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
    let _guard = Unmount(root.to_path_buf());
    let mut r = Recorder::create(&root, "run", settings(), T0).unwrap();
    let mut failure = None;
    for k in 0..200_000u64 {
        let now = T0 + k * MS;
        let res = r
            .on_stim_tick(&tick(k), now)
            .and_then(|()| r.on_force(&sample(k), now))
            .and_then(|()| r.maybe_flush(now));
        if let Err(e) = res {
            failure = Some(e.to_string());
            break;
        }
    }
    let e = failure.expect("96 KiB filled without an error");
    assert!(e.contains("No space left on device"), "{e}");
    assert!(e.starts_with("recording: cannot "), "{e}");
    assert!(r.on_event(T0, "after").is_err(), "writes after a failure");
    assert!(r.finish(T0).is_err());
    let _ = Path::new("/");
}

// ---- The whole stack on CAN: killing any one process ----------------------------------

use crate::stack_support;
use fes_bench::bench::ChainTiming;

use fes_tests::stack::{stack_binaries, stimulator_rows};

/// The stimulator's per-tick record: (CLOCK_MONOTONIC ns, state, pulse applied).
fn stimulator_ticks(path: &Path) -> Vec<(u64, String, bool)> {
    stimulator_rows(path)
        .into_iter()
        .map(|r| (r.t_ns, r.state, r.pulse.is_some()))
        .collect()
}

/// Runs the stack with a cardiac profile, kills `victim` with SIGKILL, and checks: the
/// supervisor stops stimulation and names the victim (unless it is the victim), the
/// stimulator applies no pulse after the chain's reaction time and ends with its output
/// off (the supervisor as victim: the driver's supervisor watch sees its node dead and
/// sends NMT stop), and the recording up to that moment is a readable data set. Prints
/// the kill → stimulator-stopped time per victim.
/// `iface` is a CAN interface or `None` for the host bus (in the stack's directory); the
/// kill comes `after_ms` into the profile.
/// `Err` (the stack stopped, nothing asserted) when a host stall had already stopped
/// stimulation before the kill: a timing trip ([`stack_support::is_timing_trip`]), not the
/// case under test.
fn kill_one(
    bins: &Path,
    iface: Option<&str>,
    timing: ChainTiming,
    victim: &str,
    after_ms: u64,
) -> Result<(), String> {
    use fes_bench::bench::process_logs;
    use nix::sys::signal::Signal;
    use std::time::{Duration, Instant};
    use supervisor::protocol::Command as Cmd;

    let dir = tempdir(&format!("kill-{victim}"));
    let iface = iface.map_or_else(
        || format!("hostbus:{}", dir.join("bus").display()),
        str::to_owned,
    );
    let _one = stack_support::one_stack_at_a_time();
    let uml = timing == ChainTiming::Uml;
    let stack = stack_support::start_armed(
        victim,
        &dir,
        bins,
        iface,
        timing,
        format!("kill{}{}", std::process::id(), &victim[..3]),
        Vec::new(),
    );
    std::thread::sleep(Duration::from_millis(after_ms));
    let before = stack.status().expect("status");
    if let Some(trip) = before
        .fault
        .clone()
        .filter(|_| stack_support::is_timing_trip(&before))
    {
        let _ = stack.stop(Duration::from_secs(5));
        let trips = stack_support::driver_trips(&dir);
        return Err(format!("{trip}; driver: {trips}"));
    }
    assert_eq!(before.state, "armed", "{victim}: {before:?}");
    let killed_ns = fes_rt::rt::clock::monotonic_ns();
    stack.signal(victim, Signal::SIGKILL).expect("kill");
    // The chain's reaction: the stimulator watchdog (UML: 1 s) or rt-core's staleness
    // ramp (UML: 1 s + 0.15 s), plus generous slack for a UML guest.
    let settle = Duration::from_millis(if uml { 4000 } else { 1000 });
    if victim != "supervisor" {
        let deadline = Instant::now() + settle + Duration::from_secs(5);
        let status = loop {
            let s = stack.status().expect("the supervisor answers");
            if s.state == "fault" || Instant::now() > deadline {
                break s;
            }
            std::thread::sleep(Duration::from_millis(100));
        };
        let fault = status.fault.clone().unwrap_or_default();
        assert_eq!(
            status.state,
            "fault",
            "{victim}: {status:?}\n{}",
            process_logs(&dir)
        );
        // Typed: the killed process, and that it died (not stalled, not exited).
        assert!(
            matches!(
                status.fault_cause,
                Some(FaultCause::Process { process, cause: Cause::Died, .. })
                    if process.name() == victim
            ),
            "{victim} killed, the supervisor reports: {fault} ({:?})",
            status.fault_cause
        );
        assert!(
            status.reference_stop && status.reference == 0.0,
            "{status:?}"
        );
        // Re-arming is refused while the process is dead.
        let r = stack.command(Cmd::Arm).expect("arm answer");
        assert!(!r.ok, "{victim}: re-armed with a dead process");
    }
    std::thread::sleep(settle);
    let recordings = stack.recordings();
    let _ = stack.stop(Duration::from_secs(if uml { 10 } else { 5 }));
    // The stimulator: no pulse after the reaction time, output off at the end.
    if victim != "sim-muscle" {
        let ticks = stimulator_ticks(&dir.join("stimulator.csv"));
        // Stimulation was under way: rt-core decided pulses and the stimulator applied
        // some (how many of the decisions arrive in time is the host's: at a noisy hour
        // the driver refused 6 of 14 as late, rightly).
        let applied = ticks.iter().filter(|t| t.0 < killed_ns && t.2).count();
        let decided = recordings.last().map_or(0, |run| {
            stack_support::raw_ticks(run)
                .iter()
                .filter(|t| t.t_ns < killed_ns && t.pulse)
                .count()
        });
        assert!(
            applied >= 1 && decided > 5,
            "{victim}: no stimulation before the kill ({decided} pulses decided, {applied} applied)"
        );
        let limit = killed_ns + settle.as_nanos() as u64 / 2;
        let late: Vec<u64> = ticks
            .iter()
            .filter(|t| t.0 > limit && t.2)
            .map(|t| (t.0 - killed_ns) / 1_000_000)
            .collect();
        assert!(
            late.is_empty(),
            "{victim}: pulses at {late:?} ms after the kill"
        );
        // The last state before the stack was stopped by the test.
        let last = ticks
            .iter()
            .rfind(|t| t.0 < killed_ns + settle.as_nanos() as u64)
            .expect("stimulator ticks after the kill");
        assert!(
            ["stopped", "fault", "pre_operational"].contains(&last.1.as_str()),
            "{victim}: the stimulator is still {} after the kill",
            last.1
        );
        // Reaction time: the kill to the stimulator's first tick out of operation.
        let stopped = ticks
            .iter()
            .find(|t| t.0 > killed_ns && !["stimulating", "armed"].contains(&t.1.as_str()))
            .map(|t| (t.0 - killed_ns) as f64 / 1e6);
        eprintln!(
            "kill {victim}: stimulator out of operation {} after SIGKILL{}",
            stopped.map_or("never".to_owned(), |ms| format!("{ms:.1} ms")),
            if uml {
                " (UML guest: functional only)"
            } else {
                ""
            }
        );
    }
    // The recording up to that moment reads back as a data set, each of its samples the
    // tick it says it is. How many samples it holds is the host's to decide (a tick with
    // no force sample in time ends a record: on this VM at a noisy hour rt-core missed a
    // third of its periods and the data set held 844 samples of 1.7 s); the in-process
    // tests above count them exactly.
    let run = recordings.last().expect("a recording run");
    let ds = DataSet::read(run).unwrap_or_else(|e| panic!("{victim}: {e}"));
    let samples = records_match_the_ticks(run, &ds).unwrap_or_else(|e| panic!("{victim}: {e}"));
    eprintln!(
        "kill {victim}: the data set holds {samples} samples in {} records",
        ds.records.len()
    );
    Ok(())
}

/// Checks that every sample of every record of the recording `run`'s data set is the tick
/// its record names (`... (tick N)`, then N + 1, ...): its decision is that tick's pulse in
/// `ticks.csv`, the raw stream (as far as it was flushed), and it was delivered only if it
/// was decided. Returns the number of samples.
fn records_match_the_ticks(run: &Path, ds: &DataSet) -> Result<usize, String> {
    let raw = stack_support::raw_ticks(run);
    let pulse_of: std::collections::HashMap<u64, bool> =
        raw.iter().map(|t| (t.seq, t.pulse)).collect();
    // A killed supervisor leaves each file at its last flush: ticks past the raw stream's
    // last row are not in it yet.
    let last_raw = raw.iter().map(|t| t.seq).max().unwrap_or(0);
    if ds.records.len() < 2 {
        return Err(format!("{} records", ds.records.len()));
    }
    let mut samples = 0;
    for r in &ds.records {
        let first: u64 = r
            .kind
            .rsplit_once("(tick ")
            .and_then(|(_, t)| t.trim_end_matches(')').parse().ok())
            .ok_or_else(|| format!("{}: kind `{}` names no tick", r.file, r.kind))?;
        let decided = r
            .decided
            .as_ref()
            .ok_or_else(|| format!("{}: no decided column", r.file))?;
        for (i, (&delivered, &pulse)) in r.pulse.iter().zip(decided).enumerate() {
            let seq = first + i as u64;
            if delivered && !pulse {
                return Err(format!(
                    "{} sample {i} (tick {seq}): delivered but not decided",
                    r.file
                ));
            }
            if seq > last_raw {
                break;
            }
            match pulse_of.get(&seq) {
                Some(&p) if p == pulse => {}
                other => {
                    return Err(format!(
                        "{} sample {i} (tick {seq}): decided {pulse}, ticks.csv {other:?}",
                        r.file
                    ));
                }
            }
        }
        samples += r.len();
    }
    Ok(samples)
}

/// [`kill_one`], repeated while a host stall voids the attempt (three attempts at most).
fn kill_one_of_three(
    bins: &Path,
    iface: Option<&str>,
    timing: ChainTiming,
    victim: &str,
    after_ms: u64,
) {
    for attempt in 1..=3 {
        match kill_one(bins, iface, timing, victim, after_ms) {
            Ok(()) => return,
            Err(trip) => {
                eprintln!("kill {victim}, attempt {attempt} void (before the kill: {trip}); again")
            }
        }
    }
    panic!("kill {victim}: three attempts in a row were ended by host stalls before the kill");
}

/// "Killing any one process mid-run leaves the stimulator stopped and the supervisor
/// reporting which process died; the recording up to that moment is readable." The four
/// processes on the host bus (the CAN frames over Unix datagrams, fes_hostbus), one
/// stack per victim and seed, at the host's real-time latencies; the moment of the kill is
/// drawn from a seeded generator (1.0-2.5 s into the profile), two seeds per victim.
#[test]
fn killing_any_one_process_stops_stimulation_and_names_it() {
    use rand::{RngExt, SeedableRng};
    let bins = stack_binaries();
    for (index, victim) in ["rt-core", "stim-driver", "sim-muscle", "supervisor"]
        .into_iter()
        .enumerate()
    {
        for seed in 1..=2u64 {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed * 104_729 + index as u64);
            let after_ms = rng.random_range(1000..2500);
            eprintln!("kill {victim}, seed {seed}: {after_ms} ms into the profile");
            kill_one_of_three(&bins, None, ChainTiming::Tolerant, victim, after_ms);
        }
    }
}

/// The same on SocketCAN (one CAN environment, one UML boot).
///
/// Ignored on hosts without CAN: in the User-Mode Linux guest the four processes share one
/// emulated CPU and stall for seconds (2026-11-22, three runs on an idle 2-core VM: the
/// virtual stimulator's catch-up read queued PULSEs as min-IPI violations, fixed since by
/// its arrival timestamps; then the supervisor's control loop answered no status within
/// 10 s; then no FORCE for 3.5 s, which the supervisor rightly reports as a silent
/// stimulator before the kill). Run it on a machine with vcan (native, real time):
/// `cargo test -p workbench --test it runtime_recording::killing -- --ignored --nocapture`.
#[test]
#[ignore = "needs a native vcan: the UML guest stalls for seconds (see the doc comment)"]
fn killing_any_one_process_on_vcan_stops_stimulation_and_names_it() {
    let bins = stack_binaries();
    fes_testkit::vcan::with_vcan(|can| {
        let timing = if can.backend == fes_testkit::vcan::Backend::Uml {
            ChainTiming::Uml
        } else {
            ChainTiming::Tolerant
        };
        for victim in ["rt-core", "stim-driver", "sim-muscle", "supervisor"] {
            kill_one_of_three(&bins, Some(&can.iface), timing, victim, 2000);
        }
    });
}
