//! The recording protocol of thesis 5.1 (and a richer variant): which stimulation
//! pattern each record of a data set gets.
//!
//! Thesis protocol: supramaximal 200 us pulses, inter-pulse intervals drawn at random
//! from 1-70 ms, trains of at most 300 ms, records of 590 ms (fast) / 600 ms (slow),
//! 60 / 84 records, a constant 40 Hz check record every 5 minutes, 1 ms sampling, 30 s
//! rest between records. Decisions the thesis leaves open (documented in
//! `docs/sim-muscle.md`): each train starts `train_start_ms` (10 ms) into its record, so
//! every record has a rest baseline for offset removal; its length is drawn uniformly
//! from `train_min_ms..=train_max_ms` (100-300 ms) and pulses follow at uniformly drawn
//! whole-ms IPIs while they stay within that length; every `const_every`-th record
//! (10: 5 min of 30 s rests) is the constant-IPI check record, `train_max_ms` long.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::pattern::{PatternError, constant_train, from_samples};
use crate::preset::Preset;

/// ChaCha stream of the protocol's random draws (the sensor noise uses stream 0 of the
/// same seed), so patterns and noise are independent.
pub const PROTOCOL_STREAM: u64 = 1;

/// Most samples in one record (about 2.8 h at 1 ms).
pub const MAX_RECORD_SAMPLES: usize = 10_000_000;
/// Most samples in a data set.
pub const MAX_TOTAL_SAMPLES: usize = 50_000_000;

/// Which patterns the records get.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ProtocolKind {
    /// Thesis 5.1: random IPI trains plus the constant check record.
    Thesis,
    /// Beyond the thesis: records cycle through random trains, constant-frequency
    /// trains spread over `rich_min_hz..rich_max_hz`, and doublet-led constant trains, so
    /// the data cover the whole scheduling range (the thesis's random trains never push
    /// phi above about 0.8); the constant check record stays.
    Rich,
}

/// Every number of the protocol; defaults are the thesis's values (5.1, 5.2.1).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ProtocolConfig {
    /// Pattern family.
    pub kind: ProtocolKind,
    /// Number of records.
    pub records: usize,
    /// The first `train_records` records train, the rest test (thesis: 30).
    pub train_records: usize,
    /// Record length, ms.
    pub record_ms: u32,
    /// Sample period, ms.
    pub ts_ms: f64,
    /// Time of a record's first pulse, ms.
    pub train_start_ms: u32,
    /// Shortest train (first to last pulse at most this long), ms.
    pub train_min_ms: u32,
    /// Longest train, ms (thesis: 300).
    pub train_max_ms: u32,
    /// Shortest random IPI, ms (thesis: 1).
    pub ipi_min_ms: u32,
    /// Longest random IPI, ms (thesis: 70).
    pub ipi_max_ms: u32,
    /// Every `const_every`-th record is the constant check record; 0 = none.
    pub const_every: usize,
    /// IPI of the constant check record, ms (thesis: 25, i.e. 40 Hz).
    pub const_ipi_ms: u32,
    /// Rest before each record, s (thesis: 30).
    pub rest_s: f64,
    /// Rich protocol: lowest constant frequency, Hz.
    pub rich_min_hz: f64,
    /// Rich protocol: highest constant frequency, Hz.
    pub rich_max_hz: f64,
    /// Rich protocol: shortest doublet IPI, ms.
    pub doublet_min_ms: u32,
    /// Rich protocol: longest doublet IPI, ms.
    pub doublet_max_ms: u32,
}

/// Why a protocol was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProtocolError {
    /// A setting is out of range or inconsistent with another.
    #[error("protocol setting `{name}`: {problem}")]
    Invalid {
        /// The setting (as its command-line flag).
        name: &'static str,
        /// What is wrong.
        problem: String,
    },
    /// A pattern could not be built.
    #[error(transparent)]
    Pattern(#[from] PatternError),
}

/// One record's stimulation pattern.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordPlan {
    /// What kind of pattern (stored in the data set's record list).
    pub kind: String,
    /// Pulse at the start of each sample.
    pub pulses: Vec<bool>,
}

/// A refused setting, named as its flag.
fn bad(name: &'static str, problem: String) -> Result<(), ProtocolError> {
    Err(ProtocolError::Invalid { name, problem })
}

impl ProtocolConfig {
    /// The thesis protocol for `preset` (record length and count from 5.2.1).
    pub fn thesis(preset: Preset) -> Self {
        ProtocolConfig {
            kind: ProtocolKind::Thesis,
            records: preset.records(),
            train_records: 30,
            record_ms: preset.record_ms(),
            ts_ms: 1.0,
            train_start_ms: 10,
            train_min_ms: 100,
            train_max_ms: 300,
            ipi_min_ms: 1,
            ipi_max_ms: 70,
            const_every: 10,
            const_ipi_ms: 25,
            rest_s: 30.0,
            rich_min_hz: 5.0,
            rich_max_hz: 100.0,
            doublet_min_ms: 2,
            doublet_max_ms: 10,
        }
    }

    /// Samples per record.
    pub fn samples(&self) -> usize {
        self.ms_to_samples(self.record_ms)
    }

    fn ms_to_samples(&self, ms: u32) -> usize {
        (f64::from(ms) / self.ts_ms).round() as usize
    }

    /// Checks every setting and their consistency.
    pub fn validate(&self) -> Result<(), ProtocolError> {
        self.validate_records_and_trains()?;
        self.validate_size_and_checks()?;
        self.validate_rich()
    }

    /// The sample period, the records and their split, the IPI and train ranges.
    fn validate_records_and_trains(&self) -> Result<(), ProtocolError> {
        if !(self.ts_ms.is_finite() && self.ts_ms > 0.0) {
            return bad(
                "--ts-ms",
                format!("{} is not a sample period > 0 ms", self.ts_ms),
            );
        }
        if self.records < 2 {
            return bad(
                "--records",
                format!("{} records; at least 2 (train and test)", self.records),
            );
        }
        if self.train_records == 0 || self.train_records >= self.records {
            return bad(
                "--train-records",
                format!(
                    "{} of {} records; both the train and the test split must be non-empty",
                    self.train_records, self.records
                ),
            );
        }
        if self.ipi_min_ms == 0 {
            return bad("--ipi-min-ms", "must be >= 1 ms".into());
        }
        if self.ipi_min_ms > self.ipi_max_ms {
            return bad(
                "--ipi-min-ms",
                format!(
                    "IPI range inverted: min {} ms > max {} ms",
                    self.ipi_min_ms, self.ipi_max_ms
                ),
            );
        }
        if self.ts_ms > f64::from(self.ipi_min_ms) {
            return bad(
                "--ts-ms",
                format!(
                    "{} ms exceeds the shortest IPI {} ms (one pulse per sample at most)",
                    self.ts_ms, self.ipi_min_ms
                ),
            );
        }
        if self.train_min_ms > self.train_max_ms {
            return bad(
                "--train-min-ms",
                format!(
                    "train length range inverted: min {} ms > max {} ms",
                    self.train_min_ms, self.train_max_ms
                ),
            );
        }
        if self.train_start_ms.saturating_add(self.train_max_ms) >= self.record_ms {
            return bad(
                "--record-ms",
                format!(
                    "{} ms leaves no room: trains start at {} ms and last up to {} ms",
                    self.record_ms, self.train_start_ms, self.train_max_ms
                ),
            );
        }
        Ok(())
    }

    /// The memory the records take, the constant check train, the rest.
    fn validate_size_and_checks(&self) -> Result<(), ProtocolError> {
        let total = self.samples() as f64 * self.records as f64;
        if self.samples() > MAX_RECORD_SAMPLES || total > MAX_TOTAL_SAMPLES as f64 {
            return bad(
                "--record-ms",
                format!(
                    "{} records of {} samples is more than this tool holds in memory ({} per record, {} in all)",
                    self.records,
                    self.samples(),
                    MAX_RECORD_SAMPLES,
                    MAX_TOTAL_SAMPLES
                ),
            );
        }
        if self.const_every > 0
            && (self.const_ipi_ms == 0 || self.ts_ms > f64::from(self.const_ipi_ms))
        {
            return bad(
                "--const-ipi-ms",
                format!("{} ms is shorter than a sample", self.const_ipi_ms),
            );
        }
        if !(self.rest_s.is_finite() && self.rest_s >= 0.0) {
            return bad("--rest-s", format!("{} is not a rest >= 0 s", self.rest_s));
        }
        Ok(())
    }

    /// The rich protocol's frequency and doublet ranges.
    fn validate_rich(&self) -> Result<(), ProtocolError> {
        // The rich-protocol settings are checked even for the thesis protocol: they are
        // stored in the data set either way.
        let max_hz = 1e3 / self.ts_ms;
        if !(self.rich_min_hz.is_finite() && self.rich_min_hz > 0.0) {
            return bad(
                "--rich-min-hz",
                format!("{} is not a frequency > 0 Hz", self.rich_min_hz),
            );
        }
        if !(self.rich_max_hz.is_finite() && self.rich_max_hz <= max_hz) {
            return bad(
                "--rich-max-hz",
                format!(
                    "{} Hz is not a frequency up to one pulse per sample ({max_hz} Hz)",
                    self.rich_max_hz
                ),
            );
        }
        if self.rich_min_hz > self.rich_max_hz {
            return bad(
                "--rich-min-hz",
                format!(
                    "frequency range inverted: {} Hz > {} Hz",
                    self.rich_min_hz, self.rich_max_hz
                ),
            );
        }
        if self.doublet_min_ms == 0 || self.ts_ms > f64::from(self.doublet_min_ms) {
            return bad(
                "--doublet-min-ms",
                format!("{} ms is shorter than a sample", self.doublet_min_ms),
            );
        }
        if self.doublet_min_ms > self.doublet_max_ms {
            return bad(
                "--doublet-min-ms",
                format!(
                    "doublet IPI range inverted: {} ms > {} ms",
                    self.doublet_min_ms, self.doublet_max_ms
                ),
            );
        }
        Ok(())
    }

    /// Whether record `i` is the constant check record.
    pub fn is_check_record(&self, i: usize) -> bool {
        self.const_every > 0 && (i + 1).is_multiple_of(self.const_every)
    }

    /// The patterns of all records, drawn with `seed`.
    pub fn plan(&self, seed: u64) -> Result<Vec<RecordPlan>, ProtocolError> {
        self.validate()?;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(PROTOCOL_STREAM);
        let (mut constant_j, mut doublet_j) = (0usize, 0usize);
        let mut plans = Vec::with_capacity(self.records);
        for i in 0..self.records {
            let plan = if self.is_check_record(i) {
                self.check_record()?
            } else if self.kind == ProtocolKind::Rich && i % 3 == 1 {
                constant_j += 1;
                self.constant_record(
                    &mut rng,
                    spread(constant_j, self.rich_min_hz, self.rich_max_hz),
                )?
            } else if self.kind == ProtocolKind::Rich && i % 3 == 2 {
                doublet_j += 1;
                self.doublet_record(
                    &mut rng,
                    spread(doublet_j, self.rich_min_hz, self.rich_max_hz),
                )?
            } else {
                self.random_record(&mut rng)
            };
            plans.push(plan);
        }
        Ok(plans)
    }

    fn train_len(&self, rng: &mut ChaCha8Rng) -> u32 {
        rng.random_range(self.train_min_ms..=self.train_max_ms)
    }

    /// Thesis 5.1: IPIs drawn uniformly from `ipi_min_ms..=ipi_max_ms` (whole ms).
    fn random_record(&self, rng: &mut ChaCha8Rng) -> RecordPlan {
        let len = self.train_len(rng);
        let end = self.train_start_ms + len;
        let mut times = vec![self.train_start_ms];
        let mut t = self.train_start_ms;
        loop {
            t += rng.random_range(self.ipi_min_ms..=self.ipi_max_ms);
            if t > end {
                break;
            }
            times.push(t);
        }
        let samples: Vec<usize> = times.iter().map(|&t| self.ms_to_samples(t)).collect();
        RecordPlan {
            kind: "random".into(),
            pulses: from_samples(&samples, self.samples()),
        }
    }

    /// The constant check record: IPI `const_ipi_ms` over `train_max_ms`.
    fn check_record(&self) -> Result<RecordPlan, ProtocolError> {
        let hz = 1e3 / f64::from(self.const_ipi_ms);
        let samples = constant_train(
            hz,
            self.ms_to_samples(self.train_start_ms),
            self.ms_to_samples(self.train_max_ms) + 1,
            self.ts_ms * 1e-3,
        )?;
        Ok(RecordPlan {
            kind: format!("constant {hz} Hz"),
            pulses: from_samples(&samples, self.samples()),
        })
    }

    /// Rich: a constant-frequency train of random length.
    fn constant_record(&self, rng: &mut ChaCha8Rng, hz: f64) -> Result<RecordPlan, ProtocolError> {
        let len = self.ms_to_samples(self.train_len(rng)) + 1;
        let samples = constant_train(
            hz,
            self.ms_to_samples(self.train_start_ms),
            len,
            self.ts_ms * 1e-3,
        )?;
        Ok(RecordPlan {
            kind: format!("constant {hz:.1} Hz"),
            pulses: from_samples(&samples, self.samples()),
        })
    }

    /// Rich: a doublet (IPI drawn from `doublet_min_ms..=doublet_max_ms`) whose second
    /// pulse starts a constant-frequency train, all within a random train length.
    fn doublet_record(&self, rng: &mut ChaCha8Rng, hz: f64) -> Result<RecordPlan, ProtocolError> {
        let len = self.train_len(rng);
        let d = rng
            .random_range(self.doublet_min_ms..=self.doublet_max_ms)
            .min(len);
        let start = self.ms_to_samples(self.train_start_ms);
        let second = self.ms_to_samples(self.train_start_ms + d);
        let rest_len = self.ms_to_samples(self.train_start_ms + len) + 1 - second;
        let mut samples = vec![start];
        samples.extend(constant_train(hz, second, rest_len, self.ts_ms * 1e-3)?);
        Ok(RecordPlan {
            kind: format!("doublet {d} ms + {hz:.1} Hz"),
            pulses: from_samples(&samples, self.samples()),
        })
    }
}

/// The j-th frequency of a low-discrepancy sweep of `[lo, hi]`, uniform in log
/// frequency (golden-ratio sequence), so any run of records covers the band evenly.
pub fn spread(j: usize, lo: f64, hi: f64) -> f64 {
    const GOLDEN: f64 = 0.618_033_988_749_894_9;
    let u = (0.5 + j as f64 * GOLDEN).fract();
    lo * (hi / lo).powf(u)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The golden-ratio sweep stays in the band and fills it: 20 draws leave no gap wider
    /// than a fifth of the log band.
    #[test]
    fn spread_covers_band() {
        let mut u: Vec<f64> = (1..=20)
            .map(|j| (spread(j, 5.0, 100.0) / 5.0).ln() / 20f64.ln())
            .collect();
        assert!(u.iter().all(|&x| (0.0..1.0).contains(&x)));
        u.sort_by(f64::total_cmp);
        let gaps = u
            .windows(2)
            .map(|w| w[1] - w[0])
            .fold(u[0], f64::max)
            .max(1.0 - u[19]);
        assert!(gaps < 0.2, "largest gap {gaps}");
    }

    /// Inverted ranges and empty splits are refused, naming the flag.
    #[test]
    fn invalid_settings_name_the_flag() {
        let ok = ProtocolConfig::thesis(Preset::Fast);
        assert_eq!(ok.validate(), Ok(()));
        let cases: [(ProtocolConfig, &str); 5] = [
            (
                ProtocolConfig {
                    ipi_min_ms: 80,
                    ..ok
                },
                "--ipi-min-ms",
            ),
            (
                ProtocolConfig {
                    train_records: 60,
                    ..ok
                },
                "--train-records",
            ),
            (
                ProtocolConfig {
                    train_min_ms: 400,
                    ..ok
                },
                "--train-min-ms",
            ),
            (
                ProtocolConfig {
                    record_ms: 200,
                    ..ok
                },
                "--record-ms",
            ),
            (
                ProtocolConfig {
                    ts_ms: f64::NAN,
                    ..ok
                },
                "--ts-ms",
            ),
        ];
        for (cfg, flag) in cases {
            let err = cfg.validate().expect_err("invalid");
            assert!(err.to_string().contains(flag), "{err}");
        }
    }
}
