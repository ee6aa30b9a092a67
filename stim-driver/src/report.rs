//! The report thread (normal priority): everything the forward thread must not do.
//!
//! * drains the forward thread's [`DriverEvent`]s: logs decisions, refusals, faults and
//!   state changes ([`log_event`]) and fills the histograms ([`DriverTelemetry`]);
//! * pairs kernel transmit timestamps of PULSE frames with their StimTicks
//!   ([`crate::txstamp`]);
//! * checks the StimTick publisher's liveness through iceoryx2 ([`LivenessMonitor`]) every
//!   `liveness_check_ms` and hands it to the forward thread;
//! * publishes a [`PulseOutcome`] for every StimTick that asked for a pulse (sent, refused,
//!   not armed, not written, late), and a second one for every pulse sent once the
//!   stimulator has accounted for it (applied, not applied: [`crate::applied`]), so that a
//!   recording says what was decided, sent and applied;
//! * publishes [`DriverStatus`] every `status_period_ms` and at once on a state change, and
//!   a cumulative [`TimingReport`] (and an `.hlog` interval) every `report_period_ms`;
//! * once the forward thread has ended: a last drain, the final DriverStatus and the final
//!   TimingReport ([`TimingReport::FLAG_FINAL`]).

use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use fes_can::{Message, MessageKind, Nodes};
use fes_rt::msg::port;
use fes_rt::msg::{DeviceState, DriverCommand, DriverStatus, PulseOutcome, StimTick, TimingReport};
use fes_rt::rt::clock::monotonic_ns;
use fes_rt::rt::hlog::HlogWriter;
use fes_rt::rt::liveness::{Liveness, LivenessMonitor};
use fes_rt::rt::node::{RunError, create_node};
use fes_rt::rt::telemetry::IntervalQuantities;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::prelude::ipc;
use tracing::{debug, error, info, warn};

use crate::config::DriverConfig;
use crate::event::{Counters, DriverEvent, DriverState};
use crate::runner::Shared;
use crate::telemetry::DriverTelemetry;
use crate::txstamp::{PulseTimes, TxStampReader};

/// The iceoryx2 node name of the report thread.
pub const NODE_NAME: &str = "stim-driver-report";
/// How often the report thread wakes.
pub const REPORT_WAKE: Duration = Duration::from_millis(2);
/// An armed driver whose last PULSE left within this is reported as `Stimulating`, ns.
pub const STIMULATING_WINDOW_NS: u64 = 100_000_000;

/// The [`DriverStatus`] for counters `c` at `t_ns`.
pub fn driver_status(seq: u64, t_ns: u64, c: &Counters) -> DriverStatus {
    let mut state = c.state;
    if state == DeviceState::Armed as u8
        && c.last_pulse_ns != 0
        && t_ns.saturating_sub(c.last_pulse_ns) <= STIMULATING_WINDOW_NS
    {
        state = DeviceState::Stimulating as u8;
    }
    DriverStatus {
        seq,
        t_ns,
        // The counters are read one by one; a pulse counted before its tick is not.
        ticks_received: c.ticks_received.max(c.pulses_sent),
        ticks_lost: c.ticks_lost,
        pulses_sent: c.pulses_sent,
        pulses_rejected: c.pulses_rejected,
        can_tx_errors: c.can_tx_errors,
        watchdog_trips: c.watchdog_trips,
        fault_code: c.fault_code,
        state,
        stimulator_state: c.stimulator_state,
        command_seq: c.command_seq,
        command_result: c.command_result,
        command_reason: c.command_reason,
        reserved: [0; 6],
    }
}

/// Logs a publisher's liveness: `who` is the publisher, `unit_key` the `[watchdog]` key
/// naming the unit it must run in.
fn log_liveness(who: &str, unit_key: &str, l: Liveness) {
    match l {
        Liveness::Alive => info!("{who} alive"),
        Liveness::Unknown => warn!("{who}: liveness unknown"),
        Liveness::Dead => warn!("{who}: its node is DEAD"),
        Liveness::NoPublisher => warn!("no {who}"),
        Liveness::Foreign => {
            error!("{who}: runs outside watchdog.{unit_key}: a FOREIGN publisher, not the stack's")
        }
    }
}

/// Logs one event at its level (the per-tick timing events are not logged).
pub fn log_event(event: &DriverEvent) {
    match *event {
        DriverEvent::Wake { .. }
        | DriverEvent::Tick { .. }
        | DriverEvent::PulseSent { .. }
        | DriverEvent::Outcome { .. } => {}
        DriverEvent::Rejected {
            tick_seq,
            violation,
            pulse,
        } => warn!(
            "StimTick {tick_seq} refused{}: {violation}",
            if pulse { " (its pulse NOT sent)" } else { "" }
        ),
        DriverEvent::TicksLost { seq, count } => {
            warn!("{count} StimTick(s) missing before seq {seq}")
        }
        DriverEvent::StaleTick { seq, age_ns } => warn!(
            "StimTick {seq} refused: {:.3} ms old on arrival",
            age_ns as f64 / 1e6
        ),
        DriverEvent::TxProblem { frame, error } => {
            warn!("CAN write of a {frame:?} frame failed: {error}")
        }
        DriverEvent::StateChanged { from, to } => match to {
            DriverState::SafeState(_) | DriverState::ConfigRefused => {
                error!("state: {from} -> {to}")
            }
            _ => info!("state: {from} -> {to}"),
        },
        DriverEvent::Armed { command_seq } => {
            info!("ARMED by command {command_seq}: NMT start sent")
        }
        DriverEvent::ArmRefused {
            command_seq,
            refusal,
        } => warn!("Arm command {command_seq} refused: {refusal}"),
        DriverEvent::Disarmed { command_seq } => {
            info!("disarmed by command {command_seq}: NMT stop sent")
        }
        DriverEvent::Tripped { fault, stop_sent } => error!(
            "SAFE STATE: {fault}; {}",
            if stop_sent {
                "NMT stop sent"
            } else {
                "NMT stop could NOT be written (retrying)"
            }
        ),
        DriverEvent::CommandInvalid { seq, error } => {
            warn!("DriverCommand {seq} invalid, ignored: {error}")
        }
        DriverEvent::BringUp(step) => info!("stimulator bring-up: {step:?}"),
        DriverEvent::StimulatorState {
            state,
            pulses_delivered,
        } => info!("stimulator state {state:?} ({pulses_delivered} pulses applied)"),
        DriverEvent::StimulatorEmcy(emcy) => warn!(
            "stimulator EMCY {} ({:#06x}), state {:?}, pulse seq {}",
            emcy.code,
            emcy.code.raw(),
            emcy.state,
            emcy.seq
        ),
        DriverEvent::Bus(bus) => warn!("bus: {bus:?}"),
        DriverEvent::SupervisorLiveness(l) => {
            log_liveness("supervisor (DriverCommand publisher)", "supervisor_unit", l);
        }
        DriverEvent::Liveness(l) => log_liveness("StimTick publisher", "generator_unit", l),
        DriverEvent::PulseLate {
            tick_seq,
            waited_ns,
            sent,
        } => {
            if sent {
                debug!(
                    "pulse of tick {tick_seq} written {:.1} ms late (transport busy)",
                    waited_ns as f64 / 1e6
                );
            } else {
                warn!(
                    "pulse of tick {tick_seq} NOT sent: the transport was busy for {:.1} ms",
                    waited_ns as f64 / 1e6
                );
            }
        }
        DriverEvent::StopResent => info!("NMT stop (re)sent"),
        DriverEvent::Shutdown { stop_sent } => info!(
            "shutdown: {}",
            if stop_sent {
                "NMT stop sent"
            } else {
                "NMT stop could NOT be written"
            }
        ),
    }
}

/// What the report thread ends with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReportOutcome {
    /// The final TimingReport.
    pub timing: TimingReport,
    /// The final DriverStatus.
    pub status: DriverStatus,
    /// Transmit timestamps paired with their StimTicks.
    pub tx_stamps: u64,
}

/// Runs the report thread until the forward thread has ended (see the module
/// documentation). `on_ready` is called once its ports exist.
pub fn run_report(
    config: &DriverConfig,
    shared: &Shared,
    hlog: Option<HlogWriter>,
    tx_stamps: Option<TxStampReader>,
    on_ready: impl FnOnce(),
) -> Result<ReportOutcome, RunError> {
    let prefix = config.ipc.prefix.as_str();
    let node = create_node(NODE_NAME)?;
    let ports = ReportPorts {
        status: port::publisher::<DriverStatus>(&node, prefix)?,
        timing: port::publisher::<TimingReport>(&node, prefix)?,
        outcome: port::publisher::<PulseOutcome>(&node, prefix)?,
        generator: LivenessMonitor::<StimTick>::new(&node, prefix)?
            .in_unit(config.watchdog.generator_unit.clone()),
        supervisor: LivenessMonitor::<DriverCommand>::new(&node, prefix)?
            .in_unit(config.watchdog.supervisor_unit.clone()),
    };
    let nodes: Nodes = config.nodes().map_err(|e| RunError::Config(Box::new(e)))?;
    on_ready();
    let mut reporter = Reporter::new(config, shared, ports, nodes, hlog, tx_stamps);
    let panic_at = test_panic_after().map(|after| Instant::now() + after);
    while !shared.forward_ended.load(Ordering::Relaxed) {
        std::thread::sleep(REPORT_WAKE);
        let now = Instant::now();
        if panic_at.is_some_and(|t| now >= t) {
            panic!("test-only panic of the report thread ({ENV_TEST_PANIC_REPORT})");
        }
        reporter.pass(now)?;
    }
    reporter.finish()
}

/// Test-only switch: the report thread panics this many ms after it starts (the fault
/// suite's proof that a panicking thread stops the stimulator). Logged
/// loudly when set; never set by the units or the installer.
pub const ENV_TEST_PANIC_REPORT: &str = "FES_TEST_PANIC_REPORT_AFTER_MS";

fn test_panic_after() -> Option<Duration> {
    let ms: u64 = std::env::var(ENV_TEST_PANIC_REPORT).ok()?.parse().ok()?;
    error!("TEST SWITCH ON: {ENV_TEST_PANIC_REPORT}={ms}: the report thread will panic");
    Some(Duration::from_millis(ms))
}

/// The report thread's iceoryx2 ports.
struct ReportPorts {
    status: Publisher<ipc::Service, DriverStatus, ()>,
    timing: Publisher<ipc::Service, TimingReport, ()>,
    outcome: Publisher<ipc::Service, PulseOutcome, ()>,
    generator: LivenessMonitor<StimTick>,
    supervisor: LivenessMonitor<DriverCommand>,
}

/// The report thread's state between passes.
struct Reporter<'a> {
    shared: &'a Shared,
    ports: ReportPorts,
    nodes: Nodes,
    pulse_id: u32,
    hlog: Option<HlogWriter>,
    tx_stamps: Option<TxStampReader>,
    telemetry: DriverTelemetry,
    pulse_times: PulseTimes,
    stamps_paired: u64,
    status_seq: u64,
    report_seq: u64,
    outcome_seq: u64,
    /// The command acknowledgement last published: a new one is published at once.
    last_ack: (u64, u8),
    start: Instant,
    status_period: Duration,
    report_period: Duration,
    liveness_period: Duration,
    next_status: Instant,
    next_report: Instant,
    next_liveness: Instant,
    interval_start: Duration,
    last_overflows: u64,
}

impl<'a> Reporter<'a> {
    fn new(
        config: &DriverConfig,
        shared: &'a Shared,
        ports: ReportPorts,
        nodes: Nodes,
        hlog: Option<HlogWriter>,
        tx_stamps: Option<TxStampReader>,
    ) -> Self {
        let start = Instant::now();
        let report_period = Duration::from_millis(config.telemetry.report_period_ms);
        Self {
            shared,
            ports,
            pulse_id: u32::from(nodes.id_of(MessageKind::Pulse)),
            nodes,
            hlog,
            tx_stamps,
            telemetry: DriverTelemetry::new(),
            pulse_times: PulseTimes::new(),
            stamps_paired: 0,
            status_seq: 0,
            report_seq: 0,
            outcome_seq: 0,
            last_ack: (0, 0),
            start,
            status_period: Duration::from_millis(config.telemetry.own.status_period_ms),
            report_period,
            liveness_period: Duration::from_millis(u64::from(config.watchdog.liveness_check_ms)),
            next_status: start,
            next_report: start + report_period,
            next_liveness: start,
            interval_start: Duration::ZERO,
            last_overflows: 0,
        }
    }

    /// One pass at `now`: the forward thread's events, the transmit timestamps, the
    /// publishers' liveness, DriverStatus and TimingReport when due, lost events.
    fn pass(&mut self, now: Instant) -> Result<(), RunError> {
        let changed = self.drain();
        self.read_stamps();
        if now >= self.next_liveness {
            self.next_liveness = now + self.liveness_period;
            self.check_liveness();
        }
        let ack = {
            let c = self.shared.status.load();
            (c.command_seq, c.command_result)
        };
        if changed || ack != self.last_ack || now >= self.next_status {
            self.last_ack = ack;
            self.next_status = now + self.status_period;
            self.publish_status();
        }
        if now >= self.next_report {
            self.next_report += self.report_period;
            self.emit_report(0)?;
        }
        let overflows = self.shared.event_overflows.load(Ordering::Relaxed);
        if overflows != self.last_overflows {
            warn!(
                "{} driver events lost (report queue full)",
                overflows - self.last_overflows
            );
            self.last_overflows = overflows;
        }
        Ok(())
    }

    /// The last pass: what is left of the events and stamps, the final DriverStatus and
    /// the final TimingReport.
    fn finish(mut self) -> Result<ReportOutcome, RunError> {
        self.drain();
        self.read_stamps();
        let status = self.publish_status();
        let timing = self.emit_report(TimingReport::FLAG_FINAL)?;
        Ok(ReportOutcome {
            timing,
            status,
            tx_stamps: self.stamps_paired,
        })
    }

    /// Takes the forward thread's events: telemetry, pulse send times, the log. Returns
    /// whether the driver's state changed.
    fn drain(&mut self) -> bool {
        let mut state_changed = false;
        while let Some(event) = self.shared.events.pop() {
            self.telemetry.record(&event);
            match event {
                DriverEvent::PulseSent {
                    pulse_seq,
                    t_publish_ns,
                    ..
                } => self.pulse_times.insert(pulse_seq, t_publish_ns),
                DriverEvent::Outcome {
                    tick_seq,
                    tick_t_ns,
                    fate,
                } => {
                    self.outcome_seq += 1;
                    let outcome = PulseOutcome::new(
                        self.outcome_seq,
                        monotonic_ns(),
                        tick_seq,
                        tick_t_ns,
                        fate,
                    );
                    // A lost outcome is not fatal: the recorder counts a pulse it never
                    // heard of as not delivered.
                    let _ = self.ports.outcome.send_copy(outcome);
                }
                DriverEvent::StateChanged { .. } => state_changed = true,
                _ => {}
            }
            log_event(&event);
        }
        state_changed
    }

    fn read_stamps(&mut self) {
        if let Some(reader) = &self.tx_stamps {
            self.stamps_paired += read_stamps(
                reader,
                self.pulse_id,
                &self.nodes,
                &mut self.pulse_times,
                &mut self.telemetry,
            );
        }
    }

    /// The StimTick publisher's and the supervisor's iceoryx2 nodes: alive, dead, gone.
    fn check_liveness(&mut self) {
        let check = self.ports.generator.check();
        self.shared.status.set_liveness(check.liveness);
        if check.cleaned_up {
            warn!("removed the dead StimTick publisher's stale iceoryx2 resources");
        }
        let check = self.ports.supervisor.check();
        self.shared.status.set_supervisor_liveness(check.liveness);
        if check.cleaned_up {
            warn!("removed the dead supervisor's stale iceoryx2 resources");
        }
    }

    fn publish_status(&mut self) -> DriverStatus {
        self.status_seq += 1;
        let s = driver_status(self.status_seq, monotonic_ns(), &self.shared.status.load());
        // A failed publish is not fatal: the next one carries the same cumulative numbers.
        let _ = self.ports.status.send_copy(s);
        s
    }

    /// Writes the hlog interval and publishes a TimingReport with `flags` (plus DEGRADED
    /// and ALLOCATIONS_UNCOUNTED as they apply).
    fn emit_report(&mut self, flags: u8) -> Result<TimingReport, RunError> {
        let now = self.start.elapsed();
        if let Some(log) = &mut self.hlog {
            self.telemetry
                .write_interval(
                    log,
                    self.interval_start,
                    now.saturating_sub(self.interval_start),
                )
                .map_err(RunError::Hlog)?;
            log.flush().map_err(RunError::Hlog)?;
        }
        self.interval_start = now;
        self.report_seq += 1;
        let mut flags = flags;
        if self.shared.rt_status.get().is_some_and(|s| s.is_degraded()) {
            flags |= TimingReport::FLAG_DEGRADED;
        }
        if !fes_rt::rt::alloc::counting_allocator_installed() {
            flags |= TimingReport::FLAG_ALLOCATIONS_UNCOUNTED;
        }
        let report = TimingReport {
            prescription: self.shared.prescription.get().copied().unwrap_or_default(),
            ..self.telemetry.report(
                self.report_seq,
                monotonic_ns(),
                &self.shared.status.load(),
                self.shared.event_overflows.load(Ordering::Relaxed),
                self.shared.hot_path_allocations.load(Ordering::Relaxed),
                flags,
            )
        };
        let _ = self.ports.timing.send_copy(report);
        Ok(report)
    }
}

/// Reads every queued transmit timestamp; a PULSE's is paired with its StimTick's publish
/// time. Returns how many were paired.
fn read_stamps(
    reader: &TxStampReader,
    pulse_id: u32,
    nodes: &Nodes,
    pulse_times: &mut PulseTimes,
    telemetry: &mut DriverTelemetry,
) -> u64 {
    let mut paired = 0;
    while let Ok(Some(stamp)) = reader.read() {
        if stamp.id != pulse_id {
            continue;
        }
        let data = &stamp.data[..usize::from(stamp.dlc)];
        if let Ok(Message::Pulse(p)) = nodes.decode(stamp.id, data)
            && let Some(t_publish_ns) = pulse_times.take(p.seq)
        {
            telemetry.record_tx_stamp(stamp.monotonic_ns().saturating_sub(t_publish_ns));
            paired += 1;
        }
    }
    paired
}

#[cfg(test)]
mod tests {
    use super::*;
    use fes_rt::msg::Contract;

    #[test]
    fn status_refines_armed_to_stimulating_within_the_window_and_validates() {
        let c = Counters {
            ticks_received: 10,
            pulses_sent: 11,
            state: DeviceState::Armed as u8,
            stimulator_state: DeviceState::Armed as u8,
            last_pulse_ns: 1_000_000_000,
            ..Counters::default()
        };
        let s = driver_status(1, 1_000_000_000 + STIMULATING_WINDOW_NS, &c);
        assert_eq!(s.state(), Ok(DeviceState::Stimulating));
        assert_eq!(s.validate(), Ok(()));
        assert_eq!(s.ticks_received, 11);
        let s = driver_status(2, 1_000_000_001 + STIMULATING_WINDOW_NS, &c);
        assert_eq!(s.state(), Ok(DeviceState::Armed));
        let idle = Counters {
            state: DeviceState::PreOperational as u8,
            ..c
        };
        assert_eq!(
            driver_status(3, 1_000_000_000, &idle).state(),
            Ok(DeviceState::PreOperational)
        );
    }
}
