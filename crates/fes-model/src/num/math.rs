//! f64 math without the standard library (compiled only without the `std` feature).
//!
//! `core` has no `exp`, `ln`, `sqrt`, `sin`, ... for `f64` on stable Rust. This private
//! extension trait gives `f64` (and nalgebra's `Complex<f64>`) the methods of those names
//! that the crate calls, computed by the `libm` crate, so the call sites read the same in both
//! builds: a module that calls one of them imports the trait under
//! `#[cfg(not(feature = "std"))]` only. A `std` build never sees this module and keeps std's
//! inherent methods (bit-identical to a build without this module); a `no_std` build may
//! differ from it in the last bits.
//!
//! Where [`crate::num::Scalar`] is in scope, `x.exp()` on an `f64` resolves to
//! [`Scalar::exp`](crate::num::Scalar::exp), whose `f64` implementation calls this trait, so
//! such a module needs the import only for the methods `Scalar` does not have (with both
//! traits in scope, a method they share is ambiguous: a compile error, never a silent choice).

use nalgebra::Complex;

/// The f64 methods of std that the crate uses, by `libm`.
pub(crate) trait FloatMath: Sized {
    /// e^self.
    fn exp(self) -> Self;
    /// e^self - 1, accurate near 0.
    fn exp_m1(self) -> Self;
    /// Natural logarithm.
    fn ln(self) -> Self;
    /// Square root.
    fn sqrt(self) -> Self;
    /// Sine (radians).
    fn sin(self) -> Self;
    /// Cosine (radians).
    fn cos(self) -> Self;
    /// `(sin, cos)` at once.
    fn sin_cos(self) -> (Self, Self);
    /// self^n by repeated squaring.
    fn powi(self, n: i32) -> Self;
}

impl FloatMath for f64 {
    #[inline(always)]
    fn exp(self) -> Self {
        libm::exp(self)
    }
    #[inline(always)]
    fn exp_m1(self) -> Self {
        libm::expm1(self)
    }
    #[inline(always)]
    fn ln(self) -> Self {
        libm::log(self)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        libm::sqrt(self)
    }
    #[inline(always)]
    fn sin(self) -> Self {
        libm::sin(self)
    }
    #[inline(always)]
    fn cos(self) -> Self {
        libm::cos(self)
    }
    #[inline(always)]
    fn sin_cos(self) -> (Self, Self) {
        libm::sincos(self)
    }
    /// The algorithm of compiler-rt's `__powidf2`, which std's `powi` calls at run time.
    #[inline]
    fn powi(self, n: i32) -> Self {
        let mut base = self;
        let mut e = n;
        let mut r = 1.0;
        loop {
            if e & 1 != 0 {
                r *= base;
            }
            e /= 2;
            if e == 0 {
                break;
            }
            base *= base;
        }
        if n < 0 { 1.0 / r } else { r }
    }
}

/// The `Complex<f64>` methods of num-complex's `std` (or `libm`) feature that the crate uses.
pub(crate) trait ComplexMath {
    /// |self| = hypot(re, im), as num-complex computes it.
    fn norm(self) -> f64;
}

impl ComplexMath for Complex<f64> {
    #[inline(always)]
    fn norm(self) -> f64 {
        libm::hypot(self.re, self.im)
    }
}
