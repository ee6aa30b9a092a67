//! The report thread (normal priority): everything the forward thread must not do.
//!
//! * drains the forward thread's [`DriverEvent`]s: logs decisions, refusals, faults and
//!   state changes ([`log_event`]) and fills the histograms ([`DriverTelemetry`]);
//! * pairs kernel transmit timestamps of PULSE frames with their StimTicks
//!   ([`crate::txstamp`]);
//! * checks the StimTick publisher's liveness through iceoryx2 ([`LivenessMonitor`]) every
//!   `liveness_check_ms` and hands it to the forward thread;
//! * publishes [`DriverStatus`] every `status_period_ms` and at once on a state change, and
//!   a cumulative [`TimingReport`] (and an `.hlog` interval) every `report_period_ms`;
//! * once the forward thread has ended: a last drain, the final DriverStatus and the final
//!   TimingReport ([`TimingReport::FLAG_FINAL`]).

use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use fes_can::{Message, MessageKind, Nodes};
use fes_rt::msg::port;
use fes_rt::msg::{DeviceState, DriverCommand, DriverStatus, StimTick, TimingReport};
use fes_rt::rt::clock::monotonic_ns;
use fes_rt::rt::hlog::HlogWriter;
use fes_rt::rt::node::{RunError, create_node};
use tracing::{error, info, warn};

use crate::config::DriverConfig;
use crate::event::{Counters, DriverEvent, DriverState, Liveness};
use crate::liveness::LivenessMonitor;
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
    }
}

/// Logs one event at its level (the per-tick timing events are not logged).
pub fn log_event(event: &DriverEvent) {
    match *event {
        DriverEvent::Wake { .. } | DriverEvent::Tick { .. } | DriverEvent::PulseSent { .. } => {}
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
        DriverEvent::SupervisorLiveness(l) => match l {
            Liveness::Alive => info!("supervisor (DriverCommand publisher) alive"),
            Liveness::Unknown => warn!("supervisor liveness unknown"),
            Liveness::Dead => warn!("the supervisor's node is DEAD"),
            Liveness::NoPublisher => warn!("no supervisor (no DriverCommand publisher)"),
        },
        DriverEvent::Liveness(l) => match l {
            Liveness::Alive => info!("StimTick publisher alive"),
            Liveness::Unknown => warn!("StimTick publisher liveness unknown"),
            Liveness::Dead => warn!("StimTick publisher's node is DEAD"),
            Liveness::NoPublisher => warn!("no StimTick publisher"),
        },
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
    mut hlog: Option<HlogWriter>,
    tx_stamps: Option<TxStampReader>,
    on_ready: impl FnOnce(),
) -> Result<ReportOutcome, RunError> {
    let prefix = config.ipc.prefix.as_str();
    let node = create_node(NODE_NAME)?;
    let status_pub = port::publisher::<DriverStatus>(&node, prefix)?;
    let timing_pub = port::publisher::<TimingReport>(&node, prefix)?;
    let liveness = LivenessMonitor::<StimTick>::new(&node, prefix)?;
    let supervisor = LivenessMonitor::<DriverCommand>::new(&node, prefix)?;
    let nodes: Nodes = config
        .nodes()
        .map_err(|e| RunError::Node(format!("configuration: {e}")))?;
    let pulse_id = u32::from(nodes.id_of(MessageKind::Pulse));
    on_ready();

    let start = Instant::now();
    let status_period = Duration::from_millis(config.telemetry.status_period_ms);
    let report_period = Duration::from_millis(config.telemetry.report_period_ms);
    let liveness_period = Duration::from_millis(u64::from(config.watchdog.liveness_check_ms));
    let mut telemetry = DriverTelemetry::new();
    let mut pulse_times = PulseTimes::new();
    let mut stamps_paired = 0u64;
    let mut status_seq = 0u64;
    let mut report_seq = 0u64;
    let mut next_status = start;
    let mut next_report = start + report_period;
    let mut next_liveness = start;
    let mut interval_start = Duration::ZERO;
    let mut last_overflows = 0u64;

    let drain = |telemetry: &mut DriverTelemetry, pulse_times: &mut PulseTimes| -> bool {
        let mut state_changed = false;
        while let Some(event) = shared.events.pop() {
            telemetry.record(&event);
            match event {
                DriverEvent::PulseSent {
                    pulse_seq,
                    t_publish_ns,
                    ..
                } => pulse_times.insert(pulse_seq, t_publish_ns),
                DriverEvent::StateChanged { .. } => state_changed = true,
                _ => {}
            }
            log_event(&event);
        }
        state_changed
    };
    let publish_status = |seq: &mut u64| -> DriverStatus {
        *seq += 1;
        let s = driver_status(*seq, monotonic_ns(), &shared.status.load());
        // A failed publish is not fatal: the next one carries the same cumulative numbers.
        let _ = status_pub.send_copy(s);
        s
    };
    let mut emit_report = |telemetry: &mut DriverTelemetry,
                           seq: &mut u64,
                           interval_start: &mut Duration,
                           flags: u8|
     -> Result<TimingReport, RunError> {
        let now = start.elapsed();
        if let Some(log) = &mut hlog {
            telemetry
                .write_interval(log, *interval_start, now.saturating_sub(*interval_start))
                .map_err(|e| RunError::Node(format!("telemetry.hlog: {e}")))?;
        }
        *interval_start = now;
        *seq += 1;
        let mut flags = flags;
        if shared.rt_status.get().is_some_and(|s| s.is_degraded()) {
            flags |= TimingReport::FLAG_DEGRADED;
        }
        if !fes_rt::rt::alloc::counting_allocator_installed() {
            flags |= TimingReport::FLAG_ALLOCATIONS_UNCOUNTED;
        }
        let report = telemetry.report(
            *seq,
            monotonic_ns(),
            &shared.status.load(),
            shared.event_overflows.load(Ordering::Relaxed),
            shared.hot_path_allocations.load(Ordering::Relaxed),
            flags,
        );
        let _ = timing_pub.send_copy(report);
        Ok(report)
    };

    while !shared.forward_ended.load(Ordering::Relaxed) {
        std::thread::sleep(REPORT_WAKE);
        let now = Instant::now();
        let changed = drain(&mut telemetry, &mut pulse_times);
        if let Some(reader) = &tx_stamps {
            stamps_paired +=
                read_stamps(reader, pulse_id, &nodes, &mut pulse_times, &mut telemetry);
        }
        if now >= next_liveness {
            next_liveness = now + liveness_period;
            let check = liveness.check();
            shared.status.set_liveness(check.liveness);
            if check.cleaned_up {
                warn!("removed the dead StimTick publisher's stale iceoryx2 resources");
            }
            let check = supervisor.check();
            shared.status.set_supervisor_liveness(check.liveness);
            if check.cleaned_up {
                warn!("removed the dead supervisor's stale iceoryx2 resources");
            }
        }
        if changed || now >= next_status {
            next_status = now + status_period;
            publish_status(&mut status_seq);
        }
        if now >= next_report {
            next_report += report_period;
            emit_report(&mut telemetry, &mut report_seq, &mut interval_start, 0)?;
        }
        let overflows = shared.event_overflows.load(Ordering::Relaxed);
        if overflows != last_overflows {
            warn!(
                "{} driver events lost (report queue full)",
                overflows - last_overflows
            );
            last_overflows = overflows;
        }
    }
    drain(&mut telemetry, &mut pulse_times);
    if let Some(reader) = &tx_stamps {
        stamps_paired += read_stamps(reader, pulse_id, &nodes, &mut pulse_times, &mut telemetry);
    }
    let status = publish_status(&mut status_seq);
    let timing = emit_report(
        &mut telemetry,
        &mut report_seq,
        &mut interval_start,
        TimingReport::FLAG_FINAL,
    )?;
    Ok(ReportOutcome {
        timing,
        status,
        tx_stamps: stamps_paired,
    })
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
