//! Telemetry that leaves the real-time thread without touching the hot path.
//!
//! The real-time thread pushes one [`TickTiming`] per tick into a preallocated
//! [`crossbeam::queue::ArrayQueue`] (lock-free, never blocks, never allocates; when full the
//! record is dropped and counted) and updates [`LoopCounters`] with relaxed atomic stores. A
//! normal-priority thread drains the queue into a [`TimingAggregator`]: bounded
//! HdrHistograms (cumulative and per interval), interval logs, and [`TimingReport`]s.

use std::sync::atomic::{AtomicU8, AtomicU64, Ordering};
use std::time::Duration;

use crossbeam::queue::ArrayQueue;

use super::histogram::LatencyHistogram;
use super::hlog::{HlogError, HlogWriter};
use crate::msg::{LatencySummary, TimingReport, TimingSource};

/// Timing of one tick, ns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct TickTiming {
    /// Grid point served.
    pub grid_ns: u64,
    /// Wake-up lateness (wake minus deadline).
    pub lateness_ns: u64,
    /// Wake to inputs taken (references and force samples received and checked).
    pub input_ns: u64,
    /// Inputs taken to decision made (the tick source).
    pub compute_ns: u64,
    /// Decision made to sample sent (and listeners notified).
    pub publish_ns: u64,
}

/// Counters the real-time thread keeps for the telemetry thread (single writer, relaxed).
#[derive(Debug, Default)]
pub struct LoopCounters {
    /// Ticks executed.
    pub ticks: AtomicU64,
    /// Periods skipped.
    pub misses: AtomicU64,
    /// Ticks preceded by at least one skipped period.
    pub overruns: AtomicU64,
    /// Inputs rejected by validation or ordering.
    pub rejected_inputs: AtomicU64,
    /// System-heap allocations made by the real-time thread after start-up (must stay 0).
    pub hot_path_allocations: AtomicU64,
    /// System-heap allocations iceoryx2 made on the real-time thread while connecting a
    /// peer that appeared after start-up (a supervisor or driver started later): once per
    /// new connection, counted apart from [`Self::hot_path_allocations`].
    pub connection_allocations: AtomicU64,
    /// Allocations the real-time thread took from the real-time pool of
    /// [`super::alloc::CountingAllocator`] (iceoryx2's one `Rc` per publish).
    pub pool_allocations: AtomicU64,
    /// Ticks on which the tick source produced a non-finite value.
    pub source_faults: AtomicU64,
    /// Failed publishes (loan or send errors).
    pub publish_errors: AtomicU64,
    /// Failed receives.
    pub receive_errors: AtomicU64,
}

/// A snapshot of [`LoopCounters`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CounterSnapshot {
    /// Ticks executed.
    pub ticks: u64,
    /// Periods skipped.
    pub misses: u64,
    /// Ticks preceded by skipped periods.
    pub overruns: u64,
    /// Inputs rejected.
    pub rejected_inputs: u64,
    /// Hot-path heap allocations.
    pub hot_path_allocations: u64,
    /// Allocations while connecting late peers.
    pub connection_allocations: u64,
    /// Hot-path pool allocations.
    pub pool_allocations: u64,
    /// Source faults.
    pub source_faults: u64,
    /// Publish errors.
    pub publish_errors: u64,
    /// Receive errors.
    pub receive_errors: u64,
}

impl LoopCounters {
    /// Adds `n` to a counter that only this thread writes (a load and a store, no read-modify-
    /// write bus lock).
    #[inline]
    pub fn bump(counter: &AtomicU64, n: u64) {
        counter.store(counter.load(Ordering::Relaxed) + n, Ordering::Relaxed);
    }

    /// Reads all counters.
    pub fn snapshot(&self) -> CounterSnapshot {
        let r = |c: &AtomicU64| c.load(Ordering::Relaxed);
        CounterSnapshot {
            ticks: r(&self.ticks),
            misses: r(&self.misses),
            overruns: r(&self.overruns),
            rejected_inputs: r(&self.rejected_inputs),
            hot_path_allocations: r(&self.hot_path_allocations),
            connection_allocations: r(&self.connection_allocations),
            pool_allocations: r(&self.pool_allocations),
            source_faults: r(&self.source_faults),
            publish_errors: r(&self.publish_errors),
            receive_errors: r(&self.receive_errors),
        }
    }
}

/// The real-time thread's outbound telemetry: a fixed-capacity queue and the counters.
#[derive(Debug)]
pub struct TelemetryChannel {
    queue: ArrayQueue<TickTiming>,
    overflows: AtomicU64,
    report_flags: AtomicU8,
    /// Counters updated by the real-time thread.
    pub counters: LoopCounters,
}

impl TelemetryChannel {
    /// A channel holding up to `capacity` tick records (allocated here, once).
    ///
    /// # Panics
    /// If `capacity` is 0 (crossbeam's precondition; callers pass validated configuration).
    pub fn new(capacity: usize) -> Self {
        Self {
            queue: ArrayQueue::new(capacity),
            overflows: AtomicU64::new(0),
            report_flags: AtomicU8::new(0),
            counters: LoopCounters::default(),
        }
    }

    /// Pushes a record without blocking or allocating; a full queue drops it and counts an
    /// overflow.
    #[inline]
    pub fn push(&self, timing: TickTiming) {
        if self.queue.push(timing).is_err() {
            self.overflows.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Takes the oldest record.
    pub fn pop(&self) -> Option<TickTiming> {
        self.queue.pop()
    }

    /// Records dropped because the queue was full.
    pub fn overflows(&self) -> u64 {
        self.overflows.load(Ordering::Relaxed)
    }

    /// Sets the [`TimingReport`] flags that describe the loop (degraded, allocations
    /// uncounted); the real-time thread sets them once at start.
    pub fn set_report_flags(&self, flags: u8) {
        self.report_flags.store(flags, Ordering::Relaxed);
    }

    /// The flags set by [`TelemetryChannel::set_report_flags`].
    pub fn report_flags(&self) -> u8 {
        self.report_flags.load(Ordering::Relaxed)
    }

    /// Queue capacity.
    pub fn capacity(&self) -> usize {
        self.queue.capacity()
    }
}

/// hlog tags of the three loop-side quantities.
pub const TAG_WAKE: &str = "wake";
/// See [`TAG_WAKE`].
pub const TAG_INPUT: &str = "input";
/// See [`TAG_WAKE`].
pub const TAG_COMPUTE: &str = "compute";
/// See [`TAG_WAKE`].
pub const TAG_PUBLISH: &str = "publish";
/// hlog tag of publish-to-receive latency (written by receivers).
pub const TAG_IPC: &str = "ipc";
/// hlog tag of a receiver's own receive cost: from its wake-up to the sample in hand.
pub const TAG_RECEIVE: &str = "receive";

/// A cumulative histogram and the current interval's: one measured quantity, as rt-core's
/// loop and stim-driver both record, report and log them.
#[derive(Debug, Clone, Default)]
pub struct Quantity {
    total: LatencyHistogram,
    interval: LatencyHistogram,
}

impl Quantity {
    /// Records one measurement, ns.
    pub fn record(&mut self, ns: u64) {
        self.total.record(ns);
        self.interval.record(ns);
    }

    /// Everything recorded since start.
    pub fn total(&self) -> &LatencyHistogram {
        &self.total
    }

    /// The summary of everything recorded since start.
    pub fn summary(&self) -> LatencySummary {
        self.total.summary()
    }

    /// Writes the current interval under `tag` and starts a new one.
    pub fn write_interval(
        &mut self,
        log: &mut HlogWriter,
        tag: &str,
        start: Duration,
        duration: Duration,
    ) -> Result<(), HlogError> {
        log.write(&self.interval, tag, start, duration)?;
        self.interval.reset();
        Ok(())
    }
}

/// A process's histograms written together as one `.hlog` interval: every process writes
/// its intervals the same way and only names its quantities.
pub trait IntervalQuantities {
    /// Each quantity with its hlog tag, in the order they are written.
    fn quantities(&mut self) -> impl IntoIterator<Item = (&'static str, &mut Quantity)>;

    /// Writes the current interval of every quantity and starts new ones.
    fn write_interval(
        &mut self,
        log: &mut HlogWriter,
        start: Duration,
        duration: Duration,
    ) -> Result<(), HlogError> {
        for (tag, q) in self.quantities() {
            q.write_interval(log, tag, start, duration)?;
        }
        Ok(())
    }
}

/// The telemetry thread's state: cumulative and per-interval histograms.
#[derive(Debug, Clone, Default)]
pub struct TimingAggregator {
    wake: Quantity,
    input: Quantity,
    compute: Quantity,
    publish: Quantity,
}

impl TimingAggregator {
    /// Empty histograms (allocated here, once).
    pub fn new() -> Self {
        Self::default()
    }

    /// Records one tick.
    pub fn record(&mut self, t: &TickTiming) {
        self.wake.record(t.lateness_ns);
        self.input.record(t.input_ns);
        self.compute.record(t.compute_ns);
        self.publish.record(t.publish_ns);
    }

    /// Drains every queued record of `channel`; returns how many.
    pub fn drain(&mut self, channel: &TelemetryChannel) -> usize {
        let mut n = 0;
        while let Some(t) = channel.pop() {
            self.record(&t);
            n += 1;
        }
        n
    }

    /// Cumulative wake-up lateness.
    pub fn wake(&self) -> &LatencyHistogram {
        self.wake.total()
    }

    /// Cumulative input time.
    pub fn input(&self) -> &LatencyHistogram {
        self.input.total()
    }

    /// Cumulative compute time.
    pub fn compute(&self) -> &LatencyHistogram {
        self.compute.total()
    }

    /// Cumulative publish time.
    pub fn publish(&self) -> &LatencyHistogram {
        self.publish.total()
    }

    /// A cumulative [`TimingReport`] (without `ipc`, which receivers measure).
    pub fn report(
        &self,
        seq: u64,
        t_ns: u64,
        source: TimingSource,
        counters: &CounterSnapshot,
        queue_overflows: u64,
        flags: u8,
    ) -> TimingReport {
        TimingReport {
            seq,
            t_ns,
            ticks: counters.ticks,
            misses: counters.misses,
            overruns: counters.overruns,
            queue_overflows,
            hot_path_allocations: counters.hot_path_allocations,
            rejected_inputs: counters.rejected_inputs,
            wake: self.wake.summary(),
            input: self.input.summary(),
            compute: self.compute.summary(),
            publish: self.publish.summary(),
            ipc: LatencySummary::default(),
            source: source as u8,
            flags,
            prescription: [0; 6],
        }
    }
}

/// Tags [`TAG_WAKE`], [`TAG_INPUT`], [`TAG_COMPUTE`], [`TAG_PUBLISH`].
impl IntervalQuantities for TimingAggregator {
    fn quantities(&mut self) -> impl IntoIterator<Item = (&'static str, &mut Quantity)> {
        [
            (TAG_WAKE, &mut self.wake),
            (TAG_INPUT, &mut self.input),
            (TAG_COMPUTE, &mut self.compute),
            (TAG_PUBLISH, &mut self.publish),
        ]
    }
}
