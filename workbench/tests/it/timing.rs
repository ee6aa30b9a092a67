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

/// Issue 22's acceptance: the bench on the ScienceMode transport (the virtual RehaStim 2
/// on a pty) tracks the same cardiac profile with the same pulses as on CAN (the host
/// bus: the CAN frames over Unix datagrams, on any kernel): the same summary keys, equal
/// pulses per contraction, and RMS tracking errors (model and measured force) within 5 %
/// of each other.
#[test]
fn the_bench_on_sciencemode_tracks_the_profile_with_the_pulses_of_can() {
    let _one = crate::stack_support::one_stack_at_a_time();
    let bins = stack_binaries();
    assert!(Path::new(env!("CARGO_BIN_EXE_fes")).parent() == Some(bins.as_path()));
    let can = bench("can", &["--bus", "host"]);
    let sm = bench("sciencemode", &["--stimulator", "sciencemode"]);
    let keys = |v: &serde_json::Value| {
        let mut k: Vec<String> = v.as_object().unwrap().keys().cloned().collect();
        k.retain(|k| k != "command" && k != "plots");
        k
    };
    assert_eq!(keys(&can), keys(&sm), "summary keys");
    for (name, v) in [("can", &can), ("sciencemode", &sm)] {
        println!(
            "{name}: {} contractions, {} pulses per contraction, RMS model {:.4} measured {:.4}, {} pulses sent",
            v["contractions"],
            v["pulses_per_contraction"],
            f(v, "rms_error_model"),
            f(v, "rms_error_measured"),
            v["pulses_sent"]
        );
    }
    assert_eq!(can["contractions"], sm["contractions"]);
    assert_eq!(
        f(&can, "pulses_per_contraction"),
        f(&sm, "pulses_per_contraction"),
        "pulses per contraction"
    );
    for key in ["rms_error_model", "rms_error_measured"] {
        let (a, b) = (f(&can, key), f(&sm, key));
        assert!(
            (b - a).abs() <= 0.05 * a,
            "{key}: {b} on sciencemode, {a} on CAN (more than 5 % apart)"
        );
    }
}
