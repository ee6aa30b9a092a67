//! The Ding muscle as a sampled plant: pulses at sample starts, an electromechanical
//! delay, force in newtons at sample ends ([`MusclePlant`] timing convention).

use std::collections::{BTreeMap, VecDeque};

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

    /// Sets the model parameter `name` (as in the papers: `tauc`, `r0`, `km`, `a`,
    /// `tau1`, `tau2`; with fatigue on also `alpha_a`, `alpha_km`, `alpha_tau1`,
    /// `tau_fat`; SI units) and re-validates.
    pub fn set(&mut self, name: &str, value: f64) -> Result<(), ParamError> {
        let slot = match (self.ding.get_mut(name), self.fatigue.as_mut()) {
            (Some(slot), _) => slot,
            (None, Some(f)) => match f.get_mut(name) {
                Some(slot) => slot,
                None => return Err(self.unknown(name)),
            },
            (None, None) => return Err(self.unknown(name)),
        };
        *slot = value;
        self.validate()
    }

    fn unknown(&self, name: &str) -> ParamError {
        let mut known: Vec<String> = DingParams::NAMES
            .iter()
            .map(|(n, u)| format!("{n} [{u}]"))
            .collect();
        let fatigue: Vec<String> = FatigueParams::NAMES
            .iter()
            .map(|(n, u)| format!("{n} [{u}]"))
            .collect();
        if self.fatigue.is_some() {
            known.extend(fatigue);
        } else if FatigueParams::NAMES.iter().any(|(n, _)| *n == name) {
            return ParamError::Unknown {
                name: name.to_string(),
                known: format!("{} (fatigue coefficients need --fatigue)", known.join(", ")),
            };
        }
        ParamError::Unknown {
            name: name.to_string(),
            known: known.join(", "),
        }
    }

    /// Every model number by name, SI units, for a data set's `parameters`.
    pub fn parameters(&self) -> BTreeMap<String, f64> {
        let mut m: BTreeMap<String, f64> = self
            .ding
            .entries()
            .iter()
            .map(|&(n, v)| (n.to_string(), v))
            .collect();
        if let Some(f) = &self.fatigue {
            m.extend(f.entries().iter().map(|&(n, v)| (n.to_string(), v)));
        }
        if let Some(p) = &self.pulse_width {
            m.insert("pd0_us".into(), p.pd0_us);
            m.insert("pdt_us".into(), p.pdt_us);
            m.insert("ref_us".into(), p.ref_us);
        }
        m.insert("emd_s".into(), self.emd_s);
        m.insert("ts_s".into(), self.ts_s);
        m.insert("max_substep_s".into(), self.max_substep_s);
        m
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

/// A muscle's maximal force, N: the peak of a 1 s, 100 Hz train from rest (the top of
/// the protocols' frequency range, where both presets' force-frequency curves have
/// flattened). Scales the default sensor noise and offset. The plant is reset first and
/// left wherever the train leaves it.
pub fn max_force(plant: &mut dyn MusclePlant) -> f64 {
    plant.reset();
    let n = (1.0 / plant.ts()).round().max(2.0) as usize;
    let hz = 100f64.min(1.0 / plant.ts());
    let train = crate::pattern::constant_train(hz, 0, n, plant.ts()).unwrap_or_default();
    let pattern = crate::pattern::from_samples(&train, n);
    let force = crate::simulate::simulate(plant, &pattern, Pulse::SUPRAMAXIMAL);
    force.into_iter().fold(0.0, f64::max)
}

/// [`max_force`] of the Ding muscle with parameters `ding` (no delay, 1 ms sampling).
pub fn max_force_n(ding: &DingParams) -> Result<f64, ParamError> {
    let config = MuscleConfig {
        ding: *ding,
        emd_s: 0.0,
        ..MuscleConfig::preset(Preset::Fast)
    };
    Ok(max_force(&mut Muscle::new(config)?))
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
        // emd / ts split into whole samples and a fraction; a fraction within 1e-9 of a
        // whole sample counts as whole (7e-3 / 1e-3 is not exactly 7 in floating point).
        let delay = config.emd_s / config.ts_s;
        let whole = (delay + 1e-9).floor();
        let frac = if delay - whole < 1e-9 {
            0.0
        } else {
            delay - whole
        };
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
        if pulse.amplitude_ma.is_nan()
            || pulse.amplitude_ma <= 0.0
            || pulse.width_us.is_nan()
            || pulse.width_us <= 0.0
        {
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
