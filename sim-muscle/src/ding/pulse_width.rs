//! The pulse-width variant of the Ding model (Ding et al. 2007): the force scaling factor
//! grows with the pulse duration as more motor units are recruited.

use serde::{Deserialize, Serialize};

use super::params::{ParamError, positive};

/// Recruitment by pulse width, Ding et al. 2007: `A(PD) = a_scale (1 - exp(-(PD - PD0)/PDt))`,
/// normalised here so that the reference (supramaximal) width gives exactly the base
/// model's `A`: the gain is `A(PD)/A(ref_us)`, 0 below `pd0_us`, and at most 1 because a
/// supramaximal pulse already recruits every motor unit (thesis 5.1.1).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PulseWidthParams {
    /// Pulse duration below which no motor unit is recruited, us (paper: 131.405 us).
    pub pd0_us: f64,
    /// Recruitment time constant over pulse duration, us (paper: 194.138 us).
    pub pdt_us: f64,
    /// The supramaximal reference width at which the base model applies, us (thesis: 200).
    pub ref_us: f64,
}

impl Default for PulseWidthParams {
    fn default() -> Self {
        Self::DING_2007
    }
}

impl PulseWidthParams {
    /// PD0 and PDt as tabulated for Ding et al. 2007 (human quadriceps; values as
    /// reproduced by the cocofest implementation), reference 200 us (thesis 5.1).
    pub const DING_2007: PulseWidthParams = PulseWidthParams {
        pd0_us: 131.405,
        pdt_us: 194.138,
        ref_us: 200.0,
    };

    /// Checks ranges: all positive and the reference above the threshold.
    pub fn validate(&self) -> Result<(), ParamError> {
        positive("pd0_us", self.pd0_us)?;
        positive("pdt_us", self.pdt_us)?;
        positive("ref_us", self.ref_us)?;
        if self.ref_us <= self.pd0_us {
            return Err(ParamError::OutOfRange {
                name: "ref_us",
                value: self.ref_us,
                requirement: "must exceed pd0_us (the reference pulse must recruit)",
            });
        }
        Ok(())
    }

    /// The activation gain of a pulse of `width_us`: `A(width)/A(ref)`, clamped to [0, 1].
    pub fn gain(&self, width_us: f64) -> f64 {
        if width_us <= self.pd0_us || width_us.is_nan() {
            return 0.0;
        }
        let recruit = |pd: f64| 1.0 - (-(pd - self.pd0_us) / self.pdt_us).exp();
        (recruit(width_us) / recruit(self.ref_us)).min(1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The reference width gives exactly the base model (gain 1); the threshold gives 0;
    /// a width halfway up follows the published exponential.
    #[test]
    fn gain_is_normalised_at_reference() {
        let p = PulseWidthParams::DING_2007;
        assert_eq!(p.gain(200.0), 1.0);
        assert_eq!(p.gain(500.0), 1.0);
        assert_eq!(p.gain(131.0), 0.0);
        let w = 131.405 + 30.0;
        let expected =
            (1.0 - (-30.0f64 / 194.138).exp()) / (1.0 - (-(200.0 - 131.405) / 194.138f64).exp());
        assert!((p.gain(w) - expected).abs() < 1e-15);
        assert!(p.gain(w) > 0.0 && p.gain(w) < 1.0);
    }
}
