//! [`TimingReport`]: latency percentiles and counters of a real-time loop (rt-core,
//! stim-driver, probes -> supervisor).

use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

use super::service::{Contract, PubSubQos, TOPIC_TIMING};
use super::validate::{ValidationError, known_flags, nonzero_seq, u8_enum};

u8_enum! {
    /// Who sent a [`TimingReport`].
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
    pub enum TimingSource: "source" {
        /// The rt-core pattern generator.
        RtCore = 1,
        /// The stimulator driver.
        StimDriver = 2,
        /// The virtual muscle / stimulator.
        SimMuscle = 3,
        /// A measurement probe (rt-probe).
        Probe = 4,
    }
}

/// Percentiles of one latency distribution, nanoseconds (from an HdrHistogram with 3
/// significant digits). All zero when `count` is 0.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend, Serialize, Deserialize)]
#[type_name("fes::LatencySummary::v1")]
pub struct LatencySummary {
    /// Number of values recorded.
    pub count: u64,
    /// Median, ns.
    pub p50_ns: u64,
    /// 99th percentile, ns.
    pub p99_ns: u64,
    /// 99.9th percentile, ns.
    pub p999_ns: u64,
    /// Largest value, ns.
    pub max_ns: u64,
}

impl LatencySummary {
    fn validate(&self, field: &'static str) -> Result<(), ValidationError> {
        let ordered = self.p50_ns <= self.p99_ns
            && self.p99_ns <= self.p999_ns
            && self.p999_ns <= self.max_ns;
        let empty_is_zero =
            self.count > 0 || (self.p50_ns | self.p99_ns | self.p999_ns | self.max_ns) == 0;
        if ordered && empty_is_zero {
            Ok(())
        } else {
            Err(ValidationError::Inconsistent(match field {
                "wake" => "wake percentiles not ordered (or non-zero with count 0)",
                "input" => "input percentiles not ordered (or non-zero with count 0)",
                "compute" => "compute percentiles not ordered (or non-zero with count 0)",
                "publish" => "publish percentiles not ordered (or non-zero with count 0)",
                _ => "ipc percentiles not ordered (or non-zero with count 0)",
            }))
        }
    }
}

/// Cumulative timing of a real-time loop since it started, published periodically by its
/// telemetry thread (never by the real-time thread itself). Its JSON form (serde) is what
/// rt-probe keeps of rt-core's last report in its summary.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend, Serialize, Deserialize)]
#[type_name("fes::TimingReport::v2")]
pub struct TimingReport {
    /// Sequence number, 1, 2, ... per publisher.
    pub seq: u64,
    /// CLOCK_MONOTONIC time of this report, ns.
    pub t_ns: u64,
    /// Ticks executed (wake-ups).
    pub ticks: u64,
    /// Periods skipped because a wake-up came a whole period or more late (deadline misses).
    pub misses: u64,
    /// Ticks that were preceded by at least one skipped period.
    pub overruns: u64,
    /// Telemetry records dropped because the queue to the telemetry thread was full.
    pub queue_overflows: u64,
    /// Heap allocations made by the real-time thread after start-up (must be 0; see
    /// [`TimingReport::FLAG_ALLOCATIONS_UNCOUNTED`]).
    pub hot_path_allocations: u64,
    /// Received inputs rejected by validation (or out of order).
    pub rejected_inputs: u64,
    /// Wake-up lateness: wake time minus deadline.
    pub wake: LatencySummary,
    /// Input time: wake to inputs taken (references and force samples received, checked).
    pub input: LatencySummary,
    /// Compute time: inputs taken to decision made (the tick source, e.g. the pattern
    /// generator).
    pub compute: LatencySummary,
    /// Publish time: decision made to sample sent (and listeners notified).
    pub publish: LatencySummary,
    /// Publish-to-receive latency (filled by receivers; count 0 otherwise).
    pub ipc: LatencySummary,
    /// A [`TimingSource`] as `u8`.
    pub source: u8,
    /// `TimingReport::FLAG_*` bits.
    pub flags: u8,
    /// The prescription the sender enforces: the first 6 bytes of its file's SHA-256, all
    /// zero for none (a probe, the virtual stimulator). The supervisor refuses to arm
    /// while rt-core's or stim-driver's differs from its own: one prescription across the
    /// stack, also after a restart of some processes only (v2; v1 had zero here).
    pub prescription: [u8; 6],
}

impl TimingReport {
    /// Last report of this run (the loop has stopped).
    pub const FLAG_FINAL: u8 = 1 << 0;
    /// The loop runs without some real-time guarantee (best-effort mode).
    pub const FLAG_DEGRADED: u8 = 1 << 1;
    /// No counting allocator is installed: `hot_path_allocations` means nothing.
    pub const FLAG_ALLOCATIONS_UNCOUNTED: u8 = 1 << 2;
    /// All flags defined in v1.
    pub const KNOWN_FLAGS: u8 = (1 << 3) - 1;

    /// The sender, decoded.
    pub fn source(&self) -> Result<TimingSource, ValidationError> {
        TimingSource::try_from(self.source)
    }
}

impl Contract for TimingReport {
    const TOPIC: &'static str = TOPIC_TIMING;
    const QOS: PubSubQos = PubSubQos::status_report(8);

    fn validate(&self) -> Result<(), ValidationError> {
        nonzero_seq(self.seq)?;
        self.source()?;
        known_flags("flags", self.flags.into(), Self::KNOWN_FLAGS.into())?;
        if self.overruns > self.misses || self.overruns > self.ticks {
            return Err(ValidationError::Inconsistent(
                "overruns exceed misses or ticks",
            ));
        }
        self.wake.validate("wake")?;
        self.input.validate("input")?;
        self.compute.validate("compute")?;
        self.publish.validate("publish")?;
        self.ipc.validate("ipc")
    }
}
