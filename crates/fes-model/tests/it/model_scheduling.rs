//! The input-scheduling prefilter (thesis 5.4.1, eq. 5.3-5.4), discretised exactly (ZOH).
#![allow(clippy::needless_range_loop)] // index loops mirror the equations
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use fes_model::model::scheduling::Prefilter;

const TS: f64 = 1e-3;

/// Step response of G_pre = 25000/(s+50)^2: s(t) = 10 (1 - e^{-50t} (1 + 50t)), t >= 0.
fn step_response(t: f64) -> f64 {
    if t <= 0.0 {
        0.0
    } else {
        10.0 * (1.0 - (-50.0 * t).exp() * (1.0 + 50.0 * t))
    }
}

/// Impulse response g(t) = 25000 t e^{-50t}.
fn impulse_response(t: f64) -> f64 {
    25000.0 * t * (-50.0 * t).exp()
}

/// phi samples for a pulse train (phi[k] is the output before input k is applied).
fn run(pf: &Prefilter, u: &[f64]) -> Vec<f64> {
    let mut w = [0.0; 2];
    u.iter()
        .map(|&v| {
            let phi = pf.output(&w);
            pf.advance(&mut w, v);
            phi
        })
        .collect()
}

/// A 1-sample pulse at k = 0 is a rectangle of width Ts: the exact response at t = kTs is
/// s(kTs) - s((k-1)Ts). Checked to 1e-12 over 400 ms.
#[test]
fn pulse_gives_the_exact_rectangle_response() {
    let pf = Prefilter::thesis(TS).unwrap();
    let mut u = vec![0.0; 400];
    u[0] = 1.0;
    let phi = run(&pf, &u);
    for (k, &p) in phi.iter().enumerate() {
        let t = k as f64 * TS;
        let exact = step_response(t) - step_response(t - TS);
        assert!((p - exact).abs() < 1e-12, "k={k}: {p} vs {exact}");
    }
    // Superposition: a train is the sum of shifted pulse responses (linearity, exactness).
    let mut train = vec![0.0; 400];
    for k in [3, 10, 12, 40, 41, 90] {
        train[k] = 1.0;
    }
    let phi_train = run(&pf, &train);
    for (k, &p) in phi_train.iter().enumerate() {
        let t = k as f64 * TS;
        let exact: f64 = [3, 10, 12, 40, 41, 90]
            .iter()
            .map(|&j| {
                let tj = t - j as f64 * TS;
                step_response(tj) - step_response(tj - TS)
            })
            .sum();
        assert!((p - exact).abs() < 1e-12, "k={k}");
    }
}

/// The pulse response approximates the analytic impulse response times the pulse area Ts.
/// The ZOH rectangle is centred half a sample earlier, so the comparison is at the rectangle
/// centre (k - 1/2) Ts: required within 3 % of the peak g(1/50) Ts = 0.1839. (At the sample
/// instant kTs itself the difference is about Ts^2/2 g'(t), at most 25000 Ts^2 / 2 = 0.0125 =
/// 6.8 % of the peak at t -> 0; that bound is checked too.)
#[test]
fn pulse_response_matches_the_analytic_impulse_response() {
    let pf = Prefilter::thesis(TS).unwrap();
    let mut u = vec![0.0; 300];
    u[0] = 1.0;
    let phi = run(&pf, &u);
    let peak = impulse_response(1.0 / 50.0) * TS;
    assert!((peak - 0.18394).abs() < 1e-4);
    let mut worst_mid: f64 = 0.0;
    for (k, &p) in phi.iter().enumerate().skip(1) {
        let mid = impulse_response((k as f64 - 0.5) * TS) * TS;
        worst_mid = worst_mid.max((p - mid).abs());
        let at = impulse_response(k as f64 * TS) * TS;
        assert!(
            (p - at).abs() <= 25000.0 * TS * TS / 2.0,
            "k={k}: {p} vs {at}"
        );
    }
    assert!(worst_mid < 0.03 * peak, "worst {worst_mid} vs 3% of {peak}");
    // The peak sample itself lies within 3 % of the analytic peak.
    let max = phi.iter().cloned().fold(0.0, f64::max);
    assert!((max - peak).abs() < 0.03 * peak, "{max} vs {peak}");
}

/// Constant 40 Hz (a pulse every 25 ms): mean phi after the transient = DC gain 10 times the
/// mean input 40 * 0.001 = 0.40; required 0.40 +- 0.02.
#[test]
fn forty_hertz_train_has_mean_phi_point_four() {
    let pf = Prefilter::thesis(TS).unwrap();
    assert!((pf.dc_gain() - 10.0).abs() < 1e-12);
    let u: Vec<f64> = (0..2000)
        .map(|k| if k % 25 == 0 { 1.0 } else { 0.0 })
        .collect();
    let phi = run(&pf, &u);
    // Whole periods after 500 ms (10 time constants of the double pole at 50 rad/s: the
    // transient is e^{-25}-small).
    let tail = &phi[500..2000];
    let mean = tail.iter().sum::<f64>() / tail.len() as f64;
    assert!((mean - 0.40).abs() < 0.02, "mean phi {mean}");
    // With the transient gone the periodic mean is exact: 10 * 40 * Ts.
    assert!((mean - 0.40).abs() < 1e-9, "mean phi {mean}");
}

/// Thesis Fig. 5.29: a doublet (IPI 2 ms) drives phi to about 0.4-0.5.
#[test]
fn doublet_peaks_near_point_four_five() {
    let pf = Prefilter::thesis(TS).unwrap();
    let mut u = vec![0.0; 200];
    u[0] = 1.0;
    u[2] = 1.0;
    let phi = run(&pf, &u);
    let max = phi.iter().cloned().fold(0.0, f64::max);
    assert!((0.33..=0.5).contains(&max), "doublet peak {max}");
}

/// Other sampling periods: the discretisation stays exact (5 and 10 ms shift models).
#[test]
fn exact_at_other_sampling_periods() {
    for ts in [5e-3, 10e-3] {
        let pf = Prefilter::thesis(ts).unwrap();
        let mut u = vec![0.0; 60];
        u[0] = 1.0;
        let phi = run(&pf, &u);
        for (k, &p) in phi.iter().enumerate() {
            let t = k as f64 * ts;
            let exact = step_response(t) - step_response(t - ts);
            assert!((p - exact).abs() < 1e-12, "Ts={ts} k={k}");
        }
    }
    assert!(Prefilter::new(25000.0, 50.0, 1.0, 0.0).is_err());
    assert!(Prefilter::new(25000.0, -50.0, 1.0, TS).is_err());
    assert!(Prefilter::new(f64::NAN, 50.0, 1.0, TS).is_err());
}
