//! `fes_dataset::merge`: every record kept, the union of the splits, the origin of each set,
//! a valid data set on disk; sets on another force scale or period refused.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use std::collections::BTreeMap;

use fes_dataset::merge::{MergeError, merge};
use fes_dataset::{DataSet, Header, Record, Split, WriteMode};
use fes_testkit::Scratch;
use serde_json::json;

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
    let dir = Scratch::new("merge");
    m.write(dir.path(), WriteMode::CreateNew).unwrap();
    assert_eq!(DataSet::read(dir.path()).unwrap(), m);
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
