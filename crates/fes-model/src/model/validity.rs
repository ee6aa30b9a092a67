//! Validity functions: B-splines over the scheduling variable (thesis 2.2.3, eq. 2.27-2.30).
//!
//! M validity functions of order p are defined by M + p non-decreasing knots
//! tau_1 <= ... <= tau_{M+p} through the de Boor recursion (eq. 2.29-2.30). On the valid range
//! [tau_p, tau_{M+1}] (1-based) they are non-negative and sum to one (eq. 2.27, 2.28), and at
//! most p of them are non-zero at any phi (local support), so evaluation returns a sparse
//! [`Activation`]: the index of the first non-zero unit and at most p values. This is what
//! makes a network step cost independent of M.
//!
//! Conventions (docs/model.md):
//! - order p = min(3, M): quadratic B-splines (p = 3) for M >= 3, linear hats for M = 2, the
//!   constant 1 for M = 1 (order-3 B-splines cannot form a partition of unity with fewer
//!   than 3 functions);
//! - `uniform` uses an open (clamped) uniform knot vector on [lo, hi]: p-fold end knots and
//!   evenly spaced interior knots, so the valid range is exactly [lo, hi] and the edge units
//!   peak (value 1) at the range ends;
//! - phi outside the valid range is clamped into it before evaluation (constant extrapolation
//!   of the edge models);
//! - [`KnotLayout::Uniform`] (`uniform_extended`) is the thesis's reading of "uniformly
//!   distributed B-spline validity functions" (5.4.1): every knot evenly spaced, extended
//!   beyond [lo, hi] so that the valid range is exactly [lo, hi]; every unit is the same
//!   shifted quadratic spline, and the edge units never reach 1 (at lo: 1/2, 1/2 and 0 of
//!   the first three). Order 3 needs M >= 3; with fewer units it is the clamped layout.
//!
//! Everything is generic over [`Scalar`]: with `f64` it is the hot path, with
//! [`Dual`] it gives exact derivatives with respect to phi ([`ValidityFunctions::d_dphi`]) and
//! the knots ([`ValidityFunctions::knot_jacobian`]) from the same recursion.

use crate::num::{Dual, Scalar};

/// Compile-time maximum number of units (local models) in a network.
pub const MAX_UNITS: usize = 16;
/// Maximum B-spline order (3 = piecewise quadratic, thesis 2.2.3).
pub const MAX_ORDER: usize = 3;
/// Maximum number of knots (M + p).
pub const MAX_KNOTS: usize = MAX_UNITS + MAX_ORDER;

/// Grid size of the numerical partition-of-unity check done on construction.
const POU_GRID: usize = 257;
/// Tolerance of that check.
const POU_TOL: f64 = 1e-9;

/// How [`ValidityFunctions::with_layout`] places the knots on [lo, hi].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum KnotLayout {
    /// Open (clamped) uniform knots: p-fold end knots, even interior knots (ours).
    #[default]
    Clamped,
    /// Every knot evenly spaced, extended beyond the range (the thesis's uniform splines).
    Uniform,
}

/// Why a set of validity functions was rejected.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum ValidityError {
    /// The number of units is outside 1..=MAX_UNITS.
    #[error("number of units {units} is outside 1..={MAX_UNITS}")]
    UnitCount {
        /// Requested number of units.
        units: usize,
    },
    /// The order is outside 1..=3 or larger than the number of units.
    #[error(
        "B-spline order {order} is invalid for {units} units (need 1 <= order <= min(3, units))"
    )]
    Order {
        /// Requested order.
        order: usize,
        /// Number of units.
        units: usize,
    },
    /// The knot count is not units + order.
    #[error("knot count {knots} does not equal units + order = {expected}")]
    KnotCount {
        /// Number of knots given.
        knots: usize,
        /// units + order.
        expected: usize,
    },
    /// A knot is NaN or infinite.
    #[error("knot {index} is not finite ({value})")]
    NonFiniteKnot {
        /// 0-based knot index.
        index: usize,
        /// Its value.
        value: f64,
    },
    /// Knots decrease.
    #[error("knots are not sorted: knot {index} = {value} is smaller than knot {} = {previous}", .index - 1)]
    UnsortedKnots {
        /// 0-based index of the offending knot.
        index: usize,
        /// Its value.
        value: f64,
        /// The previous knot's value.
        previous: f64,
    },
    /// The valid range [tau_p, tau_{M+1}] is empty.
    #[error("the valid scheduling range [{lo}, {hi}] is empty")]
    EmptyRange {
        /// tau_p.
        lo: f64,
        /// tau_{M+1}.
        hi: f64,
    },
    /// A unit's support [tau_i, tau_{i+p}] is a single point: it would never be active.
    #[error("unit {unit} has an empty support (knot multiplicity > order)")]
    EmptySupport {
        /// 0-based unit index.
        unit: usize,
    },
    /// The numerical partition-of-unity check failed (eq. 2.28).
    #[error("validity functions do not sum to 1 at phi = {phi}: sum = {sum}")]
    PartitionOfUnity {
        /// Where the check failed.
        phi: f64,
        /// The sum found there.
        sum: f64,
    },
    /// A range bound of the uniform construction is not finite or lo >= hi.
    #[error("scheduling range [{lo}, {hi}] is invalid (need finite lo < hi)")]
    Range {
        /// Lower bound.
        lo: f64,
        /// Upper bound.
        hi: f64,
    },
}

/// The active validity functions at one phi: units `first .. first + len` have the values
/// `values[..len]`; every other unit is exactly zero.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Activation<S = f64> {
    /// Index of the first non-zero unit.
    pub first: usize,
    /// Number of active units (the order p).
    pub len: usize,
    /// rho_{first + j}(phi) for j < len.
    pub values: [S; MAX_ORDER],
}

impl<S: Scalar> Activation<S> {
    /// rho_i(phi) for any unit i (zero outside the active set).
    #[inline]
    pub fn get(&self, unit: usize) -> S {
        if unit >= self.first && unit < self.first + self.len {
            self.values[unit - self.first]
        } else {
            S::zero()
        }
    }

    /// (unit index, rho) for the active units.
    #[inline]
    pub fn iter(&self) -> impl Iterator<Item = (usize, S)> + '_ {
        self.values[..self.len]
            .iter()
            .enumerate()
            .map(move |(j, &r)| (self.first + j, r))
    }

    /// Interpolates per-unit quantities with these weights: sum_i rho_i(phi) q_i (eq. 2.16).
    /// `f(i)` is only called for the active units.
    #[inline(always)]
    pub fn interpolate<T, F>(&self, mut f: F) -> T
    where
        T: core::ops::Add<Output = T> + core::ops::Mul<S, Output = T>,
        F: FnMut(usize) -> T,
    {
        let mut acc = f(self.first) * self.values[0];
        for j in 1..self.len {
            acc = acc + f(self.first + j) * self.values[j];
        }
        acc
    }
}

/// Derivatives of the active validity functions with respect to the knots at one phi.
///
/// `d[j][k]` is d rho_{activation.first + j} / d tau_k (0-based knots, k < M + p); inactive
/// units have derivative zero with respect to every knot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KnotJacobian {
    /// Values at phi.
    pub activation: Activation<f64>,
    /// d rho / d tau (rows: active units, columns: knots).
    pub d: [[f64; MAX_KNOTS]; MAX_ORDER],
}

/// A set of M B-spline validity functions of order p (thesis 2.2.3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ValidityFunctions<S = f64> {
    knots: [S; MAX_KNOTS],
    units: usize,
    order: usize,
}

/// Order used for M units: min(3, M) (see the module docs).
#[inline]
pub fn order_for_units(units: usize) -> usize {
    units.min(MAX_ORDER)
}

/// The range and unit count every knot layout needs.
fn check_layout(units: usize, lo: f64, hi: f64) -> Result<(), ValidityError> {
    if !(lo.is_finite() && hi.is_finite() && lo < hi) {
        return Err(ValidityError::Range { lo, hi });
    }
    if !(1..=MAX_UNITS).contains(&units) {
        return Err(ValidityError::UnitCount { units });
    }
    Ok(())
}

impl ValidityFunctions<f64> {
    /// M validity functions on an open uniform knot vector over [lo, hi], order min(3, M).
    pub fn uniform(units: usize, lo: f64, hi: f64) -> Result<Self, ValidityError> {
        check_layout(units, lo, hi)?;
        let p = order_for_units(units);
        let mut knots = [0.0; MAX_KNOTS];
        let interior = units - p;
        for (i, k) in knots.iter_mut().take(units + p).enumerate() {
            *k = if i < p {
                lo
            } else if i < p + interior {
                let j = (i - p + 1) as f64;
                lo + (hi - lo) * j / (interior + 1) as f64
            } else {
                hi
            };
        }
        Self::from_knots(&knots[..units + p], p)
    }

    /// M validity functions of order min(3, M) with every knot evenly spaced by
    /// `h = (hi - lo) / (M - p + 1)`, the first at `lo - (p - 1) h`: the valid range is
    /// exactly [lo, hi] and every unit is the same spline shifted by `h` (module docs).
    pub fn uniform_extended(units: usize, lo: f64, hi: f64) -> Result<Self, ValidityError> {
        check_layout(units, lo, hi)?;
        let p = order_for_units(units);
        if p < MAX_ORDER {
            // One or two units: the linear hats (or the constant) of the clamped layout.
            return Self::uniform(units, lo, hi);
        }
        let h = (hi - lo) / (units - p + 1) as f64;
        let mut knots = [0.0; MAX_KNOTS];
        for (i, k) in knots.iter_mut().take(units + p).enumerate() {
            *k = lo + (i as f64 - (p - 1) as f64) * h;
        }
        // The ends exactly, whatever the rounding of the spacing.
        knots[p - 1] = lo;
        knots[units] = hi;
        Self::from_knots(&knots[..units + p], p)
    }

    /// M validity functions on [lo, hi] by `layout`.
    pub fn with_layout(
        layout: KnotLayout,
        units: usize,
        lo: f64,
        hi: f64,
    ) -> Result<Self, ValidityError> {
        match layout {
            KnotLayout::Clamped => Self::uniform(units, lo, hi),
            KnotLayout::Uniform => Self::uniform_extended(units, lo, hi),
        }
    }

    /// d rho_i / d phi for the active units, from the same recursion (Dual seeded on phi).
    pub fn d_dphi(&self, phi: f64) -> (Activation<f64>, [f64; MAX_ORDER]) {
        let knots: [Dual<1>; MAX_KNOTS] = core::array::from_fn(|i| Dual::constant(self.knots[i]));
        let a = eval_bspline(&knots, self.units, self.order, Dual::variable(phi, 0));
        let mut val = [0.0; MAX_ORDER];
        let mut der = [0.0; MAX_ORDER];
        for j in 0..a.len {
            val[j] = a.values[j].v;
            der[j] = a.values[j].d[0];
        }
        (
            Activation {
                first: a.first,
                len: a.len,
                values: val,
            },
            der,
        )
    }

    /// Exact derivatives of the active validity functions with respect to every knot
    /// (for knot optimisation, 5.4.2), from the same recursion (Dual seeded on the knots).
    pub fn knot_jacobian(&self, phi: f64) -> KnotJacobian {
        let knots: [Dual<MAX_KNOTS>; MAX_KNOTS] =
            core::array::from_fn(|i| Dual::variable(self.knots[i], i));
        let a = eval_bspline(&knots, self.units, self.order, Dual::constant(phi));
        let mut val = [0.0; MAX_ORDER];
        let mut d = [[0.0; MAX_KNOTS]; MAX_ORDER];
        for j in 0..a.len {
            val[j] = a.values[j].v;
            d[j] = a.values[j].d;
        }
        KnotJacobian {
            activation: Activation {
                first: a.first,
                len: a.len,
                values: val,
            },
            d,
        }
    }

    /// The same functions in another scalar type (e.g. knots seeded as [`Dual`] variables).
    pub fn cast<T: Scalar>(&self, f: impl Fn(usize, f64) -> T) -> ValidityFunctions<T> {
        ValidityFunctions {
            knots: core::array::from_fn(|i| f(i, self.knots[i])),
            units: self.units,
            order: self.order,
        }
    }
}

impl<S: Scalar> ValidityFunctions<S> {
    /// Validity functions from a knot vector (M + p knots) and order p.
    ///
    /// Checks: 1 <= M <= 16, 1 <= p <= min(3, M), finite non-decreasing knots, a non-empty
    /// valid range, no unit with empty support, and partition of unity on a grid over the
    /// valid range (eq. 2.28).
    pub fn from_knots(knots: &[S], order: usize) -> Result<Self, ValidityError> {
        if !(1..=MAX_ORDER).contains(&order) || knots.len() <= order {
            let units = knots.len().saturating_sub(order);
            if !(1..=MAX_UNITS).contains(&units) {
                return Err(ValidityError::UnitCount { units });
            }
            return Err(ValidityError::Order { order, units });
        }
        let units = knots.len() - order;
        if units > MAX_UNITS {
            return Err(ValidityError::UnitCount { units });
        }
        if order > units {
            return Err(ValidityError::Order { order, units });
        }
        for (i, k) in knots.iter().enumerate() {
            if !k.value().is_finite() {
                return Err(ValidityError::NonFiniteKnot {
                    index: i,
                    value: k.value(),
                });
            }
            if i > 0 && k.value() < knots[i - 1].value() {
                return Err(ValidityError::UnsortedKnots {
                    index: i,
                    value: k.value(),
                    previous: knots[i - 1].value(),
                });
            }
        }
        let (lo, hi) = (knots[order - 1].value(), knots[units].value());
        if lo >= hi {
            return Err(ValidityError::EmptyRange { lo, hi });
        }
        for unit in 0..units {
            if knots[unit].value() >= knots[unit + order].value() {
                return Err(ValidityError::EmptySupport { unit });
            }
        }
        let mut k = [knots[0]; MAX_KNOTS];
        k[..knots.len()].copy_from_slice(knots);
        // Pad with the last knot so fixed-size loops never read garbage.
        let last = knots[knots.len() - 1];
        for x in k.iter_mut().skip(knots.len()) {
            *x = last;
        }
        let vf = Self {
            knots: k,
            units,
            order,
        };
        for g in 0..POU_GRID {
            let phi = lo + (hi - lo) * g as f64 / (POU_GRID - 1) as f64;
            let a = vf.eval(S::from_f64(phi));
            let mut sum = 0.0;
            for (_, r) in a.iter() {
                let r = r.value();
                if !(-POU_TOL..=1.0 + POU_TOL).contains(&r) {
                    return Err(ValidityError::PartitionOfUnity { phi, sum: r });
                }
                sum += r;
            }
            if (sum - 1.0).abs() > POU_TOL {
                return Err(ValidityError::PartitionOfUnity { phi, sum });
            }
        }
        Ok(vf)
    }

    /// Number of units M.
    #[inline]
    pub fn units(&self) -> usize {
        self.units
    }

    /// B-spline order p.
    #[inline]
    pub fn order(&self) -> usize {
        self.order
    }

    /// The M + p knots.
    #[inline]
    pub fn knots(&self) -> &[S] {
        &self.knots[..self.units + self.order]
    }

    /// The valid range [tau_p, tau_{M+1}] (1-based) on which the functions form a partition
    /// of unity.
    #[inline]
    pub fn valid_range(&self) -> (S, S) {
        (self.knots[self.order - 1], self.knots[self.units])
    }

    /// The active validity functions at phi (clamped into the valid range), eq. 2.29-2.30.
    #[inline]
    pub fn eval(&self, phi: S) -> Activation<S> {
        eval_bspline(&self.knots, self.units, self.order, phi)
    }

    /// All M values rho_i(phi) (zeros for inactive units).
    pub fn eval_dense(&self, phi: S) -> [S; MAX_UNITS] {
        let a = self.eval(phi);
        let mut out = [S::zero(); MAX_UNITS];
        for (i, r) in a.iter() {
            out[i] = r;
        }
        out
    }
}

/// The knot span holding phi: the largest s in [p-1, M-1] (0-based) with tau_s <= phi and
/// tau_s < tau_{s+1}; phi is assumed clamped into [tau_{p-1}, tau_M].
#[inline(always)]
fn find_span<S: Scalar>(knots: &[S; MAX_KNOTS], units: usize, order: usize, phi: f64) -> usize {
    let lo = order - 1;
    let hi_knot = knots[units].value();
    if phi >= hi_knot {
        // Right end: the last non-degenerate span (its polynomial piece reaches tau_M).
        let mut s = units - 1;
        while s > lo && knots[s].value() >= hi_knot {
            s -= 1;
        }
        return s;
    }
    // Branch-free count of interior knots <= phi.
    let mut s = lo;
    for k in knots.iter().take(units).skip(lo + 1) {
        s += (k.value() <= phi) as usize;
    }
    s
}

/// The de Boor recursion (eq. 2.29-2.30) restricted to the p functions that are non-zero on
/// the span of phi (the triangular scheme: B_{s,1} = 1, then each order raised by eq. 2.30).
/// Denominators are knot differences that contain the non-degenerate span, hence > 0.
#[inline(always)]
fn eval_bspline<S: Scalar>(
    knots: &[S; MAX_KNOTS],
    units: usize,
    order: usize,
    phi: S,
) -> Activation<S> {
    let phi = phi.clamp_to(knots[order - 1], knots[units]);
    let s = find_span(knots, units, order, phi.value());
    let mut n = [S::zero(); MAX_ORDER];
    n[0] = S::one();
    let mut left = [S::zero(); MAX_ORDER];
    let mut right = [S::zero(); MAX_ORDER];
    for r in 1..order {
        left[r] = phi - knots[s + 1 - r];
        right[r] = knots[s + r] - phi;
        let mut saved = S::zero();
        for k in 0..r {
            let temp = n[k] / (right[k + 1] + left[r - k]);
            n[k] = saved + right[k + 1] * temp;
            saved = left[r - k] * temp;
        }
        n[r] = saved;
    }
    Activation {
        first: s + 1 - order,
        len: order,
        values: n,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Independent truth: the plain recursive definition (eq. 2.29-2.30) with the 0/0 = 0
    /// convention, evaluated for every unit.
    fn cox_de_boor(t: &[f64], j: usize, p: usize, x: f64) -> f64 {
        if p == 1 {
            return if t[j] <= x && x < t[j + 1] { 1.0 } else { 0.0 };
        }
        let mut v = 0.0;
        let d1 = t[j + p - 1] - t[j];
        if d1 > 0.0 {
            v += (x - t[j]) / d1 * cox_de_boor(t, j, p - 1, x);
        }
        let d2 = t[j + p] - t[j + 1];
        if d2 > 0.0 {
            v += (t[j + p] - x) / d2 * cox_de_boor(t, j + 1, p - 1, x);
        }
        v
    }

    #[test]
    fn matches_plain_recursion_inside_the_range() {
        let t = [0.0, 0.0, 0.1, 0.3, 0.35, 0.7, 0.9, 1.0, 1.0];
        let vf = ValidityFunctions::from_knots(&t, 3).unwrap();
        for g in 0..997 {
            let x = 0.1 + 0.8 * g as f64 / 997.0;
            let dense = vf.eval_dense(x);
            for (i, &v) in dense.iter().enumerate().take(vf.units()) {
                let truth = cox_de_boor(&t, i, 3, x);
                assert!((v - truth).abs() < 1e-14, "unit {i} at {x}: {v} vs {truth}");
            }
        }
    }

    /// The thesis's uniform splines: knots evenly spaced beyond the range, valid range exactly
    /// [0, 1], a partition of unity there (against the plain recursion), every unit the same
    /// shifted shape, and at the range's ends the edge units at 1/2 (a clamped edge unit is 1).
    #[test]
    fn uniform_extended_layout() {
        for m in [3usize, 5, 6, 8] {
            let vf = ValidityFunctions::with_layout(KnotLayout::Uniform, m, 0.0, 1.0).unwrap();
            assert_eq!(vf.order(), 3);
            assert_eq!(vf.valid_range(), (0.0, 1.0));
            let t = vf.knots().to_vec();
            let h = 1.0 / (m - 2) as f64;
            for w in t.windows(2) {
                assert!((w[1] - w[0] - h).abs() < 1e-12, "{t:?}");
            }
            for g in 0..=400 {
                let x = g as f64 / 400.0;
                let dense = vf.eval_dense(x);
                let sum: f64 = dense.iter().take(m).sum();
                assert!((sum - 1.0).abs() < 1e-12, "M = {m}, phi = {x}: {sum}");
                if x < 1.0 {
                    for (i, &v) in dense.iter().enumerate().take(m) {
                        let truth = cox_de_boor(&t, i, 3, x);
                        assert!((v - truth).abs() < 1e-13, "unit {i} at {x}");
                    }
                }
            }
            // Shifted copies: unit i at x equals unit i + 1 at x + h.
            if m >= 4 {
                let x = 0.5 * h;
                assert!((vf.eval_dense(x)[0] - vf.eval_dense(x + h)[1]).abs() < 1e-12);
            }
            assert!((vf.eval_dense(0.0)[0] - 0.5).abs() < 1e-12);
            assert!((vf.eval_dense(0.0)[1] - 0.5).abs() < 1e-12);
        }
        // Fewer than three units: the clamped layout (order min(3, M)).
        assert_eq!(
            ValidityFunctions::with_layout(KnotLayout::Uniform, 2, 0.0, 1.0).unwrap(),
            ValidityFunctions::uniform(2, 0.0, 1.0).unwrap()
        );
    }

    #[test]
    fn uniform_shapes() {
        let one = ValidityFunctions::uniform(1, 0.0, 1.0).unwrap();
        assert_eq!(one.order(), 1);
        for &x in &[-1.0, 0.0, 0.4, 1.0, 3.0] {
            assert_eq!(one.eval(x).get(0), 1.0);
        }
        let two = ValidityFunctions::uniform(2, 0.0, 1.0).unwrap();
        assert_eq!(two.order(), 2);
        let a = two.eval(0.25);
        assert!((a.get(0) - 0.75).abs() < 1e-15 && (a.get(1) - 0.25).abs() < 1e-15);
        let six = ValidityFunctions::uniform(6, 0.0, 1.0).unwrap();
        assert_eq!(six.knots().len(), 9);
        assert_eq!(six.eval(0.0).get(0), 1.0);
        assert_eq!(six.eval(1.0).get(5), 1.0);
        assert_eq!(six.eval(7.0), six.eval(1.0));
        assert_eq!(six.eval(-7.0), six.eval(0.0));
    }

    #[test]
    fn rejects_bad_knots() {
        assert!(matches!(
            ValidityFunctions::from_knots(&[0.0, 0.0, 0.5, 0.4, 1.0, 1.0], 3),
            Err(ValidityError::UnsortedKnots { index: 3, .. })
        ));
        assert!(matches!(
            ValidityFunctions::from_knots(&[0.0, 0.0, f64::NAN, 1.0, 1.0, 1.0], 3),
            Err(ValidityError::NonFiniteKnot { index: 2, .. })
        ));
        assert!(matches!(
            ValidityFunctions::from_knots(&[0.0, 0.5, 0.5, 0.5, 1.0, 1.0], 3),
            Err(ValidityError::EmptyRange { .. })
        ));
        assert!(matches!(
            ValidityFunctions::uniform(17, 0.0, 1.0),
            Err(ValidityError::UnitCount { units: 17 })
        ));
    }
}
