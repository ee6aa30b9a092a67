//! [`FeedbackTracker`]: the newest valid measured force, for the feedback mode of the
//! pattern generator (thesis Fig. 6.6(a)); too old a sample is not used.

use fes_rt::msg::{Contract, ForceSample, ValidationError};

/// Why a received force sample was not used.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum FeedbackRejection {
    /// It failed validation.
    #[error("invalid force sample: {0}")]
    Invalid(#[from] ValidationError),
    /// Its `seq` is not newer than the one held.
    #[error("force sample seq {seq} is not newer than {last_seq}")]
    OutOfOrder {
        /// Received seq.
        seq: u64,
        /// Seq held.
        last_seq: u64,
    },
}

/// Holds the newest valid [`ForceSample`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FeedbackTracker {
    max_age_ns: u64,
    latest: Option<ForceSample>,
}

impl FeedbackTracker {
    /// A tracker that uses samples no older than `max_age_ns`.
    pub fn new(max_age_ns: u64) -> Self {
        Self {
            max_age_ns,
            latest: None,
        }
    }

    /// Offers a received sample.
    pub fn offer(&mut self, sample: &ForceSample) -> Result<(), FeedbackRejection> {
        sample.validate()?;
        if let Some(latest) = &self.latest
            && sample.seq <= latest.seq
        {
            return Err(FeedbackRejection::OutOfOrder {
                seq: sample.seq,
                last_seq: latest.seq,
            });
        }
        self.latest = Some(*sample);
        Ok(())
    }

    /// The measured normalised force at `now_ns`, if a fresh enough sample is held.
    pub fn measured(&self, now_ns: u64) -> Option<f64> {
        self.latest
            .filter(|s| now_ns.saturating_sub(s.t_ns) <= self.max_age_ns)
            .map(|s| s.force)
    }
}
