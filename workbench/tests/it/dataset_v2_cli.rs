//! The workbench and `fes-dataset/2`: every command that takes `--data` refuses
//! a version-2 data set with an error that names the format and says what reads it (the
//! heat-transfer path), and `fes dataset inspect` describes a data set of either version.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use fes_dataset::signals::SignalSet;
use fes_dataset::{DataSet, Header, Record, Split, WriteMode};
use workbench::data::{DataVersionError, describe, require_pulses};

const BIN: &str = env!("CARGO_BIN_EXE_fes");

fn scratch(name: &str) -> fes_testkit::Scratch {
    fes_testkit::Scratch::new_in(Path::new(env!("CARGO_TARGET_TMPDIR")), name)
}

fn fes(args: &[&str]) -> Output {
    Command::new(BIN)
        .args(args)
        .env("RUST_BACKTRACE", "0")
        .output()
        .expect("run fes")
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The heat-transfer experiments (sim-heat, seed 1) written to `dir`.
fn heat(dir: &Path) -> SignalSet {
    let set = sim_heat::experiment::dataset(&sim_heat::HeatParams::default(), 1).unwrap();
    set.write(dir, WriteMode::CreateNew).unwrap();
    set
}

/// A small fes-dataset/1 data set: three records at 1 ms.
fn pulses(dir: &Path) -> DataSet {
    let records = (0..3usize)
        .map(|i| {
            let n = 30 + 5 * i;
            Record::uniform(
                format!("r{i}.csv"),
                "random",
                1e-3,
                (0..n).map(|k| k % 7 == 2).collect(),
                (0..n).map(|k| 0.01 * k as f64).collect(),
            )
        })
        .collect();
    let ds = DataSet {
        header: Header {
            source: "dataset_v2_cli test".into(),
            preset: None,
            parameters: Default::default(),
            seed: None,
            noise: serde_json::Value::Null,
            protocol: serde_json::Value::Null,
            scale_n: 300.0,
            offset_n: 2.0,
            ts_s: 1e-3,
            split: Split {
                train: vec![0, 1],
                test: vec![2],
            },
        },
        records,
    };
    ds.write(dir, WriteMode::CreateNew).unwrap();
    ds
}

#[test]
fn a_version_two_data_set_is_refused_by_name_as_a_typed_error() {
    let dir = scratch("v2_typed");
    let data = dir.join("heat");
    heat(&data);
    match require_pulses(&data).unwrap_err() {
        DataVersionError::Signals {
            inputs,
            outputs,
            ts_s,
            records,
            ..
        } => {
            assert_eq!(inputs, ["alpha", "u"]);
            assert_eq!(outputs, ["y"]);
            assert_eq!(ts_s, 0.05);
            assert_eq!(records, 9);
        }
        other => panic!("{other:?}"),
    }
    // A version-1 data set passes; so does a directory that is no data set at all (the
    // version-1 reader says what is wrong with it).
    let v1 = dir.join("v1");
    pulses(&v1);
    require_pulses(&v1).unwrap();
    require_pulses(&dir.join("missing")).unwrap();
    // A broken version-2 data set: the version-2 reader's error is kept as the source.
    let path = data.join("fast-random-1.csv");
    let text = std::fs::read_to_string(&path).unwrap();
    std::fs::write(&path, text.replacen("\n0.1,", "\n0.12,", 1)).unwrap();
    let e = require_pulses(&data).unwrap_err();
    assert!(
        matches!(e, DataVersionError::InvalidSignals { .. }),
        "{e:?}"
    );
    let source = std::error::Error::source(&e).unwrap().to_string();
    assert!(
        source.contains("fast-random-1.csv:4: field `t_s`: step"),
        "{source}"
    );
}

#[test]
fn every_data_command_refuses_version_two_saying_what_reads_it() {
    let dir = scratch("v2_cli");
    let data = dir.join("heat");
    heat(&data);
    let d = data.to_str().unwrap();
    let model = repo().join("models/fast.lmn.json");
    let m = model.to_str().unwrap();
    let out = dir.join("out");
    let o = out.to_str().unwrap();
    let lmn_path = dir.join("x.lmn.json");
    let lmn = lmn_path.to_str().unwrap();
    let commands: [&[&str]; 5] = [
        &[
            "identify",
            "--data",
            d,
            "--structure",
            "arx-shift",
            "--units",
            "1",
            "--out",
            lmn,
        ],
        &[
            "sweep",
            "--data",
            d,
            "--structure",
            "arx-shift",
            "--units",
            "1..2",
            "--out",
            o,
        ],
        &["compare", "--data", d, "--out", o],
        &["analyse", "--model", m, "--data", d, "--out", o],
        &[
            "modify",
            "--model",
            m,
            "--stabilise",
            "--data",
            d,
            "--out",
            lmn,
        ],
    ];
    for args in commands {
        let r = fes(args);
        let stderr = String::from_utf8_lossy(&r.stderr);
        assert!(
            !r.status.success(),
            "{args:?} accepted a fes-dataset/2 data set"
        );
        for needle in [
            &format!(
                "data set {d} is fes-dataset/2 (inputs alpha, u; outputs y; Ts = 50 ms; 9 records)"
            ),
            "read fes-dataset/1 (one pulse input and normalised force) only",
            "as the heat-transfer binary does (scripts/heat-transfer, docs/heat-transfer.md)",
            "fes dataset inspect",
        ] {
            assert!(
                stderr.contains(needle),
                "{args:?}: `{needle}` not in\n{stderr}"
            );
        }
    }
    assert!(!out.join("compare.md").exists());
    assert!(!lmn_path.exists());
}

#[test]
fn inspect_describes_either_version() {
    let dir = scratch("v2_inspect");
    let data = dir.join("heat");
    let set = heat(&data);
    let r = fes(&["dataset", "inspect", data.to_str().unwrap()]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let text = String::from_utf8(r.stdout).unwrap();
    assert_eq!(text, describe(&data).unwrap());
    assert!(
        text.contains(": fes-dataset/2 (named continuous channels)"),
        "{text}"
    );
    assert!(text.contains("\nperiod    50 ms\n"), "{text}");
    assert!(
        text.contains("\nrecords   9 (train 5: 0, 1, 3, 5, 7; test 4: 2, 4, 6, 8)\n"),
        "{text}"
    );
    assert!(text.contains("\nsamples   17000 (850 s)\n"), "{text}");
    // Each channel's stored extremes, as the Rust side computes them.
    let extremes = |v: Vec<f64>| {
        let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        (lo, hi)
    };
    let y: Vec<f64> = set
        .records
        .iter()
        .flat_map(|r| r.outputs[0].clone())
        .collect();
    let (lo, hi) = extremes(y);
    let row = text.lines().find(|l| l.starts_with("| y |")).unwrap();
    let cells: Vec<&str> = row.split('|').map(str::trim).collect();
    assert_eq!(cells[2..5], ["output", "normalised", "20 .. 60"], "{row}");
    assert!(
        (cells[5].parse::<f64>().unwrap() - lo).abs() < 1e-4,
        "{row} vs {lo}"
    );
    assert!(
        (cells[6].parse::<f64>().unwrap() - hi).abs() < 1e-4,
        "{row} vs {hi}"
    );
    for (i, r) in set.records.iter().enumerate() {
        let split = if set.header.split.train.contains(&i) {
            "train"
        } else {
            "test"
        };
        let line = format!(
            "| {i} | {} | {} | {} | 0 | {split} |",
            r.file,
            r.kind,
            r.len()
        );
        assert!(text.contains(&line), "{line} not in\n{text}");
    }
    // Version 1.
    let v1 = dir.join("v1");
    let ds = pulses(&v1);
    let r = fes(&["dataset", "inspect", v1.to_str().unwrap()]);
    assert!(r.status.success());
    let text = String::from_utf8(r.stdout).unwrap();
    assert!(
        text.contains(": fes-dataset/1 (one pulse input, normalised force)"),
        "{text}"
    );
    assert!(text.contains("\nperiod    1 ms\n"), "{text}");
    let pulses: usize = ds.records.iter().map(Record::pulses).sum();
    assert!(
        text.contains(&format!("\nsamples   105, pulses {pulses}\n")),
        "{text}"
    );
    assert!(
        text.contains("| 2 | r2.csv | random | 40 | 6 | test |"),
        "{text}"
    );
    // Not a data set: an error naming the directory.
    let r = fes(&["dataset", "inspect", dir.join("none").to_str().unwrap()]);
    assert!(!r.status.success());
    assert!(String::from_utf8_lossy(&r.stderr).contains("cannot read data set"));
}
