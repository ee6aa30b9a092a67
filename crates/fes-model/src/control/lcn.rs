//! The Local Controller Network (thesis 3.3, Fig. 3.2): one state-feedback controller with
//! integral action per local model, interpolated with the same validity functions as the
//! Local Model Network.
//!
//! Gains at the scheduling value `phi` (eq. 2.16 applied to the controllers):
//!
//! ```text
//! K_I(phi) = sum_i rho_i(phi) K_I,i,     K_x(phi) = sum_i rho_i(phi) K_x,i,
//! ```
//!
//! summed over the (at most 3) active units only, using the model's own sparse
//! [`Activation`]. Control law (eq. C.26): `u_raw = -K_I(phi) x_I - K_x(phi)' z`.
//!
//! **Output.** With the shaper's [`ShaperSum::Clamped`](super::shaper::ShaperSum) rule a
//! stimulation signal cannot be negative, so `u_cont = max(u_raw, 0)`; with the thesis's
//! [`ShaperSum::Signed`](super::shaper::ShaperSum) rule the shaper sums `u_cont = u_raw`
//! as it is (eq. 6.8) and the output is never clamped.
//!
//! **Anti-windup** ([`AntiWindup`]), for the clamped output. Left alone, the integrator
//! keeps integrating while the output is held at zero; with a positive rest force and
//! `r = 0` it grows without bound, and the force then lags or overshoots when the reference
//! rises again (thesis E.4.7). The rules:
//!
//! - [`AntiWindup::None`] (default) — plain integral action, never frozen (the thesis's
//!   loop, 6.5.3: "integral action ... to ensure zero steady state error"). In a periodic
//!   pulsed steady state an integrator that always integrates returns to its value after
//!   every period, so the mean error over a period is exactly zero, at every level. The
//!   windup at rest is handled by the pattern generator, which resets the integrator with
//!   the shaper at a zero reference.
//! - [`AntiWindup::IntegralSign`] — conditional integration (`δx_I = e = y - r`, eq. C.24,
//!   frozen for a sample) when the output is clamped (`u_raw < 0`), integrating `e` would
//!   push `u_raw` further down (`K_I(phi) e > 0`, since `∂u_raw/∂x_I = -K_I`), *and* the
//!   integral action itself already asks for negative stimulation (`-K_I(phi) x_I < 0`).
//!   Freezing on the clamp alone biases the pulsed loop (`u_raw` is negative for part of
//!   every inter-pulse interval, so the integrator only sees the negative errors); this
//!   rule still settles above `r` where one twitch overshoots the reference (docs/control.md).
//! - [`AntiWindup::OutputClamp`] — the clamp and error conditions alone (textbook
//!   conditional integration). Kept for comparison; docs/control.md gives the measured bias.

use core::ops::{Add, Mul};

use serde::{Deserialize, Serialize};

use crate::model::{Activation, MAX_UNITS};

use super::design::LocalGains;

/// When the integrator is frozen (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AntiWindup {
    /// Freeze when clamped, the error drives `u_raw` down, and the integral term itself
    /// asks for negative stimulation (the default until 2026-12, and the rule of
    /// controller files that do not name one).
    IntegralSign,
    /// Freeze when clamped and the error drives `u_raw` down (biased in pulsed operation).
    OutputClamp,
    /// Never freeze: plain integral action (thesis 6.5.3); the default (docs/control.md,
    /// "Variants", gives the measurements that chose it).
    #[default]
    None,
}

impl AntiWindup {
    /// The rule of a controller file that does not name one: [`AntiWindup::IntegralSign`].
    pub const fn legacy() -> Self {
        Self::IntegralSign
    }
}

/// Gains `[K_I, K_x,1, K_x,2]` of one controller, interpolated as a unit.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GainVector {
    /// Integral gain `K_I`.
    pub k_i: f64,
    /// State gain `K_x`.
    pub k_x: [f64; 2],
}

impl From<LocalGains> for GainVector {
    fn from(g: LocalGains) -> Self {
        Self {
            k_i: g.k_i,
            k_x: g.k_x,
        }
    }
}

impl Add for GainVector {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        Self {
            k_i: self.k_i + o.k_i,
            k_x: [self.k_x[0] + o.k_x[0], self.k_x[1] + o.k_x[1]],
        }
    }
}

impl Mul<f64> for GainVector {
    type Output = Self;
    #[inline(always)]
    fn mul(self, r: f64) -> Self {
        Self {
            k_i: self.k_i * r,
            k_x: [self.k_x[0] * r, self.k_x[1] * r],
        }
    }
}

/// Why an LCN could not be assembled from per-unit gains.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum LcnError {
    /// Number of controllers outside `1..=MAX_UNITS`.
    #[error("{0} local controllers given; need 1..={MAX_UNITS}")]
    UnitCount(usize),
    /// A gain is NaN or infinite.
    #[error("unit {unit}: gain {field} is not finite")]
    NonFinite {
        /// Unit index.
        unit: usize,
        /// Which gain.
        field: &'static str,
    },
    /// The sampling period must be finite and positive.
    #[error("sampling period Ts = {0} s is not a finite positive number")]
    SamplingPeriod(f64),
}

/// Result of evaluating the control law at one sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControlAction {
    /// Interpolated gains at this sample.
    pub gains: GainVector,
    /// Unclamped control law `-K_I x_I - K_x' z` (eq. C.26).
    pub u_raw: f64,
    /// The control signal handed to the pulse shaper: `max(u_raw, 0)` when the output is
    /// clamped, else `u_raw`.
    pub u_cont: f64,
    /// Whether the clamp held the output at zero (`u_raw < 0` with a clamped output).
    pub clamped: bool,
}

impl ControlAction {
    /// `true` when the output is held at zero by the clamp.
    #[inline]
    pub fn clamped(&self) -> bool {
        self.clamped
    }
}

/// The Local Controller Network: per-unit gains and the integrator state `x_I`.
/// Fixed size and `Copy`; nothing allocates after construction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalControllerNetwork {
    gains: [GainVector; MAX_UNITS],
    units: usize,
    ts: f64,
    anti_windup: AntiWindup,
    x_i: f64,
}

impl LocalControllerNetwork {
    /// An LCN from per-unit gains (unit `i` pairs with validity function `i`), `x_I = 0`.
    pub fn new(units: &[LocalGains], ts: f64, anti_windup: AntiWindup) -> Result<Self, LcnError> {
        if !(1..=MAX_UNITS).contains(&units.len()) {
            return Err(LcnError::UnitCount(units.len()));
        }
        if !(ts.is_finite() && ts > 0.0) {
            return Err(LcnError::SamplingPeriod(ts));
        }
        let mut gains = [GainVector::default(); MAX_UNITS];
        for (i, g) in units.iter().enumerate() {
            if !g.k_i.is_finite() {
                return Err(LcnError::NonFinite {
                    unit: i,
                    field: "K_I",
                });
            }
            if !g.k_x.iter().all(|v| v.is_finite()) {
                return Err(LcnError::NonFinite {
                    unit: i,
                    field: "K_x",
                });
            }
            gains[i] = (*g).into();
        }
        Ok(Self {
            gains,
            units: units.len(),
            ts,
            anti_windup,
            x_i: 0.0,
        })
    }

    /// Number of local controllers M.
    pub fn units(&self) -> usize {
        self.units
    }

    /// Gains of unit `i` (`None` for `i >= M`).
    pub fn unit_gains(&self, i: usize) -> Option<GainVector> {
        (i < self.units).then(|| self.gains[i])
    }

    /// The integrator state `x_I`.
    #[inline]
    pub fn x_i(&self) -> f64 {
        self.x_i
    }

    /// Back to `x_I = 0`.
    pub fn reset(&mut self) {
        self.x_i = 0.0;
    }

    /// Interpolated gains `K(phi) = sum rho_i(phi) K_i` over the active units (eq. 2.16).
    #[inline(always)]
    pub fn gains(&self, act: &Activation<f64>) -> GainVector {
        act.interpolate(|i| self.gains[i])
    }

    /// Control law (eq. C.26) at the core state `z` with the activation of the present
    /// scheduling value; with `clamp` the output is clamped at zero (module docs).
    #[inline(always)]
    pub fn control(&self, act: &Activation<f64>, z: [f64; 2], clamp: bool) -> ControlAction {
        let gains = self.gains(act);
        let u_raw = -gains.k_i * self.x_i - gains.k_x[0] * z[0] - gains.k_x[1] * z[1];
        // Written out rather than `u_raw.max(0.0)`: `max` may return either zero for
        // u_raw = -0.0, and which one depends on the optimisation level, so a live loop and
        // its offline replay built differently disagreed bit for bit. This is always +0.0
        // at and below zero, and NaN (impossible for finite state) maps to 0 as well.
        let u_cont = if !clamp || u_raw > 0.0 { u_raw } else { 0.0 };
        let clamped = clamp && u_raw < 0.0;
        ControlAction {
            gains,
            u_raw,
            u_cont,
            clamped,
        }
    }

    /// The anti-windup rule.
    pub fn anti_windup(&self) -> AntiWindup {
        self.anti_windup
    }

    /// Integrator update `x_I += Ts e`, `e = y - r` (eq. C.24), with conditional
    /// integration (module docs). Returns whether it integrated. A non-finite error is not
    /// integrated.
    #[inline(always)]
    pub fn integrate(&mut self, action: &ControlAction, error: f64) -> bool {
        let k_i = action.gains.k_i;
        let drives_down = action.clamped() && k_i * error > 0.0;
        let winds_up = match self.anti_windup {
            AntiWindup::IntegralSign => drives_down && k_i * self.x_i > 0.0,
            AntiWindup::OutputClamp => drives_down,
            AntiWindup::None => false,
        };
        if winds_up || !error.is_finite() {
            return false;
        }
        self.x_i += self.ts * error;
        true
    }
}
