//! Force-time integral and force-time integral per pulse (thesis 6.1), in one place for
//! the optimal-pattern analyses.

use crate::pattern::from_samples;
use crate::plant::{MusclePlant, Pulse};
use crate::simulate::simulate;

/// Why an FTIpP could not be formed.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum MetricsError {
    /// The pattern has no pulse.
    #[error("FTIpP needs at least one pulse (p = 0)")]
    NoPulse,
    /// The single-pulse FTI is zero, negative or not finite.
    #[error("the twitch force-time integral FTI_1 = {0} must be finite and > 0")]
    BadTwitch(f64),
}

/// Force-time integral, eq. (6.2): `FTI = sum_i F(tau_i) Ts` over the samples given
/// (the window `[t0, t1)` is the caller's slice).
pub fn fti(force: &[f64], ts_s: f64) -> f64 {
    force.iter().sum::<f64>() * ts_s
}

/// Normalised force-time integral per pulse, eq. (6.3): `FTI_p / (FTI_1 p)`.
pub fn ftipp(fti_p: f64, fti_1: f64, p: usize) -> Result<f64, MetricsError> {
    if p == 0 {
        return Err(MetricsError::NoPulse);
    }
    if !fti_1.is_finite() || fti_1 <= 0.0 {
        return Err(MetricsError::BadTwitch(fti_1));
    }
    Ok(fti_p / (fti_1 * p as f64))
}

/// FTI (eq. 6.2) of the response of `plant`, from rest, to supramaximal pulses at the
/// sample indices `pulses`, over the window `[0, window ts)`. Choose `window` long enough
/// for the force to return to rest after the last pulse, or eq. (6.3) compares truncated
/// responses.
pub fn response_fti(plant: &mut dyn MusclePlant, pulses: &[usize], window: usize) -> f64 {
    plant.reset();
    let force = simulate(plant, &from_samples(pulses, window), Pulse::SUPRAMAXIMAL);
    fti(&force, plant.ts())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sum rule integrates a known signal: F = 2 N for 100 samples of 1 ms is 0.2 N s;
    /// two twitch-sized FTIs from two pulses is FTIpP 1.
    #[test]
    fn fti_and_ftipp_identities() {
        assert!((fti(&[2.0; 100], 1e-3) - 0.2).abs() < 1e-15);
        assert_eq!(ftipp(2.0, 1.0, 2), Ok(1.0));
        assert_eq!(ftipp(1.0, 1.0, 0), Err(MetricsError::NoPulse));
        assert_eq!(ftipp(1.0, 0.0, 1), Err(MetricsError::BadTwitch(0.0)));
    }
}
