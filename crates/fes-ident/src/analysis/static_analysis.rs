//! Static analysis of a Local Model Network at fixed values of the scheduling variable
//! (thesis 2.4.2, 5.4.3, Fig. 5.27-5.28).
//!
//! At a fixed phi the network is a linear parameter-invariant model (the interpolated local
//! model, eq. 2.16 / 2.26). For it this module reports the activations rho_i(phi), the model
//! itself, the steady-state gain (state space G = -c' A^-1 b, eq. A.18; ARX B(1)/A(1),
//! eq. A.38; for a 1-sample pulse G is also the sum of the output's pulse response, i.e. the
//! force-time integral per pulse is G Ts), the poles (delta domain, eq. A.19, complex
//! allowed; ARX: (z - 1)/Ts), the steady-state output with no input (eq. A.17 at u = 0), and
//! the stability margin max |1 + Ts p| (< 1 is stable, Fig. D.4). These are properties of the
//! frozen LPI model only; they do not prove properties of the LPV network, except through the
//! common-eigenvector test (2.4.1): real local eigensystems with common eigenvectors and
//! every local model stable make the network stable.

use fes_model::model::arx::{ArxUnit, shift_gain, shift_offset_output, shift_poles};
use fes_model::model::lmn::{Lmn, LmnError, UnitStability};
use fes_model::model::local_model::SsLocalModel;
use fes_model::model::network::{LocalModels, Network};
use nalgebra::Complex;

/// The interpolated (frozen) local model at one phi.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FrozenModel {
    /// State space, delta domain (eq. 2.16).
    StateSpace(SsLocalModel<f64>),
    /// ARX in shift form (eq. 2.26).
    Arx {
        /// n.
        order: usize,
        /// Shift-form coefficients.
        model: ArxUnit<f64>,
    },
}

/// The network frozen at one phi.
#[derive(Debug, Clone, PartialEq)]
pub struct StaticPoint {
    /// The scheduling value.
    pub phi: f64,
    /// rho_i(phi) for every unit (zeros for inactive ones).
    pub activations: Vec<f64>,
    /// The interpolated model.
    pub model: FrozenModel,
    /// Steady-state gain (eq. A.18 / A.38); `None` if singular.
    pub gain: Option<f64>,
    /// Steady-state output with no input (eq. A.17 at u = 0); `None` if singular.
    pub offset_output: Option<f64>,
    /// Delta-domain poles.
    pub poles: Vec<Complex<f64>>,
    /// max |1 + Ts p| over the poles (shift-domain pole magnitude).
    pub stability_radius: f64,
    /// stability_radius < 1.
    pub stable: bool,
}

/// The network frozen at `phi`.
pub fn analyse_at(net: &Network<f64>, phi: f64) -> StaticPoint {
    let ts = net.ts();
    let act = net.validity().eval(phi);
    let activations = (0..net.units()).map(|i| act.get(i)).collect();
    match net.local_models() {
        LocalModels::StateSpace(_) => {
            let m = net.ss_interpolated(&act).unwrap_or_else(SsLocalModel::zero);
            let radius = m.stability_radius(ts);
            StaticPoint {
                phi,
                activations,
                model: FrozenModel::StateSpace(m),
                gain: m.gain(),
                offset_output: m.offset_output(),
                poles: m.poles().to_vec(),
                stability_radius: radius,
                stable: radius < 1.0,
            }
        }
        LocalModels::Arx { order, .. } => {
            let n = *order;
            let m = net.arx_interpolated(&act).unwrap_or_else(ArxUnit::zero);
            let z = shift_poles(&m, n);
            let radius = z.iter().map(|z| z.norm()).fold(0.0, f64::max);
            StaticPoint {
                phi,
                activations,
                model: FrozenModel::Arx { order: n, model: m },
                gain: shift_gain(&m, n),
                offset_output: shift_offset_output(&m, n),
                poles: z.iter().map(|z| (z - 1.0) / ts).collect(),
                stability_radius: radius,
                stable: radius < 1.0,
            }
        }
    }
}

/// `n` evenly spaced phi values over the valid range of the validity functions (n >= 2).
pub fn phi_grid(net: &Network<f64>, n: usize) -> Vec<f64> {
    let (lo, hi) = net.validity().valid_range();
    let n = n.max(2);
    (0..n)
        .map(|i| lo + (hi - lo) * i as f64 / (n - 1) as f64)
        .collect()
}

/// [`analyse_at`] over a grid of phi values (Fig. 5.27).
pub fn sweep(net: &Network<f64>, phis: &[f64]) -> Vec<StaticPoint> {
    phis.iter().map(|&phi| analyse_at(net, phi)).collect()
}

/// The common real eigenvectors of a set of 2x2 matrices, as angles in [0, pi) (sorted), if
/// every matrix has a real eigenbasis and all share it (within `tol` radians). A multiple of
/// the identity accepts any eigenvectors; `None` for complex or defective eigensystems or
/// differing eigenvectors.
pub fn common_eigenvectors(a: &[[[f64; 2]; 2]], tol: f64) -> Option<[f64; 2]> {
    let mut common: Option<[f64; 2]> = None;
    for m in a {
        let Some(dirs) = eigenvector_angles(m)? else {
            continue; // scalar matrix: any basis
        };
        match common {
            None => common = Some(dirs),
            Some(c) => {
                let close = |x: f64, y: f64| {
                    let d = (x - y).rem_euclid(core::f64::consts::PI);
                    d.min(core::f64::consts::PI - d) <= tol
                };
                if !(close(c[0], dirs[0]) && close(c[1], dirs[1])) {
                    return None;
                }
            }
        }
    }
    Some(common.unwrap_or([0.0, core::f64::consts::FRAC_PI_2]))
}

/// Eigenvector directions of a real 2x2 matrix as sorted angles in [0, pi):
/// `None` = no real eigenbasis, `Some(None)` = multiple of the identity.
fn eigenvector_angles(m: &[[f64; 2]; 2]) -> Option<Option<[f64; 2]>> {
    let scale = m
        .iter()
        .flatten()
        .map(|v| v.abs())
        .fold(0.0, f64::max)
        .max(f64::MIN_POSITIVE);
    let p = fes_model::model::local_model::eig2(m);
    if p[0].im != 0.0 {
        return None;
    }
    let (l0, l1) = (p[0].re, p[1].re);
    if (l0 - l1).abs() <= 1e-12 * scale {
        let scalar = m[0][1].abs() <= 1e-12 * scale && m[1][0].abs() <= 1e-12 * scale;
        return if scalar { Some(None) } else { None };
    }
    let dir = |l: f64| {
        // Null vector of (A - l I): either row gives one; take the better conditioned.
        let v1 = [m[0][1], l - m[0][0]];
        let v2 = [l - m[1][1], m[1][0]];
        let v = if v1[0].hypot(v1[1]) >= v2[0].hypot(v2[1]) {
            v1
        } else {
            v2
        };
        v[1].atan2(v[0]).rem_euclid(core::f64::consts::PI)
    };
    let mut d = [dir(l0), dir(l1)];
    d.sort_by(f64::total_cmp);
    Some(Some(d))
}

/// Whole-model static report: a sweep, per-unit stability, and the common-eigenvector
/// guarantee.
#[derive(Debug, Clone, PartialEq)]
pub struct StaticReport {
    /// The sweep over phi.
    pub points: Vec<StaticPoint>,
    /// Per-unit stability.
    pub units: Vec<UnitStability>,
    /// Common eigenvector angles (radians in [0, pi)), when the state-space local models
    /// share a real eigenbasis (always for `ss-eig-common`: the gauge makes them the axes).
    pub common_eigenvectors: Option<[f64; 2]>,
    /// True when common eigenvectors exist and every local model is stable: then the network
    /// is stable for any scheduling sequence (2.4.1).
    pub network_stable_by_construction: bool,
}

/// The full static analysis of a model over `grid_points` phi values across the valid range.
pub fn analyse(lmn: &Lmn, grid_points: usize) -> Result<StaticReport, LmnError> {
    let net = lmn.network()?;
    let points = sweep(&net, &phi_grid(&net, grid_points));
    let units = lmn.stability();
    let common = lmn.ss_units().and_then(|u| {
        let a: Vec<_> = u.iter().map(|m| m.a).collect();
        common_eigenvectors(&a, 1e-9)
    });
    let all_stable = units.iter().all(|u| u.stable);
    Ok(StaticReport {
        points,
        network_stable_by_construction: common.is_some() && all_stable,
        common_eigenvectors: common,
        units,
    })
}
