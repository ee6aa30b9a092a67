//! [`ForceSample`]: one force measurement (stim-driver -> supervisor, rt-core in feedback mode).

use iceoryx2::prelude::ZeroCopySend;

use super::service::{Contract, PubSubQos, TOPIC_FORCE_SAMPLE};
use super::validate::{ValidationError, in_range, nonzero_seq};

/// A force sample y(t) from the transducer (or sim-muscle), every 1 ms.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("fes::ForceSample::v1")]
pub struct ForceSample {
    /// Sequence number, 1, 2, ... per publisher.
    pub seq: u64,
    /// CLOCK_MONOTONIC time of the measurement, ns.
    pub t_ns: u64,
    /// `seq` of the last StimTick the stimulator had applied when it sampled; 0 = none yet.
    pub stim_seq: u64,
    /// Force in newtons (may be slightly negative: transducer offset and noise).
    pub force_n: f64,
    /// Force normalised to the muscle's maximum (nominally [0, 1]; noise may leave it).
    pub force: f64,
}

impl ForceSample {
    /// Accepted range of [`ForceSample::force`]: beyond it the sample is garbage, not noise.
    pub const FORCE_RANGE: (f64, f64) = (-1.0, 2.0);
    /// Accepted range of [`ForceSample::force_n`], newtons.
    pub const FORCE_N_RANGE: (f64, f64) = (-10_000.0, 10_000.0);
}

impl Contract for ForceSample {
    const TOPIC: &'static str = TOPIC_FORCE_SAMPLE;
    const QOS: PubSubQos = PubSubQos {
        max_publishers: 2,
        max_subscribers: 8,
        subscriber_buffer: 64,
        history: 0,
        max_loaned_samples: 2,
    };

    fn validate(&self) -> Result<(), ValidationError> {
        nonzero_seq(self.seq)?;
        let (lo, hi) = Self::FORCE_N_RANGE;
        in_range("force_n", self.force_n, lo, hi)?;
        let (lo, hi) = Self::FORCE_RANGE;
        in_range("force", self.force, lo, hi)
    }
}
