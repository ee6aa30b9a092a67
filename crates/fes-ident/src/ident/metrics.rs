//! Error measures (thesis 5.3, eq. B.8) and the validity weight each unit gets from the
//! training data (pitfall (d)).
//!
//! - Training MSPE: one-step-ahead prediction (eq. B.4) on the training records; defined for
//!   ARX structures only (a state-space network's state is not measured).
//! - Training / test MSSE: free-run simulation from rest (eq. B.6/B.7) of every record.
//!
//! All three are eq. B.8 over every base-period sample of the records concatenated (the
//! normalised force), the model output interpolated to the base period when the model runs
//! at a longer period (5.3).

use super::problem::{Horizon, ModelData, ProblemError, run_record_base};
use fes_model::model::arx::ArxUnit;
use fes_model::model::lmn::Lmn;
use fes_model::model::network::Network;
use fes_model::model::scheduling::Scheduler;
use fes_model::model::simulate::{mse, predict};
use fes_model::model::validity::MAX_UNITS;
use fes_model::num::Dual;

/// Warn when a unit gets less than this share of the training data's validity weight.
pub const MIN_UNIT_SHARE: f64 = 0.02;

/// The three error measures of 5.3.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Metrics {
    /// Training MSPE (ARX structures only).
    pub train_mspe: Option<f64>,
    /// Training MSSE (may be infinite if the simulation diverges).
    pub train_msse: f64,
    /// Test MSSE (may be infinite if the simulation diverges).
    pub test_msse: f64,
}

/// Eq. B.8 of the horizon's output over all records (infinite if it diverges).
pub fn mean_squared_error(net: &Network<f64>, data: &ModelData, horizon: Horizon) -> f64 {
    let mut y = Vec::with_capacity(data.base_samples());
    let mut yh = Vec::with_capacity(data.base_samples());
    for rec in &data.records {
        match run_record_base(net, rec, horizon, data.factor) {
            Ok(o) => yh.extend(o),
            Err(_) => return f64::INFINITY,
        }
        y.extend_from_slice(&rec.y_base);
    }
    match mse(&y, &yh) {
        Ok(v) if v.is_finite() => v,
        _ => f64::INFINITY,
    }
}

/// Training MSPE (ARX only), training MSSE and test MSSE of a model.
pub fn evaluate(lmn: &Lmn, train: &ModelData, test: &ModelData) -> Result<Metrics, ProblemError> {
    let net = lmn.network().map_err(|e| ProblemError::Param(e.into()))?;
    let train_mspe = (!lmn.structure().is_state_space())
        .then(|| mean_squared_error(&net, train, Horizon::Prediction));
    Ok(Metrics {
        train_mspe,
        train_msse: mean_squared_error(&net, train, Horizon::Simulation),
        test_msse: mean_squared_error(&net, test, Horizon::Simulation),
    })
}

/// How much of the training data a unit covers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UnitWeight {
    /// The unit.
    pub unit: usize,
    /// sum_k rho_i(phi_k) / (number of samples): its share of the total validity weight.
    pub share: f64,
    /// max_k rho_i(phi_k).
    pub peak: f64,
}

/// rho_i(phi_k) for every unit, record and model-period sample, with phi as the network
/// computes it on the measured data (input scheduling: the prefilter on the delayed input;
/// output scheduling: the measured output one sample earlier). Obtained from the network's
/// own step: a probe network whose unit i has offset d_i = a dual variable and nothing
/// else outputs sum_i rho_i d_i, so d y / d d_i = rho_i.
pub fn validity_weights(
    template: &Lmn,
    data: &ModelData,
) -> Result<Vec<Vec<Vec<f64>>>, ProblemError> {
    let m = template.units();
    let scheduler = Scheduler::new(&template.scheduling, template.ts)
        .map_err(|e| ProblemError::Param(fes_model::model::lmn::LmnError::Scheduling(e).into()))?;
    let units: Vec<ArxUnit<Dual<MAX_UNITS>>> = (0..m)
        .map(|i| {
            let mut u = ArxUnit::zero();
            u.d = Dual::variable(0.0, i);
            u
        })
        .collect();
    let validity = template.validity.cast(|_, k| Dual::constant(k));
    let probe = Network::arx(template.ts, template.delay, validity, scheduler, 1, &units)
        .map_err(|e| ProblemError::Param(e.into()))?;
    let mut out = vec![Vec::with_capacity(data.records.len()); m];
    for rec in &data.records {
        let mut y = vec![Dual::constant(0.0); rec.u.len()];
        predict(&probe, &rec.u, &rec.y, &mut y)?;
        for (i, o) in out.iter_mut().enumerate() {
            o.push(y.iter().map(|v| v.d[i]).collect());
        }
    }
    Ok(out)
}

/// Each unit's share and peak of the validity weight ([`validity_weights`]).
pub fn unit_weights(weights: &[Vec<Vec<f64>>]) -> Vec<UnitWeight> {
    weights
        .iter()
        .enumerate()
        .map(|(unit, recs)| {
            let n: usize = recs.iter().map(|r| r.len()).sum();
            let sum: f64 = recs.iter().flatten().sum();
            let peak = recs.iter().flatten().fold(0.0f64, |a, &v| a.max(v));
            UnitWeight {
                unit,
                share: if n > 0 { sum / n as f64 } else { 0.0 },
                peak,
            }
        })
        .collect()
}
