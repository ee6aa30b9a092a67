//! Prediction-mode estimation (thesis 2.3.2, B.2): linear least squares for ARX local models.
//!
//! With the one-step-ahead predictor (eq. B.4) the measured outputs fill the data vector and
//! phi comes from measured data (input scheduling: the prefilter on the delayed input;
//! output scheduling: y(k-1), eq. 5.1), so the network output is affine in theta:
//! y_hat = y_hat(theta_ref) + Psi (theta - theta_ref) exactly, for any reference theta_ref.
//! Psi is taken from the network's own predictor with `Dual` parameters
//! ([`super::problem::Problem::jacobian`]), so the data vector, delays and start-up
//! conventions are the model's (no second implementation of eq. 2.18/2.24).
//!
//! - **Global learning** (eq. 2.33): one least-squares problem for all units' parameters.
//! - **Local learning** (eq. 2.35): per unit m, the unit's own model (a one-unit network)
//!   fitted with the weights gamma_k = rho_m(phi_k) (eq. B.2 with B.13).
//!
//! Both solve with the SVD ([`super::lsq`]). A unit the data never activate gets no
//! information; with local learning it is given the unweighted (linear) fit instead and
//! reported.

use super::lsq::{self, DEFAULT_RCOND};
use super::metrics::validity_weights;
use super::problem::{Horizon, ModelData, Problem, ThetaMap};
use super::{IdentError, PREDICTION_NEEDS_ARX};
use fes_model::model::lmn::{Lmn, LocalModelSet};
use fes_model::model::params::ParamLayout;
use fes_model::model::validity::ValidityFunctions;

/// Global (eq. 2.33) or local (eq. 2.35) learning.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Learning {
    /// One criterion for all parameters.
    Global,
    /// One weighted criterion per unit.
    Local,
}

/// Least-squares solution of an affine problem: theta = theta_ref + argmin ||r + J d||.
fn affine_solve<M: super::problem::ParamMap>(
    problem: &Problem<'_, M>,
    theta_ref: &[f64],
) -> Result<(Vec<f64>, usize), IdentError> {
    let cols: Vec<usize> = (0..theta_ref.len()).collect();
    let (r, j) = problem.jacobian(theta_ref, &cols)?;
    let sol = lsq::solve(&j, &(-r), DEFAULT_RCOND)?;
    let theta = theta_ref
        .iter()
        .zip(sol.x.iter())
        .map(|(a, b)| a + b)
        .collect();
    Ok((theta, sol.rank))
}

/// Prediction-mode estimate of an ARX network `template` (its current parameters are the
/// reference point; they must define a network with a rest state). Returns theta and the
/// units that had to fall back to the linear fit (local learning).
pub fn fit_prediction(
    template: &Lmn,
    data: &ModelData,
    learning: Learning,
) -> Result<(Vec<f64>, Vec<usize>), IdentError> {
    if template.structure().is_state_space() {
        return Err(IdentError::Conflict {
            option: "mode",
            value: "prediction".into(),
            with: format!("structure {}", template.structure()),
            rule: PREDICTION_NEEDS_ARX,
        });
    }
    let layout = ParamLayout::new(template);
    let theta_ref = layout.theta(template)?;
    match learning {
        Learning::Global => {
            let problem = Problem::new(
                ThetaMap {
                    template,
                    layout: &layout,
                },
                data,
                Horizon::Prediction,
            );
            Ok((affine_solve(&problem, &theta_ref)?.0, Vec::new()))
        }
        Learning::Local => {
            let m = template.units();
            let weights = validity_weights(template, data)?;
            // The one-unit model of each local model (same structure, Ts, delay).
            let mut single = template.clone();
            single.validity = ValidityFunctions::uniform(1, 0.0, 1.0)
                .map_err(fes_model::model::params::ParamError::from)?;
            single.local = first_unit(&template.local);
            let layout1 = ParamLayout::new(&single);
            let ref1 = layout1.theta(&single)?;
            let map = ThetaMap {
                template: &single,
                layout: &layout1,
            };
            let linear =
                affine_solve(&Problem::new(map.clone(), data, Horizon::Prediction), &ref1)?.0;
            let rows: f64 = data.records.iter().map(|r| r.u.len()).sum::<usize>() as f64;
            let mut theta = theta_ref.clone();
            let mut fallback = Vec::new();
            for (unit, w) in weights.iter().enumerate().take(m) {
                let total: f64 = w.iter().flatten().sum();
                let theta_m = if total < 1e-6 * rows {
                    fallback.push(unit);
                    linear.clone()
                } else {
                    let problem = Problem {
                        map: map.clone(),
                        data,
                        horizon: Horizon::Prediction,
                        weights: Some(w),
                        prior: None,
                    };
                    affine_solve(&problem, &ref1)?.0
                };
                theta[layout.unit_range(unit)].copy_from_slice(&theta_m);
            }
            Ok((theta, fallback))
        }
    }
}

/// The first unit of a local model set as a one-unit set.
fn first_unit(set: &LocalModelSet) -> LocalModelSet {
    super::start::replicate(set, 1, 0)
}
