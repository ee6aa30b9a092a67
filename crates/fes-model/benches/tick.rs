//! Criterion benchmark of the pattern-generator tick (thesis Fig. 6.8): nanoseconds per
//! tick for M = 1, 6 and 10 units, in the model mode (the default) and, for M = 10, the
//! measured-force mode (estimator + d-step re-prediction).
//!
//! Run: `cargo bench -p rt-core --bench tick`.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use fes_model::control::design::EstimatorPoles;
use fes_model::control::file::{Controller, ControllerSettings};
use fes_model::control::pattern_generator::{FeedbackMode, TickInput};
use fes_model::control::poles::dominant_pair;

#[path = "../tests/it/control_support.rs"]
mod control_support;
use control_support::{TS, fast_muscle, table_6_1_specs};

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

criterion_group!(benches, bench_tick);
criterion_main!(benches);
