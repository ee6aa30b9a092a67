//! Identification records: the training and test records of a data set as (u, y) at the
//! data set's sampling period (thesis 5.2, 5.3: 30 records train, the rest test; the split
//! comes from the data set's metadata).
//!
//! u is the pulse train (1.0 in the sample where a pulse fires, else 0.0, as the model
//! expects, docs/model.md convention 1), y the normalised force.

use fes_dataset::{DataSet, ReadError, Record};
use std::path::Path;

/// Why records could not be prepared for identification.
#[derive(Debug, thiserror::Error)]
pub enum RecordsError {
    /// The data set could not be read (missing directory, bad file...).
    #[error("data set: {0}")]
    Read(#[from] ReadError),
    /// The pulses delivered differ from the pulses decided.
    #[error(
        "{} pulse(s) were decided but not delivered and {} delivered but not decided \
         (the data set's `decided` column against its `pulse` column): a model fitted to it \
         would fit pulses the muscle did not receive; --allow-undelivered fits the delivered \
         pulses anyway and says so in the model's provenance",
        .0.decided_not_delivered,
        .0.delivered_not_decided
    )]
    Undelivered(Undelivered),
    /// Fewer records than identification needs.
    #[error("the data set has {found} {which} record(s); identification needs at least {needed}")]
    TooFew {
        /// `training` or `test`.
        which: &'static str,
        /// How many there are.
        found: usize,
        /// How many are needed.
        needed: usize,
    },
    /// A record contains a value that is not finite.
    #[error("record {record}: sample {sample}: {field} is {value}, not a finite number")]
    NonFinite {
        /// Record name.
        record: String,
        /// Sample index.
        sample: usize,
        /// `force` or `pulse`.
        field: &'static str,
        /// The value.
        value: f64,
    },
    /// The pulse input is not 0/1.
    #[error("record {record}: sample {sample}: pulse is {value}; pulses must be 0 or 1")]
    PulseValue {
        /// Record name.
        record: String,
        /// Sample index.
        sample: usize,
        /// The value.
        value: f64,
    },
    /// The pulse and force columns differ in length, or the record is too short.
    #[error("record {record}: {problem}")]
    Shape {
        /// Record name.
        record: String,
        /// What is wrong.
        problem: String,
    },
    /// The sampling period is unusable.
    #[error("sampling period {0} s must be finite and > 0")]
    SamplingPeriod(f64),
}

/// One record: pulse input and normalised force, both at the data set's period.
#[derive(Debug, Clone, PartialEq)]
pub struct IdentRecord {
    /// A name for messages (the record's file name).
    pub name: String,
    /// Pulse train u\[k\] in {0, 1}.
    pub u: Vec<f64>,
    /// Normalised force y\[k\].
    pub y: Vec<f64>,
}

impl IdentRecord {
    /// A validated record (finite values, pulses 0/1, equal lengths, at least 2 samples).
    pub fn new(name: impl Into<String>, u: Vec<f64>, y: Vec<f64>) -> Result<Self, RecordsError> {
        let name = name.into();
        if u.len() != y.len() {
            return Err(RecordsError::Shape {
                record: name,
                problem: format!("{} pulse samples but {} force samples", u.len(), y.len()),
            });
        }
        if u.len() < 2 {
            return Err(RecordsError::Shape {
                record: name,
                problem: format!("{} sample(s); a record needs at least 2", u.len()),
            });
        }
        for (k, (&uk, &yk)) in u.iter().zip(&y).enumerate() {
            for (field, v) in [("pulse", uk), ("force", yk)] {
                if !v.is_finite() {
                    return Err(RecordsError::NonFinite {
                        record: name,
                        sample: k,
                        field,
                        value: v,
                    });
                }
            }
            if uk != 0.0 && uk != 1.0 {
                return Err(RecordsError::PulseValue {
                    record: name,
                    sample: k,
                    value: uk,
                });
            }
        }
        Ok(Self { name, u, y })
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.y.len()
    }

    /// True when the record has no samples (never for a validated record).
    pub fn is_empty(&self) -> bool {
        self.y.is_empty()
    }

    fn from_dataset(r: &Record) -> Result<Self, RecordsError> {
        let u = r.pulse.iter().map(|&p| if p { 1.0 } else { 0.0 }).collect();
        Self::new(r.file.clone(), u, r.force.clone())
    }
}

/// Training and test records at the base sampling period `ts` (seconds).
#[derive(Debug, Clone, PartialEq)]
pub struct RecordSet {
    /// Where the records came from (the data-set directory), for provenance.
    pub source: String,
    /// Newtons per unit of normalised force (the data set's `scale_n`; 1 if unknown).
    pub force_scale_n: f64,
    /// Sampling period of the records (1 ms for the thesis protocol).
    pub ts: f64,
    /// Training records (each simulated from rest).
    pub train: Vec<IdentRecord>,
    /// Test records.
    pub test: Vec<IdentRecord>,
    /// Samples of the data set whose decision and delivery differ (a recording's `decided`
    /// column against its `pulse` column, [`DataSet::undelivered`]): identification uses the
    /// delivered pulses; a caller refuses the set unless told otherwise
    /// ([`RecordSet::check_deliveries`]).
    pub undelivered: Undelivered,
}

/// How many pulses of a data set were decided but not delivered, or delivered but not
/// decided.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct Undelivered {
    /// Decided by the pattern generator, not delivered (refused by the driver, not armed).
    pub decided_not_delivered: usize,
    /// Delivered without a decision (not expected: a foreign pulse).
    pub delivered_not_decided: usize,
}

impl Undelivered {
    /// No difference.
    pub fn is_none(&self) -> bool {
        *self == Self::default()
    }
}

impl RecordSet {
    /// A validated record set: `ts` finite and positive, at least one training and one test
    /// record.
    pub fn new(
        ts: f64,
        train: Vec<IdentRecord>,
        test: Vec<IdentRecord>,
    ) -> Result<Self, RecordsError> {
        if !(ts.is_finite() && ts > 0.0) {
            return Err(RecordsError::SamplingPeriod(ts));
        }
        for (which, list) in [("training", &train), ("test", &test)] {
            if list.is_empty() {
                return Err(RecordsError::TooFew {
                    which,
                    found: 0,
                    needed: 1,
                });
            }
        }
        Ok(Self {
            source: "(memory)".into(),
            force_scale_n: 1.0,
            ts,
            train,
            test,
            undelivered: Undelivered::default(),
        })
    }

    /// Refuses a set whose decisions and deliveries differ, unless `allow`: a model fitted
    /// to such data would be fitted to pulses the muscle never received (or did without
    /// a decision). Returns the differences (for the model's provenance when allowed).
    pub fn check_deliveries(&self, allow: bool) -> Result<Undelivered, RecordsError> {
        if self.undelivered.is_none() || allow {
            Ok(self.undelivered)
        } else {
            Err(RecordsError::Undelivered(self.undelivered))
        }
    }

    /// The records of a data set, split as its metadata says.
    pub fn from_dataset(ds: &DataSet) -> Result<Self, RecordsError> {
        let train = ds
            .train()
            .map(IdentRecord::from_dataset)
            .collect::<Result<Vec<_>, _>>()?;
        let test = ds
            .test()
            .map(IdentRecord::from_dataset)
            .collect::<Result<Vec<_>, _>>()?;
        let mut set = Self::new(ds.header.ts_s, train, test)?;
        set.force_scale_n = ds.header.scale_n;
        let (decided_not_delivered, delivered_not_decided) = ds.undelivered();
        set.undelivered = Undelivered {
            decided_not_delivered,
            delivered_not_decided,
        };
        Ok(set)
    }

    /// Reads and validates the data set in `dir` (format: `fes_dataset`).
    pub fn load(dir: impl AsRef<Path>) -> Result<Self, RecordsError> {
        let mut set = Self::from_dataset(&DataSet::read(dir.as_ref())?)?;
        set.source = dir.as_ref().display().to_string();
        Ok(set)
    }

    /// Total number of training samples.
    pub fn train_samples(&self) -> usize {
        self.train.iter().map(|r| r.len()).sum()
    }
}
