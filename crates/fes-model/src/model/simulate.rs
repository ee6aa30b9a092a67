//! Running a network over a record: free-run simulation (thesis B.1, eq. B.6/B.7), one-step
//! prediction (eq. B.4) and the mean squared error (eq. B.8).

use super::network::{LocalModels, Network, NetworkError};
use super::scheduling::Scheduler;
use crate::num::Scalar;

/// Why a record could not be run.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum RunError {
    /// Input and output slices differ in length.
    #[error("length mismatch: {what} has {got} samples, expected {expected}")]
    Length {
        /// Which slice.
        what: &'static str,
        /// Its length.
        got: usize,
        /// The input's length.
        expected: usize,
    },
    /// One-step prediction needs measured outputs in the data vector: only ARX networks have
    /// that; a state-space network's state is not measured (B.5).
    #[error(
        "one-step prediction needs ARX local models (a state-space network's state is not measured)"
    )]
    PredictionNeedsArx,
    /// The network has no rest state.
    #[error(transparent)]
    Network(#[from] NetworkError),
}

/// Free-run simulation from rest (eq. B.6/B.7): y_hat\[k\] for the pulse train u\[0..N\], with
/// u = 0 before the record. Writes `y.len() == u.len()` outputs.
pub fn simulate<S: Scalar>(net: &Network<S>, u: &[f64], y: &mut [S]) -> Result<(), RunError> {
    if y.len() != u.len() {
        return Err(RunError::Length {
            what: "output",
            got: y.len(),
            expected: u.len(),
        });
    }
    let mut st = net.rest_state()?;
    let d = net.delay();
    for (k, yk) in y.iter_mut().enumerate() {
        let v = if k >= d { u[k - d] } else { 0.0 };
        *yk = net.step_each(&mut st, v, u[k]);
    }
    Ok(())
}

/// One-step-ahead prediction (eq. B.4) of an ARX network: y_hat\[k\] from measured outputs
/// y\[k-1..k-n\] (and, with output scheduling, phi_k = y\[k-1\]); the measured record is
/// extended to negative times by y\[0\] and the input by zeros (records start at rest).
pub fn predict<S: Scalar>(
    net: &Network<S>,
    u: &[f64],
    y_measured: &[f64],
    y_hat: &mut [S],
) -> Result<(), RunError> {
    if !matches!(net.local_models(), LocalModels::Arx { .. }) {
        return Err(RunError::PredictionNeedsArx);
    }
    for (what, len) in [
        ("measured output", y_measured.len()),
        ("prediction", y_hat.len()),
    ] {
        if len != u.len() {
            return Err(RunError::Length {
                what,
                got: len,
                expected: u.len(),
            });
        }
    }
    if u.is_empty() {
        return Ok(());
    }
    let mut st = net.rest_state()?;
    let d = net.delay();
    let meas = |k: isize| -> f64 {
        if k < 0 {
            y_measured[0]
        } else {
            y_measured[k as usize]
        }
    };
    for (k, yk) in y_hat.iter_mut().enumerate() {
        let k_i = k as isize;
        st.x = [
            S::from_f64(meas(k_i - 1)),
            S::from_f64(meas(k_i - 2)),
            S::from_f64(meas(k_i - 3)),
        ];
        if matches!(net.scheduler(), Scheduler::Output) {
            st.phi = S::from_f64(meas(k_i - 1));
        }
        let v = if k >= d { u[k - d] } else { 0.0 };
        *yk = net.step_each(&mut st, v, u[k]);
    }
    Ok(())
}

/// Mean squared error (eq. B.8): (1/N) sum (y - y_hat)^2; 0 for empty records.
pub fn mse<S: Scalar>(y: &[f64], y_hat: &[S]) -> Result<S, RunError> {
    if y.len() != y_hat.len() {
        return Err(RunError::Length {
            what: "model output",
            got: y_hat.len(),
            expected: y.len(),
        });
    }
    if y.is_empty() {
        return Ok(S::zero());
    }
    let mut acc = S::zero();
    for (a, b) in y.iter().zip(y_hat) {
        let e = *b - *a;
        acc += e * e;
    }
    Ok(acc / y.len() as f64)
}
