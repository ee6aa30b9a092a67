//! The Ding / Wexler / Binder-Macleod force model (Ding et al. 2002, 2003, 2007).
//!
//! CN is advanced exactly ([`calcium`]); the force F (and, with fatigue, A, Km and tau1)
//! by classical fourth-order Runge-Kutta on substeps no longer than
//! [`DingModel::max_substep`], with CN evaluated in closed form inside each substep.

pub mod calcium;
pub mod fatigue;
pub mod params;
pub mod pulse_width;

pub use calcium::Calcium;
pub use fatigue::FatigueParams;
pub use params::{DingParams, ParamError};
pub use pulse_width::PulseWidthParams;

/// Default longest RK4 substep, s: a quarter of the 1 ms sample, which keeps the force
/// error near 1e-7 of the peak (see the accuracy test against Dormand-Prince).
pub const DEFAULT_MAX_SUBSTEP_S: f64 = 0.25e-3;

/// The slowly varying part of the state: the force and the three parameters the fatigue
/// extension lets drift (constant without fatigue).
#[derive(Debug, Clone, Copy, PartialEq)]
struct ForceState {
    f: f64,
    a: f64,
    km: f64,
    tau1: f64,
}

impl ForceState {
    fn add(self, k: ForceState, h: f64) -> ForceState {
        ForceState {
            f: self.f + h * k.f,
            a: self.a + h * k.a,
            km: self.km + h * k.km,
            tau1: self.tau1 + h * k.tau1,
        }
    }
}

/// The Ding muscle in continuous time: [`DingModel::fire`] delivers a pulse now,
/// [`DingModel::advance`] lets time pass.
#[derive(Debug, Clone)]
pub struct DingModel {
    rest: DingParams,
    fatigue: Option<FatigueParams>,
    max_substep: f64,
    calcium: Calcium,
    state: ForceState,
    /// Activation gain of the most recent pulse (pulse-width variant; 1 otherwise).
    gain: f64,
}

impl DingModel {
    /// A muscle at rest with the force-model parameters `params`, optionally with the
    /// fatigue extension, integrated with RK4 substeps of at most `max_substep` seconds.
    pub fn new(
        params: DingParams,
        fatigue: Option<FatigueParams>,
        max_substep: f64,
    ) -> Result<Self, ParamError> {
        params.validate()?;
        if let Some(f) = &fatigue {
            f.validate()?;
        }
        params::positive("max_substep", max_substep)?;
        Ok(Self {
            rest: params,
            fatigue,
            max_substep,
            calcium: Calcium::REST,
            state: Self::rested(&params),
            gain: 1.0,
        })
    }

    fn rested(p: &DingParams) -> ForceState {
        ForceState {
            f: 0.0,
            a: p.a,
            km: p.km,
            tau1: p.tau1,
        }
    }

    /// The rested force-model parameters.
    pub fn params(&self) -> &DingParams {
        &self.rest
    }

    /// The fatigue coefficients, if the fatigue extension is on.
    pub fn fatigue(&self) -> Option<&FatigueParams> {
        self.fatigue.as_ref()
    }

    /// Longest RK4 substep, s.
    pub fn max_substep(&self) -> f64 {
        self.max_substep
    }

    /// Back to rest: no CN, no force, no stimulation history, rested parameters.
    pub fn reset(&mut self) {
        self.calcium = Calcium::REST;
        self.state = Self::rested(&self.rest);
        self.gain = 1.0;
    }

    /// Force, N.
    pub fn force(&self) -> f64 {
        self.state.f
    }

    /// CN (dimensionless).
    pub fn cn(&self) -> f64 {
        self.calcium.cn()
    }

    /// Current (possibly fatigued) A (N/s), Km and tau1 (s).
    pub fn current_a_km_tau1(&self) -> (f64, f64, f64) {
        (self.state.a, self.state.km, self.state.tau1)
    }

    /// Current R0: the rested one, or with fatigue `Km + (r0_rest - km_rest)` (Ding 2003).
    pub fn r0(&self) -> f64 {
        match self.fatigue {
            Some(_) => self.state.km + (self.rest.r0 - self.rest.km),
            None => self.rest.r0,
        }
    }

    /// Delivers a pulse now. `gain` in (0, 1] scales A from this pulse on (pulse-width
    /// variant, Ding 2007); a supramaximal pulse has gain 1. Gains <= 0 deliver nothing.
    pub fn fire(&mut self, gain: f64) {
        if gain.is_nan() || gain <= 0.0 {
            return;
        }
        let r = self.calcium.enhancement(self.r0(), self.rest.tauc);
        self.calcium.fire(r);
        self.gain = gain.min(1.0);
    }

    /// The right-hand side of the force and fatigue equations for CN = `cn`.
    fn derivative(&self, y: ForceState, cn: f64) -> ForceState {
        let s = cn / (y.km + cn);
        let df = self.gain * y.a * s - y.f / (y.tau1 + self.rest.tau2 * s);
        match &self.fatigue {
            None => ForceState {
                f: df,
                a: 0.0,
                km: 0.0,
                tau1: 0.0,
            },
            Some(fp) => ForceState {
                f: df,
                a: -(y.a - self.rest.a) / fp.tau_fat + fp.alpha_a * y.f,
                km: -(y.km - self.rest.km) / fp.tau_fat + fp.alpha_km * y.f,
                tau1: -(y.tau1 - self.rest.tau1) / fp.tau_fat + fp.alpha_tau1 * y.f,
            },
        }
    }

    /// Lets `h` seconds pass without a pulse.
    pub fn advance(&mut self, h: f64) {
        if h.is_nan() || h <= 0.0 {
            return;
        }
        let n = (h / self.max_substep).ceil().max(1.0);
        let hs = h / n;
        let tauc = self.rest.tauc;
        for _ in 0..n as u64 {
            let c = self.calcium;
            let (cn0, cn_mid, cn1) = (c.cn(), c.cn_after(0.5 * hs, tauc), c.cn_after(hs, tauc));
            let y = self.state;
            let k1 = self.derivative(y, cn0);
            let k2 = self.derivative(y.add(k1, 0.5 * hs), cn_mid);
            let k3 = self.derivative(y.add(k2, 0.5 * hs), cn_mid);
            let k4 = self.derivative(y.add(k3, hs), cn1);
            self.state = ForceState {
                f: y.f + hs / 6.0 * (k1.f + 2.0 * k2.f + 2.0 * k3.f + k4.f),
                a: y.a + hs / 6.0 * (k1.a + 2.0 * k2.a + 2.0 * k3.a + k4.a),
                km: y.km + hs / 6.0 * (k1.km + 2.0 * k2.km + 2.0 * k3.km + k4.km),
                tau1: y.tau1 + hs / 6.0 * (k1.tau1 + 2.0 * k2.tau1 + 2.0 * k3.tau1 + k4.tau1),
            };
            self.calcium.advance(hs, tauc);
        }
    }

    /// Whether the muscle is quiescent: CN and force negligible (below 1e-12 and 1e-9 N).
    pub fn is_quiescent(&self) -> bool {
        self.calcium.is_below(1e-12) && self.state.f.abs() < 1e-9
    }

    /// Lets `seconds` pass without pulses once the muscle is quiescent: CN and force are
    /// zero, and the fatigued parameters recover exactly as `exp(-t/tau_fat)` (with F = 0
    /// the fatigue equations are linear). Call only when [`DingModel::is_quiescent`].
    pub fn relax(&mut self, seconds: f64) {
        self.calcium = Calcium::REST;
        self.state.f = 0.0;
        if let Some(fp) = &self.fatigue {
            let w = (-seconds.max(0.0) / fp.tau_fat).exp();
            self.state.a = self.rest.a + (self.state.a - self.rest.a) * w;
            self.state.km = self.rest.km + (self.state.km - self.rest.km) * w;
            self.state.tau1 = self.rest.tau1 + (self.state.tau1 - self.rest.tau1) * w;
        }
    }
}
