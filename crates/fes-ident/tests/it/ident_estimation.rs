//! Estimation against known truths: prediction-mode least squares against a hand-built
//! regression (eq. 2.18, B.11) and exact recovery of a known ARX network; LM recovering a
//! known common-eigenvector network; the full `identify` pipeline on data from a known
//! network (errors at the noise floor); gauge invariance; knot optimisation; validity
//! weights against an independent prefilter loop.
#![allow(clippy::needless_range_loop)] // index loops mirror the equations
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use fes_ident::ident::gauge::fix_gauge;
use fes_ident::ident::lm::{LmOptions, levenberg_marquardt};
use fes_ident::ident::metrics::validity_weights;
use fes_ident::ident::problem::{Horizon, ModelData, Problem, ThetaMap};
use fes_ident::ident::records::{IdentRecord, RecordSet};
use fes_ident::ident::regression::{Learning, fit_prediction};
use fes_ident::ident::{Hooks, IdentOptions, Mode, SchedulingKind, identify};
use fes_model::model::arx::ArxUnit;
use fes_model::model::lmn::{Lmn, LocalModelSet, Provenance, Structure};
use fes_model::model::local_model::{EigCommonUnit, EigLocalUnit, SsLocalModel};
use fes_model::model::params::ParamLayout;
use fes_model::model::scheduling::{Prefilter, SchedulingSpec};
use fes_model::model::simulate::simulate;
use fes_model::model::validity::{KnotLayout, ValidityFunctions};
use nalgebra::{DMatrix, DVector};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

const TS: f64 = 1e-3;

/// Thesis-like pulse trains (5.1): 590 ms records, a train from 10 ms of 100-300 ms with
/// random IPIs of 1-70 ms; every 5th record a constant 25 ms train.
fn pulse_trains(n_records: usize, seed: u64) -> Vec<Vec<f64>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n_records)
        .map(|r| {
            let mut u = vec![0.0; 590];
            let len = rng.random_range(100..=300usize);
            let mut k = 10;
            while k <= 10 + len {
                u[k] = 1.0;
                k += if r % 5 == 4 {
                    25
                } else {
                    rng.random_range(1..=70usize)
                };
            }
            u
        })
        .collect()
}

/// Records of a network's free-run output plus Gaussian noise of standard deviation `sigma`.
fn records_of(truth: &Lmn, n_train: usize, n_test: usize, sigma: f64, seed: u64) -> RecordSet {
    let net = truth.network().expect("truth network");
    let normal = Normal::new(0.0, sigma.max(1e-300)).expect("normal");
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed);
    let mut recs: Vec<IdentRecord> = pulse_trains(n_train + n_test, seed)
        .into_iter()
        .enumerate()
        .map(|(i, u)| {
            let mut y = vec![0.0; u.len()];
            simulate(&net, &u, &mut y).expect("simulate truth");
            if sigma > 0.0 {
                for v in &mut y {
                    *v += normal.sample(&mut rng);
                }
            }
            IdentRecord::new(format!("r{i}"), u, y).expect("record")
        })
        .collect();
    let test = recs.split_off(n_train);
    RecordSet::new(TS, recs, test).expect("record set")
}

fn lmn(local: LocalModelSet, m: usize, zero_offsets: bool, scheduling: SchedulingSpec) -> Lmn {
    Lmn {
        ts: TS,
        delay: 7,
        scheduling,
        validity: ValidityFunctions::uniform(m, 0.0, 1.0).expect("uniform"),
        local,
        zero_offsets,
        force_scale_n: 1.0,
        provenance: Provenance::default(),
    }
}

/// A 3-unit shift ARX network (input or output scheduling) whose gain grows with phi.
fn arx_truth(scheduling: SchedulingSpec) -> Lmn {
    let units = (0..3)
        .map(|i| {
            let z = [0.95 - 0.01 * i as f64, 0.90];
            ArxUnit {
                a: [-(z[0] + z[1]), z[0] * z[1], 0.0],
                b: [0.004 + 0.002 * i as f64, 0.001, 0.0],
                d: 0.0002 * (i + 1) as f64,
            }
        })
        .collect();
    lmn(
        LocalModelSet::ArxShift { order: 2, units },
        3,
        false,
        scheduling,
    )
}

/// A 3-unit common-eigenvector network (modal gauge, reference unit 1).
fn ss_truth(zero_offsets: bool) -> Lmn {
    let units = (0..3)
        .map(|i| {
            let f = i as f64;
            EigCommonUnit {
                eigenvalues: [-120.0 + 20.0 * f, -22.0 + 3.0 * f],
                b: if i == 1 {
                    [1.0, 1.0]
                } else {
                    [1.0 + 0.3 * f, 0.9 + 0.1 * f]
                },
                c: [-30.0 - 5.0 * f, 32.0 + 8.0 * f],
                dx: if zero_offsets {
                    [0.0; 2]
                } else {
                    [0.01 * f, 0.0]
                },
                dy: if zero_offsets { 0.0 } else { 0.002 * f },
            }
        })
        .collect();
    lmn(
        LocalModelSet::SsEigCommon {
            units,
            reference_unit: 1,
        },
        3,
        zero_offsets,
        SchedulingSpec::default(),
    )
}

/// Noise-free data from a known ARX network: global least squares returns its parameters
/// with input scheduling. With output scheduling phi = y(k-1) is also a regressor, and
/// rho_i(phi) y(k-1) and rho_i(phi) span the same functions phi (alpha + beta phi): a
/// 2-dimensional family of parameters gives identical predictions (and simulations), so
/// the regression has rank P - 2 and the estimate must reproduce the truth's predictions
/// rather than its parameters.
#[test]
fn global_least_squares_recovers_a_known_arx_network() {
    for sched in [SchedulingSpec::default(), SchedulingSpec::Output] {
        let truth = arx_truth(sched);
        // Output scheduling: prediction feeds measured outputs, so the data must come from
        // the network's own simulation (noise-free).
        let recs = records_of(&truth, 12, 2, 0.0, 3);
        let data = ModelData::new(&recs.train, 1).expect("data");
        // A template with other (stable) parameters as the reference point.
        let mut template = truth.clone();
        if let LocalModelSet::ArxShift { units, .. } = &mut template.local {
            for u in units.iter_mut() {
                *u = ArxUnit {
                    a: [-1.6, 0.64, 0.0],
                    b: [0.01, 0.0, 0.0],
                    d: 0.0,
                };
            }
        }
        let (theta, fallback) = fit_prediction(&template, &data, Learning::Global).expect("fit");
        assert!(fallback.is_empty());
        let layout = ParamLayout::new(&truth);
        let want = layout.theta(&truth).expect("theta");
        let problem = Problem::new(
            ThetaMap {
                template: &truth,
                layout: &layout,
            },
            &data,
            Horizon::Prediction,
        );
        let cols: Vec<usize> = (0..want.len()).collect();
        let (_, j) = problem.jacobian(&want, &cols).expect("jacobian");
        let jn = j.norm();
        let rank = j.svd(false, false).rank(1e-9 * jn);
        if sched == SchedulingSpec::Output {
            assert_eq!(
                rank,
                want.len() - 2,
                "output scheduling: rank of the regression"
            );
            let r = problem.residuals(&theta).expect("residuals");
            let worst = r.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            assert!(worst < 1e-10, "predictions differ by {worst:.3e}");
        } else {
            assert_eq!(rank, want.len());
            for (i, (a, b)) in theta.iter().zip(&want).enumerate() {
                assert!(
                    (a - b).abs() < 1e-7 * (1.0 + b.abs()),
                    "{}: {a} vs {b}",
                    layout.names()[i]
                );
            }
        }
    }
}

/// Local learning (eq. 2.35) against an independent construction: the data vector of
/// eq. A.35 built by hand (u zero and y = y[0] before the record), phi from a hand-run
/// prefilter on the delayed input, rho from the validity functions; each unit's estimate
/// must satisfy its weighted normal equations (eq. B.11) to 1e-9.
#[test]
fn local_learning_solves_the_hand_built_weighted_normal_equations() {
    let truth = arx_truth(SchedulingSpec::default());
    let recs = records_of(&truth, 8, 2, 0.003, 5);
    let data = ModelData::new(&recs.train, 1).expect("data");
    let (theta, _) = fit_prediction(&truth, &data, Learning::Local).expect("fit");
    let layout = ParamLayout::new(&truth);
    let d = truth.delay;
    let pf = Prefilter::thesis(TS).expect("prefilter");
    for m in 0..3 {
        let mut ata = DMatrix::<f64>::zeros(5, 5);
        let mut aty = DVector::<f64>::zeros(5);
        for r in &recs.train {
            let (u, y) = (&r.u, &r.y);
            let mut w = [0.0; 2];
            for k in 0..u.len() {
                let phi = pf.output(&w);
                let v = if k >= d { u[k - d] } else { 0.0 };
                let ui = |l: usize| if k >= d + l { u[k - d - l] } else { 0.0 };
                let yi = |i: usize| if k >= i { y[k - i] } else { y[0] };
                let psi = [ui(0), ui(1), yi(1), yi(2), 1.0];
                let rho = truth.validity.eval(phi).get(m);
                for a in 0..5 {
                    aty[a] += rho * psi[a] * y[k];
                    for b in 0..5 {
                        ata[(a, b)] += rho * psi[a] * psi[b];
                    }
                }
                pf.advance(&mut w, v);
            }
        }
        let th = DVector::from_column_slice(&theta[layout.unit_range(m)]);
        let res = &ata * &th - &aty;
        assert!(
            res.norm() < 1e-9 * aty.norm(),
            "unit {m}: |A'W(A theta - y)| = {:.3e}",
            res.norm()
        );
    }
}

/// Validity weights from the probe network equal rho_i(phi_k) with phi from a hand-run
/// prefilter on the delayed input, and sum to one at every sample.
#[test]
fn validity_weights_match_an_independent_prefilter_loop() {
    let truth = ss_truth(false);
    let recs = records_of(&truth, 3, 1, 0.0, 9);
    let data = ModelData::new(&recs.train, 1).expect("data");
    let w = validity_weights(&truth, &data).expect("weights");
    let pf = Prefilter::thesis(TS).expect("prefilter");
    for (ri, r) in recs.train.iter().enumerate() {
        let mut st = [0.0; 2];
        for k in 0..r.u.len() {
            let a = truth.validity.eval(pf.output(&st));
            let sum: f64 = (0..3).map(|i| w[i][ri][k]).sum();
            assert!((sum - 1.0).abs() < 1e-12);
            for i in 0..3 {
                assert!(
                    (w[i][ri][k] - a.get(i)).abs() < 1e-12,
                    "record {ri} sample {k} unit {i}"
                );
            }
            pf.advance(
                &mut st,
                if k >= truth.delay {
                    r.u[k - truth.delay]
                } else {
                    0.0
                },
            );
        }
    }
}

/// LM from a perturbed start recovers a known common-eigenvector network from noise-free
/// data: the cost falls to rounding level and the output matches on test records.
#[test]
fn levenberg_marquardt_recovers_a_known_network() {
    let truth = ss_truth(false);
    let recs = records_of(&truth, 10, 3, 0.0, 11);
    let data = ModelData::new(&recs.train, 1).expect("data");
    let mut start = truth.clone();
    if let LocalModelSet::SsEigCommon { units, .. } = &mut start.local {
        for (i, u) in units.iter_mut().enumerate() {
            u.eigenvalues = [u.eigenvalues[0] * 1.15, u.eigenvalues[1] * 0.9];
            u.c = [u.c[0] * 1.05, u.c[1] * 0.97];
            if i != 1 {
                u.b[0] *= 1.1;
            }
        }
    }
    let mut gauged = start.clone();
    let fixed = fix_gauge(&mut gauged, 1);
    let layout = ParamLayout::new(&gauged);
    let theta0 = layout.theta(&gauged).expect("theta");
    let problem = Problem::new(
        ThetaMap {
            template: &gauged,
            layout: &layout,
        },
        &data,
        Horizon::Simulation,
    );
    let free: Vec<usize> = (0..theta0.len()).filter(|i| !fixed.contains(i)).collect();
    let opts = LmOptions {
        max_iter: 300,
        window_tol: 0.0,
        ..LmOptions::default()
    };
    let rep = levenberg_marquardt(&problem, &theta0, &free, &opts, &mut |_, _| {}).expect("lm");
    let n = data.base_samples() as f64;
    assert!(
        rep.initial_cost / n > 1e-6,
        "the start must be wrong: {}",
        rep.initial_cost / n
    );
    assert!(
        rep.cost / n < 1e-18,
        "training MSE {} after {} iterations ({})",
        rep.cost / n,
        rep.iterations,
        rep.stop
    );
    let fitted = layout
        .apply(&gauged, &rep.p)
        .expect("apply")
        .network()
        .expect("network");
    let net = truth.network().expect("truth");
    for r in &recs.test {
        let (mut a, mut b) = (vec![0.0; r.u.len()], vec![0.0; r.u.len()]);
        simulate(&fitted, &r.u, &mut a).expect("fitted");
        simulate(&net, &r.u, &mut b).expect("truth");
        for k in 0..a.len() {
            assert!(
                (a[k] - b[k]).abs() < 1e-7,
                "test output differs at {k}: {} vs {}",
                a[k],
                b[k]
            );
        }
    }
}

/// The whole pipeline (linear starts, network starts, LM) on noisy data from a known
/// network reaches the noise floor: training and test MSSE within 15 % of sigma^2.
#[test]
fn identify_reaches_the_noise_floor_on_data_from_a_known_network() {
    let sigma = 0.005;
    for zero_offsets in [false, true] {
        let truth = ss_truth(zero_offsets);
        let recs = records_of(&truth, 20, 10, sigma, 21);
        let opts = IdentOptions {
            structure: Structure::SsEigCommon,
            units: 3,
            zero_offsets,
            ..IdentOptions::default()
        };
        let r = identify(&recs, &opts, &Hooks::silent()).expect("identify");
        let s2 = sigma * sigma;
        for (what, v) in [
            ("train", r.metrics.train_msse),
            ("test", r.metrics.test_msse),
        ] {
            assert!(
                v < 1.15 * s2 && v > 0.85 * s2,
                "zero offsets {zero_offsets}: {what} MSSE {v:.4e} vs noise {s2:.4e} ({} iterations)",
                r.iterations
            );
        }
        assert!(r.lmn.stability().iter().all(|s| s.stable));
        assert_eq!(r.lmn.provenance.train_msse, Some(r.metrics.train_msse));
        // The field's figures agree with the thesis's: RRSE^2 = N MSSE / sum (y - mean)^2
        // over the same base-period samples, fit = 100 (1 - RRSE).
        let v = &r.validation;
        let y: Vec<f64> = v.test.iter().flat_map(|t| t.measured.clone()).collect();
        let mean = y.iter().sum::<f64>() / y.len() as f64;
        let spread: f64 = y.iter().map(|a| (a - mean) * (a - mean)).sum();
        let rrse = v.test_rrse.expect("test RRSE");
        let via_msse = (y.len() as f64 * r.metrics.test_msse / spread).sqrt();
        assert!(
            (rrse - via_msse).abs() < 1e-9 * via_msse,
            "{rrse} vs {via_msse}"
        );
        assert!((v.test_fit_percent.unwrap() - 100.0 * (1.0 - rrse)).abs() < 1e-9);
        let p = &r.lmn.provenance.extra;
        assert_eq!(p["test_rrse"].as_f64(), Some(rrse));
        assert_eq!(p["test_fit_percent"].as_f64(), v.test_fit_percent);
        assert_eq!(p["train_fit_percent"].as_f64(), v.train_fit_percent);
        // At the noise floor the residuals are the white noise added: few of the 25 lags
        // of either test outside the 99 % band.
        let resid = v.resid.as_ref().expect("residual tests");
        assert!(
            resid.autocorr_outside <= 3 && resid.xcorr_outside <= 4,
            "zero offsets {zero_offsets}: {resid:?}"
        );
    }
}

/// Gauge fixing maps a model to one with identical output, puts the reference unit into
/// the documented form, and removes the exactly singular Hessian directions.
#[test]
fn gauge_fixing_keeps_the_output_and_regularises_the_hessian() {
    let common = ss_truth(false);
    let LocalModelSet::SsEigCommon { units, .. } = &common.local else {
        unreachable!()
    };
    let local: Vec<EigLocalUnit> = units
        .iter()
        .enumerate()
        .map(|(i, u)| EigLocalUnit {
            eigenvalues: u.eigenvalues,
            eigenvector_angles: [0.4 + 0.1 * i as f64, 1.7],
            b: u.b,
            c: u.c,
            dx: [0.01, -0.02 * i as f64],
            dy: u.dy,
        })
        .collect();
    let direct: Vec<SsLocalModel> = local
        .iter()
        .map(|u| u.to_local_model().expect("angles"))
        .collect();
    let models = [
        common.clone(),
        lmn(
            LocalModelSet::SsEigLocal(local),
            3,
            false,
            SchedulingSpec::default(),
        ),
        lmn(
            LocalModelSet::SsDirect(direct),
            3,
            false,
            SchedulingSpec::default(),
        ),
    ];
    let recs = records_of(&common, 4, 1, 0.002, 2);
    let data = ModelData::new(&recs.train, 1).expect("data");
    for m in models {
        let mut g = m.clone();
        let fixed = fix_gauge(&mut g, 1);
        let names = ParamLayout::new(&g).names().to_vec();
        let fixed_names: Vec<&str> = fixed.iter().map(|&i| names[i].as_str()).collect();
        let (a, b) = (m.network().expect("net"), g.network().expect("gauged net"));
        for r in &recs.train {
            let (mut ya, mut yb) = (vec![0.0; r.u.len()], vec![0.0; r.u.len()]);
            simulate(&a, &r.u, &mut ya).expect("sim");
            simulate(&b, &r.u, &mut yb).expect("sim");
            for k in 0..ya.len() {
                assert!(
                    (ya[k] - yb[k]).abs() < 1e-9,
                    "{}: output changed at {k}",
                    m.structure()
                );
            }
        }
        let unit = g.ss_units().expect("ss")[1];
        assert!(
            unit.dx[0].abs() < 1e-12 && unit.dx[1].abs() < 1e-12,
            "{}: dx_r",
            m.structure()
        );
        match m.structure() {
            Structure::SsDirect => {
                assert!(unit.a[0][0].abs() < 1e-9 && (unit.a[0][1] - 1.0).abs() < 1e-9);
                assert!(unit.b[0].abs() < 1e-12 && (unit.b[1] - 1.0).abs() < 1e-12);
                assert_eq!(
                    fixed_names,
                    [
                        "units[1].a00",
                        "units[1].a01",
                        "units[1].b0",
                        "units[1].b1",
                        "units[1].dx0",
                        "units[1].dx1"
                    ]
                );
            }
            Structure::SsEigLocal => {
                assert!(
                    (unit.a[0][1]).abs() < 1e-9 && (unit.a[1][0]).abs() < 1e-9,
                    "V_r = I"
                );
                assert!((unit.b[0] - 1.0).abs() < 1e-12 && (unit.b[1] - 1.0).abs() < 1e-12);
                assert_eq!(fixed_names.len(), 6);
            }
            _ => assert_eq!(fixed_names, ["units[1].dx0", "units[1].dx1"]),
        }
        // Hessian over every parameter: exactly singular (translation and, for the
        // non-modal structures, T); over the free ones: regular.
        let layout = ParamLayout::new(&g);
        let theta = layout.theta(&g).expect("theta");
        let problem = Problem::new(
            ThetaMap {
                template: &g,
                layout: &layout,
            },
            &data,
            Horizon::Simulation,
        );
        let min_eig = |cols: &[usize]| {
            let h = problem.normal(&theta, cols).expect("normal").h;
            let d: Vec<f64> = (0..cols.len()).map(|k| h[(k, k)].sqrt()).collect();
            let hs = DMatrix::from_fn(cols.len(), cols.len(), |i, j| h[(i, j)] / (d[i] * d[j]));
            hs.symmetric_eigen().eigenvalues.min()
        };
        let all: Vec<usize> = (0..theta.len()).collect();
        let free: Vec<usize> = all.iter().copied().filter(|i| !fixed.contains(i)).collect();
        let (e_all, e_free) = (min_eig(&all), min_eig(&free));
        assert!(
            e_all < 1e-10,
            "{}: smallest scaled eigenvalue with the gauge free {e_all:.3e}",
            m.structure()
        );
        assert!(
            e_free > 1e3 * e_all.abs().max(1e-14),
            "{}: with the gauge fixed {e_free:.3e}",
            m.structure()
        );
    }
}

/// Knot optimisation on data from a network with non-uniform knots: the training error of
/// the optimised network is below the uniform one's, and the knots stay ordered inside the
/// range.
#[test]
fn knot_optimisation_improves_the_fit_and_keeps_knots_ordered() {
    let mut truth = ss_truth(false);
    let LocalModelSet::SsEigCommon { units, .. } = &truth.local else {
        unreachable!()
    };
    let mut five = units.clone();
    five.push(units[2]);
    five.push(units[0]);
    truth.local = LocalModelSet::SsEigCommon {
        units: five,
        reference_unit: 1,
    };
    truth.validity = ValidityFunctions::from_knots(&[0.0, 0.0, 0.0, 0.12, 0.3, 1.0, 1.0, 1.0], 3)
        .expect("knots");
    let recs = records_of(&truth, 12, 4, 0.002, 31);
    let base = IdentOptions {
        units: 5,
        max_iter: 60,
        ..IdentOptions::default()
    };
    let plain = identify(&recs, &base, &Hooks::silent()).expect("uniform");
    let opt = identify(
        &recs,
        &IdentOptions {
            optimise_knots: true,
            ..base
        },
        &Hooks::silent(),
    )
    .expect("knots");
    assert!(
        opt.metrics.train_msse < plain.metrics.train_msse,
        "optimised {} vs uniform {}",
        opt.metrics.train_msse,
        plain.metrics.train_msse
    );
    let k = opt.lmn.validity.knots();
    assert!(
        k.windows(2)
            .all(|w| w[0] < w[1] || w[0] == w[1] && (w[0] == 0.0 || w[0] == 1.0)),
        "{k:?}"
    );
    assert_eq!((k[0], k[k.len() - 1]), (0.0, 1.0));
}

/// The thesis's knot layout reaches the fit: the identified model keeps the evenly spaced,
/// extended knots (valid range [0, 1]) and fits data from a clamped-knot network about as
/// well as the clamped layout does.
#[test]
fn uniform_knot_layout_identifies_and_keeps_its_knots() {
    let truth = ss_truth(false);
    let recs = records_of(&truth, 12, 4, 0.002, 7);
    let base = IdentOptions {
        units: truth.units(),
        max_iter: 60,
        ..IdentOptions::default()
    };
    let clamped = identify(&recs, &base, &Hooks::silent()).expect("clamped");
    let uniform = identify(
        &recs,
        &IdentOptions {
            knots: KnotLayout::Uniform,
            ..base
        },
        &Hooks::silent(),
    )
    .expect("uniform");
    let want = ValidityFunctions::uniform_extended(truth.units(), 0.0, 1.0).unwrap();
    assert_eq!(uniform.lmn.validity, want);
    assert!(uniform.lmn.validity.knots()[0] < 0.0);
    assert!(
        uniform.metrics.test_msse < 10.0 * clamped.metrics.test_msse.max(4e-6),
        "uniform {} vs clamped {}",
        uniform.metrics.test_msse,
        clamped.metrics.test_msse
    );
}

/// Prediction mode with a state-space structure and bad options are refused, naming the
/// problem.
#[test]
fn bad_options_are_refused() {
    let truth = ss_truth(false);
    let recs = records_of(&truth, 2, 1, 0.0, 1);
    let cases = [
        (
            IdentOptions {
                units: 0,
                ..IdentOptions::default()
            },
            "units",
        ),
        (
            IdentOptions {
                units: 17,
                ..IdentOptions::default()
            },
            "units",
        ),
        (
            IdentOptions {
                mode: Mode::Prediction,
                ..IdentOptions::default()
            },
            "prediction mode needs an ARX structure",
        ),
        (
            IdentOptions {
                starts: 0,
                ..IdentOptions::default()
            },
            "starts",
        ),
        (
            IdentOptions {
                optimise_knots: true,
                knots: KnotLayout::Uniform,
                ..IdentOptions::default()
            },
            "clamped layout",
        ),
        (
            IdentOptions {
                arx_order: 4,
                structure: Structure::ArxDelta,
                ..IdentOptions::default()
            },
            "order",
        ),
        (
            IdentOptions {
                range: (1.0, 0.0),
                ..IdentOptions::default()
            },
            "range",
        ),
        (
            IdentOptions {
                prior: f64::NAN,
                ..IdentOptions::default()
            },
            "prior",
        ),
        (
            IdentOptions {
                structure: Structure::ArxShift,
                mode: Mode::Prediction,
                optimise_knots: true,
                scheduling: SchedulingKind::Output,
                ..IdentOptions::default()
            },
            "knot optimisation",
        ),
    ];
    for (o, want) in cases {
        let e = identify(&recs, &o, &Hooks::silent())
            .expect_err("must fail")
            .to_string();
        assert!(e.contains(want), "{e:?} should mention {want:?}");
    }
}
