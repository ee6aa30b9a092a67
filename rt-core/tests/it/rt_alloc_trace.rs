//! The counting allocator's trace of the first heap allocation on a tracked thread
//! (`fes_rt::rt::alloc::trace_first_heap_allocation`): it names the allocating function,
//! is taken once, skips the allocations of an `untraced` section and of the installation
//! probe, and does not count its own allocations. The trace is process-wide: the test holds `exclusive_allocator`.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use fes_rt::rt::alloc::{
    self, current_thread_allocations, take_first_heap_allocation, trace_first_heap_allocation,
    track_current_thread, untraced,
};

/// Larger than a pool block, so it goes to the heap.
const BIG: usize = alloc::POOL_BLOCK_BYTES * 4;

#[inline(never)]
fn an_expected_connection_allocation() -> Vec<u8> {
    std::hint::black_box(vec![1u8; BIG])
}

#[inline(never)]
fn the_offending_allocation() -> Vec<u8> {
    std::hint::black_box(vec![2u8; BIG + 8])
}

#[test]
fn the_first_heap_allocation_is_traced_once_with_its_caller() {
    let _exclusive = crate::exclusive_allocator();
    let worker = std::thread::Builder::new()
        .name("traced-loop".into())
        .spawn(|| {
            // Off: a heap allocation is counted, not traced.
            track_current_thread(true);
            let base = current_thread_allocations().allocations;
            drop(the_offending_allocation());
            track_current_thread(false);
            assert!(take_first_heap_allocation().is_none(), "traced while off");
            assert_eq!(current_thread_allocations().allocations - base, 1);

            trace_first_heap_allocation(true);
            assert!(alloc::counting_allocator_installed());
            assert!(
                take_first_heap_allocation().is_none(),
                "the installation probe was traced"
            );
            track_current_thread(true);
            let base = current_thread_allocations().allocations;
            // Pool-sized: no heap allocation, nothing to trace.
            drop(std::hint::black_box(Box::new([0u8; 16])));
            // Expected and counted apart: counted, not traced.
            drop(untraced(an_expected_connection_allocation));
            drop(the_offending_allocation());
            drop(the_offending_allocation());
            let counted = current_thread_allocations().allocations - base;
            track_current_thread(false);
            trace_first_heap_allocation(false);
            // The capture's own allocations are not counted.
            assert_eq!(counted, 3, "connection + two offending allocations");
        })
        .unwrap();
    worker.join().unwrap();

    let trace = take_first_heap_allocation().expect("the first heap allocation traced");
    assert_eq!(trace.bytes, BIG + 8);
    assert_eq!(trace.thread.as_deref(), Some("traced-loop"));
    let text = trace.to_string();
    assert!(
        text.contains("the_offending_allocation") && !text.contains("an_expected_connection"),
        "{text}"
    );
    assert!(take_first_heap_allocation().is_none(), "taken twice");
}
