//! Timing-dependent checks of the workbench (run one at a time, nothing else running:
//! `scripts/test`'s `timing::` phase).

use std::path::Path;
use std::process::Command;

use fes_tests::stack::{stack_binaries, workspace_root};

/// One bench (`fes bench --seconds 30`, the default length of `scripts/bench`) with `args`; its summary JSON. A run the
/// shared host's noise stops (a watchdog trip: the bench fails) is repeated, at most
/// three times.
fn bench(tag: &str, args: &[&str]) -> serde_json::Value {
    let mut failures = Vec::new();
    for attempt in 1..=3 {
        let dir =
            std::env::temp_dir().join(format!("fes-bench-{tag}-{}-{attempt}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let json = dir.with_extension("json");
        let out = Command::new(env!("CARGO_BIN_EXE_fes"))
            .current_dir(workspace_root())
            .args(["bench", "--seconds", "30", "--out"])
            .arg(&dir)
            .arg("--json")
            .arg(&json)
            .args(args)
            .env("RUST_BACKTRACE", "0")
            .output()
            .expect("run fes bench");
        if out.status.success() {
            let v: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
            let _ = std::fs::remove_dir_all(&dir);
            let _ = std::fs::remove_file(&json);
            return v;
        }
        failures.push(format!(
            "attempt {attempt}: {}\n{}",
            out.status,
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    panic!(
        "fes bench {args:?} failed three times:\n{}",
        failures.join("\n")
    );
}

fn f(v: &serde_json::Value, key: &str) -> f64 {
    v[key].as_f64().unwrap_or_else(|| panic!("{key}: {v}"))
}

/// The figures of one pair of benches compared: `(key, CAN, ScienceMode)`.
fn rms_pairs(can: &[serde_json::Value], sm: &[serde_json::Value]) -> Vec<(&'static str, f64, f64)> {
    let mean = |runs: &[serde_json::Value], key: &str| {
        runs.iter().map(|v| f(v, key)).sum::<f64>() / runs.len() as f64
    };
    ["rms_error_model", "rms_error_measured"]
        .into_iter()
        .map(|key| (key, mean(can, key), mean(sm, key)))
        .collect()
}

/// Issue 22's acceptance: the bench on the ScienceMode transport (the virtual RehaStim 2
/// on a pty) tracks the same cardiac profile with the same pulses as on CAN (the host
/// bus: the CAN frames over Unix datagrams, on any kernel): the same summary keys, the
/// same pulses per contraction, and RMS tracking errors (model and measured force) within
/// 5 % of each other.
///
/// Both are real-time runs on a shared host, and the outer loop answers the measured
/// force, so neither figure repeats exactly on one transport: over 37 beats the mean
/// pulses per contraction moved by one pulse in all (6.97 against 7.0) and the RMS by up to
/// 4 % between two runs of the same transport (docs/sciencemode.md, "The bench on this
/// transport"). So the pulses a contraction gets are compared as a whole number (the
/// mean, rounded) and the pulses over all complete beats may differ by two at most; when a first pair of runs is more than 5 % apart in RMS a second
/// pair is run and the means of the two pairs are judged: a transport that is off by more
/// than 5 % stays off in the mean, a noisy pair does not fail the check.
#[test]
fn the_bench_on_sciencemode_tracks_the_profile_with_the_pulses_of_can() {
    let _one = crate::stack_support::one_stack_at_a_time();
    let bins = stack_binaries();
    assert!(Path::new(env!("CARGO_BIN_EXE_fes")).parent() == Some(bins.as_path()));
    let mut can = vec![bench("can", &["--bus", "host"])];
    let mut sm = vec![bench("sciencemode", &["--stimulator", "sciencemode"])];
    let keys = |v: &serde_json::Value| {
        let mut k: Vec<String> = v.as_object().unwrap().keys().cloned().collect();
        k.retain(|k| k != "command" && k != "plots");
        k
    };
    assert_eq!(keys(&can[0]), keys(&sm[0]), "summary keys");
    let within =
        |pairs: &[(&str, f64, f64)]| pairs.iter().all(|(_, a, b)| (b - a).abs() <= 0.05 * a);
    if !within(&rms_pairs(&can, &sm)) {
        println!("RMS more than 5 % apart in the first pair: a second pair");
        can.push(bench("can-2", &["--bus", "host"]));
        sm.push(bench("sciencemode-2", &["--stimulator", "sciencemode"]));
    }
    for (name, runs) in [("can", &can), ("sciencemode", &sm)] {
        for v in runs.iter() {
            println!(
                "{name}: {} contractions, {} pulses per contraction, RMS model {:.4} measured {:.4}, {} pulses sent",
                v["contractions"],
                v["pulses_per_contraction"],
                f(v, "rms_error_model"),
                f(v, "rms_error_measured"),
                v["pulses_sent"]
            );
        }
    }
    for (c, s) in can.iter().zip(&sm) {
        assert_eq!(c["contractions"], s["contractions"]);
        assert_eq!(
            f(c, "pulses_per_contraction").round(),
            f(s, "pulses_per_contraction").round(),
            "pulses per contraction: {} on CAN, {} on sciencemode",
            c["pulses_per_contraction"],
            s["pulses_per_contraction"]
        );
        let (pc, ps) = (f(c, "pulses"), f(s, "pulses"));
        assert!(
            (pc - ps).abs() <= 2.0,
            "pulses over the complete beats: {pc} on CAN, {ps} on sciencemode (more than 2 apart)"
        );
    }
    for (key, a, b) in rms_pairs(&can, &sm) {
        assert!(
            (b - a).abs() <= 0.05 * a,
            "{key}: {b} on sciencemode, {a} on CAN (more than 5 % apart, mean of {} pairs)",
            can.len()
        );
    }
}
