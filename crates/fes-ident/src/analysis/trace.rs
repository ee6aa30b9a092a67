//! A free-run simulation from rest that also records the scheduling variable and the state
//! (for the phi range of a data set, the force-frequency curve, phase planes, Figs.
//! 5.26, 5.31, 5.32).
//!
//! It runs the model library's own network step ([`Network::step_each`]) with the delayed
//! input (and, for the undelayed scheduling class, the input now) exactly as [`fes_model::model::simulate::simulate`] does, so `y` equals that function's output.

use fes_model::model::Network;
use fes_model::model::simulate::RunError;

/// Output, scheduling variable and state of one run.
#[derive(Debug, Clone, PartialEq)]
pub struct Trace {
    /// Model output y\[k\].
    pub y: Vec<f64>,
    /// The scheduling value used at step k (phi_k, eq. 5.2-5.4 or 5.1).
    pub phi: Vec<f64>,
    /// The state x\[k\] before step k (state space; ARX: the two latest past outputs).
    pub x: Vec<[f64; 2]>,
}

/// Free run from rest over the pulse train `u` (u = 1 in a pulse's sample, else 0), with
/// u = 0 before the record (eq. B.6/B.7).
pub fn simulate_trace(net: &Network<f64>, u: &[f64]) -> Result<Trace, RunError> {
    let mut st = net.rest_state()?;
    let d = net.delay();
    let mut t = Trace {
        y: Vec::with_capacity(u.len()),
        phi: Vec::with_capacity(u.len()),
        x: Vec::with_capacity(u.len()),
    };
    for k in 0..u.len() {
        t.phi.push(st.phi);
        t.x.push(st.ss_state());
        let v = if k >= d { u[k - d] } else { 0.0 };
        t.y.push(net.step_each(&mut st, v, u[k]));
    }
    Ok(t)
}

/// The range `[min, max]` of the scheduling variable over records (each from rest), as the
/// model's own scheduler computes it; `None` when there are no samples.
pub fn phi_range<'a>(
    net: &Network<f64>,
    inputs: impl IntoIterator<Item = &'a [f64]>,
) -> Result<Option<(f64, f64)>, RunError> {
    let mut range: Option<(f64, f64)> = None;
    for u in inputs {
        for phi in simulate_trace(net, u)?.phi {
            if !phi.is_finite() {
                continue;
            }
            range = Some(match range {
                None => (phi, phi),
                Some((lo, hi)) => (lo.min(phi), hi.max(phi)),
            });
        }
    }
    Ok(range)
}
