//! Thesis form (input delay line, state x) == advanced form (core state z[k] = x[k+d] plus an
//! output ring) for random pulse trains, to 1e-12 (thesis 2.2.2; docs/model.md item 4).
#![allow(clippy::needless_range_loop)] // index loops mirror the equations
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use fes_model::model::arx::ArxUnit;
use fes_model::model::local_model::EigLocalUnit;
use fes_model::model::network::Network;
use fes_model::model::scheduling::{Scheduler, SchedulingSpec};
use fes_model::model::validity::ValidityFunctions;
use fes_model::model::{AdvancedForm, ThesisForm};
use proptest::prelude::*;

const TS: f64 = 1e-3;

fn ss_network(m: usize, delay: usize, sched: SchedulingSpec, seed: u64) -> Network<f64> {
    // Deterministic pseudo-random stable units with offsets.
    let mut s = seed | 1;
    let mut r = |lo: f64, hi: f64| {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        lo + (hi - lo) * ((s >> 11) as f64 / (1u64 << 53) as f64)
    };
    // Eigenvectors near a common pair (jitter +- 0.2 rad), so the interpolated A stays
    // regular and the rest state exists for output scheduling too.
    let (th0, dth) = (r(0.0, 3.0), r(0.8, 2.2));
    let units: Vec<_> = (0..m)
        .map(|_| {
            let th = th0 + r(-0.2, 0.2);
            EigLocalUnit {
                eigenvalues: [r(-600.0, -50.0), r(-60.0, -2.0)],
                eigenvector_angles: [th, th + dth + r(-0.2, 0.2)],
                b: [r(-2.0, 2.0), r(-2.0, 2.0)],
                c: [r(-3.0, 3.0), r(-3.0, 3.0)],
                dx: [r(-1.0, 1.0), r(-1.0, 1.0)],
                dy: r(-0.1, 0.1),
            }
            .to_local_model()
            .unwrap()
        })
        .collect();
    let vf = ValidityFunctions::uniform(m, 0.0, 1.0).unwrap();
    Network::state_space(TS, delay, vf, Scheduler::new(&sched, TS).unwrap(), &units).unwrap()
}

fn compare(net: Network<f64>, u: &[f64]) -> Result<(), TestCaseError> {
    let d = net.delay();
    let mut thesis = ThesisForm::new(net).unwrap();
    let mut adv = AdvancedForm::new(net).unwrap();
    let mut ahead = Vec::with_capacity(u.len());
    for (k, &uk) in u.iter().enumerate() {
        // z[k] = x[k+d]: record the advanced core state and check it d steps later.
        ahead.push(adv.state().x);
        let yt = thesis.step(uk);
        let ya = adv.step(uk);
        prop_assert!(
            (yt - ya.y).abs() < 1e-12,
            "k={}: thesis {} advanced {}",
            k,
            yt,
            ya.y
        );
        if k + 1 >= d {
            // After the thesis step k, its state is x[k+1] = z[k+1-d].
            let z = ahead.get(k + 1 - d).copied();
            if let Some(z) = z {
                for i in 0..2 {
                    prop_assert!((thesis.state().x[i] - z[i]).abs() < 1e-12);
                }
            }
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// State-space networks, input and output scheduling, random M, d and pulse trains.
    #[test]
    fn thesis_form_equals_advanced_form(
        m in 1usize..=10, delay in 0usize..=20, seed in any::<u64>(), output_sched in any::<bool>(),
        bits in prop::collection::vec(prop::bool::weighted(0.12), 1500),
    ) {
        let sched = if output_sched { SchedulingSpec::Output } else { SchedulingSpec::default() };
        let u: Vec<f64> = bits.iter().map(|&b| if b { 1.0 } else { 0.0 }).collect();
        compare(ss_network(m, delay, sched, seed), &u)?;
    }

    /// ARX networks (shift form, order 2), same property.
    #[test]
    fn thesis_form_equals_advanced_form_arx(
        delay in 0usize..=12, output_sched in any::<bool>(),
        bits in prop::collection::vec(prop::bool::weighted(0.12), 800),
    ) {
        let units = [
            ArxUnit { a: [-1.90, 0.9025, 0.0], b: [0.010, 0.002, 0.0], d: 0.001 },
            ArxUnit { a: [-1.80, 0.8200, 0.0], b: [0.020, 0.001, 0.0], d: 0.000 },
            ArxUnit { a: [-1.85, 0.8600, 0.0], b: [0.015, 0.004, 0.0], d: -0.001 },
        ];
        let sched = if output_sched { SchedulingSpec::Output } else { SchedulingSpec::default() };
        let vf = ValidityFunctions::uniform(3, 0.0, 1.0).unwrap();
        let net = Network::arx(TS, delay, vf, Scheduler::new(&sched, TS).unwrap(), 2, &units).unwrap();
        let u: Vec<f64> = bits.iter().map(|&b| if b { 1.0 } else { 0.0 }).collect();
        let mut thesis = ThesisForm::new(net).unwrap();
        let mut adv = AdvancedForm::new(net).unwrap();
        for (k, &uk) in u.iter().enumerate() {
            let (yt, ya) = (thesis.step(uk), adv.step(uk).y);
            prop_assert!((yt - ya).abs() < 1e-12, "k={}", k);
        }
    }
}

/// The advanced form's look-ahead: y_ahead at step k is the output the thesis form shows at
/// k + d, and `pending_output(i)` is y[k + i].
#[test]
fn advanced_form_look_ahead() {
    let net = ss_network(6, 7, SchedulingSpec::default(), 42);
    let u: Vec<f64> = (0..600)
        .map(|k| if k % 23 == 0 || k % 37 == 0 { 1.0 } else { 0.0 })
        .collect();
    let mut thesis = ThesisForm::new(net).unwrap();
    let y_thesis: Vec<f64> = u.iter().map(|&x| thesis.step(x)).collect();
    let mut adv = AdvancedForm::new(net).unwrap();
    for (k, &uk) in u.iter().enumerate() {
        for i in 0..7 {
            if k + i < u.len() {
                assert!((adv.pending_output(i).unwrap() - y_thesis[k + i]).abs() < 1e-12);
            }
        }
        let s = adv.step(uk);
        if k + 7 < u.len() {
            assert!((s.y_ahead - y_thesis[k + 7]).abs() < 1e-12, "k={k}");
        }
    }
}
