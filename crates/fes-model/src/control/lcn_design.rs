//! Design of a whole Local Controller Network from a Local Model Network (thesis 3.3,
//! 6.5.3): every state-space local model gets its own controller (and, for the
//! measured-force mode, its own estimator), from a per-unit rise time and damping.

use serde::{Deserialize, Serialize};

use crate::model::Network;

use super::design::{
    ClosedLoopPoles, DesignError, DesignOptions, EstimatorPoles, LocalGains, design_controller,
    design_estimator,
};
use super::poles::{Pole, RiseTimeRule, SpecError, default_third_pole, dominant_pair_by};
use alloc::vec::Vec;

/// The thesis's damping factor: `xi = 1.2`, no overshoot (6.5.3).
pub const THESIS_DAMPING: f64 = 1.2;

/// Closed-loop specification of one local controller (6.5.3).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct UnitSpec {
    /// Rise time `t_r` in seconds.
    pub rise_time_s: f64,
    /// Damping factor `xi`.
    pub damping: f64,
    /// Third (integrator) pole, delta domain, 1/s (thesis: `-1.9/Ts`).
    pub p3: Pole,
}

impl UnitSpec {
    /// The thesis's choice for a rise time: `xi = 1.2`, `p3 = -1.9/Ts`.
    pub fn thesis(rise_time_s: f64, ts: f64) -> Self {
        Self {
            rise_time_s,
            damping: THESIS_DAMPING,
            p3: default_third_pole(ts),
        }
    }

    /// One specification per rise time (seconds), all with the same damping and `p3`.
    pub fn for_rise_times(rise_times_s: &[f64], damping: f64, p3: Pole) -> Vec<Self> {
        rise_times_s
            .iter()
            .map(|&rise_time_s| Self {
                rise_time_s,
                damping,
                p3,
            })
            .collect()
    }

    /// The three closed-loop poles: the dominant pair from `t_r, xi` by `rule` and `p3`.
    pub fn poles(&self, rule: RiseTimeRule, ts: f64) -> Result<ClosedLoopPoles, SpecError> {
        let [p1, p2] = dominant_pair_by(rule, self.rise_time_s, self.damping, ts)?;
        Ok(ClosedLoopPoles {
            p1,
            p2,
            p3: self.p3,
        })
    }
}

/// The design of one local controller: specification, poles and gains (one column of
/// thesis Tables 6.1/6.2), and the estimator gain when one was designed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UnitDesign {
    /// The specification.
    pub spec: UnitSpec,
    /// The placed poles.
    pub poles: ClosedLoopPoles,
    /// The controller gains.
    pub gains: LocalGains,
    /// The local estimator gain `L_i` (eq. C.21), if estimator poles were given.
    pub estimator_gain: Option<[f64; 2]>,
}

/// Why an LCN could not be designed.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum LcnDesignError {
    /// The network's local models are ARX; the state-feedback LCN needs state-space ones.
    #[error(
        "the model's local models are ARX; the LCN needs state-space local models \
         (structure ss-direct, ss-eig-local or ss-eig-common)"
    )]
    NotStateSpace,
    /// One specification per unit is needed.
    #[error("{specs} controller specifications given for {units} local models")]
    UnitMismatch {
        /// Specifications given.
        specs: usize,
        /// Units of the model.
        units: usize,
    },
    /// A specification is invalid.
    #[error("unit {unit}: {source}")]
    Spec {
        /// Unit index.
        unit: usize,
        /// What is wrong.
        source: SpecError,
    },
    /// The local design failed.
    #[error(transparent)]
    Design(#[from] DesignError),
}

/// Design the local controllers (and estimators, if `estimator` is given) for every unit
/// of a state-space network, unit `i` from `specs[i]`.
pub fn design_lcn(
    net: &Network<f64>,
    specs: &[UnitSpec],
    estimator: Option<&EstimatorPoles>,
    opts: &DesignOptions,
) -> Result<Vec<UnitDesign>, LcnDesignError> {
    let units = net.units();
    if specs.len() != units {
        return Err(LcnDesignError::UnitMismatch {
            specs: specs.len(),
            units,
        });
    }
    let ts = net.ts();
    let mut out = Vec::with_capacity(units);
    for (i, spec) in specs.iter().enumerate() {
        let m = net.ss_unit(i).ok_or(LcnDesignError::NotStateSpace)?;
        let poles = spec
            .poles(opts.rise_time_rule, ts)
            .map_err(|source| LcnDesignError::Spec { unit: i, source })?;
        let gains = design_controller(i, m, &poles, ts, opts)?;
        let estimator_gain = estimator
            .map(|ep| design_estimator(i, m, ep, ts, opts))
            .transpose()?;
        out.push(UnitDesign {
            spec: *spec,
            poles,
            gains,
            estimator_gain,
        });
    }
    Ok(out)
}
