//! The system tests' library: what the cross-process suites share beyond the testkit
//! (`fes-testkit`: the vcan harness, the bus tap and the process helpers that every crate's
//! tests use). The latency tools are the `fes-latency` package.
//!
//! * [`cantools`]: decoding a `candump -L` log with cantools against the DBC.
//! * [`stack`]: building the four binaries and reading the virtual stimulator's record,
//!   for tests that run the whole stack (`fes_bench::bench::Stack`).
// A testkit: its helpers panic on a failed setup step by design (a failed test).
#![allow(clippy::unwrap_used, clippy::expect_used)]

pub mod cantools;
pub mod stack;
