//! Writes the outer-loop figures of the documentation: docs/img/outer-loop-fatigue.png (the
//! control tests' fixture controller, exact force) and docs/img/outer-loop-fatigue-bench.png
//! (the shipped controller in the bench's chain, its sensor): 60 s of the fast muscle with
//! fatigue, 75 beats/min, target 0.3, outer loop on and off; prints each run's beats.
//!
//! `cargo run --release -p workbench --example outer_loop_figures [-- OUT_DIR]`
//! (default OUT_DIR: docs/img). The functional checks of the same runs are the tests
//! `runtime_outer_loop::*` of workbench.
#![allow(clippy::unwrap_used, clippy::expect_used)] // a tool: a failed step ends it with its message

use std::path::{Path, PathBuf};

use fes_bench::simulation::{SimSettings, simulate};
use fes_model::control::file::{Controller, ControllerSettings};
use fes_testkit::control;
use sim_muscle::muscle::MuscleConfig;
use sim_muscle::preset::Preset;
use supervisor::contraction::ContractionSettings;
use supervisor::limits::ReferenceLimits;
use supervisor::outer_loop::OuterLoopSettings;
use supervisor::profile::{CardiacSpec, ProfileSpec};
use workbench::plots::{BeatLine, plot_beats};

const TARGET: f64 = 0.3;

fn cardiac() -> ProfileSpec {
    ProfileSpec::Cardiac(CardiacSpec {
        bpm: 75.0,
        duty: 0.4,
        amplitude: TARGET,
        edge_rate_per_s: None,
        outer_loop: None,
        start_rest_ms: None,
    })
}

fn outer(enabled: bool) -> OuterLoopSettings {
    OuterLoopSettings {
        enabled,
        ..Default::default()
    }
}

/// The fixture's run: exact force (no sensor), 364 N full scale.
fn exact(outer_on: bool) -> SimSettings {
    let mut muscle = MuscleConfig::preset(Preset::Fast);
    muscle.fatigue = Some(sim_muscle::ding::FatigueParams::for_muscle(&muscle.ding));
    SimSettings {
        muscle,
        sensor: None,
        scale_n: 364.0,
        offset_n: 0.0,
        profile: cardiac(),
        outer_loop: outer(outer_on),
        contraction: ContractionSettings::default(),
        limits: ReferenceLimits::default(),
        seconds: 60.0,
        max_train_hz: 100,
    }
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let out_dir: PathBuf = std::env::args()
        .nth(1)
        .map_or_else(|| root.join("docs/img"), PathBuf::from);
    let fixture = Controller::design(
        control::fast_muscle(6),
        &control::table_6_1_specs(6),
        ControllerSettings::default(),
    )
    .expect("fixture controller");
    let shipped =
        Controller::load(root.join("models/fast.lcn.json")).expect("models/fast.lcn.json");
    let figures = [
        ("outer-loop-fatigue.png", "fixture controller", &fixture),
        (
            "outer-loop-fatigue-bench.png",
            "models/fast.lcn.json, bench sensor",
            &shipped,
        ),
    ];
    for (file, what, c) in figures {
        let mut lines = Vec::new();
        for (on, label) in [(true, "outer loop on"), (false, "outer loop off")] {
            let s = if file == "outer-loop-fatigue.png" {
                exact(on)
            } else {
                SimSettings::bench(c, true, cardiac(), outer(on), 60.0).unwrap()
            };
            let r = simulate(c, &s).unwrap();
            let t0 = r.beats[0].measurement.beat.start_ns;
            let points: Vec<(f64, f64)> = r
                .beats
                .iter()
                .filter_map(|b| {
                    let t = (b.measurement.beat.start_ns - t0) as f64 * 1e-9;
                    b.measurement.plateau_mean.map(|p| (t, p))
                })
                .collect();
            let p: Vec<f64> = points.iter().map(|x| x.1).collect();
            let fives: Vec<f64> = p[10..].windows(5).map(mean).collect();
            let worst = |v: &[f64]| {
                v.iter()
                    .map(|x| (x - TARGET).abs() / TARGET)
                    .fold(0.0, f64::max)
            };
            eprintln!(
                "{what}, {label}: first 5 beats {:.4}, last 5 beats {:.4}, mean {:.4}, worst beat after 10 {:.1} %, worst 5-beat mean after 10 {:.1} %",
                mean(&p[..5]),
                mean(&p[p.len() - 5..]),
                mean(&p),
                100.0 * worst(&p[10..]),
                100.0 * worst(&fives)
            );
            lines.push(BeatLine {
                label: label.into(),
                points,
            });
        }
        let out = out_dir.join(file);
        plot_beats(
            &out,
            &format!(
                "Fast muscle with fatigue, 75 beats/min, target 0.3 ({what}): contraction per beat"
            ),
            "plateau force per beat (normalised)",
            &lines,
            TARGET,
            0.1,
        )
        .unwrap();
        eprintln!("wrote {}", out.display());
    }
}
