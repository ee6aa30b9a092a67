//! The stimulator side of the protocol as a pure state machine: frames and time in,
//! frames and plant steps out. No socket, no clock, no allocation; the socket loop
//! (`socket_loop`) is a thin adapter around it, and tests drive it directly.
//!
//! States (STATUS `state`): boot -> pre-operational -> operational (armed / stimulating)
//! -> stopped; a watchdog expiry enters *fault*, which (like stopped) has the output off
//! and is left only by an explicit NMT command, never by itself.
//!
//! Timing: ticks are 1 ms apart. Frames received before tick `k` are handled before it;
//! an accepted PULSE is applied to the plant at tick `k`. Frames are handled with their
//! arrival time (the adapter passes the kernel's receive timestamp): a PULSE that arrived
//! during tick period `j` of a stall of the loop is applied at tick `j` in the catch-up
//! that follows (`PendingPulses`), as the hardware would have, instead of all at once. At each tick the stimulator
//! publishes FORCE (the force at the tick's time, before this tick's pulse), steps the
//! plant one sample, and sends STATUS every 10 ms and its heartbeat every heartbeat period.

use fes_can::counter::{AliveCheck, SequenceCheck};
use fes_can::table::pulse as pulse_sig;
use fes_can::{
    ConfigAssembler, DecodeError, Emcy, ErrorCode, Force, Heartbeat, Message, MessageKind,
    NmtCommand, NmtState, Nodes, Pulse, Status, StimLimits, StimState,
};

use super::interlock::{Interlock, no_looser_than};
use super::outbox::Outbox;
use super::pending::{PENDING_CAPACITY, PendingPulses};
use super::watchdog::HeartbeatWatchdog;
use crate::plant::{self, Plant};

/// Tick period (ns): the stimulator runs at 1 kHz.
pub const TICK_NS: u64 = 1_000_000;
/// A pulse within this many ticks makes an operational stimulator "stimulating".
pub const STIMULATING_HOLD_TICKS: u64 = 100;
/// Most plant samples simulated to catch up after missed ticks (1 s).
pub const MAX_CATCH_UP_STEPS: u64 = 1000;

/// Settings of one stimulator, fixed for its lifetime.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// Node ids of host and stimulator.
    pub nodes: Nodes,
    /// The stimulator's own limits: the boot configuration (config id 0) and the ceiling
    /// no CONFIG may loosen.
    pub ceiling: StimLimits,
    /// Number of output channels (1..=16).
    pub channels: u8,
    /// Period of the stimulator's own heartbeat, ms.
    pub heartbeat_ms: u16,
    /// Period at which the host sends its heartbeat, ms; a watchdog must span at least two.
    pub host_heartbeat_ms: u16,
    /// TEST ONLY (a fault to inject, never on a rig): apply every CONFIG with the amplitude
    /// ceiling of the stimulator's own limits instead of the one requested, i.e. a stimulator
    /// that applies a looser limit than it was sent. It reports what it applied in
    /// CONFIG_APPLIED, so the host must refuse to arm (`sim-muscle stimulator
    /// --test-fault-loose-config`).
    pub test_fault_loose_config: bool,
}

/// Invalid [`Settings`].
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum SettingsError {
    /// A limit is outside what the protocol can carry.
    #[error(transparent)]
    Limits(#[from] fes_can::LimitsError),
    /// Channel count outside 1..=16 (PULSE carries a 4-bit channel).
    #[error("{0} output channels; the protocol addresses 1..=16")]
    Channels(u8),
    /// A heartbeat period of zero.
    #[error("heartbeat periods must be at least 1 ms (stimulator {stim} ms, host {host} ms)")]
    HeartbeatPeriod {
        /// Stimulator heartbeat period.
        stim: u16,
        /// Host heartbeat period.
        host: u16,
    },
    /// The watchdog would fire between two healthy host heartbeats.
    #[error(
        "watchdog {watchdog_ms} ms is shorter than two host heartbeat periods ({host_heartbeat_ms} ms each)"
    )]
    WatchdogTooShort {
        /// Watchdog time.
        watchdog_ms: u16,
        /// Host heartbeat period.
        host_heartbeat_ms: u16,
    },
}

impl Settings {
    /// Checks the settings.
    pub fn validate(&self) -> Result<(), SettingsError> {
        self.ceiling.validate()?;
        if !(1..=16).contains(&self.channels) {
            return Err(SettingsError::Channels(self.channels));
        }
        if self.heartbeat_ms == 0 || self.host_heartbeat_ms == 0 {
            return Err(SettingsError::HeartbeatPeriod {
                stim: self.heartbeat_ms,
                host: self.host_heartbeat_ms,
            });
        }
        if u32::from(self.ceiling.watchdog_ms) < 2 * u32::from(self.host_heartbeat_ms) {
            return Err(SettingsError::WatchdogTooShort {
                watchdog_ms: self.ceiling.watchdog_ms,
                host_heartbeat_ms: self.host_heartbeat_ms,
            });
        }
        Ok(())
    }
}

/// One tick of the 1 ms loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Tick {
    /// Tick number on the absolute schedule (`nominal_ns = t0 + index * 1 ms`).
    pub index: u64,
    /// The tick's scheduled time (CLOCK_MONOTONIC ns): the FORCE sample time.
    pub nominal_ns: u64,
    /// The time actually read after waking (used by the watchdog).
    pub now_ns: u64,
}

/// What one tick did, for the record and the log.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TickReport {
    /// The force published in this tick's FORCE frame (N).
    pub force_n: f64,
    /// The pulse applied at this tick.
    pub applied: Option<Pulse>,
    /// Pulses applied at the missed ticks caught up before this one (a stall of the loop).
    pub caught_up_pulses: u32,
    /// State after the tick.
    pub state: StimState,
}

/// A pulse applied at a missed tick in the catch-up after a stall of the loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CaughtUp {
    /// The tick it was applied at.
    pub tick: u64,
    /// The plant's force at that tick, before the pulse (N; not sent as FORCE).
    pub force_n: f64,
    /// The pulse.
    pub pulse: Pulse,
}

/// Counters that are not on the bus, for logs and tests.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Diagnostics {
    /// Ticks skipped because the loop woke late (the plant still advanced through them).
    pub missed_ticks: u64,
    /// Frames that could not be encoded (a bug if ever non-zero).
    pub encode_errors: u64,
}

/// The virtual stimulator's protocol state machine.
#[derive(Debug, Clone)]
pub struct Stimulator {
    settings: Settings,
    limits: StimLimits,
    config_id: u8,
    assembler: ConfigAssembler,
    state: StimState,
    last_error: ErrorCode,
    pulses_delivered: u32,
    rejected: u8,
    status_counter: u8,
    force_seq: u16,
    alive: AliveCheck,
    seq: SequenceCheck,
    interlock: Interlock,
    pending: PendingPulses,
    caught_up: [Option<CaughtUp>; PENDING_CAPACITY],
    caught_up_len: usize,
    grid_origin_ns: Option<u64>,
    next_tick: u64,
    force_n: f64,
    watchdog: HeartbeatWatchdog,
    next_status_ns: u64,
    next_heartbeat_ns: u64,
    started: bool,
    diagnostics: Diagnostics,
}

fn ms_to_ns(ms: u16) -> u64 {
    u64::from(ms) * 1_000_000
}

/// The next deadline after `now` on the grid `deadline + n * period`.
fn advance(deadline: u64, period: u64, now: u64) -> u64 {
    if now < deadline {
        return deadline;
    }
    deadline + ((now - deadline) / period + 1) * period
}

impl Stimulator {
    /// Boots at `now_ns`: sends the boot-up message and enters pre-operational.
    /// `settings` must have passed [`Settings::validate`].
    pub fn new(settings: Settings, now_ns: u64, out: &mut Outbox) -> Self {
        let mut s = Self {
            settings,
            limits: settings.ceiling,
            config_id: 0,
            assembler: ConfigAssembler::new(),
            state: StimState::Boot,
            last_error: ErrorCode::NoError,
            pulses_delivered: 0,
            rejected: 0,
            status_counter: 0,
            force_seq: 0,
            alive: AliveCheck::new(),
            seq: SequenceCheck::new(),
            interlock: Interlock::new(settings.channels),
            pending: PendingPulses::new(),
            caught_up: [None; PENDING_CAPACITY],
            caught_up_len: 0,
            grid_origin_ns: None,
            next_tick: 0,
            force_n: 0.0,
            watchdog: HeartbeatWatchdog::new(settings.ceiling.watchdog_ms, now_ns),
            next_status_ns: now_ns,
            next_heartbeat_ns: now_ns,
            started: false,
            diagnostics: Diagnostics::default(),
        };
        s.boot_up(now_ns, out);
        s
    }

    /// Current state.
    pub const fn state(&self) -> StimState {
        self.state
    }

    /// Active run limits.
    pub const fn limits(&self) -> &StimLimits {
        &self.limits
    }

    /// Id of the active configuration (0: the stimulator's own).
    pub const fn config_id(&self) -> u8 {
        self.config_id
    }

    /// Pulses applied since reset (the full count; STATUS carries it modulo 2^24).
    pub const fn pulses_delivered(&self) -> u32 {
        self.pulses_delivered
    }

    /// Frames rejected since reset, modulo 256.
    pub const fn rejected(&self) -> u8 {
        self.rejected
    }

    /// Code of the most recent emergency since reset.
    pub const fn last_error(&self) -> ErrorCode {
        self.last_error
    }

    /// The tick an accepted pulse would be applied at.
    pub const fn next_tick(&self) -> u64 {
        self.next_tick
    }

    /// The pulses the last [`Self::tick`] applied at missed ticks, in tick order (for the
    /// record: the adapter writes a row for each).
    pub fn caught_up(&self) -> impl Iterator<Item = &CaughtUp> {
        self.caught_up[..self.caught_up_len].iter().flatten()
    }

    /// True when an accepted pulse waits for its tick.
    pub const fn has_pending_pulse(&self) -> bool {
        !self.pending.is_empty()
    }

    /// The tick a pulse that arrived at `arrival_ns` is applied at: the tick period it
    /// arrived in, and never before the next tick to run. Before the first tick (no grid
    /// yet), the next tick.
    fn arrival_tick(&self, arrival_ns: u64) -> u64 {
        self.grid_origin_ns
            .map_or(self.next_tick, |o| arrival_ns.saturating_sub(o) / TICK_NS)
            .max(self.next_tick)
    }

    /// Off-bus counters.
    pub const fn diagnostics(&self) -> Diagnostics {
        self.diagnostics
    }

    /// The STATUS message describing the current state.
    pub fn status(&self) -> Status {
        Status {
            state: self.state,
            counter: self.status_counter,
            last_error: self.last_error,
            pulses_delivered: self.pulses_delivered & 0xFF_FFFF,
            rejected: self.rejected,
            config_id: self.config_id,
        }
    }

    const fn operational(&self) -> bool {
        matches!(self.state, StimState::Armed | StimState::Stimulating)
    }

    fn send(&mut self, message: Message, out: &mut Outbox) {
        match message.encode_for(&self.settings.nodes) {
            Ok(frame) => out.push(frame),
            Err(_) => self.diagnostics.encode_errors += 1,
        }
    }

    fn emcy(&mut self, code: ErrorCode, seq: u16, detail: u16, out: &mut Outbox) {
        if code != ErrorCode::NoError {
            self.last_error = code;
        }
        self.send(Message::Emcy(Emcy::new(code, self.state, seq, detail)), out);
    }

    /// Drops a frame: counts it and reports it by EMCY.
    fn reject(&mut self, code: ErrorCode, seq: u16, detail: u16, out: &mut Outbox) {
        self.rejected = self.rejected.wrapping_add(1);
        self.emcy(code, seq, detail, out);
    }

    fn pulse_id(&self) -> u16 {
        self.settings.nodes.id_of(MessageKind::Pulse)
    }

    /// Output off: an accepted pulse that has not been applied yet is cancelled and
    /// reported (a command is never dropped silently).
    fn output_off(&mut self, out: &mut Outbox) {
        while let Some(p) = self.pending.pop() {
            let id = self.pulse_id();
            self.reject(ErrorCode::WrongState, p.seq, id, out);
        }
    }

    fn boot_up(&mut self, now_ns: u64, out: &mut Outbox) {
        self.state = StimState::Boot;
        self.send(
            Message::StimHeartbeat(Heartbeat {
                state: NmtState::BootUp,
            }),
            out,
        );
        self.state = StimState::PreOperational;
        self.next_heartbeat_ns = now_ns + ms_to_ns(self.settings.heartbeat_ms);
    }

    fn enter_operational(&mut self, now_ns: u64, out: &mut Outbox) {
        if self.state == StimState::Fault {
            self.state = StimState::Armed;
            self.emcy(ErrorCode::NoError, 0, 0, out);
        }
        self.state = StimState::Armed;
        self.alive.reset();
        self.seq.reset();
        self.assembler.clear();
        self.watchdog.feed(now_ns);
    }

    fn enter_fault(&mut self, code: ErrorCode, detail: u16, out: &mut Outbox) {
        self.state = StimState::Fault;
        self.emcy(code, 0, detail, out);
        self.output_off(out);
    }

    /// Handles one received frame (standard identifier `id`) at `now_ns`. Frames not
    /// addressed to this stimulator are ignored; frames addressed to it that fail
    /// decoding or a check are dropped and reported by EMCY.
    pub fn on_frame(&mut self, now_ns: u64, id: u32, data: &[u8], out: &mut Outbox) {
        let Some(kind) = self.settings.nodes.kind_of(id) else {
            return;
        };
        if !matches!(
            kind,
            MessageKind::Nmt
                | MessageKind::Pulse
                | MessageKind::Config
                | MessageKind::HostHeartbeat
        ) {
            return;
        }
        match self.settings.nodes.decode(id, data) {
            Err(e) => self.reject_undecodable(kind, data, e, out),
            Ok(Message::Nmt(m)) => self.on_nmt(now_ns, m.command, m.node, out),
            Ok(Message::Pulse(p)) => self.on_pulse(now_ns, p, out),
            Ok(Message::Config(c)) => self.on_config(&c, out),
            Ok(Message::HostHeartbeat(_)) => self.watchdog.feed(now_ns),
            Ok(_) => {}
        }
    }

    fn reject_undecodable(
        &mut self,
        kind: MessageKind,
        data: &[u8],
        e: DecodeError,
        out: &mut Outbox,
    ) {
        let detail = match e {
            DecodeError::WrongLength { actual, .. } => u16::try_from(actual).unwrap_or(u16::MAX),
            DecodeError::BadCrc { received, computed } => u16::from_be_bytes([received, computed]),
            // The low 16 bits of the offending raw value.
            DecodeError::OutOfRange { raw, .. } | DecodeError::UnknownValue { raw, .. } => {
                raw as u16
            }
            DecodeError::UnknownId { id } => id as u16,
            // The index of the first payload byte with a reserved bit set.
            DecodeError::ReservedNonZero { byte, .. } => byte as u16,
        };
        // An intact PULSE (length and CRC good) still names its sequence number.
        let seq = match (kind, e) {
            (
                MessageKind::Pulse,
                DecodeError::OutOfRange { .. } | DecodeError::UnknownValue { .. },
            ) => {
                let mut d = [0u8; 8];
                d[..data.len().min(8)].copy_from_slice(&data[..data.len().min(8)]);
                pulse_sig::SEQ.extract(&d) as u16
            }
            _ => 0,
        };
        self.reject(e.error_code(), seq, detail, out);
    }

    fn on_nmt(&mut self, now_ns: u64, command: NmtCommand, node: u8, out: &mut Outbox) {
        if node != 0 && node != self.settings.nodes.stim() {
            return;
        }
        match command {
            NmtCommand::Start => {
                if !self.operational() {
                    self.enter_operational(now_ns, out);
                }
            }
            NmtCommand::Stop => {
                if !matches!(self.state, StimState::Stopped | StimState::Fault) {
                    self.output_off(out);
                    self.state = StimState::Stopped;
                }
            }
            NmtCommand::EnterPreOperational => {
                self.output_off(out);
                if self.state == StimState::Fault {
                    self.state = StimState::PreOperational;
                    self.emcy(ErrorCode::NoError, 0, 0, out);
                }
                self.state = StimState::PreOperational;
            }
            NmtCommand::ResetNode => {
                self.output_off(out);
                self.limits = self.settings.ceiling;
                self.config_id = 0;
                self.watchdog.set_timeout(self.limits.watchdog_ms);
                self.last_error = ErrorCode::NoError;
                self.pulses_delivered = 0;
                self.rejected = 0;
                self.status_counter = 0;
                self.force_seq = 0;
                // The applied-pulse history survives the reset: the minimum IPI and the
                // rate window protect the tissue, and a protocol reset does not undo the
                // pulses it has had (a host resetting and restarting between pulses got
                // around both; found by the stimulator property test).
                self.reset_communication();
                self.boot_up(now_ns, out);
            }
            NmtCommand::ResetCommunication => {
                self.output_off(out);
                self.reset_communication();
                self.boot_up(now_ns, out);
            }
        }
    }

    fn reset_communication(&mut self) {
        self.alive.reset();
        self.seq.reset();
        self.assembler.clear();
    }

    fn on_pulse(&mut self, arrival_ns: u64, p: Pulse, out: &mut Outbox) {
        // The watchdog as of the frame's arrival: frames are handled in arrival order, so
        // after a stall of this loop a pulse that arrived once the host's heartbeat had
        // already been missing for the watchdog time trips it, as it would have on time.
        if self.operational()
            && let Some(elapsed_ns) = self.watchdog.expired(arrival_ns)
        {
            let elapsed_ms = u16::try_from(elapsed_ns / 1_000_000).unwrap_or(u16::MAX);
            self.enter_fault(ErrorCode::HeartbeatLost, elapsed_ms, out);
        }
        if !self.operational() {
            let id = self.pulse_id();
            return self.reject(ErrorCode::WrongState, p.seq, id, out);
        }
        if let Err(e) = self.alive.check(p.alive_counter) {
            return self.reject(
                ErrorCode::BadAliveCounter,
                p.seq,
                u16::from_be_bytes([e.received, e.expected]),
                out,
            );
        }
        if let Err(e) = self.seq.check(p.seq) {
            return self.reject(ErrorCode::SequenceError, p.seq, e.last, out);
        }
        let tick = self.arrival_tick(arrival_ns);
        match self
            .interlock
            .check(&p, tick, self.pending.ticks(), &self.limits)
        {
            Ok(()) => {
                if !self.pending.push(tick, p) {
                    // More pulses waiting than a 64 ms stall can hold: refuse, never drop.
                    let detail = u16::try_from(PENDING_CAPACITY).unwrap_or(u16::MAX);
                    self.reject(ErrorCode::RateViolation, p.seq, detail, out);
                }
            }
            Err(r) => self.reject(r.code, p.seq, r.detail, out),
        }
    }

    fn on_config(&mut self, c: &fes_can::Config, out: &mut Outbox) {
        if self.state != StimState::PreOperational {
            let id = self.settings.nodes.id_of(MessageKind::Config);
            return self.reject(ErrorCode::WrongState, 0, id, out);
        }
        let Some((config_id, limits)) = self.assembler.push(c) else {
            return;
        };
        if let Err(index) = no_looser_than(&limits, &self.settings.ceiling) {
            return self.reject(ErrorCode::ConfigInvalid, 0, index, out);
        }
        if u32::from(limits.watchdog_ms) < 2 * u32::from(self.settings.host_heartbeat_ms) {
            return self.reject(ErrorCode::ConfigInvalid, 0, 5, out);
        }
        let applied = if self.settings.test_fault_loose_config {
            StimLimits {
                max_amplitude_100ua: self.settings.ceiling.max_amplitude_100ua,
                ..limits
            }
        } else {
            limits
        };
        self.limits = applied;
        self.config_id = config_id;
        self.watchdog.set_timeout(applied.watchdog_ms);
        // The read-back: the limits now in force (not an echo of the request), so the host
        // can refuse to arm on any difference.
        for page in applied.to_pages(config_id) {
            self.send(Message::ConfigApplied(page), out);
        }
    }

    /// Reports a bus problem seen by the adapter (error frame, full transmit queue).
    pub fn on_bus_error(&mut self, code: ErrorCode, detail: u16, out: &mut Outbox) {
        self.emcy(code, 0, detail, out);
    }

    /// Runs tick `tick`: watchdog, FORCE, pulse application and plant step, STATUS and
    /// heartbeat when due. Missed ticks (index jumped) advance the plant without pulses;
    /// no pulse is ever repeated or caught up.
    pub fn tick(&mut self, tick: Tick, plant: &mut dyn Plant, out: &mut Outbox) -> TickReport {
        let k = self.place_on_grid(tick);
        let caught_up_pulses = self.catch_up(k, plant, out);
        self.check_watchdog(tick.now_ns, out);
        let published_n = self.publish_force(tick.nominal_ns, out);
        let applied = self.pending.take_due(k);
        self.apply(k, applied, plant);
        self.update_stimulating(k);
        self.send_periodic(tick.nominal_ns, out);
        self.next_tick = k + 1;
        TickReport {
            force_n: published_n,
            applied,
            caught_up_pulses,
            state: self.state,
        }
    }

    /// The index this tick runs at (never behind the next one due); the first tick also
    /// sets the phase of the periodic frames and the grid's origin.
    fn place_on_grid(&mut self, tick: Tick) -> u64 {
        if !self.started {
            // The periodic frames take their phase from the first tick.
            self.started = true;
            self.next_status_ns = tick.nominal_ns;
            self.next_heartbeat_ns = tick.nominal_ns + ms_to_ns(self.settings.heartbeat_ms);
        }
        let k = tick.index.max(self.next_tick);
        if self.grid_origin_ns.is_none() {
            self.grid_origin_ns = Some(tick.nominal_ns.saturating_sub(k * TICK_NS));
        }
        k
    }

    /// Advances the plant through the ticks missed before `k` (at most
    /// [`MAX_CATCH_UP_STEPS`] of them), applying the pulses due then and cancelling the
    /// older ones; returns the number of pulses applied in the catch-up.
    fn catch_up(&mut self, k: u64, plant: &mut dyn Plant, out: &mut Outbox) -> u32 {
        let missed = k - self.next_tick;
        let mut caught_up_pulses = 0;
        self.caught_up_len = 0;
        if missed > 0 {
            self.diagnostics.missed_ticks += missed;
            let first = k - missed.min(MAX_CATCH_UP_STEPS);
            // Pulses for ticks beyond the catch-up horizon are cancelled and reported.
            while self.pending.ticks().first().is_some_and(|&t| t < first) {
                if let Some(p) = self.pending.pop() {
                    let id = self.pulse_id();
                    self.reject(ErrorCode::WrongState, p.seq, id, out);
                }
            }
            for j in first..k {
                let p = self.pending.take_due(j);
                if let Some(pulse) = p
                    && self.caught_up_len < PENDING_CAPACITY
                {
                    self.caught_up[self.caught_up_len] = Some(CaughtUp {
                        tick: j,
                        force_n: self.force_n,
                        pulse,
                    });
                    self.caught_up_len += 1;
                }
                caught_up_pulses += u32::from(p.is_some());
                self.apply(j, p, plant);
            }
        }
        caught_up_pulses
    }

    /// An operational stimulator whose host heartbeat expired goes to FAULT.
    fn check_watchdog(&mut self, now_ns: u64, out: &mut Outbox) {
        if self.operational()
            && let Some(elapsed_ns) = self.watchdog.expired(now_ns)
        {
            let elapsed_ms = u16::try_from(elapsed_ns / 1_000_000).unwrap_or(u16::MAX);
            self.enter_fault(ErrorCode::HeartbeatLost, elapsed_ms, out);
        }
    }

    /// Sends this tick's FORCE (the plant's force before this tick's step); a force FORCE
    /// cannot carry is a FAULT. Returns the force published, N.
    fn publish_force(&mut self, nominal_ns: u64, out: &mut Outbox) -> f64 {
        let sample_time_us = ((nominal_ns / 1000) & 0xFF_FFFF) as u32;
        let published_n = self.force_n;
        let force_mn = Force::raw_force(self.force_n);
        self.send(
            Message::Force(Force {
                seq: self.force_seq,
                force_mn: force_mn.unwrap_or(0),
                sample_time_us,
            }),
            out,
        );
        self.force_seq = self.force_seq.wrapping_add(1);
        if force_mn.is_none() && self.state != StimState::Fault {
            // The measurement left the range FORCE can carry (or is not a number).
            self.enter_fault(ErrorCode::Generic, 0, out);
        }
        published_n
    }

    /// While operational: STIMULATING for a while after a pulse at or before tick `k`,
    /// ARMED otherwise.
    fn update_stimulating(&mut self, k: u64) {
        if self.operational() {
            let recent = self
                .interlock
                .last_pulse_tick()
                .is_some_and(|t| k < t + STIMULATING_HOLD_TICKS);
            self.state = if recent {
                StimState::Stimulating
            } else {
                StimState::Armed
            };
        }
    }

    /// STATUS and the stimulator's heartbeat, each when its period is due.
    fn send_periodic(&mut self, nominal_ns: u64, out: &mut Outbox) {
        let status_ns = ms_to_ns(MessageKind::Status.desc().cycle_time_ms.unwrap_or(10));
        if nominal_ns >= self.next_status_ns {
            self.send(Message::Status(self.status()), out);
            self.status_counter = (self.status_counter + 1) % 16;
            self.next_status_ns = advance(self.next_status_ns, status_ns, nominal_ns);
        }
        if nominal_ns >= self.next_heartbeat_ns {
            self.send(
                Message::StimHeartbeat(Heartbeat {
                    state: self.state.nmt(),
                }),
                out,
            );
            self.next_heartbeat_ns = advance(
                self.next_heartbeat_ns,
                ms_to_ns(self.settings.heartbeat_ms),
                nominal_ns,
            );
        }
    }

    /// Steps the plant one sample at tick `k`, applying `pulse` (recorded for the
    /// interlocks and counted).
    fn apply(&mut self, k: u64, pulse: Option<Pulse>, plant: &mut dyn Plant) {
        if pulse.is_some() {
            self.interlock.record(k);
            self.pulses_delivered = self.pulses_delivered.wrapping_add(1);
        }
        self.force_n = plant.step(pulse.map(|p| plant::Pulse {
            amplitude_ma: p.amplitude_ma(),
            width_us: f64::from(p.width_us),
        }));
    }

    /// Orderly shutdown (SIGINT/SIGTERM): output off, stopped, a final STATUS and heartbeat.
    pub fn shutdown(&mut self, out: &mut Outbox) {
        self.output_off(out);
        if self.state != StimState::Fault {
            self.state = StimState::Stopped;
        }
        self.send(Message::Status(self.status()), out);
        self.status_counter = (self.status_counter + 1) % 16;
        self.send(
            Message::StimHeartbeat(Heartbeat {
                state: self.state.nmt(),
            }),
            out,
        );
    }
}

#[cfg(test)]
mod tests;
