//! The free parameters of a model as one flat vector theta (for identification, 2.3.2, B.3).
//!
//! [`ParamLayout`] fixes the order of the parameters for a structure; [`ParamLayout::network`]
//! builds the run-time network from theta in any [`Scalar`] through the parameterisation maps
//! (so `Dual` theta gives exact Jacobians), and [`ParamLayout::theta`] /
//! [`ParamLayout::apply`] convert between a model and theta.
//!
//! Per unit i, in this order (bracketed entries only when `zero_offsets` is false):
//! - `ss-direct`: a00 a01 a10 a11 b0 b1 c0 c1 [dx0 dx1 dy]
//! - `ss-eig-local`: eta0 eta1 theta0 theta1 b0 b1 c0 c1 [dx0 dx1 dy], e_j =
//!   [`super::local_model::eigenvalue_from_eta`]`(eta_j)`, theta_j the
//!   eigenvector angles
//! - `ss-eig-common`: eta0 eta1 b0 b1 c0 c1 [dx0 dx1 dy], without b0 b1 for the reference unit
//!   (fixed at (1, 1), the gauge)
//! - `arx-shift`: b_0..b_{n-1}, -a_1..-a_n, \[d\]: the thesis's Theta' (eq. A.30b), so that
//!   y = psi'^T Theta' is linear in theta (prediction-mode least squares, B.2)
//! - `arx-delta`: beta_0..beta_{n-1}, -alpha_0..-alpha_{n-1}, \[d\]
//!
//! The knots are not in theta; pass them separately (as `Dual` variables for knot
//! optimisation, 5.4.2).

use super::arx::{ArxUnit, delta_to_shift};
use super::lmn::{Lmn, LmnError, LocalModelSet, Structure};
use super::local_model::{
    EigCommonUnit, EigLocalUnit, SsLocalModel, eigenvalue_from_eta, eta_from_eigenvalue,
};
use super::network::Network;
use super::scheduling::Scheduler;
use super::validity::ValidityFunctions;
use crate::num::Scalar;
use alloc::{format, string::String, vec::Vec};

/// Why theta could not be mapped.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ParamError {
    /// theta has the wrong length.
    #[error("theta has {got} entries, the layout has {expected}")]
    Length {
        /// Given.
        got: usize,
        /// Expected.
        expected: usize,
    },
    /// An eigenvalue has no eta (outside (-1/Ts, 0)).
    #[error("units[{unit}].eigenvalues[{index}] = {value} is outside (-1/Ts, 0): no eta exists")]
    Eigenvalue {
        /// Unit.
        unit: usize,
        /// 0 or 1.
        index: usize,
        /// The eigenvalue.
        value: f64,
    },
    /// The eigenvector angles give parallel eigenvectors.
    #[error("unit {unit}: eigenvector angles give parallel eigenvectors")]
    ParallelEigenvectors {
        /// Unit.
        unit: usize,
    },
    /// The model or network is invalid.
    #[error(transparent)]
    Model(#[from] LmnError),
    /// Knots invalid.
    #[error("knots: {0}")]
    Knots(#[from] super::validity::ValidityError),
    /// Network construction failed.
    #[error(transparent)]
    Network(#[from] super::network::NetworkError),
}

/// The parameter layout of a model (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct ParamLayout {
    structure: Structure,
    units: usize,
    zero_offsets: bool,
    reference_unit: usize,
    arx_order: usize,
    ts: f64,
    names: Vec<String>,
    offsets: Vec<usize>,
}

impl ParamLayout {
    /// The layout for a model's structure, size and options.
    pub fn new(lmn: &Lmn) -> Self {
        let structure = lmn.structure();
        let units = lmn.units();
        let zo = lmn.zero_offsets;
        let (reference_unit, arx_order) = match &lmn.local {
            LocalModelSet::SsEigCommon { reference_unit, .. } => (*reference_unit, 0),
            LocalModelSet::ArxShift { order, .. } | LocalModelSet::ArxDelta { order, .. } => {
                (0, *order)
            }
            _ => (0, 0),
        };
        let mut names = Vec::new();
        let mut offsets = Vec::with_capacity(units + 1);
        for i in 0..units {
            offsets.push(names.len());
            let mut add = |n: &str| names.push(format!("units[{i}].{n}"));
            match structure {
                Structure::SsDirect => {
                    for n in ["a00", "a01", "a10", "a11"] {
                        add(n);
                    }
                }
                Structure::SsEigLocal => {
                    for n in ["eta0", "eta1", "angle0", "angle1"] {
                        add(n);
                    }
                }
                Structure::SsEigCommon => {
                    add("eta0");
                    add("eta1");
                }
                Structure::ArxShift | Structure::ArxDelta => {
                    for l in 0..arx_order {
                        add(&format!("b{l}"));
                    }
                    let a0 = if structure == Structure::ArxShift {
                        1
                    } else {
                        0
                    };
                    for l in 0..arx_order {
                        add(&format!("neg_a{}", l + a0));
                    }
                    if !zo {
                        add("d");
                    }
                    continue;
                }
            }
            if !(structure == Structure::SsEigCommon && i == reference_unit) {
                add("b0");
                add("b1");
            }
            add("c0");
            add("c1");
            if !zo {
                for n in ["dx0", "dx1", "dy"] {
                    add(n);
                }
            }
        }
        offsets.push(names.len());
        Self {
            structure,
            units,
            zero_offsets: zo,
            reference_unit,
            arx_order,
            ts: lmn.ts,
            names,
            offsets,
        }
    }

    /// Number of parameters.
    pub fn len(&self) -> usize {
        self.names.len()
    }

    /// True when there are no parameters.
    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }

    /// Parameter names, e.g. `units[2].eta1`.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// The index range of unit i's parameters in theta.
    pub fn unit_range(&self, i: usize) -> core::ops::Range<usize> {
        self.offsets[i]..self.offsets[i + 1]
    }

    /// theta of a model with this layout.
    pub fn theta(&self, lmn: &Lmn) -> Result<Vec<f64>, ParamError> {
        let mut t = Vec::with_capacity(self.len());
        let zo = self.zero_offsets;
        let ts = self.ts;
        let push_ss =
            |t: &mut Vec<f64>, b: Option<[f64; 2]>, c: [f64; 2], dx: [f64; 2], dy: f64| {
                if let Some(b) = b {
                    t.extend_from_slice(&b);
                }
                t.extend_from_slice(&c);
                if !zo {
                    t.extend_from_slice(&[dx[0], dx[1], dy]);
                }
            };
        let eta = |unit: usize, e: [f64; 2]| -> Result<[f64; 2], ParamError> {
            let f = |index: usize| {
                eta_from_eigenvalue(e[index], ts).ok_or(ParamError::Eigenvalue {
                    unit,
                    index,
                    value: e[index],
                })
            };
            Ok([f(0)?, f(1)?])
        };
        match &lmn.local {
            LocalModelSet::SsDirect(u) => {
                for m in u {
                    t.extend_from_slice(&[m.a[0][0], m.a[0][1], m.a[1][0], m.a[1][1]]);
                    push_ss(&mut t, Some(m.b), m.c, m.dx, m.dy);
                }
            }
            LocalModelSet::SsEigLocal(u) => {
                for (i, m) in u.iter().enumerate() {
                    t.extend_from_slice(&eta(i, m.eigenvalues)?);
                    t.extend_from_slice(&m.eigenvector_angles);
                    push_ss(&mut t, Some(m.b), m.c, m.dx, m.dy);
                }
            }
            LocalModelSet::SsEigCommon {
                units,
                reference_unit,
            } => {
                for (i, m) in units.iter().enumerate() {
                    t.extend_from_slice(&eta(i, m.eigenvalues)?);
                    push_ss(
                        &mut t,
                        (i != *reference_unit).then_some(m.b),
                        m.c,
                        m.dx,
                        m.dy,
                    );
                }
            }
            LocalModelSet::ArxShift { order, units } | LocalModelSet::ArxDelta { order, units } => {
                for m in units {
                    t.extend_from_slice(&m.b[..*order]);
                    t.extend(m.a[..*order].iter().map(|a| -a));
                    if !zo {
                        t.push(m.d);
                    }
                }
            }
        }
        Ok(t)
    }

    /// The model with its parameters replaced by theta (eigenvalues re-derived from eta).
    pub fn apply(&self, lmn: &Lmn, theta: &[f64]) -> Result<Lmn, ParamError> {
        self.check_len(theta.len())?;
        let mut out = lmn.clone();
        out.local = match self.structure {
            Structure::SsDirect => LocalModelSet::SsDirect(self.ss_direct(theta)),
            Structure::SsEigLocal => LocalModelSet::SsEigLocal(self.ss_eig_local(theta)),
            Structure::SsEigCommon => LocalModelSet::SsEigCommon {
                units: self.ss_eig_common(theta),
                reference_unit: self.reference_unit,
            },
            Structure::ArxShift => LocalModelSet::ArxShift {
                order: self.arx_order,
                units: self.arx(theta),
            },
            Structure::ArxDelta => LocalModelSet::ArxDelta {
                order: self.arx_order,
                units: self.arx(theta),
            },
        };
        Ok(out)
    }

    /// The run-time network for theta (and optionally other knots), generic over the scalar:
    /// with `Dual` theta/knots the network's outputs carry exact derivatives.
    pub fn network<S: Scalar>(
        &self,
        lmn: &Lmn,
        theta: &[S],
        knots: Option<&[S]>,
    ) -> Result<Network<S>, ParamError> {
        self.check_len(theta.len())?;
        let validity = match knots {
            Some(k) => ValidityFunctions::from_knots(k, lmn.validity.order())?,
            None => lmn.validity.cast(|_, k| S::from_f64(k)),
        };
        let scheduler = Scheduler::new(&lmn.scheduling, lmn.ts).map_err(LmnError::Scheduling)?;
        let net = match self.structure {
            Structure::SsDirect => Network::state_space(
                lmn.ts,
                lmn.delay,
                validity,
                scheduler,
                &self.ss_direct(theta),
            )?,
            Structure::SsEigLocal => {
                let units = self
                    .ss_eig_local(theta)
                    .iter()
                    .enumerate()
                    .map(|(unit, u)| {
                        u.to_local_model()
                            .ok_or(ParamError::ParallelEigenvectors { unit })
                    })
                    .collect::<Result<Vec<_>, _>>()?;
                Network::state_space(lmn.ts, lmn.delay, validity, scheduler, &units)?
            }
            Structure::SsEigCommon => {
                let units: Vec<_> = self
                    .ss_eig_common(theta)
                    .iter()
                    .map(|u| u.to_local_model())
                    .collect();
                Network::state_space(lmn.ts, lmn.delay, validity, scheduler, &units)?
            }
            Structure::ArxShift => Network::arx(
                lmn.ts,
                lmn.delay,
                validity,
                scheduler,
                self.arx_order,
                &self.arx(theta),
            )?,
            Structure::ArxDelta => {
                let units: Vec<_> = self
                    .arx(theta)
                    .iter()
                    .map(|u| delta_to_shift(u, self.arx_order, lmn.ts))
                    .collect();
                Network::arx(
                    lmn.ts,
                    lmn.delay,
                    validity,
                    scheduler,
                    self.arx_order,
                    &units,
                )?
            }
        };
        Ok(net)
    }

    fn check_len(&self, got: usize) -> Result<(), ParamError> {
        if got != self.len() {
            return Err(ParamError::Length {
                got,
                expected: self.len(),
            });
        }
        Ok(())
    }

    /// Reads b (unless fixed), c and the offsets from `t` at `*k`.
    fn ss_tail<S: Scalar>(
        &self,
        t: &[S],
        k: &mut usize,
        fixed_b: bool,
    ) -> ([S; 2], [S; 2], [S; 2], S) {
        let mut next = || {
            let v = t[*k];
            *k += 1;
            v
        };
        let b = if fixed_b {
            [S::one(), S::one()]
        } else {
            [next(), next()]
        };
        let c = [next(), next()];
        let (dx, dy) = if self.zero_offsets {
            ([S::zero(); 2], S::zero())
        } else {
            ([next(), next()], next())
        };
        (b, c, dx, dy)
    }

    fn ss_direct<S: Scalar>(&self, t: &[S]) -> Vec<SsLocalModel<S>> {
        (0..self.units)
            .map(|i| {
                let mut k = self.offsets[i];
                let a = [[t[k], t[k + 1]], [t[k + 2], t[k + 3]]];
                k += 4;
                let (b, c, dx, dy) = self.ss_tail(t, &mut k, false);
                SsLocalModel { a, b, c, dx, dy }
            })
            .collect()
    }

    /// The two eigenvalues a unit's parameters `t[k]`, `t[k + 1]` (eta_1, eta_2) stand for.
    fn eigenvalues<S: Scalar>(&self, t: &[S], k: usize) -> [S; 2] {
        [t[k], t[k + 1]].map(|eta| eigenvalue_from_eta(eta, self.ts))
    }

    fn ss_eig_local<S: Scalar>(&self, t: &[S]) -> Vec<EigLocalUnit<S>> {
        (0..self.units)
            .map(|i| {
                let mut k = self.offsets[i];
                let eigenvalues = self.eigenvalues(t, k);
                let eigenvector_angles = [t[k + 2], t[k + 3]];
                k += 4;
                let (b, c, dx, dy) = self.ss_tail(t, &mut k, false);
                EigLocalUnit {
                    eigenvalues,
                    eigenvector_angles,
                    b,
                    c,
                    dx,
                    dy,
                }
            })
            .collect()
    }

    fn ss_eig_common<S: Scalar>(&self, t: &[S]) -> Vec<EigCommonUnit<S>> {
        (0..self.units)
            .map(|i| {
                let mut k = self.offsets[i];
                let eigenvalues = self.eigenvalues(t, k);
                k += 2;
                let (b, c, dx, dy) = self.ss_tail(t, &mut k, i == self.reference_unit);
                EigCommonUnit {
                    eigenvalues,
                    b,
                    c,
                    dx,
                    dy,
                }
            })
            .collect()
    }

    fn arx<S: Scalar>(&self, t: &[S]) -> Vec<ArxUnit<S>> {
        let n = self.arx_order;
        (0..self.units)
            .map(|i| {
                let k = self.offsets[i];
                let mut u = ArxUnit::zero();
                for l in 0..n {
                    u.b[l] = t[k + l];
                    u.a[l] = -t[k + n + l];
                }
                u.d = if self.zero_offsets {
                    S::zero()
                } else {
                    t[k + 2 * n]
                };
                u
            })
            .collect()
    }
}
