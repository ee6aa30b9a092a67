//! What the pattern generator knows of the reference ahead: the setpoint changes already
//! scheduled (a cardiac profile's next contraction: its onset, level, ramps and end), and
//! the target `r` they give tick by tick.
//!
//! The reference of a cardiac profile is a train of square waves whose timing comes from
//! the heart rate and whose amplitude comes from the outer controller (thesis ch. 1): both
//! are known at least a contraction ahead. A [`Preview`] carries them as setpoint changes,
//! each taking effect at a tick offset from now and reached by the same slew as rt-core's
//! reference tracker applies ([`slew`]), so that [`Preview::sample`] gives exactly the
//! targets the tracker will hand to the generator, if nothing unscheduled happens.
//!
//! An operator's unscheduled change has no preview: the supervisor then announces none
//! and the generator decides causally.

/// Most setpoint changes a preview holds (a contraction in progress, then two more:
/// the current setpoint, its end, and two onsets with their ends).
pub const MAX_PREVIEW_POINTS: usize = 8;

/// One announced setpoint of the reference.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PreviewPoint {
    /// Ticks from the current one at which the setpoint takes effect (0: in effect now).
    pub at: u32,
    /// The setpoint, normalised force in `[0, 1]`.
    pub force: f64,
    /// Largest slope of the target towards `force`, normalised force per second; 0 is a
    /// step.
    pub rate_per_s: f64,
}

/// Why a preview was refused.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum PreviewError {
    /// More points than [`MAX_PREVIEW_POINTS`].
    #[error("{0} preview points; at most {MAX_PREVIEW_POINTS}")]
    TooMany(usize),
    /// The first point must be the setpoint in effect now (`at` = 0).
    #[error("the first preview point takes effect at tick {0}, not now (0)")]
    FirstNotNow(u32),
    /// Points must take effect at strictly increasing ticks.
    #[error("preview point {index} takes effect at tick {at}, not after the previous one")]
    NotIncreasing {
        /// The point.
        index: usize,
        /// Its tick offset.
        at: u32,
    },
    /// A force outside `[0, 1]` or not finite.
    #[error("preview point {index}: force {force} is outside [0, 1]")]
    Force {
        /// The point.
        index: usize,
        /// Its force.
        force: f64,
    },
    /// A rate outside `[0, 1000]` per second or not finite.
    #[error("preview point {index}: rate {rate} /s is outside [0, 1000]")]
    Rate {
        /// The point.
        index: usize,
        /// Its rate.
        rate: f64,
    },
}

/// The setpoints known ahead, from the one in effect now (module docs). Fixed-size and
/// `Copy`: it travels in every tick's input.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Preview {
    len: u8,
    points: [PreviewPoint; MAX_PREVIEW_POINTS],
}

impl Preview {
    /// No preview: the generator decides causally.
    pub const NONE: Preview = Preview {
        len: 0,
        points: [PreviewPoint {
            at: 0,
            force: 0.0,
            rate_per_s: 0.0,
        }; MAX_PREVIEW_POINTS],
    };

    /// A preview of `points`, the first in effect now; validated.
    pub fn new(points: &[PreviewPoint]) -> Result<Self, PreviewError> {
        if points.len() > MAX_PREVIEW_POINTS {
            return Err(PreviewError::TooMany(points.len()));
        }
        let mut out = Self::NONE;
        for (index, p) in points.iter().enumerate() {
            if index == 0 && p.at != 0 {
                return Err(PreviewError::FirstNotNow(p.at));
            }
            if index > 0 && p.at <= points[index - 1].at {
                return Err(PreviewError::NotIncreasing { index, at: p.at });
            }
            if !(p.force.is_finite() && (0.0..=1.0).contains(&p.force)) {
                return Err(PreviewError::Force {
                    index,
                    force: p.force,
                });
            }
            if !(p.rate_per_s.is_finite() && (0.0..=1000.0).contains(&p.rate_per_s)) {
                return Err(PreviewError::Rate {
                    index,
                    rate: p.rate_per_s,
                });
            }
            out.points[index] = *p;
        }
        out.len = points.len() as u8;
        Ok(out)
    }

    /// True when nothing is known ahead.
    pub fn is_none(&self) -> bool {
        self.len == 0
    }

    /// The announced setpoints, the first in effect now.
    pub fn points(&self) -> &[PreviewPoint] {
        &self.points[..self.len as usize]
    }

    /// Whether a setpoint above zero takes effect within `ticks` from now (the one in
    /// effect now included): a contraction is running or announced to start that soon.
    /// False without a preview.
    pub fn contraction_within(&self, ticks: u32) -> bool {
        self.points().iter().any(|p| p.at <= ticks && p.force > 0.0)
    }

    /// The targets of the ticks `0..r.len()` from now: `r[0] = target_now` (the target in
    /// use this tick), then each tick's target slewed towards the setpoint in effect at it
    /// by that setpoint's rate ([`slew`], `ts` seconds per tick), as rt-core's tracker
    /// moves it; `rest[j]` is true where the setpoint is zero (the target is at or on its
    /// way to rest, where the generator never fires). `rest[0] = resting_now`. Returns
    /// false (and fills nothing) without a preview.
    pub fn sample(
        &self,
        target_now: f64,
        resting_now: bool,
        ts: f64,
        r: &mut [f64],
        rest: &mut [bool],
    ) -> bool {
        let points = self.points();
        if points.is_empty() || r.is_empty() || rest.len() < r.len() {
            return false;
        }
        r[0] = target_now;
        rest[0] = resting_now;
        let mut p = 0usize;
        for j in 1..r.len() {
            while p + 1 < points.len() && points[p + 1].at as usize <= j {
                p += 1;
            }
            let sp = points[p];
            r[j] = slew(r[j - 1], sp.force, sp.rate_per_s, ts);
            rest[j] = sp.force == 0.0;
        }
        true
    }
}

/// Moves `from` towards `to` by at most `rate_per_s * dt_s`; a rate of 0 means "at once".
/// The reference tracker's ramp (rt-core) and the preview's sampling share it.
#[inline]
pub fn slew(from: f64, to: f64, rate_per_s: f64, dt_s: f64) -> f64 {
    if rate_per_s <= 0.0 {
        return to;
    }
    let step = rate_per_s * dt_s;
    if to > from {
        (from + step).min(to)
    } else {
        (from - step).max(to)
    }
}
