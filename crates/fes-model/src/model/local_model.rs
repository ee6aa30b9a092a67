//! State-space local models in the delta domain (thesis 2.2.2, eq. 2.13; App. D.2.2) and
//! their parameterisations (5.4.2, eq. 5.5-5.6).
//!
//! A local model is x\[k+1\] = x\[k\] + Ts (A x\[k\] + b u\[k-d\] + dx), y\[k\] = c' x\[k\] + dy, with
//! state order n = 2. The network interpolates A, b, c, dx, dy with the validity functions
//! (eq. 2.16), so every parameterisation is first mapped to this direct form
//! ([`SsLocalModel`]):
//!
//! - `ss-direct`: A, b, c, dx, dy free (11 per unit);
//! - `ss-eig-local`: A_i = V_i diag(e_i) V_i^-1 (eq. 5.5), columns of V_i unit vectors
//!   (cos theta, sin theta) given by angles ([`EigLocalUnit`]);
//! - `ss-eig-common`: A_i = V diag(e_i) V^-1 (eq. 5.6) with the gauge V = I, b_r = (1, 1) for
//!   a reference unit r ([`EigCommonUnit`]; [`CommonEigenvectorForm`] holds the thesis's
//!   general-V form and converts it).
//!
//! Stability by construction: a real eigenvalue is e = -(1/Ts) sigmoid(eta), inside
//! (-1/Ts, 0) ([`eigenvalue_from_eta`]). The delta-domain stability region is the disc
//! |1 + Ts p| < 1 (Fig. D.4), i.e. -2/Ts < e < 0 for real e, but (-2/Ts, -1/Ts] holds only
//! modes that flip sign every sample, which no sampled real continuous pole produces
//! ((e^{s Ts} - 1)/Ts lies in (-1/Ts, 0) for s < 0). All maps are generic over [`Scalar`].

#[cfg(not(feature = "std"))]
use crate::num::math::ComplexMath as _;
use crate::num::{Scalar, sigmoid};
use alloc::vec::Vec;
use nalgebra::Complex;

/// A second-order delta-domain local model in direct form (eq. 2.13 with D.2.2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SsLocalModel<S = f64> {
    /// State matrix A (delta domain), row-major: `a[row][col]`.
    pub a: [[S; 2]; 2],
    /// Input vector b.
    pub b: [S; 2],
    /// Output vector c.
    pub c: [S; 2],
    /// State offset d^x (eq. 2.11a).
    pub dx: [S; 2],
    /// Output offset d^y (eq. 2.11b).
    pub dy: S,
}

impl<S: Scalar> SsLocalModel<S> {
    /// All parameters zero.
    pub fn zero() -> Self {
        let z = S::zero();
        Self {
            a: [[z; 2]; 2],
            b: [z; 2],
            c: [z; 2],
            dx: [z; 2],
            dy: z,
        }
    }

    /// One delta-domain step: returns (y\[k\], x\[k+1\]) for state x\[k\] and input u.
    #[inline(always)]
    pub fn step(&self, x: [S; 2], u: S, ts: f64) -> (S, [S; 2]) {
        let y = self.c[0] * x[0] + self.c[1] * x[1] + self.dy;
        let d0 = self.a[0][0] * x[0] + self.a[0][1] * x[1] + self.b[0] * u + self.dx[0];
        let d1 = self.a[1][0] * x[0] + self.a[1][1] * x[1] + self.b[1] * u + self.dx[1];
        (y, [x[0] + d0 * ts, x[1] + d1 * ts])
    }

    /// The equilibrium for constant input u: A x + b u + dx = 0 (eq. A.17), or `None` when
    /// A is singular.
    pub fn equilibrium(&self, u: S) -> Option<[S; 2]> {
        let rhs = [-(self.b[0] * u + self.dx[0]), -(self.b[1] * u + self.dx[1])];
        solve2(&self.a, rhs)
    }

    /// True when every parameter (and derivative) is finite.
    pub fn is_finite(&self) -> bool {
        self.a.iter().flatten().all(|v| v.is_finite())
            && self
                .b
                .iter()
                .chain(&self.c)
                .chain(&self.dx)
                .all(|v| v.is_finite())
            && self.dy.is_finite()
    }
}

impl SsLocalModel<f64> {
    /// Poles p = eig(A) in the delta domain (eq. A.19), complex allowed.
    pub fn poles(&self) -> [Complex<f64>; 2] {
        eig2(&self.a)
    }

    /// max |1 + Ts p| over the poles: < 1 means asymptotically stable (Fig. D.4).
    pub fn stability_radius(&self, ts: f64) -> f64 {
        self.poles()
            .iter()
            .map(|p| (Complex::new(1.0, 0.0) + p * ts).norm())
            .fold(0.0, f64::max)
    }

    /// Steady-state gain G = -c' A^-1 b (eq. A.18), `None` if A is singular. For a pulse
    /// input (u = 1 for one sample) it is also the sum of the output's pulse response.
    pub fn gain(&self) -> Option<f64> {
        let x = solve2(&self.a, self.b)?;
        Some(-(self.c[0] * x[0] + self.c[1] * x[1]))
    }

    /// Steady-state output with no input: -c' A^-1 dx + dy (eq. A.17 at u = 0).
    pub fn offset_output(&self) -> Option<f64> {
        let x = self.equilibrium(0.0)?;
        Some(self.c[0] * x[0] + self.c[1] * x[1] + self.dy)
    }
}

impl<S: Scalar> core::ops::Add for SsLocalModel<S> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        Self {
            a: [
                [self.a[0][0] + o.a[0][0], self.a[0][1] + o.a[0][1]],
                [self.a[1][0] + o.a[1][0], self.a[1][1] + o.a[1][1]],
            ],
            b: [self.b[0] + o.b[0], self.b[1] + o.b[1]],
            c: [self.c[0] + o.c[0], self.c[1] + o.c[1]],
            dx: [self.dx[0] + o.dx[0], self.dx[1] + o.dx[1]],
            dy: self.dy + o.dy,
        }
    }
}

impl<S: Scalar> core::ops::Mul<S> for SsLocalModel<S> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, r: S) -> Self {
        Self {
            a: [
                [self.a[0][0] * r, self.a[0][1] * r],
                [self.a[1][0] * r, self.a[1][1] * r],
            ],
            b: [self.b[0] * r, self.b[1] * r],
            c: [self.c[0] * r, self.c[1] * r],
            dx: [self.dx[0] * r, self.dx[1] * r],
            dy: self.dy * r,
        }
    }
}

/// Margin that keeps [`eigenvalue_from_eta`] strictly inside (-1/Ts, 0) in floating point
/// (sigmoid rounds to exactly 0 or 1 for |eta| > ~37).
pub const EIG_MARGIN: f64 = 1e-9;

/// e = -(1/Ts) (m + (1 - 2m) sigmoid(eta)), m = [`EIG_MARGIN`]: a real delta-domain
/// eigenvalue inside [-(1-m)/Ts, -m/Ts] for every eta, so 1 + Ts e is in [m, 1 - m]
/// (stability by construction, see the module docs).
#[inline]
pub fn eigenvalue_from_eta<S: Scalar>(eta: S, ts: f64) -> S {
    -(sigmoid(eta) * (1.0 - 2.0 * EIG_MARGIN) + EIG_MARGIN) / ts
}

/// The inverse of [`eigenvalue_from_eta`]; `None` unless -(1-m)/Ts < e < -m/Ts.
pub fn eta_from_eigenvalue(e: f64, ts: f64) -> Option<f64> {
    let p = (-e * ts - EIG_MARGIN) / (1.0 - 2.0 * EIG_MARGIN);
    if !(p > 0.0 && p < 1.0) {
        return None;
    }
    let eta = crate::num::logit(p);
    eta.is_finite().then_some(eta)
}

/// True when a real eigenvalue lies in the physical part of the stability region,
/// -1/Ts < e < 0 (within [`EIG_MARGIN`], i.e. exactly when [`eta_from_eigenvalue`] exists).
pub fn eigenvalue_in_region(e: f64, ts: f64) -> bool {
    eta_from_eigenvalue(e, ts).is_some()
}

/// The matrix V whose columns are the unit eigenvectors (cos theta_j, sin theta_j).
#[inline]
pub fn eigenvector_matrix<S: Scalar>(angles: [S; 2]) -> [[S; 2]; 2] {
    [
        [angles[0].cos(), angles[1].cos()],
        [angles[0].sin(), angles[1].sin()],
    ]
}

/// Inverse of a 2x2 matrix, `None` if it is singular (|det| <= 1e-12 times the squared
/// largest entry).
#[inline]
pub fn inverse2<S: Scalar>(m: &[[S; 2]; 2]) -> Option<[[S; 2]; 2]> {
    let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
    let scale = m
        .iter()
        .flatten()
        .map(|v| v.value().abs())
        .fold(0.0, f64::max);
    let big_enough = det.value().abs() > 1e-12 * scale * scale;
    if !big_enough {
        return None;
    }
    Some([
        [m[1][1] / det, -m[0][1] / det],
        [-m[1][0] / det, m[0][0] / det],
    ])
}

/// Solves M x = r for a 2x2 M, `None` if M is singular (see [`inverse2`]).
#[inline]
pub fn solve2<S: Scalar>(m: &[[S; 2]; 2], r: [S; 2]) -> Option<[S; 2]> {
    let inv = inverse2(m)?;
    Some([
        inv[0][0] * r[0] + inv[0][1] * r[1],
        inv[1][0] * r[0] + inv[1][1] * r[1],
    ])
}

/// 2x2 matrix product.
#[inline]
pub fn mat_mul2<S: Scalar>(x: &[[S; 2]; 2], y: &[[S; 2]; 2]) -> [[S; 2]; 2] {
    [
        [
            x[0][0] * y[0][0] + x[0][1] * y[1][0],
            x[0][0] * y[0][1] + x[0][1] * y[1][1],
        ],
        [
            x[1][0] * y[0][0] + x[1][1] * y[1][0],
            x[1][0] * y[0][1] + x[1][1] * y[1][1],
        ],
    ]
}

/// 2x2 matrix times vector.
#[inline]
pub fn mat_vec2<S: Scalar>(m: &[[S; 2]; 2], v: [S; 2]) -> [S; 2] {
    [
        m[0][0] * v[0] + m[0][1] * v[1],
        m[1][0] * v[0] + m[1][1] * v[1],
    ]
}

/// A = V diag(e) V^-1 (eq. 5.5/5.6), `None` if V is singular (parallel eigenvectors).
#[inline]
pub fn a_from_eigensystem<S: Scalar>(v: &[[S; 2]; 2], e: [S; 2]) -> Option<[[S; 2]; 2]> {
    let vi = inverse2(v)?;
    let ve = [
        [v[0][0] * e[0], v[0][1] * e[1]],
        [v[1][0] * e[0], v[1][1] * e[1]],
    ];
    Some(mat_mul2(&ve, &vi))
}

/// Eigenvalues of a real 2x2 matrix (closed form), as complex numbers.
pub fn eig2(a: &[[f64; 2]; 2]) -> [Complex<f64>; 2] {
    let m = 0.5 * (a[0][0] + a[1][1]);
    let det = a[0][0] * a[1][1] - a[0][1] * a[1][0];
    let disc = m * m - det;
    if disc >= 0.0 {
        let r = disc.sqrt();
        // The root of larger magnitude first, the other from det = p1 p2 (no cancellation).
        let p1 = if m >= 0.0 { m + r } else { m - r };
        let p2 = if p1 != 0.0 { det / p1 } else { 0.0 };
        [Complex::new(p1, 0.0), Complex::new(p2, 0.0)]
    } else {
        let i = (-disc).sqrt();
        [Complex::new(m, i), Complex::new(m, -i)]
    }
}

/// A unit of an `ss-eig-local` network: A = V diag(e) V^-1 with its own eigenvectors (eq. 5.5).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EigLocalUnit<S = f64> {
    /// Real eigenvalues e (delta domain).
    pub eigenvalues: [S; 2],
    /// Eigenvector angles theta_j in radians: column j of V is (cos theta_j, sin theta_j).
    pub eigenvector_angles: [S; 2],
    /// Input vector b.
    pub b: [S; 2],
    /// Output vector c.
    pub c: [S; 2],
    /// State offset d^x.
    pub dx: [S; 2],
    /// Output offset d^y.
    pub dy: S,
}

impl<S: Scalar> EigLocalUnit<S> {
    /// The direct form; `None` if the eigenvectors are parallel.
    pub fn to_local_model(&self) -> Option<SsLocalModel<S>> {
        let v = eigenvector_matrix(self.eigenvector_angles);
        Some(SsLocalModel {
            a: a_from_eigensystem(&v, self.eigenvalues)?,
            b: self.b,
            c: self.c,
            dx: self.dx,
            dy: self.dy,
        })
    }
}

/// A unit of an `ss-eig-common` network in the gauge-fixed modal coordinates: A = diag(e)
/// (eq. 5.6 with V = I).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EigCommonUnit<S = f64> {
    /// Real eigenvalues e (delta domain).
    pub eigenvalues: [S; 2],
    /// Input vector b (modal coordinates).
    pub b: [S; 2],
    /// Output vector c (modal coordinates).
    pub c: [S; 2],
    /// State offset d^x (modal coordinates).
    pub dx: [S; 2],
    /// Output offset d^y.
    pub dy: S,
}

impl<S: Scalar> EigCommonUnit<S> {
    /// The direct form, A = diag(e).
    pub fn to_local_model(&self) -> SsLocalModel<S> {
        let z = S::zero();
        SsLocalModel {
            a: [[self.eigenvalues[0], z], [z, self.eigenvalues[1]]],
            b: self.b,
            c: self.c,
            dx: self.dx,
            dy: self.dy,
        }
    }
}

/// Why a general common-eigenvector model cannot be put into the gauge-fixed form.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum GaugeError {
    /// The common eigenvectors are parallel (V singular).
    #[error("the common eigenvectors are parallel (V is singular)")]
    SingularEigenvectors,
    /// The reference unit does not exist.
    #[error("reference unit {unit} does not exist ({units} units)")]
    NoSuchUnit {
        /// Requested reference unit.
        unit: usize,
        /// Number of units.
        units: usize,
    },
    /// In modal coordinates the reference unit's b has a zero entry: it is not controllable
    /// and cannot fix the state scaling.
    #[error(
        "reference unit {unit} has modal input gain b = ({b0}, {b1}) with a zero entry (not controllable)"
    )]
    Uncontrollable {
        /// The reference unit.
        unit: usize,
        /// First modal entry of b.
        b0: f64,
        /// Second modal entry of b.
        b1: f64,
    },
}

/// The thesis's form of a common-eigenvector network (eq. 5.6, Fig. 5.22): one V for all
/// units, and b, c, dx in the original state coordinates x.
///
/// With free b_i, c_i the coordinates are not identifiable: T maps (V, b, c, dx) to
/// (T V, T b, T^-T c, T dx) with the same output. [`Self::to_gauge_fixed`] removes that
/// freedom: modal coordinates (V = I) and b_r = (1, 1) for a reference unit r.
#[derive(Debug, Clone, PartialEq)]
pub struct CommonEigenvectorForm {
    /// Common eigenvector angles (radians): column j of V is (cos theta_j, sin theta_j).
    pub eigenvector_angles: [f64; 2],
    /// Units, with b, c, dx in x coordinates (their A is V diag(e) V^-1).
    pub units: Vec<EigCommonUnit<f64>>,
}

impl CommonEigenvectorForm {
    /// The direct form of unit i (A_i = V diag(e_i) V^-1), `None` if V is singular.
    pub fn local_model(&self, i: usize) -> Option<SsLocalModel<f64>> {
        let u = self.units.get(i)?;
        EigLocalUnit {
            eigenvalues: u.eigenvalues,
            eigenvector_angles: self.eigenvector_angles,
            b: u.b,
            c: u.c,
            dx: u.dx,
            dy: u.dy,
        }
        .to_local_model()
    }

    /// The equivalent gauge-fixed units: w = D V^-1 x with D = diag(1 / (V^-1 b_r)), so
    /// A_i = diag(e_i), b_i' = D V^-1 b_i (b_r' = (1, 1)), c_i' = D^-1 V' c_i,
    /// dx_i' = D V^-1 dx_i, dy unchanged. The output sequence is identical.
    pub fn to_gauge_fixed(
        &self,
        reference_unit: usize,
    ) -> Result<Vec<EigCommonUnit<f64>>, GaugeError> {
        let v = eigenvector_matrix(self.eigenvector_angles);
        let vi = inverse2(&v).ok_or(GaugeError::SingularEigenvectors)?;
        let r = self
            .units
            .get(reference_unit)
            .ok_or(GaugeError::NoSuchUnit {
                unit: reference_unit,
                units: self.units.len(),
            })?;
        let br = mat_vec2(&vi, r.b);
        let scale = br.iter().map(|x| x.abs()).fold(0.0, f64::max);
        if br
            .iter()
            .any(|x| x.abs() <= 1e-12 * scale.max(f64::MIN_POSITIVE) || x.is_nan())
        {
            return Err(GaugeError::Uncontrollable {
                unit: reference_unit,
                b0: br[0],
                b1: br[1],
            });
        }
        let d = [1.0 / br[0], 1.0 / br[1]];
        let vt = [[v[0][0], v[1][0]], [v[0][1], v[1][1]]];
        Ok(self
            .units
            .iter()
            .map(|u| {
                let b = mat_vec2(&vi, u.b);
                let c = mat_vec2(&vt, u.c);
                let dx = mat_vec2(&vi, u.dx);
                EigCommonUnit {
                    eigenvalues: u.eigenvalues,
                    b: [d[0] * b[0], d[1] * b[1]],
                    c: [c[0] / d[0], c[1] / d[1]],
                    dx: [d[0] * dx[0], d[1] * dx[1]],
                    dy: u.dy,
                }
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::num::Dual;

    #[test]
    fn eigensystem_reconstructs_eigenpairs() {
        let angles = [0.3, 2.0];
        let e = [-150.0, -20.0];
        let v = eigenvector_matrix(angles);
        let a = a_from_eigensystem(&v, e).unwrap();
        for j in 0..2 {
            let col = [v[0][j], v[1][j]];
            let av = mat_vec2(&a, col);
            for i in 0..2 {
                assert!((av[i] - e[j] * col[i]).abs() < 1e-10);
            }
        }
        let p = eig2(&a);
        let mut re = [p[0].re, p[1].re];
        re.sort_by(f64::total_cmp);
        assert!((re[0] + 150.0).abs() < 1e-9 && (re[1] + 20.0).abs() < 1e-9);
    }

    #[test]
    fn eta_map_stays_in_region_and_inverts() {
        let ts = 1e-3;
        for &eta in &[-800.0, -40.0, -3.0, 0.0, 1.5, 40.0, 800.0] {
            let e: f64 = eigenvalue_from_eta(eta, ts);
            assert!(e < 0.0 && e > -1.0 / ts, "eta {eta} -> {e}");
            assert!((1.0 + ts * e).abs() < 1.0);
            if let Some(back) = eta_from_eigenvalue(e, ts) {
                assert!((back - eta).abs() < 1e-6 * (1.0 + eta.abs()));
            }
        }
        assert!(eta_from_eigenvalue(0.0, ts).is_none());
        assert!(eta_from_eigenvalue(-1000.0, ts).is_none());
        assert!(eta_from_eigenvalue(9.96, ts).is_none());
    }

    /// d A / d theta and d A / d e from the Dual path against central differences.
    #[test]
    fn eigensystem_derivatives_match_finite_differences() {
        let theta = [0.4, 1.9];
        let eta = [1.2, -2.1];
        let ts = 1e-3;
        let f = |x: [f64; 4]| {
            let e = [eigenvalue_from_eta(x[2], ts), eigenvalue_from_eta(x[3], ts)];
            a_from_eigensystem(&eigenvector_matrix([x[0], x[1]]), e).unwrap()
        };
        let x0 = [theta[0], theta[1], eta[0], eta[1]];
        let xd: [Dual<4>; 4] = core::array::from_fn(|j| Dual::variable(x0[j], j));
        let ed = [
            eigenvalue_from_eta(xd[2], ts),
            eigenvalue_from_eta(xd[3], ts),
        ];
        let ad = a_from_eigensystem(&eigenvector_matrix([xd[0], xd[1]]), ed).unwrap();
        for j in 0..4 {
            let h = 1e-6;
            let mut xp = x0;
            xp[j] += h;
            let mut xm = x0;
            xm[j] -= h;
            let (ap, am) = (f(xp), f(xm));
            for r in 0..2 {
                for c in 0..2 {
                    let fd = (ap[r][c] - am[r][c]) / (2.0 * h);
                    let ex = ad[r][c].d[j];
                    assert!(
                        (fd - ex).abs() < 1e-5 * (1.0 + ex.abs()),
                        "A[{r}][{c}] d/dx{j}: {ex} vs {fd}"
                    );
                }
            }
        }
    }
}
