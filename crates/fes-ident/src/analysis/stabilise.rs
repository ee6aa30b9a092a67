//! Stabilising an identified model (thesis 5.4.3, "Modification of a Model", Table 5.3-5.4):
//! every unstable local eigenvalue is replaced by a slow stable one (thesis: -1 /s) and the
//! offsets (d^x_i, d^y_i) of each modified unit, which carry its operating point (eq. A.7),
//! are re-estimated on the training data; nothing else changes.
//!
//! **Re-estimation.** With input scheduling phi does not depend on the model output, so the
//! network is linear time-varying in its state with the offsets entering affinely (through
//! the state and output equations and the rest state x0 = -A(0)^-1 d^x(0)): the free-run
//! output is *affine* in the offsets and minimising the simulation error (eq. B.8) over them
//! is an exact linear least-squares problem. Its matrix is the output's sensitivity to the
//! offsets, computed exactly with [`Dual`] numbers through the model's own simulation
//! ([`ParamLayout::network`], [`simulate`]); solved by SVD. With output scheduling the
//! output is not affine (phi = y\[k-1\]); the same step is repeated (Gauss-Newton, halving a
//! step that does not lower the error) until it no longer changes the offsets.
//!
//! **Which eigenvalues.** `ss-eig-local` / `ss-eig-common`: every eigenvalue outside
//! (-1/Ts, 0), the region the strict model loader requires. An *unstable* one (`e >= 0` or
//! `e <= -2/Ts`, |1 + Ts e| >= 1) becomes the given slow eigenvalue (thesis: -1 /s); a
//! *stable* one in (-2/Ts, -1/Ts] (a mode faster than one sample, whose shift-domain pole
//! 1 + Ts e lies in (-1, 0]) becomes [`fastest_eigenvalue`], the fastest of the region (shift
//! pole 1e-6, dead-beat): a fast mode stays fast. (Until 2026-12 both became -1 /s, which
//! turned a fast stable mode into the slowest one.) `ss-direct`: every real
//! eigenvalue with |1 + Ts e| >= 1, replaced through the spectral projector
//! A' = A + (e' - e) (A - e_2 I)/(e - e_2) (same eigenvectors, Sylvester's formula); an
//! unstable complex pair or a repeated unstable eigenvalue cannot be replaced this way and is
//! refused. ARX local models are refused. A model with offsets fixed at zero
//! (`zero_offsets`) keeps them at zero: only the eigenvalue changes.

use nalgebra::{Complex, DMatrix, DVector};

use fes_model::model::lmn::{Lmn, LocalModelSet};
use fes_model::model::local_model::eigenvalue_in_region;
use fes_model::model::params::{ParamError, ParamLayout};
use fes_model::model::simulate::{RunError, simulate};
use fes_model::num::Dual;

/// Default replacement eigenvalue, 1/s (thesis 5.4.3).
pub const DEFAULT_EIGENVALUE: f64 = -1.0;

/// The replacement of a stable eigenvalue in (-2/Ts, -1/Ts]: the fastest eigenvalue of the
/// region (-1/Ts, 0), `-(1 - 1e-6)/Ts` (shift-domain pole 1e-6).
pub fn fastest_eigenvalue(ts: f64) -> f64 {
    -(1.0 - 1e-6) / ts
}

/// Why a model could not be stabilised.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StabiliseError {
    /// The replacement eigenvalue is not a slow stable real eigenvalue.
    #[error(
        "replacement eigenvalue {value} 1/s must lie in (-1/Ts, 0) = ({}, 0)",
        -1.0 / ts
    )]
    Eigenvalue {
        /// Given.
        value: f64,
        /// Sampling period.
        ts: f64,
    },
    /// ARX local models have no eigenvalues to replace in this sense.
    #[error(
        "structure {0} is not supported: stabilisation replaces eigenvalues of state-space local models (ss-direct, ss-eig-local, ss-eig-common)"
    )]
    Structure(&'static str),
    /// An ss-direct unit has an unstable complex pair or a repeated unstable eigenvalue.
    #[error(
        "units[{unit}]: the unstable poles {poles} are a complex pair or repeated; only distinct real eigenvalues can be replaced"
    )]
    NotReplaceable {
        /// Unit.
        unit: usize,
        /// Its poles, formatted.
        poles: String,
    },
    /// No training records were given.
    #[error("re-estimating the offsets needs at least one training record")]
    NoRecords,
    /// The records do not excite the modified units' offsets.
    #[error(
        "the offsets of units {units:?} cannot be estimated: the training data hardly activate them (rank {rank} of {params})"
    )]
    NotIdentifiable {
        /// The units.
        units: Vec<usize>,
        /// Numerical rank of the sensitivity matrix.
        rank: usize,
        /// Number of offset parameters.
        params: usize,
    },
    /// The modified model's simulation diverges on the training data.
    #[error("the simulation of the modified model is not finite on the training data")]
    Diverges,
    /// The model or its parameter vector is invalid.
    #[error(transparent)]
    Param(#[from] ParamError),
    /// A record could not be simulated.
    #[error(transparent)]
    Run(#[from] RunError),
}

/// One replaced eigenvalue.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EigenvalueChange {
    /// Unit.
    pub unit: usize,
    /// Which of its two eigenvalues.
    pub index: usize,
    /// The eigenvalue before, 1/s.
    pub old: f64,
    /// The eigenvalue after, 1/s.
    pub new: f64,
}

/// Offsets (d^x_0, d^x_1, d^y) of one unit before and after re-estimation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OffsetChange {
    /// Unit.
    pub unit: usize,
    /// Before.
    pub before: [f64; 3],
    /// After.
    pub after: [f64; 3],
}

/// The result of [`stabilise`].
#[derive(Debug, Clone, PartialEq)]
pub struct Stabilised {
    /// The modified model.
    pub model: Lmn,
    /// Every replaced eigenvalue.
    pub changes: Vec<EigenvalueChange>,
    /// The re-estimated offsets (empty for zero-offset models).
    pub offsets: Vec<OffsetChange>,
    /// Least-squares steps taken (1 for input scheduling plus the confirming one).
    pub iterations: usize,
    /// Training MSSE (eq. B.8) after replacing the eigenvalues, before re-estimating.
    pub msse_replaced: f64,
    /// Training MSSE after re-estimating the offsets.
    pub msse_final: f64,
}

/// A training record: pulse input u (1 in a pulse's sample) and measured normalised force y.
pub type Series<'a> = (&'a [f64], &'a [f64]);

/// Replaces every unstable eigenvalue (module docs) by `eigenvalue`; returns the model and
/// the list of changes (empty when the model is already stable).
pub fn replace_unstable_eigenvalues(
    lmn: &Lmn,
    eigenvalue: f64,
) -> Result<(Lmn, Vec<EigenvalueChange>), StabiliseError> {
    let ts = lmn.ts;
    if !eigenvalue_in_region(eigenvalue, ts) {
        return Err(StabiliseError::Eigenvalue {
            value: eigenvalue,
            ts,
        });
    }
    let mut out = lmn.clone();
    let mut changes = Vec::new();
    let mut replace_eig = |unit: usize, e: &mut [f64; 2]| {
        for (index, v) in e.iter_mut().enumerate() {
            if !eigenvalue_in_region(*v, ts) {
                let stable = (1.0 + ts * *v).abs() < 1.0;
                let new = if stable {
                    fastest_eigenvalue(ts)
                } else {
                    eigenvalue
                };
                changes.push(EigenvalueChange {
                    unit,
                    index,
                    old: *v,
                    new,
                });
                *v = new;
            }
        }
    };
    match &mut out.local {
        LocalModelSet::SsEigLocal(units) => {
            for (i, u) in units.iter_mut().enumerate() {
                replace_eig(i, &mut u.eigenvalues);
            }
        }
        LocalModelSet::SsEigCommon { units, .. } => {
            for (i, u) in units.iter_mut().enumerate() {
                replace_eig(i, &mut u.eigenvalues);
            }
        }
        LocalModelSet::SsDirect(units) => {
            let unstable = |p: Complex<f64>| (Complex::new(1.0, 0.0) + p * ts).norm() >= 1.0;
            for (unit, m) in units.iter_mut().enumerate() {
                // At most two replacements; the poles are recomputed after each.
                for _ in 0..2 {
                    let p = m.poles();
                    let Some(index) = (0..2).find(|&i| unstable(p[i])) else {
                        break;
                    };
                    if p[0].im != 0.0 || p[0].re == p[1].re {
                        return Err(StabiliseError::NotReplaceable {
                            unit,
                            poles: format!("{:.4}, {:.4}", p[0], p[1]),
                        });
                    }
                    let (e, other) = (p[index].re, p[1 - index].re);
                    // Spectral projector onto e's eigenvector: P = (A - other I)/(e - other).
                    let a = m.a;
                    let s = (eigenvalue - e) / (e - other);
                    m.a = [
                        [a[0][0] + s * (a[0][0] - other), a[0][1] + s * a[0][1]],
                        [a[1][0] + s * a[1][0], a[1][1] + s * (a[1][1] - other)],
                    ];
                    changes.push(EigenvalueChange {
                        unit,
                        index,
                        old: e,
                        new: eigenvalue,
                    });
                }
            }
        }
        LocalModelSet::ArxShift { .. } | LocalModelSet::ArxDelta { .. } => {
            return Err(StabiliseError::Structure(lmn.structure().name()));
        }
    }
    Ok((out, changes))
}

/// Index of unit `i`'s d^x_0, d^x_1, d^y in theta.
fn offset_indices(layout: &ParamLayout, unit: usize) -> Option<[usize; 3]> {
    let find = |n: &str| {
        let name = format!("units[{unit}].{n}");
        layout.names().iter().position(|x| *x == name)
    };
    Some([find("dx0")?, find("dx1")?, find("dy")?])
}

/// The model with the offsets of `units` taken from theta (every other number exactly as
/// in `lmn`: re-deriving eigenvalues from eta would round them).
fn with_offsets(lmn: &Lmn, units: &[usize], idx: &[[usize; 3]], theta: &[f64]) -> Lmn {
    let mut out = lmn.clone();
    for (&u, ix) in units.iter().zip(idx) {
        let [dx0, dx1, dy] = ix.map(|i| theta[i]);
        let set = |dx: &mut [f64; 2], y: &mut f64| {
            *dx = [dx0, dx1];
            *y = dy;
        };
        match &mut out.local {
            LocalModelSet::SsDirect(m) => {
                let m = &mut m[u];
                set(&mut m.dx, &mut m.dy)
            }
            LocalModelSet::SsEigLocal(m) => {
                let m = &mut m[u];
                set(&mut m.dx, &mut m.dy)
            }
            LocalModelSet::SsEigCommon { units, .. } => {
                let m = &mut units[u];
                set(&mut m.dx, &mut m.dy)
            }
            LocalModelSet::ArxShift { .. } | LocalModelSet::ArxDelta { .. } => {}
        }
    }
    out
}

/// Sum of squared simulation errors over the records, and the sample count.
fn sse(lmn: &Lmn, records: &[Series<'_>]) -> Result<(f64, usize), StabiliseError> {
    let net = lmn.network().map_err(|e| StabiliseError::Param(e.into()))?;
    let mut sum = 0.0;
    let mut n = 0;
    for (u, y) in records {
        let mut y_hat = vec![0.0; u.len()];
        simulate(&net, u, &mut y_hat)?;
        sum += y
            .iter()
            .zip(&y_hat)
            .map(|(a, b)| (b - a).powi(2))
            .sum::<f64>();
        n += y.len();
    }
    Ok((if sum.is_finite() { sum } else { f64::INFINITY }, n))
}

/// One least-squares step on the offsets of `units`: the exact minimiser when the output is
/// affine in them (input scheduling). Returns the new theta.
fn offset_step(
    lmn: &Lmn,
    layout: &ParamLayout,
    theta: &[f64],
    units: &[usize],
    idx: &[[usize; 3]],
    records: &[Series<'_>],
) -> Result<Vec<f64>, StabiliseError> {
    let rows: usize = records.iter().map(|(u, _)| u.len()).sum();
    let cols = 3 * units.len();
    let mut jac = DMatrix::<f64>::zeros(rows, cols);
    let mut resid = DVector::<f64>::zeros(rows);
    for (j, ix) in idx.iter().enumerate() {
        let mut th: Vec<Dual<3>> = theta.iter().map(|&v| Dual::constant(v)).collect();
        for (s, &i) in ix.iter().enumerate() {
            th[i] = Dual::variable(theta[i], s);
        }
        let net = layout.network::<Dual<3>>(lmn, &th, None)?;
        let mut row = 0;
        for (u, y) in records {
            let mut y_hat = vec![Dual::<3>::constant(0.0); u.len()];
            simulate(&net, u, &mut y_hat)?;
            for (k, yh) in y_hat.iter().enumerate() {
                if !(yh.v.is_finite() && yh.d.iter().all(|d| d.is_finite())) {
                    return Err(StabiliseError::Diverges);
                }
                if j == 0 {
                    resid[row + k] = y[k] - yh.v;
                }
                for s in 0..3 {
                    jac[(row + k, 3 * j + s)] = yh.d[s];
                }
            }
            row += u.len();
        }
    }
    // Column scaling, then SVD with a relative rank threshold.
    let scale: Vec<f64> = (0..cols)
        .map(|c| jac.column(c).norm().max(f64::MIN_POSITIVE))
        .collect();
    for (c, s) in scale.iter().enumerate() {
        jac.column_mut(c).unscale_mut(*s);
    }
    let svd = jac.svd(true, true);
    let smax = svd.singular_values.max();
    let tol = 1e-10 * smax;
    let rank = svd.singular_values.iter().filter(|&&s| s > tol).count();
    if rank < cols || smax == 0.0 {
        return Err(StabiliseError::NotIdentifiable {
            units: units.to_vec(),
            rank,
            params: cols,
        });
    }
    let delta = svd
        .solve(&resid, tol)
        .map_err(|_| StabiliseError::Diverges)?;
    let mut out = theta.to_vec();
    for (j, ix) in idx.iter().enumerate() {
        for s in 0..3 {
            out[ix[s]] += delta[3 * j + s] / scale[3 * j + s];
        }
    }
    Ok(out)
}

/// Re-estimates the offsets of `units` on the training records (module docs); other
/// parameters are unchanged. Returns the model, the number of steps and the offsets.
pub fn reestimate_offsets(
    lmn: &Lmn,
    units: &[usize],
    records: &[Series<'_>],
) -> Result<(Lmn, usize, Vec<OffsetChange>), StabiliseError> {
    if records.is_empty() {
        return Err(StabiliseError::NoRecords);
    }
    if lmn.zero_offsets || units.is_empty() {
        return Ok((lmn.clone(), 0, Vec::new()));
    }
    let layout = ParamLayout::new(lmn);
    let idx: Vec<[usize; 3]> = units
        .iter()
        .map(|&u| offset_indices(&layout, u))
        .collect::<Option<_>>()
        .ok_or(StabiliseError::Structure(lmn.structure().name()))?;
    let theta0 = layout.theta(lmn)?;
    let mut theta = theta0.clone();
    let mut model = lmn.clone();
    let (mut cost, _) = sse(&model, records)?;
    let mut steps = 0;
    for _ in 0..20 {
        let proposal = offset_step(&model, &layout, &theta, units, &idx, records)?;
        steps += 1;
        // Accept the step, halving it while it does not lower the error (output scheduling).
        let mut alpha = 1.0;
        let mut accepted = None;
        for _ in 0..30 {
            let trial: Vec<f64> = theta
                .iter()
                .zip(&proposal)
                .map(|(t, p)| t + alpha * (p - t))
                .collect();
            let m = with_offsets(lmn, units, &idx, &trial);
            let (c, _) = sse(&m, records)?;
            if c <= cost {
                accepted = Some((trial, m, c));
                break;
            }
            alpha *= 0.5;
        }
        let Some((trial, m, c)) = accepted else {
            break;
        };
        let moved = trial
            .iter()
            .zip(&theta)
            .map(|(a, b)| (a - b).abs() / b.abs().max(1e-6))
            .fold(0.0, f64::max);
        let improvement = (cost - c) / cost.max(f64::MIN_POSITIVE);
        theta = trial;
        model = m;
        cost = c;
        if moved < 1e-9 || improvement < 1e-12 {
            break;
        }
    }
    if !cost.is_finite() {
        return Err(StabiliseError::Diverges);
    }
    let offsets = units
        .iter()
        .zip(&idx)
        .map(|(&unit, ix)| OffsetChange {
            unit,
            before: ix.map(|i| theta0[i]),
            after: ix.map(|i| theta[i]),
        })
        .collect();
    Ok((model, steps, offsets))
}

/// Replaces every unstable eigenvalue by `eigenvalue` and re-estimates the modified units'
/// offsets on `records` (thesis 5.4.3). A stable model comes back unchanged.
pub fn stabilise(
    lmn: &Lmn,
    eigenvalue: f64,
    records: &[Series<'_>],
) -> Result<Stabilised, StabiliseError> {
    if records.is_empty() {
        return Err(StabiliseError::NoRecords);
    }
    let (replaced, changes) = replace_unstable_eigenvalues(lmn, eigenvalue)?;
    let mut units: Vec<usize> = changes.iter().map(|c| c.unit).collect();
    units.dedup();
    let (sse_replaced, n) = sse(&replaced, records)?;
    let (model, iterations, offsets) = reestimate_offsets(&replaced, &units, records)?;
    let (sse_final, _) = sse(&model, records)?;
    let n = n.max(1) as f64;
    Ok(Stabilised {
        model,
        changes,
        offsets,
        iterations,
        msse_replaced: sse_replaced / n,
        msse_final: sse_final / n,
    })
}
