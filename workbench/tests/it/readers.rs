//! The readers for other languages against files the workbench writes:
//! `python/fes_io.py` (data set, recording, model files, `.hlog`, into pandas) through
//! `python/test_fes_io.py`, and `matlab/load_fes_dataset.m` under octave-cli. The Rust
//! side writes the files and what it knows of them; the other side must read the same.
//! Both data-set versions: `fes-dataset/1` (pulses and force) and `fes-dataset/2` (the
//! heat-transfer experiments of `sim-heat`, named continuous channels at 50 ms), and for
//! version 2 every way of breaking it that the Rust reader refuses.
//! Needs python3 with pandas and hdrhistogram, and octave-cli (scripts/setup installs them).
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, UNIX_EPOCH};

use fes_dataset::signals::SignalSet;
use fes_dataset::{DataSet, Header, Record, Split, WriteMode};
use fes_rt::msg::{ForceSample, StimTick};
use fes_rt::rt::histogram::LatencyHistogram;
use fes_rt::rt::hlog::HlogWriter;
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

/// The heat-transfer experiments of thesis App. E.2 as `sim-heat` writes them (seed 1):
/// a `fes-dataset/2` data set, inputs `alpha` and `u`, output `y`, Ts = 50 ms.
fn heat_dataset() -> SignalSet {
    sim_heat::experiment::dataset(&sim_heat::HeatParams::default(), 1).unwrap()
}

/// What the Rust side knows of a `fes-dataset/2` data set: header, records and every
/// value by channel name.
fn signals_expect(dir: &Path, s: &SignalSet) -> serde_json::Value {
    let h = &s.header;
    let names: Vec<&str> = h
        .inputs
        .iter()
        .chain(&h.outputs)
        .map(|c| c.name.as_str())
        .collect();
    json!({
        "dir": dir,
        "source": h.source,
        "seed": h.seed,
        "ts_s": h.ts_s,
        "inputs": h.inputs,
        "outputs": h.outputs,
        "split": {"train": h.split.train, "test": h.split.test},
        "records": s.records.iter().map(|r| json!({
            "file": r.file,
            "kind": r.kind,
            "samples": r.len(),
            "t0_s": r.t0_s,
            "values": names
                .iter()
                .zip(r.inputs.iter().chain(&r.outputs))
                .map(|(n, v)| (n.to_string(), json!(v)))
                .collect::<serde_json::Map<_, _>>(),
        })).collect::<Vec<_>>(),
    })
}

/// One way to break a `fes-dataset/2` data set, and what a reader must say about it.
struct Violation {
    /// Directory name of the broken copy.
    name: &'static str,
    /// Texts the error message must contain (file and line first).
    expect: Vec<String>,
    /// Whether the Octave reader checks it too (UTF-8 and JSON syntax are Python's only,
    /// as for version 1: Octave's jsondecode reports its own).
    octave: bool,
}

fn edit_meta(dir: &Path, f: impl FnOnce(&mut serde_json::Value)) {
    let path = dir.join("dataset.json");
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    f(&mut v);
    std::fs::write(&path, serde_json::to_string_pretty(&v).unwrap()).unwrap();
}

/// Edits the fields of line `line` (1 = header) of a record file.
fn edit_line(dir: &Path, file: &str, line: usize, f: impl FnOnce(&mut Vec<String>)) {
    let path = dir.join(file);
    let text = std::fs::read_to_string(&path).unwrap();
    let mut lines: Vec<String> = text.split('\n').map(str::to_string).collect();
    let mut fields: Vec<String> = lines[line - 1].split(',').map(str::to_string).collect();
    f(&mut fields);
    lines[line - 1] = fields.join(",");
    std::fs::write(&path, lines.join("\n")).unwrap();
}

/// Copies of a small heat-transfer data set (every record cut to 40 samples), each broken
/// in one of the ways the Rust reader refuses, under `root`; returns the directories and
/// what the readers must say.
fn violations(root: &Path) -> Vec<(PathBuf, Violation)> {
    let mut small = heat_dataset();
    for r in &mut small.records {
        for c in r.inputs.iter_mut().chain(r.outputs.iter_mut()) {
            c.truncate(40);
        }
    }
    let base = root.join("base");
    small.write(&base, WriteMode::CreateNew).unwrap();
    SignalSet::read(&base).unwrap();
    let f0 = small.records[0].file.clone();
    let f1 = small.records[1].file.clone();
    type Edit = Box<dyn FnOnce(&Path)>;
    let meta = |f: fn(&mut serde_json::Value)| -> Edit { Box::new(move |d| edit_meta(d, f)) };
    let line = |l: usize, f: fn(&mut Vec<String>)| -> Edit {
        let file = f0.clone();
        Box::new(move |d| edit_line(d, &file, l, f))
    };
    let at = |l: usize, rest: &str| format!("{f0}:{l}: {rest}");
    let cases: Vec<(&'static str, Edit, Vec<String>, bool)> = vec![
        (
            "schema",
            meta(|v| v["schema"] = json!("fes-dataset/9")),
            vec![
                r#"field `schema` is "fes-dataset/9", expected one of "fes-dataset/1", "fes-dataset/2""#
                    .into(),
            ],
            true,
        ),
        (
            "missing",
            meta(|v| {
                v.as_object_mut().unwrap().remove("ts_s");
            }),
            vec!["missing field `ts_s`".into()],
            true,
        ),
        (
            "unknown",
            meta(|v| v["colour"] = json!("red")),
            vec!["unknown field `colour`".into()],
            true,
        ),
        (
            "period",
            meta(|v| v["ts_s"] = json!(0)),
            vec!["field `ts_s`: 0 is not a sample period > 0 s".into()],
            true,
        ),
        (
            "no-outputs",
            meta(|v| v["outputs"] = json!([])),
            vec!["field `outputs`: at least one channel is needed".into()],
            true,
        ),
        (
            "name",
            meta(|v| v["inputs"][1]["name"] = json!("u v")),
            vec!["field `inputs[1].name`: `u v` is not a column name".into()],
            true,
        ),
        (
            "repeat",
            meta(|v| v["outputs"][0]["name"] = json!("alpha")),
            vec!["field `outputs[0].name`: `alpha` repeats (or is `t_s`)".into()],
            true,
        ),
        (
            "time-name",
            meta(|v| v["inputs"][0]["name"] = json!("t_s")),
            vec!["field `inputs[0].name`: `t_s` repeats (or is `t_s`)".into()],
            true,
        ),
        (
            "range",
            meta(|v| v["outputs"][0]["range"] = json!([5, 5])),
            vec![
                "field `outputs[0].range`: [5, 5] is not a finite, non-empty range".into(),
            ],
            true,
        ),
        (
            "one-record",
            meta(|v| {
                v["records"].as_array_mut().unwrap().truncate(1);
                v["split"] = json!({"train": [0], "test": [0]});
            }),
            vec!["field `records`: 1 record(s); a data set needs at least 2".into()],
            true,
        ),
        (
            "empty-split",
            meta(|v| v["split"]["test"] = json!([])),
            vec!["field `split.test`: the test split is empty".into()],
            true,
        ),
        (
            "out-of-range",
            meta(|v| v["split"]["train"].as_array_mut().unwrap().push(json!(99))),
            vec![
                "field `split.train`: record index 99 is out of range (there are 9 records)"
                    .into(),
            ],
            true,
        ),
        (
            "repeated-index",
            meta(|v| v["split"]["train"].as_array_mut().unwrap().push(json!(0))),
            vec!["field `split.train`: record index 0 repeats".into()],
            true,
        ),
        (
            "both",
            meta(|v| v["split"]["test"].as_array_mut().unwrap().push(json!(0))),
            vec!["field `split`: record 0 is in both train and test".into()],
            true,
        ),
        (
            "path",
            meta(|v| v["records"][1]["file"] = json!("../x.csv")),
            vec!["field `records[1].file`: `../x.csv` is not a plain file name".into()],
            true,
        ),
        (
            "twice",
            Box::new({
                let f0 = f0.clone();
                move |d: &Path| edit_meta(d, |v| v["records"][1]["file"] = json!(f0))
            }),
            vec![format!("field `records[1].file`: `{f0}` is listed twice")],
            true,
        ),
        (
            "count",
            meta(|v| v["records"][0]["samples"] = json!(41)),
            vec![format!("{f0}: samples is 40, but dataset.json lists 41")],
            true,
        ),
        (
            "header",
            line(1, |f| f.swap(1, 2)),
            vec![at(1, "field `header`: `t_s,u,alpha,y` does not name the channels of dataset.json: expected `t_s,alpha,u,y`")],
            true,
        ),
        (
            "columns",
            line(5, |f| {
                f.pop();
            }),
            vec![at(5, "3 field(s), expected 4 (as the header)")],
            true,
        ),
        (
            "not-a-number",
            line(4, |f| f[3] = "abc".into()),
            vec![at(4, "field `y`: `abc` is not a number")],
            true,
        ),
        (
            "underscore",
            line(4, |f| f[3] = "1_0".into()),
            vec![at(4, "field `y`: `1_0` is not a number")],
            true,
        ),
        (
            "not-finite",
            line(4, |f| f[1] = "inf".into()),
            vec![at(4, "field `alpha`: inf is not finite")],
            true,
        ),
        (
            "time-not-finite",
            line(4, |f| f[0] = "NaN".into()),
            vec![at(4, "field `t_s`: NaN is not finite")],
            true,
        ),
        (
            "step",
            line(4, |f| f[0] = "0.12".into()),
            vec![at(4, "field `t_s`: step "), "differs from ts_s = 0.05 s".into()],
            true,
        ),
        (
            "short",
            Box::new({
                let f1 = f1.clone();
                move |d: &Path| {
                    let path = d.join(&f1);
                    let text = std::fs::read_to_string(&path).unwrap();
                    let kept: Vec<&str> = text.lines().take(2).collect();
                    std::fs::write(&path, kept.join("\n") + "\n").unwrap();
                    edit_meta(d, |v| v["records"][1]["samples"] = json!(1));
                }
            }),
            vec![format!("{f1}: 1 sample(s); a record needs at least 2")],
            true,
        ),
        (
            "utf8",
            Box::new({
                let f0 = f0.clone();
                move |d: &Path| {
                    let path = d.join(&f0);
                    let mut bytes = std::fs::read(&path).unwrap();
                    let third = bytes
                        .iter()
                        .enumerate()
                        .filter(|(_, b)| **b == b'\n')
                        .nth(1)
                        .unwrap()
                        .0;
                    bytes.insert(third + 1, 0xff);
                    std::fs::write(&path, bytes).unwrap();
                }
            }),
            vec![at(3, "not UTF-8 text")],
            false,
        ),
        (
            "json",
            Box::new(|d: &Path| {
                let path = d.join("dataset.json");
                let text = std::fs::read_to_string(&path).unwrap();
                std::fs::write(&path, text.replacen('{', "{,", 1)).unwrap();
            }),
            vec!["dataset.json:1:".into()],
            false,
        ),
    ];
    let mut out = Vec::new();
    for (name, edit, expect, octave) in cases {
        let dir = root.join(name);
        std::fs::create_dir_all(&dir).unwrap();
        for e in std::fs::read_dir(&base).unwrap() {
            let e = e.unwrap();
            std::fs::copy(e.path(), dir.join(e.file_name())).unwrap();
        }
        edit(&dir);
        // The Rust reader refuses every one of them: the readers are held to the format,
        // not to what some reader happens to accept.
        let rust = fes_dataset::signals::read_any(&dir);
        assert!(rust.is_err(), "{name}: the Rust reader accepts it");
        out.push((
            dir,
            Violation {
                name,
                expect,
                octave,
            },
        ));
    }
    out
}

#[test]
fn python_reads_data_sets_recordings_models_and_hlogs() {
    let dir = scratch("readers_python");
    let data = dir.join("data");
    let ds = dataset();
    ds.write(&data, WriteMode::CreateNew).unwrap();
    let (_, recording) = recording(&dir.join("recordings"));
    let heat = dir.join("heat");
    heat_dataset().write(&heat, WriteMode::CreateNew).unwrap();
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
        "signals": signals_expect(&heat, &heat_dataset()),
        "violations": violations(&dir.join("broken")).iter().map(|(d, v)| json!({
            "name": v.name,
            "dir": d,
            "expect": v.expect,
        })).collect::<Vec<_>>(),
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
    assert!(stderr.contains("Ran 7 tests"), "{stderr}");
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

/// Octave's `printf('%s', sprintf('%.17g,', v))` of a column, parsed back.
fn numbers(text: &str) -> Vec<f64> {
    text.trim_end_matches(',')
        .split(',')
        .map(|x| x.parse().unwrap())
        .collect()
}

#[test]
fn octave_reads_a_signal_data_set() {
    let dir = scratch("readers_octave_v2");
    let data = dir.join("heat");
    let set = heat_dataset();
    set.write(&data, WriteMode::CreateNew).unwrap();
    let script = format!(
        "addpath('{}'); ds = load_fes_dataset('{}'); \
         printf('schema %s ts %.17g train %s test %s\\n', ds.meta.schema, ds.ts_s, mat2str(ds.train), mat2str(ds.test)); \
         for k = 1:numel(ds.channels); c = ds.channels(k); \
           printf('channel %s|%s|%s|%s|%s\\n', c.name, c.field, c.role, c.unit, sprintf('%.17g,', c.range)); \
         end; \
         for i = 1:numel(ds.records); r = ds.records(i); \
           t = r.t0_s + (0:r.samples - 1)' * ds.ts_s; \
           printf('record %s|%s|%s|%d|%.17g|%d\\n', r.file, r.kind, r.split, r.samples, r.t0_s, isequal(r.t_s, t)); \
           for k = 1:numel(ds.channels); \
             printf('%s|%d|%s\\n', ds.channels(k).name, isequal(r.values(:, k), r.signals.(ds.channels(k).field)), \
                    sprintf('%.17g,', r.signals.(ds.channels(k).field))); \
           end; \
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
        "octave: {}\n{}",
        String::from_utf8_lossy(&out.stderr),
        &stdout[..stdout.len().min(2000)]
    );
    let h = &set.header;
    let mut lines = stdout.lines();
    let ones = |v: &[usize]| {
        format!(
            "[{}]",
            v.iter()
                .map(|i| (i + 1).to_string())
                .collect::<Vec<_>>()
                .join(" ")
        )
    };
    assert_eq!(
        lines.next().unwrap(),
        format!(
            "schema fes-dataset/2 ts 0.050000000000000003 train {} test {}",
            ones(&h.split.train),
            ones(&h.split.test)
        )
    );
    let channels: Vec<_> = h
        .inputs
        .iter()
        .map(|c| (c, "input"))
        .chain(h.outputs.iter().map(|c| (c, "output")))
        .collect();
    for (c, role) in &channels {
        let line = lines.next().unwrap();
        let f: Vec<&str> = line.strip_prefix("channel ").unwrap().split('|').collect();
        assert_eq!(
            &f[..4],
            &[c.name.as_str(), c.name.as_str(), *role, c.unit.as_str()]
        );
        assert_eq!(numbers(f[4]), c.range.unwrap().to_vec(), "{}", c.name);
    }
    for (i, r) in set.records.iter().enumerate() {
        let line = lines.next().unwrap();
        let f: Vec<&str> = line.strip_prefix("record ").unwrap().split('|').collect();
        let split = if h.split.train.contains(&i) {
            "train"
        } else {
            "test"
        };
        assert_eq!(
            f[..4],
            [
                r.file.as_str(),
                r.kind.as_str(),
                split,
                &r.len().to_string()
            ]
        );
        assert_eq!(f[4].parse::<f64>().unwrap(), r.t0_s);
        assert_eq!(f[5], "1", "{}: t_s = t0_s + k ts_s", r.file);
        for ((c, _), v) in channels.iter().zip(r.inputs.iter().chain(&r.outputs)) {
            let line = lines.next().unwrap();
            let f: Vec<&str> = line.split('|').collect();
            assert_eq!(f[0], c.name);
            assert_eq!(f[1], "1", "{}: values and signals agree", r.file);
            assert_eq!(
                &numbers(f[2]),
                v,
                "{} {}: every value exactly",
                r.file,
                c.name
            );
        }
    }
    assert_eq!(lines.next(), None);
}

#[test]
fn octave_refuses_what_the_rust_reader_refuses() {
    let dir = scratch("readers_octave_v2_bad");
    let cases = violations(&dir);
    let mut script = format!("addpath('{}');", repo().join("matlab").display());
    for (d, v) in cases.iter().filter(|(_, v)| v.octave) {
        script.push_str(&format!(
            " try; load_fes_dataset('{}'); printf('{}\\taccepted\\n'); \
              catch err; printf('{}\\t%s\\n', strrep(err.message, char(10), ' ')); end;",
            d.display(),
            v.name,
            v.name
        ));
    }
    let out = Command::new("octave-cli")
        .args(["--no-gui", "--norc", "--quiet", "--eval", &script])
        .output()
        .expect("octave-cli runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "octave: {}\n{stdout}",
        String::from_utf8_lossy(&out.stderr)
    );
    let said: std::collections::BTreeMap<&str, &str> =
        stdout.lines().filter_map(|l| l.split_once('\t')).collect();
    let mut checked = 0;
    for (d, v) in cases.iter().filter(|(_, v)| v.octave) {
        let message = said.get(v.name).copied().unwrap_or("(nothing)");
        for e in &v.expect {
            assert!(
                message.contains(e.as_str()),
                "{}: `{message}` lacks `{e}`",
                v.name
            );
        }
        // The message names the file: dataset.json or the record file.
        assert!(
            message.contains(&d.display().to_string()),
            "{}: {message}",
            v.name
        );
        checked += 1;
    }
    assert_eq!(checked, 25);
}
