//! [`ForwardPath`]: the driver's whole decision logic, without I/O threads or clocks.
//!
//! StimTicks, commands, bus events and the publisher's liveness go in, each with the
//! current CLOCK_MONOTONIC time; frames go out through a [`CanTx`] and reports through an
//! [`EventSink`]. Nothing here allocates, locks, logs or reads a clock, so the same code
//! runs on the real-time thread, in the unit tests on simulated time, and in the
//! benchmark on a counting sink.
//!
//! Two orthogonal state variables:
//!
//! * **configuration** of the stimulator (while not armed): NMT enter pre-operational; on
//!   a STATUS showing pre-operational, both CONFIG pages with a configuration id different
//!   from the one the stimulator reports; on a STATUS showing that id, confirmed. No
//!   confirmation within the retry time, or a stimulator that restarts or loses the
//!   configuration, starts it over; an EMCY `config_invalid` ends it (refused). The
//!   stimulator reads back the limits it applied (CONFIG_APPLIED, all pages): limits that
//!   differ in any field end it too (refused), and no Arm is accepted until the read-back
//!   equals what was sent. A read-back still incomplete the retry time
//!   after the confirmation (a lost page) starts the configuration over.
//! * **mode**: disarmed, armed, or the safe state. Only an Arm command arms (after checking
//!   its preconditions: see [`crate::fault::ArmRefusal`]); every fault while armed sends NMT
//!   stop and enters the safe state, which only an Arm command leaves. The driver never
//!   re-arms itself.
//!
//! While armed, the watchdog trips on: no valid StimTick for `tick_timeout`, a StimTick
//! older than `stale_after` on arrival, the final tick, the publisher's node dead or gone,
//! no STATUS for `stimulator_timeout`, NMT start not confirmed within `arm_confirm`; and
//! the bus side trips on an EMCY, bus-off, the link going down, a failed write, lost bus
//! events, and a STATUS whose delivered-pulse count disagrees with the pulses written
//! ([`crate::reconcile`]). In every mode, armed or not, a frame on one of the driver's own
//! identifiers that it did not write trips ([`crate::intrusion`]), and every further one
//! gets another NMT stop. An NMT stop that could not be written is retried until it is;
//! while disarmed, a STATUS that still shows the stimulator operational gets another NMT
//! stop.

use fes_can::{ConfigAssembler, ErrorCode, NmtState, Nodes, Status, StimLimits, StimState};
use fes_rt::msg::{
    CommandRefusal, CommandResult, Contract, DriverCommand, DriverCommandKind, PulseFate, StimTick,
};
use fes_rt::rt::liveness::Liveness;

use crate::applied::{AppliedLedger, OpenPulse};
use crate::event::{
    BringUp, BusErrorKind, BusEvent, Counters, DriverEvent, DriverState, EventSink, FrameKind,
    stimulator_device_state,
};
use crate::fault::{ArmRefusal, Fault};
use crate::interlock::{InterlockLimits, Interlocks, PulseCommand, Verdict, Violation};
use crate::output::{ControlFrame, Disarmed, Output, SendError};
use crate::reconcile::{self, Baseline, PulseWindow};
use crate::tx::{CanTx, TxError};

/// Timing and identity settings of the forward path (from the configuration file).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ForwardSettings {
    /// Node ids on the bus.
    pub nodes: Nodes,
    /// The run's limits sent to the stimulator in CONFIG.
    pub stim_limits: StimLimits,
    /// The driver's own interlocks.
    pub interlocks: InterlockLimits,
    /// Host heartbeat period, ns.
    pub heartbeat_ns: u64,
    /// No valid StimTick for this long trips the watchdog, ns.
    pub tick_timeout_ns: u64,
    /// A StimTick older than this on arrival (publish to receive) trips the watchdog, ns.
    pub stale_after_ns: u64,
    /// No STATUS from the stimulator for this long trips (and refuses an Arm), ns.
    pub stimulator_timeout_ns: u64,
    /// After NMT start the stimulator must report operational within this, ns.
    pub arm_confirm_ns: u64,
    /// An Arm command older than this is refused, ns.
    pub command_max_age_ns: u64,
    /// Bringing the stimulator up starts over when a step is not confirmed in this, ns.
    pub bringup_retry_ns: u64,
    /// Longest sleep of the loop, ns: bus events and liveness changes are acted on at the
    /// latest this long after they arrive.
    pub max_wait_ns: u64,
    /// Trip when the supervisor's node dies or leaves while armed ([`ForwardPath::on_supervisor_liveness`]).
    pub supervisor_watch: bool,
    /// A liveness that stays [`Liveness::Unknown`] longer than this counts as dead, ns.
    pub liveness_unknown_grace_ns: u64,
    /// How long a pulse may wait for a busy transport ([`TxError::Busy`]: ScienceMode 2
    /// waits for each answer) before it is dropped as late, ns.
    pub pulse_lateness_ns: u64,
    /// The shortest interval between pulses the transport delivers, ns (0: no limit, CAN).
    /// An Arm is refused while the generator states a shorter minimum interval.
    pub transport_min_interval_ns: u64,
    /// rt-core's tick period, ns (StimTick `min_gap_ticks` is in ticks).
    pub tick_period_ns: u64,
}

/// A liveness [`Liveness::Unknown`] since `since` has lasted beyond the grace period.
fn unknown_too_long(since: Option<u64>, s: &ForwardSettings, now_ns: u64) -> bool {
    since.is_some_and(|t| now_ns.saturating_sub(t) > s.liveness_unknown_grace_ns)
}

/// Reports what became of the pulse `tick` asked for.
fn outcome(tick: &StimTick, fate: PulseFate, ev: &mut impl EventSink) {
    ev.emit(DriverEvent::Outcome {
        tick_seq: tick.seq,
        tick_t_ns: tick.t_ns,
        fate,
    });
}

/// Reports what the stimulator did with a pulse sent earlier ([`crate::applied`]).
fn account(counters: &mut Counters, pulse: &OpenPulse, fate: PulseFate, ev: &mut impl EventSink) {
    match fate {
        PulseFate::Applied => counters.pulses_applied += 1,
        _ => counters.pulses_not_applied += 1,
    }
    ev.emit(DriverEvent::Outcome {
        tick_seq: pulse.tick_seq,
        tick_t_ns: pulse.tick_t_ns,
        fate,
    });
}

/// A pulse that passed the interlocks while the transport was busy ([`TxError::Busy`]),
/// held until it can be written or is too late.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Deferred {
    command: PulseCommand,
    tick: StimTick,
    since_ns: u64,
}

/// While a pulse waits for the transport, the loop looks again this often, ns.
const DEFERRED_RETRY_NS: u64 = 250_000;

/// A pending NMT stop is not re-sent more often than this, ns.
const STOP_RESEND_NS: u64 = 10_000_000;
/// A command may be this far in the future of the driver's clock (same host), ns.
const COMMAND_FUTURE_TOLERANCE_NS: u64 = 1_000_000;

/// Progress of configuring the stimulator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ConfigState {
    /// Nothing sent yet.
    Idle,
    /// NMT enter pre-operational sent at `sent_ns`; waiting for a pre-operational STATUS.
    Probing { sent_ns: u64 },
    /// CONFIG `id` sent at `sent_ns`; waiting for STATUS to show it.
    Configuring { id: u8, sent_ns: u64 },
    /// Applied and confirmed by STATUS at `at_ns`.
    Confirmed { id: u8, at_ns: u64 },
    /// Refused by the stimulator.
    Refused,
}

/// Armed or not.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    Disarmed,
    Armed { since_ns: u64, confirmed: bool },
    Safe(Fault),
}

/// The forward path (see the module documentation).
#[derive(Debug)]
pub struct ForwardPath<T: CanTx> {
    settings: ForwardSettings,
    interlocks: Interlocks,
    output: Option<Output<T>>,
    config: ConfigState,
    mode: Mode,
    counters: Counters,
    link_up: bool,
    stop_pending: bool,
    last_stop_ns: u64,
    started: bool,
    next_heartbeat_ns: u64,
    last_valid_tick_ns: Option<u64>,
    generator_stopped: bool,
    liveness: Liveness,
    supervisor: Liveness,
    /// Since when each liveness has been [`Liveness::Unknown`] (publisher, supervisor).
    liveness_unknown_since: Option<u64>,
    supervisor_unknown_since: Option<u64>,
    last_status: Option<(Status, u64)>,
    last_command_t_ns: u64,
    /// The supervisor has been seen alive since the last Arm (see [`Self::poll`]).
    supervisor_seen_armed: bool,
    /// PULSE frames written over the last in-flight window ([`crate::reconcile`]).
    pulse_window: PulseWindow,
    /// The reconciliation baseline of the current armed period.
    baseline: Option<Baseline>,
    /// CONFIG_APPLIED pages of the current configuration attempt.
    readback: ConfigAssembler,
    /// The limits the stimulator read back for the current attempt (id, limits).
    applied: Option<(u8, StimLimits)>,
    /// A pulse waiting for a busy transport (at most one: never a burst).
    deferred: Option<Deferred>,
    /// The pulses sent that the stimulator has not accounted for yet.
    ledger: AppliedLedger,
    /// The newest valid StimTick's `min_gap_ticks` (the generator's minimum interval).
    generator_gap_ticks: u16,
}

/// The first limit in which `a` and `b` differ (CONFIG signal name), if any.
pub fn first_difference(a: &StimLimits, b: &StimLimits) -> Option<&'static str> {
    [
        (
            "max_amplitude",
            a.max_amplitude_100ua == b.max_amplitude_100ua,
        ),
        ("max_width", a.max_width_us == b.max_width_us),
        ("min_ipi", a.min_ipi_ms == b.min_ipi_ms),
        ("max_pulses", a.max_pulses == b.max_pulses),
        ("rate_window", a.rate_window_ms == b.rate_window_ms),
        ("watchdog", a.watchdog_ms == b.watchdog_ms),
        ("max_charge", a.max_charge_10nc == b.max_charge_10nc),
    ]
    .into_iter()
    .find_map(|(name, same)| (!same).then_some(name))
}

impl<T: CanTx> ForwardPath<T> {
    /// A forward path writing to `tx`, disarmed, not yet started (call [`Self::start`]).
    pub fn new(settings: ForwardSettings, tx: T) -> Self {
        Self {
            interlocks: Interlocks::new(settings.interlocks),
            output: Some(Output::Disarmed(Disarmed::new(tx, settings.nodes))),
            config: ConfigState::Idle,
            mode: Mode::Disarmed,
            counters: Counters {
                state: DriverState::Starting.device_state() as u8,
                stimulator_state: fes_rt::msg::DeviceState::Unknown as u8,
                ..Counters::default()
            },
            settings,
            link_up: true,
            stop_pending: false,
            last_stop_ns: 0,
            started: false,
            next_heartbeat_ns: 0,
            last_valid_tick_ns: None,
            generator_stopped: false,
            liveness: Liveness::Unknown,
            supervisor: Liveness::Unknown,
            liveness_unknown_since: None,
            supervisor_unknown_since: None,
            last_status: None,
            last_command_t_ns: 0,
            supervisor_seen_armed: false,
            pulse_window: PulseWindow::new(settings.stimulator_timeout_ns),
            baseline: None,
            readback: ConfigAssembler::new(),
            applied: None,
            deferred: None,
            // Twice the in-flight window STATUS reconciliation allows a pulse to be
            // uncounted: a pulse still open then will not be counted.
            ledger: AppliedLedger::new(2 * settings.stimulator_timeout_ns),
            generator_gap_ticks: 0,
        }
    }

    /// The settings.
    pub fn settings(&self) -> &ForwardSettings {
        &self.settings
    }

    /// The counters.
    pub fn counters(&self) -> &Counters {
        &self.counters
    }

    /// The transmit side.
    pub fn tx(&self) -> &T {
        match &self.output {
            Some(o) => o.tx(),
            None => unreachable!("the output is only taken within a transition"),
        }
    }

    /// The driver's state.
    pub fn state(&self) -> DriverState {
        match self.mode {
            Mode::Armed { .. } => DriverState::Armed,
            Mode::Safe(fault) => DriverState::SafeState(fault),
            Mode::Disarmed => match self.config {
                ConfigState::Confirmed { .. } => DriverState::Disarmed,
                ConfigState::Refused => DriverState::ConfigRefused,
                _ => DriverState::Starting,
            },
        }
    }

    /// True when armed.
    pub fn is_armed(&self) -> bool {
        matches!(self.mode, Mode::Armed { .. })
    }

    /// The confirmed configuration id, if any.
    pub fn config_id(&self) -> Option<u8> {
        match self.config {
            ConfigState::Confirmed { id, .. } => Some(id),
            _ => None,
        }
    }

    /// Starts: boot-up heartbeat, then NMT enter pre-operational (bringing the stimulator
    /// up). Call once, before anything else.
    pub fn start(&mut self, now_ns: u64, ev: &mut impl EventSink) {
        let before = self.state();
        self.started = true;
        self.control(ControlFrame::Heartbeat(NmtState::BootUp), now_ns, ev);
        self.next_heartbeat_ns = now_ns + self.settings.heartbeat_ns;
        self.probe(now_ns, ev);
        self.finish(before, ev);
    }

    /// Handles one StimTick received at `now_ns`.
    pub fn on_tick(&mut self, tick: &StimTick, now_ns: u64, ev: &mut impl EventSink) {
        let before = self.state();
        self.counters.ticks_received += 1;
        let age_ns = now_ns.saturating_sub(tick.t_publish_ns);
        if age_ns > self.settings.stale_after_ns {
            self.counters.ticks_refused += 1;
            ev.emit(DriverEvent::StaleTick {
                seq: tick.seq,
                age_ns,
            });
            if tick.pulse != 0 {
                outcome(tick, PulseFate::Refused, ev);
            }
            if self.is_armed() {
                self.trip(Fault::StaleTick { age_ns }, now_ns, ev);
            }
            self.finish(before, ev);
            return;
        }
        let mut assessment = self.interlocks.assess(tick, now_ns);
        if !self.is_armed()
            && matches!(
                assessment.verdict,
                Verdict::Rejected {
                    violation: Violation::OutOfOrder { .. },
                    ..
                }
            )
        {
            // A restarted generator (its `seq` starts again at 1). Nothing is forwarded
            // now, so follow it: otherwise every tick of it would be refused and it could
            // never be armed. While armed, its ticks stay refused and the watchdog trips.
            self.interlocks.resync_sequence();
            assessment = self.interlocks.assess(tick, now_ns);
        }
        if assessment.lost_ticks > 0 {
            self.counters.ticks_lost += assessment.lost_ticks;
            ev.emit(DriverEvent::TicksLost {
                seq: tick.seq,
                count: assessment.lost_ticks,
            });
        }
        if let Verdict::Rejected { violation, pulse } = assessment.verdict
            && violation.is_stream_fault()
        {
            self.counters.ticks_refused += 1;
            self.reject(tick, violation, pulse, ev);
            self.finish(before, ev);
            return;
        }
        self.last_valid_tick_ns = Some(now_ns);
        self.generator_gap_ticks = tick.min_gap_ticks;
        if let Some(o) = self.output.as_mut() {
            o.contraction_ahead(tick.has(StimTick::FLAG_CONTRACTION_AHEAD));
        }
        self.generator_stopped = tick.has(StimTick::FLAG_FINAL);
        if self.generator_stopped && self.is_armed() {
            self.trip(Fault::GeneratorStopped, now_ns, ev);
        }
        match assessment.verdict {
            Verdict::NoPulse => {}
            Verdict::Rejected { violation, pulse } => self.reject(tick, violation, pulse, ev),
            Verdict::Pulse(command) => self.pulse(tick, command, now_ns, ev),
        }
        self.finish(before, ev);
    }

    /// Counts and reports a tick the interlocks refused, and its pulse as refused.
    fn reject(
        &mut self,
        tick: &StimTick,
        violation: Violation,
        pulse: bool,
        ev: &mut impl EventSink,
    ) {
        self.counters.pulses_rejected += u64::from(pulse);
        ev.emit(DriverEvent::Rejected {
            tick_seq: tick.seq,
            violation,
            pulse,
        });
        if pulse {
            outcome(tick, PulseFate::Refused, ev);
        }
    }

    /// Writes the pulse the interlocks accepted, or keeps it for the transport's next
    /// free moment.
    fn pulse(
        &mut self,
        tick: &StimTick,
        command: PulseCommand,
        now_ns: u64,
        ev: &mut impl EventSink,
    ) {
        // A newer decision takes the place of a pulse still waiting for the transport:
        // the two never go out as a burst.
        self.drop_deferred(PulseFate::Late, now_ns, ev);
        let written = if self.write_keeps_interval(now_ns) {
            self.forward(&command, now_ns, ev)
        } else {
            None
        };
        match written {
            Some(fate) => outcome(tick, fate, ev),
            None => {
                self.deferred = Some(Deferred {
                    command,
                    tick: *tick,
                    since_ns: now_ns,
                });
            }
        }
    }

    /// Sends an accepted pulse if armed; what became of it, `None` when the transport is
    /// busy (nothing written: to be tried again).
    fn forward(
        &mut self,
        command: &PulseCommand,
        now_ns: u64,
        ev: &mut impl EventSink,
    ) -> Option<PulseFate> {
        let result = match self.output.as_mut() {
            Some(Output::Armed(armed)) => armed.send_pulse(command),
            _ => {
                self.counters.pulses_not_armed += 1;
                return Some(PulseFate::NotArmed);
            }
        };
        match result {
            Ok(sent) => {
                self.counters.pulses_sent += 1;
                self.pulse_window.record(now_ns);
                self.counters.tx_retries += u64::from(sent.done.retries);
                self.counters.last_pulse_ns = sent.done.written_ns.max(now_ns);
                self.counters.last_pulse_tick_seq = command.tick_seq;
                let counters = &mut self.counters;
                self.ledger.on_sent(
                    OpenPulse::new(
                        command.tick_seq,
                        command.t_ns,
                        sent.pulse.seq,
                        counters.last_pulse_ns,
                    ),
                    |p, fate| account(counters, p, fate, ev),
                );
                ev.emit(DriverEvent::PulseSent {
                    tick_seq: command.tick_seq,
                    pulse_seq: sent.pulse.seq,
                    t_publish_ns: command.t_publish_ns,
                    written_ns: sent.done.written_ns,
                    write_ns: sent.done.write_ns,
                    retries: sent.done.retries,
                });
                Some(PulseFate::Sent)
            }
            Err(SendError::Tx(TxError::Busy)) => None,
            Err(error) => {
                self.tx_problem(FrameKind::Pulse, error, now_ns, ev);
                Some(PulseFate::NotWritten)
            }
        }
    }

    /// The pulse waiting for the transport, if any: written once the transport is free
    /// and the interval since the last pulse written is kept
    /// ([`Self::write_keeps_interval`]), dropped as late past
    /// [`ForwardSettings::pulse_lateness_ns`], or not armed any more.
    fn retry_deferred(&mut self, now_ns: u64, ev: &mut impl EventSink) {
        let Some(d) = self.deferred else {
            return;
        };
        if !self.is_armed() {
            self.drop_deferred(PulseFate::NotArmed, now_ns, ev);
            return;
        }
        if now_ns.saturating_sub(d.since_ns) > self.settings.pulse_lateness_ns {
            self.drop_deferred(PulseFate::Late, now_ns, ev);
            return;
        }
        if !self.write_keeps_interval(now_ns) {
            return;
        }
        if let Some(fate) = self.forward(&d.command, now_ns, ev) {
            self.deferred = None;
            if fate == PulseFate::Sent {
                self.counters.pulses_late += 1;
                ev.emit(DriverEvent::PulseLate {
                    tick_seq: d.tick.seq,
                    waited_ns: now_ns.saturating_sub(d.since_ns),
                    sent: true,
                });
            }
            outcome(&d.tick, fate, ev);
        }
    }

    /// Whether a PULSE written at `now_ns` keeps the stimulator's minimum inter-pulse
    /// interval (`[stimulator] min_ipi_ms`) after the last one written. The interlocks
    /// judge decisions; a transport that makes pulses wait (ScienceMode 2, whose device
    /// takes no CONFIG and enforces no interval) could otherwise write a late pulse and
    /// the next one closer than that. On a transport that never waits (CAN, lateness 0)
    /// the stimulator itself enforces it: always true.
    fn write_keeps_interval(&self, now_ns: u64) -> bool {
        let min_ns = u64::from(self.settings.stim_limits.min_ipi_ms) * 1_000_000;
        self.settings.pulse_lateness_ns == 0
            || self.counters.last_pulse_ns == 0
            || now_ns >= self.counters.last_pulse_ns + min_ns
    }

    /// Gives up the pulse waiting for the transport, if any, with `fate`.
    fn drop_deferred(&mut self, fate: PulseFate, now_ns: u64, ev: &mut impl EventSink) {
        let Some(d) = self.deferred.take() else {
            return;
        };
        match fate {
            PulseFate::NotArmed => self.counters.pulses_not_armed += 1,
            _ => {
                self.counters.pulses_dropped_late += 1;
                ev.emit(DriverEvent::PulseLate {
                    tick_seq: d.tick.seq,
                    waited_ns: now_ns.saturating_sub(d.since_ns),
                    sent: false,
                });
            }
        }
        outcome(&d.tick, fate, ev);
    }

    /// Counts and reports a failed write; a down link or a hard failure trips.
    fn tx_problem(
        &mut self,
        frame: FrameKind,
        error: SendError,
        now_ns: u64,
        ev: &mut impl EventSink,
    ) {
        if let SendError::Tx(TxError::Busy) = error {
            // Not written yet, not a failure: the periodic frames go in the next gap.
            return;
        }
        self.counters.can_tx_errors += 1;
        ev.emit(DriverEvent::TxProblem { frame, error });
        match error {
            SendError::Tx(TxError::Dropped { attempts }) => {
                self.counters.tx_retries += u64::from(attempts.saturating_sub(1));
            }
            SendError::Tx(TxError::LinkDown { .. }) => {
                self.link_up = false;
                if self.is_armed() {
                    self.trip(Fault::LinkDown, now_ns, ev);
                }
            }
            SendError::Tx(TxError::Failed { errno }) => {
                if self.is_armed() {
                    self.trip(Fault::TxFailed { errno }, now_ns, ev);
                }
            }
            SendError::Tx(TxError::Busy) | SendError::Encode(_) => {}
        }
    }

    /// Sends a control frame, handling failures.
    fn control(&mut self, frame: ControlFrame, now_ns: u64, ev: &mut impl EventSink) -> bool {
        let result = match self.output.as_mut() {
            Some(o) => o.send_control(&frame),
            None => unreachable!("the output is only taken within a transition"),
        };
        match result {
            Ok(done) => {
                self.counters.tx_retries += u64::from(done.retries);
                true
            }
            Err(error) => {
                let kind = match frame {
                    ControlFrame::Heartbeat(_) => FrameKind::Heartbeat,
                    ControlFrame::Config(_) => FrameKind::Config,
                    ControlFrame::Stop | ControlFrame::EnterPreOperational => FrameKind::Nmt,
                };
                self.tx_problem(kind, error, now_ns, ev);
                false
            }
        }
    }

    /// Enters the safe state: NMT stop (retried later if it cannot be written now).
    fn trip(&mut self, fault: Fault, now_ns: u64, ev: &mut impl EventSink) {
        self.counters.trips += 1;
        if fault.is_watchdog() {
            self.counters.watchdog_trips += 1;
        }
        self.counters.fault_code = fault.code();
        self.mode = Mode::Safe(fault);
        let stop_sent = self.send_stop(now_ns, ev);
        ev.emit(DriverEvent::Tripped { fault, stop_sent });
    }

    /// Disarms the output (if armed) with NMT stop, or sends NMT stop; remembers a stop
    /// that could not be written.
    fn send_stop(&mut self, now_ns: u64, ev: &mut impl EventSink) -> bool {
        self.last_stop_ns = now_ns;
        let result = match self.output.take() {
            Some(Output::Armed(armed)) => {
                let (disarmed, result) = armed.disarm();
                self.output = Some(Output::Disarmed(disarmed));
                result.map(|_| ())
            }
            Some(Output::Disarmed(mut d)) => {
                let result = d.send_control(&ControlFrame::Stop).map(|_| ());
                self.output = Some(Output::Disarmed(d));
                result
            }
            None => unreachable!("the output is only taken within a transition"),
        };
        match result {
            Ok(()) => {
                self.stop_pending = false;
                true
            }
            Err(SendError::Tx(TxError::Busy)) => {
                // The transport awaits the answer to its previous command: the stop goes
                // as soon as it may (resent from `poll`). Disarmed already: no pulse
                // leaves meanwhile.
                self.stop_pending = true;
                false
            }
            Err(error) => {
                self.stop_pending = true;
                self.counters.can_tx_errors += 1;
                if let SendError::Tx(TxError::LinkDown { .. }) = error {
                    self.link_up = false;
                }
                ev.emit(DriverEvent::TxProblem {
                    frame: FrameKind::Nmt,
                    error,
                });
                false
            }
        }
    }

    /// Handles one command received at `now_ns`. Stops are obeyed whatever their age;
    /// an Arm must be fresh and newer than the last command.
    pub fn on_command(&mut self, command: &DriverCommand, now_ns: u64, ev: &mut impl EventSink) {
        let before = self.state();
        if let Err(error) = command.validate() {
            self.counters.commands_refused += 1;
            if (1..DriverCommand::MAX_SEQ).contains(&command.seq) {
                self.acknowledge(command.seq, Some(CommandRefusal::InvalidCommand));
            }
            ev.emit(DriverEvent::CommandInvalid {
                seq: command.seq,
                error,
            });
            self.finish(before, ev);
            return;
        }
        let fresh = command.t_ns <= now_ns + COMMAND_FUTURE_TOLERANCE_NS
            && now_ns.saturating_sub(command.t_ns) <= self.settings.command_max_age_ns
            && command.t_ns > self.last_command_t_ns;
        if fresh {
            // Only a command in its time window sets the order (a bogus future time must not
            // block the next genuine one).
            self.last_command_t_ns = command.t_ns;
        }
        match command.kind() {
            Ok(DriverCommandKind::Arm) => {
                if fresh {
                    self.try_arm(command.seq, now_ns, ev);
                } else {
                    self.refuse_arm(command.seq, ArmRefusal::StaleCommand, ev);
                }
            }
            Ok(DriverCommandKind::Disarm) => {
                self.send_stop(now_ns, ev);
                // A disarm never clears the safe state (only an Arm does).
                if self.is_armed() {
                    self.mode = Mode::Disarmed;
                }
                self.acknowledge(command.seq, None);
                ev.emit(DriverEvent::Disarmed {
                    command_seq: command.seq,
                });
            }
            Ok(DriverCommandKind::SafeStop) => {
                if let Mode::Safe(_) = self.mode {
                    // Already safe (the supervisor re-sends a SafeStop until it reads the
                    // acknowledgement): the stop again, idempotent, but no new trip, so
                    // the fault that made it safe stays the named one.
                    self.send_stop(now_ns, ev);
                } else {
                    self.trip(Fault::SafeStopCommand, now_ns, ev);
                }
                self.acknowledge(command.seq, None);
            }
            // validate() above decoded the kind already.
            Err(_) => {}
        }
        self.finish(before, ev);
    }

    /// Records what was done with command `seq` (the acknowledgement in DriverStatus):
    /// accepted, or refused for `refusal`.
    fn acknowledge(&mut self, seq: u64, refusal: Option<CommandRefusal>) {
        self.counters.command_seq = seq;
        (self.counters.command_result, self.counters.command_reason) = match refusal {
            None => (CommandResult::Accepted as u8, 0),
            Some(r) => (CommandResult::Refused as u8, r as u8),
        };
    }

    fn refuse_arm(&mut self, command_seq: u64, refusal: ArmRefusal, ev: &mut impl EventSink) {
        self.counters.commands_refused += 1;
        self.acknowledge(command_seq, Some(refusal.reason()));
        ev.emit(DriverEvent::ArmRefused {
            command_seq,
            refusal,
        });
    }

    /// The first unmet precondition of arming, if any.
    fn arm_refusal(&self, now_ns: u64) -> Option<ArmRefusal> {
        let s = &self.settings;
        if let Some((_, applied)) = self.applied
            && let Some(field) = first_difference(&applied, &s.stim_limits)
        {
            return Some(ArmRefusal::StimulatorLimitsDiffer { field });
        }
        let Some(expected) = self.config_id() else {
            return Some(ArmRefusal::NotConfigured);
        };
        // The limits in force, as the stimulator reports them, must be exactly ours.
        if self.applied != Some((expected, s.stim_limits)) {
            return Some(ArmRefusal::LimitsNotReadBack);
        }
        if !self.link_up || self.stop_pending {
            return Some(ArmRefusal::LinkDown);
        }
        let Some((status, at)) = self.last_status else {
            return Some(ArmRefusal::StimulatorSilent);
        };
        if now_ns.saturating_sub(at) > s.stimulator_timeout_ns {
            return Some(ArmRefusal::StimulatorSilent);
        }
        if status.config_id != expected {
            return Some(ArmRefusal::StimulatorConfigMismatch {
                reported: status.config_id,
                expected,
            });
        }
        match self.last_valid_tick_ns {
            Some(t) if now_ns.saturating_sub(t) <= s.tick_timeout_ns => {}
            _ => return Some(ArmRefusal::NoTicks),
        }
        if self.liveness != Liveness::Alive {
            return Some(ArmRefusal::PublisherNotAlive);
        }
        // The command itself proves a publisher existed when it was sent; a node seen
        // dead means it came from a sample its dead sender left behind.
        if s.supervisor_watch
            && (matches!(self.supervisor, Liveness::Dead | Liveness::Foreign)
                || unknown_too_long(self.supervisor_unknown_since, s, now_ns))
        {
            return Some(ArmRefusal::SupervisorDead);
        }
        if self.generator_stopped {
            return Some(ArmRefusal::GeneratorStopped);
        }
        let generator_ns = u64::from(self.generator_gap_ticks) * s.tick_period_ns;
        if generator_ns < s.transport_min_interval_ns {
            return Some(ArmRefusal::GeneratorGapTooShort {
                generator_us: generator_ns / 1000,
                transport_us: s.transport_min_interval_ns / 1000,
            });
        }
        None
    }

    fn try_arm(&mut self, command_seq: u64, now_ns: u64, ev: &mut impl EventSink) {
        if self.is_armed() {
            self.acknowledge(command_seq, None);
            return;
        }
        if let Some(refusal) = self.arm_refusal(now_ns) {
            self.refuse_arm(command_seq, refusal, ev);
            return;
        }
        match self.output.take() {
            Some(Output::Disarmed(disarmed)) => match disarmed.arm() {
                Ok(armed) => {
                    self.output = Some(Output::Armed(armed));
                    // arm_refusal() required a recent STATUS.
                    self.baseline = self.last_status.map(|(status, _)| Baseline {
                        delivered: status.pulses_delivered,
                        sent: self.pulses_to_deliver(),
                        carry: self.pulse_window.count(now_ns),
                    });
                    self.mode = Mode::Armed {
                        since_ns: now_ns,
                        confirmed: false,
                    };
                    self.interlocks.resync_sequence();
                    self.supervisor_seen_armed = self.supervisor == Liveness::Alive;
                    self.acknowledge(command_seq, None);
                    ev.emit(DriverEvent::Armed { command_seq });
                }
                Err((disarmed, error)) => {
                    self.output = Some(Output::Disarmed(disarmed));
                    self.tx_problem(FrameKind::Nmt, error, now_ns, ev);
                    self.refuse_arm(command_seq, ArmRefusal::TxFailed, ev);
                }
            },
            other => self.output = other,
        }
    }

    /// Handles one bus event received by `now_ns`.
    pub fn on_bus(&mut self, event: BusEvent, now_ns: u64, ev: &mut impl EventSink) {
        let before = self.state();
        match event {
            BusEvent::Status(status) => self.on_status(status, now_ns, ev),
            BusEvent::Emcy(emcy) => {
                ev.emit(DriverEvent::StimulatorEmcy(emcy));
                // An EMCY naming a pulse (seq 0: none) rejected it: not applied.
                if emcy.seq != 0 {
                    self.ledger.on_rejected(emcy.seq);
                }
                if emcy.code == ErrorCode::ConfigInvalid
                    && matches!(self.config, ConfigState::Configuring { .. })
                {
                    self.config = ConfigState::Refused;
                    ev.emit(DriverEvent::BringUp(BringUp::ConfigRefused {
                        detail: emcy.detail,
                    }));
                }
                if emcy.code != ErrorCode::NoError && self.is_armed() {
                    self.trip(
                        Fault::StimulatorEmcy {
                            code: emcy.code,
                            detail: emcy.detail,
                        },
                        now_ns,
                        ev,
                    );
                }
            }
            BusEvent::StimHeartbeat(state) => {
                if state == NmtState::BootUp {
                    ev.emit(DriverEvent::Bus(event));
                    self.stimulator_lost(now_ns, ev);
                }
            }
            BusEvent::BusError(kind) => {
                ev.emit(DriverEvent::Bus(event));
                if kind == BusErrorKind::BusOff {
                    self.link_up = false;
                    if self.is_armed() {
                        self.trip(Fault::BusOff, now_ns, ev);
                    }
                }
            }
            BusEvent::LinkDown => {
                if self.link_up {
                    ev.emit(DriverEvent::Bus(event));
                }
                self.link_up = false;
                if self.is_armed() {
                    self.trip(Fault::LinkDown, now_ns, ev);
                }
            }
            BusEvent::LinkUp => {
                if !self.link_up {
                    ev.emit(DriverEvent::Bus(event));
                }
                self.link_up = true;
                if self.stop_pending && self.send_stop(now_ns, ev) {
                    ev.emit(DriverEvent::StopResent);
                }
            }
            BusEvent::EventsLost => {
                ev.emit(DriverEvent::Bus(event));
                if self.is_armed() {
                    self.trip(Fault::BusEventsLost, now_ns, ev);
                }
            }
            BusEvent::Intrusion { cob_id, kind } => {
                ev.emit(DriverEvent::Bus(event));
                if matches!(self.mode, Mode::Safe(Fault::Intrusion { .. })) {
                    // Tripped on an intrusion already: stop again at once (the intruder
                    // may have started the stimulator since), without a new trip.
                    if self.send_stop(now_ns, ev) {
                        ev.emit(DriverEvent::StopResent);
                    }
                } else {
                    self.trip(Fault::Intrusion { cob_id, kind }, now_ns, ev);
                }
            }
            BusEvent::ConfigApplied(page) => self.on_config_applied(&page, now_ns, ev),
            BusEvent::DeviceBusy { pulse } => {
                self.counters.device_busy += 1;
                if pulse {
                    // Answered busy: not delivered, and not to be counted as written in
                    // STATUS reconciliation.
                    self.counters.pulses_busy += 1;
                    self.ledger.on_busy();
                }
                ev.emit(DriverEvent::Bus(event));
            }
        }
        self.finish(before, ev);
    }

    /// The stimulator restarted or lost our configuration.
    fn stimulator_lost(&mut self, now_ns: u64, ev: &mut impl EventSink) {
        let counters = &mut self.counters;
        self.ledger
            .on_stimulator_lost(|p, fate| account(counters, p, fate, ev));
        if self.is_armed() {
            self.trip(Fault::StimulatorReset, now_ns, ev);
        }
        if !matches!(self.config, ConfigState::Probing { .. } | ConfigState::Idle) {
            ev.emit(DriverEvent::BringUp(BringUp::StimulatorLost));
            self.probe(now_ns, ev);
        }
    }

    fn on_status(&mut self, status: Status, now_ns: u64, ev: &mut impl EventSink) {
        let changed = self
            .last_status
            .is_none_or(|(s, _)| s.state != status.state);
        self.last_status = Some((status, now_ns));
        self.counters.stimulator_state = stimulator_device_state(status.state) as u8;
        self.counters.stimulator_pulses = status.pulses_delivered;
        let counters = &mut self.counters;
        self.ledger.on_status(status.pulses_delivered, |p, fate| {
            account(counters, p, fate, ev)
        });
        if changed {
            ev.emit(DriverEvent::StimulatorState {
                state: status.state,
                pulses_delivered: status.pulses_delivered,
            });
        }
        let operational = matches!(status.state, StimState::Armed | StimState::Stimulating);
        match self.mode {
            Mode::Armed {
                since_ns,
                confirmed,
            } => {
                if Some(status.config_id) != self.config_id() {
                    self.stimulator_lost(now_ns, ev);
                    return;
                }
                if let Some(base) = self.baseline
                    && let Some(fault) = reconcile::check(
                        &base,
                        status.pulses_delivered,
                        self.pulses_to_deliver(),
                        self.pulse_window.count(now_ns),
                    )
                {
                    self.trip(fault, now_ns, ev);
                    return;
                }
                if operational && !confirmed {
                    self.mode = Mode::Armed {
                        since_ns,
                        confirmed: true,
                    };
                } else if !operational && confirmed {
                    self.trip(Fault::StimulatorNotOperational, now_ns, ev);
                }
                return;
            }
            Mode::Disarmed | Mode::Safe(_) => {
                if operational
                    && now_ns.saturating_sub(self.last_stop_ns) >= STOP_RESEND_NS
                    && self.link_up
                {
                    // Not armed, yet the stimulator is operational: stop it (again).
                    if self.send_stop(now_ns, ev) {
                        ev.emit(DriverEvent::StopResent);
                    }
                }
            }
        }
        match self.config {
            ConfigState::Probing { .. } if status.state == StimState::PreOperational => {
                // A different id, so that an old configuration cannot confirm ours.
                let id = status.config_id % 255 + 1;
                let mut ok = true;
                for page in self.settings.stim_limits.to_pages(id) {
                    ok &= self.control(ControlFrame::Config(page), now_ns, ev);
                }
                if ok {
                    self.config = ConfigState::Configuring {
                        id,
                        sent_ns: now_ns,
                    };
                    ev.emit(DriverEvent::BringUp(BringUp::ConfigSent { config_id: id }));
                }
            }
            ConfigState::Configuring { id, .. }
                if status.config_id == id && status.state == StimState::PreOperational =>
            {
                self.config = ConfigState::Confirmed { id, at_ns: now_ns };
                ev.emit(DriverEvent::BringUp(BringUp::ConfigConfirmed {
                    config_id: id,
                }));
            }
            ConfigState::Confirmed { id, .. } if status.config_id != id => {
                self.stimulator_lost(now_ns, ev);
            }
            _ => {}
        }
    }

    /// A CONFIG_APPLIED page: collects the read-back of the current attempt; limits that
    /// differ from the ones sent refuse the configuration, and while armed trip the
    /// driver (what the stimulator enforces changed under it: a CONFIG another sender
    /// wrote, or a stimulator that changed its limits).
    fn on_config_applied(&mut self, page: &fes_can::Config, now_ns: u64, ev: &mut impl EventSink) {
        let id = match self.config {
            ConfigState::Configuring { id, .. } | ConfigState::Confirmed { id, .. } => id,
            _ => return,
        };
        if page.config_id != id {
            return;
        }
        let Some((config_id, limits)) = self.readback.push(page) else {
            return;
        };
        self.applied = Some((config_id, limits));
        let differs = first_difference(&limits, &self.settings.stim_limits);
        ev.emit(DriverEvent::BringUp(BringUp::LimitsReadBack {
            config_id,
            differs,
        }));
        match differs {
            Some(field) if self.is_armed() => {
                self.config = ConfigState::Refused;
                self.trip(Fault::LimitsChanged { field }, now_ns, ev);
            }
            Some(_) => self.config = ConfigState::Refused,
            None => {}
        }
    }

    /// Sends NMT enter pre-operational and waits for the stimulator to show it.
    fn probe(&mut self, now_ns: u64, ev: &mut impl EventSink) {
        self.readback.clear();
        self.applied = None;
        if self.control(ControlFrame::EnterPreOperational, now_ns, ev) {
            ev.emit(DriverEvent::BringUp(BringUp::PreOperationalSent));
        }
        // Even when the write failed: the retry timer starts over from here.
        self.config = ConfigState::Probing { sent_ns: now_ns };
    }

    /// Takes the publisher liveness the report thread found.
    pub fn on_liveness(&mut self, liveness: Liveness, now_ns: u64, ev: &mut impl EventSink) {
        if liveness == self.liveness {
            return;
        }
        let before = self.state();
        self.liveness = liveness;
        self.liveness_unknown_since = (liveness == Liveness::Unknown).then_some(now_ns);
        ev.emit(DriverEvent::Liveness(liveness));
        if self.is_armed() {
            match liveness {
                Liveness::Dead => self.trip(Fault::PublisherDead, now_ns, ev),
                Liveness::NoPublisher => self.trip(Fault::PublisherGone, now_ns, ev),
                Liveness::Foreign => {
                    self.trip(Fault::ForeignPublisher { supervisor: false }, now_ns, ev)
                }
                Liveness::Alive | Liveness::Unknown => {}
            }
        }
        self.finish(before, ev);
    }

    /// Takes the supervisor's liveness (its DriverCommand publisher's node) the report
    /// thread found. With `supervisor_watch`, while armed: dead → [`Fault::SupervisorDead`],
    /// no publisher → [`Fault::SupervisorGone`]; and not seen alive within the arm
    /// confirmation time of an Arm → the same, from [`Self::poll`]. Nothing re-arms when it
    /// comes back.
    pub fn on_supervisor_liveness(
        &mut self,
        liveness: Liveness,
        now_ns: u64,
        ev: &mut impl EventSink,
    ) {
        if liveness == self.supervisor {
            return;
        }
        let before = self.state();
        self.supervisor = liveness;
        self.supervisor_unknown_since = (liveness == Liveness::Unknown).then_some(now_ns);
        if liveness == Liveness::Alive {
            self.supervisor_seen_armed = true;
        }
        ev.emit(DriverEvent::SupervisorLiveness(liveness));
        if self.settings.supervisor_watch && self.is_armed() {
            match liveness {
                Liveness::Dead => self.trip(Fault::SupervisorDead, now_ns, ev),
                Liveness::NoPublisher => self.trip(Fault::SupervisorGone, now_ns, ev),
                Liveness::Foreign => {
                    self.trip(Fault::ForeignPublisher { supervisor: true }, now_ns, ev)
                }
                Liveness::Alive | Liveness::Unknown => {}
            }
        }
        self.finish(before, ev);
    }

    /// PULSE frames written that the stimulator should count as delivered: all but those
    /// it answered busy.
    fn pulses_to_deliver(&self) -> u64 {
        self.counters.pulses_sent - self.counters.pulses_busy
    }

    /// Runs the timers due at `now_ns`: watchdogs, bring-up retries, a pending stop, a
    /// pulse waiting for the transport, the heartbeat, the account of pulses no STATUS
    /// counted.
    pub fn poll(&mut self, now_ns: u64, ev: &mut impl EventSink) {
        let before = self.state();
        let s = self.settings;
        let counters = &mut self.counters;
        self.ledger
            .expire(now_ns, |p, fate| account(counters, p, fate, ev));
        if let Mode::Armed {
            since_ns,
            confirmed,
        } = self.mode
        {
            let silent_ns = self
                .last_valid_tick_ns
                .map_or(u64::MAX, |t| now_ns.saturating_sub(t));
            let status_silent_ns = self
                .last_status
                .map_or(u64::MAX, |(_, at)| now_ns.saturating_sub(at));
            if silent_ns > s.tick_timeout_ns {
                self.trip(Fault::TickTimeout { silent_ns }, now_ns, ev);
            } else if status_silent_ns > s.stimulator_timeout_ns {
                self.trip(
                    Fault::StimulatorSilent {
                        silent_ns: status_silent_ns,
                    },
                    now_ns,
                    ev,
                );
            } else if !confirmed && now_ns.saturating_sub(since_ns) > s.arm_confirm_ns {
                self.trip(Fault::StimulatorNotOperational, now_ns, ev);
            } else if unknown_too_long(self.liveness_unknown_since, &s, now_ns) {
                // A node whose state cannot be read for this long is taken as dead.
                self.trip(Fault::PublisherDead, now_ns, ev);
            } else if s.supervisor_watch
                && unknown_too_long(self.supervisor_unknown_since, &s, now_ns)
            {
                self.trip(Fault::SupervisorDead, now_ns, ev);
            } else if s.supervisor_watch
                && !self.supervisor_seen_armed
                && now_ns.saturating_sub(since_ns) > s.arm_confirm_ns
            {
                // An Arm is accepted before the liveness check has seen its sender (the
                // check lags the command); the sender must then be seen alive within the
                // arm confirmation time. Without this, a supervisor gone right after its
                // Arm left the value at "no publisher", unchanged, and never tripped
                // (found by the forward-path property test).
                let fault = if self.supervisor == Liveness::Dead {
                    Fault::SupervisorDead
                } else {
                    Fault::SupervisorGone
                };
                self.trip(fault, now_ns, ev);
            }
        } else {
            match self.config {
                ConfigState::Probing { sent_ns } | ConfigState::Configuring { sent_ns, .. }
                    if now_ns.saturating_sub(sent_ns) > s.bringup_retry_ns =>
                {
                    ev.emit(DriverEvent::BringUp(BringUp::Retry));
                    self.probe(now_ns, ev);
                }
                // Confirmed, but the read-back of the applied limits (CONFIG_APPLIED) is
                // incomplete: a lost page would otherwise refuse every Arm until a restart.
                // The configuration starts over with a fresh id, so the stimulator reads
                // back again.
                ConfigState::Confirmed { at_ns, .. }
                    if self.applied.is_none()
                        && now_ns.saturating_sub(at_ns) > s.bringup_retry_ns =>
                {
                    ev.emit(DriverEvent::BringUp(BringUp::Retry));
                    self.probe(now_ns, ev);
                }
                _ => {}
            }
        }
        self.retry_deferred(now_ns, ev);
        if self.stop_pending
            && self.link_up
            && now_ns.saturating_sub(self.last_stop_ns) >= STOP_RESEND_NS
            && self.send_stop(now_ns, ev)
        {
            ev.emit(DriverEvent::StopResent);
        }
        if now_ns >= self.next_heartbeat_ns {
            let state = self.host_nmt_state();
            self.control(ControlFrame::Heartbeat(state), now_ns, ev);
            self.next_heartbeat_ns += s.heartbeat_ns;
            if self.next_heartbeat_ns <= now_ns {
                // Late by more than a period: keep the period, do not send a burst.
                self.next_heartbeat_ns = now_ns + s.heartbeat_ns;
            }
        }
        self.finish(before, ev);
    }

    /// The host's NMT state for its heartbeat.
    fn host_nmt_state(&self) -> NmtState {
        match self.mode {
            Mode::Armed { .. } => NmtState::Operational,
            Mode::Safe(_) => NmtState::Stopped,
            Mode::Disarmed => NmtState::PreOperational,
        }
    }

    /// When the loop must wake next at the latest, ns (never before `now_ns`, never later
    /// than `now_ns + max_wait`).
    pub fn next_deadline(&self, now_ns: u64) -> u64 {
        let s = &self.settings;
        let mut d = self.next_heartbeat_ns.min(now_ns + s.max_wait_ns);
        if self.deferred.is_some() {
            d = d.min(now_ns + DEFERRED_RETRY_NS);
        }
        if let Mode::Armed {
            since_ns,
            confirmed,
        } = self.mode
        {
            if let Some(t) = self.last_valid_tick_ns {
                d = d.min(t + s.tick_timeout_ns + 1);
            }
            if let Some((_, at)) = self.last_status {
                d = d.min(at + s.stimulator_timeout_ns + 1);
            }
            if !confirmed {
                d = d.min(since_ns + s.arm_confirm_ns + 1);
            }
            for since in [self.liveness_unknown_since, self.supervisor_unknown_since]
                .into_iter()
                .flatten()
            {
                d = d.min(since + s.liveness_unknown_grace_ns + 1);
            }
        }
        d.max(now_ns)
    }

    /// Shutdown: NMT stop (armed or not) and a heartbeat showing "stopped".
    pub fn shutdown(&mut self, now_ns: u64, ev: &mut impl EventSink) {
        let before = self.state();
        let stop_sent = self.send_stop(now_ns, ev);
        if let Mode::Armed { .. } = self.mode {
            self.mode = Mode::Disarmed;
        }
        self.control(ControlFrame::Heartbeat(NmtState::Stopped), now_ns, ev);
        ev.emit(DriverEvent::Shutdown { stop_sent });
        self.finish(before, ev);
    }

    /// Records the state and reports a change.
    fn finish(&mut self, before: DriverState, ev: &mut impl EventSink) {
        let after = self.state();
        self.counters.state = after.device_state() as u8;
        if after != before {
            ev.emit(DriverEvent::StateChanged {
                from: before,
                to: after,
            });
        }
    }

    /// Counts one wake-up of the loop (progress for the systemd watchdog).
    pub fn count_wakeup(&mut self) {
        self.counters.wakeups += 1;
    }

    /// True while an NMT stop could not be written yet (it is retried).
    pub fn stop_pending(&self) -> bool {
        self.stop_pending
    }

    /// Whether [`Self::start`] was called.
    pub fn is_started(&self) -> bool {
        self.started
    }
}
