//! Identification of multi-input ARX networks ([`fes_model::model::miso`]): the heat-transfer
//! process of thesis App. E (Examples E.4.2-E.4.4, E.4.6).
//!
//! - **Prediction mode** (B.2, eq. B.4): the measured outputs fill the data vector, so the
//!   output is linear in theta and the fit is one least-squares problem solved by the SVD
//!   ([`super::lsq`]): global learning (eq. 2.33) on the rows rho_i(phi_k) psi_k' for all
//!   units at once, local learning (eq. 2.35) per unit on psi_k weighted by rho_i(phi_k).
//! - **Simulation mode** (B.3, eq. B.6/B.7): the model's own past outputs fill the data
//!   vector; the criterion is minimised by the same Levenberg-Marquardt as the muscle's
//!   ([`super::lm`], through [`LeastSquares`]) with exact Jacobians from `Dual` parameters
//!   run through the network's own simulation. Global learning fits every theta_i on the
//!   network's output; local learning fits each unit as a model of its own, simulated alone,
//!   its errors weighted by rho_i(phi_k) (eq. 2.35 in simulation mode).
//!
//! Records start with the plant running (the [`fes_model::model::miso`] convention): the
//! simulation starts from the first measured output.

use super::IdentError;
use super::lm::{LeastSquares, LmOptions, levenberg_marquardt};
use super::lsq::{self, DEFAULT_RCOND};
use super::problem::{DUAL_WIDTH, Horizon, Normal, ProblemError};
use super::regression::Learning;
use fes_dataset::signals::SignalSet;
use fes_model::model::miso::{MisoArx, MisoError, MisoLocal};
use fes_model::model::miso_ss::MisoSs;
use fes_model::model::validity::ValidityFunctions;
use fes_model::num::{Dual, Scalar};
use nalgebra::{Complex, DMatrix, DVector};
use rayon::prelude::*;

/// One record: the input channels and the output.
#[derive(Debug, Clone, PartialEq)]
pub struct MisoRecord {
    /// Record name (its file).
    pub name: String,
    /// One vector per model input, in the model's input order.
    pub u: Vec<Vec<f64>>,
    /// The measured output.
    pub y: Vec<f64>,
}

impl MisoRecord {
    /// The inputs as slices.
    pub fn inputs(&self) -> Vec<&[f64]> {
        self.u.iter().map(Vec::as_slice).collect()
    }
}

/// The training and test records of a signal data set for a model with inputs `inputs`
/// (channel names, in the model's order) and output `output`.
pub fn records(
    set: &SignalSet,
    inputs: &[&str],
    output: &str,
) -> Result<(Vec<MisoRecord>, Vec<MisoRecord>), IdentError> {
    let idx: Vec<usize> = inputs
        .iter()
        .map(|n| {
            set.input_index(n).ok_or_else(|| IdentError::NoChannel {
                kind: "input",
                name: (*n).to_owned(),
            })
        })
        .collect::<Result<_, _>>()?;
    let out = set
        .header
        .outputs
        .iter()
        .position(|c| c.name == output)
        .ok_or_else(|| IdentError::NoChannel {
            kind: "output",
            name: output.to_owned(),
        })?;
    let take = |list: &[usize]| {
        list.iter()
            .filter_map(|&i| set.records.get(i))
            .map(|r| MisoRecord {
                name: r.file.clone(),
                u: idx.iter().map(|&j| r.inputs[j].clone()).collect(),
                y: r.outputs[out].clone(),
            })
            .collect()
    };
    Ok((take(&set.header.split.train), take(&set.header.split.test)))
}

/// Mean squared error (eq. B.8) over every sample of the records, in simulation (MSSE) or
/// prediction (MSPE) mode; infinite if the simulation diverges.
pub fn mse(model: &MisoArx, recs: &[MisoRecord], horizon: Horizon) -> Result<f64, IdentError> {
    mean_squared(recs, |r| run(model, r, horizon))
}

/// Mean squared error (eq. B.8) of `output` (a record's model output) against every
/// record's y; infinite when not finite (a diverging simulation).
fn mean_squared<E>(
    recs: &[MisoRecord],
    mut output: impl FnMut(&MisoRecord) -> Result<Vec<f64>, E>,
) -> Result<f64, E> {
    let mut sum = 0.0;
    let mut n = 0usize;
    for r in recs {
        let yh = output(r)?;
        sum += yh
            .iter()
            .zip(&r.y)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>();
        n += r.y.len();
    }
    let m = sum / n.max(1) as f64;
    Ok(if m.is_finite() { m } else { f64::INFINITY })
}

/// The model output over one record.
pub fn run(model: &MisoArx, r: &MisoRecord, horizon: Horizon) -> Result<Vec<f64>, IdentError> {
    let mut yh = vec![0.0; r.y.len()];
    let u = r.inputs();
    match horizon {
        Horizon::Simulation => model.simulate(&u, r.y[0], &mut yh),
        Horizon::Prediction => model.predict(&u, &r.y, &mut yh),
    }?;
    Ok(yh)
}

/// Prediction-mode least squares (module docs). `template` gives the structure and the
/// validity functions; its theta is replaced.
pub fn fit_prediction(
    template: &MisoArx,
    recs: &[MisoRecord],
    learning: Learning,
) -> Result<MisoArx, IdentError> {
    let st = &template.structure;
    let (m, r) = (template.units(), st.regressors());
    let rows: usize = recs.iter().map(|x| x.y.len()).sum();
    let mut psi = vec![0.0; r];
    // Each unit's regressors (they differ with per-unit delays), the activations and the
    // targets of every sample.
    let mut psis = vec![DMatrix::zeros(rows, r); m];
    let mut rho = DMatrix::zeros(rows, m);
    let mut y = DVector::zeros(rows);
    let mut at = 0;
    for rec in recs {
        let u = rec.inputs();
        st.check_record(&u, rec.y.len())
            .map_err(|source| IdentError::MisoRecord {
                record: rec.name.clone(),
                source,
            })?;
        for k in 0..rec.y.len() {
            for (i, p) in psis.iter_mut().enumerate() {
                st.regressor(&u, &rec.y, k, i, &mut psi);
                for (c, v) in psi.iter().enumerate() {
                    p[(at, c)] = *v;
                }
            }
            let (act, n) = template.activations(&u, k);
            for &(i, w) in &act[..n] {
                rho[(at, i)] = w;
            }
            y[at] = rec.y[k];
            at += 1;
        }
    }
    let mut theta = vec![0.0; m * r];
    match learning {
        Learning::Global => {
            let a = DMatrix::from_fn(rows, m * r, |k, c| {
                rho[(k, c / r)] * psis[c / r][(k, c % r)]
            });
            let sol = lsq::solve(&a, &y, DEFAULT_RCOND)?;
            theta.copy_from_slice(sol.x.as_slice());
        }
        Learning::Local => {
            for i in 0..m {
                let total: f64 = rho.column(i).sum();
                let ti = if total < 1e-6 * rows as f64 {
                    // A unit the data never activate: the unweighted (linear) fit.
                    lsq::solve(&psis[i], &y, DEFAULT_RCOND)?.x
                } else {
                    let w: Vec<f64> = rho.column(i).iter().map(|v| v.max(0.0).sqrt()).collect();
                    let a = DMatrix::from_fn(rows, r, |k, c| w[k] * psis[i][(k, c)]);
                    let b = DVector::from_fn(rows, |k, _| w[k] * y[k]);
                    lsq::solve(&a, &b, DEFAULT_RCOND)?.x
                };
                theta[i * r..(i + 1) * r].copy_from_slice(ti.as_slice());
            }
        }
    }
    let mut out = template.clone();
    out.theta = theta;
    Ok(out)
}

/// A multi-input network that the simulation-mode search can run with any scalar type:
/// the ARX networks ([`MisoArx`]) and the state-space ones ([`MisoSs`], E.4.5).
pub trait FreeRun: Clone + Sync {
    /// The parameters.
    fn theta(&self) -> &[f64];
    /// The same network with other parameters.
    fn with_theta(&self, p: &[f64]) -> Self;
    /// Free run over a record with parameters `theta` in `S`.
    fn run<S: Scalar>(&self, theta: &[S], rec: &MisoRecord, out: &mut [S])
    -> Result<(), MisoError>;
}

/// The [`FreeRun`] of a network whose parameters are its `theta`: the types differ only
/// in how `$net` (the network with the candidate's parameters) runs over `$rec` into `$out`.
macro_rules! free_run {
    ($ty:ident, |$net:ident, $rec:ident, $out:ident| $simulate:expr) => {
        impl FreeRun for $ty {
            fn theta(&self) -> &[f64] {
                &self.theta
            }
            fn with_theta(&self, p: &[f64]) -> Self {
                self.with_params(p.to_vec())
            }
            fn run<S: Scalar>(
                &self,
                theta: &[S],
                $rec: &MisoRecord,
                $out: &mut [S],
            ) -> Result<(), MisoError> {
                let $net = self.with_params(theta.to_vec());
                $simulate
            }
        }
    };
}

free_run!(MisoArx, |net, rec, out| net.simulate(
    &rec.inputs(),
    rec.y[0],
    out
));
free_run!(MisoSs, |net, rec, out| net.simulate(&rec.inputs(), out));

/// Simulation MSE (eq. B.8) of any [`FreeRun`] network; infinite if it diverges or
/// cannot be run.
pub fn msse<M: FreeRun>(model: &M, recs: &[MisoRecord]) -> f64 {
    mean_squared(recs, |r| {
        let mut yh = vec![0.0; r.y.len()];
        model.run(model.theta(), r, &mut yh).map(|()| yh)
    })
    .unwrap_or(f64::INFINITY)
}

/// One record's weighted residuals and their derivatives with respect to a block of `N`
/// parameters.
type RecordJacobian<const N: usize> = (Vec<f64>, Vec<[f64; N]>);

/// The simulation-mode criterion of [`fit_simulation`] as a [`LeastSquares`] problem.
pub struct SimulationProblem<'a, M: FreeRun = MisoArx> {
    model: M,
    recs: &'a [MisoRecord],
    /// Local learning of one unit: the unit's activations per record, as residual weights
    /// (square roots).
    weights: Option<Vec<Vec<f64>>>,
}

impl<'a, M: FreeRun> SimulationProblem<'a, M> {
    /// Global learning: the network's simulation error over every parameter.
    pub fn global(template: &M, recs: &'a [MisoRecord]) -> Self {
        Self {
            model: template.clone(),
            recs,
            weights: None,
        }
    }
}

impl<'a> SimulationProblem<'a, MisoArx> {
    /// Local learning of unit `i`: its local model simulated alone, its errors weighted by
    /// rho_i(phi_k) of the template's validity functions. The parameters are theta_i.
    pub fn local(template: &MisoArx, i: usize, recs: &'a [MisoRecord]) -> Result<Self, IdentError> {
        let st = &template.structure;
        let weights = recs
            .iter()
            .map(|r| {
                let u = r.inputs();
                (0..r.y.len())
                    .map(|k| {
                        let (act, n) = template.activations(&u, k);
                        act[..n]
                            .iter()
                            .find(|(j, _)| *j == i)
                            .map_or(0.0, |(_, w)| w.max(0.0).sqrt())
                    })
                    .collect()
            })
            .collect();
        let one = ValidityFunctions::uniform(1, 0.0, 1.0)
            .map_err(fes_model::model::params::ParamError::from)?;
        let mut st1 = st.clone();
        st1.scheduling2 = None;
        if let Some(d) = st.unit_delays.get(i) {
            st1.unit_delays = vec![d.clone()];
        }
        let model = MisoArx::new(template.ts, st1, one, template.unit(i).to_vec())?;
        Ok(Self {
            model,
            recs,
            weights: Some(weights),
        })
    }
}

impl<M: FreeRun> SimulationProblem<'_, M> {
    fn weight(&self, rec: usize, k: usize) -> f64 {
        self.weights.as_ref().map_or(1.0, |w| w[rec][k])
    }

    fn residuals_n<const N: usize>(
        &self,
        p: &[f64],
        block: &[usize],
    ) -> Result<Vec<RecordJacobian<N>>, ProblemError> {
        let theta: Vec<Dual<N>> = p
            .iter()
            .enumerate()
            .map(|(i, &v)| match block.iter().position(|&c| c == i) {
                Some(j) => Dual::variable(v, j),
                None => Dual::constant(v),
            })
            .collect();
        self.recs
            .par_iter()
            .enumerate()
            .map(|(ri, r)| {
                let mut yh = vec![Dual::<N>::constant(0.0); r.y.len()];
                self.model
                    .run(&theta, r, &mut yh)
                    .map_err(|_| ProblemError::NonFinite)?;
                let mut res = Vec::with_capacity(yh.len());
                let mut jac = Vec::with_capacity(yh.len());
                for (k, (a, b)) in yh.iter().zip(&r.y).enumerate() {
                    let w = self.weight(ri, k);
                    res.push(w * (a.v - b));
                    jac.push(a.d.map(|d| w * d));
                }
                if res.iter().all(|v| v.is_finite()) && jac.iter().flatten().all(|v| v.is_finite())
                {
                    Ok((res, jac))
                } else {
                    Err(ProblemError::NonFinite)
                }
            })
            .collect()
    }
}

impl<M: FreeRun> LeastSquares for SimulationProblem<'_, M> {
    fn bounds(&self) -> Vec<(f64, f64)> {
        vec![(f64::NEG_INFINITY, f64::INFINITY); self.model.theta().len()]
    }

    fn cost(&self, p: &[f64]) -> Result<f64, ProblemError> {
        let mut cost = 0.0;
        for (ri, r) in self.recs.iter().enumerate() {
            let mut yh = vec![0.0; r.y.len()];
            self.model
                .run(p, r, &mut yh)
                .map_err(|_| ProblemError::NonFinite)?;
            for (k, (a, b)) in yh.iter().zip(&r.y).enumerate() {
                let e = self.weight(ri, k) * (a - b);
                cost += e * e;
            }
        }
        if cost.is_finite() {
            Ok(cost)
        } else {
            Err(ProblemError::NonFinite)
        }
    }

    fn normal(&self, p: &[f64], cols: &[usize]) -> Result<Normal, ProblemError> {
        let n = cols.len();
        let rows: usize = self.recs.iter().map(|r| r.y.len()).sum();
        let mut jac = DMatrix::zeros(rows, n);
        let mut res = DVector::zeros(rows);
        for (b, block) in cols.chunks(DUAL_WIDTH).enumerate() {
            let parts = self.residuals_n::<DUAL_WIDTH>(p, block)?;
            let mut at = 0;
            for (r, j) in parts {
                for (k, (rv, jv)) in r.iter().zip(&j).enumerate() {
                    res[at + k] = *rv;
                    for l in 0..block.len() {
                        jac[(at + k, b * DUAL_WIDTH + l)] = jv[l];
                    }
                }
                at += r.len();
            }
        }
        Ok(Normal {
            cost: res.iter().map(|v| v * v).sum::<f64>(),
            g: jac.tr_mul(&res),
            h: jac.tr_mul(&jac),
        })
    }
}

/// Global simulation-mode fit of any [`FreeRun`] network from its current parameters
/// (E.4.5's state-space networks; [`fit_simulation`] for the ARX ones).
pub fn fit_free_run<M: FreeRun>(
    start: &M,
    recs: &[MisoRecord],
    opts: &LmOptions,
) -> Result<M, IdentError> {
    let problem = SimulationProblem::global(start, recs);
    let free: Vec<usize> = (0..start.theta().len()).collect();
    let rep = levenberg_marquardt(&problem, start.theta(), &free, opts, &mut |_, _| {})?;
    Ok(start.with_theta(&rep.p))
}

/// Simulation-mode fit (module docs) from the parameters of `start` (typically the
/// prediction-mode fit).
pub fn fit_simulation(
    start: &MisoArx,
    recs: &[MisoRecord],
    learning: Learning,
    opts: &LmOptions,
) -> Result<MisoArx, IdentError> {
    let mut out = start.clone();
    match learning {
        Learning::Global => {
            let problem = SimulationProblem::global(start, recs);
            let free: Vec<usize> = (0..start.theta.len()).collect();
            let rep = levenberg_marquardt(&problem, &start.theta, &free, opts, &mut |_, _| {})?;
            out.theta = rep.p;
        }
        Learning::Local => {
            let r = start.structure.regressors();
            for i in 0..start.units() {
                let problem = SimulationProblem::local(start, i, recs)?;
                let p0 = start.unit(i).to_vec();
                let free: Vec<usize> = (0..r).collect();
                let rep = levenberg_marquardt(&problem, &p0, &free, opts, &mut |_, _| {})?;
                out.theta[i * r..(i + 1) * r].copy_from_slice(&rep.p);
            }
        }
    }
    Ok(out)
}

/// The network frozen at one scheduling value (thesis 2.4.2, Fig. E.7).
#[derive(Debug, Clone, PartialEq)]
pub struct FrozenPoint {
    /// phi.
    pub phi: f64,
    /// rho_i(phi), every unit.
    pub rho: Vec<f64>,
    /// Steady-state gain from each input (eq. A.38), NaN where A(1) = 0.
    pub gains: Vec<f64>,
    /// Poles of the interpolated model.
    pub poles: Vec<Complex<f64>>,
    /// The interpolated model.
    pub model: MisoLocal,
}

/// Static analysis over `points` scheduling values evenly across the valid range.
pub fn static_analysis(model: &MisoArx, points: usize) -> Vec<FrozenPoint> {
    let (lo, hi) = model.validity.valid_range();
    let n = points.max(2);
    (0..n)
        .map(|g| {
            let phi = lo + (hi - lo) * g as f64 / (n - 1) as f64;
            let frozen = model.frozen(phi);
            let act = model.validity.eval(phi);
            FrozenPoint {
                phi,
                rho: (0..model.units()).map(|i| act.get(i)).collect(),
                gains: (0..model.structure.inputs())
                    .map(|j| frozen.gain(j).unwrap_or(f64::NAN))
                    .collect(),
                poles: frozen.poles(),
                model: frozen,
            }
        })
        .collect()
}
