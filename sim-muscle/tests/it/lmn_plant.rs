//! An LMN model file as the muscle: the plant's samples equal rt-core's own free-run
//! simulation of the model (`fes_model::model::simulate::simulate`), scaled to newtons and
//! aligned to the MusclePlant timing; the CLI runs it with `--model`.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use crate::support;

use fes_dataset::DataSet;
use fes_model::model::file;
use fes_model::model::lmn::Stability;
use sim_muscle::lmn_plant::{LmnPlant, LmnPlantError};
use sim_muscle::pattern::from_samples;
use sim_muscle::plant::{MusclePlant, Pulse};
use sim_muscle::simulate::simulate;
use support::{Scratch, run, run_ok};

/// The example model of rt-core's docs/model.md (4 units, common eigenvectors, d = 7).
const MODEL: &str = r#"{
  "schema": "fes-lmn/1",
  "ts_s": 0.001,
  "delay_samples": 7,
  "scheduling": { "kind": "input", "gain": 25000.0, "natural_frequency_rad_s": 50.0, "damping": 1.0 },
  "order": 3,
  "knots": [0.0, 0.0, 0.0, 0.5, 1.0, 1.0, 1.0],
  "structure": "ss-eig-common",
  "zero_offsets": false,
  "reference_unit": 0,
  "force_scale_n": 12.5,
  "units": [
    { "eigenvalues": [-250.0, -30.0], "b": [1.0, 1.0], "c": [0.02, -0.01], "dx": [0.0, 0.0], "dy": 0.0 },
    { "eigenvalues": [-90.0, -8.0], "b": [2.0, 0.5], "c": [0.02, -0.01], "dx": [1.0, 0.0], "dy": 0.0 },
    { "eigenvalues": [-220.0, -1.0], "b": [1.5, 0.7], "c": [0.03, -0.02], "dx": [0.0, 0.2], "dy": 0.01 },
    { "eigenvalues": [-128.0, -29.0], "b": [1.0, 1.2], "c": [0.02, -0.01], "dx": [0.0, 0.0], "dy": 0.0 }
  ],
  "provenance": { "tool": "test" }
}"#;

const PULSES: [usize; 8] = [3, 5, 40, 41, 90, 130, 170, 171];

#[test]
fn plant_equals_rt_core_simulation() {
    let lmn = file::from_json_str(MODEL, Stability::Require).expect("model");
    let net = lmn.network().expect("network");
    let n = 400;
    let train = from_samples(&PULSES, n);
    let u: Vec<f64> = train.iter().map(|&p| if p { 1.0 } else { 0.0 }).collect();
    let mut y = vec![0.0; n];
    fes_model::model::simulate::simulate(&net, &u, &mut y).expect("simulate");
    let mut plant = LmnPlant::new(&lmn).expect("plant");
    let force = simulate(&mut plant, &train, Pulse::SUPRAMAXIMAL);
    for k in 0..n {
        let want = y[k] * lmn.force_scale_n;
        assert!(
            (force[k] - want).abs() <= 1e-12 * want.abs().max(1.0),
            "k = {k}: {} vs {want}",
            force[k]
        );
    }
    // Nothing moves before the first pulse's force appears at 3 + d + 1 = 11.
    assert!(force[..11].iter().all(|&f| f == force[0]));
    assert_ne!(force[11], force[0]);
    // reset returns to rest: the same record again.
    plant.reset();
    assert_eq!(simulate(&mut plant, &train, Pulse::SUPRAMAXIMAL), force);
    // A pulse without charge is no pulse.
    plant.reset();
    let none = simulate(
        &mut plant,
        &train,
        Pulse {
            amplitude_ma: 0.0,
            ..Pulse::SUPRAMAXIMAL
        },
    );
    assert!(none.iter().all(|&f| f == force[0]));
}

#[test]
fn model_without_delay_is_refused() {
    let lmn = file::from_json_str(
        &MODEL.replace("\"delay_samples\": 7", "\"delay_samples\": 0"),
        Stability::Require,
    )
    .expect("model");
    assert!(matches!(LmnPlant::new(&lmn), Err(LmnPlantError::NoDelay)));
}

#[test]
fn cli_runs_a_model_file() {
    let dir = Scratch::new("lmn");
    std::fs::create_dir_all(dir.path()).expect("dir");
    let model = dir.join("m.lmn.json");
    std::fs::write(&model, MODEL).expect("write");
    let m = model.to_str().expect("utf-8");
    let csv = run_ok(&[
        "simulate",
        "--model",
        m,
        "--pulses",
        "3,5,40",
        "--duration-ms",
        "100",
    ]);
    assert_eq!(csv.lines().count(), 101);
    let out = dir.join("data");
    let o = out.to_str().expect("utf-8");
    run_ok(&[
        "record",
        "--model",
        m,
        "--records",
        "12",
        "--train-records",
        "6",
        "--seed",
        "4",
        "--out",
        o,
    ]);
    let ds = DataSet::read(&out).expect("read");
    assert_eq!(ds.records.len(), 12);
    assert_eq!(ds.header.preset, None);
    assert_eq!(ds.header.parameters.get("force_scale_n"), Some(&12.5));
    for (args, expected) in [
        (
            vec![
                "simulate",
                "--model",
                m,
                "--preset",
                "fast",
                "--pulses",
                "0",
                "--duration-ms",
                "10",
            ],
            "cannot be used with",
        ),
        (
            vec![
                "simulate",
                "--model",
                "/nonexistent.lmn.json",
                "--pulses",
                "0",
                "--duration-ms",
                "10",
            ],
            "/nonexistent.lmn.json",
        ),
        (
            vec!["simulate", "--pulses", "0", "--duration-ms", "10"],
            "--preset",
        ),
    ] {
        let r = run(&args);
        assert!(!r.status.success(), "{args:?}");
        let stderr = String::from_utf8_lossy(&r.stderr);
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
    }
}
