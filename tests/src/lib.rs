//! The system tests' library: what the cross-process suites and the latency tools share
//! beyond the testkit (`fes-testkit`: the vcan harness, the bus tap and the process helpers
//! that every crate's tests use).
//!
//! * [`cantools`]: decoding a `candump -L` log with cantools against the DBC.
//! * [`cyclictest`]: running cyclictest and reading its histogram (the latency tools).
//! * [`stack`]: building the four binaries and reading the virtual stimulator's record,
//!   for tests that run the whole stack (`workbench::bench::Stack`).
// A testkit: its helpers panic on a failed setup step by design (a failed test).
#![allow(clippy::unwrap_used, clippy::expect_used)]

pub mod cantools;
pub mod cyclictest;
pub mod stack;
