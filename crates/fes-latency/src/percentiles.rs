//! [`Percentiles`]: what rt-latency writes to its JSON and prints, and latency-regression
//! reads back and prints per condition, so both print one table.

use fes_rt::rt::histogram::LatencyHistogram;
use serde::{Deserialize, Serialize};

use crate::cyclictest::CyclictestHistogram;

/// p50 / p99 / p99.9 / max, µs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Percentiles {
    /// Median.
    pub p50: f64,
    /// 99th percentile.
    pub p99: f64,
    /// 99.9th percentile.
    pub p999: f64,
    /// Largest value.
    pub max: f64,
}

impl Percentiles {
    /// The quantiles of a histogram of ns.
    pub fn from_histogram(h: &LatencyHistogram) -> Self {
        let us = |ns: u64| ns as f64 / 1000.0;
        Self {
            p50: us(h.quantile_ns(0.5)),
            p99: us(h.quantile_ns(0.99)),
            p999: us(h.quantile_ns(0.999)),
            max: us(h.max_ns()),
        }
    }

    /// The quantiles of cyclictest's histogram (µs).
    pub fn from_cyclictest(h: &CyclictestHistogram) -> Self {
        Self {
            p50: h.quantile_us(0.5) as f64,
            p99: h.quantile_us(0.99) as f64,
            p999: h.quantile_us(0.999) as f64,
            max: h.max_us as f64,
        }
    }

    /// Prints the header of the latency table.
    pub fn print_header() {
        println!(
            "{:<28} {:>9} {:>9} {:>9} {:>9}",
            "latency (us)", "p50", "p99", "p99.9", "max"
        );
    }

    /// Prints the table's row `name`.
    pub fn print_row(&self, name: &str) {
        println!(
            "{:<28} {:>9.1} {:>9.1} {:>9.1} {:>9.1}",
            name, self.p50, self.p99, self.p999, self.max
        );
    }
}
