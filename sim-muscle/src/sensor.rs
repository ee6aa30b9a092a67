//! Force measurement: an additive offset, seeded Gaussian noise and an optional
//! first-order sensor low-pass, as on a rig's force transducer.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use crate::ding::{
    ParamError,
    params::{finite, non_negative},
};
use crate::plant::{MusclePlant, Pulse};

/// Default noise standard deviation as a fraction of the muscle's maximal force (0.3 %).
pub const DEFAULT_NOISE_FRACTION: f64 = 0.003;
/// Default offset as a fraction of the muscle's maximal force (1 %): nonzero so the
/// recorder's offset removal is exercised, as with a real transducer.
pub const DEFAULT_OFFSET_FRACTION: f64 = 0.01;

/// How the force is measured.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SensorConfig {
    /// Additive offset, N.
    pub offset_n: f64,
    /// Standard deviation of the additive white Gaussian noise, N (>= 0).
    pub noise_std_n: f64,
    /// Time constant of the first-order sensor low-pass, s; 0 = no low-pass.
    pub lowpass_tau_s: f64,
    /// Seed of the noise generator (ChaCha8).
    pub seed: u64,
}

impl SensorConfig {
    /// An ideal sensor: no offset, no noise, no low-pass.
    pub const IDEAL: SensorConfig = SensorConfig {
        offset_n: 0.0,
        noise_std_n: 0.0,
        lowpass_tau_s: 0.0,
        seed: 0,
    };

    /// The defaults for a muscle whose maximal force is `max_force_n`: offset 1 % and
    /// noise 0.3 % of it, no low-pass.
    pub fn defaults_for(max_force_n: f64, seed: u64) -> Self {
        SensorConfig {
            offset_n: DEFAULT_OFFSET_FRACTION * max_force_n,
            noise_std_n: DEFAULT_NOISE_FRACTION * max_force_n,
            lowpass_tau_s: 0.0,
            seed,
        }
    }

    /// Checks every field.
    pub fn validate(&self) -> Result<(), ParamError> {
        finite("offset", self.offset_n)?;
        non_negative("noise_std", self.noise_std_n)?;
        non_negative("sensor_tau", self.lowpass_tau_s)
    }
}

/// A force sensor: `y = offset + lowpass(F) + noise`.
#[derive(Debug, Clone)]
pub struct ForceSensor {
    config: SensorConfig,
    /// Low-pass coefficient `1 - exp(-ts/tau)` (1 = no low-pass).
    alpha: f64,
    filtered: f64,
    noise: Normal<f64>,
    rng: ChaCha8Rng,
}

impl ForceSensor {
    /// A sensor sampled every `ts_s` seconds, its low-pass at rest (zero force).
    pub fn new(config: SensorConfig, ts_s: f64) -> Result<Self, ParamError> {
        config.validate()?;
        crate::ding::params::positive("ts", ts_s)?;
        let alpha = if config.lowpass_tau_s > 0.0 {
            1.0 - (-ts_s / config.lowpass_tau_s).exp()
        } else {
            1.0
        };
        let noise = Normal::new(0.0, config.noise_std_n).map_err(|_| ParamError::NotFinite {
            name: "noise_std",
            value: config.noise_std_n,
        })?;
        Ok(Self {
            config,
            alpha,
            filtered: 0.0,
            noise,
            rng: ChaCha8Rng::seed_from_u64(config.seed),
        })
    }

    /// The configuration it was built with.
    pub fn config(&self) -> &SensorConfig {
        &self.config
    }

    /// Measures the true force `force_n` (one sample): the low-pass is the exact
    /// discretisation of `tau dy/dt = F - y` for a force held over the sample.
    pub fn measure(&mut self, force_n: f64) -> f64 {
        self.filtered += self.alpha * (force_n - self.filtered);
        let noise = if self.config.noise_std_n > 0.0 {
            self.noise.sample(&mut self.rng)
        } else {
            0.0
        };
        self.config.offset_n + self.filtered + noise
    }

    /// Returns the low-pass to zero force; the noise sequence continues.
    pub fn reset(&mut self) {
        self.filtered = 0.0;
    }
}

/// A plant seen through a force sensor: `step` returns the measured force.
#[derive(Debug, Clone)]
pub struct Measured<P> {
    plant: P,
    sensor: ForceSensor,
}

impl<P: MusclePlant> Measured<P> {
    /// `plant` measured by `sensor`.
    pub fn new(plant: P, sensor: ForceSensor) -> Self {
        Self { plant, sensor }
    }

    /// The plant inside.
    pub fn plant(&self) -> &P {
        &self.plant
    }
}

impl<P: MusclePlant> MusclePlant for Measured<P> {
    fn ts(&self) -> f64 {
        self.plant.ts()
    }

    fn step(&mut self, pulse: Option<Pulse>) -> f64 {
        let f = self.plant.step(pulse);
        self.sensor.measure(f)
    }

    fn reset(&mut self) {
        self.plant.reset();
        self.sensor.reset();
    }

    fn initial_force(&mut self) -> f64 {
        let f = self.plant.initial_force();
        self.sensor.measure(f)
    }

    fn rest(&mut self, seconds: f64) {
        self.plant.rest(seconds);
        self.sensor.reset();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The low-pass's step response is the closed form `1 - exp(-t/tau)` at every
    /// sample; the noise has the configured mean and standard deviation (20 000 samples,
    /// 3 % tolerance); equal seeds give equal sequences.
    #[test]
    fn lowpass_closed_form_and_noise_statistics() {
        let cfg = SensorConfig {
            offset_n: 0.0,
            noise_std_n: 0.0,
            lowpass_tau_s: 0.01,
            seed: 1,
        };
        let mut s = ForceSensor::new(cfg, 1e-3).expect("valid");
        for k in 1..=50 {
            let y = s.measure(1.0);
            let exact = 1.0 - (-(k as f64) * 1e-3 / 0.01).exp();
            assert!((y - exact).abs() < 1e-12);
        }
        let cfg = SensorConfig {
            offset_n: 2.0,
            noise_std_n: 0.5,
            lowpass_tau_s: 0.0,
            seed: 7,
        };
        let mut a = ForceSensor::new(cfg, 1e-3).expect("valid");
        let mut b = ForceSensor::new(cfg, 1e-3).expect("valid");
        let n = 20_000;
        let ys: Vec<f64> = (0..n).map(|_| a.measure(0.0)).collect();
        let ys_b: Vec<f64> = (0..n).map(|_| b.measure(0.0)).collect();
        assert_eq!(ys, ys_b);
        let mean = ys.iter().sum::<f64>() / n as f64;
        let sd = (ys.iter().map(|y| (y - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt();
        assert!((mean - 2.0).abs() < 4.0 * 0.5 / (n as f64).sqrt());
        assert!((sd / 0.5 - 1.0).abs() < 0.03);
    }
}
