//! `fes modify --stabilise` on the thesis's Table 5.3 situation.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use crate::analysis_support;

use analysis_support::*;
use fes_ident::analysis::trace::simulate_trace;
use fes_model::model::file;
use fes_model::model::lmn::LocalModelSet;

/// The unstable model (+9.96 in unit 2) repaired with data from the stable truth: the file
/// loads with the strict loader, unit 2's slow eigenvalue is -1 and its offsets are the
/// truth's (1e-6), its 50 Hz long-train response stays bounded (|y| < 1) where the original
/// passes 10; the report has Table 5.4 and the plot.
#[test]
fn table_5_3_model_is_repaired() {
    let dir = tmp("modify");
    let model = save_model(&dir, "u.lmn.json", &fixtures::unstable());
    let data = save_dataset(&dir, &fixtures::truth(), 40, 590, 30, 5);
    let out = dir.join("fixed.lmn.json");
    let stdout = ok(&[
        "modify",
        "--model",
        model.to_str().unwrap(),
        "--stabilise",
        "--data",
        data.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--long-train-hz",
        "50",
    ]);
    assert!(
        stdout.contains("Table 5.4") && stdout.contains("| modified |"),
        "{stdout}"
    );
    let fixed = file::load(&out).expect("strict loader accepts the repaired model");
    let LocalModelSet::SsEigLocal(units) = &fixed.local else {
        panic!()
    };
    assert_eq!(units[2].eigenvalues[1], -1.0);
    assert_eq!(units[2].eigenvalues[0], fixtures::TABLE_5_3[2][0]);
    let got = [units[2].dx[0], units[2].dx[1], units[2].dy];
    for (g, w) in got.iter().zip(fixtures::TRUE_OFFSETS[2]) {
        assert!((g - w).abs() < 1e-6, "{got:?}");
    }
    assert!(fixed.provenance.train_msse.unwrap() < 1e-16);
    assert!(fixed.provenance.extra.contains_key("modified"));
    let train = fixtures::constant(20, 3000);
    let amax = |y: &[f64]| y.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    let after = simulate_trace(&fixed.network().unwrap(), &train).unwrap();
    let before = simulate_trace(&fixtures::unstable().network().unwrap(), &train).unwrap();
    assert!(amax(&after.y) < 1.0 && amax(&before.y) > 10.0);
    assert!(is_png(&dir.join("fixed-long-train.png")));
    let md = std::fs::read_to_string(dir.join("fixed-modify.md")).unwrap();
    assert!(md.contains("9.96") && md.contains("fixed-long-train.png"));
}

/// Refusals: no action, no data set, a replacement eigenvalue outside (-1/Ts, 0), an
/// output that is not a .json file; nothing is written.
#[test]
fn refusals_name_the_problem() {
    let dir = tmp("modify-bad");
    let model = save_model(&dir, "u.json", &fixtures::unstable());
    let data = save_dataset(&dir, &fixtures::truth(), 4, 300, 2, 1);
    let (m, d) = (model.to_str().unwrap(), data.to_str().unwrap());
    let out = dir.join("f.json");
    let o = out.to_str().unwrap();
    fails(
        &["modify", "--model", m, "--data", d, "--out", o],
        &["--stabilise"],
    );
    fails(
        &[
            "modify",
            "--model",
            m,
            "--stabilise",
            "--data",
            dir.join("x").to_str().unwrap(),
            "--out",
            o,
        ],
        &["does not exist"],
    );
    fails(
        &[
            "modify",
            "--model",
            m,
            "--stabilise",
            "--data",
            d,
            "--out",
            o,
            "--eigenvalue",
            "2",
        ],
        &["replacement eigenvalue 2"],
    );
    fails(
        &[
            "modify",
            "--model",
            m,
            "--stabilise",
            "--data",
            d,
            "--out",
            dir.join("f.txt").to_str().unwrap(),
        ],
        &[".json"],
    );
    assert!(!out.exists());
}
