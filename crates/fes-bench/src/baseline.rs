//! The comparison stimulation: constant-frequency 40 Hz trains of equal contraction.
//!
//! For a beat of the cardiac profile (period T, contraction D, amplitude A) and the
//! contraction the LCN patterns achieved, measured as the force-time integral of the beat
//! (thesis eq. 6.2, normalised force x s over `[d, T + d)`), the baseline is the 40 Hz
//! train starting at the beat onset whose FTI over the same window is the same: the
//! number of pulses n is found by simulating the same sim-muscle preset from rest with
//! n = 1, 2, ... pulses 25 ms apart and interpolating linearly between the two counts
//! whose FTI brackets the target (**same FTI**, not same peak: FTI is what the thesis's
//! optimal-pattern chapter compares, and it is monotone in n). Also reported: the FTI and
//! pulse count of a 40 Hz train filling the whole contraction D, and the RMS tracking
//! error of the matched train against the beat's square-wave reference.

use fes_ident::analysis::osp::fti;
use serde::{Deserialize, Serialize};
use sim_muscle::muscle::{Muscle, MuscleConfig};
use sim_muscle::pattern::{constant_train, from_samples};
use sim_muscle::plant::{MusclePlant, Pulse};
use sim_muscle::simulate::simulate;

/// The beat to match.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BeatShape {
    /// Beat period, ms.
    pub period_ms: usize,
    /// Contraction length, ms.
    pub on_ms: usize,
    /// Reference amplitude, normalised force.
    pub amplitude: f64,
    /// Edge rate of the reference, normalised force per second.
    pub edge_rate_per_s: f64,
    /// Delay between reference and force, samples (the model's d).
    pub delay: usize,
}

impl BeatShape {
    /// The square-wave reference of one beat, with its ramped edges, 1 ms samples.
    pub fn reference(&self) -> Vec<f64> {
        let step = self.edge_rate_per_s * 1e-3;
        let mut r = Vec::with_capacity(self.period_ms);
        let mut v: f64 = 0.0;
        for k in 0..self.period_ms {
            let goal = if k < self.on_ms { self.amplitude } else { 0.0 };
            v = if goal > v {
                (v + step).min(goal)
            } else {
                (v - step).max(goal)
            };
            r.push(v);
        }
        r
    }
}

/// The 40 Hz baseline of one beat.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Baseline {
    /// Train frequency, Hz (40).
    pub freq_hz: f64,
    /// FTI to match, normalised force x s.
    pub target_fti: f64,
    /// Pulses of the train of equal FTI (interpolated).
    pub pulses: f64,
    /// Whether even the train filling the whole beat stays below the target.
    pub saturated: bool,
    /// FTI of the 40 Hz train filling the whole contraction.
    pub full_contraction_fti: f64,
    /// Pulses of that train.
    pub full_contraction_pulses: usize,
    /// RMS error of the matched train (nearest whole pulse count) against the reference,
    /// normalised force.
    pub rms_error: f64,
    /// Peak force of the matched train, normalised.
    pub peak: f64,
}

/// The normalised force of `n` pulses at `freq_hz` from the beat onset, over the beat
/// window plus the delay, from rest.
fn response(
    muscle: &MuscleConfig,
    scale_n: f64,
    shape: &BeatShape,
    freq_hz: f64,
    n: usize,
) -> Vec<f64> {
    let len = shape.period_ms + shape.delay;
    let mut plant = match Muscle::new(*muscle) {
        Ok(m) => m,
        Err(_) => return vec![0.0; len],
    };
    let times = constant_train(freq_hz, 0, len, 1e-3).unwrap_or_default();
    let train = from_samples(&times[..n.min(times.len())], len);
    // Sample k of the record is the force at k Ts (the plant returns the force at the end
    // of each sample): prepend the rest value.
    let mut f = vec![plant.initial_force()];
    f.extend(simulate(&mut plant, &train, Pulse::SUPRAMAXIMAL));
    f.truncate(len);
    f.iter().map(|x| x / scale_n).collect()
}

/// The 40 Hz baseline of equal FTI for `target_fti` (normalised force x s) on the
/// rested muscle `muscle` (fatigue off), normalised by `scale_n`.
pub fn baseline_40hz(
    muscle: &MuscleConfig,
    scale_n: f64,
    shape: &BeatShape,
    target_fti: f64,
) -> Baseline {
    const FREQ: f64 = 40.0;
    let mut muscle = *muscle;
    muscle.fatigue = None;
    let window = |f: &[f64]| fti(&f[shape.delay.min(f.len())..], 1e-3);
    let max_n = (shape.period_ms as f64 * FREQ / 1000.0).floor() as usize;
    let full_n = ((shape.on_ms as f64) * FREQ / 1000.0).ceil() as usize;
    let full = window(&response(&muscle, scale_n, shape, FREQ, full_n));
    let mut prev = 0.0;
    let mut pulses = max_n as f64;
    let mut saturated = true;
    for n in 1..=max_n {
        let f = window(&response(&muscle, scale_n, shape, FREQ, n));
        if f >= target_fti {
            let frac = if f > prev {
                (target_fti - prev) / (f - prev)
            } else {
                1.0
            };
            pulses = (n - 1) as f64 + frac.clamp(0.0, 1.0);
            saturated = false;
            break;
        }
        prev = f;
    }
    let n_near = (pulses.round() as usize).max(1);
    let force = response(&muscle, scale_n, shape, FREQ, n_near);
    let reference = shape.reference();
    let err: f64 = reference
        .iter()
        .enumerate()
        .map(|(k, r)| {
            let y = force.get(k + shape.delay).copied().unwrap_or(0.0);
            (y - r).powi(2)
        })
        .sum::<f64>()
        / reference.len() as f64;
    Baseline {
        freq_hz: FREQ,
        target_fti,
        pulses,
        saturated,
        full_contraction_fti: full,
        full_contraction_pulses: full_n,
        rms_error: err.sqrt(),
        peak: force.iter().copied().fold(0.0, f64::max),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sim_muscle::preset::Preset;

    fn shape() -> BeatShape {
        BeatShape {
            period_ms: 800,
            on_ms: 320,
            amplitude: 0.3,
            edge_rate_per_s: 50.0,
            delay: 7,
        }
    }

    /// The FTI of n pulses is what the interpolation inverts: asking for the FTI of
    /// exactly 5 pulses returns 5 pulses, and a target between 5 and 6 returns a count
    /// between them.
    #[test]
    fn inverts_the_fti_of_whole_trains() {
        let m = MuscleConfig::preset(Preset::Fast);
        let s = shape();
        let f5 = fti(&response(&m, 364.0, &s, 40.0, 5)[7..], 1e-3);
        let f6 = fti(&response(&m, 364.0, &s, 40.0, 6)[7..], 1e-3);
        assert!(f6 > f5 && f5 > 0.0);
        let b = baseline_40hz(&m, 364.0, &s, f5);
        assert!((b.pulses - 5.0).abs() < 1e-12, "{}", b.pulses);
        let b = baseline_40hz(&m, 364.0, &s, 0.5 * (f5 + f6));
        assert!((b.pulses - 5.5).abs() < 1e-12, "{}", b.pulses);
        assert!(!b.saturated);
        assert_eq!(b.full_contraction_pulses, 13);
    }

    #[test]
    fn reference_has_ramped_edges() {
        let r = shape().reference();
        assert!((r[0] - 0.05).abs() < 1e-12);
        assert!((r[5] - 0.3).abs() < 1e-12);
        assert!((r[319] - 0.3).abs() < 1e-12);
        assert!((r[320] - 0.25).abs() < 1e-12);
        assert_eq!(r[330], 0.0);
    }
}
