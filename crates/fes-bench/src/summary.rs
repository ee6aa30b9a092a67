//! The figures of a stimulation run, computed from its recording (so any recording,
//! bench or rig, can be summarised again later): tracking error, pulses, contractions,
//! the 40 Hz baseline, deadline misses and latencies.
//!
//! Tracking error: the LCN regulates the force `d` samples ahead (docs/control.md), so
//! the force at tick k is compared with the reference of tick k - d:
//! `rms = sqrt(mean((y[k] - r[k-d])^2))` over the complete beats, for the model force
//! (StimTick `model_force`) and the measured force (the ForceSample nearest in time).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::baseline::Baseline;

/// A recording that cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum SummaryError {
    /// A file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// File.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// A line is malformed.
    #[error("{path}:{line}: {problem}")]
    Format {
        /// File.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// What is wrong.
        problem: String,
    },
}

/// Rows of a CSV file of numbers, by column name.
#[derive(Debug, Clone, Default)]
pub struct Table {
    /// Column names.
    pub columns: Vec<String>,
    /// Rows (empty fields are NaN).
    pub rows: Vec<Vec<f64>>,
}

impl Table {
    /// Reads a CSV of numbers with a header line.
    pub fn read(path: &Path) -> Result<Self, SummaryError> {
        let text = std::fs::read_to_string(path).map_err(|source| SummaryError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let mut lines = text.lines();
        let columns: Vec<String> = lines
            .next()
            .unwrap_or_default()
            .split(',')
            .map(str::to_string)
            .collect();
        let mut rows = Vec::new();
        for (i, l) in lines.enumerate() {
            if l.trim().is_empty() {
                continue;
            }
            let row: Result<Vec<f64>, _> = l
                .split(',')
                .map(|f| {
                    if f.is_empty() {
                        Ok(f64::NAN)
                    } else {
                        f.parse::<f64>()
                    }
                })
                .collect();
            let row = row.map_err(|e| SummaryError::Format {
                path: path.to_path_buf(),
                line: i + 2,
                problem: e.to_string(),
            })?;
            if row.len() != columns.len() {
                // A line cut by a crash: the rest of the file is not usable.
                break;
            }
            rows.push(row);
        }
        Ok(Self { columns, rows })
    }

    /// The column `name`.
    pub fn col(&self, name: &str) -> Vec<f64> {
        match self.columns.iter().position(|c| c == name) {
            Some(i) => self.rows.iter().map(|r| r[i]).collect(),
            None => Vec::new(),
        }
    }
}

/// Latency figures of one process (its last TimingReport).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Latency {
    /// Ticks counted.
    pub ticks: u64,
    /// Skipped periods.
    pub misses: u64,
    /// Wake-up lateness p50 / p99 / max, µs.
    pub wake_us: [f64; 3],
    /// Publish-to-receive latency p50 / p99 / max, µs.
    pub ipc_us: [f64; 3],
    /// Compute p99, µs.
    pub compute_p99_us: f64,
    /// Publish p99, µs (rt-core: the StimTick publish; stim-driver: StimTick publish to
    /// PULSE written on the bus).
    pub publish_p99_us: f64,
    /// The same, p50 / p99 / max, µs (NaN in recordings made before it was recorded).
    #[serde(default)]
    pub publish_us: [f64; 3],
}

/// The run's figures (the `--json` file; keys documented in docs/bench.md).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// Profile time analysed, s.
    pub duration_s: f64,
    /// Complete contractions (beats).
    pub contractions: u64,
    /// RMS of model force - reference (delayed by d), normalised.
    pub rms_error_model: f64,
    /// RMS of measured force - reference (delayed by d), normalised.
    pub rms_error_measured: f64,
    /// Pulses fired by rt-core over the complete beats.
    pub pulses: u64,
    /// `pulses / contractions`.
    pub pulses_per_contraction: f64,
    /// The 40 Hz train of equal FTI: pulses per contraction.
    pub baseline_pulses_per_contraction: f64,
    /// The 40 Hz train's RMS tracking error, normalised.
    pub baseline_rms_error: f64,
    /// Full 40 Hz baseline.
    pub baseline: Option<Baseline>,
    /// Mean FTI of a contraction (measured), normalised force x s.
    pub fti_per_contraction: f64,
    /// Target amplitude.
    pub target: f64,
    /// Mean plateau contraction over all beats, normalised.
    pub mean_contraction: f64,
    /// Mean plateau contraction of the first and the last 5 beats.
    pub first_last_contraction: [f64; 2],
    /// Largest deviation of a beat's plateau from the target after the first 10 beats,
    /// as a fraction of the target.
    pub worst_deviation_after_10: f64,
    /// The same over the beats that got every planned pulse (none refused by the driver):
    /// the controller's own figure, apart from the pulses the host's timing cost.
    #[serde(default)]
    pub worst_deviation_after_10_delivered: f64,
    /// Beats with a pulse refused by the driver (the outer loop skips them).
    #[serde(default)]
    pub beats_with_refused_pulses: u64,
    /// Pulses decided over the complete beats that the driver did not send: refused by its
    /// interlocks, or dropped as late by a busy transport (the beats' `pulses_refused`).
    #[serde(default)]
    pub pulses_not_sent: u64,
    /// PULSE frames the driver wrote over the whole run (DriverStatus `pulses_sent`,
    /// last), if known.
    pub pulses_sent: Option<u64>,
    /// Every pulse decided over the whole run, how many the driver sent and how many the
    /// stimulator applied (the recording's `pulses.csv`); none in-process or in a
    /// recording made before it.
    #[serde(default)]
    pub pulse_ledger: Option<PulseLedger>,
    /// Skipped periods of rt-core (its final TimingReport).
    pub deadline_misses: u64,
    /// rt-core wake-up lateness p99, µs.
    pub rt_wake_p99_us: f64,
    /// stim-driver forward latency (StimTick publish to PULSE written on the bus) p99, µs.
    pub driver_forward_p99_us: f64,
    /// rt-core figures.
    pub rt_core: Latency,
    /// stim-driver figures.
    pub stim_driver: Option<Latency>,
    /// Whether the timings were taken inside a UML guest (functional only).
    pub timing_functional_only: bool,
    /// The recording directory.
    pub recording: String,
    /// The verdict against the constant-frequency trains (keys `cft_front`, `lcn`,
    /// `reference_fti_per_contraction`, `lcn_dominated`, `pulses_vs_equal_rms_cft`,
    /// `ftipp_vs_best_cft`; docs/bench.md).
    #[serde(flatten, default)]
    pub front: Option<crate::cft::FrontVerdict>,
}

fn rms(pairs: impl Iterator<Item = (f64, f64)>) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for (a, b) in pairs {
        if a.is_finite() && b.is_finite() {
            s += (a - b).powi(2);
            n += 1;
        }
    }
    if n == 0 {
        f64::NAN
    } else {
        (s / n as f64).sqrt()
    }
}

/// Computes the 40 Hz baseline from a measured FTI per contraction and a beat (period ms,
/// on ms).
pub type BaselineFn = Box<dyn Fn(f64, usize, usize) -> Baseline>;

/// What the analysis needs besides the recording.
pub struct AnalysisInput {
    /// The constant-frequency-train front to judge the run against (`None`: not judged).
    pub front: Option<crate::cft::FrontSettings>,
    /// The model's delay, samples.
    pub delay: usize,
    /// The target amplitude.
    pub target: f64,
    /// Computes the 40 Hz baseline (see [`BaselineFn`]).
    pub baseline: Option<BaselineFn>,
    /// Timings from a UML guest.
    pub uml: bool,
}

/// The time series of a recording (for plots).
#[derive(Debug, Clone, Default)]
pub struct Series {
    /// Tick times, ns.
    pub t_ns: Vec<u64>,
    /// Reference per tick.
    pub reference: Vec<f64>,
    /// Model force per tick.
    pub model: Vec<f64>,
    /// Measured force nearest each tick (NaN when none within 1.5 ms).
    pub measured: Vec<f64>,
    /// Pulse per tick.
    pub pulse: Vec<bool>,
    /// Beats.
    pub beats: Vec<BeatRow>,
}

/// One line of `beats.csv`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BeatRow {
    /// Start, ns.
    pub start_ns: u64,
    /// Period, ns.
    pub period_ns: u64,
    /// Contraction, ns.
    pub on_ns: u64,
    /// Plateau mean (NaN when not measured).
    pub plateau: f64,
    /// Pulses in the beat.
    pub pulses: u64,
    /// FTI of the beat window.
    pub fti: f64,
    /// Pulses of the beat the driver refused (0 in recordings made before the column).
    pub pulses_refused: u64,
}

/// Reads the time series of the recording in `dir`.
pub fn read_series(dir: &Path) -> Result<Series, SummaryError> {
    let ticks = Table::read(&dir.join("ticks.csv"))?;
    let force = Table::read(&dir.join("force.csv"))?;
    let beats = Table::read(&dir.join("beats.csv"))?;
    let t_ns: Vec<u64> = ticks.col("t_ns").iter().map(|&x| x as u64).collect();
    let ft: Vec<u64> = force.col("t_ns").iter().map(|&x| x as u64).collect();
    let fv = force.col("force");
    // Nearest force sample to each tick (both sorted by time).
    let mut measured = Vec::with_capacity(t_ns.len());
    let mut j = 0usize;
    for &t in &t_ns {
        while j + 1 < ft.len() && ft[j + 1] <= t {
            j += 1;
        }
        let mut best = f64::NAN;
        let mut best_d = u64::MAX;
        for i in [j, j + 1] {
            if let (Some(&ti), Some(&fi)) = (ft.get(i), fv.get(i)) {
                let d = ti.abs_diff(t);
                if d < best_d && d <= 1_500_000 {
                    best_d = d;
                    best = fi;
                }
            }
        }
        measured.push(best);
    }
    let b: Vec<BeatRow> = {
        let (s, p, o, m, n, f) = (
            beats.col("start_ns"),
            beats.col("period_ns"),
            beats.col("on_ns"),
            beats.col("plateau_mean"),
            beats.col("pulses"),
            beats.col("fti"),
        );
        let refused = beats.col("pulses_refused");
        (0..s.len())
            .map(|i| BeatRow {
                start_ns: s[i] as u64,
                period_ns: p[i] as u64,
                on_ns: o[i] as u64,
                plateau: m[i],
                pulses: n[i] as u64,
                fti: f[i],
                pulses_refused: refused.get(i).map_or(0, |&x| x as u64),
            })
            .collect()
    };
    Ok(Series {
        t_ns,
        reference: ticks.col("reference"),
        model: ticks.col("model_force"),
        measured,
        pulse: ticks.col("pulse").iter().map(|&p| p == 1.0).collect(),
        beats: b,
    })
}

fn latency(row: &BTreeMap<&str, f64>) -> Latency {
    let us = |k: &str| row.get(k).copied().unwrap_or(f64::NAN) * 1e-3;
    Latency {
        ticks: row.get("ticks").copied().unwrap_or(0.0) as u64,
        misses: row.get("misses").copied().unwrap_or(0.0) as u64,
        wake_us: [us("wake_p50_ns"), us("wake_p99_ns"), us("wake_max_ns")],
        ipc_us: [us("ipc_p50_ns"), us("ipc_p99_ns"), us("ipc_max_ns")],
        compute_p99_us: us("compute_p99_ns"),
        publish_p99_us: us("publish_p99_ns"),
        publish_us: [
            us("publish_p50_ns"),
            us("publish_p99_ns"),
            us("publish_max_ns"),
        ],
    }
}

/// What a run's figures need besides its time series: the processes' timing and the
/// stimulator's pulse count (none for an in-process simulation).
#[derive(Debug, Clone, Default)]
pub struct RunTiming {
    /// rt-core's last TimingReport.
    pub rt_core: Latency,
    /// stim-driver's last TimingReport.
    pub stim_driver: Option<Latency>,
    /// DriverStatus `pulses_sent`, last.
    pub pulses_sent: Option<u64>,
    /// The recording's decided / sent / applied counts.
    pub ledger: Option<PulseLedger>,
}

/// Decided, sent and applied, counted over a recording's `pulses.csv` (one line per pulse
/// decided: `tick_seq,t_ns,decided,sent,applied,fate`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct PulseLedger {
    /// Pulses rt-core decided.
    pub decided: u64,
    /// Of those, pulses the driver wrote to the stimulator.
    pub sent: u64,
    /// Of those, pulses the stimulator accounted for as applied.
    pub applied: u64,
}

impl PulseLedger {
    /// Reads `pulses.csv`; `None` when the recording has none (made before it existed).
    pub fn read(path: &Path) -> Result<Option<Self>, SummaryError> {
        let text = match std::fs::read_to_string(path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(source) => {
                return Err(SummaryError::Io {
                    path: path.to_path_buf(),
                    source,
                });
            }
        };
        let mut lines = text.lines();
        let header: Vec<&str> = lines.next().unwrap_or_default().split(',').collect();
        let at = |name: &str| {
            header
                .iter()
                .position(|c| *c == name)
                .ok_or_else(|| SummaryError::Format {
                    path: path.to_path_buf(),
                    line: 1,
                    problem: format!("no column `{name}`"),
                })
        };
        let cols = [at("decided")?, at("sent")?, at("applied")?];
        let mut ledger = Self::default();
        for (i, l) in lines.enumerate() {
            let fields: Vec<&str> = l.split(',').collect();
            if fields.len() != header.len() {
                // A line cut by a crash: the rest of the file is not usable.
                break;
            }
            let mut bits = [0u64; 3];
            for (bit, &c) in bits.iter_mut().zip(&cols) {
                *bit = match fields[c] {
                    "0" => 0,
                    "1" => 1,
                    other => {
                        return Err(SummaryError::Format {
                            path: path.to_path_buf(),
                            line: i + 2,
                            problem: format!("`{other}` is not 0 or 1"),
                        });
                    }
                };
            }
            ledger.decided += bits[0];
            ledger.sent += bits[1];
            ledger.applied += bits[2];
        }
        Ok(Some(ledger))
    }
}

/// Summarises the recording in `dir`.
pub fn analyse(dir: &Path, input: &AnalysisInput) -> Result<Summary, SummaryError> {
    let s = read_series(dir)?;
    let timing = Table::read(&dir.join("timing.csv"))?;
    let status = Table::read(&dir.join("status.csv"))?;
    // The last report of each source.
    let mut last: BTreeMap<u8, BTreeMap<&str, f64>> = BTreeMap::new();
    for r in &timing.rows {
        let row: BTreeMap<&str, f64> = timing
            .columns
            .iter()
            .map(String::as_str)
            .zip(r.iter().copied())
            .collect();
        last.insert(row.get("source").copied().unwrap_or(0.0) as u8, row);
    }
    let timing = RunTiming {
        rt_core: last.get(&1).map(latency).unwrap_or_default(),
        stim_driver: last.get(&2).map(latency),
        pulses_sent: status.col("pulses_sent").last().map(|&x| x as u64),
        ledger: PulseLedger::read(&dir.join("pulses.csv"))?,
    };
    Ok(summarise(&s, input, timing, dir.display().to_string()))
}

/// The figures of a run from its time series (a recording's, or an in-process
/// simulation's) and its timing; `recording` names where the series came from.
pub fn summarise(
    s: &Series,
    input: &AnalysisInput,
    timing: RunTiming,
    recording: String,
) -> Summary {
    let RunTiming {
        rt_core: rt,
        stim_driver: drv,
        pulses_sent,
        ledger,
    } = timing;
    // Complete beats only.
    let (from, to) = match (s.beats.first(), s.beats.last()) {
        (Some(a), Some(b)) => (a.start_ns, b.start_ns + b.period_ns),
        _ => (0, 0),
    };
    let d = input.delay;
    let idx: Vec<usize> = (d..s.t_ns.len())
        .filter(|&k| s.t_ns[k] >= from && s.t_ns[k] < to)
        .collect();
    let rms_model = rms(idx.iter().map(|&k| (s.model[k], s.reference[k - d])));
    let rms_measured = rms(idx.iter().map(|&k| (s.measured[k], s.reference[k - d])));
    let pulses = idx.iter().filter(|&&k| s.pulse[k]).count() as u64;
    let n = s.beats.len() as u64;
    let plateaus: Vec<f64> = s
        .beats
        .iter()
        .map(|b| b.plateau)
        .filter(|x| x.is_finite())
        .collect();
    let mean = |v: &[f64]| {
        if v.is_empty() {
            f64::NAN
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        }
    };
    let ftis: Vec<f64> = s
        .beats
        .iter()
        .map(|b| b.fti)
        .filter(|x| x.is_finite())
        .collect();
    let fti = mean(&ftis);
    let (period_ms, on_ms) = s.beats.first().map_or((0, 0), |b| {
        (
            (b.period_ns / 1_000_000) as usize,
            (b.on_ns / 1_000_000) as usize,
        )
    });
    let baseline = match (&input.baseline, n > 0 && fti.is_finite()) {
        (Some(f), true) => Some(f(fti, period_ms, on_ms)),
        _ => None,
    };
    let deviation = |b: &&BeatRow| ((b.plateau - input.target) / input.target).abs();
    let measured_beats = || s.beats.iter().filter(|b| b.plateau.is_finite()).skip(10);
    let worst = measured_beats().map(|b| deviation(&b)).fold(0.0, f64::max);
    let worst_delivered = measured_beats()
        .filter(|b| b.pulses_refused == 0)
        .map(|b| deviation(&b))
        .fold(0.0, f64::max);
    let k5 = plateaus.len().min(5);
    Summary {
        duration_s: (to.saturating_sub(from)) as f64 * 1e-9,
        contractions: n,
        rms_error_model: rms_model,
        rms_error_measured: rms_measured,
        pulses,
        pulses_per_contraction: if n > 0 {
            pulses as f64 / n as f64
        } else {
            f64::NAN
        },
        baseline_pulses_per_contraction: baseline.map_or(f64::NAN, |b| b.pulses),
        baseline_rms_error: baseline.map_or(f64::NAN, |b| b.rms_error),
        baseline,
        fti_per_contraction: fti,
        target: input.target,
        mean_contraction: mean(&plateaus),
        first_last_contraction: [
            mean(&plateaus[..k5]),
            mean(&plateaus[plateaus.len() - k5..]),
        ],
        worst_deviation_after_10: worst,
        worst_deviation_after_10_delivered: worst_delivered,
        beats_with_refused_pulses: s.beats.iter().filter(|b| b.pulses_refused > 0).count() as u64,
        pulses_not_sent: s.beats.iter().map(|b| b.pulses_refused).sum(),
        pulses_sent,
        pulse_ledger: ledger,
        deadline_misses: rt.misses,
        rt_wake_p99_us: rt.wake_us[1],
        driver_forward_p99_us: drv.map_or(f64::NAN, |l| l.publish_us[1]),
        rt_core: rt,
        stim_driver: drv,
        timing_functional_only: input.uml,
        recording,
        front: input.front.as_ref().and_then(|f| f.verdict(s).ok()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    /// 14 beats at the target but beat 12 (a refused pulse: 50 %) and beat 13 (110 %): the
    /// overall worst is 50 %, the worst over beats that got every pulse 10 %, one beat
    /// with a refusal; the first 10 beats are not judged (beat 3 at 0 would be 100 %).
    #[test]
    fn worst_beat_is_reported_with_and_without_the_beats_with_a_refused_pulse() {
        let beat = |k: u64, plateau: f64, refused: u64| BeatRow {
            start_ns: k * 800 * MS,
            period_ns: 800 * MS,
            on_ns: 320 * MS,
            plateau,
            pulses: 8,
            fti: 0.1,
            pulses_refused: refused,
        };
        let beats: Vec<BeatRow> = (0..14)
            .map(|k| match k {
                3 => beat(k, 0.0, 0),
                12 => beat(k, 0.15, 1),
                13 => beat(k, 0.33, 0),
                _ => beat(k, 0.3, 0),
            })
            .collect();
        let series = Series {
            beats,
            ..Series::default()
        };
        let input = AnalysisInput {
            delay: 0,
            target: 0.3,
            baseline: None,
            uml: false,
            front: None,
        };
        let s = summarise(&series, &input, RunTiming::default(), String::new());
        assert!((s.worst_deviation_after_10 - 0.5).abs() < 1e-12);
        assert!((s.worst_deviation_after_10_delivered - 0.1).abs() < 1e-12);
        assert_eq!(s.beats_with_refused_pulses, 1);
    }
}
