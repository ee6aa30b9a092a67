//! Cost of one 1 ms `Muscle::step` (4 RK4 substeps), with and without fatigue.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use sim_muscle::ding::FatigueParams;
use sim_muscle::muscle::{Muscle, MuscleConfig};
use sim_muscle::plant::{MusclePlant, Pulse};
use sim_muscle::preset::Preset;

fn step(c: &mut Criterion) {
    for fatigue in [false, true] {
        let mut cfg = MuscleConfig::preset(Preset::Fast);
        if fatigue {
            cfg.fatigue = Some(FatigueParams::for_muscle(&cfg.ding));
        }
        let mut m = Muscle::new(cfg).expect("valid preset");
        let mut k = 0u32;
        let name = if fatigue {
            "muscle_step_fatigue"
        } else {
            "muscle_step"
        };
        c.bench_function(name, |b| {
            b.iter(|| {
                k = k.wrapping_add(1);
                // 40 Hz: a pulse every 25 samples.
                black_box(m.step(k.is_multiple_of(25).then_some(Pulse::SUPRAMAXIMAL)))
            })
        });
    }
}

criterion_group!(benches, step);
criterion_main!(benches);
