//! The on-disk data-set format `fes-dataset/1`: records of stimulation pulses and
//! normalised force, as the thesis's identification data (5.1, 5.2).
//!
//! A data set is a directory holding `dataset.json` (schema, origin, scaling, sample
//! period, train/test split and the record list) and one CSV file per record with the
//! header `t_ms,pulse,force`: time in ms (uniform steps of `ts_s`), pulse 0/1 (a pulse
//! fires at the start of that sample), force normalised (offset removed, divided by
//! `scale_n`). A recording of the stimulation chain adds a fourth column, `decided`: the
//! pattern generator's decision, while `pulse` is what the driver delivered to the
//! stimulator (the two differ where the driver refused a pulse or was not armed; a reader
//! without the column takes the pulses as the decisions). `docs/sim-muscle.md` documents
//! every field. Simulated and rig recordings
//! use the same format and the same validating reader, [`DataSet::read`]; every
//! violation is reported with the file, line and field. Tables recorded elsewhere (any
//! rate, columns, units and record layout) become data sets through [`import`]
//! (`fes dataset import`); several recordings of one muscle become one data set through
//! [`merge::merge`] (`fes dataset merge`).
//!
//! Plants other than muscle (several continuous-valued inputs and outputs, any sample
//! period: the heat-transfer process of App. E) use version 2, `fes-dataset/2`, in
//! [`signals`]; version-1 files and this reader are unchanged, and [`signals::read_any`]
//! opens either.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::fs;
use std::io;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

pub mod import;
pub mod merge;
pub mod signals;

/// Value of the `schema` field this module reads and writes.
pub const SCHEMA: &str = "fes-dataset/1";
/// Name of the metadata file inside a data-set directory.
pub const META_FILE: &str = "dataset.json";
/// The header line of every record file.
pub const CSV_HEADER: &str = "t_ms,pulse,force";
/// Column names of a record file, in order.
pub const COLUMNS: [&str; 3] = ["t_ms", "pulse", "force"];
/// The header of a record file with the decisions beside the delivered pulses.
pub const CSV_HEADER_DECIDED: &str = "t_ms,pulse,force,decided";
/// Column names of a record file with the decisions, in order.
pub const COLUMNS_DECIDED: [&str; 4] = ["t_ms", "pulse", "force", "decided"];
/// Normalised force must lie in `[-FORCE_SLACK, 1 + FORCE_SLACK]`: room for the noise
/// floor around the removed offset, while raw newtons are caught.
pub const FORCE_SLACK: f64 = 0.1;
/// Relative tolerance on each time step against `ts_s`.
pub const TIME_STEP_TOLERANCE: f64 = 1e-3;

/// Every way a data set can violate the format, naming the file and, for record files,
/// the line (1 = header) and field.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FormatError {
    /// A file is not UTF-8 text.
    #[error("{}:{line}: not UTF-8 text", path.display())]
    NotUtf8 {
        /// The file.
        path: PathBuf,
        /// Line of the first invalid byte.
        line: usize,
    },
    /// `dataset.json` is not valid JSON or lacks / mistypes a field.
    #[error("{}:{line}:{column}: {message}", path.display())]
    Json {
        /// The file.
        path: PathBuf,
        /// Line (1-based; 0 if unknown).
        line: usize,
        /// Column (1-based; 0 if unknown).
        column: usize,
        /// What serde_json reported.
        message: String,
    },
    /// The `schema` field is absent or not [`SCHEMA`].
    #[error("{}: field `schema` is {found}, expected \"{SCHEMA}\"", path.display())]
    Schema {
        /// The file.
        path: PathBuf,
        /// What was found (JSON text, or "missing").
        found: String,
    },
    /// A metadata field has an unusable value.
    #[error("{}: field `{field}`: {problem}", path.display())]
    Field {
        /// The file.
        path: PathBuf,
        /// The field (dotted path, e.g. `records[3].file`).
        field: String,
        /// What is wrong.
        problem: String,
    },
    /// Fewer than two records.
    #[error("{}: field `records`: {count} record(s); a data set needs at least 2 (train and test)", path.display())]
    TooFewRecords {
        /// The file.
        path: PathBuf,
        /// Number of records listed.
        count: usize,
    },
    /// The train or the test split is empty.
    #[error("{}: field `split.{which}`: the {which} split is empty", path.display())]
    EmptySplit {
        /// The file.
        path: PathBuf,
        /// `train` or `test`.
        which: &'static str,
    },
    /// The header line is not `t_ms,pulse,force` (or `t_ms,pulse,force,decided`).
    #[error("{}:1: header `{found}`: {problem}; expected `{CSV_HEADER}` (or `{CSV_HEADER_DECIDED}`)", path.display())]
    Header {
        /// The record file.
        path: PathBuf,
        /// The header found.
        found: String,
        /// Missing / extra / misordered columns.
        problem: String,
    },
    /// A data line has the wrong number of fields.
    #[error("{}:{line}: {found} field(s), expected {expected} (as the header)", path.display())]
    Columns {
        /// The record file.
        path: PathBuf,
        /// Line number.
        line: usize,
        /// Fields found.
        found: usize,
        /// Fields the header names.
        expected: usize,
    },
    /// A value is not a number, not finite, or out of its range.
    #[error("{}:{line}: field `{field}`: {problem}", path.display())]
    Value {
        /// The record file.
        path: PathBuf,
        /// Line number.
        line: usize,
        /// Column name.
        field: &'static str,
        /// What is wrong.
        problem: String,
    },
    /// A record has fewer than two samples.
    #[error("{}: {samples} sample(s); a record needs at least 2", path.display())]
    TooShort {
        /// The record file.
        path: PathBuf,
        /// Samples found.
        samples: usize,
    },
    /// The record file disagrees with its entry in `dataset.json`.
    #[error("{}: {what} is {found}, but dataset.json lists {listed}", path.display())]
    Mismatch {
        /// The record file.
        path: PathBuf,
        /// `samples` or `pulses`.
        what: &'static str,
        /// Counted in the file.
        found: usize,
        /// Listed in the metadata.
        listed: usize,
    },
}

/// An I/O error on one file or directory of a data set, reading or writing: one type, so
/// both directions name the path the same way.
#[derive(Debug, thiserror::Error)]
#[error("{}: {source}", path.display())]
pub struct FileError {
    /// The file or directory.
    pub path: PathBuf,
    /// The I/O error.
    pub source: io::Error,
}

impl FileError {
    /// Tags an I/O error on `path` (for `map_err`).
    fn at(path: &Path) -> impl FnOnce(io::Error) -> Self + use<> {
        let path = path.to_path_buf();
        move |source| Self { path, source }
    }
}

/// Why a data set could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The directory does not exist or is not a directory.
    #[error("data-set directory {} does not exist or is not a directory", path.display())]
    MissingDir {
        /// The path given.
        path: PathBuf,
    },
    /// A file could not be read (missing, permissions...).
    #[error(transparent)]
    Io(#[from] FileError),
    /// The content violates the format.
    #[error(transparent)]
    Format(#[from] FormatError),
}

/// Why a data set could not be written. Nothing is written when the data set is invalid
/// or the directory is in use.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    /// The directory exists and is not empty, and overwriting was not asked for.
    #[error("{} exists and is not empty; choose another directory or allow overwriting", path.display())]
    DirNotEmpty {
        /// The directory.
        path: PathBuf,
    },
    /// A file or directory could not be written.
    #[error(transparent)]
    Io(#[from] FileError),
    /// The data set violates the format.
    #[error(transparent)]
    Format(#[from] FormatError),
}

/// What [`DataSet::write`] does with an existing non-empty directory.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WriteMode {
    /// Refuse ([`WriteError::DirNotEmpty`]).
    CreateNew,
    /// Replace the data set there: its `dataset.json` and the record files it lists are
    /// removed first; other files are left alone.
    Overwrite,
}

impl WriteMode {
    /// The mode of a command's `--force` flag: [`WriteMode::Overwrite`] with it, else
    /// [`WriteMode::CreateNew`].
    pub fn from_force(force: bool) -> Self {
        if force {
            WriteMode::Overwrite
        } else {
            WriteMode::CreateNew
        }
    }
}

/// Which records identify the model and which test it (thesis 5.3: the first 30
/// records train). Indices into [`DataSet::records`].
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Split {
    /// Training records.
    pub train: Vec<usize>,
    /// Test records.
    pub test: Vec<usize>,
}

impl Split {
    /// The training records of `records`, in split order (indices past the end skipped).
    pub fn train_of<'a, T>(&'a self, records: &'a [T]) -> impl Iterator<Item = &'a T> {
        self.train.iter().filter_map(|&i| records.get(i))
    }

    /// The test records of `records`, in split order (indices past the end skipped).
    pub fn test_of<'a, T>(&'a self, records: &'a [T]) -> impl Iterator<Item = &'a T> {
        self.test.iter().filter_map(|&i| records.get(i))
    }

    /// The first `n_train` of `n` records train, the rest test.
    pub fn first(n_train: usize, n: usize) -> Split {
        Split {
            train: (0..n_train.min(n)).collect(),
            test: (n_train.min(n)..n).collect(),
        }
    }
}

/// Everything in `dataset.json` except the record list.
#[derive(Debug, Clone, PartialEq)]
pub struct Header {
    /// Who produced the data (e.g. `sim-muscle 0.1.0`, or a rig's name).
    pub source: String,
    /// Simulated muscle preset, if any.
    pub preset: Option<String>,
    /// Model parameters by name (SI units), if simulated.
    pub parameters: BTreeMap<String, f64>,
    /// Random seed, if simulated.
    pub seed: Option<u64>,
    /// Measurement settings (free-form object; `null` if unknown).
    pub noise: serde_json::Value,
    /// Recording protocol (free-form object; `null` if unknown).
    pub protocol: serde_json::Value,
    /// Newtons per unit of normalised force: `F_N = force scale_n + offset_n`.
    pub scale_n: f64,
    /// Offset removed from the measured force, N.
    pub offset_n: f64,
    /// Sample period, s.
    pub ts_s: f64,
    /// Train/test split.
    pub split: Split,
}

/// One record: a stimulation pattern and the normalised force it produced.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// File name inside the data-set directory (a plain name, no path).
    pub file: String,
    /// What kind of pattern (e.g. `random`, `constant 40 Hz`); free text.
    pub kind: String,
    /// Sample times, ms.
    pub t_ms: Vec<f64>,
    /// Pulse at the start of each sample.
    pub pulse: Vec<bool>,
    /// Normalised force at each sample time.
    pub force: Vec<f64>,
    /// The pattern generator's decision at each sample, when the record tells it apart
    /// from the delivered `pulse` (a recording of the stimulation chain); `None`: the
    /// pulses are the decisions (simulated data, imported data).
    pub decided: Option<Vec<bool>>,
}

impl Record {
    /// A record sampled every `ts_s` from t = 0.
    pub fn uniform(
        file: impl Into<String>,
        kind: impl Into<String>,
        ts_s: f64,
        pulse: Vec<bool>,
        force: Vec<f64>,
    ) -> Record {
        let ts_ms = ts_s * 1e3;
        let t_ms = (0..pulse.len()).map(|k| k as f64 * ts_ms).collect();
        Record {
            file: file.into(),
            kind: kind.into(),
            t_ms,
            pulse,
            force,
            decided: None,
        }
    }

    /// Samples where the decision and the delivery differ: (decided but not delivered,
    /// delivered but not decided). Both 0 without a `decided` column.
    pub fn undelivered(&self) -> (usize, usize) {
        let Some(decided) = &self.decided else {
            return (0, 0);
        };
        decided
            .iter()
            .zip(&self.pulse)
            .fold((0, 0), |(missed, extra), (&d, &p)| {
                (missed + usize::from(d && !p), extra + usize::from(p && !d))
            })
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.force.len()
    }

    /// Whether the record has no samples.
    pub fn is_empty(&self) -> bool {
        self.force.is_empty()
    }

    /// Number of pulses.
    pub fn pulses(&self) -> usize {
        self.pulse.iter().filter(|&&p| p).count()
    }
}

/// A whole data set in memory.
#[derive(Debug, Clone, PartialEq)]
pub struct DataSet {
    /// Metadata.
    pub header: Header,
    /// Records, in order.
    pub records: Vec<Record>,
}

/// `dataset.json` as stored.
#[derive(Debug, Serialize, Deserialize)]
struct MetaFile {
    schema: String,
    source: String,
    #[serde(default)]
    preset: Option<String>,
    #[serde(default)]
    parameters: BTreeMap<String, f64>,
    #[serde(default)]
    seed: Option<u64>,
    #[serde(default)]
    noise: serde_json::Value,
    #[serde(default)]
    protocol: serde_json::Value,
    scale_n: f64,
    offset_n: f64,
    ts_s: f64,
    split: Split,
    records: Vec<RecordEntry>,
}

/// One entry of the record list.
#[derive(Debug, Serialize, Deserialize)]
struct RecordEntry {
    file: String,
    kind: String,
    samples: usize,
    pulses: usize,
}

impl DataSet {
    /// Samples of the whole data set where the decision and the delivery differ: (decided
    /// but not delivered, delivered but not decided). Identification from such data would
    /// fit the model to pulses the muscle never received (docs/identification.md).
    pub fn undelivered(&self) -> (usize, usize) {
        self.records.iter().fold((0, 0), |(a, b), r| {
            let (x, y) = r.undelivered();
            (a + x, b + y)
        })
    }
}

impl DataSet {
    /// The training records, in split order.
    pub fn train(&self) -> impl Iterator<Item = &Record> {
        self.header.split.train_of(&self.records)
    }

    /// The test records, in split order.
    pub fn test(&self) -> impl Iterator<Item = &Record> {
        self.header.split.test_of(&self.records)
    }

    /// Reads and validates the data set in `dir`.
    pub fn read(dir: impl AsRef<Path>) -> Result<DataSet, ReadError> {
        let dir = dir.as_ref();
        let (meta_path, bytes) = read_meta(dir)?;
        let meta = parse_meta(&meta_path, &bytes)?;
        let header = Header {
            source: meta.source,
            preset: meta.preset,
            parameters: meta.parameters,
            seed: meta.seed,
            noise: meta.noise,
            protocol: meta.protocol,
            scale_n: meta.scale_n,
            offset_n: meta.offset_n,
            ts_s: meta.ts_s,
            split: meta.split,
        };
        check_header(&meta_path, &header, meta.records.len())?;
        check_files(&meta_path, meta.records.iter().map(|e| e.file.as_str()))?;
        let mut records = Vec::with_capacity(meta.records.len());
        for entry in meta.records {
            let path = dir.join(&entry.file);
            let bytes = read_file(&path)?;
            let cols = parse_record_csv(&path, &bytes, header.ts_s)?;
            let record = Record {
                file: entry.file,
                kind: entry.kind,
                t_ms: cols.t_ms,
                pulse: cols.pulse,
                force: cols.force,
                decided: cols.decided,
            };
            check_listed(&path, "samples", record.len(), entry.samples)?;
            check_listed(&path, "pulses", record.pulses(), entry.pulses)?;
            records.push(record);
        }
        Ok(DataSet { header, records })
    }

    /// Checks the data set as [`DataSet::read`] would check its files (`dir` only names
    /// the files in the errors).
    pub fn validate(&self, dir: impl AsRef<Path>) -> Result<(), FormatError> {
        let dir = dir.as_ref();
        let meta_path = dir.join(META_FILE);
        check_header(&meta_path, &self.header, self.records.len())?;
        check_files(&meta_path, self.records.iter().map(|r| r.file.as_str()))?;
        for r in &self.records {
            let path = dir.join(&r.file);
            let decided_len = r.decided.as_ref().map_or(r.force.len(), Vec::len);
            if r.pulse.len() != r.force.len()
                || r.t_ms.len() != r.force.len()
                || decided_len != r.force.len()
            {
                return Err(FormatError::Field {
                    path: meta_path.clone(),
                    field: format!("records[{}]", r.file),
                    problem: format!(
                        "columns differ in length: t_ms {}, pulse {}, force {}, decided {}",
                        r.t_ms.len(),
                        r.pulse.len(),
                        r.force.len(),
                        decided_len
                    ),
                });
            }
            let mut rows = RowChecker::new(&path, self.header.ts_s);
            for k in 0..r.len() {
                rows.check(k + 2, r.t_ms[k], r.force[k])?;
            }
            rows.finish()?;
        }
        Ok(())
    }

    /// Writes the data set into `dir` (created if needed): the record files first, then
    /// `dataset.json`, so an interrupted write leaves no readable half data set.
    pub fn write(&self, dir: impl AsRef<Path>, mode: WriteMode) -> Result<(), WriteError> {
        let dir = dir.as_ref();
        self.validate(dir)?;
        let meta = MetaFile {
            schema: SCHEMA.to_string(),
            source: self.header.source.clone(),
            preset: self.header.preset.clone(),
            parameters: self.header.parameters.clone(),
            seed: self.header.seed,
            noise: self.header.noise.clone(),
            protocol: self.header.protocol.clone(),
            scale_n: self.header.scale_n,
            offset_n: self.header.offset_n,
            ts_s: self.header.ts_s,
            split: self.header.split.clone(),
            records: self
                .records
                .iter()
                .map(|r| RecordEntry {
                    file: r.file.clone(),
                    kind: r.kind.clone(),
                    samples: r.len(),
                    pulses: r.pulses(),
                })
                .collect(),
        };
        let files = self.records.iter().map(|r| (&r.file, record_csv(r)));
        write_files(dir, mode, files, &meta)
    }
}

/// Writes a data set into `dir` ([`prepare_dir`]): the record files (name, text) first,
/// then `meta` as `dataset.json`, so an interrupted write leaves no readable half data set.
fn write_files<N: AsRef<Path>>(
    dir: &Path,
    mode: WriteMode,
    records: impl IntoIterator<Item = (N, String)>,
    meta: &impl Serialize,
) -> Result<(), WriteError> {
    prepare_dir(dir, mode)?;
    for (file, text) in records {
        let path = dir.join(file);
        fs::write(&path, text).map_err(FileError::at(&path))?;
    }
    let meta_path = dir.join(META_FILE);
    let mut text = serde_json::to_string_pretty(meta).map_err(|e| FormatError::Json {
        path: meta_path.clone(),
        line: 0,
        column: 0,
        message: e.to_string(),
    })?;
    text.push('\n');
    fs::write(&meta_path, text).map_err(FileError::at(&meta_path))?;
    Ok(())
}

/// The path and bytes of the `dataset.json` of the data set in `dir` (either version).
fn read_meta(dir: &Path) -> Result<(PathBuf, Vec<u8>), ReadError> {
    if !dir.is_dir() {
        return Err(ReadError::MissingDir {
            path: dir.to_path_buf(),
        });
    }
    let meta_path = dir.join(META_FILE);
    let bytes = read_file(&meta_path)?;
    Ok((meta_path, bytes))
}

/// The bytes of a data set's file.
fn read_file(path: &Path) -> Result<Vec<u8>, ReadError> {
    Ok(fs::read(path).map_err(FileError::at(path))?)
}

/// A record whose `what` (samples, pulses) differs from what `dataset.json` lists for it.
fn check_listed(
    path: &Path,
    what: &'static str,
    found: usize,
    listed: usize,
) -> Result<(), FormatError> {
    if found == listed {
        Ok(())
    } else {
        Err(FormatError::Mismatch {
            path: path.to_path_buf(),
            what,
            found,
            listed,
        })
    }
}

/// Makes `dir` ready for a data set: created if missing; if it is not empty, refused
/// ([`WriteMode::CreateNew`]) or the previous data set removed ([`WriteMode::Overwrite`]).
fn prepare_dir(dir: &Path, mode: WriteMode) -> Result<(), WriteError> {
    if dir.exists() {
        let mut entries = fs::read_dir(dir).map_err(FileError::at(dir))?;
        if entries.next().is_some() {
            match mode {
                WriteMode::CreateNew => {
                    return Err(WriteError::DirNotEmpty {
                        path: dir.to_path_buf(),
                    });
                }
                WriteMode::Overwrite => remove_previous(dir)?,
            }
        }
    } else {
        fs::create_dir_all(dir).map_err(FileError::at(dir))?;
    }
    Ok(())
}

/// Removes a previous data set's `dataset.json` and the record files it lists.
fn remove_previous(dir: &Path) -> Result<(), WriteError> {
    let meta_path = dir.join(META_FILE);
    let Ok(bytes) = fs::read(&meta_path) else {
        return Ok(());
    };
    #[derive(Deserialize)]
    struct Listed {
        #[serde(default)]
        records: Vec<ListedFile>,
    }
    #[derive(Deserialize)]
    struct ListedFile {
        file: String,
    }
    if let Ok(listed) = serde_json::from_slice::<Listed>(&bytes) {
        for f in listed.records {
            if is_plain_file_name(&f.file) {
                let path = dir.join(&f.file);
                if path.is_file() {
                    fs::remove_file(&path).map_err(FileError::at(&path))?;
                }
            }
        }
    }
    Ok(fs::remove_file(&meta_path).map_err(FileError::at(&meta_path))?)
}

/// The CSV text of a record. Numbers use Rust's shortest round-trip form, so reading
/// gives back exactly the values written.
fn record_csv(r: &Record) -> String {
    let mut s = String::with_capacity(26 * r.len() + 26);
    match &r.decided {
        None => {
            s.push_str(CSV_HEADER);
            s.push('\n');
            for k in 0..r.len() {
                let _ = writeln!(s, "{},{},{}", r.t_ms[k], u8::from(r.pulse[k]), r.force[k]);
            }
        }
        Some(decided) => {
            s.push_str(CSV_HEADER_DECIDED);
            s.push('\n');
            for (k, &d) in decided.iter().enumerate().take(r.len()) {
                let _ = writeln!(
                    s,
                    "{},{},{},{}",
                    r.t_ms[k],
                    u8::from(r.pulse[k]),
                    r.force[k],
                    u8::from(d)
                );
            }
        }
    }
    s
}

/// Line number (1-based) of byte `offset` in `bytes` (also the importer's).
pub(crate) fn line_of(bytes: &[u8], offset: usize) -> usize {
    1 + bytes[..offset.min(bytes.len())]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
}

/// Text of a file, or [`FormatError::NotUtf8`].
fn utf8<'a>(path: &Path, bytes: &'a [u8]) -> Result<&'a str, FormatError> {
    std::str::from_utf8(bytes).map_err(|e| FormatError::NotUtf8 {
        path: path.to_path_buf(),
        line: line_of(bytes, e.valid_up_to()),
    })
}

/// Parses `dataset.json`, checking the schema before anything else.
fn parse_meta(path: &Path, bytes: &[u8]) -> Result<MetaFile, FormatError> {
    let (text, schema) = meta_schema(path, bytes)?;
    match schema {
        Some(serde_json::Value::String(s)) if s == SCHEMA => {}
        Some(other) => {
            return Err(FormatError::Schema {
                path: path.to_path_buf(),
                found: other.to_string(),
            });
        }
        None => {
            return Err(FormatError::Schema {
                path: path.to_path_buf(),
                found: "missing".into(),
            });
        }
    }
    serde_json::from_str(text).map_err(json_error(path))
}

/// The text of a `dataset.json` (either version) and its `schema` field, which the
/// reader checks before anything else.
fn meta_schema<'b>(
    path: &Path,
    bytes: &'b [u8],
) -> Result<(&'b str, Option<serde_json::Value>), FormatError> {
    let text = utf8(path, bytes)?;
    let value: serde_json::Value = serde_json::from_str(text).map_err(json_error(path))?;
    Ok((text, value.get("schema").cloned()))
}

/// A JSON error in the file at `path`, with its line and column.
fn json_error(path: &Path) -> impl Fn(serde_json::Error) -> FormatError + '_ {
    |e| FormatError::Json {
        path: path.to_path_buf(),
        line: e.line(),
        column: e.column(),
        message: e.to_string(),
    }
}

/// Checks the metadata fields that do not depend on the record files.
fn check_header(path: &Path, h: &Header, n_records: usize) -> Result<(), FormatError> {
    let field = |field: &str, problem: String| FormatError::Field {
        path: path.to_path_buf(),
        field: field.to_string(),
        problem,
    };
    if !(h.ts_s.is_finite() && h.ts_s > 0.0) {
        return Err(field(
            "ts_s",
            format!("{} is not a sample period > 0 s", h.ts_s),
        ));
    }
    if !(h.scale_n.is_finite() && h.scale_n > 0.0) {
        return Err(field(
            "scale_n",
            format!("{} is not a scale > 0 N", h.scale_n),
        ));
    }
    if !h.offset_n.is_finite() {
        return Err(field("offset_n", format!("{} is not finite", h.offset_n)));
    }
    for (name, v) in &h.parameters {
        if !v.is_finite() {
            return Err(field(
                &format!("parameters.{name}"),
                format!("{v} is not finite"),
            ));
        }
    }
    check_split(path, &h.split, n_records)
}

/// At least two records, both halves of the split non-empty, in range, without repeats and
/// disjoint (shared by both format versions).
fn check_split(path: &Path, split: &Split, n_records: usize) -> Result<(), FormatError> {
    let field = |field: &str, problem: String| FormatError::Field {
        path: path.to_path_buf(),
        field: field.to_string(),
        problem,
    };
    if n_records < 2 {
        return Err(FormatError::TooFewRecords {
            path: path.to_path_buf(),
            count: n_records,
        });
    }
    for (which, list) in [("train", &split.train), ("test", &split.test)] {
        if list.is_empty() {
            return Err(FormatError::EmptySplit {
                path: path.to_path_buf(),
                which,
            });
        }
        let mut seen = BTreeSet::new();
        for &i in list.iter() {
            if i >= n_records {
                return Err(field(
                    &format!("split.{which}"),
                    format!("record index {i} is out of range (there are {n_records} records)"),
                ));
            }
            if !seen.insert(i) {
                return Err(field(
                    &format!("split.{which}"),
                    format!("record index {i} repeats"),
                ));
            }
        }
    }
    if let Some(i) = split.train.iter().find(|i| split.test.contains(i)) {
        return Err(field(
            "split",
            format!("record {i} is in both train and test"),
        ));
    }
    Ok(())
}

/// Whether `name` is a plain file name (no directory part, not `.`/`..`).
fn is_plain_file_name(name: &str) -> bool {
    !name.is_empty()
        && name != "."
        && name != ".."
        && name != META_FILE
        && !name.contains(['/', '\\', '\0'])
}

/// Checks that record file names are plain and unique.
fn check_files<'a>(path: &Path, files: impl Iterator<Item = &'a str>) -> Result<(), FormatError> {
    let mut seen = BTreeSet::new();
    for (i, f) in files.enumerate() {
        let problem = if !is_plain_file_name(f) {
            format!("`{f}` is not a plain file name inside the data-set directory")
        } else if !seen.insert(f) {
            format!("`{f}` is listed twice")
        } else {
            continue;
        };
        return Err(FormatError::Field {
            path: path.to_path_buf(),
            field: format!("records[{i}].file"),
            problem,
        });
    }
    Ok(())
}

/// The checks shared by the reader and [`DataSet::validate`] on each sample.
struct RowChecker<'a> {
    path: &'a Path,
    ts_ms: f64,
    previous_t: Option<f64>,
    samples: usize,
}

impl<'a> RowChecker<'a> {
    fn new(path: &'a Path, ts_s: f64) -> Self {
        Self {
            path,
            ts_ms: ts_s * 1e3,
            previous_t: None,
            samples: 0,
        }
    }

    fn value(&self, line: usize, field: &'static str, problem: String) -> FormatError {
        FormatError::Value {
            path: self.path.to_path_buf(),
            line,
            field,
            problem,
        }
    }

    /// Checks one sample's time and force (the pulse is checked while parsing).
    fn check(&mut self, line: usize, t: f64, force: f64) -> Result<(), FormatError> {
        if !t.is_finite() {
            return Err(self.value(line, "t_ms", format!("{t} is not finite")));
        }
        if t < 0.0 {
            return Err(self.value(line, "t_ms", format!("{t} is negative")));
        }
        if let Some(prev) = self.previous_t {
            if t <= prev {
                return Err(self.value(
                    line,
                    "t_ms",
                    format!("{t} does not increase (previous {prev})"),
                ));
            }
            let step = t - prev;
            if (step - self.ts_ms).abs() > TIME_STEP_TOLERANCE * self.ts_ms {
                return Err(self.value(
                    line,
                    "t_ms",
                    format!("step {step} ms differs from ts_s = {} ms", self.ts_ms),
                ));
            }
        }
        self.previous_t = Some(t);
        if !force.is_finite() {
            return Err(self.value(line, "force", format!("{force} is not finite")));
        }
        if !(-FORCE_SLACK..=1.0 + FORCE_SLACK).contains(&force) {
            return Err(self.value(
                line,
                "force",
                format!(
                    "{force} is outside [{}, {}]: force must be normalised (offset removed, divided by scale_n)",
                    -FORCE_SLACK,
                    1.0 + FORCE_SLACK
                ),
            ));
        }
        self.samples += 1;
        Ok(())
    }

    fn finish(&self) -> Result<(), FormatError> {
        if self.samples < 2 {
            return Err(FormatError::TooShort {
                path: self.path.to_path_buf(),
                samples: self.samples,
            });
        }
        Ok(())
    }
}

/// Columns of a parsed record file.
#[derive(Debug, Clone, PartialEq)]
pub struct Columns {
    /// `t_ms`.
    pub t_ms: Vec<f64>,
    /// `pulse`: what was delivered.
    pub pulse: Vec<bool>,
    /// `force`.
    pub force: Vec<f64>,
    /// `decided`, when the file has the column.
    pub decided: Option<Vec<bool>>,
}

/// Parses and checks the content of one record file (`path` names it in errors; the
/// file is not opened). [`DataSet::read`] uses it for every record.
pub fn parse_record_csv(path: &Path, bytes: &[u8], ts_s: f64) -> Result<Columns, FormatError> {
    let text = utf8(path, bytes)?;
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut lines: Vec<&str> = text
        .split('\n')
        .map(|l| l.strip_suffix('\r').unwrap_or(l))
        .collect();
    while lines.last().is_some_and(|l| l.trim().is_empty()) {
        lines.pop();
    }
    let Some(header) = lines.first() else {
        return Err(FormatError::Header {
            path: path.to_path_buf(),
            found: String::new(),
            problem: "the file is empty".into(),
        });
    };
    let with_decided = check_csv_header(path, header)?;
    let width = if with_decided { 4 } else { 3 };
    let mut rows = RowChecker::new(path, ts_s);
    let n = lines.len() - 1;
    let (mut t_ms, mut pulse, mut force) = (
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
    );
    let mut decided = with_decided.then(|| Vec::with_capacity(n));
    for (i, l) in lines.iter().enumerate().skip(1) {
        let line = i + 1;
        let fields: Vec<&str> = l.split(',').map(str::trim).collect();
        if fields.len() != width {
            return Err(FormatError::Columns {
                path: path.to_path_buf(),
                line,
                found: if l.trim().is_empty() { 0 } else { fields.len() },
                expected: width,
            });
        }
        let number = |k: usize| -> Result<f64, FormatError> {
            fields[k].parse::<f64>().map_err(|_| FormatError::Value {
                path: path.to_path_buf(),
                line,
                field: COLUMNS[k],
                problem: format!("`{}` is not a number", fields[k]),
            })
        };
        let bit = |k: usize, field: &'static str| -> Result<bool, FormatError> {
            match fields[k] {
                "1" => Ok(true),
                "0" => Ok(false),
                _ => match number(k)? {
                    1.0 => Ok(true),
                    0.0 => Ok(false),
                    _ => Err(rows.value(line, field, format!("`{}` is not 0 or 1", fields[k]))),
                },
            }
        };
        let t = number(0)?;
        let fired = bit(1, "pulse")?;
        let f = number(2)?;
        if let Some(decided) = decided.as_mut() {
            decided.push(bit(3, "decided")?);
        }
        rows.check(line, t, f)?;
        t_ms.push(t);
        pulse.push(fired);
        force.push(f);
    }
    rows.finish()?;
    Ok(Columns {
        t_ms,
        pulse,
        force,
        decided,
    })
}

/// Checks the header line, naming missing, extra or misordered columns. Returns whether
/// the file has the `decided` column.
fn check_csv_header(path: &Path, header: &str) -> Result<bool, FormatError> {
    let found: Vec<&str> = header.split(',').map(str::trim).collect();
    if found == COLUMNS {
        return Ok(false);
    }
    if found == COLUMNS_DECIDED {
        return Ok(true);
    }
    let missing: Vec<&str> = COLUMNS
        .iter()
        .copied()
        .filter(|c| !found.contains(c))
        .collect();
    let extra: Vec<&str> = found
        .iter()
        .copied()
        .filter(|c| !COLUMNS_DECIDED.contains(c))
        .collect();
    let mut problems = Vec::new();
    if !missing.is_empty() {
        let names: Vec<String> = missing.iter().map(|c| format!("`{c}`")).collect();
        problems.push(format!("missing column(s) {}", names.join(", ")));
    }
    if !extra.is_empty() {
        let names: Vec<String> = extra.iter().map(|c| format!("`{c}`")).collect();
        problems.push(format!("extra column(s) {}", names.join(", ")));
    }
    if problems.is_empty() {
        problems.push("columns repeated or out of order".into());
    }
    Err(FormatError::Header {
        path: path.to_path_buf(),
        found: header.to_string(),
        problem: problems.join("; "),
    })
}
