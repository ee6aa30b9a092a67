//! The readers for other languages (issue 20, item 2) against files the workbench writes:
//! `python/fes_io.py` (data set, recording, model files, `.hlog`, into pandas) through
//! `python/test_fes_io.py`, and `matlab/load_fes_dataset.m` under octave-cli. The Rust
//! side writes the files and what it knows of them; the other side must read the same.
//! Needs python3 with pandas and hdrhistogram, and octave-cli (scripts/setup installs them).
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, UNIX_EPOCH};

use fes_dataset::{DataSet, Header, Record, Split, WriteMode};
use rt_core::msg::{ForceSample, StimTick};
use rt_core::rt::histogram::LatencyHistogram;
use rt_core::rt::hlog::HlogWriter;
use serde_json::json;
use supervisor::recording::{Recorder, RecorderSettings};

const MS: u64 = 1_000_000;
const T0: u64 = 50_000 * MS;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn scratch(name: &str) -> fes_testkit::Scratch {
    fes_testkit::Scratch::new_in(Path::new(env!("CARGO_TARGET_TMPDIR")), name)
}

/// Three records with awkward values (a kind with a comma, a record with decisions that
/// differ from the deliveries) at 1 ms.
fn dataset() -> DataSet {
    let mut records = Vec::new();
    for i in 0..3usize {
        let n = 40 + 7 * i;
        let pulse: Vec<bool> = (0..n).map(|k| k % (9 + i) == 4).collect();
        let force: Vec<f64> = (0..n)
            .map(|k| 0.45 + 0.5 * ((k as f64) * 0.3 + i as f64).sin() / 3.0)
            .collect();
        let kind = ["random", "constant 40 Hz", "doublet 4 ms, then 25.1 Hz"][i];
        records.push(Record::uniform(
            format!("rec {i}.csv"),
            kind,
            1e-3,
            pulse,
            force,
        ));
    }
    let mut decided = records[1].pulse.clone();
    decided[1] = true;
    records[1].decided = Some(decided);
    DataSet {
        header: Header {
            source: "readers test".into(),
            preset: None,
            parameters: Default::default(),
            seed: None,
            noise: serde_json::Value::Null,
            protocol: serde_json::Value::Null,
            scale_n: 364.25,
            offset_n: 4.5,
            ts_s: 1e-3,
            split: Split {
                train: vec![0, 2],
                test: vec![1],
            },
        },
        records,
    }
}

/// Tick k of the recording: quiet, with a 20 mA x 200 us pulse every 20th tick from 5.
fn tick(k: u64) -> StimTick {
    let t = StimTick::quiet(k + 1, T0 + k * MS);
    if k % 20 == 5 {
        t.firing(0, 20_000, 200)
    } else {
        t
    }
}

fn force(k: u64) -> f64 {
    0.3 + 0.2 * ((k as f64) * 0.01).sin()
}

/// A supervisor recording of 1500 ticks (records of at most 1000): returns its directory
/// and what it holds.
fn recording(root: &Path) -> (PathBuf, serde_json::Value) {
    let settings = RecorderSettings {
        flush_period_ns: 1_000 * MS,
        max_record_ticks: 1000,
        scale_n: 1.0,
        offset_n: 0.0,
        source: "readers test".into(),
        protocol: json!({"test": true}),
        prescription_sha256: None,
    };
    let mut r = Recorder::create(root, "run", settings, T0).unwrap();
    let n = 1500u64;
    let mut force_sum = 0.0;
    for k in 0..n {
        let now = T0 + k * MS + 500_000;
        r.on_stim_tick(&tick(k), now).unwrap();
        let f = force(k);
        force_sum += f;
        r.on_force(
            &ForceSample {
                seq: k + 1,
                t_ns: T0 + k * MS + 300_000,
                stim_seq: k,
                force_n: 364.0 * f + 2.0,
                force: f,
            },
            now,
        )
        .unwrap();
        r.maybe_flush(now).unwrap();
    }
    r.on_event(T0 + n * MS, "operator stop").unwrap();
    r.finish(T0 + (n + 1) * MS).unwrap();
    let dir = root.join("run");
    let ds = DataSet::read(&dir).unwrap();
    let expect = json!({
        "dir": dir,
        "ticks": n,
        "force_samples": n,
        "tick_pulses": (0..n).map(|k| u8::from(k % 20 == 5)).collect::<Vec<_>>(),
        "force_sum": force_sum,
        "records": ds.records.len(),
        "record_samples": ds.records.iter().map(Record::len).collect::<Vec<_>>(),
        "events": std::fs::read_to_string(dir.join("events.jsonl")).unwrap().lines().count(),
        "event_text": "operator stop",
    });
    (dir, expect)
}

/// An .hlog of three intervals, two tags, with known values.
fn hlog(path: &Path) -> serde_json::Value {
    let mut w = HlogWriter::create(
        path,
        "readers test",
        UNIX_EPOCH + Duration::from_secs(1_800_000_000),
    )
    .unwrap();
    let mut intervals = Vec::new();
    for (i, tag) in ["wake", "ipc", "wake"].iter().enumerate() {
        let mut h = LatencyHistogram::new();
        for v in 0..(100 + 50 * i as u64) {
            h.record(10_000 + 37 * v * v);
        }
        w.write(
            &h,
            tag,
            Duration::from_secs(i as u64),
            Duration::from_secs(1),
        )
        .unwrap();
        intervals.push(json!({
            "tag": tag,
            "start_s": i as f64,
            "count": h.count(),
            "max": h.raw().max(),
            "p50": h.raw().value_at_quantile(0.5),
        }));
    }
    w.flush().unwrap();
    json!({"path": path, "intervals": intervals})
}

fn dataset_expect(dir: &Path, ds: &DataSet) -> serde_json::Value {
    let ones = |v: &[bool]| {
        v.iter()
            .enumerate()
            .filter(|(_, p)| **p)
            .map(|(k, _)| k)
            .collect::<Vec<_>>()
    };
    json!({
        "dir": dir,
        "scale_n": ds.header.scale_n,
        "offset_n": ds.header.offset_n,
        "ts_s": ds.header.ts_s,
        "split": {"train": ds.header.split.train, "test": ds.header.split.test},
        "records": ds.records.iter().map(|r| json!({
            "file": r.file,
            "kind": r.kind,
            "samples": r.len(),
            "pulses": r.pulses(),
            "force": r.force,
            "pulse_at": ones(&r.pulse),
            "decided_at": r.decided.as_deref().map(ones),
        })).collect::<Vec<_>>(),
    })
}

#[test]
fn python_reads_data_sets_recordings_models_and_hlogs() {
    let dir = scratch("readers_python");
    let data = dir.join("data");
    let ds = dataset();
    ds.write(&data, WriteMode::CreateNew).unwrap();
    let (_, recording) = recording(&dir.join("recordings"));
    let lmn = repo().join("models/fast.lmn.json");
    let model: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&lmn).unwrap()).unwrap();
    let units = model["units"].as_array().unwrap();
    let lcn = repo().join("models/fast.lcn.json");
    let controller: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&lcn).unwrap()).unwrap();
    let expect = json!({
        "dataset": dataset_expect(&data, &ds),
        "recording": recording,
        "models": {
            "lmn": lmn,
            "lmn_units": units.len(),
            "eigenvalues_0": units.iter().map(|u| u["eigenvalues"][0].clone()).collect::<Vec<_>>(),
            "structure": model["structure"],
            "lcn": lcn,
            "lcn_units": controller["units"].as_array().unwrap().len(),
        },
        "hlog": hlog(&dir.join("rt-core.hlog")),
    });
    let expect_path = dir.join("expect.json");
    std::fs::write(&expect_path, expect.to_string()).unwrap();
    let out = Command::new("python3")
        .arg(repo().join("python/test_fes_io.py"))
        .arg(&expect_path)
        .output()
        .expect("python3 runs (scripts/setup installs it)");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !stderr.contains("No module named"),
        "python3 lacks a module: python3 -m pip install pandas hdrhistogram (scripts/setup does)\n{stderr}"
    );
    assert!(
        out.status.success(),
        "python/test_fes_io.py failed:\n{stderr}"
    );
    assert!(stderr.contains("Ran 5 tests"), "{stderr}");
}

#[test]
fn octave_reads_a_data_set() {
    let dir = scratch("readers_octave");
    let data = dir.join("data");
    let ds = dataset();
    ds.write(&data, WriteMode::CreateNew).unwrap();
    // Octave prints what it read, every number in full; Rust compares.
    let script = format!(
        "addpath('{}'); ds = load_fes_dataset('{}'); \
         printf('records %d train %s test %s scale %.17g\\n', numel(ds.records), mat2str(ds.train), mat2str(ds.test), ds.meta.scale_n); \
         for i = 1:numel(ds.records); r = ds.records(i); \
           printf('%s|%s|%s|%d|%d|%s|%s|%s\\n', r.file, r.kind, r.split, r.samples, r.pulses, \
             mat2str(find(r.pulse)' - 1), mat2str(find(r.decided)' - 1), sprintf('%.17g,', r.force)); \
         end",
        repo().join("matlab").display(),
        data.display()
    );
    let out = Command::new("octave-cli")
        .args(["--no-gui", "--norc", "--quiet", "--eval", &script])
        .output()
        .expect("octave-cli runs (scripts/setup installs Debian's octave)");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "octave: {}\n{stdout}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut lines = stdout.lines();
    assert_eq!(
        lines.next().unwrap(),
        "records 3 train [1 3] test 2 scale 364.25"
    );
    for r in &ds.records {
        let line = lines.next().unwrap();
        let f: Vec<&str> = line.split('|').collect();
        assert_eq!(f[0], r.file);
        assert_eq!(f[1], r.kind);
        assert_eq!(
            f[2],
            if r.file == "rec 1.csv" {
                "test"
            } else {
                "train"
            }
        );
        assert_eq!(f[3], r.len().to_string());
        assert_eq!(f[4], r.pulses().to_string());
        let at = |v: &[bool]| -> Vec<usize> {
            v.iter()
                .enumerate()
                .filter(|(_, p)| **p)
                .map(|(k, _)| k)
                .collect()
        };
        let mat = |k: Vec<usize>| -> String {
            match k.len() {
                1 => k[0].to_string(),
                _ => format!(
                    "[{}]",
                    k.iter().map(usize::to_string).collect::<Vec<_>>().join(" ")
                ),
            }
        };
        assert_eq!(f[5], mat(at(&r.pulse)), "{}", r.file);
        assert_eq!(
            f[6],
            mat(at(r.decided.as_deref().unwrap_or(&r.pulse))),
            "{}",
            r.file
        );
        let force: Vec<f64> = f[7]
            .trim_end_matches(',')
            .split(',')
            .map(|x| x.parse().unwrap())
            .collect();
        assert_eq!(force, r.force, "{}: every value exactly", r.file);
    }
    // A violation is an error naming the file and line.
    let bad = data.join("rec 0.csv");
    let text = std::fs::read_to_string(&bad).unwrap();
    std::fs::write(&bad, text.replacen("\n2,0,", "\n2,0,7", 1)).unwrap();
    let out = Command::new("octave-cli")
        .args(["--no-gui", "--norc", "--quiet", "--eval"])
        .arg(format!(
            "addpath('{}'); load_fes_dataset('{}');",
            repo().join("matlab").display(),
            data.display()
        ))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("rec 0.csv:4: field `force`:") && stderr.contains("is outside [-0.1, 1.1]"),
        "{stderr}"
    );
}
