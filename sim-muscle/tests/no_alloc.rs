//! The virtual stimulator steps the muscle every 1 ms: `Muscle::step` (with fatigue, a
//! 7.5 ms delay and a sensor) must not allocate. A counting global allocator checks it.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use sim_muscle::ding::FatigueParams;
use sim_muscle::muscle::{Muscle, MuscleConfig};
use sim_muscle::plant::{MusclePlant, Pulse};
use sim_muscle::preset::Preset;
use sim_muscle::sensor::{ForceSensor, Measured, SensorConfig};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards to the system allocator unchanged; only counts calls.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

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
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    let mut sum = 0.0;
    // Pulses as dense as allowed (every sample) and sparse, 100 000 steps, with resets.
    for k in 0..100_000u32 {
        let fire = k % 1000 < 200 || k % 7 == 0;
        sum += plant.step(fire.then_some(Pulse::SUPRAMAXIMAL));
        if k % 25_000 == 0 {
            plant.reset();
        }
    }
    let after = ALLOCATIONS.load(Ordering::Relaxed);
    assert!(sum.is_finite());
    assert_eq!(after - before, 0, "Muscle::step allocated");
}
