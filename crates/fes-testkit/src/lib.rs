//! What the project's tests share: a dev-dependency of every crate, so it sits below all of
//! them (it links only the leaf crates `fes-can` and `fes-hostbus`, for the bus tap; no
//! dependency cycle through the system tests of `fes-tests`). With its feature `control` it
//! links `fes-model` too, for the control tests' fixture.
//!
//! * [`Scratch`]: a scratch directory, removed when the test passes, kept (and named) when
//!   it fails or `FES_TEST_KEEP` is set;
//! * [`vcan`]: a CAN interface for a test (native vcan, a given interface, or a User-Mode
//!   Linux guest) ([`vcan::with_vcan`]), or for any command (`vcan-run`);
//! * [`bus`]: host-side helpers for protocol tests: a frame tap with timestamps, a host
//!   port that sends PULSE/NMT/CONFIG with correct counters, a heartbeat thread;
//! * [`child`]: test children die with the test thread that started them;
//! * [`assert_refused`]: the bad-input sweeps' one check that a run refused its input
//!   clearly (exit code, no panic, the offending name in a short message);
//! * [`target_dir`]: the cargo target directory the tests were built in;
//! * [`table`]: the tools' CSV files as a header and rows of fields;
//! * [`noise`]: the host's own wake-up noise, measured beside a timing check, so that the
//!   check is judged against what the host allowed in the same run (docs/latency.md);
//! * `control` (feature `control`): the control tests' fixture, muscle-like Local Model
//!   Networks built in code (the fast muscle, Table 6.1's rise times).
//!
//! Functional tests assert what a program does, whatever the host's timing; checks that
//! depend on the host's timing live in `timing` modules of the test binaries and are
//! judged against [`noise::HostNoise`] (docs/architecture.md, "Tests").

// A testkit: its helpers panic on a failed setup step by design (a failed test).
#![allow(clippy::unwrap_used, clippy::expect_used)]

pub mod bus;
pub mod child;
#[cfg(feature = "control")]
pub mod control;
pub mod noise;
mod refused;
mod scratch;
pub mod table;
pub mod vcan;

pub use refused::assert_refused;
pub use scratch::Scratch;

/// The cargo target directory of the workspace at `workspace_root`: `CARGO_TARGET_DIR`
/// (relative to the root when relative), else `target` under the root.
pub fn target_dir(workspace_root: &std::path::Path) -> std::path::PathBuf {
    match std::env::var_os("CARGO_TARGET_DIR").map(std::path::PathBuf::from) {
        Some(dir) if dir.is_absolute() => dir,
        Some(dir) => workspace_root.join(dir),
        None => workspace_root.join("target"),
    }
}
