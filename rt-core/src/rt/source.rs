//! [`TickSource`]: what the real-time loop runs once per tick.
//!
//! The loop is written against this small trait, so that it can be tested with the
//! deterministic [`TestPattern`] and run the thesis's pattern generator (LCN -> pulse shaper
//! -> LMN, Fig. 6.8) in production. A source is called exactly once per wake-up: after a
//! stall it is *not* called for the skipped periods, so it can never emit a catch-up burst.

use std::path::Path;
use std::time::Duration;

use super::reference::Target;
use fes_model::control::file::{Controller, ControllerFileError};
use fes_model::control::pattern_generator::{
    FeedbackMode, PatternGenerator, PatternGeneratorError, TickInput,
};
use fes_model::control::planner::{Deadline, PlannerStats};

/// The decision of one tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TickDecision {
    /// Fire one pulse now.
    pub pulse: bool,
    /// Continuous control signal u_cont (thesis 6.5.2).
    pub u_cont: f64,
    /// Pulse-shaper energy since the last pulse, E (eq. 6.8).
    pub energy: f64,
    /// Output of the simulated muscle model, normalised force.
    pub model_force: f64,
    /// Model force predicted over the input delay, normalised force.
    pub predicted_force: f64,
    /// Scheduling variable phi.
    pub phi: f64,
}

impl TickDecision {
    /// True when every number is finite.
    pub fn is_finite(&self) -> bool {
        [
            self.u_cont,
            self.energy,
            self.model_force,
            self.predicted_force,
            self.phi,
        ]
        .iter()
        .all(|v| v.is_finite())
    }
}

/// One step of a pattern generator, called once per tick from the real-time thread: it must
/// not allocate, lock, log or block.
pub trait TickSource {
    /// Decides this tick from the target (its value, normalised force in [0, 1], and
    /// whether it is heading to rest) and, in feedback mode, the latest measured force.
    fn tick(&mut self, target: &Target, measured_force: Option<f64>) -> TickDecision;

    /// The `periods` before this tick were skipped (the thread woke that late); called
    /// before [`Self::tick`]. Nothing was fired in them. A source that keeps time in ticks
    /// (a model of the muscle, a plan on the announced schedule) steps them without a
    /// pulse, so that its clock stays the wall clock's. Required, so that no wrapper can
    /// drop it unseen.
    fn missed(&mut self, periods: u32, target: &Target);

    /// Returns to rest (all states zero), e.g. after a fault.
    fn reset(&mut self);

    /// Shortest spacing between two pulses, in ticks, that this source guarantees (the
    /// thesis's shaper: a pulse is always followed by at least one empty sample, so 2).
    fn min_pulse_gap_ticks(&self) -> u32;

    /// What the source has to say when the loop ends (read after the hot path; may
    /// allocate). None by default.
    fn summary(&self) -> Option<String> {
        None
    }
}

/// The thesis's pattern generator (LCN -> pulse shaper -> LMN, Fig. 6.8) as a tick source,
/// built from a validated controller file (schema "fes-lcn/1").
#[derive(Debug, Clone)]
pub struct ControllerSource {
    generator: PatternGenerator,
    /// The planner's wall-clock budget per tick, ns (`None`: no clock, the step budget
    /// alone bounds it, deterministic).
    plan_budget_ns: Option<u64>,
    min_gap_ticks: u32,
    units: usize,
    mode: FeedbackMode,
}

/// The controller cannot run in this loop.
#[derive(Debug, thiserror::Error)]
pub enum ControllerSourceError {
    /// The controller file is unreadable or invalid.
    #[error(transparent)]
    File(#[from] ControllerFileError),
    /// The pattern generator cannot be built from it.
    #[error(transparent)]
    Generator(#[from] PatternGeneratorError),
    /// The controller was designed for another sampling period than the loop's.
    #[error(
        "the controller's model samples at {model_ts_us} us but the loop period is \
         {period_us} us (period_us must equal the model's Ts)"
    )]
    Period {
        /// The model's sampling period, µs.
        model_ts_us: f64,
        /// The loop period, µs.
        period_us: f64,
    },
}

impl ControllerSource {
    /// Reads and validates a controller file and checks that its model's sampling period is
    /// the loop `period`.
    pub fn load(path: &Path, period: Duration) -> Result<Self, ControllerSourceError> {
        Self::from_controller(&Controller::load(path)?, period)
    }

    /// Builds the source from a validated controller.
    pub fn from_controller(
        controller: &Controller,
        period: Duration,
    ) -> Result<Self, ControllerSourceError> {
        let model_ts = controller.network.ts();
        let period_s = period.as_secs_f64();
        if (model_ts - period_s).abs() > 1e-9 * period_s.max(model_ts) {
            return Err(ControllerSourceError::Period {
                model_ts_us: model_ts * 1e6,
                period_us: period_s * 1e6,
            });
        }
        let generator = controller.pattern_generator()?;
        let plan_budget_ns = generator
            .planner()
            .map(|p| (p.config().budget_us * 1e3) as u64);
        Ok(Self {
            plan_budget_ns,
            units: generator.network().units(),
            mode: generator.mode(),
            generator,
            min_gap_ticks: controller.settings.shaper.min_gap.saturating_add(1),
        })
    }

    /// Number of local models (units).
    pub fn units(&self) -> usize {
        self.units
    }

    /// The controller's feedback mode.
    pub fn mode(&self) -> FeedbackMode {
        self.mode
    }

    /// The wrapped pattern generator.
    pub fn generator(&self) -> &PatternGenerator {
        &self.generator
    }

    /// Planning bounded by its step budget alone, without reading the clock (tests that
    /// replay decisions; rt-core itself keeps the clock).
    pub fn without_plan_clock(mut self) -> Self {
        self.plan_budget_ns = None;
        self
    }

    /// The planner's counters (zero without planning).
    pub fn planner_stats(&self) -> PlannerStats {
        self.generator.stats().planner
    }
}

/// The planner's deadline in rt-core: CLOCK_MONOTONIC against the tick's start plus the
/// controller file's `planning.budget_us`.
struct ClockDeadline {
    until_ns: u64,
}

impl Deadline for ClockDeadline {
    #[inline]
    fn expired(&mut self) -> bool {
        fes_rt::rt::clock::monotonic_ns() >= self.until_ns
    }
}

/// The pattern generator's input for the tracker's `target` (and, in feedback mode, the
/// latest measured force).
#[inline]
fn tick_input(target: &Target, measured_force: Option<f64>) -> TickInput {
    TickInput {
        reference: target.value,
        measured_force,
        resting: target.resting,
        preview: target.preview,
    }
}

impl TickSource for ControllerSource {
    #[inline]
    fn tick(&mut self, target: &Target, measured_force: Option<f64>) -> TickDecision {
        let input = tick_input(target, measured_force);
        let out = match self.plan_budget_ns {
            Some(budget) => {
                let mut deadline = ClockDeadline {
                    until_ns: fes_rt::rt::clock::monotonic_ns().saturating_add(budget),
                };
                self.generator.tick_within(&input, &mut deadline)
            }
            None => self.generator.tick(&input),
        };
        TickDecision {
            pulse: out.pulse,
            u_cont: out.u_cont,
            energy: out.energy,
            model_force: out.model_force,
            predicted_force: out.predicted_force,
            phi: out.phi,
        }
    }

    fn missed(&mut self, periods: u32, target: &Target) {
        self.generator.missed(periods, &tick_input(target, None));
    }

    fn reset(&mut self) {
        self.generator.reset();
    }

    fn min_pulse_gap_ticks(&self) -> u32 {
        self.min_gap_ticks
    }

    fn summary(&self) -> Option<String> {
        self.generator.planner().map(|p| {
            let s = p.stats();
            format!(
                "planner: {} contraction(s) planned, {} replanned, {} rebased, {} converged; \
                 {} tick(s) decided by a plan, {} causal for want of a plan; {} tick(s) cut \
                 by the {} us budget; {} without an end in sight; plans dropped: {} for want \
                 of a preview, {} with nothing announced; {} skipped period(s) stepped \
                 without a pulse; {} rollouts, {} steps",
                s.windows,
                s.replans,
                s.rebased,
                s.converged,
                s.planned_ticks,
                s.causal_fallbacks,
                s.deadline_cuts,
                p.config().budget_us,
                s.no_end,
                s.dropped_no_preview,
                s.dropped_nothing_ahead,
                s.skipped_ticks,
                s.rollouts,
                s.steps
            )
        })
    }
}

/// Invalid [`TestPattern`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("test-pattern ipi_ticks = {0} must be at least 2 (a pulse is followed by an empty tick)")]
pub struct TestPatternError(pub u32);

/// A deterministic bench source with no muscle model: while the reference is above zero it
/// fires every `ipi_ticks` ticks, starting on the first such tick; a zero reference stops it
/// and restarts the count. `u_cont` echoes the reference; the model outputs are 0.
///
/// It exists to test and measure the real-time plumbing independently of the controller.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TestPattern {
    ipi_ticks: u32,
    since_last: Option<u32>,
}

impl TestPattern {
    /// A pattern with a constant inter-pulse interval of `ipi_ticks` (>= 2).
    pub fn new(ipi_ticks: u32) -> Result<Self, TestPatternError> {
        if ipi_ticks < 2 {
            return Err(TestPatternError(ipi_ticks));
        }
        Ok(Self {
            ipi_ticks,
            since_last: None,
        })
    }
}

impl TickSource for TestPattern {
    fn tick(&mut self, target: &Target, _measured_force: Option<f64>) -> TickDecision {
        let reference = target.value;
        // `reference > 0.0` is false for NaN as well: no pulse on a bad input.
        let pulse = if reference > 0.0 {
            let fire = self.since_last.is_none_or(|n| n + 1 >= self.ipi_ticks);
            self.since_last = if fire {
                Some(0)
            } else {
                self.since_last.map(|n| n + 1)
            };
            fire
        } else {
            self.since_last = None;
            false
        };
        TickDecision {
            pulse,
            u_cont: if reference.is_finite() {
                reference
            } else {
                0.0
            },
            ..TickDecision::default()
        }
    }

    /// The interval counts wall-clock ticks: skipped periods are ticks without a pulse.
    fn missed(&mut self, periods: u32, _target: &Target) {
        self.since_last = self.since_last.map(|n| n.saturating_add(periods));
    }

    fn reset(&mut self) {
        self.since_last = None;
    }

    fn min_pulse_gap_ticks(&self) -> u32 {
        self.ipi_ticks
    }
}
