//! The achieved contraction of each beat, from the measured force (outer loop input).
//!
//! The force of a beat is collected over the beat shifted by the electromechanical delay
//! (thesis 5.2.2: Td ~ 7 ms; the model's d): `[start + delay, end + delay)`. Three figures
//! per beat:
//!
//! - **plateau mean**: the mean force over the second part of the contraction,
//!   `[start + f on + delay, start + on + delay)` with `f` = `plateau_start` (default 0.5):
//!   the level the square wave asked for, once the rise is over. It is what the outer loop
//!   regulates: averaging over the inter-pulse ripple makes it insensitive to sensor
//!   noise, unlike a peak;
//! - **peak**: the largest sample (reported, not regulated: noise biases it upwards);
//! - **FTI**: the force-time integral of the beat window (thesis eq. 6.2), as the mean
//!   force times the window length so that a lost sample does not bias it.

use std::collections::VecDeque;
use std::ops::Range;

use serde::{Deserialize, Serialize};

use crate::profile::Beat;
use crate::range::{self, Interval, RangeError};

/// Where the plateau is and how much of it must have been measured.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ContractionSettings {
    /// Start of the plateau window as a fraction of the contraction, in [0, 1). Default 0.5.
    pub plateau_start: f64,
    /// Delay between the reference and the force, ms (the model's d x Ts). Default 7.
    pub delay_ms: f64,
    /// Fewest samples, as a fraction of the plateau's 1 ms samples, for a valid plateau
    /// mean, in (0, 1]. Default 0.8.
    pub min_coverage: f64,
}

impl Default for ContractionSettings {
    fn default() -> Self {
        Self {
            plateau_start: 0.5,
            delay_ms: 7.0,
            min_coverage: 0.8,
        }
    }
}

impl ContractionSettings {
    /// Checks the ranges; the error names the key.
    pub fn validate(&self) -> Result<(), RangeError> {
        range::check(
            "plateau_start",
            self.plateau_start,
            Interval::right_open(0.0, 1.0),
        )?;
        range::check("delay_ms", self.delay_ms, Interval::closed(0.0, 1000.0))?;
        range::check(
            "min_coverage",
            self.min_coverage,
            Interval::left_open(0.0, 1.0),
        )
    }

    /// The plateau window of a beat starting at `start` whose contraction lasts `on`, the
    /// force lagging by `delay`, all in one time unit (ns here, 1 ms samples on the bench):
    /// `[start + round(plateau_start on) + delay, start + on + delay)`.
    pub fn plateau_window(&self, start: u64, on: u64, delay: u64) -> Range<u64> {
        let offset = (self.plateau_start * on as f64).round() as u64;
        start + offset + delay..start + on + delay
    }
}

/// The measured contraction of one beat.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BeatMeasurement {
    /// The beat as it was run.
    pub beat: Beat,
    /// Mean force over the plateau window, normalised; `None` when too few samples came.
    pub plateau_mean: Option<f64>,
    /// Largest force sample of the beat window, normalised (NaN when there was none).
    pub peak: f64,
    /// Force-time integral of the beat window, normalised force x s (eq. 6.2).
    pub fti: f64,
    /// Force samples in the beat window.
    pub samples: u64,
    /// Share of the plateau's 1 ms samples that were measured.
    pub plateau_coverage: f64,
    /// Pulses delivered during the beat (StimTicks that fired in `[start, end)`).
    pub pulses: u64,
    /// Pulses of the beat the stimulator driver refused (its interlocks: late, IPI, rate,
    /// ...), from its DriverStatus counts. Such a beat's force is not the response to the
    /// train the inner loop planned, so the outer loop does not learn from it.
    #[serde(default)]
    pub pulses_refused: u64,
}

#[derive(Debug, Clone, Copy)]
struct Window {
    beat: Beat,
    from_ns: u64,
    to_ns: u64,
    plateau_from_ns: u64,
    plateau_to_ns: u64,
    sum: f64,
    n: u64,
    plateau_sum: f64,
    plateau_n: u64,
    peak: f64,
    pulses: u64,
    pulses_refused: u64,
}

/// Collects force samples and pulses into beat windows.
#[derive(Debug, Clone)]
pub struct ContractionEstimator {
    settings: ContractionSettings,
    open: VecDeque<Window>,
}

/// Windows left open at most this long after their end when no later sample arrives, ns.
pub const CLOSE_GRACE_NS: u64 = 200_000_000;

impl ContractionEstimator {
    /// An estimator with no beat open.
    pub fn new(settings: ContractionSettings) -> Self {
        Self {
            settings,
            open: VecDeque::new(),
        }
    }

    /// Opens the window of `beat`.
    pub fn begin(&mut self, beat: Beat) {
        let delay = (self.settings.delay_ms * 1e6).round() as u64;
        let plateau = self
            .settings
            .plateau_window(beat.start_ns, beat.on_ns, delay);
        self.open.push_back(Window {
            beat,
            from_ns: beat.start_ns + delay,
            to_ns: beat.end_ns() + delay,
            plateau_from_ns: plateau.start,
            plateau_to_ns: plateau.end,
            sum: 0.0,
            n: 0,
            plateau_sum: 0.0,
            plateau_n: 0,
            peak: f64::NAN,
            pulses: 0,
            pulses_refused: 0,
        });
    }

    /// Drops every open window (profile changed or stopped).
    pub fn clear(&mut self) {
        self.open.clear();
    }

    /// Adds a force sample taken at `t_ns` (normalised force).
    pub fn add_force(&mut self, t_ns: u64, force: f64) {
        if !force.is_finite() {
            return;
        }
        for w in &mut self.open {
            if (w.from_ns..w.to_ns).contains(&t_ns) {
                w.sum += force;
                w.n += 1;
                w.peak = if w.peak.is_nan() {
                    force
                } else {
                    w.peak.max(force)
                };
                if (w.plateau_from_ns..w.plateau_to_ns).contains(&t_ns) {
                    w.plateau_sum += force;
                    w.plateau_n += 1;
                }
            }
        }
    }

    /// Counts a pulse fired at `t_ns` (StimTick time).
    pub fn add_pulse(&mut self, t_ns: u64) {
        for w in &mut self.open {
            if (w.beat.start_ns..w.beat.end_ns()).contains(&t_ns) {
                w.pulses += 1;
            }
        }
    }

    /// Counts `n` pulses the driver refused somewhere in `(from_ns, to_ns]` (between two
    /// of its status reports, 100 ms apart): every open beat overlapping that interval
    /// is marked, so a refusal near a beat boundary marks both beats (conservative).
    pub fn add_refused(&mut self, from_ns: u64, to_ns: u64, n: u64) {
        for w in &mut self.open {
            if w.beat.start_ns <= to_ns && from_ns < w.beat.end_ns() {
                w.pulses_refused += n;
            }
        }
    }

    /// Closes the windows that are complete: those ending at or before `latest_sample_ns`
    /// (a later sample has arrived), or more than [`CLOSE_GRACE_NS`] before `now_ns`.
    pub fn poll(&mut self, latest_sample_ns: u64, now_ns: u64) -> Vec<BeatMeasurement> {
        let mut done = Vec::new();
        let complete =
            |w: &Window| w.to_ns <= latest_sample_ns || w.to_ns + CLOSE_GRACE_NS <= now_ns;
        while self.open.front().is_some_and(complete) {
            if let Some(w) = self.open.pop_front() {
                done.push(self.finish(&w));
            }
        }
        done
    }

    fn finish(&self, w: &Window) -> BeatMeasurement {
        let plateau_len_ms = (w.plateau_to_ns - w.plateau_from_ns) as f64 * 1e-6;
        let expected = plateau_len_ms.floor().max(1.0);
        let coverage = (w.plateau_n as f64 / expected).min(1.0);
        let plateau_mean = (w.plateau_n > 0 && coverage >= self.settings.min_coverage)
            .then(|| w.plateau_sum / w.plateau_n as f64);
        let window_s = (w.to_ns - w.from_ns) as f64 * 1e-9;
        let fti = if w.n > 0 {
            w.sum / w.n as f64 * window_s
        } else {
            f64::NAN
        };
        BeatMeasurement {
            beat: w.beat,
            plateau_mean,
            peak: w.peak,
            fti,
            samples: w.n,
            plateau_coverage: coverage,
            pulses: w.pulses,
            pulses_refused: w.pulses_refused,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    fn beat(start_ms: u64) -> Beat {
        Beat {
            index: 0,
            start_ns: start_ms * MS,
            period_ns: 800 * MS,
            on_ns: 320 * MS,
            bpm: 75.0,
            target: 0.3,
            amplitude: 0.3,
        }
    }

    /// A force that is 0.3 exactly in the plateau window and 0 elsewhere gives a plateau
    /// mean of 0.3, and the FTI of the window is 0.3 x (plateau length) by the sum rule.
    #[test]
    fn plateau_mean_and_fti_of_a_known_signal() {
        let mut est = ContractionEstimator::new(ContractionSettings::default());
        est.begin(beat(1000));
        // Plateau window: [1000 + 160 + 7, 1000 + 320 + 7) = [1167, 1327) ms.
        for t in 1000..1900u64 {
            let f = if (1167..1327).contains(&t) { 0.3 } else { 0.0 };
            est.add_force(t * MS, f);
            if t % 25 == 0 && t < 1800 {
                est.add_pulse(t * MS);
            }
        }
        assert!(est.poll(1806 * MS, 1806 * MS).is_empty());
        let m = est.poll(1807 * MS, 1807 * MS);
        assert_eq!(m.len(), 1);
        let m = m[0];
        assert!((m.plateau_mean.unwrap() - 0.3).abs() < 1e-12);
        assert_eq!(m.samples, 800);
        assert!((m.fti - 0.3 * 0.160).abs() < 1e-12, "{}", m.fti);
        assert_eq!(m.peak, 0.3);
        assert_eq!(m.pulses, 32);
        assert_eq!(m.plateau_coverage, 1.0);
    }

    /// Too few plateau samples give no plateau mean (the outer loop then skips the beat);
    /// a window without any later sample closes after the grace time.
    #[test]
    fn sparse_samples_give_no_plateau_mean() {
        let mut est = ContractionEstimator::new(ContractionSettings::default());
        est.begin(beat(0));
        for t in (0..800u64).step_by(2) {
            est.add_force(t * MS, 0.2);
        }
        let m = est.poll(0, 807 * MS + CLOSE_GRACE_NS);
        assert_eq!(m.len(), 1);
        assert_eq!(m[0].plateau_mean, None);
        assert!((m[0].plateau_coverage - 0.5).abs() < 0.01);
    }

    /// A refusal reported between two driver statuses marks the beats whose window
    /// overlaps that interval, and only those: the one it fell in, and at a boundary both.
    #[test]
    fn refusals_mark_the_overlapping_beats() {
        let mut est = ContractionEstimator::new(ContractionSettings::default());
        for k in 0..3 {
            est.begin(beat(800 * k));
        }
        // Beat 0 is [0, 800) ms, beat 1 [800, 1600), beat 2 [1600, 2400).
        est.add_refused(100 * MS, 200 * MS, 1);
        est.add_refused(1550 * MS, 1650 * MS, 2);
        let m = est.poll(0, 2407 * MS + CLOSE_GRACE_NS);
        let refused: Vec<u64> = m.iter().map(|m| m.pulses_refused).collect();
        assert_eq!(refused, [1, 2, 2]);
        let mut est = ContractionEstimator::new(ContractionSettings::default());
        est.begin(beat(800));
        est.add_refused(700 * MS, 800 * MS, 1); // ends at the beat's start: overlaps
        est.add_refused(1600 * MS, 1700 * MS, 4); // starts at its end: does not
        let m = est.poll(0, 1607 * MS + CLOSE_GRACE_NS);
        assert_eq!(m[0].pulses_refused, 1);
    }
}
