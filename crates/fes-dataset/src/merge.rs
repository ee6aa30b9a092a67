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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Record;

    fn set(source: &str, seed: u64, scale_n: f64, ts_s: f64, n: usize) -> DataSet {
        let records = (0..n)
            .map(|i| Record {
                file: format!("record_{i:03}.csv"),
                kind: format!("{source} {i}"),
                t_ms: (0..4).map(|k| k as f64 * ts_s * 1e3).collect(),
                pulse: vec![true, false, i % 2 == 0, false],
                force: vec![0.0, 0.1 * i as f64, 0.2, 0.1],
                decided: (i == 1).then(|| vec![true, true, false, false]),
            })
            .collect();
        DataSet {
            header: Header {
                source: source.into(),
                preset: Some("slow".into()),
                parameters: BTreeMap::from([("tau1".into(), 0.09)]),
                seed: Some(seed),
                noise: json!({"noise_std_n": 0.7}),
                protocol: json!({"kind": source}),
                scale_n,
                offset_n: seed as f64,
                ts_s,
                split: Split::first(n / 2, n),
            },
            records,
        }
    }

    #[test]
    fn the_merge_keeps_every_record_and_the_union_of_the_splits() {
        let (a, b) = (
            set("thesis", 1, 235.25, 1e-3, 4),
            set("rich", 3, 235.25, 1e-3, 6),
        );
        let m = merge(&[("a".into(), a.clone()), ("b".into(), b.clone())]).unwrap();
        assert_eq!(m.records.len(), 10);
        assert_eq!(m.header.split.train, vec![0, 1, 4, 5, 6]);
        assert_eq!(m.header.split.test, vec![2, 3, 7, 8, 9]);
        // Each record unchanged but for its file name, which is unique and in order.
        for (i, (got, want)) in m
            .records
            .iter()
            .zip(a.records.iter().chain(&b.records))
            .enumerate()
        {
            assert_eq!(got.file, format!("record_{i:03}.csv"));
            assert_eq!(
                (&got.kind, &got.pulse, &got.force, &got.decided, &got.t_ms),
                (
                    &want.kind,
                    &want.pulse,
                    &want.force,
                    &want.decided,
                    &want.t_ms
                )
            );
        }
        // Shared origin kept, differing origin per set.
        assert_eq!(m.header.source, "thesis + rich");
        assert_eq!(m.header.preset.as_deref(), Some("slow"));
        assert_eq!(m.header.parameters, a.header.parameters);
        assert_eq!(m.header.seed, None);
        assert_eq!(m.header.offset_n, 1.0);
        let sets = m.header.protocol["sets"].as_array().unwrap();
        assert_eq!(sets[1]["first_record"], 4);
        assert_eq!(sets[1]["seed"], 3);
        assert_eq!(sets[1]["offset_n"], 3.0);
        assert_eq!(sets[1]["protocol"]["kind"], "rich");
        // It writes and reads back as a valid data set.
        let dir = std::env::temp_dir().join(format!("fes-merge-{}", std::process::id()));
        m.write(&dir, crate::WriteMode::Overwrite).unwrap();
        let back = DataSet::read(&dir).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(back, m);
    }

    #[test]
    fn sets_on_different_scales_or_periods_are_refused() {
        let a = set("a", 1, 235.25, 1e-3, 4);
        let scaled = set("b", 2, 364.48, 1e-3, 4);
        let slower = set("c", 2, 235.25, 2e-3, 4);
        assert!(matches!(
            merge(&[("a".into(), a.clone()), ("b".into(), scaled)]),
            Err(MergeError::Scale { ref name, .. }) if name == "b"
        ));
        assert!(matches!(
            merge(&[("a".into(), a.clone()), ("c".into(), slower)]),
            Err(MergeError::Period { ref name, .. }) if name == "c"
        ));
        assert_eq!(merge(&[("a".into(), a)]), Err(MergeError::TooFew(1)));
        assert_eq!(merge(&[]), Err(MergeError::TooFew(0)));
    }
}
