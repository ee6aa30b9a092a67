//! encode and decode never touch the heap: a counting global allocator sees zero
//! allocations while every message kind is encoded and decoded, valid or not.
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

use fes_can::{
    AliveCheck, AliveCounter, Config, ConfigAssembler, ConfigPage, Emcy, ErrorCode, Force,
    Heartbeat, Message, Nmt, NmtCommand, NmtState, Pulse, SequenceCheck, Status, StimLimits,
    StimState, decode,
};

#[test]
fn codec_hot_path_allocates_nothing() {
    let messages = [
        Message::Nmt(Nmt {
            command: NmtCommand::Start,
            node: 0x10,
        }),
        Message::Emcy(Emcy::new(
            ErrorCode::MinIpiViolation,
            StimState::Stimulating,
            9,
            1,
        )),
        Message::Pulse(Pulse {
            seq: 5,
            alive_counter: 3,
            channel: 0,
            amplitude_100ua: 200,
            width_us: 200,
        }),
        Message::Force(Force {
            seq: 1,
            force_mn: -1234,
            sample_time_us: 99,
        }),
        Message::Status(Status {
            state: StimState::Armed,
            counter: 1,
            last_error: ErrorCode::NoError,
            pulses_delivered: 3,
            rejected: 0,
            config_id: 1,
        }),
        Message::Config(Config {
            config_id: 1,
            page: ConfigPage::OutputLimits {
                max_amplitude_100ua: 1,
                max_width_us: 1,
                min_ipi_ms: 1,
            },
        }),
        Message::HostHeartbeat(Heartbeat {
            state: NmtState::Operational,
        }),
        Message::StimHeartbeat(Heartbeat {
            state: NmtState::PreOperational,
        }),
    ];
    let mut tx = AliveCounter::new();
    let mut rx = AliveCheck::new();
    let mut seq = SequenceCheck::new();
    let mut asm = ConfigAssembler::new();
    let limits = StimLimits::default();
    MEASURING.with(|m| m.set(true));
    let before = ALLOCATIONS.load(Ordering::SeqCst);
    let mut ok = 0usize;
    for i in 0..10_000u32 {
        for m in &messages {
            let f = m.encode().expect("valid");
            let mut corrupt = f.data;
            corrupt[(i % 8) as usize] ^= 0x40;
            ok += usize::from(decode(u32::from(f.id), f.payload()).is_ok());
            let _ = decode(u32::from(f.id), &corrupt[..usize::from(f.dlc)]);
            let _ = decode(u32::from(f.id), &corrupt[..usize::from(f.dlc) / 2]);
            let _ = decode(0x555, f.payload());
        }
        let _ = rx.check(tx.next_value());
        let _ = seq.check(i as u16);
        for p in limits.to_pages(7) {
            let _ = asm.push(&p);
        }
        let _ = limits.validate();
    }
    let after = ALLOCATIONS.load(Ordering::SeqCst);
    MEASURING.with(|m| m.set(false));
    assert_eq!(ok, 10_000 * messages.len());
    assert_eq!(after - before, 0, "heap allocations on the codec path");
}
