//! The controller file `fes-lcn/1`: round trip, and rejection of corrupted, mismatched or
//! invalid files with errors that name the field.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use super::control_support;

use control_support::{TS, fast_muscle, table_6_1_specs};
use fes_model::control::design::{DesignError, DesignOptions, EstimatorPoles};
use fes_model::control::file::{
    Controller, ControllerFile, ControllerFileError, ControllerSettings,
};
use fes_model::control::lcn_design::LcnDesignError;
use fes_model::control::pattern_generator::{FeedbackMode, TickInput};
use fes_model::control::poles::dominant_pair;
use fes_model::model::lmn::LocalModelSet;
use serde_json::Value;

fn measured_settings() -> ControllerSettings {
    let [p1, p2] = dominant_pair(0.005, 1.2, TS).unwrap();
    ControllerSettings {
        mode: FeedbackMode::MeasuredForce,
        estimator_poles: Some(EstimatorPoles { p1, p2 }),
        ..ControllerSettings::default()
    }
}

fn designed() -> Controller {
    Controller::design(fast_muscle(6), &table_6_1_specs(6), measured_settings()).unwrap()
}

fn document() -> Value {
    serde_json::from_str(&designed().to_json_string().unwrap()).unwrap()
}

fn load(doc: &Value) -> Result<Controller, ControllerFileError> {
    Controller::from_json_str(&doc.to_string())
}

#[test]
fn round_trip_through_a_file_keeps_everything() {
    let c = designed();
    let dir = fes_testkit::Scratch::new("lcn-roundtrip");
    let path = dir.join("lcn-roundtrip.json");
    c.save(&path).unwrap();
    let back = Controller::load(&path).unwrap();
    // rt-core enables serde_json's `float_roundtrip`: every number reads back exactly.
    assert_eq!(back.units, c.units);
    assert_eq!(back.settings, c.settings);
    assert_eq!(back.lmn, c.lmn);
    // Same controller, same pulses.
    let (mut a, mut b) = (
        c.pattern_generator().unwrap(),
        back.pattern_generator().unwrap(),
    );
    for k in 0..2000 {
        let input = TickInput {
            reference: 0.4,
            measured_force: Some(0.1 * (k % 5) as f64),
            resting: false,
            ..Default::default()
        };
        assert_eq!(a.tick(&input), b.tick(&input), "k {k}");
    }
    // The text names the schema and the thesis fields.
    let text = c.to_json_string().unwrap();
    for key in [
        "\"fes-lcn/1\"",
        "\"fes-lmn/1\"",
        "rise_time_s",
        "k_x",
        "k_i",
        "p3",
        "min_gap",
    ] {
        assert!(text.contains(key), "{key} missing from the file");
    }
}

#[test]
fn a_corrupted_gain_is_rejected_naming_unit_and_field() {
    let mut doc = document();
    let k = doc["units"][2]["k_x"][1].as_f64().unwrap();
    doc["units"][2]["k_x"][1] = (k * (1.0 + 1e-6)).into();
    let err = load(&doc).unwrap_err();
    assert!(
        matches!(&err, ControllerFileError::Mismatch { unit: 2, field, .. } if field == "k_x[1]"),
        "{err}"
    );
    assert!(err.to_string().starts_with("units[2].k_x[1]"), "{err}");
    // A change far below the tolerance (1e-9 relative) is accepted.
    let mut doc = document();
    let k = doc["units"][4]["k_i"].as_f64().unwrap();
    doc["units"][4]["k_i"] = (k * (1.0 + 1e-12)).into();
    load(&doc).unwrap();
    // A corrupted estimator gain and a corrupted pole too.
    let mut doc = document();
    let l = doc["units"][0]["l"][0].as_f64().unwrap();
    doc["units"][0]["l"][0] = (l * 1.001).into();
    assert!(matches!(
        load(&doc),
        Err(ControllerFileError::Mismatch { unit: 0, .. })
    ));
    let mut doc = document();
    doc["units"][5]["p2"]["re"] = (-60.0).into();
    assert!(
        matches!(load(&doc), Err(ControllerFileError::Mismatch { unit: 5, field, .. }) if field == "p2.re")
    );
}

#[test]
fn gains_designed_for_another_model_are_rejected() {
    let mut doc = document();
    let c = doc["model"]["units"][3]["c"][0].as_f64().unwrap();
    doc["model"]["units"][3]["c"][0] = (c * 1.05).into();
    let err = load(&doc).unwrap_err();
    assert!(
        matches!(err, ControllerFileError::Mismatch { unit: 3, .. }),
        "{err}"
    );
}

#[test]
fn structural_errors_name_the_problem() {
    let mut doc = document();
    doc["schema"] = "fes-lcn/2".into();
    assert!(
        matches!(load(&doc), Err(ControllerFileError::Schema { found }) if found == "fes-lcn/2")
    );

    let text = document()
        .to_string()
        .replacen("\"k_i\":", "\"k_i\":NaN,\"x\":", 1);
    let err = Controller::from_json_str(&text).unwrap_err();
    assert!(matches!(err, ControllerFileError::Syntax(_)), "{err}");
    assert!(err.to_string().contains("NaN"), "{err}");

    let mut doc = document();
    doc["units"][1]["gain_typo"] = 1.0.into();
    let err = load(&doc).unwrap_err();
    assert!(err.to_string().contains("gain_typo"), "{err}");

    let mut doc = document();
    doc["units"][1].as_object_mut().unwrap().remove("k_i");
    let err = load(&doc).unwrap_err();
    assert!(err.to_string().contains("missing field `k_i`"), "{err}");

    let mut doc = document();
    doc["units"].as_array_mut().unwrap().pop();
    let err = load(&doc).unwrap_err();
    assert!(
        matches!(&err, ControllerFileError::Invalid { field, .. } if field == "units"),
        "{err}"
    );

    let mut doc = document();
    doc["units"][1]["rise_time_s"] = (-0.03).into();
    let err = load(&doc).unwrap_err();
    assert!(err.to_string().starts_with("units[1].rise_time_s"), "{err}");

    let mut doc = document();
    doc["shaper"]["min_gap"] = 0.into();
    let err = load(&doc).unwrap_err();
    assert!(matches!(err, ControllerFileError::Shaper(_)), "{err}");
    assert!(err.to_string().contains("min_gap"), "{err}");

    let mut doc = document();
    doc.as_object_mut().unwrap().remove("estimator_poles");
    let err = load(&doc).unwrap_err();
    assert!(err.to_string().starts_with("units[0].l"), "{err}");
}

#[test]
fn an_invalid_embedded_model_is_reported_by_the_model_library() {
    let mut doc = document();
    doc["model"]["units"][2]["eigenvalues"][0] = 5.0.into();
    let err = load(&doc).unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, ControllerFileError::Model(_)), "{msg}");
    assert!(
        msg.starts_with("model.") && msg.contains("units[2]"),
        "{msg}"
    );
}

#[test]
fn a_negative_gain_model_needs_the_explicit_override() {
    let mut lmn = fast_muscle(6);
    if let LocalModelSet::SsEigCommon { units, .. } = &mut lmn.local {
        units[4].c = [-units[4].c[0], -units[4].c[1]];
    }
    let err = Controller::design(
        lmn.clone(),
        &table_6_1_specs(6),
        ControllerSettings::default(),
    )
    .unwrap_err();
    assert!(
        matches!(
            err,
            ControllerFileError::Design(LcnDesignError::Design(DesignError::NegativeGain {
                unit: 4,
                ..
            }))
        ),
        "{err}"
    );
    let settings = ControllerSettings {
        design: DesignOptions {
            allow_negative_gain: true,
            ..DesignOptions::default()
        },
        ..ControllerSettings::default()
    };
    let c = Controller::design(lmn, &table_6_1_specs(6), settings).unwrap();
    // The override is stored, so the file loads again.
    let back = Controller::from_json_str(&c.to_json_string().unwrap()).unwrap();
    assert!(back.settings.design.allow_negative_gain);
    let file: ControllerFile = serde_json::from_str(&c.to_json_string().unwrap()).unwrap();
    assert!(file.design.allow_negative_gain);
}

use super::json_mutation;

/// Cases of the controller-file fuzz target: about 2.5 s in a debug build on one core.
const CONTROLLER_FUZZ_CASES: u32 = 2500;

/// Fuzz target: a designed controller's valid file, mutated as in the model-file
/// target. The loader must return an error value, or a controller whose file re-loads to the
/// same gains and whose pattern generator builds; a panic fails the test. Non-UTF-8 inputs
/// go through `Controller::load`, whose error must name the file.
#[test]
fn mutated_files_are_rejected_or_load_a_valid_controller() {
    use json_mutation::{Mutation, Tally, apply, mutation, scratch_file};
    use proptest::test_runner::{Config, TestCaseError, TestRunner};
    use proptest::{prop_assert, prop_assert_eq};
    use std::cell::RefCell;

    let dir = fes_testkit::Scratch::new("controller-fuzz");
    let doc = document();
    let same = apply(
        &doc,
        &Mutation {
            structural: vec![],
            bytes: None,
        },
    );
    assert_eq!(serde_json::from_slice::<Value>(&same).unwrap(), doc);
    let tally = RefCell::new(Tally::default());
    let started = std::time::Instant::now();
    let mut runner = TestRunner::new(Config {
        cases: CONTROLLER_FUZZ_CASES,
        failure_persistence: None,
        ..Config::default()
    });
    let result = runner.run(&mutation(), |m| {
        let bytes = apply(&doc, &m);
        let mut t = tally.borrow_mut();
        t.cases += 1;
        let loaded = match std::str::from_utf8(&bytes) {
            Ok(text) => Controller::from_json_str(text),
            Err(_) => {
                t.non_utf8 += 1;
                let path = scratch_file(&dir, "controller", &bytes);
                let r = Controller::load(&path);
                if let Err(e) = &r {
                    let msg = e.to_string();
                    prop_assert!(msg.contains("fuzz-controller"), "names no path: {}", msg);
                }
                r
            }
        };
        match loaded {
            Err(_) => t.rejected += 1,
            Ok(c) => {
                t.accepted += 1;
                let text = c
                    .to_json_string()
                    .map_err(|e| TestCaseError::fail(format!("accepted, not writable: {e}")))?;
                let back = Controller::from_json_str(&text)
                    .map_err(|e| TestCaseError::fail(format!("accepted, not re-loadable: {e}")))?;
                prop_assert_eq!(back.gains(), c.gains());
                c.pattern_generator()
                    .map_err(|e| TestCaseError::fail(format!("accepted, no generator: {e}")))?;
            }
        }
        Ok(())
    });
    let t = tally.into_inner();
    eprintln!(
        "controller file fuzz: {} cases in {:.2?} ({} accepted and valid, {} rejected, {} non-UTF-8)",
        t.cases,
        started.elapsed(),
        t.accepted,
        t.rejected,
        t.non_utf8
    );
    result.unwrap();
    assert!(
        t.rejected > t.cases / 2,
        "mutations should mostly break the file: {t:?}"
    );
}
