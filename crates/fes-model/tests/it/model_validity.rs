//! Validity functions (thesis 2.2.3): partition of unity, non-negativity, and exact
//! derivatives checked against central finite differences.
#![allow(clippy::needless_range_loop)] // index loops mirror the equations
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use fes_model::model::validity::{MAX_UNITS, ValidityFunctions};
use proptest::prelude::*;

/// Random valid knot vectors: order p in 1..=3, M in p..=16, sorted knots from random gaps
/// (some zero, giving repeated knots) with a non-empty valid range.
fn knot_vector() -> impl Strategy<Value = (Vec<f64>, usize)> {
    (1usize..=3, 0usize..=MAX_UNITS).prop_flat_map(|(p, extra)| {
        let m = (p + extra).min(MAX_UNITS);
        prop::collection::vec(prop_oneof![1 => Just(0.0), 6 => 0.01f64..1.0], m + p - 1).prop_map(
            move |gaps| {
                let mut k = vec![-0.3];
                for g in gaps {
                    let last = *k.last().unwrap();
                    k.push(last + g);
                }
                (k, p)
            },
        )
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    /// eq. 2.27-2.28: values in [0, 1] summing to 1 everywhere on the valid range (and, by
    /// clamping, outside it). Knot vectors the constructor rejects (a unit with empty
    /// support, an empty range) are skipped; those rejections are tested separately.
    #[test]
    fn partition_of_unity_and_non_negativity((knots, p) in knot_vector(), t in 0.0f64..=1.0, out in -2.0f64..2.0) {
        let Ok(vf) = ValidityFunctions::from_knots(&knots, p) else { return Ok(()); };
        let (lo, hi) = vf.valid_range();
        for phi in [lo + (hi - lo) * t, lo, hi, if out < 0.0 { lo + out } else { hi + out }] {
            let a = vf.eval(phi);
            prop_assert_eq!(a.len, p);
            let mut sum = 0.0;
            for (i, r) in a.iter() {
                prop_assert!(i < vf.units());
                prop_assert!((-1e-12..=1.0 + 1e-12).contains(&r), "rho_{} = {} at {}", i, r, phi);
                sum += r;
            }
            prop_assert!((sum - 1.0).abs() < 1e-12, "sum {} at phi {}", sum, phi);
            // The dense view agrees with the sparse one.
            let dense = vf.eval_dense(phi);
            for (i, &v) in dense.iter().enumerate() { prop_assert_eq!(v, a.get(i)); }
        }
    }

    /// d rho / d phi from the Dual recursion against central differences (away from knots,
    /// where the quadratic B-splines are C^1 anyway but the FD stencil must stay in one
    /// polynomial piece).
    #[test]
    fn d_dphi_matches_finite_differences((knots, p) in knot_vector(), t in 0.0f64..=1.0) {
        let Ok(vf) = ValidityFunctions::from_knots(&knots, p) else { return Ok(()); };
        let (lo, hi) = vf.valid_range();
        let phi = lo + (hi - lo) * t;
        let h = 1e-6;
        prop_assume!(vf.knots().iter().all(|k| (k - phi).abs() > 10.0 * h));
        prop_assume!(phi - h > lo && phi + h < hi);
        let (act, d) = vf.d_dphi(phi);
        let (ap, am) = (vf.eval_dense(phi + h), vf.eval_dense(phi - h));
        for i in 0..vf.units() {
            let fd = (ap[i] - am[i]) / (2.0 * h);
            let ex = if i >= act.first && i < act.first + act.len { d[i - act.first] } else { 0.0 };
            prop_assert!((fd - ex).abs() < 1e-6 * (1.0 + ex.abs()), "unit {}: {} vs fd {}", i, ex, fd);
        }
    }

    /// d rho / d tau_k from the Dual recursion against central differences on every knot
    /// (perturbations small enough to keep the knot order and the span of phi).
    #[test]
    fn d_dknots_matches_finite_differences((knots, p) in knot_vector(), t in 0.0f64..=1.0) {
        let Ok(vf) = ValidityFunctions::from_knots(&knots, p) else { return Ok(()); };
        let (lo, hi) = vf.valid_range();
        let phi = lo + (hi - lo) * t;
        let h = 1e-7;
        // Distinct knots, phi away from every knot: the FD stencil stays in one piece.
        prop_assume!(knots.windows(2).all(|w| w[1] - w[0] > 100.0 * h));
        prop_assume!(knots.iter().all(|k| (k - phi).abs() > 100.0 * h));
        let jac = vf.knot_jacobian(phi);
        for k in 0..knots.len() {
            let mut kp = knots.clone();
            kp[k] += h;
            let mut km = knots.clone();
            km[k] -= h;
            let (vp, vm) = (
                ValidityFunctions::from_knots(&kp, p).unwrap().eval_dense(phi),
                ValidityFunctions::from_knots(&km, p).unwrap().eval_dense(phi),
            );
            for i in 0..vf.units() {
                let fd = (vp[i] - vm[i]) / (2.0 * h);
                let a = jac.activation;
                let ex = if i >= a.first && i < a.first + a.len { jac.d[i - a.first][k] } else { 0.0 };
                prop_assert!((fd - ex).abs() < 1e-5 * (1.0 + ex.abs()), "unit {} knot {}: {} vs fd {}", i, k, ex, fd);
            }
        }
    }
}

/// The uniform construction: clamped uniform knots, valid range [lo, hi], edge units peak
/// at 1 at the ends, order min(3, M), and interior uniform quadratic B-splines take their
/// textbook values 1/2, 1/2 at an interior knot (M >= 4).
#[test]
fn uniform_construction() {
    for m in 1..=MAX_UNITS {
        let vf = ValidityFunctions::uniform(m, 0.0, 1.0).unwrap();
        assert_eq!(vf.order(), m.min(3));
        assert_eq!(vf.knots().len(), m + m.min(3));
        assert_eq!(vf.valid_range(), (0.0, 1.0));
        assert_eq!(vf.eval(0.0).get(0), 1.0);
        assert!((vf.eval(1.0).get(m - 1) - 1.0).abs() < 1e-15);
        if m >= 6 {
            // Knot spacing h = 1/(M-2); unit 3 has the fully interior knots h, 2h, 3h, 4h:
            // the uniform quadratic B-spline is 1/2 at its inner knots, 3/4 at its centre.
            let h = 1.0 / (m as f64 - 2.0);
            for (x, v) in [(2.0 * h, 0.5), (3.0 * h, 0.5), (2.5 * h, 0.75)] {
                let r = vf.eval(x).get(3);
                assert!(
                    (r - v).abs() < 1e-14,
                    "M={m}, x={x}: rho_3 = {r}, expected {v}"
                );
            }
        }
    }
    let vf = ValidityFunctions::uniform(6, -1.0, 3.0).unwrap();
    assert_eq!(vf.valid_range(), (-1.0, 3.0));
}

/// Local support: only the functions whose knot interval contains phi are active, so an
/// evaluation touches at most p units whatever M is.
#[test]
fn local_support_is_at_most_order() {
    let vf = ValidityFunctions::uniform(16, 0.0, 1.0).unwrap();
    for g in 0..=1000 {
        let a = vf.eval(g as f64 / 1000.0);
        assert_eq!(a.len, 3);
        let dense = vf.eval_dense(g as f64 / 1000.0);
        assert!(dense.iter().filter(|&&v| v != 0.0).count() <= 3);
    }
}
