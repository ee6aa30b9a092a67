//! Static analysis (thesis 2.4.2, 5.4.3) against independent truths: simulated pulse-response
//! sums, simulated steady states, eigenvalues by construction, and the common-eigenvector test.
#![allow(clippy::needless_range_loop)] // index loops mirror the equations
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use fes_ident::analysis::static_analysis::{
    FrozenModel, analyse, analyse_at, common_eigenvectors, phi_grid,
};
use fes_model::model::arx::ArxUnit;
use fes_model::model::lmn::{Lmn, LocalModelSet, Provenance};
use fes_model::model::local_model::{
    EigCommonUnit, EigLocalUnit, a_from_eigensystem, eigenvector_matrix,
};
use fes_model::model::network::Network;
use fes_model::model::scheduling::{Scheduler, SchedulingSpec};
use fes_model::model::simulate::simulate;
use fes_model::model::validity::ValidityFunctions;

const TS: f64 = 1e-3;

fn lmn(local: LocalModelSet, m: usize) -> Lmn {
    Lmn {
        ts: TS,
        delay: 7,
        scheduling: SchedulingSpec::default(),
        validity: ValidityFunctions::uniform(m, 0.0, 1.0).unwrap(),
        local,
        zero_offsets: false,
        force_scale_n: 1.0,
        provenance: Provenance::default(),
    }
}

/// A network whose units are all the frozen model at phi (so simulation is LTI).
fn frozen_network(m: &FrozenModel) -> Network<f64> {
    let vf = ValidityFunctions::uniform(1, 0.0, 1.0).unwrap();
    let s = Scheduler::new(&SchedulingSpec::default(), TS).unwrap();
    match m {
        FrozenModel::StateSpace(x) => Network::state_space(TS, 0, vf, s, &[*x]).unwrap(),
        FrozenModel::Arx { order, model } => Network::arx(TS, 0, vf, s, *order, &[*model]).unwrap(),
    }
}

/// Gain = sum of the pulse response (thesis 5.4.3: FTI per pulse = G Ts), offset = the
/// output at rest, for the frozen model at several phi; state space and ARX.
#[test]
fn gain_and_offset_match_simulation_of_the_frozen_model() {
    let ss = lmn(
        LocalModelSet::SsEigLocal(
            [
                [-256.27, -33.24],
                [-87.07, -7.71],
                [-220.68, -12.0],
                [-128.48, -29.61],
            ]
            .iter()
            .enumerate()
            .map(|(i, e)| EigLocalUnit {
                eigenvalues: *e,
                eigenvector_angles: [0.2 + 0.3 * i as f64, 1.6 + 0.1 * i as f64],
                b: [1.0, 0.5],
                c: [0.02, 0.01 * i as f64],
                dx: [0.1 * i as f64, -0.02],
                dy: 0.001,
            })
            .collect(),
        ),
        4,
    );
    let arx = lmn(
        LocalModelSet::ArxShift {
            order: 2,
            units: vec![
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
            ],
        },
        3,
    );
    for model in [ss, arx] {
        let net = model.network().unwrap();
        for phi in [0.0, 0.13, 0.5, 0.77, 1.0] {
            let p = analyse_at(&net, phi);
            assert!((p.activations.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            let frozen = frozen_network(&p.model);
            let n = 40_000;
            let mut rest = vec![0.0; n];
            simulate(&frozen, &vec![0.0; n], &mut rest).unwrap();
            let mut u = vec![0.0; n];
            u[0] = 1.0;
            let mut y = vec![0.0; n];
            simulate(&frozen, &u, &mut y).unwrap();
            let sum: f64 = y.iter().zip(&rest).map(|(a, b)| a - b).sum();
            let g = p.gain.unwrap();
            assert!(
                (sum - g).abs() < 1e-9 * (1.0 + g.abs()),
                "{} phi={phi}: sum {sum} vs G {g}",
                model.structure()
            );
            let off = p.offset_output.unwrap();
            assert!(
                (rest[n - 1] - off).abs() < 1e-12,
                "offset {off} vs {}",
                rest[n - 1]
            );
            // Stability margin agrees with the poles.
            let r = p
                .poles
                .iter()
                .map(|q| (1.0 + TS * q).norm())
                .fold(0.0, f64::max);
            assert!((r - p.stability_radius).abs() < 1e-12 && p.stable);
        }
    }
}

/// Common eigenvectors: interpolated poles are the interpolated eigenvalues (eq. 5.6), and the
/// report recognises the guarantee; local eigenvectors that differ do not qualify.
#[test]
fn common_eigenvector_poles_and_guarantee() {
    let e = [
        [-250.0, -30.0],
        [-90.0, -8.0],
        [-220.0, -1.0],
        [-128.0, -29.0],
    ];
    let units: Vec<_> = e
        .iter()
        .enumerate()
        .map(|(i, e)| EigCommonUnit {
            eigenvalues: *e,
            b: if i == 0 { [1.0, 1.0] } else { [2.0, 0.5] },
            c: [0.02, -0.01],
            dx: [0.0; 2],
            dy: 0.0,
        })
        .collect();
    let model = lmn(
        LocalModelSet::SsEigCommon {
            units,
            reference_unit: 0,
        },
        4,
    );
    let rep = analyse(&model, 101).unwrap();
    assert!(rep.network_stable_by_construction);
    let c = rep.common_eigenvectors.unwrap();
    assert!(c[0].abs() < 1e-12 && (c[1] - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    for p in &rep.points {
        let mut want = [0.0; 2];
        for (i, r) in p.activations.iter().enumerate() {
            want[0] += r * e[i][0];
            want[1] += r * e[i][1];
        }
        let mut got: Vec<f64> = p.poles.iter().map(|q| q.re).collect();
        got.sort_by(f64::total_cmp);
        want.sort_by(f64::total_cmp);
        assert!(
            (got[0] - want[0]).abs() < 1e-9 && (got[1] - want[1]).abs() < 1e-9,
            "phi {}",
            p.phi
        );
    }
    // Direct-form matrices built from one V are recognised, with V's angles.
    let v = eigenvector_matrix([0.3, 2.0]);
    let a: Vec<_> = e
        .iter()
        .map(|e| a_from_eigensystem(&v, *e).unwrap())
        .collect();
    let c = common_eigenvectors(&a, 1e-9).unwrap();
    assert!(
        (c[0] - 0.3).abs() < 1e-9 && (c[1] - 2.0).abs() < 1e-9,
        "{c:?}"
    );
    // Different eigenvectors, or a complex pair, are not common.
    let v2 = eigenvector_matrix([0.5, 2.0]);
    let mut a2 = a.clone();
    a2.push(a_from_eigensystem(&v2, [-50.0, -5.0]).unwrap());
    assert!(common_eigenvectors(&a2, 1e-9).is_none());
    assert!(common_eigenvectors(&[[[-1.0, -5.0], [5.0, -1.0]]], 1e-9).is_none());
}

/// Thesis Table 5.3: the fast-muscle LMN with local eigenvectors whose third unit has the
/// unstable eigenvalue +9.96; the analysis flags unit 2 and the phi region it dominates.
#[test]
fn table_5_3_instability_is_detected() {
    let eig = [
        [-256.27, -33.24],
        [-87.07, -7.71],
        [-220.68, 9.96],
        [-128.48, -29.61],
    ];
    let units = eig
        .iter()
        .enumerate()
        .map(|(i, e)| EigLocalUnit {
            eigenvalues: *e,
            eigenvector_angles: [0.2 + 0.3 * i as f64, 1.6 + 0.1 * i as f64],
            b: [1.0, 0.5],
            c: [0.02, 0.01],
            dx: [0.0; 2],
            dy: 0.0,
        })
        .collect();
    let model = lmn(LocalModelSet::SsEigLocal(units), 4);
    let rep = analyse(&model, 201).unwrap();
    assert!(!rep.network_stable_by_construction);
    assert!(rep.common_eigenvectors.is_none());
    let bad: Vec<_> = rep
        .units
        .iter()
        .filter(|u| !u.stable)
        .map(|u| u.unit)
        .collect();
    assert_eq!(bad, vec![2]);
    // Where unit 2 dominates (its peak), the frozen model is unstable; at phi = 0 it is not.
    let net = model.network().unwrap();
    let peak = phi_grid(&net, 201)
        .into_iter()
        .max_by(|a, b| {
            analyse_at(&net, *a).activations[2].total_cmp(&analyse_at(&net, *b).activations[2])
        })
        .unwrap();
    assert!(!analyse_at(&net, peak).stable, "peak of unit 2 at {peak}");
    assert!(analyse_at(&net, 0.0).stable);
}
