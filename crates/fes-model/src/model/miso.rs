//! Local ARX models with several inputs, a delay per input, scheduled on a measured input
//! (thesis 2.2.2, eq. 2.20 and 2.24 with the data vector of App. E.3-E.4: the
//! heat-transfer process, Examples E.4.2-E.4.7).
//!
//! The muscle network ([`super::network`]) has one pulse input and schedules on a
//! prefiltered input or the output; a plant such as the air heater of App. E has two
//! continuous inputs (valve angle alpha, heater voltage u), a different delay on each
//! (Table E.1) and is scheduled on a *measured input*, phi(t) = alpha(t - T_d,alpha)
//! (eq. E.2). This module is that generalisation; the validity functions
//! ([`ValidityFunctions`], eq. 2.27-2.30), the interpolation ([`super::validity::Activation`]),
//! and the shift-form polynomial analysis ([`super::arx::shift_poles`],
//! [`super::arx::shift_gain`]) are the same code as the muscle's.
//!
//! Local model i of order n (eq. 2.20, one B polynomial per input j, delay d_j):
//!
//! y_k = sum_j sum_{l<n} b_{i,j,l} u_j(k - d_j - l) - sum_{l=1..n} a_{i,l} y(k - l) + c_i,
//!
//! i.e. y_k = psi_k' theta_i with
//! psi_k = [u_0(k-d_0) .. u_0(k-d_0-n+1), u_1(k-d_1) .., y(k-1) .. y(k-n), 1] and
//! theta_i = [b_{i,0,*}, b_{i,1,*}, .., -a_{i,1} .. -a_{i,n}, c_i] (the thesis's Theta',
//! eq. A.30b). The network output is y_k = sum_i rho_i(phi_k) psi_k' theta_i (eq. 2.24),
//! phi_k = u_s(k - d_s) for the scheduling input s.
//!
//! **Start of a record.** The records of App. E.2 start with the plant running, not at
//! rest: before the first sample every input is taken at its first value and the output at
//! its first measured value (the steady state they describe). [`MisoArx::simulate`] and
//! [`MisoArx::predict`] use this one convention.
//!
//! Everything is generic over [`Scalar`] in theta, so `Dual` parameters give the exact
//! Jacobian of a free-run simulation (identification in simulation mode, B.3).

use super::arx::{ArxUnit, MAX_ARX_ORDER, shift_gain, shift_poles};
use super::validity::ValidityFunctions;
use crate::num::Scalar;
use alloc::vec::Vec;
use nalgebra::Complex;

/// Why a multi-input ARX network was rejected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MisoError {
    /// ARX order outside 1..=3.
    #[error("ARX order {0} is outside 1..={MAX_ARX_ORDER}")]
    Order(usize),
    /// No inputs in the data vector.
    #[error("no input in the data vector (no delays given)")]
    Inputs,
    /// theta has the wrong length.
    #[error("theta has {got} entries, the structure has {expected}")]
    Theta {
        /// Given.
        got: usize,
        /// Units x regressors.
        expected: usize,
    },
    /// Sampling period not finite and positive.
    #[error("sampling period Ts = {0} s must be finite and > 0")]
    SamplingPeriod(f64),
    /// A record's channels differ in length or count.
    #[error("record shape: {0}")]
    Record(&'static str),
}

/// The data vector of the local models: order, delays, scheduling, offset.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MisoStructure {
    /// ARX order n (1..=3).
    pub order: usize,
    /// Delay d_j in samples of each input j (its first regressor is u_j(k - d_j)).
    pub delays: Vec<usize>,
    /// Per-unit delays d_{i,j} overriding `delays` (E.4.7: psi_i = \[u(t - T_d,i), ..\],
    /// the delay of Table E.1 at unit i's angle); empty: every unit uses `delays`.
    pub unit_delays: Vec<Vec<usize>>,
    /// Which input channel schedules: phi_k = u_s(k - `scheduling_delay`). Channels
    /// `0..delays.len()` are the data vector's inputs; a record may carry further channels
    /// that only schedule (E.4.7: the voltage in the data vector, scheduled on the angle).
    pub scheduling_input: usize,
    /// Delay of the scheduling variable, samples.
    pub scheduling_delay: usize,
    /// A second scheduling variable (channel, delay): the scheduling vector
    /// phi = \[u_s(k - d_s), u_s2(k - d_s2)\] of eq. E.1 over tensor-product B-splines
    /// ([`MisoArx::tensor`]); `None`: one-dimensional scheduling (eq. E.2).
    pub scheduling2: Option<(usize, usize)>,
    /// Whether each local model has an offset c_i (eq. 2.24's d).
    pub offset: bool,
}

impl MisoStructure {
    /// Number of inputs.
    pub fn inputs(&self) -> usize {
        self.delays.len()
    }

    /// Regressors per local model (length of psi).
    pub fn regressors(&self) -> usize {
        (self.inputs() + 1) * self.order + usize::from(self.offset)
    }

    /// Index in psi of b_{j,l}.
    pub fn b_index(&self, j: usize, l: usize) -> usize {
        j * self.order + l
    }

    /// Index in psi of -a_l (l = 1..=n).
    pub fn a_index(&self, l: usize) -> usize {
        self.inputs() * self.order + l - 1
    }

    /// Checks the order and the inputs.
    pub fn validate(&self) -> Result<(), MisoError> {
        if !(1..=MAX_ARX_ORDER).contains(&self.order) {
            return Err(MisoError::Order(self.order));
        }
        if self.delays.is_empty() {
            return Err(MisoError::Inputs);
        }
        if self
            .unit_delays
            .iter()
            .any(|d| d.len() != self.delays.len())
        {
            return Err(MisoError::Record(
                "every unit's delays must name one delay per input",
            ));
        }
        Ok(())
    }

    /// u_j at sample k (k may be negative: the first value, module docs).
    #[inline]
    fn input(u: &[f64], k: isize) -> f64 {
        if k <= 0 { u[0] } else { u[k as usize] }
    }

    /// The second scheduling variable, if any.
    #[inline]
    pub fn phi2(&self, u: &[&[f64]], k: usize) -> Option<f64> {
        self.scheduling2
            .map(|(c, d)| Self::input(u[c], k as isize - d as isize))
    }

    /// The scheduling variable phi_k = u_s(k - d_s).
    #[inline]
    pub fn phi(&self, u: &[&[f64]], k: usize) -> f64 {
        Self::input(
            u[self.scheduling_input],
            k as isize - self.scheduling_delay as isize,
        )
    }

    /// The delay of input j in unit i's data vector.
    #[inline]
    pub fn delay(&self, unit: usize, j: usize) -> usize {
        self.unit_delays
            .get(unit)
            .and_then(|d| d.get(j))
            .copied()
            .unwrap_or(self.delays[j])
    }

    /// Fills the input and offset entries of unit i's psi_k (the outputs are filled by the
    /// caller).
    #[inline]
    fn fill_inputs<S: Scalar>(&self, u: &[&[f64]], k: usize, unit: usize, psi: &mut [S]) {
        let n = self.order;
        for (j, uj) in u.iter().enumerate().take(self.inputs()) {
            let dj = self.delay(unit, j);
            for l in 0..n {
                let kk = k as isize - dj as isize - l as isize;
                psi[j * n + l] = S::from_f64(Self::input(uj, kk));
            }
        }
        if self.offset {
            psi[self.regressors() - 1] = S::one();
        }
    }

    /// Unit i's regressor psi_k with measured outputs (one-step prediction, eq. B.4), for
    /// building least-squares problems (B.2).
    pub fn regressor(&self, u: &[&[f64]], y: &[f64], k: usize, unit: usize, psi: &mut [f64]) {
        self.fill_inputs(u, k, unit, psi);
        for l in 1..=self.order {
            psi[self.a_index(l)] = Self::input(y, k as isize - l as isize);
        }
    }

    /// Checks that a record's channels fit: one per input of the data vector (and the
    /// scheduling channel), all as long as the output and not empty.
    pub fn check_record(&self, u: &[&[f64]], y_len: usize) -> Result<(), MisoError> {
        let second = self.scheduling2.map_or(0, |(c, _)| c);
        if u.len() < self.inputs() || u.len() <= self.scheduling_input || u.len() <= second {
            return Err(MisoError::Record(
                "a channel per input of the data vector and the scheduling channel are needed",
            ));
        }
        if y_len == 0 {
            return Err(MisoError::Record("the record is empty"));
        }
        if u.iter().any(|c| c.len() != y_len) {
            return Err(MisoError::Record(
                "input and output channels differ in length",
            ));
        }
        Ok(())
    }
}

/// A network of multi-input ARX local models (module docs), parameters theta in `S`.
#[derive(Debug, Clone, PartialEq)]
pub struct MisoArx<S = f64> {
    /// Sampling period, s.
    pub ts: f64,
    /// The data vector.
    pub structure: MisoStructure,
    /// The validity functions over phi (the first scheduling variable).
    pub validity: ValidityFunctions<f64>,
    /// The validity functions over the second scheduling variable (eq. E.1): unit
    /// i = i_1 M_2 + i_2 has rho_i = rho_{i_1}(phi_1) rho_{i_2}(phi_2), a partition of unity
    /// again (tensor-product B-splines, Johansen and Foss 1995).
    pub validity2: Option<ValidityFunctions<f64>>,
    /// theta_0, theta_1, ... concatenated (units x regressors).
    pub theta: Vec<S>,
}

/// One local (or interpolated) model in its polynomials.
#[derive(Debug, Clone, PartialEq)]
pub struct MisoLocal {
    /// a_1..a_n of A(q^-1) = 1 + a_1 q^-1 + ...
    pub a: Vec<f64>,
    /// b_{j,0..n-1} per input j.
    pub b: Vec<Vec<f64>>,
    /// Offset c.
    pub c: f64,
}

impl MisoLocal {
    /// The input-j model as a single-input [`ArxUnit`] (shift form), for the shared
    /// analysis code.
    pub fn arx_unit(&self, j: usize) -> ArxUnit<f64> {
        let mut u = ArxUnit::zero();
        u.a[..self.a.len()].copy_from_slice(&self.a);
        u.b[..self.b[j].len()].copy_from_slice(&self.b[j]);
        u.d = self.c;
        u
    }

    /// Steady-state gain from input j, B_j(1) / A(1) (eq. A.38); `None` if A(1) = 0.
    pub fn gain(&self, j: usize) -> Option<f64> {
        shift_gain(&self.arx_unit(j), self.a.len())
    }

    /// Poles: roots of z^n + a_1 z^{n-1} + ... + a_n.
    pub fn poles(&self) -> Vec<Complex<f64>> {
        shift_poles(&self.arx_unit(0), self.a.len())
    }
}

impl<S> MisoArx<S> {
    /// The same network with parameters `theta`, in any scalar type (a candidate of the
    /// identification, e.g. with dual numbers for its derivatives).
    pub fn with_params<T>(&self, theta: Vec<T>) -> MisoArx<T> {
        MisoArx {
            ts: self.ts,
            structure: self.structure.clone(),
            validity: self.validity,
            validity2: self.validity2,
            theta,
        }
    }
}

impl<S: Scalar> MisoArx<S> {
    /// A network; theta must hold units x regressors entries.
    pub fn new(
        ts: f64,
        structure: MisoStructure,
        validity: ValidityFunctions<f64>,
        theta: Vec<S>,
    ) -> Result<Self, MisoError> {
        if structure.scheduling2.is_some() {
            return Err(MisoError::Record(
                "a second scheduling variable needs its validity functions (MisoArx::tensor)",
            ));
        }
        Self::build(ts, structure, validity, None, theta)
    }

    /// A network scheduled on two variables (eq. E.1) over the tensor product of
    /// `validity` (first) and `validity2` (second, `structure.scheduling2`).
    pub fn tensor(
        ts: f64,
        structure: MisoStructure,
        validity: ValidityFunctions<f64>,
        validity2: ValidityFunctions<f64>,
        theta: Vec<S>,
    ) -> Result<Self, MisoError> {
        if structure.scheduling2.is_none() {
            return Err(MisoError::Record(
                "tensor-product validity functions need a second scheduling variable",
            ));
        }
        Self::build(ts, structure, validity, Some(validity2), theta)
    }

    fn build(
        ts: f64,
        structure: MisoStructure,
        validity: ValidityFunctions<f64>,
        validity2: Option<ValidityFunctions<f64>>,
        theta: Vec<S>,
    ) -> Result<Self, MisoError> {
        structure.validate()?;
        if !(ts.is_finite() && ts > 0.0) {
            return Err(MisoError::SamplingPeriod(ts));
        }
        let units = validity.units() * validity2.map_or(1, |v| v.units());
        if !structure.unit_delays.is_empty() && structure.unit_delays.len() != units {
            return Err(MisoError::Record("unit_delays needs one entry per unit"));
        }
        let expected = units * structure.regressors();
        if theta.len() != expected {
            return Err(MisoError::Theta {
                got: theta.len(),
                expected,
            });
        }
        Ok(Self {
            ts,
            structure,
            validity,
            validity2,
            theta,
        })
    }

    /// Number of units M (M_1 M_2 with two scheduling variables).
    pub fn units(&self) -> usize {
        self.validity.units() * self.validity2.map_or(1, |v| v.units())
    }

    /// The active units and their weights at (phi_1, phi_2): at most 3 x 3 (units,
    /// count). With one scheduling variable `phi2` is ignored; with two and `phi2` `None`
    /// the second is taken at the middle of its range.
    pub fn activation_at(&self, phi: f64, phi2: Option<f64>) -> ([(usize, f64); 9], usize) {
        let mut out = [(0, 0.0); 9];
        let mut n = 0;
        let a1 = self.validity.eval(phi);
        match &self.validity2 {
            None => {
                for (i, r) in a1.iter() {
                    out[n] = (i, r);
                    n += 1;
                }
            }
            Some(v2) => {
                let (lo, hi) = v2.valid_range();
                let a2 = v2.eval(phi2.unwrap_or(0.5 * (lo + hi)));
                let m2 = v2.units();
                for (i1, r1) in a1.iter() {
                    for (i2, r2) in a2.iter() {
                        out[n] = (i1 * m2 + i2, r1 * r2);
                        n += 1;
                    }
                }
            }
        }
        (out, n)
    }

    /// The active units and their weights at sample k of a record.
    pub fn activations(&self, u: &[&[f64]], k: usize) -> ([(usize, f64); 9], usize) {
        let st = &self.structure;
        self.activation_at(st.phi(u, k), st.phi2(u, k))
    }

    /// theta_i.
    pub fn unit(&self, i: usize) -> &[S] {
        let r = self.structure.regressors();
        &self.theta[i * r..(i + 1) * r]
    }

    /// y_k = sum_i rho_i(phi_k) psi_{i,k}' theta_i with the outputs `past` =
    /// \[y_{k-1}, .., y_{k-n}\] in the data vector.
    #[inline]
    fn output_k(&self, u: &[&[f64]], k: usize, past: &[S], psi: &mut [S]) -> S {
        let st = &self.structure;
        for l in 1..=st.order {
            psi[st.a_index(l)] = past[l - 1];
        }
        let (act, n) = self.activations(u, k);
        let mut y = S::zero();
        for &(i, rho) in &act[..n] {
            st.fill_inputs(u, k, i, psi);
            let mut yi = S::zero();
            for (p, t) in psi.iter().zip(self.unit(i)) {
                yi += *p * *t;
            }
            y += yi * rho;
        }
        y
    }

    /// Free-run simulation (eq. B.6/B.7) over inputs `u` (one slice per channel), the
    /// model's own past outputs in psi; `y0` is the output before the record (module docs).
    pub fn simulate(&self, u: &[&[f64]], y0: f64, out: &mut [S]) -> Result<(), MisoError> {
        let st = &self.structure;
        st.check_record(u, out.len())?;
        let mut psi = alloc::vec![S::zero(); st.regressors()];
        let mut past = [S::from_f64(y0); MAX_ARX_ORDER];
        for (k, o) in out.iter_mut().enumerate() {
            let y = self.output_k(u, k, &past, &mut psi);
            *o = y;
            for l in (1..MAX_ARX_ORDER).rev() {
                past[l] = past[l - 1];
            }
            past[0] = y;
        }
        Ok(())
    }

    /// One output y_k of a free run, given the input channels up to sample k - 1 (at least)
    /// and the model's own past outputs `y_past` = \[y_{k-1}, .., y_{k-n}\] (closed-loop
    /// simulation, one sample at a time).
    pub fn output_at(&self, u: &[&[f64]], y_past: &[S], k: usize) -> S {
        let mut psi = alloc::vec![S::zero(); self.structure.regressors()];
        self.output_k(u, k, y_past, &mut psi)
    }

    /// One-step-ahead prediction (eq. B.4) from the measured outputs `y`.
    pub fn predict(&self, u: &[&[f64]], y: &[f64], out: &mut [S]) -> Result<(), MisoError> {
        let st = &self.structure;
        st.check_record(u, y.len())?;
        if out.len() != y.len() {
            return Err(MisoError::Record("prediction and output differ in length"));
        }
        let mut psi = alloc::vec![S::zero(); st.regressors()];
        let mut past = [S::zero(); MAX_ARX_ORDER];
        for (k, o) in out.iter_mut().enumerate() {
            for (l, p) in past.iter_mut().enumerate().take(st.order) {
                *p = S::from_f64(MisoStructure::input(y, k as isize - 1 - l as isize));
            }
            *o = self.output_k(u, k, &past, &mut psi);
        }
        Ok(())
    }
}

impl MisoArx<f64> {
    /// Local model i in its polynomials.
    pub fn local(&self, i: usize) -> MisoLocal {
        self.polynomials(self.unit(i))
    }

    /// The interpolated model frozen at phi (eq. 2.26): sum_i rho_i(phi) theta_i (a second
    /// scheduling variable at the middle of its range, [`Self::activation_at`]).
    pub fn frozen(&self, phi: f64) -> MisoLocal {
        self.frozen_at(phi, None)
    }

    /// The interpolated model frozen at (phi_1, phi_2).
    pub fn frozen_at(&self, phi: f64, phi2: Option<f64>) -> MisoLocal {
        let r = self.structure.regressors();
        let (act, n) = self.activation_at(phi, phi2);
        let mut t = alloc::vec![0.0; r];
        for &(i, rho) in &act[..n] {
            for (a, b) in t.iter_mut().zip(self.unit(i)) {
                *a += rho * b;
            }
        }
        self.polynomials(&t)
    }

    /// The frozen model's input j as one B polynomial over the delays of every unit:
    /// (d_min, taps) with y_k = .. + sum_t taps\[t\] u_j(k - d_min - t) (per-unit delays
    /// make the interpolated model's B span several delays).
    pub fn frozen_input_taps(&self, phi: f64, j: usize) -> (usize, Vec<f64>) {
        let st = &self.structure;
        let (act, n) = self.activation_at(phi, None);
        let d_min = (0..self.units()).map(|i| st.delay(i, j)).min().unwrap_or(0);
        let d_max = (0..self.units()).map(|i| st.delay(i, j)).max().unwrap_or(0);
        let mut taps = alloc::vec![0.0; d_max - d_min + st.order];
        for &(i, rho) in &act[..n] {
            let off = st.delay(i, j) - d_min;
            for l in 0..st.order {
                taps[off + l] += rho * self.unit(i)[st.b_index(j, l)];
            }
        }
        (d_min, taps)
    }

    fn polynomials(&self, t: &[f64]) -> MisoLocal {
        let st = &self.structure;
        MisoLocal {
            a: (1..=st.order).map(|l| -t[st.a_index(l)]).collect(),
            b: (0..st.inputs())
                .map(|j| (0..st.order).map(|l| t[st.b_index(j, l)]).collect())
                .collect(),
            c: if st.offset {
                t[st.regressors() - 1]
            } else {
                0.0
            },
        }
    }
}
