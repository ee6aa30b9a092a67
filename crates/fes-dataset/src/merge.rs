//! Several recordings of one muscle as one data set (`fes dataset merge`), as a system
//! identification tool merges experiments: a model is fitted to all of them at once.
//!
//! A second recording usually exists because the first one misses something the model
//! must get right (close pulse pairs from rest, a frequency band). The records of every
//! set are kept as they are, in order, renamed `record_000.csv` on; the split is the union
//! of the sets' splits (a training record stays a training record). The forces must be on
//! one scale: the sets must share the sample period and `scale_n` (record the later ones
//! with `sim-muscle record --scale-from`, or import them with the first's
//! `--force-scale`), else the merge is refused. What the sets do not share (origin,
//! protocol, seed, offset) is kept, set by set, under `protocol.sets`.

use std::collections::BTreeMap;

use serde_json::json;

use crate::{DataSet, Header, Split};

/// Why a list of data sets cannot be merged.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MergeError {
    /// Fewer than two sets.
    #[error("merging needs at least two data sets, got {0}")]
    TooFew(usize),
    /// Sets at different sample periods.
    #[error(
        "data set {name} is sampled every {got_ms} ms, {first} every {want_ms} ms: \
         resample it first (fes dataset import --ts-ms)"
    )]
    Period {
        /// The set that differs.
        name: String,
        /// The first set.
        first: String,
        /// The first set's period, ms.
        want_ms: f64,
        /// This set's period, ms.
        got_ms: f64,
    },
    /// Sets whose normalised forces are on different scales.
    #[error(
        "data set {name} normalises force by {got} N, {first} by {want} N: the forces are \
         not on one scale (record it with `sim-muscle record --scale-from`, or import it with \
         --force-scale {want})"
    )]
    Scale {
        /// The set that differs.
        name: String,
        /// The first set.
        first: String,
        /// The first set's scale, N.
        want: f64,
        /// This set's scale, N.
        got: f64,
    },
}

/// Relative tolerance for "the same" period and scale (both are written with 17
/// significant digits; a copied scale comes back exactly).
const SAME: f64 = 1e-12;

fn same(a: f64, b: f64) -> bool {
    (a - b).abs() <= SAME * a.abs().max(b.abs())
}

/// The first value when every set has the same one, else `None`.
fn common<T: PartialEq + Clone>(mut values: impl Iterator<Item = T>) -> Option<T> {
    let first = values.next()?;
    values.all(|v| v == first).then_some(first)
}

/// Merges `sets` (each with the name it is reported under, e.g. its directory) into one
/// data set: records in order, renamed; the union of the splits; origin fields kept where
/// all sets agree, and every set's own under `protocol.sets`. `offset_n` is the first
/// set's (the offset converts normalised force back to the sensor's reading; each set's
/// is in `protocol.sets`).
pub fn merge(sets: &[(String, DataSet)]) -> Result<DataSet, MergeError> {
    let Some((first_name, first)) = sets.first() else {
        return Err(MergeError::TooFew(0));
    };
    if sets.len() < 2 {
        return Err(MergeError::TooFew(sets.len()));
    }
    let h0 = &first.header;
    for (name, set) in &sets[1..] {
        let h = &set.header;
        if !same(h.ts_s, h0.ts_s) {
            return Err(MergeError::Period {
                name: name.clone(),
                first: first_name.clone(),
                want_ms: h0.ts_s * 1e3,
                got_ms: h.ts_s * 1e3,
            });
        }
        if !same(h.scale_n, h0.scale_n) {
            return Err(MergeError::Scale {
                name: name.clone(),
                first: first_name.clone(),
                want: h0.scale_n,
                got: h.scale_n,
            });
        }
    }
    let mut records = Vec::new();
    let mut split = Split {
        train: Vec::new(),
        test: Vec::new(),
    };
    let mut origins = Vec::with_capacity(sets.len());
    for (name, set) in sets {
        let base = records.len();
        let h = &set.header;
        origins.push(json!({
            "name": name,
            "source": h.source,
            "preset": h.preset,
            "seed": h.seed,
            "noise": h.noise,
            "protocol": h.protocol,
            "offset_n": h.offset_n,
            "first_record": base,
            "records": set.records.len(),
        }));
        split.train.extend(h.split.train.iter().map(|i| base + i));
        split.test.extend(h.split.test.iter().map(|i| base + i));
        for r in &set.records {
            let mut r = r.clone();
            r.file = format!("record_{:03}.csv", records.len());
            records.push(r);
        }
    }
    let headers = || sets.iter().map(|(_, s)| &s.header);
    let header = Header {
        source: common(headers().map(|h| h.source.clone())).unwrap_or_else(|| {
            headers()
                .map(|h| h.source.as_str())
                .collect::<Vec<_>>()
                .join(" + ")
        }),
        preset: common(headers().map(|h| h.preset.clone())).flatten(),
        parameters: common(headers().map(|h| h.parameters.clone())).unwrap_or_else(BTreeMap::new),
        seed: common(headers().map(|h| h.seed)).flatten(),
        noise: common(headers().map(|h| h.noise.clone())).unwrap_or(serde_json::Value::Null),
        protocol: json!({ "kind": "merged", "sets": origins }),
        scale_n: h0.scale_n,
        offset_n: h0.offset_n,
        ts_s: h0.ts_s,
        split,
    };
    Ok(DataSet { header, records })
}
