//! `supervisor run`: the daemon's loop. It wires the pure parts ([`crate::core`],
//! [`crate::health`]) to iceoryx2, the control socket and the recorder.
//!
//! Every iteration (at most every [`POLL_MS`] ms, and at each profile edge), one method per
//! phase, in this order: check its own stall (passes further apart than `[health]
//! self_stall_ms` while armed are a fault); drain StimTick, ForceSample, DriverStatus and
//! TimingReport; serve operator requests; list the iceoryx2 nodes when due and check health
//! (a fault stops stimulation at once); send driver orders; publish the Reference when its
//! period is up or it changed; record; flush. Arming starts a recording run; stop or fault
//! ends it (fsync).

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;

use fes_rt::msg::service::ServiceError;
use fes_rt::msg::{
    Contract, DriverCommand, DriverStatus, ForceSample, PreviewEdge, PulseFate, PulseOutcome,
    Reference, ReferencePreview, StimTick, TimingReport,
};
use fes_rt::msg::{PortError, port};
use fes_rt::rt::clock::{monotonic_ns, sleep_until};
use fes_rt::rt::liveness::{LivenessMonitor, list_nodes};
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;

use crate::command_link::{self, CommandLink, LinkEvent, LinkSettings, OrderRecord};
use crate::config::{RecordingConfig, SupervisorConfig};
use crate::control::{ControlServer, Pending};
use crate::core::{ArmState, DriverOrder, Fault, FaultCause, SupervisorCore};
use crate::health::{HealthMonitor, ServiceOwners, Severity, proc_state};
use crate::pass;
use crate::protocol::{Command, DriverOrderStatus, Response, Status};
use crate::recording::{RecorderSettings, utc_stamp};
use crate::recording_thread::{Item, RecorderThread};

/// Longest sleep of the loop, ms (StimTick buffers hold about 1 s).
pub const POLL_MS: u64 = 5;

/// A daemon failure (start-up or a broken iceoryx2 port).
#[derive(Debug, thiserror::Error)]
pub enum DaemonError {
    /// The iceoryx2 node.
    #[error("iceoryx2: {0}")]
    Node(#[from] fes_rt::rt::node::RunError),
    /// An iceoryx2 service.
    #[error("iceoryx2: {0}")]
    Service(#[from] ServiceError),
    /// An iceoryx2 port.
    #[error("iceoryx2: {0}")]
    Port(#[from] PortError),
    /// Control socket.
    #[error("control socket: {0}")]
    Control(#[from] crate::control::ControlError),
    /// Recording is on and the prescription, whose checksum every recording carries,
    /// cannot be read.
    #[error("recording needs the prescription's checksum ([recording] prescription): {0}")]
    Prescription(#[from] fes_prescription::PrescriptionError),
}

/// How the daemon ended.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// Recording directories written.
    pub recordings: Vec<PathBuf>,
    /// The fault in force at exit, if any.
    pub fault: Option<Fault>,
}

/// The iceoryx2 ports of the daemon, opened under the configured prefix.
struct Ports {
    /// Reference to rt-core.
    reference: Publisher<ipc::Service, Reference, ()>,
    /// The profile's scheduled setpoints, published beside each Reference.
    preview: Publisher<ipc::Service, ReferencePreview, ()>,
    /// Orders to stim-driver.
    command: Publisher<ipc::Service, DriverCommand, ()>,
    ticks: Subscriber<ipc::Service, StimTick, ()>,
    forces: Subscriber<ipc::Service, ForceSample, ()>,
    statuses: Subscriber<ipc::Service, DriverStatus, ()>,
    /// The StimTick service's publishers: this stack's rt-core.
    tick_publishers: LivenessMonitor<StimTick>,
    /// The DriverStatus service's publishers: this stack's stim-driver.
    status_publishers: LivenessMonitor<DriverStatus>,
    timings: Subscriber<ipc::Service, TimingReport, ()>,
    /// What the driver did with each pulse decision (for the recording).
    outcomes: Subscriber<ipc::Service, PulseOutcome, ()>,
}

impl Ports {
    /// Opens every port on `node` under `prefix`.
    fn open(node: &Node<ipc::Service>, prefix: &str) -> Result<Self, DaemonError> {
        Ok(Self {
            reference: port::publisher::<Reference>(node, prefix)?,
            preview: port::publisher::<ReferencePreview>(node, prefix)?,
            command: port::publisher::<DriverCommand>(node, prefix)?,
            ticks: port::subscriber::<StimTick>(node, prefix)?,
            forces: port::subscriber::<ForceSample>(node, prefix)?,
            statuses: port::subscriber::<DriverStatus>(node, prefix)?,
            tick_publishers: LivenessMonitor::new(node, prefix)?,
            status_publishers: LivenessMonitor::new(node, prefix)?,
            timings: port::subscriber::<TimingReport>(node, prefix)?,
            outcomes: port::subscriber::<PulseOutcome>(node, prefix)?,
        })
    }
}

/// The recording runs of the daemon's life.
struct Run {
    recorder: Option<RecorderThread>,
    /// Runs ended and being finished by their writer threads.
    closing: Vec<RecorderThread>,
    dirs: Vec<PathBuf>,
    index: u32,
}

impl Run {
    /// Queues `item` for the recording of the current run; a failure (the writer failed or
    /// fell behind) ends the recording and stops stimulation.
    fn record(&mut self, core: &mut SupervisorCore, item: Item) {
        if let Some(r) = &self.recorder
            && let Err(e) = r.send(item)
        {
            self.recorder = None;
            core.fault(recording_fault(&e));
        }
    }
}

/// The fault that a failed recording raises: no recording means no evidence.
fn recording_fault(e: &dyn std::fmt::Display) -> Fault {
    Fault::new(
        FaultCause::Recording,
        format!("{e}; no recording means no evidence"),
    )
}

/// The daemon between two passes of its loop: its ports and control socket, the pure
/// parts (core, health), the recording runs, and when what is next due.
struct Daemon<'a> {
    cfg: &'a SupervisorConfig,
    ports: Ports,
    /// The iceoryx2 node of the ports (declared after them: dropped after them).
    _node: Node<ipc::Service>,
    /// Operator requests from the control socket's threads.
    requests: mpsc::Receiver<Pending>,
    server: ControlServer,
    core: SupervisorCore,
    health: HealthMonitor,
    run: Run,
    settings: RecorderSettings,
    /// systemd's watchdog period, when it watches us.
    watchdog: Option<std::time::Duration>,
    start_ns: u64,
    period_ns: u64,
    scan_ns: u64,
    next_publish: u64,
    /// `seq` of the last ReferencePreview published.
    preview_seq: u64,
    next_scan: u64,
    next_watchdog: u64,
    /// The arming state at the last pass (a change starts a recording run).
    last_state: ArmState,
    /// When the last pass began (for the self-stall check).
    last_pass: u64,
    /// The orders to the driver and their acknowledgements.
    link: CommandLink,
    /// The DriverStatuses of this pass, taken off their queue before the StimTicks.
    statuses_in: Vec<DriverStatus>,
}

/// Runs the daemon until `stop` is set. `on_ready` is called once the ports and the
/// socket exist.
pub fn run(
    cfg: &SupervisorConfig,
    stop: &AtomicBool,
    on_ready: impl FnOnce(&std::path::Path),
) -> Result<Outcome, DaemonError> {
    let mut daemon = Daemon::open(cfg, on_ready)?;
    loop {
        let now = monotonic_ns();
        let stopping = stop.load(Ordering::Relaxed);
        daemon.pass(now, stopping);
        if stopping {
            daemon.leave();
            break;
        }
        sleep_until(daemon.wake_at(now));
    }
    Ok(daemon.finish())
}

/// The recorder's settings from the `[recording]` section.
fn recorder_settings(cfg: &RecordingConfig) -> RecorderSettings {
    RecorderSettings {
        flush_period_ns: cfg.flush_period_ms * 1_000_000,
        max_record_ticks: cfg.max_record_ms as usize,
        scale_n: cfg.scale_n,
        offset_n: cfg.offset_n,
        source: cfg.source.clone(),
        protocol: serde_json::Value::Null,
        prescription_sha256: None,
    }
}

impl<'a> Daemon<'a> {
    /// Opens the iceoryx2 ports and the control socket, calls `on_ready` with the socket's
    /// path, tells systemd it is ready, and starts disarmed with nothing recorded.
    fn open(
        cfg: &'a SupervisorConfig,
        on_ready: impl FnOnce(&std::path::Path),
    ) -> Result<Self, DaemonError> {
        // Every recording names the prescription it was made under.
        let prescription_sha256 = if cfg.recording.enabled {
            let p = fes_prescription::Prescription::load(&cfg.recording.prescription)?;
            tracing::info!("{}", p.summary());
            Some(p.sha256)
        } else {
            None
        };
        let node = fes_rt::rt::node::create_node(&cfg.ipc.own.node_name)?;
        let ports = Ports::open(&node, cfg.ipc.prefix.as_str())?;
        let (tx, requests) = mpsc::channel::<Pending>();
        let server = ControlServer::start(&cfg.control, tx)?;
        on_ready(server.path());
        let _ = sd_notify::notify(&[sd_notify::NotifyState::Ready]);
        let watchdog = sd_notify::watchdog_enabled();
        let core = SupervisorCore::new(cfg.reference.limits(), cfg.outer_loop, cfg.contraction);
        let mut health = HealthMonitor::new(cfg.health.clone());
        if let Some(sha256) = &prescription_sha256 {
            health.set_prescription(fes_prescription::fingerprint_of(sha256));
        }
        let start_ns = monotonic_ns();
        let last_state = core.state().clone();
        Ok(Self {
            cfg,
            ports,
            _node: node,
            requests,
            server,
            core,
            health,
            run: Run {
                recorder: None,
                closing: Vec::new(),
                dirs: Vec::new(),
                index: 0,
            },
            settings: RecorderSettings {
                prescription_sha256,
                ..recorder_settings(&cfg.recording)
            },
            watchdog,
            start_ns,
            period_ns: cfg.reference.period_ms * 1_000_000,
            scan_ns: cfg.health.node_scan_period_ms * 1_000_000,
            next_publish: start_ns,
            preview_seq: 0,
            next_scan: start_ns,
            next_watchdog: start_ns,
            last_state,
            last_pass: monotonic_ns(),
            link: CommandLink::new(
                start_ns / 1_000,
                LinkSettings {
                    required: cfg.health.watch_stim_driver,
                    ..LinkSettings::default()
                },
            ),
            statuses_in: Vec::with_capacity(64),
        })
    }

    /// One pass of the loop at `now` (`stopping`: the process was asked to stop), in this
    /// order: own stall, inputs, operator requests, health, driver orders, recording life
    /// cycle, Reference, events and recorder, systemd's watchdog.
    fn pass(&mut self, now: u64, stopping: bool) {
        self.check_own_stall(now);
        self.read_inputs(now);
        self.serve_requests(now, stopping);
        self.check_health(now);
        self.send_orders(now);
        self.follow_arming(now);
        self.record_beats();
        self.publish_reference(now);
        self.record_events(now);
        self.follow_recorders(now);
        self.notify_watchdog(now);
    }

    /// Our own stall (SIGSTOP, starvation): while armed, a fault before anything else,
    /// so the references that follow are the stop reference.
    fn check_own_stall(&mut self, now: u64) {
        let gap = now.saturating_sub(self.last_pass);
        self.last_pass = now;
        if *self.core.state() == ArmState::Armed
            && let Some(reason) = self.cfg.health.self_stall(gap)
        {
            self.core.fault(Fault::new(FaultCause::SelfStall, reason));
        }
    }

    /// Inputs, to the health monitor, the core and the recording. The DriverStatuses
    /// are taken off their queue first and judged after the StimTicks: every tick rt-core
    /// published before a status is then known when the status is, so a driver watchdog
    /// trip is blamed by the tick stream around it (health.rs, TickGaps), however late
    /// this pass runs.
    fn read_inputs(&mut self, now: u64) {
        self.statuses_in.clear();
        while let Ok(Some(s)) = self.ports.statuses.receive() {
            self.statuses_in.push(*s.payload());
        }
        self.read_ticks(now);
        self.read_outcomes(now);
        self.read_forces(now);
        self.judge_statuses(now);
        self.read_timings();
    }

    /// The StimTicks received: health, pulses for the contraction estimate, recording.
    fn read_ticks(&mut self, now: u64) {
        while let Ok(Some(s)) = self.ports.ticks.receive() {
            let t = *s.payload();
            drop(s);
            self.health.on_stim_tick(&t, now);
            if t.validate().is_ok() {
                if t.fires() {
                    self.core.on_pulse(t.t_ns);
                }
                self.run.record(&mut self.core, Item::Tick(t, now));
            }
        }
    }

    /// The PulseOutcomes received (valid ones): recording, so that the data set says what
    /// was sent and applied; a pulse dropped as late or not applied is charged to its beat.
    fn read_outcomes(&mut self, now: u64) {
        while let Ok(Some(s)) = self.ports.outcomes.receive() {
            let o = *s.payload();
            drop(s);
            if o.validate().is_ok() {
                if matches!(o.fate(), Ok(PulseFate::Late | PulseFate::NotApplied)) {
                    self.core.on_pulse_not_delivered(o.tick_t_ns);
                }
                self.run.record(&mut self.core, Item::Outcome(o, now));
            }
        }
    }

    /// The ForceSamples received: health, the measured force, recording.
    fn read_forces(&mut self, now: u64) {
        while let Ok(Some(s)) = self.ports.forces.receive() {
            let f = *s.payload();
            drop(s);
            self.health.on_force_sample(&f, now);
            if f.validate().is_ok() {
                self.core.on_force(f.t_ns, f.force);
                self.run.record(&mut self.core, Item::Force(f, now));
            }
        }
    }

    /// The DriverStatuses taken off their queue at the start of [`Self::read_inputs`]:
    /// health, refused pulses, recording.
    fn judge_statuses(&mut self, now: u64) {
        let mut statuses = std::mem::take(&mut self.statuses_in);
        for st in statuses.drain(..) {
            self.health.on_driver_status(&st, now);
            if st.validate().is_ok() {
                self.core.on_driver_status(&st);
                if let Some(e) = self.link.on_status(&st) {
                    self.on_link_event(e);
                }
            }
            self.run.record(&mut self.core, Item::Status(st));
        }
        // The buffer is kept (no allocation per pass).
        self.statuses_in = statuses;
    }

    /// The TimingReports received: health, recording.
    fn read_timings(&mut self) {
        while let Ok(Some(s)) = self.ports.timings.receive() {
            let tr = *s.payload();
            drop(s);
            self.health.on_timing(&tr);
            self.run.record(&mut self.core, Item::Timing(tr));
        }
    }

    /// Operator requests, served before the health check so that a fault found there
    /// reaches the driver (SafeStop) and rt-core (the zero Reference) in this same pass,
    /// before any status shows it. When `stopping`, stimulation is stopped.
    fn serve_requests(&mut self, now: u64, stopping: bool) {
        while let Ok(p) = self.requests.try_recv() {
            let response = self.answer(&p, now);
            let _ = p.reply.try_send(response);
        }
        if stopping && *self.core.state() == ArmState::Armed {
            let _ = self.core.command(&Command::Stop, now, Ok(()));
        }
    }

    /// Serves one request; the response carries the status after it.
    fn answer(&mut self, p: &Pending, now: u64) -> Response {
        let id = p.request.id;
        let result = pass::serve_command(
            &mut self.core,
            &mut self.health,
            &p.request.command,
            now,
            &proc_state,
        );
        // The order the command gave goes out now, so that the status in the answer names
        // it (the operator's `stop` and `arm` then wait for its acknowledgement).
        self.send_orders(now);
        let status = self.status(now);
        match result {
            Ok(m) => Response::ok(id, m, Some(status)),
            Err(e) => {
                let mut r = Response::error(id, e.to_string());
                r.status = Some(status);
                r
            }
        }
    }

    /// Health: the node listing when due, then the check (a fault stops stimulation
    /// at once); what it found goes to the log.
    fn check_health(&mut self, now: u64) {
        if now >= self.next_scan {
            self.next_scan = now + self.scan_ns;
            let owners = ServiceOwners {
                stim_tick: self.ports.tick_publishers.publisher_ids(),
                driver_status: self.ports.status_publishers.publisher_ids(),
            };
            let listed = list_nodes();
            self.health.on_nodes(&listed, &owners);
        }
        for e in pass::check_health(&mut self.core, &mut self.health, now, &proc_state) {
            match e.severity {
                Severity::Fault => tracing::error!("{}", e.message),
                Severity::Warning => tracing::warn!("{}", e.message),
            }
        }
    }

    /// The core's orders to the driver, the stops it has not acknowledged yet again, and
    /// what the wait for acknowledgements found ([`CommandLink`]).
    fn send_orders(&mut self, now: u64) {
        for order in self.core.take_orders() {
            let command = self.link.issue(order, now);
            self.send_command(command);
        }
        let (resend, event) = self.link.poll(now);
        if let Some(command) = resend {
            self.send_command(command);
        }
        if let Some(e) = event {
            self.on_link_event(e);
        }
        // A fault found just now orders a safe stop: send it in this pass.
        for order in self.core.take_orders() {
            let command = self.link.issue(order, now);
            self.send_command(command);
        }
    }

    fn send_command(&mut self, command: DriverCommand) {
        if let Err(e) = self.ports.command.send_copy(command) {
            let kind = command.kind();
            self.core
                .note(format!("driver order {kind:?} not sent: {e}"));
            tracing::error!("driver order {kind:?} not sent: {e}");
        }
    }

    /// Acts on a [`LinkEvent`]; alarms and faults go to the log at `err`.
    fn on_link_event(&mut self, event: LinkEvent) {
        if let Some(m) = pass::on_link_event(&mut self.core, event) {
            tracing::error!("{m}");
        }
    }

    /// Recording life cycle: arming starts a run (when recording is enabled and none
    /// is open).
    fn follow_arming(&mut self, now: u64) {
        let state = self.core.state().clone();
        if state != self.last_state {
            if state == ArmState::Armed && self.cfg.recording.enabled && self.run.recorder.is_none()
            {
                self.start_recording(now);
            }
            self.last_state = self.core.state().clone();
        }
    }

    /// Starts a recording run at `now`; a run that cannot start is a fault.
    fn start_recording(&mut self, now: u64) {
        self.run.index += 1;
        let name = format!(
            "run-{}-{}-{}",
            utc_stamp(),
            std::process::id(),
            self.run.index
        );
        let started =
            RecorderThread::start(&self.cfg.recording.dir, &name, self.settings.clone(), now);
        match started {
            Ok(r) => {
                self.core
                    .note(format!("recording to {}", r.dir().display()));
                self.run.dirs.push(r.dir().to_path_buf());
                self.run.recorder = Some(r);
            }
            Err(e) => {
                self.core.fault(recording_fault(&e));
            }
        }
    }

    /// The beats started and completed since the last pass, to the recording.
    fn record_beats(&mut self) {
        for b in self.core.take_beat_starts() {
            let kind = format!("beat {} ({} beats/min)", b.index, b.bpm);
            self.run
                .record(&mut self.core, Item::Boundary(b.start_ns, kind));
        }
        for b in self.core.take_beats() {
            self.run.record(&mut self.core, Item::Beat(b));
        }
    }

    /// The Reference, published when its period is up, at a profile edge, or when
    /// arming or a stop changed it.
    fn publish_reference(&mut self, now: u64) {
        let edge = self.core.next_change_ns(now).is_some_and(|t| t <= now);
        let changed = self
            .core
            .last_reference()
            .is_none_or(|r| r.is_stop() != (*self.core.state() != ArmState::Armed));
        if now >= self.next_publish || edge || changed {
            let r = self.core.reference(now);
            if let Err(e) = self.ports.reference.send_copy(r) {
                tracing::warn!("Reference not published: {e:?}");
            }
            self.run.record(&mut self.core, Item::Reference(r));
            // What the profile has scheduled, beside it (rt-core plans over it; nothing
            // scheduled, e.g. an operator's setpoint, is announced as an empty preview).
            let mut edges = [PreviewEdge::default(); ReferencePreview::MAX_EDGES];
            let n = self.core.preview(now, &mut edges);
            self.preview_seq += 1;
            let p = ReferencePreview::new(self.preview_seq, now, r.seq, &edges[..n]);
            if let Err(e) = self.ports.preview.send_copy(p) {
                tracing::warn!("ReferencePreview not published: {e:?}");
            }
            self.run.record(&mut self.core, Item::Preview(p));
            self.next_publish = now + self.period_ns;
        }
    }

    /// The events of this pass to the log and the recording, then a flush when due.
    fn record_events(&mut self, now: u64) {
        let events = self.core.take_new_events();
        for e in &events {
            tracing::info!("{e}");
        }
        for e in &events {
            self.run.record(&mut self.core, Item::Event(now, e.clone()));
        }
        self.run.record(&mut self.core, Item::Flush(now));
    }

    /// The writers: a failed one ends the recording and stops stimulation; the run is
    /// closed once no longer armed; runs whose writer has finished (flushed, fsynced) are
    /// reported.
    fn follow_recorders(&mut self, now: u64) {
        if let Some(e) = self.run.recorder.as_ref().and_then(RecorderThread::failure) {
            self.run.recorder = None;
            self.core.fault(recording_fault(&e));
        }
        if *self.core.state() != ArmState::Armed
            && let Some(mut rec) = self.run.recorder.take()
        {
            rec.close(now);
            self.run.closing.push(rec);
        }
        while let Some(i) = self.run.closing.iter().position(RecorderThread::is_closed) {
            let rec = self.run.closing.swap_remove(i);
            note_closed(&mut self.core, rec);
        }
    }

    /// Tells systemd we are alive, three times per watchdog period, when it watches.
    fn notify_watchdog(&mut self, now: u64) {
        if let Some(wd) = self.watchdog
            && now >= self.next_watchdog
        {
            let _ = sd_notify::notify(&[sd_notify::NotifyState::Watchdog]);
            self.next_watchdog = now + wd.as_nanos() as u64 / 3;
        }
    }

    /// On the way out: leaves the reference stopped for rt-core and the driver disarmed.
    fn leave(&mut self) {
        let t = monotonic_ns();
        let r = self.core.reference(t);
        let _ = self.ports.reference.send_copy(r);
        self.preview_seq += 1;
        let _ =
            self.ports
                .preview
                .send_copy(ReferencePreview::new(self.preview_seq, t, r.seq, &[]));
        let disarm = self.link.issue(DriverOrder::Disarm, t);
        let _ = self.ports.command.send_copy(disarm);
    }

    /// When the next pass is due after the one at `now`: at most [`POLL_MS`] later, at
    /// the next publication, at the next profile edge.
    fn wake_at(&self, now: u64) -> u64 {
        let mut wake = (now + POLL_MS * 1_000_000).min(self.next_publish);
        if let Some(t) = self.core.next_change_ns(now) {
            wake = wake.min(t.max(now));
        }
        wake
    }

    /// Ends the daemon: waits for the writers (every run on disk, fsynced, before the
    /// process exits), logs the last events, closes the control socket.
    fn finish(mut self) -> Outcome {
        let fault = match self.core.state() {
            ArmState::Fault(f) => Some(f.clone()),
            _ => None,
        };
        if let Some(mut rec) = self.run.recorder.take() {
            rec.close(monotonic_ns());
            self.run.closing.push(rec);
        }
        for rec in self.run.closing.drain(..) {
            note_closed(&mut self.core, rec);
        }
        for e in self.core.take_new_events() {
            tracing::info!("{e}");
        }
        drop(self.server);
        Outcome {
            recordings: self.run.dirs,
            fault,
        }
    }

    /// The daemon's state for `status` at `now`.
    fn status(&self, now: u64) -> Status {
        let last = self.core.last_reference();
        let (driver_state, stimulator_state) = self.health.device_states();
        Status {
            state: match self.core.state() {
                ArmState::Armed if !self.link.armed_confirmed() => "arming".into(),
                state => state.name().into(),
            },
            fault: match self.core.state() {
                ArmState::Fault(f) => Some(f.message.clone()),
                _ => None,
            },
            fault_cause: match self.core.state() {
                ArmState::Fault(f) => Some(f.cause),
                _ => None,
            },
            uptime_s: (now - self.start_ns) as f64 * 1e-9,
            reference: last.map_or(0.0, |r| r.force),
            reference_rate_per_s: last.map_or(0.0, |r| r.max_rate_per_s),
            reference_stop: last.is_none_or(|r| r.is_stop()),
            references_published: last.map_or(0, |r| r.seq),
            profile: self.core.profile().map(|p| p.spec().describe()),
            beat: self.core.profile().and_then(|p| p.beat()).map(|b| b.index),
            outer_loop: self.core.outer_loop().enabled(),
            outer_loop_correction: self.core.outer_loop().correction(),
            last_contraction: self.core.last_contraction(),
            processes: self.health.statuses(now),
            driver_state,
            stimulator_state,
            recording: self
                .run
                .recorder
                .as_ref()
                .map(|r| r.dir().display().to_string())
                .or_else(|| self.run.dirs.last().map(|d| d.display().to_string())),
            driver_order: self.link.last_order().map(order_status),
            events: self.core.events().cloned().collect(),
        }
    }
}

/// An [`OrderRecord`] as `status` shows it.
fn order_status(r: OrderRecord) -> DriverOrderStatus {
    let (outcome, reason) = match r.outcome {
        command_link::Outcome::Pending => ("pending", None),
        command_link::Outcome::Confirmed => ("confirmed", None),
        command_link::Outcome::Refused(why) => ("refused", Some(why.name().to_owned())),
        command_link::Outcome::Unacknowledged => ("unacknowledged", None),
        command_link::Outcome::Unwatched => ("unwatched", None),
    };
    DriverOrderStatus {
        order: match r.order {
            DriverOrder::Arm => "arm",
            DriverOrder::Disarm => "disarm",
            DriverOrder::SafeStop => "safe_stop",
        }
        .to_owned(),
        id: r.id,
        outcome: outcome.to_owned(),
        reason,
    }
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
