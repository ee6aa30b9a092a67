//! `fes dataset import` end to end: a sim-muscle data set written out in a
//! foreign layout (time in seconds at 2 kHz, force in mN with the sensor's offset, a 0/1
//! stimulation column, a quoted free-text column, the records concatenated with rests
//! between them) is imported, identified with the same options as the original, and gives
//! the same model. Refusals name the line and column; `--help` teaches with examples.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use crate::analysis_support::assert_close;
use fes_dataset::{DataSet, WriteMode};
use sim_muscle::muscle::{Muscle, MuscleConfig, max_force};
use sim_muscle::plant::MusclePlant;
use sim_muscle::preset::Preset;
use sim_muscle::protocol::ProtocolConfig;
use sim_muscle::recorder::{Origin, record};
use sim_muscle::sensor::{ForceSensor, Measured, SensorConfig};

const BIN: &str = env!("CARGO_BIN_EXE_fes");

fn scratch(name: &str) -> fes_testkit::Scratch {
    fes_testkit::Scratch::new_in(Path::new(env!("CARGO_TARGET_TMPDIR")), name)
}

fn fes(args: &[&str]) -> Output {
    Command::new(BIN).args(args).output().expect("run fes")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// A small sim-muscle data set (fast preset, thesis protocol, 8 records, 4 train).
fn small_recording() -> DataSet {
    let preset = Preset::Fast;
    let protocol = ProtocolConfig {
        records: 8,
        train_records: 4,
        const_every: 4,
        ..ProtocolConfig::thesis(preset)
    };
    let cfg = MuscleConfig::preset(preset);
    let mut muscle = Muscle::new(cfg).unwrap();
    let fmax = max_force(&mut muscle);
    muscle.reset();
    let sensor = SensorConfig::defaults_for(fmax, 3);
    let mut plant = Measured::new(muscle, ForceSensor::new(sensor, cfg.ts_s).unwrap());
    let origin = Origin {
        source: "sim-muscle (dataset_import_cli test)".into(),
        preset: Some(preset.name().into()),
        parameters: cfg.parameters(),
        seed: 3,
        noise: serde_json::Value::Null,
    };
    record(&mut plant, &protocol, origin).unwrap()
}

/// The data set as another lab would export it: one table, `"Time (s)"` at 2 kHz (each
/// record starts a whole second after the previous one), `"Force (mN)"` raw (offset not
/// removed, in millinewtons; the half-millisecond samples are midpoints), `Stim` 0/1, and a
/// quoted `Trial` text with a comma in it.
fn foreign_layout(ds: &DataSet) -> String {
    let (scale, offset) = (ds.header.scale_n, ds.header.offset_n);
    let mn = |f: f64| (f * scale + offset) * 1e3;
    let mut s = String::from("\"Time (s)\",\"Force (mN)\",Stim,Trial\n");
    for (i, r) in ds.records.iter().enumerate() {
        for k in 0..r.len() {
            let t = i as f64 + k as f64 * 1e-3;
            let trial = format!("\"trial {i}, {}\"", r.kind);
            s.push_str(&format!(
                "{t:.4},{},{},{trial}\n",
                mn(r.force[k]),
                u8::from(r.pulse[k])
            ));
            if k + 1 < r.len() {
                let mid = 0.5 * (r.force[k] + r.force[k + 1]);
                s.push_str(&format!("{:.4},{},0,{trial}\n", t + 5e-4, mn(mid)));
            }
        }
    }
    s
}

fn import_args<'a>(input: &'a str, out: &'a str, offset: &'a str, scale: &'a str) -> Vec<&'a str> {
    vec![
        "dataset",
        "import",
        input,
        "--out",
        out,
        "--time-col",
        "Time (s)",
        "--force-col",
        "force (mN)",
        "--force-gain",
        "0.001",
        "--force-offset",
        offset,
        "--force-scale",
        scale,
        "--pulse-col",
        "Stim",
        "--split-gap",
        "0.2",
        "--train-records",
        "4",
    ]
}

fn identify(data: &Path, out: &Path) -> serde_json::Value {
    let o = fes(&[
        "identify",
        "--data",
        data.to_str().unwrap(),
        "--structure",
        "ss-eig-common",
        "--units",
        "2",
        "--zero-offsets",
        "--max-iter",
        "12",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "identify: {}", text(&o.stderr));
    serde_json::from_str(&std::fs::read_to_string(out).unwrap()).unwrap()
}

#[test]
fn a_foreign_layout_of_sim_muscle_data_imports_and_identifies_to_the_same_model() {
    let dir = scratch("dataset_import_round_trip");
    let original = small_recording();
    let orig_dir = dir.join("original");
    original.write(&orig_dir, WriteMode::CreateNew).unwrap();
    let csv = dir.join("lab export.csv");
    std::fs::write(&csv, foreign_layout(&original)).unwrap();
    let imported_dir = dir.join("imported");
    let (offset, scale) = (
        original.header.offset_n.to_string(),
        original.header.scale_n.to_string(),
    );
    let o = fes(&import_args(
        csv.to_str().unwrap(),
        imported_dir.to_str().unwrap(),
        &offset,
        &scale,
    ));
    assert!(o.status.success(), "import: {}", text(&o.stderr));
    let out = text(&o.stdout);
    assert!(out.contains("records        8 (4 train, 4 test)"), "{out}");
    assert!(out.contains("moved at most 0.000 ms"), "{out}");

    // The data sets agree: records, split, pulses exactly; force to rounding.
    let back = DataSet::read(&imported_dir).unwrap();
    assert_eq!(back.records.len(), original.records.len());
    assert_eq!(back.header.split, original.header.split);
    assert_eq!(back.header.scale_n, original.header.scale_n);
    assert_eq!(back.header.offset_n, original.header.offset_n);
    for (a, b) in back.records.iter().zip(&original.records) {
        assert_eq!(a.len(), b.len(), "{}", b.file);
        assert_eq!(a.pulse, b.pulse, "{}", b.file);
        assert_eq!(a.t_ms, b.t_ms, "{}", b.file);
        for (k, (x, y)) in a.force.iter().zip(&b.force).enumerate() {
            assert!((x - y).abs() < 1e-9, "{} sample {k}: {x} vs {y}", b.file);
        }
    }

    // The same identification on both gives the same model.
    let m_orig = identify(&orig_dir, &dir.join("original.lmn.json"));
    let m_imp = identify(&imported_dir, &dir.join("imported.lmn.json"));
    assert_close(&m_orig, &m_imp, 1e-6, "model");
    let msse = |m: &serde_json::Value| m["provenance"]["train_msse"].as_f64().unwrap();
    assert!((msse(&m_orig) - msse(&m_imp)).abs() <= 1e-6 * msse(&m_orig));

    // With the offset and scale estimated, the importer finds sim-muscle's own (the
    // offset from the rest before each first pulse, the scale from the largest sample):
    // equal to rounding, since the midpoints are never above the samples' maximum.
    let auto_dir = dir.join("auto");
    let o = fes(&import_args(
        csv.to_str().unwrap(),
        auto_dir.to_str().unwrap(),
        "auto",
        "auto",
    ));
    assert!(o.status.success(), "import auto: {}", text(&o.stderr));
    let auto = DataSet::read(&auto_dir).unwrap();
    // The rest samples include the 2 kHz midpoints, so the offset differs by a fraction of
    // the noise (1.4 N here); the peak force, offset plus scale, is the same sample.
    let (a, b) = (&auto.header, &original.header);
    assert!(
        (a.offset_n - b.offset_n).abs() < 0.5,
        "{} vs {}",
        a.offset_n,
        b.offset_n
    );
    let peak = |h: &fes_dataset::Header| h.offset_n + h.scale_n;
    assert!((peak(a) - peak(b)).abs() < 1e-9 * peak(b));
    let max = auto
        .records
        .iter()
        .flat_map(|r| r.force.iter().copied())
        .fold(f64::MIN, f64::max);
    assert!((max - 1.0).abs() < 1e-12, "{max}");
    // An existing data set is not overwritten without --force.
    let o = fes(&import_args(
        csv.to_str().unwrap(),
        auto_dir.to_str().unwrap(),
        "auto",
        "auto",
    ));
    assert_eq!(o.status.code(), Some(1));
    assert!(
        text(&o.stderr).contains("exists and is not empty"),
        "{}",
        text(&o.stderr)
    );
}

#[test]
fn import_refusals_name_the_line_and_column_and_help_has_examples() {
    let dir = scratch("dataset_import_refusals");
    let csv: PathBuf = dir.join("in.csv");
    let mut s = String::from("t,F,stim\n");
    for r in 0..2 {
        for k in 0..40 {
            let t = r as f64 * 10.0 + k as f64 * 0.0004;
            // Two samples 0.4 ms apart, at 4.8 and 5.2 ms, are both pulses (lines 14 and
            // 15): one tick.
            let p = r == 0 && (k == 12 || k == 13);
            s.push_str(&format!(
                "{t:.4},{},{}\n",
                1.0 + 0.01 * k as f64,
                u8::from(p)
            ));
        }
    }
    std::fs::write(&csv, &s).unwrap();
    let out = dir.join("out");
    let args = |extra: &[&'static str]| -> Output {
        let mut a = vec![
            "dataset",
            "import",
            csv.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--time-col",
            "t",
            "--force-col",
            "F",
            "--pulse-col",
            "stim",
            "--split-gap",
            "1",
            "--force-offset",
            "1",
            "--force-scale",
            "1",
        ];
        a.extend_from_slice(extra);
        fes(&a)
    };
    let o = args(&[]);
    assert_eq!(o.status.code(), Some(1));
    let e = text(&o.stderr);
    assert!(
        e.contains("in.csv:15: column 3 `stim`: the pulse at t = 0.0052 s falls on the same 1 ms tick (record 0, sample 5) as the pulse of line 14"),
        "{e}"
    );
    assert!(!out.exists(), "nothing written on a refusal");
    // As edges they are one pulse.
    let o = args(&["--pulse-edges"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let ds = DataSet::read(&out).unwrap();
    assert_eq!(ds.records[0].pulses(), 1);
    // A column that is not there; the usage errors are clap's (exit 2).
    let o = fes(&[
        "dataset",
        "import",
        csv.to_str().unwrap(),
        "--out",
        dir.join("x").to_str().unwrap(),
        "--time-col",
        "time",
        "--force-col",
        "F",
        "--pulse-col",
        "stim",
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        text(&o.stderr)
            .contains("time column `time`: no such column; the columns are 1 `t`, 2 `F`, 3 `stim`"),
        "{}",
        text(&o.stderr)
    );
    let o = fes(&[
        "dataset",
        "import",
        "x.csv",
        "--out",
        "y",
        "--force-col",
        "F",
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    let o = fes(&["dataset", "import", "--help"]);
    assert!(o.status.success());
    let help = text(&o.stdout);
    for key in [
        "EXAMPLES",
        "--split-gap",
        "--pulse-times",
        "--force-scale",
        "auto",
    ] {
        assert!(help.contains(key), "{key} missing from --help");
    }
}

/// The README's "Use your own data" commands, as written there (with this build's `fes`
/// for `target/release/fes` and a scratch directory for `target/mine`), on the committed
/// `examples/lab-export.csv`: a CSV becomes a data set, a model, an analysis and a
/// controller file.
#[test]
fn the_readme_use_your_own_data_commands_run() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let readme = std::fs::read_to_string(repo.join("README.md")).unwrap();
    let section = readme
        .split("## Use your own data")
        .nth(1)
        .and_then(|s| s.split("```").nth(1))
        .expect("README has the section and its code block");
    let joined = section.replace("\\\n", " ");
    let commands: Vec<&str> = joined
        .lines()
        .map(str::trim)
        .filter(|l| l.starts_with("target/release/fes "))
        .collect();
    assert_eq!(commands.len(), 4, "{section}");
    let dir = scratch("readme_own_data");
    let mine = dir.join("mine");
    for c in commands {
        let args: Vec<String> = c
            .split_whitespace()
            .skip(1)
            .map(|a| a.replace("target/mine", mine.to_str().unwrap()))
            .collect();
        let o = Command::new(BIN)
            .args(&args)
            .current_dir(&repo)
            .output()
            .unwrap();
        assert!(o.status.success(), "{c}\n{}", text(&o.stderr));
    }
    let ds = DataSet::read(mine.join("data")).unwrap();
    assert_eq!(ds.records.len(), 20);
    assert_eq!(ds.header.split.train.len(), 10);
    let lcn: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(mine.join("mine.lcn.json")).unwrap())
            .unwrap();
    assert_eq!(lcn["schema"], "fes-lcn/1");
    assert!(mine.join("analysis/report.md").exists());
}

/// `fes dataset merge`: two recordings become one data set that reads back with every
/// record and the union of the splits; a set on another force scale is refused (exit 1,
/// the message naming the set and the way to record it on one scale) and nothing is
/// written; fewer than two sets is a usage error (exit 2).
#[test]
fn merge_joins_recordings_and_refuses_another_scale() {
    let s = scratch("merge");
    let a = small_recording();
    let mut b = small_recording();
    b.records.truncate(6);
    b.header.split = fes_dataset::Split::first(2, 6);
    let (da, db, out) = (s.join("a"), s.join("b"), s.join("ab"));
    a.write(&da, WriteMode::CreateNew).unwrap();
    b.write(&db, WriteMode::CreateNew).unwrap();
    let path = |p: &Path| p.to_str().unwrap().to_owned();
    let o = fes(&[
        "dataset",
        "merge",
        &path(&da),
        &path(&db),
        "--out",
        &path(&out),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let m = DataSet::read(&out).unwrap();
    assert_eq!(m.records.len(), 14);
    assert_eq!(m.header.split.train, vec![0, 1, 2, 3, 8, 9]);
    assert_eq!(m.records[13].force, b.records[5].force);
    assert_eq!(m.header.protocol["sets"][1]["first_record"], 8);
    // Another force scale: refused, nothing written.
    let mut c = b.clone();
    c.header.scale_n *= 1.5;
    let (dc, bad) = (s.join("c"), s.join("ac"));
    c.write(&dc, WriteMode::CreateNew).unwrap();
    let o = fes(&[
        "dataset",
        "merge",
        &path(&da),
        &path(&dc),
        "--out",
        &path(&bad),
    ]);
    assert_eq!(o.status.code(), Some(1));
    let err = text(&o.stderr);
    assert!(
        err.contains(&path(&dc)) && err.contains("--scale-from"),
        "{err}"
    );
    assert!(!bad.exists());
    let o = fes(&["dataset", "merge", &path(&da), "--out", &path(&bad)]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
}
