//! The force-frequency curve of a model (thesis 5.4.3, Fig. 5.26): the mean model output
//! "after the initial rising portion" of long constant-frequency trains (thesis: 1000 ms).
//!
//! The trains are the caller's (sim-muscle's `pattern::constant_train` places each pulse
//! at the nearest sample, so the mean frequency is exact); here each is simulated from rest
//! and averaged over `[average_from, samples)`. The scheduling variable over the same
//! window tells whether the train drives the model where it was identified (the caller
//! compares it with the training data's phi range).

use fes_model::model::Network;
use fes_model::model::simulate::RunError;

use super::trace::simulate_trace;

/// One point of the curve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForceFrequencyPoint {
    /// Stimulation frequency, Hz.
    pub frequency_hz: f64,
    /// Mean model output over the averaging window (normalised force).
    pub mean_output: f64,
    /// Mean of phi over the averaging window.
    pub phi_mean: f64,
    /// Largest phi over the whole train.
    pub phi_max: f64,
}

/// Why a force-frequency curve could not be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ForceFrequencyError {
    /// The averaging window is empty.
    #[error("averaging window starts at sample {from} but the trains have only {samples} samples")]
    Window {
        /// First averaged sample.
        from: usize,
        /// Train length.
        samples: usize,
    },
    /// The model could not be run.
    #[error(transparent)]
    Run(#[from] RunError),
}

/// The curve for `trains` = (frequency in Hz, pulse sample indices) of `samples` samples
/// each, averaged over samples `average_from..samples`. Pulses at or after `samples` are
/// ignored.
pub fn force_frequency(
    net: &Network<f64>,
    trains: &[(f64, Vec<usize>)],
    samples: usize,
    average_from: usize,
) -> Result<Vec<ForceFrequencyPoint>, ForceFrequencyError> {
    if average_from >= samples {
        return Err(ForceFrequencyError::Window {
            from: average_from,
            samples,
        });
    }
    let n = (samples - average_from) as f64;
    trains
        .iter()
        .map(|(f, pulses)| {
            let mut u = vec![0.0; samples];
            for &k in pulses.iter().filter(|&&k| k < samples) {
                u[k] = 1.0;
            }
            let t = simulate_trace(net, &u)?;
            Ok(ForceFrequencyPoint {
                frequency_hz: *f,
                mean_output: t.y[average_from..].iter().sum::<f64>() / n,
                phi_mean: t.phi[average_from..].iter().sum::<f64>() / n,
                phi_max: t.phi.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            })
        })
        .collect()
}
