//! rt-core's integration tests, one binary: the real-time plumbing (clock, configuration,
//! realtime setup, telemetry, message contracts), the no-allocation proof of the loop under
//! fes-rt's counting allocator, and the rt-core process end to end.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use fes_rt::rt::alloc::CountingAllocator;

/// Every test of this binary runs under the counting allocator; a thread counts only
/// while it tracks itself (`rt::alloc::track_current_thread`).
#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

mod rt_common;

mod rt_alloc_trace;
mod rt_clock;
mod rt_config;
mod rt_feedback;
mod rt_generator;
mod rt_msg;
mod rt_no_alloc;
mod rt_process;
mod rt_realtime;
mod rt_reference;
mod rt_source;
mod rt_telemetry;
mod timing;

/// The allocation tests share process-wide state (the first-allocation trace, the pool's
/// bitmap): they run one at a time, whatever the harness's thread count.
pub fn exclusive_allocator() -> std::sync::MutexGuard<'static, ()> {
    static ALLOCATION_TESTS: std::sync::Mutex<()> = std::sync::Mutex::new(());
    ALLOCATION_TESTS
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}
