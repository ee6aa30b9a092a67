//! State-space local models with several inputs, in their real eigensystem (thesis 2.2.2,
//! eq. 2.13-2.16 in the delta domain, App. D.2.2; eq. E.4: A_i = V_i diag(e_i) V_i^-1),
//! scheduled on a measured input: Example E.4.5 on the heat-transfer process.
//!
//! Local model i (delta domain, per input j a delay d_j):
//!
//! x_{k+1} = x_k + Ts (A_i x_k + sum_j b_{i,j} u_j(k - d_j) + dx_i), y_k = c_i' x_k + dy_i,
//!
//! and the network interpolates A, b, c, dx, dy with rho_i(phi_k) (eq. 2.16),
//! phi_k = u_s(k - d_s). The eigenvalues come from unbounded parameters eta
//! ([`super::local_model::eigenvalue_from_eta`]: real, inside (-1/Ts, 0), every local model
//! stable by construction) and the eigenvectors from angles
//! ([`super::local_model::eigenvector_matrix`]), per unit (**general**) or shared by every
//! unit (**restricted**, common eigenvectors: 2.4.1, a network that is stable for any
//! scheduling).
//!
//! The parameter vector theta: the two common angles first (restricted only), then per
//! unit eta_0, eta_1, the two angles (general only), b_{j,0}, b_{j,1} for every input j,
//! c_0, c_1, dx_0, dx_1, dy.
//!
//! A record starts in the steady state of the model frozen at the first scheduling value
//! with the first inputs (the records of App. E.2 start with the plant running).

use super::local_model::{a_from_eigensystem, eigenvalue_from_eta, eigenvector_matrix, solve2};
use super::miso::MisoError;
use super::validity::ValidityFunctions;
use crate::num::Scalar;
use alloc::{vec, vec::Vec};

/// Eigenvectors per unit or common to all (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Eigenvectors {
    /// Each unit its own (the general model).
    Local,
    /// One pair for every unit (the restricted model).
    Common,
}

/// One local model with its matrices.
#[derive(Debug, Clone, PartialEq)]
pub struct SsUnit<S> {
    /// A (delta domain).
    pub a: [[S; 2]; 2],
    /// b_j per input.
    pub b: Vec<[S; 2]>,
    /// c.
    pub c: [S; 2],
    /// dx.
    pub dx: [S; 2],
    /// dy.
    pub dy: S,
}

/// A multi-input state-space network in eigensystem form (module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct MisoSs<S = f64> {
    /// Sampling period, s.
    pub ts: f64,
    /// Input delays d_j, samples.
    pub delays: Vec<usize>,
    /// The channel that schedules.
    pub scheduling_input: usize,
    /// Its delay, samples.
    pub scheduling_delay: usize,
    /// The validity functions.
    pub validity: ValidityFunctions<f64>,
    /// General or restricted.
    pub eigenvectors: Eigenvectors,
    /// The parameters (module docs).
    pub theta: Vec<S>,
}

/// Parameters per unit for `inputs` inputs.
pub fn unit_params(inputs: usize, eigenvectors: Eigenvectors) -> usize {
    let angles = if eigenvectors == Eigenvectors::Local {
        2
    } else {
        0
    };
    2 + angles + 2 * inputs + 5
}

/// Length of theta.
pub fn theta_len(inputs: usize, units: usize, eigenvectors: Eigenvectors) -> usize {
    let common = if eigenvectors == Eigenvectors::Common {
        2
    } else {
        0
    };
    common + units * unit_params(inputs, eigenvectors)
}

impl<S> MisoSs<S> {
    /// The same network with parameters `theta`, in any scalar type (a candidate of the
    /// identification, e.g. with dual numbers for its derivatives).
    pub fn with_params<T>(&self, theta: Vec<T>) -> MisoSs<T> {
        MisoSs {
            ts: self.ts,
            delays: self.delays.clone(),
            scheduling_input: self.scheduling_input,
            scheduling_delay: self.scheduling_delay,
            validity: self.validity,
            eigenvectors: self.eigenvectors,
            theta,
        }
    }
}

impl<S: Scalar> MisoSs<S> {
    /// Number of inputs in the data vector.
    pub fn inputs(&self) -> usize {
        self.delays.len()
    }

    /// Checks theta's length and the delays.
    pub fn validate(&self) -> Result<(), MisoError> {
        if self.delays.is_empty() {
            return Err(MisoError::Inputs);
        }
        if !(self.ts.is_finite() && self.ts > 0.0) {
            return Err(MisoError::SamplingPeriod(self.ts));
        }
        let expected = theta_len(self.inputs(), self.validity.units(), self.eigenvectors);
        if self.theta.len() != expected {
            return Err(MisoError::Theta {
                got: self.theta.len(),
                expected,
            });
        }
        Ok(())
    }

    /// Offset of unit i's parameters in theta.
    fn offset(&self, i: usize) -> usize {
        let common = if self.eigenvectors == Eigenvectors::Common {
            2
        } else {
            0
        };
        common + i * unit_params(self.inputs(), self.eigenvectors)
    }

    /// Local model i; `None` if its eigenvectors are parallel.
    pub fn unit(&self, i: usize) -> Option<SsUnit<S>> {
        let t = &self.theta;
        let mut k = self.offset(i);
        let e = [
            eigenvalue_from_eta(t[k], self.ts),
            eigenvalue_from_eta(t[k + 1], self.ts),
        ];
        k += 2;
        let angles = match self.eigenvectors {
            Eigenvectors::Local => {
                k += 2;
                [t[k - 2], t[k - 1]]
            }
            Eigenvectors::Common => [t[0], t[1]],
        };
        let a = a_from_eigensystem(&eigenvector_matrix(angles), e)?;
        let b = (0..self.inputs())
            .map(|j| [t[k + 2 * j], t[k + 2 * j + 1]])
            .collect();
        k += 2 * self.inputs();
        Some(SsUnit {
            a,
            b,
            c: [t[k], t[k + 1]],
            dx: [t[k + 2], t[k + 3]],
            dy: t[k + 4],
        })
    }

    /// Every local model; `None` if one has parallel eigenvectors.
    pub fn units(&self) -> Option<Vec<SsUnit<S>>> {
        (0..self.validity.units()).map(|i| self.unit(i)).collect()
    }

    /// The interpolated model at phi.
    fn interpolate(&self, units: &[SsUnit<S>], phi: f64) -> SsUnit<S> {
        let z = S::zero();
        let mut m = SsUnit {
            a: [[z; 2]; 2],
            b: vec![[z; 2]; self.inputs()],
            c: [z; 2],
            dx: [z; 2],
            dy: z,
        };
        for (i, rho) in self.validity.eval(phi).iter() {
            let u = &units[i];
            for r in 0..2 {
                for c in 0..2 {
                    m.a[r][c] += u.a[r][c] * rho;
                }
                m.c[r] += u.c[r] * rho;
                m.dx[r] += u.dx[r] * rho;
                for (mb, ub) in m.b.iter_mut().zip(&u.b) {
                    mb[r] += ub[r] * rho;
                }
            }
            m.dy += u.dy * rho;
        }
        m
    }

    /// Free-run simulation over the channels `u` (module docs for the start).
    pub fn simulate(&self, u: &[&[f64]], out: &mut [S]) -> Result<(), MisoError> {
        self.validate()?;
        if u.len() < self.inputs() || u.len() <= self.scheduling_input {
            return Err(MisoError::Record(
                "a channel per input and the scheduling channel are needed",
            ));
        }
        if out.is_empty() || u.iter().any(|c| c.len() != out.len()) {
            return Err(MisoError::Record("channels differ in length or are empty"));
        }
        let units = self.units().ok_or(MisoError::Record(
            "a unit's eigenvectors are parallel (V is singular)",
        ))?;
        let at = |c: &[f64], k: isize| if k <= 0 { c[0] } else { c[k as usize] };
        let phi = |k: usize| {
            at(
                u[self.scheduling_input],
                k as isize - self.scheduling_delay as isize,
            )
        };
        let input = |m: &SsUnit<S>, k: usize| {
            let mut v = m.dx;
            for (j, b) in m.b.iter().enumerate() {
                let uj = at(u[j], k as isize - self.delays[j] as isize);
                v[0] += b[0] * uj;
                v[1] += b[1] * uj;
            }
            v
        };
        // Steady state at the start: A x + B u_0 + dx = 0.
        let m0 = self.interpolate(&units, phi(0));
        let r = input(&m0, 0);
        let mut x = solve2(&m0.a, [-r[0], -r[1]])
            .ok_or(MisoError::Record("the start model is singular"))?;
        for (k, o) in out.iter_mut().enumerate() {
            let m = self.interpolate(&units, phi(k));
            *o = m.c[0] * x[0] + m.c[1] * x[1] + m.dy;
            let v = input(&m, k);
            let ax = [
                m.a[0][0] * x[0] + m.a[0][1] * x[1],
                m.a[1][0] * x[0] + m.a[1][1] * x[1],
            ];
            x = [
                x[0] + (ax[0] + v[0]) * self.ts,
                x[1] + (ax[1] + v[1]) * self.ts,
            ];
        }
        Ok(())
    }
}
