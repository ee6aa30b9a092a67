//! Input-output pole placement with integral action for ARX local models (thesis App. C.1,
//! eq. C.1-C.7) and the Local Controller Network built from it (3.3; Example E.4.7).
//!
//! **Plant.** A shift-form ARX model
//! y_k = sum_{l<nb} b_l u_{k-d-l} - sum_{i<=na} a_i y_{k-i} + c
//! (delay d >= 1, [`crate::model::arx`]) has the transfer function
//! q^-d B(q^-1) / A(q^-1) = B'(q) / A'(q) with (eq. C.2, our delay convention: the first
//! input regressor is u_{k-d}; N = max(na, d + nb - 1))
//!
//! A'(q) = q^{N-na} (q^na + a_1 q^{na-1} + ... + a_na), B'(q) = sum_l b_l q^{N-d-l}.
//!
//! **Controller** (eq. C.3, C.5): H(q) u = S(q) r - G(q) y with H = (q - 1) H' (integral
//! action; it also removes the offset c, C.1). The integrator is part of the plant for the
//! design: A_I = (q - 1) A' of degree n_p = N + 1. With H' monic of degree n_p - 1 and G of
//! degree n_p - 1, the Diophantine equation (C.6)
//!
//! A_I(q) H'(q) + B'(q) G(q) = A_o(q) A_m(q)
//!
//! has a unique solution (2 n_p - 1 unknowns for the 2 n_p - 1 free coefficients of the
//! degree-(2 n_p - 1) right-hand side), solved as a linear (Sylvester) system. A_m is the
//! dominant pair of the rise-time and damping specification (the 10-90 % rise time of the
//! continuous pair, [`rise_factor`], mapped exactly to z = e^{s Ts}); the observer is
//! dead-beat, A_o = q^{2 n_p - 3} (C.1.1). S = s_0 q^{n_p - 1} with
//! s_0 = A_m(1) A_o(1) / B'(1) (eq. C.7): zero steady-state error, and the servo response
//! r -> y is exactly s_0 B'(q) / (q^{n_p - 2} A_m(q)).
//!
//! In difference form (divided by q^{n_p}) the controller is strictly proper: u_k is a
//! function of u_{k-1..k-n_p}, y_{k-1..k-n_p} and r_{k-1}.
//!
//! **LCN.** Every local controller has polynomials of the same degrees; the network
//! interpolates their coefficients with the validity functions rho_i(phi_k) (eq. 3.x,
//! the LCN of 3.3). Each interpolated H is still (q - 1) times a monic polynomial (the
//! weights sum to one), so integral action survives interpolation. The input history holds
//! the *applied* (clamped) input: the polynomial controller's anti-reset-windup (the
//! thesis's remedy for Fig. E.8's overshoot at 37 s).

use super::poles::{SpecError, dominant_pair};
use crate::model::arx::ArxUnit;
use crate::model::validity::ValidityFunctions;
#[cfg(not(feature = "std"))]
use crate::num::math::FloatMath as _;
use alloc::{vec, vec::Vec};
use nalgebra::{DMatrix, DVector};

/// Why a design failed.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum IoDesignError {
    /// The specification gives no poles.
    #[error(transparent)]
    Spec(#[from] SpecError),
    /// Order outside 1..=3 or delay 0.
    #[error("ARX order {order} with delay {delay}: need order 1..=3 and delay >= 1")]
    Structure {
        /// n.
        order: usize,
        /// d.
        delay: usize,
    },
    /// B'(1) = 0 or the Sylvester system is singular (A' and B' share a root).
    #[error("unit {unit}: the plant is not controllable (A' and B' share a root, or B'(1) = 0)")]
    Singular {
        /// The unit (0 for a single design).
        unit: usize,
    },
    /// The local controllers and the validity functions disagree.
    #[error("{controllers} controllers for {units} validity functions")]
    Units {
        /// Controllers.
        controllers: usize,
        /// Units.
        units: usize,
    },
}

/// A polynomial controller H u = S r - G y, coefficients in descending powers of q.
#[derive(Debug, Clone, PartialEq)]
pub struct PolyController {
    /// H (monic, degree n_p; contains the factor q - 1).
    pub h: Vec<f64>,
    /// G (degree n_p - 1).
    pub g: Vec<f64>,
    /// s_0 of S = s_0 q^{n_p - 1}.
    pub s0: f64,
}

/// Polynomial product (descending powers).
fn mul(a: &[f64], b: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; a.len() + b.len() - 1];
    for (i, x) in a.iter().enumerate() {
        for (j, y) in b.iter().enumerate() {
            out[i + j] += x * y;
        }
    }
    out
}

/// Value at q = 1 (sum of the coefficients).
fn at_one(p: &[f64]) -> f64 {
    p.iter().sum()
}

/// w_n t_r of the 10-90 % rise time t_r of the continuous second-order step response
/// y'' + 2 ξ y' + y = 1 (w_n = 1) from rest, integrated by RK4 in steps of 1e-3. At
/// ξ = 1.2 it is 4.47: the thesis's rule w_n t_r = 3.2 (6.5.3, [`dominant_pair`]) gives a
/// 10-90 % rise time 40 % longer than asked, so E.4.7's rise times use this factor.
pub fn rise_factor(damping: f64) -> f64 {
    let f = |y: f64, v: f64| (v, 1.0 - y - 2.0 * damping * v);
    let h = 1e-3;
    let (mut y, mut v, mut t) = (0.0_f64, 0.0_f64, 0.0_f64);
    let mut t10 = None;
    while t < 1e3 {
        let (k1y, k1v) = f(y, v);
        let (k2y, k2v) = f(y + 0.5 * h * k1y, v + 0.5 * h * k1v);
        let (k3y, k3v) = f(y + 0.5 * h * k2y, v + 0.5 * h * k2v);
        let (k4y, k4v) = f(y + h * k3y, v + h * k3v);
        let y_next = y + h / 6.0 * (k1y + 2.0 * k2y + 2.0 * k3y + k4y);
        v += h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v);
        // Crossing times by linear interpolation within the step.
        let cross = |level: f64| t + h * (level - y) / (y_next - y);
        if t10.is_none() && y_next >= 0.1 {
            t10 = Some(cross(0.1));
        }
        if y_next >= 0.9 {
            return cross(0.9) - t10.unwrap_or(0.0);
        }
        y = y_next;
        t += h;
    }
    f64::NAN
}

/// The dominant pair's polynomial A_m(q) = q^2 + m_1 q + m_0 for a 10-90 % rise time (s)
/// and a damping: the continuous pair w_n (-ξ ± sqrt(ξ^2 - 1)) with
/// w_n = [`rise_factor`]`(ξ) / t_r`, mapped exactly, z = e^{s Ts}.
pub fn dominant_polynomial(rise_time_s: f64, damping: f64, ts: f64) -> Result<[f64; 3], SpecError> {
    // The checks of the thesis's rule (finite positive rise time, damping, Ts).
    dominant_pair(rise_time_s, damping, ts)?;
    let wn = rise_factor(damping) / rise_time_s;
    let disc = damping * damping - 1.0;
    let (sum, product) = if disc >= 0.0 {
        let r = disc.sqrt();
        let z1 = (wn * (-damping + r) * ts).exp();
        let z2 = (wn * (-damping - r) * ts).exp();
        (z1 + z2, z1 * z2)
    } else {
        let decay = (-damping * wn * ts).exp();
        (
            2.0 * decay * (wn * (-disc).sqrt() * ts).cos(),
            decay * decay,
        )
    };
    Ok([1.0, -sum, product])
}

/// C.1 pole placement with integral action for a shift-form ARX model (module docs)
/// y_k = sum_{l < nb} b_l u_{k-d-l} - sum_{i = 1..na} a_i y_{k-i} + c, given `a` =
/// \[a_1..a_na\], `b` = \[b_0..b_{nb-1}\] and the delay `d` >= 1 of b_0 (the offset c
/// does not enter: integral action removes it).
pub fn design(
    a: &[f64],
    b: &[f64],
    d: usize,
    rise_time_s: f64,
    damping: f64,
    ts: f64,
) -> Result<PolyController, IoDesignError> {
    // Zero taps at either end of B are delay, not dynamics: a trailing zero would give B'
    // a root at q = 0 shared with A' (no solution).
    let lead = b.iter().take_while(|v| **v == 0.0).count();
    let trail = b.iter().rev().take_while(|v| **v == 0.0).count();
    let b = &b[lead.min(b.len())..b.len() - trail.min(b.len() - lead.min(b.len()))];
    let d = d + lead;
    let (na, nb) = (a.len(), b.len());
    if na == 0 || nb == 0 || d == 0 {
        return Err(IoDesignError::Structure {
            order: na,
            delay: d,
        });
    }
    let am = dominant_polynomial(rise_time_s, damping, ts)?;
    // Transfer function times q^N / q^N, N = max(na, d + nb - 1):
    // A'(q) = q^{N - na} (q^na + a_1 q^{na-1} + ...), B'(q) = sum_l b_l q^{N - d - l}.
    let big_n = na.max(d + nb - 1);
    let mut a_prime = vec![1.0];
    a_prime.extend_from_slice(a);
    a_prime.extend(core::iter::repeat_n(0.0, big_n - na));
    let deg_b = big_n - d;
    let mut b_prime = b.to_vec();
    b_prime.extend(core::iter::repeat_n(0.0, deg_b + 1 - nb));
    // The integrator is part of the plant: A_I = (q - 1) A', degree n_p = N + 1.
    let a_i = mul(&[1.0, -1.0], &a_prime);
    let np = a_i.len() - 1;
    // A_cl = q^{2 np - 3} A_m, degree 2 np - 1.
    let mut a_cl = am.to_vec();
    a_cl.extend(core::iter::repeat_n(0.0, 2 * np - 3));
    let ncl = a_cl.len() - 1;
    // Unknowns: h'_1..h'_{np-1} (H' monic, degree np - 1), g_0..g_{np-1}.
    let nh = np - 1;
    let ng = np;
    let m = nh + ng;
    let mut sys = DMatrix::zeros(m, m);
    let mut rhs = DVector::zeros(m);
    let ai = |k: isize| -> f64 {
        if k >= 0 && (k as usize) < a_i.len() {
            a_i[k as usize]
        } else {
            0.0
        }
    };
    // Row r = 1..=ncl is the coefficient of q^{ncl - r} (r = 0, the leading 1, holds).
    // A_I H': the term h'_j contributes a_i[r - j]. B' G: b_l q^{deg_b - l} times
    // g_j q^{np - 1 - j} lands in row r = ncl - deg_b - np + 1 + l + j.
    let shift = ncl as isize - deg_b as isize - np as isize + 1;
    for (r, &acl) in a_cl.iter().enumerate().skip(1) {
        let row = r - 1;
        rhs[row] = acl - ai(r as isize);
        for j in 1..=nh {
            sys[(row, j - 1)] = ai(r as isize - j as isize);
        }
        for j in 0..ng {
            let l = r as isize - shift - j as isize;
            if l >= 0 && (l as usize) < b_prime.len() {
                sys[(row, nh + j)] = b_prime[l as usize];
            }
        }
    }
    let sol = sys
        .lu()
        .solve(&rhs)
        .filter(|x| x.iter().all(|v| v.is_finite()))
        .ok_or(IoDesignError::Singular { unit: 0 })?;
    let mut h_prime = vec![1.0];
    h_prime.extend(sol.iter().take(nh));
    let g: Vec<f64> = sol.iter().skip(nh).copied().collect();
    let h = mul(&[1.0, -1.0], &h_prime);
    let b1 = at_one(&b_prime);
    if b1 == 0.0 || !b1.is_finite() {
        return Err(IoDesignError::Singular { unit: 0 });
    }
    Ok(PolyController {
        h,
        g,
        s0: at_one(&a_cl) / b1,
    })
}

/// [`design`] for an [`ArxUnit`] of order n (a and b of length n).
pub fn design_arx(
    model: &ArxUnit<f64>,
    n: usize,
    d: usize,
    rise_time_s: f64,
    damping: f64,
    ts: f64,
) -> Result<PolyController, IoDesignError> {
    if !(1..=3).contains(&n) {
        return Err(IoDesignError::Structure { order: n, delay: d });
    }
    design(&model.a[..n], &model.b[..n], d, rise_time_s, damping, ts)
}

/// A network of polynomial controllers interpolated by validity functions (module docs),
/// with its input, output and reference histories.
#[derive(Debug, Clone, PartialEq)]
pub struct PolyLcn {
    validity: ValidityFunctions<f64>,
    units: Vec<PolyController>,
    u_past: Vec<f64>,
    y_past: Vec<f64>,
    r_past: f64,
    limits: (f64, f64),
    anti_windup: bool,
}

impl PolyLcn {
    /// A network of local controllers (all of the same degrees) over `validity`, its input
    /// clamped into `limits`.
    pub fn new(
        validity: ValidityFunctions<f64>,
        units: Vec<PolyController>,
        limits: (f64, f64),
    ) -> Result<Self, IoDesignError> {
        if units.len() != validity.units() {
            return Err(IoDesignError::Units {
                controllers: units.len(),
                units: validity.units(),
            });
        }
        // Controllers of different degrees (different delays per unit) are padded with
        // zero coefficients on the oldest samples: the same difference equation.
        let np = units.iter().map(|c| c.h.len() - 1).max().unwrap_or(1);
        let units = units
            .into_iter()
            .map(|mut c| {
                c.h.resize(np + 1, 0.0);
                c.g.resize(np, 0.0);
                c
            })
            .collect();
        Ok(Self {
            validity,
            units,
            u_past: vec![0.0; np],
            y_past: vec![0.0; np],
            r_past: 0.0,
            limits,
            anti_windup: true,
        })
    }

    /// The same network keeping the *computed* input in its history instead of the
    /// applied one: no anti-reset-windup (for comparison, Fig. E.8's overshoot at 37 s).
    pub fn without_anti_windup(mut self) -> Self {
        self.anti_windup = false;
        self
    }

    /// One linear controller (a one-unit network).
    pub fn single(c: PolyController, limits: (f64, f64)) -> Result<Self, IoDesignError> {
        let v = ValidityFunctions::uniform(1, 0.0, 1.0).map_err(|_| IoDesignError::Units {
            controllers: 1,
            units: 0,
        })?;
        Self::new(v, alloc::vec![c], limits)
    }

    /// Starts in the steady state with input `u`, output `y` and reference `y`.
    pub fn settle(&mut self, u: f64, y: f64) {
        self.u_past.iter_mut().for_each(|v| *v = u);
        self.y_past.iter_mut().for_each(|v| *v = y);
        self.r_past = y;
    }

    /// The input for this sample, from the scheduling value `phi`, the output measured
    /// last sample `y_prev` and the reference `r` (used from the next sample on); the
    /// applied (clamped) input enters the history unless built
    /// [`Self::without_anti_windup`].
    pub fn step(&mut self, phi: f64, y_prev: f64, r: f64) -> f64 {
        self.y_past.rotate_right(1);
        self.y_past[0] = y_prev;
        let act = self.validity.eval(phi);
        let np = self.u_past.len();
        let mut u = 0.0;
        for (i, rho) in act.iter() {
            let c = &self.units[i];
            let mut ui = c.s0 * self.r_past;
            for k in 0..np {
                ui -= c.h[k + 1] * self.u_past[k] + c.g[k] * self.y_past[k];
            }
            u += rho * ui;
        }
        let applied = u.clamp(self.limits.0, self.limits.1);
        self.u_past.rotate_right(1);
        self.u_past[0] = if self.anti_windup { applied } else { u };
        self.r_past = r;
        applied
    }
}
