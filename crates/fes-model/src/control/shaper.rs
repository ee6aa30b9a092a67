//! The pulse shaper (thesis 6.5.2, eq. 6.7-6.8): turns the continuous control signal
//! `u_cont` into a train of supramaximal pulses.
//!
//! Semantics, per sample `k`:
//!
//! 1. `u = u_cont[k]` if it is finite (and, with [`ShaperSum::Clamped`], non-negative),
//!    else `u = 0` (counted in [`ShaperStats::rejected_inputs`]).
//! 2. `E += u` — the energy since the last pulse, eq. (6.8).
//! 3. A pulse fires when `E >= eta` and at least `min_gap` empty samples have passed since
//!    the last pulse (thesis: `k > lp + 1`, i.e. `min_gap = 1`, a pulse is always followed
//!    by a zero). Firing **restarts the sum at zero** (thesis 6.5.2: "the sum ... since the
//!    last pulse"); the remainder `E - eta` is counted in [`ShaperStats::dropped`].
//! 4. `E` is capped at `e_max` while the gap holds a pulse back; the excess is counted in
//!    [`ShaperStats::discarded`].
//!
//! With the counters the energy balance of eq. (6.7) is exact at every sample:
//! `sum u = pulses * eta + E + dropped + discarded` (up to rounding).
//!
//! Why restart and not carry the remainder over (this module carried it until 2026-11-22):
//! carrying keeps `sum u = pulses * eta + E` but, when `u_cont` rises steeply before a
//! pulse (it does, once per inter-pulse interval, at the LCN's plateau), `E` overshoots
//! `eta` by most of one sample's input and the carried remainder fires a second pulse
//! `min_gap + 1` samples later: a spurious doublet in the middle of a plateau, which the
//! fatigued muscle answers with 20 % more force than the model predicts (docs/bench.md,
//! "Fatigue and the outer loop"). Restarting gives doublets only where `u_cont >= eta`
//! per sample, i.e. at a large error (thesis Phase a, 6.5.4).
//!
//! **Rest:** [`PulseShaper::rest`] holds the shaper at a zero reference: no pulse, `E`
//! cleared (counted in `dropped`). The pattern generator calls it whenever the reference
//! is zero, so no pulse is ever delivered while the muscle is to be at rest (the LCN's
//! integrator can still drive `u_cont > 0` for tens of ms after the reference fell) and
//! every contraction starts from the same shaper state.
//!
//! **Sum rule** ([`ShaperSum`]). The thesis sums `u_cont` as it is (eq. 6.8,
//! [`ShaperSum::Signed`]): while the force is above the reference the control signal is
//! negative, `E` falls below zero and the next pulse comes later, so the controller can
//! delay a pulse (which a muscle whose single twitch overshoots the reference needs to hold
//! a low force). With [`ShaperSum::Clamped`] the LCN's output is clamped at zero before
//! the shaper (`u_cont = max(u_raw, 0)`), `E` never falls and a pulse can only be hastened.
//! A negative `E` is never a hazard: it only postpones the next pulse.
//!
//! **Safety property: no catch-up burst.** After any period of saturation (or a stall
//! upstream that made `u_cont` huge) at most one pulse follows once the input falls to
//! zero: the banked energy is capped at `e_max` and a pulse restarts it at zero.

use serde::{Deserialize, Serialize};

/// What the shaper sums (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ShaperSum {
    /// The control signal as it is, negative values included (thesis eq. 6.8).
    Signed,
    /// The control signal clamped at zero (`u_cont = max(u_raw, 0)`); the rule of
    /// controller files written before the rule was stored.
    #[default]
    Clamped,
}

impl ShaperSum {
    /// The rule of a controller file that does not name one: [`ShaperSum::Clamped`].
    pub const fn legacy() -> Self {
        Self::Clamped
    }
}

/// Settings of the pulse shaper.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShaperConfig {
    /// Energy threshold `eta` for one pulse (eq. 6.8; the thesis uses 1 so that the pulse
    /// train keeps the energy of `u_cont`, eq. 6.7). Default 1.
    pub eta: f64,
    /// Least number of empty samples between two pulses (thesis: 1, so the minimum IPI is
    /// 2 samples). Must be at least 1. Default 1.
    pub min_gap: u32,
    /// Cap on the energy `E` banked while the gap holds a pulse back; must be at least
    /// `eta`. Default `2 eta`.
    pub e_max: f64,
    /// What is summed (default [`ShaperSum::default`]; a file without it was written with
    /// [`ShaperSum::legacy`]).
    #[serde(default = "ShaperSum::legacy")]
    pub sum: ShaperSum,
    /// Floor of `E` under the signed sum, `<= 0` (`None`: unbounded, as eq. 6.8). It
    /// bounds how long a run of negative control signal can postpone the next pulse; the
    /// energy below it is counted in [`ShaperStats::discarded`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub e_min: Option<f64>,
}

impl Default for ShaperConfig {
    fn default() -> Self {
        Self {
            eta: 1.0,
            min_gap: 1,
            e_max: 2.0,
            sum: ShaperSum::default(),
            e_min: None,
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
    /// `e_min` must be finite and at most 0.
    #[error("shaper e_min = {0} must be finite and at most 0")]
    EMin(f64),
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
        if let Some(m) = self.e_min
            && !(m.is_finite() && m <= 0.0)
        {
            return Err(ShaperConfigError::EMin(m));
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
    /// Energy dropped by the `e_max` cap (would otherwise have become a catch-up burst),
    /// plus the (negative) energy cut off by the `e_min` floor.
    pub discarded: f64,
    /// Energy dropped when a pulse restarted the sum (`E - eta` at each pulse) and when
    /// [`PulseShaper::rest`] cleared it.
    pub dropped: f64,
    /// Inputs that were not finite (or, with [`ShaperSum::Clamped`], negative) and were
    /// treated as 0.
    pub rejected_inputs: u64,
}

/// The pulse shaper of eq. (6.7)-(6.8). Fixed size, `Copy`; `step` never allocates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PulseShaper {
    config: ShaperConfig,
    /// Energy since the last pulse, `E` (eq. 6.8).
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

    /// Present energy since the last pulse, `E`, at most `e_max` (and at least 0 with
    /// [`ShaperSum::Clamped`]).
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

    /// One sample at a zero reference (rest): no pulse, `E` cleared into
    /// [`ShaperStats::dropped`]; the gap keeps counting.
    pub fn rest(&mut self) {
        self.stats.dropped += self.energy;
        self.energy = 0.0;
        self.empty_since_pulse = self.empty_since_pulse.saturating_add(1);
    }

    /// One sample: accumulate `u_cont` and decide whether to fire a pulse now.
    pub fn step(&mut self, u_cont: f64) -> bool {
        let accepted = match self.config.sum {
            ShaperSum::Signed => u_cont.is_finite(),
            ShaperSum::Clamped => u_cont.is_finite() && u_cont >= 0.0,
        };
        let u = if accepted {
            u_cont
        } else {
            self.stats.rejected_inputs += 1;
            0.0
        };
        self.energy += u;
        let pulse = self.energy >= self.config.eta && self.empty_since_pulse >= self.config.min_gap;
        if pulse {
            self.stats.dropped += self.energy - self.config.eta;
            self.energy = 0.0;
            self.empty_since_pulse = 0;
            self.stats.pulses += 1;
        } else {
            self.empty_since_pulse = self.empty_since_pulse.saturating_add(1);
        }
        if self.energy > self.config.e_max {
            self.stats.discarded += self.energy - self.config.e_max;
            self.energy = self.config.e_max;
        }
        if let Some(m) = self.config.e_min
            && self.energy < m
        {
            self.stats.discarded += self.energy - m;
            self.energy = m;
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
    fn firing_restarts_the_sum_the_gap_blocks_and_the_cap_discards() {
        let mut s = PulseShaper::new(ShaperConfig::default()).unwrap();
        assert!(s.step(10.0)); // E = 10 -> fire -> restart at 0, 9 dropped
        assert_eq!(s.energy(), 0.0);
        assert_eq!(s.stats().dropped, 9.0);
        assert!(!s.step(10.0)); // gap: E = 10 -> cap 2, 8 discarded
        assert_eq!((s.energy(), s.stats().discarded), (2.0, 8.0));
        assert!(s.step(0.0)); // E = 2 -> fire -> 0, 1 more dropped
        assert_eq!(s.stats().dropped, 10.0);
        assert!((0..10).all(|_| !s.step(0.0))); // nothing left: no burst
    }

    #[test]
    fn constant_input_fires_every_ceil_eta_over_u_samples() {
        // u = 0.3: E = 0.3, 0.6, 0.9, 1.2 -> fire, dropping 0.2 each time.
        let mut s = PulseShaper::new(ShaperConfig::default()).unwrap();
        let fired: Vec<usize> = (0..20).filter(|_| s.step(0.3)).collect();
        assert_eq!(fired, [3, 7, 11, 15, 19]);
        assert!((s.stats().dropped - 5.0 * 0.2).abs() < 1e-12);
    }

    #[test]
    fn rest_clears_the_energy_and_never_fires() {
        let mut s = PulseShaper::new(ShaperConfig::default()).unwrap();
        assert!(!s.step(0.9));
        s.rest();
        assert_eq!(s.energy(), 0.0);
        assert!((s.stats().dropped - 0.9).abs() < 1e-15);
        assert!(!s.step(0.9)); // starts again from zero
        assert!(s.step(0.2));
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
    fn signed_sum_delays_the_next_pulse() {
        let signed = ShaperConfig {
            sum: ShaperSum::Signed,
            ..ShaperConfig::default()
        };
        let mut s = PulseShaper::new(signed).unwrap();
        assert!(s.step(1.0));
        // Force above the reference: the control signal is negative and E falls below 0.
        for _ in 0..4 {
            assert!(!s.step(-0.5));
        }
        assert_eq!(s.energy(), -2.0);
        // E must climb back through 0 to eta: 3 / 0.5 = 6 samples, not 2.
        let fired: Vec<bool> = (0..6).map(|_| s.step(0.5)).collect();
        assert_eq!(fired, [false, false, false, false, false, true]);
        assert_eq!(s.stats().rejected_inputs, 0);
        // The same inputs clamped: negative samples count as zero (and as rejected).
        let mut c = PulseShaper::new(ShaperConfig {
            sum: ShaperSum::Clamped,
            ..signed
        })
        .unwrap();
        assert!(c.step(1.0));
        (0..4).for_each(|_| assert!(!c.step(-0.5)));
        assert_eq!(c.energy(), 0.0);
        assert!(!c.step(0.5));
        assert!(c.step(0.5));
        assert_eq!(c.stats().rejected_inputs, 4);
    }

    #[test]
    fn a_file_without_a_sum_rule_reads_the_legacy_clamp() {
        let c: ShaperConfig =
            serde_json::from_str(r#"{"eta": 1.0, "min_gap": 1, "e_max": 2.0}"#).unwrap();
        assert_eq!(c.sum, ShaperSum::Clamped);
        let c: ShaperConfig =
            serde_json::from_str(r#"{"eta": 1.0, "min_gap": 1, "e_max": 2.0, "sum": "signed"}"#)
                .unwrap();
        assert_eq!(c.sum, ShaperSum::Signed);
        assert!(
            serde_json::from_str::<ShaperConfig>(
                r#"{"eta": 1.0, "min_gap": 1, "e_max": 2.0, "extra": 1}"#
            )
            .is_err()
        );
    }

    #[test]
    fn bad_inputs_count_as_zero() {
        let clamped = ShaperConfig {
            sum: ShaperSum::Clamped,
            ..ShaperConfig::default()
        };
        let mut s = PulseShaper::new(clamped).unwrap();
        for u in [f64::NAN, -1.0, f64::INFINITY, f64::NEG_INFINITY] {
            assert!(!s.step(u));
        }
        assert_eq!(s.energy(), 0.0);
        assert_eq!(s.stats().rejected_inputs, 4);
    }
}
