//! What flows between the driver's threads, all `Copy` and fixed-size:
//!
//! * [`BusEvent`]: receive thread → forward thread (STATUS, EMCY, heartbeats, CAN error
//!   frames, link changes), through a preallocated lock-free queue;
//! * [`DriverEvent`]: forward thread → report thread (decisions, faults, timing), through
//!   another; the report thread logs them (the forward thread never logs);
//! * [`Counters`] / [`SharedStatus`]: the forward thread's counters, published with relaxed
//!   atomic stores after each wake-up for the report thread to read.

use std::sync::atomic::{AtomicU8, AtomicU64, Ordering};

use crossbeam::queue::ArrayQueue;
use fes_can::{Emcy, MessageKind, NmtState, Status, StimState};
use fes_rt::msg::{DeviceState, DriverCommand, PulseFate, ValidationError};
use fes_rt::rt::liveness::Liveness;

use crate::fault::{ArmRefusal, Fault};
use crate::interlock::Violation;
use crate::output::SendError;

/// A CAN error frame, classified (linux/can/error.h classes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BusErrorKind {
    /// The controller went bus-off.
    BusOff,
    /// The controller restarted after bus-off.
    Restarted,
    /// The controller reached error-passive.
    ErrorPassive,
    /// The controller reached the error-warning level.
    ErrorWarning,
    /// Receive or transmit buffer overflow in the controller.
    Overflow,
    /// The controller is error-active again.
    ErrorActive,
    /// Any other error (protocol violation, no ACK, transceiver, lost arbitration...):
    /// the error class bits of the identifier.
    Other {
        /// CAN_ERR_* class bits.
        class: u32,
    },
}

/// An event from the bus side, for the forward thread.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BusEvent {
    /// A STATUS frame from the stimulator.
    Status(Status),
    /// An EMCY frame from the stimulator.
    Emcy(Emcy),
    /// The stimulator's heartbeat (state `BootUp` = it has just started).
    StimHeartbeat(NmtState),
    /// A CAN error frame.
    BusError(BusErrorKind),
    /// The interface went down (or a read failed with `ENETDOWN`).
    LinkDown,
    /// The interface is up and running again.
    LinkUp,
    /// Bus events were dropped because the queue to the forward thread was full.
    EventsLost,
    /// A frame on one of the driver's own transmit identifiers that the driver did not
    /// write ([`crate::intrusion`]).
    Intrusion {
        /// The frame's COB-ID.
        cob_id: u16,
        /// The message kind of that identifier.
        kind: MessageKind,
    },
    /// A CONFIG_APPLIED page: limits the stimulator says it applied.
    ConfigApplied(fes_can::Config),
    /// The stimulator answered a command "busy" and did not execute it (ScienceMode 2,
    /// -8; [`crate::serial_rx`]): waited out, not a fault.
    DeviceBusy {
        /// The command was a SinglePulse: that pulse was not delivered.
        pulse: bool,
    },
}

/// The driver's state as a whole.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DriverState {
    /// Bringing the stimulator up (pre-operational, CONFIG, waiting for confirmation).
    Starting,
    /// The stimulator refused the configuration; the driver cannot arm.
    ConfigRefused,
    /// Ready; forwards nothing until armed.
    Disarmed,
    /// Forwarding pulses.
    Armed,
    /// Safe state after a fault; forwards nothing until explicitly re-armed.
    SafeState(Fault),
}

impl DriverState {
    /// The state as `DriverStatus.state` encodes it (`Armed` becomes `Stimulating` when a
    /// pulse left in the last 100 ms: that is decided by the status publisher).
    pub const fn device_state(&self) -> DeviceState {
        match self {
            DriverState::Starting => DeviceState::Boot,
            DriverState::Disarmed => DeviceState::PreOperational,
            DriverState::Armed => DeviceState::Armed,
            DriverState::ConfigRefused | DriverState::SafeState(_) => DeviceState::Fault,
        }
    }
}

impl core::fmt::Display for DriverState {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            DriverState::Starting => f.write_str("starting"),
            DriverState::ConfigRefused => f.write_str("configuration refused"),
            DriverState::Disarmed => f.write_str("disarmed"),
            DriverState::Armed => f.write_str("ARMED"),
            DriverState::SafeState(fault) => write!(f, "SAFE STATE ({fault})"),
        }
    }
}

/// The stimulator's state as `DriverStatus.stimulator_state` encodes it: a stopped
/// stimulator (output off until NMT start) is `Stopped`, not a fault.
pub const fn stimulator_device_state(state: StimState) -> DeviceState {
    match state {
        StimState::Boot => DeviceState::Boot,
        StimState::PreOperational => DeviceState::PreOperational,
        StimState::Armed => DeviceState::Armed,
        StimState::Stimulating => DeviceState::Stimulating,
        StimState::Stopped => DeviceState::Stopped,
        StimState::Fault => DeviceState::Fault,
    }
}

/// Which step of bringing the stimulator up happened.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BringUp {
    /// NMT enter pre-operational sent.
    PreOperationalSent,
    /// Both CONFIG pages sent under this id.
    ConfigSent {
        /// The configuration id.
        config_id: u8,
    },
    /// STATUS shows the configuration applied.
    ConfigConfirmed {
        /// The configuration id.
        config_id: u8,
    },
    /// The stimulator refused it (EMCY config_invalid).
    ConfigRefused {
        /// Index of the offending limit.
        detail: u16,
    },
    /// The stimulator read back the limits it applied (CONFIG_APPLIED, all pages).
    LimitsReadBack {
        /// The configuration id.
        config_id: u8,
        /// The first limit that differs from what was sent (CONFIG signal name), if any:
        /// the configuration is then refused and arming with it is impossible.
        differs: Option<&'static str>,
    },
    /// No confirmation in time: starting over.
    Retry,
    /// The stimulator restarted or lost its configuration: starting over.
    StimulatorLost,
}

/// Which frame a transmit problem concerned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameKind {
    /// A PULSE.
    Pulse,
    /// An NMT command.
    Nmt,
    /// The host heartbeat.
    Heartbeat,
    /// A CONFIG page.
    Config,
}

/// What the forward thread reports to the report thread.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DriverEvent {
    /// One wake-up of the forward loop.
    Wake {
        /// Lateness behind the deadline of a timed wake-up, ns; `None` when woken by a
        /// StimTick notification.
        timer_lateness_ns: Option<u64>,
        /// Wake-up to all inputs taken and handled, ns.
        input_ns: u64,
    },
    /// One StimTick handled.
    Tick {
        /// Its sequence number.
        seq: u64,
        /// Its publish time to its receipt, ns.
        ipc_ns: u64,
        /// Time to decide (interlocks) and act on it, ns.
        decide_ns: u64,
    },
    /// A PULSE was written.
    PulseSent {
        /// The StimTick that asked for it.
        tick_seq: u64,
        /// The PULSE's sequence number.
        pulse_seq: u16,
        /// The StimTick's publish time, ns.
        t_publish_ns: u64,
        /// When the write returned, ns.
        written_ns: u64,
        /// Time in the write call(s), ns.
        write_ns: u64,
        /// Retries after a full transmit queue.
        retries: u32,
    },
    /// What became of the pulse a StimTick asked for (one per such tick received), and
    /// for a pulse sent, later, what the stimulator did with it: the recording's record
    /// of what was sent and what was applied.
    Outcome {
        /// The StimTick's sequence number.
        tick_seq: u64,
        /// Its grid time, ns.
        tick_t_ns: u64,
        /// Sent, refused, not armed, not written or late; then applied or not applied.
        fate: PulseFate,
    },
    /// A tick was refused (its pulse, if any, not sent).
    Rejected {
        /// The tick's sequence number.
        tick_seq: u64,
        /// Why.
        violation: Violation,
        /// It asked for a pulse.
        pulse: bool,
    },
    /// Ticks missing before `seq`.
    TicksLost {
        /// The tick after the gap.
        seq: u64,
        /// How many are missing.
        count: u64,
    },
    /// A tick arrived older than the staleness limit (not used).
    StaleTick {
        /// Its sequence number.
        seq: u64,
        /// Its age on arrival, ns.
        age_ns: u64,
    },
    /// A frame could not be sent.
    TxProblem {
        /// Which frame.
        frame: FrameKind,
        /// Why.
        error: SendError,
    },
    /// The driver's state changed.
    StateChanged {
        /// Before.
        from: DriverState,
        /// After.
        to: DriverState,
    },
    /// Armed: NMT start sent.
    Armed {
        /// The command's sequence number.
        command_seq: u64,
    },
    /// An Arm command was refused.
    ArmRefused {
        /// The command's sequence number.
        command_seq: u64,
        /// Why.
        refusal: ArmRefusal,
    },
    /// Disarmed by command: NMT stop sent.
    Disarmed {
        /// The command's sequence number.
        command_seq: u64,
    },
    /// The driver entered its safe state.
    Tripped {
        /// Why.
        fault: Fault,
        /// Whether the NMT stop was written (else it is retried).
        stop_sent: bool,
    },
    /// A command failed validation.
    CommandInvalid {
        /// Its sequence number.
        seq: u64,
        /// Why.
        error: ValidationError,
    },
    /// Bringing the stimulator up.
    BringUp(BringUp),
    /// The stimulator's STATUS state changed.
    StimulatorState {
        /// The new state.
        state: StimState,
        /// Pulses it has applied (modulo 2^24).
        pulses_delivered: u32,
    },
    /// The stimulator sent an EMCY.
    StimulatorEmcy(Emcy),
    /// A bus condition (error frame, link change, lost bus events).
    Bus(BusEvent),
    /// The StimTick publisher's liveness changed.
    Liveness(Liveness),
    /// The supervisor's (DriverCommand publisher's) liveness changed.
    SupervisorLiveness(Liveness),
    /// A pulse waited for a busy transport (ScienceMode 2's stop-and-wait): written
    /// `waited_ns` after its decision, or dropped as late.
    PulseLate {
        /// The StimTick that asked for it.
        tick_seq: u64,
        /// How long it waited, ns.
        waited_ns: u64,
        /// Written in the end (else dropped: outcome `late`).
        sent: bool,
    },
    /// A pending NMT stop was (re)sent.
    StopResent,
    /// Shutdown: NMT stop and a final heartbeat.
    Shutdown {
        /// Whether the NMT stop was written.
        stop_sent: bool,
    },
}

/// Where the forward path's events go.
pub trait EventSink {
    /// Takes one event; must not block or allocate.
    fn emit(&mut self, event: DriverEvent);
}

impl EventSink for Vec<DriverEvent> {
    fn emit(&mut self, event: DriverEvent) {
        self.push(event);
    }
}

/// An [`EventSink`] into a preallocated lock-free queue; a full queue drops the event and
/// counts it.
#[derive(Debug)]
pub struct QueueSink<'a> {
    queue: &'a ArrayQueue<DriverEvent>,
    overflows: &'a AtomicU64,
}

impl<'a> QueueSink<'a> {
    /// A sink into `queue`, counting drops in `overflows`.
    pub fn new(queue: &'a ArrayQueue<DriverEvent>, overflows: &'a AtomicU64) -> Self {
        Self { queue, overflows }
    }
}

impl EventSink for QueueSink<'_> {
    fn emit(&mut self, event: DriverEvent) {
        if self.queue.push(event).is_err() {
            self.overflows.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// An [`EventSink`] that discards everything (benchmarks).
#[derive(Debug, Default)]
pub struct NullSink;

impl EventSink for NullSink {
    fn emit(&mut self, _: DriverEvent) {}
}

/// The forward path's counters since start.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Counters {
    /// StimTicks received (valid or not).
    pub ticks_received: u64,
    /// StimTicks missing (gaps in `seq`).
    pub ticks_lost: u64,
    /// Ticks refused as defective (invalid, duplicate, out of order, future, stale).
    pub ticks_refused: u64,
    /// PULSE frames written.
    pub pulses_sent: u64,
    /// Pulse commands refused by an interlock.
    pub pulses_rejected: u64,
    /// Pulse commands that passed the interlocks while the driver was not armed.
    pub pulses_not_armed: u64,
    /// Pulses written after waiting for a busy transport (within the lateness bound).
    pub pulses_late: u64,
    /// Pulses dropped after waiting for a busy transport beyond the lateness bound, or
    /// replaced by a newer decision (outcome `late`).
    pub pulses_dropped_late: u64,
    /// Busy answers from the stimulator (ScienceMode 2, -8): commands not executed.
    pub device_busy: u64,
    /// PULSE frames among them: written but not delivered.
    pub pulses_busy: u64,
    /// Frames that could not be written (dropped after retries, or failed).
    pub can_tx_errors: u64,
    /// Writes retried after a full transmit queue.
    pub tx_retries: u64,
    /// Trips of the watchdog conditions ([`Fault::is_watchdog`]).
    pub watchdog_trips: u32,
    /// All trips into the safe state.
    pub trips: u32,
    /// Commands refused (invalid, or an Arm refused).
    pub commands_refused: u64,
    /// Code of the last fault (`Fault::code`), 0 = none.
    pub fault_code: u16,
    /// The driver's state, a [`DeviceState`] as `u8` (without the `Stimulating` refinement).
    pub state: u8,
    /// The stimulator's state, a [`DeviceState`] as `u8`.
    pub stimulator_state: u8,
    /// When the last PULSE was written, ns (0 = never).
    pub last_pulse_ns: u64,
    /// The StimTick of the last PULSE written.
    pub last_pulse_tick_seq: u64,
    /// Pulses the stimulator reports applied (STATUS, modulo 2^24).
    pub stimulator_pulses: u32,
    /// Pulses sent that the stimulator accounted for as applied ([`crate::applied`]).
    pub pulses_applied: u64,
    /// Pulses sent that it rejected or never counted.
    pub pulses_not_applied: u64,
    /// Wake-ups of the forward loop (its progress, for the systemd watchdog).
    pub wakeups: u64,
    /// `seq` of the last DriverCommand handled (below [`DriverCommand::MAX_SEQ`]); 0 = none.
    pub command_seq: u64,
    /// What was done with it, a [`fes_rt::msg::CommandResult`] as `u8`.
    pub command_result: u8,
    /// Why it was refused, a [`fes_rt::msg::CommandRefusal`] as `u8`; 0 unless refused.
    pub command_reason: u8,
}

/// [`Counters`] shared between threads: one writer (the forward thread), relaxed stores.
#[derive(Debug, Default)]
pub struct SharedStatus {
    ticks_received: AtomicU64,
    ticks_lost: AtomicU64,
    ticks_refused: AtomicU64,
    pulses_sent: AtomicU64,
    pulses_rejected: AtomicU64,
    pulses_not_armed: AtomicU64,
    pulses_late: AtomicU64,
    pulses_dropped_late: AtomicU64,
    device_busy: AtomicU64,
    pulses_busy: AtomicU64,
    can_tx_errors: AtomicU64,
    tx_retries: AtomicU64,
    watchdog_trips: AtomicU64,
    trips: AtomicU64,
    commands_refused: AtomicU64,
    fault_code: AtomicU64,
    state: AtomicU8,
    stimulator_state: AtomicU8,
    last_pulse_ns: AtomicU64,
    last_pulse_tick_seq: AtomicU64,
    stimulator_pulses: AtomicU64,
    pulses_applied: AtomicU64,
    pulses_not_applied: AtomicU64,
    wakeups: AtomicU64,
    /// `command_seq << 8 | command_result << 6 | command_reason`: the acknowledgement in one
    /// store, so a reader never sees the seq of one command with the result of another.
    command_ack: AtomicU64,
    /// Liveness of the StimTick publisher (a [`Liveness`] as `u8`), written by the report
    /// thread, read by the forward thread.
    pub liveness: AtomicU8,
    /// Liveness of the DriverCommand publisher (the supervisor), likewise.
    pub supervisor_liveness: AtomicU8,
}

impl SharedStatus {
    /// Stores `c` (forward thread).
    pub fn store(&self, c: &Counters) {
        let r = Ordering::Relaxed;
        self.ticks_received.store(c.ticks_received, r);
        self.ticks_lost.store(c.ticks_lost, r);
        self.ticks_refused.store(c.ticks_refused, r);
        self.pulses_sent.store(c.pulses_sent, r);
        self.pulses_rejected.store(c.pulses_rejected, r);
        self.pulses_not_armed.store(c.pulses_not_armed, r);
        self.pulses_late.store(c.pulses_late, r);
        self.pulses_dropped_late.store(c.pulses_dropped_late, r);
        self.device_busy.store(c.device_busy, r);
        self.pulses_busy.store(c.pulses_busy, r);
        self.can_tx_errors.store(c.can_tx_errors, r);
        self.tx_retries.store(c.tx_retries, r);
        self.watchdog_trips.store(u64::from(c.watchdog_trips), r);
        self.trips.store(u64::from(c.trips), r);
        self.commands_refused.store(c.commands_refused, r);
        self.fault_code.store(u64::from(c.fault_code), r);
        self.state.store(c.state, r);
        self.stimulator_state.store(c.stimulator_state, r);
        self.last_pulse_ns.store(c.last_pulse_ns, r);
        self.last_pulse_tick_seq.store(c.last_pulse_tick_seq, r);
        self.stimulator_pulses
            .store(u64::from(c.stimulator_pulses), r);
        self.pulses_applied.store(c.pulses_applied, r);
        self.pulses_not_applied.store(c.pulses_not_applied, r);
        self.wakeups.store(c.wakeups, r);
        self.command_ack.store(
            (c.command_seq & (DriverCommand::MAX_SEQ - 1)) << 8
                | u64::from(c.command_result & 0x3) << 6
                | u64::from(c.command_reason & 0x3f),
            r,
        );
    }

    /// Reads a snapshot (fields individually consistent; the set may straddle a wake-up).
    pub fn load(&self) -> Counters {
        let r = Ordering::Relaxed;
        let ack = self.command_ack.load(r);
        Counters {
            ticks_received: self.ticks_received.load(r),
            ticks_lost: self.ticks_lost.load(r),
            ticks_refused: self.ticks_refused.load(r),
            pulses_sent: self.pulses_sent.load(r),
            pulses_rejected: self.pulses_rejected.load(r),
            pulses_not_armed: self.pulses_not_armed.load(r),
            pulses_late: self.pulses_late.load(r),
            pulses_dropped_late: self.pulses_dropped_late.load(r),
            device_busy: self.device_busy.load(r),
            pulses_busy: self.pulses_busy.load(r),
            can_tx_errors: self.can_tx_errors.load(r),
            tx_retries: self.tx_retries.load(r),
            watchdog_trips: u32::try_from(self.watchdog_trips.load(r)).unwrap_or(u32::MAX),
            trips: u32::try_from(self.trips.load(r)).unwrap_or(u32::MAX),
            commands_refused: self.commands_refused.load(r),
            fault_code: u16::try_from(self.fault_code.load(r)).unwrap_or(u16::MAX),
            state: self.state.load(r),
            stimulator_state: self.stimulator_state.load(r),
            last_pulse_ns: self.last_pulse_ns.load(r),
            last_pulse_tick_seq: self.last_pulse_tick_seq.load(r),
            stimulator_pulses: u32::try_from(self.stimulator_pulses.load(r)).unwrap_or(0),
            pulses_applied: self.pulses_applied.load(r),
            pulses_not_applied: self.pulses_not_applied.load(r),
            wakeups: self.wakeups.load(r),
            command_seq: ack >> 8,
            command_result: ((ack >> 6) & 0x3) as u8,
            command_reason: (ack & 0x3f) as u8,
        }
    }

    /// The forward loop's wake-up count (its progress, for the systemd watchdog).
    pub fn wakeups(&self) -> &AtomicU64 {
        &self.wakeups
    }

    /// The publisher liveness last stored.
    pub fn liveness(&self) -> Liveness {
        Liveness::from_u8(self.liveness.load(Ordering::Relaxed))
    }

    /// Stores the publisher liveness (report thread).
    pub fn set_liveness(&self, l: Liveness) {
        self.liveness.store(l as u8, Ordering::Relaxed);
    }

    /// The supervisor's liveness last stored.
    pub fn supervisor_liveness(&self) -> Liveness {
        Liveness::from_u8(self.supervisor_liveness.load(Ordering::Relaxed))
    }

    /// Stores the supervisor's liveness (report thread).
    pub fn set_supervisor_liveness(&self, l: Liveness) {
        self.supervisor_liveness.store(l as u8, Ordering::Relaxed);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shared_status_round_trips() {
        let c = Counters {
            ticks_received: 1,
            ticks_lost: 2,
            ticks_refused: 3,
            pulses_sent: 4,
            pulses_rejected: 5,
            pulses_not_armed: 6,
            pulses_late: 17,
            pulses_dropped_late: 18,
            device_busy: 19,
            pulses_busy: 20,
            can_tx_errors: 7,
            tx_retries: 8,
            watchdog_trips: 9,
            trips: 10,
            commands_refused: 11,
            fault_code: 0xFF21,
            state: 2,
            stimulator_state: 3,
            last_pulse_ns: 13,
            last_pulse_tick_seq: 14,
            stimulator_pulses: 15,
            pulses_applied: 21,
            pulses_not_applied: 22,
            wakeups: 16,
            command_seq: (1 << 56) - 1,
            command_result: 2,
            command_reason: 12,
        };
        let s = SharedStatus::default();
        s.store(&c);
        assert_eq!(s.load(), c);
        s.set_liveness(Liveness::Dead);
        assert_eq!(s.liveness(), Liveness::Dead);
    }

    #[test]
    fn queue_sink_counts_overflow() {
        let q = ArrayQueue::new(1);
        let n = AtomicU64::new(0);
        let mut s = QueueSink::new(&q, &n);
        s.emit(DriverEvent::StopResent);
        s.emit(DriverEvent::StopResent);
        assert_eq!((q.len(), n.load(Ordering::Relaxed)), (1, 1));
    }
}
