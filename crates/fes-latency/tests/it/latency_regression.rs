//! The latency regression suite (`latency-regression`, run by `scripts/latency-regression`):
//!
//! - the gate applies the tolerance stated in the baseline exactly: values at a limit
//!   pass, values just above fail and are named; a baseline that cannot judge a run, or
//!   that states a nonsensical tolerance, is an error (exit 1 with `latency-regression: error:`), not a pass;
//! - the CI short run: the real rt-core loop against cyclictest, with and without load,
//!   5 s each (debug binaries: `cargo test` has built them; the ratios compare the
//!   loop's wake-ups with cyclictest's and barely depend on the optimisation level),
//!   passes against the stored baseline `crates/fes-latency/latency-baseline.json` and
//!   writes the report, plot, summary and interval logs;
//! - the same suite with the test-only slowdown (`FES_TEST_TICK_BUSY_US=1100`: each tick
//!   busy-waits longer than the 1 ms period) exits 1 and names the exceeded compute budget
//!   and the lateness (the p99 ratio or the late-wake-up rate).
//!
//! Needs root (SCHED_FIFO), cyclictest and stress-ng, as the rt-core tests do.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use crate::support::{scratch, workspace_root};

const BIN: &str = env!("CARGO_BIN_EXE_latency-regression");

/// Runs the suite: its exit code and its report (stdout, then the lines of stderr that
/// are not log records). The processes' log records (thousands of lines on a long run)
/// go to a file in `log_dir` (the test's scratch directory, kept when the test fails)
/// named in the text, so that a failed assertion shows its reason and the report, not a
/// screenful of logs.
fn run(log_dir: &Path, args: &[&str], env: &[(&str, &str)]) -> (Option<i32>, String) {
    static RUN: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
    let mut cmd = Command::new(BIN);
    cmd.args(args).env_remove("FES_TEST_TICK_BUSY_US");
    for (k, v) in env {
        cmd.env(k, v);
    }
    let Output {
        status,
        stdout,
        stderr,
    } = cmd.output().expect("run latency-regression");
    let mut text = String::from_utf8_lossy(&stdout).into_owned();
    let stderr = String::from_utf8_lossy(&stderr);
    // A tracing record starts with its RFC 3339 time (after an ANSI colour code, if any).
    let is_log = |l: &str| {
        let l = l.strip_prefix("\x1b[2m").unwrap_or(l).as_bytes();
        l.len() > 20 && l[..4].iter().all(u8::is_ascii_digit) && l[4] == b'-' && l[10] == b'T'
    };
    let logs: Vec<&str> = stderr.lines().filter(|l| is_log(l)).collect();
    for line in stderr.lines().filter(|l| !is_log(l)) {
        text.push_str(line);
        text.push('\n');
    }
    let n = RUN.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let log_path = log_dir.join(format!("latency-regression-{n}.log"));
    std::fs::write(&log_path, logs.join("\n")).expect("write the run's log");
    text.push_str(&format!(
        "({} log records in {})\n",
        logs.len(),
        log_path.display()
    ));
    println!("{text}");
    (status.code(), text)
}

/// A baseline with binary-exact numbers: limits are exact by hand and in f64.
fn write_baseline(dir: &Path, tolerance_p99: f64, with_load: bool, min_tail: u64) -> PathBuf {
    let load = if with_load {
        r#", "load": {"ratio_p99": 1.5, "ratio_p999": 1.25}"#
    } else {
        ""
    };
    let text = format!(
        r#"{{"schema": "fes-latency-baseline/1", "measured": "test",
            "tolerance": {{"ratio_p99_factor": {tolerance_p99}, "ratio_p999_factor": 2.0,
                          "overrun_rate_factor": 3.0, "overrun_rate_floor": 0.002,
                          "compute_p99_us_max": 50.0, "hot_path_allocations_max": 0,
                          "min_tail_samples": {min_tail}}},
            "conditions": {{"no_load": {{"ratio_p99": 1.25, "ratio_p999": 0.75}}{load}}}}}"#
    );
    let path = dir.join(format!(
        "baseline-{tolerance_p99}-{with_load}-{min_tail}.json"
    ));
    std::fs::write(&path, text).expect("write baseline");
    path
}

/// One condition's figures as `latency-regression` writes them.
#[derive(Clone, Copy)]
struct Figures {
    ratio_p99: f64,
    ratio_p999: f64,
    overruns: u64,
    compute_p99: f64,
    allocations: u64,
    /// The driver's hot-path allocations; `None`: no driver measured.
    driver_allocations: Option<u64>,
}

const GOOD: Figures = Figures {
    ratio_p99: 1.0,
    ratio_p999: 1.0,
    overruns: 0,
    compute_p99: 2.0,
    allocations: 0,
    driver_allocations: None,
};

fn condition_json(f: Figures) -> String {
    let p = |x: f64| format!(r#"{{"p50": {x}, "p99": {x}, "p999": {x}, "max": {x}}}"#);
    format!(
        r#"{{"ticks": 1024, "misses": {o}, "overruns": {o}, "wake_us": {w},
            "compute_us": {{"p50": 1.0, "p99": {c}, "p999": {c}, "max": {c}}},
            "ipc_us": {w}, "driver_forward_us": null, "driver": {d}, "cyclictest_us": {w},
            "ratio_p99": {r99}, "ratio_p999": {r999},
            "cyclictest_samples": 1024, "cyclictest_over_period": 2,
            "hot_path_allocations": {a}, "probe_lost": 0, "input_us": {w},
            "publish_us": {w}, "seconds": 10, "rounds": 1, "load": null,
            "cyclictest_command": "cyclictest"}}"#,
        o = f.overruns,
        w = p(30.0),
        c = f.compute_p99,
        r99 = f.ratio_p99,
        r999 = f.ratio_p999,
        a = f.allocations,
        d = f.driver_allocations.map_or("null".to_owned(), |n| {
            format!(r#"{{"pulses_sent": 10, "hot_path_allocations": {n}}}"#)
        })
    )
}

fn write_summary(dir: &Path, name: &str, no_load: Figures, load: Option<Figures>) -> PathBuf {
    let load = load.map_or(String::new(), |f| {
        format!(r#", "load": {}"#, condition_json(f))
    });
    let text = format!(
        r#"{{"schema": "fes-latency-summary/1",
            "conditions": {{"no_load": {}{load}}},
            "ratio_p99": null, "ratio_p999": null, "driver_forward_note": null,
            "test_slowdown_us": null, "kernel": "k", "load_average": ["0", "0"],
            "started": "t", "command": "c"}}"#,
        condition_json(no_load)
    );
    let path = dir.join(format!("{name}.json"));
    std::fs::write(&path, text).expect("write summary");
    path
}

fn compare(dir: &Path, summary: &Path, baseline: &Path) -> (Option<i32>, String) {
    run(
        dir,
        &[
            "--compare",
            &summary.display().to_string(),
            "--baseline",
            &baseline.display().to_string(),
        ],
        &[],
    )
}

#[test]
fn the_gate_applies_the_stated_tolerance() {
    let scratch = scratch("latency-gate");
    let dir = scratch.path();
    // 1024 ticks: one sample beyond p99.9, so `min_tail_samples` 1 lets it be judged.
    let baseline = write_baseline(dir, 1.5, true, 1);
    // Limits by hand: ratio_p99 1.5 * 1.25 = 1.875 (no_load), 1.5 * 1.5 = 2.25 (load);
    // ratio_p999 2 * max(0.75, 1) = 2.0 (no_load: a baseline below parity does not
    // tighten), 2 * 1.25 = 2.5 (load); overrun rate max(0.002, 3 * 2/1024) = 6/1024, i.e.
    // 6 of 1024 ticks; compute p99 50 µs; allocations 0.
    let at_limits = Figures {
        ratio_p99: 1.875,
        ratio_p999: 2.0,
        overruns: 6,
        compute_p99: 50.0,
        allocations: 0,
        driver_allocations: Some(0),
    };
    let load_at_limits = Figures {
        ratio_p99: 2.25,
        ratio_p999: 2.5,
        ..at_limits
    };
    let s = write_summary(dir, "at-limits", at_limits, Some(load_at_limits));
    let (code, out) = compare(dir, &s, &baseline);
    assert_eq!(code, Some(0), "every value at its limit passes:\n{out}");
    assert!(out.contains("PASS"), "{out}");
    assert_eq!(out.matches(" ok").count(), 12, "6 checks x 2 conditions");

    let over: [(&str, Figures); 6] = [
        (
            "no_load.ratio_p99",
            Figures {
                ratio_p99: 1.876,
                ..GOOD
            },
        ),
        (
            "no_load.ratio_p999",
            Figures {
                ratio_p999: 2.01,
                ..GOOD
            },
        ),
        (
            "no_load.overrun_rate",
            Figures {
                overruns: 7,
                ..GOOD
            },
        ),
        (
            "no_load.compute_us.p99",
            Figures {
                compute_p99: 50.1,
                ..GOOD
            },
        ),
        (
            "no_load.hot_path_allocations",
            Figures {
                allocations: 1,
                ..GOOD
            },
        ),
        (
            "no_load.driver_allocations",
            Figures {
                driver_allocations: Some(1),
                ..GOOD
            },
        ),
    ];
    for (i, (name, figures)) in over.into_iter().enumerate() {
        let s = write_summary(dir, &format!("over-{i}"), figures, Some(GOOD));
        let (code, out) = compare(dir, &s, &baseline);
        assert_eq!(code, Some(1), "{name} just over its limit fails:\n{out}");
        assert!(
            !out.contains("error:"),
            "a regression is not an error:\n{out}"
        );
        assert!(
            out.contains(&format!("FAIL: regressed: {name}\n")),
            "only {name} is named:\n{out}"
        );
    }
    // The loaded condition is judged against its own baseline.
    let s = write_summary(
        dir,
        "load-over",
        GOOD,
        Some(Figures {
            ratio_p99: 2.26,
            ..GOOD
        }),
    );
    let (code, out) = compare(dir, &s, &baseline);
    assert_eq!(code, Some(1), "{out}");
    assert!(out.contains("FAIL: regressed: load.ratio_p99\n"), "{out}");

    // With too few samples beyond p99.9 (1 < 2) the p99.9 ratio is not judged.
    let strict_tail = write_baseline(dir, 1.5, true, 2);
    let s = write_summary(dir, "tail", over[1].1, Some(GOOD));
    let (code, out) = compare(dir, &s, &strict_tail);
    assert_eq!(code, Some(0), "{out}");
    assert_eq!(
        out.matches("not judged (too few tail samples)").count(),
        2,
        "{out}"
    );

    // With 3 or more rounds the median of the per-round p99 ratios is judged instead of
    // the pooled one (here pooled 3.0, over its limit; median 1.875, at it).
    let text = std::fs::read_to_string(write_summary(
        dir,
        "rounds",
        Figures {
            ratio_p99: 3.0,
            ..GOOD
        },
        None,
    ))
    .expect("summary")
    .replacen(
        r#""rounds": 1,"#,
        r#""rounds": 5, "ratio_p99_round_median": 1.875,"#,
        1,
    );
    let s = dir.join("rounds.json");
    std::fs::write(&s, text).expect("rewrite");
    let (code, out) = compare(dir, &s, &baseline);
    assert_eq!(code, Some(0), "{out}");
    assert!(out.contains("no_load  ratio_p99_rounds"), "{out}");

    // A baseline without the loaded condition cannot judge a loaded run.
    let no_load_only = write_baseline(dir, 1.5, false, 1);
    let s = write_summary(dir, "both", GOOD, Some(GOOD));
    let (code, out) = compare(dir, &s, &no_load_only);
    assert_eq!(code, Some(1), "{out}");
    assert!(out.contains("latency-regression: error:"), "{out}");
    assert!(out.contains("no 'load' condition"), "{out}");
    // A factor below 1 would fail the baseline's own run: refused, naming the key.
    let bad = write_baseline(dir, 0.9, true, 1);
    let (code, out) = compare(dir, &s, &bad);
    assert_eq!(code, Some(1), "{out}");
    assert!(out.contains("latency-regression: error:"), "{out}");
    assert!(out.contains("tolerance.ratio_p99_factor = 0.9"), "{out}");
    // A run without cyclictest cannot be judged.
    let text = std::fs::read_to_string(&s).expect("summary").replacen(
        r#""ratio_p99": 1"#,
        r#""ratio_p99": null"#,
        1,
    );
    std::fs::write(&s, text).expect("rewrite");
    let (code, out) = compare(dir, &s, &baseline);
    assert_eq!(code, Some(1), "{out}");
    assert!(out.contains("latency-regression: error:"), "{out}");
    assert!(out.contains("no cyclictest comparison"), "{out}");
}

/// The suite on this host: judged against cyclictest in the same run, so it runs in the
/// test command's timing phase, one test at a time with nothing else on the machine
/// (`scripts/test`; beside the other system tests its load condition saw 12 % of rt-core's
/// periods missed and failed the gate).
mod timing {
    use super::*;

    /// The release binaries the suite measures, built as `scripts/latency-regression`
    /// builds them: the baseline's figures are of the shipped build, and a debug build of
    /// the loop (workspace code at opt-level 0) is not what it judges (in this phase its
    /// load condition came out at 3.9 times cyclictest's p99, the release build's at 1.6).
    fn release_tools() -> PathBuf {
        let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
        let status = Command::new(cargo)
            .current_dir(workspace_root())
            .args([
                "build",
                "--release",
                "--quiet",
                "-p",
                "rt-core",
                "-p",
                "fes-latency",
                "--bins",
            ])
            .status()
            .expect("run cargo build --release");
        assert!(
            status.success(),
            "cargo build --release of the latency tools failed"
        );
        crate::support::target_dir().join("release")
    }

    #[test]
    fn short_run_passes_and_a_slowed_tick_is_caught() {
        let bins = release_tools();
        let scratch = scratch("latency-run");
        let baseline = workspace_root().join("crates/fes-latency/latency-baseline.json");
        let out_dir = scratch.path().join("report");
        let json = scratch.path().join("summary-copy.json");
        let common = |out: &Path| {
            vec![
                "--bin-dir".to_owned(),
                bins.display().to_string(),
                "--baseline".to_owned(),
                baseline.display().to_string(),
                "--out-dir".to_owned(),
                out.display().to_string(),
            ]
        };

        // The CI short form: 5 s of rt-core and 5 s of cyclictest per condition.
        let mut args = common(&out_dir);
        args.extend(["--seconds", "5", "--json"].map(str::to_owned));
        args.push(json.display().to_string());
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let (code, out) = run(scratch.path(), &args, &[]);
        assert_eq!(
            code,
            Some(0),
            "the current code passes its baseline:\n{out}"
        );
        assert!(out.contains("PASS: no regression"), "{out}");
        let summary: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).expect("--json written"))
                .expect("summary JSON");
        assert_eq!(
            std::fs::read_to_string(&json).expect("copy"),
            std::fs::read_to_string(out_dir.join("summary.json")).expect("summary.json"),
            "--json is the same document"
        );
        for condition in ["no_load", "load"] {
            let c = &summary["conditions"][condition];
            // 5 s at 1 kHz; rt-core's start-up on a loaded machine can take a good part of
            // each round (its clock runs from the spawn); cyclictest's count nearly exact.
            let ticks = c["ticks"].as_u64().expect("ticks");
            assert!((2500..=5600).contains(&ticks), "{condition}: {ticks} ticks");
            // cyclictest runs 1 s per round: a host stall costs it the periods it spans. How
            // many is the host's (a quiet hour: 4848; 2026-12-02 at a noisy one: 3901, a
            // second of stalls in five); the bounds check the parse and the run's length,
            // as for rt-core's ticks above.
            let samples = c["cyclictest_samples"].as_u64().expect("samples");
            assert!((2500..=5000).contains(&samples), "{condition}: {samples}");
            for key in ["wake_us", "compute_us", "ipc_us", "cyclictest_us"] {
                for p in ["p50", "p99", "p999", "max"] {
                    assert!(
                        c[key][p].as_f64().is_some_and(|v| v >= 0.0),
                        "{condition}.{key}.{p}"
                    );
                }
                assert!(
                    c[key]["p50"].as_f64() <= c[key]["p99"].as_f64()
                        && c[key]["p99"].as_f64() <= c[key]["p999"].as_f64()
                        && c[key]["p999"].as_f64() <= c[key]["max"].as_f64(),
                    "{condition}.{key} percentiles are ordered"
                );
            }
            // The driver's forward path: the test pattern fires every 20 ticks, and every
            // PULSE written reached the virtual stimulator (a pulse written in the tick before
            // a round's final tick may be cancelled by the safe stop that answers it).
            let d = &c["driver_forward_us"];
            assert!(
                d["p50"].as_f64() <= d["p99"].as_f64()
                    && d["p99"].as_f64() <= d["p999"].as_f64()
                    && d["p999"].as_f64() <= d["max"].as_f64()
                    && d["p50"].as_f64().is_some_and(|v| v > 0.0),
                "{condition}.driver_forward_us: {d}"
            );
            let driver = &c["driver"];
            let sent = driver["pulses_sent"].as_u64().expect("pulses_sent");
            let applied = driver["stimulator_pulses"].as_u64().expect("applied");
            let rounds = c["rounds"].as_u64().expect("rounds");
            assert!(sent >= 50, "{condition}: {sent} pulses written: {driver}");
            assert!(
                applied <= sent && applied + rounds >= sent,
                "{condition}: {sent} written, {applied} applied"
            );
            // Refusals (a pulse come too late after a host stall, a stale tick and the trip
            // that answers it) are the driver doing its job; they are reported, not judged.
            assert!(out_dir.join(condition).join("driver-0.hlog").is_file());
            // The ratio is wake p99 over the middle of cyclictest's microsecond bucket.
            let expected = c["wake_us"]["p99"].as_f64().expect("wake")
                / (c["cyclictest_us"]["p99"].as_f64().expect("cyclictest") + 0.5);
            let ratio = c["ratio_p99"].as_f64().expect("ratio");
            assert!((ratio - expected).abs() < 1e-9, "{ratio} vs {expected}");
            for file in ["rt-core-0.hlog", "rt-probe-0.hlog", "cyclictest.hlog"] {
                assert!(out_dir.join(condition).join(file).is_file(), "{file}");
            }
        }
        assert!(summary["driver_forward_note"].is_string());
        let png = std::fs::read(out_dir.join("percentiles.png")).expect("percentiles.png");
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
        let md = std::fs::read_to_string(out_dir.join("report.md")).expect("report.md");
        assert!(
            md.contains("## no_load") && md.contains("## load") && md.contains("| cyclictest |")
        );

        // The test-only slowdown: every tick busy-waits longer than the period. The loop then
        // holds its core at SCHED_FIFO 80 without pause, which would starve a subscriber
        // below it on that core: the probe moves to the other core.
        let slow_dir = scratch.path().join("slow");
        let mut args = common(&slow_dir);
        args.extend(["--seconds", "2", "--no-load", "--probe-core", "0"].map(str::to_owned));
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let (code, out) = run(scratch.path(), &args, &[("FES_TEST_TICK_BUSY_US", "1100")]);
        assert_eq!(code, Some(1), "a slowed loop is a regression:\n{out}");
        let failed = out
            .lines()
            .find_map(|l| l.strip_prefix("FAIL: regressed: "))
            .expect("the failed checks are listed");
        // The compute budget is absolute and always exceeded; of the two gates relative to
        // cyclictest at least one must see the lateness: the ratio of p99s (a 2 s run's
        // cyclictest p99 can reach 0.5 ms on a noisy CI host, which brings the loop's 1.1 ms
        // p99 under the 2.6x limit) or the late-wake-up rate (15 % of ticks here).
        assert!(
            failed.contains("no_load.compute_us.p99"),
            "compute_us.p99 in {failed:?}"
        );
        assert!(
            failed.contains("no_load.ratio_p99") || failed.contains("no_load.overrun_rate"),
            "the lateness is named (ratio_p99 or overrun_rate) in {failed:?}"
        );
        let md = std::fs::read_to_string(slow_dir.join("report.md")).expect("report.md");
        assert!(md.contains("TEST SLOWDOWN ON"), "the report says so");
        // The regression was confirmed by a second measurement (`--confirm`, default 1):
        // the first is kept aside and named, the second is the one judged.
        assert!(
            out.contains("no_load: attempt 1 failed") && md.contains("no_load attempt 1 failed"),
            "the first failed measurement is reported:\n{out}"
        );
        assert!(slow_dir.join("no_load-attempt-1/rt-core-0.hlog").is_file());
        assert!(slow_dir.join("no_load/rt-core-0.hlog").is_file());
        let summary: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(slow_dir.join("summary.json")).expect("summary.json"),
        )
        .expect("summary JSON");
        assert_eq!(summary["unconfirmed"][0]["condition"], "no_load");
        assert_eq!(summary["unconfirmed"].as_array().map(Vec::len), Some(1));
    }
}
