//! Simulated against measured records (thesis 5.3, 5.4.3, Fig. 5.24): free-run simulation
//! from rest of each record (eq. B.6/B.7) and its mean squared simulation error (eq. B.8).

use fes_model::model::Network;
use fes_model::model::simulate::{RunError, mse, simulate};

/// One record's simulation and error.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordFit {
    /// The simulated output (normalised force).
    pub simulated: Vec<f64>,
    /// Its MSSE against the measured force, eq. (B.8) (infinite when the simulation
    /// diverges).
    pub msse: f64,
}

/// Simulates one record from rest and scores it.
pub fn fit_record(net: &Network<f64>, u: &[f64], y: &[f64]) -> Result<RecordFit, RunError> {
    let mut simulated = vec![0.0; u.len()];
    simulate(net, u, &mut simulated)?;
    let e = mse(y, &simulated)?;
    Ok(RecordFit {
        simulated,
        msse: if e.is_finite() { e } else { f64::INFINITY },
    })
}

/// MSSE (eq. B.8) over several records concatenated (each simulated from rest): the
/// sample-weighted mean of their squared errors, as the thesis's training/test MSSE.
pub fn msse<'a>(
    net: &Network<f64>,
    records: impl IntoIterator<Item = (&'a [f64], &'a [f64])>,
) -> Result<f64, RunError> {
    let mut sum = 0.0;
    let mut n = 0usize;
    for (u, y) in records {
        let fit = fit_record(net, u, y)?;
        sum += fit.msse * y.len() as f64;
        n += y.len();
    }
    let e = if n == 0 { 0.0 } else { sum / n as f64 };
    Ok(if e.is_finite() { e } else { f64::INFINITY })
}
