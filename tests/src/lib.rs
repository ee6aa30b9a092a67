//! Cross-process CAN tests and the vcan harness shared by every CAN test of the workspace.
//!
//! * [`vcan`]: get a CAN interface (native vcan, a given interface, or a User-Mode Linux
//!   guest) for a `#[test]` ([`vcan::with_vcan`]) or for any command (`vcan-run`).
//! * [`bus`]: host-side helpers for protocol tests: a frame tap with timestamps, a host
//!   port that sends PULSE/NMT/CONFIG with correct counters, a heartbeat thread.
//! * [`child`]: test children die with the test thread that started them.
//! * [`cli`]: the common assertion of the binaries' bad-input sweeps.
//! * [`cyclictest`]: running cyclictest and reading its histogram (the latency tools).
//! * [`stack`]: building the four binaries and reading the virtual stimulator's record,
//!   for tests that run the whole stack (`workbench::bench::Stack`).
#![deny(missing_docs)]
// A testkit: its helpers panic on a failed setup step by design (a failed test).
#![allow(clippy::unwrap_used, clippy::expect_used)]

pub mod bus;
pub mod child;
pub mod cli;
pub mod cyclictest;
pub mod stack;
pub mod vcan;
