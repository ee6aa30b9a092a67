//! The targets the shipped controllers (`models/{fast,slow}.lcn.json`) must meet, on the
//! deterministic in-process chain: the pattern generator on step references from rest, its
//! pattern driving sim-muscle's Ding muscle outside the loop (thesis Fig. 6.6(b)); and the
//! in-process bench's verdict against the constant-frequency trains (docs/bench.md).
//!
//! The step runs are the variant table's (`StepSettings::variant_table`: step at 50 ms,
//! 3 s, the hold scored over 1.5-3 s in whole inter-pulse intervals, convention 11).
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use std::path::Path;

use crate::analysis_support::bench_profile;

use fes_bench::simulation::{SimSettings, simulate};
use fes_bench::summary::{AnalysisInput, RunTiming, summarise};
use fes_ident::analysis::osp::ForceResponse;
use fes_ident::analysis::osp::lcn::{StepScore, StepSettings, evaluate_step};
use fes_model::control::file::Controller;
use sim_muscle::muscle::{Muscle, MuscleConfig};
use sim_muscle::preset::Preset;
use sim_muscle::simulate::MuscleResponse;
use supervisor::outer_loop::OuterLoopSettings;

const LEVELS: [f64; 7] = [0.1, 0.15, 0.2, 0.3, 0.5, 0.7, 0.9];

fn shipped(name: &str) -> Controller {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../models/{name}.lcn.json"));
    Controller::load(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Every level's step score with the Ding muscle of `preset` driven by the pattern.
fn scores(c: &Controller, preset: Preset) -> Vec<StepScore> {
    let muscle = MuscleResponse::new(Muscle::new(MuscleConfig::preset(preset)).unwrap());
    let subjects: [(&dyn ForceResponse, f64); 1] = [(&muscle, 1.0 / c.lmn.force_scale_n)];
    let settings = StepSettings::variant_table(c.lmn.ts);
    let mut pg = c.pattern_generator().unwrap();
    LEVELS
        .iter()
        .map(|&r| evaluate_step(&mut pg, r, &settings, &subjects).unwrap().1)
        .collect()
}

/// The loop's own model's mean over the second half within `within` (relative) of the level.
fn assert_loop_holds(s: &StepScore, within: f64) {
    assert!(
        (s.loop_mean - s.level).abs() <= within * s.level,
        "r = {}: loop {}",
        s.level,
        s.loop_mean
    );
}

/// The Ding muscle's mean over the second half within 5 % of the level.
fn assert_held(s: &StepScore) {
    let e = (s.subjects[0].mean - s.level) / s.level;
    assert!(
        e.abs() <= 0.05,
        "r = {}: muscle mean {:.4} ({:+.1} %)",
        s.level,
        s.subjects[0].mean,
        100.0 * e
    );
}

/// Slow muscle: the Ding muscle driven by the pattern holds every level within 5 % (the
/// slow muscle's single twitch peaks far above the low levels: the loop must space its
/// pulses out, not fire as soon as the force falls back to r), and no pattern opens with a
/// doublet: the first IPI is shorter than the later ones but longer than 10 ms (6.5.4).
#[test]
fn slow_muscle_is_held_at_every_level_without_a_doublet() {
    for s in scores(&shipped("slow"), Preset::Slow) {
        assert_held(&s);
        assert_loop_holds(&s, 0.01);
        let first = s.first_ipi().expect("at least two pulses");
        assert!(first > 10, "r = {}: first IPI {first} ms", s.level);
        let shape = s.shape.as_ref().unwrap();
        assert!(!shape.has_burst, "r = {}: {shape:?}", s.level);
        if let Some(m) = shape.steady_median {
            assert!(
                (first as f64) <= m,
                "r = {}: first IPI {first} vs later {m}",
                s.level
            );
        }
        assert_eq!(s.short_ipis_after_opening(10), 0, "r = {}", s.level);
    }
}

/// Fast muscle: every level within 5 % on the Ding muscle; a single opening pulse at
/// r <= 0.15 ("a single pulse suffices", 6.5.4); from r = 0.3 a doublet or triplet, then a
/// pause, then nearly even pulses (Fig. 6.9, convention 9); no burst limit cycle.
#[test]
fn fast_muscle_patterns_are_the_thesis_shapes_at_every_level() {
    for s in scores(&shipped("fast"), Preset::Fast) {
        assert_held(&s);
        let shape = s.shape.as_ref().expect("at least two pulses");
        if s.level <= 0.15 {
            assert!(
                !shape.has_burst,
                "r = {}: opens with a burst {shape:?}",
                s.level
            );
        }
        if s.level >= 0.3 {
            assert!(
                shape.is_doublet_pause_even() && shape.burst_pulses <= 3,
                "r = {}: {shape:?}",
                s.level
            );
        }
        assert_eq!(s.short_ipis_after_opening(10), 0, "r = {}", s.level);
    }
}

/// The in-process bench (30 s at 75 beats/min, fast muscle, bench sensor, outer loop on):
/// at amplitudes 0.2, 0.3 and 0.4 no constant-frequency train of the same FTI (within 5 %)
/// delivers the contraction with no more pulses and no larger tracking error.
#[test]
fn no_constant_frequency_train_dominates_the_shipped_controller() {
    let c = shipped("fast");
    for amplitude in [0.2, 0.3, 0.4] {
        let profile = bench_profile(amplitude, None);
        let settings =
            SimSettings::bench(&c, false, profile, OuterLoopSettings::default(), 30.0).unwrap();
        let run = simulate(&c, &settings).unwrap();
        let summary = summarise(
            &run.series(),
            &AnalysisInput {
                delay: c.lmn.delay,
                target: amplitude,
                baseline: None,
                uml: false,
                front: Some(settings.front(amplitude, 0)),
            },
            RunTiming::default(),
            String::new(),
        );
        let v = summary.front.expect("front");
        // Every train CFT(f, n), 5-100 Hz, n up to all that fit in the contraction: the
        // whole trains are among them.
        assert!(v.cft_front.len() > 1000, "{} trains", v.cft_front.len());
        for hz in 5..=100u32 {
            let all = sim_muscle::pattern::constant_train(hz as f64, 0, 320, 1e-3)
                .unwrap()
                .len() as u32;
            assert!(
                v.cft_front
                    .iter()
                    .any(|p| p.hz == Some(hz) && p.n == Some(all))
                    || v.cft_front
                        .iter()
                        .any(|p| p.n == Some(all) && p.hz < Some(hz)),
                "{hz} Hz x {all} missing"
            );
        }
        assert!(
            !v.lcn_dominated,
            "amplitude {amplitude}: LCN {:?} dominated",
            v.lcn
        );
        eprintln!(
            "amplitude {amplitude}: LCN {:.2} pulses, RMS {:.4}; pulses vs the cheapest CFT as good {:?}",
            v.lcn.pulses_per_contraction, v.lcn.rms_error, v.pulses_vs_equal_rms_cft
        );
    }
}

/// The shipped fast controller is steady under fatigue with the outer loop (60 s at 0.3,
/// the bench's fatigue run): every beat after the 10th within 2 % of the target
/// (`scripts/lcn-search` chose it among the designs that meet the step targets).
#[test]
fn shipped_controller_is_steady_under_fatigue() {
    // The causal loop (planning under fatigue: `planning_bench`), on the profile as this
    // figure was measured: the first contraction at once. With the default 200 ms start rest
    // the same loop gives 2.22 %: the sensor noise falls differently on the beats, so the
    // 2 % is met with little margin.
    let mut c = shipped("fast");
    c.settings.planning.mode = fes_model::control::planner::PlanningMode::Off;
    let profile = bench_profile(0.3, Some(0.0));
    let settings =
        SimSettings::bench(&c, true, profile, OuterLoopSettings::default(), 60.0).unwrap();
    let run = simulate(&c, &settings).unwrap();
    let plateaus: Vec<f64> = run
        .beats
        .iter()
        .filter_map(|b| b.measurement.plateau_mean)
        .collect();
    assert!(plateaus.len() >= 73, "{} beats", plateaus.len());
    let worst = plateaus[10..]
        .iter()
        .map(|p| (p - 0.3).abs() / 0.3)
        .fold(0.0, f64::max);
    assert!(
        worst <= 0.02,
        "worst beat after the 10th {:.2} %",
        100.0 * worst
    );
}

/// The thesis's kind of plant (`thesis-fast`: identified local models with a fast pole of
/// -97 to -238 1/s beside a slow one of -11 to -20 1/s, Table 5.3's kind) and the model
/// class of eq. 5.2 (`models/thesis-fast.lmn.json`, `scheduling_input = "undelayed"`). Its
/// shipped controller is the thesis's delayed loop (x[k] fed back, gains scheduled on
/// phi(t) = Gamma{u(t)}, plain integral action) with slower rise times (120-300 ms) and the
/// clamped shaper sum: it holds every level within 5 % on the Ding muscle, and the loop's
/// model within 1 %.
#[test]
fn the_delayed_loop_holds_the_thesis_like_plant_at_every_level() {
    use fes_model::control::pattern_generator::FeedbackState;
    use fes_model::model::scheduling::SchedulingInput;
    let c = shipped("thesis-fast");
    assert_eq!(
        c.lmn.scheduling.scheduling_input(),
        SchedulingInput::Undelayed
    );
    assert_eq!(c.settings.feedback_state, FeedbackState::Delayed);
    for s in scores(&c, Preset::ThesisFast) {
        assert_held(&s);
        assert_loop_holds(&s, 0.01);
    }
}

/// The thesis's loop exactly on the thesis-like plant (`models/thesis-fast-thesis.lcn.json`:
/// the signed shaper sum of eq. 6.8, no anti-windup, delayed state, Table 6.1's rise times
/// of the units at the same scheduling values, p3 = -1.9/Ts) does not hold: the 7 ms delay
/// inside loops of 10-30 ms rise time opens every level with a burst of 7 or more pulses,
/// and the signed sum winds E down by thousands (below -10^4 at some level) while the
/// muscle misses by more than 5 % at every level. With the same loop and 120-300 ms rise
/// times E stays within a few hundred and the loop holds its model within 2.5 %, but the
/// Ding muscle sits more than 15 % low at every level: the signed sum's patterns are where
/// the identified model over-predicts the muscle (docs/control.md, section 10).
#[test]
fn the_thesis_loop_exactly_fails_on_the_thesis_like_plant_where_the_docs_say() {
    let exact = shipped("thesis-fast-thesis");
    let runs = scores(&exact, Preset::ThesisFast);
    let lowest = runs
        .iter()
        .map(|s| s.min_energy)
        .fold(f64::INFINITY, f64::min);
    assert!(lowest < -1e4, "E wound down only to {lowest}");
    for s in &runs {
        let e = (s.subjects[0].mean - s.level) / s.level;
        assert!(
            e.abs() > 0.05,
            "r = {}: held ({:+.1} %)",
            s.level,
            100.0 * e
        );
        let shape = s.shape.as_ref().expect("pulses");
        assert!(shape.burst_pulses >= 7, "r = {}: {shape:?}", s.level);
    }
    let slower = Controller::design(
        exact.lmn.clone(),
        &fes_model::control::lcn_design::UnitSpec::for_rise_times(
            &[0.120, 0.180, 0.240, 0.300],
            fes_model::control::lcn_design::THESIS_DAMPING,
            exact.units[0].spec.p3,
        ),
        exact.settings,
    )
    .unwrap();
    for s in scores(&slower, Preset::ThesisFast) {
        assert!(
            s.min_energy > -1000.0,
            "r = {}: E {}",
            s.level,
            s.min_energy
        );
        assert_loop_holds(&s, 0.025);
        let e = (s.subjects[0].mean - s.level) / s.level;
        assert!(e < -0.15, "r = {}: muscle {:+.1} %", s.level, 100.0 * e);
    }
}
