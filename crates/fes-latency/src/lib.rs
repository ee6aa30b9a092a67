//! The latency tools, shipped beside the stack: `rt-latency` (the real rt-core loop against
//! cyclictest on this machine), `driver-latency` (the stim-driver's forward path on a
//! socket-pair bus) and `latency-regression` (the suite, its report and its gate against
//! `crates/fes-latency/latency-baseline.json`; run by `scripts/latency-regression`,
//! docs/latency.md).
//!
//! The library holds what the tools share and the tests reach:
//!
//! * [`cyclictest`]: running cyclictest and reading its histogram.
//! * [`Percentiles`]: the latency quantiles rt-latency writes and latency-regression reads,
//!   and their table.
//! * [`DriverCounters`]: the driver's counters driver-latency writes and rt-latency sums.

pub mod cyclictest;
mod driver_counters;
mod percentiles;

pub use driver_counters::DriverCounters;
pub use percentiles::Percentiles;
