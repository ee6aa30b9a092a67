//! [`PulseOutcome`]: what the driver did with one pulse decision, and then what the
//! stimulator did with it (stim-driver -> supervisor), so that a recording says what was
//! decided, what was sent and what was applied, not only what was decided.

use iceoryx2::prelude::ZeroCopySend;

use super::service::{Contract, PubSubQos, TOPIC_PULSE_OUTCOME};
use super::validate::{ValidationError, int_in_range, nonzero_seq, reserved_zero};
use crate::code_enum::code_enum;

/// The driver's outcome for one StimTick that fired a pulse: sent to the stimulator, or not
/// and why. Published for every such tick the driver received, in tick order; for a pulse
/// sent, a second outcome follows once the stimulator has accounted for it
/// ([`PulseFate::Applied`] or [`PulseFate::NotApplied`]), these too in tick order.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend)]
#[type_name("fes::PulseOutcome::v3")]
pub struct PulseOutcome {
    /// Sequence number, 1, 2, ... per publisher.
    pub seq: u64,
    /// CLOCK_MONOTONIC time of the driver's decision, ns.
    pub t_ns: u64,
    /// `seq` of the StimTick whose pulse this is.
    pub tick_seq: u64,
    /// Grid time of that StimTick, ns.
    pub tick_t_ns: u64,
    /// A [`PulseFate`] as `u8`.
    pub fate: u8,
    /// Reserved, zero.
    pub reserved: [u8; 7],
}

code_enum! {
    /// What became of a pulse decision.
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    pub enum PulseFate {
        /// Written to the stimulator as a PULSE frame.
        Sent = 1,
        /// Refused by the driver's interlocks (late, minimum IPI, rate, ceilings, a stream
        /// fault): not sent, reported.
        Refused = 2,
        /// The driver was not armed: not sent.
        NotArmed = 3,
        /// The frame could not be written (the bus): not sent.
        NotWritten = 4,
        /// The transport was still waiting for the stimulator's answer to its previous
        /// command (ScienceMode 2 is stop-and-wait) beyond the driver's lateness bound, or a
        /// newer pulse decision took its place: not sent.
        Late = 5,
        /// A pulse sent earlier: the stimulator counted it as applied (its STATUS pulse count,
        /// in the order the pulses were written; a RehaStim 2's SinglePulse acknowledgement).
        Applied = 6,
        /// A pulse sent earlier that the stimulator did not apply: it rejected it (EMCY naming
        /// the pulse, a busy answer), or no STATUS counted it within the driver's confirmation
        /// window (a lost frame, a stimulator that stopped).
        NotApplied = 7,
    }
}

impl TryFrom<u8> for PulseFate {
    type Error = ValidationError;

    fn try_from(v: u8) -> Result<Self, ValidationError> {
        Self::from_code(v).ok_or(ValidationError::IntOutOfRange {
            field: "fate",
            value: u64::from(v),
            min: 1,
            max: 7,
        })
    }
}

impl PulseFate {
    /// The name written into recordings.
    pub const fn name(self) -> &'static str {
        match self {
            PulseFate::Sent => "sent",
            PulseFate::Refused => "refused",
            PulseFate::NotArmed => "not_armed",
            PulseFate::NotWritten => "not_written",
            PulseFate::Late => "late",
            PulseFate::Applied => "applied",
            PulseFate::NotApplied => "not_applied",
        }
    }

    /// Whether this is the stimulator's account of a pulse sent earlier (the second
    /// outcome of that tick), not the driver's decision on it.
    pub const fn is_confirmation(self) -> bool {
        matches!(self, PulseFate::Applied | PulseFate::NotApplied)
    }
}

impl PulseOutcome {
    /// The outcome `fate` of tick `tick_seq` (grid time `tick_t_ns`), decided at `t_ns`.
    pub const fn new(seq: u64, t_ns: u64, tick_seq: u64, tick_t_ns: u64, fate: PulseFate) -> Self {
        Self {
            seq,
            t_ns,
            tick_seq,
            tick_t_ns,
            fate: fate as u8,
            reserved: [0; 7],
        }
    }

    /// The fate, decoded.
    pub fn fate(&self) -> Result<PulseFate, ValidationError> {
        PulseFate::try_from(self.fate)
    }
}

impl Contract for PulseOutcome {
    const TOPIC: &'static str = TOPIC_PULSE_OUTCOME;
    const QOS: PubSubQos = PubSubQos {
        // The driver alone says what it sent.
        max_publishers: 1,
        max_subscribers: 8,
        // A second of pulses at the 500 Hz ceiling, two outcomes each (sent, then applied):
        // the recorder's thread may be descheduled for hundreds of ms.
        subscriber_buffer: 1024,
        history: 0,
        max_loaned_samples: 2,
    };

    fn validate(&self) -> Result<(), ValidationError> {
        nonzero_seq(self.seq)?;
        nonzero_seq(self.tick_seq)?;
        int_in_range("fate", u64::from(self.fate), 1, 7)?;
        reserved_zero("reserved", &self.reserved)
    }
}
