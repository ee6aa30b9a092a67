//! Generic scalars: one implementation of each equation, two arithmetics.
//!
//! The validity functions, the parameterisation maps and the network step are written once,
//! generic over [`Scalar`]. Instantiated with `f64` they are the real-time hot path;
//! instantiated with the forward-mode dual number [`Dual<N>`] they return exact first
//! derivatives with respect to up to `N` seeded quantities (parameters, knots, or the
//! scheduling variable), which identification (Levenberg-Marquardt, thesis B.3) and knot
//! optimisation (5.4.2) need. `Dual` lives on the stack (no heap).
//!
//! Comparisons (`<`, `==`, ...) look at the value only: branches such as "which knot span
//! holds phi" are piecewise constant, so the derivative of the taken branch is the derivative.

use core::fmt::Debug;
use core::ops::{Add, AddAssign, Div, DivAssign, Mul, MulAssign, Neg, Sub, SubAssign};

#[cfg(not(feature = "std"))]
pub(crate) mod math;

/// A real number type the model equations can be evaluated in.
///
/// Implemented for `f64` (values) and [`Dual<N>`] (values plus `N` exact partial
/// derivatives). Mixed arithmetic with plain `f64` constants is available on the right-hand
/// side (`s * 2.0`), so constants never carry derivative storage.
pub trait Scalar:
    Copy
    + Debug
    + PartialEq
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
    + DivAssign
    + Add<f64, Output = Self>
    + Sub<f64, Output = Self>
    + Mul<f64, Output = Self>
    + Div<f64, Output = Self>
    + 'static
{
    /// A constant (all derivatives zero).
    fn from_f64(v: f64) -> Self;
    /// The value (derivatives dropped).
    fn value(self) -> f64;
    /// e^self.
    fn exp(self) -> Self;
    /// Natural logarithm.
    fn ln(self) -> Self;
    /// Square root.
    fn sqrt(self) -> Self;
    /// Sine (radians).
    fn sin(self) -> Self;
    /// Cosine (radians).
    fn cos(self) -> Self;
    /// True when the value and every derivative are finite.
    fn is_finite(self) -> bool;

    /// The constant 0.
    #[inline(always)]
    fn zero() -> Self {
        Self::from_f64(0.0)
    }
    /// The constant 1.
    #[inline(always)]
    fn one() -> Self {
        Self::from_f64(1.0)
    }
    /// |self| (derivative sign follows the value; 0 has derivative +d).
    #[inline(always)]
    fn abs(self) -> Self {
        if self.value() < 0.0 { -self } else { self }
    }
    /// self clamped into [lo, hi] by value; the bound taken carries its own derivatives.
    #[inline(always)]
    fn clamp_to(self, lo: Self, hi: Self) -> Self {
        if self.value() < lo.value() {
            lo
        } else if self.value() > hi.value() {
            hi
        } else {
            self
        }
    }
}

/// The math methods of [`Scalar`] for `f64`: std's inherent methods, or without std those of
/// `math::FloatMath` (`libm`). Spelled out per build because without std `f64::exp` would
/// resolve to `Scalar::exp` itself.
macro_rules! f64_math {
    ($($name:ident),*) => {$(
        #[cfg(feature = "std")]
        #[inline(always)]
        fn $name(self) -> Self {
            f64::$name(self)
        }
        #[cfg(not(feature = "std"))]
        #[inline(always)]
        fn $name(self) -> Self {
            math::FloatMath::$name(self)
        }
    )*};
}

impl Scalar for f64 {
    #[inline(always)]
    fn from_f64(v: f64) -> Self {
        v
    }
    #[inline(always)]
    fn value(self) -> f64 {
        self
    }
    f64_math!(exp, ln, sqrt, sin, cos);
    #[inline(always)]
    fn is_finite(self) -> bool {
        f64::is_finite(self)
    }
}

/// Forward-mode dual number: a value `v` and its partial derivatives `d[j] = dv/dp_j` with
/// respect to `N` seeded quantities `p_j`.
///
/// Equality and ordering compare values only (see the module docs).
#[derive(Clone, Copy, Debug)]
pub struct Dual<const N: usize> {
    /// The value.
    pub v: f64,
    /// Partial derivatives with respect to the `N` seeded quantities.
    pub d: [f64; N],
}

impl<const N: usize> Dual<N> {
    /// A constant (all derivatives zero).
    #[inline(always)]
    pub const fn constant(v: f64) -> Self {
        Self { v, d: [0.0; N] }
    }

    /// The seeded variable number `j`: value `v`, derivative 1 with respect to itself.
    /// Panics if `j >= N` (a programming error, never data-dependent).
    #[inline]
    pub fn variable(v: f64, j: usize) -> Self {
        let mut d = [0.0; N];
        d[j] = 1.0;
        Self { v, d }
    }

    /// Applies a scalar function with value `f` and derivative `df` at `self.v`
    /// (chain rule).
    #[inline(always)]
    fn chain(self, f: f64, df: f64) -> Self {
        let mut d = self.d;
        for x in &mut d {
            *x *= df;
        }
        Self { v: f, d }
    }
}

impl<const N: usize> PartialEq for Dual<N> {
    #[inline(always)]
    fn eq(&self, other: &Self) -> bool {
        self.v == other.v
    }
}

impl<const N: usize> PartialOrd for Dual<N> {
    #[inline(always)]
    fn partial_cmp(&self, other: &Self) -> Option<core::cmp::Ordering> {
        self.v.partial_cmp(&other.v)
    }
}

impl<const N: usize> Add for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn add(mut self, rhs: Self) -> Self {
        self.v += rhs.v;
        for (a, b) in self.d.iter_mut().zip(rhs.d.iter()) {
            *a += *b;
        }
        self
    }
}

impl<const N: usize> Sub for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn sub(mut self, rhs: Self) -> Self {
        self.v -= rhs.v;
        for (a, b) in self.d.iter_mut().zip(rhs.d.iter()) {
            *a -= *b;
        }
        self
    }
}

impl<const N: usize> Mul for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, rhs: Self) -> Self {
        let mut d = [0.0; N];
        for (j, x) in d.iter_mut().enumerate() {
            *x = self.d[j] * rhs.v + rhs.d[j] * self.v;
        }
        Self {
            v: self.v * rhs.v,
            d,
        }
    }
}

impl<const N: usize> Div for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn div(self, rhs: Self) -> Self {
        let inv = 1.0 / rhs.v;
        let v = self.v * inv;
        let mut d = [0.0; N];
        for (j, x) in d.iter_mut().enumerate() {
            *x = (self.d[j] - v * rhs.d[j]) * inv;
        }
        Self { v, d }
    }
}

impl<const N: usize> Neg for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn neg(mut self) -> Self {
        self.v = -self.v;
        for x in &mut self.d {
            *x = -*x;
        }
        self
    }
}

impl<const N: usize> Add<f64> for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn add(mut self, rhs: f64) -> Self {
        self.v += rhs;
        self
    }
}

impl<const N: usize> Sub<f64> for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn sub(mut self, rhs: f64) -> Self {
        self.v -= rhs;
        self
    }
}

impl<const N: usize> Mul<f64> for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn mul(mut self, rhs: f64) -> Self {
        self.v *= rhs;
        for x in &mut self.d {
            *x *= rhs;
        }
        self
    }
}

impl<const N: usize> Div<f64> for Dual<N> {
    type Output = Self;
    #[inline(always)]
    fn div(self, rhs: f64) -> Self {
        self * (1.0 / rhs)
    }
}

macro_rules! assign_op {
    ($tr:ident, $m:ident, $op:tt) => {
        impl<const N: usize> $tr for Dual<N> {
            #[inline(always)]
            fn $m(&mut self, rhs: Self) {
                *self = *self $op rhs;
            }
        }
    };
}
assign_op!(AddAssign, add_assign, +);
assign_op!(SubAssign, sub_assign, -);
assign_op!(MulAssign, mul_assign, *);
assign_op!(DivAssign, div_assign, /);

impl<const N: usize> Scalar for Dual<N> {
    #[inline(always)]
    fn from_f64(v: f64) -> Self {
        Self::constant(v)
    }
    #[inline(always)]
    fn value(self) -> f64 {
        self.v
    }
    #[inline(always)]
    fn exp(self) -> Self {
        let e = self.v.exp();
        self.chain(e, e)
    }
    #[inline(always)]
    fn ln(self) -> Self {
        self.chain(self.v.ln(), 1.0 / self.v)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        let s = self.v.sqrt();
        self.chain(s, 0.5 / s)
    }
    #[inline(always)]
    fn sin(self) -> Self {
        self.chain(self.v.sin(), self.v.cos())
    }
    #[inline(always)]
    fn cos(self) -> Self {
        self.chain(self.v.cos(), -self.v.sin())
    }
    #[inline(always)]
    fn is_finite(self) -> bool {
        self.v.is_finite() && self.d.iter().all(|x| x.is_finite())
    }
}

/// The logistic function 1 / (1 + e^-x), evaluated without overflow for large |x|.
#[inline(always)]
pub fn sigmoid<S: Scalar>(x: S) -> S {
    if x.value() >= 0.0 {
        S::one() / ((-x).exp() + 1.0)
    } else {
        let e = x.exp();
        e / (e + 1.0)
    }
}

/// The inverse of [`sigmoid`]: ln(p / (1 - p)) for p in (0, 1).
#[inline]
pub fn logit(p: f64) -> f64 {
    (p / (1.0 - p)).ln()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// f(x, y) = exp(sin x) * sqrt(y) / ln(1 + y) - cos(x * y), derivatives checked against
    /// the hand-derived closed form.
    #[test]
    fn dual_matches_closed_form_derivatives() {
        fn f<S: Scalar>(x: S, y: S) -> S {
            x.sin().exp() * y.sqrt() / (y + 1.0).ln() - (x * y).cos()
        }
        let (x0, y0) = (0.7, 2.3);
        let r = f(Dual::<2>::variable(x0, 0), Dual::<2>::variable(y0, 1));
        let g = |x: f64, y: f64| (x.sin()).exp() * y.sqrt() / (1.0 + y).ln();
        let dfdx = g(x0, y0) * x0.cos() + (x0 * y0).sin() * y0;
        let l = (1.0 + y0).ln();
        let dfdy = (x0.sin()).exp() * (0.5 / y0.sqrt() / l - y0.sqrt() / (l * l * (1.0 + y0)))
            + (x0 * y0).sin() * x0;
        assert!((r.v - f(x0, y0)).abs() < 1e-15);
        assert!((r.d[0] - dfdx).abs() < 1e-13, "{} vs {}", r.d[0], dfdx);
        assert!((r.d[1] - dfdy).abs() < 1e-13, "{} vs {}", r.d[1], dfdy);
    }

    #[test]
    fn sigmoid_is_stable_and_inverts_logit() {
        for &x in &[-800.0, -30.0, -1.0, 0.0, 2.5, 40.0, 800.0] {
            let s = sigmoid(Dual::<1>::variable(x, 0));
            assert!(s.is_finite(), "x = {x}");
            let expected_d = s.v * (1.0 - s.v);
            assert!((s.d[0] - expected_d).abs() < 1e-15);
        }
        for &p in &[1e-9, 0.01, 0.5, 0.97] {
            assert!((sigmoid(logit(p)) - p).abs() < 1e-15);
        }
    }

    #[test]
    fn comparisons_use_the_value_only() {
        let a = Dual::<1>::variable(1.0, 0);
        let b = Dual::<1>::constant(1.0);
        assert!(a == b);
        assert!(Dual::<1>::constant(0.5) < a);
        let c = Dual::<1>::constant(3.0);
        assert_eq!(a.clamp_to(c, c).d[0], 0.0);
    }
}
