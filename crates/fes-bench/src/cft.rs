//! The bench's verdict: the LCN's patterns against the front of constant-frequency trains
//! (CFTs) on the same muscle (docs/bench.md "The CFT front").
//!
//! For the bench's reference profile, every CFT(f, n) from `min_hz` to `max_hz` in 1 Hz
//! steps starts at each beat's onset with pulses at `onset + round(j 1000/f) ms` inside its
//! contraction window, and stops after `n` of them (`n` = 1 up to all that fit: a train
//! that simply stops is as easy for a clinician to set as one that fills the
//! contraction); it drives the same simulated muscle (same preset, same fatigue setting,
//! same force sensor and seed) over the same beats. Trains with the same pulses (low `n`
//! at neighbouring frequencies) are one point, named by the lowest frequency.
//! Each train, and the LCN's run, is scored by the same three numbers:
//!
//! - pulses per contraction;
//! - RMS tracking error: the measured (normalised) force against the *profile's*
//!   reference (its amplitude, with the ramped edges; not the outer loop's corrected
//!   one) delayed by the model's `d`, over the complete beats;
//! - FTIpP (eq. 6.3) of a contraction: its FTI (eq. 6.2, measured force over
//!   `[onset + d, onset + period + d)`) over `FTI_1 x pulses`, `FTI_1` the rested muscle's
//!   twitch over the same window.
//!
//! With a stimulation lead (`lead_ms`) the run stimulates a window `lead_ms` shorter than
//! the contraction it is judged against, and so do the trains (same window, same judge).
//!
//! The verdict: `beats_every_cft` when every train with no more pulses per contraction than
//! the run tracks strictly worse (a higher RMS error): the question a user asks of a
//! pattern generator ("is there a constant train, as easy to set, that does as well with no
//! more pulses?"), counting the run's mean per contraction as it is; and
//! `beats_every_cft_whole_count`, the same against every train with no more pulses than that
//! mean rounded to the nearest whole pulse: a user sees a plan of 2.97 pulses and a train
//! of 3 as the same count, so a plan that leaves out one pulse in a few dozen beats must
//! not rule out the trains of its own count; `beats_every_cft_holding_level`, the same
//! whole count among the trains whose contraction misses the level by no more than the
//! run's (the plateau mean the outer loop regulates): a train that tracks better by
//! stopping short of the level is not a pattern that does as well; `lcn_dominated` when
//! some CFT whose FTI per contraction is within 5 % of the reference's has no more pulses
//! and no larger RMS error than the LCN, one of them strictly less;
//! `pulses_vs_equal_rms_cft`, the LCN's pulses over those of the cheapest CFT that tracks
//! at least as well (none: `None`); `ftipp_vs_best_cft`, the LCN's FTIpP over the best of
//! the CFTs of equal FTI (within 5 %).

use serde::{Deserialize, Serialize};
use sim_muscle::muscle::{Muscle, MuscleConfig};
use sim_muscle::pattern::constant_train;
use sim_muscle::plant::{MusclePlant, Pulse};
use sim_muscle::sensor::{ForceSensor, SensorConfig};

use supervisor::contraction::ContractionSettings;

use crate::baseline::BeatShape;
use crate::summary::Series;

/// How close a CFT's FTI per contraction must be to the reference's to count as the same
/// contraction (fraction).
pub const EQUAL_FTI: f64 = 0.05;

/// Most beats [`FrontSettings`] simulates before it copies a settled beat (the slow
/// muscle's force settles to 1e-12 within a few beats of 800 ms).
pub const PERIODIC_BEATS: usize = 12;

/// One beat of a run, in samples from the run's first.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BeatWindow {
    /// First sample of the beat.
    pub start: usize,
    /// Beat period, samples.
    pub period: usize,
    /// Contraction, samples.
    pub on: usize,
}

/// The beats of a run's series (complete beats only), in tick indices. A recording that
/// skipped ticks has fewer than one tick per millisecond, so a beat's window is cut where
/// the next beat starts: no tick is counted in two beats.
pub fn beat_windows(series: &Series) -> Vec<BeatWindow> {
    let Some(&t0) = series.t_ns.first() else {
        return Vec::new();
    };
    let n = series.t_ns.len();
    let mut out: Vec<BeatWindow> = series
        .beats
        .iter()
        .filter(|b| b.start_ns >= t0)
        .map(|b| BeatWindow {
            start: series.t_ns.partition_point(|&t| t < b.start_ns),
            period: (b.period_ns / 1_000_000) as usize,
            on: (b.on_ns / 1_000_000) as usize,
        })
        .filter(|w| w.start < n)
        .collect();
    for i in 1..out.len() {
        let gap = out[i].start.saturating_sub(out[i - 1].start);
        out[i - 1].period = out[i - 1].period.min(gap);
    }
    out
}

/// The muscle and sensor the trains drive, and the profile they are judged against.
#[derive(Debug, Clone)]
pub struct FrontSettings {
    /// The muscle (preset, fatigue, delay), as in the run.
    pub muscle: MuscleConfig,
    /// The force sensor of the run, or the exact force.
    pub sensor: Option<SensorConfig>,
    /// Newtons per normalised force.
    pub scale_n: f64,
    /// Offset removed before normalising, N.
    pub offset_n: f64,
    /// The model's delay, samples.
    pub delay: usize,
    /// The profile's amplitude, normalised.
    pub amplitude: f64,
    /// The profile's edge rate, normalised force per second.
    pub edge_rate_per_s: f64,
    /// Lowest train frequency, Hz.
    pub min_hz: u32,
    /// Highest train frequency, Hz.
    pub max_hz: u32,
    /// Stimulation lead, ms: the contraction judged (the reference) lasts this much longer
    /// than the stimulated window the beats of the run give (`fes bench
    /// --stim-lead-ms`); the trains span the stimulated window, as the LCN's pulses do.
    pub lead_ms: usize,
}

/// One point of the front (or the LCN's).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FrontPoint {
    /// Train frequency, Hz (`None` for the LCN).
    pub hz: Option<u32>,
    /// Pulses of the train per contraction before it stops (`None` for the LCN).
    #[serde(default)]
    pub n: Option<u32>,
    /// Pulses per contraction.
    pub pulses_per_contraction: f64,
    /// RMS of the measured force against the profile's reference (delayed by d).
    pub rms_error: f64,
    /// FTI per pulse normalised by the twitch's (eq. 6.3), per contraction.
    pub ftipp: f64,
    /// FTI per contraction (eq. 6.2), normalised force x s.
    pub fti_per_contraction: f64,
    /// How far the contraction's level misses the profile's amplitude: the mean over the
    /// beats of |plateau mean - amplitude| / amplitude, the plateau being the window the
    /// outer loop regulates ([`supervisor::contraction`]). Summaries written before it: NaN.
    #[serde(default = "not_measured")]
    pub level_error: f64,
}

fn not_measured() -> f64 {
    f64::NAN
}

/// The verdict of a run against the CFT front (module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrontVerdict {
    /// The trains compared: every frequency of `min_hz..=max_hz`.
    #[serde(default = "default_hz_range")]
    pub hz_range: (u32, u32),
    /// Every train of the front, by frequency.
    pub cft_front: Vec<FrontPoint>,
    /// The LCN's point.
    pub lcn: FrontPoint,
    /// Every train with no more pulses per contraction than the LCN tracks worse (higher
    /// RMS error).
    pub beats_every_cft: bool,
    /// The train with the lowest RMS error among those with no more pulses per contraction
    /// than the LCN (`None`: no train has so few).
    pub best_cft_no_more_pulses: Option<FrontPoint>,
    /// Every train with no more pulses per contraction than the LCN's rounded to the
    /// nearest whole pulse tracks worse (module docs). Summaries written before it: false.
    #[serde(default)]
    pub beats_every_cft_whole_count: bool,
    /// The train with the lowest RMS error among those with no more pulses than the LCN's
    /// count rounded to the nearest whole pulse.
    #[serde(default)]
    pub best_cft_whole_count: Option<FrontPoint>,
    /// Every train with no more pulses than the LCN's whole count that misses the level by
    /// no more than the LCN ([`FrontPoint::level_error`]) tracks worse (module docs).
    /// Summaries written before it: false.
    #[serde(default)]
    pub beats_every_cft_holding_level: bool,
    /// The train with the lowest RMS error among those with no more pulses than the LCN's
    /// whole count and a level error no larger than the LCN's.
    #[serde(default)]
    pub best_cft_holding_level: Option<FrontPoint>,
    /// FTI of one beat of the profile's reference, normalised force x s.
    pub reference_fti_per_contraction: f64,
    /// Some CFT of equal FTI has pulses <= and RMS <= the LCN's, one strictly.
    pub lcn_dominated: bool,
    /// LCN pulses / pulses of the cheapest CFT whose RMS is at most the LCN's.
    pub pulses_vs_equal_rms_cft: Option<f64>,
    /// LCN FTIpP / the best FTIpP of the CFTs of equal FTI.
    pub ftipp_vs_best_cft: Option<f64>,
}

/// One pattern of [`FrontSettings::pattern_search`] and its score.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SearchedPattern {
    /// Pulse times from each onset, ms.
    pub offsets_ms: Vec<usize>,
    /// Its score (`hz` and `n` unset).
    pub point: FrontPoint,
}

/// The outcome of [`FrontSettings::pattern_search`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PatternSearch {
    /// Pulses per contraction of every pattern searched.
    pub pulses: usize,
    /// Grid of the pulse times, ms.
    pub grid_ms: usize,
    /// Patterns scored.
    pub patterns: usize,
    /// The lowest RMS error of them all.
    pub best: Option<SearchedPattern>,
    /// The lowest RMS error among those missing the level by no more than asked.
    pub best_holding_level: Option<SearchedPattern>,
}

/// Summaries written before the range was recorded compared 5-100 Hz.
fn default_hz_range() -> (u32, u32) {
    (5, 100)
}

impl FrontSettings {
    fn shape(&self, b: &BeatWindow) -> BeatShape {
        BeatShape {
            period_ms: b.period,
            on_ms: (b.on + self.lead_ms).min(b.period),
            amplitude: self.amplitude,
            edge_rate_per_s: self.edge_rate_per_s,
            delay: self.delay,
        }
    }

    /// The measured, normalised force of `pulse` on this muscle and sensor, sample k being
    /// the force after the pulses of samples < k (the in-process chain's alignment).
    pub fn measured(&self, pulse: &[bool]) -> Result<Vec<f64>, sim_muscle::ding::ParamError> {
        let mut muscle = Muscle::new(self.muscle)?;
        let mut sensor = match &self.sensor {
            Some(c) => Some(ForceSensor::new(*c, self.muscle.ts_s)?),
            None => None,
        };
        let mut read = |f: f64| match &mut sensor {
            Some(s) => (s.measure(f) - self.offset_n) / self.scale_n,
            None => (f - self.offset_n) / self.scale_n,
        };
        let mut out = Vec::with_capacity(pulse.len());
        let mut now = read(0.0);
        for &p in pulse {
            out.push(now);
            let f = muscle.step(p.then_some(Pulse::SUPRAMAXIMAL));
            now = read(f);
        }
        Ok(out)
    }

    /// The sensor's reading of zero force, sample by sample, less the offset removed, in
    /// newtons: what [`Self::measured`] adds to the muscle's force (the sensor is linear
    /// and its noise does not depend on the force). `None` when the sensor filters (then
    /// only the full simulation is exact).
    fn zero_reading(&self, n: usize) -> Result<Option<Vec<f64>>, sim_muscle::ding::ParamError> {
        match &self.sensor {
            Some(c) if c.lowpass_tau_s > 0.0 => Ok(None),
            Some(c) => {
                let mut s = ForceSensor::new(*c, self.muscle.ts_s)?;
                Ok(Some(
                    (0..n).map(|_| s.measure(0.0) - self.offset_n).collect(),
                ))
            }
            None => Ok(Some(vec![-self.offset_n; n])),
        }
    }

    /// [`Self::measured`] of a train that repeats the same pulses (`offsets` from each
    /// onset) in every beat, over `n` samples. A muscle without fatigue whose beats all
    /// have the same shape, one after the other, settles into the same force in every beat:
    /// at once when it forgets each beat before the next (the fast muscle), after a few
    /// beats when some force is left at each onset (the slow one, whose residue shrinks
    /// geometrically from beat to beat). So up to [`PERIODIC_BEATS`] beats are simulated,
    /// the first beat equal to the next (to 1e-12 of the force scale) found, and the rest
    /// copied from it. Anything else (fatigue, a filtering sensor, uneven beats, a force
    /// not settled by then) is simulated in full.
    fn train_measured(
        &self,
        beats: &[BeatWindow],
        n: usize,
        offsets: &[usize],
        zero: Option<&[f64]>,
    ) -> Result<Vec<f64>, sim_muscle::ding::ParamError> {
        let full = |s: &Self| s.measured(&pattern_pulses(beats, n, offsets));
        let Some(zero) = zero else {
            return full(self);
        };
        let Some(first) = beats.first() else {
            return full(self);
        };
        let p = first.period;
        let even = beats
            .iter()
            .enumerate()
            .all(|(i, b)| b.period == p && b.on == first.on && b.start == first.start + i * p);
        let s0 = first.start;
        let end = s0 + beats.len() * p;
        let sim = PERIODIC_BEATS.min(beats.len());
        if self.muscle.fatigue.is_some() || !even || sim < 3 || end > n {
            return full(self);
        }
        // Beat after beat until one repeats the beat before it (to 1e-12 of the force
        // scale), then the tail after the last beat from there: the state at the end of a
        // settled beat is the state at the end of every later one.
        let tol = 1e-12 * self.scale_n;
        let mut muscle = Muscle::new(self.muscle)?;
        let mut force = Vec::with_capacity(sim * p + n - end + 1);
        force.push(0.0);
        let mut settled = None;
        for beat in 0..sim {
            for j in 0..p {
                let fire = offsets.contains(&j);
                force.push(muscle.step(fire.then_some(Pulse::SUPRAMAXIMAL)));
            }
            if beat >= 2
                && (0..p).all(|j| (force[(beat - 1) * p + j] - force[beat * p + j]).abs() <= tol)
            {
                settled = Some(beat - 1);
                break;
            }
        }
        // m: the first beat whose force the next beat repeats.
        let Some(m) = settled else {
            return full(self);
        };
        for _ in end..n {
            force.push(muscle.step(None));
        }
        let tail_at = (m + 2) * p;
        // force[j]: the force j samples after the first onset (after j steps).
        let at = |k: usize| -> f64 {
            if k <= s0 {
                return 0.0;
            }
            let j = k - s0;
            if j <= m * p {
                force[j]
            } else if k < end {
                force[m * p + (j - m * p) % p]
            } else {
                force[tail_at + (k - end)]
            }
        };
        Ok((0..n).map(|k| (at(k) + zero[k]) / self.scale_n).collect())
    }

    /// The twitch FTI of the rested muscle (no fatigue, exact force) over a beat window.
    fn twitch_fti(&self, b: &BeatWindow) -> Result<f64, sim_muscle::ding::ParamError> {
        let mut cfg = self.muscle;
        cfg.fatigue = None;
        let exact = FrontSettings {
            muscle: cfg,
            sensor: None,
            offset_n: 0.0,
            ..self.clone()
        };
        let len = b.period + self.delay + 1;
        let mut train = vec![false; len];
        train[0] = true;
        let f = exact.measured(&train)?;
        Ok(f[self.delay..self.delay + b.period].iter().sum::<f64>() * 1e-3)
    }

    /// Scores one run (pulses and measured force over the same samples) on the beats.
    fn score(
        &self,
        hz: Option<u32>,
        beats: &[BeatWindow],
        pulse: &[bool],
        measured: &[f64],
        fti_1: f64,
    ) -> FrontPoint {
        let n = measured.len();
        let (mut pulses, mut sq, mut count, mut fti) = (0usize, 0.0, 0usize, 0.0);
        let (mut level_error, mut levels) = (0.0, 0usize);
        for b in beats {
            let shape = self.shape(b);
            let reference = shape.reference();
            pulses += (b.start..(b.start + b.period).min(n))
                .filter(|&k| pulse[k])
                .count();
            for (j, r) in reference.iter().enumerate() {
                let k = b.start + j + self.delay;
                if k < n && measured[k].is_finite() {
                    sq += (measured[k] - r).powi(2);
                    count += 1;
                    fti += measured[k] * 1e-3;
                }
            }
            if let Some(plateau) = self.plateau_mean(b, shape.on_ms, measured) {
                level_error += (plateau - self.amplitude).abs() / self.amplitude;
                levels += 1;
            }
        }
        let beats_n = beats.len().max(1) as f64;
        let ppc = pulses as f64 / beats_n;
        let fti_pc = fti / beats_n;
        FrontPoint {
            hz,
            n: None,
            pulses_per_contraction: ppc,
            rms_error: if count > 0 {
                (sq / count as f64).sqrt()
            } else {
                f64::NAN
            },
            ftipp: fti_pc / (fti_1 * ppc),
            fti_per_contraction: fti_pc,
            level_error: if levels > 0 {
                level_error / levels as f64
            } else {
                f64::NAN
            },
        }
    }

    /// The plateau mean of beat `b` whose contraction lasts `on` ms: the measured force
    /// over the outer loop's window, the contraction's second part shifted by the delay
    /// (`supervisor::contraction`, `plateau_start`), if every sample of it was measured.
    fn plateau_mean(&self, b: &BeatWindow, on: usize, measured: &[f64]) -> Option<f64> {
        let w = ContractionSettings::default().plateau_window(
            b.start as u64,
            on as u64,
            self.delay as u64,
        );
        let window = measured.get(w.start as usize..w.end as usize)?;
        (!window.is_empty() && window.iter().all(|f| f.is_finite()))
            .then(|| window.iter().sum::<f64>() / window.len() as f64)
    }

    /// The point of the pattern that fires at `offsets` (ms from each onset) in every beat.
    fn pattern_point(
        &self,
        beats: &[BeatWindow],
        n: usize,
        offsets: &[usize],
        zero: Option<&[f64]>,
        fti_1: f64,
    ) -> Result<FrontPoint, sim_muscle::ding::ParamError> {
        let measured = self.train_measured(beats, n, offsets, zero)?;
        let pulse = pattern_pulses(beats, n, offsets);
        Ok(self.score(None, beats, &pulse, &measured, fti_1))
    }

    /// Every pattern of `pulses` pulses per contraction on this muscle, the same in every
    /// beat of `run`: each pulse on a `grid_ms` grid inside the contraction (from its onset),
    /// at least `min_interval_ms` after the one before. The best by RMS, and the best of
    /// those missing the level by no more than `level_error` (the run's, to ask "does any
    /// pattern of this count track better and hold the level as closely?"). The trains are
    /// some of these patterns; this answers the question for every pattern, and so says
    /// how far a pattern generator of this count can go at all (docs/bench.md, "Planning").
    /// The work grows as the contraction's grid points to the power `pulses`: 1-3 pulses.
    /// `progress` hears (patterns scored, patterns in all) now and then.
    pub fn pattern_search(
        &self,
        run: &Series,
        pulses: usize,
        grid_ms: usize,
        min_interval_ms: usize,
        level_error: f64,
        progress: &mut dyn FnMut(usize, usize),
    ) -> Result<PatternSearch, sim_muscle::ding::ParamError> {
        let beats = beat_windows(run);
        let n = run.pulse.len();
        let mut out = PatternSearch {
            pulses,
            grid_ms,
            patterns: 0,
            best: None,
            best_holding_level: None,
        };
        let Some(first) = beats.first().filter(|_| pulses > 0) else {
            return Ok(out);
        };
        let fti_1 = self.twitch_fti(first)?;
        let zero = self.zero_reading(n)?;
        let (grid, gap) = (grid_ms.max(1), min_interval_ms.max(1));
        let mut total = 0usize;
        for_each_pattern(pulses, first.on, grid, gap, &mut |_| {
            total += 1;
            Ok::<(), sim_muscle::ding::ParamError>(())
        })?;
        for_each_pattern(pulses, first.on, grid, gap, &mut |offsets| {
            let point = self.pattern_point(&beats, n, offsets, zero.as_deref(), fti_1)?;
            out.patterns += 1;
            if out.patterns.is_multiple_of(256) || out.patterns == total {
                progress(out.patterns, total);
            }
            let better = |b: &Option<SearchedPattern>| {
                b.as_ref()
                    .is_none_or(|b| point.rms_error < b.point.rms_error)
            };
            let searched = || SearchedPattern {
                offsets_ms: offsets.to_vec(),
                point,
            };
            if better(&out.best) {
                out.best = Some(searched());
            }
            if point.level_error <= level_error && better(&out.best_holding_level) {
                out.best_holding_level = Some(searched());
            }
            Ok(())
        })?;
        Ok(out)
    }

    /// Every CFT(f, n) over `beats` (contraction `on` samples, `n` samples in all), scored;
    /// trains with the same pulses counted once, by their lowest frequency.
    fn front(
        &self,
        beats: &[BeatWindow],
        on: usize,
        n: usize,
        fti_1: f64,
    ) -> Result<Vec<FrontPoint>, sim_muscle::ding::ParamError> {
        let zero = self.zero_reading(n)?;
        let mut front: Vec<FrontPoint> = Vec::new();
        let mut seen: std::collections::HashSet<Vec<usize>> = std::collections::HashSet::new();
        for hz in self.min_hz..=self.max_hz {
            let times = constant_train(hz as f64, 0, on, 1e-3).unwrap_or_default();
            for k in 1..=times.len() {
                if !seen.insert(times[..k].to_vec()) {
                    continue;
                }
                let mut point =
                    self.pattern_point(beats, n, &times[..k], zero.as_deref(), fti_1)?;
                point.hz = Some(hz);
                point.n = Some(k as u32);
                front.push(point);
            }
        }
        Ok(front)
    }

    /// The CFT front and the verdict for a run: its beats, pulses and measured force.
    pub fn verdict(&self, run: &Series) -> Result<FrontVerdict, sim_muscle::ding::ParamError> {
        let beats = beat_windows(run);
        let n = run.pulse.len();
        let Some(first) = beats.first() else {
            return Ok(FrontVerdict {
                hz_range: (self.min_hz, self.max_hz),
                cft_front: Vec::new(),
                lcn: FrontPoint {
                    hz: None,
                    n: None,
                    pulses_per_contraction: f64::NAN,
                    rms_error: f64::NAN,
                    ftipp: f64::NAN,
                    fti_per_contraction: f64::NAN,
                    level_error: f64::NAN,
                },
                reference_fti_per_contraction: f64::NAN,
                beats_every_cft: false,
                best_cft_no_more_pulses: None,
                beats_every_cft_whole_count: false,
                best_cft_whole_count: None,
                beats_every_cft_holding_level: false,
                best_cft_holding_level: None,
                lcn_dominated: false,
                pulses_vs_equal_rms_cft: None,
                ftipp_vs_best_cft: None,
            });
        };
        let fti_1 = self.twitch_fti(first)?;
        let reference_fti = self.shape(first).reference().iter().sum::<f64>() * 1e-3;
        let lcn = self.score(None, &beats, &run.pulse, &run.measured, fti_1);
        let front = self.front(&beats, first.on, n, fti_1)?;
        let equal_fti = |p: &&FrontPoint| {
            (p.fti_per_contraction - reference_fti).abs() <= EQUAL_FTI * reference_fti
        };
        let lcn_dominated = front.iter().filter(equal_fti).any(|p| {
            p.pulses_per_contraction <= lcn.pulses_per_contraction
                && p.rms_error <= lcn.rms_error
                && (p.pulses_per_contraction < lcn.pulses_per_contraction
                    || p.rms_error < lcn.rms_error)
        });
        let cheapest = front
            .iter()
            .filter(|p| p.rms_error <= lcn.rms_error)
            .map(|p| p.pulses_per_contraction)
            .fold(f64::INFINITY, f64::min);
        let best_ftipp = front
            .iter()
            .filter(equal_fti)
            .map(|p| p.ftipp)
            .fold(f64::NEG_INFINITY, f64::max);
        // "No more pulses": a train's count against the run's mean per contraction, as it
        // is and rounded to the nearest whole pulse.
        let (best_cft_no_more_pulses, beats_every_cft) =
            beats_every_train_up_to(&front, &lcn, lcn.pulses_per_contraction);
        let whole = lcn.pulses_per_contraction.round();
        let (best_cft_whole_count, beats_every_cft_whole_count) =
            beats_every_train_up_to(&front, &lcn, whole);
        // The level as well: only the trains whose contraction is as close to the level.
        let holding: Vec<FrontPoint> = front
            .iter()
            .filter(|p| p.level_error <= lcn.level_error)
            .copied()
            .collect();
        let (best_cft_holding_level, beats_every_cft_holding_level) =
            beats_every_train_up_to(&holding, &lcn, whole);
        Ok(FrontVerdict {
            hz_range: (self.min_hz, self.max_hz),
            beats_every_cft,
            best_cft_no_more_pulses,
            beats_every_cft_whole_count,
            best_cft_whole_count,
            beats_every_cft_holding_level,
            best_cft_holding_level,
            pulses_vs_equal_rms_cft: cheapest
                .is_finite()
                .then(|| lcn.pulses_per_contraction / cheapest),
            ftipp_vs_best_cft: best_ftipp.is_finite().then(|| lcn.ftipp / best_ftipp),
            cft_front: front,
            lcn,
            reference_fti_per_contraction: reference_fti,
            lcn_dominated,
        })
    }
}

/// The pulses, sample by sample over `n` samples, of a pattern that fires at `offsets`
/// from each beat's onset.
fn pattern_pulses(beats: &[BeatWindow], n: usize, offsets: &[usize]) -> Vec<bool> {
    let mut pulse = vec![false; n];
    for b in beats {
        for &t in offsets {
            if b.start + t < n {
                pulse[b.start + t] = true;
            }
        }
    }
    pulse
}

/// Calls `f` with every pattern of `pulses` pulse times on a `grid` inside `0..on`, each at
/// least `gap` after the one before, in lexicographic order (an odometer over the grid).
fn for_each_pattern<E>(
    pulses: usize,
    on: usize,
    grid: usize,
    gap: usize,
    f: &mut dyn FnMut(&[usize]) -> Result<(), E>,
) -> Result<(), E> {
    if pulses == 0 {
        return Ok(());
    }
    let mut offsets: Vec<usize> = Vec::with_capacity(pulses);
    let mut next = vec![0usize; pulses];
    let mut i = 0;
    loop {
        if next[i] >= on {
            if i == 0 {
                return Ok(());
            }
            offsets.pop();
            i -= 1;
            next[i] += grid;
            continue;
        }
        offsets.push(next[i]);
        if i + 1 < pulses {
            next[i + 1] = (next[i] + gap).div_ceil(grid) * grid;
            i += 1;
            continue;
        }
        f(&offsets)?;
        offsets.pop();
        next[i] += grid;
    }
}

/// The best train of `front` with at most `pulses` per contraction, and whether the run
/// `lcn` tracks strictly better than every such train.
fn beats_every_train_up_to(
    front: &[FrontPoint],
    lcn: &FrontPoint,
    pulses: f64,
) -> (Option<FrontPoint>, bool) {
    let no_more = |p: &&FrontPoint| p.pulses_per_contraction <= pulses + 1e-9;
    let best = front
        .iter()
        .filter(no_more)
        .min_by(|a, b| a.rms_error.total_cmp(&b.rms_error))
        .copied();
    let beats = lcn.rms_error.is_finite()
        && front
            .iter()
            .filter(no_more)
            .all(|p| p.rms_error > lcn.rms_error);
    (best, beats)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::summary::BeatRow;
    use sim_muscle::preset::Preset;

    fn settings() -> FrontSettings {
        let muscle = MuscleConfig::preset(Preset::Fast);
        FrontSettings {
            muscle,
            sensor: None,
            scale_n: sim_muscle::muscle::max_force_n(&muscle.ding).unwrap(),
            offset_n: 0.0,
            delay: 7,
            amplitude: 0.3,
            edge_rate_per_s: 10.0,
            min_hz: 5,
            max_hz: 100,
            lead_ms: 0,
        }
    }

    /// A recording that skipped ticks (here 3 in the first beat): the first beat's window
    /// ends where the second starts, so no tick (and no pulse) counts in both.
    #[test]
    fn beat_windows_of_a_recording_with_skipped_ticks_do_not_overlap() {
        let ms = 1_000_000u64;
        let t_ns: Vec<u64> = (0..1600u64)
            .filter(|k| !(100..103).contains(k))
            .map(|k| 1_000 * ms + k * ms)
            .collect();
        let beat = |start: u64| BeatRow {
            start_ns: 1_000 * ms + start * ms,
            period_ns: 800 * ms,
            on_ns: 320 * ms,
            plateau: f64::NAN,
            pulses: 0,
            fti: 0.0,
            pulses_refused: 0,
        };
        let series = Series {
            t_ns,
            beats: vec![beat(0), beat(800)],
            ..Series::default()
        };
        let w = beat_windows(&series);
        assert_eq!(w.len(), 2);
        assert_eq!((w[0].start, w[1].start), (0, 797));
        assert_eq!(w[0].period, 797);
        assert_eq!(w[1].period, 800);
    }

    /// `beats` even beats of `period` ms from sample 3, contraction `on`, in `n` samples.
    fn even_beats(count: usize, period: usize, on: usize) -> (Vec<BeatWindow>, usize) {
        let beats = (0..count)
            .map(|i| BeatWindow {
                start: 3 + i * period,
                period,
                on,
            })
            .collect();
        (beats, 3 + count * period + 137)
    }

    /// The periodic shortcut gives the full simulation's measured force to 1e-9.
    fn assert_shortcut_is_full(s: &FrontSettings, beats: &[BeatWindow], n: usize, o: &[usize]) {
        let zero = s.zero_reading(n).unwrap();
        let mut pulse = vec![false; n];
        for b in beats {
            for &t in o {
                pulse[b.start + t] = true;
            }
        }
        let full = s.measured(&pulse).unwrap();
        let fast = s.train_measured(beats, n, o, zero.as_deref()).unwrap();
        assert_eq!(full.len(), fast.len());
        for (k, (a, b)) in full.iter().zip(&fast).enumerate() {
            assert!((a - b).abs() < 1e-9, "{o:?}: sample {k}: {a} vs {b}");
        }
    }

    /// The periodic shortcut of the front (beats simulated until one repeats the one
    /// before, the rest copied) gives the full simulation's measured force to 1e-9, with
    /// the run's noisy sensor, for a doublet-led train, a single pulse and a 100 Hz train,
    /// on the fast muscle (settled from the second beat) and on the slow one (which keeps
    /// force at each onset and settles a few beats later); with fatigue it falls back to
    /// the full simulation, exactly.
    #[test]
    fn the_periodic_front_is_the_full_simulation() {
        let mut s = settings();
        s.sensor = Some(SensorConfig::defaults_for(s.scale_n, 7));
        let (beats, n) = even_beats(6, 800, 320);
        let trains = [
            vec![0, 3, 40, 80, 120],
            vec![0],
            (0..32).map(|k| k * 10).collect::<Vec<usize>>(),
        ];
        for o in &trains {
            assert_shortcut_is_full(&s, &beats, n, o);
        }
        let mut slow = s.clone();
        slow.muscle = MuscleConfig::preset(Preset::Slow);
        let (slow_beats, slow_n) = even_beats(16, 800, 320);
        for o in &trains {
            assert_shortcut_is_full(&slow, &slow_beats, slow_n, o);
        }
        let mut tired = s.clone();
        tired.muscle.fatigue = Some(sim_muscle::ding::FatigueParams::for_muscle(
            &tired.muscle.ding,
        ));
        let offsets = [0usize, 25, 50];
        let mut pulse = vec![false; n];
        for b in &beats {
            for &t in &offsets {
                pulse[b.start + t] = true;
            }
        }
        let zero = tired.zero_reading(n).unwrap();
        assert_eq!(
            tired.measured(&pulse).unwrap(),
            tired
                .train_measured(&beats, n, &offsets, zero.as_deref())
                .unwrap()
        );
    }

    /// A run that *is* one of the CFTs (20 Hz over each contraction): its own point lies
    /// on the front, so it is not dominated by itself, and its pulse ratio against the
    /// cheapest train that tracks as well is at most 1.
    #[test]
    fn a_cft_run_scores_as_its_own_front_point() {
        check_own_point(0);
    }

    /// With a stimulation lead the run and the trains stimulate the shortened window and
    /// are judged against the whole contraction: the run's point is still its own train's,
    /// and the reference's FTI is the whole contraction's.
    #[test]
    fn with_a_lead_trains_span_the_stimulated_window_judged_on_the_whole() {
        check_own_point(30);
    }

    fn check_own_point(lead: usize) {
        let s = FrontSettings {
            lead_ms: lead,
            ..settings()
        };
        let on = 320usize - lead;
        let v = s.verdict(&train_run(&s, 20.0, on, 4, None)).unwrap();
        // Every CFT(f, n): the whole train of each frequency (one per Hz, 5..=100) and each
        // of its prefixes, a train that stops after n pulses, counted once per pulse set.
        let whole = |p: &&FrontPoint| {
            let hz = p.hz.unwrap() as f64;
            let count = constant_train(hz, 0, on, 1e-3).unwrap().len();
            p.n == Some(count as u32)
        };
        let trains: Vec<&FrontPoint> = v.cft_front.iter().filter(whole).collect();
        assert_eq!(trains.len(), 96);
        assert!(v.cft_front.len() > trains.len());
        assert!(
            v.cft_front
                .iter()
                .all(|p| (p.pulses_per_contraction - f64::from(p.n.unwrap())).abs() < 1e-9)
        );
        let own = trains.iter().find(|p| p.hz == Some(20)).unwrap();
        assert_eq!(own.pulses_per_contraction, v.lcn.pulses_per_contraction);
        assert_eq!(
            own.pulses_per_contraction,
            if lead == 0 { 7.0 } else { 6.0 }
        );
        assert!((own.rms_error - v.lcn.rms_error).abs() < 1e-12);
        assert!((own.ftipp - v.lcn.ftipp).abs() < 1e-12);
        // The run is itself a point of the front, so the cheapest train that tracks as well
        // needs at most its pulses, and the best train with no more pulses tracks at least
        // as well.
        let ratio = v.pulses_vs_equal_rms_cft.unwrap();
        assert!(ratio >= 1.0 - 1e-12, "{ratio}");
        let best = v.best_cft_no_more_pulses.unwrap();
        assert!(best.rms_error <= v.lcn.rms_error + 1e-12);
        assert!(!v.beats_every_cft);
        // Pulses grow with the frequency; the twitch normalisation makes FTIpP finite.
        assert!(
            trains
                .windows(2)
                .all(|w| { w[1].pulses_per_contraction >= w[0].pulses_per_contraction })
        );
        assert!(
            v.cft_front
                .iter()
                .all(|p| p.ftipp.is_finite() && p.ftipp > 0.0)
        );
        // The reference's FTI: 0.3 over (about) 320 ms, less the ramps.
        assert!((v.reference_fti_per_contraction - 0.3 * 0.32).abs() < 0.3 * 0.32 * 0.1);
    }

    /// A run of `beats` beats (800 ms) of the `hz` train over `on` ms, the muscle of `s`
    /// answering; `leave_out` = (beat, pulse) removes that pulse from that beat.
    fn train_run(
        s: &FrontSettings,
        hz: f64,
        on: usize,
        beats: usize,
        leave_out: Option<(usize, usize)>,
    ) -> Series {
        let period = 800usize;
        let n = period * beats + 100;
        let mut pulse = vec![false; n];
        for b in 0..beats {
            for (j, t) in constant_train(hz, 0, on, 1e-3)
                .unwrap()
                .into_iter()
                .enumerate()
            {
                pulse[b * period + t] = leave_out != Some((b, j));
            }
        }
        let measured = s.measured(&pulse).unwrap();
        Series {
            t_ns: (0..n as u64)
                .map(|k| 1_000_000_000 + k * 1_000_000)
                .collect(),
            reference: vec![0.0; n],
            model: vec![0.0; n],
            measured,
            pulse,
            beats: (0..beats as u64)
                .map(|b| BeatRow {
                    start_ns: 1_000_000_000 + b * period as u64 * 1_000_000,
                    period_ns: period as u64 * 1_000_000,
                    on_ns: on as u64 * 1_000_000,
                    plateau: f64::NAN,
                    pulses: 0,
                    fti: 0.0,
                    pulses_refused: 0,
                })
                .collect(),
        }
    }

    /// Every pattern of one and of two pulses: as many as the grid gives ((on - gap)(on -
    /// gap + 1) / 2 pairs), each train of that count among them with its own score, none
    /// better than the best; the best holding the level misses it by no more than asked;
    /// and a run of the best pattern scores as it.
    #[test]
    fn the_pattern_search_tries_every_pattern_and_keeps_the_best() {
        let s = settings();
        let on = 120;
        let run = train_run(&s, 20.0, on, 4, None);
        let v = s.verdict(&run).unwrap();
        for (k, gap) in [(1, 1), (2, 1), (2, 10)] {
            let r = s
                .pattern_search(&run, k, 1, gap, 0.05, &mut |_, _| {})
                .unwrap();
            let expected = if k == 1 {
                on
            } else {
                (on - gap) * (on - gap + 1) / 2
            };
            assert_eq!(r.patterns, expected, "{k} pulses, gap {gap}");
            let best = r.best.unwrap();
            assert_eq!(best.offsets_ms.len(), k);
            for p in v.cft_front.iter().filter(|p| p.n == Some(k as u32)) {
                assert!(
                    best.point.rms_error <= p.rms_error + 1e-15,
                    "{p:?} vs {best:?}"
                );
            }
            if let Some(held) = r.best_holding_level {
                assert!(held.point.level_error <= 0.05, "{held:?}");
                assert!(held.point.rms_error >= best.point.rms_error);
            }
            let any = s
                .pattern_search(&run, k, 1, gap, f64::INFINITY, &mut |_, _| {})
                .unwrap();
            assert_eq!(any.best_holding_level, any.best);
        }
        // The onset pulse is one of the single-pulse patterns, scored as the 5 Hz x 1 train.
        let one = s
            .pattern_search(&run, 1, 1, 1, f64::INFINITY, &mut |_, _| {})
            .unwrap();
        let onset = v
            .cft_front
            .iter()
            .find(|p| p.n == Some(1))
            .unwrap()
            .rms_error;
        let best = one.best.unwrap();
        assert!(best.point.rms_error <= onset);
        // A run firing the best pair in every beat scores as the search said.
        let pair = s
            .pattern_search(&run, 2, 1, 1, 0.0, &mut |_, _| {})
            .unwrap()
            .best
            .unwrap();
        let mut pulse = vec![false; run.pulse.len()];
        for b in beat_windows(&run) {
            for &t in &pair.offsets_ms {
                pulse[b.start + t] = true;
            }
        }
        let measured = s.measured(&pulse).unwrap();
        let own = s
            .verdict(&Series {
                pulse,
                measured,
                ..run.clone()
            })
            .unwrap()
            .lcn;
        assert!(
            (own.rms_error - pair.point.rms_error).abs() < 1e-12,
            "{own:?} vs {pair:?}"
        );
    }

    /// The 20 Hz train (7 pulses) with its onset pulse left out in one beat of eight: 6.875
    /// pulses per contraction, and that beat tracks worse than the whole train. Against
    /// its mean count no 7-pulse train is compared, so the whole 20 Hz train cannot beat
    /// it; at the count rounded to 7 it does, and the whole-count verdict says so.
    #[test]
    fn a_pulse_left_out_now_and_then_does_not_rule_out_the_trains_of_its_count() {
        let s = settings();
        let v = s
            .verdict(&train_run(&s, 20.0, 320, 8, Some((3, 0))))
            .unwrap();
        assert!((v.lcn.pulses_per_contraction - 6.875).abs() < 1e-9);
        let own = v
            .cft_front
            .iter()
            .find(|p| p.hz == Some(20) && p.n == Some(7))
            .unwrap();
        assert!(own.rms_error < v.lcn.rms_error, "{own:?} vs {:?}", v.lcn);
        let mean_best = v.best_cft_no_more_pulses.unwrap();
        assert!(mean_best.n.unwrap() <= 6, "{mean_best:?}");
        let best_up_to = |n: u32| {
            v.cft_front
                .iter()
                .filter(|p| p.n.unwrap() <= n)
                .min_by(|a, b| a.rms_error.total_cmp(&b.rms_error))
                .copied()
        };
        assert_eq!(Some(mean_best), best_up_to(6));
        let whole_best = v.best_cft_whole_count.unwrap();
        assert_eq!(Some(whole_best), best_up_to(7));
        assert_eq!(
            whole_best.n,
            Some(7),
            "a 7-pulse train is the best of the count"
        );
        assert!(!v.beats_every_cft_whole_count);
        // Holding the level: the best of the same count among the trains whose level
        // error is no larger than the run's.
        let holding = v
            .cft_front
            .iter()
            .filter(|p| p.n.unwrap() <= 7 && p.level_error <= v.lcn.level_error)
            .min_by(|a, b| a.rms_error.total_cmp(&b.rms_error))
            .copied();
        assert_eq!(v.best_cft_holding_level, holding);
        assert!(v.cft_front.iter().all(|p| p.level_error.is_finite()));
    }

    /// The level error is the plateau's relative miss over the outer loop's window (the
    /// contraction's second half, shifted by the delay): a force of 1.1 x the amplitude
    /// there and anything outside misses it by 10 %, one sample earlier counts too.
    #[test]
    fn the_level_error_is_the_plateaus_relative_miss() {
        let s = settings();
        let beats: Vec<BeatWindow> = (0..3)
            .map(|i| BeatWindow {
                start: i * 800,
                period: 800,
                on: 320,
            })
            .collect();
        let n = 3 * 800 + 50;
        let plateau = |b: &BeatWindow| (b.start + 160 + s.delay)..(b.start + 320 + s.delay);
        let mut measured = vec![5.0; n];
        for b in &beats {
            for k in plateau(b) {
                measured[k] = 1.1 * s.amplitude;
            }
        }
        let pulse = vec![false; n];
        let p = s.score(None, &beats, &pulse, &measured, 1.0);
        assert!((p.level_error - 0.1).abs() < 1e-12, "{}", p.level_error);
        // The sample before the window does not count; its first one does.
        measured[plateau(&beats[1]).start - 1] = 0.0;
        measured[plateau(&beats[1]).start] = 0.0;
        let p = s.score(None, &beats, &pulse, &measured, 1.0);
        let expected = (0.1 + (1.1 * 159.0 / 160.0 - 1.0) + 0.1) / 3.0;
        assert!(
            (p.level_error - expected).abs() < 1e-12,
            "{}",
            p.level_error
        );
    }
}
