//! The whole chain in one process, in simulated time: the supervisor's profile and outer
//! loop ([`supervisor::core`]), rt-core's reference tracking (`rt::reference`) and pattern
//! generator (the controller file's LCN + shaper + LMN), and sim-muscle's Ding muscle
//! (optionally fatiguing, optionally with its force sensor), 1 ms per step.
//!
//! It is the bench without processes, buses or clocks: deterministic, a few seconds of
//! CPU for a minute of stimulation. The outer-loop tests and the fatigue figures of
//! docs/bench.md use it; the bench checks the same loop across processes.

use fes_model::control::file::Controller;
use fes_model::control::pattern_generator::TickInput;
use fes_rt::msg::{PreviewEdge, ReferencePreview};
use rt_core::rt::reference::{ReferencePolicy, ReferenceTracker};
use sim_muscle::muscle::{Muscle, MuscleConfig};
use sim_muscle::plant::{MusclePlant, Pulse};
use sim_muscle::sensor::{ForceSensor, SensorConfig};

use crate::summary::{BeatRow, Series};
use supervisor::contraction::ContractionSettings;
use supervisor::core::{BeatRecord, CommandError, SupervisorCore};
use supervisor::limits::ReferenceLimits;
use supervisor::outer_loop::OuterLoopSettings;
use supervisor::profile::ProfileSpec;
use supervisor::protocol::Command;

/// What to simulate.
#[derive(Debug, Clone)]
pub struct SimSettings {
    /// The muscle (preset, fatigue, delay).
    pub muscle: MuscleConfig,
    /// A force sensor (offset, noise), or the exact force.
    pub sensor: Option<SensorConfig>,
    /// Newtons per normalised force (the model's `force_scale_n`).
    pub scale_n: f64,
    /// Offset removed before normalising, N (the sensor's).
    pub offset_n: f64,
    /// Profile run after arming.
    pub profile: ProfileSpec,
    /// Outer loop.
    pub outer_loop: OuterLoopSettings,
    /// Beat measurement.
    pub contraction: ContractionSettings,
    /// Reference limits.
    pub limits: ReferenceLimits,
    /// Simulated time, s.
    pub seconds: f64,
    /// The fastest constant-frequency train the front compares against: 100 Hz, or less
    /// when the controller's minimum pulse interval is longer (a controller designed for a
    /// transport that cannot deliver closer pulses is compared with trains it could).
    pub max_train_hz: u32,
}

/// The controller's minimum pulse interval, s: its shaper's `min_gap` + 1 model samples.
pub fn min_pulse_interval_s(controller: &Controller) -> f64 {
    f64::from(controller.settings.shaper.min_gap + 1) * controller.lmn.ts
}

/// 100 Hz, or the rate of the controller's minimum pulse interval
/// ([`min_pulse_interval_s`]) when that is lower.
pub fn max_train_hz(controller: &Controller) -> u32 {
    ((1.0 / min_pulse_interval_s(controller) + 1e-9).floor() as u32).clamp(1, 100)
}

impl SimSettings {
    /// The bench's chain (`fes bench --in-process`): sim-muscle's fast preset
    /// (optionally fatiguing, Ding 2003) measured by the bench's sensor
    /// (`sim-muscle stimulator --measured --offset-n 0`: default noise, seed 1), normalised
    /// by the controller's model, beats measured with the model's delay, default limits.
    pub fn bench(
        controller: &Controller,
        fatigue: bool,
        profile: ProfileSpec,
        outer_loop: OuterLoopSettings,
        seconds: f64,
    ) -> Result<Self, SimError> {
        Self::bench_muscle(
            controller,
            sim_muscle::preset::Preset::Fast,
            fatigue,
            profile,
            outer_loop,
            seconds,
        )
    }

    /// [`Self::bench`] on either of sim-muscle's presets (`fes bench --muscle`).
    pub fn bench_muscle(
        controller: &Controller,
        preset: sim_muscle::preset::Preset,
        fatigue: bool,
        profile: ProfileSpec,
        outer_loop: OuterLoopSettings,
        seconds: f64,
    ) -> Result<Self, SimError> {
        let mut muscle = MuscleConfig::preset(preset);
        if fatigue {
            muscle.fatigue = Some(sim_muscle::ding::FatigueParams::for_muscle(&muscle.ding));
        }
        let fmax = sim_muscle::muscle::max_force_n(&muscle.ding)?;
        Ok(Self {
            muscle,
            sensor: Some(SensorConfig {
                offset_n: 0.0,
                ..SensorConfig::defaults_for(fmax, 1)
            }),
            scale_n: controller.lmn.force_scale_n,
            offset_n: 0.0,
            profile,
            outer_loop,
            contraction: ContractionSettings {
                delay_ms: controller.lmn.delay as f64,
                ..Default::default()
            },
            limits: ReferenceLimits::default(),
            seconds,
            max_train_hz: max_train_hz(controller),
        })
    }
}

impl SimSettings {
    /// The constant-frequency-train front on this run's muscle and sensor, judged against a
    /// profile of `amplitude` whose contractions last `lead_ms` longer than the stimulated
    /// ones (5-100 Hz, [`crate::cft`]).
    pub fn front(&self, amplitude: f64, lead_ms: usize) -> crate::cft::FrontSettings {
        crate::cft::FrontSettings {
            muscle: self.muscle,
            sensor: self.sensor,
            scale_n: self.scale_n,
            offset_n: self.offset_n,
            delay: self.contraction.delay_ms.round() as usize,
            amplitude,
            edge_rate_per_s: self.limits.max_rate_per_s,
            min_hz: 5,
            max_hz: self.max_train_hz.max(5),
            lead_ms,
        }
    }
}

/// A simulation failure.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The controller cannot run.
    #[error("pattern generator: {0}")]
    Generator(#[from] fes_model::control::pattern_generator::PatternGeneratorError),
    /// The muscle or sensor settings are invalid.
    #[error("muscle: {0}")]
    Muscle(#[from] sim_muscle::ding::ParamError),
    /// The profile or a command was refused.
    #[error("supervisor refused: {0}")]
    Refused(#[source] CommandError),
}

/// Time series of a simulation (one entry per 1 ms sample).
#[derive(Debug, Clone, Default)]
pub struct SimResult {
    /// Target r handed to the generator (after rt-core's ramps).
    pub reference: Vec<f64>,
    /// The model force (rt-core's LMN output).
    pub model_force: Vec<f64>,
    /// The measured force, normalised.
    pub measured: Vec<f64>,
    /// Pulses.
    pub pulse: Vec<bool>,
    /// Completed beats with the outer loop's reaction.
    pub beats: Vec<BeatRecord>,
    /// The planner's counters at the end (all zero without planning).
    pub planner: fes_model::control::planner::PlannerStats,
}

const MS: u64 = 1_000_000;

/// CLOCK_MONOTONIC time of the first simulated sample, ns (1 s, so that no stamp is 0).
pub const T0_NS: u64 = 1_000 * MS;

impl SimResult {
    /// The run as the time series of a recording (sample k at [`T0_NS`] + k ms), for
    /// [`crate::summary::summarise`] and the plots.
    pub fn series(&self) -> Series {
        Series {
            t_ns: (0..self.pulse.len() as u64)
                .map(|k| T0_NS + k * MS)
                .collect(),
            reference: self.reference.clone(),
            model: self.model_force.clone(),
            measured: self.measured.clone(),
            pulse: self.pulse.clone(),
            beats: self
                .beats
                .iter()
                .map(|b| {
                    let m = &b.measurement;
                    BeatRow {
                        start_ns: m.beat.start_ns,
                        period_ns: m.beat.period_ns,
                        on_ns: m.beat.on_ns,
                        plateau: m.plateau_mean.unwrap_or(f64::NAN),
                        pulses: m.pulses,
                        fti: m.fti,
                        pulses_refused: m.pulses_refused,
                    }
                })
                .collect(),
        }
    }
}

/// Runs the chain for `settings.seconds`.
pub fn simulate(controller: &Controller, s: &SimSettings) -> Result<SimResult, SimError> {
    let mut pg = controller.pattern_generator()?;
    let mut muscle = Muscle::new(s.muscle)?;
    let mut sensor = match &s.sensor {
        Some(c) => Some(ForceSensor::new(*c, s.muscle.ts_s)?),
        None => None,
    };
    let mut core = SupervisorCore::new(s.limits, s.outer_loop, s.contraction);
    let mut tracker = ReferenceTracker::new(ReferencePolicy {
        stale_after_ns: 100 * MS,
        stale_ramp_per_s: 2.0,
        tick_ns: MS,
    });
    let mut edges = [PreviewEdge::default(); ReferencePreview::MAX_EDGES];
    let t0 = T0_NS;
    core.command(&Command::Arm, t0, Ok(()))
        .map_err(SimError::Refused)?;
    core.command(
        &Command::Profile {
            profile: s.profile.clone(),
        },
        t0,
        Ok(()),
    )
    .map_err(SimError::Refused)?;
    let n = (s.seconds * 1000.0).round() as usize;
    let mut out = SimResult {
        reference: Vec::with_capacity(n),
        model_force: Vec::with_capacity(n),
        measured: Vec::with_capacity(n),
        pulse: Vec::with_capacity(n),
        beats: Vec::new(),
        planner: Default::default(),
    };
    let mut measured_now = match &mut sensor {
        Some(sen) => (sen.measure(0.0) - s.offset_n) / s.scale_n,
        None => 0.0,
    };
    for k in 0..n as u64 {
        let t = t0 + k * MS;
        let r = core.reference(t);
        // Offered once per tick, as rt-core takes the newest waiting reference, with the
        // preview the supervisor publishes beside it.
        let _ = tracker.offer(&r, t);
        let n = core.preview(t, &mut edges);
        let _ = tracker.offer_preview(&ReferencePreview::new(r.seq, t, r.seq, &edges[..n]), t);
        let target = tracker.advance(t);
        let o = pg.tick(&TickInput {
            reference: target.value,
            measured_force: Some(measured_now),
            resting: target.resting,
            preview: target.preview,
        });
        out.reference.push(target.value);
        out.model_force.push(o.model_force);
        out.measured.push(measured_now);
        out.pulse.push(o.pulse);
        core.on_force(t, measured_now);
        if o.pulse {
            core.on_pulse(t);
        }
        let f_n = muscle.step(o.pulse.then_some(Pulse::SUPRAMAXIMAL));
        let y_n = match &mut sensor {
            Some(sen) => sen.measure(f_n),
            None => f_n,
        };
        measured_now = (y_n - s.offset_n) / s.scale_n;
        out.beats.extend(core.take_beats());
    }
    out.planner = pg.stats().planner;
    Ok(out)
}
