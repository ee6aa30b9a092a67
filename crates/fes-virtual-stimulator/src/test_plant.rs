//! A deterministic test plant for the stimulator: the "force" is the electric charge
//! delivered so far, so every applied pulse is visible, with its amplitude and width, in
//! the FORCE stream. It stands in for the muscle in protocol tests (the physiological
//! models live in sim-muscle).

use crate::plant::{Plant, Pulse};

/// Force (N) = cumulative charge per phase (uC) of the applied pulses; 1 ms samples.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ChargeIntegrator {
    charge_uc: f64,
    steps: u64,
    pulses: u64,
}

impl ChargeIntegrator {
    /// A plant at rest.
    pub const fn new() -> Self {
        Self {
            charge_uc: 0.0,
            steps: 0,
            pulses: 0,
        }
    }

    /// Charge of one pulse in uC: amplitude (mA) x width (us) x 1e-3.
    pub fn pulse_charge_uc(pulse: &Pulse) -> f64 {
        pulse.amplitude_ma * pulse.width_us * 1e-3
    }

    /// Samples advanced since the last reset.
    pub const fn steps(&self) -> u64 {
        self.steps
    }

    /// Pulses applied since the last reset.
    pub const fn pulses(&self) -> u64 {
        self.pulses
    }

    /// Returns the plant to rest (no charge, no steps, no pulses).
    pub fn reset(&mut self) {
        *self = Self::new();
    }
}

impl Plant for ChargeIntegrator {
    fn ts(&self) -> f64 {
        1e-3
    }

    fn step(&mut self, pulse: Option<Pulse>) -> f64 {
        if let Some(p) = pulse {
            self.charge_uc += Self::pulse_charge_uc(&p);
            self.pulses += 1;
        }
        self.steps += 1;
        self.charge_uc
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn force_is_the_running_charge() {
        let mut p = ChargeIntegrator::new();
        assert_eq!(p.step(None), 0.0);
        // 20 mA x 200 us = 4 uC.
        let supramaximal = Pulse {
            amplitude_ma: 20.0,
            width_us: 200.0,
        };
        assert!((p.step(Some(supramaximal)) - 4.0).abs() < 1e-12);
        assert!(
            (p.step(Some(Pulse {
                amplitude_ma: 1.5,
                width_us: 100.0
            })) - 4.15)
                .abs()
                < 1e-12
        );
        assert_eq!((p.steps(), p.pulses()), (3, 2));
        p.reset();
        assert_eq!(p.step(None), 0.0);
    }
}
