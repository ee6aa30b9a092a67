//! The model file `fes-lmn/1`: round trips and rejections that name the problem.
#![allow(clippy::needless_range_loop)] // index loops mirror the equations
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use fes_model::model::arx::ArxUnit;
use fes_model::model::file::{self, FileError, SCHEMA};
use fes_model::model::lmn::{Lmn, LocalModelSet, Provenance, Stability, Structure};
use fes_model::model::local_model::{EigCommonUnit, EigLocalUnit, SsLocalModel};
use fes_model::model::scheduling::SchedulingSpec;
use fes_model::model::simulate::simulate;
use fes_model::model::validity::ValidityFunctions;
use serde_json::Value;

const TS: f64 = 1e-3;

fn provenance() -> Provenance {
    let mut p = Provenance {
        train_msse: Some(3.5e-4),
        test_msse: Some(5.0e-4),
        fit_seconds: Some(812.5),
        ..Default::default()
    };
    p.extra.insert("data_set".into(), Value::from("fast-seed7"));
    p.extra.insert("seed".into(), Value::from(7));
    p
}

fn base(local: LocalModelSet, m: usize) -> Lmn {
    Lmn {
        ts: TS,
        delay: 7,
        scheduling: SchedulingSpec::default(),
        validity: ValidityFunctions::uniform(m, 0.0, 1.0).unwrap(),
        local,
        zero_offsets: false,
        force_scale_n: 12.5,
        provenance: provenance(),
    }
}

fn eig_common() -> Lmn {
    let units = vec![
        EigCommonUnit {
            eigenvalues: [-250.0, -30.0],
            b: [1.0, 1.0],
            c: [0.02, -0.01],
            dx: [0.0, 0.0],
            dy: 0.0,
        },
        EigCommonUnit {
            eigenvalues: [-90.0, -8.0],
            b: [2.0, 0.5],
            c: [0.02, -0.01],
            dx: [1.0, 0.0],
            dy: 0.0,
        },
        EigCommonUnit {
            eigenvalues: [-220.0, -1.0],
            b: [1.5, 0.7],
            c: [0.03, -0.02],
            dx: [0.0, 0.2],
            dy: 0.01,
        },
        EigCommonUnit {
            eigenvalues: [-128.48, -29.61],
            b: [1.0, 1.2],
            c: [0.02, -0.01],
            dx: [0.0, 0.0],
            dy: 0.0,
        },
    ];
    base(
        LocalModelSet::SsEigCommon {
            units,
            reference_unit: 0,
        },
        4,
    )
}

/// Table 5.3's fast-muscle LMN (local eigenvectors) with its unstable third unit (+9.96).
fn table_5_3(unstable: bool) -> Lmn {
    let eig = [
        [-256.27, -33.24],
        [-87.07, -7.71],
        [-220.68, if unstable { 9.96 } else { -1.0 }],
        [-128.48, -29.61],
    ];
    let units = eig
        .iter()
        .enumerate()
        .map(|(i, e)| EigLocalUnit {
            eigenvalues: *e,
            eigenvector_angles: [0.2 + 0.3 * i as f64, 1.6 + 0.1 * i as f64],
            b: [1.0, 0.5],
            c: [0.02, 0.01],
            dx: [0.1 * i as f64, 0.0],
            dy: 0.0,
        })
        .collect();
    base(LocalModelSet::SsEigLocal(units), 4)
}

fn all_structures() -> Vec<Lmn> {
    let direct = vec![
        SsLocalModel {
            a: [[-200.0, 30.0], [-40.0, -50.0]],
            b: [1.0, 0.2],
            c: [0.01, 0.03],
            dx: [0.1, 0.0],
            dy: 0.001,
        },
        SsLocalModel {
            a: [[-150.0, 10.0], [0.0, -20.0]],
            b: [0.5, 1.0],
            c: [0.02, 0.01],
            dx: [0.0, 0.3],
            dy: 0.0,
        },
    ];
    let arx = vec![
        ArxUnit {
            a: [-1.90, 0.9025, 0.0],
            b: [0.010, 0.002, 0.0],
            d: 0.001,
        },
        ArxUnit {
            a: [-1.80, 0.8200, 0.0],
            b: [0.020, 0.001, 0.0],
            d: 0.0,
        },
        ArxUnit {
            a: [-1.85, 0.8600, 0.0],
            b: [0.015, 0.004, 0.0],
            d: -0.001,
        },
    ];
    let arx_delta = vec![
        ArxUnit {
            a: [2500.0, 100.0, 0.0],
            b: [25.0, 0.1, 0.0],
            d: 0.5,
        },
        ArxUnit {
            a: [900.0, 80.0, 0.0],
            b: [20.0, 0.0, 0.0],
            d: 0.0,
        },
    ];
    let mut zero = eig_common();
    zero.zero_offsets = true;
    if let LocalModelSet::SsEigCommon { units, .. } = &mut zero.local {
        for u in units {
            u.dx = [0.0; 2];
            u.dy = 0.0;
        }
    }
    let mut out_sched = table_5_3(false);
    out_sched.scheduling = SchedulingSpec::Output;
    let mut arx5 = base(
        LocalModelSet::ArxShift {
            order: 2,
            units: arx,
        },
        3,
    );
    arx5.ts = 5e-3;
    arx5.delay = 2;
    vec![
        base(LocalModelSet::SsDirect(direct), 2),
        table_5_3(false),
        eig_common(),
        zero,
        out_sched,
        arx5,
        base(
            LocalModelSet::ArxDelta {
                order: 2,
                units: arx_delta,
            },
            2,
        ),
    ]
}

fn sim(lmn: &Lmn) -> Vec<f64> {
    try_sim(lmn).unwrap()
}

/// Simulates a fixed irregular pulse train from rest (the error says which step failed).
fn try_sim(lmn: &Lmn) -> Result<Vec<f64>, String> {
    let net = lmn.network().map_err(|e| format!("no network: {e}"))?;
    let u: Vec<f64> = (0..1500)
        .map(|k| if k % 17 == 0 || k % 29 == 0 { 1.0 } else { 0.0 })
        .collect();
    let mut y = vec![0.0; u.len()];
    simulate(&net, &u, &mut y).map_err(|e| format!("cannot simulate: {e}"))?;
    Ok(y)
}

/// save -> load -> identical parameters and bit-identical simulation, for every structure.
#[test]
fn round_trip_gives_identical_simulation() {
    let dir = fes_testkit::Scratch::new("model-file-rt");
    for (i, lmn) in all_structures().into_iter().enumerate() {
        lmn.validate(Stability::Require)
            .unwrap_or_else(|e| panic!("case {i}: {e}"));
        let path = dir.join(format!("m{i}.lmn.json"));
        file::save(&lmn, &path).unwrap();
        let back =
            file::load(&path).unwrap_or_else(|e| panic!("case {i} ({}): {e}", lmn.structure()));
        assert_eq!(back, lmn, "case {i}");
        assert_eq!(sim(&back), sim(&lmn), "case {i}");
    }
}

/// Applies `edit` to the JSON of a valid model and returns the loader's error message.
fn reject(edit: impl FnOnce(&mut Value)) -> String {
    reject_in(&eig_common(), edit)
}

/// [`reject`] for the JSON of `lmn`.
fn reject_in(lmn: &Lmn, edit: impl FnOnce(&mut Value)) -> String {
    let mut v: Value = serde_json::from_str(&file::to_json_string(lmn).unwrap()).unwrap();
    edit(&mut v);
    let text = serde_json::to_string_pretty(&v).unwrap();
    match file::from_json_str(&text, Stability::Require) {
        Ok(_) => panic!("accepted: {text}"),
        Err(e) => e.to_string(),
    }
}

fn assert_names(msg: &str, parts: &[&str]) {
    for p in parts {
        assert!(msg.contains(p), "error {msg:?} does not mention {p:?}");
    }
}

#[test]
fn rejects_nan() {
    // JSON has no NaN: a NaN written into the file is a syntax error quoting the line.
    let text = file::to_json_string(&eig_common())
        .unwrap()
        .replacen("-250.0", "NaN", 1);
    let e = file::from_json_str(&text, Stability::Require).unwrap_err();
    assert!(matches!(e, FileError::Syntax { .. }));
    assert_names(&e.to_string(), &["NaN", "line"]);
    // serde_json writes a NaN as null: named with its field.
    let msg = reject(|v| v["units"][1]["eigenvalues"][0] = Value::Null);
    assert_names(&msg, &["units[1].eigenvalues[0]", "finite number", "null"]);
    let msg = reject(|v| v["ts_s"] = Value::Null);
    assert_names(&msg, &["ts_s"]);
}

#[test]
fn rejects_an_unstable_local_model() {
    let text = file::to_json_string(&table_5_3(true)).unwrap();
    let msg = file::from_json_str(&text, Stability::Require)
        .unwrap_err()
        .to_string();
    assert_names(&msg, &["units[2].eigenvalues[1]", "9.96", "region"]);
    // Direct form with an unstable pole.
    let mut lmn = all_structures().remove(0);
    if let LocalModelSet::SsDirect(u) = &mut lmn.local {
        u[1].a = [[-150.0, 10.0], [0.0, 3.0]];
    }
    let msg = file::from_json_str(&file::to_json_string(&lmn).unwrap(), Stability::Require)
        .unwrap_err()
        .to_string();
    assert_names(&msg, &["units[1]", "unstable"]);
    // A stable eigenvalue that is not physical (-1500 at Ts = 1 ms: |1 + Ts e| = 0.5).
    let msg = reject(|v| v["units"][3]["eigenvalues"][0] = Value::from(-1500.0));
    assert_names(&msg, &["units[3].eigenvalues[0]", "-1500", "region"]);
}

/// The lenient loader opens the unstable model and reports it as data.
#[test]
fn lenient_loader_reports_instability() {
    let dir = fes_testkit::Scratch::new("model-unstable");
    let path = dir.join("model_unstable.lmn.json");
    file::save(&table_5_3(true), &path).unwrap();
    assert!(file::load(&path).is_err());
    let (lmn, report) = file::load_allow_unstable(&path).unwrap();
    assert_eq!(report.len(), 4);
    let unstable: Vec<_> = report
        .iter()
        .filter(|s| !s.stable)
        .map(|s| s.unit)
        .collect();
    assert_eq!(unstable, vec![2]);
    assert!((report[2].radius - (1.0 + TS * 9.96)).abs() < 1e-9);
    assert!(report[2].poles.iter().any(|p| (p.re - 9.96).abs() < 1e-6));
    assert!(lmn.network().is_ok());
}

/// Finite but absurd parameters are refused (their simulated force overflows), and so is a
/// model that cannot start: one with no rest state, even when opened for repair.
#[test]
fn rejects_huge_parameters_and_a_model_without_a_rest_state() {
    let msg = reject(|v| v["units"][1]["c"][0] = Value::from(1e13));
    assert_names(&msg, &["units[1].c[0]", "1e13", "exceeds"]);
    let msg = reject(|v| v["units"][0]["dy"] = Value::from(-2e12));
    assert_names(&msg, &["units[0].dy", "exceeds"]);
    // ARX(1) units with a = -1: A(1) = 1 + a = 0 at every phi, so no equilibrium exists.
    let unit = ArxUnit {
        a: [-1.0, 0.0, 0.0],
        b: [0.01, 0.0, 0.0],
        d: 0.001,
    };
    let singular = base(
        LocalModelSet::ArxShift {
            order: 1,
            units: vec![unit; 2],
        },
        2,
    );
    let text = file::to_json_string(&singular).unwrap();
    // Two stable direct-form local models (poles -150 and -20, and those of unit 0) whose
    // half-and-half interpolation has complex poles of radius ~200 at Ts = 1 ms.
    let mut coupled = all_structures().remove(0);
    if let LocalModelSet::SsDirect(u) = &mut coupled.local {
        u[1].a[0][1] = 4294967296.0;
    }
    assert!(coupled.stability().iter().all(|s| s.stable));
    let msg = file::from_json_str(&file::to_json_string(&coupled).unwrap(), Stability::Require)
        .unwrap_err()
        .to_string();
    assert_names(
        &msg,
        &["local models are stable but their interpolation", "phi ="],
    );
    for stability in [Stability::Require, Stability::Report] {
        let msg = file::from_json_str(&text, stability)
            .unwrap_err()
            .to_string();
        let expected = if stability == Stability::Require {
            "unstable"
        } else {
            "no rest state"
        };
        assert_names(&msg, &[expected]);
    }
}

#[test]
fn rejects_unsorted_knots() {
    let msg = reject(|v| {
        v["knots"][3] = Value::from(0.9);
        v["knots"][4] = Value::from(0.2);
    });
    assert_names(&msg, &["knots", "not sorted", "knot 4"]);
}

#[test]
fn rejects_a_missing_field() {
    for (key, name) in [
        ("force_scale_n", "force_scale_n"),
        ("delay_samples", "delay_samples"),
        ("schema", "schema"),
    ] {
        let msg = reject(|v| {
            v.as_object_mut().unwrap().remove(key);
        });
        assert_names(&msg, &[name, "missing field"]);
    }
    // serde names a missing field in the message, after the path of its object.
    let msg = reject(|v| {
        v["units"][2].as_object_mut().unwrap().remove("c");
    });
    assert_names(&msg, &["units[2]", "missing field `c`"]);
}

#[test]
fn rejects_a_wrong_schema() {
    let msg = reject(|v| v["schema"] = Value::from("fes-lmn/2"));
    assert_names(&msg, &["schema", "fes-lmn/2", SCHEMA]);
}

#[test]
fn rejects_an_unknown_structure() {
    let msg = reject(|v| v["structure"] = Value::from("ss-free"));
    assert_eq!(
        msg,
        "structure: unknown structure \"ss-free\" (expected one of ss-direct, ss-eig-local, \
         ss-eig-common, arx-shift, arx-delta)"
    );
    let e = "ss-free".parse::<Structure>().unwrap_err();
    assert_eq!(e.name, "ss-free");
    assert_eq!(format!("structure: {e}"), msg);
    for s in Structure::ALL {
        assert_eq!(s.name().parse::<Structure>(), Ok(s));
    }
}

#[test]
fn rejects_a_wrong_knot_count() {
    let msg = reject(|v| v["knots"].as_array_mut().unwrap().push(Value::from(1.0)));
    assert_names(
        &msg,
        &["knots", "8 knots given for 4 units", "units + order = 7"],
    );
    let msg = reject(|v| {
        v["units"].as_array_mut().unwrap().pop();
    });
    assert_names(&msg, &["knots", "3 units", "units + order = 6"]);
}

#[test]
fn rejects_other_bad_fields() {
    assert_names(&reject(|v| v["ts_s"] = Value::from(-0.001)), &["ts_s"]);
    assert_names(
        &reject(|v| v["delay_samples"] = Value::from(1001)),
        &["delay_samples", "1000"],
    );
    assert_names(
        &reject(|v| v["delay_samples"] = Value::from(-1)),
        &["delay_samples", "non-negative integer"],
    );
    assert_names(
        &reject(|v| v["structure"] = Value::from("ss-magic")),
        &["structure", "ss-magic", "ss-eig-common"],
    );
    assert_names(
        &reject(|v| v["units"][0]["b"] = Value::from(vec![2.0, 1.0])),
        &["units[0].b", "(1, 1)"],
    );
    assert_names(
        &reject(|v| v["reference_unit"] = Value::from(9)),
        &["reference_unit"],
    );
    assert_names(
        &reject(|v| v["units"][1]["eigenvalue"] = Value::from(1.0)),
        &["units[1].eigenvalue", "unknown field"],
    );
    assert_names(
        &reject(|v| v["units"][1]["b"] = Value::from(vec![1.0])),
        &["units[1].b", "expected 2 numbers"],
    );
    assert_names(
        &reject(|v| v["scheduling"]["natural_frequency_rad_s"] = Value::from(0.0)),
        &["scheduling", "natural frequency"],
    );
    assert_names(
        &reject(|v| v["scheduling"]["kind"] = Value::from("both")),
        &["scheduling.kind"],
    );
    assert_names(
        &reject(|v| v["force_scale_n"] = Value::from(0.0)),
        &["force_scale_n"],
    );
    assert_names(
        &reject(|v| v["order"] = Value::from(4)),
        &["knots", "order 4"],
    );
    assert_names(
        &reject(|v| v["provenance"]["test_msse"] = Value::from("low")),
        &["provenance.test_msse"],
    );
    assert_names(
        &reject(|v| {
            v["zero_offsets"] = Value::from(true);
        }),
        &["units[1].dx", "zero_offsets"],
    );
    let e = file::load("/nonexistent/model.lmn.json").unwrap_err();
    assert_names(&e.to_string(), &["/nonexistent/model.lmn.json"]);
}

/// A field that belongs to another form (another scheduling kind, another structure, or
/// offsets written as null) is refused, and an error inside `scheduling` names its field.
#[test]
fn rejects_fields_of_another_form() {
    let mut output = table_5_3(false);
    output.scheduling = SchedulingSpec::Output;
    assert_names(
        &reject_in(&output, |v| v["scheduling"]["gain"] = Value::from(1.0)),
        &["scheduling.gain", "unknown field", "output"],
    );
    assert_names(
        &reject(|v| v["scheduling"]["gain"] = Value::from("high")),
        &["scheduling.gain", "finite number"],
    );
    assert_names(
        &reject(|v| {
            v["scheduling"].as_object_mut().unwrap().remove("damping");
        }),
        &["scheduling", "missing field `damping`"],
    );
    let direct = all_structures().remove(0);
    assert_names(
        &reject_in(&direct, |v| v["reference_unit"] = Value::from(0)),
        &["reference_unit", "unknown field", "ss-direct"],
    );
    assert_names(
        &reject(|v| {
            v.as_object_mut().unwrap().remove("reference_unit");
        }),
        &["missing field `reference_unit`"],
    );
    let zero = all_structures().remove(3);
    assert!(zero.zero_offsets);
    assert_names(
        &reject_in(&zero, |v| {
            v["units"][1]["dx"] = Value::Null;
            v["units"][1]["dy"] = Value::Null;
        }),
        &["units[1].dx", "null"],
    );
    assert_names(
        &reject_in(&zero, |v| v["units"][1]["dx"] = Value::from(vec![0.0, 0.0])),
        &["units[1]", "missing field `dy`"],
    );
    assert_names(
        &reject_in(&direct, |v| {
            v["units"][0]["a"]
                .as_array_mut()
                .unwrap()
                .push(Value::from(vec![0.0, 0.0]));
        }),
        &["units[0].a", "expected 2 rows, found 3"],
    );
}

/// The example in docs/model.md is a valid file.
#[test]
fn documented_example_loads() {
    let doc = include_str!("../../../../docs/model.md");
    let start = doc.find("```json\n").unwrap() + 8;
    let end = start + doc[start..].find("```").unwrap();
    let lmn = file::from_json_str(&doc[start..end], Stability::Require).unwrap();
    assert_eq!(lmn.units(), 4);
    assert_eq!(lmn.provenance.test_msse, Some(0.0005));
}

use super::json_mutation;

/// Cases of the model-file fuzz target: about 2.5 s in a debug build on one core.
const MODEL_FUZZ_CASES: u32 = 3000;

/// Fuzz target: every structure's valid file, mutated (numbers replaced by
/// NaN / 1e308 / -1 / a 10 000-element array..., keys dropped or duplicated, the text
/// truncated, a byte flipped, non-UTF-8 inserted). The loader must return an error value or
/// a model that passes validation with stability required and simulates to finite forces;
/// a panic fails the test. Non-UTF-8 inputs go through `file::load` (the reader's path).
#[test]
fn mutated_files_are_rejected_or_load_a_valid_model() {
    use json_mutation::{Mutation, Tally, apply, mutation, scratch_file};
    use proptest::prop_assert;
    use proptest::test_runner::{Config, TestCaseError, TestRunner};
    use std::cell::RefCell;

    let dir = fes_testkit::Scratch::new("model-fuzz");
    let docs: Vec<Value> = all_structures()
        .iter()
        .map(|l| serde_json::from_str(&file::to_json_string(l).unwrap()).unwrap())
        .collect();
    // The mutator without edits writes the document back unchanged (its own identity).
    for d in &docs {
        let same = apply(
            d,
            &Mutation {
                structural: vec![],
                bytes: None,
            },
        );
        assert_eq!(&serde_json::from_slice::<Value>(&same).unwrap(), d);
    }
    let tally = RefCell::new(Tally::default());
    let started = std::time::Instant::now();
    let mut runner = TestRunner::new(Config {
        cases: MODEL_FUZZ_CASES,
        failure_persistence: None,
        ..Config::default()
    });
    let strategy = (0..docs.len(), mutation());
    let result = runner.run(&strategy, |(which, m)| {
        let bytes = apply(&docs[which], &m);
        let mut t = tally.borrow_mut();
        t.cases += 1;
        let loaded = match std::str::from_utf8(&bytes) {
            Ok(text) => file::from_json_str(text, Stability::Require),
            Err(_) => {
                t.non_utf8 += 1;
                let path = scratch_file(&dir, "model", &bytes);
                let r = file::load(&path);
                if let Err(e) = &r {
                    let msg = e.to_string();
                    prop_assert!(msg.contains("fuzz-model"), "names no path: {}", msg);
                }
                r
            }
        };
        match loaded {
            Err(_) => t.rejected += 1,
            Ok(lmn) => {
                t.accepted += 1;
                lmn.validate(Stability::Require)
                    .map_err(|e| TestCaseError::fail(format!("accepted but invalid: {e}")))?;
                // Accepted means runnable: a rest state exists and the magnitude bound
                // keeps the simulated force finite.
                let y = try_sim(&lmn)
                    .map_err(|e| TestCaseError::fail(format!("accepted but {e} ({m:?})")))?;
                if !y.iter().all(|v| v.is_finite()) {
                    t.non_finite += 1;
                    if t.example.is_empty() {
                        t.example = format!("{m:?}");
                    }
                }
            }
        }
        Ok(())
    });
    let t = tally.into_inner();
    eprintln!(
        "model file fuzz: {} cases in {:.2?} ({} accepted and valid, {} rejected, {} non-UTF-8; \
         {} accepted models simulate to a non-finite force, e.g. {})",
        t.cases,
        started.elapsed(),
        t.accepted,
        t.rejected,
        t.non_utf8,
        t.non_finite,
        t.example
    );
    result.unwrap();
    assert_eq!(
        t.non_finite, 0,
        "accepted models with a non-finite force: {t:?}"
    );
    assert!(
        t.rejected > t.cases / 2,
        "the mutations should mostly break the file: {t:?}"
    );
}

/// The shipped model files (`models/*.lmn.json`, and the model embedded in each controller
/// file `models/*.lcn.json`): every one loads with stability required, the writer reproduces
/// a model file byte for byte, and writing then reading gives the identical model.
#[test]
fn shipped_models_load_and_round_trip() {
    use fes_model::control::file::Controller;
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models");
    let mut names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.to_string_lossy().ends_with(".json"))
        .collect();
    names.sort();
    let (mut models, mut controllers) = (0, 0);
    for path in &names {
        let text = std::fs::read_to_string(path).unwrap();
        let name = path.display();
        let model_text = if name.to_string().ends_with(".lcn.json") {
            controllers += 1;
            Controller::from_json_str(&text).unwrap_or_else(|e| panic!("{name}: {e}"));
            let v: Value = serde_json::from_str(&text).unwrap();
            v["model"].to_string()
        } else {
            models += 1;
            text.clone()
        };
        let lmn = file::from_json_str(&model_text, Stability::Require)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let written = file::to_json_string(&lmn).unwrap();
        if model_text == text {
            assert_eq!(written, text, "{name}: the writer changed the file");
        }
        let back = file::from_json_str(&written, Stability::Require)
            .unwrap_or_else(|e| panic!("{name} written back: {e}"));
        assert_eq!(back, lmn, "{name}");
    }
    assert!(models >= 2 && controllers >= 2, "{names:?}");
}
