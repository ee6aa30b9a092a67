//! `fes osp` on sim-muscle's Ding presets (the thesis's findings, 6.2-6.4), side by
//! side with a model, and the LCN method; bad inputs.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use crate::analysis_support;

use analysis_support::*;
use fes_testkit::control;

fn cell(h: &[String], rows: &[Vec<String>], subject: &str, pulses: usize, ipi: f64) -> f64 {
    let (s, p, i, f) = (
        h.iter().position(|x| x == "subject").unwrap(),
        h.iter().position(|x| x == "pulses").unwrap(),
        h.iter().position(|x| x == "ipi_ms").unwrap(),
        h.iter().position(|x| x == "ftipp").unwrap(),
    );
    rows.iter()
        .find(|r| {
            r[s] == subject && r[p] == pulses.to_string() && r[i].parse::<f64>().unwrap() == ipi
        })
        .map(|r| r[f].parse().unwrap())
        .unwrap_or_else(|| panic!("no cell {subject} {pulses} {ipi}"))
}

/// Fast preset (catch-like): short high-frequency bursts have FTIpP above 1 (doublet at
/// 2-5 ms > 1.3, triplet at 5 ms > 1.1, thesis Fig. 6.3(a) area A); the iterative method
/// starts with a doublet at <= 5 ms; the best random pattern is above 1 and FTIpP grows
/// with the average frequency (positive correlation, Fig. 6.1).
#[test]
fn fast_preset_gains_from_short_bursts() {
    let out = tmp("osp-fast");
    ok(&[
        "osp",
        "--muscle",
        "fast",
        "--method",
        "trains,iterative,random",
        "--patterns",
        "120",
        "--out",
        out.to_str().unwrap(),
    ]);
    let (h, rows) = csv(&out.join("trains.csv"));
    let s = "Ding fast muscle";
    assert!(cell(&h, &rows, s, 2, 2.0) > 1.3);
    assert!(cell(&h, &rows, s, 2, 5.0) > 1.3);
    assert!(cell(&h, &rows, s, 3, 5.0) > 1.1);
    assert!((cell(&h, &rows, s, 1, 50.0) - 1.0).abs() < 1e-12);
    let (h, rows) = csv(&out.join("iterative.csv"));
    let ft = column(&h, &rows, "ftipp");
    let ipi = column(&h, &rows, "last_ipi_ms");
    let pulses = column(&h, &rows, "pulses");
    let (best_i, _) = ft
        .iter()
        .enumerate()
        .filter(|(i, _)| pulses[*i] == 2.0)
        .fold((0, f64::MIN), |b, (i, &v)| if v > b.1 { (i, v) } else { b });
    assert!(ipi[best_i] <= 5.0, "doublet IPI {}", ipi[best_i]);
    let (h, rows) = csv(&out.join("random.csv"));
    let ft = column(&h, &rows, "ftipp");
    assert!(ft.iter().copied().fold(f64::MIN, f64::max) > 1.0);
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(
        md.contains("| Ding fast muscle |") && md.contains("+0."),
        "positive correlation:\n{md}"
    );
    for png in ["trains.png", "iterative.png", "random.png"] {
        assert!(is_png(&out.join(png)));
    }
}

/// Slow preset (no catch-like effect): no train has FTIpP above 1 (1e-9), the best cell is
/// the single pulse, every iterative stage is below 1, and FTIpP falls with the average
/// frequency (Figs. 6.2, 6.3(b), 6.4(b)).
#[test]
fn slow_preset_is_best_with_single_pulses() {
    let out = tmp("osp-slow");
    ok(&[
        "osp",
        "--muscle",
        "slow",
        "--method",
        "trains,iterative,random",
        "--patterns",
        "80",
        "--out",
        out.to_str().unwrap(),
    ]);
    let (h, rows) = csv(&out.join("trains.csv"));
    let ft = column(&h, &rows, "ftipp");
    let pulses = column(&h, &rows, "pulses");
    for (v, p) in ft.iter().zip(&pulses) {
        assert!(*v <= 1.0 + 1e-9, "{p} pulses: {v}");
        if *p > 1.0 {
            assert!(*v < 1.0);
        }
    }
    let (h, rows) = csv(&out.join("iterative.csv"));
    assert!(column(&h, &rows, "ftipp").iter().all(|v| *v < 1.0));
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(
        md.contains("1.000 (1 pulse: the twitch)") && md.contains("-0."),
        "{md}"
    );
}

/// A model and the Ding muscle side by side: one heat-map image, both subjects in the CSV;
/// the LCN method with a controller drives both with its pattern.
#[test]
fn model_and_muscle_side_by_side_and_lcn() {
    let dir = tmp("osp-both");
    let mut lmn = control::fast_muscle(6);
    lmn.force_scale_n = 400.0;
    let model = save_model(&dir, "m.json", &lmn);
    let ctl = dir.join("c.json");
    ok(&[
        "design",
        "--model",
        model.to_str().unwrap(),
        "--rise-ms",
        "100,30,30,10,20,30",
        "--out",
        ctl.to_str().unwrap(),
    ]);
    let out = dir.join("out");
    ok(&[
        "osp",
        "--model",
        model.to_str().unwrap(),
        "--muscle",
        "fast",
        "--controller",
        ctl.to_str().unwrap(),
        "--method",
        "trains,lcn",
        "--train-pulses",
        "4",
        "--ipi-max-ms",
        "40",
        "--levels",
        "0.3,0.5",
        "--out",
        out.to_str().unwrap(),
    ]);
    let (h, rows) = csv(&out.join("trains.csv"));
    let s = h.iter().position(|x| x == "subject").unwrap();
    assert!(
        rows.iter().any(|r| r[s] == "model m.json")
            && rows.iter().any(|r| r[s] == "Ding fast muscle")
    );
    assert_eq!(rows.len(), 2 * 4 * 39);
    let (h, rows) = csv(&out.join("lcn.csv"));
    assert_eq!(rows.len(), 2);
    let n = column(&h, &rows, "pulses");
    assert!(n[1] > n[0] && n[0] > 3.0, "{n:?}");
    assert!(is_png(&out.join("lcn.png")) && is_png(&out.join("trains.png")));
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("LCN-generated patterns") && md.contains("Ding fast muscle:"));
}

/// lcn without a controller, no subject for trains, a window shorter than the patterns,
/// an inverted IPI range, a reference level outside [0, 1].
#[test]
fn refusals_name_the_problem() {
    let out = tmp("osp-bad");
    let o = out.to_str().unwrap();
    fails(
        &["osp", "--muscle", "fast", "--method", "lcn", "--out", o],
        &["--controller"],
    );
    fails(
        &[
            "osp",
            "--muscle",
            "fast",
            "--method",
            "trains",
            "--window-ms",
            "500",
            "--out",
            o,
        ],
        &["--window-ms 500", "too short"],
    );
    fails(
        &[
            "osp",
            "--muscle",
            "fast",
            "--method",
            "trains",
            "--ipi-min-ms",
            "50",
            "--ipi-max-ms",
            "10",
            "--out",
            o,
        ],
        &["--ipi-min-ms"],
    );
    fails(
        &[
            "osp", "--muscle", "fast", "--method", "trains", "--levels", "0.2,1.5", "--out", o,
        ],
        &["1.5", "[0, 1]"],
    );
    fails(&["osp", "--method", "trains", "--out", o], &["--model"]);
}
