//! [`LatencyHistogram`]: a bounded HdrHistogram of nanosecond latencies that never resizes.

use hdrhistogram::Histogram;

use crate::msg::LatencySummary;

/// Latencies in ns from [`LatencyHistogram::LOWEST_NS`] to [`LatencyHistogram::HIGHEST_NS`]
/// with [`LatencyHistogram::SIGNIFICANT_DIGITS`] significant digits; auto-resize is off, so
/// its memory is fixed at creation. Values above the range are clamped to it and counted as
/// saturated.
#[derive(Debug, Clone)]
pub struct LatencyHistogram {
    hist: Histogram<u64>,
    saturated: u64,
}

impl Default for LatencyHistogram {
    fn default() -> Self {
        Self::new()
    }
}

impl LatencyHistogram {
    /// Lowest discernible value, ns.
    pub const LOWEST_NS: u64 = 1;
    /// Highest trackable value, ns (10 s).
    pub const HIGHEST_NS: u64 = 10_000_000_000;
    /// Significant decimal digits kept (relative error <= 0.1 %).
    pub const SIGNIFICANT_DIGITS: u8 = 3;

    /// An empty histogram with the fixed range.
    #[expect(
        clippy::expect_used,
        reason = "the bounds are constants that satisfy HdrHistogram's preconditions"
    )]
    pub fn new() -> Self {
        let mut hist =
            Histogram::new_with_bounds(Self::LOWEST_NS, Self::HIGHEST_NS, Self::SIGNIFICANT_DIGITS)
                // The bounds are constants that satisfy every precondition (low >= 1, high >= 2 * low,
                // digits <= 5); a failure here is a programming error, caught by the tests.
                .expect("constant HdrHistogram bounds are valid");
        hist.auto(false);
        Self { hist, saturated: 0 }
    }

    /// Records one value; a value above the range is clamped and counted as saturated.
    pub fn record(&mut self, ns: u64) {
        let v = if ns > Self::HIGHEST_NS {
            self.saturated += 1;
            Self::HIGHEST_NS
        } else {
            ns
        };
        // In range by construction, and auto-resize is off: this cannot fail.
        let _ = self.hist.record(v);
    }

    /// Adds all counts of `other` (same fixed range, so this cannot fail).
    pub fn add(&mut self, other: &LatencyHistogram) {
        let _ = self.hist.add(&other.hist);
        self.saturated += other.saturated;
    }

    /// Adds all counts of a raw histogram read back from a log (values above the range are
    /// clamped into it).
    pub fn add_raw(&mut self, other: &Histogram<u64>) {
        for v in other.iter_recorded() {
            let value = v.value_iterated_to().min(Self::HIGHEST_NS);
            let _ = self.hist.record_n(value, v.count_at_value());
        }
    }

    /// Empties it (keeps the memory).
    pub fn reset(&mut self) {
        self.hist.reset();
        self.saturated = 0;
    }

    /// Number of values recorded.
    pub fn count(&self) -> u64 {
        self.hist.len()
    }

    /// Values that were above the range and clamped.
    pub fn saturated(&self) -> u64 {
        self.saturated
    }

    /// The value at quantile `q` in [0, 1], ns (0 when empty).
    pub fn quantile_ns(&self, q: f64) -> u64 {
        if self.hist.is_empty() {
            0
        } else {
            self.hist.value_at_quantile(q)
        }
    }

    /// Largest value recorded, ns (0 when empty).
    pub fn max_ns(&self) -> u64 {
        if self.hist.is_empty() {
            0
        } else {
            self.hist.max()
        }
    }

    /// p50 / p99 / p99.9 / max.
    pub fn summary(&self) -> LatencySummary {
        LatencySummary {
            count: self.count(),
            p50_ns: self.quantile_ns(0.5),
            p99_ns: self.quantile_ns(0.99),
            p999_ns: self.quantile_ns(0.999),
            max_ns: self.max_ns(),
        }
    }

    /// The underlying HdrHistogram (for serialisation).
    pub fn raw(&self) -> &Histogram<u64> {
        &self.hist
    }
}
