//! The ScienceMode 2 receive side: one normal-priority thread that reads the
//! RehaStim 2's packets from the serial line and hands the forward thread the SAME
//! [`BusEvent`]s the CAN receive thread ([`crate::bus`]) produces, so that the forward
//! path, its interlocks, its watchdog and the arming sequence stay as they are.
//!
//! The device has no STATUS, EMCY, heartbeat or CONFIG; this module stands in for them
//! (`docs/sciencemode.md`, "The driver's receive side"):
//!
//! | RehaStim 2 | [`BusEvent`] |
//! |------------|--------------|
//! | Init (the device announces itself) | handshake: the transmit side writes InitAck; a second Init after a handshake is [`BusEvent::StimHeartbeat`] `BootUp` (the device restarted) |
//! | GetStimulationModeAck (the liveness query the transmit side sends in place of a Watchdog once `poll` has passed since the last answer that stood for STATUS), or SinglePulseAck result 0 (a SinglePulse is executed only in the start mode, §3.6 Fig. 4, so it tells the mode too) | [`BusEvent::Status`]: `pulses_delivered` = SinglePulse acknowledgements with result 0 so far, `state` from the NMT state the driver commanded (channel list mode running: `Stimulating`), `config_id` = the driver's last CONFIG id once the handshake is done and the device is not in channel list mode (0 otherwise) |
//! | the same, the first time a configuration id shows | [`BusEvent::ConfigApplied`], the driver's configured limits, only when they lie within the device's fixed ones ([`limits_within_device`]) |
//! | SinglePulseAck result 0 | one pulse delivered |
//! | any answer (an acknowledgement, UnknownCommand) | the command with its packet number is answered: the transmit side may send the next (stop-and-wait, [`SerialLink::answer_received`]) |
//! | an acknowledgement with result -8 busy (§5.1) | [`BusEvent::DeviceBusy`] (the command was not executed; a SinglePulse is not delivered), not a fault; the [`BUSY_LIMIT`]-th in a row is [`BusEvent::Emcy`] |
//! | any acknowledgement with an error result (GetStimulationModeAck's carries no mode, §4.2), UnknownCommand (echoing the command byte it did not know, §4.1), StimulationError | [`BusEvent::Emcy`] ([`device_emcy`]: the CANopen code and a detail naming the ScienceMode command and code) |
//! | MOTOmed information packets (ActualValues every 20 ms, PhaseResult, MotomedCommandDone, MotomedError; §3.5, §4.4) | nothing: counted ([`Receiver::information_packets`], `BusCounters::information_packets`) and skipped, never a link fault |
//! | a packet that fails to decode (checksum, stuffing, length, unknown command), a failed read, the port gone (EIO / ENXIO / ENODEV, a hang-up) | [`BusEvent::LinkDown`]; the next good packet is [`BusEvent::LinkUp`] (which never re-arms) |
//! | no answer for `stimulator_timeout_ms` | nothing: no STATUS, so the forward path's existing stimulator-silence trip |
//!
//! Hot path: the thread owns a fixed read buffer and a [`Decoder`] (no heap), and the
//! events are `Copy` into a preallocated queue: nothing is allocated per packet.

use std::fs::File;
use std::io::{self, Read as _};
use std::os::fd::AsRawFd as _;
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU16, AtomicU32, AtomicU64, Ordering};
use std::time::Duration;

use crossbeam::queue::ArrayQueue;
use fes_can::values::error_register;
use fes_can::{Emcy, ErrorCode, NmtState, StimLimits, StimState};
use fes_sciencemode::limits::{MAX_CURRENT_MA, MAX_PULSE_WIDTH_US};
use fes_sciencemode::{AckResult, Command, Decoder, Message, Packet, StimulationMode};

use crate::bus::BusCounters;
use crate::event::BusEvent;
use crate::reconcile::COUNT_MODULUS;

/// The longest the thread waits for a byte before looking at `stop` again.
pub const READ_TIMEOUT: Duration = Duration::from_millis(5);

/// The longest the RehaStim 2 takes to answer a command, ms (§2.3 MaxResponseTime: "up to
/// 100 ms", on average below 20 ms; Hasomed quotes 10-24 ms elsewhere,
/// `docs/sciencemode.md`). Past it, an answer is taken as lost. The stimulator timeout
/// and the in-flight allowance of STATUS reconciliation (`watchdog.stimulator_timeout_ms`)
/// must cover it plus two liveness periods.
pub const MAX_RESPONSE_MS: u32 = 100;

/// How long the transport waits for an answer before taking it as lost, ms: the longest
/// answer ([`MAX_RESPONSE_MS`]) plus the USB adapter's latency timer at its Linux default
/// (16 ms, §2.1) and a margin, so that a command answered at the limit is never followed
/// by one the device would refuse -8 busy.
pub const ANSWER_TIMEOUT_MS: u32 = MAX_RESPONSE_MS + 20;

/// Answers -8 busy in a row that are still waited out (§5.1: "wait for the response
/// packet"); the next is a device error ([`device_emcy`]).
pub const BUSY_LIMIT: u8 = 4;

/// What the driver last commanded over NMT (the device has no such state; the receive
/// side reports it back in STATUS as a CAN stimulator would).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Commanded {
    /// Enter pre-operational, a reset, or nothing yet.
    PreOperational = 0,
    /// NMT start (armed).
    Operational = 1,
    /// NMT stop.
    Stopped = 2,
}

/// What the transmit side (forward thread) and the receive thread share: lock-free
/// atomics, one writer each (see the field comments).
#[derive(Debug, Default)]
pub struct SerialLink {
    /// `0x100 | number` while an Init waits for its InitAck (receive thread sets, transmit
    /// side takes).
    init_pending: AtomicU16,
    /// InitAck written since the last Init (transmit side sets, receive thread clears).
    handshake: AtomicBool,
    /// The id of the last CONFIG the driver wrote since the handshake, 0 for none
    /// (transmit side sets, receive thread clears on a new Init).
    config_id: AtomicU8,
    /// [`Commanded`] (transmit side).
    commanded: AtomicU8,
    /// `0x100 | number` of the command whose answer is awaited (stop-and-wait), 0 for
    /// none (transmit side sets before the write, receive thread clears on the answer
    /// carrying that number or on Init).
    awaiting: AtomicU16,
    /// When the awaited command was written, CLOCK_MONOTONIC ns (transmit side).
    awaiting_since_ns: AtomicU64,
    /// Answers that stood for STATUS after the handshake (a mode query's, a SinglePulse's
    /// with result 0; receive thread): the transmit side schedules its next query from
    /// the last of them.
    status_answers: AtomicU32,
}

impl SerialLink {
    /// A link before any handshake.
    pub fn new() -> Self {
        Self::default()
    }

    /// The device announced itself with Init packet `number`: InitAck is due, the
    /// handshake (and the configuration that came with it) is void.
    pub fn init_received(&self, number: u8) {
        // A device that announces itself has forgotten any command it was processing.
        self.awaiting.store(0, Ordering::Release);
        self.handshake.store(false, Ordering::Release);
        self.config_id.store(0, Ordering::Release);
        self.init_pending
            .store(0x100 | u16::from(number), Ordering::Release);
    }

    /// Command `number`, which the device answers, is about to be written at `now_ns`
    /// (transmit side; before the write, so that an answer faster than the store cannot
    /// be missed).
    pub fn awaiting_answer_to(&self, number: u8, now_ns: u64) {
        self.awaiting_since_ns.store(now_ns, Ordering::Release);
        self.awaiting
            .store(0x100 | u16::from(number), Ordering::Release);
    }

    /// The write of the awaited command failed: nothing is awaited (transmit side).
    pub fn not_awaiting(&self) {
        self.awaiting.store(0, Ordering::Release);
    }

    /// An answer stood for STATUS (receive thread).
    pub fn status_answered(&self) {
        self.status_answers.fetch_add(1, Ordering::AcqRel);
    }

    /// Answers that stood for STATUS so far (wrapping).
    pub fn status_answers(&self) -> u32 {
        self.status_answers.load(Ordering::Acquire)
    }

    /// The device answered packet `number` (receive thread): if that is the awaited
    /// command, the next may be sent. Returns whether it was.
    pub fn answer_received(&self, number: u8) -> bool {
        self.awaiting
            .compare_exchange(
                0x100 | u16::from(number),
                0,
                Ordering::AcqRel,
                Ordering::Acquire,
            )
            .is_ok()
    }

    /// Whether a command written less than `timeout_ns` before `now_ns` still awaits its
    /// answer (transmit side). An answer lost on the line stops the wait after the
    /// timeout, the device's longest response time; the pulse it belonged to is then
    /// missing from the device's count, which STATUS reconciliation reports.
    pub fn awaiting(&self, now_ns: u64, timeout_ns: u64) -> bool {
        self.awaiting.load(Ordering::Acquire) != 0
            && now_ns.saturating_sub(self.awaiting_since_ns.load(Ordering::Acquire)) < timeout_ns
    }

    /// The number of the Init an InitAck is due for, taken (transmit side).
    pub fn take_init(&self) -> Option<u8> {
        let v = self.init_pending.swap(0, Ordering::AcqRel);
        (v & 0x100 != 0).then_some((v & 0xFF) as u8)
    }

    /// InitAck was written (transmit side).
    pub fn init_acknowledged(&self) {
        self.handshake.store(true, Ordering::Release);
    }

    /// Whether the handshake is done.
    pub fn handshake_done(&self) -> bool {
        self.handshake.load(Ordering::Acquire)
    }

    /// The driver wrote CONFIG `id` (transmit side).
    pub fn config_written(&self, id: u8) {
        self.config_id.store(id, Ordering::Release);
    }

    /// The id of the last CONFIG written since the handshake (0: none).
    pub fn config_id(&self) -> u8 {
        self.config_id.load(Ordering::Acquire)
    }

    /// The driver commanded `c` over NMT (transmit side).
    pub fn commanded(&self, c: Commanded) {
        self.commanded.store(c as u8, Ordering::Release);
    }

    /// What the driver last commanded.
    pub fn last_commanded(&self) -> Commanded {
        match self.commanded.load(Ordering::Acquire) {
            1 => Commanded::Operational,
            2 => Commanded::Stopped,
            _ => Commanded::PreOperational,
        }
    }
}

/// Whether the limits the driver is configured with lie within the RehaStim 2's fixed ones
/// (`fes_sciencemode::limits`): amplitude ceiling at most 126 mA, width ceiling at most
/// 500 us. `Err` names the first that does not.
pub fn limits_within_device(limits: &StimLimits) -> Result<(), &'static str> {
    if u32::from(limits.max_amplitude_100ua) > u32::from(MAX_CURRENT_MA) * 10 {
        return Err("max_amplitude_ua");
    }
    if limits.max_width_us > MAX_PULSE_WIDTH_US {
        return Err("max_width_us");
    }
    Ok(())
}

/// The EMCY that stands for a device error: an acknowledgement of `command` with result
/// `code` (an error), UnknownCommand (`command` = UnknownCommand, `code` its data byte) or
/// StimulationError. `detail` = ScienceMode command id × 256 + the code as a byte, so the
/// fault names both (`docs/sciencemode.md`).
pub fn device_emcy(command: Command, code: i8, state: StimState) -> Emcy {
    let error = match command {
        Command::StimulationError => ErrorCode::Generic,
        Command::UnknownCommand => ErrorCode::Communication,
        _ => match AckResult::from_code(code) {
            AckResult::ParameterError => ErrorCode::ValueOutOfRange,
            AckResult::WrongModeError => ErrorCode::WrongState,
            AckResult::TransferError => ErrorCode::Communication,
            _ => ErrorCode::Generic,
        },
    };
    Emcy {
        code: error,
        register: error_register::GENERIC | error_register::MANUFACTURER,
        state,
        seq: 0,
        detail: (u16::from(command.id()) << 8) | u16::from(code as u8),
    }
}

/// The receive side's state, without I/O (see the module documentation): packets in,
/// [`BusEvent`]s out.
#[derive(Debug, Clone)]
pub struct Receiver {
    limits: StimLimits,
    limits_ok: bool,
    delivered: u32,
    rejected: u8,
    counter: u8,
    last_error: ErrorCode,
    /// The configuration id whose read-back was sent (0: none).
    read_back: u8,
    link_up: bool,
    /// An Init was seen.
    seen_init: bool,
    state: StimState,
    /// MOTOmed information packets skipped.
    information: u64,
    /// -8 busy answers in a row.
    busy_streak: u8,
}

impl Receiver {
    /// A receiver for a driver configured with `limits`.
    pub fn new(limits: StimLimits) -> Self {
        Self {
            limits,
            limits_ok: limits_within_device(&limits).is_ok(),
            delivered: 0,
            rejected: 0,
            counter: 0,
            last_error: ErrorCode::NoError,
            read_back: 0,
            link_up: true,
            seen_init: false,
            state: StimState::Boot,
            information: 0,
            busy_streak: 0,
        }
    }

    /// MOTOmed information packets (§3.5) received and skipped so far.
    pub const fn information_packets(&self) -> u64 {
        self.information
    }

    /// SinglePulse acknowledgements with result 0 so far (modulo 2^24).
    pub const fn delivered(&self) -> u32 {
        self.delivered
    }

    fn fault(&mut self, command: Command, code: i8, push: &mut impl FnMut(BusEvent)) {
        let emcy = device_emcy(command, code, self.state);
        self.last_error = emcy.code;
        push(BusEvent::Emcy(emcy));
    }

    /// One packet from the device.
    pub fn on_packet(
        &mut self,
        packet: &Packet,
        link: &SerialLink,
        push: &mut impl FnMut(BusEvent),
    ) {
        if !self.link_up {
            self.link_up = true;
            push(BusEvent::LinkUp);
        }
        if packet.message.is_answer() {
            link.answer_received(packet.number);
            if packet.message.ack_result() == Some(AckResult::BusyError) {
                self.on_busy(packet.message.command(), push);
                return;
            }
            self.busy_streak = 0;
        }
        match packet.message {
            Message::Init { .. } => {
                if link.handshake_done() {
                    // The device announced itself again: it restarted (its watchdog, a
                    // power cycle). What the driver set up with it is gone.
                    push(BusEvent::StimHeartbeat(NmtState::BootUp));
                }
                self.seen_init = true;
                self.read_back = 0;
                link.init_received(packet.number);
            }
            Message::GetStimulationModeAck { result, mode } => {
                if !result.is_ok() {
                    self.fault(Command::GetStimulationModeAck, result.code(), push);
                    return;
                }
                if link.handshake_done() {
                    self.status(mode, link, push);
                }
            }
            Message::SinglePulseAck { result } => {
                if result.is_ok() {
                    self.delivered = (self.delivered + 1) % COUNT_MODULUS;
                    // §3.6 Fig. 4: a SinglePulse is executed only in the start mode, so its
                    // acknowledgement tells the mode as a mode query would; the transmit
                    // side then leaves the query out, keeping the line free for pulses.
                    if link.handshake_done() {
                        self.status(Some(StimulationMode::Start), link, push);
                    }
                } else {
                    self.rejected = self.rejected.wrapping_add(1);
                    self.fault(Command::SinglePulseAck, result.code(), push);
                }
            }
            Message::StopChannelListModeAck { result } => {
                // The driver's NMT stop: executed, or refused for the wrong mode (channel
                // list mode was not running: nothing to stop). Anything else is a fault.
                if !matches!(result, AckResult::Ok | AckResult::WrongModeError) {
                    self.fault(Command::StopChannelListModeAck, result.code(), push);
                }
            }
            Message::InitChannelListModeAck { result }
            | Message::StartChannelListModeAck { result } => {
                // Never asked for by the driver; an error is still a device error.
                if !result.is_ok() {
                    self.fault(packet.message.command(), result.code(), push);
                }
            }
            // §4.1: the device echoes the command byte it did not recognise; the EMCY's
            // detail names it.
            Message::UnknownCommand { command } => {
                self.fault(Command::UnknownCommand, i8::from_be_bytes([command]), push);
            }
            // §3.5: information packets a device sends unasked with a MOTOmed attached
            // (ActualValues every 20 ms). They answer no command of the driver's: counted
            // and skipped, never a fault.
            Message::PhaseResult(_)
            | Message::ActualValues { .. }
            | Message::MotomedCommandDone { .. }
            | Message::MotomedError { .. } => {
                self.information += 1;
            }
            Message::StimulationError { error } => {
                self.fault(Command::StimulationError, error.code(), push);
            }
            // The host's own commands: a device never sends them. The line is not what it
            // should be.
            Message::InitAck { .. }
            | Message::Watchdog
            | Message::GetStimulationMode
            | Message::InitChannelListMode(_)
            | Message::StartChannelListMode(_)
            | Message::StopChannelListMode
            | Message::SinglePulse(_) => self.on_line_fault(push),
        }
    }

    /// The STATUS that stands for the device in `mode` (see the module table).
    fn status(
        &mut self,
        mode: Option<StimulationMode>,
        link: &SerialLink,
        push: &mut impl FnMut(BusEvent),
    ) {
        // §3.6 Fig. 4: the driver's SinglePulse is accepted only in the start mode;
        // initialised or started, the device is in channel list mode, which the driver
        // never enters: no configuration shows, so no Arm, and a disarmed driver stops it.
        link.status_answered();
        let channel_list = mode != Some(StimulationMode::Start);
        self.state = if channel_list {
            StimState::Stimulating
        } else {
            match link.last_commanded() {
                Commanded::Operational => StimState::Armed,
                Commanded::Stopped => StimState::Stopped,
                Commanded::PreOperational => StimState::PreOperational,
            }
        };
        let config_id = if !channel_list && self.limits_ok {
            link.config_id()
        } else {
            0
        };
        self.counter = (self.counter + 1) & 0x0F;
        push(BusEvent::Status(fes_can::Status {
            state: self.state,
            counter: self.counter,
            last_error: self.last_error,
            pulses_delivered: self.delivered,
            rejected: self.rejected,
            config_id,
        }));
        if config_id != 0 && config_id != self.read_back {
            self.read_back = config_id;
            for page in self.limits.to_pages(config_id) {
                push(BusEvent::ConfigApplied(page));
            }
        }
    }

    /// A -8 busy answer to `command` (§5.1: the device was still processing the last
    /// command; this one was not executed). The driver waits for each answer, so a busy
    /// device is one whose processing outlasted the wait or that is busy by itself: waited
    /// out ([`BusEvent::DeviceBusy`]), and the [`BUSY_LIMIT`]-th in a row is a device error.
    fn on_busy(&mut self, command: Command, push: &mut impl FnMut(BusEvent)) {
        push(BusEvent::DeviceBusy {
            pulse: command == Command::SinglePulseAck,
        });
        self.busy_streak = self.busy_streak.saturating_add(1);
        if self.busy_streak >= BUSY_LIMIT {
            self.busy_streak = 0;
            self.fault(command, AckResult::BusyError.code(), push);
        }
    }

    /// A packet that failed to decode, a failed read, or the port gone: a link fault.
    pub fn on_line_fault(&mut self, push: &mut impl FnMut(BusEvent)) {
        if self.link_up {
            self.link_up = false;
            push(BusEvent::LinkDown);
        }
    }
}

/// Settings of the ScienceMode receive thread.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SerialRxSettings {
    /// The driver's configured limits (read back once the handshake is done).
    pub limits: StimLimits,
}

/// Runs the receive thread on `port` until `stop` is set (see the module documentation).
/// `on_ready` is called before the first read.
pub fn run_serial_rx(
    settings: &SerialRxSettings,
    mut port: File,
    link: &SerialLink,
    to_forward: &ArrayQueue<BusEvent>,
    counters: &BusCounters,
    stop: &AtomicBool,
    on_ready: impl FnOnce(),
) -> io::Result<()> {
    let mut receiver = Receiver::new(settings.limits);
    let mut decoder = Decoder::new();
    let mut buf = [0u8; 256];
    let fd = port.as_raw_fd();
    let bump = |c: &std::sync::atomic::AtomicU64| {
        c.fetch_add(1, Ordering::Relaxed);
    };
    let mut push = |e: BusEvent| {
        if to_forward.push(e).is_err() {
            bump(&counters.events_lost);
        }
    };
    on_ready();
    while !stop.load(Ordering::Relaxed) {
        let mut pfd = libc::pollfd {
            fd,
            events: libc::POLLIN,
            revents: 0,
        };
        // SAFETY: `pfd` is valid for the call; one descriptor, owned by `port`, open.
        let rc = unsafe { libc::poll(&mut pfd, 1, READ_TIMEOUT.as_millis() as libc::c_int) };
        if rc == 0 {
            continue;
        }
        if rc < 0 {
            if io::Error::last_os_error().kind() != io::ErrorKind::Interrupted {
                bump(&counters.read_errors);
                std::thread::sleep(READ_TIMEOUT);
            }
            continue;
        }
        match port.read(&mut buf) {
            Ok(0) => {
                // End of file: the peer hung up.
                bump(&counters.read_errors);
                receiver.on_line_fault(&mut push);
                std::thread::sleep(READ_TIMEOUT);
            }
            Ok(n) => {
                for result in decoder.feed(&buf[..n]) {
                    match result {
                        Ok(packet) => {
                            bump(&counters.frames);
                            if packet.message.is_motomed_information() {
                                bump(&counters.information_packets);
                            }
                            receiver.on_packet(&packet, link, &mut push);
                        }
                        Err(_) => {
                            bump(&counters.decode_errors);
                            receiver.on_line_fault(&mut push);
                        }
                    }
                }
            }
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
                ) => {}
            Err(_) => {
                // EIO (a pty whose device end closed), ENXIO / ENODEV (the USB adapter
                // unplugged), anything else: the link is gone until reads work again.
                bump(&counters.read_errors);
                receiver.on_line_fault(&mut push);
                std::thread::sleep(READ_TIMEOUT);
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use fes_sciencemode::StimulationError;

    fn run(r: &mut Receiver, link: &SerialLink, m: Message) -> Vec<BusEvent> {
        let mut out = Vec::new();
        r.on_packet(&Packet::new(3, m), link, &mut |e| out.push(e));
        out
    }

    fn mode_ack(mode: StimulationMode) -> Message {
        Message::GetStimulationModeAck {
            result: AckResult::Ok,
            mode: Some(mode),
        }
    }

    fn status(events: &[BusEvent]) -> fes_can::Status {
        match events.first() {
            Some(BusEvent::Status(s)) => *s,
            other => panic!("no STATUS: {other:?}"),
        }
    }

    #[test]
    fn handshake_then_status_carries_the_acknowledged_pulses_and_the_config() {
        let link = SerialLink::new();
        let mut r = Receiver::new(StimLimits::DEFAULT);
        // Init: InitAck due; no event (it is not a restart).
        assert!(run(&mut r, &link, Message::Init { version: 1 }).is_empty());
        assert_eq!(link.take_init(), Some(3));
        assert_eq!(link.take_init(), None);
        // Before the handshake a mode answer is no STATUS.
        assert!(run(&mut r, &link, mode_ack(StimulationMode::Start)).is_empty());
        link.init_acknowledged();
        let s = status(&run(&mut r, &link, mode_ack(StimulationMode::Start)));
        assert_eq!(
            (s.state, s.config_id, s.pulses_delivered),
            (StimState::PreOperational, 0, 0)
        );
        // CONFIG 7 written: STATUS shows it, then the read-back follows once.
        link.config_written(7);
        let e = run(&mut r, &link, mode_ack(StimulationMode::Start));
        assert_eq!(status(&e).config_id, 7);
        assert_eq!(e.len(), 1 + StimLimits::DEFAULT.to_pages(7).len());
        assert!(matches!(e[1], BusEvent::ConfigApplied(c) if c.config_id == 7));
        assert_eq!(
            run(&mut r, &link, mode_ack(StimulationMode::Start)).len(),
            1
        );
        // Armed: pulses acknowledged count; each acknowledgement tells the start mode
        // (§3.6 Fig. 4) and is a STATUS too, and tells the transmit side so.
        link.commanded(Commanded::Operational);
        for n in 1..=5 {
            let s = status(&run(
                &mut r,
                &link,
                Message::SinglePulseAck {
                    result: AckResult::Ok,
                },
            ));
            assert_eq!(
                (s.state, s.pulses_delivered, s.config_id),
                (StimState::Armed, n, 7)
            );
        }
        // Each stood for STATUS (3 mode answers after the handshake, 5 pulses).
        assert_eq!(link.status_answers(), 8);
        let s = status(&run(&mut r, &link, mode_ack(StimulationMode::Start)));
        assert_eq!((s.state, s.pulses_delivered), (StimState::Armed, 5));
    }

    #[test]
    fn channel_list_mode_or_limits_beyond_the_device_show_no_configuration() {
        let link = SerialLink::new();
        link.init_acknowledged();
        link.config_written(4);
        let mut r = Receiver::new(StimLimits::DEFAULT);
        for mode in [StimulationMode::Started, StimulationMode::Initialised] {
            let e = run(&mut r, &link, mode_ack(mode));
            assert_eq!(e.len(), 1, "{e:?}");
            let s = status(&e);
            assert_eq!(
                (s.state, s.config_id),
                (StimState::Stimulating, 0),
                "{mode:?}"
            );
        }
        // 130 mA: more than the device's 126 mA. Never read back, never confirmed.
        let wide = StimLimits {
            max_amplitude_100ua: 1300,
            ..StimLimits::DEFAULT
        };
        assert_eq!(limits_within_device(&wide), Err("max_amplitude_ua"));
        let mut r = Receiver::new(wide);
        let e = run(&mut r, &link, mode_ack(StimulationMode::Start));
        assert_eq!(e.len(), 1, "{e:?}");
        assert_eq!(status(&e).config_id, 0);
    }

    #[test]
    fn device_errors_are_emcys_naming_command_and_code() {
        let link = SerialLink::new();
        let mut r = Receiver::new(StimLimits::DEFAULT);
        let cases = [
            (
                Message::SinglePulseAck {
                    result: AckResult::ParameterError,
                },
                ErrorCode::ValueOutOfRange,
                0x25FE,
            ),
            (
                Message::SinglePulseAck {
                    result: AckResult::WrongModeError,
                },
                ErrorCode::WrongState,
                0x25FD,
            ),
            (
                // §4.1: UnknownCommand echoes the command byte (here 50).
                Message::UnknownCommand { command: 50 },
                ErrorCode::Communication,
                0x0332,
            ),
            (
                // §4.2: an error acknowledgement without a mode (-1 transfer error).
                Message::GetStimulationModeAck {
                    result: AckResult::TransferError,
                    mode: None,
                },
                ErrorCode::Communication,
                0x0BFF,
            ),
            (
                Message::StimulationError {
                    error: StimulationError::Electrode,
                },
                ErrorCode::Generic,
                0x26FE,
            ),
        ];
        for (m, code, detail) in cases {
            match run(&mut r, &link, m).as_slice() {
                [BusEvent::Emcy(e)] => assert_eq!((e.code, e.detail), (code, detail), "{m:?}"),
                other => panic!("{m:?}: {other:?}"),
            }
        }
        // A stop refused because nothing ran is not an error.
        assert!(
            run(
                &mut r,
                &link,
                Message::StopChannelListModeAck {
                    result: AckResult::WrongModeError
                }
            )
            .is_empty()
        );
    }

    #[test]
    fn an_answer_frees_the_awaited_command_and_busy_is_waited_out_up_to_the_limit() {
        let link = SerialLink::new();
        link.init_acknowledged();
        let mut r = Receiver::new(StimLimits::DEFAULT);
        let feed = |r: &mut Receiver, number: u8, m: Message| {
            let mut out = Vec::new();
            r.on_packet(&Packet::new(number, m), &link, &mut |e| out.push(e));
            out
        };
        // §2.3: the answer carries the command's packet number; another number (a late
        // answer to an earlier command) or an unasked packet frees nothing.
        link.awaiting_answer_to(7, 1_000);
        assert!(link.awaiting(2_000, 100_000_000));
        feed(&mut r, 6, mode_ack(StimulationMode::Start));
        feed(&mut r, 0, Message::MotomedError { code: -4 });
        assert!(link.awaiting(2_000, 100_000_000));
        feed(&mut r, 7, mode_ack(StimulationMode::Start));
        assert!(!link.awaiting(2_000, 100_000_000));
        // A lost answer stops the wait after the timeout; an Init ends it at once.
        link.awaiting_answer_to(8, 1_000);
        assert!(!link.awaiting(1_000 + 100_000_000, 100_000_000));
        link.init_received(0);
        assert!(!link.awaiting(2_000, 100_000_000));
        link.init_acknowledged();
        // §5.1 -8: the command was not executed. Waited out, a pulse not delivered; the
        // BUSY_LIMIT-th in a row is a device error naming the command and -8.
        let busy_pulse = Message::SinglePulseAck {
            result: AckResult::BusyError,
        };
        let busy_poll = Message::GetStimulationModeAck {
            result: AckResult::BusyError,
            mode: None,
        };
        assert_eq!(
            feed(&mut r, 9, busy_pulse),
            [BusEvent::DeviceBusy { pulse: true }]
        );
        assert_eq!(
            feed(&mut r, 10, busy_poll),
            [BusEvent::DeviceBusy { pulse: false }]
        );
        // Any other answer ends the run of busy answers.
        let ok = Message::SinglePulseAck {
            result: AckResult::Ok,
        };
        assert!(matches!(
            feed(&mut r, 11, ok).as_slice(),
            [BusEvent::Status(_)]
        ));
        for n in 1..BUSY_LIMIT {
            assert_eq!(
                feed(&mut r, 11 + n, busy_pulse),
                [BusEvent::DeviceBusy { pulse: true }]
            );
        }
        match feed(&mut r, 20, busy_pulse).as_slice() {
            [BusEvent::DeviceBusy { pulse: true }, BusEvent::Emcy(e)] => {
                assert_eq!((e.code, e.detail), (ErrorCode::Generic, 0x25F8));
            }
            other => panic!("{other:?}"),
        }
        // Busy answers deliver nothing.
        assert_eq!(r.delivered(), 1);
    }

    #[test]
    fn motomed_information_packets_are_counted_and_never_a_fault() {
        // §3.5 / §2.3: with a MOTOmed attached the device sends ActualValues every 20 ms
        // (and PhaseResult, MotomedCommandDone, MotomedError) on its own packet counter.
        let link = SerialLink::new();
        link.init_acknowledged();
        let mut r = Receiver::new(StimLimits::DEFAULT);
        let info = [
            Message::ActualValues {
                angle_deg: 90,
                speed_rpm: -30,
                torque_dnm: 15,
            },
            Message::PhaseResult(fes_sciencemode::PhaseResult::default()),
            Message::MotomedCommandDone {
                result: AckResult::Ok,
            },
            Message::MotomedError { code: -4 },
        ];
        for m in info {
            assert!(run(&mut r, &link, m).is_empty(), "{m:?}");
        }
        assert_eq!(r.information_packets(), 4);
        // The link stays up: a STATUS follows as usual.
        let s = status(&run(&mut r, &link, mode_ack(StimulationMode::Start)));
        assert_eq!(s.state, StimState::PreOperational);
    }

    #[test]
    fn a_second_init_is_a_restart_and_line_faults_are_link_faults() {
        let link = SerialLink::new();
        let mut r = Receiver::new(StimLimits::DEFAULT);
        run(&mut r, &link, Message::Init { version: 1 });
        link.take_init();
        link.init_acknowledged();
        link.config_written(2);
        assert_eq!(
            run(&mut r, &link, Message::Init { version: 1 }),
            [BusEvent::StimHeartbeat(NmtState::BootUp)]
        );
        assert!(!link.handshake_done());
        assert_eq!(link.config_id(), 0);
        let mut out = Vec::new();
        r.on_line_fault(&mut |e| out.push(e));
        r.on_line_fault(&mut |e| out.push(e));
        assert_eq!(out, [BusEvent::LinkDown]);
        // A host command from the device's side: the line is wrong.
        let mut r = Receiver::new(StimLimits::DEFAULT);
        assert_eq!(run(&mut r, &link, Message::Watchdog), [BusEvent::LinkDown]);
        // The next good packet: link up (which never re-arms by itself).
        assert_eq!(
            run(
                &mut r,
                &link,
                Message::SinglePulseAck {
                    result: AckResult::Ok
                }
            ),
            [BusEvent::LinkUp]
        );
    }
}
