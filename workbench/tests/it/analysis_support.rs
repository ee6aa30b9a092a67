//! Helpers of the analysis CLI tests: temporary directories, running the binary, model and
//! data-set fixtures (fes-ident's test fixtures, shared by path).

#[path = "../../../crates/fes-ident/tests/it/analysis_support.rs"]
pub mod fixtures;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use fes_dataset::{DataSet, Header, Record, Split, WriteMode};
use fes_model::model::{Lmn, file};

/// A fresh empty directory, removed when the test passes (the testkit's).
pub fn tmp(tag: &str) -> fes_testkit::Scratch {
    fes_testkit::Scratch::new(tag)
}

/// Runs `supervisor` with `args`.
pub fn run(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_fes"))
        .args(args)
        .output()
        .expect("run supervisor")
}

/// Runs and asserts success; returns stdout.
pub fn ok(args: &[&str]) -> String {
    let o = run(args);
    assert!(
        o.status.success(),
        "supervisor {args:?} failed:\nstdout: {}\nstderr: {}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Runs, asserts failure and that stderr contains every `needle`; returns stderr.
pub fn fails(args: &[&str], needles: &[&str]) -> String {
    let o = run(args);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(
        !o.status.success(),
        "supervisor {args:?} should fail; stdout {}",
        String::from_utf8_lossy(&o.stdout)
    );
    for n in needles {
        assert!(err.contains(n), "stderr of {args:?} lacks {n:?}:\n{err}");
    }
    err
}

/// Saves a model file.
pub fn save_model(dir: &Path, name: &str, lmn: &Lmn) -> PathBuf {
    let p = dir.join(name);
    file::save(lmn, &p).expect("save model");
    p
}

/// A noise-free data set of `n` records of `len` samples from `truth` (the first `train`
/// records train): random thesis-like trains, output = the model's normalised output.
pub fn save_dataset(
    dir: &Path,
    truth: &Lmn,
    n: usize,
    len: usize,
    train: usize,
    seed: u64,
) -> PathBuf {
    let inputs = fixtures::random_inputs(n, len, seed);
    let outputs = fixtures::outputs(truth, &inputs);
    let records = inputs
        .into_iter()
        .zip(outputs)
        .enumerate()
        .map(|(i, (u, y))| {
            Record::uniform(
                format!("record_{i:03}.csv"),
                "random",
                truth.ts,
                u.iter().map(|&v| v > 0.5).collect(),
                y,
            )
        })
        .collect();
    let ds = DataSet {
        header: Header {
            source: "analysis test".into(),
            preset: None,
            parameters: Default::default(),
            seed: Some(seed),
            noise: serde_json::Value::Null,
            protocol: serde_json::Value::Null,
            scale_n: truth.force_scale_n,
            offset_n: 0.0,
            ts_s: truth.ts,
            split: Split::first(train, n),
        },
        records,
    };
    let p = dir.join("data");
    ds.write(&p, WriteMode::CreateNew).expect("write data set");
    p
}

/// True when the file starts with the PNG signature.
pub fn is_png(p: &Path) -> bool {
    std::fs::read(p).is_ok_and(|b| b.starts_with(b"\x89PNG\r\n\x1a\n"))
}

/// Reads a CSV written by the tools: header names and rows of fields.
pub fn csv(p: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    fes_testkit::table::read_csv(p)
}

/// Column `name` of a CSV as numbers.
pub fn column(h: &[String], rows: &[Vec<String>], name: &str) -> Vec<f64> {
    let i = h
        .iter()
        .position(|x| x == name)
        .unwrap_or_else(|| panic!("no column {name}"));
    rows.iter().map(|r| r[i].parse().expect("number")).collect()
}

/// The bench's cardiac profile (`fes bench`: 75 beats/min, duty 0.4, the outer loop on) at
/// `amplitude`, resting `start_rest_ms` before the first contraction (None: the profile's
/// default).
pub fn bench_profile(
    amplitude: f64,
    start_rest_ms: Option<f64>,
) -> supervisor::profile::ProfileSpec {
    supervisor::profile::ProfileSpec::Cardiac(supervisor::profile::CardiacSpec {
        bpm: 75.0,
        duty: 0.4,
        amplitude,
        edge_rate_per_s: None,
        outer_loop: Some(true),
        start_rest_ms,
    })
}

/// Every number of the JSON value `a` equals `b`'s within `rel` (relative, with an absolute
/// floor of `rel`), everything else equal; `provenance` objects are skipped (a model
/// re-identified differs there only).
pub fn assert_close(a: &serde_json::Value, b: &serde_json::Value, rel: f64, at: &str) {
    use serde_json::Value;
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
            assert!(
                (x - y).abs() <= rel * x.abs().max(y.abs()).max(1.0),
                "{at}: {x} vs {y}"
            );
        }
        (Value::Array(x), Value::Array(y)) => {
            assert_eq!(x.len(), y.len(), "{at}: lengths");
            for (i, (x, y)) in x.iter().zip(y).enumerate() {
                assert_close(x, y, rel, &format!("{at}[{i}]"));
            }
        }
        (Value::Object(x), Value::Object(y)) => {
            let keys: Vec<&String> = x.keys().filter(|k| *k != "provenance").collect();
            let other: Vec<&String> = y.keys().filter(|k| *k != "provenance").collect();
            assert_eq!(keys, other, "{at}: keys");
            for k in keys {
                assert_close(&x[k], &y[k], rel, &format!("{at}.{k}"));
            }
        }
        _ => assert_eq!(a, b, "{at}"),
    }
}
