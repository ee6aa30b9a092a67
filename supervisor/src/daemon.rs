//! `supervisor run`: the daemon's loop. It wires the pure parts ([`crate::core`],
//! [`crate::health`]) to iceoryx2, the control socket and the recorder.
//!
//! Every iteration (at most every [`POLL_MS`] ms, and at each profile edge): check its own
//! stall (passes further apart than `[health] self_stall_ms` while armed are a fault); drain
//! StimTick, ForceSample, DriverStatus and TimingReport; list the iceoryx2 nodes when due;
//! check health (a fault stops stimulation at once); serve operator requests; send driver
//! orders; publish the Reference when its period is up or it changed; record; flush.
//! Arming starts a recording run; stop or fault ends it (fsync).

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;

use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;
use rt_core::msg::service::{ServiceError, open_pubsub};
use rt_core::msg::{
    Contract, DriverCommand, DriverCommandKind, DriverStatus, ForceSample, Reference, StimTick,
    TimingReport,
};
use rt_core::msg::{PortError, port};
use rt_core::rt::clock::{monotonic_ns, sleep_until};

use crate::config::SupervisorConfig;
use crate::control::{ControlServer, Pending};
use crate::core::{ArmState, DriverOrder, Fault, FaultCause, SupervisorCore};
use crate::health::{HealthMonitor, NodeObservation, ServiceOwners, Severity, proc_state};
use crate::pass;
use crate::protocol::{Command, Response, Status};
use crate::recording::{RecorderSettings, utc_stamp};
use crate::recording_thread::{Item, RecorderThread};

/// Longest sleep of the loop, ms (StimTick buffers hold about 1 s).
pub const POLL_MS: u64 = 5;

/// A daemon failure (start-up or a broken iceoryx2 port).
#[derive(Debug, thiserror::Error)]
pub enum DaemonError {
    /// The iceoryx2 node.
    #[error("iceoryx2: {0}")]
    Node(#[from] rt_core::rt::node::RunError),
    /// An iceoryx2 service.
    #[error("iceoryx2: {0}")]
    Service(#[from] ServiceError),
    /// An iceoryx2 port.
    #[error("iceoryx2: {0}")]
    Port(#[from] PortError),
    /// Control socket.
    #[error("control socket: {0}")]
    Control(#[from] crate::control::ControlError),
}

/// How the daemon ended.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// Recording directories written.
    pub recordings: Vec<PathBuf>,
    /// The fault in force at exit, if any.
    pub fault: Option<Fault>,
}

fn node_id(id: &iceoryx2::identifiers::UniqueNodeId) -> u128 {
    u128::from_str_radix(&id.to_string(), 16).unwrap_or(0)
}

/// Lists the iceoryx2 nodes of this machine (name, pid, id, dead).
pub fn list_nodes() -> Vec<NodeObservation> {
    let config = iceoryx2::config::Config::default();
    let mut out = Vec::new();
    let _ = Node::<ipc::Service>::list(&config, |state| {
        let (view_dead, details, id) = match &state {
            NodeState::Alive(v) => (false, v.details().clone(), node_id(v.id())),
            NodeState::Dead(v) => (true, v.details().clone(), node_id(v.id())),
            _ => return CallbackProgression::Continue,
        };
        if let Some(d) = details {
            out.push(NodeObservation {
                name: d.name().as_str().to_string(),
                pid: d.process_id().value() as u32,
                id,
                dead: view_dead,
            });
        }
        CallbackProgression::Continue
    });
    out
}

/// The node ids of a service's publishers.
fn publisher_nodes<T: Contract>(
    service: &iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, T, ()>,
) -> Vec<u128> {
    use iceoryx2::service::port_factory::PortFactory as _;
    let mut ids = Vec::new();
    service.dynamic_config().list_publishers(|p| {
        ids.push(node_id(&p.node_id));
        CallbackProgression::Continue
    });
    ids
}

struct Run {
    recorder: Option<RecorderThread>,
    /// Runs ended and being finished by their writer threads.
    closing: Vec<RecorderThread>,
    dirs: Vec<PathBuf>,
    index: u32,
}

/// Runs the daemon until `stop` is set. `on_ready` is called once the ports and the
/// socket exist.
pub fn run(
    cfg: &SupervisorConfig,
    stop: &AtomicBool,
    on_ready: impl FnOnce(&std::path::Path),
) -> Result<Outcome, DaemonError> {
    let node = rt_core::rt::runner::create_node(&cfg.ipc.node_name)?;
    let prefix = cfg.ipc.prefix.as_str();
    let ref_pub = port::publisher::<Reference>(&node, prefix)?;
    let cmd_pub = port::publisher::<DriverCommand>(&node, prefix)?;
    let mut cmd_seq = 0u64;
    let ticks = port::subscriber::<StimTick>(&node, prefix)?;
    let forces = port::subscriber::<ForceSample>(&node, prefix)?;
    let statuses = port::subscriber::<DriverStatus>(&node, prefix)?;
    // The services whose publishers are this stack's rt-core and stim-driver.
    let tick_service = open_pubsub::<StimTick>(&node, prefix)?;
    let status_service = open_pubsub::<DriverStatus>(&node, prefix)?;
    let timings = port::subscriber::<TimingReport>(&node, prefix)?;

    let (tx, rx) = mpsc::channel::<Pending>();
    let server = ControlServer::start(&cfg.control, tx)?;
    on_ready(server.path());
    let _ = sd_notify::notify(&[sd_notify::NotifyState::Ready]);
    let watchdog = sd_notify::watchdog_enabled();

    let limits = cfg.reference.limits();
    let mut core = SupervisorCore::new(limits, cfg.outer_loop, cfg.contraction);
    let mut health = HealthMonitor::new(cfg.health.clone());
    let start_ns = monotonic_ns();
    let period_ns = cfg.reference.period_ms * 1_000_000;
    let scan_ns = cfg.health.node_scan_period_ms * 1_000_000;
    let mut next_publish = start_ns;
    let mut next_scan = start_ns;
    let mut next_watchdog = start_ns;
    let mut last_state = core.state().clone();
    let mut run = Run {
        recorder: None,
        closing: Vec::new(),
        dirs: Vec::new(),
        index: 0,
    };
    let settings = RecorderSettings {
        flush_period_ns: cfg.recording.flush_period_ms * 1_000_000,
        max_record_ticks: cfg.recording.max_record_ms as usize,
        scale_n: cfg.recording.scale_n,
        offset_n: cfg.recording.offset_n,
        source: cfg.recording.source.clone(),
        protocol: serde_json::Value::Null,
    };

    let mut last_pass = monotonic_ns();
    let mut statuses_in: Vec<DriverStatus> = Vec::with_capacity(64);
    loop {
        let now = monotonic_ns();
        let stopping = stop.load(Ordering::Relaxed);

        // 0. Our own stall (SIGSTOP, starvation): while armed, a fault before anything
        //    else, so the references that follow are the stop reference.
        let gap = now.saturating_sub(last_pass);
        last_pass = now;
        if *core.state() == ArmState::Armed
            && let Some(reason) = cfg.health.self_stall(gap)
        {
            core.fault(Fault::new(FaultCause::SelfStall, reason));
        }

        // 1. Inputs. The DriverStatuses are taken off their queue first and judged after
        //    the StimTicks: every tick rt-core published before a status is then known
        //    when the status is, so a driver watchdog trip is blamed by the tick stream
        //    around it (health.rs, TickGaps), however late this pass runs.
        statuses_in.clear();
        while let Ok(Some(s)) = statuses.receive() {
            statuses_in.push(*s.payload());
        }
        while let Ok(Some(s)) = ticks.receive() {
            let t = *s.payload();
            drop(s);
            health.on_stim_tick(&t, now);
            if t.validate().is_ok() {
                if t.fires() {
                    core.on_pulse(t.t_ns);
                }
                record(&mut run, &mut core, Item::Tick(t, now));
            }
        }
        while let Ok(Some(s)) = forces.receive() {
            let f = *s.payload();
            drop(s);
            health.on_force_sample(&f, now);
            if f.validate().is_ok() {
                core.on_force(f.t_ns, f.force);
                record(&mut run, &mut core, Item::Force(f, now));
            }
        }
        for st in statuses_in.drain(..) {
            health.on_driver_status(&st, now);
            if st.validate().is_ok() {
                core.on_driver_status(&st);
            }
            record(&mut run, &mut core, Item::Status(st));
        }
        while let Ok(Some(s)) = timings.receive() {
            let tr = *s.payload();
            drop(s);
            health.on_timing(&tr);
            record(&mut run, &mut core, Item::Timing(tr));
        }

        // 2. Operator requests, served before the health check so that a fault found
        //    below reaches the driver (SafeStop) and rt-core (the zero Reference) in this
        //    same pass, before any status shows it.
        while let Ok(p) = rx.try_recv() {
            let response = serve(&mut core, &mut health, &run, &p, now, start_ns);
            let _ = p.reply.try_send(response);
        }
        if stopping && *core.state() == ArmState::Armed {
            let _ = core.command(&Command::Stop, now, Ok(()));
        }

        // 3. Health.
        if now >= next_scan {
            next_scan = now + scan_ns;
            let owners = ServiceOwners {
                stim_tick: publisher_nodes(&tick_service),
                driver_status: publisher_nodes(&status_service),
            };
            let listed = list_nodes();
            health.on_nodes(&listed, &owners);
        }
        for e in pass::check_health(&mut core, &mut health, now, &proc_state) {
            match e.severity {
                Severity::Fault => tracing::error!("{}", e.message),
                Severity::Warning => tracing::warn!("{}", e.message),
            }
        }

        // 4. Driver orders.
        for order in core.take_orders() {
            cmd_seq += 1;
            let kind = match order {
                DriverOrder::Arm => DriverCommandKind::Arm,
                DriverOrder::Disarm => DriverCommandKind::Disarm,
                DriverOrder::SafeStop => DriverCommandKind::SafeStop,
            };
            if let Err(e) = cmd_pub.send_copy(DriverCommand::new(cmd_seq, now, kind)) {
                core.note(format!("driver order {order:?} not sent: {e}"));
                tracing::error!("driver order {order:?} not sent: {e}");
            }
        }

        // 5. Recording life cycle.
        let state = core.state().clone();
        if state != last_state {
            if state == ArmState::Armed && cfg.recording.enabled && run.recorder.is_none() {
                run.index += 1;
                let name = format!("run-{}-{}-{}", utc_stamp(), std::process::id(), run.index);
                let started =
                    RecorderThread::start(&cfg.recording.dir, &name, settings.clone(), now);
                match started {
                    Ok(r) => {
                        core.note(format!("recording to {}", r.dir().display()));
                        run.dirs.push(r.dir().to_path_buf());
                        run.recorder = Some(r);
                    }
                    Err(e) => {
                        core.fault(Fault::new(
                            FaultCause::Recording,
                            format!("{e}; no recording means no evidence"),
                        ));
                    }
                }
            }
            last_state = core.state().clone();
        }
        for b in core.take_beat_starts() {
            let kind = format!("beat {} ({} beats/min)", b.index, b.bpm);
            record(&mut run, &mut core, Item::Boundary(b.start_ns, kind));
        }
        for b in core.take_beats() {
            record(&mut run, &mut core, Item::Beat(b));
        }

        // 6. Reference.
        let edge = core.next_change_ns(now).is_some_and(|t| t <= now);
        let changed = core
            .last_reference()
            .is_none_or(|r| r.is_stop() != (*core.state() != ArmState::Armed));
        if now >= next_publish || edge || changed {
            let r = core.reference(now);
            match ref_pub.send_copy(r) {
                Ok(_) => {}
                Err(e) => tracing::warn!("Reference not published: {e:?}"),
            }
            record(&mut run, &mut core, Item::Reference(r));
            next_publish = now + period_ns;
        }

        // 7. Events to the recording, flush, end of a run.
        let events = core.take_new_events();
        for e in &events {
            tracing::info!("{e}");
        }
        for e in &events {
            record(&mut run, &mut core, Item::Event(now, e.clone()));
        }
        record(&mut run, &mut core, Item::Flush(now));
        if let Some(e) = run.recorder.as_ref().and_then(RecorderThread::failure) {
            run.recorder = None;
            core.fault(Fault::new(
                FaultCause::Recording,
                format!("{e}; no recording means no evidence"),
            ));
        }
        if *core.state() != ArmState::Armed
            && let Some(mut rec) = run.recorder.take()
        {
            rec.close(now);
            run.closing.push(rec);
        }
        // Runs whose writer has finished (flushed, fsynced): say so.
        while let Some(i) = run.closing.iter().position(RecorderThread::is_closed) {
            let rec = run.closing.swap_remove(i);
            note_closed(&mut core, rec);
        }

        if let Some(wd) = watchdog
            && now >= next_watchdog
        {
            let _ = sd_notify::notify(&[sd_notify::NotifyState::Watchdog]);
            next_watchdog = now + wd.as_nanos() as u64 / 3;
        }

        if stopping {
            // Leave the reference stopped for rt-core and the driver disarmed, then go.
            let t = monotonic_ns();
            let r = core.reference(t);
            let _ = ref_pub.send_copy(r);
            cmd_seq += 1;
            let _ = cmd_pub.send_copy(DriverCommand::new(cmd_seq, t, DriverCommandKind::Disarm));
            break;
        }

        // 8. Sleep to the next event.
        let mut wake = (now + POLL_MS * 1_000_000).min(next_publish);
        if let Some(t) = core.next_change_ns(now) {
            wake = wake.min(t.max(now));
        }
        sleep_until(wake);
    }
    let fault = match core.state() {
        ArmState::Fault(f) => Some(f.clone()),
        _ => None,
    };
    // Wait for the writers: every run on disk, fsynced, before the process exits.
    if let Some(mut rec) = run.recorder.take() {
        rec.close(monotonic_ns());
        run.closing.push(rec);
    }
    for rec in run.closing.drain(..) {
        note_closed(&mut core, rec);
    }
    for e in core.take_new_events() {
        tracing::info!("{e}");
    }
    drop(server);
    Ok(Outcome {
        recordings: run.dirs,
        fault,
    })
}

/// Waits for a closing run's writer and notes the outcome.
fn note_closed(core: &mut SupervisorCore, rec: RecorderThread) {
    match rec.join() {
        Ok(s) => core.note(format!(
            "recording closed: {} ({} records, {} ticks)",
            s.dir.display(),
            s.records,
            s.ticks
        )),
        Err(e) => core.note(format!("recording could not be closed cleanly: {e}")),
    }
}

/// Queues `item` for the recording of the current run; a failure (the writer failed or
/// fell behind) ends the recording and stops stimulation.
fn record(run: &mut Run, core: &mut SupervisorCore, item: Item) {
    if let Some(r) = &run.recorder
        && let Err(e) = r.send(item)
    {
        run.recorder = None;
        core.fault(Fault::new(
            FaultCause::Recording,
            format!("{e}; no recording means no evidence"),
        ));
    }
}

fn serve(
    core: &mut SupervisorCore,
    health: &mut HealthMonitor,
    run: &Run,
    p: &Pending,
    now: u64,
    start_ns: u64,
) -> Response {
    let id = p.request.id;
    let result = pass::serve_command(core, health, &p.request.command, now, &proc_state);
    let status = status(core, health, run, now, start_ns);
    match result {
        Ok(m) => Response::ok(id, m, Some(status)),
        Err(e) => {
            let mut r = Response::error(id, e.to_string());
            r.status = Some(status);
            r
        }
    }
}

// The daemon's state for `status`.
fn status(
    core: &SupervisorCore,
    health: &HealthMonitor,
    run: &Run,
    now: u64,
    start_ns: u64,
) -> Status {
    let last = core.last_reference();
    let (driver_state, stimulator_state) = health.device_states();
    Status {
        state: core.state().name().into(),
        fault: match core.state() {
            ArmState::Fault(f) => Some(f.message.clone()),
            _ => None,
        },
        fault_cause: match core.state() {
            ArmState::Fault(f) => Some(f.cause),
            _ => None,
        },
        uptime_s: (now - start_ns) as f64 * 1e-9,
        reference: last.map_or(0.0, |r| r.force),
        reference_rate_per_s: last.map_or(0.0, |r| r.max_rate_per_s),
        reference_stop: last.is_none_or(|r| r.is_stop()),
        references_published: last.map_or(0, |r| r.seq),
        profile: core.profile().map(|p| p.spec().describe()),
        beat: core.profile().and_then(|p| p.beat()).map(|b| b.index),
        outer_loop: core.outer_loop().enabled(),
        outer_loop_correction: core.outer_loop().correction(),
        last_contraction: core.last_contraction(),
        processes: health.statuses(now),
        driver_state,
        stimulator_state,
        recording: run
            .recorder
            .as_ref()
            .map(|r| r.dir().display().to_string())
            .or_else(|| run.dirs.last().map(|d| d.display().to_string())),
        events: core.events().cloned().collect(),
    }
}
