//! `fes identify / sweep / compare` end to end, bad inputs, and the acceptance ratios
//! of the common-eigenvector network against the linear delta model on the sim-muscle
//! `fast` and `slow` data sets (thesis protocol, seed 1), recorded here with sim-muscle's
//! library exactly as `sim-muscle record --preset P --seed 1` does.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use fes_dataset::{DataSet, WriteMode};
use fes_ident::ident::{Hooks, IdentOptions, RecordSet, identify};
use fes_model::model::{Structure, file};
use sim_muscle::muscle::{Muscle, MuscleConfig, max_force};
use sim_muscle::plant::MusclePlant;
use sim_muscle::preset::Preset;
use sim_muscle::protocol::ProtocolConfig;
use sim_muscle::recorder::{Normalise, Origin, record_normalised};
use sim_muscle::sensor::{ForceSensor, Measured, SensorConfig};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

const BIN: &str = env!("CARGO_BIN_EXE_fes");

fn tmp(name: &str) -> fes_testkit::Scratch {
    fes_testkit::Scratch::new_in(Path::new(env!("CARGO_TARGET_TMPDIR")), name)
}

/// The data set `sim-muscle record --preset <preset> --seed <seed>` writes.
fn record_preset(preset: Preset, seed: u64) -> DataSet {
    record_protocol(
        preset,
        seed,
        &ProtocolConfig::thesis(preset),
        Normalise::Peak,
    )
}

/// The data set `sim-muscle record --preset <preset> --seed <seed>` writes with `protocol`
/// and the scale chosen by `norm` (`--scale-from`).
fn record_protocol(
    preset: Preset,
    seed: u64,
    protocol: &ProtocolConfig,
    norm: Normalise,
) -> DataSet {
    let cfg = MuscleConfig::preset(preset);
    let mut muscle = Muscle::new(cfg).expect("preset muscle");
    let fmax = max_force(&mut muscle);
    muscle.reset();
    let sensor = SensorConfig::defaults_for(fmax, seed);
    let mut plant = Measured::new(muscle, ForceSensor::new(sensor, cfg.ts_s).expect("sensor"));
    let origin = Origin {
        source: "sim-muscle (ident_cli test)".into(),
        preset: Some(preset.name().into()),
        parameters: cfg.parameters(),
        seed,
        noise: serde_json::Value::Null,
    };
    record_normalised(&mut plant, protocol, origin, norm).expect("record")
}

/// The fast and slow data sets, recorded once per test binary.
fn data_dir(preset: Preset) -> &'static Path {
    static FAST: OnceLock<PathBuf> = OnceLock::new();
    static SLOW: OnceLock<PathBuf> = OnceLock::new();
    static THESIS_FAST: OnceLock<PathBuf> = OnceLock::new();
    let cell = match preset {
        Preset::Fast => &FAST,
        Preset::Slow => &SLOW,
        Preset::ThesisFast => &THESIS_FAST,
    };
    cell.get_or_init(|| {
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
            .join("ident_cli_data")
            .join(preset.name());
        let ds = record_preset(preset, 1);
        ds.write(&dir, WriteMode::Overwrite)
            .expect("write data set");
        dir
    })
}

/// The shipped models, `models/` at the workspace root.
fn models_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../models")
}

fn run(args: &[&str]) -> Output {
    Command::new(BIN)
        .args(args)
        .output()
        .expect("run supervisor")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// A small valid data set written by hand: `n` records of 200 ms, every pulse 20 ms apart.
fn small_dataset(dir: &Path, n: usize) {
    let mut records = Vec::new();
    let mut entries = Vec::new();
    for i in 0..n {
        let name = format!("r{i}.csv");
        let mut csv = String::from("t_ms,pulse,force\n");
        let mut pulses = 0;
        for k in 0..200 {
            let p = k >= 10 && k % 20 == 10;
            pulses += usize::from(p);
            let f = if k > 17 {
                0.2 + 0.1 * ((k as f64) / 13.0).sin()
            } else {
                0.0
            };
            csv.push_str(&format!("{k},{},{f}\n", u8::from(p)));
        }
        std::fs::write(dir.join(&name), csv).expect("write csv");
        entries.push(format!(
            r#"{{"file": "{name}", "kind": "random", "samples": 200, "pulses": {pulses}}}"#
        ));
        records.push(i);
    }
    let (train, test): (Vec<usize>, Vec<usize>) = records.iter().partition(|&&i| i + 1 < n.max(2));
    let json = format!(
        r#"{{"schema": "fes-dataset/1", "source": "test", "scale_n": 10.0, "offset_n": 0.0, "ts_s": 0.001,
            "split": {{"train": {train:?}, "test": {test:?}}}, "records": [{}]}}"#,
        entries.join(",")
    );
    std::fs::write(dir.join("dataset.json"), json).expect("write meta");
}

#[test]
fn identify_writes_a_loadable_model_with_provenance() {
    let dir = tmp("identify_ok");
    let data = dir.join("data");
    std::fs::create_dir_all(&data).expect("dir");
    small_dataset(&data, 4);
    let out = dir.join("m.lmn.json");
    let o = run(&[
        "identify",
        "--data",
        data.to_str().expect("utf8"),
        "--structure",
        "ss-eig-common",
        "--units",
        "2",
        "--max-iter",
        "15",
        "--out",
        out.to_str().expect("utf8"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    for key in ["train MSSE", "test MSSE", "iterations", "fit time"] {
        assert!(text.contains(key), "{key} missing from:\n{text}");
    }
    let lmn = file::load(&out).expect("the model loads with the stability check");
    assert_eq!(lmn.structure(), Structure::SsEigCommon);
    let p = &lmn.provenance;
    assert!(p.train_msse.is_some() && p.test_msse.is_some() && p.fit_seconds.is_some());
    for key in ["data_set", "seed", "structure", "options", "tool"] {
        assert!(p.extra.contains_key(key), "provenance lacks {key}");
    }
    // Prediction mode, ARX at 5 ms, global learning: MSPE is reported.
    let out2 = dir.join("arx.lmn.json");
    let o = run(&[
        "identify",
        "--data",
        data.to_str().expect("utf8"),
        "--structure",
        "arx-shift",
        "--ts-ms",
        "5",
        "--mode",
        "prediction",
        "--learning",
        "global",
        "--units",
        "3",
        "--out",
        out2.to_str().expect("utf8"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (lmn, _) = file::load_allow_unstable(&out2).expect("load");
    assert_eq!(lmn.ts, 5e-3);
    assert_eq!(lmn.delay, 2, "10 ms delay at 5 ms (Fig. 5.6)");
    assert!(lmn.provenance.train_mspe.is_some());
}

/// `fes identify --validation DIR`: the traces and the residual tests as CSV and a figure;
/// the fit and RRSE in the provenance are what the written traces give when recomputed
/// here from the CSV (MATLAB's definition), and the summary prints them.
#[test]
fn identify_writes_the_fields_validation_figures() {
    let dir = tmp("identify_validation");
    let data = dir.join("data");
    std::fs::create_dir_all(&data).expect("dir");
    small_dataset(&data, 4);
    let out = dir.join("m.lmn.json");
    let val = dir.join("validation");
    let o = run(&[
        "identify",
        "--data",
        data.to_str().expect("utf8"),
        "--structure",
        "ss-eig-common",
        "--units",
        "2",
        "--max-iter",
        "15",
        "--out",
        out.to_str().expect("utf8"),
        "--validation",
        val.to_str().expect("utf8"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    assert!(
        text.contains("fit (NRMSE)") && text.contains("resid (99 %)"),
        "{text}"
    );
    let p = file::load(&out).expect("model").provenance;
    let test_fit = p.extra["test_fit_percent"]
        .as_f64()
        .expect("test_fit_percent");
    let test_rrse = p.extra["test_rrse"].as_f64().expect("test_rrse");
    assert!(p.extra["train_fit_percent"].is_f64());
    assert_eq!(p.extra["test_resid"]["lags"], 25);
    // Recompute from the written traces: fit = 100 (1 - ||y - yh|| / ||y - mean y||).
    let csv = std::fs::read_to_string(val.join("traces_test.csv")).expect("traces");
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some("record,t_ms,measured,simulated"));
    let (y, yh): (Vec<f64>, Vec<f64>) = lines
        .map(|l| {
            let f: Vec<f64> = l.split(',').map(|v| v.parse().expect("number")).collect();
            (f[2], f[3])
        })
        .unzip();
    let mean = y.iter().sum::<f64>() / y.len() as f64;
    let num: f64 = y.iter().zip(&yh).map(|(a, b)| (a - b).powi(2)).sum();
    let den: f64 = y.iter().map(|a| (a - mean).powi(2)).sum();
    let rrse = (num / den).sqrt();
    assert!(
        (rrse - test_rrse).abs() < 1e-9 * rrse.max(1.0),
        "{rrse} vs {test_rrse}"
    );
    assert!((100.0 * (1.0 - rrse) - test_fit).abs() < 1e-7);
    let resid = std::fs::read_to_string(val.join("resid.csv")).expect("resid.csv");
    assert_eq!(resid.lines().count(), 1 + 51, "header + lags -25..25");
    assert!(
        resid.lines().nth(26).expect("lag 0").starts_with("0,1,"),
        "r_ee(0) = 1"
    );
    let png = std::fs::read(val.join("resid.png")).expect("resid.png");
    assert_eq!(&png[..4], b"\x89PNG");
    assert!(val.join("traces_train.csv").exists());
    // The figure as SVG when asked.
    let svg_dir = dir.join("validation-svg");
    let o = run(&[
        "identify",
        "--data",
        data.to_str().expect("utf8"),
        "--structure",
        "ss-eig-common",
        "--units",
        "1",
        "--max-iter",
        "5",
        "--out",
        dir.join("m1.lmn.json").to_str().expect("utf8"),
        "--validation",
        svg_dir.to_str().expect("utf8"),
        "--format",
        "svg",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let svg = std::fs::read_to_string(svg_dir.join("resid.svg")).expect("resid.svg");
    assert!(svg.starts_with("<svg"));
}

/// A recording whose delivered pulses differ from the decided ones (the driver refused
/// one) is refused by `fes identify` naming the counts and the flag; with
/// `--allow-undelivered` the delivered pulses are fitted and the model says how many
/// differed.
#[test]
fn identify_refuses_a_recording_with_undelivered_pulses_unless_allowed() {
    use fes_dataset::DataSet;
    let dir = tmp("identify_undelivered");
    let data = dir.join("data");
    std::fs::create_dir_all(&data).expect("dir");
    small_dataset(&data, 4);
    // What a recording of the chain writes: the decision beside the delivery, one pulse of
    // record 0 refused by the driver.
    let mut ds = DataSet::read(&data).expect("read");
    let r = &mut ds.records[0];
    let mut decided = r.pulse.clone();
    let k = r.pulse.iter().position(|&p| p).expect("a pulse");
    r.pulse[k] = false;
    decided[k] = true;
    r.decided = Some(decided);
    ds.write(&data, WriteMode::Overwrite).expect("write");
    let out = dir.join("m.lmn.json");
    let args = |extra: &[&'static str]| {
        let mut a = vec![
            "identify",
            "--data",
            data.to_str().expect("utf8"),
            "--structure",
            "ss-eig-common",
            "--units",
            "2",
            "--max-iter",
            "10",
            "--out",
            out.to_str().expect("utf8"),
        ];
        a.extend_from_slice(extra);
        a
    };
    let o = run(&args(&[]));
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(
        e.contains("1 pulse(s) were decided but not delivered")
            && e.contains("--allow-undelivered"),
        "{e}"
    );
    assert!(!out.exists(), "a refused run wrote a model");
    let o = run(&args(&["--allow-undelivered"]));
    assert!(o.status.success(), "{}", stderr(&o));
    let lmn = file::load_allow_unstable(&out).expect("load").0;
    assert_eq!(
        lmn.provenance.extra.get("undelivered_pulses"),
        Some(&serde_json::json!({"decided_not_delivered": 1, "delivered_not_decided": 0}))
    );
}

/// Each bad input ends with a non-zero status and a message naming the problem.
#[test]
fn bad_inputs_are_refused_with_clear_errors() {
    let dir = tmp("bad_inputs");
    let good = dir.join("good");
    std::fs::create_dir_all(&good).expect("dir");
    small_dataset(&good, 3);
    let one = dir.join("one");
    std::fs::create_dir_all(&one).expect("dir");
    small_dataset(&one, 1);
    let nan = dir.join("nan");
    std::fs::create_dir_all(&nan).expect("dir");
    small_dataset(&nan, 3);
    // The force at t = 50 ms of one record becomes NaN.
    let csv = std::fs::read_to_string(nan.join("r1.csv")).expect("read");
    let fixed: String = csv
        .lines()
        .map(|l| {
            if l.starts_with("50,") {
                "50,0,NaN".to_string()
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    std::fs::write(nan.join("r1.csv"), fixed + "\n").expect("write");
    let out = dir.join("m.json");
    let (g, o1, n, missing, outp) = (
        good.to_str().expect("utf8"),
        one.to_str().expect("utf8"),
        nan.to_str().expect("utf8"),
        dir.join("nope"),
        out.to_str().expect("utf8"),
    );
    let missing = missing.to_str().expect("utf8");
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec![
                "identify",
                "--data",
                missing,
                "--structure",
                "ss-eig-common",
                "--units",
                "2",
                "--out",
                outp,
            ],
            "does not exist",
        ),
        (
            vec![
                "identify",
                "--data",
                o1,
                "--structure",
                "ss-eig-common",
                "--units",
                "2",
                "--out",
                outp,
            ],
            "at least 2",
        ),
        (
            vec![
                "identify",
                "--data",
                n,
                "--structure",
                "ss-eig-common",
                "--units",
                "2",
                "--out",
                outp,
            ],
            "r1.csv",
        ),
        (
            vec![
                "identify",
                "--data",
                g,
                "--structure",
                "ss-eig-common",
                "--units",
                "0",
                "--out",
                outp,
            ],
            "units = 0",
        ),
        (
            vec![
                "identify",
                "--data",
                g,
                "--structure",
                "ss-eig-common",
                "--units",
                "17",
                "--out",
                outp,
            ],
            "units = 17",
        ),
        (
            vec![
                "identify",
                "--data",
                g,
                "--structure",
                "ss-direct",
                "--units",
                "2",
                "--mode",
                "prediction",
                "--out",
                outp,
            ],
            "prediction mode needs an ARX structure",
        ),
        (
            vec![
                "identify",
                "--data",
                g,
                "--structure",
                "arx-shift",
                "--units",
                "2",
                "--ts-ms",
                "0",
                "--out",
                outp,
            ],
            "--ts-ms",
        ),
        (
            vec![
                "identify",
                "--data",
                g,
                "--structure",
                "arx-shift",
                "--units",
                "2",
                "--ts-ms",
                "5",
                "--delay-ms",
                "7",
                "--out",
                outp,
            ],
            "--delay-ms",
        ),
        (
            vec![
                "identify",
                "--data",
                g,
                "--structure",
                "arx-delta",
                "--units",
                "2",
                "--learning",
                "global",
                "--out",
                outp,
            ],
            "--learning applies to prediction mode",
        ),
        (
            vec![
                "identify",
                "--data",
                g,
                "--structure",
                "arx-delta",
                "--units",
                "2",
                "--order",
                "5",
                "--out",
                outp,
            ],
            "ARX order = 5",
        ),
        (
            vec![
                "identify",
                "--data",
                g,
                "--structure",
                "arx-delta",
                "--units",
                "1",
                "--starts",
                "0",
                "--out",
                outp,
            ],
            "starts",
        ),
        (
            vec![
                "identify",
                "--data",
                g,
                "--structure",
                "nonsense",
                "--units",
                "1",
                "--out",
                outp,
            ],
            "nonsense",
        ),
        (
            vec![
                "identify",
                "--data",
                g,
                "--structure",
                "arx-delta",
                "--units",
                "1",
                "--out",
                "/nonexistent-dir/m.json",
            ],
            "cannot write",
        ),
        (
            vec![
                "sweep",
                "--data",
                g,
                "--structure",
                "arx-delta",
                "--units",
                "3..2",
            ],
            "unit range",
        ),
        (
            vec![
                "sweep",
                "--data",
                g,
                "--structure",
                "arx-delta",
                "--units",
                "0..2",
            ],
            "unit range",
        ),
        (vec!["compare", "--data", missing], "does not exist"),
    ];
    for (args, want) in cases {
        let o = run(&args);
        let err = stderr(&o);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert!(
            err.contains(want),
            "{args:?}: stderr should mention {want:?}:\n{err}"
        );
        assert!(!err.contains("panicked"), "{args:?} panicked:\n{err}");
    }
}

#[test]
fn help_explains_structures_and_modes() {
    let o = run(&["identify", "--help"]);
    assert!(o.status.success());
    let h = stdout(&o);
    for s in [
        "arx-shift",
        "arx-delta",
        "ss-direct",
        "ss-eig-local",
        "ss-eig-common",
        "eq. 5.6",
        "prediction",
        "simulation",
        "--zero-offsets",
        "--optimise-knots",
        "--starts",
        "--seed",
    ] {
        assert!(h.contains(s), "identify --help lacks {s}");
    }
}

#[test]
fn sweep_and_compare_write_tables_and_plot() {
    let dir = tmp("sweep_compare");
    let data = dir.join("data");
    std::fs::create_dir_all(&data).expect("dir");
    small_dataset(&data, 4);
    let d = data.to_str().expect("utf8");
    let sw = dir.join("sweep");
    let o = run(&[
        "sweep",
        "--data",
        d,
        "--structure",
        "arx-delta",
        "--units",
        "1..3",
        "--max-iter",
        "10",
        "--out",
        sw.to_str().expect("utf8"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    assert!(text.contains("best size:"), "{text}");
    assert_eq!(
        text.lines()
            .filter(|l| l.starts_with("| ") && !l.starts_with("| units"))
            .count(),
        3
    );
    for f in [
        "sweep.md",
        "sweep.json",
        "sweep.png",
        "units_1.lmn.json",
        "units_3.lmn.json",
    ] {
        assert!(sw.join(f).is_file(), "{f} missing");
    }
    let png = std::fs::read(sw.join("sweep.png")).expect("png");
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(sw.join("sweep.json")).expect("json"))
            .expect("parse");
    assert_eq!(json["rows"].as_array().map(|r| r.len()), Some(3));
    // Each size carries the field's fit and RRSE beside the MSSE: fit = 100 (1 - RRSE).
    for row in json["rows"].as_array().expect("rows") {
        let (fit, rrse) = (row["test_fit_percent"].as_f64(), row["test_rrse"].as_f64());
        let (fit, rrse) = (fit.expect("test_fit_percent"), rrse.expect("test_rrse"));
        assert!((fit - 100.0 * (1.0 - rrse)).abs() < 1e-9, "{row}");
    }
    let cmp = dir.join("compare");
    let o = run(&[
        "compare",
        "--data",
        d,
        "--quick",
        "--out",
        cmp.to_str().expect("utf8"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(cmp.join("compare.json")).expect("json"))
            .expect("parse");
    let rows = json["rows"].as_array().expect("rows");
    assert_eq!(
        rows.len(),
        11,
        "Table 5.1 rows + 2 state-space rows + zero offsets"
    );
    assert!(cmp.join("compare.md").is_file());
}

/// Acceptance: on the thesis protocol's fast and slow data sets (seed 1) the 4-unit
/// common-eigenvector network's test MSSE is at most 0.3 (fast) / 0.03 (slow) of the
/// 2nd-order linear delta model's, and every local model is stable.
#[test]
fn common_eigenvector_network_beats_the_linear_model_by_the_thesis_ratios() {
    for (preset, limit) in [(Preset::Fast, 0.3), (Preset::Slow, 0.03)] {
        let recs = RecordSet::load(data_dir(preset)).expect("data set");
        assert_eq!(recs.train.len(), 30);
        let linear = identify(
            &recs,
            &IdentOptions {
                structure: Structure::ArxDelta,
                units: 1,
                ..IdentOptions::default()
            },
            &Hooks::silent(),
        )
        .expect("linear delta model");
        let lmn = identify(
            &recs,
            &IdentOptions {
                structure: Structure::SsEigCommon,
                units: 4,
                ..IdentOptions::default()
            },
            &Hooks::silent(),
        )
        .expect("common-eigenvector network");
        let ratio = lmn.metrics.test_msse / linear.metrics.test_msse;
        eprintln!(
            "{}: linear delta test MSSE {:.3e}, 4-unit ss-eig-common {:.3e}, ratio {ratio:.4}",
            preset.name(),
            linear.metrics.test_msse,
            lmn.metrics.test_msse
        );
        assert!(ratio <= limit, "{}: ratio {ratio} > {limit}", preset.name());
        assert!(lmn.lmn.stability().iter().all(|s| s.stable));
        file::to_json_string(&lmn.lmn).expect("serialisable");
    }
}

/// Each unit's share of the training validity weight, from the model's provenance.
fn validity_shares(model: &Path) -> Vec<f64> {
    let lmn = file::load(model).expect("model");
    lmn.provenance.extra["unit_validity_share"]
        .as_array()
        .expect("shares")
        .iter()
        .map(|v| v.as_f64().expect("number"))
        .collect()
}

/// `identify --range LO,HI` spans the validity functions over where the data are: on the
/// thesis protocol's fast data (whose random trains seldom reach phi = 0.6, a 60 Hz mean)
/// eight units over [0, 1] leave the top three under 0.5 % of the training validity weight
/// each (pitfall d), over [0, 0.5] every unit gets more than 2 %. Input scheduling makes the
/// shares a function of the pulses alone, so two iterations suffice. A range that is not
/// two numbers, or inverted, is refused naming the flag.
#[test]
fn identify_range_puts_every_unit_where_the_data_are() {
    let dir = tmp("identify_range");
    let data = data_dir(Preset::Fast).to_str().expect("utf8");
    let fit = |range: &str, name: &str| {
        let out = dir.join(name);
        let o = run(&[
            "identify",
            "--data",
            data,
            "--structure",
            "ss-eig-common",
            "--units",
            "8",
            "--zero-offsets",
            "--max-iter",
            "2",
            "--range",
            range,
            "--out",
            out.to_str().expect("utf8"),
        ]);
        (o, out)
    };
    let (o, whole) = fit("0,1", "whole.lmn.json");
    assert!(o.status.success(), "{}", stderr(&o));
    let shares = validity_shares(&whole);
    assert!(
        shares[5..].iter().all(|&s| s < 0.005),
        "over [0, 1] the top units get little: {shares:?}"
    );
    assert!(stderr(&o).contains("unit 7 gets only"), "{}", stderr(&o));
    let (o, low) = fit("0,0.5", "low.lmn.json");
    assert!(o.status.success(), "{}", stderr(&o));
    let shares = validity_shares(&low);
    assert!(
        shares.iter().all(|&s| s > 0.02),
        "over [0, 0.5] every unit is reached: {shares:?}"
    );
    assert!(!stderr(&o).contains("gets only"), "{}", stderr(&o));
    let lmn = file::load(&low).expect("model");
    assert_eq!(
        lmn.provenance.extra["options"]["range"],
        serde_json::json!([0.0, 0.5])
    );
    for (bad, says) in [("0.5", "LO,HI"), ("0,x", "`x`"), ("0.5,0.2", "lo < hi")] {
        let (o, _) = fit(bad, "bad.lmn.json");
        assert!(!o.status.success(), "--range {bad} accepted");
        let err = stderr(&o);
        assert!(err.contains(says), "--range {bad}: {err}");
    }
}

/// Every unit of the shipped model `name` (`models/<name>.lmn.json`, the model its
/// controllers embed) gets at least `MIN_UNIT_SHARE` (2 %) of the validity weight of
/// `data`'s training records, recomputed here, not read from the file's provenance. A unit
/// the data barely reach is fitted to little information, and the receding-horizon planner
/// drives exactly such units (docs/bench.md, "Planning").
fn assert_every_unit_reached(name: &str, data: &DataSet) {
    use fes_ident::ident::metrics::{MIN_UNIT_SHARE, unit_weights, validity_weights};
    use fes_ident::ident::problem::ModelData;
    let models = models_dir();
    let lmn = file::load(models.join(format!("{name}.lmn.json"))).unwrap();
    for controller in [
        format!("{name}.lcn.json"),
        format!("{name}-rehastim2.lcn.json"),
    ] {
        let c = fes_model::control::file::Controller::load(models.join(&controller)).unwrap();
        assert_eq!(c.lmn, lmn, "{controller} embeds another model");
    }
    let records = RecordSet::from_dataset(data).unwrap();
    let train = ModelData::new(&records.train, 1).unwrap();
    let weights = unit_weights(&validity_weights(&lmn, &train).unwrap());
    assert_eq!(weights.len(), lmn.units());
    for w in &weights {
        assert!(
            w.share >= MIN_UNIT_SHARE,
            "{name} unit {}: {:.2} % of the validity weight",
            w.unit,
            100.0 * w.share
        );
    }
}

/// A rich-protocol recording (`sim-muscle record --protocol rich ... --scale-from`) of
/// `preset` with `seed` and `protocol`, normalised by the thesis recording's `scale_n`:
/// `records` records of which `train` train (those over 1.1 of the scale are left out).
fn rich_recording(
    preset: Preset,
    seed: u64,
    protocol: ProtocolConfig,
    scale_n: f64,
    (records, train): (usize, usize),
) -> DataSet {
    let protocol = ProtocolConfig {
        kind: sim_muscle::protocol::ProtocolKind::Rich,
        ..protocol
    };
    let set = record_protocol(preset, seed, &protocol, Normalise::Scale(scale_n));
    assert_eq!(
        (set.records.len(), set.header.split.train.len()),
        (records, train)
    );
    assert_eq!(set.header.scale_n, scale_n);
    set
}

/// The slow muscle's recording of close pulse pairs from rest, at the thesis recording's
/// scale `scale_n`: `sim-muscle record --preset slow --seed 3 --protocol rich --records 60
/// --train-records 30 --rich-min-hz 4 --rich-max-hz 12 --doublet-min-ms 2 --doublet-max-ms 6
/// --scale-from target/models/data-slow` (models/README.md).
fn slow_pairs_recording(scale_n: f64) -> DataSet {
    let protocol = ProtocolConfig {
        records: 60,
        train_records: 30,
        rich_min_hz: 4.0,
        rich_max_hz: 12.0,
        doublet_min_ms: 2,
        doublet_max_ms: 6,
        ..ProtocolConfig::thesis(Preset::Slow)
    };
    rich_recording(Preset::Slow, 3, protocol, scale_n, (60, 30))
}

/// The shipped slow model is identified on the thesis protocol merged with close pulse
/// pairs from rest (models/README.md), 6 units over `--range 0,0.5`; on those data every
/// unit is reached.
#[test]
fn every_unit_of_the_shipped_slow_model_is_reached_by_its_training_data() {
    let thesis = record_preset(Preset::Slow, 1);
    let pairs = slow_pairs_recording(thesis.header.scale_n);
    let merged =
        fes_dataset::merge::merge(&[("thesis".into(), thesis), ("pairs".into(), pairs)]).unwrap();
    assert_every_unit_reached("slow", &merged);
}

/// `again` fits its data as `stored` did: the same train and test MSSE, relative 1e-6 (a
/// shipped model re-identified with the options its provenance records).
fn assert_same_fit(again: &fes_model::model::Lmn, stored: &fes_model::model::Lmn) {
    let (a, b) = (&again.provenance, &stored.provenance);
    for (what, x, y) in [
        ("train", a.train_msse.unwrap(), b.train_msse.unwrap()),
        ("test", a.test_msse.unwrap(), b.test_msse.unwrap()),
    ] {
        assert!(
            (x - y).abs() <= 1e-6 * y,
            "{what} MSSE {x:e} vs stored {y:e}"
        );
    }
}

/// models/README.md's recipe for the shipped slow model, run through the commands: the two
/// recordings joined by `fes dataset merge`, then `fes identify` with the recipe's options,
/// give the stored model (the same local models to 1e-9, the same train and test MSSE to
/// 1e-6), so the file is what the recipe makes.
#[test]
fn the_shipped_slow_model_is_what_its_recipe_makes() {
    let dir = tmp("slow_recipe");
    let thesis = data_dir(Preset::Slow);
    let scale_n = DataSet::read(thesis).unwrap().header.scale_n;
    let pairs = dir.join("pairs");
    slow_pairs_recording(scale_n)
        .write(&pairs, WriteMode::CreateNew)
        .unwrap();
    let (merged, out) = (dir.join("all"), dir.join("slow.lmn.json"));
    let path = |p: &Path| p.to_str().expect("utf8").to_owned();
    let o = run(&[
        "dataset",
        "merge",
        &path(thesis),
        &path(&pairs),
        "--out",
        &path(&merged),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = run(&[
        "identify",
        "--data",
        &path(&merged),
        "--structure",
        "ss-eig-common",
        "--units",
        "6",
        "--range",
        "0,0.5",
        "--zero-offsets",
        "--starts",
        "8",
        "--out",
        &path(&out),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let again = file::load(&out).unwrap();
    let models = models_dir();
    let stored = file::load(models.join("slow.lmn.json")).unwrap();
    assert_same_fit(&again, &stored);
    let units = |p: &Path| -> serde_json::Value {
        serde_json::from_slice::<serde_json::Value>(&std::fs::read(p).unwrap()).unwrap()["units"]
            .clone()
    };
    assert_eq!(units(&out).as_array().map(Vec::len), Some(6), "six units");
    crate::analysis_support::assert_close(
        &units(&out),
        &units(&models.join("slow.lmn.json")),
        1e-9,
        "units",
    );
}

/// Peaks of the normalised force from rest, (model, muscle), for one pulse and for pairs
/// `ipis_ms` apart: the model `models/<name>.lmn.json` run free (eq. B.6/B.7), the preset's
/// noise-free muscle divided by the model's force scale.
fn pair_peaks(name: &str, preset: Preset, ipis_ms: &[usize]) -> Vec<(usize, f64, f64)> {
    use sim_muscle::plant::Pulse;
    let models = models_dir();
    let lmn = file::load(models.join(format!("{name}.lmn.json"))).unwrap();
    let net = lmn.network().unwrap();
    let mut muscle = Muscle::new(MuscleConfig::preset(preset)).unwrap();
    let peak = |v: &[f64]| v.iter().copied().fold(f64::MIN, f64::max);
    std::iter::once(0)
        .chain(ipis_ms.iter().copied())
        .map(|ipi| {
            let mut train = vec![false; 600];
            train[0] = true;
            train[ipi] = true;
            let u: Vec<f64> = train.iter().map(|&p| f64::from(u8::from(p))).collect();
            let mut y = vec![0.0; u.len()];
            fes_model::model::simulate::simulate(&net, &u, &mut y).unwrap();
            muscle.reset();
            let f = sim_muscle::simulate::simulate(&mut muscle, &train, Pulse::SUPRAMAXIMAL);
            (ipi, peak(&y), peak(&f) / lmn.force_scale_n)
        })
        .collect()
}

/// The shipped slow model answers a single pulse and close pulse pairs from rest (2-6 ms
/// apart: a plan's opening) within 10 % of the slow muscle's peak (2 ms: +9.4 %; one
/// pulse: -3.6 %). The model of the thesis protocol alone, whose data hold pulses 1-70 ms
/// apart but few pairs from rest, answered a 2 ms pair 20.3 % above the muscle (0.64
/// against 0.53), 3 ms 16.5 %, 4 ms 13.5 %: its plans at 0.5 opened with the wrong pair and
/// lost to 8 Hz x 2 (docs/bench.md, "Every pattern, not only trains").
#[test]
fn the_shipped_slow_model_answers_close_pairs_as_the_muscle_does() {
    for (ipi, model, muscle) in pair_peaks("slow", Preset::Slow, &[2, 3, 4, 6]) {
        let e = model / muscle - 1.0;
        assert!(
            e.abs() < 0.10,
            "pair {ipi} ms: model {model:.4}, muscle {muscle:.4} ({:+.1} %)",
            100.0 * e
        );
    }
}

/// The shipped fast model is identified on the rich protocol normalised by the thesis
/// recording's scale (models/README.md: `sim-muscle record --protocol rich ... --scale-from
/// target/models/data-fast`), 4 units over `--range 0,0.7`; on those data every unit is
/// reached. On the thesis recording alone the data stop short of phi ~ 0.6, where 0.9 goes.
#[test]
fn every_unit_of_the_shipped_fast_model_is_reached_by_its_training_data() {
    let scale_n = record_preset(Preset::Fast, 1).header.scale_n;
    let protocol = ProtocolConfig {
        records: 90,
        train_records: 60,
        rich_min_hz: 20.0,
        train_min_ms: 250,
        ..ProtocolConfig::thesis(Preset::Fast)
    };
    // The records that exceed 1.1 of the thesis scale (the fastest trains) are left out.
    let rich = rich_recording(Preset::Fast, 1, protocol, scale_n, (77, 51));
    assert_every_unit_reached("fast", &rich);
}

/// The shipped model of eq. 5.2's class (`models/thesis-fast.lmn.json`, `scheduling_input =
/// "undelayed"`) is reproduced by `fes identify` with the options its provenance records, on
/// the data set `sim-muscle record --preset thesis-fast --seed 1` writes: the same train and
/// test MSSE (relative 1e-6) and the same class. Its local models have the thesis's kind of
/// dynamics (Table 5.3: a fast pole beside a slow one): every unit a pole faster than
/// -87 1/s and one between -8 and -33 1/s, and every unit at least `MIN_UNIT_SHARE` of
/// the training validity weight. The model of today's class identified with the same
/// options fits the same data within 5 % of its test MSSE (docs/model.md: 9.22e-5 against
/// 9.11e-5).
#[test]
fn the_undelayed_class_reproduces_its_stored_fit() {
    use fes_model::model::LocalModelSet;
    use fes_model::model::scheduling::SchedulingInput;
    let models = models_dir();
    let stored = file::load(models.join("thesis-fast.lmn.json")).unwrap();
    assert_eq!(
        stored.scheduling.scheduling_input(),
        SchedulingInput::Undelayed
    );
    let LocalModelSet::SsEigCommon { units, .. } = &stored.local else {
        panic!("ss-eig-common expected");
    };
    for (i, u) in units.iter().enumerate() {
        let (fast, slow) = (
            u.eigenvalues[0].min(u.eigenvalues[1]),
            u.eigenvalues[0].max(u.eigenvalues[1]),
        );
        assert!(fast < -87.0, "unit {i}: fast pole {fast}");
        assert!((-33.0..=-8.0).contains(&slow), "unit {i}: slow pole {slow}");
    }
    let dir = tmp("undelayed_class");
    let data = data_dir(Preset::ThesisFast).to_str().expect("utf8");
    let fit = |class: &str| {
        let out = dir.join(format!("{class}.lmn.json"));
        let o = run(&[
            "identify",
            "--data",
            data,
            "--structure",
            "ss-eig-common",
            "--units",
            "4",
            "--range",
            "0,0.6",
            "--zero-offsets",
            "--starts",
            "4",
            "--scheduling-input",
            class,
            "--out",
            out.to_str().expect("utf8"),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        file::load(&out).unwrap()
    };
    let again = fit("undelayed");
    assert_eq!(again.scheduling, stored.scheduling);
    assert_same_fit(&again, &stored);
    for (i, share) in validity_shares(&models.join("thesis-fast.lmn.json"))
        .iter()
        .enumerate()
    {
        assert!(
            *share >= fes_ident::ident::metrics::MIN_UNIT_SHARE,
            "unit {i}: {share}"
        );
    }
    let ours = fit("delayed").provenance.test_msse.unwrap();
    let theirs = stored.provenance.test_msse.unwrap();
    assert!(
        (ours - theirs).abs() <= 0.05 * theirs,
        "delayed class test MSSE {ours:e} vs undelayed {theirs:e}"
    );
}
