//! The virtual stimulator steps the muscle every 1 ms: `Muscle::step` (with fatigue, a
//! 7.5 ms delay and a sensor) must not allocate. A counting global allocator checks it.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use fes_rt::rt::alloc::{self, CountingAllocator};
use sim_muscle::ding::FatigueParams;
use sim_muscle::muscle::{Muscle, MuscleConfig};
use sim_muscle::plant::{MusclePlant, Pulse};
use sim_muscle::preset::Preset;
use sim_muscle::sensor::{ForceSensor, Measured, SensorConfig};

// Counts the allocations of the tracked (test) thread only: the test harness's own threads
// allocate too (a "running for over 60 seconds" notice on a loaded CI machine did).
#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

#[test]
fn step_does_not_allocate() {
    let mut cfg = MuscleConfig {
        emd_s: 7.5e-3,
        ..MuscleConfig::preset(Preset::Fast)
    };
    cfg.fatigue = Some(FatigueParams::for_muscle(&cfg.ding));
    let sensor = SensorConfig {
        offset_n: 1.0,
        noise_std_n: 0.5,
        lowpass_tau_s: 2e-3,
        seed: 3,
    };
    let mut plant = Measured::new(
        Muscle::new(cfg).expect("valid"),
        ForceSensor::new(sensor, cfg.ts_s).expect("valid"),
    );
    alloc::track_current_thread(true);
    let before = alloc::current_thread_allocations();
    let mut sum = 0.0;
    // Pulses as dense as allowed (every sample) and sparse, 100 000 steps, with resets.
    for k in 0..100_000u32 {
        let fire = k % 1000 < 200 || k % 7 == 0;
        sum += plant.step(fire.then_some(Pulse::SUPRAMAXIMAL));
        if k % 25_000 == 0 {
            plant.reset();
        }
    }
    let after = alloc::current_thread_allocations();
    alloc::track_current_thread(false);
    assert!(sum.is_finite());
    assert_eq!(
        after.allocations - before.allocations,
        0,
        "Muscle::step allocated"
    );
    assert_eq!(
        after.pool_allocations - before.pool_allocations,
        0,
        "Muscle::step allocated (small blocks)"
    );
}
