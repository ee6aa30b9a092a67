//! The network step never touches the heap: a counting global allocator observes zero
//! allocations (and zero bytes) over 100 000 steps of an M = 10 network, in both forms.
#![allow(clippy::needless_range_loop)] // index loops mirror the equations
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use rt_core::model::local_model::EigLocalUnit;
use rt_core::model::network::Network;
use rt_core::model::scheduling::{Scheduler, SchedulingSpec};
use rt_core::model::validity::ValidityFunctions;
use rt_core::model::{AdvancedForm, ThesisForm};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;

// Only allocations made by the measuring thread count (the test harness's own threads may
// allocate meanwhile). Const-initialised, so reading it never allocates.
thread_local! {
    static MEASURING: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

fn measuring() -> bool {
    MEASURING.try_with(|m| m.get()).unwrap_or(false)
}

static ALLOCS: AtomicUsize = AtomicUsize::new(0);
static BYTES: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards every call to the system allocator unchanged; only counts.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if measuring() {
            ALLOCS.fetch_add(1, Ordering::SeqCst);
            BYTES.fetch_add(layout.size(), Ordering::SeqCst);
        }
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if measuring() {
            ALLOCS.fetch_add(1, Ordering::SeqCst);
            BYTES.fetch_add(new_size, Ordering::SeqCst);
        }
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn network(m: usize, sched: SchedulingSpec) -> Network<f64> {
    let units: Vec<_> = (0..m)
        .map(|i| {
            let f = i as f64;
            EigLocalUnit {
                eigenvalues: [-300.0 + 10.0 * f, -30.0 + f],
                eigenvector_angles: [0.2 + 0.1 * f, 1.7 - 0.05 * f],
                b: [1.0, 0.5 + 0.1 * f],
                c: [0.02, 0.01],
                dx: [0.1, -0.05 * f],
                dy: 0.001 * f,
            }
            .to_local_model()
            .unwrap()
        })
        .collect();
    let vf = ValidityFunctions::uniform(m, 0.0, 1.0).unwrap();
    Network::state_space(1e-3, 7, vf, Scheduler::new(&sched, 1e-3).unwrap(), &units).unwrap()
}

#[test]
fn network_steps_do_not_allocate() {
    for sched in [SchedulingSpec::default(), SchedulingSpec::Output] {
        let net = network(10, sched);
        let mut thesis = ThesisForm::new(net).unwrap();
        let mut adv = AdvancedForm::new(net).unwrap();
        let mut st = net.rest_state().unwrap();
        let mut acc = 0.0;
        let (a0, b0) = (ALLOCS.load(Ordering::SeqCst), BYTES.load(Ordering::SeqCst));
        MEASURING.with(|m| m.set(true));
        for k in 0..100_000u32 {
            // A pattern that sweeps phi across all units (bursts of rising frequency).
            let period = 2 + (k / 1000) % 40;
            let u = if k % period == 0 { 1.0 } else { 0.0 };
            acc += thesis.step(u);
            let act = adv.activation();
            acc += adv.step_with_activation(&act, u).y;
            acc += net.step(&mut st, u);
        }
        MEASURING.with(|m| m.set(false));
        let (a1, b1) = (ALLOCS.load(Ordering::SeqCst), BYTES.load(Ordering::SeqCst));
        assert!(acc.is_finite());
        assert_eq!(
            a1 - a0,
            0,
            "{sched:?}: {} allocations ({} bytes) in 100 000 steps",
            a1 - a0,
            b1 - b0
        );
        assert_eq!(b1 - b0, 0);
        // The counter is live: a heap allocation is seen.
        MEASURING.with(|m| m.set(true));
        let v = std::hint::black_box(vec![1u8; 16]);
        MEASURING.with(|m| m.set(false));
        assert!(ALLOCS.load(Ordering::SeqCst) > a1 && v.len() == 16);
    }
}
