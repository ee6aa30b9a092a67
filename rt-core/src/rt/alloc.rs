//! A counting global allocator that proves a real-time thread allocates nothing.
//!
//! Install it in a binary or test with
//! `#[global_allocator] static A: CountingAllocator = CountingAllocator;`. A thread opts in
//! with [`track_current_thread`]; from then on every allocation (and reallocation) it makes
//! is counted in a thread-local counter, read with [`current_thread_allocations`]. Other
//! threads pay one thread-local flag check per allocation.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

/// The system allocator, counting the allocations of tracked threads.
#[derive(Debug, Default, Clone, Copy)]
pub struct CountingAllocator;

thread_local! {
    // `const` initialisers without destructors: no lazy registration, so reading them from
    // inside the allocator can never allocate or recurse.
    static TRACKED: Cell<bool> = const { Cell::new(false) };
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
    static BYTES: Cell<u64> = const { Cell::new(0) };
}

#[inline]
fn count(size: usize) {
    // `try_with` fails only while the thread is being torn down; then nothing is counted.
    let _ = TRACKED.try_with(|tracked| {
        if tracked.get() {
            let _ = ALLOCATIONS.try_with(|n| n.set(n.get() + 1));
            let _ = BYTES.try_with(|b| b.set(b.get() + size as u64));
        }
    });
}

// SAFETY: every method forwards to `System` with the same arguments and returns its result
// unchanged; the counting only touches thread-local `Cell`s, which neither allocate nor
// unwind.
unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count(layout.size());
        // SAFETY: forwarded verbatim; the caller upholds `GlobalAlloc::alloc`'s contract.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count(layout.size());
        // SAFETY: as above.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count(new_size);
        // SAFETY: as above; `ptr` and `layout` come from this allocator (which is `System`).
        unsafe { System.realloc(ptr, layout, new_size) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: as above.
        unsafe { System.dealloc(ptr, layout) }
    }
}

/// Allocations counted for the current thread since it was first tracked.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct AllocCount {
    /// Number of `alloc`, `alloc_zeroed` and `realloc` calls.
    pub allocations: u64,
    /// Bytes requested by them.
    pub bytes: u64,
}

/// Starts (or stops) counting the current thread's allocations.
pub fn track_current_thread(on: bool) {
    TRACKED.with(|t| t.set(on));
}

/// The current thread's counted allocations.
pub fn current_thread_allocations() -> AllocCount {
    AllocCount {
        allocations: ALLOCATIONS.with(Cell::get),
        bytes: BYTES.with(Cell::get),
    }
}

/// True when [`CountingAllocator`] is the global allocator (checked by making one tracked
/// allocation and seeing whether it was counted). Without it the counts stay 0 and mean
/// nothing.
pub fn counting_allocator_installed() -> bool {
    let was_tracked = TRACKED.with(Cell::get);
    track_current_thread(true);
    let before = current_thread_allocations();
    let probe = std::hint::black_box(Box::new(0u64));
    drop(probe);
    let installed = current_thread_allocations().allocations > before.allocations;
    // The probe is not the caller's allocation: restore the counters.
    ALLOCATIONS.with(|n| n.set(before.allocations));
    BYTES.with(|b| b.set(before.bytes));
    track_current_thread(was_tracked);
    installed
}
