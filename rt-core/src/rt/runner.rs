//! The iceoryx2 adapter of the rt-core process: the real-time loop thread and its
//! normal-priority telemetry thread. The binary is a thin shell around these two functions,
//! which tests also call directly.
//!
//! Real-time thread ([`run_pattern_loop`]): [`enter_realtime`] first, then create the
//! iceoryx2 ports *inside* the thread (they are not `Send`), connect them, start counting
//! allocations, and loop: sleep to the next absolute deadline; take every waiting
//! [`Reference`] without blocking (bounded by the subscriber buffer); run the source once;
//! publish one [`StimTick`] (loaned sample, stamped just before `send`, safe overflow: never
//! blocks); notify the tick event; push the tick's timing into the telemetry queue. Nothing
//! on this path allocates, locks, logs or blocks; failures are counted, not logged.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;

use fes_rt::msg::port;
use fes_rt::rt::node::connect_err;
use fes_rt::rt::node::{RunError, create_node};

use super::generator::{PatternLoop, StepEvents};
use super::process_config::RtCoreConfig;
use super::source::TickSource;
use fes_rt::msg::{
    Contract, ForceSample, Reference, ReferencePreview, StimTick, TimingReport, TimingSource,
};
use fes_rt::rt::alloc;
use fes_rt::rt::clock::{PeriodicClock, Wakeup, monotonic_ns};
use fes_rt::rt::hlog::HlogWriter;
use fes_rt::rt::realtime::{RtStatus, enter_realtime};
use fes_rt::rt::telemetry::{
    IntervalQuantities, LoopCounters, TelemetryChannel, TickTiming, TimingAggregator,
};

/// How a finished real-time loop went.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LoopOutcome {
    /// What [`enter_realtime`] achieved.
    pub status: RtStatus,
    /// `seq` of the final tick.
    pub final_seq: u64,
    /// Whether the counting allocator was installed (else allocations were not counted).
    pub allocations_counted: bool,
    /// The source's closing words ([`TickSource::summary`]), e.g. the planner's counters.
    pub source_summary: Option<String>,
}

/// Runs the pattern generator's real-time loop on the calling thread until `stop` is set,
/// then publishes the final tick. `on_ready` is called once real time has been entered and
/// the ports exist (before the first tick), with what was achieved.
pub fn run_pattern_loop<S: TickSource>(
    node: &Node<ipc::Service>,
    config: &RtCoreConfig,
    source: S,
    telemetry: &TelemetryChannel,
    stop: &AtomicBool,
    on_ready: impl FnOnce(&RtStatus),
) -> Result<LoopOutcome, RunError> {
    let status = enter_realtime(&config.rt)?;
    let ports = LoopPorts::open(node, config)?;
    let mut rt_loop = RtLoop::new(ports, config, source, telemetry, &status)?;
    on_ready(&status);
    rt_loop.run(config.telemetry.trace_allocations, stop);
    let allocations_counted = rt_loop.allocations_counted;
    let source_summary = rt_loop.generator.source().summary();
    let final_seq = rt_loop.finish();
    Ok(LoopOutcome {
        status,
        final_seq,
        allocations_counted,
        source_summary,
    })
}

/// The loop's iceoryx2 ports, created on the real-time thread (they are not `Send`).
/// Fields are declared in the reverse of their creation order, so they are dropped in it.
struct LoopPorts {
    /// The stim-tick event, notified after each StimTick (`ipc.notify`).
    notifier: Option<Notifier<ipc::Service>>,
    /// Measured force (feedback mode only).
    forces: Option<Subscriber<ipc::Service, ForceSample, ()>>,
    /// The supervisor's scheduled setpoints.
    previews: Subscriber<ipc::Service, ReferencePreview, ()>,
    /// The supervisor's references.
    references: Subscriber<ipc::Service, Reference, ()>,
    /// One StimTick per tick.
    publisher: Publisher<ipc::Service, StimTick, ()>,
}

impl LoopPorts {
    /// Creates the ports `config` asks for and connects each to the peers already there.
    fn open(node: &Node<ipc::Service>, config: &RtCoreConfig) -> Result<Self, RunError> {
        let prefix = config.ipc.prefix.as_str();
        let ports = Self {
            publisher: port::publisher::<StimTick>(node, prefix)?,
            references: port::subscriber::<Reference>(node, prefix)?,
            previews: port::subscriber::<ReferencePreview>(node, prefix)?,
            forces: if config.feedback.enabled {
                Some(port::subscriber::<ForceSample>(node, prefix)?)
            } else {
                None
            },
            notifier: if config.ipc.own.notify {
                Some(port::stim_tick_notifier(node, prefix)?)
            } else {
                None
            },
        };
        ports.connect()?;
        Ok(ports)
    }

    /// Connects every port to the peers already there, before the first tick.
    fn connect(&self) -> Result<(), RunError> {
        self.publisher
            .update_connections()
            .map_err(connect_err("StimTick publisher"))?;
        self.references
            .update_connections()
            .map_err(connect_err("Reference subscriber"))?;
        self.previews
            .update_connections()
            .map_err(connect_err("ReferencePreview subscriber"))?;
        if let Some(n) = &self.notifier {
            n.update_connections()
                .map_err(connect_err("stim-tick notifier"))?;
        }
        if let Some(f) = &self.forces {
            f.update_connections()
                .map_err(connect_err("ForceSample subscriber"))?;
        }
        Ok(())
    }
}

/// The real-time loop's state: made at start-up ([`RtLoop::new`]), then one
/// [`RtLoop::tick`] per wake-up on the hot path ([`RtLoop::run`]), then the final tick
/// ([`RtLoop::finish`]). Nothing in `run` takes from the heap, locks, logs or blocks.
struct RtLoop<'a, S> {
    /// The absolute-time periodic clock.
    clock: PeriodicClock,
    /// The tick logic around the source.
    generator: PatternLoop<S>,
    /// The iceoryx2 ports.
    ports: LoopPorts,
    /// Timing records and counters for the telemetry thread.
    telemetry: &'a TelemetryChannel,
    /// Whether the counting allocator is installed.
    allocations_counted: bool,
    /// The thread's allocation counts when the hot path began.
    alloc_baseline: alloc::AllocCount,
    /// Heap allocations made by iceoryx2 connecting late peers, counted apart.
    connection_allocs: u64,
}

impl<'a, S: TickSource> RtLoop<'a, S> {
    /// Start-up (may allocate): the generator, the report flags and the first deadline.
    fn new(
        ports: LoopPorts,
        config: &RtCoreConfig,
        source: S,
        telemetry: &'a TelemetryChannel,
        status: &RtStatus,
    ) -> Result<Self, RunError> {
        let generator = PatternLoop::new(
            source,
            config.reference_policy(),
            config.feedback_max_age_ns(),
            config.pulse_settings(),
            status.is_degraded(),
        );
        let allocations_counted = alloc::counting_allocator_installed();
        telemetry.set_report_flags(report_flags(status.is_degraded(), allocations_counted));
        let clock = PeriodicClock::start(config.period())?;
        Ok(Self {
            clock,
            generator,
            ports,
            telemetry,
            allocations_counted,
            alloc_baseline: alloc::AllocCount::default(),
            connection_allocs: 0,
        })
    }

    /// The hot path: sleeps to each deadline and runs one tick per wake-up until `stop`
    /// is set, with the thread's allocations tracked (and the first one traced when
    /// `trace_allocations`).
    fn run(&mut self, trace_allocations: bool, stop: &AtomicBool) {
        // ---- hot path from here on: no allocation, lock, log or blocking call ----
        alloc::trace_first_heap_allocation(trace_allocations);
        alloc::track_current_thread(true);
        self.alloc_baseline = alloc::current_thread_allocations();
        while !stop.load(Ordering::Relaxed) {
            let wake = self.clock.wait();
            if stop.load(Ordering::Relaxed) {
                break;
            }
            self.tick(&wake);
        }
        // ---- end of the hot path ----
        alloc::track_current_thread(false);
    }

    /// One tick: connect late peers, take the inputs, run the source once, publish and
    /// notify, then count and push the tick's timing.
    #[inline]
    fn tick(&mut self, wake: &Wakeup) {
        self.connect_inputs();
        self.receive_references(wake.wake_ns);
        self.receive_forces();
        let t_inputs = monotonic_ns();
        let (tick, events) = self.generator.step(wake);
        let t_decided = monotonic_ns();
        self.publish_and_notify(tick);
        let t_done = monotonic_ns();
        self.count(wake, events);
        self.telemetry.push(TickTiming {
            grid_ns: wake.grid_ns,
            lateness_ns: wake.lateness_ns,
            input_ns: t_inputs.saturating_sub(wake.wake_ns),
            compute_ns: t_decided.saturating_sub(t_inputs),
            publish_ns: t_done.saturating_sub(t_decided),
        });
    }

    /// Peers that appeared since the last tick (a supervisor, a driver, a probe started
    /// later): iceoryx2 allocates a connection's state once, when it connects; that
    /// happens explicitly, right before each port is used, and is counted apart from the
    /// hot path (it would otherwise happen inside the receive or send). Without new peers
    /// this only compares a change counter.
    #[inline]
    fn connect_inputs(&mut self) {
        let ports = &self.ports;
        connecting(&mut self.connection_allocs, || {
            let _ = ports.references.update_connections();
            let _ = ports.previews.update_connections();
            if let Some(f) = &ports.forces {
                let _ = f.update_connections();
            }
        });
    }

    /// Takes every waiting Reference (at most the subscriber buffer) without blocking.
    #[inline]
    fn receive_references(&mut self, wake_ns: u64) {
        let generator = &mut self.generator;
        receive_each(
            &self.ports.references,
            &self.telemetry.counters,
            |reference| generator.offer_reference(reference, wake_ns).is_ok(),
        );
        receive_each(&self.ports.previews, &self.telemetry.counters, |preview| {
            generator.offer_preview(preview, wake_ns).is_ok()
        });
    }

    /// In feedback mode, takes every waiting ForceSample (at most the subscriber buffer).
    #[inline]
    fn receive_forces(&mut self) {
        if let Some(forces) = &self.ports.forces {
            let generator = &mut self.generator;
            receive_each(forces, &self.telemetry.counters, |force| {
                generator.offer_force(force).is_ok()
            });
        }
    }

    /// Publishes the tick, then notifies the stim-tick event; connection work is counted
    /// apart.
    #[inline]
    fn publish_and_notify(&mut self, tick: StimTick) {
        let ports = &self.ports;
        let counters = &self.telemetry.counters;
        let _ = connecting(&mut self.connection_allocs, || {
            ports.publisher.update_connections()
        });
        if !publish(&ports.publisher, tick) {
            LoopCounters::bump(&counters.publish_errors, 1);
        }
        // iceoryx2 0.10's `Notifier::notify` updates its listener connections itself
        // (`__internal_notify` -> `update_connections` -> `populate_listener_channels`,
        // which allocates when the listener set changed); its only other work is one
        // datagram per listener. A driver whose listener appears while the loop runs was
        // connected inside `notify` whenever it landed between an explicit update and the
        // notify (found by the allocation trace: 1 heap allocation in about 30 stack
        // runs). The whole notify is therefore connection work, counted apart; the tick
        // has been published before it.
        if let Some(n) = &ports.notifier
            && connecting(&mut self.connection_allocs, || {
                let _ = n.update_connections();
                n.notify()
            })
            .is_err()
        {
            LoopCounters::bump(&counters.publish_errors, 1);
        }
        if self.connection_allocs != counters.connection_allocations.load(Ordering::Relaxed) {
            counters
                .connection_allocations
                .store(self.connection_allocs, Ordering::Relaxed);
        }
    }

    /// Counts the tick, its skipped periods, a source fault and the thread's allocations
    /// since the hot path began (connection work apart).
    #[inline]
    fn count(&self, wake: &Wakeup, events: StepEvents) {
        let counters = &self.telemetry.counters;
        LoopCounters::bump(&counters.ticks, 1);
        if wake.missed_periods > 0 {
            LoopCounters::bump(&counters.misses, u64::from(wake.missed_periods));
            LoopCounters::bump(&counters.overruns, 1);
        }
        if events.source_fault {
            LoopCounters::bump(&counters.source_faults, 1);
        }
        let allocs = alloc::current_thread_allocations();
        let baseline = &self.alloc_baseline;
        counters.hot_path_allocations.store(
            allocs.allocations - baseline.allocations - self.connection_allocs,
            Ordering::Relaxed,
        );
        counters.pool_allocations.store(
            allocs.pool_allocations - baseline.pool_allocations,
            Ordering::Relaxed,
        );
    }

    /// Shutdown: publishes the final tick (pulse 0, [`StimTick::FLAG_FINAL`]) and
    /// notifies; returns its `seq`. The ports are dropped afterwards.
    fn finish(mut self) -> u64 {
        let final_tick = self.generator.final_tick(monotonic_ns());
        if !publish(&self.ports.publisher, final_tick) {
            LoopCounters::bump(&self.telemetry.counters.publish_errors, 1);
        }
        if let Some(n) = &self.ports.notifier {
            let _ = n.notify();
        }
        final_tick.seq
    }
}

/// The TimingReport flags of a loop: degraded real time, allocations not counted.
fn report_flags(degraded: bool, allocations_counted: bool) -> u8 {
    let mut flags = 0;
    if degraded {
        flags |= TimingReport::FLAG_DEGRADED;
    }
    if !allocations_counted {
        flags |= TimingReport::FLAG_ALLOCATIONS_UNCOUNTED;
    }
    flags
}

/// Takes up to the topic's subscriber buffer of waiting samples from `subscriber` without
/// blocking and gives each to `accept` (copied out, the sample released first); counts
/// the samples it rejects and stops at the first receive error, counted too.
#[inline]
fn receive_each<M: Contract>(
    subscriber: &Subscriber<ipc::Service, M, ()>,
    counters: &LoopCounters,
    mut accept: impl FnMut(&M) -> bool,
) {
    for _ in 0..M::QOS.subscriber_buffer {
        match subscriber.receive() {
            Ok(Some(sample)) => {
                let value = *sample.payload();
                drop(sample);
                if !accept(&value) {
                    LoopCounters::bump(&counters.rejected_inputs, 1);
                }
            }
            Ok(None) => break,
            Err(_) => {
                LoopCounters::bump(&counters.receive_errors, 1);
                break;
            }
        }
    }
}

/// Runs `f`, iceoryx2's connection work (a late peer connecting), untraced, and adds the
/// heap allocations it made to `connection_allocs` (counted apart from the hot path's).
#[inline]
fn connecting<R>(connection_allocs: &mut u64, f: impl FnOnce() -> R) -> R {
    let before = alloc::current_thread_allocations().allocations;
    let r = alloc::untraced(f);
    *connection_allocs += alloc::current_thread_allocations().allocations - before;
    r
}

/// Loans a sample, writes `tick`, stamps `t_publish_ns` and sends it. False on failure.
#[inline]
fn publish(publisher: &Publisher<ipc::Service, StimTick, ()>, tick: StimTick) -> bool {
    match publisher.loan_uninit() {
        Ok(sample) => {
            let mut sample = sample.write_payload(tick);
            sample.payload_mut().t_publish_ns = monotonic_ns();
            sample.send().is_ok()
        }
        Err(_) => false,
    }
}

/// Settings of the telemetry thread.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TelemetrySettings {
    /// Node name of the telemetry thread's iceoryx2 node.
    pub node_name: String,
    /// Service-name prefix.
    pub prefix: String,
    /// Period of reports and hlog intervals.
    pub report_period: Duration,
    /// Who is reporting.
    pub source: TimingSource,
    /// The prescription the process enforces ([`TimingReport::prescription`]; zeros for
    /// none).
    pub prescription: [u8; 6],
}

impl TelemetrySettings {
    /// The rt-core process's telemetry settings.
    pub fn for_rt_core(config: &RtCoreConfig) -> Self {
        Self {
            node_name: "rt-core-telemetry".to_owned(),
            prefix: config.ipc.prefix.clone(),
            report_period: Duration::from_millis(config.telemetry.report_period_ms),
            source: TimingSource::RtCore,
            prescription: [0; 6],
        }
    }
}

/// How often the telemetry thread drains the queue.
pub const DRAIN_PERIOD: Duration = Duration::from_millis(10);

/// Runs the telemetry thread (normal priority) until `stop` is set: drains `channel` every
/// [`DRAIN_PERIOD`], and every report period writes an interval to `hlog` (if given) and
/// publishes a cumulative [`TimingReport`]. `on_ready` is called once its port exists. On
/// stop it drains what is left and writes the final interval and the final report
/// ([`TimingReport::FLAG_FINAL`]), which it also returns.
pub fn run_telemetry(
    settings: &TelemetrySettings,
    mut hlog: Option<HlogWriter>,
    channel: &TelemetryChannel,
    stop: &AtomicBool,
    on_ready: impl FnOnce(),
) -> Result<TimingReport, RunError> {
    let node = create_node(&settings.node_name)?;
    let publisher = port::publisher::<TimingReport>(&node, &settings.prefix)?;
    on_ready();
    let start = Instant::now();
    let mut aggregator = TimingAggregator::new();
    let mut seq = 0u64;
    let mut interval_start = Duration::ZERO;
    let mut emit = |aggregator: &mut TimingAggregator,
                    final_flag: u8|
     -> Result<TimingReport, RunError> {
        let now = start.elapsed();
        if let Some(log) = &mut hlog {
            aggregator.write_interval(log, interval_start, now.saturating_sub(interval_start))?;
            log.flush()?;
        }
        interval_start = now;
        seq += 1;
        let report = TimingReport {
            prescription: settings.prescription,
            ..aggregator.report(
                seq,
                monotonic_ns(),
                settings.source,
                &channel.counters.snapshot(),
                channel.overflows(),
                channel.report_flags() | final_flag,
            )
        };
        // A failed report is not fatal: the next one carries the same cumulative numbers.
        let _ = publisher.send_copy(report);
        Ok(report)
    };
    let mut next_report = start + settings.report_period;
    while !stop.load(Ordering::Relaxed) {
        std::thread::sleep(DRAIN_PERIOD);
        aggregator.drain(channel);
        if Instant::now() >= next_report {
            emit(&mut aggregator, 0)?;
            next_report += settings.report_period;
        }
    }
    aggregator.drain(channel);
    emit(&mut aggregator, TimingReport::FLAG_FINAL)
}
