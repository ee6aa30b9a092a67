//! The pattern generator: one 1 ms tick of the simulated closed loop of thesis Fig. 6.8,
//! LCN -> pulse shaper -> LMN, run in the model's *advanced form*.
//!
//! The model library runs the network as an undelayed core (state `z[k] = x[k+d]`, known
//! exactly at time `k` because every pulse that reaches it is already decided) followed by
//! a pure `d`-sample output delay. The controller acts on the core, so the loop
//! LCN -> shaper -> core has no delay and each frozen local loop has exactly the designed
//! poles; the force the model shows now is the core output of `d` samples ago.
//!
//! One tick at time `k` ([`FeedbackMode::Model`], the thesis's Fig. 6.6(b)):
//!
//! 1. `r` = reference clamped to `[0, 1]` (non-finite -> 0);
//! 2. activation `rho(phi_k)` of the core's scheduling value (model library);
//! 3. `u_cont = -K_I(phi) x_I - K_x(phi)' z[k]` (LCN, eq. C.26), clamped at zero unless
//!    the shaper sums the signed signal ([`ShaperSum`]);
//! 4. pulse = shaper(`u_cont`) (eq. 6.8); at rest (`r = 0`, or a reference ramping down to
//!    zero: [`TickInput::resting`]) the shaper rests instead (no pulse,
//!    its energy cleared: no stimulation while the muscle is to be at rest), and with
//!    [`AntiWindup::None`] the integrator is reset (every contraction starts from rest, as
//!    the thesis's step responses do; plain integral action would otherwise integrate the
//!    whole relaxation, and a rest force above zero without bound);
//! 5. core step with `u = pulse` (model library): predicted force `y[k+d]`, model force
//!    `y[k]`;
//! 6. `x_I += Ts (y[k+d] - r)` with conditional integration (eq. C.24, LCN).
//!
//! [`FeedbackMode::MeasuredForce`] (Fig. 6.6(a)) replaces step 2's core state by the one
//! re-predicted from the measured force by the state estimator ([`super::estimator`]), and
//! feeds the integrator with the Smith-predictor error
//! `e = y_pred[k+d] - r + (y_meas[k] - y_pred[k])`, where `y_pred[k]` is the prediction of
//! `y[k]` made `d` samples ago: for a perfect model the correction term is zero and the loop
//! is the designed one, and at steady state `e = 0` forces `y_meas = r` (zero steady-state
//! error on the *real* force). See docs/control.md for its limits.
//!
//! `tick` never allocates, locks, or panics on finite input: every type is fixed-size.

use serde::{Deserialize, Serialize};

use crate::model::{AdvancedForm, CoreState, DelayLine, Network, NetworkError, ThesisForm};

use super::design::LocalGains;
use super::estimator::{EstimatorError, ForceEstimator};
use super::lcn::{AntiWindup, ControlAction, LcnError, LocalControllerNetwork};
use super::planner::{
    CausalRollout, Deadline, NoDeadline, Planner, PlannerStats, PlanningConfig,
    PlanningConfigError, PlanningMode,
};
use super::preview::Preview;
use super::shaper::{PulseShaper, ShaperConfig, ShaperConfigError, ShaperStats, ShaperSum};

/// Which signal closes the controller's loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FeedbackMode {
    /// The simulated model closes the loop; no sensor needed (thesis Fig. 6.6(b), 6.8).
    #[default]
    Model,
    /// The measured force corrects the model state through the estimator and drives the
    /// integral action (thesis Fig. 6.6(a)).
    MeasuredForce,
}

/// Which model state the LCN feeds back in [`FeedbackMode::Model`] (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FeedbackState {
    /// The advanced core state `z[k] = x[k+d]`, integrating `y[k+d] - r`: the loop has no
    /// delay and each frozen local loop has exactly the designed poles (ours; the rule of
    /// controller files written before the choice was stored).
    #[default]
    Advanced,
    /// The model state now, `x[k] = z[k-d]`, integrating `y[k] - r`: the thesis's loop
    /// (Fig. 6.8, designed "assuming T_d = 0", C.2), whose `d`-sample delay the design
    /// ignores. The controller sees a pulse's effect only `d` samples after it fired. On a
    /// model of the undelayed scheduling class (eq. 5.2) the model runs in the thesis's form
    /// and the gains are scheduled on phi(t) = Gamma{u(t)}, as the thesis schedules them.
    Delayed,
}

impl FeedbackState {
    /// The choice of a controller file that does not name one: [`FeedbackState::Advanced`].
    pub const fn legacy() -> Self {
        Self::Advanced
    }
}

/// Most skipped periods [`PatternGenerator::missed`] steps (50 ms: a stall longer than
/// that is a fault of the host, not scheduling noise, and stepping it would make the
/// late tick later still).
pub const MAX_CATCH_UP_TICKS: u32 = 50;

/// Inputs of one tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TickInput {
    /// Reference force `r`, normalised (clamped to `[0, 1]`; non-finite -> 0).
    pub reference: f64,
    /// Measured force `y[k]`, normalised (used only in [`FeedbackMode::MeasuredForce`]).
    pub measured_force: Option<f64>,
    /// The reference is heading to rest (ramping down to zero): the shaper rests as at a
    /// zero reference (rt-core's reference tracker sets it; `false` when only a value is
    /// known).
    pub resting: bool,
    /// The setpoints known ahead ([`Preview::NONE`]: none; the planner then leaves the
    /// decision to the causal loop).
    pub preview: Preview,
}

/// Outputs of one tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TickOutput {
    /// Fire a pulse now.
    pub pulse: bool,
    /// Control signal handed to the shaper (clamped at 0 unless the shaper sums the signed
    /// signal).
    pub u_cont: f64,
    /// Unclamped control law `-K_I x_I - K_x' z`.
    pub u_raw: f64,
    /// Shaper energy `E` after this tick.
    pub energy: f64,
    /// Model force now, `y[k]` (measured mode: the estimator's `ŷ[k]`).
    pub model_force: f64,
    /// Predicted force `y[k+d]` (the core output; on a model of the undelayed scheduling
    /// class, which cannot be run ahead, the model force `y[k]`).
    pub predicted_force: f64,
    /// Scheduling value `phi` used for this tick.
    pub phi: f64,
    /// Integrator state `x_I` used for this tick (before the update).
    pub x_i: f64,
    /// Core state `z[k]` used for this tick.
    pub z: [f64; 2],
    /// Whether the integrator integrated (false while anti-windup holds it).
    pub integrated: bool,
    /// Measured mode: innovation `y[k] - ŷ[k]` (0 otherwise or when the sample was missing).
    pub innovation: f64,
    /// The decision came from the planner's plan (false: the causal LCN + shaper).
    pub planned: bool,
}

/// Why a pattern generator could not be built.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum PatternGeneratorError {
    /// The network's local models are ARX; the LCN needs state-space ones.
    #[error("the model's local models are ARX; the LCN needs state-space local models")]
    NotStateSpace,
    /// One controller per local model is needed.
    #[error("{controllers} local controllers given for {units} local models")]
    UnitMismatch {
        /// Controllers given.
        controllers: usize,
        /// Units of the model.
        units: usize,
    },
    /// Measured-force mode without estimator gains.
    #[error("feedback mode measured_force needs one estimator gain per unit")]
    MissingEstimator,
    /// The delayed feedback state exists in the model mode only.
    #[error(
        "feedback_state delayed needs mode model (the measured-force mode re-predicts the advanced state)"
    )]
    DelayedMeasured,
    /// Invalid LCN gains.
    #[error(transparent)]
    Lcn(#[from] LcnError),
    /// Invalid shaper settings.
    #[error(transparent)]
    Shaper(#[from] ShaperConfigError),
    /// Invalid estimator.
    #[error(transparent)]
    Estimator(#[from] EstimatorError),
    /// Invalid planner settings.
    #[error(transparent)]
    Planning(#[from] PlanningConfigError),
    /// The planner's warm start runs the advanced loop.
    #[error("planning needs feedback_state advanced")]
    PlanningDelayed,
    /// The network cannot start.
    #[error(transparent)]
    Network(#[from] NetworkError),
}

/// Measured-force loop state.
#[derive(Debug, Clone, Copy)]
struct MeasuredLoop {
    estimator: ForceEstimator,
    /// Core outputs predicted over the last `d` samples; popping gives the prediction of
    /// `y[k]` made at `k - d`.
    predictions: DelayLine<f64>,
    initial_predictions: DelayLine<f64>,
}

/// Counters since construction or the last reset.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PatternGeneratorStats {
    /// Ticks run.
    pub ticks: u64,
    /// References that were not finite or outside `[0, 1]` and were clamped.
    pub references_clamped: u64,
    /// Ticks on which the anti-windup held the integrator.
    pub integrator_held: u64,
    /// Measured mode: samples without a usable measurement.
    pub measurements_missing: u64,
    /// Shaper counters.
    pub shaper: ShaperStats,
    /// Planner counters (all zero without planning).
    pub planner: PlannerStats,
}

/// The model the loop runs.
#[derive(Debug, Clone)]
enum Core {
    /// Ahead of the pulses (module docs); every mode and state.
    Advanced(AdvancedForm<f64>),
    /// In the thesis's form, `x[k]`: the delayed loop on a model of the undelayed scheduling
    /// class, which cannot run ahead ([`Network::can_run_ahead`]).
    Thesis(ThesisForm<f64>),
}

impl Core {
    fn network(&self) -> &Network<f64> {
        match self {
            Self::Advanced(c) => c.network(),
            Self::Thesis(c) => c.network(),
        }
    }

    /// The state the next step starts from (advanced: z\[k\]; thesis form: x\[k\]).
    fn state(&self) -> &CoreState<f64> {
        match self {
            Self::Advanced(c) => c.state(),
            Self::Thesis(c) => c.state(),
        }
    }
}

/// Whether the loop of `mode` and `state` runs on `net`: every loop does where the model can
/// be run ahead; on the undelayed scheduling class (eq. 5.2) only the thesis's delayed loop
/// in model mode (shared by the generator and the controller design).
pub fn loop_runs_on(net: &Network<f64>, mode: FeedbackMode, state: FeedbackState) -> bool {
    net.can_run_ahead() || (mode, state) == (FeedbackMode::Model, FeedbackState::Delayed)
}

/// The pattern generator (thesis Fig. 6.8 in the advanced form).
#[derive(Debug, Clone)]
pub struct PatternGenerator {
    core: Core,
    initial_core: Core,
    lcn: LocalControllerNetwork,
    shaper: PulseShaper,
    measured: Option<MeasuredLoop>,
    /// [`FeedbackState::Delayed`]: the last `d` core states; pushing `z[k]` returns
    /// `z[k-d] = x[k]`.
    delayed: Option<DelayLine<CoreState<f64>>>,
    initial_delayed: Option<DelayLine<CoreState<f64>>>,
    planner: Option<Planner>,
    ticks: u64,
    references_clamped: u64,
    integrator_held: u64,
}

impl PatternGenerator {
    /// Build from a state-space network, one gain set per unit, shaper settings, the
    /// anti-windup rule, the feedback mode and state and, for
    /// [`FeedbackMode::MeasuredForce`], one estimator gain per unit. May allocate; `tick`
    /// does not.
    pub fn new(
        net: Network<f64>,
        gains: &[LocalGains],
        shaper: ShaperConfig,
        anti_windup: AntiWindup,
        mode: FeedbackMode,
        feedback_state: FeedbackState,
        estimator_gains: Option<&[[f64; 2]]>,
    ) -> Result<Self, PatternGeneratorError> {
        if net.ss_unit(0).is_none() {
            return Err(PatternGeneratorError::NotStateSpace);
        }
        if gains.len() != net.units() {
            return Err(PatternGeneratorError::UnitMismatch {
                controllers: gains.len(),
                units: net.units(),
            });
        }
        let lcn = LocalControllerNetwork::new(gains, net.ts(), anti_windup)?;
        let shaper = PulseShaper::new(shaper)?;
        if !loop_runs_on(&net, mode, feedback_state) {
            return Err(NetworkError::CannotRunAhead { delay: net.delay() }.into());
        }
        if !net.can_run_ahead() {
            // The undelayed class (eq. 5.2): the thesis's delayed loop, on the model in the
            // thesis's form.
            let core = Core::Thesis(ThesisForm::new(net)?);
            return Ok(Self {
                initial_core: core.clone(),
                core,
                lcn,
                shaper,
                measured: None,
                initial_delayed: None,
                delayed: None,
                planner: None,
                ticks: 0,
                references_clamped: 0,
                integrator_held: 0,
            });
        }
        let core = AdvancedForm::new(net)?;
        let measured = match mode {
            FeedbackMode::Model => None,
            FeedbackMode::MeasuredForce => {
                let l = estimator_gains.ok_or(PatternGeneratorError::MissingEstimator)?;
                let estimator = ForceEstimator::new(&net, l)?;
                let d = net.delay();
                let mut predictions = DelayLine::new(d, 0.0).ok_or(NetworkError::Delay(d))?;
                for i in 0..d {
                    predictions.push(core.pending_output(i).unwrap_or(0.0));
                }
                Some(MeasuredLoop {
                    estimator,
                    predictions,
                    initial_predictions: predictions,
                })
            }
        };
        let delayed = match (feedback_state, mode) {
            (FeedbackState::Advanced, _) => None,
            (FeedbackState::Delayed, FeedbackMode::MeasuredForce) => {
                return Err(PatternGeneratorError::DelayedMeasured);
            }
            (FeedbackState::Delayed, FeedbackMode::Model) => {
                let d = net.delay();
                Some(DelayLine::new(d, *core.state()).ok_or(NetworkError::Delay(d))?)
            }
        };
        let core = Core::Advanced(core);
        Ok(Self {
            initial_core: core.clone(),
            core,
            lcn,
            shaper,
            measured,
            initial_delayed: delayed,
            delayed,
            planner: None,
            ticks: 0,
            references_clamped: 0,
            integrator_held: 0,
        })
    }

    /// Adds receding-horizon planning over the preview ([`super::planner`]);
    /// [`PlanningMode::Off`] leaves the generator as it is (causal, bit for bit). Allocates
    /// the planner's buffers.
    pub fn with_planning(mut self, cfg: PlanningConfig) -> Result<Self, PatternGeneratorError> {
        if cfg.mode == PlanningMode::Off {
            self.planner = None;
            return Ok(self);
        }
        if self.delayed.is_some() || matches!(self.core, Core::Thesis(_)) {
            return Err(PatternGeneratorError::PlanningDelayed);
        }
        let min_ipi = self.shaper.config().min_gap as usize + 1;
        self.planner = Some(Planner::new(cfg, self.core.network().ts(), min_ipi)?);
        Ok(self)
    }

    /// The planner, when planning is on.
    pub fn planner(&self) -> Option<&Planner> {
        self.planner.as_ref()
    }

    /// The feedback mode.
    pub fn mode(&self) -> FeedbackMode {
        if self.measured.is_some() {
            FeedbackMode::MeasuredForce
        } else {
            FeedbackMode::Model
        }
    }

    /// The model network.
    pub fn network(&self) -> &Network<f64> {
        self.core.network()
    }

    /// The LCN (gains and integrator state).
    pub fn lcn(&self) -> &LocalControllerNetwork {
        &self.lcn
    }

    /// Counters since construction or the last reset.
    pub fn stats(&self) -> PatternGeneratorStats {
        PatternGeneratorStats {
            ticks: self.ticks,
            references_clamped: self.references_clamped,
            integrator_held: self.integrator_held,
            measurements_missing: self.measured.as_ref().map_or(0, |m| m.estimator.missing()),
            shaper: self.shaper.stats(),
            planner: self
                .planner
                .as_ref()
                .map(Planner::stats)
                .unwrap_or_default(),
        }
    }

    /// Back to rest: model at rest, `x_I = 0`, `E = 0`, counters zero. Does not allocate.
    pub fn reset(&mut self) {
        self.core.clone_from(&self.initial_core);
        self.lcn.reset();
        self.shaper.reset();
        self.delayed = self.initial_delayed;
        if let Some(p) = self.planner.as_mut() {
            p.reset();
        }
        if let Some(m) = self.measured.as_mut() {
            m.estimator.reset(self.core.network());
            m.predictions = m.initial_predictions;
        }
        self.ticks = 0;
        self.references_clamped = 0;
        self.integrator_held = 0;
    }

    /// One tick (module docs): decide whether to fire a pulse now. With planning, the
    /// planner's step budget alone bounds its work (deterministic).
    #[inline]
    pub fn tick(&mut self, input: &TickInput) -> TickOutput {
        self.advance(input, true, &mut NoDeadline, false)
    }

    /// Periods the caller skipped before this tick (its thread stalled past them): the
    /// stimulator received nothing in them, so each is stepped as a tick in which no pulse
    /// is fired and nothing is planned (model, controller and planner clock stay on wall
    /// time, and the muscle's model decays as the muscle did). At most
    /// [`MAX_CATCH_UP_TICKS`] are stepped; a longer stall leaves the model that much
    /// behind. `input` is this tick's (its measurement, if any, is not used for them).
    pub fn missed(&mut self, periods: u32, input: &TickInput) {
        let quiet = TickInput {
            measured_force: None,
            ..*input
        };
        for _ in 0..periods.min(MAX_CATCH_UP_TICKS) {
            self.advance(&quiet, true, &mut NoDeadline, true);
        }
    }

    /// [`Self::tick`] with a caller's clock: the planner stops planning when `deadline`
    /// says the tick's time is up (rt-core), keeping the plan it has or, without one,
    /// leaving the decision to the causal loop (both counted).
    #[inline]
    pub fn tick_within(&mut self, input: &TickInput, deadline: &mut dyn Deadline) -> TickOutput {
        self.advance(input, true, deadline, false)
    }

    /// One tick with the pulse shaper bypassed: `u_cont` itself drives the model (the
    /// continuous loop of the design, for analysis and verification; never for
    /// stimulation — `pulse` is always `false`).
    pub fn tick_unshaped(&mut self, input: &TickInput) -> TickOutput {
        self.advance(input, false, &mut NoDeadline, false)
    }

    #[inline(always)]
    fn reference(&mut self, r: f64) -> f64 {
        if r.is_finite() && (0.0..=1.0).contains(&r) {
            r
        } else {
            self.references_clamped += 1;
            if r.is_finite() {
                r.clamp(0.0, 1.0)
            } else {
                0.0
            }
        }
    }

    #[inline(always)]
    fn advance(
        &mut self,
        input: &TickInput,
        shaped: bool,
        deadline: &mut dyn Deadline,
        withheld: bool,
    ) -> TickOutput {
        self.ticks += 1;
        let r = self.reference(input.reference);
        // At rest (a zero reference, or one ramping down to zero) the shaper rests.
        let rest = r == 0.0 || input.resting;
        let facts = TickFacts {
            preview: &input.preview,
            r,
            rest,
            shaped,
            withheld,
            clamp: self.shaper.config().sum == ShaperSum::Clamped,
            x_i: self.lcn.x_i(),
        };
        let out = if self.measured.is_some() {
            self.advance_measured(input.measured_force, &facts, deadline)
        } else {
            self.advance_model(&facts, deadline)
        };
        if !out.integrated {
            self.integrator_held += 1;
        }
        if rest && shaped && self.lcn.anti_windup() == AntiWindup::None {
            self.lcn.reset();
        }
        out
    }

    /// The tick in model mode: the LCN feeds back the model's state (advanced, or the
    /// thesis's delayed one), Fig. 6.8.
    #[inline(always)]
    fn advance_model(&mut self, facts: &TickFacts<'_>, deadline: &mut dyn Deadline) -> TickOutput {
        let TickFacts { r, clamp, x_i, .. } = *facts;
        let core_now = *self.core.state();
        let act_core = self.core.network().activation(&core_now);
        // The state fed back: the advanced core state, or the model state now.
        let (act, state) = match self.delayed.as_mut() {
            None => (act_core, core_now),
            Some(ring) => {
                let x = ring.push(core_now);
                (self.core.network().activation(&x), x)
            }
        };
        let (phi, z) = (state.phi, state.ss_state());
        let action = self.lcn.control(&act, z, clamp);
        let (pulse, u, planned) = plan_and_decide(
            self.planner.as_mut(),
            &mut self.shaper,
            &self.lcn,
            self.core.network(),
            &core_now,
            facts,
            action.u_cont,
            deadline,
        );
        // The thesis's form has no prediction: its y[k] stands in for y[k+d].
        let (y, y_ahead, ahead_fed_back) = match &mut self.core {
            Core::Advanced(c) => {
                let step = c.step_with_activation(&act_core, u);
                (step.y, step.y_ahead, self.delayed.is_none())
            }
            Core::Thesis(c) => {
                let y = c.step_with_activation(&act_core, u);
                (y, y, false)
            }
        };
        let y_fed_back = if ahead_fed_back { y_ahead } else { y };
        let integrated = self.lcn.integrate(&action, y_fed_back - r);
        TickOutput {
            pulse,
            u_cont: action.u_cont,
            u_raw: action.u_raw,
            energy: self.shaper.energy(),
            model_force: y,
            predicted_force: y_ahead,
            phi,
            x_i,
            z,
            integrated,
            innovation: 0.0,
            planned: planned.is_some(),
        }
    }

    /// The tick in measured-force mode: the LCN feeds back the estimator's state,
    /// corrected by the measured force, Fig. 6.6(a).
    #[inline(always)]
    fn advance_measured(
        &mut self,
        measured_force: Option<f64>,
        facts: &TickFacts<'_>,
        deadline: &mut dyn Deadline,
    ) -> TickOutput {
        let Some(m) = self.measured.as_mut() else {
            return self.advance_model(facts, deadline);
        };
        let TickFacts { r, clamp, x_i, .. } = *facts;
        let net = self.core.network();
        let upd = m.estimator.update(net, measured_force);
        let mut core = upd.core;
        let act = net.activation(&core);
        let phi = core.phi;
        let z = core.ss_state();
        let action = self.lcn.control(&act, z, clamp);
        let (pulse, u, planned) = plan_and_decide(
            self.planner.as_mut(),
            &mut self.shaper,
            &self.lcn,
            net,
            &core,
            facts,
            action.u_cont,
            deadline,
        );
        let y_ahead = net.step_with_activation(&mut core, &act, u);
        let y_pred_now = m.predictions.push(y_ahead);
        m.estimator.push_pulse(u);
        let mismatch = if upd.measured {
            upd.innovation + upd.model_force - y_pred_now
        } else {
            0.0
        };
        let integrated = self.lcn.integrate(&action, y_ahead - r + mismatch);
        TickOutput {
            pulse,
            u_cont: action.u_cont,
            u_raw: action.u_raw,
            energy: self.shaper.energy(),
            model_force: upd.model_force,
            predicted_force: y_ahead,
            phi,
            x_i,
            z,
            integrated,
            innovation: upd.innovation,
            planned: planned.is_some(),
        }
    }
}

/// The causal loop (LCN + shaper, model mode, advanced state) on copies of its state,
/// rolled forward by the planner as its warm start: exactly the decisions
/// [`PatternGenerator::tick`] would make without a plan, on the plan's reference.
struct WarmStart<'a> {
    net: &'a Network<f64>,
    lcn0: LocalControllerNetwork,
    shaper0: PulseShaper,
    lcn: LocalControllerNetwork,
    shaper: PulseShaper,
    clamp: bool,
    action: Option<ControlAction>,
}

impl<'a> WarmStart<'a> {
    fn new(
        net: &'a Network<f64>,
        lcn: &LocalControllerNetwork,
        shaper: &PulseShaper,
        clamp: bool,
    ) -> Self {
        Self {
            net,
            lcn0: *lcn,
            shaper0: *shaper,
            lcn: *lcn,
            shaper: *shaper,
            clamp,
            action: None,
        }
    }
}

impl CausalRollout for WarmStart<'_> {
    fn begin(&mut self) {
        self.lcn = self.lcn0;
        self.shaper = self.shaper0;
        self.action = None;
    }

    fn decide(&mut self, st: &CoreState<f64>, _r: f64, rest: bool) -> bool {
        let act = self.net.activation(st);
        let action = self.lcn.control(&act, st.ss_state(), self.clamp);
        self.action = Some(action);
        apply(&mut self.shaper, action.u_cont, rest, true).0
    }

    fn observe(&mut self, y_ahead: f64, r: f64, rest: bool) {
        if let Some(action) = self.action.take() {
            self.lcn.integrate(&action, y_ahead - r);
        }
        if rest && self.lcn.anti_windup() == AntiWindup::None {
            self.lcn.reset();
        }
    }
}

/// What one tick's decision depends on besides the loop's state.
#[derive(Clone, Copy)]
struct TickFacts<'a> {
    preview: &'a Preview,
    /// The reference now.
    r: f64,
    /// At rest (zero reference or a ramp down to it).
    rest: bool,
    /// The shaper decides (not the continuous bypass).
    shaped: bool,
    /// The driver withholds this tick's pulse (the plan counts it as not fired).
    withheld: bool,
    /// The LCN's signed sum clamped (eq. 3.10's variant).
    clamp: bool,
    /// The LCN's integrator state before this tick (reported).
    x_i: f64,
}

/// One tick's pulse decision on the network state `st`: the receding-horizon plan over
/// the preview (the causal LCN + shaper as its warm start and fallback) when planning is
/// on, else the shaper's ([`decide`]); the planner then learns what was applied. Returns
/// (pulse, input applied, the plan's answer if it gave one).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn plan_and_decide(
    planner: Option<&mut Planner>,
    shaper: &mut PulseShaper,
    lcn: &LocalControllerNetwork,
    net: &Network<f64>,
    st: &CoreState<f64>,
    f: &TickFacts<'_>,
    u_cont: f64,
    deadline: &mut dyn Deadline,
) -> (bool, f64, Option<bool>) {
    let Some(p) = planner else {
        // A withheld tick is not fired and leaves the shaper as it is, planning or not.
        let planned = f.withheld.then_some(false);
        let (pulse, u) = decide(shaper, u_cont, f.rest, f.shaped, planned);
        return (pulse, u, planned);
    };
    let planned = if f.withheld {
        Some(false)
    } else if f.shaped {
        let mut warm = WarmStart::new(net, lcn, shaper, f.clamp);
        p.plan(net, st, f.preview, f.r, f.rest, &mut warm, deadline)
    } else {
        None
    };
    let (pulse, u) = decide(shaper, u_cont, f.rest, f.shaped, planned);
    if f.withheld {
        p.skip(net, st);
    } else {
        p.commit(net, st, u);
    }
    (pulse, u, planned)
}

/// The tick's decision: the plan's when there is one (never at rest; the shaper is not
/// stepped, so its energy stays as the causal loop left it), else the shaper's.
#[inline(always)]
fn decide(
    shaper: &mut PulseShaper,
    u_cont: f64,
    rest: bool,
    shaped: bool,
    planned: Option<bool>,
) -> (bool, f64) {
    match planned {
        Some(p) if shaped => {
            let fire = p && !rest;
            (fire, if fire { 1.0 } else { 0.0 })
        }
        _ => apply(shaper, u_cont, rest, shaped),
    }
}

/// Shaper decision, or the bypass: returns (pulse, input applied to the model). At a
/// zero reference `r` the shaper rests: no pulse, its energy cleared
/// ([`PulseShaper::rest`]); the bypass (analysis of the continuous loop) is not gated.
#[inline(always)]
fn apply(shaper: &mut PulseShaper, u_cont: f64, rest: bool, shaped: bool) -> (bool, f64) {
    if !shaped {
        return (false, u_cont);
    }
    if rest {
        shaper.rest();
        return (false, 0.0);
    }
    let p = shaper.step(u_cont);
    (p, if p { 1.0 } else { 0.0 })
}
