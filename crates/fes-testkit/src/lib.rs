//! What the project's tests share, and nothing else of the project: a dev-dependency of
//! every crate, so it sits below all of them (no dependency cycle through the system
//! tests of `fes-tests`).
//!
//! * [`Scratch`]: a scratch directory, removed when the test passes, kept (and named) when
//!   it fails or `FES_TEST_KEEP` is set;
//! * [`assert_refused`]: the bad-input sweeps' one check that a run refused its input
//!   clearly (exit code, no panic, the offending name in a short message);
//! * [`noise`]: the host's own wake-up noise, measured beside a timing check, so that the
//!   check is judged against what the host allowed in the same run (docs/latency.md).
//!
//! Functional tests assert what a program does, whatever the host's timing; checks that
//! depend on the host's timing live in `timing` modules of the test binaries and are
//! judged against [`noise::HostNoise`] (docs/architecture.md, "Tests").

pub mod noise;
mod refused;
mod scratch;

pub use refused::assert_refused;
pub use scratch::Scratch;
