//! encode and decode never touch the heap: a counting global allocator sees zero
//! allocations while every command is encoded and decoded, valid or not.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

std::thread_local! {
    /// Only the measuring thread counts (libtest's own threads allocate meanwhile).
    static MEASURING: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

fn count() {
    if MEASURING.with(std::cell::Cell::get) {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
    }
}

// SAFETY: forwards every call unchanged to the system allocator; only counts.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

use fes_sciencemode::{
    AckResult, ChannelListUpdate, ChannelPulse, Decoder, MAX_PACKET_LEN, Message, Packet,
    SinglePulse,
};

#[test]
fn codec_hot_path_allocates_nothing() {
    let list = ChannelListUpdate::new(&[ChannelPulse::default(); 3]).unwrap();
    let packets = [
        Packet::new(0, Message::Watchdog),
        Packet::new(
            0x0A,
            Message::SinglePulse(SinglePulse {
                channel: 2,
                pulse_width_us: 0x0F0A,
                current_ma: 0x55,
            }),
        ),
        Packet::new(3, Message::StartChannelListMode(list)),
        Packet::new(
            4,
            Message::SinglePulseAck {
                result: AckResult::BusyError,
            },
        ),
    ];
    let mut bufs = [[0u8; MAX_PACKET_LEN]; 4];
    let mut lens = [0usize; 4];
    let mut decoder = Decoder::new();
    MEASURING.with(|m| m.set(true));
    let before = ALLOCATIONS.load(Ordering::SeqCst);
    let mut decoded = 0;
    let mut errors = 0;
    for ((p, buf), len) in packets.iter().zip(bufs.iter_mut()).zip(lens.iter_mut()) {
        *len = p.encode(buf).unwrap();
    }
    for (buf, len) in bufs.iter_mut().zip(lens) {
        for r in decoder.feed(&buf[..len]) {
            decoded += usize::from(r.is_ok());
        }
        // The same packet, corrupted.
        buf[len - 2] ^= 0xFF;
        for r in decoder.feed(&buf[..len]) {
            errors += usize::from(r.is_err());
        }
    }
    let after = ALLOCATIONS.load(Ordering::SeqCst);
    MEASURING.with(|m| m.set(false));
    assert_eq!(decoded, 4);
    assert_eq!(errors, 4);
    assert_eq!(after - before, 0, "the codec allocated");
}
