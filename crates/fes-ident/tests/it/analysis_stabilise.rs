//! Model modification (thesis 5.4.3): replacing unstable local eigenvalues and
//! re-estimating that unit's offsets, on the Table 5.3 situation built in code.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use super::analysis_support;

use analysis_support::*;
use fes_ident::analysis::stabilise::{
    StabiliseError, fastest_eigenvalue, reestimate_offsets, replace_unstable_eigenvalues, stabilise,
};
use fes_ident::analysis::trace::simulate_trace;
use fes_ident::analysis::validation::msse;
use fes_model::model::arx::ArxUnit;
use fes_model::model::lmn::{LocalModelSet, Stability};
use fes_model::model::local_model::{SsLocalModel, a_from_eigensystem, eig2, eigenvector_matrix};
use fes_model::model::{Lmn, SchedulingSpec};

fn pairs<'a>(u: &'a [Vec<f64>], y: &'a [Vec<f64>]) -> Vec<(&'a [f64], &'a [f64])> {
    u.iter()
        .zip(y)
        .map(|(u, y)| (u.as_slice(), y.as_slice()))
        .collect()
}

fn offsets(lmn: &Lmn, unit: usize) -> [f64; 3] {
    match &lmn.local {
        LocalModelSet::SsEigLocal(u) => [u[unit].dx[0], u[unit].dx[1], u[unit].dy],
        _ => panic!("fixture is ss-eig-local"),
    }
}

/// Data from the stable truth, the unstable model of Table 5.3 (+9.96, wrong offsets):
/// the repair replaces exactly that eigenvalue by -1 and recovers the true offsets (the
/// output is affine in them, so one least-squares step is exact; tolerance 1e-8 on
/// offsets of order 1e-2), after which the model is the truth.
#[test]
fn table_5_3_repair_recovers_the_true_offsets() {
    let u = random_inputs(30, 590, 7);
    let y = outputs(&truth(), &u);
    let r = stabilise(&unstable(), -1.0, &pairs(&u, &y)).expect("stabilise");
    assert_eq!(r.changes.len(), 1);
    let c = r.changes[0];
    assert_eq!((c.unit, c.index, c.old, c.new), (2, 1, 9.96, -1.0));
    assert_eq!(r.offsets.len(), 1);
    assert_eq!(r.offsets[0].before, [0.05, -0.02, 0.01]);
    for (got, want) in r.offsets[0].after.iter().zip(TRUE_OFFSETS[2]) {
        assert!(
            (got - want).abs() < 1e-8,
            "{:?} vs {:?}",
            r.offsets[0].after,
            TRUE_OFFSETS[2]
        );
    }
    assert_eq!(offsets(&r.model, 2), r.offsets[0].after);
    assert!(
        r.iterations <= 2,
        "input scheduling: affine, {} steps",
        r.iterations
    );
    assert!(r.msse_final < 1e-18, "{}", r.msse_final);
    assert!(r.msse_replaced > 1e3 * r.msse_final.max(1e-30));
    r.model
        .validate(Stability::Require)
        .expect("repaired model is stable");
    // Same output as the truth on a train outside the data.
    let train = constant(20, 2000);
    let a = simulate_trace(&r.model.network().unwrap(), &train).unwrap();
    let b = simulate_trace(&truth().network().unwrap(), &train).unwrap();
    let d =
        a.y.iter()
            .zip(&b.y)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max);
    assert!(d < 1e-9, "max difference {d}");
}

/// Fig. 5.32: a 50 Hz train (phi ~ 0.5, where unit 2 weighs 0.5) drives the unstable model
/// away (|y| > 10 within 3 s); the repaired model stays bounded (|y| < 1) and settles
/// (its mean over 2.5-3 s within 2 % of the mean over 2-2.5 s; the slow mode at -1 /s
/// still creeps).
#[test]
fn long_train_diverges_before_and_settles_after() {
    let u = random_inputs(30, 590, 7);
    let y = outputs(&truth(), &u);
    let r = stabilise(&unstable(), -1.0, &pairs(&u, &y)).expect("stabilise");
    let train = constant(20, 3000);
    let before = simulate_trace(&unstable().network().unwrap(), &train).unwrap();
    let after = simulate_trace(&r.model.network().unwrap(), &train).unwrap();
    let amax = |y: &[f64]| y.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    assert!(amax(&before.y) > 10.0, "{}", amax(&before.y));
    assert!(amax(&after.y) < 1.0, "{}", amax(&after.y));
    let mean = |y: &[f64]| y.iter().sum::<f64>() / y.len() as f64;
    let (m1, m2) = (mean(&after.y[2000..2500]), mean(&after.y[2500..]));
    println!(
        "repaired: max {:.4}, mean 2.0-2.5 s {m1:.4}, 2.5-3.0 s {m2:.4}",
        amax(&after.y)
    );
    assert!((m2 - m1).abs() < 0.02 * m2.abs(), "{m1} -> {m2}");
}

/// With data the model cannot fit exactly (deterministic disturbance), the result is the
/// least-squares optimum: central differences (h = 1e-6) of the plain f64 training MSSE with
/// respect to each re-estimated offset are below 1e-6 of their value at the replaced
/// model's offsets.
#[test]
fn offsets_are_the_least_squares_optimum() {
    let u = random_inputs(20, 590, 3);
    let mut y = outputs(&truth(), &u);
    for (i, rec) in y.iter_mut().enumerate() {
        for (k, v) in rec.iter_mut().enumerate() {
            *v += 0.01 * ((0.37 * k as f64 + i as f64).sin());
        }
    }
    let data = pairs(&u, &y);
    let (replaced, _) = replace_unstable_eigenvalues(&unstable(), -1.0).unwrap();
    let (fitted, _, _) = reestimate_offsets(&replaced, &[2], &data).unwrap();
    let cost = |m: &Lmn| msse(&m.network().unwrap(), data.iter().copied()).unwrap();
    let with = |m: &Lmn, j: usize, h: f64| {
        let mut m = m.clone();
        if let LocalModelSet::SsEigLocal(units) = &mut m.local {
            match j {
                0 => units[2].dx[0] += h,
                1 => units[2].dx[1] += h,
                _ => units[2].dy += h,
            }
        }
        m
    };
    let grad = |m: &Lmn, j: usize| (cost(&with(m, j, 1e-6)) - cost(&with(m, j, -1e-6))) / 2e-6;
    for j in 0..3 {
        let g0 = grad(&replaced, j).abs();
        let g1 = grad(&fitted, j).abs();
        assert!(
            g1 <= 1e-6 * g0,
            "offset {j}: gradient {g1} at the fit, {g0} before"
        );
    }
    assert!(cost(&fitted) < cost(&replaced));
}

/// Output scheduling (phi = y[k-1]) makes the output non-affine in the offsets; the
/// repeated least-squares steps still recover the truth's offsets (1e-7).
#[test]
fn output_scheduling_converges_to_the_truth() {
    let out = |mut m: Lmn| {
        m.scheduling = SchedulingSpec::Output;
        m
    };
    let u = random_inputs(30, 590, 11);
    let y = outputs(&out(truth()), &u);
    let r = stabilise(&out(unstable()), -1.0, &pairs(&u, &y)).expect("stabilise");
    for (got, want) in r.offsets[0].after.iter().zip(TRUE_OFFSETS[2]) {
        assert!((got - want).abs() < 1e-7, "{:?}", r.offsets[0].after);
    }
    assert!(r.iterations > 1);
}

/// ss-direct: the replaced eigenvalue's eigenvector is kept (A' v = e' v) and the other
/// eigenpair is untouched (A' w = e w), residuals < 1e-9.
#[test]
fn direct_form_replacement_keeps_eigenvectors() {
    let v = eigenvector_matrix([0.3, 1.9]);
    let a = a_from_eigensystem(&v, [5.0, -100.0]).unwrap();
    let mut m = linear([-40.0, -200.0], 10.0);
    m.local = LocalModelSet::SsDirect(vec![SsLocalModel {
        a,
        b: [1.0, 0.3],
        c: [0.5, 0.1],
        dx: [0.0; 2],
        dy: 0.0,
    }]);
    let (fixed, changes) = replace_unstable_eigenvalues(&m, -1.0).unwrap();
    assert_eq!(changes.len(), 1);
    assert!((changes[0].old - 5.0).abs() < 1e-9);
    let LocalModelSet::SsDirect(u) = &fixed.local else {
        panic!()
    };
    let a2 = u[0].a;
    let mut p: Vec<f64> = eig2(&a2).iter().map(|z| z.re).collect();
    p.sort_by(f64::total_cmp);
    assert!(
        (p[0] + 100.0).abs() < 1e-9 && (p[1] + 1.0).abs() < 1e-9,
        "{p:?}"
    );
    for (col, e) in [(0, -1.0), (1, -100.0)] {
        let x = [v[0][col], v[1][col]];
        let ax = [
            a2[0][0] * x[0] + a2[0][1] * x[1],
            a2[1][0] * x[0] + a2[1][1] * x[1],
        ];
        assert!((ax[0] - e * x[0]).abs() < 1e-9 && (ax[1] - e * x[1]).abs() < 1e-9);
    }
    // A complex unstable pair cannot be replaced.
    if let LocalModelSet::SsDirect(u) = &mut m.local {
        u[0].a = [[5.0, -50.0], [50.0, 5.0]];
    }
    assert!(matches!(
        replace_unstable_eigenvalues(&m, -1.0),
        Err(StabiliseError::NotReplaceable { unit: 0, .. })
    ));
}

/// Refusals: a replacement eigenvalue outside (-1/Ts, 0), ARX models, no records; a
/// zero-offset model gets its eigenvalue replaced and keeps zero offsets; a stable model is
/// returned unchanged.
#[test]
fn refusals_and_trivial_cases() {
    let u = random_inputs(3, 300, 1);
    let y = outputs(&truth(), &u);
    let data = pairs(&u, &y);
    for bad in [1.0, 0.0, -1000.0, f64::NAN] {
        assert!(matches!(
            stabilise(&unstable(), bad, &data),
            Err(StabiliseError::Eigenvalue { .. })
        ));
    }
    assert!(matches!(
        stabilise(&unstable(), -1.0, &[]),
        Err(StabiliseError::NoRecords)
    ));
    let mut arx = linear([-40.0, -200.0], 10.0);
    arx.local = LocalModelSet::ArxShift {
        order: 1,
        units: vec![ArxUnit {
            a: [-1.5, 0.0, 0.0],
            b: [0.1, 0.0, 0.0],
            d: 0.0,
        }],
    };
    let e = stabilise(&arx, -1.0, &data).unwrap_err();
    assert!(e.to_string().contains("arx-shift"), "{e}");
    let stable = stabilise(&truth(), -1.0, &data).unwrap();
    assert!(stable.changes.is_empty() && stable.offsets.is_empty());
    assert_eq!(stable.model, truth());
    let mut zo = unstable();
    zo.zero_offsets = true;
    if let LocalModelSet::SsEigLocal(units) = &mut zo.local {
        for x in units.iter_mut() {
            x.dx = [0.0; 2];
            x.dy = 0.0;
        }
    }
    let r = stabilise(&zo, -1.0, &data).unwrap();
    assert_eq!(r.changes.len(), 1);
    assert!(r.offsets.is_empty());
    r.model.validate(Stability::Require).unwrap();
}

/// A stable eigenvalue faster than one sample (-2/Ts < e <= -1/Ts: shift-domain pole in
/// (-1, 0]) lies outside the region the eigensystem parameterisation can hold, so it is
/// replaced too, but by the region's fastest eigenvalue (a fast mode stays fast), never by
/// the slow -1 /s meant for unstable ones; the unstable eigenvalue beside it still gets -1.
#[test]
fn a_fast_stable_eigenvalue_stays_fast() {
    let mut m = unstable();
    if let LocalModelSet::SsEigLocal(units) = &mut m.local {
        units[0].eigenvalues[1] = -1500.0; // z = -0.5: stable
        units[1].eigenvalues[0] = -1000.0; // z = 0: stable, on the region's edge
    }
    let (fixed, changes) = replace_unstable_eigenvalues(&m, -1.0).unwrap();
    let got: Vec<(usize, usize, f64, f64)> = changes
        .iter()
        .map(|c| (c.unit, c.index, c.old, c.new))
        .collect();
    let fast = fastest_eigenvalue(TS);
    assert!((fast * TS + 1.0).abs() < 1e-5, "{fast}");
    assert_eq!(
        got,
        [
            (0, 1, -1500.0, fast),
            (1, 0, -1000.0, fast),
            (2, 1, 9.96, -1.0)
        ]
    );
    fixed
        .validate(Stability::Require)
        .expect("every eigenvalue in the region");
}
