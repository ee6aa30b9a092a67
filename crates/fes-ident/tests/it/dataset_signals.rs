//! The data-set format version 2 (`fes-dataset/2`, `fes_dataset::signals`): several
//! continuous-valued inputs and outputs at any period, written and read back exactly;
//! version 1 keeps its reader and opens through `read_any` as signals.

use super::dataset_support::small_dataset;
use fes_dataset::signals::{
    AnyDataSet, Channel, SCHEMA_V2, SignalHeader, SignalRecord, SignalSet, read_any,
};
use fes_dataset::{DataSet, FormatError, ReadError, Split, WriteMode};
use fes_testkit::Scratch;

/// Two inputs (valve angle, heater voltage), one output, Ts = 50 ms: the heat-transfer
/// process's shape (App. E.2).
fn heat_like() -> SignalSet {
    let rec = |i: usize, n: usize| SignalRecord {
        file: format!("r{i}.csv"),
        kind: if i == 0 {
            "fast-random"
        } else {
            "test-voltage"
        }
        .into(),
        t0_s: 0.0,
        inputs: vec![
            (0..n).map(|k| ((k * 7 + i) % 11) as f64 / 10.0).collect(),
            (0..n)
                .map(|k| (k as f64 * 0.37 + i as f64).sin().abs() / 3.0)
                .collect(),
        ],
        outputs: vec![
            (0..n)
                .map(|k| 1.0 / (1.0 + k as f64) + 0.1 * i as f64)
                .collect(),
        ],
    };
    SignalSet {
        header: SignalHeader {
            source: "test".into(),
            seed: Some(1),
            parameters: [("gain_k".to_string(), 40.0)].into_iter().collect(),
            protocol: serde_json::json!({ "experiments": "E.2" }),
            ts_s: 0.05,
            inputs: vec![
                Channel::new("alpha", "normalised").with_range(20.0, 120.0),
                Channel::new("u", "normalised").with_range(0.0, 10.0),
            ],
            outputs: vec![Channel::new("y", "normalised").with_range(20.0, 60.0)],
            split: Split {
                train: vec![0],
                test: vec![1],
            },
        },
        records: vec![rec(0, 40), rec(1, 25)],
    }
}

#[test]
fn signals_round_trip_exactly() {
    let dir = Scratch::new("signals-rt");
    let set = heat_like();
    set.write(dir.path(), WriteMode::CreateNew).unwrap();
    let meta = std::fs::read_to_string(dir.join("dataset.json")).unwrap();
    assert!(meta.contains(SCHEMA_V2), "{meta}");
    let head = std::fs::read_to_string(dir.join("r0.csv")).unwrap();
    assert!(head.starts_with("t_s,alpha,u,y\n"), "{head}");
    assert_eq!(SignalSet::read(dir.path()).unwrap(), set);
    match read_any(dir.path()).unwrap() {
        AnyDataSet::Signals(s) => assert_eq!(s, set),
        other => panic!("{other:?}"),
    }
    // The version-1 reader refuses a version-2 set by its schema.
    let e = DataSet::read(dir.path()).unwrap_err();
    assert!(
        matches!(e, ReadError::Format(FormatError::Schema { .. })),
        "{e}"
    );
}

#[test]
fn version_one_sets_open_unchanged_and_as_signals() {
    let dir = Scratch::new("signals-v1");
    let ds = small_dataset();
    ds.write(dir.path(), WriteMode::CreateNew).unwrap();
    let any = read_any(dir.path()).unwrap();
    assert_eq!(any, AnyDataSet::Pulses(ds.clone()));
    let s = any.into_signals();
    assert_eq!(s.header.ts_s, 1e-3);
    assert_eq!(s.header.inputs[0].name, "pulse");
    assert_eq!(s.records[1].inputs[0], vec![1.0, 0.0, 1.0, 0.0, 0.0]);
    assert_eq!(s.records[1].outputs[0], ds.records[1].force);
    assert_eq!(s.train().count(), 2);
}

#[test]
fn signal_files_are_checked_against_the_header() {
    let dir = Scratch::new("signals-bad");
    let set = heat_like();
    set.write(dir.path(), WriteMode::CreateNew).unwrap();
    let path = dir.join("r1.csv");
    let text = std::fs::read_to_string(&path).unwrap();
    // Columns swapped.
    std::fs::write(&path, text.replacen("t_s,alpha,u,y", "t_s,u,alpha,y", 1)).unwrap();
    let e = SignalSet::read(dir.path()).unwrap_err().to_string();
    assert!(e.contains("r1.csv") && e.contains("t_s,alpha,u,y"), "{e}");
    // A time step off the period.
    std::fs::write(&path, text.replacen("\n0.1,", "\n0.12,", 1)).unwrap();
    let e = SignalSet::read(dir.path()).unwrap_err().to_string();
    assert!(e.contains("t_s") && e.contains("step"), "{e}");
    // A channel name repeated is refused before anything is written.
    let mut bad = heat_like();
    bad.header.outputs[0].name = "u".into();
    let e = bad
        .write(Scratch::new("signals-dup").path(), WriteMode::CreateNew)
        .unwrap_err()
        .to_string();
    assert!(e.contains("outputs[0].name"), "{e}");
}

#[test]
fn a_time_that_is_not_finite_is_refused() {
    // `NaN` parses as a number and fails every comparison, so the step check alone let a
    // time of NaN (and every time after it) through.
    let dir = Scratch::new("signals-nan-time");
    let set = heat_like();
    set.write(dir.path(), WriteMode::CreateNew).unwrap();
    let path = dir.join("r0.csv");
    let text = std::fs::read_to_string(&path).unwrap();
    std::fs::write(&path, text.replacen("\n0.1,", "\nNaN,", 1)).unwrap();
    let e = SignalSet::read(dir.path()).unwrap_err();
    assert!(
        matches!(
            e,
            ReadError::Format(FormatError::Value {
                line: 4,
                field: "t_s",
                ..
            })
        ),
        "{e}"
    );
    assert!(
        e.to_string()
            .ends_with("r0.csv:4: field `t_s`: NaN is not finite"),
        "{e}"
    );
}
