//! Which data sets the workbench's commands read, and a description of any data set.
//!
//! `fes identify`, `sweep`, `compare`, `analyse` and `modify` fit and score models of one
//! pulse input and normalised force: they read `fes-dataset/1`. A `fes-dataset/2` data
//! set (named continuous input and output channels at any period, such as the
//! heat-transfer process's) is identified through `fes_ident::ident::miso` and controlled
//! through `fes_model::control::io_design`, as the `heat-transfer` binary does
//! (`scripts/heat-transfer`, docs/heat-transfer.md); the workbench has no second
//! identification pipeline. [`require_pulses`] refuses a version-2 data set with a
//! [`DataVersionError`] that says so, before the version-1 reader would only say that the
//! schema is not its own; [`describe`] (`fes dataset inspect`) describes either version.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use fes_dataset::signals::{AnyDataSet, SCHEMA_V2, SignalSet, read_any};
use fes_dataset::{DataSet, META_FILE, ReadError, SCHEMA};

/// A data set of a version the workbench's `--data` commands do not read.
#[derive(Debug, thiserror::Error)]
pub enum DataVersionError {
    /// A valid `fes-dataset/2` data set.
    #[error(
        "data set {} is {SCHEMA_V2} (inputs {}; outputs {}; Ts = {} ms; {records} records): \
         fes identify, sweep, compare, analyse and modify read {SCHEMA} (one pulse input and \
         normalised force) only. A {SCHEMA_V2} plant is identified and controlled through \
         fes_ident::ident::miso and fes_model::control::io_design, as the heat-transfer binary \
         does (scripts/heat-transfer, docs/heat-transfer.md); `fes dataset inspect {}` \
         describes the data set, python/fes_io.py and matlab/load_fes_dataset.m read it",
        dir.display(),
        inputs.join(", "),
        outputs.join(", "),
        num(ts_s * 1e3),
        dir.display()
    )]
    Signals {
        /// The directory.
        dir: PathBuf,
        /// Input channel names.
        inputs: Vec<String>,
        /// Output channel names.
        outputs: Vec<String>,
        /// Sample period, s.
        ts_s: f64,
        /// Number of records.
        records: usize,
    },
    /// A `fes-dataset/2` data set that its own reader refuses.
    #[error(
        "data set {} says it is {SCHEMA_V2}, which the workbench's --data commands do not read \
         (they read {SCHEMA}; see docs/heat-transfer.md), and it is not valid",
        dir.display()
    )]
    InvalidSignals {
        /// The directory.
        dir: PathBuf,
        /// What the version-2 reader found.
        #[source]
        source: ReadError,
    },
}

/// The `schema` field of `dir/dataset.json`, if the file reads as JSON and has one.
fn schema_of(dir: &Path) -> Option<String> {
    let bytes = std::fs::read(dir.join(META_FILE)).ok()?;
    let v: serde_json::Value = serde_json::from_slice(&bytes).ok()?;
    v.get("schema")?.as_str().map(str::to_owned)
}

/// Refuses a `fes-dataset/2` data set in `dir` (valid or not) with a
/// [`DataVersionError`]; anything else passes, for the `fes-dataset/1` reader to accept or
/// refuse.
pub fn require_pulses(dir: &Path) -> Result<(), DataVersionError> {
    if schema_of(dir).as_deref() != Some(SCHEMA_V2) {
        return Ok(());
    }
    match SignalSet::read(dir) {
        Ok(set) => {
            let names = |c: &[fes_dataset::signals::Channel]| -> Vec<String> {
                c.iter().map(|c| c.name.clone()).collect()
            };
            Err(DataVersionError::Signals {
                dir: dir.to_path_buf(),
                inputs: names(&set.header.inputs),
                outputs: names(&set.header.outputs),
                ts_s: set.header.ts_s,
                records: set.records.len(),
            })
        }
        Err(source) => Err(DataVersionError::InvalidSignals {
            dir: dir.to_path_buf(),
            source,
        }),
    }
}

/// Indices as `0, 1, 3`.
fn list(indices: &[usize]) -> String {
    indices
        .iter()
        .map(usize::to_string)
        .collect::<Vec<_>>()
        .join(", ")
}

/// A number in the shortest form that keeps four significant digits.
fn num(x: f64) -> String {
    if x == 0.0 || (1e-3..1e5).contains(&x.abs()) {
        let s = format!("{x:.4}");
        let s = s.trim_end_matches('0').trim_end_matches('.');
        s.to_owned()
    } else {
        format!("{x:.3e}")
    }
}

/// Which split a record is in.
fn split_of(split: &fes_dataset::Split, i: usize) -> &'static str {
    if split.train.contains(&i) {
        "train"
    } else if split.test.contains(&i) {
        "test"
    } else {
        "-"
    }
}

/// Reads the data set in `dir` (either version) and describes it in Markdown: version,
/// source, period, records, split, channels (for version 2 with each channel's unit,
/// range and stored minimum, maximum and mean), one row per record, and which tools read
/// it.
pub fn describe(dir: &Path) -> Result<String, ReadError> {
    Ok(match read_any(dir)? {
        AnyDataSet::Pulses(ds) => describe_pulses(dir, &ds),
        AnyDataSet::Signals(s) => describe_signals(dir, &s),
    })
}

fn describe_pulses(dir: &Path, ds: &DataSet) -> String {
    let h = &ds.header;
    let mut s = String::new();
    let samples: usize = ds.records.iter().map(|r| r.len()).sum();
    let pulses: usize = ds.records.iter().map(|r| r.pulses()).sum();
    let _ = writeln!(
        s,
        "# {}: {SCHEMA} (one pulse input, normalised force)\n",
        dir.display()
    );
    let _ = writeln!(s, "source    {}", h.source);
    let _ = writeln!(s, "period    {} ms", num(h.ts_s * 1e3));
    let _ = writeln!(
        s,
        "records   {} (train {}: {}; test {}: {})",
        ds.records.len(),
        h.split.train.len(),
        list(&h.split.train),
        h.split.test.len(),
        list(&h.split.test)
    );
    let _ = writeln!(s, "samples   {samples}, pulses {pulses}");
    let _ = writeln!(
        s,
        "channels  input `pulse` (0/1), output `force` (normalised: scale {} N, offset {} N)\n",
        num(h.scale_n),
        num(h.offset_n)
    );
    let _ = writeln!(s, "| record | file | kind | samples | pulses | split |");
    let _ = writeln!(s, "|---:|---|---|---:|---:|---|");
    for (i, r) in ds.records.iter().enumerate() {
        let _ = writeln!(
            s,
            "| {i} | {} | {} | {} | {} | {} |",
            r.file,
            r.kind,
            r.len(),
            r.pulses(),
            split_of(&h.split, i)
        );
    }
    let _ = writeln!(
        s,
        "\nRead by: fes identify, sweep, compare, analyse, modify; python/fes_io.py, \
         matlab/load_fes_dataset.m."
    );
    s
}

fn describe_signals(dir: &Path, set: &SignalSet) -> String {
    let h = &set.header;
    let mut s = String::new();
    let samples: usize = set.records.iter().map(|r| r.len()).sum();
    let _ = writeln!(
        s,
        "# {}: {SCHEMA_V2} (named continuous channels)\n",
        dir.display()
    );
    let seed = h.seed.map_or(String::new(), |x| format!(" (seed {x})"));
    let _ = writeln!(s, "source    {}{seed}", h.source);
    let _ = writeln!(s, "period    {} ms", num(h.ts_s * 1e3));
    let _ = writeln!(
        s,
        "records   {} (train {}: {}; test {}: {})",
        set.records.len(),
        h.split.train.len(),
        list(&h.split.train),
        h.split.test.len(),
        list(&h.split.test)
    );
    let _ = writeln!(
        s,
        "samples   {samples} ({} s)\n",
        num(samples as f64 * h.ts_s)
    );
    let _ = writeln!(s, "| channel | role | unit | range | min | max | mean |");
    let _ = writeln!(s, "|---|---|---|---|---:|---:|---:|");
    let roles = h
        .inputs
        .iter()
        .enumerate()
        .map(|(k, c)| (c, "input", k))
        .chain(h.outputs.iter().enumerate().map(|(k, c)| (c, "output", k)));
    for (c, role, k) in roles {
        let values = set.records.iter().flat_map(|r| {
            if role == "input" {
                r.inputs[k].iter()
            } else {
                r.outputs[k].iter()
            }
        });
        let (mut lo, mut hi, mut sum, mut n) = (f64::INFINITY, f64::NEG_INFINITY, 0.0, 0usize);
        for &v in values {
            lo = lo.min(v);
            hi = hi.max(v);
            sum += v;
            n += 1;
        }
        let range = c
            .range
            .map_or("-".to_owned(), |[a, b]| format!("{} .. {}", num(a), num(b)));
        let _ = writeln!(
            s,
            "| {} | {role} | {} | {range} | {} | {} | {} |",
            c.name,
            c.unit,
            num(lo),
            num(hi),
            num(sum / n.max(1) as f64)
        );
    }
    let _ = writeln!(
        s,
        "\n| record | file | kind | samples | start (s) | split |"
    );
    let _ = writeln!(s, "|---:|---|---|---:|---:|---|");
    for (i, r) in set.records.iter().enumerate() {
        let _ = writeln!(
            s,
            "| {i} | {} | {} | {} | {} | {} |",
            r.file,
            r.kind,
            r.len(),
            num(r.t0_s),
            split_of(&h.split, i)
        );
    }
    let _ = writeln!(
        s,
        "\nRead by: fes_dataset::signals, python/fes_io.py, matlab/load_fes_dataset.m. \
         Identified and controlled through fes_ident::ident::miso and \
         fes_model::control::io_design, as the heat-transfer binary does \
         (docs/heat-transfer.md); fes identify, sweep, compare, analyse and modify read \
         {SCHEMA} only."
    );
    s
}
