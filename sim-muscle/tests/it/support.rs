//! Helpers shared by the integration tests: scratch directories and running the binary.

use std::process::{Command, Output};

pub use fes_testkit::Scratch;

/// Runs `sim-muscle` with `args`.
pub fn run(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_sim-muscle"))
        .args(args)
        .output()
        .expect("run sim-muscle")
}

/// Runs `sim-muscle`, asserting success; returns stdout.
pub fn run_ok(args: &[&str]) -> String {
    let out = run(args);
    assert!(
        out.status.success(),
        "sim-muscle {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("utf-8 stdout")
}
