//! The Local Model Network core: an undelayed LPV system (thesis 2.2.2, eq. 2.14-2.16, 2.24).
//!
//! The network with input delay d (eq. 2.14: the local models and, in the delayed scheduling
//! class, the scheduler see u\[k-d\]) is exactly this core driven by v\[k\] = u\[k-d\].
//! Equivalently it is the core driven by u\[k\] followed by a pure d-sample output delay.
//! [`super::forms`] runs it both ways. In the undelayed class (eq. 5.2 read literally,
//! [`SchedulingInput::Undelayed`]) the prefilter is driven by u\[k\] itself while the local
//! models see v\[k\]: [`Network::step_inputs`] takes both, and only the first way exists.
//!
//! One core step at (core) time j, with scheduling value phi_j known before the input:
//! - state space: y_j = c(phi_j)' x_j + d^y(phi_j),
//!   x_{j+1} = x_j + Ts (A(phi_j) x_j + b(phi_j) v_j + d^x(phi_j)) (eq. 2.15-2.16, D.2.2);
//! - ARX: y_j = sum_i rho_i(phi_j) [psi_j' Theta_i + d_i] (eq. 2.24) with
//!   psi_j = [v_j..v_{j-n+1}, y_{j-1}..y_{j-n}];
//! - then the scheduler advances: phi_{j+1} = prefilter(v_0..v_j) (undelayed class:
//!   prefilter(u_0..u_j)) or y_j.
//!
//! Only the (at most 3) active units are interpolated, so a step costs the same for any M.
//! The step is generic over [`Scalar`]: `f64` for the real-time path and simulation,
//! [`crate::num::Dual`] for exact parameter sensitivities.

use super::arx::{ArxUnit, MAX_ARX_ORDER};
use super::local_model::SsLocalModel;
use super::scheduling::{Scheduler, SchedulingInput};
use super::validity::{Activation, MAX_UNITS, ValidityFunctions};
use crate::num::Scalar;
#[cfg(not(feature = "std"))]
use crate::num::math::ComplexMath as _;

/// Largest supported input delay in samples.
pub const MAX_DELAY: usize = 1000;

/// Why a network could not be built or started.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum NetworkError {
    /// Number of local models differs from the number of validity functions.
    #[error("{models} local models given for {units} validity functions")]
    UnitMismatch {
        /// Local models given.
        models: usize,
        /// Validity functions.
        units: usize,
    },
    /// ARX order outside 1..=3.
    #[error("ARX order {0} is outside 1..={MAX_ARX_ORDER}")]
    ArxOrder(usize),
    /// Sampling period not finite and positive.
    #[error("sampling period Ts = {0} s must be finite and > 0")]
    SamplingPeriod(f64),
    /// Delay above [`MAX_DELAY`].
    #[error("input delay {0} samples exceeds the maximum {MAX_DELAY}")]
    Delay(usize),
    /// A parameter is NaN or infinite.
    #[error("unit {unit}: a parameter is not finite")]
    NonFinite {
        /// The unit.
        unit: usize,
    },
    /// The advanced form (state d samples ahead) of an undelayed-class network: its phi d
    /// samples ahead depends on pulses not yet decided.
    #[error(
        "the model's scheduling_input is undelayed (eq. 5.2) with a {delay}-sample delay: the state {delay} samples ahead depends on pulses not yet decided, so only the delayed loop (feedback_state delayed) can run on it"
    )]
    CannotRunAhead {
        /// The input delay d.
        delay: usize,
    },
    /// The rest state does not exist: the interpolated A (or ARX A(1)) is singular at the
    /// rest scheduling value.
    #[error("no rest state: the interpolated model is singular at phi = {phi}")]
    NoRestState {
        /// The scheduling value where it failed.
        phi: f64,
    },
}

/// The local models of a network, in the direct form that is interpolated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LocalModels<S = f64> {
    /// Second-order delta-domain state-space models (eq. 2.13).
    StateSpace([SsLocalModel<S>; MAX_UNITS]),
    /// Shift-form ARX models of order `order` (eq. 2.20); delta-form models are converted
    /// to these before they get here.
    Arx {
        /// n = 1..=3.
        order: usize,
        /// Shift-form coefficients per unit.
        units: [ArxUnit<S>; MAX_UNITS],
    },
}

/// The state of the core at one time: everything the next step needs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CoreState<S = f64> {
    /// State space: the state x (`x[2]` unused). ARX: past outputs y_{j-1}, y_{j-2}, y_{j-3}.
    pub x: [S; 3],
    /// ARX: past inputs v_{j-1}, v_{j-2} (unused for state space).
    pub v_past: [f64; 2],
    /// Prefilter state (input scheduling; unused for output scheduling).
    pub w: [f64; 2],
    /// The scheduling value phi_j for the coming step.
    pub phi: S,
}

impl<S: Scalar> CoreState<S> {
    /// The state-space state x (first two entries of `x`).
    #[inline]
    pub fn ss_state(&self) -> [S; 2] {
        [self.x[0], self.x[1]]
    }
}

/// The LMN core: sampling period, delay (used by the runners), validity functions,
/// scheduler and local models.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Network<S = f64> {
    ts: f64,
    delay: usize,
    validity: ValidityFunctions<S>,
    scheduler: Scheduler,
    local: LocalModels<S>,
}

impl<S: Scalar> Network<S> {
    /// A network of state-space local models (one per validity function).
    pub fn state_space(
        ts: f64,
        delay: usize,
        validity: ValidityFunctions<S>,
        scheduler: Scheduler,
        units: &[SsLocalModel<S>],
    ) -> Result<Self, NetworkError> {
        check_common(ts, delay, validity.units(), units.len())?;
        let mut arr = [SsLocalModel::zero(); MAX_UNITS];
        for (i, u) in units.iter().enumerate() {
            if !u.is_finite() {
                return Err(NetworkError::NonFinite { unit: i });
            }
            arr[i] = *u;
        }
        Ok(Self {
            ts,
            delay,
            validity,
            scheduler,
            local: LocalModels::StateSpace(arr),
        })
    }

    /// A network of shift-form ARX local models of order n (one per validity function).
    pub fn arx(
        ts: f64,
        delay: usize,
        validity: ValidityFunctions<S>,
        scheduler: Scheduler,
        order: usize,
        units: &[ArxUnit<S>],
    ) -> Result<Self, NetworkError> {
        check_common(ts, delay, validity.units(), units.len())?;
        if !(1..=MAX_ARX_ORDER).contains(&order) {
            return Err(NetworkError::ArxOrder(order));
        }
        let mut arr = [ArxUnit::zero(); MAX_UNITS];
        for (i, u) in units.iter().enumerate() {
            if !u.is_finite() {
                return Err(NetworkError::NonFinite { unit: i });
            }
            // Coefficients beyond the order are ignored: store them as zero.
            let mut v = ArxUnit::zero();
            v.a[..order].copy_from_slice(&u.a[..order]);
            v.b[..order].copy_from_slice(&u.b[..order]);
            v.d = u.d;
            arr[i] = v;
        }
        Ok(Self {
            ts,
            delay,
            validity,
            scheduler,
            local: LocalModels::Arx { order, units: arr },
        })
    }

    /// Sampling period Ts in seconds.
    #[inline]
    pub fn ts(&self) -> f64 {
        self.ts
    }

    /// Input delay d in samples.
    #[inline]
    pub fn delay(&self) -> usize {
        self.delay
    }

    /// The validity functions.
    #[inline]
    pub fn validity(&self) -> &ValidityFunctions<S> {
        &self.validity
    }

    /// The scheduler.
    #[inline]
    pub fn scheduler(&self) -> &Scheduler {
        &self.scheduler
    }

    /// Which input drives phi.
    #[inline]
    pub fn scheduling_input(&self) -> SchedulingInput {
        self.scheduler.input()
    }

    /// The core can run ahead of the pulses: every scheduling value of the next d core steps
    /// is fixed by pulses already decided. True for the delayed class (and for d = 0);
    /// false for the undelayed class with d > 0, whose phi d samples ahead depends on the
    /// pulses of those d samples.
    #[inline]
    pub fn can_run_ahead(&self) -> bool {
        self.delay == 0 || self.scheduling_input() == SchedulingInput::Delayed
    }

    /// The local models.
    #[inline]
    pub fn local_models(&self) -> &LocalModels<S> {
        &self.local
    }

    /// Number of units M.
    #[inline]
    pub fn units(&self) -> usize {
        self.validity.units()
    }

    /// State-space local model i (`None` for ARX networks or i >= M).
    #[inline]
    pub fn ss_unit(&self, i: usize) -> Option<&SsLocalModel<S>> {
        match &self.local {
            LocalModels::StateSpace(u) if i < self.units() => Some(&u[i]),
            _ => None,
        }
    }

    /// The interpolated state-space model for an activation (eq. 2.16); `None` for ARX.
    #[inline(always)]
    pub fn ss_interpolated(&self, act: &Activation<S>) -> Option<SsLocalModel<S>> {
        match &self.local {
            LocalModels::StateSpace(u) => Some(act.interpolate(|i| u[i])),
            LocalModels::Arx { .. } => None,
        }
    }

    /// The interpolated shift-form ARX model for an activation (eq. 2.26); `None` for
    /// state-space networks.
    #[inline(always)]
    pub fn arx_interpolated(&self, act: &Activation<S>) -> Option<ArxUnit<S>> {
        match &self.local {
            LocalModels::Arx { units, .. } => Some(act.interpolate(|i| units[i])),
            LocalModels::StateSpace(_) => None,
        }
    }

    /// The activation of the validity functions for the coming step.
    #[inline(always)]
    pub fn activation(&self, st: &CoreState<S>) -> Activation<S> {
        self.validity.eval(st.phi)
    }

    /// One core step with input v, the scheduler driven by v as well: returns the core output
    /// y_j and advances `st` to j + 1 (module docs). This is the delayed class's step, and the
    /// step of any core run ahead of the pulses ([`Self::can_run_ahead`]); the undelayed class
    /// with d > 0 steps with [`Self::step_inputs`].
    #[inline]
    pub fn step(&self, st: &mut CoreState<S>, v: f64) -> S {
        self.step_each(st, v, v)
    }

    /// One core step of either class ([`Self::step_inputs`]) with the activation at `st.phi`.
    #[inline]
    pub fn step_each(&self, st: &mut CoreState<S>, v: f64, u_now: f64) -> S {
        let act = self.activation(st);
        self.step_inputs(st, &act, v, u_now)
    }

    /// [`Self::step`] with the activation already evaluated for `st.phi` (e.g. by a
    /// controller that interpolates its gains with the same weights).
    #[inline(always)]
    pub fn step_with_activation(&self, st: &mut CoreState<S>, act: &Activation<S>, v: f64) -> S {
        self.step_inputs(st, act, v, v)
    }

    /// One core step of either class: the local models see v = u\[k-d\]; the prefilter is
    /// driven by v in the delayed class and by `u_now` = u\[k\] in the undelayed class (eq.
    /// 5.2). Output scheduling ignores both.
    #[inline(always)]
    pub fn step_inputs(&self, st: &mut CoreState<S>, act: &Activation<S>, v: f64, u_now: f64) -> S {
        let y = match &self.local {
            LocalModels::StateSpace(units) => {
                let m: SsLocalModel<S> = act.interpolate(|i| units[i]);
                let (y, x) = m.step([st.x[0], st.x[1]], S::from_f64(v), self.ts);
                st.x[0] = x[0];
                st.x[1] = x[1];
                y
            }
            LocalModels::Arx { order, units } => {
                let m: ArxUnit<S> = act.interpolate(|i| units[i]);
                let u_hist = [v, st.v_past[0], st.v_past[1]];
                let y = m.output(*order, &u_hist, &st.x);
                st.x = [y, st.x[0], st.x[1]];
                st.v_past = [v, st.v_past[0]];
                y
            }
        };
        st.phi = match &self.scheduler {
            Scheduler::Input(pf, input) => {
                let s = match input {
                    SchedulingInput::Delayed => v,
                    SchedulingInput::Undelayed => u_now,
                };
                pf.advance(&mut st.w, s);
                S::from_f64(pf.output(&st.w))
            }
            Scheduler::Output => y,
        };
        y
    }

    /// Equilibrium output with no input at a fixed phi (eq. A.17 at u = 0) and the matching
    /// state (SS: x; ARX: the output repeated), `None` if singular.
    pub fn equilibrium_at(&self, phi: S) -> Option<(S, [S; 3])> {
        let act = self.validity.eval(phi);
        match &self.local {
            LocalModels::StateSpace(units) => {
                let m: SsLocalModel<S> = act.interpolate(|i| units[i]);
                let x = m.equilibrium(S::zero())?;
                let y = m.c[0] * x[0] + m.c[1] * x[1] + m.dy;
                Some((y, [x[0], x[1], S::zero()]))
            }
            LocalModels::Arx { order, units } => {
                let m: ArxUnit<S> = act.interpolate(|i| units[i]);
                let mut a1 = S::one();
                for a in &m.a[..*order] {
                    a1 += *a;
                }
                if a1.value() == 0.0 || !a1.value().is_finite() {
                    return None;
                }
                let y = m.d / a1;
                Some((y, [y; 3]))
            }
        }
    }

    /// The state "at rest": no pulses ever, and the simulated output stays constant.
    ///
    /// Input scheduling: prefilter state 0, phi = 0, x0 = the equilibrium for u = 0 at
    /// phi = 0 (x0 = -A(0)^-1 d^x(0); x0 = 0 with zero offsets). Output scheduling: phi0 is
    /// the lowest fixed point phi = y_eq(phi) (it exists because phi is clamped into the
    /// valid range, so y_eq is bounded), found by a grid scan and bisection in f64; for
    /// [`crate::num::Dual`] one Newton step in S carries the implicit derivative.
    pub fn rest_state(&self) -> Result<CoreState<S>, NetworkError> {
        let phi0 = match self.scheduler {
            Scheduler::Input(..) => S::zero(),
            Scheduler::Output => self.output_fixed_point()?,
        };
        let (_y, x) = self
            .equilibrium_at(phi0)
            .ok_or(NetworkError::NoRestState { phi: phi0.value() })?;
        Ok(CoreState {
            x,
            v_past: [0.0; 2],
            w: [0.0; 2],
            phi: phi0,
        })
    }

    /// Lowest root of h(phi) = y_eq(phi) - phi (output scheduling). Grid points where the
    /// interpolated model is singular break the bracket (y_eq has a pole there, and a sign
    /// change across a pole is not a root); a bisected bracket is accepted only if h is
    /// small at its end.
    fn output_fixed_point(&self) -> Result<S, NetworkError> {
        let h = |phi: f64| -> Option<f64> {
            let (y, _) = self.equilibrium_at(S::from_f64(phi))?;
            let v = y.value() - phi;
            v.is_finite().then_some(v)
        };
        let (lo, hi) = self.validity.valid_range();
        let (lo, hi) = (lo.value(), hi.value());
        let root = 'search: {
            if let Some(h_lo) = h(lo)
                && h_lo <= 0.0
            {
                // Below the range y_eq is constant, so the lowest root is y_eq(lo) <= lo.
                break 'search h_lo + lo;
            }
            const GRID: usize = 400;
            let mut prev = h(lo).map(|v| (lo, v));
            for g in 1..=GRID {
                let p = lo + (hi - lo) * g as f64 / GRID as f64;
                let Some(hp) = h(p) else {
                    prev = None;
                    continue;
                };
                if let Some((a0, _)) = prev
                    && hp <= 0.0
                {
                    let (mut a, mut b) = (a0, p);
                    for _ in 0..200 {
                        let mid = 0.5 * (a + b);
                        if mid <= a || mid >= b {
                            break;
                        }
                        match h(mid) {
                            Some(v) if v > 0.0 => a = mid,
                            Some(_) => b = mid,
                            None => break,
                        }
                    }
                    let r = 0.5 * (a + b);
                    if h(r).is_some_and(|v| v.abs() <= 1e-9 * (1.0 + r.abs())) {
                        break 'search r;
                    }
                }
                prev = Some((p, hp));
            }
            // Above the range y_eq is constant: the root is y_eq(hi) if that is > hi.
            match h(hi) {
                Some(v) if v > 0.0 => v + hi,
                _ => return Err(NetworkError::NoRestState { phi: hi }),
            }
        };
        let h = |phi: f64| h(phi).ok_or(NetworkError::NoRestState { phi });
        // One Newton step in S: value stays (h(root) ~ 0), derivatives become
        // -dh/dtheta / h'(root) (implicit function theorem).
        let eps = 1e-6 * (hi - lo);
        let dh = (h(root + eps)? - h(root - eps)?) / (2.0 * eps);
        let (y_s, _) = self
            .equilibrium_at(S::from_f64(root))
            .ok_or(NetworkError::NoRestState { phi: root })?;
        let hs = y_s - root;
        if dh.is_finite() && dh.abs() > 1e-12 {
            Ok(-(hs / dh) + root)
        } else {
            Ok(S::from_f64(root))
        }
    }
}

impl Network<f64> {
    /// Frozen-scheduling stability: the largest pole radius of the interpolated model
    /// (eq. 2.16 / 2.26: max |1 + Ts p| in state space, max |z| for ARX) over `points`
    /// scheduling values spread evenly across the valid range, and the phi where it occurs.
    /// Stable local models do not make their interpolation stable (a convex combination of
    /// stable matrices can be unstable), so a usable network needs this below 1 as well;
    /// it is necessary, not sufficient, for stability under fast-changing scheduling.
    pub fn frozen_stability_radius(&self, points: usize) -> (f64, f64) {
        let (lo, hi) = self.validity.valid_range();
        let mut worst = (0.0_f64, lo);
        for g in 0..points.max(2) {
            let phi = lo + (hi - lo) * g as f64 / (points.max(2) - 1) as f64;
            let act = self.validity.eval(phi);
            let radius = match &self.local {
                LocalModels::StateSpace(u) => act.interpolate(|i| u[i]).stability_radius(self.ts),
                LocalModels::Arx { order, units } => {
                    super::arx::shift_poles(&act.interpolate(|i| units[i]), *order)
                        .iter()
                        .map(|z| z.norm())
                        .fold(0.0, f64::max)
                }
            };
            // NaN (a non-finite interpolation) counts as unstable.
            if radius.is_nan() || radius > worst.0 {
                let radius = if radius.is_nan() {
                    f64::INFINITY
                } else {
                    radius
                };
                worst = (radius, phi);
                if radius.is_infinite() {
                    break;
                }
            }
        }
        worst
    }

    /// The same network in another scalar type, every parameter mapped through `f` (e.g. to
    /// constant [`crate::num::Dual`]s); the identification code seeds its parameters itself.
    pub fn cast<T: Scalar>(&self, f: impl Fn(f64) -> T + Copy) -> Network<T> {
        let local = match &self.local {
            LocalModels::StateSpace(u) => LocalModels::StateSpace(core::array::from_fn(|i| {
                let m = &u[i];
                SsLocalModel {
                    a: [[f(m.a[0][0]), f(m.a[0][1])], [f(m.a[1][0]), f(m.a[1][1])]],
                    b: [f(m.b[0]), f(m.b[1])],
                    c: [f(m.c[0]), f(m.c[1])],
                    dx: [f(m.dx[0]), f(m.dx[1])],
                    dy: f(m.dy),
                }
            })),
            LocalModels::Arx { order, units } => LocalModels::Arx {
                order: *order,
                units: core::array::from_fn(|i| {
                    let m = &units[i];
                    ArxUnit {
                        a: m.a.map(f),
                        b: m.b.map(f),
                        d: f(m.d),
                    }
                }),
            },
        };
        Network {
            ts: self.ts,
            delay: self.delay,
            validity: self.validity.cast(|_, k| f(k)),
            scheduler: self.scheduler,
            local,
        }
    }
}

fn check_common(ts: f64, delay: usize, units: usize, models: usize) -> Result<(), NetworkError> {
    if !(ts.is_finite() && ts > 0.0) {
        return Err(NetworkError::SamplingPeriod(ts));
    }
    if delay > MAX_DELAY {
        return Err(NetworkError::Delay(delay));
    }
    if units != models {
        return Err(NetworkError::UnitMismatch { models, units });
    }
    Ok(())
}
