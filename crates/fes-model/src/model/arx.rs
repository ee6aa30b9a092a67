//! Local ARX models (thesis 2.2.2, eq. 2.20-2.24; App. A.2) in shift and delta form.
//!
//! Shift form (`arx-shift`, eq. A.35 with A.32), order n = 1..=3:
//! A(q^-1) y_k = B(q^-1) u_{k-d} + d, A = 1 + a_1 q^-1 + ... + a_n q^-n,
//! B = b_0 + b_1 q^-1 + ... + b_{n-1} q^-(n-1); so
//! y_k = sum_l b_l u_{k-d-l} - sum_i a_i y_{k-i} + d = psi' Theta + d (eq. 2.20) with
//! psi = [u(k-d..k-d-n+1), y(k-1..k-n)] and Theta = [b_0..b_{n-1}, -a_1..-a_n] (eq. A.26).
//!
//! Delta form (`arx-delta`, App. D.2.2), same data vector:
//! delta^n y_{k-n} + alpha_{n-1} delta^{n-1} y_{k-n} + ... + alpha_0 y_{k-n}
//!   = beta_{n-1} delta^{n-1} u_{k-d-n+1} + ... + beta_0 u_{k-d-n+1} + d_delta,
//! with delta = (q - 1)/Ts (eq. D.7). Equivalently A_delta(delta) y = B_delta(delta) v + d_delta
//! with v_k = u_{k-d+1}: the transfer function of a delta-domain state-space model with input
//! delay d - 1 (the ARX data vector contains u(k-d) itself). The steady-state gain is
//! beta_0 / alpha_0, as in continuous time. [`delta_to_shift`] converts exactly (multiply by
//! Ts^n and expand (q - 1)^i); simulation always uses the shift coefficients.

use crate::num::Scalar;
#[cfg(not(feature = "std"))]
use crate::num::math::FloatMath as _;
use alloc::{vec, vec::Vec};
use nalgebra::{Complex, Matrix3};

/// Highest supported ARX order n.
pub const MAX_ARX_ORDER: usize = 3;

/// Coefficients of one local ARX model of order n (entries beyond n are zero).
///
/// In shift form `a` = [a_1..a_n] of A(q^-1) and `b` = [b_0..b_{n-1}] of B(q^-1); in delta
/// form `a` = [alpha_0..alpha_{n-1}] of A_delta(delta) (monic, degree n) and
/// `b` = [beta_0..beta_{n-1}] of B_delta(delta). `d` is the offset (eq. 2.24).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArxUnit<S = f64> {
    /// Denominator coefficients (see the type docs for their meaning per form).
    pub a: [S; MAX_ARX_ORDER],
    /// Numerator coefficients.
    pub b: [S; MAX_ARX_ORDER],
    /// Offset d.
    pub d: S,
}

impl<S: Scalar> ArxUnit<S> {
    /// All coefficients zero.
    pub fn zero() -> Self {
        Self {
            a: [S::zero(); MAX_ARX_ORDER],
            b: [S::zero(); MAX_ARX_ORDER],
            d: S::zero(),
        }
    }

    /// One shift-form output: y_k = sum_l b_l u_hist\[l\] - sum_i a_i y_hist\[i\] + d, with
    /// `u_hist[l]` = u_{k-d-l} and `y_hist[i]` = y_{k-1-i}.
    #[inline(always)]
    pub fn output(
        &self,
        n: usize,
        u_hist: &[f64; MAX_ARX_ORDER],
        y_hist: &[S; MAX_ARX_ORDER],
    ) -> S {
        let mut y = self.d;
        for l in 0..n {
            y += self.b[l] * u_hist[l] - self.a[l] * y_hist[l];
        }
        y
    }

    /// True when every coefficient (and derivative) is finite.
    pub fn is_finite(&self) -> bool {
        self.a.iter().chain(&self.b).all(|v| v.is_finite()) && self.d.is_finite()
    }
}

impl<S: Scalar> core::ops::Add for ArxUnit<S> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        Self {
            a: core::array::from_fn(|i| self.a[i] + o.a[i]),
            b: core::array::from_fn(|i| self.b[i] + o.b[i]),
            d: self.d + o.d,
        }
    }
}

impl<S: Scalar> core::ops::Mul<S> for ArxUnit<S> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, r: S) -> Self {
        Self {
            a: core::array::from_fn(|i| self.a[i] * r),
            b: core::array::from_fn(|i| self.b[i] * r),
            d: self.d * r,
        }
    }
}

/// binom(i, m) for i <= 3.
fn binom(i: usize, m: usize) -> f64 {
    const T: [[f64; 4]; 4] = [
        [1.0, 0.0, 0.0, 0.0],
        [1.0, 1.0, 0.0, 0.0],
        [1.0, 2.0, 1.0, 0.0],
        [1.0, 3.0, 3.0, 1.0],
    ];
    T[i][m]
}

/// Exact conversion of delta-form coefficients to shift form for order n at period ts.
///
/// Multiplying the delta equation by Ts^n gives P(q) y_{k-n} = Q(q) u_{k-d-n+1} + Ts^n d with
/// P(q) = sum_i alpha_i Ts^{n-i} (q-1)^i (alpha_n = 1) and
/// Q(q) = Ts sum_j beta_j Ts^{n-1-j} (q-1)^j; the coefficient of q^m in P is a_{n-m}, that of
/// q^m in Q is b_{n-1-m}.
pub fn delta_to_shift<S: Scalar>(delta: &ArxUnit<S>, n: usize, ts: f64) -> ArxUnit<S> {
    let mut out = ArxUnit::zero();
    let tsp = |k: usize| ts.powi(k as i32);
    for m in 0..n {
        // p_m = Ts^0 * binom(n, m) (-1)^{n-m} (alpha_n = 1) + sum_{i=m}^{n-1} ...
        let sign = |k: usize| if k.is_multiple_of(2) { 1.0 } else { -1.0 };
        let mut p = S::from_f64(binom(n, m) * sign(n - m));
        for i in m..n {
            p += delta.a[i] * (tsp(n - i) * binom(i, m) * sign(i - m));
        }
        out.a[n - 1 - m] = p;
        let mut q = S::zero();
        for j in m..n {
            q += delta.b[j] * (ts * tsp(n - 1 - j) * binom(j, m) * sign(j - m));
        }
        out.b[n - 1 - m] = q;
    }
    out.d = delta.d * tsp(n);
    out
}

/// The inverse of [`delta_to_shift`] (back-substitution over the triangular map).
pub fn shift_to_delta(shift: &ArxUnit<f64>, n: usize, ts: f64) -> ArxUnit<f64> {
    let mut out = ArxUnit::zero();
    let sign = |k: usize| if k.is_multiple_of(2) { 1.0 } else { -1.0 };
    let tsp = |k: usize| ts.powi(k as i32);
    for m in (0..n).rev() {
        // p_m = binom(n,m)(-1)^{n-m} + sum_{i=m}^{n-1} alpha_i Ts^{n-i} binom(i,m)(-1)^{i-m}
        let mut rest = binom(n, m) * sign(n - m);
        for i in (m + 1)..n {
            rest += out.a[i] * tsp(n - i) * binom(i, m) * sign(i - m);
        }
        out.a[m] = (shift.a[n - 1 - m] - rest) / tsp(n - m);
        let mut rest_b = 0.0;
        for j in (m + 1)..n {
            rest_b += out.b[j] * ts * tsp(n - 1 - j) * binom(j, m) * sign(j - m);
        }
        out.b[m] = (shift.b[n - 1 - m] - rest_b) / (ts * tsp(n - 1 - m));
    }
    out.d = shift.d / tsp(n);
    out
}

/// Shift-domain poles z of a shift-form model: roots of z^n + a_1 z^{n-1} + ... + a_n.
pub fn shift_poles(shift: &ArxUnit<f64>, n: usize) -> Vec<Complex<f64>> {
    match n {
        1 => vec![Complex::new(-shift.a[0], 0.0)],
        2 => {
            let m = [[-shift.a[0], -shift.a[1]], [1.0, 0.0]];
            super::local_model::eig2(&m).to_vec()
        }
        _ => {
            let c = Matrix3::new(
                -shift.a[0],
                -shift.a[1],
                -shift.a[2], //
                1.0,
                0.0,
                0.0, //
                0.0,
                1.0,
                0.0,
            );
            c.complex_eigenvalues().iter().copied().collect()
        }
    }
}

/// Steady-state gain B(1)/A(1) (eq. A.38) of a shift-form model, `None` if A(1) = 0.
pub fn shift_gain(shift: &ArxUnit<f64>, n: usize) -> Option<f64> {
    let a1: f64 = 1.0 + shift.a[..n].iter().sum::<f64>();
    let b1: f64 = shift.b[..n].iter().sum();
    (a1 != 0.0).then(|| b1 / a1)
}

/// Steady-state output with no input, d / A(1) (eq. A.37 at u = 0), `None` if A(1) = 0.
pub fn shift_offset_output(shift: &ArxUnit<f64>, n: usize) -> Option<f64> {
    let a1: f64 = 1.0 + shift.a[..n].iter().sum::<f64>();
    (a1 != 0.0).then(|| shift.d / a1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_order_conversion_by_hand() {
        // delta y + alpha0 y = beta0 u + d  <=>  y_k = (1 - Ts alpha0) y_{k-1} + Ts beta0 u + Ts d
        let ts = 1e-3;
        let d = ArxUnit {
            a: [30.0, 0.0, 0.0],
            b: [400.0, 0.0, 0.0],
            d: 2.0,
        };
        let s = delta_to_shift(&d, 1, ts);
        assert!((s.a[0] - (ts * 30.0 - 1.0)).abs() < 1e-15);
        assert!((s.b[0] - ts * 400.0).abs() < 1e-15);
        assert!((s.d - ts * 2.0).abs() < 1e-18);
    }

    #[test]
    fn conversion_round_trips_and_keeps_gain() {
        let ts = 1e-3;
        for n in 1..=3 {
            let d = ArxUnit {
                a: [2500.0, 100.0, 7.0],
                b: [25000.0, -3.0, 0.5],
                d: 0.3,
            };
            let mut dn = ArxUnit::zero();
            dn.a[..n].copy_from_slice(&d.a[..n]);
            dn.b[..n].copy_from_slice(&d.b[..n]);
            dn.d = d.d;
            let s = delta_to_shift(&dn, n, ts);
            let back = shift_to_delta(&s, n, ts);
            for i in 0..n {
                assert!(
                    (back.a[i] - dn.a[i]).abs() < 1e-7 * (1.0 + dn.a[i].abs()),
                    "n={n} a{i}"
                );
                assert!(
                    (back.b[i] - dn.b[i]).abs() < 1e-7 * (1.0 + dn.b[i].abs()),
                    "n={n} b{i}"
                );
            }
            // Gain: B(1)/A(1) in shift form equals beta_0/alpha_0 in delta form.
            let g = shift_gain(&s, n).unwrap();
            assert!(
                (g - dn.b[0] / dn.a[0]).abs() < 1e-6 * (dn.b[0] / dn.a[0]).abs(),
                "n={n}"
            );
        }
    }
}
