//! Exact (dual-number) Jacobians of the identification problem against central finite
//! differences, relative 1e-6, for every structure, every scheduling class (input scheduling
//! of the delayed and the undelayed input, eq. 5.2; output scheduling), both horizons,
//! a down-sampled model period, and the interior knots.
#![allow(clippy::needless_range_loop)] // index loops mirror the matrices
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use fes_ident::ident::knots::KnotMap;
use fes_ident::ident::problem::{Horizon, ModelData, ParamMap, Problem, ThetaMap};
use fes_ident::ident::records::IdentRecord;
use fes_model::model::arx::ArxUnit;
use fes_model::model::lmn::{Lmn, LocalModelSet, Provenance};
use fes_model::model::local_model::{EigCommonUnit, EigLocalUnit, SsLocalModel};
use fes_model::model::params::ParamLayout;
use fes_model::model::scheduling::{SchedulingInput, SchedulingSpec};
use fes_model::model::validity::ValidityFunctions;
use nalgebra::DMatrix;

/// Two records of pulse trains (bursts at varying rates) and a smooth measured output.
fn records() -> Vec<IdentRecord> {
    (0..2)
        .map(|r| {
            let n = 400;
            let u: Vec<f64> = (0..n)
                .map(|k| {
                    let ipi = 6 + (k / 60 + r) % 5 * 7;
                    if (20..320).contains(&k) && k % ipi == 0 {
                        1.0
                    } else {
                        0.0
                    }
                })
                .collect();
            let y: Vec<f64> = (0..n)
                .map(|k| {
                    0.3 * (1.0 - (-(k as f64) / 80.0).exp()) * (1.0 + 0.2 * (k as f64 / 30.0).sin())
                })
                .collect();
            IdentRecord::new(format!("r{r}"), u, y).expect("valid record")
        })
        .collect()
}

fn lmn(
    local: LocalModelSet,
    m: usize,
    zero_offsets: bool,
    scheduling: SchedulingSpec,
    ts: f64,
    delay: usize,
) -> Lmn {
    Lmn {
        ts,
        delay,
        scheduling,
        validity: ValidityFunctions::uniform(m, 0.0, 1.0).expect("uniform"),
        local,
        zero_offsets,
        force_scale_n: 1.0,
        provenance: Provenance::default(),
    }
}

/// One model of every structure (3 units), stable, with offsets.
fn models(scheduling: SchedulingSpec) -> Vec<Lmn> {
    let ts = 1e-3;
    let common: Vec<EigCommonUnit> = (0..4)
        .map(|i| {
            let f = i as f64;
            EigCommonUnit {
                eigenvalues: [-180.0 + 30.0 * f, -25.0 + 4.0 * f],
                b: if i == 1 {
                    [1.0, 1.0]
                } else {
                    [1.3 - 0.2 * f, 0.7 + 0.1 * f]
                },
                c: [40.0 + 5.0 * f, -38.0],
                dx: [0.02 * f, -0.01],
                dy: 0.003 * f,
            }
        })
        .collect();
    let mut common_zero = common.clone();
    for u in &mut common_zero {
        u.dx = [0.0; 2];
        u.dy = 0.0;
    }
    let local: Vec<EigLocalUnit> = common
        .iter()
        .enumerate()
        .map(|(i, u)| EigLocalUnit {
            eigenvalues: u.eigenvalues,
            eigenvector_angles: [0.3 + 0.1 * i as f64, 1.9 - 0.05 * i as f64],
            b: u.b,
            c: u.c,
            dx: u.dx,
            dy: u.dy,
        })
        .collect();
    let direct: Vec<SsLocalModel> = local
        .iter()
        .map(|u| u.to_local_model().expect("angles"))
        .collect();
    let arx: Vec<ArxUnit> = (0..4)
        .map(|i| ArxUnit {
            a: [-1.90 + 0.02 * i as f64, 0.905 - 0.02 * i as f64, 0.0],
            b: [0.010, 0.002 * i as f64, 0.0],
            // Non-zero for every unit: with output scheduling the rest state is then an
            // interior fixed point (at d = 0 it sits on the clamped range edge, a kink).
            d: 0.0005 * (i + 1) as f64,
        })
        .collect();
    let arx_delta: Vec<ArxUnit> = (0..4)
        .map(|i| ArxUnit {
            a: [2500.0 - 300.0 * i as f64, 100.0 + 10.0 * i as f64, 0.0],
            b: [25.0, 0.1 * i as f64, 0.0],
            d: 0.2 * (i + 1) as f64,
        })
        .collect();
    let s = scheduling;
    vec![
        lmn(LocalModelSet::SsDirect(direct), 4, false, s, ts, 7),
        lmn(LocalModelSet::SsEigLocal(local), 4, false, s, ts, 7),
        lmn(
            LocalModelSet::SsEigCommon {
                units: common,
                reference_unit: 1,
            },
            4,
            false,
            s,
            ts,
            7,
        ),
        lmn(
            LocalModelSet::SsEigCommon {
                units: common_zero,
                reference_unit: 1,
            },
            4,
            true,
            s,
            ts,
            7,
        ),
        lmn(
            LocalModelSet::ArxShift {
                order: 2,
                units: arx,
            },
            4,
            false,
            s,
            ts,
            7,
        ),
        lmn(
            LocalModelSet::ArxDelta {
                order: 2,
                units: arx_delta,
            },
            4,
            false,
            s,
            ts,
            7,
        ),
    ]
}

/// Central differences of the residual vector with one Richardson step,
/// (4 D(h/2) - D(h)) / 3 (truncation error O(h^4)). Step h_i = 1e-5 max(|p_i|, s_i) with
/// s_i = 1e-2 |r| / |J_i| (the change of p_i that moves the residuals by 1 % of their norm;
/// |J_i| from the column being checked, used only to size the step): rounding error about
/// 1e-16 |r| / h_i stays far below 1e-6 |J_i| for parameters that enter with tiny gains
/// (e.g. the delta-form offset, multiplied by Ts^2).
fn fd_jacobian<M: ParamMap>(problem: &Problem<'_, M>, p: &[f64], col_norm: &[f64]) -> DMatrix<f64> {
    let r0 = problem.residuals(p).expect("residuals");
    let rn = r0.iter().map(|v| v * v).sum::<f64>().sqrt();
    let central = |i: usize, h: f64| {
        let mut pp = p.to_vec();
        pp[i] += h;
        let mut pm = p.to_vec();
        pm[i] -= h;
        let rp = problem.residuals(&pp).expect("residuals +h");
        let rm = problem.residuals(&pm).expect("residuals -h");
        (0..r0.len())
            .map(|k| (rp[k] - rm[k]) / (2.0 * h))
            .collect::<Vec<f64>>()
    };
    let mut j = DMatrix::zeros(r0.len(), p.len());
    for i in 0..p.len() {
        let s_i = if col_norm[i] > 0.0 {
            1e-2 * rn / col_norm[i]
        } else {
            1.0
        };
        let h = 1e-5 * p[i].abs().max(s_i);
        let (d1, d2) = (central(i, h), central(i, h / 2.0));
        for k in 0..r0.len() {
            j[(k, i)] = (4.0 * d2[k] - d1[k]) / 3.0;
        }
    }
    j
}

/// Every column: ||J_dual - J_fd|| <= 1e-6 ||J_dual|| (plus a floor for columns that are
/// zero up to rounding).
fn check<M: ParamMap>(what: &str, problem: &Problem<'_, M>, p: &[f64], names: &[String]) {
    let cols: Vec<usize> = (0..p.len()).collect();
    let (r, jd) = problem.jacobian(p, &cols).expect("dual jacobian");
    let r0 = problem.residuals(p).expect("residuals");
    assert_eq!(r.len(), r0.len());
    for k in 0..r0.len() {
        assert!(
            (r[k] - r0[k]).abs() <= 1e-12 * (1.0 + r0[k].abs()),
            "{what}: residual {k}"
        );
    }
    let norms: Vec<f64> = (0..p.len()).map(|i| jd.column(i).norm()).collect();
    let jf = fd_jacobian(problem, p, &norms);
    let scale = jd.norm();
    for i in 0..p.len() {
        let d = (jd.column(i) - jf.column(i)).norm();
        let n = jd.column(i).norm();
        assert!(
            d <= 1e-6 * n + 1e-9 * scale,
            "{what}: column {} ({}): |dual - fd| = {d:.3e}, |dual| = {n:.3e}",
            i,
            names.get(i).map_or("?", |s| s.as_str())
        );
    }
    // The normal equations agree with the stacked Jacobian.
    let nrm = problem.normal(p, &cols).expect("normal");
    let h = jd.transpose() * &jd;
    assert!(
        (&nrm.h - &h).norm() <= 1e-10 * (1.0 + nrm.h.norm()),
        "{what}: J'J"
    );
}

#[test]
fn dual_jacobian_matches_finite_differences_for_every_structure() {
    let recs = records();
    for (sched_name, sched) in [
        ("input", SchedulingSpec::default()),
        (
            "input undelayed",
            SchedulingSpec::Input {
                gain: 25_000.0,
                natural_frequency_rad_s: 50.0,
                damping: 1.0,
                scheduling_input: SchedulingInput::Undelayed,
            },
        ),
        ("output", SchedulingSpec::Output),
    ] {
        let data = ModelData::new(&recs, 1).expect("factor 1");
        for m in models(sched) {
            let layout = ParamLayout::new(&m);
            let theta = layout.theta(&m).expect("theta");
            let horizons: &[Horizon] = if m.structure().is_state_space() {
                &[Horizon::Simulation]
            } else {
                &[Horizon::Simulation, Horizon::Prediction]
            };
            for &h in horizons {
                let problem = Problem::new(
                    ThetaMap {
                        template: &m,
                        layout: &layout,
                    },
                    &data,
                    h,
                );
                let what = format!(
                    "{} {}{} {:?}",
                    m.structure(),
                    sched_name,
                    if m.zero_offsets { " zero offsets" } else { "" },
                    h
                );
                check(&what, &problem, &theta, layout.names());
            }
        }
    }
}

/// A shift model at 5 ms: down-sampled input, output interpolated to 1 ms (linear in the
/// model output, so the dual path carries it exactly).
#[test]
fn dual_jacobian_through_down_sampling_and_interpolation() {
    let recs = records();
    let data = ModelData::new(&recs, 5).expect("factor 5");
    let m = models(SchedulingSpec::Input {
        gain: 5000.0,
        natural_frequency_rad_s: 50.0,
        damping: 1.0,
        scheduling_input: SchedulingInput::Undelayed,
    })
    .remove(4);
    let m = Lmn {
        ts: 5e-3,
        delay: 2,
        ..m
    };
    let layout = ParamLayout::new(&m);
    let theta = layout.theta(&m).expect("theta");
    for h in [Horizon::Simulation, Horizon::Prediction] {
        let problem = Problem::new(
            ThetaMap {
                template: &m,
                layout: &layout,
            },
            &data,
            h,
        );
        check(
            &format!("arx-shift 5 ms {h:?}"),
            &problem,
            &theta,
            layout.names(),
        );
    }
}

/// The interior knots (softmax gaps) of a 6-unit network: derivatives through the B-spline
/// recursion and the network step.
#[test]
fn knot_jacobian_matches_finite_differences() {
    let recs = records();
    let data = ModelData::new(&recs, 1).expect("factor 1");
    for sched in [SchedulingSpec::default(), SchedulingSpec::Output] {
        let mut m = models(sched).remove(2);
        // 6 units, non-uniform interior knots.
        let LocalModelSet::SsEigCommon { units, .. } = &m.local else {
            unreachable!()
        };
        let mut six = units.clone();
        six.extend_from_slice(&units[..2]);
        m.local = LocalModelSet::SsEigCommon {
            units: six,
            reference_unit: 1,
        };
        m.validity =
            ValidityFunctions::from_knots(&[0.0, 0.0, 0.0, 0.2, 0.45, 0.6, 1.0, 1.0, 1.0], 3)
                .expect("knots");
        let layout = ParamLayout::new(&m);
        let theta = layout.theta(&m).expect("theta");
        let map = KnotMap {
            template: &m,
            layout: &layout,
            theta: &theta,
        };
        let s = map.params().expect("distinct knots");
        assert_eq!(s.len(), 3);
        // The parameterisation reproduces the knots.
        for (a, b) in map.knots(&s).iter().zip(m.validity.knots()) {
            assert!((a - b).abs() < 1e-14);
        }
        let problem = Problem::new(map, &data, Horizon::Simulation);
        check("knots", &problem, &s, &[]);
    }
}
