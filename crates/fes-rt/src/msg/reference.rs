//! [`Reference`]: the force the muscle should produce (supervisor -> rt-core).

use iceoryx2::prelude::ZeroCopySend;

use super::service::{Contract, PubSubQos, TOPIC_REFERENCE};
use super::validate::{ValidationError, in_range, known_flags, nonzero_seq, reserved_zero};

/// The command signal r(t) of the pattern generator (thesis Fig. 6.8), normalised force.
///
/// The supervisor must refresh it periodically (a keep-alive, even when unchanged): rt-core
/// treats a reference older than its configured staleness age as lost and ramps the target to
/// zero.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("fes::Reference::v1")]
pub struct Reference {
    /// Sequence number, 1, 2, ... per publisher; must increase.
    pub seq: u64,
    /// CLOCK_MONOTONIC time the reference was issued, ns. Its age drives the staleness check.
    pub t_ns: u64,
    /// Target force, normalised to the muscle's maximum, in [0, 1].
    pub force: f64,
    /// Largest slope of the target towards `force`, normalised force per second; 0 means a
    /// step (no ramp). In [0, 1000].
    pub max_rate_per_s: f64,
    /// [`Reference::FLAG_STOP`] or 0.
    pub flags: u32,
    /// Zero.
    pub reserved: [u8; 4],
}

impl Reference {
    /// Operator stop: the target drops to zero at once, whatever `force` says.
    pub const FLAG_STOP: u32 = 1 << 0;
    /// All flags defined in v1.
    pub const KNOWN_FLAGS: u32 = Self::FLAG_STOP;
    /// Largest accepted ramp rate, normalised force per second.
    pub const MAX_RATE_PER_S: f64 = 1000.0;

    /// A reference with no ramp and no flags.
    pub fn new(seq: u64, t_ns: u64, force: f64) -> Self {
        Self {
            seq,
            t_ns,
            force,
            max_rate_per_s: 0.0,
            flags: 0,
            reserved: [0; 4],
        }
    }

    /// True when [`Reference::FLAG_STOP`] is set.
    pub fn is_stop(&self) -> bool {
        self.flags & Self::FLAG_STOP != 0
    }
}

impl Contract for Reference {
    const TOPIC: &'static str = TOPIC_REFERENCE;
    const QOS: PubSubQos = PubSubQos {
        // One commander: a second publisher (another process of the same user) is refused
        // at creation, so only the supervisor sends References.
        max_publishers: 1,
        max_subscribers: 8,
        subscriber_buffer: 8,
        history: 1,
        max_loaned_samples: 2,
    };

    fn validate(&self) -> Result<(), ValidationError> {
        nonzero_seq(self.seq)?;
        in_range("force", self.force, 0.0, 1.0)?;
        in_range(
            "max_rate_per_s",
            self.max_rate_per_s,
            0.0,
            Self::MAX_RATE_PER_S,
        )?;
        known_flags("flags", self.flags.into(), Self::KNOWN_FLAGS.into())?;
        reserved_zero("reserved", &self.reserved)
    }
}
