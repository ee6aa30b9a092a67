//! The forward thread: the real-time loop around [`ForwardPath`].
//!
//! It enters real time ([`enter_realtime`] with `[rt]`), opens its iceoryx2 ports on the
//! node `stim-driver` (the StimTick subscriber, the DriverCommand subscriber and a listener
//! on the StimTick event), brings the stimulator up ([`ForwardPath::start`]) and then loops:
//!
//! 1. wait for a StimTick notification, at most until [`ForwardPath::next_deadline`] (the
//!    heartbeat, the watchdogs, at most one tick period);
//! 2. take the publisher liveness the report thread found, the bus events the receive
//!    thread queued, the commands, then every StimTick, each with the time it was taken;
//! 3. run the timers ([`ForwardPath::poll`]), publish the counters, report the wake-up.
//!
//! Nothing in the loop allocates on the heap, locks a contended lock, logs or blocks beyond
//! the bounded write retry: events go to the report thread through [`Shared::events`]. On
//! stop it sends NMT stop and a "stopped" heartbeat ([`ForwardPath::shutdown`]).

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Duration;

use crossbeam::queue::ArrayQueue;
use fes_rt::msg::port;
use fes_rt::msg::{Contract, DriverCommand, StimTick};
use fes_rt::rt::alloc;
use fes_rt::rt::clock::monotonic_ns;
use fes_rt::rt::node::{RunError, create_node};
use fes_rt::rt::realtime::{RtStatus, enter_realtime};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::{FileDescriptorBased, ipc};

use crate::bus::BusCounters;
use crate::config::DriverConfig;
use crate::event::{BusEvent, DriverEvent, EventSink, QueueSink, SharedStatus};
use crate::forward::ForwardPath;
use crate::intrusion::{LoggingTx, SentLog};
use crate::serial_rx::SerialLink;
use crate::tx::CanTx;

/// The iceoryx2 node name of the forward thread (the supervisor watches it).
pub const NODE_NAME: &str = "stim-driver";
/// Capacity of the queue of bus events (receive thread → forward thread).
pub const BUS_QUEUE_CAPACITY: usize = 1024;

/// What the driver's threads share (allocated once, before the threads start).
#[derive(Debug)]
pub struct Shared {
    /// The forward thread's counters, and the publisher liveness for it.
    pub status: SharedStatus,
    /// Forward thread → report thread.
    pub events: ArrayQueue<DriverEvent>,
    /// Events dropped because [`Self::events`] was full.
    pub event_overflows: AtomicU64,
    /// Receive thread → forward thread.
    pub bus_events: ArrayQueue<BusEvent>,
    /// The receive thread's counters.
    pub bus: BusCounters,
    /// What the ScienceMode transmit side and receive thread share (unused on CAN).
    pub serial_link: Arc<SerialLink>,
    /// The frames the forward thread wrote, for the receive thread to tell their echoes
    /// from foreign frames ([`crate::intrusion`]).
    pub sent_log: SentLog,
    /// Heap allocations of the forward loop since it started (0 is the requirement).
    pub hot_path_allocations: AtomicU64,
    /// Set when the forward thread has ended (the other threads then finish).
    pub forward_ended: AtomicBool,
    /// Set by a thread that failed: every loop stops.
    pub failed: AtomicBool,
    /// The forward thread's real-time status line, once known.
    pub rt_status: OnceLock<RtStatus>,
    /// The prescription this driver enforces, as its TimingReports carry it
    /// (`TimingReport::prescription`; set once it is read, zeros before).
    pub prescription: OnceLock<[u8; 6]>,
}

impl Shared {
    /// Queues sized by `config`.
    pub fn new(config: &DriverConfig) -> Self {
        Self {
            status: SharedStatus::default(),
            events: ArrayQueue::new(config.telemetry.queue_capacity),
            event_overflows: AtomicU64::new(0),
            bus_events: ArrayQueue::new(BUS_QUEUE_CAPACITY),
            bus: BusCounters::default(),
            serial_link: Arc::new(SerialLink::new()),
            sent_log: SentLog::new(),
            hot_path_allocations: AtomicU64::new(0),
            forward_ended: AtomicBool::new(false),
            failed: AtomicBool::new(false),
            rt_status: OnceLock::new(),
            prescription: OnceLock::new(),
        }
    }

    /// True when the loops must end: `stop` (a signal) or a failed thread.
    pub fn stopping(&self, stop: &AtomicBool) -> bool {
        stop.load(Ordering::Relaxed) || self.failed.load(Ordering::Relaxed)
    }
}

/// How the forward thread ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ForwardOutcome {
    /// Its real-time status.
    pub rt: RtStatus,
    /// The NMT stop of the shutdown was written.
    pub stop_sent: bool,
    /// Heap allocations in the loop (0 expected; `None` without the counting allocator).
    pub hot_path_allocations: Option<u64>,
}

/// Waits until the StimTick listener's socket is readable or `timeout` passes: `Ok(true)`
/// when a notification is waiting. `ppoll` times out on a high-resolution timer (an RT
/// thread has no timer slack), where iceoryx2's own `Listener::timed_wait` uses the
/// socket's `SO_RCVTIMEO`, which the kernel counts in jiffies: a 1 ms wait lasted 4-8 ms at
/// HZ=250 (found by the forward-path histograms: timed wake-ups 5-8 ms late, and the
/// 3-tick StimTick watchdog tripping 5-12 ms after the last tick).
fn wait_for_tick(fd: i32, timeout: Duration) -> Result<bool, ()> {
    let mut pfd = libc::pollfd {
        fd,
        events: libc::POLLIN,
        revents: 0,
    };
    let ts = libc::timespec {
        tv_sec: timeout.as_secs() as libc::time_t,
        tv_nsec: timeout.subsec_nanos() as libc::c_long,
    };
    // SAFETY: `pfd` and `ts` are valid for the call; one descriptor, no signal mask.
    let rc = unsafe { libc::ppoll(&mut pfd, 1, &ts, std::ptr::null()) };
    match rc {
        0 => Ok(false),
        n if n > 0 => Ok(pfd.revents & libc::POLLIN != 0),
        _ if std::io::Error::last_os_error().kind() == std::io::ErrorKind::Interrupted => Ok(false),
        _ => Err(()),
    }
}

/// Waits for rt-core's tick notification or the forward path's `deadline` (from `now`):
/// the wake-up time and whether a notification woke it. A failed wait sleeps to the
/// deadline instead of spinning.
fn wait_for_tick_or_deadline(
    listener: &Listener<ipc::Service>,
    listener_fd: i32,
    now: u64,
    deadline: u64,
) -> (u64, bool) {
    let mut notified = false;
    let waited = wait_for_tick(
        listener_fd,
        Duration::from_nanos(deadline.saturating_sub(now).max(1_000)),
    )
    .and_then(|ready| {
        if ready {
            listener
                .try_wait(|_| notified = true)
                .map_err(|_| ())
                .map(|_| ())
        } else {
            Ok(())
        }
    });
    let wake_ns = monotonic_ns();
    if waited.is_err() {
        fes_rt::rt::clock::sleep_until(deadline);
    }
    (wake_ns, notified)
}

/// Hands the forward path what the supervisor ordered and what rt-core decided since the
/// last wake-up, each at most its subscriber buffer's worth (a flood cannot hold the loop).
fn receive_orders<T: CanTx>(
    commands: &Subscriber<ipc::Service, DriverCommand, ()>,
    ticks: &Subscriber<ipc::Service, StimTick, ()>,
    path: &mut ForwardPath<T>,
    sink: &mut QueueSink<'_>,
) {
    let max_ticks = StimTick::QOS.subscriber_buffer;
    let max_commands = DriverCommand::QOS.subscriber_buffer;
    for _ in 0..max_commands {
        match commands.receive() {
            Ok(Some(sample)) => {
                let command = *sample.payload();
                drop(sample);
                path.on_command(&command, monotonic_ns(), sink);
            }
            Ok(None) | Err(_) => break,
        }
    }
    for _ in 0..max_ticks {
        match ticks.receive() {
            Ok(Some(sample)) => {
                let tick = *sample.payload();
                drop(sample);
                let received = monotonic_ns();
                path.on_tick(&tick, received, sink);
                sink.emit(DriverEvent::Tick {
                    seq: tick.seq,
                    ipc_ns: received.saturating_sub(tick.t_publish_ns),
                    decide_ns: monotonic_ns().saturating_sub(received),
                });
            }
            Ok(None) | Err(_) => break,
        }
    }
}

/// Runs the forward thread on the calling thread until `stop` is set or another thread
/// fails (see the module documentation). `on_ready` is called once real time is entered
/// and the ports exist, before the first frame is sent.
pub fn run_forward<T: CanTx>(
    config: &DriverConfig,
    tx: T,
    shared: &Shared,
    stop: &AtomicBool,
    on_ready: impl FnOnce(&RtStatus),
) -> Result<ForwardOutcome, RunError> {
    let rt = enter_realtime(&config.rt)?;
    let settings = config
        .forward_settings()
        .map_err(|e| RunError::Config(Box::new(e)))?;
    let prefix = config.ipc.prefix.as_str();
    let node = create_node(NODE_NAME)?;
    let ticks = port::subscriber::<StimTick>(&node, prefix)?;
    let commands = port::subscriber::<DriverCommand>(&node, prefix)?;
    let listener = port::stim_tick_listener(&node, prefix)?;

    // SAFETY: the descriptor stays owned by `listener`, which outlives every use below; it
    // is only polled, never stored elsewhere or closed here.
    let listener_fd = unsafe { listener.file_descriptor().native_handle() };
    let mut path = ForwardPath::new(settings, LoggingTx::new(tx, &shared.sent_log));
    let mut sink = QueueSink::new(&shared.events, &shared.event_overflows);
    let _ = shared.rt_status.set(rt.clone());
    on_ready(&rt);
    let allocations_counted = alloc::counting_allocator_installed();

    // ---- hot path from here on: no heap allocation, log or blocking call ----
    alloc::trace_first_heap_allocation(config.telemetry.trace_allocations);
    alloc::track_current_thread(true);
    let baseline = alloc::current_thread_allocations();
    path.start(monotonic_ns(), &mut sink);
    shared.status.store(path.counters());
    let mut bus_events_lost = 0u64;
    while !shared.stopping(stop) {
        let now = monotonic_ns();
        let deadline = path.next_deadline(now);
        let (wake_ns, notified) = wait_for_tick_or_deadline(&listener, listener_fd, now, deadline);
        if shared.stopping(stop) {
            break;
        }
        path.on_liveness(shared.status.liveness(), wake_ns, &mut sink);
        path.on_supervisor_liveness(shared.status.supervisor_liveness(), wake_ns, &mut sink);
        while let Some(event) = shared.bus_events.pop() {
            path.on_bus(event, monotonic_ns(), &mut sink);
        }
        let lost = shared.bus.events_lost.load(Ordering::Relaxed);
        if lost != bus_events_lost {
            bus_events_lost = lost;
            path.on_bus(BusEvent::EventsLost, monotonic_ns(), &mut sink);
        }
        receive_orders(&commands, &ticks, &mut path, &mut sink);
        let polled = monotonic_ns();
        path.poll(polled, &mut sink);
        path.count_wakeup();
        shared.status.store(path.counters());
        sink.emit(DriverEvent::Wake {
            timer_lateness_ns: (!notified).then(|| wake_ns.saturating_sub(deadline)),
            input_ns: polled.saturating_sub(wake_ns),
        });
        if allocations_counted {
            let a = alloc::current_thread_allocations();
            shared
                .hot_path_allocations
                .store(a.allocations - baseline.allocations, Ordering::Relaxed);
        }
    }
    // ---- end of the hot path ----
    path.shutdown(monotonic_ns(), &mut sink);
    shared.status.store(path.counters());
    alloc::track_current_thread(false);
    let stop_sent = !path.stop_pending();
    Ok(ForwardOutcome {
        rt,
        stop_sent,
        hot_path_allocations: allocations_counted
            .then(|| shared.hot_path_allocations.load(Ordering::Relaxed)),
    })
}
