//! The Ding muscle as a sampled plant: pulses at sample starts, an electromechanical
//! delay, force in newtons at sample ends ([`MusclePlant`] timing convention).

use std::collections::VecDeque;

use serde::{Deserialize, Serialize};

use crate::ding::{
    DEFAULT_MAX_SUBSTEP_S, DingModel, DingParams, FatigueParams, ParamError, PulseWidthParams,
    params::{non_negative, positive},
};
use crate::plant::{MusclePlant, Pulse};
use crate::preset::Preset;

/// Default electromechanical delay, s: the thesis measured Td ~ 7 ms on both muscles
/// (5.2.2, Fig. 5.5) and its models use d = 7 samples.
pub const DEFAULT_EMD_S: f64 = 7e-3;

/// Everything that defines a simulated muscle (measurement aside: see [`crate::sensor`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MuscleConfig {
    /// Force-model parameters (rested).
    pub ding: DingParams,
    /// Fatigue extension (Ding 2003), off when `None`.
    pub fatigue: Option<FatigueParams>,
    /// Pulse-width variant (Ding 2007), off when `None`: then every delivered pulse is
    /// supramaximal whatever its width.
    pub pulse_width: Option<PulseWidthParams>,
    /// Electromechanical delay between a pulse and its effect on the force, s (>= 0).
    pub emd_s: f64,
    /// Sample period, s.
    pub ts_s: f64,
    /// Longest RK4 substep, s.
    pub max_substep_s: f64,
}

impl MuscleConfig {
    /// The preset's muscle with the defaults: no fatigue, supramaximal pulses, 7 ms
    /// electromechanical delay, 1 ms sampling.
    pub fn preset(preset: Preset) -> Self {
        Self {
            ding: preset.params(),
            fatigue: None,
            pulse_width: None,
            emd_s: DEFAULT_EMD_S,
            ts_s: 1e-3,
            max_substep_s: DEFAULT_MAX_SUBSTEP_S,
        }
    }

    /// Checks every field.
    pub fn validate(&self) -> Result<(), ParamError> {
        self.ding.validate()?;
        if let Some(f) = &self.fatigue {
            f.validate()?;
        }
        if let Some(p) = &self.pulse_width {
            p.validate()?;
        }
        non_negative("emd", self.emd_s)?;
        if self.emd_s > 1.0 {
            return Err(ParamError::OutOfRange {
                name: "emd",
                value: self.emd_s,
                requirement: "must be <= 1 s (the thesis measured about 7 ms)",
            });
        }
        positive("ts", self.ts_s)?;
        positive("max_substep", self.max_substep_s)
    }
}

/// The muscle's maximal force, N: the peak of a 1 s, 100 Hz train from rest (the top of
/// the protocols' frequency range, where both presets' force-frequency curves have
/// flattened). Scales the default sensor noise and offset.
pub fn max_force_n(ding: &DingParams) -> Result<f64, ParamError> {
    let config = MuscleConfig {
        ding: *ding,
        emd_s: 0.0,
        ..MuscleConfig::preset(Preset::Fast)
    };
    let mut muscle = Muscle::new(config)?;
    let train = crate::pattern::constant_train(100.0, 0, 1000, config.ts_s).map_err(|_| {
        ParamError::NotFinite {
            name: "ts",
            value: config.ts_s,
        }
    })?;
    let pattern = crate::pattern::from_samples(&train, 1000);
    let force = crate::simulate::simulate(&mut muscle, &pattern, Pulse::SUPRAMAXIMAL);
    Ok(force.into_iter().fold(0.0, f64::max))
}

/// A pulse waiting out the electromechanical delay.
#[derive(Debug, Clone, Copy)]
struct Pending {
    /// Sample during which it reaches the muscle.
    sample: u64,
    /// Activation gain (pulse-width variant).
    gain: f64,
}

/// The Ding muscle sampled every `ts`: implements [`MusclePlant`].
///
/// A pulse given to `step` at sample k reaches the muscle `emd` later: at sample
/// `k + floor(emd/ts)`, `frac(emd/ts) ts` into it. With emd = 7 ms at 1 ms the first
/// nonzero force is sample k + 8, as for the thesis's d = 7 delta-domain models.
#[derive(Debug, Clone)]
pub struct Muscle {
    config: MuscleConfig,
    model: DingModel,
    delay_samples: u64,
    delay_offset_s: f64,
    pending: VecDeque<Pending>,
    sample: u64,
}

impl Muscle {
    /// A muscle at rest. Allocates the delay line once; `step` never allocates.
    pub fn new(config: MuscleConfig) -> Result<Self, ParamError> {
        config.validate()?;
        let model = DingModel::new(config.ding, config.fatigue, config.max_substep_s)?;
        let delay = config.emd_s / config.ts_s;
        let mut whole = (delay + 1e-9).floor();
        let mut frac = delay - whole;
        if frac < 1e-9 {
            frac = 0.0;
        }
        if whole < 0.0 {
            whole = 0.0;
        }
        Ok(Self {
            config,
            model,
            delay_samples: whole as u64,
            delay_offset_s: frac * config.ts_s,
            pending: VecDeque::with_capacity(whole as usize + 2),
            sample: 0,
        })
    }

    /// The configuration it was built with.
    pub fn config(&self) -> &MuscleConfig {
        &self.config
    }

    /// The continuous-time model inside (state inspection).
    pub fn model(&self) -> &DingModel {
        &self.model
    }

    /// Activation gain of a delivered pulse: 0 without charge, else the pulse-width
    /// variant's gain, else 1 (supramaximal).
    fn gain(&self, pulse: &Pulse) -> f64 {
        if !(pulse.amplitude_ma > 0.0) || !(pulse.width_us > 0.0) {
            return 0.0;
        }
        match &self.config.pulse_width {
            Some(pw) => pw.gain(pulse.width_us),
            None => 1.0,
        }
    }
}

impl MusclePlant for Muscle {
    fn ts(&self) -> f64 {
        self.config.ts_s
    }

    fn step(&mut self, pulse: Option<Pulse>) -> f64 {
        if let Some(p) = pulse {
            let gain = self.gain(&p);
            if gain > 0.0 {
                // At most one pulse per sample, so the queue never outgrows its capacity.
                self.pending.push_back(Pending {
                    sample: self.sample + self.delay_samples,
                    gain,
                });
            }
        }
        let mut elapsed = 0.0;
        while let Some(p) = self.pending.front().copied() {
            if p.sample != self.sample {
                break;
            }
            self.pending.pop_front();
            self.model.advance(self.delay_offset_s - elapsed);
            elapsed = self.delay_offset_s;
            self.model.fire(p.gain);
        }
        self.model.advance(self.config.ts_s - elapsed);
        self.sample += 1;
        self.model.force()
    }

    fn reset(&mut self) {
        self.model.reset();
        self.pending.clear();
        self.sample = 0;
    }

    fn rest(&mut self, seconds: f64) {
        // Whole samples, so pulses still in the delay line keep their timing.
        let mut left = (seconds.max(0.0) / self.config.ts_s).round() as u64;
        while left > 0 && (!self.pending.is_empty() || !self.model.is_quiescent()) {
            self.step(None);
            left -= 1;
        }
        if left > 0 {
            self.model.relax(left as f64 * self.config.ts_s);
            self.sample = self.sample.saturating_add(left);
        }
    }
}
