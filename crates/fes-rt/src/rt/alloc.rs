//! A counting global allocator that proves a real-time thread takes nothing from the heap.
//!
//! Install it in a binary or test with
//! `#[global_allocator] static A: CountingAllocator = CountingAllocator;`. A thread opts in
//! with [`track_current_thread`]; from then on its allocations are counted in thread-local
//! counters read with [`current_thread_allocations`]. Other threads pay one thread-local flag
//! check per allocation.
//!
//! Small allocations (<= [`POOL_BLOCK_BYTES`], alignment <= 64) of a tracked thread are served
//! from a static pool of [`POOL_BLOCKS`] blocks (lock-free: one atomic bitmap; no system call;
//! the pool lives in `.bss`, so `mlockall` keeps it resident) and counted as *pool*
//! allocations; everything else goes to the system heap and is counted as a *heap* allocation.
//! The reason is iceoryx2 0.10 itself: every `Publisher::loan*` creates one small `Rc`
//! (`ChunkMutSharedState`), so a publish cannot be heap-free with the system allocator. With
//! this allocator the real-time loop's only allocation per tick is that one pool block, and
//! the heap count stays 0, which the tests assert.
//!
//! When a heap allocation does happen on a tracked thread, a count alone does not say where.
//! With [`trace_first_heap_allocation`] on, the first one (process-wide) also captures a
//! backtrace, taken once and kept until [`take_first_heap_allocation`]: a process logs it at
//! exit. Capturing costs nothing until that allocation happens (the hot path has already
//! broken its rule then); the capture itself is done with tracking paused, so its own
//! allocations go untracked to the system heap.

use std::alloc::{GlobalAlloc, Layout, System};
use std::backtrace::Backtrace;
use std::cell::{Cell, UnsafeCell};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// Size of one pool block, bytes.
pub const POOL_BLOCK_BYTES: usize = 256;
/// Number of pool blocks (one bit each in a `u64`).
pub const POOL_BLOCKS: usize = 64;
const POOL_ALIGN: usize = 64;

#[repr(C, align(64))]
struct Block(UnsafeCell<[u8; POOL_BLOCK_BYTES]>);

struct Pool {
    blocks: [Block; POOL_BLOCKS],
    /// Bit i set = block i in use.
    in_use: AtomicU64,
}

// SAFETY: a block's bytes are only accessed by the owner of the pointer handed out for it;
// ownership is transferred exclusively through the atomic `in_use` bitmap (acquire on take,
// release on return), exactly like any allocator.
unsafe impl Sync for Pool {}

static POOL: Pool = Pool {
    blocks: [const { Block(UnsafeCell::new([0; POOL_BLOCK_BYTES])) }; POOL_BLOCKS],
    in_use: AtomicU64::new(0),
};

impl Pool {
    fn fits(layout: &Layout) -> bool {
        layout.size() <= POOL_BLOCK_BYTES && layout.align() <= POOL_ALIGN
    }

    /// Takes a free block, or `None` when all are in use.
    fn take(&self) -> Option<*mut u8> {
        let mut used = self.in_use.load(Ordering::Relaxed);
        loop {
            if used == u64::MAX {
                return None;
            }
            let i = (!used).trailing_zeros() as usize;
            match self.in_use.compare_exchange_weak(
                used,
                used | (1 << i),
                Ordering::Acquire,
                Ordering::Relaxed,
            ) {
                Ok(_) => return Some(self.blocks[i].0.get().cast()),
                Err(now) => used = now,
            }
        }
    }

    /// The block index of `ptr`, if it points into the pool.
    fn index_of(&self, ptr: *mut u8) -> Option<usize> {
        let base = self.blocks.as_ptr() as usize;
        let addr = ptr as usize;
        let end = base + POOL_BLOCKS * core::mem::size_of::<Block>();
        (base..end)
            .contains(&addr)
            .then(|| (addr - base) / core::mem::size_of::<Block>())
    }

    fn give_back(&self, index: usize) {
        self.in_use.fetch_and(!(1 << index), Ordering::Release);
    }

    fn blocks_in_use(&self) -> u32 {
        self.in_use.load(Ordering::Relaxed).count_ones()
    }
}

/// The system allocator, counting (and pooling) the allocations of tracked threads.
#[derive(Debug, Default, Clone, Copy)]
pub struct CountingAllocator;

thread_local! {
    // `const` initialisers without destructors: no lazy registration, so reading them from
    // inside the allocator can never allocate or recurse.
    static TRACKED: Cell<bool> = const { Cell::new(false) };
    static HEAP_ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
    static HEAP_BYTES: Cell<u64> = const { Cell::new(0) };
    static POOL_ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
    // Set in a section whose allocations are expected and counted apart ([`untraced`]), and
    // while `counting_allocator_installed` makes its deliberate probe allocation.
    static UNTRACED: Cell<bool> = const { Cell::new(false) };
}

/// Whether the first heap allocation of a tracked thread is traced.
static TRACE_FIRST: AtomicBool = AtomicBool::new(false);
/// Set once the first heap allocation has been traced (or is being traced).
static TRACE_TAKEN: AtomicBool = AtomicBool::new(false);
/// The trace, until taken.
static FIRST_TRACE: Mutex<Option<HeapTrace>> = Mutex::new(None);

/// Where the first heap allocation of a tracked thread happened.
#[derive(Debug)]
pub struct HeapTrace {
    /// Bytes requested.
    pub bytes: usize,
    /// The allocating thread's name, if it has one.
    pub thread: Option<String>,
    /// The call stack at the allocation (resolved to symbols when displayed).
    pub backtrace: Backtrace,
}

impl core::fmt::Display for HeapTrace {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "first heap allocation on a tracked thread: {} bytes on thread {}, at\n{}",
            self.bytes,
            self.thread.as_deref().unwrap_or("(unnamed)"),
            self.backtrace
        )
    }
}

/// Turns the trace of the first heap allocation of a tracked thread on or off (process-wide).
pub fn trace_first_heap_allocation(on: bool) {
    TRACE_FIRST.store(on, Ordering::Relaxed);
}

/// The trace of the first heap allocation of a tracked thread, once (later calls: `None`).
pub fn take_first_heap_allocation() -> Option<HeapTrace> {
    FIRST_TRACE
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .take()
}

/// Runs `f` with the current thread's allocations counted but never traced: for a section
/// whose allocations are expected and counted apart (iceoryx2 connecting a late peer).
pub fn untraced<R>(f: impl FnOnce() -> R) -> R {
    let was = UNTRACED.with(|u| u.replace(true));
    let r = f();
    UNTRACED.with(|u| u.set(was));
    r
}

/// Records where the current (tracked) thread allocates `bytes` from the heap, if tracing is
/// on and nothing was traced before.
#[cold]
#[inline(never)]
fn trace_heap_allocation(bytes: usize) {
    if !TRACE_FIRST.load(Ordering::Relaxed)
        || UNTRACED.try_with(Cell::get).unwrap_or(true)
        || TRACE_TAKEN.swap(true, Ordering::AcqRel)
    {
        return;
    }
    // Untracked while capturing: the capture's own allocations go to the system heap and
    // are not counted (nor traced again).
    let _ = TRACKED.try_with(|t| t.set(false));
    let trace = HeapTrace {
        bytes,
        thread: std::thread::current().name().map(str::to_owned),
        backtrace: Backtrace::force_capture(),
    };
    *FIRST_TRACE
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner) = Some(trace);
    let _ = TRACKED.try_with(|t| t.set(true));
}

/// True when the current thread is tracked (false while it is being torn down).
#[inline]
fn tracked() -> bool {
    TRACKED.try_with(Cell::get).unwrap_or(false)
}

#[inline]
fn bump(counter: &'static std::thread::LocalKey<Cell<u64>>, n: u64) {
    let _ = counter.try_with(|c| c.set(c.get() + n));
}

/// Serves `layout` for a tracked thread: pool first, heap otherwise (counted).
///
/// # Safety
/// `layout` has a non-zero size (the `GlobalAlloc` contract).
unsafe fn tracked_alloc(layout: Layout, zeroed: bool) -> *mut u8 {
    if Pool::fits(&layout)
        && let Some(block) = POOL.take()
    {
        bump(&POOL_ALLOCATIONS, 1);
        if zeroed {
            // SAFETY: the block is ours, POOL_BLOCK_BYTES >= layout.size() long.
            unsafe { block.write_bytes(0, layout.size()) };
        }
        return block;
    }
    bump(&HEAP_ALLOCATIONS, 1);
    bump(&HEAP_BYTES, layout.size() as u64);
    trace_heap_allocation(layout.size());
    // SAFETY: forwarded to `System` under the caller's `GlobalAlloc` contract.
    unsafe {
        if zeroed {
            System.alloc_zeroed(layout)
        } else {
            System.alloc(layout)
        }
    }
}

// SAFETY: pool blocks are 64-byte aligned, POOL_BLOCK_BYTES long and handed to one owner at a
// time (see `Pool`); every other request is forwarded to `System` unchanged. Pointers are
// routed back to where they came from by address (`Pool::index_of`), so each is freed by the
// allocator that produced it. The counters are thread-local `Cell`s, which neither allocate
// nor unwind.
unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if tracked() {
            // SAFETY: caller upholds the `GlobalAlloc::alloc` contract.
            unsafe { tracked_alloc(layout, false) }
        } else {
            // SAFETY: as above.
            unsafe { System.alloc(layout) }
        }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        if tracked() {
            // SAFETY: as above.
            unsafe { tracked_alloc(layout, true) }
        } else {
            // SAFETY: as above.
            unsafe { System.alloc_zeroed(layout) }
        }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if let Some(index) = POOL.index_of(ptr) {
            if new_size <= POOL_BLOCK_BYTES {
                // The block already has room.
                return ptr;
            }
            // SAFETY: `new_size` is non-zero and, rounded to `layout.align()`, does not
            // overflow (the `GlobalAlloc::realloc` contract).
            let new_layout = unsafe { Layout::from_size_align_unchecked(new_size, layout.align()) };
            // SAFETY: as above.
            let fresh = unsafe { self.alloc(new_layout) };
            if !fresh.is_null() {
                // SAFETY: both regions are valid for `layout.size()` bytes and distinct.
                unsafe { core::ptr::copy_nonoverlapping(ptr, fresh, layout.size()) };
                POOL.give_back(index);
            }
            return fresh;
        }
        if tracked() {
            bump(&HEAP_ALLOCATIONS, 1);
            bump(&HEAP_BYTES, new_size as u64);
            trace_heap_allocation(new_size);
        }
        // SAFETY: `ptr` came from `System` (it is not a pool block) with `layout`.
        unsafe { System.realloc(ptr, layout, new_size) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        match POOL.index_of(ptr) {
            Some(index) => POOL.give_back(index),
            // SAFETY: `ptr` came from `System` with `layout`.
            None => unsafe { System.dealloc(ptr, layout) },
        }
    }
}

/// Allocations counted for the current thread while it was tracked.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct AllocCount {
    /// Allocations (and growing reallocations) served by the system heap.
    pub allocations: u64,
    /// Bytes requested from the system heap.
    pub bytes: u64,
    /// Allocations served from the real-time pool.
    pub pool_allocations: u64,
}

/// Starts (or stops) counting the current thread's allocations (and serving its small ones
/// from the pool).
pub fn track_current_thread(on: bool) {
    TRACKED.with(|t| t.set(on));
}

/// The current thread's counted allocations.
pub fn current_thread_allocations() -> AllocCount {
    AllocCount {
        allocations: HEAP_ALLOCATIONS.with(Cell::get),
        bytes: HEAP_BYTES.with(Cell::get),
        pool_allocations: POOL_ALLOCATIONS.with(Cell::get),
    }
}

/// Pool blocks currently in use (by any thread).
pub fn pool_blocks_in_use() -> u32 {
    POOL.blocks_in_use()
}

/// True when [`CountingAllocator`] is the global allocator (checked by making one tracked
/// allocation and seeing whether it was counted). Without it the counts stay 0 and mean
/// nothing.
pub fn counting_allocator_installed() -> bool {
    let was_tracked = TRACKED.with(Cell::get);
    let before = current_thread_allocations();
    let probe = untraced(|| {
        track_current_thread(true);
        let probe = std::hint::black_box(Box::new([0u8; POOL_BLOCK_BYTES + 1]));
        track_current_thread(was_tracked);
        probe
    });
    drop(probe);
    let installed = current_thread_allocations().allocations > before.allocations;
    // The probe is not the caller's allocation: restore the counters.
    HEAP_ALLOCATIONS.with(|n| n.set(before.allocations));
    HEAP_BYTES.with(|b| b.set(before.bytes));
    POOL_ALLOCATIONS.with(|n| n.set(before.pool_allocations));
    installed
}
