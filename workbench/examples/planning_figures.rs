//! Writes the planning figures of the documentation (docs/control.md section 11,
//! docs/bench.md "Planning"): the in-process bench at 0.5 on the fast muscle with the
//! shipped controller, planning on and off: one beat's pulses and force each
//! (docs/img/planning-beat-on.png, planning-beat-off.png) and the CFT front with both
//! points (docs/img/planning-front.png).
//!
//! `cargo run --release -p workbench --example planning_figures [-- OUT_DIR [AMPLITUDE]]`
//! (default docs/img, 0.5). The functional checks of the same runs are the tests
//! `planning_bench::*` of workbench.
#![allow(clippy::unwrap_used, clippy::expect_used)] // a tool: a failed step ends it with its message

use std::path::PathBuf;

use fes_bench::simulation::{SimResult, SimSettings, T0_NS, simulate};
use fes_model::control::file::Controller;
use fes_model::control::planner::PlanningMode;
use sim_muscle::preset::Preset;
use supervisor::outer_loop::OuterLoopSettings;
use supervisor::profile::{CardiacSpec, ProfileSpec};
use workbench::plots::{RunSeries, plot_front_compare, plot_run};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let out = PathBuf::from(args.get(1).map_or("docs/img", String::as_str));
    let amplitude: f64 = args.get(2).map_or(0.5, |a| a.parse().unwrap());
    let planned = Controller::load("models/fast.lcn.json").unwrap();
    let mut causal = planned.clone();
    causal.settings.planning.mode = PlanningMode::Off;
    let profile = ProfileSpec::Cardiac(CardiacSpec {
        bpm: 75.0,
        duty: 0.4,
        amplitude,
        edge_rate_per_s: None,
        outer_loop: Some(true),
        start_rest_ms: None,
    });
    let mut verdicts = Vec::new();
    for (name, c) in [("on", &planned), ("off", &causal)] {
        let s = SimSettings::bench_muscle(
            c,
            Preset::Fast,
            false,
            profile.clone(),
            OuterLoopSettings::default(),
            30.0,
        )
        .unwrap();
        let run = simulate(c, &s).unwrap();
        let series = run.series();
        let v = s.front(amplitude, 0).verdict(&series).unwrap();
        let t_s: Vec<f64> = (0..run.pulse.len()).map(|k| k as f64 * 1e-3).collect();
        let rs = RunSeries {
            pulses_s: t_s
                .iter()
                .zip(&run.pulse)
                .filter(|(_, p)| **p)
                .map(|(t, _)| *t)
                .collect(),
            t_s,
            reference: run.reference.clone(),
            model: run.model_force.clone(),
            measured: run.measured.clone(),
        };
        let path = out.join(format!("planning-beat-{name}.png"));
        plot_run(
            &path,
            &format!(
                "Fast muscle, target {amplitude}, planning {name}: {:.2} pulses, RMS {:.4} per contraction",
                v.lcn.pulses_per_contraction, v.lcn.rms_error
            ),
            &rs,
            beat_window(&run, 10),
        )
        .unwrap();
        println!("{}: {:?}", path.display(), v.lcn);
        verdicts.push(v);
    }
    let path = out.join("planning-front.png");
    plot_front_compare(
        &path,
        &format!("CFT(f, n) front at {amplitude}, fast muscle: planning on (red) and off (orange)"),
        &verdicts[0],
        &[("planning off", &verdicts[1].lcn)],
    )
    .unwrap();
    println!("{}", path.display());
}

/// The time span of beat `index` (s from the run's start): the beats start after the
/// profile's start rest.
fn beat_window(run: &SimResult, index: usize) -> (f64, f64) {
    let b = run.beats[index].measurement.beat;
    let start = (b.start_ns - T0_NS) as f64 * 1e-9;
    (start, start + b.period_ns as f64 * 1e-9)
}
