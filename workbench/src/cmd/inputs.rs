//! What the analysis commands share: opening a model (unstable ones too, said loudly), a
//! data set as model inputs, the output directory, CSV/Markdown writing and a progress bar.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use fes_dataset::DataSet;
use fes_model::model::file;
use fes_model::model::lmn::{Lmn, UnitStability};
use indicatif::{ProgressBar, ProgressStyle};

/// A model opened for analysis, with its per-unit stability.
pub struct OpenedModel {
    /// The model.
    pub lmn: Lmn,
    /// Per-unit stability (Fig. D.4).
    pub stability: Vec<UnitStability>,
}

impl OpenedModel {
    /// Units whose local model is unstable.
    pub fn unstable_units(&self) -> Vec<usize> {
        self.stability
            .iter()
            .filter(|s| !s.stable)
            .map(|s| s.unit)
            .collect()
    }
}

/// Opens a model file with the stability check relaxed (analysis and repair must open
/// unstable models) and warns on stderr when a local model is unstable.
pub fn open_model(path: &Path) -> Result<OpenedModel> {
    let (lmn, stability) = file::load_allow_unstable(path)
        .with_context(|| format!("model file {}", path.display()))?;
    let m = OpenedModel { lmn, stability };
    let bad = m.unstable_units();
    if !bad.is_empty() {
        eprintln!(
            "WARNING: {}: the local models of units {bad:?} are UNSTABLE (|1 + Ts p| >= 1); \
             results are shown for the model as it is (repair: fes modify --stabilise)",
            path.display()
        );
    }
    Ok(m)
}

/// One record as model input and measured output.
pub struct Series {
    /// File name.
    pub name: String,
    /// Record kind (`random`, `constant 40 Hz`, ...).
    pub kind: String,
    /// Pulse train, 1.0 in a pulse's sample.
    pub u: Vec<f64>,
    /// Measured normalised force.
    pub y: Vec<f64>,
}

/// A data set's training and test records.
pub struct Data {
    /// The directory.
    pub dir: PathBuf,
    /// Training records.
    pub train: Vec<Series>,
    /// Test records.
    pub test: Vec<Series>,
}

impl Data {
    /// (u, y) of the training records.
    pub fn train_pairs(&self) -> Vec<(&[f64], &[f64])> {
        self.train
            .iter()
            .map(|s| (s.u.as_slice(), s.y.as_slice()))
            .collect()
    }

    /// (u, y) of the test records.
    pub fn test_pairs(&self) -> Vec<(&[f64], &[f64])> {
        self.test
            .iter()
            .map(|s| (s.u.as_slice(), s.y.as_slice()))
            .collect()
    }
}

/// Reads and validates a data set (`fes_dataset`: every record finite, at least two
/// records, a non-empty train and test split) and checks its sampling period against the
/// model's; a `fes-dataset/2` data set is refused saying what reads it
/// ([`workbench::data::require_pulses`]).
pub fn open_data(dir: &Path, model_ts: f64) -> Result<Data> {
    workbench::data::require_pulses(dir)?;
    let ds = DataSet::read(dir).with_context(|| format!("data set {}", dir.display()))?;
    let ts = ds.header.ts_s;
    if ((ts - model_ts) / model_ts).abs() > 1e-9 {
        bail!(
            "data set {}: sampling period {} ms differs from the model's {} ms; \
             the records must be at the model's period",
            dir.display(),
            ts * 1e3,
            model_ts * 1e3
        );
    }
    let series = |r: &fes_dataset::Record| Series {
        name: r.file.clone(),
        kind: r.kind.clone(),
        u: r.pulse.iter().map(|&p| if p { 1.0 } else { 0.0 }).collect(),
        y: r.force.clone(),
    };
    Ok(Data {
        dir: dir.to_path_buf(),
        train: ds.train().map(series).collect(),
        test: ds.test().map(series).collect(),
    })
}

/// Creates the output directory (and parents); refuses a path that is a file.
pub fn out_dir(dir: &Path) -> Result<()> {
    if dir.exists() && !dir.is_dir() {
        bail!("--out {}: exists and is not a directory", dir.display());
    }
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))
}

/// Writes a CSV file: a header line and one line per row (fields already formatted),
/// quoted where a field holds a comma, a quote or a line break (record names and kinds
/// come from the user's data set).
pub fn write_csv(path: &Path, header: &[&str], rows: &[Vec<String>]) -> Result<()> {
    let mut w = csv::WriterBuilder::new()
        .flexible(true)
        .from_path(path)
        .with_context(|| format!("writing {}", path.display()))?;
    w.write_record(header)
        .and_then(|()| rows.iter().try_for_each(|r| w.write_record(r)))
        .with_context(|| format!("writing {}", path.display()))?;
    w.flush()
        .with_context(|| format!("writing {}", path.display()))
}

/// A Markdown table.
pub fn md_table(header: &[&str], rows: &[Vec<String>]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "| {} |", header.join(" | "));
    let _ = writeln!(
        s,
        "|{}|",
        header.iter().map(|_| "---").collect::<Vec<_>>().join("|")
    );
    for r in rows {
        let _ = writeln!(s, "| {} |", r.join(" | "));
    }
    s
}

/// A progress bar of `len` steps on stderr (drawn only on a terminal).
pub fn progress(len: usize, what: &str) -> ProgressBar {
    let bar = ProgressBar::new(len as u64);
    bar.set_style(
        ProgressStyle::with_template("{spinner} {elapsed:>4} {msg} [{bar:30}] {pos}/{len}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_message(what.to_string());
    bar
}

/// A number in scientific notation with 3 significant digits (`diverges` if not finite).
pub fn sci(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.3e}")
    } else {
        "diverges".into()
    }
}

/// Parses a comma-separated list of numbers, naming the flag in errors.
pub fn parse_list(flag: &str, text: &str) -> Result<Vec<f64>> {
    text.split(',')
        .map(|s| {
            let s = s.trim();
            let v: f64 = s
                .parse()
                .with_context(|| format!("{flag}: `{s}` is not a number"))?;
            if !v.is_finite() {
                bail!("{flag}: `{s}` is not a finite number");
            }
            Ok(v)
        })
        .collect()
}
