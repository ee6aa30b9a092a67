//! The summary document (`--json`): one object per load condition with the figures of one
//! `rt-latency` run, and the worst ratios over the conditions.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, bail};
use fes_latency::Percentiles;
use serde::{Deserialize, Serialize};

/// Schema tag of the summary.
pub const SUMMARY_SCHEMA: &str = "fes-latency-summary/1";

/// How `driver_forward_us` is measured (`driver_forward_note`): this host has no CAN.
pub const DRIVER_FORWARD_METHOD: &str = "driver-latency (fes-latency): the stim-driver's own \
forward and report threads, SCHED_FIFO one below rt-core on the probe's core, with the CAN \
socket replaced by a Unix SOCK_SEQPACKET pair (one send per frame) to sim-muscle's virtual \
stimulator on the other core; StimTick publish -> PULSE written (hlog tag tick_to_can)";

/// The load conditions the suite measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Condition {
    /// Nothing besides the machine's own background.
    NoLoad,
    /// `stress-ng --cpu 1` on the other core (`rt-latency --load`).
    Load,
}

impl Condition {
    /// Its key in the summary and the baseline.
    pub fn key(self) -> &'static str {
        match self {
            Condition::NoLoad => "no_load",
            Condition::Load => "load",
        }
    }
}

/// One condition's figures: what `rt-latency --json` wrote (the fields the suite uses),
/// plus the driver forward path.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ConditionSummary {
    /// Ticks the loop ran.
    pub ticks: u64,
    /// Skipped periods.
    pub misses: u64,
    /// Wake-ups at least one period late.
    pub overruns: u64,
    /// Wake-up lateness (deadline to wake-up).
    pub wake_us: Percentiles,
    /// The tick source's compute time.
    pub compute_us: Percentiles,
    /// Publish to receive, measured by the subscriber process.
    pub ipc_us: Percentiles,
    /// Driver forward path (StimTick published to PULSE written); `None` when not measured.
    #[serde(default)]
    pub driver_forward_us: Option<Percentiles>,
    /// The driver's counters over the rounds (rt-latency's `driver`: ticks, pulses written
    /// and refused, stimulator-applied pulses, trips, re-arms, hot-path allocations).
    #[serde(default)]
    pub driver: Option<serde_json::Value>,
    /// cyclictest's latency on the same core, priority and period, in the same run.
    pub cyclictest_us: Option<Percentiles>,
    /// Wake-up lateness p99 over cyclictest's.
    pub ratio_p99: Option<f64>,
    /// Wake-up lateness p99.9 over cyclictest's.
    pub ratio_p999: Option<f64>,
    /// The median over the rounds of each round's wake-up p99 over the same round's
    /// cyclictest p99 (rounds are adjacent in time: a burst of host noise that falls on
    /// one side of one round moves one of them, not the median).
    #[serde(default)]
    pub ratio_p99_round_median: Option<f64>,
    /// cyclictest's sample count.
    pub cyclictest_samples: u64,
    /// cyclictest's samples at least one period late.
    pub cyclictest_over_period: u64,
    /// Heap allocations on the loop's hot path.
    pub hot_path_allocations: u64,
    /// Ticks the probe process did not receive.
    pub probe_lost: u64,
    /// Receiving references.
    pub input_us: Percentiles,
    /// Loan, send, notify.
    pub publish_us: Percentiles,
    /// Seconds of rt-core (and as many of cyclictest).
    pub seconds: u64,
    /// Alternating rounds.
    pub rounds: u64,
    /// The background load, if any.
    pub load: Option<String>,
    /// cyclictest's exact command line (one round).
    pub cyclictest_command: Option<String>,
}

impl ConditionSummary {
    /// Reads `rt-latency --json` output.
    pub fn from_rt_latency_json(path: &Path) -> anyhow::Result<Self> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let value: serde_json::Value =
            serde_json::from_str(&text).with_context(|| format!("{}: not JSON", path.display()))?;
        if !value.is_object() {
            bail!("{}: not a JSON object", path.display());
        }
        serde_json::from_value(value)
            .with_context(|| format!("{}: not an rt-latency result", path.display()))
    }
}

/// A measurement that failed the gate and was not confirmed by the next one (or was,
/// when the condition's last measurement fails too).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Unconfirmed {
    /// The condition.
    pub condition: Condition,
    /// Which measurement of it (1 = the first).
    pub attempt: u32,
    /// The checks it failed.
    pub failed: Vec<String>,
    /// Where its files were kept.
    pub dir: String,
}

/// The whole summary.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Summary {
    /// [`SUMMARY_SCHEMA`].
    pub schema: String,
    /// Per condition (`no_load`, `load`), those measured.
    pub conditions: BTreeMap<Condition, ConditionSummary>,
    /// The largest `ratio_p99` over the conditions.
    pub ratio_p99: Option<f64>,
    /// The largest `ratio_p999` over the conditions.
    pub ratio_p999: Option<f64>,
    /// How `driver_forward_us` was measured ([`DRIVER_FORWARD_METHOD`]).
    pub driver_forward_note: Option<String>,
    /// Measurements that failed the gate and were measured again (`--confirm`); the
    /// conditions above are the last measurement of each, the one judged.
    #[serde(default)]
    pub unconfirmed: Vec<Unconfirmed>,
    /// `FES_TEST_TICK_BUSY_US` when the test-only slowdown was on.
    pub test_slowdown_us: Option<u64>,
    /// Kernel release.
    pub kernel: String,
    /// `/proc/loadavg` before and after.
    pub load_average: [String; 2],
    /// UTC time of the start.
    pub started: String,
    /// The command that produced it.
    pub command: String,
}

impl Summary {
    /// Reads a summary written by this program.
    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let s: Summary = serde_json::from_str(&text)
            .with_context(|| format!("{}: not a latency summary", path.display()))?;
        if s.schema != SUMMARY_SCHEMA {
            bail!(
                "{}: schema {:?}, expected {SUMMARY_SCHEMA:?}",
                path.display(),
                s.schema
            );
        }
        if s.conditions.is_empty() {
            bail!("{}: no condition was measured", path.display());
        }
        Ok(s)
    }

    /// The worst (largest) of a ratio over the conditions; `None` if any is missing.
    pub fn worst(
        conditions: &BTreeMap<Condition, ConditionSummary>,
        f: impl Fn(&ConditionSummary) -> Option<f64>,
    ) -> Option<f64> {
        conditions
            .values()
            .map(f)
            .try_fold(f64::NEG_INFINITY, |acc, r| r.map(|r| acc.max(r)))
            .filter(|r| r.is_finite())
    }
}
