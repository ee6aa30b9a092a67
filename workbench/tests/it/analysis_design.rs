//! `fes design`: Tables 6.1 / 6.2 and the closed-loop poles, and its refusals.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use crate::analysis_support;

use analysis_support::*;
use fes_model::model::lmn::LocalModelSet;
use fes_testkit::control::fast_muscle;

/// Thesis Table 6.1 (fast muscle): t_r (ms), p1, p2.
const TABLE_6_1: [(f64, f64, f64); 6] = [
    (100.0, -57.9, -17.0),
    (30.0, -180.2, -55.6),
    (30.0, -180.2, -55.6),
    (10.0, -449.1, -157.8),
    (20.0, -257.8, -82.3),
    (30.0, -180.2, -55.6),
];
/// Thesis Table 6.2 (slow muscle).
const TABLE_6_2: [(f64, f64, f64); 5] = [
    (30.0, -180.2, -55.6),
    (72.5, -79.0, -23.4),
    (115.0, -50.5, -14.8),
    (157.5, -37.2, -10.8),
    (200.0, -29.4, -8.6),
];

/// Coefficients [c2, c1, c0] of det(sI - M) = s^3 + c2 s^2 + c1 s + c0 of a 3x3 matrix.
fn char_poly(m: [[f64; 3]; 3]) -> [f64; 3] {
    let tr = m[0][0] + m[1][1] + m[2][2];
    let minors = m[0][0] * m[1][1] - m[0][1] * m[1][0] + m[0][0] * m[2][2] - m[0][2] * m[2][0]
        + m[1][1] * m[2][2]
        - m[1][2] * m[2][1];
    let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    [-tr, minors, -det]
}

/// Designs from the rise times and checks: p1, p2 of every unit against the table to its
/// printed digit (half a unit of 0.1: `w_n t_r = 3.2`, docs/control.md),
/// and the closed loop of each unit, A_aug - b_aug K (eq. C.25-C.27) built here from the
/// model file and the stored gains, has the characteristic polynomial
/// (s - p1)(s - p2)(s - p3) of the designed poles (1e-6 relative per coefficient).
fn check(table: &[(f64, f64, f64)], rise: &str) {
    let dir = tmp("design");
    let model = save_model(&dir, "m.json", &fast_muscle(table.len()));
    let out = dir.join("c.json");
    let stdout = ok(&[
        "design",
        "--model",
        model.to_str().unwrap(),
        "--rise-ms",
        rise,
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(
        stdout.contains("t_r [ms]") && stdout.contains("K_I"),
        "{stdout}"
    );
    let c: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let lmn = fes_model::model::file::load(&model).unwrap();
    let units = lmn.ss_units().unwrap();
    for (i, &(tr, p1, p2)) in table.iter().enumerate() {
        let u = &c["units"][i];
        let f = |v: &serde_json::Value| v.as_f64().unwrap();
        assert!((f(&u["rise_time_s"]) * 1e3 - tr).abs() < 1e-9);
        let (q1, q2, q3) = (f(&u["p1"]["re"]), f(&u["p2"]["re"]), f(&u["p3"]["re"]));
        assert!((q1 - p1).abs() <= 0.05, "unit {i}: p1 {q1} vs {p1}");
        assert!((q2 - p2).abs() <= 0.05, "unit {i}: p2 {q2} vs {p2}");
        let (kx, ki) = ([f(&u["k_x"][0]), f(&u["k_x"][1])], f(&u["k_i"]));
        let m = &units[i];
        // State [x_I, x]: d x_I = c'x (- r), d x = A x + b u, u = -K_I x_I - K_x' x.
        let cl = [
            [0.0, m.c[0], m.c[1]],
            [
                -m.b[0] * ki,
                m.a[0][0] - m.b[0] * kx[0],
                m.a[0][1] - m.b[0] * kx[1],
            ],
            [
                -m.b[1] * ki,
                m.a[1][0] - m.b[1] * kx[0],
                m.a[1][1] - m.b[1] * kx[1],
            ],
        ];
        let got = char_poly(cl);
        let want = [-(q1 + q2 + q3), q1 * q2 + q1 * q3 + q2 * q3, -q1 * q2 * q3];
        for j in 0..3 {
            assert!(
                (got[j] - want[j]).abs() < 1e-6 * want[j].abs(),
                "unit {i} coefficient {j}: {} vs {}",
                got[j],
                want[j]
            );
        }
    }
}

#[test]
fn reproduces_table_6_1_and_closed_loop_poles() {
    check(&TABLE_6_1, "100,30,30,10,20,30");
}

/// `--rise-ms auto` spreads 30..200 ms evenly: Table 6.2's rise times for 5 units.
#[test]
fn auto_reproduces_table_6_2() {
    check(&TABLE_6_2, "auto");
}

/// Rise-time count != units, bad numbers, negative local gains from the offsets (with the
/// zero-offset advice; overridable), an unstable model, an ARX model.
#[test]
fn refusals_name_the_problem() {
    let dir = tmp("design-bad");
    let m6 = save_model(&dir, "m6.json", &fast_muscle(6));
    let m = m6.to_str().unwrap();
    let out = dir.join("c.json");
    let o = out.to_str().unwrap();
    fails(
        &[
            "design",
            "--model",
            m,
            "--rise-ms",
            "100,30,30,10,20",
            "--out",
            o,
        ],
        &["5 rise time(s)", "6 units"],
    );
    fails(
        &[
            "design",
            "--model",
            m,
            "--rise-ms",
            "100,30,x,10,20,30",
            "--out",
            o,
        ],
        &["--rise-ms", "`x`"],
    );
    fails(
        &[
            "design",
            "--model",
            m,
            "--rise-ms",
            "100,30,0,10,20,30",
            "--out",
            o,
        ],
        &["unit 2", "> 0"],
    );
    fails(
        &[
            "design",
            "--model",
            m,
            "--rise-ms",
            "auto",
            "--damping",
            "0",
            "--out",
            o,
        ],
        &["--damping"],
    );
    assert!(!out.exists());

    // Offsets that make unit 1's gain negative (its output map flipped, offsets free).
    let mut neg = fast_muscle(3);
    neg.zero_offsets = false;
    if let LocalModelSet::SsEigCommon { units, .. } = &mut neg.local {
        units[1].c = [-units[1].c[0], -units[1].c[1]];
        units[1].dy = 0.3;
        units[1].dx = [0.5, 0.0];
    }
    let n = save_model(&dir, "neg.json", &neg);
    let n = n.to_str().unwrap();
    fails(
        &["design", "--model", n, "--rise-ms", "auto", "--out", o],
        &["negative", "unit 1", "--zero-offsets", "6.5.3"],
    );
    let err = String::from_utf8_lossy(
        &run(&[
            "design",
            "--model",
            n,
            "--rise-ms",
            "auto",
            "--out",
            o,
            "--allow-negative-gain",
        ])
        .stderr,
    )
    .into_owned();
    assert!(out.exists() && err.contains("WARNING"), "{err}");

    let unstable = save_model(&dir, "u.json", &fixtures_unstable());
    fails(
        &[
            "design",
            "--model",
            unstable.to_str().unwrap(),
            "--rise-ms",
            "auto",
            "--out",
            o,
        ],
        &["unstable", "modify --stabilise"],
    );

    let mut empty: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&m6).unwrap()).unwrap();
    empty["units"] = serde_json::json!([]);
    let e = dir.join("empty.json");
    std::fs::write(&e, empty.to_string()).unwrap();
    fails(
        &[
            "design",
            "--model",
            e.to_str().unwrap(),
            "--rise-ms",
            "auto",
            "--out",
            o,
        ],
        &["units"],
    );
}

fn fixtures_unstable() -> fes_model::model::Lmn {
    fixtures::unstable()
}

/// `--min-interval-ms`: the shaper's `min_gap` is the interval in model samples less the
/// pulse's own (thesis: 2 ms, `min_gap` 1, the default); a RehaStim 2's 20 ms is 19; an
/// interval of less than two samples is refused naming the option.
#[test]
fn the_minimum_interval_becomes_the_shapers_gap() {
    let dir = tmp("design-gap");
    let model = save_model(&dir, "m.json", &fast_muscle(6));
    let m = model.to_str().unwrap();
    let out = dir.join("c.json");
    let o = out.to_str().unwrap();
    let gap = |extra: &[&str]| {
        let mut args = vec!["design", "--model", m, "--rise-ms", "auto", "--out", o];
        args.extend_from_slice(extra);
        ok(&args);
        let c: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
        c["shaper"]["min_gap"].as_u64().unwrap()
    };
    assert_eq!(gap(&[]), 1);
    assert_eq!(gap(&["--min-interval-ms", "20"]), 19);
    assert_eq!(gap(&["--min-interval-ms", "2.5"]), 2);
    fails(
        &[
            "design",
            "--model",
            m,
            "--rise-ms",
            "auto",
            "--min-interval-ms",
            "1",
            "--out",
            o,
        ],
        &["--min-interval-ms 1"],
    );
}

/// `--feedback measured-force` writes Fig. 6.6(a)'s loop: the file's mode and the
/// estimator's pole pair from `--estimator-rise-ms` (damping 1.2, the thesis's rise-time
/// rule); the default is the model loop with no estimator; a rise time that is not a
/// positive number is refused naming the option.
#[test]
fn measured_force_feedback_writes_the_estimators_poles() {
    use fes_model::control::file::Controller;
    use fes_model::control::pattern_generator::FeedbackMode;
    let dir = tmp("design-measured");
    let lmn = fast_muscle(6);
    let ts = lmn.ts;
    let model = save_model(&dir, "m.json", &lmn);
    let m = model.to_str().unwrap();
    let out = dir.join("c.json");
    let o = out.to_str().unwrap();
    let base = ["design", "--model", m, "--rise-ms", "auto", "--out", o];
    ok(&base);
    let c = Controller::load(&out).unwrap();
    assert_eq!(c.settings.mode, FeedbackMode::Model);
    assert_eq!(c.settings.estimator_poles, None);
    let mut args = base.to_vec();
    args.extend_from_slice(&["--feedback", "measured-force", "--estimator-rise-ms", "8"]);
    ok(&args);
    let c = Controller::load(&out).unwrap();
    assert_eq!(c.settings.mode, FeedbackMode::MeasuredForce);
    let [p1, p2] = fes_model::control::poles::dominant_pair(0.008, 1.2, ts).unwrap();
    let poles = c.settings.estimator_poles.unwrap();
    assert_eq!((poles.p1, poles.p2), (p1, p2));
    let mut args = base.to_vec();
    args.extend_from_slice(&["--feedback", "measured-force", "--estimator-rise-ms", "0"]);
    fails(&args, &["--estimator-rise-ms 0"]);
}

/// A model of eq. 5.2's undelayed scheduling class cannot be run ahead: `fes design` refuses
/// the advanced loop naming `feedback_state` and designs the thesis's delayed loop (with no
/// planning by default, whose warm start is the advanced loop); `fes lcn-variants` runs only
/// the delayed-state variants on it, says which it did not run and why, reports the shaper's
/// lowest energy, and refuses a list with no delayed-state variant.
#[test]
fn the_undelayed_class_runs_only_the_delayed_loop() {
    use fes_model::model::scheduling::{SchedulingInput, SchedulingSpec};
    let dir = tmp("undelayed");
    let mut lmn = fast_muscle(4);
    let SchedulingSpec::Input {
        scheduling_input, ..
    } = &mut lmn.scheduling
    else {
        panic!("input scheduling");
    };
    *scheduling_input = SchedulingInput::Undelayed;
    let model = save_model(&dir, "m.json", &lmn);
    let m = model.to_str().unwrap();
    let out = dir.join("c.json");
    let o = out.to_str().unwrap();
    fails(
        &["design", "--model", m, "--rise-ms", "auto", "--out", o],
        &["feedback_state", "undelayed"],
    );
    ok(&[
        "design",
        "--model",
        m,
        "--rise-ms",
        "auto",
        "--feedback-state",
        "delayed",
        "--out",
        o,
    ]);
    let c = fes_model::control::file::Controller::load(&out).unwrap();
    assert_eq!(
        c.settings.planning.mode,
        fes_model::control::planner::PlanningMode::Off
    );
    let variants = dir.join("variants");
    let v = variants.to_str().unwrap();
    let common = [
        "lcn-variants",
        "--model",
        m,
        "--muscle",
        "fast",
        "--levels",
        "0.3",
        "--out",
        v,
    ];
    fails(
        &[&common[..], &["--variants", "default,p3-mapped"]].concat(),
        &["undelayed", "delayed-state"],
    );
    ok(&[&common[..], &["--variants", "default,thesis,delayed-state"]].concat());
    let md = std::fs::read_to_string(variants.join("variants.md")).unwrap();
    assert!(md.contains("Not run: `default`"), "{md}");
    assert!(
        md.contains("## `thesis`") && md.contains("## `delayed-state`"),
        "{md}"
    );
    let (h, rows) = csv(&variants.join("variants.csv"));
    assert_eq!(rows.len(), 2);
    let min_e = column(&h, &rows, "min_energy");
    assert!(
        min_e[0] < 0.0 || min_e[1] < 0.0,
        "the signed sum goes below 0: {min_e:?}"
    );
    assert!(min_e.iter().all(|e| e.is_finite()));
}
