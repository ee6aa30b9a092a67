//! Knot optimisation (thesis 2.3.1, 5.4.2): the interior knots of the B-spline validity
//! functions as free parameters, with the local model parameters held fixed.
//!
//! Only the interior knots move; the p-fold end knots (the scheduling range) stay. To keep
//! the knots ordered and inside the range for every parameter value, the q interior knots
//! are built from the q + 1 gaps between consecutive distinct knots,
//! gap_l = (hi - lo) softmax(s)_l with s_q = 0 fixed (q free parameters s_0..s_{q-1}),
//! knot_j = lo + gap_0 + ... + gap_j. The map is written once, generic over the scalar, so the
//! knot derivatives come from the same `Dual` machinery as the parameter derivatives
//! (through [`fes_model::model::validity::ValidityFunctions::from_knots`] and the network step).

use super::problem::ParamMap;
use fes_model::model::lmn::Lmn;
use fes_model::model::network::Network;
use fes_model::model::params::{ParamError, ParamLayout};
use fes_model::num::Scalar;

/// The interior knots of a model as free parameters (module docs).
#[derive(Debug, Clone)]
pub struct KnotMap<'a> {
    /// The model (structure, Ts, delay, scheduling, order, end knots).
    pub template: &'a Lmn,
    /// Its parameter layout.
    pub layout: &'a ParamLayout,
    /// Its (fixed) parameters.
    pub theta: &'a [f64],
}

impl KnotMap<'_> {
    /// Number of interior knots q = M - p.
    pub fn interior(&self) -> usize {
        self.template.units() - self.template.validity.order()
    }

    /// The softmax parameters of the template's current knots (`None` if two interior knots
    /// coincide, which the parameterisation cannot represent).
    pub fn params(&self) -> Option<Vec<f64>> {
        let p = self.template.validity.order();
        let q = self.interior();
        let k = self.template.validity.knots();
        let gaps: Vec<f64> = (0..=q).map(|l| k[p + l] - k[p + l - 1]).collect();
        if gaps.iter().any(|g| g.is_nan() || *g <= 0.0) {
            return None;
        }
        Some(gaps[..q].iter().map(|g| (g / gaps[q]).ln()).collect())
    }

    /// The full knot vector for parameters s.
    pub fn knots<S: Scalar>(&self, s: &[S]) -> Vec<S> {
        let p = self.template.validity.order();
        let q = self.interior();
        let (lo, hi) = self.template.validity.valid_range();
        // Stable softmax over (s_0..s_{q-1}, 0).
        let max = s.iter().fold(0.0f64, |a, v| a.max(v.value()));
        let e: Vec<S> = s
            .iter()
            .map(|v| (*v - max).exp())
            .chain(core::iter::once(S::from_f64((-max).exp())))
            .collect();
        let mut total = S::zero();
        for v in &e {
            total += *v;
        }
        let mut out = Vec::with_capacity(self.template.units() + p);
        out.extend(core::iter::repeat_n(S::from_f64(lo), p));
        let mut acc = S::zero();
        for v in e.iter().take(q) {
            acc += *v;
            out.push(acc / total * (hi - lo) + lo);
        }
        out.extend(core::iter::repeat_n(S::from_f64(hi), p));
        out
    }
}

impl ParamMap for KnotMap<'_> {
    fn len(&self) -> usize {
        self.interior()
    }
    /// |s| <= 8: neighbouring gaps differ by at most e^16, so no knot interval collapses.
    fn bounds(&self) -> Vec<(f64, f64)> {
        vec![(-8.0, 8.0); self.len()]
    }
    fn network<S: Scalar>(&self, s: &[S]) -> Result<Network<S>, ParamError> {
        let knots = self.knots(s);
        let theta: Vec<S> = self.theta.iter().map(|&v| S::from_f64(v)).collect();
        self.layout.network(self.template, &theta, Some(&knots))
    }
}
