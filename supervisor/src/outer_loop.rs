//! The outer loop (thesis Controller 1, slow): corrects the reference amplitude of the
//! cardiac profile, beat by beat, so that the *measured* contraction reaches the target.
//!
//! The inner loop (rt-core's LCN) makes the *model* force follow the reference; the
//! muscle differs from its model (identification error, fatigue, electrode changes), so
//! the measured contraction does not follow exactly. Per beat k, with target `A` (the
//! operator's amplitude) and measured plateau mean `c_k` ([`crate::contraction`]):
//!
//! ```text
//! e_k     = A - c_k
//! g_{k+1} = clamp(g_k + clamp(K e_k, -s, s), max(-m, -A), min(m, A_max - A))
//! a_{k+1} = A + g_{k+1}
//! ```
//!
//! a discrete integrator with gain `K` per beat (slow: its time constant is about `1/K`
//! beats, several seconds, against the inner loop's tens of milliseconds), its step
//! limited to `s` per beat (rate limit) and its correction bounded by `m` and by the
//! reference range `[0, A_max]` (bounded output, no windup). A beat without a valid
//! measurement leaves the correction unchanged; so does a beat in which the stimulator
//! driver refused a pulse ([`crate::core::SupervisorCore`] passes no measurement): the
//! muscle did not get the train the inner loop planned, so its error is not a model
//! mismatch, and integrating it would overshoot the beats after. Switched off, the correction is zero and
//! the reference amplitude is the target.

use serde::{Deserialize, Serialize};

use crate::range::{self, Interval, RangeError};

/// Outer-loop settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OuterLoopSettings {
    /// Active at start-up. Default true.
    pub enabled: bool,
    /// Integral gain K per beat, in (0, 1]. Default 0.3.
    pub gain: f64,
    /// Largest correction |g|, normalised force, in [0, 1]. Default 0.4.
    pub max_correction: f64,
    /// Largest change of the correction per beat, normalised force, in (0, 1]. Default 0.03.
    pub max_step: f64,
}

impl Default for OuterLoopSettings {
    fn default() -> Self {
        Self {
            enabled: true,
            gain: 0.3,
            max_correction: 0.4,
            max_step: 0.03,
        }
    }
}

impl OuterLoopSettings {
    /// Checks the ranges; the error names the key.
    pub fn validate(&self) -> Result<(), RangeError> {
        range::check("gain", self.gain, Interval::left_open(0.0, 1.0))?;
        range::check(
            "max_correction",
            self.max_correction,
            Interval::closed(0.0, 1.0),
        )?;
        range::check("max_step", self.max_step, Interval::left_open(0.0, 1.0))
    }
}

/// One update of the outer loop.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct OuterLoopUpdate {
    /// Target amplitude A.
    pub target: f64,
    /// Measured contraction c_k, if valid.
    pub measured: Option<f64>,
    /// Error A - c_k (0 when not measured).
    pub error: f64,
    /// Correction after the update.
    pub correction: f64,
    /// Reference amplitude for the next beat.
    pub amplitude: f64,
}

/// The outer loop's state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OuterLoop {
    settings: OuterLoopSettings,
    enabled: bool,
    correction: f64,
    updates: u64,
    skipped: u64,
}

impl OuterLoop {
    /// A loop with zero correction, on or off as configured.
    pub fn new(settings: OuterLoopSettings) -> Self {
        Self {
            settings,
            enabled: settings.enabled,
            correction: 0.0,
            updates: 0,
            skipped: 0,
        }
    }

    /// Whether the loop corrects.
    pub fn enabled(&self) -> bool {
        self.enabled
    }

    /// Switches the loop on or off; off resets the correction.
    pub fn set_enabled(&mut self, on: bool) {
        self.enabled = on;
        if !on {
            self.correction = 0.0;
        }
    }

    /// Current correction g.
    pub fn correction(&self) -> f64 {
        self.correction
    }

    /// Beats used / skipped (no valid measurement).
    pub fn counts(&self) -> (u64, u64) {
        (self.updates, self.skipped)
    }

    /// Forgets the correction (new profile, re-arm).
    pub fn reset(&mut self) {
        self.correction = 0.0;
    }

    /// The reference amplitude for target `target` with the reference ceiling `max_force`.
    pub fn amplitude(&self, target: f64, max_force: f64) -> f64 {
        (target + self.correction).clamp(0.0, max_force)
    }

    /// Updates the correction with the contraction `measured` of a beat whose target was
    /// `target`, and returns the amplitude for the next beat.
    pub fn update(
        &mut self,
        target: f64,
        measured: Option<f64>,
        max_force: f64,
    ) -> OuterLoopUpdate {
        let s = self.settings;
        let mut error = 0.0;
        match measured {
            Some(c) if self.enabled && c.is_finite() => {
                error = target - c;
                let step = (s.gain * error).clamp(-s.max_step, s.max_step);
                let lo = (-s.max_correction).max(-target);
                let hi = s.max_correction.min(max_force - target);
                self.correction = (self.correction + step).clamp(lo.min(0.0), hi.max(0.0));
                self.updates += 1;
            }
            Some(c) if c.is_finite() => error = target - c,
            _ => self.skipped += 1,
        }
        OuterLoopUpdate {
            target,
            measured,
            error,
            correction: self.correction,
            amplitude: self.amplitude(target, max_force),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against a static plant c = p a (a muscle producing p times what is asked), the loop
    /// converges to a = A/p; the error then decays geometrically with ratio (1 - K p)
    /// once the step limit no longer binds (closed form of the integrator).
    #[test]
    fn converges_on_a_static_gain_mismatch_at_the_closed_form_rate() {
        let settings = OuterLoopSettings {
            max_step: 1.0,
            ..Default::default()
        };
        let mut ol = OuterLoop::new(settings);
        let (target, p) = (0.4, 0.8);
        let mut a = target;
        let mut errors = Vec::new();
        for _ in 0..80 {
            let u = ol.update(target, Some(p * a), 1.0);
            errors.push(u.error);
            a = u.amplitude;
        }
        assert!((a - target / p).abs() < 1e-6, "a = {a}");
        for w in errors.windows(2).skip(1) {
            if w[0].abs() > 1e-6 {
                assert!((w[1] / w[0] - (1.0 - 0.3 * p)).abs() < 1e-9);
            }
        }
    }

    /// The step limit and the bounds hold whatever the measurement says; off means no
    /// correction; a missing measurement changes nothing.
    #[test]
    fn bounded_rate_limited_and_switchable() {
        let mut ol = OuterLoop::new(OuterLoopSettings::default());
        let u = ol.update(0.5, Some(0.0), 1.0);
        assert!((u.correction - 0.03).abs() < 1e-15);
        for _ in 0..100 {
            ol.update(0.5, Some(0.0), 0.8);
        }
        assert!((ol.correction() - 0.3).abs() < 1e-12, "{}", ol.correction());
        assert!((ol.amplitude(0.5, 0.8) - 0.8).abs() < 1e-12);
        let before = ol.correction();
        let u = ol.update(0.5, None, 0.8);
        assert_eq!(u.correction, before);
        assert_eq!(ol.counts().1, 1);
        for _ in 0..100 {
            ol.update(0.1, Some(1.0), 1.0);
        }
        assert!(ol.correction() >= -0.1 - 1e-12);
        ol.set_enabled(false);
        assert_eq!(ol.correction(), 0.0);
        let u = ol.update(0.5, Some(0.1), 1.0);
        assert_eq!((u.correction, u.amplitude), (0.0, 0.5));
        assert!((u.error - 0.4).abs() < 1e-15);
    }
}
