//! The network core against independent truths: closed-form modal solutions, the shift-domain
//! counterpart, a direct delta-form ARX simulation, a derived stability bound, and finite
//! differences for the Dual-number sensitivities.
#![allow(clippy::needless_range_loop)] // index loops mirror the equations
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use fes_model::model::arx::ArxUnit;
use fes_model::model::lmn::{Lmn, LocalModelSet, Provenance};
use fes_model::model::local_model::{
    CommonEigenvectorForm, EigCommonUnit, EigLocalUnit, SsLocalModel, eigenvector_matrix, inverse2,
    mat_vec2,
};
use fes_model::model::network::Network;
use fes_model::model::scheduling::{Scheduler, SchedulingSpec};
use fes_model::model::simulate::{mse, predict, simulate};
use fes_model::model::validity::ValidityFunctions;
use fes_model::num::{Dual, Scalar};
use proptest::prelude::*;

const TS: f64 = 1e-3;

fn thesis_scheduler() -> Scheduler {
    Scheduler::new(&SchedulingSpec::default(), TS).unwrap()
}

fn pulses(bits: &[bool]) -> Vec<f64> {
    bits.iter().map(|&b| if b { 1.0 } else { 0.0 }).collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// A 1-unit network is the linear model it holds. Independent truth: the explicit modal
    /// solution of x[k+1] = (I + Ts A) x + Ts b v + Ts dx with A = V diag(e) V^-1:
    /// y[k] = y_rest + sum over pulses j with k >= j + d + 1 of
    /// c' V diag((1 + Ts e)^{k-j-d-1}) V^-1 Ts b.
    #[test]
    fn one_unit_network_is_its_linear_model(
        e0 in -900.0f64..-1.0, e1 in -900.0f64..-1.0,
        th0 in 0.0f64..3.1, dth in 0.3f64..2.8,
        b in prop::array::uniform2(-3.0f64..3.0), c in prop::array::uniform2(-3.0f64..3.0),
        dx in prop::array::uniform2(-5.0f64..5.0), dy in -1.0f64..1.0,
        delay in 0usize..12,
        bits in prop::collection::vec(prop::bool::weighted(0.1), 400),
    ) {
        let unit = EigLocalUnit { eigenvalues: [e0, e1], eigenvector_angles: [th0, th0 + dth], b, c, dx, dy };
        let m = unit.to_local_model().unwrap();
        let vf = ValidityFunctions::uniform(1, 0.0, 1.0).unwrap();
        let net = Network::state_space(TS, delay, vf, thesis_scheduler(), &[m]).unwrap();
        let u = pulses(&bits);
        let mut y = vec![0.0; u.len()];
        simulate(&net, &u, &mut y).unwrap();

        let v = eigenvector_matrix([th0, th0 + dth]);
        let vi = inverse2(&v).unwrap();
        let vtc = [v[0][0] * c[0] + v[1][0] * c[1], v[0][1] * c[0] + v[1][1] * c[1]];
        let vib = mat_vec2(&vi, b);
        let lam = [1.0 + TS * e0, 1.0 + TS * e1];
        // Rest: A x0 + dx = 0.
        let vidx = mat_vec2(&vi, dx);
        let w0 = [-vidx[0] / e0, -vidx[1] / e1];
        let y_rest = vtc[0] * w0[0] + vtc[1] * w0[1] + dy;
        let scale = 1.0 + y.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        for k in 0..u.len() {
            let mut truth = y_rest;
            for (j, &uj) in u.iter().enumerate() {
                if uj == 1.0 && k > j + delay {
                    let p = (k - j - delay - 1) as i32;
                    truth += TS * (vtc[0] * lam[0].powi(p) * vib[0] + vtc[1] * lam[1].powi(p) * vib[1]);
                }
            }
            prop_assert!((y[k] - truth).abs() < 1e-9 * scale, "k={} y={} truth={}", k, y[k], truth);
        }
    }

    /// The delta-domain model equals its shift-domain counterpart
    /// x[k+1] = (I + Ts A) x + Ts b u + Ts dx, y = c'x + dy (App. D.2), for direct-form A
    /// (complex poles allowed), as a 1-unit network with no delay.
    #[test]
    fn delta_state_space_equals_shift_counterpart(
        a in prop::array::uniform4(-300.0f64..300.0),
        b in prop::array::uniform2(-3.0f64..3.0), c in prop::array::uniform2(-3.0f64..3.0),
        bits in prop::collection::vec(prop::bool::weighted(0.2), 300),
    ) {
        let m = SsLocalModel { a: [[a[0] - 400.0, a[1]], [a[2], a[3] - 400.0]], b, c, dx: [0.0; 2], dy: 0.0 };
        let vf = ValidityFunctions::uniform(1, 0.0, 1.0).unwrap();
        let net = Network::state_space(TS, 0, vf, thesis_scheduler(), &[m]).unwrap();
        let u = pulses(&bits);
        let mut y = vec![0.0; u.len()];
        simulate(&net, &u, &mut y).unwrap();
        let aq = [[1.0 + TS * m.a[0][0], TS * m.a[0][1]], [TS * m.a[1][0], 1.0 + TS * m.a[1][1]]];
        let bq = [TS * b[0], TS * b[1]];
        let mut x = [0.0; 2];
        for k in 0..u.len() {
            let yq = c[0] * x[0] + c[1] * x[1];
            prop_assert!((y[k] - yq).abs() < 1e-12 * (1.0 + yq.abs()), "k={}", k);
            x = [aq[0][0] * x[0] + aq[0][1] * x[1] + bq[0] * u[k], aq[1][0] * x[0] + aq[1][1] * x[1] + bq[1] * u[k]];
        }
    }

    /// arx-delta: the exact delta->shift conversion used for simulation against a direct
    /// delta-domain simulation of the same transfer function: the controllable canonical
    /// delta-domain state space delta xi = A_c xi + e_n v, y = beta' xi + d/alpha_0, with
    /// v_k = u_{k-d+1} (module docs of `arx`), stepped as xi += Ts (A_c xi + e_n v).
    #[test]
    fn arx_delta_conversion_matches_direct_delta_simulation(
        n in 1usize..=3,
        poles in prop::array::uniform3(-400.0f64..-5.0),
        beta in prop::array::uniform3(-2000.0f64..2000.0),
        d_off in -50.0f64..50.0,
        delay in 1usize..10,
        bits in prop::collection::vec(prop::bool::weighted(0.15), 300),
    ) {
        // alpha from real poles: prod (delta - p_i) (so the model is stable).
        let mut alpha = [1.0, 0.0, 0.0, 0.0]; // ascending powers, monic
        for (deg, &p) in poles.iter().take(n).enumerate() {
            let mut next = [0.0; 4];
            for i in 0..=deg { next[i + 1] += alpha[i]; next[i] -= p * alpha[i]; }
            alpha = next;
        }
        let mut unit = ArxUnit::zero();
        unit.a[..n].copy_from_slice(&alpha[..n]);
        unit.b[..n].copy_from_slice(&beta[..n]);
        unit.d = d_off;
        let lmn = Lmn {
            ts: TS, delay, scheduling: SchedulingSpec::default(),
            validity: ValidityFunctions::uniform(1, 0.0, 1.0).unwrap(),
            local: LocalModelSet::ArxDelta { order: n, units: vec![unit] },
            zero_offsets: false, force_scale_n: 1.0, provenance: Provenance::default(),
        };
        let net = lmn.network().unwrap();
        let u = pulses(&bits);
        let mut y = vec![0.0; u.len()];
        simulate(&net, &u, &mut y).unwrap();
        // Direct delta-form simulation.
        let dy = d_off / alpha[0];
        let mut xi = [0.0f64; 3];
        let scale = 1.0 + y.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        for k in 0..u.len() {
            let yd: f64 = (0..n).map(|i| beta[i] * xi[i]).sum::<f64>() + dy;
            prop_assert!((y[k] - yd).abs() < 1e-8 * scale, "n={} k={} shift {} delta {}", n, k, y[k], yd);
            let v = if k + 1 >= delay { u[k + 1 - delay] } else { 0.0 };
            let mut dxi = [0.0; 3];
            dxi[..n - 1].copy_from_slice(&xi[1..n]);
            dxi[n - 1] = v - (0..n).map(|i| alpha[i] * xi[i]).sum::<f64>();
            for i in 0..n { xi[i] += TS * dxi[i]; }
        }
    }
}

/// A random common-eigenvector network (thesis form, eq. 5.6, general V).
fn common_network(
    seed_units: &[UnitParams],
    angles: [f64; 2],
) -> (CommonEigenvectorForm, Network<f64>) {
    let form = CommonEigenvectorForm {
        eigenvector_angles: angles,
        units: seed_units
            .iter()
            .map(|&(e0, e1, b, c, dx, dy)| EigCommonUnit {
                eigenvalues: [e0, e1],
                b,
                c,
                dx,
                dy,
            })
            .collect(),
    };
    let models: Vec<_> = (0..form.units.len())
        .map(|i| form.local_model(i).unwrap())
        .collect();
    let vf = ValidityFunctions::uniform(models.len(), 0.0, 1.0).unwrap();
    let net = Network::state_space(TS, 7, vf, thesis_scheduler(), &models).unwrap();
    (form, net)
}

type UnitParams = (f64, f64, [f64; 2], [f64; 2], [f64; 2], f64);

fn unit_params() -> impl Strategy<Value = UnitParams> {
    (
        -999.0f64..-0.5,
        -999.0f64..-0.5,
        prop::array::uniform2(-5.0f64..5.0),
        prop::array::uniform2(-5.0f64..5.0),
        prop::array::uniform2(-20.0f64..20.0),
        -1.0f64..1.0,
    )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(6))]

    /// Common eigenvectors with every local eigenvalue in (-1/Ts, 0) give a bounded network
    /// under any pulse train (2.4.1). Derived bound: in modal coordinates w = V^-1 x each mode
    /// obeys w_i[k+1] = lambda_i w_i[k] + Ts (beta_i(phi) u + delta_i(phi)) with
    /// lambda_i = 1 + Ts e_i(phi) in (0, lambda_max,i], lambda_max,i = 1 + Ts max_j e_ij < 1
    /// (e_i(phi) is a convex combination of the e_ij), |beta_i(phi)| <= max_j |beta_ij|,
    /// |delta_i(phi)| <= max_j |delta_ij|, u in {0, 1}; so
    /// |w_i[k]| <= W_i = max(|w_i[0]|, g_i / |max_j e_ij|), g_i = max_j|beta_ij| + max_j|delta_ij|,
    /// and |y| <= sum_i max_j |(V' c_j)_i| W_i + max_j |dy_j|. Checked over 10^5 samples.
    #[test]
    fn common_eigenvector_network_stays_bounded(
        units in prop::collection::vec(unit_params(), 2..=10),
        th0 in 0.0f64..3.1, dth in 0.2f64..2.9,
        p_pulse in 0.02f64..0.5,
        seed in any::<u64>(),
    ) {
        let angles = [th0, th0 + dth];
        let (form, net) = common_network(&units, angles);
        let v = eigenvector_matrix(angles);
        let vi = inverse2(&v).unwrap();
        let vt = [[v[0][0], v[1][0]], [v[0][1], v[1][1]]];
        let mut w_bound = [0.0f64; 2];
        let st0 = net.rest_state().unwrap();
        let w0 = mat_vec2(&vi, st0.ss_state());
        let mut y_bound = 0.0;
        for i in 0..2 {
            let e_max = form.units.iter().map(|u| u.eigenvalues[i]).fold(f64::MIN, f64::max);
            let bmax = form.units.iter().map(|u| mat_vec2(&vi, u.b)[i].abs()).fold(0.0, f64::max);
            let dmax = form.units.iter().map(|u| mat_vec2(&vi, u.dx)[i].abs()).fold(0.0, f64::max);
            w_bound[i] = w0[i].abs().max((bmax + dmax) / e_max.abs());
            let cmax = form.units.iter().map(|u| mat_vec2(&vt, u.c)[i].abs()).fold(0.0, f64::max);
            y_bound += cmax * w_bound[i];
        }
        y_bound += form.units.iter().map(|u| u.dy.abs()).fold(0.0, f64::max);
        // Random pulse train (xorshift, seeded by proptest).
        let mut s = seed | 1;
        let mut form_t = fes_model::model::ThesisForm::new(net).unwrap();
        for k in 0..100_000 {
            s ^= s << 13; s ^= s >> 7; s ^= s << 17;
            let r = (s >> 11) as f64 / (1u64 << 53) as f64;
            let u = if r < p_pulse { 1.0 } else { 0.0 };
            let y = form_t.step(u);
            let w = mat_vec2(&vi, form_t.state().ss_state());
            for i in 0..2 {
                prop_assert!(w[i].abs() <= w_bound[i] * (1.0 + 1e-9) + 1e-12, "k={} mode {}: {} > {}", k, i, w[i], w_bound[i]);
            }
            prop_assert!(y.abs() <= y_bound * (1.0 + 1e-9) + 1e-12, "k={}: |y| = {} > {}", k, y.abs(), y_bound);
        }
    }
}

/// Gauge fixing (V = I, b_r = (1, 1)) does not change the output.
#[test]
fn gauge_fixed_common_eigenvectors_give_identical_output() {
    let units: Vec<UnitParams> = vec![
        (-250.0, -30.0, [1.0, 2.0], [0.02, -0.01], [0.5, 0.1], 0.0),
        (-90.0, -8.0, [2.0, 0.5], [0.03, 0.01], [1.0, 0.0], 0.01),
        (-220.0, -2.0, [1.5, -0.7], [0.01, -0.02], [0.0, 0.2], -0.01),
        (-128.0, -29.0, [-1.0, 1.2], [0.02, 0.04], [0.3, 0.3], 0.0),
    ];
    let (form, net) = common_network(&units, [0.4, 1.7]);
    let fixed = form.to_gauge_fixed(1).unwrap();
    assert_eq!(fixed[1].b, [1.0, 1.0]);
    let lmn = Lmn {
        ts: TS,
        delay: 7,
        scheduling: SchedulingSpec::default(),
        validity: ValidityFunctions::uniform(4, 0.0, 1.0).unwrap(),
        local: LocalModelSet::SsEigCommon {
            units: fixed,
            reference_unit: 1,
        },
        zero_offsets: false,
        force_scale_n: 1.0,
        provenance: Provenance::default(),
    };
    let net2 = lmn.network().unwrap();
    let u: Vec<f64> = (0..3000)
        .map(|k| if (k * 7919) % 97 < 9 { 1.0 } else { 0.0 })
        .collect();
    let (mut y1, mut y2) = (vec![0.0; u.len()], vec![0.0; u.len()]);
    simulate(&net, &u, &mut y1).unwrap();
    simulate(&net2, &u, &mut y2).unwrap();
    let scale = y1.iter().fold(0.0f64, |a, x| a.max(x.abs()));
    assert!(scale > 1e-3);
    for k in 0..u.len() {
        assert!(
            (y1[k] - y2[k]).abs() < 1e-10 * scale,
            "k={k}: {} vs {}",
            y1[k],
            y2[k]
        );
    }
    assert!(form.to_gauge_fixed(9).is_err());
}

/// With no pulses, a network started at rest stays there (SS and ARX, input and output
/// scheduling, with offsets).
#[test]
fn rest_state_is_an_equilibrium() {
    let units: Vec<UnitParams> = vec![
        (-250.0, -30.0, [1.0, 2.0], [0.02, -0.01], [0.5, 0.1], 0.05),
        (-90.0, -8.0, [2.0, 0.5], [0.03, 0.01], [1.0, -3.0], 0.01),
        (-220.0, -2.0, [1.5, -0.7], [0.01, -0.02], [0.0, 0.2], 0.3),
    ];
    let (form, _) = common_network(&units, [0.4, 1.7]);
    let models: Vec<_> = (0..3).map(|i| form.local_model(i).unwrap()).collect();
    for sched in [SchedulingSpec::default(), SchedulingSpec::Output] {
        let vf = ValidityFunctions::uniform(3, 0.0, 1.0).unwrap();
        let net =
            Network::state_space(TS, 7, vf, Scheduler::new(&sched, TS).unwrap(), &models).unwrap();
        let mut y = vec![0.0; 2000];
        simulate(&net, &vec![0.0; 2000], &mut y).unwrap();
        for k in 1..y.len() {
            assert!(
                (y[k] - y[0]).abs() < 1e-9,
                "{sched:?} k={k}: {} vs {}",
                y[k],
                y[0]
            );
        }
        if sched == SchedulingSpec::Output {
            // Fixed point: phi0 = y0.
            let st = net.rest_state().unwrap();
            assert!((st.phi - y[0]).abs() < 1e-9);
        }
    }
    let arx = [
        ArxUnit {
            a: [-1.9, 0.905, 0.0],
            b: [0.01, 0.002, 0.0],
            d: 0.001,
        },
        ArxUnit {
            a: [-1.8, 0.82, 0.0],
            b: [0.02, 0.001, 0.0],
            d: 0.004,
        },
    ];
    for sched in [SchedulingSpec::default(), SchedulingSpec::Output] {
        let vf = ValidityFunctions::uniform(2, 0.0, 1.0).unwrap();
        let net = Network::arx(TS, 7, vf, Scheduler::new(&sched, TS).unwrap(), 2, &arx).unwrap();
        let mut y = vec![0.0; 500];
        simulate(&net, &vec![0.0; 500], &mut y).unwrap();
        for k in 1..y.len() {
            assert!((y[k] - y[0]).abs() < 1e-9, "ARX {sched:?} k={k}");
        }
    }
}

/// One-step prediction of a 1-unit shift ARX against the ARX equation written out (A.35).
#[test]
fn prediction_uses_measured_outputs() {
    let unit = ArxUnit {
        a: [-1.7, 0.72, 0.0],
        b: [0.05, 0.01, 0.0],
        d: 0.002,
    };
    let vf = ValidityFunctions::uniform(1, 0.0, 1.0).unwrap();
    let d = 3;
    let net = Network::arx(
        5e-3,
        d,
        vf,
        Scheduler::new(&SchedulingSpec::default(), 5e-3).unwrap(),
        2,
        &[unit],
    )
    .unwrap();
    let u: Vec<f64> = (0..200)
        .map(|k| if k % 9 == 0 { 1.0 } else { 0.0 })
        .collect();
    let y: Vec<f64> = (0..200)
        .map(|k| (k as f64 * 0.05).sin() * 0.3 + 0.3)
        .collect();
    let mut yhat = vec![0.0; 200];
    predict(&net, &u, &y, &mut yhat).unwrap();
    let at = |v: &[f64], k: isize, before: f64| if k < 0 { before } else { v[k as usize] };
    for k in 0..200isize {
        let truth = 0.05 * at(&u, k - d as isize, 0.0)
            + 0.01 * at(&u, k - d as isize - 1, 0.0)
            + 1.7 * at(&y, k - 1, y[0])
            - 0.72 * at(&y, k - 2, y[0])
            + 0.002;
        assert!((yhat[k as usize] - truth).abs() < 1e-12, "k={k}");
    }
    // State-space networks have no one-step prediction.
    let ss = Network::state_space(
        TS,
        0,
        ValidityFunctions::uniform(1, 0.0, 1.0).unwrap(),
        thesis_scheduler(),
        &[SsLocalModel::zero()],
    )
    .unwrap();
    assert!(predict(&ss, &u, &y, &mut yhat).is_err());
    // MSE (eq. B.8) by hand.
    let e = mse(&[1.0, 2.0, 3.0], &[1.5, 2.0, 2.0]).unwrap();
    assert!((e - (0.25 + 1.0) / 3.0).abs() < 1e-15);
    assert!(mse(&[1.0], &[1.0, 2.0]).is_err());
}

/// Exact sensitivities: the same network step in Dual<4>, seeded on an eigenvalue, an input
/// gain, a state offset and a knot, against central finite differences of the f64 MSSE and
/// of individual outputs; input and output scheduling.
#[test]
fn dual_sensitivities_match_finite_differences() {
    let base: Vec<EigCommonUnit<f64>> = vec![
        EigCommonUnit {
            eigenvalues: [-250.0, -30.0],
            b: [1.0, 1.0],
            c: [0.02, -0.01],
            dx: [0.5, 0.1],
            dy: 0.0,
        },
        EigCommonUnit {
            eigenvalues: [-90.0, -8.0],
            b: [2.0, 0.5],
            c: [0.03, 0.01],
            dx: [1.0, 0.0],
            dy: 0.01,
        },
        EigCommonUnit {
            eigenvalues: [-220.0, -12.0],
            b: [1.5, 0.7],
            c: [0.01, 0.02],
            dx: [0.0, 0.2],
            dy: 0.0,
        },
        EigCommonUnit {
            eigenvalues: [-128.0, -29.0],
            b: [1.0, 1.2],
            c: [0.02, 0.04],
            dx: [0.3, 0.3],
            dy: 0.0,
        },
    ];
    let knots0 = ValidityFunctions::uniform(4, 0.0, 1.0)
        .unwrap()
        .knots()
        .to_vec();
    let u: Vec<f64> = (0..600)
        .map(|k| {
            if (k * 31) % 53 < 5 || (k > 300 && k % 11 == 0) {
                1.0
            } else {
                0.0
            }
        })
        .collect();
    let y_meas: Vec<f64> = (0..600)
        .map(|k| 0.4 * (1.0 - (-(k as f64) / 80.0).exp()))
        .collect();

    // Parameter vector p: [e_{1,1}, b_{2,0}, dx_{0,1}, knot 3].
    fn build<S: Scalar>(
        base: &[EigCommonUnit<f64>],
        knots0: &[f64],
        p: [S; 4],
        sched: &SchedulingSpec,
    ) -> Network<S> {
        let units: Vec<_> = base
            .iter()
            .enumerate()
            .map(|(i, u)| {
                let c = |x: f64| S::from_f64(x);
                let mut m = EigCommonUnit {
                    eigenvalues: u.eigenvalues.map(c),
                    b: u.b.map(c),
                    c: u.c.map(|x| c(50.0 * x)),
                    dx: u.dx.map(c),
                    dy: c(u.dy),
                };
                if i == 1 {
                    m.eigenvalues[1] = p[0];
                }
                if i == 2 {
                    m.b[0] = p[1];
                }
                if i == 0 {
                    m.dx[1] = p[2];
                }
                m.to_local_model()
            })
            .collect();
        let mut knots: Vec<S> = knots0.iter().map(|&k| S::from_f64(k)).collect();
        knots[3] = p[3];
        let vf = ValidityFunctions::from_knots(&knots, 3).unwrap();
        Network::state_space(TS, 7, vf, Scheduler::new(sched, TS).unwrap(), &units).unwrap()
    }
    let p0 = [-8.0, 1.5, 0.1, 1.0 / 3.0];
    for sched in [SchedulingSpec::default(), SchedulingSpec::Output] {
        let pd: [Dual<4>; 4] = core::array::from_fn(|j| Dual::variable(p0[j], j));
        let net_d = build(&base, &knots0, pd, &sched);
        let mut yd = vec![Dual::<4>::constant(0.0); u.len()];
        simulate(&net_d, &u, &mut yd).unwrap();
        let jd = mse(&y_meas, &yd).unwrap();
        let f = |p: [f64; 4]| {
            let net = build(&base, &knots0, p, &sched);
            let mut y = vec![0.0; u.len()];
            simulate(&net, &u, &mut y).unwrap();
            (mse(&y_meas, &y).unwrap(), y)
        };
        let (j0, y0) = f(p0);
        assert!((jd.v - j0).abs() < 1e-15 * (1.0 + j0));
        for (k, (a, b)) in yd.iter().zip(&y0).enumerate() {
            assert!((a.v - b).abs() < 1e-14, "value k={k}");
        }
        for j in 0..4 {
            let h = 1e-4 * p0[j].abs().max(1e-2);
            let mut pp = p0;
            pp[j] += h;
            let mut pm = p0;
            pm[j] -= h;
            let ((jp, yp), (jm, ym)) = (f(pp), f(pm));
            let fd = (jp - jm) / (2.0 * h);
            // FD error: truncation (relative) plus rounding ~ eps |J| / h.
            let noise = 1e3 * f64::EPSILON * j0.abs() / h;
            assert!(
                (jd.d[j] - fd).abs() < 1e-4 * jd.d[j].abs() + noise,
                "{sched:?} dJ/dp{j}: {} vs fd {fd}",
                jd.d[j]
            );
            let ymax = yd.iter().map(|y| y.d[j].abs()).fold(0.0, f64::max);
            for k in (0..u.len()).step_by(37) {
                let fdk = (yp[k] - ym[k]) / (2.0 * h);
                assert!(
                    (yd[k].d[j] - fdk).abs()
                        < 1e-4 * ymax + 1e3 * f64::EPSILON * y0[k].abs().max(1.0) / h,
                    "{sched:?} dy[{k}]/dp{j}: {} vs {fdk}",
                    yd[k].d[j]
                );
            }
        }
    }
}
