//! Pole-placement design of one local controller and one local state estimator, in the
//! delta domain (thesis 3.3, App. C.2).
//!
//! The local model of unit `i` is `δx = A x + b u + dx`, `y = c'x + dy` (App. D.2.2, the
//! delta operator replacing `d/dt` in eq. C.8). Integral action (C.2.3) augments it with
//! `δx_I = y - r` (eq. C.24), giving (eq. C.25)
//!
//! ```text
//! A_aug = [[0, c'], [0, A]],   b_aug = [0; b],
//! ```
//!
//! and the control law `u = -[K_I, K_x'] [x_I; x]` (eq. C.26). The gain is placed by
//! Ackermann's formula (eq. C.14-C.16) so that `A_aug - b_aug K` (eq. C.27) has the roots
//! `{p1, p2, p3}`. The offsets `dx, dy` do not enter the design: integral action removes
//! their steady-state effect (eq. C.28-C.29).
//!
//! The estimator gain `L` (C.2.2, eq. C.18-C.23) is placed by the dual Ackermann formula
//! (eq. C.21) so that `A - L c'` (eq. C.19) has the given estimator poles.
//!
//! Every design is checked: the controllability matrix `F` (eq. C.15) and the observability
//! matrix `O` (eq. C.22) must be numerically well conditioned, and the eigenvalues of the
//! resulting closed loop must be the requested poles (to [`PLACEMENT_TOLERANCE`]). A
//! failure is an error naming the unit, never a silent fallback.

use nalgebra::{Complex, Matrix2, Matrix3, RowVector3, Schur, Vector2, Vector3};
use serde::{Deserialize, Serialize};

use crate::model::SsLocalModel;
use crate::model::local_model::eig2;

use super::poles::{Pole, RiseTimeRule};
#[cfg(not(feature = "std"))]
use crate::num::math::ComplexMath as _;

/// The three closed-loop poles of one local loop with integral action (eq. C.27): the
/// dominant pair `p1, p2` and the integrator pole `p3` (6.5.3), delta domain, 1/s.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ClosedLoopPoles {
    /// First dominant pole (the faster one for a real pair).
    pub p1: Pole,
    /// Second dominant pole.
    pub p2: Pole,
    /// Third pole, for the integrator state (thesis: `-1.9/Ts`).
    pub p3: Pole,
}

/// The two poles of a local state estimator (eq. C.20), delta domain, 1/s.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EstimatorPoles {
    /// First estimator pole.
    pub p1: Pole,
    /// Second estimator pole.
    pub p2: Pole,
}

/// State-feedback gains of one local controller with integral action, `u = -K_I x_I - K_x' x`
/// (eq. C.26).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LocalGains {
    /// Integral gain `K_I`.
    pub k_i: f64,
    /// State gain `K_x`.
    pub k_x: [f64; 2],
}

/// Options of the local design.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DesignOptions {
    /// How a unit's rise time becomes its dominant poles (default: the thesis's rule,
    /// `w_n t_r = 3.2`). A controller file that does not name a rule was designed with
    /// [`RiseTimeRule::legacy`] and is read so.
    #[serde(default = "RiseTimeRule::legacy")]
    pub rise_time_rule: RiseTimeRule,
    /// Accept a local model with a negative steady-state gain (default `false`; see
    /// [`DesignError::NegativeGain`] for why it is refused).
    pub allow_negative_gain: bool,
    /// Smallest accepted reciprocal condition number of the column-normalised
    /// controllability matrix `F` (eq. C.15) and of the row-normalised observability matrix
    /// `O` (eq. C.22). Default `1e-9`.
    pub min_rcond: f64,
}

impl Default for DesignOptions {
    fn default() -> Self {
        Self {
            rise_time_rule: RiseTimeRule::Thesis,
            allow_negative_gain: false,
            min_rcond: 1e-9,
        }
    }
}

/// Largest accepted relative distance `|λ - p| / |p|` between a requested pole `p` and
/// the nearest eigenvalue `λ` of the designed closed loop. Every design is verified
/// against it; a model too badly conditioned to meet it is refused.
pub const PLACEMENT_TOLERANCE: f64 = 1e-6;

/// Why a local controller or estimator cannot be designed.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum DesignError {
    /// A model parameter or pole is NaN or infinite.
    #[error("unit {unit}: {field} is not finite")]
    NonFinite {
        /// Unit index.
        unit: usize,
        /// Which quantity.
        field: &'static str,
    },
    /// A requested pole lies outside the delta-domain stability region (circle of radius
    /// `1/Ts` centred at `-1/Ts`, Fig. D.4); the loop would be unstable.
    #[error(
        "unit {unit}: pole {which} = {re} {im:+}i 1/s lies outside the delta-domain stability \
         region |1 + p Ts| < 1 (Ts = {ts} s)"
    )]
    UnstablePole {
        /// Unit index.
        unit: usize,
        /// Which pole (`"p1"`, ...).
        which: &'static str,
        /// Real part, 1/s.
        re: f64,
        /// Imaginary part, 1/s.
        im: f64,
        /// Sampling period, s.
        ts: f64,
    },
    /// A pair of poles must be both real or complex conjugates, and a single pole real,
    /// for the gains to be real.
    #[error(
        "unit {unit}: poles {which} must be both real or a complex-conjugate pair (and p3 real)"
    )]
    NotConjugate {
        /// Unit index.
        unit: usize,
        /// Which poles.
        which: &'static str,
    },
    /// `A` is singular: the local model has a pole at 0 and no finite steady-state gain.
    #[error(
        "unit {unit}: the local A matrix is singular (a pole at 0), so the steady-state gain \
         G = -c'A^-1 b is undefined and integral action cannot be designed"
    )]
    SingularA {
        /// Unit index.
        unit: usize,
    },
    /// The local steady-state gain is negative. Thesis 6.5.3: an LCN whose units mix
    /// negative and positive gains switches back and forth between the neighbouring
    /// controllers and never settles. Fix: identify the model with the offsets `dx, dy`
    /// fixed at zero (a zero-offset fit keeps every local gain non-negative), or set
    /// `allow_negative_gain` if you know what you are doing.
    #[error(
        "unit {unit}: steady-state gain G = -c'A^-1 b = {gain} is negative; an LCN mixing \
         negative- and positive-gain units switches back and forth between them (thesis 6.5.3). \
         Identify the model with offsets fixed at zero (zero-offset fit), or set \
         allow_negative_gain to override"
    )]
    NegativeGain {
        /// Unit index.
        unit: usize,
        /// The local steady-state gain `G = -c'A^-1 b` (eq. A.18).
        gain: f64,
    },
    /// The augmented local model `(A_aug, b_aug)` is (numerically) not controllable: the
    /// controllability matrix `F` (eq. C.15) is near singular. This happens when `(A, b)`
    /// is not controllable or when the local gain is (nearly) zero.
    #[error(
        "unit {unit}: augmented local model is not controllable: controllability matrix F \
         (eq. C.15) has reciprocal condition {rcond:e} < {min_rcond:e} (is (A, b) \
         controllable and the local gain non-zero?)"
    )]
    Uncontrollable {
        /// Unit index.
        unit: usize,
        /// Reciprocal condition number of the column-normalised `F`.
        rcond: f64,
        /// Threshold in force.
        min_rcond: f64,
    },
    /// `(A, c')` is (numerically) not observable: the observability matrix `O` (eq. C.22)
    /// is near singular, so no estimator can place the error poles.
    #[error(
        "unit {unit}: local model is not observable: observability matrix O (eq. C.22) has \
         reciprocal condition {rcond:e} < {min_rcond:e}"
    )]
    Unobservable {
        /// Unit index.
        unit: usize,
        /// Reciprocal condition number of the row-normalised `O`.
        rcond: f64,
        /// Threshold in force.
        min_rcond: f64,
    },
    /// Ackermann's formula returned gains whose closed loop does not have the requested
    /// poles to within [`PLACEMENT_TOLERANCE`] (numerical breakdown on a badly conditioned
    /// local model, e.g. nearly equal eigenvalues with nearly parallel eigenvectors).
    #[error(
        "unit {unit}: the designed closed loop misses the requested poles by {rel_error:e} \
         (relative, limit {PLACEMENT_TOLERANCE:e}); the local model is too badly conditioned \
         for these poles"
    )]
    PlacementInaccurate {
        /// Unit index.
        unit: usize,
        /// Largest relative pole error.
        rel_error: f64,
    },
}

/// Real coefficients `[a1, a2]` of `λ² + a1 λ + a2` with roots `p, q` (both real or a
/// conjugate pair), or `None` when the pair is not self-conjugate.
fn pair_coefficients(p: Pole, q: Pole) -> Option<[f64; 2]> {
    let (pc, qc) = (p.to_complex(), q.to_complex());
    let sum = pc + qc;
    let prod = pc * qc;
    let scale = pc.norm().max(qc.norm()).max(f64::MIN_POSITIVE);
    let real_pair = p.im == 0.0 && q.im == 0.0;
    let conjugate = (p.re - q.re).abs() <= 1e-12 * scale && (p.im + q.im).abs() <= 1e-12 * scale;
    if !(real_pair || conjugate) {
        return None;
    }
    Some([-sum.re, prod.re])
}

fn check_pole(unit: usize, which: &'static str, p: Pole, ts: f64) -> Result<(), DesignError> {
    if !(p.re.is_finite() && p.im.is_finite()) {
        return Err(DesignError::NonFinite { unit, field: which });
    }
    if !p.is_stable(ts) {
        return Err(DesignError::UnstablePole {
            unit,
            which,
            re: p.re,
            im: p.im,
            ts,
        });
    }
    Ok(())
}

/// `(A, b, c)` of a local model as nalgebra values.
pub fn plant_matrices(m: &SsLocalModel<f64>) -> (Matrix2<f64>, Vector2<f64>, Vector2<f64>) {
    (
        Matrix2::new(m.a[0][0], m.a[0][1], m.a[1][0], m.a[1][1]),
        Vector2::new(m.b[0], m.b[1]),
        Vector2::new(m.c[0], m.c[1]),
    )
}

fn check_plant(
    unit: usize,
    a: &Matrix2<f64>,
    b: &Vector2<f64>,
    c: &Vector2<f64>,
) -> Result<(), DesignError> {
    if !a.iter().all(|v| v.is_finite()) {
        return Err(DesignError::NonFinite { unit, field: "A" });
    }
    if !b.iter().all(|v| v.is_finite()) {
        return Err(DesignError::NonFinite { unit, field: "b" });
    }
    if !c.iter().all(|v| v.is_finite()) {
        return Err(DesignError::NonFinite { unit, field: "c" });
    }
    Ok(())
}

/// Reciprocal condition number (smallest over largest singular value) of a 3x3 matrix
/// after scaling each column to unit length; 0 when a column is zero.
fn rcond_columns3(m: &Matrix3<f64>) -> f64 {
    let mut s = *m;
    for mut col in s.column_iter_mut() {
        let n = col.norm();
        if n == 0.0 || !n.is_finite() {
            return 0.0;
        }
        col /= n;
    }
    let sv = s.singular_values();
    let (max, min) = (sv.max(), sv.min());
    if max > 0.0 { min / max } else { 0.0 }
}

/// Reciprocal condition number of a 2x2 matrix after scaling each row to unit length.
fn rcond_rows2(m: &Matrix2<f64>) -> f64 {
    let mut s = *m;
    for mut row in s.row_iter_mut() {
        let n = row.norm();
        if n == 0.0 || !n.is_finite() {
            return 0.0;
        }
        row /= n;
    }
    let sv = s.singular_values();
    let (max, min) = (sv.max(), sv.min());
    if max > 0.0 { min / max } else { 0.0 }
}

/// The augmented local model of eq. (C.25): `A_aug = [[0, c'], [0, A]]`, `b_aug = [0; b]`.
pub fn augmented(
    a: &Matrix2<f64>,
    b: &Vector2<f64>,
    c: &Vector2<f64>,
) -> (Matrix3<f64>, Vector3<f64>) {
    let a_aug = Matrix3::new(
        0.0,
        c[0],
        c[1],
        0.0,
        a[(0, 0)],
        a[(0, 1)],
        0.0,
        a[(1, 0)],
        a[(1, 1)],
    );
    (a_aug, Vector3::new(0.0, b[0], b[1]))
}

/// Controllability matrix `F = [b, A b, A² b]` (eq. C.15) of the augmented model.
pub fn controllability_matrix(a_aug: &Matrix3<f64>, b_aug: &Vector3<f64>) -> Matrix3<f64> {
    let ab = a_aug * b_aug;
    let aab = a_aug * ab;
    Matrix3::from_columns(&[*b_aug, ab, aab])
}

/// Observability matrix `O = [c'; c'A]` (eq. C.22).
pub fn observability_matrix(a: &Matrix2<f64>, c: &Vector2<f64>) -> Matrix2<f64> {
    let ct = c.transpose();
    let cta = ct * a;
    Matrix2::from_rows(&[ct, cta])
}

/// Largest relative distance from each requested pole to its nearest not yet matched
/// eigenvalue (greedy matching); infinite when there are fewer eigenvalues than poles.
fn pole_mismatch(eigenvalues: &[Complex<f64>], poles: &[Pole]) -> f64 {
    let mut used = [false; 3];
    let mut worst = 0.0f64;
    for p in poles {
        let p = p.to_complex();
        let mut best: Option<(usize, f64)> = None;
        for (i, ev) in eigenvalues.iter().enumerate() {
            let d = (ev - p).norm();
            if !used[i] && best.is_none_or(|(_, bd)| d < bd) {
                best = Some((i, d));
            }
        }
        let Some((i, d)) = best else {
            return f64::INFINITY;
        };
        used[i] = true;
        worst = worst.max(d / p.norm().max(f64::MIN_POSITIVE));
    }
    worst
}

/// Eigenvalues of a 3x3 matrix (real Schur form, bounded iterations); `None` if the
/// iteration does not converge.
fn eigenvalues3(m: &Matrix3<f64>) -> Option<[Complex<f64>; 3]> {
    let schur = Schur::try_new(*m, f64::EPSILON, 10_000)?;
    let ev = schur.complex_eigenvalues();
    Some([ev[0], ev[1], ev[2]])
}

/// Design the state-feedback gains with integral action of local model `unit` by pole
/// placement (Ackermann, eq. C.14-C.16 on the augmented model of eq. C.25), so that the
/// closed local loop (eq. C.27) has the roots `poles`.
///
/// Checks, in order: finite data, poles inside the stability region and self-conjugate,
/// `A` non-singular, the sign of the steady-state gain `G = -c'A^-1 b` (refused when
/// negative unless `opts.allow_negative_gain`), the conditioning of `F` (eq. C.15), and that
/// the eigenvalues of the closed loop are the requested poles.
pub fn design_controller(
    unit: usize,
    model: &SsLocalModel<f64>,
    poles: &ClosedLoopPoles,
    ts: f64,
    opts: &DesignOptions,
) -> Result<LocalGains, DesignError> {
    let (a, b, c) = plant_matrices(model);
    check_plant(unit, &a, &b, &c)?;
    check_pole(unit, "p1", poles.p1, ts)?;
    check_pole(unit, "p2", poles.p2, ts)?;
    check_pole(unit, "p3", poles.p3, ts)?;
    let [s1, s2] = pair_coefficients(poles.p1, poles.p2).ok_or(DesignError::NotConjugate {
        unit,
        which: "p1, p2",
    })?;
    if poles.p3.im != 0.0 {
        return Err(DesignError::NotConjugate { unit, which: "p3" });
    }
    let p3 = poles.p3.re;
    // (λ² + s1 λ + s2)(λ - p3)
    let want = [s1 - p3, s2 - s1 * p3, -s2 * p3];

    // eq. (A.18), from the model library.
    let gain = model.gain().ok_or(DesignError::SingularA { unit })?;
    if gain < 0.0 && !opts.allow_negative_gain {
        return Err(DesignError::NegativeGain { unit, gain });
    }

    let (a_aug, b_aug) = augmented(&a, &b, &c);
    let f = controllability_matrix(&a_aug, &b_aug);
    let rcond = rcond_columns3(&f);
    if rcond.is_nan() || rcond < opts.min_rcond {
        return Err(DesignError::Uncontrollable {
            unit,
            rcond,
            min_rcond: opts.min_rcond,
        });
    }
    // α(A) = A³ + a1 A² + a2 A + a3 I  (eq. C.16)
    let a2m = a_aug * a_aug;
    let alpha = a2m * a_aug + a2m * want[0] + a_aug * want[1] + Matrix3::identity() * want[2];
    // K' = [0 0 1] F^-1 α(A)  (eq. C.14): solve F' w = e3, then K' = w' α(A).
    let w = f
        .transpose()
        .lu()
        .solve(&Vector3::new(0.0, 0.0, 1.0))
        .ok_or(DesignError::Uncontrollable {
            unit,
            rcond,
            min_rcond: opts.min_rcond,
        })?;
    let k: RowVector3<f64> = w.transpose() * alpha;
    if !k.iter().all(|v| v.is_finite()) {
        return Err(DesignError::NonFinite { unit, field: "K" });
    }
    let closed = a_aug - b_aug * k;
    let rel_error = eigenvalues3(&closed).map_or(f64::INFINITY, |ev| {
        pole_mismatch(&ev, &[poles.p1, poles.p2, poles.p3])
    });
    if rel_error.is_nan() || rel_error > PLACEMENT_TOLERANCE {
        return Err(DesignError::PlacementInaccurate { unit, rel_error });
    }
    Ok(LocalGains {
        k_i: k[0],
        k_x: [k[1], k[2]],
    })
}

/// Design the state-estimator gain `L` of local model `unit` by the dual Ackermann formula
/// `L = α_e(A) O^-1 [0; 1]` (eq. C.21-C.23), so that the estimation error `δx̃ = (A - L c') x̃`
/// (eq. C.19) has the roots `poles`.
pub fn design_estimator(
    unit: usize,
    model: &SsLocalModel<f64>,
    poles: &EstimatorPoles,
    ts: f64,
    opts: &DesignOptions,
) -> Result<[f64; 2], DesignError> {
    let (a, b, c) = plant_matrices(model);
    check_plant(unit, &a, &b, &c)?;
    check_pole(unit, "estimator p1", poles.p1, ts)?;
    check_pole(unit, "estimator p2", poles.p2, ts)?;
    let want = pair_coefficients(poles.p1, poles.p2).ok_or(DesignError::NotConjugate {
        unit,
        which: "estimator p1, p2",
    })?;
    let o = observability_matrix(&a, &c);
    let rcond = rcond_rows2(&o);
    if rcond.is_nan() || rcond < opts.min_rcond {
        return Err(DesignError::Unobservable {
            unit,
            rcond,
            min_rcond: opts.min_rcond,
        });
    }
    // α_e(A) = A² + a1 A + a2 I  (eq. C.23)
    let alpha = a * a + a * want[0] + Matrix2::identity() * want[1];
    let v = o
        .lu()
        .solve(&Vector2::new(0.0, 1.0))
        .ok_or(DesignError::Unobservable {
            unit,
            rcond,
            min_rcond: opts.min_rcond,
        })?;
    let l = alpha * v;
    if !l.iter().all(|x| x.is_finite()) {
        return Err(DesignError::NonFinite { unit, field: "L" });
    }
    let closed = a - l * c.transpose();
    // Closed-form 2x2 eigenvalues from the model library.
    let ev = eig2(&[
        [closed[(0, 0)], closed[(0, 1)]],
        [closed[(1, 0)], closed[(1, 1)]],
    ]);
    let rel_error = pole_mismatch(&ev, &[poles.p1, poles.p2]);
    if rel_error.is_nan() || rel_error > PLACEMENT_TOLERANCE {
        return Err(DesignError::PlacementInaccurate { unit, rel_error });
    }
    Ok([l[0], l[1]])
}
