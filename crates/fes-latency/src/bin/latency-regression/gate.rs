//! The regression gate: a summary against the stored baseline.
//!
//! The figures that decide are ratios to cyclictest measured *in the same run* (same core,
//! priority, period, alternating rounds), so that the machine's own noise, which moves
//! both, cancels to first order; absolute figures are gated only where the machine's speed
//! does not matter (compute time against a generous budget, hot-path allocations).
//!
//! Per measured condition:
//! - `ratio_p99  <= ratio_p99_factor  * max(baseline ratio_p99, 1)`, where with 3 or more
//!   rounds the median over the rounds of the per-round ratio is judged
//!   (`ratio_p99_rounds`);
//! - `ratio_p999 <= ratio_p999_factor * max(baseline ratio_p999, 1)`, judged only when
//!   both sides have at least `min_tail_samples` samples beyond their p99.9 (a short run's
//!   p99.9 rests on a handful of samples: one hypervisor stall moves it);
//!   (a baseline below 1, a lucky run, does not tighten the gate below parity);
//! - late-wake-up rate `overruns / ticks <= max(overrun_rate_floor, overrun_rate_factor *
//!   cyclictest's rate of samples >= one period)`;
//! - `compute_us.p99 <= compute_p99_us_max`;
//! - `hot_path_allocations <= hot_path_allocations_max` (0).

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, bail};
use serde::{Deserialize, Serialize};

use crate::summary::{Condition, ConditionSummary};

/// Schema tag of the baseline file.
pub const BASELINE_SCHEMA: &str = "fes-latency-baseline/1";

/// The tolerances (stated in the baseline file, so a change to them is reviewed).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Tolerance {
    /// Allowed growth of `ratio_p99` over the baseline (floored at 1).
    pub ratio_p99_factor: f64,
    /// Allowed growth of `ratio_p999` over the baseline (floored at 1).
    pub ratio_p999_factor: f64,
    /// Allowed late-wake-up rate relative to cyclictest's.
    pub overrun_rate_factor: f64,
    /// Late-wake-up rate always allowed (fraction of ticks).
    pub overrun_rate_floor: f64,
    /// Budget for the compute time p99, µs.
    pub compute_p99_us_max: f64,
    /// Heap allocations allowed on the hot path.
    pub hot_path_allocations_max: u64,
    /// Samples beyond p99.9 (on both sides) needed to judge `ratio_p999`.
    pub min_tail_samples: u64,
}

impl Tolerance {
    fn validate(&self) -> anyhow::Result<()> {
        for (name, v) in [
            ("ratio_p99_factor", self.ratio_p99_factor),
            ("ratio_p999_factor", self.ratio_p999_factor),
            ("overrun_rate_factor", self.overrun_rate_factor),
        ] {
            if !(v.is_finite() && v >= 1.0) {
                bail!("tolerance.{name} = {v}: must be a finite factor >= 1");
            }
        }
        if !(self.overrun_rate_floor.is_finite() && (0.0..1.0).contains(&self.overrun_rate_floor)) {
            bail!(
                "tolerance.overrun_rate_floor = {}: must be in [0, 1)",
                self.overrun_rate_floor
            );
        }
        if !(self.compute_p99_us_max.is_finite() && self.compute_p99_us_max > 0.0) {
            bail!(
                "tolerance.compute_p99_us_max = {}: must be a positive number of µs",
                self.compute_p99_us_max
            );
        }
        Ok(())
    }
}

/// The stored ratios of one condition.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BaselineRatios {
    /// Wake-up lateness p99 over cyclictest's.
    pub ratio_p99: f64,
    /// Wake-up lateness p99.9 over cyclictest's.
    pub ratio_p999: f64,
}

/// The baseline file.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Baseline {
    /// [`BASELINE_SCHEMA`].
    pub schema: String,
    /// How and where it was measured (free text, for the reader).
    pub measured: String,
    /// The tolerances.
    pub tolerance: Tolerance,
    /// Ratios per condition.
    pub conditions: BTreeMap<Condition, BaselineRatios>,
}

impl Baseline {
    /// Reads and validates a baseline file.
    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let b: Baseline = serde_json::from_str(&text)
            .with_context(|| format!("{}: not a latency baseline", path.display()))?;
        if b.schema != BASELINE_SCHEMA {
            bail!(
                "{}: schema {:?}, expected {BASELINE_SCHEMA:?}",
                path.display(),
                b.schema
            );
        }
        b.tolerance
            .validate()
            .with_context(|| path.display().to_string())?;
        for (c, r) in &b.conditions {
            for (name, v) in [("ratio_p99", r.ratio_p99), ("ratio_p999", r.ratio_p999)] {
                if !(v.is_finite() && v > 0.0) {
                    bail!(
                        "{}: {}.{name} = {v}: must be positive",
                        path.display(),
                        c.key()
                    );
                }
            }
        }
        Ok(b)
    }
}

/// One comparison.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Check {
    /// The condition.
    pub condition: Condition,
    /// What is compared (`ratio_p99`, `ratio_p999`, `overrun_rate`, `compute_us.p99`,
    /// `hot_path_allocations`, `driver_allocations`).
    pub key: String,
    /// The measured value.
    pub value: f64,
    /// The largest value that passes.
    pub limit: f64,
    /// Whether the value was judged (false: too few samples; then it passes).
    pub judged: bool,
    /// `value <= limit`, or not judged.
    pub passed: bool,
}

/// Compares every measured condition with the baseline. A condition the baseline does not
/// hold, or a missing cyclictest comparison, is an error: the gate cannot judge it.
pub fn compare(
    conditions: &BTreeMap<Condition, ConditionSummary>,
    baseline: &Baseline,
) -> anyhow::Result<Vec<Check>> {
    let t = &baseline.tolerance;
    let mut checks = Vec::new();
    for (&condition, s) in conditions {
        let Some(base) = baseline.conditions.get(&condition) else {
            bail!("the baseline has no '{}' condition", condition.key());
        };
        let (Some(r99), Some(r999)) = (s.ratio_p99, s.ratio_p999) else {
            bail!(
                "'{}': no cyclictest comparison in the run, the ratios cannot be judged",
                condition.key()
            );
        };
        if s.ticks == 0 || s.cyclictest_samples == 0 {
            bail!("'{}': no ticks or no cyclictest samples", condition.key());
        }
        let mut judge = |key: &str, value: f64, limit: f64, judged: bool| {
            checks.push(Check {
                condition,
                key: key.to_owned(),
                value,
                limit,
                judged,
                passed: !judged || value <= limit,
            });
        };
        // With 3 or more rounds the median of the per-round ratios is judged (robust to
        // a noise burst on one side of one round), else the pooled ratio.
        let (key, value) = match s.ratio_p99_round_median {
            Some(m) if s.rounds >= 3 => ("ratio_p99_rounds", m),
            _ => ("ratio_p99", r99),
        };
        judge(
            key,
            value,
            t.ratio_p99_factor * base.ratio_p99.max(1.0),
            true,
        );
        // Samples beyond p99.9 on the side with fewer samples.
        let tail = s.ticks.min(s.cyclictest_samples) / 1000;
        judge(
            "ratio_p999",
            r999,
            t.ratio_p999_factor * base.ratio_p999.max(1.0),
            tail >= t.min_tail_samples,
        );
        let mut check = |key: &str, value: f64, limit: f64| judge(key, value, limit, true);
        let cyclictest_rate = s.cyclictest_over_period as f64 / s.cyclictest_samples as f64;
        check(
            "overrun_rate",
            s.overruns as f64 / s.ticks as f64,
            t.overrun_rate_floor
                .max(t.overrun_rate_factor * cyclictest_rate),
        );
        check("compute_us.p99", s.compute_us.p99, t.compute_p99_us_max);
        check(
            "hot_path_allocations",
            s.hot_path_allocations as f64,
            t.hot_path_allocations_max as f64,
        );
        if let Some(n) = s
            .driver
            .as_ref()
            .and_then(|d| d["hot_path_allocations"].as_u64())
        {
            check(
                "driver_allocations",
                n as f64,
                t.hot_path_allocations_max as f64,
            );
        }
    }
    Ok(checks)
}
