//! The flat parameter vector theta (identification): round trips for every structure, and the
//! Dual Jacobian of the free-run MSSE through the parameterisation maps against central
//! finite differences.
#![allow(clippy::needless_range_loop)] // index loops mirror the equations
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use fes_model::model::arx::ArxUnit;
use fes_model::model::lmn::{Lmn, LocalModelSet, Provenance};
use fes_model::model::local_model::{EigCommonUnit, EigLocalUnit, SsLocalModel};
use fes_model::model::params::ParamLayout;
use fes_model::model::scheduling::SchedulingSpec;
use fes_model::model::simulate::{mse, simulate};
use fes_model::model::validity::ValidityFunctions;
use fes_model::num::Dual;

const TS: f64 = 1e-3;

fn lmn(local: LocalModelSet, m: usize, zero_offsets: bool) -> Lmn {
    Lmn {
        ts: TS,
        delay: 7,
        scheduling: SchedulingSpec::default(),
        validity: ValidityFunctions::uniform(m, 0.0, 1.0).unwrap(),
        local,
        zero_offsets,
        force_scale_n: 1.0,
        provenance: Provenance::default(),
    }
}

fn models() -> Vec<Lmn> {
    let common: Vec<_> = [[-250.0, -30.0], [-90.0, -8.0], [-220.0, -1.0]]
        .iter()
        .enumerate()
        .map(|(i, e)| EigCommonUnit {
            eigenvalues: *e,
            b: if i == 1 {
                [1.0, 1.0]
            } else {
                [2.0, 0.5 + i as f64]
            },
            c: [2.0, -1.0],
            dx: [0.5 * i as f64, 0.1],
            dy: 0.01,
        })
        .collect();
    let mut common_zero = common.clone();
    for u in &mut common_zero {
        u.dx = [0.0; 2];
        u.dy = 0.0;
    }
    let local: Vec<_> = common
        .iter()
        .enumerate()
        .map(|(i, u)| EigLocalUnit {
            eigenvalues: u.eigenvalues,
            eigenvector_angles: [0.2 + 0.2 * i as f64, 1.8],
            b: u.b,
            c: u.c,
            dx: u.dx,
            dy: u.dy,
        })
        .collect();
    let direct: Vec<_> = local
        .iter()
        .map(|u| u.to_local_model().unwrap())
        .collect::<Vec<SsLocalModel>>();
    let arx = vec![
        ArxUnit {
            a: [-1.90, 0.9025, 0.0],
            b: [0.010, 0.002, 0.0],
            d: 0.001,
        },
        ArxUnit {
            a: [-1.80, 0.8200, 0.0],
            b: [0.020, 0.001, 0.0],
            d: 0.0,
        },
        ArxUnit {
            a: [-1.85, 0.8600, 0.0],
            b: [0.015, 0.004, 0.0],
            d: -0.001,
        },
    ];
    let arx_delta = vec![
        ArxUnit {
            a: [2500.0, 100.0, 0.0],
            b: [25.0, 0.1, 0.0],
            d: 0.5,
        },
        ArxUnit {
            a: [900.0, 80.0, 0.0],
            b: [20.0, 0.0, 0.0],
            d: 0.0,
        },
        ArxUnit {
            a: [1600.0, 90.0, 0.0],
            b: [30.0, 0.2, 0.0],
            d: 0.1,
        },
    ];
    vec![
        lmn(LocalModelSet::SsDirect(direct), 3, false),
        lmn(LocalModelSet::SsEigLocal(local), 3, false),
        lmn(
            LocalModelSet::SsEigCommon {
                units: common,
                reference_unit: 1,
            },
            3,
            false,
        ),
        lmn(
            LocalModelSet::SsEigCommon {
                units: common_zero,
                reference_unit: 1,
            },
            3,
            true,
        ),
        lmn(
            LocalModelSet::ArxShift {
                order: 2,
                units: arx,
            },
            3,
            false,
        ),
        lmn(
            LocalModelSet::ArxDelta {
                order: 2,
                units: arx_delta,
            },
            3,
            false,
        ),
    ]
}

fn record() -> (Vec<f64>, Vec<f64>) {
    let u: Vec<f64> = (0..500)
        .map(|k| if (k * 13) % 41 < 4 { 1.0 } else { 0.0 })
        .collect();
    let y: Vec<f64> = (0..500)
        .map(|k| 0.3 * (1.0 - (-(k as f64) / 60.0).exp()))
        .collect();
    (u, y)
}

/// theta(model) -> apply -> same model (eigenvalues through eta to 1e-12 relative) and
/// network(theta) simulates exactly like model.network().
#[test]
fn theta_round_trips_for_every_structure() {
    let (u, _) = record();
    for m in models() {
        let layout = ParamLayout::new(&m);
        let theta = layout.theta(&m).unwrap();
        assert_eq!(theta.len(), layout.len(), "{}", m.structure());
        assert_eq!(layout.names().len(), theta.len());
        let back = layout.apply(&m, &theta).unwrap();
        assert_eq!(layout.theta(&back).unwrap().len(), theta.len());
        let (mut y1, mut y2, mut y3) = (vec![0.0; u.len()], vec![0.0; u.len()], vec![0.0; u.len()]);
        simulate(&m.network().unwrap(), &u, &mut y1).unwrap();
        simulate(&back.network().unwrap(), &u, &mut y2).unwrap();
        simulate(
            &layout.network::<f64>(&m, &theta, None).unwrap(),
            &u,
            &mut y3,
        )
        .unwrap();
        let scale = y1.iter().fold(1e-12f64, |a, x| a.max(x.abs()));
        for k in 0..u.len() {
            assert!(
                (y1[k] - y2[k]).abs() < 1e-9 * scale,
                "{} k={k}",
                m.structure()
            );
            assert!(
                (y1[k] - y3[k]).abs() < 1e-9 * scale,
                "{} k={k}",
                m.structure()
            );
        }
    }
    // Parameter counts: 11 per direct unit (thesis 5.4.2 footnote 4), 5 per ARX unit of order 2.
    let ms = models();
    assert_eq!(ParamLayout::new(&ms[0]).len(), 33);
    assert_eq!(ParamLayout::new(&ms[2]).len(), 3 * 9 - 2);
    assert_eq!(ParamLayout::new(&ms[3]).len(), 3 * 6 - 2);
    assert_eq!(ParamLayout::new(&ms[4]).len(), 15);
    assert!(
        ParamLayout::new(&ms[0])
            .network::<f64>(&ms[0], &[0.0; 3], None)
            .is_err()
    );
}

/// dMSSE/dtheta (exact, Dual seeded 8 parameters at a time) against central differences for
/// every structure (knot derivatives through the network: `model_network.rs`).
#[test]
fn msse_jacobian_matches_finite_differences() {
    let (u, y) = record();
    for m in models() {
        let layout = ParamLayout::new(&m);
        let theta = layout.theta(&m).unwrap();
        let j_of = |t: &[f64]| {
            let net = layout.network::<f64>(&m, t, None).unwrap();
            let mut yh = vec![0.0; u.len()];
            simulate(&net, &u, &mut yh).unwrap();
            mse(&y, &yh).unwrap()
        };
        let j0 = j_of(&theta);
        for chunk in (0..theta.len()).collect::<Vec<_>>().chunks(8) {
            let td: Vec<Dual<8>> = theta
                .iter()
                .enumerate()
                .map(|(i, &v)| match chunk.iter().position(|&c| c == i) {
                    Some(j) => Dual::variable(v, j),
                    None => Dual::constant(v),
                })
                .collect();
            let net = layout.network(&m, &td, None).unwrap();
            let mut yh = vec![Dual::constant(0.0); u.len()];
            simulate(&net, &u, &mut yh).unwrap();
            let jd = mse(&y, &yh).unwrap();
            assert!((jd.v - j0).abs() <= 1e-14 * j0.abs().max(1e-300));
            for (j, &i) in chunk.iter().enumerate() {
                let h = 1e-7 * theta[i].abs().max(1e-3);
                let mut tp = theta.clone();
                tp[i] += h;
                let mut tm = theta.clone();
                tm[i] -= h;
                let fd = (j_of(&tp) - j_of(&tm)) / (2.0 * h);
                let noise = 1e3 * f64::EPSILON * j0.abs() / h;
                assert!(
                    (jd.d[j] - fd).abs() < 1e-4 * jd.d[j].abs() + noise,
                    "{} {}: {} vs fd {fd}",
                    m.structure(),
                    layout.names()[i],
                    jd.d[j]
                );
            }
        }
    }
}
