//! The state estimator of the measured-force mode (thesis Fig. 6.6(a), C.2.2).
//!
//! The measured force `y[k]` is the plant output at time `k`; the model's core runs `d`
//! samples ahead (`z[k] = x[k+d]`). So the estimator works on the *delayed* model state
//! `x̂[k]` (the core state `d` samples ago, with its own scheduling pre-filter state) and
//! applies eq. (C.18) in the delta domain, with the local gains interpolated like the
//! controllers (`L(phi) = sum rho_i(phi) L_i`):
//!
//! ```text
//! x̂[k+1] = x̂[k] + Ts (A x̂[k] + b u[k-d] + dx) + Ts L(phi) (y[k] - ŷ[k]),   ŷ = c'x̂ + dy
//! ```
//!
//! The model part is the model library's own network step; only the correction term is
//! added here. The core state is then re-predicted from `x̂[k+1]` over the `d - 1` pulses
//! `u[k-d+1] .. u[k-1]` that are already decided (the network step again), giving
//! `z[k] = x̂[k+d]`: `d` calls of the network step per sample in all.
//!
//! A missing, non-finite or implausible measurement (|y| > [`MAX_MEASURED_FORCE`], in
//! normalised force units) skips the correction for that sample (the estimate runs open
//! loop) and is counted.

use crate::model::{Activation, CoreState, DelayLine, MAX_UNITS, Network, NetworkError};

/// Largest plausible |measured force| in normalised units (1 = the model's full force);
/// anything beyond is treated as a missing sample.
pub const MAX_MEASURED_FORCE: f64 = 10.0;

/// Why the estimator could not be built.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum EstimatorError {
    /// One estimator gain per unit is needed.
    #[error("{gains} estimator gains given for {units} local models")]
    UnitMismatch {
        /// Gains given.
        gains: usize,
        /// Units of the model.
        units: usize,
    },
    /// A gain is NaN or infinite.
    #[error("unit {unit}: estimator gain L is not finite")]
    NonFinite {
        /// Unit index.
        unit: usize,
    },
    /// The measured-force mode needs an input delay of at least one sample: with `d = 0`
    /// the measurement of `y[k]` and the decision of `u[k]` coincide.
    #[error("the measured-force mode needs an input delay d >= 1 sample (the model has d = 0)")]
    NoDelay,
    /// The network has no rest state.
    #[error(transparent)]
    Network(#[from] NetworkError),
}

/// Interpolable estimator gain `L`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct Gain([f64; 2]);

impl core::ops::Add for Gain {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        Self([self.0[0] + o.0[0], self.0[1] + o.0[1]])
    }
}

impl core::ops::Mul<f64> for Gain {
    type Output = Self;
    #[inline(always)]
    fn mul(self, r: f64) -> Self {
        Self([self.0[0] * r, self.0[1] * r])
    }
}

/// Result of one estimator update.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EstimatorUpdate {
    /// The model force at the measurement time, `ŷ[k]` (before the correction).
    pub model_force: f64,
    /// Innovation `y[k] - ŷ[k]` (0 when the measurement was missing).
    pub innovation: f64,
    /// Whether a valid measurement was used.
    pub measured: bool,
    /// The re-predicted core state `z[k] = x̂[k+d]`, with its scheduling state.
    pub core: CoreState<f64>,
}

/// The delayed state estimate and the pulses that are on their way to the plant.
#[derive(Debug, Clone, Copy)]
pub struct ForceEstimator {
    gains: [Gain; MAX_UNITS],
    /// `x̂[k]`: the model state at the measurement time (core state `d` samples ago).
    delayed: CoreState<f64>,
    /// The last `d` pulses `u[k-d] .. u[k-1]`, oldest first.
    pulses: DelayLine<f64>,
    initial_delayed: CoreState<f64>,
    missing: u64,
}

impl ForceEstimator {
    /// An estimator with local gains `L_i` (eq. C.21), starting at rest.
    pub fn new(net: &Network<f64>, gains: &[[f64; 2]]) -> Result<Self, EstimatorError> {
        if gains.len() != net.units() {
            return Err(EstimatorError::UnitMismatch {
                gains: gains.len(),
                units: net.units(),
            });
        }
        if net.delay() == 0 {
            return Err(EstimatorError::NoDelay);
        }
        if !net.can_run_ahead() {
            return Err(NetworkError::CannotRunAhead { delay: net.delay() }.into());
        }
        let mut g = [Gain::default(); MAX_UNITS];
        for (i, l) in gains.iter().enumerate() {
            if !l.iter().all(|v| v.is_finite()) {
                return Err(EstimatorError::NonFinite { unit: i });
            }
            g[i] = Gain(*l);
        }
        let rest = net.rest_state()?;
        let pulses = DelayLine::new(net.delay(), 0.0).ok_or(NetworkError::Delay(net.delay()))?;
        Ok(Self {
            gains: g,
            delayed: rest,
            pulses,
            initial_delayed: rest,
            missing: 0,
        })
    }

    /// Back to rest, no pulses in flight, counters zero.
    pub fn reset(&mut self, net: &Network<f64>) {
        self.delayed = self.initial_delayed;
        // Same length as before, so this cannot fail; the fallback keeps the old line.
        if let Some(p) = DelayLine::new(net.delay(), 0.0) {
            self.pulses = p;
        }
        self.missing = 0;
    }

    /// Samples whose measurement was missing, not finite or implausible.
    pub fn missing(&self) -> u64 {
        self.missing
    }

    /// The delayed estimate `x̂[k]` (before [`Self::update`] at time `k`).
    pub fn delayed_state(&self) -> &CoreState<f64> {
        &self.delayed
    }

    /// Interpolated estimator gain `L(phi)` over the active units.
    #[inline(always)]
    fn gain(&self, act: &Activation<f64>) -> [f64; 2] {
        act.interpolate(|i| self.gains[i]).0
    }

    /// At time `k`, before the decision: correct the delayed estimate with `y[k]` and
    /// re-predict the core state `z[k]` (module docs).
    #[inline]
    pub fn update(&mut self, net: &Network<f64>, measured: Option<f64>) -> EstimatorUpdate {
        let d = self.pulses.len();
        let v = self.pulses.get(0).unwrap_or(0.0);
        let act = net.activation(&self.delayed);
        let y_hat = net.step_with_activation(&mut self.delayed, &act, v);
        let (innovation, used) = match measured {
            Some(y) if y.is_finite() && y.abs() <= MAX_MEASURED_FORCE => (y - y_hat, true),
            _ => {
                self.missing += 1;
                (0.0, false)
            }
        };
        if used {
            let l = self.gain(&act);
            let ts = net.ts();
            self.delayed.x[0] += ts * l[0] * innovation;
            self.delayed.x[1] += ts * l[1] * innovation;
        }
        let mut core = self.delayed;
        for i in 1..d {
            net.step(&mut core, self.pulses.get(i).unwrap_or(0.0));
        }
        EstimatorUpdate {
            model_force: y_hat,
            innovation,
            measured: used,
            core,
        }
    }

    /// After the decision at time `k`: record the pulse `u[k]`.
    #[inline]
    pub fn push_pulse(&mut self, u: f64) {
        self.pulses.push(u);
    }
}
