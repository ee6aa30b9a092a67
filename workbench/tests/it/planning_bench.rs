//! The receding-horizon planner on the in-process bench (docs/bench.md, "Planning"), with
//! the shipped controllers (planning on) and planning switched off in the same files:
//! 30 s of the 75 beats/min cardiac profile, outer loop on, the bench's muscle and sensor.
//!
//! The verdict is the bench's own: `beats_every_cft`, every constant-frequency train
//! CFT(f, n) (5-100 Hz, stopped after each of its pulses) with no more pulses per
//! contraction than the run tracks worse.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use std::path::Path;

use crate::analysis_support::bench_profile;

use fes_bench::cft::FrontVerdict;
use fes_bench::simulation::{SimSettings, simulate};
use fes_model::control::file::Controller;
use fes_model::control::planner::{LambdaScale, PlanningMode};
use sim_muscle::preset::Preset;
use supervisor::outer_loop::OuterLoopSettings;

fn shipped(name: &str) -> Controller {
    Controller::load(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../models")
            .join(name),
    )
    .expect("shipped controller")
}

/// The in-process bench at `amplitude`, as `fes bench --in-process --muscle M`.
fn bench(c: &Controller, preset: Preset, amplitude: f64) -> (FrontVerdict, u64) {
    let profile = bench_profile(amplitude, None);
    let s = SimSettings::bench_muscle(
        c,
        preset,
        false,
        profile,
        OuterLoopSettings::default(),
        30.0,
    )
    .unwrap();
    let run = simulate(c, &s).unwrap();
    let verdict = s.front(amplitude, 0).verdict(&run.series()).unwrap();
    (verdict, run.planner.causal_fallbacks)
}

/// Which trains a verdict compares the run with.
#[derive(Debug, Clone, Copy)]
enum Trains {
    /// No more pulses per contraction than the run's mean (`beats_every_cft`).
    NoMorePulses,
    /// No more than the run's count rounded to a whole pulse
    /// (`beats_every_cft_whole_count`): a plan of 4.97 pulses against every train of 5.
    WholeCount,
    /// Those of the whole count that miss the level (the plateau the outer loop
    /// regulates) by no more than the run (`beats_every_cft_holding_level`).
    HoldingTheLevel,
}

/// The run beats every train of `trains`; the message names the best of them.
fn assert_beats_every(trains: Trains, v: &FrontVerdict, amplitude: f64) {
    let (beats, best) = match trains {
        Trains::NoMorePulses => (v.beats_every_cft, v.best_cft_no_more_pulses),
        Trains::WholeCount => (v.beats_every_cft_whole_count, v.best_cft_whole_count),
        Trains::HoldingTheLevel => (v.beats_every_cft_holding_level, v.best_cft_holding_level),
    };
    assert!(
        beats,
        "{amplitude}, {trains:?}: planned {} pulses, RMS {:.4}, level missed by {:.4}; \
         the best train {best:?}",
        v.lcn.pulses_per_contraction, v.lcn.rms_error, v.lcn.level_error
    );
}

/// The run beats every train with no more pulses per contraction.
fn assert_beats_every_train(v: &FrontVerdict, amplitude: f64) {
    assert_beats_every(Trains::NoMorePulses, v, amplitude);
}

fn off(mut c: Controller) -> Controller {
    c.settings.planning.mode = PlanningMode::Off;
    c
}

/// Fast muscle, 0.1-0.9: with planning no train of the plan's count that holds the level as
/// closely tracks as well, and from 0.2 no train with no more pulses at all; the causal
/// loop of the same file is beaten by a train at most of these levels. Every tick inside a
/// contraction is decided by a plan, the first contraction's included (the profile's start
/// rest announces it). At 0.1 a 9 Hz train of three tracks 0.3 % better than the plan's
/// three pulses by missing the level by 8.6 % (the plan: 0.5 %; docs/bench.md, "Planning").
#[test]
fn planning_beats_every_train_on_the_fast_muscle() {
    let c = shipped("fast.lcn.json");
    assert_eq!(c.settings.planning.mode, PlanningMode::RecedingHorizon);
    let mut causal_beaten = 0;
    for amplitude in [0.1, 0.2, 0.3, 0.4, 0.5, 0.7, 0.9] {
        let (v, fallbacks) = bench(&c, Preset::Fast, amplitude);
        if amplitude > 0.1 {
            assert_beats_every_train(&v, amplitude);
            assert_beats_every(Trains::WholeCount, &v, amplitude);
        }
        assert_beats_every(Trains::HoldingTheLevel, &v, amplitude);
        assert_eq!(fallbacks, 0, "{amplitude}: causal ticks");
        let (v_off, _) = bench(&off(c.clone()), Preset::Fast, amplitude);
        assert!(
            v.lcn.rms_error < v_off.lcn.rms_error,
            "{amplitude}: planned RMS {} vs causal {}",
            v.lcn.rms_error,
            v_off.lcn.rms_error
        );
        causal_beaten += usize::from(!v_off.beats_every_cft_holding_level);
    }
    assert!(
        causal_beaten >= 4,
        "{causal_beaten} levels where a train holding the level beat the causal loop"
    );
}

/// The price per pulse scaled by the level (`lambda_scale = "level"`, the shipped files'):
/// on the fast muscle at 0.9 it plans fewer pulses than eq. 6.4's fixed price of 0.5 (15.14
/// against 15.68 per contraction; the price by level is 0.9 there), and both beat every
/// train that holds the level as closely. (At every other level of both muscles the two
/// prices plan the same counts; docs/bench.md.)
#[test]
fn the_price_by_level_saves_pulses_at_0_9() {
    let mut c = shipped("fast.lcn.json");
    assert_eq!(c.settings.planning.lambda_scale, LambdaScale::Level);
    let (by_level, _) = bench(&c, Preset::Fast, 0.9);
    c.settings.planning.lambda_scale = LambdaScale::Fixed;
    c.settings.planning.lambda = 0.5;
    let (fixed, _) = bench(&c, Preset::Fast, 0.9);
    for v in [&by_level, &fixed] {
        assert_beats_every(Trains::HoldingTheLevel, v, 0.9);
    }
    assert!(
        by_level.lcn.pulses_per_contraction <= fixed.lcn.pulses_per_contraction - 0.4,
        "by level {:?}, fixed {:?}",
        by_level.lcn,
        fixed.lcn
    );
}

/// The first contraction is planned like every later one: the profile rests before it
/// (200 ms by default) and announces it, so its pulses are those of the beats after it.
/// With no start rest it is seen only at its onset and its pulses are decided before the
/// plan is complete: on the slow muscle at 0.4, one pulse where every later beat has two
/// (which also threw the outer loop's first correction off by 7 %).
#[test]
fn the_first_contraction_is_planned_like_every_other() {
    let c = shipped("slow.lcn.json");
    let first_two = |start_rest_ms: Option<f64>| {
        let profile = bench_profile(0.4, start_rest_ms);
        let s = SimSettings::bench_muscle(
            &c,
            Preset::Slow,
            false,
            profile,
            OuterLoopSettings::default(),
            3.0,
        )
        .unwrap();
        let r = simulate(&c, &s).unwrap();
        (r.beats[0].measurement.pulses, r.beats[1].measurement.pulses)
    };
    assert_eq!(first_two(None), (2, 2));
    assert_eq!(first_two(Some(0.0)), (1, 2));
}

/// Slow muscle, 0.5, 0.7 and 0.9: no train with no more pulses tracks as well, and a train
/// beats the causal loop of the same file at each. At 0.5 the plan's three pulses open
/// with a close pair, which the shipped model answers as the muscle does because its data
/// hold such pairs from rest (models/README.md; a model of the thesis protocol alone
/// answers a 2 ms pair 20 % above the muscle, and its plan lost to 8 Hz x 2). At 0.9 the
/// plan drives the top of the model's scheduling range, which the shipped model's data
/// reach (every unit at least 2 % of the validity weight): on a model whose top units the
/// data did not reach the plan tracked worse than the causal loop there. (At 0.2-0.4 a
/// train of one or two pulses tracks better than the plan, which must hold the plateau the
/// outer loop regulates: docs/bench.md, "Planning".)
#[test]
fn planning_beats_every_train_on_the_slow_muscle_at_0_5_0_7_and_0_9() {
    let c = shipped("slow.lcn.json");
    for amplitude in [0.5, 0.7, 0.9] {
        let (v_off, _) = bench(&off(c.clone()), Preset::Slow, amplitude);
        assert!(
            !v_off.beats_every_cft,
            "{amplitude}: causal {:?}",
            v_off.lcn
        );
        let (v, _) = bench(&c, Preset::Slow, amplitude);
        assert_beats_every_train(&v, amplitude);
        assert_beats_every(Trains::WholeCount, &v, amplitude);
        assert_beats_every(Trains::HoldingTheLevel, &v, amplitude);
        assert!(
            v.lcn.rms_error < v_off.lcn.rms_error,
            "{amplitude}: planned RMS {} vs causal {}",
            v.lcn.rms_error,
            v_off.lcn.rms_error
        );
    }
}

/// Slow muscle, 0.2-0.4: a train of fewer pulses tracks better, but only by missing the
/// level the outer loop regulates (one twitch at the onset holds the plateau at 0.125;
/// docs/bench.md, "Why the slow muscle's low levels lose"); among the trains that hold the
/// level as closely as the plan, none of its whole count tracks as well. At 0.2 the plan is
/// one pulse, late enough (about 43 ms) for its twitch to hold the plateau: the local
/// search reaches it from the two onset pulses the trains give by deleting one and moving
/// the other later together (two pulses at 2 and 18 ms, RMS 0.125, without that move).
#[test]
fn on_the_slow_muscle_the_trains_that_track_better_miss_the_level() {
    let c = shipped("slow.lcn.json");
    for amplitude in [0.2, 0.3, 0.4] {
        let (v, _) = bench(&c, Preset::Slow, amplitude);
        assert!(!v.beats_every_cft, "{amplitude}: {:?}", v.lcn);
        let best = v.best_cft_no_more_pulses.unwrap();
        assert!(
            best.level_error > 0.05 && v.lcn.level_error < 0.02,
            "{amplitude}: {best:?} vs {:?}",
            v.lcn
        );
        assert_beats_every(Trains::HoldingTheLevel, &v, amplitude);
        if amplitude == 0.2 {
            assert!(
                v.lcn.pulses_per_contraction == 1.0
                    && v.lcn.level_error < 0.01
                    && v.lcn.rms_error < 0.095,
                "0.2: {:?}",
                v.lcn
            );
        }
    }
}

/// The in-process bench with planning is deterministic: two runs, the same pulses and force.
#[test]
fn planned_runs_are_deterministic() {
    let c = shipped("fast.lcn.json");
    let profile = bench_profile(0.5, None);
    let s = SimSettings::bench_muscle(
        &c,
        Preset::Fast,
        false,
        profile,
        OuterLoopSettings::default(),
        5.0,
    )
    .unwrap();
    let a = simulate(&c, &s).unwrap();
    let b = simulate(&c, &s).unwrap();
    assert_eq!(a.pulse, b.pulse);
    assert_eq!(a.measured, b.measured);
    assert!(a.planner.planned_ticks > 1000, "{:?}", a.planner);
}

/// The bench's fatigue run (`fes bench --in-process --fatigue --amplitude 0.3`): the fast
/// muscle with fatigue, the outer loop on, `seconds` long.
fn under_fatigue(c: &Controller, seconds: f64) -> fes_bench::simulation::SimResult {
    let profile = bench_profile(0.3, None);
    let s = SimSettings::bench_muscle(
        c,
        Preset::Fast,
        true,
        profile,
        OuterLoopSettings::default(),
        seconds,
    )
    .unwrap();
    simulate(c, &s).unwrap()
}

/// 60 s at 0.3 with fatigue and the outer loop (the bench's fatigue run): with planning every
/// contraction after the 10th holds the target within 2 %, with fewer pulses per contraction
/// than the causal loop of the same file (which holds 2 % too, `lcn_targets`). The shipped
/// fast controller opens with a burst only from level 0.35 (`burst_min_level`); with bursts
/// at every level the plan switches from six evenly spread pulses to seven opening with a
/// doublet as fatigue raises the level, and the fatigued muscle answers the doublet above the
/// model: that beat is 3 % over the target (docs/bench.md, "Under fatigue").
#[test]
fn planning_under_fatigue_holds_every_beat_with_fewer_pulses() {
    let c = shipped("fast.lcn.json");
    assert_eq!(c.settings.planning.burst_min_level, 0.35);
    let run = |c: &Controller| {
        let r = under_fatigue(c, 60.0);
        let plateaus: Vec<f64> = r
            .beats
            .iter()
            .filter_map(|b| b.measurement.plateau_mean)
            .collect();
        let pulses =
            r.beats.iter().map(|b| b.measurement.pulses).sum::<u64>() as f64 / r.beats.len() as f64;
        assert!(plateaus.len() >= 73, "{} beats", plateaus.len());
        let worst = plateaus[10..]
            .iter()
            .map(|p| (p - 0.3).abs() / 0.3)
            .fold(0.0, f64::max);
        (worst, pulses)
    };
    let (worst, pulses_planned) = run(&c);
    let (_, pulses_causal) = run(&off(c.clone()));
    assert!(
        worst <= 0.02,
        "worst beat after the 10th {:.2} %",
        100.0 * worst
    );
    assert!(
        pulses_planned < pulses_causal,
        "{pulses_planned:.2} planned vs {pulses_causal:.2} causal pulses per contraction"
    );
    let mut bursts_everywhere = c.clone();
    bursts_everywhere.settings.planning.burst_min_level = 0.0;
    let (worst_everywhere, _) = run(&bursts_everywhere);
    assert!(
        worst_everywhere > 0.025,
        "bursts at every level: worst beat {:.2} %",
        100.0 * worst_everywhere
    );
}

/// 90 s at 0.3 with fatigue and the outer loop: the shipped fast controller keeps close
/// pairs to each contraction's opening (`burst_ipi_ms` 15), and every beat after the 10th
/// stays within 5 % of the target. Without the rule, once fatigue has raised the level to
/// about 0.39 the plan moves one plateau pulse of a seven-pulse pattern next to another
/// (137 and 139 ms) and back, beat after beat: the fatigued muscle's catch-like gain answers
/// the pair some 12 % above the model, the outer loop pulls the level down, the pair goes,
/// the plateau falls 7 % short, and so on (docs/bench.md, "Under fatigue").
#[test]
fn under_long_fatigue_close_pairs_stay_in_the_opening() {
    let c = shipped("fast.lcn.json");
    assert_eq!(c.settings.planning.burst_ipi_ms, 15.0);
    let run = |c: &Controller| {
        let r = under_fatigue(c, 90.0);
        let worst = r.beats[10..]
            .iter()
            .filter_map(|b| b.measurement.plateau_mean)
            .map(|p| (p - 0.3).abs() / 0.3)
            .fold(0.0, f64::max);
        // Intervals under 15 ms after the first of 15 ms or more, within each beat.
        let ticks: Vec<usize> = (0..r.pulse.len()).filter(|&k| r.pulse[k]).collect();
        let beat_ms = 800;
        let mut late = 0;
        let mut opened = false;
        for w in ticks.windows(2) {
            if w[0] / beat_ms != w[1] / beat_ms {
                opened = false;
                continue;
            }
            let short = w[1] - w[0] < 15;
            late += usize::from(short && opened);
            opened |= !short;
        }
        (worst, late)
    };
    let (worst, late) = run(&c);
    assert_eq!(late, 0, "close pairs after the opening");
    assert!(
        worst <= 0.05,
        "worst beat after the 10th {:.1} %",
        100.0 * worst
    );
    let mut without = c.clone();
    without.settings.planning.burst_ipi_ms = 0.0;
    let (worst_without, late_without) = run(&without);
    assert!(late_without > 0);
    assert!(
        worst_without > 0.08,
        "without the rule: worst beat {:.1} %",
        100.0 * worst_without
    );
}
