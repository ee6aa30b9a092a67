//! The data-set format `fes-dataset/2`: records of any number of continuous-valued inputs
//! and outputs at any sample period, for plants other than muscle (the heat-transfer
//! process of thesis App. E: valve angle and heater voltage in, outlet temperature out).
//!
//! Version 2 generalises version 1 (one 0/1 pulse input, one force output) rather than
//! replacing it: `fes-dataset/1` keeps its own reader ([`crate::DataSet::read`]) and
//! files unchanged, [`read_any`] opens either version, and [`SignalSet::from_pulses`]
//! views a version-1 data set as signals (input `pulse` 0/1, output `force`).
//!
//! A data set is a directory holding `dataset.json` and one CSV file per record:
//!
//! ```json
//! {
//!   "schema": "fes-dataset/2",
//!   "source": "sim-heat 0.1.0",
//!   "seed": 1,
//!   "parameters": { "gain_k": 40.0 },
//!   "protocol": { "experiment": "E.2" },
//!   "ts_s": 0.05,
//!   "inputs": [ { "name": "alpha", "unit": "normalised", "range": [20.0, 120.0] } ],
//!   "outputs": [ { "name": "y", "unit": "normalised", "range": [20.0, 60.0] } ],
//!   "split": { "train": [0], "test": [1] },
//!   "records": [ { "file": "r1.csv", "kind": "fast-random", "samples": 1000 } ]
//! }
//! ```
//!
//! Each record file's header is `t_s` followed by the input names and then the output
//! names, in the order of `inputs` and `outputs`; times are finite, uniform steps of
//! `ts_s` from any start. Channel names are unique, non-empty and free of `,` and
//! whitespace. A channel's optional `range` records the physical values that the
//! normalised 0 and 1 stand for (E.2's normalisation); values themselves must only be
//! finite.
//!
//! Readers for other languages: `python/fes_io.py` (`read_dataset` gives a `SignalSet`)
//! and `matlab/load_fes_dataset.m`, both dispatching on `schema` and making the same
//! checks as this reader.

use std::fmt::Write as _;
use std::fs;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::{DataSet, FormatError, META_FILE, ReadError, Split, WriteError, WriteMode};

/// Value of the `schema` field of a signal data set.
pub const SCHEMA_V2: &str = "fes-dataset/2";

/// One input or output channel.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Channel {
    /// Column name in the record files.
    pub name: String,
    /// Unit of the stored values (e.g. `normalised`, `V`, `degC`).
    pub unit: String,
    /// The physical values the stored 0 and 1 stand for, if normalised.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub range: Option<[f64; 2]>,
}

impl Channel {
    /// A channel without a range.
    pub fn new(name: impl Into<String>, unit: impl Into<String>) -> Self {
        Self {
            name: name.into(),
            unit: unit.into(),
            range: None,
        }
    }

    /// The same channel with the range its normalised values map.
    pub fn with_range(mut self, lo: f64, hi: f64) -> Self {
        self.range = Some([lo, hi]);
        self
    }
}

/// Everything in `dataset.json` except the record list.
#[derive(Debug, Clone, PartialEq)]
pub struct SignalHeader {
    /// Who produced the data.
    pub source: String,
    /// Random seed, if simulated.
    pub seed: Option<u64>,
    /// Plant parameters by name, if simulated.
    pub parameters: std::collections::BTreeMap<String, f64>,
    /// Recording protocol (free-form; `null` if unknown).
    pub protocol: serde_json::Value,
    /// Sample period, s.
    pub ts_s: f64,
    /// The input channels.
    pub inputs: Vec<Channel>,
    /// The output channels.
    pub outputs: Vec<Channel>,
    /// Train / test split.
    pub split: Split,
}

/// One record: every channel sampled at the same times.
#[derive(Debug, Clone, PartialEq)]
pub struct SignalRecord {
    /// File name inside the data-set directory.
    pub file: String,
    /// What kind of experiment (free text).
    pub kind: String,
    /// Time of the first sample, s.
    pub t0_s: f64,
    /// Input values, one vector per input channel.
    pub inputs: Vec<Vec<f64>>,
    /// Output values, one vector per output channel.
    pub outputs: Vec<Vec<f64>>,
}

impl SignalRecord {
    /// Number of samples (of the first channel).
    pub fn len(&self) -> usize {
        self.inputs
            .first()
            .or(self.outputs.first())
            .map_or(0, Vec::len)
    }

    /// Whether the record has no samples.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// A whole signal data set in memory.
#[derive(Debug, Clone, PartialEq)]
pub struct SignalSet {
    /// Metadata.
    pub header: SignalHeader,
    /// Records, in order.
    pub records: Vec<SignalRecord>,
}

/// A data set of either version, as [`read_any`] found it.
#[derive(Debug, Clone, PartialEq)]
pub enum AnyDataSet {
    /// `fes-dataset/1`: pulses and force.
    Pulses(DataSet),
    /// `fes-dataset/2`: signals.
    Signals(SignalSet),
}

impl AnyDataSet {
    /// The data as signals (a version-1 set through [`SignalSet::from_pulses`]).
    pub fn into_signals(self) -> SignalSet {
        match self {
            Self::Pulses(ds) => SignalSet::from_pulses(&ds),
            Self::Signals(s) => s,
        }
    }
}

/// Reads the data set in `dir` whatever its version (the `schema` field decides).
pub fn read_any(dir: impl AsRef<Path>) -> Result<AnyDataSet, ReadError> {
    let dir = dir.as_ref();
    let meta_path = dir.join(META_FILE);
    if let Ok(bytes) = fs::read(&meta_path)
        && let Ok(v) = serde_json::from_slice::<serde_json::Value>(&bytes)
        && v.get("schema").and_then(|s| s.as_str()) == Some(SCHEMA_V2)
    {
        return SignalSet::read(dir).map(AnyDataSet::Signals);
    }
    DataSet::read(dir).map(AnyDataSet::Pulses)
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct MetaV2 {
    schema: String,
    source: String,
    #[serde(default)]
    seed: Option<u64>,
    #[serde(default)]
    parameters: std::collections::BTreeMap<String, f64>,
    #[serde(default)]
    protocol: serde_json::Value,
    ts_s: f64,
    inputs: Vec<Channel>,
    outputs: Vec<Channel>,
    split: Split,
    records: Vec<EntryV2>,
}

#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct EntryV2 {
    file: String,
    kind: String,
    samples: usize,
}

impl SignalSet {
    /// A version-1 data set as signals: input `pulse` (0/1), output `force` (normalised,
    /// range 0 N to `scale_n` + `offset_n`), the same period, records and split.
    pub fn from_pulses(ds: &DataSet) -> SignalSet {
        let h = &ds.header;
        SignalSet {
            header: SignalHeader {
                source: h.source.clone(),
                seed: h.seed,
                parameters: h.parameters.clone(),
                protocol: h.protocol.clone(),
                ts_s: h.ts_s,
                inputs: vec![Channel::new("pulse", "pulse")],
                outputs: vec![
                    Channel::new("force", "normalised")
                        .with_range(h.offset_n, h.offset_n + h.scale_n),
                ],
                split: h.split.clone(),
            },
            records: ds
                .records
                .iter()
                .map(|r| SignalRecord {
                    file: r.file.clone(),
                    kind: r.kind.clone(),
                    t0_s: r.t_ms.first().map_or(0.0, |t| t * 1e-3),
                    inputs: vec![r.pulse.iter().map(|&p| f64::from(u8::from(p))).collect()],
                    outputs: vec![r.force.clone()],
                })
                .collect(),
        }
    }

    /// The training records, in split order.
    pub fn train(&self) -> impl Iterator<Item = &SignalRecord> {
        self.header.split.train_of(&self.records)
    }

    /// The test records, in split order.
    pub fn test(&self) -> impl Iterator<Item = &SignalRecord> {
        self.header.split.test_of(&self.records)
    }

    /// Index of the input channel `name`.
    pub fn input_index(&self, name: &str) -> Option<usize> {
        self.header.inputs.iter().position(|c| c.name == name)
    }

    /// Checks the data set as [`SignalSet::read`] would (`dir` names the files in errors).
    pub fn validate(&self, dir: impl AsRef<Path>) -> Result<(), FormatError> {
        let meta_path = dir.as_ref().join(META_FILE);
        check_header(&meta_path, &self.header, self.records.len())?;
        crate::check_files(&meta_path, self.records.iter().map(|r| r.file.as_str()))?;
        let (ni, no) = (self.header.inputs.len(), self.header.outputs.len());
        for (i, r) in self.records.iter().enumerate() {
            let path = dir.as_ref().join(&r.file);
            let field = |problem: String| FormatError::Field {
                path: meta_path.clone(),
                field: format!("records[{i}]"),
                problem,
            };
            if r.inputs.len() != ni || r.outputs.len() != no {
                return Err(field(format!(
                    "{} input and {} output channel(s), the header names {ni} and {no}",
                    r.inputs.len(),
                    r.outputs.len()
                )));
            }
            let n = r.len();
            if r.inputs.iter().chain(&r.outputs).any(|c| c.len() != n) {
                return Err(field("channels differ in length".into()));
            }
            if n < 2 {
                return Err(FormatError::TooShort { path, samples: n });
            }
            if !r.t0_s.is_finite() {
                return Err(field(format!("start time {} is not finite", r.t0_s)));
            }
            for (c, name) in r
                .inputs
                .iter()
                .chain(&r.outputs)
                .zip(self.header.inputs.iter().chain(&self.header.outputs))
            {
                if let Some(k) = c.iter().position(|v| !v.is_finite()) {
                    return Err(FormatError::Value {
                        path: path.clone(),
                        line: k + 2,
                        field: "signal",
                        problem: format!("`{}` = {} is not finite", name.name, c[k]),
                    });
                }
            }
        }
        Ok(())
    }

    /// Reads and validates the signal data set in `dir`.
    pub fn read(dir: impl AsRef<Path>) -> Result<SignalSet, ReadError> {
        let dir = dir.as_ref();
        let (meta_path, bytes) = crate::read_meta(dir)?;
        let (text, schema) = crate::meta_schema(&meta_path, &bytes)?;
        match schema {
            Some(serde_json::Value::String(s)) if s == SCHEMA_V2 => {}
            other => {
                return Err(FormatError::Field {
                    path: meta_path.clone(),
                    field: "schema".into(),
                    problem: format!(
                        "{} is not \"{SCHEMA_V2}\"",
                        other.map_or("missing".into(), |v| v.to_string())
                    ),
                }
                .into());
            }
        }
        let meta: MetaV2 = serde_json::from_str(text).map_err(crate::json_error(&meta_path))?;
        let header = SignalHeader {
            source: meta.source,
            seed: meta.seed,
            parameters: meta.parameters,
            protocol: meta.protocol,
            ts_s: meta.ts_s,
            inputs: meta.inputs,
            outputs: meta.outputs,
            split: meta.split,
        };
        check_header(&meta_path, &header, meta.records.len())?;
        crate::check_files(&meta_path, meta.records.iter().map(|e| e.file.as_str()))?;
        let mut records = Vec::with_capacity(meta.records.len());
        for entry in meta.records {
            let path = dir.join(&entry.file);
            let bytes = crate::read_file(&path)?;
            let record = parse_csv(&path, &bytes, &header, entry.file, entry.kind)?;
            crate::check_listed(&path, "samples", record.len(), entry.samples)?;
            records.push(record);
        }
        let set = SignalSet { header, records };
        set.validate(dir)?;
        Ok(set)
    }

    /// Writes the data set into `dir` (created if needed), record files first and then
    /// `dataset.json`; as [`DataSet::write`] for an existing directory.
    pub fn write(&self, dir: impl AsRef<Path>, mode: WriteMode) -> Result<(), WriteError> {
        let dir = dir.as_ref();
        self.validate(dir)?;
        let h = &self.header;
        let meta = MetaV2 {
            schema: SCHEMA_V2.into(),
            source: h.source.clone(),
            seed: h.seed,
            parameters: h.parameters.clone(),
            protocol: h.protocol.clone(),
            ts_s: h.ts_s,
            inputs: h.inputs.clone(),
            outputs: h.outputs.clone(),
            split: h.split.clone(),
            records: self
                .records
                .iter()
                .map(|r| EntryV2 {
                    file: r.file.clone(),
                    kind: r.kind.clone(),
                    samples: r.len(),
                })
                .collect(),
        };
        let files = self.records.iter().map(|r| (&r.file, self.record_csv(r)));
        crate::write_files(dir, mode, files, &meta)
    }

    /// The header line of a record file.
    fn csv_header(&self) -> String {
        let names: Vec<&str> = std::iter::once("t_s")
            .chain(self.header.inputs.iter().map(|c| c.name.as_str()))
            .chain(self.header.outputs.iter().map(|c| c.name.as_str()))
            .collect();
        names.join(",")
    }

    /// A record's CSV text (shortest round-trip numbers).
    fn record_csv(&self, r: &SignalRecord) -> String {
        let mut s = self.csv_header();
        s.push('\n');
        for k in 0..r.len() {
            let _ = write!(s, "{}", r.t0_s + k as f64 * self.header.ts_s);
            for c in r.inputs.iter().chain(&r.outputs) {
                let _ = write!(s, ",{}", c[k]);
            }
            s.push('\n');
        }
        s
    }
}

/// Checks the header fields that do not depend on the record files.
fn check_header(path: &Path, h: &SignalHeader, n_records: usize) -> Result<(), FormatError> {
    let field = |field: String, problem: String| FormatError::Field {
        path: path.to_path_buf(),
        field,
        problem,
    };
    if !(h.ts_s.is_finite() && h.ts_s > 0.0) {
        return Err(field(
            "ts_s".into(),
            format!("{} is not a sample period > 0 s", h.ts_s),
        ));
    }
    if h.inputs.is_empty() || h.outputs.is_empty() {
        return Err(field(
            if h.inputs.is_empty() {
                "inputs"
            } else {
                "outputs"
            }
            .into(),
            "at least one channel is needed".into(),
        ));
    }
    let mut seen = std::collections::BTreeSet::new();
    seen.insert("t_s");
    for (which, list) in [("inputs", &h.inputs), ("outputs", &h.outputs)] {
        for (i, c) in list.iter().enumerate() {
            let bad_name = c.name.is_empty()
                || c.name.contains(',')
                || c.name.chars().any(char::is_whitespace);
            if bad_name {
                return Err(field(
                    format!("{which}[{i}].name"),
                    format!(
                        "`{}` is not a column name (non-empty, no `,` or spaces)",
                        c.name
                    ),
                ));
            }
            if !seen.insert(c.name.as_str()) {
                return Err(field(
                    format!("{which}[{i}].name"),
                    format!("`{}` repeats (or is `t_s`)", c.name),
                ));
            }
            if let Some([lo, hi]) = c.range
                && !(lo.is_finite() && hi.is_finite() && lo != hi)
            {
                return Err(field(
                    format!("{which}[{i}].range"),
                    format!("[{lo}, {hi}] is not a finite, non-empty range"),
                ));
            }
        }
    }
    for (name, v) in &h.parameters {
        if !v.is_finite() {
            return Err(field(
                format!("parameters.{name}"),
                format!("{v} is not finite"),
            ));
        }
    }
    crate::check_split(path, &h.split, n_records)
}

/// Parses one record file against the header's channels.
fn parse_csv(
    path: &Path,
    bytes: &[u8],
    h: &SignalHeader,
    file: String,
    kind: String,
) -> Result<SignalRecord, FormatError> {
    let text = crate::utf8(path, bytes)?;
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut lines = text
        .split('\n')
        .map(|l| l.strip_suffix('\r').unwrap_or(l))
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    let expected: Vec<&str> = std::iter::once("t_s")
        .chain(h.inputs.iter().map(|c| c.name.as_str()))
        .chain(h.outputs.iter().map(|c| c.name.as_str()))
        .collect();
    let found = lines.next().map_or("", |(_, l)| l);
    let names: Vec<&str> = found.split(',').map(str::trim).collect();
    if names != expected {
        return Err(FormatError::Field {
            path: path.to_path_buf(),
            field: "header".into(),
            problem: format!(
                "`{found}` does not name the channels of dataset.json: expected `{}`",
                expected.join(",")
            ),
        });
    }
    let (ni, no) = (h.inputs.len(), h.outputs.len());
    let mut inputs = vec![Vec::new(); ni];
    let mut outputs = vec![Vec::new(); no];
    let mut t0 = None;
    let mut previous: Option<f64> = None;
    for (i, l) in lines {
        let line = i + 1;
        let fields: Vec<&str> = l.split(',').map(str::trim).collect();
        if fields.len() != expected.len() {
            return Err(FormatError::Columns {
                path: path.to_path_buf(),
                line,
                found: fields.len(),
                expected: expected.len(),
            });
        }
        let mut values = Vec::with_capacity(fields.len());
        for f in &fields {
            let v: f64 = f.parse().map_err(|_| FormatError::Value {
                path: path.to_path_buf(),
                line,
                field: "signal",
                problem: format!("`{f}` is not a number"),
            })?;
            values.push(v);
        }
        let t = values[0];
        if !t.is_finite() {
            return Err(FormatError::Value {
                path: path.to_path_buf(),
                line,
                field: "t_s",
                problem: format!("{t} is not finite"),
            });
        }
        if let Some(p) = previous {
            let step = t - p;
            if (step - h.ts_s).abs() > crate::TIME_STEP_TOLERANCE * h.ts_s {
                return Err(FormatError::Value {
                    path: path.to_path_buf(),
                    line,
                    field: "t_s",
                    problem: format!("step {step} s differs from ts_s = {} s", h.ts_s),
                });
            }
        }
        previous = Some(t);
        t0.get_or_insert(t);
        for (c, v) in inputs.iter_mut().zip(&values[1..=ni]) {
            c.push(*v);
        }
        for (c, v) in outputs.iter_mut().zip(&values[1 + ni..]) {
            c.push(*v);
        }
    }
    Ok(SignalRecord {
        file,
        kind,
        t0_s: t0.unwrap_or(0.0),
        inputs,
        outputs,
    })
}
