//! Criterion benchmark of the pattern-generator tick (thesis Fig. 6.8): nanoseconds per
//! tick for M = 1, 6 and 10 units, in the model mode (the default) and, for M = 10, the
//! measured-force mode (estimator + d-step re-prediction).
//!
//! `planning_beat`: one whole 800 ms beat of the cardiac profile (320 ms at 0.5) with the
//! receding-horizon planner and its preview, M = 1, 6 and 10: the time per beat over 800
//! is the mean planning tick; the planner works at most `budget_steps` network steps in a
//! tick, so its worst tick is that many steps (rt-core's compute histogram has it).
//!
//! Run: `cargo bench -p fes-model --bench tick`.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use fes_model::control::design::EstimatorPoles;
use fes_model::control::file::{Controller, ControllerSettings};
use fes_model::control::pattern_generator::{FeedbackMode, TickInput};
use fes_model::control::poles::dominant_pair;
use fes_testkit::control::{TS, fast_muscle, table_6_1_specs};

fn controller(m: usize, mode: FeedbackMode) -> Controller {
    let [p1, p2] = dominant_pair(0.005, 1.2, TS).expect("valid estimator spec");
    let settings = ControllerSettings {
        mode,
        estimator_poles: Some(EstimatorPoles { p1, p2 }),
        ..ControllerSettings::default()
    };
    Controller::design(fast_muscle(m), &table_6_1_specs(m), settings).expect("design")
}

fn bench_tick(c: &mut Criterion) {
    let mut group = c.benchmark_group("tick");
    let cases = [
        (1, FeedbackMode::Model),
        (6, FeedbackMode::Model),
        (10, FeedbackMode::Model),
        (10, FeedbackMode::MeasuredForce),
    ];
    for (m, mode) in cases {
        let mut pg = controller(m, mode)
            .pattern_generator()
            .expect("pattern generator");
        // Settle into steady pulsing first, so the measured ticks are representative.
        let input = TickInput {
            reference: 0.5,
            measured_force: Some(0.5),
            resting: false,
            ..Default::default()
        };
        for _ in 0..2000 {
            pg.tick(&input);
        }
        let name = match mode {
            FeedbackMode::Model => "model",
            FeedbackMode::MeasuredForce => "measured",
        };
        group.bench_with_input(BenchmarkId::new(name, m), &input, |b, input| {
            b.iter(|| black_box(pg.tick(black_box(input))))
        });
    }
    group.finish();
}

fn bench_planning(c: &mut Criterion) {
    use fes_model::control::planner::PlanningConfig;
    use fes_model::control::preview::{Preview, PreviewPoint};

    let mut group = c.benchmark_group("planning_beat");
    group.sample_size(20);
    let (period, on, level) = (800usize, 320usize, 0.5);
    let setpoint = |k: usize| if k % period < on { level } else { 0.0 };
    // One beat's inputs, precomputed: the tracker's targets and the previews.
    let mut r = 0.0f64;
    let inputs: Vec<TickInput> = (0..period)
        .map(|k| {
            let mut points = vec![PreviewPoint {
                at: 0,
                force: setpoint(k),
                rate_per_s: 50.0,
            }];
            for edge in [on, period, period + on] {
                if edge > k {
                    points.push(PreviewPoint {
                        at: (edge - k) as u32,
                        force: setpoint(edge),
                        rate_per_s: 50.0,
                    });
                }
            }
            let goal = setpoint(k);
            r = if goal > r {
                (r + 0.05).min(goal)
            } else {
                (r - 0.05).max(goal)
            };
            TickInput {
                reference: r,
                measured_force: None,
                resting: goal == 0.0,
                preview: Preview::new(&points).expect("valid preview"),
            }
        })
        .collect();
    for m in [1, 6, 10] {
        let settings = ControllerSettings {
            planning: PlanningConfig::RECOMMENDED,
            ..ControllerSettings::default()
        };
        let ctl =
            Controller::design(fast_muscle(m), &table_6_1_specs(m), settings).expect("design");
        let mut pg = ctl.pattern_generator().expect("pattern generator");
        group.bench_function(BenchmarkId::new("model", m), |b| {
            b.iter(|| {
                for input in &inputs {
                    black_box(pg.tick(black_box(input)));
                }
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench_tick, bench_planning);
criterion_main!(benches);
