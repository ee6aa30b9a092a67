//! Validation as the system-identification field reports it, beside the thesis's MSSE
//! (eq. B.8): MATLAB's `compare` fit (NRMSE, %), sysidentpy's RRSE, and MATLAB's `resid`
//! residual tests (autocorrelation of the residuals and their cross-correlation with the
//! input over ±[`RESID_LAGS`] lags, with the 99 % band of a white, independent residual).
//!
//! Definitions (y measured, ŷ simulated, ȳ the mean of y, e = y − ŷ, N samples):
//!
//! - fit = 100 (1 − ‖y − ŷ‖ / ‖y − ȳ‖) (MATLAB `compare`, `goodnessOfFit` `'NRMSE'`);
//! - RRSE = ‖y − ŷ‖ / ‖y − ȳ‖ (sysidentpy `root_relative_squared_error`), so fit = 100 (1 − RRSE);
//! - r_ee(k) = Σ_t e(t) e(t+k) / Σ_t e(t)², k = 0..K;
//!   r_ue(k) = Σ_t u(t) e(t+k) / sqrt(Σ u(t)² Σ e(t)²), k = −K..K, with u and e centred;
//! - the 99 % band: ±2.576 / sqrt(N) (the normal quantile of a white sequence's sample
//!   correlation, as MATLAB's `resid` draws it).
//!
//! Correlations are summed within records only (no product spans two records), which is
//! what concatenating independent experiments requires.

use super::problem::{Horizon, ModelData, run_record, run_record_base};
use fes_model::model::lmn::Lmn;

/// Lags of the residual tests, each side (MATLAB's `resid` default).
pub const RESID_LAGS: usize = 25;
/// The two-sided 99 % quantile of the standard normal distribution.
pub const Z_99: f64 = 2.575_829_303_548_901;

/// ‖y − ŷ‖ / ‖y − ȳ‖ over all samples of the record pairs; `None` when y is constant or
/// the lengths differ.
pub fn rrse(y: &[f64], yh: &[f64]) -> Option<f64> {
    if y.len() != yh.len() || y.is_empty() {
        return None;
    }
    let mean = y.iter().sum::<f64>() / y.len() as f64;
    let err: f64 = y.iter().zip(yh).map(|(a, b)| (a - b) * (a - b)).sum();
    let spread: f64 = y.iter().map(|a| (a - mean) * (a - mean)).sum();
    (spread > 0.0 && err.is_finite()).then(|| (err / spread).sqrt())
}

/// MATLAB's NRMSE fit in percent: 100 (1 − RRSE); 100 is a perfect fit, 0 no better than
/// the mean, negative worse.
pub fn fit_percent(y: &[f64], yh: &[f64]) -> Option<f64> {
    rrse(y, yh).map(|r| 100.0 * (1.0 - r))
}

/// The residual tests of `resid`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Resid {
    /// r_ee(k), k = 0..=K.
    pub autocorr: Vec<f64>,
    /// r_ue(k), k = −K..=K (index k + K).
    pub xcorr: Vec<f64>,
    /// The 99 % band: ±this.
    pub band: f64,
    /// Samples used.
    pub samples: usize,
    /// Lags k ≥ 1 whose |r_ee(k)| is outside the band.
    pub autocorr_outside: usize,
    /// Lags whose |r_ue(k)| is outside the band.
    pub xcorr_outside: usize,
}

/// The residual tests of residuals `e` and inputs `u`, one pair of slices per record,
/// over ±`lags` (see the module documentation). `None` without samples or with a zero
/// residual or input.
pub fn resid(records: &[(&[f64], &[f64])], lags: usize) -> Option<Resid> {
    let n: usize = records.iter().map(|(e, _)| e.len()).sum();
    if n == 0 || records.iter().any(|(e, u)| e.len() != u.len()) {
        return None;
    }
    let (se, su) = records.iter().fold((0.0, 0.0), |(se, su), (e, u)| {
        (se + e.iter().sum::<f64>(), su + u.iter().sum::<f64>())
    });
    let (me, mu) = (se / n as f64, su / n as f64);
    let centred: Vec<(Vec<f64>, Vec<f64>)> = records
        .iter()
        .map(|(e, u)| {
            (
                e.iter().map(|v| v - me).collect(),
                u.iter().map(|v| v - mu).collect(),
            )
        })
        .collect();
    // Σ_t a(t) b(t + k) within records, k may be negative.
    let cross = |k: isize, a_is_u: bool| -> f64 {
        centred
            .iter()
            .map(|(e, u)| {
                let (a, b) = if a_is_u { (u, e) } else { (e, e) };
                let len = a.len() as isize;
                (0..len)
                    .filter(|t| (0..len).contains(&(t + k)))
                    .map(|t| a[t as usize] * b[(t + k) as usize])
                    .sum::<f64>()
            })
            .sum()
    };
    let ee = cross(0, false);
    let uu: f64 = centred.iter().flat_map(|(_, u)| u).map(|v| v * v).sum();
    if ee <= 0.0 || uu <= 0.0 {
        return None;
    }
    let k = lags as isize;
    let autocorr: Vec<f64> = (0..=k).map(|j| cross(j, false) / ee).collect();
    let xcorr: Vec<f64> = (-k..=k)
        .map(|j| cross(j, true) / (ee * uu).sqrt())
        .collect();
    let band = Z_99 / (n as f64).sqrt();
    Some(Resid {
        autocorr_outside: autocorr[1..].iter().filter(|r| r.abs() > band).count(),
        xcorr_outside: xcorr.iter().filter(|r| r.abs() > band).count(),
        autocorr,
        xcorr,
        band,
        samples: n,
    })
}

/// One record's measured and simulated output at the base period.
#[derive(Debug, Clone, PartialEq)]
pub struct Trace {
    /// Measured (normalised) force.
    pub measured: Vec<f64>,
    /// The model's free-run simulation.
    pub simulated: Vec<f64>,
}

/// The field's validation figures of a model on its training and test data.
#[derive(Debug, Clone, PartialEq)]
pub struct Validation {
    /// NRMSE fit on the training records, % (simulation).
    pub train_fit_percent: Option<f64>,
    /// NRMSE fit on the test records, %.
    pub test_fit_percent: Option<f64>,
    /// RRSE on the test records.
    pub test_rrse: Option<f64>,
    /// Residual tests of the test records' simulation residuals, at the model period.
    pub resid: Option<Resid>,
    /// Training records' traces.
    pub train: Vec<Trace>,
    /// Test records' traces.
    pub test: Vec<Trace>,
}

fn traces(net: &fes_model::model::network::Network<f64>, data: &ModelData) -> Option<Vec<Trace>> {
    data.records
        .iter()
        .map(|rec| {
            let simulated = run_record_base(net, rec, Horizon::Simulation, data.factor).ok()?;
            Some(Trace {
                measured: rec.y_base.clone(),
                simulated,
            })
        })
        .collect()
}

/// NRMSE fit (%) and RRSE of the records laid end to end (one ȳ over all of them, as
/// MATLAB's `compare` on a multi-experiment data set).
pub fn fit_and_rrse(traces: &[Trace]) -> (Option<f64>, Option<f64>) {
    let y: Vec<f64> = traces
        .iter()
        .flat_map(|t| t.measured.iter().copied())
        .collect();
    let yh: Vec<f64> = traces
        .iter()
        .flat_map(|t| t.simulated.iter().copied())
        .collect();
    (fit_percent(&y, &yh), rrse(&y, &yh))
}

/// Fit, RRSE, residual tests and traces of `lmn` in simulation mode. A model whose
/// simulation diverges gets `None` figures and no traces for that side.
pub fn validate(lmn: &Lmn, train: &ModelData, test: &ModelData) -> Validation {
    let Ok(net) = lmn.network() else {
        return Validation {
            train_fit_percent: None,
            test_fit_percent: None,
            test_rrse: None,
            resid: None,
            train: Vec::new(),
            test: Vec::new(),
        };
    };
    let train_traces = traces(&net, train).unwrap_or_default();
    let test_traces = traces(&net, test).unwrap_or_default();
    let (train_fit_percent, _) = fit_and_rrse(&train_traces);
    let (test_fit_percent, test_rrse) = fit_and_rrse(&test_traces);
    let residuals: Option<Vec<(Vec<f64>, &[f64])>> = test
        .records
        .iter()
        .map(|rec| {
            let yh = run_record(&net, rec, Horizon::Simulation).ok()?;
            let e: Vec<f64> = rec.y.iter().zip(&yh).map(|(a, b)| a - b).collect();
            Some((e, rec.u.as_slice()))
        })
        .collect();
    let resid = residuals.and_then(|r| {
        let pairs: Vec<(&[f64], &[f64])> = r.iter().map(|(e, u)| (e.as_slice(), *u)).collect();
        resid(&pairs, RESID_LAGS)
    });
    Validation {
        train_fit_percent,
        test_fit_percent,
        test_rrse,
        resid,
        train: train_traces,
        test: test_traces,
    }
}
