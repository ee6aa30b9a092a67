//! Gauge fixing for state-space networks: the state coordinates are not identifiable
//! (pitfall (a)), so identification holds some parameters of a reference unit r fixed.
//!
//! Every change of state coordinates x' = T x + s leaves the output of a network unchanged
//! when every unit is mapped by A_i' = T A_i T^-1, b_i' = T b_i, c_i' = T^-T c_i,
//! dx_i' = T dx_i - A_i' s, dy_i' = dy_i - c_i'' s (the interpolation of eq. 2.16 is linear,
//! so the mapped network is again a network of the same form; the rest state moves to
//! T x0 + s). With free b_i, c_i, dx_i, dy_i that is a 6-dimensional family of identical
//! models, and the Gauss-Newton Hessian is exactly singular along it. The fixes, each
//! reachable from any model by one such map (so nothing is lost):
//!
//! - **translation s** (2 dimensions; not with zero offsets, where dx = 0 pins it):
//!   dx_r = 0 (s = A_r^-1 T dx_r). This one is not in the model library's parameter layout;
//!   it is found here, in an independent fit of these structures: two exactly zero
//!   Hessian eigenvalues along the offsets of the low units.
//! - **T** for `ss-eig-common`: already fixed by the layout (V = I, b_r = (1, 1)).
//! - **T** for `ss-eig-local`: V_r = I (angles (0, pi/2)) and b_r = (1, 1), the same gauge
//!   applied to unit r (T = diag(1 / (V_r^-1 b_r)) V_r^-1).
//! - **T** for `ss-direct`: unit r in controllable canonical form, a_r00 = 0, a_r01 = 1,
//!   b_r = (0, 1) (T = C_c C^-1 with C = [b_r, A_r b_r]; needs (A_r, b_r) controllable,
//!   otherwise that part is skipped).
//!
//! [`fix_gauge`] maps a model into the gauge (output unchanged) and returns the indices of
//! the parameters to hold fixed.

use fes_model::model::lmn::{Lmn, LocalModelSet};
use fes_model::model::local_model::{
    SsLocalModel, eigenvector_matrix, inverse2, mat_mul2, mat_vec2, solve2,
};
use fes_model::model::params::ParamLayout;

/// The affine state map x' = T x + s applied to a direct-form unit (module docs).
fn transform(
    m: &SsLocalModel<f64>,
    t: &[[f64; 2]; 2],
    ti: &[[f64; 2]; 2],
    s: [f64; 2],
) -> SsLocalModel<f64> {
    let a = mat_mul2(&mat_mul2(t, &m.a), ti);
    let tit = [[ti[0][0], ti[1][0]], [ti[0][1], ti[1][1]]];
    let c = mat_vec2(&tit, m.c);
    let tdx = mat_vec2(t, m.dx);
    let as_ = mat_vec2(&a, s);
    SsLocalModel {
        a,
        b: mat_vec2(t, m.b),
        c,
        dx: [tdx[0] - as_[0], tdx[1] - as_[1]],
        dy: m.dy - (c[0] * s[0] + c[1] * s[1]),
    }
}

const I2: [[f64; 2]; 2] = [[1.0, 0.0], [0.0, 1.0]];

/// Maps `lmn` into the gauge with reference unit `r` (module docs) and returns the indices
/// (in [`ParamLayout::new`]`(lmn)`) of the parameters identification must hold fixed.
/// ARX networks have no gauge (their outputs are measured quantities): empty.
pub fn fix_gauge(lmn: &mut Lmn, r: usize) -> Vec<usize> {
    let zo = lmn.zero_offsets;
    let Some(direct) = lmn.ss_units() else {
        return Vec::new();
    };
    if r >= direct.len() {
        return Vec::new();
    }
    let mut fixed_names: Vec<String> = Vec::new();
    // The linear part T (structure-specific), then the translation s in the new
    // coordinates.
    let (t, ti) = match &lmn.local {
        LocalModelSet::SsEigLocal(u) => {
            let v = eigenvector_matrix(u[r].eigenvector_angles);
            match inverse2(&v) {
                Some(vi) => {
                    let br = mat_vec2(&vi, u[r].b);
                    if br.iter().all(|x| x.abs() > 1e-12) {
                        let d = [[1.0 / br[0], 0.0], [0.0, 1.0 / br[1]]];
                        let t = mat_mul2(&d, &vi);
                        fixed_names.extend(
                            ["angle0", "angle1", "b0", "b1"].map(|n| format!("units[{r}].{n}")),
                        );
                        (t, inverse2(&t).unwrap_or(I2))
                    } else {
                        (I2, I2)
                    }
                }
                None => (I2, I2),
            }
        }
        LocalModelSet::SsDirect(u) => {
            let m = &u[r];
            let ab = mat_vec2(&m.a, m.b);
            let c = [[m.b[0], ab[0]], [m.b[1], ab[1]]];
            match inverse2(&c) {
                Some(ci) => {
                    // Canonical form: b_c = (0, 1), A_c = [[0, 1], [-det, tr]], so
                    // C_c = [b_c, A_c b_c] = [[0, 1], [1, tr]].
                    let tr = m.a[0][0] + m.a[1][1];
                    let cc = [[0.0, 1.0], [1.0, tr]];
                    let t = mat_mul2(&cc, &ci);
                    fixed_names
                        .extend(["a00", "a01", "b0", "b1"].map(|n| format!("units[{r}].{n}")));
                    (t, inverse2(&t).unwrap_or(I2))
                }
                None => (I2, I2),
            }
        }
        _ => (I2, I2),
    };
    let mapped: Vec<SsLocalModel<f64>> = direct
        .iter()
        .map(|m| transform(m, &t, &ti, [0.0; 2]))
        .collect();
    // Translation: dx_r' = dx_r - A_r s = 0.
    let s = if zo {
        None
    } else {
        solve2(&mapped[r].a, mapped[r].dx)
    };
    let mapped: Vec<SsLocalModel<f64>> = match s {
        Some(s) => {
            fixed_names.extend(["dx0", "dx1"].map(|n| format!("units[{r}].{n}")));
            mapped.iter().map(|m| transform(m, &I2, &I2, s)).collect()
        }
        None => mapped,
    };
    write_back(&mut lmn.local, &mapped, t);
    let layout = ParamLayout::new(lmn);
    layout
        .names()
        .iter()
        .enumerate()
        .filter(|(_, n)| fixed_names.contains(n))
        .map(|(i, _)| i)
        .collect()
}

/// Stores mapped direct-form units back into the structure's parameterisation.
fn write_back(set: &mut LocalModelSet, mapped: &[SsLocalModel<f64>], t: [[f64; 2]; 2]) {
    match set {
        LocalModelSet::SsDirect(u) => u.copy_from_slice(mapped),
        LocalModelSet::SsEigLocal(u) => {
            for (x, m) in u.iter_mut().zip(mapped) {
                // Eigenvectors map with T; store them as unit-vector angles.
                let v = eigenvector_matrix(x.eigenvector_angles);
                let tv = mat_mul2(&t, &v);
                x.eigenvector_angles = [tv[1][0].atan2(tv[0][0]), tv[1][1].atan2(tv[0][1])];
                x.b = m.b;
                x.c = m.c;
                x.dx = m.dx;
                x.dy = m.dy;
            }
        }
        LocalModelSet::SsEigCommon { units, .. } => {
            // Modal coordinates stay modal: only the translation applies here (T = I).
            for (x, m) in units.iter_mut().zip(mapped) {
                x.b = m.b;
                x.c = m.c;
                x.dx = m.dx;
                x.dy = m.dy;
            }
        }
        _ => {}
    }
}
