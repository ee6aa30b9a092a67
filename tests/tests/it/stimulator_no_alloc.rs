//! The stimulator's state machine runs its 1 ms path without heap allocation: a counting
//! global allocator sees zero allocations over 20 000 ticks with pulses, heartbeats,
//! rejected frames (CRC, counter, length, state, rate), a watchdog fault and re-arming.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use fes_rt::rt::alloc::{self, CountingAllocator};

/// The project's counting allocator; only the measuring thread is tracked (libtest's own
/// threads allocate meanwhile). Its small-block pool counts too: zero means zero.
#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

use fes_can::{
    AliveCounter, Heartbeat, Message, Nmt, NmtCommand, NmtState, Nodes, Pulse, StimLimits,
    StimState,
};
use fes_virtual_stimulator::machine::{Settings, Stimulator, TICK_NS, Tick};
use fes_virtual_stimulator::outbox::Outbox;
use fes_virtual_stimulator::test_plant::ChargeIntegrator;

#[test]
fn state_machine_allocates_nothing_per_tick() {
    let settings = Settings {
        nodes: Nodes::DEFAULT,
        ceiling: StimLimits::DEFAULT,
        channels: 1,
        heartbeat_ms: 100,
        host_heartbeat_ms: 10,
        test_fault_loose_config: false,
    };
    settings.validate().unwrap();
    let mut out = Outbox::new();
    let mut plant = ChargeIntegrator::new();
    let mut stim = Stimulator::new(settings, 0, &mut out);
    let hb = Message::HostHeartbeat(Heartbeat {
        state: NmtState::Operational,
    })
    .encode()
    .unwrap();
    let start = Message::Nmt(Nmt {
        command: NmtCommand::Start,
        node: 0,
    })
    .encode()
    .unwrap();
    let pages = StimLimits::DEFAULT
        .to_pages(3)
        .map(|p| Message::Config(p).encode().unwrap());
    let mut alive = AliveCounter::new();
    let mut sent = 0u64;
    let mut frames_out = 0usize;

    assert!(alloc::counting_allocator_installed());
    alloc::track_current_thread(true);
    let before = alloc::current_thread_allocations();
    for k in 0..20_000u64 {
        let now = (k + 1) * TICK_NS;
        let silent = (5_000..5_300).contains(&k); // the host goes quiet: watchdog fault
        if !silent && k % 10 == 0 {
            stim.on_frame(now, u32::from(hb.id), hb.payload(), &mut out);
        }
        if k == 10 || k == 6_000 {
            for p in &pages {
                stim.on_frame(now, u32::from(p.id), p.payload(), &mut out); // wrong state once operational
            }
            stim.on_frame(now, u32::from(start.id), start.payload(), &mut out);
        }
        if k % 7 == 0 {
            let p = Pulse {
                seq: sent as u16,
                alive_counter: alive.next_value(),
                channel: 0,
                amplitude_100ua: 200,
                width_us: 200,
            };
            sent += 1;
            let mut f = Message::Pulse(p).encode().unwrap();
            if k % 700 == 0 {
                f.data[7] ^= 0xFF; // corrupt now and then
            }
            stim.on_frame(now, u32::from(f.id), f.payload(), &mut out);
        }
        stim.on_frame(now, 0x701, &[1, 2, 3], &mut out); // wrong length every tick
        stim.tick(
            Tick {
                index: k,
                nominal_ns: now,
                now_ns: now,
            },
            &mut plant,
            &mut out,
        );
        frames_out += out.frames().len();
        out.clear();
    }
    let after = alloc::current_thread_allocations();
    alloc::track_current_thread(false);
    assert_eq!(
        (after.allocations - before.allocations)
            + (after.pool_allocations - before.pool_allocations),
        0,
        "allocations in the stimulator's tick path"
    );
    // The run did what it should, so the path measured was the real one: pulses every
    // 7 ms are capped by the default 100-per-second rate limit, minus the fault period.
    assert!(
        (1_800..=2_000).contains(&stim.pulses_delivered()),
        "{}",
        stim.pulses_delivered()
    );
    assert!(
        matches!(stim.state(), StimState::Armed | StimState::Stimulating),
        "{:?}",
        stim.state()
    );
    assert!(frames_out > 20_000);
}
