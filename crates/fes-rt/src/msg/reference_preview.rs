//! [`ReferencePreview`]: the setpoints the supervisor has scheduled ahead (supervisor ->
//! rt-core).

use iceoryx2::prelude::ZeroCopySend;

use super::service::{Contract, PubSubQos, TOPIC_REFERENCE_PREVIEW};
use super::validate::{ValidationError, in_range, nonzero_seq, reserved_zero};

/// One scheduled change of the reference: from `t_ns` on, the setpoint is `force`, reached
/// at `max_rate_per_s` (the fields of a [`super::Reference`] the supervisor will publish
/// then).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[type_name("fes::PreviewEdge::v1")]
pub struct PreviewEdge {
    /// CLOCK_MONOTONIC time the change takes effect, ns.
    pub t_ns: u64,
    /// The setpoint from then on, normalised force in [0, 1].
    pub force: f64,
    /// Largest slope of the target towards it, normalised force per second, in [0, 1000].
    pub max_rate_per_s: f64,
}

/// What the reference will do: the profile's scheduled setpoint changes after `t_ns`, in
/// time order (a cardiac profile: the running contraction's end and the next beats' onsets
/// and ends, thesis ch. 1: their timing comes from the heart rate, their level from the
/// outer loop). `len = 0` announces nothing (no profile, disarmed, or an operator's
/// unscheduled setpoint): rt-core then decides causally.
///
/// The supervisor publishes it beside every [`super::Reference`]; rt-core uses the newest
/// valid one while it is no older than its reference staleness age.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("fes::ReferencePreview::v1")]
pub struct ReferencePreview {
    /// Sequence number, 1, 2, ... per publisher; must increase.
    pub seq: u64,
    /// CLOCK_MONOTONIC time the preview was issued, ns.
    pub t_ns: u64,
    /// `seq` of the [`super::Reference`] published with it.
    pub ref_seq: u64,
    /// Edges in use, `0..=MAX_EDGES`.
    pub len: u32,
    /// Zero.
    pub reserved: [u8; 4],
    /// The edges, `edges[..len]` strictly after `t_ns` and in increasing time; the rest zero.
    pub edges: [PreviewEdge; ReferencePreview::MAX_EDGES],
}

impl ReferencePreview {
    /// Most edges one preview carries (a contraction's end and two beats).
    pub const MAX_EDGES: usize = 6;

    /// A preview of `edges` (at most [`Self::MAX_EDGES`]; more are cut).
    pub fn new(seq: u64, t_ns: u64, ref_seq: u64, edges: &[PreviewEdge]) -> Self {
        let len = edges.len().min(Self::MAX_EDGES);
        let mut out = Self {
            seq,
            t_ns,
            ref_seq,
            len: len as u32,
            reserved: [0; 4],
            edges: [PreviewEdge::default(); Self::MAX_EDGES],
        };
        out.edges[..len].copy_from_slice(&edges[..len]);
        out
    }

    /// The edges in use (all of them when `len` is out of range: validate first).
    pub fn edges(&self) -> &[PreviewEdge] {
        &self.edges[..(self.len as usize).min(Self::MAX_EDGES)]
    }
}

impl Contract for ReferencePreview {
    const TOPIC: &'static str = TOPIC_REFERENCE_PREVIEW;
    /// One commander, as for the reference: the two travel together.
    const QOS: PubSubQos = <super::Reference as Contract>::QOS;

    fn validate(&self) -> Result<(), ValidationError> {
        nonzero_seq(self.seq)?;
        nonzero_seq(self.ref_seq)?;
        if self.len as usize > Self::MAX_EDGES {
            return Err(ValidationError::IntOutOfRange {
                field: "len",
                value: self.len.into(),
                min: 0,
                max: Self::MAX_EDGES as u64,
            });
        }
        reserved_zero("reserved", &self.reserved)?;
        let mut after = self.t_ns;
        for (i, e) in self.edges.iter().enumerate() {
            if i >= self.len as usize {
                let zero = e.t_ns == 0 && e.force.to_bits() == 0 && e.max_rate_per_s.to_bits() == 0;
                if !zero {
                    return Err(ValidationError::Inconsistent(
                        "an unused preview edge is not zero",
                    ));
                }
                continue;
            }
            if e.t_ns <= after {
                return Err(ValidationError::TimestampOrder {
                    earlier: if i == 0 { "t_ns" } else { "edges[i-1].t_ns" },
                    earlier_ns: after,
                    later: "edges[i].t_ns",
                    later_ns: e.t_ns,
                });
            }
            after = e.t_ns;
            in_range("edges[].force", e.force, 0.0, 1.0)?;
            in_range(
                "edges[].max_rate_per_s",
                e.max_rate_per_s,
                0.0,
                super::Reference::MAX_RATE_PER_S,
            )?;
        }
        Ok(())
    }
}
