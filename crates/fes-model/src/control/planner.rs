//! Receding-horizon pulse decisions over the reference preview.
//!
//! The thesis's generator is "a simulated closed-loop controller as part of a feedforward
//! control technique" (6.5.4): it runs on the model, not on the muscle, and the cardiac
//! reference it follows is known a contraction ahead (ch. 1; [`super::preview`]). The
//! LCN + shaper decide causally: they cannot see that a contraction ends, so the last
//! pulse comes late and its force lands in the relaxation, and one loop with fixed rise
//! times cannot be fast at the onset and frugal on the plateau at every level. The planner
//! chooses the pulse times of the next contraction on the same network instead, minimising
//!
//! ```text
//! J = sum_j (y_core[j] - r[j])^2 + lambda * pulses            (j over the horizon)
//! ```
//!
//! the objective of the thesis's optimal patterns (6.4: force-time integral against the
//! number of pulses) written as tracking error plus a price per pulse. The price is
//! `lambda` itself ([`LambdaScale::Fixed`], eq. 6.4's constant weight) or `lambda` times
//! the contraction's level ([`LambdaScale::Level`], the default: the error a pulse removes
//! grows with the level, and a fixed price buys one pulse too few at low levels and one
//! too many at high ones). `y_core[j]` is the
//! network's core output (the force `d` samples after `j`, the advanced form), so a pulse
//! decided at `j` is judged by the force it causes, exactly as the LCN's integrator judges it.
//!
//! **Horizon.** From the tick the contraction is first seen (in the rest before it, as soon
//! as the previous contraction ends) to the next onset or `max_tail_ms` after its end,
//! whichever is first: one contraction plus its relaxation. Pulses may come only inside
//! the contraction (the target positive and not heading to rest), at least the shaper's
//! minimum interval apart, as the causal loop's.
//!
//! **Candidates.** (1) the LCN + shaper rolled forward on a copy of the loop (the warm
//! start), (2) every constant-frequency train `min_hz..=max_hz` started at the onset and
//! stopped after each of its pulses (`CFT(f, n)`, so that on the model the plan is never
//! worse than any train with no more pulses: with `J` minimal, `SSE_plan <= SSE_train +
//! lambda (n_train - n_plan)`), then (3) a local search on the best: each pulse shifted by
//! 1-8 ticks, deleted, or a pulse inserted, every later pulse shifted together, or a pulse
//! deleted with every later one moved 8, 16 or 32 ticks later (its force given back by the
//! rest coming later: from the onset pair the trains give, the slow muscle's one pulse at
//! 43 ms that holds 0.2 is two moves away, and neither a deletion nor a shift alone
//! improves), first improvement, until a full pass improves nothing. Every rollout starts
//! from the state stored at the pulse before the first change and stops as soon as its
//! cost exceeds the best (branch and bound).
//!
//! **Receding.** The plan is made over the whole contraction before it starts and kept as
//! the ticks pass; the search goes on within each tick's budget on the pulses not yet
//! fired. When the state the generator hands in differs from the one the plan predicted
//! (the measured-force mode's estimator corrected it, or the causal loop decided before a
//! plan existed, or a pulse it wanted fell in a period the caller skipped, which then
//! moves to the first tick allowed after it), the plan is re-evaluated from the state
//! now; when the announced contraction changes (the outer loop moved the next level, an
//! operator's change), it is made again. A stall is not a change: the clock counts the
//! periods skipped ([`Planner::skip`]).
//!
//! **Budget.** Work is counted in network steps: at most `budget_steps` per tick (plus one
//! rollout already started), and a caller's deadline ([`Deadline`], rt-core's clock) is
//! asked before each rollout. Without a plan the tick is the causal one (counted). Every
//! buffer is allocated at construction; nothing allocates, locks or panics per tick.

use alloc::boxed::Box;

use serde::{Deserialize, Serialize};

use super::preview::Preview;
use crate::model::{CoreState, Network};

/// Longest horizon in ticks (a contraction and its relaxation at 60 beats/min and 1 ms).
pub const MAX_HORIZON: usize = 2048;

/// Most pulses a plan holds (a 950 ms contraction at 100 Hz and then some).
pub const MAX_PLAN_PULSES: usize = 128;

/// Whether the pattern generator plans over the preview.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PlanningMode {
    /// The causal LCN + shaper decide every pulse (the rule of files without planning).
    #[default]
    Off,
    /// Receding-horizon pulse decisions over the preview (module docs).
    RecedingHorizon,
}

/// How the plan prices a pulse (`lambda_scale` of the controller file's `planning`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LambdaScale {
    /// `lambda` itself, the same at every level: eq. 6.4's constant weight of the pulse
    /// count (the rule of files without the key).
    #[default]
    Fixed,
    /// `lambda` times the contraction's level: the squared error a pulse can remove grows
    /// with the level, so a fixed price is dear at low levels (one pulse too few) and cheap
    /// at high ones. Measured on the in-process bench (docs/control.md, section 11).
    Level,
}

/// Planner settings (controller file `planning`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanningConfig {
    /// Off (causal) or receding horizon.
    pub mode: PlanningMode,
    /// Price of one pulse, in the units of the summed squared error (normalised force
    /// squared, summed over 1 ms ticks). 0: as many pulses as track best.
    pub lambda: f64,
    /// Whether `lambda` is the price at every level or scales with the contraction's.
    #[serde(default)]
    pub lambda_scale: LambdaScale,
    /// Lowest and highest frequency of the train candidates, Hz.
    pub min_hz: u32,
    /// Highest train frequency, Hz.
    pub max_hz: u32,
    /// Weight `mu` of the plateau's mean error: `J` adds `mu N_p mean_p(y - r)^2` over the
    /// second half of the contraction (`plateau_start` on), the level the outer loop
    /// regulates. Like the LCN's integral action it holds the level on average; without it
    /// (0) a plan may trade the plateau's mean for a pulse less, and the outer loop then
    /// hunts between pulse counts.
    pub mean_weight: f64,
    /// Start of the plateau as a fraction of the contraction, in [0, 1).
    pub plateau_start: f64,
    /// Price of each pulse a contraction has more or fewer than the last one, in the
    /// units of `lambda`. Between two pulse counts whose plateaus straddle the target the
    /// outer loop would otherwise move the level to and fro, and the pattern with it, beat
    /// after beat; the price makes the count change only when it pays.
    #[serde(default)]
    pub count_change: f64,
    /// Shortest interval between two pulses after the opening burst, ms (0: no such rule,
    /// the rule of files without the key). The thesis's patterns (6.5.4) open with a
    /// doublet or triplet (intervals of at most 10 ms) and go on with nearly even pulses;
    /// a plan may otherwise put a close pair in the middle of the contraction where the
    /// model sees two spread pulses' worth of force. A fatiguing muscle's catch-like gain
    /// answers such a pair far above the model identified on the fresh muscle (the bench
    /// under fatigue: +12 % beats alternating with -7 % ones as the plan moves one pulse
    /// of a pair; docs/control.md, section 11). With a value `m`, an interval shorter than
    /// `m` comes only while every earlier interval of the contraction is shorter than `m`.
    #[serde(default)]
    pub burst_ipi_ms: f64,
    /// Lowest contraction level (its highest target) that may open with a burst (0: every
    /// level, the rule of files without the key). Below it no interval of the contraction
    /// is shorter than `burst_ipi_ms`. The opening doublet buys the fast rise a high level
    /// needs, but at low levels a fatiguing muscle answers it above the model, and the
    /// plan's switch from evenly spread pulses to a pattern with a doublet, as the outer
    /// loop raises the level, is then the worst beat of the run (docs/control.md,
    /// section 11, "Bursts by level").
    #[serde(default)]
    pub burst_min_level: f64,
    /// Relaxation counted after a contraction's end, at most, ms (the horizon ends at the
    /// next onset if that is sooner).
    pub max_tail_ms: u32,
    /// Network steps of planning work per tick (deterministic bound).
    pub budget_steps: u32,
    /// Wall-clock planning budget per tick, µs: rt-core stops planning past it.
    pub budget_us: f64,
}

impl Default for PlanningConfig {
    /// Off, with [`PlanningConfig::RECOMMENDED`]'s numbers.
    fn default() -> Self {
        Self {
            mode: PlanningMode::Off,
            ..Self::RECOMMENDED
        }
    }
}

impl PlanningConfig {
    /// Planning on with the settings measured on the in-process bench (docs/control.md,
    /// section 11): a pulse priced at the contraction's level (`lambda` 1.0, scale
    /// `level`: every constant train beaten from 0.1 to 0.9 on the fast muscle, where the
    /// fixed 0.5 lost 0.1), `mean_weight` 20 with the supervisor's plateau
    /// (the second half of the contraction), trains 5-100 Hz, a relaxation of up to
    /// 500 ms, 3000 network steps (about 150 µs on this project's 2-core VM) and 200 µs
    /// per tick.
    pub const RECOMMENDED: PlanningConfig = PlanningConfig {
        mode: PlanningMode::RecedingHorizon,
        lambda: 1.0,
        lambda_scale: LambdaScale::Level,
        mean_weight: 20.0,
        plateau_start: 0.5,
        count_change: 2.0,
        burst_ipi_ms: 0.0,
        burst_min_level: 0.0,
        min_hz: 5,
        max_hz: 100,
        max_tail_ms: 500,
        budget_steps: 3000,
        budget_us: 200.0,
    };
}

/// Invalid planner settings.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum PlanningConfigError {
    /// `lambda` must be finite and non-negative.
    #[error("planning lambda = {0} must be finite and >= 0")]
    Lambda(f64),
    /// `mean_weight` must be finite and non-negative.
    #[error("planning mean_weight = {0} must be finite and >= 0")]
    MeanWeight(f64),
    /// `count_change` must be finite and non-negative.
    #[error("planning count_change = {0} must be finite and >= 0")]
    CountChange(f64),
    /// `burst_ipi_ms` must be finite, non-negative and at most a horizon.
    #[error("planning burst_ipi_ms = {0} must be finite and in [0, 1000]")]
    BurstIpi(f64),
    /// `burst_min_level` must be finite and non-negative.
    #[error("planning burst_min_level = {0} must be finite and >= 0")]
    BurstMinLevel(f64),
    /// `plateau_start` must lie in [0, 1).
    #[error("planning plateau_start = {0} must be in [0, 1)")]
    PlateauStart(f64),
    /// The train range must satisfy 1 <= min_hz <= max_hz <= 1000.
    #[error("planning trains {min_hz}-{max_hz} Hz: need 1 <= min_hz <= max_hz <= 1000")]
    Trains {
        /// Lowest.
        min_hz: u32,
        /// Highest.
        max_hz: u32,
    },
    /// The tail must fit the horizon.
    #[error("planning max_tail_ms = {0} must be in 0..={MAX_HORIZON}")]
    Tail(u32),
    /// The step budget must be positive and bounded (one work item, at most a horizon of
    /// steps, runs whenever any budget is left).
    #[error("planning budget_steps = {0} must be in 256..=10000000")]
    BudgetSteps(u32),
    /// The time budget must be finite and positive.
    #[error("planning budget_us = {0} must be finite and > 0")]
    BudgetUs(f64),
}

impl PlanningConfig {
    /// The price of one pulse in a contraction of `level` (its highest target): `lambda`,
    /// times `level` under [`LambdaScale::Level`].
    pub fn price(&self, level: f64) -> f64 {
        match self.lambda_scale {
            LambdaScale::Fixed => self.lambda,
            LambdaScale::Level => self.lambda * level,
        }
    }

    /// Checks the settings.
    pub fn validate(&self) -> Result<(), PlanningConfigError> {
        if !(self.lambda.is_finite() && self.lambda >= 0.0) {
            return Err(PlanningConfigError::Lambda(self.lambda));
        }
        if !(self.mean_weight.is_finite() && self.mean_weight >= 0.0) {
            return Err(PlanningConfigError::MeanWeight(self.mean_weight));
        }
        if !(self.count_change.is_finite() && self.count_change >= 0.0) {
            return Err(PlanningConfigError::CountChange(self.count_change));
        }
        if !(self.burst_ipi_ms.is_finite() && (0.0..=1000.0).contains(&self.burst_ipi_ms)) {
            return Err(PlanningConfigError::BurstIpi(self.burst_ipi_ms));
        }
        if !(self.burst_min_level.is_finite() && self.burst_min_level >= 0.0) {
            return Err(PlanningConfigError::BurstMinLevel(self.burst_min_level));
        }
        if !(self.plateau_start.is_finite() && (0.0..1.0).contains(&self.plateau_start)) {
            return Err(PlanningConfigError::PlateauStart(self.plateau_start));
        }
        if !(1 <= self.min_hz && self.min_hz <= self.max_hz && self.max_hz <= 1000) {
            return Err(PlanningConfigError::Trains {
                min_hz: self.min_hz,
                max_hz: self.max_hz,
            });
        }
        if self.max_tail_ms as usize > MAX_HORIZON {
            return Err(PlanningConfigError::Tail(self.max_tail_ms));
        }
        if !(256..=10_000_000).contains(&self.budget_steps) {
            return Err(PlanningConfigError::BudgetSteps(self.budget_steps));
        }
        if !(self.budget_us.is_finite() && self.budget_us > 0.0) {
            return Err(PlanningConfigError::BudgetUs(self.budget_us));
        }
        Ok(())
    }
}

/// A caller's clock: asked before each rollout whether the tick's time is up.
pub trait Deadline {
    /// True when no more planning fits in this tick.
    fn expired(&mut self) -> bool;
}

/// No deadline: the step budget alone bounds the work (deterministic; simulation, tests).
#[derive(Debug, Clone, Copy, Default)]
pub struct NoDeadline;

impl Deadline for NoDeadline {
    #[inline]
    fn expired(&mut self) -> bool {
        false
    }
}

/// Counters since construction or the last reset.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct PlannerStats {
    /// Contractions (windows) planned from their start.
    pub windows: u64,
    /// Plans made again because the preview changed under them.
    pub replans: u64,
    /// Plans re-evaluated from a state other than the predicted one.
    pub rebased: u64,
    /// Ticks whose decision came from a plan.
    pub planned_ticks: u64,
    /// Ticks inside a contraction decided causally because no plan was ready yet.
    pub causal_fallbacks: u64,
    /// Ticks whose planning work the caller's deadline cut short.
    pub deadline_cuts: u64,
    /// Ticks with a preview whose contraction has no end inside the horizon (causal).
    pub no_end: u64,
    /// Plans dropped because the preview went missing under them (none received, stale,
    /// a stop or an operator's setpoint).
    pub dropped_no_preview: u64,
    /// Plans dropped because the preview no longer announced any contraction.
    pub dropped_nothing_ahead: u64,
    /// Rollouts run.
    pub rollouts: u64,
    /// Network steps run by the planner.
    pub steps: u64,
    /// Windows whose search converged (a full pass without improvement) before they ended.
    pub converged: u64,
    /// Plans that improved on the best candidate so far.
    pub improvements: u64,
    /// Periods the caller skipped (stalls), counted on the clock with nothing fired.
    pub skipped_ticks: u64,
}

/// The pulse times of a plan, in ticks from the window's first tick.
#[derive(Debug, Clone, Copy)]
struct Plan {
    n: usize,
    t: [u16; MAX_PLAN_PULSES],
    j: f64,
}

impl Plan {
    const EMPTY: Plan = Plan {
        n: 0,
        t: [0; MAX_PLAN_PULSES],
        j: f64::INFINITY,
    };

    fn pulses(&self) -> &[u16] {
        &self.t[..self.n]
    }

    fn contains(&self, j: usize) -> bool {
        self.pulses().binary_search(&(j as u16)).is_ok()
    }
}

/// The error of a rollout so far: the squared error summed from the base, and the error
/// summed over the plateau (whose mean the objective holds at zero).
#[derive(Debug, Clone, Copy, Default)]
struct Acc {
    sq: f64,
    plateau: f64,
}

impl Acc {
    const ZERO: Acc = Acc {
        sq: 0.0,
        plateau: 0.0,
    };

    #[inline(always)]
    fn add(&mut self, j: usize, err: f64, w: &Window) {
        self.sq += err * err;
        if j >= w.pa && j < w.b {
            self.plateau += err;
        }
    }

    /// The objective's error terms: `sum e^2 + mu N_p mean_p(e)^2`.
    #[inline]
    fn cost(&self, mu: f64, w: &Window) -> f64 {
        let np = (w.b - w.pa).max(1) as f64;
        self.sq + mu * self.plateau * self.plateau / np
    }
}

/// The network state just before the step at a pulse's tick, and the error summed from
/// the base up to that tick.
#[derive(Debug, Clone, Copy)]
struct Check {
    st: CoreState<f64>,
    sse: Acc,
}

/// One planned contraction, in ticks from its first tick `h0`.
#[derive(Debug, Clone, Copy)]
struct Window {
    /// Absolute tick of index 0.
    h0: u64,
    /// First tick a pulse may come (onset).
    a: usize,
    /// First tick after the contraction (at or heading to rest).
    b: usize,
    /// First tick of the plateau, whose mean error the objective holds at zero.
    pa: usize,
    /// End of the horizon (exclusive).
    e: usize,
    /// The contraction's level: the highest target over `a..b`.
    level: f64,
    /// Whether the contraction may open with a burst (`burst_min_level`).
    burst: bool,
    /// First tick a pulse may come after the last one fired (the minimum interval).
    first_ok: usize,
    /// Tick of the base state (rollouts start here; earlier pulses are history).
    base_at: usize,
    /// The state before the step at `base_at`.
    base: CoreState<f64>,
}

/// Where the search stands.
#[derive(Debug, Clone, Copy)]
enum Phase {
    Idle,
    /// The warm start (the causal loop rolled forward) is due.
    Warm,
    /// Evaluating the trains: at frequency `hz`, the train's pulse `m` is next; `st` is the
    /// state before the step at `tick`, `sse` the error summed from the base to there.
    Sweep {
        hz: u32,
        m: usize,
        n: usize,
        tick: usize,
        st: CoreState<f64>,
        sse: Acc,
    },
    /// The incumbent's checkpoints are to be computed (after a sweep or a re-base).
    Checkpoints,
    /// Local search: move `mv` of pulse `i` is next.
    Refine {
        i: usize,
        mv: usize,
        improved: bool,
    },
    /// Converged: nothing left to try until something changes.
    Done,
}

/// The local-search moves, tried in this order for each pulse.
#[derive(Debug, Clone, Copy)]
enum Move {
    Shift(i16),
    Delete,
    InsertBefore,
    Suffix(i16),
    /// Delete the pulse and move every later one by the ticks given.
    DeleteSuffix(i16),
}

const MOVES: [Move; 18] = [
    Move::Shift(-1),
    Move::Shift(1),
    Move::Delete,
    Move::Shift(-2),
    Move::Shift(2),
    Move::Shift(-4),
    Move::Shift(4),
    Move::Shift(-8),
    Move::Shift(8),
    Move::InsertBefore,
    Move::Suffix(-1),
    Move::Suffix(1),
    Move::Suffix(-3),
    Move::Suffix(3),
    Move::Suffix(-6),
    Move::DeleteSuffix(8),
    Move::DeleteSuffix(16),
    Move::DeleteSuffix(32),
];

/// The planner's buffers: allocated once.
struct Buffers {
    /// The window's reference, from `h0`.
    r: [f64; MAX_HORIZON],
    /// This tick's sampled preview, from now.
    r_now: [f64; MAX_HORIZON],
    rest_now: [bool; MAX_HORIZON],
    inc: Plan,
    cand: Plan,
    inc_ck: [Check; MAX_PLAN_PULSES],
    cand_ck: [Check; MAX_PLAN_PULSES],
    /// Train pulse times (sweep) and the previous frequency's, whose first candidates
    /// need no second evaluation where the two trains agree.
    train: [u16; MAX_PLAN_PULSES],
    prev_train: [u16; MAX_PLAN_PULSES],
    /// The pulses applied since the window began (whoever decided them): every plan
    /// adopted must have exactly these before the tick now.
    fired: [u16; MAX_PLAN_PULSES],
}

/// What the causal loop would do, rolled forward on copies of its state (the warm start).
pub trait CausalRollout {
    /// Starts a rollout from the loop's state now.
    fn begin(&mut self);
    /// The decision at a tick, from the network state before its step, the target and
    /// whether the tick is at rest.
    fn decide(&mut self, st: &CoreState<f64>, r: f64, rest: bool) -> bool;
    /// The core output of that tick's step (for the loop's integrator).
    fn observe(&mut self, y_ahead: f64, r: f64, rest: bool);
}

/// The receding-horizon planner (module docs).
pub struct Planner {
    cfg: PlanningConfig,
    min_ipi: usize,
    /// `burst_ipi_ms` in ticks (0: no rule).
    burst_ipi: usize,
    ts: f64,
    bufs: Box<Buffers>,
    win: Option<Window>,
    /// The state before the onset's step and the error summed from the base to it.
    onset: Check,
    phase: Phase,
    /// The state expected at the next tick if the decision made is applied.
    expected: Option<CoreState<f64>>,
    /// This tick, from the window's first.
    jn: usize,
    /// The last tick a pulse was applied.
    last_fire: Option<u64>,
    /// Pulses in `bufs.fired`.
    n_fired: usize,
    /// Pulses of the last contraction completed.
    n_prev: Option<usize>,
    /// A pulse of the plan fell in a skipped period ([`Planner::skip`]): rebase.
    lost_pulse: bool,
    ticks: u64,
    stats: PlannerStats,
}

impl core::fmt::Debug for Planner {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Planner")
            .field("cfg", &self.cfg)
            .field("min_ipi", &self.min_ipi)
            .field("burst_ipi", &self.burst_ipi)
            .field("win", &self.win)
            .field("phase", &self.phase)
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

impl Clone for Planner {
    fn clone(&self) -> Self {
        let b = &*self.bufs;
        Self {
            cfg: self.cfg,
            min_ipi: self.min_ipi,
            burst_ipi: self.burst_ipi,
            ts: self.ts,
            bufs: Box::new(Buffers {
                r: b.r,
                r_now: b.r_now,
                rest_now: b.rest_now,
                inc: b.inc,
                cand: b.cand,
                inc_ck: b.inc_ck,
                cand_ck: b.cand_ck,
                train: b.train,
                prev_train: b.prev_train,
                fired: b.fired,
            }),
            win: self.win,
            onset: self.onset,
            phase: self.phase,
            expected: self.expected,
            jn: self.jn,
            last_fire: self.last_fire,
            n_fired: self.n_fired,
            n_prev: self.n_prev,
            lost_pulse: self.lost_pulse,
            ticks: self.ticks,
            stats: self.stats,
        }
    }
}

/// A contraction's level: the highest of its targets `r`.
fn level(r: &[f64]) -> f64 {
    r.iter().fold(0.0f64, |m, &v| m.max(v))
}

/// Tolerance on a contraction's level when deciding that a window is the one planned.
const SAME_REFERENCE: f64 = 1e-9;
/// Ticks an announced edge may move and still be the one planned: the caller's clock
/// jitter puts each announcement a tick either way, so two announcements of one edge may
/// differ by two.
const EDGE_TICKS: usize = 2;
/// Tolerance on the state handed in against the predicted one (relative).
const SAME_STATE: f64 = 1e-12;

/// A rollout's pulses: the plan's times and the index of the first one not yet passed.
struct Pulses<'a> {
    t: &'a [u16],
    next: usize,
}

impl Planner {
    /// A planner for a network with sampling period `ts` whose pulses must be at least
    /// `min_ipi` ticks apart. Allocates its buffers (once).
    pub fn new(cfg: PlanningConfig, ts: f64, min_ipi: usize) -> Result<Self, PlanningConfigError> {
        cfg.validate()?;
        let rest = CoreState {
            x: [0.0; 3],
            v_past: [0.0; 2],
            w: [0.0; 2],
            phi: 0.0,
        };
        let ck = Check {
            st: rest,
            sse: Acc::ZERO,
        };
        Ok(Self {
            cfg,
            min_ipi: min_ipi.max(1),
            burst_ipi: libm::ceil(cfg.burst_ipi_ms * 1e-3 / ts - 1e-9).max(0.0) as usize,
            ts,
            bufs: Box::new(Buffers {
                r: [0.0; MAX_HORIZON],
                r_now: [0.0; MAX_HORIZON],
                rest_now: [false; MAX_HORIZON],
                inc: Plan::EMPTY,
                cand: Plan::EMPTY,
                inc_ck: [ck; MAX_PLAN_PULSES],
                cand_ck: [ck; MAX_PLAN_PULSES],
                train: [0; MAX_PLAN_PULSES],
                prev_train: [0; MAX_PLAN_PULSES],
                fired: [0; MAX_PLAN_PULSES],
            }),
            win: None,
            onset: ck,
            phase: Phase::Idle,
            expected: None,
            jn: 0,
            last_fire: None,
            n_fired: 0,
            n_prev: None,
            lost_pulse: false,
            ticks: 0,
            stats: PlannerStats::default(),
        })
    }

    /// The settings.
    pub fn config(&self) -> &PlanningConfig {
        &self.cfg
    }

    /// Counters.
    pub fn stats(&self) -> PlannerStats {
        self.stats
    }

    /// The plan in force: its pulse times in ticks from now (negative: already fired) and
    /// its objective `J`; `None` without one.
    pub fn plan_now(&self, out: &mut [i64]) -> Option<(usize, f64)> {
        let w = self.win?;
        let inc = &self.bufs.inc;
        if !inc.j.is_finite() {
            return None;
        }
        let now = self.ticks.checked_sub(w.h0)? as i64;
        let n = inc.n.min(out.len());
        for (o, &t) in out.iter_mut().zip(inc.pulses()) {
            *o = t as i64 - now;
        }
        Some((n, inc.j))
    }

    /// Forgets every plan and zeroes the counters (the generator's reset).
    pub fn reset(&mut self) {
        self.drop_window();
        self.ticks = 0;
        self.jn = 0;
        self.last_fire = None;
        self.n_prev = None;
        self.lost_pulse = false;
        self.stats = PlannerStats::default();
    }

    /// One tick: follows the preview, plans within the budget, and returns the plan's
    /// decision for this tick, or `None` when the causal loop decides (no preview, no
    /// contraction ahead, no end in sight, or no plan yet). `st` is the network's core
    /// state before this tick's step. Call [`Self::commit`] with the input applied.
    #[allow(clippy::too_many_arguments)]
    pub fn plan(
        &mut self,
        net: &Network<f64>,
        st: &CoreState<f64>,
        preview: &Preview,
        target_now: f64,
        resting_now: bool,
        warm: &mut dyn CausalRollout,
        deadline: &mut dyn Deadline,
    ) -> Option<bool> {
        let now = self.ticks;
        self.follow_preview(now, st, preview, target_now, resting_now);
        let w = self.win?;
        self.jn = (now - w.h0) as usize;
        let lost = core::mem::take(&mut self.lost_pulse);
        if (lost || self.expected.is_some_and(|x| !same_state(&x, st))) && self.jn < w.b {
            self.rebase(st, lost);
        }
        self.work(net, warm, deadline);
        let w = self.win?;
        if self.jn < w.a || self.jn >= w.b {
            return None;
        }
        if self.bufs.inc.j.is_finite() {
            self.stats.planned_ticks += 1;
            // Never closer than the minimum interval to the last pulse applied, whoever
            // decided it.
            let gap_ok = self
                .last_fire
                .is_none_or(|l| now >= l + self.min_ipi as u64);
            Some(self.bufs.inc.contains(self.jn) && gap_ok)
        } else {
            self.stats.causal_fallbacks += 1;
            None
        }
    }

    /// Ends the tick: `st` is the state before the step, `u` the input applied (so that
    /// the planner can tell next tick whether the network followed its prediction).
    pub fn commit(&mut self, net: &Network<f64>, st: &CoreState<f64>, u: f64) {
        self.expected = self.win.map(|_| {
            let mut next = *st;
            net.step(&mut next, u);
            next
        });
        if u != 0.0 {
            self.last_fire = Some(self.ticks);
            if let Some(w) = self.win
                && self.n_fired < MAX_PLAN_PULSES
            {
                self.bufs.fired[self.n_fired] = (self.ticks - w.h0) as u16;
                self.n_fired += 1;
            }
        }
        self.ticks += 1;
    }

    /// A period the caller skipped (its thread stalled past the tick): nothing was fired
    /// in it. `st` is the network's state before the model's step for it (taken with no
    /// pulse). The clock advances, so that the window stays on the schedule the preview
    /// gives in wall-clock ticks; counting calls instead put the plan a stall's length
    /// late and made every stall of three periods or more look like a moved edge, whose
    /// replan restarted the search from the causal loop's pattern mid-contraction. A pulse
    /// the plan wanted here is lost: the state then differs from the plan's prediction and
    /// the next tick plans on from the state reached (a rebase).
    pub fn skip(&mut self, net: &Network<f64>, st: &CoreState<f64>) {
        let wanted = self.win.is_some_and(|w| {
            let j = (self.ticks - w.h0) as usize;
            (w.a..w.b).contains(&j) && self.bufs.inc.j.is_finite() && self.bufs.inc.contains(j)
        });
        self.stats.skipped_ticks += 1;
        self.lost_pulse |= wanted;
        self.commit(net, st, 0.0);
    }

    /// No contraction planned: the causal loop decides until a window opens.
    fn drop_window(&mut self) {
        self.win = None;
        self.phase = Phase::Idle;
        self.expected = None;
    }

    /// Samples the preview and keeps, replaces or drops the window.
    fn follow_preview(
        &mut self,
        now: u64,
        st: &CoreState<f64>,
        preview: &Preview,
        target_now: f64,
        resting_now: bool,
    ) {
        let b = &mut *self.bufs;
        if !preview.sample(
            target_now,
            resting_now,
            self.ts,
            &mut b.r_now,
            &mut b.rest_now,
        ) {
            if self.win.is_some() {
                self.stats.dropped_no_preview += 1;
            }
            self.drop_window();
            return;
        }
        // The contraction announced: its onset and end in ticks from now.
        let a_new = (0..MAX_HORIZON).find(|&j| self.scheduled_on(j));
        let b_new = a_new.and_then(|a| (a + 1..MAX_HORIZON).find(|&j| !self.scheduled_on(j)));
        if self.keeps_window(now, a_new, b_new) {
            return;
        }
        let (a, bb) = match (a_new, b_new) {
            (Some(a), Some(bb)) => (a, bb),
            (Some(_), None) => {
                self.stats.no_end += 1;
                self.drop_window();
                return;
            }
            (None, _) => {
                if self.win.is_some() {
                    self.stats.dropped_nothing_ahead += 1;
                }
                self.drop_window();
                return;
            }
        };
        self.open_window(now, st, a, bb);
    }

    /// Whether the contraction is on at tick j of the sampled preview, by the schedule:
    /// from the next tick on the preview says (tick 0 is the tracker's target, which
    /// follows the supervisor's Reference; a Reference published late at an edge, by
    /// milliseconds on a loaded host, must not move the announced contraction).
    fn scheduled_on(&self, j: usize) -> bool {
        let j = j.max(1);
        !self.bufs.rest_now[j] && self.bufs.r_now[j] > 0.0
    }

    /// Whether the window planned still holds the contraction announced (onset `a_new`,
    /// end `b_new`, ticks from now); a window that does not is counted as a replan.
    /// Kept while the contraction announced is the one planned: the same onset and end to
    /// two ticks, the same level. rt-core's clock jitters by tens of microseconds, so an
    /// edge may land a tick either way and a ramp's targets differ in the last digits
    /// from tick to tick; neither is a new contraction.
    fn keeps_window(&mut self, now: u64, a_new: Option<usize>, b_new: Option<usize>) -> bool {
        let Some(w) = self.win else { return false };
        let jn = (now - w.h0) as usize;
        if jn >= w.b {
            // An end announced up to two ticks late: the same contraction, its last
            // ticks decided causally.
            return jn < w.b + EDGE_TICKS && self.scheduled_on(0);
        }
        // An onset announced up to two ticks from the planned one is still to come.
        let onset_due = a_new.is_some_and(|a| a > 0 && (jn + a).abs_diff(w.a) <= EDGE_TICKS);
        let same = if jn >= w.a && !self.scheduled_on(0) && !onset_due {
            // The contraction is announced over: an end up to two ticks early is the one
            // planned (its last ticks fire nothing), an earlier one is not. (Activity is
            // read from the next tick: the end announced is jn + 1.)
            jn + 1 + EDGE_TICKS >= w.b
        } else {
            match (a_new, b_new) {
                (Some(a), Some(bb)) => {
                    // Active now: the onset is due (announced late, at most).
                    let onset_ok = if a == 0 {
                        jn + 1 + EDGE_TICKS >= w.a
                    } else {
                        onset_due
                    };
                    onset_ok
                        && (jn + bb).abs_diff(w.b) <= EDGE_TICKS
                        && (level(&self.bufs.r_now[a..bb]) - w.level).abs() <= SAME_REFERENCE
                }
                _ => false,
            }
        };
        if !same {
            self.stats.replans += 1;
        }
        same
    }

    /// A new window over the contraction announced from tick `a` to `bb` (ticks from
    /// now), with its relaxation up to the next onset or `max_tail_ms`; the warm start
    /// comes next.
    fn open_window(&mut self, now: u64, st: &CoreState<f64>, a: usize, bb: usize) {
        let next = (bb + 1..MAX_HORIZON)
            .find(|&j| self.scheduled_on(j))
            .unwrap_or(MAX_HORIZON);
        let e = next
            .min(bb + self.cfg.max_tail_ms as usize)
            .min(MAX_HORIZON);
        let b = &mut *self.bufs;
        b.r[..e].copy_from_slice(&b.r_now[..e]);
        let first_ok = self.last_fire.map_or(0, |l| {
            (l + self.min_ipi as u64).saturating_sub(now) as usize
        });
        // The last contraction's count, if it was planned before its onset (the first
        // one of a profile starts unannounced and is no reference).
        if let Some(old) = self.win
            && now >= old.h0 + old.b as u64
        {
            self.n_prev = (old.a > 0).then_some(self.n_fired);
        }
        let pa = a + (self.cfg.plateau_start * (bb - a) as f64) as usize;
        let lvl = level(&b.r[a..bb]);
        self.win = Some(Window {
            h0: now,
            a,
            b: bb,
            pa,
            e,
            level: lvl,
            burst: lvl >= self.cfg.burst_min_level,
            first_ok,
            base_at: 0,
            base: *st,
        });
        b.inc = Plan::EMPTY;
        self.n_fired = 0;
        self.lost_pulse = false;
        self.phase = Phase::Warm;
        self.expected = None;
        self.stats.windows += 1;
    }

    /// The state now differs from the prediction: plan on from it (the pulses already
    /// fired are history; `lost`: a pulse the plan wanted fell in a skipped period).
    fn rebase(&mut self, st: &CoreState<f64>, lost: bool) {
        let jn = self.jn;
        let first_ok = self.last_fire.map_or(0, |l| {
            (l + self.min_ipi as u64).saturating_sub(self.ticks - jn as u64) as usize
        });
        let Some(w) = self.win.as_mut() else { return };
        w.base_at = jn;
        w.base = *st;
        w.first_ok = w.first_ok.max(first_ok);
        let (first_ok, b) = (w.first_ok.max(jn), w.b);
        if lost {
            self.defer_lost_pulses(first_ok, b);
        }
        self.stats.rebased += 1;
        if self.bufs.inc.j.is_finite() {
            self.phase = Phase::Checkpoints;
        } else {
            self.phase = Phase::Warm;
        }
    }

    /// Makes the incumbent agree with the past: the pulses fired so far, then each pulse it
    /// wanted before now that was not fired (lost in a stall: [`Self::skip`]) moved to the
    /// first ticks allowed from `first_ok` on, in order, then its later pulses (each at
    /// least the minimum interval after the one before, none at or past `b`). The count
    /// the plan chose is kept: on the process bench a plateau pulse lost in a 5 ms stall,
    /// left out, took a contraction to 5 of its 6 pulses and its plateau 38 % under the
    /// level, and the outer loop then learned that beat; moved, it costs a few ticks of
    /// timing, and the local search moves it on from there.
    fn defer_lost_pulses(&mut self, first_ok: usize, b: usize) {
        let jn = self.jn;
        let ipi = self.min_ipi;
        let bufs = &mut *self.bufs;
        let inc = bufs.inc;
        let planned_past = inc.pulses().iter().filter(|&&t| (t as usize) < jn).count();
        let fired = &bufs.fired[..self.n_fired];
        let kept = inc.pulses()[..planned_past]
            .iter()
            .filter(|t| fired.contains(t))
            .count();
        if !inc.j.is_finite() || kept == planned_past {
            return;
        }
        let mut lost = planned_past - kept;
        let c = &mut bufs.cand;
        c.t[..fired.len()].copy_from_slice(fired);
        c.n = fired.len();
        let mut next = first_ok;
        for &t in &inc.pulses()[planned_past..] {
            while lost > 0 && next + ipi <= t as usize && c.n < MAX_PLAN_PULSES {
                c.t[c.n] = next as u16;
                c.n += 1;
                next += ipi;
                lost -= 1;
            }
            let t = (t as usize).max(next);
            if t < b && c.n < MAX_PLAN_PULSES {
                c.t[c.n] = t as u16;
                c.n += 1;
                next = t + ipi;
            }
        }
        while lost > 0 && next < b && c.n < MAX_PLAN_PULSES {
            c.t[c.n] = next as u16;
            c.n += 1;
            next += ipi;
            lost -= 1;
        }
        bufs.inc.t[..c.n].copy_from_slice(&c.t[..c.n]);
        bufs.inc.n = c.n;
    }

    /// Runs work items until the budget or the deadline ends the tick.
    fn work(
        &mut self,
        net: &Network<f64>,
        warm: &mut dyn CausalRollout,
        deadline: &mut dyn Deadline,
    ) {
        let budget = self.cfg.budget_steps as u64;
        let start = self.stats.steps;
        while !matches!(self.phase, Phase::Idle | Phase::Done) {
            if self.stats.steps - start >= budget {
                return;
            }
            if deadline.expired() {
                self.stats.deadline_cuts += 1;
                return;
            }
            self.item(net, warm);
        }
    }

    /// One work item (at most about one rollout over the horizon).
    fn item(&mut self, net: &Network<f64>, warm: &mut dyn CausalRollout) {
        let Some(w) = self.win else {
            self.phase = Phase::Idle;
            return;
        };
        self.phase = match self.phase {
            Phase::Idle => Phase::Idle,
            Phase::Done => Phase::Done,
            Phase::Warm => {
                self.warm_start(net, &w, warm);
                if w.base_at <= w.a && self.jn <= w.a {
                    self.sweep_begin(net, &w)
                } else {
                    Phase::Checkpoints
                }
            }
            Phase::Sweep {
                hz,
                m,
                n,
                tick,
                st,
                sse,
            } => self.sweep_item(net, &w, hz, m, n, tick, st, sse),
            Phase::Checkpoints => {
                self.checkpoints(net, &w);
                Phase::Refine {
                    i: 0,
                    mv: 0,
                    improved: false,
                }
            }
            Phase::Refine { i, mv, improved } => self.refine_item(net, &w, i, mv, improved),
        };
    }

    /// Pulses fired before the base: in every plan, not priced (they are the past of
    /// every candidate alike).
    fn history(&self, w: &Window) -> usize {
        self.bufs.fired[..self.n_fired]
            .iter()
            .take_while(|&&t| (t as usize) < w.base_at)
            .count()
    }

    /// The price of a contraction of `n` pulses for differing from the last one's count.
    fn count_change(&self, n: usize) -> f64 {
        count_change(self.cfg.count_change, self.n_prev, n)
    }

    /// Whether `pulses` has exactly the pulses fired before the tick now (a plan that
    /// does not could not be the one running).
    fn agrees_with_the_past(&self, pulses: &[u16]) -> bool {
        let past = pulses
            .iter()
            .take_while(|&&t| (t as usize) < self.jn)
            .count();
        past == self.n_fired && pulses[..past] == self.bufs.fired[..past]
    }

    /// Rolls the causal loop forward from the base and takes its pulses as the first plan
    /// (better than none: kept only if the incumbent is worse).
    fn warm_start(&mut self, net: &Network<f64>, w: &Window, warm: &mut dyn CausalRollout) {
        let keep = self.history(w);
        let lambda = self.cfg.price(w.level);
        let min_ipi = self.min_ipi;
        let (price, n_prev) = (self.cfg.count_change, self.n_prev);
        let change = move |n| count_change(price, n_prev, n);
        let jn = self.jn;
        let n_fired = self.n_fired;
        let b = &mut *self.bufs;
        b.cand.t[..keep].copy_from_slice(&b.fired[..keep]);
        let mut n = keep;
        let mut past = keep;
        let mut last = b.cand.t[..keep]
            .last()
            .map(|&t| t as usize)
            .or((w.first_ok > 0).then(|| w.first_ok.saturating_sub(min_ipi)));
        let mut st = w.base;
        let mut sse = Acc::ZERO;
        warm.begin();
        for j in w.base_at..w.e {
            let rest = j < w.a || j >= w.b;
            let wants = warm.decide(&st, b.r[j], rest);
            // Before now, what was fired; from now on, what the causal loop would do.
            let fire = if j < jn {
                past < n_fired && b.fired[past] as usize == j
            } else {
                wants && !rest && n < MAX_PLAN_PULSES && last.is_none_or(|l| j >= l + min_ipi)
            };
            if fire && j < jn {
                past += 1;
            }
            if fire {
                b.cand.t[n] = j as u16;
                n += 1;
                last = Some(j);
            }
            let y = net.step(&mut st, if fire { 1.0 } else { 0.0 });
            warm.observe(y, b.r[j], rest);
            sse.add(j, y - b.r[j], w);
        }
        self.stats.rollouts += 1;
        self.stats.steps += (w.e - w.base_at) as u64;
        b.cand.n = n;
        b.cand.j = sse.cost(self.cfg.mean_weight, w) + lambda * (n - keep) as f64 + change(n);
        let shaped = opens_only_with_bursts(b.cand.pulses(), self.burst_ipi, w.burst);
        if shaped && (b.cand.j < b.inc.j || !b.inc.j.is_finite()) {
            b.inc = b.cand;
        }
    }

    /// Runs freely from the base to the onset and starts the sweep at `min_hz`.
    fn sweep_begin(&mut self, net: &Network<f64>, w: &Window) -> Phase {
        let mut st = w.base;
        let mut sse = Acc::ZERO;
        let mut none = Pulses { t: &[], next: 0 };
        rollout(
            net,
            w,
            &self.bufs.r,
            &mut st,
            w.base_at,
            w.a,
            &mut sse,
            &mut none,
            f64::INFINITY,
            None,
            &mut self.stats,
        );
        self.onset = Check { st, sse };
        // The plan without any pulse.
        let mu = self.cfg.mean_weight;
        let mut tail_st = st;
        let mut tail = sse;
        let bound = self.bufs.inc.j;
        let mut none = Pulses { t: &[], next: 0 };
        if rollout(
            net,
            w,
            &self.bufs.r,
            &mut tail_st,
            w.a,
            w.e,
            &mut tail,
            &mut none,
            bound,
            None,
            &mut self.stats,
        ) && tail.cost(mu, w) < self.bufs.inc.j
        {
            self.adopt_train(w, 0, tail.cost(mu, w));
        }
        self.bufs.prev_train = [0; MAX_PLAN_PULSES];
        self.train_begin(w, self.cfg.min_hz)
    }

    /// The train at `hz` from the onset (thesis 6.3: pulse `k` at `round(k / (f Ts))`),
    /// `prev_n` the previous train's length.
    fn train_begin(&mut self, w: &Window, hz: u32) -> Phase {
        if hz > self.cfg.max_hz {
            return Phase::Checkpoints;
        }
        let start = w.a.max(w.first_ok);
        let n = train_times(hz, self.ts, start, w.b, &mut self.bufs.train);
        self.bufs.train[n..].fill(u16::MAX);
        Phase::Sweep {
            hz,
            m: 0,
            n,
            tick: w.a,
            st: self.onset.st,
            sse: self.onset.sse,
        }
    }

    /// One sweep item: the train `hz` stopped after `m` pulses (when `m >= 1` and no
    /// previous train had the same first `m`), then on to its next pulse.
    #[allow(clippy::too_many_arguments)]
    fn sweep_item(
        &mut self,
        net: &Network<f64>,
        w: &Window,
        hz: u32,
        m: usize,
        n: usize,
        tick: usize,
        mut st: CoreState<f64>,
        mut sse: Acc,
    ) -> Phase {
        let lambda = self.cfg.price(w.level);
        let mu = self.cfg.mean_weight;
        let b = &*self.bufs;
        let seen = hz > self.cfg.min_hz && b.train[..m] == b.prev_train[..m];
        if m >= 1 && !seen {
            let bound = self.bufs.inc.j - lambda * m as f64;
            let mut tail_st = st;
            let mut total = sse;
            let mut none = Pulses { t: &[], next: 0 };
            if rollout(
                net,
                w,
                &self.bufs.r,
                &mut tail_st,
                tick,
                w.e,
                &mut total,
                &mut none,
                bound,
                None,
                &mut self.stats,
            ) && total.cost(mu, w) + lambda * (m as f64) + self.count_change(m) < self.bufs.inc.j
            {
                self.adopt_train(
                    w,
                    m,
                    total.cost(mu, w) + lambda * m as f64 + self.count_change(m),
                );
            }
        }
        if m == n {
            self.bufs.prev_train = self.bufs.train;
            return self.train_begin(w, hz + 1);
        }
        // On through pulse m to the next pulse (or the end of the horizon).
        let next = if m + 1 < n {
            self.bufs.train[m + 1] as usize
        } else {
            w.e
        };
        let bound = self.bufs.inc.j - lambda * (m + 1) as f64;
        let b = &*self.bufs;
        let mut p = Pulses {
            t: &b.train[..n],
            next: m,
        };
        let alive = rollout(
            net,
            w,
            &b.r,
            &mut st,
            tick,
            next,
            &mut sse,
            &mut p,
            bound,
            None,
            &mut self.stats,
        );
        if !alive {
            // Every longer stop of this train costs more than the best plan.
            self.bufs.prev_train = self.bufs.train;
            self.bufs.prev_train[m..].fill(u16::MAX);
            return self.train_begin(w, hz + 1);
        }
        if m + 1 == n {
            // The whole train: judged over the horizon already run.
            let j = sse.cost(mu, w) + lambda * n as f64 + self.count_change(n);
            if j < self.bufs.inc.j {
                self.adopt_train(w, n, j);
            }
            self.bufs.prev_train = self.bufs.train;
            return self.train_begin(w, hz + 1);
        }
        Phase::Sweep {
            hz,
            m: m + 1,
            n,
            tick: next,
            st,
            sse,
        }
    }

    /// The train's first `m` pulses become the incumbent (checkpoints follow later).
    fn adopt_train(&mut self, w: &Window, m: usize, j: f64) {
        if !self.agrees_with_the_past(&self.bufs.train[..m])
            || !opens_only_with_bursts(&self.bufs.train[..m], self.burst_ipi, w.burst)
        {
            return;
        }
        let b = &mut *self.bufs;
        b.inc.t[..m].copy_from_slice(&b.train[..m]);
        b.inc.n = m;
        b.inc.j = j;
        self.stats.improvements += 1;
    }

    /// One rollout of the incumbent from the base: its objective and checkpoints.
    fn checkpoints(&mut self, net: &Network<f64>, w: &Window) {
        let keep = self.history(w);
        let b = &mut *self.bufs;
        let mut st = w.base;
        let mut sse = Acc::ZERO;
        let mut p = Pulses {
            t: b.inc.pulses(),
            next: keep,
        };
        rollout(
            net,
            w,
            &b.r,
            &mut st,
            w.base_at,
            w.e,
            &mut sse,
            &mut p,
            f64::INFINITY,
            Some(&mut b.inc_ck),
            &mut self.stats,
        );
        b.inc.j = sse.cost(self.cfg.mean_weight, w)
            + self.cfg.price(w.level) * (b.inc.n - keep) as f64
            + count_change(self.cfg.count_change, self.n_prev, b.inc.n);
    }

    /// One local-search move of pulse `i` (module docs); at the end of a pass, a new pass
    /// if the last one improved, else converged.
    fn refine_item(
        &mut self,
        net: &Network<f64>,
        w: &Window,
        i: usize,
        mv: usize,
        improved: bool,
    ) -> Phase {
        let lo = w.a.max(w.base_at).max(self.jn).max(w.first_ok);
        let inc = self.bufs.inc;
        let first = inc
            .pulses()
            .iter()
            .take_while(|&&t| (t as usize) < lo)
            .count();
        let i = i.max(first);
        if i > inc.n {
            if improved {
                return Phase::Refine {
                    i: first,
                    mv: 0,
                    improved: false,
                };
            }
            self.stats.converged += 1;
            return Phase::Done;
        }
        let (next_i, next_mv) = if mv + 1 < MOVES.len() {
            (i, mv + 1)
        } else {
            (i + 1, 0)
        };
        let Some(tau) = self.candidate(w, lo, i, MOVES[mv]) else {
            return Phase::Refine {
                i: next_i,
                mv: next_mv,
                improved,
            };
        };
        if self.evaluate(net, w, tau) {
            self.stats.improvements += 1;
            return Phase::Refine {
                i,
                mv: next_mv,
                improved: true,
            };
        }
        Phase::Refine {
            i: next_i,
            mv: next_mv,
            improved,
        }
    }

    /// Builds the incumbent with `mv` applied to pulse `i` into the candidate; returns the
    /// first tick it changes, or `None` when the move breaks a constraint (the window, the
    /// minimum interval, the pulses already fired before `lo`).
    fn candidate(&mut self, w: &Window, lo: usize, i: usize, mv: Move) -> Option<usize> {
        let ipi = self.min_ipi as i64;
        let b = &mut *self.bufs;
        let inc = &b.inc;
        let n = inc.n;
        let c = &mut b.cand;
        let t = |k: usize| inc.t[k] as i64;
        let prev = if i > 0 { Some(t(i - 1)) } else { None };
        let (lo, hi) = (lo as i64, w.b as i64);
        let fits = |x: i64, before: Option<i64>, after: Option<i64>| {
            x >= lo
                && x < hi
                && before.is_none_or(|p| x >= p + ipi)
                && after.is_none_or(|q| x + ipi <= q)
        };
        c.t[..n].copy_from_slice(&inc.t[..n]);
        let tau = match mv {
            Move::Shift(d) => {
                if i >= n {
                    return None;
                }
                let x = t(i) + d as i64;
                let next = if i + 1 < n { Some(t(i + 1)) } else { None };
                if !fits(x, prev, next) {
                    return None;
                }
                c.t[i] = x as u16;
                c.n = n;
                x.min(t(i))
            }
            Move::Delete => {
                if i >= n {
                    return None;
                }
                c.t.copy_within(i + 1..n, i);
                c.n = n - 1;
                t(i)
            }
            Move::InsertBefore => {
                if n >= MAX_PLAN_PULSES {
                    return None;
                }
                let (x, after) = match (prev, i < n) {
                    (Some(p), true) => ((p + t(i)) / 2, Some(t(i))),
                    (None, true) => (t(i) - 2 * ipi.max(1), Some(t(i))),
                    (Some(p), false) => ((p + hi) / 2, None),
                    (None, false) => (lo, None),
                };
                if !fits(x, prev, after) {
                    return None;
                }
                c.t.copy_within(i..n, i + 1);
                c.t[i] = x as u16;
                c.n = n + 1;
                x
            }
            Move::Suffix(d) | Move::DeleteSuffix(d) => {
                // The pulses from `from` on move by d into the slots from i on (pulse i
                // itself dropped when deleting).
                let from = i + usize::from(matches!(mv, Move::DeleteSuffix(_)));
                if from >= n {
                    return None;
                }
                let d = d as i64;
                let x0 = t(from) + d;
                let xl = t(n - 1) + d;
                if !fits(x0, prev, None) || xl >= hi {
                    return None;
                }
                for k in from..n {
                    c.t[i + k - from] = (t(k) + d) as u16;
                }
                c.n = n - (from - i);
                x0.min(t(i))
            }
        };
        opens_only_with_bursts(c.pulses(), self.burst_ipi, w.burst).then_some(tau as usize)
    }

    /// Evaluates the candidate, which equals the incumbent before tick `tau`, from the
    /// incumbent's last checkpoint at or before `tau`; adopts it when `J` is lower.
    fn evaluate(&mut self, net: &Network<f64>, w: &Window, tau: usize) -> bool {
        let keep = self.history(w);
        let inc = self.bufs.inc;
        // The last incumbent pulse at or before tau, counted from the base.
        let k = inc.pulses()[..inc.n]
            .iter()
            .take_while(|&&t| (t as usize) <= tau)
            .count();
        let (mut st, mut sse, from, idx) = if k > keep {
            let c = self.bufs.inc_ck[k - 1];
            (c.st, c.sse, inc.t[k - 1] as usize, k - 1)
        } else {
            (w.base, Acc::ZERO, w.base_at, keep)
        };
        let lambda = self.cfg.price(w.level);
        let b = &mut *self.bufs;
        let priced = lambda * (b.cand.n - keep) as f64
            + count_change(self.cfg.count_change, self.n_prev, b.cand.n);
        let bound = inc.j - priced;
        let mut p = Pulses {
            t: b.cand.pulses(),
            next: idx,
        };
        if !rollout(
            net,
            w,
            &b.r,
            &mut st,
            from,
            w.e,
            &mut sse,
            &mut p,
            bound,
            Some(&mut b.cand_ck),
            &mut self.stats,
        ) {
            return false;
        }
        let j = sse.cost(self.cfg.mean_weight, w) + priced;
        if j >= inc.j {
            return false;
        }
        b.cand_ck[..idx].copy_from_slice(&b.inc_ck[..idx]);
        core::mem::swap(&mut b.inc, &mut b.cand);
        core::mem::swap(&mut b.inc_ck, &mut b.cand_ck);
        b.inc.j = j;
        true
    }
}

/// Runs the network from `st` (the state before the step at `from`) to `to`, firing at the
/// pulses' ticks, adding the error against `r` to `sse`; stops with `false` once the
/// squared sum exceeds `bound` (every term of the objective is at least that). With `ck`, stores the state before each pulse.
#[allow(clippy::too_many_arguments)]
#[inline]
fn rollout(
    net: &Network<f64>,
    w: &Window,
    r: &[f64; MAX_HORIZON],
    st: &mut CoreState<f64>,
    from: usize,
    to: usize,
    sse: &mut Acc,
    p: &mut Pulses<'_>,
    bound: f64,
    mut ck: Option<&mut [Check; MAX_PLAN_PULSES]>,
    stats: &mut PlannerStats,
) -> bool {
    stats.rollouts += 1;
    for (j, &rj) in r.iter().enumerate().take(to).skip(from) {
        let fire = p.next < p.t.len() && p.t[p.next] as usize == j;
        if fire {
            if let Some(ck) = ck.as_deref_mut() {
                ck[p.next] = Check { st: *st, sse: *sse };
            }
            p.next += 1;
        }
        let y = net.step(st, if fire { 1.0 } else { 0.0 });
        sse.add(j, y - rj, w);
        if sse.sq > bound {
            stats.steps += (j + 1 - from) as u64;
            return false;
        }
    }
    stats.steps += (to - from) as u64;
    true
}

/// Whether every interval shorter than `burst_ipi` ticks comes before the first that is
/// not (the opening burst of thesis 6.5.4; `burst_ipi` 0: always); without `burst`, whether
/// there is no such interval at all.
#[inline]
fn opens_only_with_bursts(t: &[u16], burst_ipi: usize, burst: bool) -> bool {
    if burst_ipi == 0 {
        return true;
    }
    let mut opened = !burst;
    for p in t.windows(2) {
        let short = (p[1].saturating_sub(p[0]) as usize) < burst_ipi;
        if short && opened {
            return false;
        }
        opened |= !short;
    }
    true
}

/// `price x |n - previous|`, 0 without a previous contraction.
#[inline]
fn count_change(price: f64, previous: Option<usize>, n: usize) -> f64 {
    previous.map_or(0.0, |p| price * p.abs_diff(n) as f64)
}

/// The pulse ticks of a constant-frequency train at `hz` from the onset `a`, inside
/// `[a, b)`: pulse `k` at `a + round(k / (hz Ts))` (the trains of thesis 6.3 and of the
/// bench's CFT front). Returns how many were written.
pub fn train_times(hz: u32, ts: f64, a: usize, b: usize, out: &mut [u16]) -> usize {
    let per = 1.0 / (hz as f64 * ts);
    let mut n = 0;
    while n < out.len() {
        let k = a + libm::round(n as f64 * per) as usize;
        if k >= b {
            break;
        }
        out[n] = k as u16;
        n += 1;
    }
    n
}

#[inline]
fn same_state(a: &CoreState<f64>, b: &CoreState<f64>) -> bool {
    let close = |p: f64, q: f64| (p - q).abs() <= SAME_STATE * (1.0 + p.abs().max(q.abs()));
    close(a.x[0], b.x[0])
        && close(a.x[1], b.x[1])
        && close(a.w[0], b.w[0])
        && close(a.w[1], b.w[1])
        && close(a.phi, b.phi)
}
