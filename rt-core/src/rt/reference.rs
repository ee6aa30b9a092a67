//! [`ReferenceTracker`]: turns received [`Reference`] messages into the target r(t) of each
//! tick: it holds the newest valid reference, applies its ramp limit, and ramps the target
//! to zero when the reference goes stale (the supervisor stopped refreshing it).

use crate::msg::{Contract, Reference, ValidationError};

/// How a reference ages. Read from the process configuration; never changed in the loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReferencePolicy {
    /// A reference older than this (by its `t_ns`) is stale, ns.
    pub stale_after_ns: u64,
    /// Rate at which a stale reference's target ramps to zero, normalised force per second
    /// (0 = drop to zero at once).
    pub stale_ramp_per_s: f64,
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
        }
    }
}

/// Holds the reference in use and the ramped target.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReferenceTracker {
    policy: ReferencePolicy,
    current: Option<Reference>,
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
            target: 0.0,
            last_advance_ns: None,
        }
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
    /// advances a ramp by the time that really passed.
    pub fn advance(&mut self, now_ns: u64) -> Target {
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
            };
        };
        let stale = now_ns.saturating_sub(reference.t_ns) > self.policy.stale_after_ns;
        let stop = reference.is_stop();
        let (desired, rate) = if stop {
            (0.0, 0.0)
        } else if stale {
            (0.0, self.policy.stale_ramp_per_s)
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
        }
    }
}

/// Moves `from` towards `to` by at most `rate * dt_s`; a rate of 0 means "at once".
fn slew(from: f64, to: f64, rate: f64, dt_s: f64) -> f64 {
    if rate <= 0.0 {
        return to;
    }
    let step = rate * dt_s;
    if to > from {
        (from + step).min(to)
    } else {
        (from - step).max(to)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    fn tracker() -> ReferenceTracker {
        ReferenceTracker::new(ReferencePolicy {
            stale_after_ns: 100 * MS,
            stale_ramp_per_s: 2.0,
        })
    }

    #[test]
    fn no_reference_means_zero_target() {
        let mut t = tracker();
        let target = t.advance(5 * MS);
        assert!(target.none);
        assert_eq!(target.value, 0.0);
    }

    #[test]
    fn a_step_reference_applies_at_once_and_a_ramp_follows_its_rate() {
        let mut t = tracker();
        t.offer(&Reference::new(1, MS, 0.5), MS).unwrap();
        assert_eq!(t.advance(MS).value, 0.5);
        let mut r = Reference::new(2, 2 * MS, 1.0);
        r.max_rate_per_s = 10.0; // 0.01 per ms
        t.offer(&r, 2 * MS).unwrap();
        for k in 1..=50u64 {
            let v = t.advance(MS + k * MS).value;
            let expect = (0.5 + 0.01 * k as f64).min(1.0);
            assert!((v - expect).abs() < 1e-12, "k={k}: {v} vs {expect}");
        }
    }

    /// A reference of zero force reached by a ramp: the target is resting from the first
    /// tick of the ramp down (the pattern generator then fires no pulse while the force is
    /// to fall), and not while it ramps up.
    #[test]
    fn a_ramp_down_to_zero_is_resting_from_its_first_tick() {
        let mut t = tracker();
        let mut up = Reference::new(1, MS, 0.4);
        up.max_rate_per_s = 50.0;
        t.offer(&up, MS).unwrap();
        let first = t.advance(MS);
        assert!(!first.resting && first.value == 0.0, "{first:?}");
        let rising = t.advance(2 * MS);
        assert!(!rising.resting && rising.value > 0.0, "{rising:?}");
        for k in 3..20 {
            t.advance(k * MS);
        }
        let mut down = Reference::new(2, 20 * MS, 0.0);
        down.max_rate_per_s = 50.0;
        t.offer(&down, 20 * MS).unwrap();
        let ramp = t.advance(21 * MS);
        assert!(ramp.resting && ramp.value > 0.3, "{ramp:?}");
        assert!(Target::at(0.0).resting && !Target::at(0.2).resting);
    }

    #[test]
    fn a_stale_reference_ramps_to_zero_at_the_configured_rate() {
        let mut t = tracker();
        t.offer(&Reference::new(1, 0, 0.8), 0).unwrap();
        assert_eq!(t.advance(0).value, 0.8);
        // Fresh until 100 ms.
        let at_100 = t.advance(100 * MS);
        assert!(!at_100.stale);
        assert_eq!(at_100.value, 0.8);
        // From 101 ms on: 2.0 per second = 0.002 per ms, measured from the last advance.
        let a = t.advance(101 * MS);
        assert!(a.stale);
        assert!((a.value - 0.798).abs() < 1e-12);
        let b = t.advance(201 * MS);
        assert!((b.value - 0.598).abs() < 1e-12);
        let c = t.advance(2_000 * MS);
        assert_eq!(c.value, 0.0);
        // A fresh reference revives it.
        t.offer(&Reference::new(2, 2_000 * MS, 0.3), 2_000 * MS)
            .unwrap();
        let d = t.advance(2_001 * MS);
        assert!(!d.stale);
        assert_eq!(d.value, 0.3);
    }

    #[test]
    fn stop_drops_the_target_at_once() {
        let mut t = tracker();
        t.offer(&Reference::new(1, 0, 0.8), 0).unwrap();
        t.advance(0);
        let mut r = Reference::new(2, MS, 0.8);
        r.flags = Reference::FLAG_STOP;
        t.offer(&r, MS).unwrap();
        let s = t.advance(MS);
        assert!(s.stop);
        assert_eq!(s.value, 0.0);
    }

    #[test]
    fn invalid_old_and_future_references_are_rejected_and_the_last_one_held() {
        let mut t = tracker();
        t.offer(&Reference::new(5, 10 * MS, 0.4), 10 * MS).unwrap();
        assert!(matches!(
            t.offer(&Reference::new(6, 10 * MS, 1.5), 10 * MS),
            Err(ReferenceRejection::Invalid(_))
        ));
        assert!(matches!(
            t.offer(&Reference::new(6, 10 * MS, f64::NAN), 10 * MS),
            Err(ReferenceRejection::Invalid(_))
        ));
        assert_eq!(
            t.offer(&Reference::new(5, 10 * MS, 0.1), 10 * MS),
            Err(ReferenceRejection::OutOfOrder {
                seq: 5,
                last_seq: 5
            })
        );
        assert!(matches!(
            t.offer(&Reference::new(7, 100 * MS, 0.1), 10 * MS),
            Err(ReferenceRejection::FromTheFuture { .. })
        ));
        let held = t.advance(11 * MS);
        assert_eq!((held.value, held.ref_seq), (0.4, 5));
    }
}
