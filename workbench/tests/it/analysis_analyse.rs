//! `fes analyse`: static analysis, force-frequency curve, stability report,
//! validation, on the Table 5.3 model; bad inputs.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use crate::analysis_support;

use analysis_support::*;
use fes_model::model::simulate::{mse, simulate};
use fes_testkit::control;

/// `--format svg`: the analysis's figures are written as SVG (vector, for papers) under
/// the same names, and no PNG is.
#[test]
fn figures_are_svg_when_asked() {
    let dir = tmp("analyse-svg");
    let model = save_model(&dir, "u.json", &fixtures::unstable());
    let data = save_dataset(&dir, &fixtures::truth(), 12, 590, 8, 3);
    let out = dir.join("out");
    let o = run(&[
        "analyse",
        "--model",
        model.to_str().unwrap(),
        "--data",
        data.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--format",
        "svg",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for name in ["static", "force_frequency", "validation", "resid"] {
        let text = std::fs::read_to_string(out.join(format!("{name}.svg")))
            .unwrap_or_else(|e| panic!("{name}.svg: {e}"));
        assert!(
            text.starts_with("<svg") && text.contains("</svg>"),
            "{name}"
        );
        assert!(!out.join(format!("{name}.png")).exists(), "{name}.png");
    }
}

/// The unstable Table 5.3 model with a data set from the stable truth: the report flags the
/// instability prominently, says the eigenvectors are local with the LPV caveat, marks
/// extrapolation above the training phi range, and each test record's MSSE in
/// validation.csv equals rt-core's simulation + eq. B.8 computed here (1e-12 relative).
#[test]
fn unstable_model_report() {
    let dir = tmp("analyse");
    let model = save_model(&dir, "u.json", &fixtures::unstable());
    let data = save_dataset(&dir, &fixtures::truth(), 12, 590, 8, 3);
    let out = dir.join("out");
    let o = run(&[
        "analyse",
        "--model",
        model.to_str().unwrap(),
        "--data",
        data.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("WARNING") && err.contains("[2]"), "{err}");
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    for needle in [
        "UNSTABLE MODEL",
        "**UNSTABLE**",
        "eigenvectors are local",
        "does **not** imply",
        "|1 + Ts p| < 1",
        "extrapolation",
        "test MSSE",
    ] {
        assert!(md.contains(needle), "report lacks {needle:?}");
    }
    for png in ["static.png", "force_frequency.png", "validation.png"] {
        assert!(is_png(&out.join(png)), "{png}");
        assert!(md.contains(&format!("({png})")));
    }
    // Static analysis: the frozen model is unstable somewhere, stable at phi = 0.
    let (h, rows) = csv(&out.join("static.csv"));
    let stable_col = h.iter().position(|x| x == "stable").unwrap();
    assert_eq!(rows[0][stable_col], "true");
    assert!(rows.iter().any(|r| r[stable_col] == "false"));
    // Force-frequency: 150 points; low frequencies inside, the highest extrapolated.
    let (h, rows) = csv(&out.join("force_frequency.csv"));
    assert_eq!(rows.len(), 150);
    let ex = h.iter().position(|x| x == "extrapolated").unwrap();
    assert_eq!(rows[0][ex], "false");
    assert_eq!(rows[149][ex], "true");
    // Validation: MSSE per test record recomputed.
    let ds = fes_dataset::DataSet::read(&data).unwrap();
    let net = fixtures::unstable().network().unwrap();
    let (h, rows) = csv(&out.join("validation.csv"));
    let got = column(&h, &rows, "msse");
    let fits = column(&h, &rows, "fit_percent");
    let rrses = column(&h, &rows, "rrse");
    assert_eq!(got.len(), 4);
    for (((rec, g), fit), rrse) in ds.test().zip(got).zip(fits).zip(rrses) {
        let u: Vec<f64> = rec
            .pulse
            .iter()
            .map(|&p| if p { 1.0 } else { 0.0 })
            .collect();
        let mut y = vec![0.0; u.len()];
        simulate(&net, &u, &mut y).unwrap();
        let want = mse(&rec.force, &y).unwrap();
        assert!(
            (g - want).abs() <= 1e-12 * want.max(1e-300),
            "{g} vs {want}"
        );
        // MATLAB's NRMSE fit and sysidentpy's RRSE, from their definitions.
        let mean = rec.force.iter().sum::<f64>() / rec.force.len() as f64;
        let err: f64 = rec.force.iter().zip(&y).map(|(a, b)| (a - b).powi(2)).sum();
        let spread: f64 = rec.force.iter().map(|a| (a - mean).powi(2)).sum();
        let want_rrse = (err / spread).sqrt();
        assert!(
            (rrse - want_rrse).abs() <= 1e-9 * want_rrse,
            "{rrse} vs {want_rrse}"
        );
        let want_fit = 100.0 * (1.0 - want_rrse);
        assert!((fit - want_fit).abs() <= 1e-7, "{fit} vs {want_fit}");
    }
    for needle in ["NRMSE fit", "test RRSE", "Residual tests", "(resid.png)"] {
        assert!(md.contains(needle), "report lacks {needle:?}");
    }
    assert!(is_png(&out.join("resid.png")));
    let (h, rows) = csv(&out.join("resid.csv"));
    assert_eq!(rows.len(), 51, "lags -25..=25");
    assert_eq!(h[0], "lag");
    let (h, rows) = csv(&out.join("traces_test.csv"));
    assert_eq!(h, ["record", "t_ms", "measured", "simulated"]);
    let samples: usize = ds.test().map(|r| r.force.len()).sum();
    assert_eq!(rows.len(), samples);
}

/// A common-eigenvector model with stable units: the report says the network is stable
/// for any scheduling sequence (2.4.1) and, without data, that nothing was validated.
#[test]
fn stable_common_eigenvector_model_without_data() {
    let dir = tmp("analyse-common");
    let model = save_model(&dir, "m.json", &control::fast_muscle(6));
    let out = dir.join("out");
    ok(&[
        "analyse",
        "--model",
        model.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--max-hz",
        "60",
    ]);
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(
        md.contains("share real eigenvectors") && md.contains("stable for any scheduling sequence"),
        "{md}"
    );
    assert!(md.contains("No data set given") && !md.contains("UNSTABLE"));
    let (h, rows) = csv(&out.join("force_frequency.csv"));
    // The fixture's output rises with frequency (gain 10 + 15 phi > 0).
    let y = column(&h, &rows, "mean_output");
    assert!(y.windows(2).all(|w| w[1] > w[0]));
    assert!(!out.join("validation.png").exists());
}

/// Missing data set, fewer than two records, a record with NaN, a model with no units,
/// bad option values: each a non-zero exit naming the problem.
#[test]
fn bad_inputs_name_the_problem() {
    let dir = tmp("analyse-bad");
    let model = save_model(&dir, "t.json", &fixtures::truth());
    let m = model.to_str().unwrap();
    let out = dir.join("out");
    let o = out.to_str().unwrap();
    let missing = dir.join("nope");
    fails(
        &[
            "analyse",
            "--model",
            m,
            "--data",
            missing.to_str().unwrap(),
            "--out",
            o,
        ],
        &["does not exist"],
    );

    let data = save_dataset(&dir, &fixtures::truth(), 3, 200, 2, 1);
    let meta = data.join("dataset.json");
    let original = std::fs::read_to_string(&meta).unwrap();
    let mut one: serde_json::Value = serde_json::from_str(&original).unwrap();
    one["records"] = serde_json::json!([one["records"][0].clone()]);
    one["split"] = serde_json::json!({"train": [0], "test": [0]});
    std::fs::write(&meta, one.to_string()).unwrap();
    fails(
        &[
            "analyse",
            "--model",
            m,
            "--data",
            data.to_str().unwrap(),
            "--out",
            o,
        ],
        &["1 record(s)", "at least 2"],
    );
    std::fs::write(&meta, &original).unwrap();

    let rec = data.join("record_001.csv");
    let text = std::fs::read_to_string(&rec).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let fields: Vec<&str> = lines[5].split(',').collect();
    lines[5] = format!("{},{},NaN", fields[0], fields[1]);
    std::fs::write(&rec, lines.join("\n") + "\n").unwrap();
    fails(
        &[
            "analyse",
            "--model",
            m,
            "--data",
            data.to_str().unwrap(),
            "--out",
            o,
        ],
        &["record_001.csv", "force", "not finite"],
    );

    let mut empty: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&model).unwrap()).unwrap();
    empty["units"] = serde_json::json!([]);
    let e = dir.join("empty.json");
    std::fs::write(&e, empty.to_string()).unwrap();
    fails(
        &["analyse", "--model", e.to_str().unwrap(), "--out", o],
        &["units"],
    );
    fails(
        &[
            "analyse",
            "--model",
            m,
            "--out",
            o,
            "--average-from-ms",
            "1000",
        ],
        &["--average-from-ms"],
    );
    fails(
        &[
            "analyse",
            "--model",
            dir.join("none.json").to_str().unwrap(),
            "--out",
            o,
        ],
        &["none.json"],
    );
}
