//! Starting points for simulation-mode estimation (thesis 5.3, 5.4.2; pitfalls (b) and (c)
//! of docs/identification.md).
//!
//! Linear models start from *separated real* poles: every pair (or n-tuple for ARX order n)
//! from [`POLE_GRID`], continuous-time poles s mapped exactly to the model's domain
//! (delta: (e^{s Ts} - 1)/Ts, inside (-1/Ts, 0) for every s < 0; shift: e^{s Ts}). The
//! parameters that enter the output linearly for fixed poles (c and d^y of a state-space
//! unit with b = (1, 1); b and d of an ARX unit) are then solved exactly by least squares
//! (see [`super::identify`](mod@super::identify)). A Local Model Network starts from a linear fit copied into every
//! unit (the network output equals the linear model's, since the validity functions sum to
//! one).

use fes_model::model::arx::ArxUnit;
use fes_model::model::lmn::{LocalModelSet, Structure};
use fes_model::model::local_model::{EigCommonUnit, EigLocalUnit, SsLocalModel};

/// Continuous-time poles (1/s) the linear starts are built from: time constants from
/// 3 ms to 125 ms, covering fast and slow twitches.
pub const POLE_GRID: [f64; 5] = [-8.0, -20.0, -50.0, -120.0, -300.0];

/// A continuous pole s as a delta-domain eigenvalue at period ts: (e^{s Ts} - 1)/Ts.
pub fn delta_eigenvalue(s: f64, ts: f64) -> f64 {
    (s * ts).exp_m1() / ts
}

/// Every choice of `n` distinct poles from [`POLE_GRID`] (in grid order).
pub fn pole_sets(n: usize) -> Vec<Vec<f64>> {
    fn rec(from: usize, n: usize, cur: &mut Vec<f64>, out: &mut Vec<Vec<f64>>) {
        if cur.len() == n {
            out.push(cur.clone());
            return;
        }
        for (i, &p) in POLE_GRID.iter().enumerate().skip(from) {
            cur.push(p);
            rec(i + 1, n, cur, out);
            cur.pop();
        }
    }
    let mut out = Vec::new();
    rec(0, n, &mut Vec::new(), &mut out);
    out
}

/// Coefficients c_1..c_n of prod_j (x - r_j) = x^n + c_1 x^{n-1} + ... + c_n.
fn monic_from_roots(roots: &[f64]) -> Vec<f64> {
    let mut c = vec![1.0];
    for r in roots {
        let mut next = vec![0.0; c.len() + 1];
        for (i, v) in c.iter().enumerate() {
            next[i] += v;
            next[i + 1] -= r * v;
        }
        c = next;
    }
    c[1..].to_vec()
}

/// An ARX unit with the given continuous poles, numerator b_0 = `gain_hint` (the rest 0) and
/// no offset; shift or delta form at period ts.
pub fn arx_unit_from_poles(poles: &[f64], ts: f64, delta: bool, gain_hint: f64) -> ArxUnit<f64> {
    let n = poles.len();
    let mut u = ArxUnit::zero();
    if delta {
        // A_delta(delta) = prod (delta - e_j) = delta^n + alpha_{n-1} delta^{n-1} + ... + alpha_0.
        let e: Vec<f64> = poles.iter().map(|&s| delta_eigenvalue(s, ts)).collect();
        let c = monic_from_roots(&e);
        for i in 0..n {
            u.a[i] = c[n - 1 - i];
        }
    } else {
        // A(q^-1) = prod (1 - z_j q^-1): a_i is the coefficient of z^{n-i} in prod (z - z_j).
        let z: Vec<f64> = poles.iter().map(|&s| (s * ts).exp()).collect();
        let c = monic_from_roots(&z);
        u.a[..n].copy_from_slice(&c);
    }
    u.b[0] = gain_hint;
    u
}

/// A one-unit local model set of `structure` with the given delta eigenvalues, b = (1, 1)
/// and c, offsets zero (ARX structures: `arx_order` poles from `poles`).
pub fn linear_set(structure: Structure, poles: &[f64], ts: f64, arx_order: usize) -> LocalModelSet {
    let e = |j: usize| delta_eigenvalue(poles[j.min(poles.len() - 1)], ts);
    let b = [1.0, 1.0];
    let zero2 = [0.0; 2];
    match structure {
        Structure::SsDirect => LocalModelSet::SsDirect(vec![SsLocalModel {
            a: [[e(0), 0.0], [0.0, e(1)]],
            b,
            c: zero2,
            dx: zero2,
            dy: 0.0,
        }]),
        Structure::SsEigLocal => LocalModelSet::SsEigLocal(vec![EigLocalUnit {
            eigenvalues: [e(0), e(1)],
            eigenvector_angles: [0.0, core::f64::consts::FRAC_PI_2],
            b,
            c: zero2,
            dx: zero2,
            dy: 0.0,
        }]),
        Structure::SsEigCommon => LocalModelSet::SsEigCommon {
            units: vec![EigCommonUnit {
                eigenvalues: [e(0), e(1)],
                b,
                c: zero2,
                dx: zero2,
                dy: 0.0,
            }],
            reference_unit: 0,
        },
        Structure::ArxShift => LocalModelSet::ArxShift {
            order: arx_order,
            units: vec![arx_unit_from_poles(&poles[..arx_order], ts, false, 0.0)],
        },
        Structure::ArxDelta => LocalModelSet::ArxDelta {
            order: arx_order,
            units: vec![arx_unit_from_poles(&poles[..arx_order], ts, true, 0.0)],
        },
    }
}

/// The first unit of `one` copied into `m` units (`reference_unit` for `ss-eig-common`,
/// whose b must then be (1, 1) in `one`, as it is for a one-unit gauge-fixed model).
pub fn replicate(one: &LocalModelSet, m: usize, reference_unit: usize) -> LocalModelSet {
    match one {
        LocalModelSet::SsDirect(u) => LocalModelSet::SsDirect(vec![u[0]; m]),
        LocalModelSet::SsEigLocal(u) => LocalModelSet::SsEigLocal(vec![u[0]; m]),
        LocalModelSet::SsEigCommon { units, .. } => LocalModelSet::SsEigCommon {
            units: vec![units[0]; m],
            reference_unit,
        },
        LocalModelSet::ArxShift { order, units } => LocalModelSet::ArxShift {
            order: *order,
            units: vec![units[0]; m],
        },
        LocalModelSet::ArxDelta { order, units } => LocalModelSet::ArxDelta {
            order: *order,
            units: vec![units[0]; m],
        },
    }
}

/// The delta eigenvalues of a state-space unit set's first unit (`None` for ARX or a
/// direct-form unit with complex poles).
pub fn eigenvalues(set: &LocalModelSet) -> Option<[f64; 2]> {
    match set {
        LocalModelSet::SsEigLocal(u) => Some(u[0].eigenvalues),
        LocalModelSet::SsEigCommon { units, .. } => Some(units[0].eigenvalues),
        LocalModelSet::SsDirect(u) => {
            let p = u[0].poles();
            (p[0].im == 0.0).then_some([p[0].re, p[1].re])
        }
        _ => None,
    }
}

/// Pitfall (b): two real eigenvalues closer than 20 % of their mean have (nearly) collapsed
/// onto a double pole; the modes are then indistinguishable and the Jacobian degenerate.
pub fn collapsed(e: [f64; 2]) -> bool {
    (e[0] - e[1]).abs() < 0.2 * 0.5 * (e[0].abs() + e[1].abs())
}

/// Separates a collapsed pair of delta eigenvalues around their geometric mean by a factor
/// of 4 (kept inside (-1/Ts, 0) by mapping through continuous time).
pub fn separate(e: [f64; 2], ts: f64) -> [f64; 2] {
    let s = |d: f64| (1.0 + d * ts).max(1e-12).ln() / ts; // delta eigenvalue -> continuous
    let mean = (s(e[0]) * s(e[1])).sqrt();
    [
        delta_eigenvalue(-2.0 * mean, ts),
        delta_eigenvalue(-0.5 * mean, ts),
    ]
}

/// Sets the eigenvalues of every unit of a state-space set (direct form: A = diag(e) in the
/// unit's current eigenbasis is not available, so A is replaced by diag(e)).
pub fn set_eigenvalues(set: &mut LocalModelSet, e: [f64; 2]) {
    match set {
        LocalModelSet::SsEigLocal(u) => u.iter_mut().for_each(|x| x.eigenvalues = e),
        LocalModelSet::SsEigCommon { units, .. } => {
            units.iter_mut().for_each(|x| x.eigenvalues = e)
        }
        LocalModelSet::SsDirect(u) => u.iter_mut().for_each(|x| x.a = [[e[0], 0.0], [0.0, e[1]]]),
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fes_model::model::arx::{delta_to_shift, shift_poles};

    #[test]
    fn arx_poles_land_where_asked() {
        let ts = 5e-3;
        let u = arx_unit_from_poles(&[-20.0, -120.0], ts, false, 1.0);
        let mut z: Vec<f64> = shift_poles(&u, 2).iter().map(|p| p.re).collect();
        z.sort_by(f64::total_cmp);
        assert!((z[0] - (-120.0 * ts).exp()).abs() < 1e-12);
        assert!((z[1] - (-20.0 * ts).exp()).abs() < 1e-12);
        // Delta form: the same poles after the exact conversion.
        let ts = 1e-3;
        let d = arx_unit_from_poles(&[-20.0, -120.0, -300.0], ts, true, 1.0);
        let s = delta_to_shift(&d, 3, ts);
        let mut z: Vec<f64> = shift_poles(&s, 3).iter().map(|p| p.re).collect();
        z.sort_by(f64::total_cmp);
        for (zi, p) in z.iter().zip([-300.0, -120.0, -20.0]) {
            assert!((zi - (p * ts).exp()).abs() < 1e-9, "{zi} vs {p}");
        }
    }

    #[test]
    fn pole_sets_count_and_separation() {
        assert_eq!(pole_sets(1).len(), 5);
        assert_eq!(pole_sets(2).len(), 10);
        assert_eq!(pole_sets(3).len(), 10);
        let ts = 1e-3;
        let e = separate([-50.0, -50.5], ts);
        assert!(!collapsed(e));
        assert!(e.iter().all(|v| *v < 0.0 && *v > -1.0 / ts));
    }
}
