//! The real-time loop takes nothing from the system heap after start-up (docs/realtime.md,
//! "The rules and where each is kept"), proven with the counting global allocator over hundreds of ticks of the
//! real loop with real iceoryx2 ports, references flowing in and ticks flowing out.
#![allow(clippy::unwrap_used, clippy::expect_used)] // test code: a failed assumption is a failed test

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use fes_rt::msg::port;
use fes_rt::msg::service::{open_pubsub, open_stim_tick_event};
use fes_rt::msg::{Contract, Reference, StimTick};
use fes_rt::rt::clock::monotonic_ns;
use fes_rt::rt::node::create_node;
use fes_rt::rt::telemetry::TelemetryChannel;
use fes_rt::rt::{MissingRightsPolicy, RtConfig};
use rt_core::rt::process_config::{RtCoreConfig, SourceConfig};
use rt_core::rt::runner::run_pattern_loop;
use rt_core::rt::source::{ControllerSource, TestPattern, TickSource};

use crate::rt_common;

const TICKS: u64 = 400;

/// The loop's configuration: a test pattern firing every 3 ticks, real time best effort
/// at a low priority, memory not locked (the tests run in parallel).
fn loop_config(prefix: &str) -> RtCoreConfig {
    let mut config = RtCoreConfig::with_source(SourceConfig::TestPattern { ipi_ticks: 3 });
    config.ipc.prefix = prefix.to_owned();
    config.rt = RtConfig {
        priority: 10,
        core: None,
        on_missing_rights: MissingRightsPolicy::BestEffort,
        lock_memory: false,
        prefault_stack_bytes: 64 * 1024,
        cpu_dma_latency_us: None,
    };
    config
}

/// Runs the real loop with `source` for [`TICKS`] ticks and checks the allocation counts.
fn run_counting<S: TickSource + Send>(source: S, name: &str) {
    let prefix = format!("noalloc{name}{}", std::process::id());
    let config = loop_config(&prefix);

    // Receiver side first, so that every connection exists before the loop starts.
    let node = create_node("noalloc-test").unwrap();
    let subscriber = port::subscriber::<StimTick>(&node, &prefix).unwrap();
    let listener = port::stim_tick_listener(&node, &prefix).unwrap();
    let reference_publisher = port::publisher::<Reference>(&node, &prefix).unwrap();

    let telemetry = TelemetryChannel::new(1024);
    let stop = AtomicBool::new(false);
    let mut received = Vec::with_capacity(TICKS as usize + 100);
    let mut ref_seq = 0;
    std::thread::scope(|s| {
        let rt = s.spawn(|| {
            let node = create_node("noalloc-loop").unwrap();
            run_pattern_loop(&node, &config, source, &telemetry, &stop, |_| {})
        });
        let deadline = Instant::now() + Duration::from_secs(20);
        while telemetry.counters.snapshot().ticks < TICKS {
            assert!(Instant::now() < deadline, "the loop did not run");
            // Keep a fresh reference flowing in (new samples every 10 ms).
            ref_seq += 1;
            reference_publisher
                .send_copy(Reference::new(ref_seq, monotonic_ns(), 0.5))
                .unwrap();
            let _ = listener.timed_wait(|_| {}, Duration::from_millis(10));
            while let Some(sample) = subscriber.receive().unwrap() {
                received.push(*sample.payload());
            }
            while telemetry.pop().is_some() {}
        }
        stop.store(true, Ordering::Relaxed);
        let outcome = rt.join().unwrap().unwrap();
        assert!(outcome.allocations_counted);
    });

    let counters = telemetry.counters.snapshot();
    assert!(counters.ticks >= TICKS);
    assert_eq!(
        counters.hot_path_allocations, 0,
        "heap allocation on the hot path"
    );
    // iceoryx2 0.10 creates exactly one Rc per loaned sample: one pool block per tick.
    assert_eq!(counters.pool_allocations, counters.ticks);
    assert_eq!(counters.rejected_inputs, 0);
    assert_eq!(counters.publish_errors, 0);
    // The ticks really went out and the references really came in.
    assert!(received.len() as u64 >= TICKS / 2);
    assert!(received.iter().all(|t| t.validate().is_ok()));
    assert!(received.iter().any(|t| t.fires()));
    assert!(received.iter().filter(|t| t.ref_seq > 0).count() > 10);
}

#[test]
fn the_loop_makes_no_heap_allocation_and_exactly_one_pool_allocation_per_publish() {
    let _exclusive = crate::exclusive_allocator();
    run_counting(TestPattern::new(3).unwrap(), "pattern");
}

#[test]
fn so_does_the_loop_running_a_ten_unit_pattern_generator() {
    let _exclusive = crate::exclusive_allocator();
    let dir = rt_common::Scratch::new("noalloc");
    let path = dir.join("controller.json");
    rt_common::write_controller(&path, 10);
    let source = ControllerSource::load(&path, Duration::from_millis(1)).unwrap();
    assert_eq!(source.units(), 10);
    run_counting(source, "controller");
}

/// Peers that come and go while the loop runs (a driver's listener, a probe's subscriber, a
/// supervisor's reference publisher; 400 cycles at random moments of the tick) are connected
/// by the loop's explicit connection updates, counted apart: the hot path's heap count stays
/// 0. (A listener appearing between the tick's first update and its notify used to be
/// connected inside `notify`, an allocation on the hot path once in about 30 stack runs.)
#[test]
fn peers_connecting_while_the_loop_runs_are_counted_apart_from_the_hot_path() {
    let _exclusive = crate::exclusive_allocator();
    let prefix = format!("noalloclate{}", std::process::id());
    let config = loop_config(&prefix);
    let telemetry = TelemetryChannel::new(1 << 16);
    let stop = AtomicBool::new(false);
    std::thread::scope(|s| {
        let rt = s.spawn(|| {
            let node = create_node("noalloc-late-loop").unwrap();
            run_pattern_loop(
                &node,
                &config,
                TestPattern::new(3).unwrap(),
                &telemetry,
                &stop,
                |_| {},
            )
        });
        let deadline = Instant::now() + Duration::from_secs(20);
        while telemetry.counters.snapshot().ticks < 50 {
            assert!(Instant::now() < deadline, "the loop did not run");
            std::thread::sleep(Duration::from_millis(5));
        }
        let node = create_node("noalloc-late-peers").unwrap();
        let events = open_stim_tick_event(&node, &prefix).unwrap();
        let ticks = open_pubsub::<StimTick>(&node, &prefix).unwrap();
        let references = open_pubsub::<Reference>(&node, &prefix).unwrap();
        for cycle in 0..400u64 {
            let listener = events.listener_builder().create().unwrap();
            let subscriber = ticks.subscriber_builder().create().unwrap();
            let publisher = references.publisher_builder().create().unwrap();
            publisher
                .send_copy(Reference::new(cycle + 1, monotonic_ns(), 0.5))
                .unwrap();
            // A moment that is not a multiple of the tick.
            std::thread::sleep(Duration::from_micros(3_000 + 137 * (cycle % 7)));
            let _ = listener.try_wait(|_| {});
            while let Ok(Some(_)) = subscriber.receive() {}
            while telemetry.pop().is_some() {}
            drop((listener, subscriber, publisher));
            std::thread::sleep(Duration::from_micros(1_000 + 211 * (cycle % 5)));
        }
        stop.store(true, Ordering::Relaxed);
        assert!(rt.join().unwrap().unwrap().allocations_counted);
    });
    let counters = telemetry.counters.snapshot();
    assert_eq!(
        counters.hot_path_allocations,
        0,
        "heap allocation on the hot path: {:?}",
        fes_rt::rt::alloc::take_first_heap_allocation().map(|t| t.to_string())
    );
    assert!(
        counters.connection_allocations > 0,
        "no connection was made while the loop ran"
    );
}
