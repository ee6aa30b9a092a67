//! The pattern-generator tick allocates nothing: a counting global allocator watches
//! 100 000 ticks with M = 10 units, in both feedback modes, plus `reset`.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

mod control_support;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use control_support::{TS, fast_muscle, table_6_1_specs};
use rt_core::control::design::EstimatorPoles;
use rt_core::control::file::{Controller, ControllerSettings};
use rt_core::control::pattern_generator::{FeedbackMode, TickInput};
use rt_core::control::poles::dominant_pair;

/// Counts allocations per thread, only while that thread has armed it (the other test
/// threads of this binary neither count nor disturb the count).
struct CountingAlloc;

thread_local! {
    static ARMED: Cell<bool> = const { Cell::new(false) };
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

fn count() {
    if ARMED.with(Cell::get) {
        ALLOCATIONS.with(|n| n.set(n.get() + 1));
    }
}

// SAFETY: every call is forwarded unchanged to the system allocator; counting has no
// effect on the returned memory.
unsafe impl GlobalAlloc for CountingAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        count();
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

/// Allocations made by `f` on this thread.
fn allocations_in(f: impl FnOnce()) -> u64 {
    let before = ALLOCATIONS.with(Cell::get);
    ARMED.with(|a| a.set(true));
    f();
    ARMED.with(|a| a.set(false));
    ALLOCATIONS.with(Cell::get) - before
}

#[test]
fn counter_sees_an_allocation() {
    let n = allocations_in(|| {
        std::hint::black_box(vec![1u8; 16]);
    });
    assert!(n >= 1, "the counting allocator must count");
}

#[test]
fn tick_and_reset_never_allocate_with_ten_units() {
    let [p1, p2] = dominant_pair(0.005, 1.2, TS).unwrap();
    for mode in [FeedbackMode::Model, FeedbackMode::MeasuredForce] {
        let settings = ControllerSettings {
            mode,
            estimator_poles: Some(EstimatorPoles { p1, p2 }),
            ..ControllerSettings::default()
        };
        let c = Controller::design(fast_muscle(10), &table_6_1_specs(10), settings).unwrap();
        let mut pg = c.pattern_generator().unwrap();
        let mut pulses = 0u64;
        let n = allocations_in(|| {
            for k in 0..100_000u32 {
                // Steps through the whole force range, plus bad references and samples.
                let reference = match (k / 500) % 6 {
                    0 => 0.2,
                    1 => 0.9,
                    2 => 0.0,
                    3 => 0.5,
                    4 => f64::NAN,
                    _ => 2.0,
                };
                let measured_force = match k % 11 {
                    0 => None,
                    1 => Some(f64::INFINITY),
                    _ => Some(0.3),
                };
                let out = pg.tick(&TickInput {
                    reference,
                    measured_force,
                    resting: false,
                });
                pulses += out.pulse as u64;
                if k == 50_000 {
                    pg.reset();
                }
            }
        });
        assert_eq!(n, 0, "{mode:?}: {n} allocations in 100 000 ticks");
        assert!(
            pulses > 100,
            "{mode:?}: the run must exercise the shaper ({pulses} pulses)"
        );
    }
}
