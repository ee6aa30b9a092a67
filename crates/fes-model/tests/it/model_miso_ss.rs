//! Multi-input state-space networks in eigensystem form (`model::miso_ss`, App. E.4.5):
//! a record starts in the steady state, the eigenvalues are the parameters', and the
//! restricted form with the same angles is the general form.

use fes_model::model::local_model::{eig2, eta_from_eigenvalue};
use fes_model::model::miso_ss::{Eigenvectors, MisoSs, theta_len};
use fes_model::model::validity::ValidityFunctions;

fn network(ev: Eigenvectors) -> MisoSs {
    let ts = 0.05;
    let eta = |e: f64| eta_from_eigenvalue(e, ts).unwrap();
    let mut theta = Vec::new();
    if ev == Eigenvectors::Common {
        theta.extend([0.3, 1.4]);
    }
    for i in 0..3 {
        let s = i as f64;
        theta.extend([eta(-1.0 - 0.5 * s), eta(-8.0)]);
        if ev == Eigenvectors::Local {
            theta.extend([0.3, 1.4]);
        }
        theta.extend([-0.2, 0.1, 0.9 - 0.1 * s, 0.3, 1.0, 0.2, 0.05, 0.0, 0.01]);
    }
    assert_eq!(theta.len(), theta_len(2, 3, ev));
    MisoSs {
        ts,
        delays: vec![2, 4],
        scheduling_input: 0,
        scheduling_delay: 3,
        validity: ValidityFunctions::uniform(3, 0.0, 1.0).unwrap(),
        eigenvectors: ev,
        theta,
    }
}

#[test]
fn constant_inputs_keep_the_steady_state_and_forms_agree() {
    let g = network(Eigenvectors::Local);
    let r = network(Eigenvectors::Common);
    let a = vec![0.4; 200];
    let u = vec![0.6; 200];
    let (mut yg, mut yr) = (vec![0.0; 200], vec![0.0; 200]);
    g.simulate(&[&a, &u], &mut yg).unwrap();
    r.simulate(&[&a, &u], &mut yr).unwrap();
    assert!(
        yg.iter().all(|y| (y - yg[0]).abs() < 1e-12),
        "steady: {:?}",
        &yg[..5]
    );
    assert_eq!(yg, yr);
    // A step in u moves it, the eigenvalues are the parameters'.
    let u2: Vec<f64> = (0..200).map(|k| if k < 50 { 0.6 } else { 0.8 }).collect();
    g.simulate(&[&a, &u2], &mut yg).unwrap();
    assert!((yg[199] - yg[0]).abs() > 1e-3);
    let m = g.unit(1).unwrap();
    let mut e: Vec<f64> = eig2(&m.a).iter().map(|c| c.re).collect();
    e.sort_by(f64::total_cmp);
    assert!(
        (e[0] + 8.0).abs() < 1e-9 && (e[1] + 1.5).abs() < 1e-9,
        "{e:?}"
    );
}
