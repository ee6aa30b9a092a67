//! Multi-input ARX networks (`model::miso`, `ident::miso`): a known network is recovered
//! from its own noise-free output, in prediction mode by least squares (exactly) and in
//! simulation mode by Levenberg-Marquardt from a perturbed start; the frozen model's gains
//! and poles are the polynomials'.

use fes_ident::ident::Learning;
use fes_ident::ident::lm::LmOptions;
use fes_ident::ident::miso::{self, MisoRecord};
use fes_ident::ident::problem::Horizon;
use fes_model::model::miso::{MisoArx, MisoStructure};
use fes_model::model::validity::ValidityFunctions;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Three 1st-order units, two inputs with delays 2 and 1, scheduled on input 0 (delay 2).
fn truth() -> MisoArx {
    let st = MisoStructure {
        order: 1,
        delays: vec![2, 1],
        unit_delays: vec![],
        scheduling_input: 0,
        scheduling_delay: 2,
        scheduling2: None,
        offset: true,
    };
    // theta_i = [b_alpha, b_u, -a_1, c]
    let theta = vec![
        -0.05, 0.10, 0.90, 0.01, //
        -0.03, 0.08, 0.85, 0.00, //
        -0.01, 0.05, 0.80, -0.01,
    ];
    let v = ValidityFunctions::uniform(3, 0.0, 1.0).unwrap();
    MisoArx::new(0.05, st, v, theta).unwrap()
}

fn records(model: &MisoArx, seed: u64) -> Vec<MisoRecord> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..3)
        .map(|i| {
            let n = 400;
            let level = |hold: usize, rng: &mut ChaCha8Rng| {
                let mut v = Vec::with_capacity(n);
                while v.len() < n {
                    let x: f64 = rng.random_range(0.0..1.0);
                    v.extend(std::iter::repeat_n(x, hold.min(n - v.len())));
                }
                v
            };
            let u = vec![level(25, &mut rng), level(3, &mut rng)];
            // Start in the steady state of the first inputs (the records' convention).
            let f = model.frozen_at(u[0][0], model.structure.scheduling2.map(|(c, _)| u[c][0]));
            let y0 = (f.b[0][0] * u[0][0] + f.b[1][0] * u[1][0] + f.c) / (1.0 + f.a[0]);
            let mut y = vec![0.0; n];
            let refs: Vec<&[f64]> = u.iter().map(Vec::as_slice).collect();
            model.simulate(&refs, y0, &mut y).unwrap();
            assert!((y[0] - y0).abs() < 1e-12);
            MisoRecord {
                name: format!("r{i}"),
                u,
                y,
            }
        })
        .collect()
}

#[test]
fn prediction_least_squares_recovers_a_known_network() {
    let t = truth();
    let recs = records(&t, 1);
    let mut start = t.clone();
    start.theta.iter_mut().for_each(|v| *v = 0.0);
    let fit = miso::fit_prediction(&start, &recs, Learning::Global).unwrap();
    assert_identifiable_close(&fit, &t, 1e-8);
    assert!(miso::mse(&fit, &recs, Horizon::Prediction).unwrap() < 1e-20);
    // Local learning has the bias of eq. 2.35 but stays close.
    let local = miso::fit_prediction(&start, &recs, Learning::Local).unwrap();
    assert!(miso::mse(&local, &recs, Horizon::Prediction).unwrap() < 1e-4);
}

#[test]
fn simulation_levenberg_marquardt_recovers_a_known_network() {
    let t = truth();
    let recs = records(&t, 2);
    let mut start = t.clone();
    for (k, v) in start.theta.iter_mut().enumerate() {
        *v *= if k % 2 == 0 { 0.97 } else { 1.02 };
    }
    let opts = LmOptions {
        rel_tol: 1e-12,
        window_tol: 0.0,
        ..LmOptions::default()
    };
    let fit = miso::fit_simulation(&start, &recs, Learning::Global, &opts).unwrap();
    let e = miso::mse(&fit, &recs, Horizon::Simulation).unwrap();
    assert!(e < 1e-12, "{e}");
    assert_identifiable_close(&fit, &t, 1e-4);
}

/// b_u and a_1 of every unit. The scheduling input is also a regressor at the same delay,
/// so sum_i rho_i(alpha)(b_alpha,i alpha + c_i) is a cubic in alpha with six parameters:
/// b_alpha and c are not identifiable one by one (the SVD's minimum-norm solution picks
/// one), only the function they make.
fn assert_identifiable_close(fit: &MisoArx, t: &MisoArx, tol: f64) {
    for i in 0..t.units() {
        for k in [1, 2] {
            let (a, b) = (fit.unit(i)[k], t.unit(i)[k]);
            assert!((a - b).abs() < tol, "unit {i} theta[{k}]: {a} vs {b}");
        }
    }
}

#[test]
fn frozen_model_gains_and_poles() {
    let t = truth();
    // At phi = 0 only unit 0 is active (clamped uniform splines peak at the ends).
    let p = miso::static_analysis(&t, 3);
    assert_eq!(p[0].rho, vec![1.0, 0.0, 0.0]);
    assert!((p[0].poles[0].re - 0.90).abs() < 1e-12);
    assert!((p[0].gains[0] - (-0.05 / 0.10)).abs() < 1e-12);
    assert!((p[0].gains[1] - (0.10 / 0.10)).abs() < 1e-12);
    assert!((p[2].poles[0].re - 0.80).abs() < 1e-12);
}

/// Two scheduling variables (eq. E.1): the tensor-product weights sum to one, and a known
/// 2 x 3-unit network is recovered from its own output by prediction-mode least squares.
#[test]
fn tensor_product_scheduling_recovers_a_known_network() {
    let mut st = truth().structure;
    st.scheduling2 = Some((1, 1));
    let v1 = ValidityFunctions::uniform(2, 0.0, 1.0).unwrap();
    let v2 = ValidityFunctions::uniform(3, 0.0, 1.0).unwrap();
    let theta: Vec<f64> = (0..6)
        .flat_map(|i| {
            let s = i as f64;
            [-0.05 + 0.01 * s, 0.1 - 0.01 * s, 0.9 - 0.02 * s, 0.01]
        })
        .collect();
    let t = MisoArx::tensor(0.05, st.clone(), v1, v2, theta).unwrap();
    assert_eq!(t.units(), 6);
    for (a, b) in [(0.1, 0.2), (0.5, 0.77), (0.9, 0.0)] {
        let (act, n) = t.activation_at(a, Some(b));
        let sum: f64 = act[..n].iter().map(|x| x.1).sum();
        assert!((sum - 1.0).abs() < 1e-12, "{sum}");
    }
    // A one-dimensional constructor refuses a second scheduling variable.
    assert!(MisoArx::new(0.05, st, v1, vec![0.0; 8]).is_err());
    let recs = records(&t, 3);
    let mut start = t.clone();
    start.theta.iter_mut().for_each(|v| *v = 0.0);
    let fit = miso::fit_prediction(&start, &recs, Learning::Global).unwrap();
    assert!(miso::mse(&fit, &recs, Horizon::Prediction).unwrap() < 1e-20);
    // Both inputs now schedule at their regressors' delays: only the a_1 are
    // identifiable one by one (see assert_identifiable_close).
    for i in 0..t.units() {
        assert!((fit.unit(i)[2] - t.unit(i)[2]).abs() < 1e-6, "unit {i}");
    }
}
