//! [`ReferenceTracker`]: turns received [`Reference`] messages into the target r(t) of each
//! tick: it holds the newest valid reference, applies its ramp limit, and ramps the target
//! to zero when the reference goes stale (the supervisor stopped refreshing it).

use fes_model::control::preview::{MAX_PREVIEW_POINTS, Preview, PreviewPoint};
use fes_rt::msg::{Contract, PreviewEdge, Reference, ReferencePreview, ValidationError};

/// How a reference ages. Read from the process configuration; never changed in the loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReferencePolicy {
    /// A reference older than this (by its `t_ns`) is stale, ns.
    pub stale_after_ns: u64,
    /// Rate at which a stale reference's target ramps to zero, normalised force per second
    /// (0 = drop to zero at once).
    pub stale_ramp_per_s: f64,
    /// The loop period, ns: a scheduled edge `t` ns ahead takes effect `ceil(t / tick_ns)`
    /// ticks from now in the preview handed to the generator.
    pub tick_ns: u64,
}

/// Why a received reference was not used.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum ReferenceRejection {
    /// It failed validation.
    #[error("invalid reference: {0}")]
    Invalid(#[from] ValidationError),
    /// Its `seq` is not newer than the one in use (replayed or reordered).
    #[error("reference seq {seq} is not newer than {last_seq}")]
    OutOfOrder {
        /// Received seq.
        seq: u64,
        /// Seq in use.
        last_seq: u64,
    },
    /// Its timestamp lies further in the future than [`ReferenceTracker::FUTURE_TOLERANCE_NS`]
    /// (a clock or stamping fault).
    #[error("reference t_ns {t_ns} lies in the future (now {now_ns})")]
    FromTheFuture {
        /// Received stamp.
        t_ns: u64,
        /// Receive time.
        now_ns: u64,
    },
}

/// The target of one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Target {
    /// Target r, normalised force in [0, 1].
    pub value: f64,
    /// `seq` of the reference in use; 0 = none.
    pub ref_seq: u64,
    /// No valid reference received yet (target 0).
    pub none: bool,
    /// The reference is stale; the target ramps to zero.
    pub stale: bool,
    /// The reference's operator stop is in effect (target 0).
    pub stop: bool,
    /// The target is at or on its way to zero (no reference, a stale one, an operator stop,
    /// or a reference of zero force still ramping down): the pattern generator rests (no
    /// pulse) from the first tick of the ramp, not only once the ramp has reached zero.
    pub resting: bool,
    /// The setpoints scheduled ahead, from the reference in use ([`Preview::NONE`] without a
    /// fresh preview, or while the reference is missing, stale or stopped).
    pub preview: Preview,
}

impl Target {
    /// A target of `value` from a reference in use (tests, tools): resting exactly when the
    /// value is zero.
    pub fn at(value: f64) -> Self {
        Self {
            value,
            ref_seq: 0,
            none: false,
            stale: false,
            stop: false,
            resting: value == 0.0,
            preview: Preview::NONE,
        }
    }
}

/// Holds the reference in use and the ramped target.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReferenceTracker {
    policy: ReferencePolicy,
    current: Option<Reference>,
    preview: Option<ReferencePreview>,
    target: f64,
    last_advance_ns: Option<u64>,
}

impl ReferenceTracker {
    /// Stamps up to this far ahead of the receive time are accepted (a reference issued
    /// between this tick's wake-up and its receive), ns.
    pub const FUTURE_TOLERANCE_NS: u64 = 10_000_000;

    /// A tracker with no reference (target 0).
    pub fn new(policy: ReferencePolicy) -> Self {
        Self {
            policy,
            current: None,
            preview: None,
            target: 0.0,
            last_advance_ns: None,
        }
    }

    /// The newest scheduled edge already due at `now_ns` that the reference in use does not
    /// reflect yet (published before it), from a fresh preview. The supervisor publishes an
    /// edge's Reference after the edge, and on a loaded host by milliseconds; the schedule it
    /// announced is what the reference is now.
    fn due_edge(&self, reference: &Reference, now_ns: u64, grid_ns: u64) -> Option<PreviewEdge> {
        let p = self.preview.as_ref()?;
        if now_ns.saturating_sub(p.t_ns) > self.policy.stale_after_ns {
            return None;
        }
        p.edges()
            .iter()
            .rfind(|e| e.t_ns <= grid_ns && e.t_ns > reference.t_ns)
            .copied()
    }

    /// Offers a received preview at time `now_ns`; a valid, newer one replaces the one kept.
    pub fn offer_preview(
        &mut self,
        preview: &ReferencePreview,
        now_ns: u64,
    ) -> Result<(), ReferenceRejection> {
        preview.validate()?;
        if let Some(current) = &self.preview
            && preview.seq <= current.seq
        {
            return Err(ReferenceRejection::OutOfOrder {
                seq: preview.seq,
                last_seq: current.seq,
            });
        }
        if preview.t_ns > now_ns.saturating_add(Self::FUTURE_TOLERANCE_NS) {
            return Err(ReferenceRejection::FromTheFuture {
                t_ns: preview.t_ns,
                now_ns,
            });
        }
        self.preview = Some(*preview);
        Ok(())
    }

    /// The preview of the tick at `now_ns`: the setpoint in effect now (`force` at `rate`:
    /// the reference, or an edge already due that it does not reflect yet), then every edge
    /// of the kept preview still ahead, at the tick it takes effect (edges on the same tick:
    /// the later wins). None without a fresh preview (no older than `stale_after_ns` at
    /// `now_ns`). The ticks are counted from the grid point `grid_ns` (see
    /// [`Self::advance_on_grid`]).
    fn preview_at(&self, force: f64, rate: f64, now_ns: u64, grid_ns: u64) -> Preview {
        let Some(p) = &self.preview else {
            return Preview::NONE;
        };
        if now_ns.saturating_sub(p.t_ns) > self.policy.stale_after_ns || p.edges().is_empty() {
            return Preview::NONE;
        }
        let tick = self.policy.tick_ns.max(1);
        let mut points = [PreviewPoint::default(); MAX_PREVIEW_POINTS];
        points[0] = PreviewPoint {
            at: 0,
            force,
            rate_per_s: rate,
        };
        let mut n = 1;
        for e in p.edges().iter().filter(|e| e.t_ns > grid_ns) {
            let at = (e.t_ns - grid_ns).div_ceil(tick).min(u32::MAX as u64) as u32;
            let point = PreviewPoint {
                at,
                force: e.force,
                rate_per_s: e.max_rate_per_s,
            };
            if points[n - 1].at == at {
                points[n - 1] = point;
            } else if n < MAX_PREVIEW_POINTS {
                points[n] = point;
                n += 1;
            }
        }
        // Validated on receipt, so this holds; a preview that fails is dropped, not trusted.
        Preview::new(&points[..n]).unwrap_or(Preview::NONE)
    }

    /// Offers a received reference at time `now_ns`; a valid, newer one replaces the one in
    /// use.
    pub fn offer(&mut self, reference: &Reference, now_ns: u64) -> Result<(), ReferenceRejection> {
        reference.validate()?;
        if let Some(current) = &self.current
            && reference.seq <= current.seq
        {
            return Err(ReferenceRejection::OutOfOrder {
                seq: reference.seq,
                last_seq: current.seq,
            });
        }
        if reference.t_ns > now_ns.saturating_add(Self::FUTURE_TOLERANCE_NS) {
            return Err(ReferenceRejection::FromTheFuture {
                t_ns: reference.t_ns,
                now_ns,
            });
        }
        self.current = Some(*reference);
        Ok(())
    }

    /// Moves the target to time `now_ns` and returns it. The target moves towards the
    /// reference's force at most at its `max_rate_per_s` (0: at once); a stale reference
    /// (older than `stale_after_ns`) moves it towards zero at `stale_ramp_per_s`; an operator
    /// stop sets it to zero at once. The elapsed time is measured between calls, so a stall
    /// advances a ramp by the time that really passed. The tick serves the time `now_ns`
    /// (its grid point and wake-up in one: [`Self::advance_on_grid`]).
    pub fn advance(&mut self, now_ns: u64) -> Target {
        self.advance_on_grid(now_ns, now_ns)
    }

    /// [`Self::advance`] for a tick woken at `now_ns` that serves the grid point `grid_ns`
    /// (`<= now_ns`). The schedule is read on the grid: an announced edge takes effect at the
    /// first tick whose grid point is at or after it, and the preview counts its ticks from
    /// the grid point, so the tick an edge is announced for is the tick it takes effect
    /// however late the announcing tick woke. Read from the wake-up time instead, a tick
    /// woken later than the edge's offset within its period (0.2 ms on the process bench,
    /// after a stall) announced the edge one tick early; the planner kept that onset for
    /// the whole contraction and its opening pulse fell on the last tick at rest, where
    /// nothing fires. Staleness and the ramp's elapsed time stay on the wake-up time.
    pub fn advance_on_grid(&mut self, now_ns: u64, grid_ns: u64) -> Target {
        let grid_ns = grid_ns.min(now_ns);
        let dt_s = self
            .last_advance_ns
            .map_or(0.0, |t| now_ns.saturating_sub(t) as f64 * 1e-9);
        self.last_advance_ns = Some(now_ns);
        let Some(reference) = self.current else {
            self.target = 0.0;
            return Target {
                value: 0.0,
                ref_seq: 0,
                none: true,
                stale: false,
                stop: false,
                resting: true,
                preview: Preview::NONE,
            };
        };
        let stale = now_ns.saturating_sub(reference.t_ns) > self.policy.stale_after_ns;
        let stop = reference.is_stop();
        let (desired, rate) = if stop {
            (0.0, 0.0)
        } else if stale {
            (0.0, self.policy.stale_ramp_per_s)
        } else if let Some(e) = self.due_edge(&reference, now_ns, grid_ns) {
            // The schedule's edge is due and its Reference not in yet: follow the schedule,
            // so that a contraction starts and ends when announced, not when the supervisor
            // gets round to publishing it. A stop still wins the moment it arrives.
            (e.force, e.max_rate_per_s)
        } else {
            (reference.force, reference.max_rate_per_s)
        };
        self.target = slew(self.target, desired, rate, dt_s);
        Target {
            value: self.target,
            ref_seq: reference.seq,
            none: false,
            stale,
            stop,
            resting: desired == 0.0,
            preview: if stale || stop {
                Preview::NONE
            } else {
                self.preview_at(desired, rate, now_ns, grid_ns)
            },
        }
    }
}

use fes_model::control::preview::slew;
