//! Optimal stimulation patterns (thesis ch. 6): the force-time integral and its normalised
//! per-pulse form, and the methods that search for patterns maximising it.
//!
//! - eq. (6.1)-(6.2): [`fti`], the force-time integral `FTI_p = sum_i F(tau_i) Ts`;
//! - eq. (6.3): [`ftipp`], `FTIpP_p = FTI_p / (FTI_1 p)`;
//! - eq. (6.5)-(6.6): [`average_frequency`] of a pattern;
//! - [`Evaluator`]: FTI, FTIpP and peak of any pattern on any muscle or model
//!   ([`ForceResponse`]) over one fixed window;
//! - [`random`] (6.2), [`trains`] (6.3), [`iterative`] (6.4): the three search methods,
//!   parallel over patterns (rayon);
//! - [`lcn`] (6.5): the pattern generator driven by step references and the shape of the
//!   pattern it produces (6.5.4).
//!
//! **The window.** Every FTI of one analysis (the twitch's `FTI_1` included) is summed over
//! the same window `[t0, t1)`, `t0` = the start of the pattern (sample 0, which is also the
//! twitch's pulse), `t1 = t0 + window` (eq. 6.1: "the recorded interval"). The window must be
//! long enough for the force to return to rest after the last pulse; each
//! [`PatternResult`] carries the force left at `t1` relative to its peak so a truncated
//! response is visible. **Rest force.** The response of a muscle or model is the force
//! *produced by the stimulation*: its output minus the output with no pulses at all (zero for
//! the Ding muscle; the rest output of an LMN with offsets is constant and would otherwise add
//! `y_rest * window` to every FTI).

pub mod iterative;
pub mod lcn;
pub mod random;
pub mod trains;

use fes_model::model::lmn::LmnError;
use fes_model::model::simulate::{RunError, simulate};
use fes_model::model::{Lmn, Network};

/// Why an FTI, an FTIpP or a pattern evaluation failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OspError {
    /// The pattern has no pulse (eq. 6.3 divides by p).
    #[error("FTIpP needs at least one pulse (p = 0)")]
    NoPulse,
    /// The single-pulse FTI is zero, negative or not finite, so eq. (6.3) is undefined.
    #[error(
        "the twitch force-time integral FTI_1 = {0} must be finite and > 0 (does a single pulse produce force in this muscle or model?)"
    )]
    BadTwitch(f64),
    /// Pulse times must be strictly increasing sample indices inside the window.
    #[error("pulse #{index} at sample {sample} is {problem}")]
    BadPulse {
        /// Position in the pattern.
        index: usize,
        /// Its sample index.
        sample: usize,
        /// What is wrong.
        problem: &'static str,
    },
    /// The window has too few samples.
    #[error("the FTI window of {0} samples is too short (at least 2)")]
    Window(usize),
    /// The response contains a non-finite value (an unstable model diverged).
    #[error(
        "the response to a {pulses}-pulse pattern is not finite at sample {sample} (the model diverges)"
    )]
    NonFinite {
        /// Pulses in the pattern.
        pulses: usize,
        /// First bad sample.
        sample: usize,
    },
    /// A method's setting is outside its allowed range `min..=max` (`max` `None`:
    /// unbounded).
    #[error("{method}: {setting} = {value} is outside {}", allowed(*.min, *.max))]
    Settings {
        /// The method (or step) whose setting it is.
        method: &'static str,
        /// The setting.
        setting: &'static str,
        /// Its value.
        value: usize,
        /// The least allowed value.
        min: usize,
        /// The greatest allowed value, if any.
        max: Option<usize>,
    },
    /// The model could not be run.
    #[error("model: {0}")]
    Model(#[from] RunError),
    /// The model's run-time network could not be built.
    #[error("model: {0}")]
    Network(#[from] LmnError),
}

/// The allowed range of [`OspError::Settings`] as text.
fn allowed(min: usize, max: Option<usize>) -> String {
    match max {
        Some(max) => format!("{min}..={max}"),
        None => format!("{min}.."),
    }
}

/// Force-time integral, eq. (6.2): `FTI = sum_i F(tau_i) Ts` over the samples given (the
/// window `[t0, t1)` is the caller's slice).
pub fn fti(force: &[f64], ts_s: f64) -> f64 {
    force.iter().sum::<f64>() * ts_s
}

/// Normalised force-time integral per pulse, eq. (6.3): `FTI_p / (FTI_1 p)`.
pub fn ftipp(fti_p: f64, fti_1: f64, p: usize) -> Result<f64, OspError> {
    if p == 0 {
        return Err(OspError::NoPulse);
    }
    if !fti_1.is_finite() || fti_1 <= 0.0 {
        return Err(OspError::BadTwitch(fti_1));
    }
    Ok(fti_p / (fti_1 * p as f64))
}

/// Average stimulation frequency of a pattern, eq. (6.5)-(6.6): the mean over its
/// inter-pulse intervals of `1 / (t_{k+1} - t_k)`, in Hz, for pulse sample indices at period
/// `ts_s`. `None` for fewer than two pulses (no interval).
pub fn average_frequency(pulses: &[usize], ts_s: f64) -> Option<f64> {
    if pulses.len() < 2 {
        return None;
    }
    let sum: f64 = pulses
        .windows(2)
        .map(|w| 1.0 / ((w[1] as f64 - w[0] as f64) * ts_s))
        .sum();
    Some(sum / (pulses.len() - 1) as f64)
}

/// A muscle or a model seen as a map from a pulse pattern to the force it produces.
///
/// `Sync` so the search methods can evaluate patterns in parallel; every call starts from
/// rest and must not depend on earlier calls.
pub trait ForceResponse: Sync {
    /// Sampling period, s.
    fn ts(&self) -> f64;
    /// The force produced by the pulse train `train` (`true` = a supramaximal pulse at the
    /// start of that sample), from rest, one value per sample, with the rest force (the
    /// output with no pulses) removed.
    fn force(&self, train: &[bool]) -> Result<Vec<f64>, OspError>;
}

/// An LMN's output as the force (normalised units): free-run simulation from rest
/// (`model::simulate::simulate`, eq. B.6/B.7) minus the constant rest output.
#[derive(Debug, Clone)]
pub struct ModelResponse {
    net: Network<f64>,
    rest: f64,
}

impl ModelResponse {
    /// The response of a model (unstable local models allowed: a diverging response is
    /// reported as [`OspError::NonFinite`] by the evaluation).
    pub fn new(lmn: &Lmn) -> Result<Self, OspError> {
        let net = lmn.network()?;
        Self::from_network(net)
    }

    /// The response of a run-time network.
    pub fn from_network(net: Network<f64>) -> Result<Self, OspError> {
        let mut y = [0.0];
        simulate(&net, &[0.0], &mut y)?;
        Ok(Self { net, rest: y[0] })
    }

    /// The constant output with no pulses (normalised force).
    pub fn rest_output(&self) -> f64 {
        self.rest
    }

    /// The network.
    pub fn network(&self) -> &Network<f64> {
        &self.net
    }
}

impl ForceResponse for ModelResponse {
    fn ts(&self) -> f64 {
        self.net.ts()
    }

    fn force(&self, train: &[bool]) -> Result<Vec<f64>, OspError> {
        let u: Vec<f64> = train.iter().map(|&p| if p { 1.0 } else { 0.0 }).collect();
        let mut y = vec![0.0; u.len()];
        simulate(&self.net, &u, &mut y)?;
        for v in &mut y {
            *v -= self.rest;
        }
        Ok(y)
    }
}

/// FTI, FTIpP and shape of the response to one pattern.
#[derive(Debug, Clone, PartialEq)]
pub struct PatternResult {
    /// Pulse sample indices (strictly increasing).
    pub pulses: Vec<usize>,
    /// Force-time integral over the window, eq. (6.2) (force units x s).
    pub fti: f64,
    /// Normalised FTI per pulse, eq. (6.3).
    pub ftipp: f64,
    /// Largest force in the window.
    pub peak: f64,
    /// |force at the last sample of the window| / peak: how far the response is from rest
    /// when the window ends (should be small, e.g. < 0.01).
    pub end_fraction: f64,
}

/// Evaluates patterns on one muscle or model over one window (module docs), relative to
/// the twitch (one pulse at sample 0).
pub struct Evaluator<'r, R: ForceResponse + ?Sized> {
    response: &'r R,
    window: usize,
    twitch: PatternResult,
}

impl<'r, R: ForceResponse + ?Sized> Evaluator<'r, R> {
    /// Records the twitch (eq. 6.3's `FTI_1`) over `window` samples.
    pub fn new(response: &'r R, window: usize) -> Result<Self, OspError> {
        if window < 2 {
            return Err(OspError::Window(window));
        }
        let (fti_1, peak, end_fraction) = run(response, &[0], window)?;
        if !fti_1.is_finite() || fti_1 <= 0.0 {
            return Err(OspError::BadTwitch(fti_1));
        }
        Ok(Self {
            response,
            window,
            twitch: PatternResult {
                pulses: vec![0],
                fti: fti_1,
                ftipp: 1.0,
                peak,
                end_fraction,
            },
        })
    }

    /// The twitch (single pulse at sample 0).
    pub fn twitch(&self) -> &PatternResult {
        &self.twitch
    }

    /// The window length in samples.
    pub fn window(&self) -> usize {
        self.window
    }

    /// The sampling period, s.
    pub fn ts(&self) -> f64 {
        self.response.ts()
    }

    /// FTI, FTIpP and peak of the pattern with pulses at the given sample indices.
    pub fn evaluate(&self, pulses: &[usize]) -> Result<PatternResult, OspError> {
        let (fti_p, peak, end_fraction) = run(self.response, pulses, self.window)?;
        Ok(PatternResult {
            pulses: pulses.to_vec(),
            fti: fti_p,
            ftipp: ftipp(fti_p, self.twitch.fti, pulses.len())?,
            peak,
            end_fraction,
        })
    }
}

/// FTI, peak and end fraction of one pattern over `window` samples.
fn run<R: ForceResponse + ?Sized>(
    response: &R,
    pulses: &[usize],
    window: usize,
) -> Result<(f64, f64, f64), OspError> {
    if pulses.is_empty() {
        return Err(OspError::NoPulse);
    }
    let mut train = vec![false; window];
    let mut previous: Option<usize> = None;
    for (index, &sample) in pulses.iter().enumerate() {
        if previous.is_some_and(|p| sample <= p) {
            return Err(OspError::BadPulse {
                index,
                sample,
                problem: "not after the previous pulse",
            });
        }
        if sample + 1 >= window {
            return Err(OspError::BadPulse {
                index,
                sample,
                problem: "not inside the FTI window (before its last sample)",
            });
        }
        train[sample] = true;
        previous = Some(sample);
    }
    let force = response.force(&train)?;
    if let Some(sample) = force.iter().position(|v| !v.is_finite()) {
        return Err(OspError::NonFinite {
            pulses: pulses.len(),
            sample,
        });
    }
    let peak = force.iter().copied().fold(0.0, f64::max);
    let end = force.last().copied().unwrap_or(0.0).abs();
    let end_fraction = if peak > 0.0 { end / peak } else { 0.0 };
    Ok((fti(&force, response.ts()), peak, end_fraction))
}

/// Inter-pulse intervals `ipi_min..=ipi_max` in samples, validated (`1 <= min <= max`).
pub(crate) fn ipi_range(ipi_min: usize, ipi_max: usize) -> Result<Vec<usize>, OspError> {
    if ipi_min == 0 || ipi_min > ipi_max {
        return Err(OspError::Settings {
            method: "the IPI range (samples)",
            setting: "ipi_min",
            value: ipi_min,
            min: 1,
            max: Some(ipi_max),
        });
    }
    Ok((ipi_min..=ipi_max).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sum rule integrates a known signal: F = 2 for 100 samples of 1 ms is 0.2;
    /// two twitch-sized FTIs from two pulses is FTIpP 1; eq. (6.6) by hand.
    #[test]
    fn fti_ftipp_and_average_frequency_identities() {
        assert!((fti(&[2.0; 100], 1e-3) - 0.2).abs() < 1e-15);
        assert_eq!(ftipp(2.0, 1.0, 2), Ok(1.0));
        assert_eq!(ftipp(1.0, 1.0, 0), Err(OspError::NoPulse));
        assert_eq!(ftipp(1.0, 0.0, 1), Err(OspError::BadTwitch(0.0)));
        // IPIs 10 ms and 40 ms: (100 Hz + 25 Hz) / 2.
        let f = average_frequency(&[0, 10, 50], 1e-3).expect("two intervals");
        assert!((f - 62.5).abs() < 1e-12);
        assert_eq!(average_frequency(&[3], 1e-3), None);
    }
}
