//! The fatigue extension of the Ding model (Ding, Wexler & Binder-Macleod 2003): A, Km
//! and tau1 drift with the force and recover towards their rested values with tau_fat.

use serde::{Deserialize, Serialize};

use super::params::{DingParams, ParamError, finite, positive};

/// Fatigue coefficients (Ding et al. 2003, eq. 8-11), converted to SI units:
/// - `dA/dt = -(A - A_rest)/tau_fat + alpha_a F`,
/// - `dKm/dt = -(Km - Km_rest)/tau_fat + alpha_km F`,
/// - `dtau1/dt = -(tau1 - tau1_rest)/tau_fat + alpha_tau1 F`,
/// - `R0 = Km + (r0_rest - km_rest)` (the paper's `R0 = Km + 1.04`, with the preset's own
///   offset so a preset's rested R0 is kept).
///
/// The rested values are the force-model parameters the muscle was built with.
///
/// The published coefficients belong to the published muscle ([`DING_2003_MUSCLE`]);
/// [`FatigueParams::for_muscle`] carries them over to another parameter set.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FatigueParams {
    /// Coefficient of A, s^-2 (paper: -4.0e-7 ms^-2 = -0.4 s^-2). Must be <= 0.
    pub alpha_a: f64,
    /// Coefficient of Km, s^-1 N^-1 (paper: 1.9e-8 ms^-1 N^-1 = 1.9e-5 s^-1 N^-1). >= 0.
    pub alpha_km: f64,
    /// Coefficient of tau1, N^-1 (paper: 2.1e-5 N^-1, the same in any time unit). >= 0.
    pub alpha_tau1: f64,
    /// Recovery time constant, s (paper: 127 000 ms = 127 s). > 0.
    pub tau_fat: f64,
}

impl Default for FatigueParams {
    fn default() -> Self {
        Self::DING_2003
    }
}

/// The force-model parameters the fatigue coefficients were identified with (Ding,
/// Wexler & Binder-Macleod 2003, Table 1, human quadriceps; tau2 = 124.4 ms as in Ding et
/// al. 2002), in SI units.
pub const DING_2003_MUSCLE: DingParams = DingParams {
    tauc: 0.020,
    r0: 0.103 + 1.04,
    km: 0.103,
    a: 3009.0,
    tau1: 0.050957,
    tau2: 0.1244,
};

impl FatigueParams {
    /// The published values (Ding, Wexler & Binder-Macleod 2003, Table 1, human
    /// quadriceps), converted from ms to s.
    pub const DING_2003: FatigueParams = FatigueParams {
        alpha_a: -0.4,
        alpha_km: 1.9e-5,
        alpha_tau1: 2.1e-5,
        tau_fat: 127.0,
    };

    /// The published coefficients carried over to a muscle with rested parameters `to`,
    /// so that each parameter drifts by the same *fraction* per newton of force as in
    /// the published muscle ([`DING_2003_MUSCLE`]): `alpha_a` scales with A, `alpha_km`
    /// with Km, and `alpha_tau1` with `tau1 + tau2`, the relaxation time constant at full
    /// activation (CN >> Km), which is what sets a fused contraction's force. For the
    /// published muscle this is the identity. Without it a muscle with a short tau1 (the
    /// `fast` preset) would gain force as it fatigues, because the published tau1 drift
    /// is large next to its tau1.
    pub fn for_muscle(to: &DingParams) -> FatigueParams {
        let from = DING_2003_MUSCLE;
        let p = Self::DING_2003;
        FatigueParams {
            alpha_a: p.alpha_a * to.a / from.a,
            alpha_km: p.alpha_km * to.km / from.km,
            alpha_tau1: p.alpha_tau1 * (to.tau1 + to.tau2) / (from.tau1 + from.tau2),
            tau_fat: p.tau_fat,
        }
    }

    /// Parameter names accepted by [`FatigueParams::get_mut`], with their units.
    pub const NAMES: [(&'static str, &'static str); 4] = [
        ("alpha_a", "1/s^2"),
        ("alpha_km", "1/(s N)"),
        ("alpha_tau1", "1/N"),
        ("tau_fat", "s"),
    ];

    /// Checks signs and ranges (fatigue weakens: A falls, Km and tau1 rise).
    pub fn validate(&self) -> Result<(), ParamError> {
        finite("alpha_a", self.alpha_a)?;
        if self.alpha_a > 0.0 {
            return Err(ParamError::OutOfRange {
                name: "alpha_a",
                value: self.alpha_a,
                requirement: "must be <= 0 (A falls with fatigue)",
            });
        }
        for (name, value) in [("alpha_km", self.alpha_km), ("alpha_tau1", self.alpha_tau1)] {
            finite(name, value)?;
            if value < 0.0 {
                return Err(ParamError::OutOfRange {
                    name,
                    value,
                    requirement: "must be >= 0 (rises with fatigue)",
                });
            }
        }
        positive("tau_fat", self.tau_fat)
    }

    /// Returns a mutable reference to the coefficient called `name`, if there is one.
    pub fn get_mut(&mut self, name: &str) -> Option<&mut f64> {
        match name {
            "alpha_a" => Some(&mut self.alpha_a),
            "alpha_km" => Some(&mut self.alpha_km),
            "alpha_tau1" => Some(&mut self.alpha_tau1),
            "tau_fat" => Some(&mut self.tau_fat),
            _ => None,
        }
    }

    /// The coefficients as (name, value) pairs, in the order of [`FatigueParams::NAMES`].
    pub fn entries(&self) -> [(&'static str, f64); 4] {
        [
            ("alpha_a", self.alpha_a),
            ("alpha_km", self.alpha_km),
            ("alpha_tau1", self.alpha_tau1),
            ("tau_fat", self.tau_fat),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Carrying the coefficients over to the published muscle changes nothing; to a muscle
    /// with twice A, Km and tau1 + tau2 doubles each coefficient (exact ratios).
    #[test]
    fn transfer_is_identity_on_published_muscle() {
        let same = FatigueParams::for_muscle(&DING_2003_MUSCLE);
        assert_eq!(same, FatigueParams::DING_2003);
        let m = DingParams {
            a: 2.0 * DING_2003_MUSCLE.a,
            km: 2.0 * DING_2003_MUSCLE.km,
            tau1: 2.0 * DING_2003_MUSCLE.tau1,
            tau2: 2.0 * DING_2003_MUSCLE.tau2,
            ..DING_2003_MUSCLE
        };
        let t = FatigueParams::for_muscle(&m);
        let d = FatigueParams::DING_2003;
        assert!((t.alpha_a / d.alpha_a - 2.0).abs() < 1e-12);
        assert!((t.alpha_km / d.alpha_km - 2.0).abs() < 1e-12);
        assert!((t.alpha_tau1 / d.alpha_tau1 - 2.0).abs() < 1e-12);
        assert_eq!(t.tau_fat, d.tau_fat);
    }
}
