//! The rt-core process end to end: rt-probe records every StimTick while the real binary
//! runs; the tests check the stream against the rules (gap-free seq, final tick on
//! SIGTERM, no catch-up after a stall, staleness ramp, degraded environments).
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use crate::rt_common;

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use fes_model::control::file::Controller;
use fes_model::control::pattern_generator::TickInput;
use fes_rt::msg::port;
use fes_rt::msg::{Contract, ForceSample, Reference, StimTick, TimingReport};
use fes_rt::rt::clock::monotonic_ns;
use fes_rt::rt::hlog::merge_by_tag;
use fes_rt::rt::node::create_node;
use fes_rt::rt::telemetry::{TAG_COMPUTE, TAG_INPUT, TAG_PUBLISH, TAG_WAKE};
use nix::sys::signal::Signal;
use rt_common::*;
use rt_core::rt::process_config::{PulseConfig, RtCoreConfig, SourceConfig};
use std::path::PathBuf;
use std::process::Command;

const MS: u64 = 1_000_000;

/// Publishes a fresh Reference with `force` every 10 ms until `stop`.
fn feed_references(prefix: &str, force: f64, stop: &AtomicBool) {
    let node = create_node("test-reference").unwrap();
    let publisher = port::publisher::<Reference>(&node, prefix).unwrap();
    let mut seq = 0;
    while !stop.load(Ordering::Relaxed) {
        seq += 1;
        publisher
            .send_copy(Reference::new(seq, monotonic_ns(), force))
            .unwrap();
        std::thread::sleep(Duration::from_millis(10));
    }
}

#[test]
fn ticks_are_gap_free_and_sigterm_ends_with_a_final_tick_and_flushed_histograms() {
    let dir = Scratch::new("gapfree");
    let prefix = prefix("gapfree");
    let mut config = config(&prefix, 4);
    config.telemetry.hlog = Some(dir.join("rt-core.hlog"));
    let path = write_config(&dir, &config);
    let probe = start_probe(&dir, &prefix);
    let stop = AtomicBool::new(false);
    std::thread::scope(|s| {
        s.spawn(|| feed_references(&prefix, 0.5, &stop));
        let rt = start_rt_core(&path, false);
        std::thread::sleep(Duration::from_millis(1000));
        rt.signal(Signal::SIGTERM);
        let (status, stderr) = rt.finish(Duration::from_secs(10));
        stop.store(true, Ordering::Relaxed);
        assert!(status.success(), "rt-core: {status}\n{stderr}");
        assert!(stderr.contains("final tick seq"), "{stderr}");
    });
    let (status, _) = probe.finish(Duration::from_secs(10));
    assert!(status.success(), "probe did not see the final tick");

    let ticks = read_ticks(&dir);
    let summary = read_summary(&dir);
    assert!(ticks.len() > 300, "only {} ticks", ticks.len());
    assert_eq!(
        (summary.first_seq, summary.lost, summary.invalid),
        (1, 0, 0)
    );
    for (k, r) in ticks.iter().enumerate() {
        assert_eq!(r.tick.seq, k as u64 + 1, "gap before tick {k}");
    }
    let last = ticks.last().unwrap().tick;
    assert!(last.has(StimTick::FLAG_FINAL) && !last.fires());
    assert_eq!(
        ticks
            .iter()
            .filter(|r| r.tick.has(StimTick::FLAG_FINAL))
            .count(),
        1
    );
    // The grid: consecutive deadlines one period apart (no stall in this test).
    let missed: u64 = ticks.iter().map(|r| u64::from(r.tick.missed_periods)).sum();
    for w in ticks[..ticks.len() - 1].windows(2) {
        let gap = w[1].tick.t_ns - w[0].tick.t_ns;
        assert_eq!(gap, MS * (1 + u64::from(w[1].tick.missed_periods)));
    }
    // Pulses every 4 ticks once the reference is in.
    assert!(summary.pulses > 50);

    // rt-core's final TimingReport and its interval log agree with the stream.
    let report = summary.rt_core.expect("timing report");
    assert!(summary.rt_core_final);
    assert_eq!(
        report.ticks,
        ticks.len() as u64 - 1,
        "every tick but the final one"
    );
    assert_eq!(report.misses, missed);
    assert_eq!(report.hot_path_allocations, 0);
    assert_eq!(report.flags & TimingReport::FLAG_ALLOCATIONS_UNCOUNTED, 0);
    let logged = merge_by_tag(&dir.join("rt-core.hlog")).unwrap();
    for tag in [TAG_WAKE, TAG_INPUT, TAG_COMPUTE, TAG_PUBLISH] {
        assert_eq!(logged[tag].count(), report.ticks, "hlog {tag} count");
    }
}

/// Replays the recorded references through a fresh pattern generator from the same file
/// (record == resim): the live loop must have made exactly the offline decisions, the
/// periods it skipped stepped without a pulse before the tick that reports them.
fn assert_replay_matches(controller: &Controller, ticks: &[StimTick]) {
    let mut generator = controller.pattern_generator().unwrap();
    for t in ticks.iter().filter(|t| !t.has(StimTick::FLAG_FINAL)) {
        let input = TickInput {
            reference: t.reference,
            measured_force: None,
            resting: t.has(StimTick::FLAG_RESTING),
            ..Default::default()
        };
        generator.missed(t.missed_periods, &input);
        let out = generator.tick(&input);
        assert_eq!(out.pulse, t.fires(), "pulse at seq {}", t.seq);
        assert_eq!(
            out.u_cont.to_bits(),
            t.u_cont.to_bits(),
            "u_cont at seq {}",
            t.seq
        );
        assert_eq!(
            out.model_force.to_bits(),
            t.model_force.to_bits(),
            "y at seq {}",
            t.seq
        );
        assert_eq!(out.phi.to_bits(), t.phi.to_bits(), "phi at seq {}", t.seq);
    }
}

#[test]
fn the_pattern_generator_runs_from_a_controller_file_exactly_as_offline() {
    let dir = Scratch::new("controller");
    let prefix = prefix("controller");
    let controller = write_controller(&dir.join("controller.json"), 10);
    let mut config = config(&prefix, 2);
    config.source = SourceConfig::Controller {
        path: dir.join("controller.json"),
    };
    let path = write_config(&dir, &config);
    let probe = start_probe(&dir, &prefix);
    let stop = AtomicBool::new(false);
    std::thread::scope(|s| {
        s.spawn(|| feed_references(&prefix, 0.5, &stop));
        let rt = start_rt_core(&path, false);
        std::thread::sleep(Duration::from_millis(1000));
        rt.signal(Signal::SIGTERM);
        let (status, stderr) = rt.finish(Duration::from_secs(10));
        stop.store(true, Ordering::Relaxed);
        assert!(status.success(), "{stderr}");
        assert!(
            stderr.contains("pattern generator, 10 unit(s), Model mode"),
            "{stderr}"
        );
    });
    let (status, _) = probe.finish(Duration::from_secs(10));
    assert!(status.success());
    let ticks: Vec<StimTick> = read_ticks(&dir).iter().map(|r| r.tick).collect();
    assert_eq!(read_summary(&dir).lost, 0);
    assert!(ticks.iter().filter(|t| t.fires()).count() > 10);
    assert!(ticks.iter().any(|t| t.model_force > 0.1));
    assert_replay_matches(&controller, &ticks);
}

/// Publishes a ForceSample (normalised `force`) every ms for `duration`; returns the
/// samples' timestamps, so a test can judge each tick by what was actually sent.
fn feed_forces(prefix: &str, force: f64, duration: Duration) -> Vec<u64> {
    let node = create_node("test-force").unwrap();
    let publisher = port::publisher::<ForceSample>(&node, prefix).unwrap();
    let end = std::time::Instant::now() + duration;
    let mut seq = 0;
    let mut sent = Vec::new();
    while std::time::Instant::now() < end {
        seq += 1;
        let sample = ForceSample {
            seq,
            t_ns: monotonic_ns(),
            stim_seq: 0,
            force_n: force * 20.0,
            force,
        };
        publisher.send_copy(sample).unwrap();
        sent.push(sample.t_ns);
        std::thread::sleep(Duration::from_millis(1));
    }
    sent
}

#[test]
fn in_feedback_mode_fresh_force_samples_reach_the_generator_and_stale_ones_do_not() {
    let dir = Scratch::new("feedback");
    let prefix = prefix("feedback");
    write_measured_controller(&dir.join("controller.json"), 4);
    let mut config = config(&prefix, 2);
    config.source = SourceConfig::Controller {
        path: dir.join("controller.json"),
    };
    config.feedback.enabled = true;
    config.feedback.max_age_ms = 5;
    let path = write_config(&dir, &config);
    let probe = start_probe(&dir, &prefix);
    let stop = AtomicBool::new(false);
    let (forces_from, forces_to, sent) = std::thread::scope(|s| {
        s.spawn(|| feed_references(&prefix, 0.4, &stop));
        let rt = start_rt_core(&path, false);
        std::thread::sleep(Duration::from_millis(300));
        let from = monotonic_ns();
        let sent = feed_forces(&prefix, 0.3, Duration::from_millis(400));
        let to = monotonic_ns();
        std::thread::sleep(Duration::from_millis(300));
        rt.signal(Signal::SIGINT);
        let (status, stderr) = rt.finish(Duration::from_secs(10));
        stop.store(true, Ordering::Relaxed);
        assert!(status.success(), "SIGINT stops cleanly too: {stderr}");
        assert!(stderr.contains("MeasuredForce mode"), "{stderr}");
        (from, to, sent)
    });
    let _ = probe.finish(Duration::from_secs(10));
    let ticks: Vec<StimTick> = read_ticks(&dir)
        .iter()
        .map(|r| r.tick)
        .filter(|t| !t.has(StimTick::FLAG_FINAL))
        .collect();
    let fed = |t: &StimTick| t.has(StimTick::FLAG_FEEDBACK);
    // The newest sample sent before `at` (timestamps are taken just before sending).
    let newest_before = |at: u64| sent.iter().rev().find(|&&t_ns| t_ns <= at).copied();
    // No sample before the feed started, none older than 5 ms used after it stopped.
    assert!(
        ticks
            .iter()
            .filter(|t| t.t_wake_ns < forces_from)
            .all(|t| !fed(t))
    );
    assert!(
        ticks
            .iter()
            .filter(|t| t.t_wake_ns > forces_to + 6 * MS)
            .all(|t| !fed(t))
    );
    // Safety, tick by tick: a tick that used feedback had a sample no older than 5 ms at
    // its wake-up (the newest sample sent before it published is at least as new as the
    // one it used).
    for t in ticks.iter().filter(|t| fed(t)) {
        let newest = newest_before(t.t_publish_ns).expect("fed before any sample");
        assert!(
            t.t_wake_ns.saturating_sub(newest) <= 5 * MS,
            "tick {} used a sample {} µs old",
            t.seq,
            (t.t_wake_ns - newest) / 1000
        );
    }
    // Liveness: where the feeder (a non-real-time thread, which a loaded machine can
    // delay by several ms) had sent a sample between 0.5 and 4 ms before the tick woke,
    // the tick used it. The fraction is judged only over those ticks.
    let during: Vec<&StimTick> = ticks
        .iter()
        .filter(|t| t.t_wake_ns > forces_from + 20 * MS && t.t_wake_ns < forces_to)
        .collect();
    assert!(during.len() > 200);
    let available: Vec<&&StimTick> = during
        .iter()
        .filter(|t| newest_before(t.t_wake_ns - MS / 2).is_some_and(|n| t.t_wake_ns - n <= 4 * MS))
        .collect();
    assert!(
        available.len() * 2 >= during.len(),
        "the feeder sent too few samples to judge: {} of {} ticks",
        available.len(),
        during.len()
    );
    let used = available.iter().filter(|t| fed(t)).count();
    assert!(
        used * 100 >= available.len() * 98,
        "{used} of {} ticks with a fresh sample used it",
        available.len()
    );
    assert!(ticks.iter().all(|t| t.validate().is_ok()));
}

#[test]
fn a_controller_that_does_not_fit_the_loop_is_refused_at_start() {
    let dir = Scratch::new("ctrlmismatch");
    write_controller(&dir.join("controller.json"), 3);
    let mut config = config(&prefix("ctrlmismatch"), 2);
    config.source = SourceConfig::Controller {
        path: dir.join("controller.json"),
    };
    config.period_us = 2000;
    let (status, stderr) =
        start_rt_core(&write_config(&dir, &config), false).finish(Duration::from_secs(10));
    assert_eq!(status.code(), Some(1));
    assert!(
        stderr.contains("period_us must equal the model's Ts"),
        "{stderr}"
    );

    config.period_us = 1000;
    config.feedback.enabled = true;
    let (status, stderr) =
        start_rt_core(&write_config(&dir, &config), false).finish(Duration::from_secs(10));
    assert_eq!(status.code(), Some(1));
    assert!(stderr.contains("[feedback] enabled = true"), "{stderr}");

    std::fs::write(dir.join("controller.json"), "{\"schema\": \"fes-lcn/1\"}").unwrap();
    config.feedback.enabled = false;
    let (status, stderr) =
        start_rt_core(&write_config(&dir, &config), false).finish(Duration::from_secs(10));
    assert_eq!(status.code(), Some(1));
    assert!(stderr.contains("controller.json"), "{stderr}");
}

#[test]
fn a_100_ms_stall_skips_periods_keeps_the_phase_and_emits_no_burst() {
    let dir = Scratch::new("stall");
    let prefix = prefix("stall");
    let controller = write_controller(&dir.join("controller.json"), 10);
    let mut config = config(&prefix, 2);
    config.source = SourceConfig::Controller {
        path: dir.join("controller.json"),
    };
    config.reference.stale_after_ms = 2000;
    let path = write_config(&dir, &config);
    let probe = start_probe(&dir, &prefix);
    let stop = AtomicBool::new(false);
    std::thread::scope(|s| {
        s.spawn(|| feed_references(&prefix, 0.7, &stop));
        let rt = start_rt_core(&path, false);
        std::thread::sleep(Duration::from_millis(400));
        rt.signal(Signal::SIGSTOP);
        std::thread::sleep(Duration::from_millis(100));
        rt.signal(Signal::SIGCONT);
        std::thread::sleep(Duration::from_millis(400));
        rt.signal(Signal::SIGTERM);
        let (status, stderr) = rt.finish(Duration::from_secs(10));
        stop.store(true, Ordering::Relaxed);
        assert!(status.success(), "{stderr}");
    });
    let (status, _) = probe.finish(Duration::from_secs(10));
    assert!(status.success());
    let ticks: Vec<StimTick> = read_ticks(&dir).iter().map(|r| r.tick).collect();
    let summary = read_summary(&dir);
    assert_eq!((summary.first_seq, summary.lost), (1, 0));

    // Exactly one wake-up reports the stall, with ~100 skipped periods.
    let stalled: Vec<&StimTick> = ticks.iter().filter(|t| t.missed_periods >= 50).collect();
    assert_eq!(stalled.len(), 1, "one wake-up after the stall");
    let s = stalled[0];
    assert!(
        (90..=300).contains(&s.missed_periods),
        "{}",
        s.missed_periods
    );
    assert!(s.has(StimTick::FLAG_OVERRUN));
    let report = summary.rt_core.unwrap();
    assert!(report.misses >= u64::from(s.missed_periods));
    assert!(report.overruns >= 1);

    // Phase kept: every deadline on the original 1 ms grid.
    let periodic: Vec<&StimTick> = ticks
        .iter()
        .filter(|t| !t.has(StimTick::FLAG_FINAL))
        .collect();
    let t0 = periodic[0].t_ns;
    assert!(periodic.iter().all(|t| (t.t_ns - t0).is_multiple_of(MS)));

    // No burst: at most one pulse per tick, and pulses at least 2 ticks and 2 ms apart,
    // across the stall too.
    let pulses: Vec<&StimTick> = periodic.iter().copied().filter(|t| t.fires()).collect();
    assert!(pulses.len() > 10);
    assert!(ticks.iter().all(|t| t.pulse <= 1));
    for w in pulses.windows(2) {
        assert!(
            w[1].seq - w[0].seq >= 2,
            "pulses at seq {} and {}",
            w[0].seq,
            w[1].seq
        );
        assert!(w[1].t_ns - w[0].t_ns >= 2 * MS);
    }
    // The generator was called once per wake-up, stall or not: the live decisions are the
    // offline ones.
    assert_replay_matches(&controller, &ticks);
}

#[test]
fn a_stale_reference_ramps_the_target_to_zero_at_the_configured_rate() {
    let dir = Scratch::new("stale");
    let prefix = prefix("stale");
    let mut config = config(&prefix, 3);
    // Each phase (fresh 300 ms, ramp 200 ms, rest) far longer than the host's stalls.
    config.reference.stale_after_ms = 300;
    config.reference.stale_ramp_per_s = 4.0;
    let path = write_config(&dir, &config);
    let probe = start_probe(&dir, &prefix);
    // One reference, then silence.
    let node = create_node("test-stale").unwrap();
    let publisher = port::publisher::<Reference>(&node, &prefix).unwrap();
    let ticks_seen = port::subscriber::<StimTick>(&node, &prefix).unwrap();
    let rt = start_rt_core(&path, false);
    // The reference goes out once, so only after rt-core ticks: its ports are connected
    // before its first tick. A fixed 150 ms wait lost the one sample on a loaded host,
    // where rt-core ticked first 250 ms after its start and no tick ever had a reference.
    let started = std::time::Instant::now();
    while ticks_seen.receive().unwrap().is_none() {
        assert!(
            started.elapsed() < Duration::from_secs(10),
            "rt-core never ticked"
        );
        std::thread::sleep(Duration::from_millis(1));
    }
    std::thread::sleep(Duration::from_millis(50));
    let issued = monotonic_ns();
    publisher.send_copy(Reference::new(1, issued, 0.8)).unwrap();
    std::thread::sleep(Duration::from_millis(900));
    rt.signal(Signal::SIGTERM);
    let (status, stderr) = rt.finish(Duration::from_secs(10));
    assert!(status.success(), "{stderr}");
    let _ = probe.finish(Duration::from_secs(10));

    let ticks: Vec<StimTick> = read_ticks(&dir)
        .iter()
        .map(|r| r.tick)
        .filter(|t| !t.has(StimTick::FLAG_FINAL))
        .collect();
    let before: Vec<&StimTick> = ticks.iter().filter(|t| t.ref_seq == 0).collect();
    assert!(!before.is_empty());
    assert!(
        before
            .iter()
            .all(|t| t.has(StimTick::FLAG_NO_REFERENCE) && t.reference == 0.0 && !t.fires())
    );
    let with_ref: Vec<&StimTick> = ticks.iter().filter(|t| t.ref_seq == 1).collect();
    let fresh: Vec<&StimTick> = with_ref
        .iter()
        .copied()
        .filter(|t| !t.has(StimTick::FLAG_STALE_REFERENCE))
        .collect();
    let stale: Vec<&StimTick> = with_ref
        .iter()
        .copied()
        .filter(|t| t.has(StimTick::FLAG_STALE_REFERENCE))
        .collect();
    // Every phase is covered, however many ticks the host let through (at a noisy hour
    // rt-core missed 40 % of its periods): the fresh reference, the ramp, the rest.
    assert!(!fresh.is_empty(), "no tick with the fresh reference");
    assert!(
        stale.iter().any(|t| t.reference > 0.0 && t.reference < 0.8),
        "no tick on the ramp"
    );
    // Fresh: the reference as sent, for its first 300 ms of age.
    for t in &fresh {
        assert_eq!(t.reference, 0.8);
        assert!(t.t_wake_ns - issued <= 300 * MS);
    }
    for t in &stale {
        assert!(t.t_wake_ns - issued > 300 * MS);
    }
    // Stale: closed form r(t) = max(0, 0.8 - 4.0 * (t - t_last_fresh)), t = wake times.
    let t_last_fresh = fresh.last().unwrap().t_wake_ns;
    for t in &stale {
        let expect = (0.8 - 4.0 * (t.t_wake_ns - t_last_fresh) as f64 * 1e-9).max(0.0);
        assert!(
            (t.reference - expect).abs() < 1e-9,
            "{} vs {expect}",
            t.reference
        );
    }
    assert_eq!(stale.last().unwrap().reference, 0.0);
    assert!(!stale.last().unwrap().fires());
}

#[test]
fn a_missing_core_is_refused_in_one_line_or_run_best_effort_as_configured() {
    let dir = Scratch::new("nocore");
    let prefix = prefix("nocore");
    let mut config = config(&prefix, 4);
    config.rt.core = Some(512);
    config.rt.on_missing_rights = fes_rt::rt::MissingRightsPolicy::Refuse;
    let path = write_config(&dir, &config);
    let (status, stderr) = start_rt_core(&path, false).finish(Duration::from_secs(10));
    assert_eq!(status.code(), Some(1), "{stderr}");
    let refusal: Vec<&str> = stderr.lines().filter(|l| l.contains("refused")).collect();
    assert_eq!(refusal.len(), 1, "{stderr}");
    assert!(
        refusal[0].contains("core 512 does not exist"),
        "{}",
        refusal[0]
    );

    config.rt.on_missing_rights = fes_rt::rt::MissingRightsPolicy::BestEffort;
    let path = write_config(&dir, &config);
    let probe = start_probe(&dir, &prefix);
    let rt = start_rt_core(&path, false);
    std::thread::sleep(Duration::from_millis(800));
    rt.signal(Signal::SIGTERM);
    let (status, stderr) = rt.finish(Duration::from_secs(10));
    assert!(status.success(), "{stderr}");
    assert!(
        stderr.contains("DEGRADED (best-effort)") && stderr.contains("core 512"),
        "{stderr}"
    );
    let _ = probe.finish(Duration::from_secs(10));
    let ticks = read_ticks(&dir);
    assert!(ticks.len() > 100);
    assert!(ticks.iter().all(|r| r.tick.has(StimTick::FLAG_DEGRADED)));
    let report = read_summary(&dir).rt_core.unwrap();
    assert_ne!(report.flags & TimingReport::FLAG_DEGRADED, 0);
}

#[test]
fn without_sched_fifo_rights_it_refuses_or_runs_best_effort_as_configured() {
    let dir = Scratch::new("norights");
    let prefix = prefix("norights");
    let mut config = config(&prefix, 4);
    config.rt.on_missing_rights = fes_rt::rt::MissingRightsPolicy::Refuse;
    let path = write_config(&dir, &config);
    let (status, stderr) = start_rt_core(&path, true).finish(Duration::from_secs(10));
    assert_eq!(status.code(), Some(1), "{stderr}");
    let refusal: Vec<&str> = stderr.lines().filter(|l| l.contains("refused")).collect();
    assert_eq!(refusal.len(), 1, "{stderr}");
    assert!(
        refusal[0].contains("no SCHED_FIFO 60 (EPERM"),
        "{}",
        refusal[0]
    );

    config.rt.on_missing_rights = fes_rt::rt::MissingRightsPolicy::BestEffort;
    let path = write_config(&dir, &config);
    let probe = start_probe(&dir, &prefix);
    let rt = start_rt_core(&path, true);
    std::thread::sleep(Duration::from_millis(800));
    rt.signal(Signal::SIGTERM);
    let (status, stderr) = rt.finish(Duration::from_secs(10));
    assert!(status.success(), "{stderr}");
    assert!(
        stderr.contains("no SCHED_FIFO 60") && stderr.contains("got: SCHED_OTHER"),
        "{stderr}"
    );
    let _ = probe.finish(Duration::from_secs(10));
    let ticks = read_ticks(&dir);
    assert!(ticks.len() > 100);
    assert!(ticks.iter().all(|r| r.tick.has(StimTick::FLAG_DEGRADED)));
}

#[test]
fn bad_configuration_is_reported_clearly_and_exits_1() {
    let dir = Scratch::new("badcfg");
    let cases = [
        (
            "schema = \"fes-rt-core/2\"\n[source]\nkind = \"test-pattern\"\nipi_ticks = 4\n",
            "schema",
        ),
        ("schema = \"fes-rt-core/1\"\n", "source"),
        (
            "schema = \"fes-rt-core/1\"\nperiod_us = 50\n[source]\nkind = \"test-pattern\"\nipi_ticks = 4\n",
            "period_us = 50",
        ),
        (
            "schema = \"fes-rt-core/1\"\n[source]\nkind = \"test-pattern\"\nipi_ticks = 1\n",
            "ipi_ticks",
        ),
        (
            "schema = \"fes-rt-core/1\"\n[source]\nkind = \"test-pattern\"\nipi_ticks = 4\n[rt]\npriority = 0\n",
            "rt.priority = 0",
        ),
        (
            "schema = \"fes-rt-core/1\"\n[source]\nkind = \"test-pattern\"\nipi_ticks = 4\n[pulse]\namplitude_ua = 900000\n",
            "pulse.amplitude_ua",
        ),
        (
            "schema = \"fes-rt-core/1\"\n[source]\nkind = \"test-pattern\"\nipi_ticks = 4\n[ipc]\nprefix = \"a b\"\n",
            "prefix",
        ),
        (
            "schema = \"fes-rt-core/1\"\n[source]\nkind = \"test-pattern\"\nipi_ticks = 4\ntypo = 1\n",
            "typo",
        ),
        // The bad-input sweep: NaN, infinity, negative, huge, truncated.
        (
            "schema = \"fes-rt-core/1\"\n[source]\nkind = \"test-pattern\"\nipi_ticks = 4\n[reference]\nstale_ramp_per_s = nan\n",
            "reference.stale_ramp_per_s",
        ),
        (
            "schema = \"fes-rt-core/1\"\n[source]\nkind = \"test-pattern\"\nipi_ticks = 4\n[reference]\nstale_ramp_per_s = inf\n",
            "reference.stale_ramp_per_s",
        ),
        (
            "schema = \"fes-rt-core/1\"\nperiod_us = -1000\n[source]\nkind = \"test-pattern\"\nipi_ticks = 4\n",
            "period_us",
        ),
        (
            "schema = \"fes-rt-core/1\"\n[source]\nkind = \"test-pattern\"\nipi_ticks = 4\n[rt]\nprefault_stack_bytes = 99999999999\n",
            "prefault_stack_bytes",
        ),
        (
            "schema = \"fes-rt-core/1\"\n[source]\nkind = \"test-pat",
            "TOML",
        ),
    ];
    let mut cases: Vec<(Vec<u8>, &str)> = cases
        .iter()
        .map(|(t, n)| (t.as_bytes().to_vec(), *n))
        .collect();
    cases.push((
        b"schema = \"fes-rt-core/1\"\n# \xff\xfe\n".to_vec(),
        "UTF-8",
    ));
    for (text, needle) in cases {
        let path = dir.join("bad.toml");
        std::fs::write(&path, &text).unwrap();
        let text = String::from_utf8_lossy(&text);
        let (status, stderr) = start_rt_core(&path, false).finish(Duration::from_secs(10));
        assert_eq!(status.code(), Some(1), "{text}\n{stderr}");
        assert!(stderr.contains(needle), "expected {needle:?} in:\n{stderr}");
        assert!(!stderr.contains("panicked"), "{text}\n{stderr}");
    }
    let (status, stderr) =
        start_rt_core(&dir.join("missing.toml"), false).finish(Duration::from_secs(10));
    assert_eq!(status.code(), Some(1));
    assert!(stderr.contains("missing.toml"), "{stderr}");
}

/// A run of rt-core with slow consumers on its output services: subscribers that never
/// read StimTick or TimingReport (in this process) and a whole subscriber process stopped
/// with SIGSTOP. It runs until a live subscriber here has received more ticks than the
/// stopped one's buffer holds (so the publisher has met a full buffer), then gets SIGTERM.
pub struct SlowConsumerRun {
    /// What the live probe (rt-probe) recorded.
    pub summary: fes_rt::rt::probe::ProbeSummary,
    /// Its ticks.
    pub ticks: Vec<fes_rt::rt::probe::TickRecord>,
    /// The host's noise over the run, when asked for.
    pub noise: Option<fes_testkit::noise::HostNoise>,
}

/// Runs [`SlowConsumerRun`] (`tag` names its scratch and services); `noise`: measure the
/// host's noise beside it at rt-core's priority.
pub fn slow_consumer_run(tag: &str, noise: bool) -> SlowConsumerRun {
    use std::sync::atomic::AtomicU64;
    let dir = Scratch::new(tag);
    let stopped_dir = Scratch::new(&format!("{tag}-stopped"));
    let prefix = prefix(tag);
    let mut config = config(&prefix, 4);
    // Measured: rt-core and the noise probe on the same (last) CPU, which each see the
    // same stalls of the host (a VM's virtual CPUs are stalled one by one).
    let core = std::thread::available_parallelism().map_or(0, |n| n.get() - 1);
    if noise {
        config.rt.core = Some(core);
    }
    let priority = config.rt.priority;
    let path = write_config(&dir, &config);
    let node = create_node("test-slow-consumer").unwrap();
    let _never_read_ticks = port::subscriber::<StimTick>(&node, &prefix).unwrap();
    let _never_read_reports = port::subscriber::<TimingReport>(&node, &prefix).unwrap();
    let stopped = start_probe(&stopped_dir, &prefix);
    stopped.signal(Signal::SIGSTOP);
    let probe = start_probe(&dir, &prefix);
    // Past the stopped subscriber's full buffer, with room to spare.
    let enough = StimTick::QOS.subscriber_buffer as u64 + 200;
    let stop = AtomicBool::new(false);
    let received = AtomicU64::new(0);
    let mut noise_probe = None;
    let noise = std::thread::scope(|s| {
        s.spawn(|| feed_references(&prefix, 0.5, &stop));
        s.spawn(|| {
            let node = create_node("test-slow-consumer-count").unwrap();
            let live = port::subscriber::<StimTick>(&node, &prefix).unwrap();
            while !stop.load(Ordering::Relaxed) {
                while let Ok(Some(_)) = live.receive() {
                    received.fetch_add(1, Ordering::Relaxed);
                }
                std::thread::sleep(Duration::from_millis(5));
            }
        });
        let rt = start_rt_core(&path, false);
        noise_probe = noise.then(|| fes_testkit::noise::NoiseProbe::start_on(priority, Some(core)));
        let deadline = std::time::Instant::now() + Duration::from_secs(30);
        while received.load(Ordering::Relaxed) < enough {
            assert!(
                std::time::Instant::now() < deadline,
                "rt-core published only {} ticks in 30 s: blocked by a full subscriber?",
                received.load(Ordering::Relaxed)
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        let noise = noise_probe
            .take()
            .map(fes_testkit::noise::NoiseProbe::finish);
        rt.signal(Signal::SIGTERM);
        let (status, stderr) = rt.finish(Duration::from_secs(10));
        stop.store(true, Ordering::Relaxed);
        assert!(status.success(), "rt-core: {status}\n{stderr}");
        noise
    });
    let (status, _) = probe.finish(Duration::from_secs(10));
    assert!(
        status.success(),
        "the live probe did not see the final tick"
    );
    stopped.signal(Signal::SIGCONT);
    stopped.signal(Signal::SIGKILL);
    SlowConsumerRun {
        summary: read_summary(&dir),
        ticks: read_ticks(&dir),
        noise,
    }
}

/// Fault injection: slow consumers on rt-core's output services ([`slow_consumer_run`])
/// must not block the publisher: with iceoryx2's safe overflow the loop runs on past the
/// stopped subscriber's full buffer, a live subscriber still receives every tick, the loop
/// allocates nothing, and SIGTERM ends it cleanly. How well it kept its period meanwhile
/// is a timing check (`timing::`).
#[test]
fn slow_and_stopped_consumers_never_block_the_loop() {
    let run = slow_consumer_run("slowconsumer", false);
    let buffer = StimTick::QOS.subscriber_buffer;
    assert!(
        run.ticks.len() > buffer + 100,
        "only {} ticks: the stopped subscriber's buffer ({buffer}) was not passed",
        run.ticks.len()
    );
    assert_eq!(
        (run.summary.first_seq, run.summary.lost, run.summary.invalid),
        (1, 0, 0)
    );
    let report = run.summary.rt_core.expect("timing report");
    assert_eq!(report.hot_path_allocations, 0);
}

/// Fault injection: iceoryx2 resources left stale by a SIGKILLed rt-core. A new rt-core
/// with the same services starts (the dead node's StimTick publisher slot is reclaimed)
/// and a subscriber receives its ticks from seq 1.
#[test]
fn a_restart_after_sigkill_reclaims_the_stale_services() {
    let dir = Scratch::new("stalerestart");
    let prefix = prefix("stalerestart");
    let path = write_config(&dir, &config(&prefix, 4));
    let stop = AtomicBool::new(false);
    std::thread::scope(|s| {
        s.spawn(|| feed_references(&prefix, 0.5, &stop));
        let first = start_rt_core(&path, false);
        std::thread::sleep(Duration::from_millis(700));
        first.signal(Signal::SIGKILL);
        let (status, _) = first.finish(Duration::from_secs(10));
        assert!(!status.success(), "killed");
        let probe = start_probe(&dir, &prefix);
        let second = start_rt_core(&path, false);
        std::thread::sleep(Duration::from_millis(1000));
        second.signal(Signal::SIGTERM);
        let (status, stderr) = second.finish(Duration::from_secs(10));
        stop.store(true, Ordering::Relaxed);
        assert!(
            status.success(),
            "the restarted rt-core: {status}\n{stderr}"
        );
        let (status, _) = probe.finish(Duration::from_secs(10));
        assert!(status.success(), "the probe did not see the final tick");
    });
    let summary = read_summary(&dir);
    assert_eq!(
        (summary.first_seq, summary.lost, summary.invalid),
        (1, 0, 0)
    );
    assert!(read_ticks(&dir).len() > 300);
}

/// A 5x amplitude slip in rt-core's `[pulse]` (100 mA for the prescription's 20 mA) is
/// refused at start, before the loop exists, so no StimTick (let alone a pulse) is ever
/// published; so are a longer phase and a charge above the
/// prescription's, and an unreadable prescription. The prescribed pulse starts.
#[test]
fn a_5x_amplitude_slip_is_refused_before_any_tick() {
    let dir = Scratch::new("presc");
    std::fs::write(
        dir.join("prescription.toml"),
        "format = \"fes-prescription/1\"\nmax_amplitude_ua = 20000\nmax_phase_width_us = 200\n\
         max_charge_per_phase_nc = 3000\nmin_ipi_us = 2000\nmax_pulses_per_s = 100\n",
    )
    .unwrap();
    let mut config = config(&prefix("presc"), 2);
    config.prescription = Some(PathBuf::from("prescription.toml"));
    config.pulse.amplitude_ua = 15_000;
    config.pulse.width_us = 200;
    let refused = |config: &RtCoreConfig, needle: &str| {
        let (status, stderr) =
            start_rt_core(&write_config(&dir, config), false).finish(Duration::from_secs(10));
        assert_eq!(status.code(), Some(1), "{stderr}");
        assert!(stderr.contains(needle), "{needle}: {stderr}");
        assert!(
            !stderr.contains("real-time") && !stderr.contains("running"),
            "refused before the loop started: {stderr}"
        );
    };
    let slip = RtCoreConfig {
        pulse: PulseConfig {
            amplitude_ua: 100_000,
            ..config.pulse
        },
        ..config.clone()
    };
    refused(
        &slip,
        "amplitude = 100000 uA exceeds the prescription's 20000 uA",
    );
    let wide = RtCoreConfig {
        pulse: PulseConfig {
            width_us: 201,
            ..config.pulse
        },
        ..config.clone()
    };
    refused(&wide, "phase width = 201 us");
    // 20 mA x 200 us = 4 uC: each within its ceiling, the charge above 3 uC.
    let charge = RtCoreConfig {
        pulse: PulseConfig {
            amplitude_ua: 20_000,
            ..config.pulse
        },
        ..config.clone()
    };
    refused(&charge, "charge per phase = 4000 nC");
    let missing = RtCoreConfig {
        prescription: Some(PathBuf::from("missing.toml")),
        ..config.clone()
    };
    refused(&missing, "missing.toml");
    // The prescribed pulse passes the same check.
    let out = Command::new(RT_CORE)
        .arg("--config")
        .arg(write_config(&dir, &config))
        .arg("--check")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// rt-core refuses to start on an iceoryx2 root that others may write: in a private mount
/// namespace `/tmp/iceoryx2` is a tmpfs of mode 0777, and rt-core exits non-zero naming
/// the root and the mode, before it creates any service. Without the check it runs (and
/// iceoryx2 would keep its bookkeeping there). Root only (a mount namespace); CI runs as
/// root.
#[test]
fn rt_core_refuses_an_iceoryx2_root_others_may_write() {
    if !nix::unistd::geteuid().is_root() {
        eprintln!("SKIPPED: needs root (a private mount namespace)");
        return;
    }
    let dir = Scratch::new("ipcroot");
    let path = write_config(&dir, &config(&prefix("ipcroot"), 4));
    let _ = std::fs::create_dir_all("/tmp/iceoryx2");
    let out = Command::new("unshare")
        .args(["--mount", "--propagation", "private", "sh", "-c"])
        .arg(
            "mount -t tmpfs -o mode=0777 fes-ipcroot-test /tmp/iceoryx2 && \
             exec timeout 10 \"$0\" --config \"$1\"",
        )
        .arg(RT_CORE)
        .arg(&path)
        .output()
        .expect("run unshare");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "rt-core ran: {stderr}");
    assert!(
        stderr.contains("iceoryx2's root /tmp/iceoryx2") && stderr.contains("mode 777"),
        "{}: {stderr}",
        out.status
    );
}
