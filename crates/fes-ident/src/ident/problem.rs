//! The least-squares problem of identification (thesis B.1-B.3): residuals of a network over
//! a set of records and their exact Jacobian.
//!
//! A [`ParamMap`] turns a free parameter vector p into a run-time network, generic over the
//! scalar (the model parameters theta through [`ParamLayout`], or the interior knots,
//! [`super::knots`]). A [`Problem`] runs that network over the records, each from rest:
//!
//! - [`Horizon::Simulation`] (free run, eq. B.6/B.7): the model output is interpolated to
//!   the base period and compared with the measured base-period output, so the cost is
//!   exactly the training MSSE reported (5.3) times the sample count;
//! - [`Horizon::Prediction`] (one step ahead, eq. B.4, ARX only): compared at the model's
//!   own period with the (down-sampled) measured output the predictor is fed, the usual
//!   regression of prediction mode (B.2).
//!
//! Rows can be weighted (gamma_i of eq. B.2; local learning, eq. 2.35).
//!
//! **Exact Jacobians.** The parameters are seeded `N` at a time ([`DUAL_WIDTH`]) as
//! [`Dual<N>`] variables and the network's own step code is run (no finite differences,
//! unlike the thesis's B.3.1): one pass per block of `N` columns. Records are processed in
//! parallel (rayon), so both cores work; each record's block Jacobian is reduced to J'J
//! and J'r on the spot.

use super::records::IdentRecord;
use super::resample::{
    PulseShift, ResampleError, coarse_len, downsample_output, downsample_pulses, interpolate,
};
use fes_model::model::lmn::Lmn;
use fes_model::model::network::Network;
use fes_model::model::params::{ParamError, ParamLayout};
use fes_model::model::simulate::{RunError, predict, simulate};
use fes_model::num::{Dual, Scalar};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

/// Why residuals or Jacobians could not be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProblemError {
    /// The parameters do not define a network.
    #[error(transparent)]
    Param(#[from] ParamError),
    /// The network could not be run (e.g. no rest state).
    #[error(transparent)]
    Run(#[from] RunError),
    /// The model output or a derivative is not finite (diverging simulation).
    #[error("the model output is not finite (the simulation diverges)")]
    NonFinite,
}

/// A free parameter vector and the network it defines, in any scalar type.
pub trait ParamMap: Sync {
    /// Number of free parameters.
    fn len(&self) -> usize;
    /// True when there are none.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// The network for p.
    fn network<S: Scalar>(&self, p: &[S]) -> Result<Network<S>, ParamError>;
    /// Parameter names, if the map has them.
    fn names(&self) -> Option<Vec<String>> {
        None
    }
    /// Box bounds (lo, hi) per parameter that the optimiser keeps (default: none).
    fn bounds(&self) -> Vec<(f64, f64)> {
        vec![(f64::NEG_INFINITY, f64::INFINITY); self.len()]
    }
}

/// Parameters seeded per dual pass. Measured on the 4- and 6-unit common-eigenvector
/// Jacobians of the fast data set (`benches/ident_fit.rs`): 8 was fastest among 4, 6, 8, 12,
/// 16, 24 and 36; wider duals make every copy of the interpolated local model larger and
/// cost more per column than the passes they save.
pub const DUAL_WIDTH: usize = 8;

/// Bound on the eigenvalue parameters eta: |eta| <= 12 keeps e = -(1/Ts) sigmoid(eta) within
/// [-0.999994/Ts, -6.1e-6/Ts] (at 1 ms: time constants from 1 ms to 160 s), far outside
/// any muscle's dynamics, while stopping eta from running off to infinity where the cost
/// is flat ([`super::lm`]).
pub const ETA_BOUND: f64 = 12.0;

/// The model parameters theta of a template model ([`ParamLayout`], knots fixed).
#[derive(Debug, Clone)]
pub struct ThetaMap<'a> {
    /// The model whose structure, knots, scheduling, Ts and delay are used.
    pub template: &'a Lmn,
    /// Its layout.
    pub layout: &'a ParamLayout,
}

impl ParamMap for ThetaMap<'_> {
    fn len(&self) -> usize {
        self.layout.len()
    }
    fn network<S: Scalar>(&self, p: &[S]) -> Result<Network<S>, ParamError> {
        self.layout.network(self.template, p, None)
    }
    fn names(&self) -> Option<Vec<String>> {
        Some(self.layout.names().to_vec())
    }
    fn bounds(&self) -> Vec<(f64, f64)> {
        self.layout
            .names()
            .iter()
            .map(|n| {
                if n.ends_with(".eta0") || n.ends_with(".eta1") {
                    (-ETA_BOUND, ETA_BOUND)
                } else {
                    (f64::NEG_INFINITY, f64::INFINITY)
                }
            })
            .collect()
    }
}

/// Which model output is compared with the data (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Horizon {
    /// Free-run simulation from rest (eq. B.6/B.7), compared at the base period.
    Simulation,
    /// One-step-ahead prediction (eq. B.4), compared at the model period.
    Prediction,
}

/// One record as the model sees it.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelRecord {
    /// Pulse train at the model period.
    pub u: Vec<f64>,
    /// Measured output at the model period (filtered and decimated; the base output when
    /// the periods agree).
    pub y: Vec<f64>,
    /// Measured output at the base period.
    pub y_base: Vec<f64>,
}

/// Records down-sampled to a model period of `factor` base samples (thesis 5.2.2).
#[derive(Debug, Clone, PartialEq)]
pub struct ModelData {
    /// Base samples per model sample.
    pub factor: usize,
    /// The records.
    pub records: Vec<ModelRecord>,
    /// How far pulses were moved.
    pub shift: PulseShift,
}

impl ModelData {
    /// Down-samples records ([`super::resample`]).
    pub fn new(records: &[IdentRecord], factor: usize) -> Result<Self, ResampleError> {
        let mut shift = PulseShift::default();
        let records = records
            .iter()
            .map(|r| {
                let (u, s) = downsample_pulses(&r.u, factor)?;
                shift = shift.merge(s);
                Ok(ModelRecord {
                    u,
                    y: downsample_output(&r.y, factor),
                    y_base: r.y.clone(),
                })
            })
            .collect::<Result<Vec<_>, ResampleError>>()?;
        Ok(Self {
            factor,
            records,
            shift,
        })
    }

    /// Number of base samples over all records.
    pub fn base_samples(&self) -> usize {
        self.records.iter().map(|r| r.y_base.len()).sum()
    }
}

/// The network's output over a record at the model period (simulation or prediction).
pub fn run_record<S: Scalar>(
    net: &Network<S>,
    rec: &ModelRecord,
    horizon: Horizon,
) -> Result<Vec<S>, RunError> {
    let mut out = vec![S::zero(); rec.u.len()];
    match horizon {
        Horizon::Simulation => simulate(net, &rec.u, &mut out)?,
        Horizon::Prediction => predict(net, &rec.u, &rec.y, &mut out)?,
    }
    Ok(out)
}

/// The network's output over a record at the base period (interpolated, module
/// [`super::resample`]).
pub fn run_record_base<S: Scalar>(
    net: &Network<S>,
    rec: &ModelRecord,
    horizon: Horizon,
    factor: usize,
) -> Result<Vec<S>, RunError> {
    let coarse = run_record(net, rec, horizon)?;
    let mut out = vec![S::zero(); rec.y_base.len()];
    debug_assert_eq!(coarse.len(), coarse_len(out.len(), factor));
    interpolate(&coarse, factor, &mut out);
    Ok(out)
}

/// The normal equations at p: cost = sum r^2, g = J' r, h = J' J (over the chosen columns).
#[derive(Debug, Clone, PartialEq)]
pub struct Normal {
    /// Sum of squared (weighted) residuals.
    pub cost: f64,
    /// J' r.
    pub g: DVector<f64>,
    /// J' J.
    pub h: DMatrix<f64>,
}

/// A Gaussian prior on the parameters: the cost gains sum_i w_i (p_i - center_i)^2
/// ([`super::identify`](mod@super::identify) uses it to keep units the data barely reach near the start,
/// pitfall (d)).
#[derive(Debug, Clone, PartialEq)]
pub struct Prior {
    /// The parameters the prior pulls towards.
    pub center: Vec<f64>,
    /// Weight w_i >= 0 of each parameter.
    pub weight: Vec<f64>,
}

impl Prior {
    fn cost(&self, p: &[f64]) -> f64 {
        p.iter()
            .zip(&self.center)
            .zip(&self.weight)
            .map(|((x, c), w)| w * (x - c) * (x - c))
            .sum()
    }
}

/// Residuals of a parameterised network over records (module docs).
pub struct Problem<'a, M: ParamMap> {
    /// The parameterisation.
    pub map: M,
    /// The records.
    pub data: &'a ModelData,
    /// Simulation or prediction.
    pub horizon: Horizon,
    /// Optional row weights per record (gamma of eq. B.2), at the compared rate.
    pub weights: Option<&'a [Vec<f64>]>,
    /// Optional prior added to [`Self::cost`] and [`Self::normal`] (not to the residuals).
    pub prior: Option<Prior>,
}

impl<'a, M: ParamMap> Problem<'a, M> {
    /// An unweighted problem.
    pub fn new(map: M, data: &'a ModelData, horizon: Horizon) -> Self {
        Self {
            map,
            data,
            horizon,
            weights: None,
            prior: None,
        }
    }

    /// Number of residual rows.
    pub fn rows(&self) -> usize {
        self.data.records.iter().map(|r| self.target(r).len()).sum()
    }

    fn target<'r>(&self, rec: &'r ModelRecord) -> &'r [f64] {
        match self.horizon {
            Horizon::Simulation => &rec.y_base,
            Horizon::Prediction => &rec.y,
        }
    }

    /// Model output rows of one record (at the compared rate).
    fn outputs<S: Scalar>(&self, net: &Network<S>, rec: &ModelRecord) -> Result<Vec<S>, RunError> {
        match self.horizon {
            Horizon::Simulation => run_record_base(net, rec, self.horizon, self.data.factor),
            Horizon::Prediction => run_record(net, rec, self.horizon),
        }
    }

    fn weight(&self, i: usize, k: usize) -> f64 {
        self.weights.map_or(1.0, |w| w[i][k].max(0.0).sqrt())
    }

    /// Residuals r = sqrt(gamma) (y_hat - y) of every record, concatenated.
    pub fn residuals(&self, p: &[f64]) -> Result<Vec<f64>, ProblemError> {
        let net = self.map.network(p)?;
        let per: Vec<Vec<f64>> = self
            .data
            .records
            .par_iter()
            .enumerate()
            .map(|(i, rec)| {
                let yh = self.outputs(&net, rec)?;
                Ok(yh
                    .iter()
                    .zip(self.target(rec))
                    .enumerate()
                    .map(|(k, (a, b))| self.weight(i, k) * (a - b))
                    .collect())
            })
            .collect::<Result<_, ProblemError>>()?;
        let r: Vec<f64> = per.into_iter().flatten().collect();
        if r.iter().all(|v| v.is_finite()) {
            Ok(r)
        } else {
            Err(ProblemError::NonFinite)
        }
    }

    /// Sum of squared residuals (plus the prior, if any).
    pub fn cost(&self, p: &[f64]) -> Result<f64, ProblemError> {
        let data: f64 = self.residuals(p)?.iter().map(|r| r * r).sum();
        Ok(data + self.prior.as_ref().map_or(0.0, |pr| pr.cost(p)))
    }

    /// The normal equations at p over the columns `cols` (all: `0..len`), including the
    /// prior: cost += sum w (p - c)^2, g += w (p - c), h += diag(w).
    pub fn normal(&self, p: &[f64], cols: &[usize]) -> Result<Normal, ProblemError> {
        let n = cols.len();
        let zero = || (0.0, DVector::zeros(n), DMatrix::zeros(n, n));
        let (mut cost, mut g, mut h) = self
            .per_record(p, cols, |r, j| {
                let cost: f64 = r.iter().map(|v| v * v).sum();
                let jt = j.transpose();
                (cost, &jt * &r, &jt * &j)
            })?
            .into_iter()
            .fold(zero(), |(c, g, h), (c2, g2, h2)| (c + c2, g + g2, h + h2));
        if let Some(pr) = &self.prior {
            cost += pr.cost(p);
            for (k, &i) in cols.iter().enumerate() {
                g[k] += pr.weight[i] * (p[i] - pr.center[i]);
                h[(k, k)] += pr.weight[i];
            }
        }
        Ok(Normal { cost, g, h })
    }

    /// Residuals and the full stacked Jacobian over the columns `cols` (rows: every
    /// record's rows in order). For the SVD solution of linear problems (B.14).
    pub fn jacobian(
        &self,
        p: &[f64],
        cols: &[usize],
    ) -> Result<(DVector<f64>, DMatrix<f64>), ProblemError> {
        let parts = self.per_record(p, cols, |r, j| (r, j))?;
        let rows: usize = parts.iter().map(|(r, _)| r.len()).sum();
        let mut r = DVector::zeros(rows);
        let mut j = DMatrix::zeros(rows, cols.len());
        let mut at = 0;
        for (ri, ji) in parts {
            let m = ri.len();
            r.rows_mut(at, m).copy_from(&ri);
            j.rows_mut(at, m).copy_from(&ji);
            at += m;
        }
        Ok((r, j))
    }

    /// Runs `f(r_i, J_i)` on every record's residuals and Jacobian (columns `cols`), in
    /// parallel. Columns are seeded 8 at a time ([`DUAL_WIDTH`]; 4 for tiny problems).
    fn per_record<T: Send>(
        &self,
        p: &[f64],
        cols: &[usize],
        f: impl Fn(DVector<f64>, DMatrix<f64>) -> T + Sync,
    ) -> Result<Vec<T>, ProblemError> {
        if cols.len() <= 4 {
            self.per_record_n::<4, T>(p, cols, &f)
        } else {
            self.per_record_n::<DUAL_WIDTH, T>(p, cols, &f)
        }
    }

    fn per_record_n<const N: usize, T: Send>(
        &self,
        p: &[f64],
        cols: &[usize],
        f: &(impl Fn(DVector<f64>, DMatrix<f64>) -> T + Sync),
    ) -> Result<Vec<T>, ProblemError> {
        // One network per block of N seeded columns, shared by all records.
        let blocks: Vec<&[usize]> = cols.chunks(N).collect();
        let nets = blocks
            .iter()
            .map(|block| {
                let pd: Vec<Dual<N>> = p
                    .iter()
                    .enumerate()
                    .map(|(i, &v)| match block.iter().position(|&c| c == i) {
                        Some(j) => Dual::variable(v, j),
                        None => Dual::constant(v),
                    })
                    .collect();
                self.map.network(&pd)
            })
            .collect::<Result<Vec<_>, _>>()?;
        self.data
            .records
            .par_iter()
            .enumerate()
            .map(|(i, rec)| {
                let target = self.target(rec);
                let rows = target.len();
                let mut r = DVector::zeros(rows);
                let mut j = DMatrix::zeros(rows, cols.len());
                for (b, net) in nets.iter().enumerate() {
                    let yh = self.outputs(net, rec)?;
                    for (k, y) in yh.iter().enumerate() {
                        let w = self.weight(i, k);
                        if b == 0 {
                            r[k] = w * (y.v - target[k]);
                        }
                        for l in 0..blocks[b].len() {
                            j[(k, b * N + l)] = w * y.d[l];
                        }
                    }
                }
                if !(r.iter().all(|v| v.is_finite()) && j.iter().all(|v| v.is_finite())) {
                    return Err(ProblemError::NonFinite);
                }
                Ok(f(r, j))
            })
            .collect()
    }
}
