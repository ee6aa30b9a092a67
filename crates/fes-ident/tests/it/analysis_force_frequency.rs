//! Force-frequency curve (Fig. 5.26), the phi/state trace, and simulated-vs-measured
//! errors (eq. B.8), against closed forms.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use super::analysis_support;

use analysis_support::*;
use fes_ident::analysis::force_frequency::{ForceFrequencyError, force_frequency};
use fes_ident::analysis::trace::{phi_range, simulate_trace};
use fes_ident::analysis::validation::{fit_record, msse};
use fes_model::model::simulate::simulate;

/// A linear model under a pulse every `ipi` samples reaches a periodic steady state whose
/// mean output is G / ipi (one pulse response, summing to G, per period), and the thesis
/// pre-filter's mean phi is 10 / ipi (= f/100): both to 1e-6 relative over 500..1000 ms
/// (transients e^{-40 x 0.5}, e^{-50 x 0.5}).
#[test]
fn linear_curve_is_gain_times_rate() {
    let g = 12.0;
    let net = linear([-40.0, -200.0], g).network().unwrap();
    let trains: Vec<(f64, Vec<usize>)> = [10usize, 20, 25, 50, 100]
        .iter()
        .map(|&ipi| (1000.0 / ipi as f64, (0..1000).step_by(ipi).collect()))
        .collect();
    let pts = force_frequency(&net, &trains, 1000, 500).unwrap();
    for (p, (_, t)) in pts.iter().zip(&trains) {
        let ipi = t[1] - t[0];
        let want = g / ipi as f64;
        assert!(
            (p.mean_output - want).abs() < 1e-6 * want,
            "{} Hz: {} vs {want}",
            p.frequency_hz,
            p.mean_output
        );
        let phi = 10.0 / ipi as f64;
        assert!(
            (p.phi_mean - phi).abs() < 1e-6 * phi,
            "{} vs {phi}",
            p.phi_mean
        );
        assert!(p.phi_max >= p.phi_mean);
    }
    assert_eq!(
        force_frequency(&net, &trains, 1000, 1000),
        Err(ForceFrequencyError::Window {
            from: 1000,
            samples: 1000
        })
    );
}

/// The trace's output is the model library's simulation exactly; its phi range over
/// records is the min/max of the traced phi (and starts at rest, phi = 0).
#[test]
fn trace_equals_simulation_and_phi_range_is_its_extent() {
    let m = truth();
    let net = m.network().unwrap();
    let inputs = random_inputs(4, 400, 9);
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for u in &inputs {
        let t = simulate_trace(&net, u).unwrap();
        let mut y = vec![0.0; u.len()];
        simulate(&net, u, &mut y).unwrap();
        assert_eq!(t.y, y);
        assert_eq!(t.phi[0], 0.0);
        for &p in &t.phi {
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }
    let r = phi_range(&net, inputs.iter().map(|u| u.as_slice())).unwrap();
    assert_eq!(r, Some((lo, hi)));
    assert!(hi > 0.3, "random trains reach phi {hi}");
    assert_eq!(phi_range(&net, std::iter::empty()).unwrap(), None);
}

/// MSSE by hand: one record's mean squared error, and the sample-weighted mean over two
/// records of different lengths (eq. B.8 over the records concatenated).
#[test]
fn msse_by_hand() {
    let net = truth().network().unwrap();
    let u1 = random_inputs(1, 300, 1).remove(0);
    let u2 = random_inputs(1, 500, 2).remove(0);
    let y1: Vec<f64> = outputs(&truth(), std::slice::from_ref(&u1))
        .remove(0)
        .iter()
        .map(|v| v + 0.01)
        .collect();
    let y2: Vec<f64> = outputs(&truth(), std::slice::from_ref(&u2))
        .remove(0)
        .iter()
        .map(|v| v - 0.02)
        .collect();
    let f1 = fit_record(&net, &u1, &y1).unwrap();
    assert!((f1.msse - 1e-4).abs() < 1e-15, "{}", f1.msse);
    let all = msse(
        &net,
        [
            (u1.as_slice(), y1.as_slice()),
            (u2.as_slice(), y2.as_slice()),
        ],
    )
    .unwrap();
    let want = (300.0 * 1e-4 + 500.0 * 4e-4) / 800.0;
    assert!((all - want).abs() < 1e-15, "{all} vs {want}");
}
