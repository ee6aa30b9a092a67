//! The pulse shaper (thesis 6.5.2, eq. 6.7-6.8): turns the continuous control signal
//! `u_cont` into a train of supramaximal pulses.
//!
//! Semantics, per sample `k`:
//!
//! 1. `u = u_cont[k]` if it is finite and non-negative, else `u = 0` (counted in
//!    [`ShaperStats::rejected_inputs`]).
//! 2. `E += u` — the energy since the last pulse, eq. (6.8), with the remainder of earlier
//!    pulses carried over (see below).
//! 3. A pulse fires when `E >= eta` and at least `min_gap` empty samples have passed since
//!    the last pulse (thesis: `k > lp + 1`, i.e. `min_gap = 1`, a pulse is always followed
//!    by a zero). Firing subtracts `eta` from `E`.
//! 4. `E` is capped at `e_max`; the excess is counted in [`ShaperStats::discarded`].
//!
//! Carrying the remainder (instead of restarting the sum at zero) makes eq. (6.7) hold with
//! equality up to the present energy: at every sample
//! `sum u = pulses * eta + E + discarded` exactly (up to rounding), and with
//! `eta = 1` the pulse count never differs from the integral of `u_cont` by more than the
//! current `E`.
//!
//! **Safety property: no catch-up burst.** While the gap holds back a pulse, undelivered
//! energy is banked only up to `e_max` (default `2 eta`). After any period of saturation
//! (or a stall upstream that made `u_cont` huge) at most `floor(e_max / eta)` pulses
//! follow once the input falls to zero, each still separated by the gap.

use serde::{Deserialize, Serialize};

/// Settings of the pulse shaper.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ShaperConfig {
    /// Energy threshold `eta` for one pulse (eq. 6.8; the thesis uses 1 so that the pulse
    /// train keeps the energy of `u_cont`, eq. 6.7). Default 1.
    pub eta: f64,
    /// Least number of empty samples between two pulses (thesis: 1, so the minimum IPI is
    /// 2 samples). Must be at least 1. Default 1.
    pub min_gap: u32,
    /// Cap on the banked energy `E`; must be at least `eta`. Default `2 eta`.
    pub e_max: f64,
}

impl Default for ShaperConfig {
    fn default() -> Self {
        Self {
            eta: 1.0,
            min_gap: 1,
            e_max: 2.0,
        }
    }
}

/// Invalid shaper settings.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum ShaperConfigError {
    /// `eta` must be finite and positive.
    #[error("shaper eta = {0} is not a finite positive number")]
    Eta(f64),
    /// `min_gap` must be at least 1 (a pulse is always followed by a zero, thesis 6.5.2).
    #[error("shaper min_gap = {0} must be at least 1 (a pulse is always followed by a zero)")]
    MinGap(u32),
    /// `e_max` must be finite and at least `eta`, or no pulse could ever fire.
    #[error("shaper e_max = {e_max} must be finite and at least eta = {eta}")]
    EMax {
        /// The offending cap.
        e_max: f64,
        /// The threshold.
        eta: f64,
    },
}

impl ShaperConfig {
    /// Check the settings.
    pub fn validate(&self) -> Result<(), ShaperConfigError> {
        if !(self.eta.is_finite() && self.eta > 0.0) {
            return Err(ShaperConfigError::Eta(self.eta));
        }
        if self.min_gap < 1 {
            return Err(ShaperConfigError::MinGap(self.min_gap));
        }
        if !(self.e_max.is_finite() && self.e_max >= self.eta) {
            return Err(ShaperConfigError::EMax {
                e_max: self.e_max,
                eta: self.eta,
            });
        }
        Ok(())
    }
}

/// Running counters of the shaper since construction or the last reset.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ShaperStats {
    /// Pulses fired.
    pub pulses: u64,
    /// Energy dropped by the `e_max` cap (would otherwise have become a catch-up burst).
    pub discarded: f64,
    /// Inputs that were negative or not finite and were treated as 0.
    pub rejected_inputs: u64,
}

/// The pulse shaper of eq. (6.7)-(6.8). Fixed size, `Copy`; `step` never allocates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PulseShaper {
    config: ShaperConfig,
    /// Energy since the last pulse, `E` (eq. 6.8), including the carried remainder.
    energy: f64,
    /// Empty samples since the last pulse (saturating; `u32::MAX` before the first pulse).
    empty_since_pulse: u32,
    stats: ShaperStats,
}

impl PulseShaper {
    /// A shaper with validated settings, `E = 0`, ready to fire at once.
    pub fn new(config: ShaperConfig) -> Result<Self, ShaperConfigError> {
        config.validate()?;
        Ok(Self {
            config,
            energy: 0.0,
            empty_since_pulse: u32::MAX,
            stats: ShaperStats::default(),
        })
    }

    /// The settings.
    pub fn config(&self) -> &ShaperConfig {
        &self.config
    }

    /// Present energy since the last pulse, `E`, in `[0, e_max]`.
    pub fn energy(&self) -> f64 {
        self.energy
    }

    /// Counters since construction or the last reset.
    pub fn stats(&self) -> ShaperStats {
        self.stats
    }

    /// Back to the initial state (E = 0, no previous pulse, counters zero).
    pub fn reset(&mut self) {
        self.energy = 0.0;
        self.empty_since_pulse = u32::MAX;
        self.stats = ShaperStats::default();
    }

    /// One sample: accumulate `u_cont` and decide whether to fire a pulse now.
    pub fn step(&mut self, u_cont: f64) -> bool {
        let u = if u_cont.is_finite() && u_cont >= 0.0 {
            u_cont
        } else {
            self.stats.rejected_inputs += 1;
            0.0
        };
        self.energy += u;
        let pulse = self.energy >= self.config.eta && self.empty_since_pulse >= self.config.min_gap;
        if pulse {
            self.energy -= self.config.eta;
            self.empty_since_pulse = 0;
            self.stats.pulses += 1;
        } else {
            self.empty_since_pulse = self.empty_since_pulse.saturating_add(1);
        }
        if self.energy > self.config.e_max {
            self.stats.discarded += self.energy - self.config.e_max;
            self.energy = self.config.e_max;
        }
        pulse
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thesis_example_constant_half_gives_every_second_sample() {
        // u = 0.5 per sample: E reaches 1 every second sample, the gap allows it.
        let mut s = PulseShaper::new(ShaperConfig::default()).unwrap();
        let fired: Vec<bool> = (0..8).map(|_| s.step(0.5)).collect();
        assert_eq!(fired, [false, true, false, true, false, true, false, true]);
    }

    #[test]
    fn gap_blocks_and_cap_discards() {
        let mut s = PulseShaper::new(ShaperConfig::default()).unwrap();
        assert!(s.step(10.0)); // E = 10 -> fire -> 9 -> cap 2, discard 7
        assert_eq!(s.energy(), 2.0);
        assert_eq!(s.stats().discarded, 7.0);
        assert!(!s.step(0.0)); // gap
        assert!(s.step(0.0)); // E = 2 -> 1
        assert!(!s.step(0.0));
        assert!(s.step(0.0)); // E = 1 -> 0
        assert!(!s.step(0.0));
        assert!(!s.step(0.0)); // nothing left: no burst beyond e_max / eta = 2 pulses
    }

    #[test]
    fn rejects_bad_settings() {
        let bad = |c: ShaperConfig| PulseShaper::new(c).unwrap_err();
        let d = ShaperConfig::default();
        assert_eq!(
            bad(ShaperConfig { eta: 0.0, ..d }),
            ShaperConfigError::Eta(0.0)
        );
        assert_eq!(
            bad(ShaperConfig { min_gap: 0, ..d }),
            ShaperConfigError::MinGap(0)
        );
        assert!(matches!(
            bad(ShaperConfig { e_max: 0.5, ..d }),
            ShaperConfigError::EMax { .. }
        ));
        assert!(matches!(
            bad(ShaperConfig { eta: f64::NAN, ..d }),
            ShaperConfigError::Eta(_)
        ));
    }

    #[test]
    fn bad_inputs_count_as_zero() {
        let mut s = PulseShaper::new(ShaperConfig::default()).unwrap();
        for u in [f64::NAN, -1.0, f64::INFINITY, f64::NEG_INFINITY] {
            assert!(!s.step(u));
        }
        assert_eq!(s.energy(), 0.0);
        assert_eq!(s.stats().rejected_inputs, 4);
    }
}
