//! The ScienceMode 2 side of the write seam: [`ScienceModeTx`] implements
//! [`CanTx`], so the forward path, its interlocks and the arming typestate drive a Hasomed
//! RehaStim 2 on a serial line exactly as they drive the CAN stimulator. Each frame the
//! driver writes is translated into the ScienceMode 2 command with the same effect
//! (`docs/sciencemode.md`):
//!
//! | Driver frame | ScienceMode 2 |
//! |--------------|---------------|
//! | PULSE (channel, amplitude, width) | SinglePulse (channel, current, width) |
//! | host heartbeat | Watchdog (the device's keep-alive) |
//! | NMT stop, enter pre-operational, resets | StopChannelListMode (nothing runs without a command; the stop makes it explicit) |
//! | NMT start | nothing (the device has no armed state: a pulse is a command) |
//! | CONFIG | nothing (the device's limits are fixed; the driver's interlocks apply the configured ones before a PULSE exists) |
//!
//! A pulse the device cannot carry exactly (a channel above 8, an amplitude that is not an
//! even number of mA, the device generating currents in 2 mA steps, or above 126 mA, a width
//! above 500 us) is never rounded: the write fails with
//! `EINVAL`, which trips an armed driver ([`crate::forward`]). Writes are allocation-free
//! (a stack buffer), non-blocking with the same bounded retry as the CAN socket, and
//! complete: a packet the line only partly took is finished within the retry budget (a
//! packet torn by a drop is discarded by the device at the next start byte).
//!
//! With a receive side ([`ScienceModeTx::with_link`], [`crate::serial_rx`]) it also
//! answers the device's Init with InitAck, reports the NMT state and CONFIG id the driver
//! commanded to the receive side, and sends GetStimulationMode, the liveness query whose
//! answer stands for STATUS, in place of a Watchdog every `poll` interval.

use std::fs::File;
use std::io::{self, Write};
use std::os::fd::AsRawFd as _;
use std::os::unix::fs::OpenOptionsExt as _;
use std::path::Path;
use std::sync::Arc;

use fes_can::{Frame, Message as CanMessage, NmtCommand, Nodes};
use fes_sciencemode::limits::{CHANNELS, MAX_CURRENT_MA, MAX_PULSE_WIDTH_US};
use fes_sciencemode::{AckResult, MAX_PACKET_LEN, Message, Packet, SinglePulse};
use nix::sys::termios::{
    BaudRate, ControlFlags, InputFlags, SetArg, Termios, cfmakeraw, cfsetspeed, tcgetattr,
    tcsetattr,
};

use crate::serial_rx::{ANSWER_TIMEOUT_MS, Commanded, SerialLink};
use crate::tx::{CanTx, RetryPolicy, TxDone, TxError, write_with_retry};

/// The ScienceMode 2 command for a driver frame (see the module table); `Ok(None)` when
/// the frame has no ScienceMode counterpart, `Err(EINVAL)` when it cannot be carried
/// exactly or is not the driver's to send.
pub fn translate(nodes: &Nodes, frame: &Frame) -> Result<Option<Message>, TxError> {
    const INVALID: TxError = TxError::Failed {
        errno: libc::EINVAL,
    };
    let message = nodes
        .decode(u32::from(frame.id), frame.payload())
        .map_err(|_| INVALID)?;
    Ok(match message {
        CanMessage::Pulse(p) => {
            let current_ma = p.amplitude_100ua / 10;
            if p.channel >= CHANNELS
                // 2 mA steps (HASOMED: 0-126 mA in 2 mA steps): an odd mA would be
                // delivered as a neighbour; refused instead of rounded.
                || !p.amplitude_100ua.is_multiple_of(20)
                || current_ma > u16::from(MAX_CURRENT_MA)
                || p.width_us > MAX_PULSE_WIDTH_US
            {
                return Err(INVALID);
            }
            Some(Message::SinglePulse(SinglePulse {
                channel: p.channel,
                pulse_width_us: p.width_us,
                // current_ma <= MAX_CURRENT_MA (126) fits a byte.
                current_ma: current_ma as u8,
            }))
        }
        CanMessage::HostHeartbeat(_) => Some(Message::Watchdog),
        CanMessage::Nmt(n) => match n.command {
            NmtCommand::Start => None,
            NmtCommand::Stop
            | NmtCommand::EnterPreOperational
            | NmtCommand::ResetNode
            | NmtCommand::ResetCommunication => Some(Message::StopChannelListMode),
        },
        CanMessage::Config(_) => None,
        // The stimulator's own messages: never written by the driver.
        CanMessage::Emcy(_)
        | CanMessage::Force(_)
        | CanMessage::Status(_)
        | CanMessage::ConfigApplied(_)
        | CanMessage::StimHeartbeat(_) => return Err(INVALID),
    })
}

/// The ScienceMode 2 transmit side over a serial port `W` (see the module documentation).
#[derive(Debug)]
pub struct ScienceModeTx<W> {
    port: W,
    nodes: Nodes,
    retry: RetryPolicy,
    number: u8,
    link: Option<Arc<SerialLink>>,
    poll_ns: u64,
    next_poll_ns: u64,
    /// [`SerialLink::status_answers`] when the poll was last scheduled.
    seen_answers: u32,
    /// When that count last changed (seen at a host heartbeat), ns; 0: never.
    last_answer_ns: u64,
    /// Pulses may come soon ([`CanTx::contraction_ahead`]).
    contraction_ahead: bool,
    /// The driver changed the state or configuration and waits for a STATUS showing it:
    /// the next heartbeat is a query.
    query_due: bool,
}

impl<W: Write> ScienceModeTx<W> {
    /// Writes to `port`, reading the driver's frames with `nodes`' identifiers; no receive
    /// side (no handshake, no liveness query).
    pub fn new(port: W, nodes: Nodes, retry: RetryPolicy) -> Self {
        Self {
            port,
            nodes,
            retry,
            number: 0,
            link: None,
            poll_ns: 0,
            next_poll_ns: 0,
            seen_answers: 0,
            last_answer_ns: 0,
            contraction_ahead: false,
            query_due: false,
        }
    }

    /// Writes to `port` beside the receive thread ([`crate::serial_rx`]) that shares
    /// `link`: answers the device's Init with InitAck before the next frame, tells the
    /// receive side the NMT state and CONFIG id the driver commanded, and sends
    /// GetStimulationMode (the liveness query whose answer becomes STATUS) in place of the
    /// Watchdog for a host heartbeat once the handshake is done and `poll_ns` has passed
    /// since the last answer that stood for STATUS (a query's, or a pulse's: it tells the
    /// same). Each command the device answers waits for the answer to the last
    /// ([`CanTx::send`]).
    pub fn with_link(
        port: W,
        nodes: Nodes,
        retry: RetryPolicy,
        link: Arc<SerialLink>,
        poll_ns: u64,
    ) -> Self {
        Self {
            link: Some(link),
            poll_ns,
            ..Self::new(port, nodes, retry)
        }
    }

    /// The number the next packet carries (0, 1, ... 255, 0, ...).
    pub const fn next_number(&self) -> u8 {
        self.number
    }

    /// The port.
    pub fn port(&self) -> &W {
        &self.port
    }

    /// Encodes and writes one packet, complete, within the retry budget.
    fn write_packet(&mut self, packet: Packet) -> Result<TxDone, TxError> {
        let mut buf = [0u8; MAX_PACKET_LEN];
        let len = packet.encode(&mut buf).map_err(|_| TxError::Failed {
            errno: libc::EINVAL,
        })?;
        let mut written = 0;
        let port = &mut self.port;
        let gone_is_down = self.link.is_some();
        let result = write_with_retry(&self.retry, || {
            while written < len {
                match port.write(&buf[written..len]) {
                    Ok(0) => return Err(libc::EIO),
                    Ok(n) => written += n,
                    Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                    Err(e) => return Err(e.raw_os_error().unwrap_or(libc::EIO)),
                }
            }
            Ok(())
        });
        match result {
            // The driver's port (beside its receive side): EIO is a tty whose other end hung
            // up (a pty's device closed), ENXIO a device gone: the link is down, as the
            // receive side reports it too, whichever sees it first.
            Err(TxError::Failed { errno })
                if gone_is_down && matches!(errno, libc::EIO | libc::ENXIO) =>
            {
                Err(TxError::LinkDown { errno })
            }
            other => other,
        }
    }

    /// The receive side's part of a frame (see [`Self::with_link`]): the InitAck due, the
    /// commanded state, and the message to send in place of `message` (none for a host
    /// heartbeat while a command awaits its answer: keep-alives go in the gaps).
    fn link_side(
        &mut self,
        frame: &Frame,
        message: Option<Message>,
        now_ns: u64,
    ) -> Result<Option<Message>, TxError> {
        let Some(link) = self.link.clone() else {
            return Ok(message);
        };
        if let Some(init) = link.take_init() {
            let ack = Packet::new(
                init,
                Message::InitAck {
                    result: AckResult::Ok,
                },
            );
            if let Err(e) = self.write_packet(ack) {
                // Still due: answered with the next frame.
                link.init_received(init);
                return Err(e);
            }
            link.init_acknowledged();
        }
        let Ok(decoded) = self.nodes.decode(u32::from(frame.id), frame.payload()) else {
            return Ok(message);
        };
        match decoded {
            CanMessage::Nmt(n) => {
                link.commanded(match n.command {
                    NmtCommand::Start => Commanded::Operational,
                    NmtCommand::Stop => Commanded::Stopped,
                    NmtCommand::EnterPreOperational
                    | NmtCommand::ResetNode
                    | NmtCommand::ResetCommunication => Commanded::PreOperational,
                });
                // The driver waits for a STATUS showing the new state (bring-up, arming):
                // the query goes with the next heartbeat, not a period later.
                self.query_due = true;
            }
            CanMessage::Config(c) => {
                link.config_written(c.config_id);
                self.query_due = true;
            }
            CanMessage::HostHeartbeat(_) if link.awaiting(now_ns, ANSWER_TIMEOUT_NS) => {
                // The awaited command fed the device's watchdog less than MaxResponseTime
                // ago (1200 ms, §2.3): this keep-alive waits for the next gap.
                return Ok(None);
            }
            CanMessage::HostHeartbeat(_) if link.handshake_done() => {
                // The next query comes `poll` after the last answer that told the mode
                // and the device's liveness (a query's own, or a pulse acknowledged:
                // §3.6 Fig. 4, a SinglePulse runs only in the start mode). The line is
                // then free for `poll` after each answer, and pulses, not queries, hold
                // it while stimulating.
                let answers = link.status_answers();
                if answers != self.seen_answers {
                    self.seen_answers = answers;
                    self.last_answer_ns = now_ns;
                    self.next_poll_ns = now_ns.saturating_add(self.poll_ns);
                }
                // While a contraction runs or a scheduled one is near, the query waits
                // (a pulse would wait behind it) until two periods have passed since the
                // last answer: the stimulator timeout (>= 100 ms + 2 periods) still holds.
                let quiet = self.contraction_ahead
                    && self.last_answer_ns != 0
                    && now_ns < self.last_answer_ns.saturating_add(2 * self.poll_ns);
                if self.query_due || (now_ns >= self.next_poll_ns && !quiet) {
                    self.query_due = false;
                    self.next_poll_ns = now_ns.saturating_add(self.poll_ns);
                    return Ok(Some(Message::GetStimulationMode));
                }
            }
            _ => {}
        }
        Ok(message)
    }
}

impl<W: Write> CanTx for ScienceModeTx<W> {
    fn contraction_ahead(&mut self, ahead: bool) {
        self.contraction_ahead = ahead;
    }

    /// Stop-and-wait with a receive side (§2.3, §5.1): a command the device answers is
    /// written only when the previous one has been answered (or [`ANSWER_TIMEOUT_MS`]
    /// has passed); until then a pulse or a stop is [`TxError::Busy`] (not written, to be tried
    /// again) and a keep-alive is skipped. Without a receive side nothing is awaited.
    fn send(&mut self, frame: &Frame) -> Result<TxDone, TxError> {
        let now = fes_rt::rt::clock::monotonic_ns();
        let message = translate(&self.nodes, frame)?;
        let Some(message) = self.link_side(frame, message, now)? else {
            return Ok(TxDone {
                retries: 0,
                written_ns: now,
                write_ns: 0,
            });
        };
        let awaits = match &self.link {
            Some(link) if message.expects_answer() => {
                if link.awaiting(now, ANSWER_TIMEOUT_NS) {
                    return Err(TxError::Busy);
                }
                link.awaiting_answer_to(self.number, now);
                true
            }
            _ => false,
        };
        let result = self.write_packet(Packet::new(self.number, message));
        if result.is_err()
            && awaits
            && let Some(link) = &self.link
        {
            link.not_awaiting();
        }
        let done = result?;
        self.number = self.number.wrapping_add(1);
        Ok(done)
    }
}

/// [`ANSWER_TIMEOUT_MS`] in ns.
const ANSWER_TIMEOUT_NS: u64 = ANSWER_TIMEOUT_MS as u64 * 1_000_000;

/// Sets `t` to ScienceMode 2's line settings: raw, 460 800 baud, 8 data bits, even parity,
/// one stop bit, no flow control (neither RTS/CTS nor XON/XOFF), modem lines ignored.
pub fn line_settings(t: &mut Termios) -> nix::Result<()> {
    cfmakeraw(t);
    cfsetspeed(t, BaudRate::B460800)?;
    t.control_flags |=
        ControlFlags::CS8 | ControlFlags::PARENB | ControlFlags::CLOCAL | ControlFlags::CREAD;
    t.control_flags &= !(ControlFlags::CSTOPB | ControlFlags::CRTSCTS | ControlFlags::PARODD);
    t.input_flags &= !(InputFlags::IXON | InputFlags::IXOFF | InputFlags::IXANY);
    Ok(())
}

/// Opens a serial device (`/dev/ttyUSB0`) for ScienceMode 2: read and write, no controlling
/// terminal, non-blocking, with [`line_settings`], and owned by this process alone. The
/// RehaStim 2 takes a SinglePulse from whoever writes to its port, so the port is locked
/// two ways: an exclusive advisory lock (`flock`; another driver or `stim-driver probe`
/// is refused with [`io::ErrorKind::ResourceBusy`] naming it, whoever runs it), and the
/// tty's exclusive mode (`TIOCEXCL`: any later `open` by an unprivileged process fails
/// with EBUSY, whatever tool it is). The systemd units add the device cgroup policy
/// (`DevicePolicy=closed`, the device allowed only to the driver).
pub fn open_serial(path: &Path) -> io::Result<File> {
    let port = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .custom_flags(libc::O_NOCTTY | libc::O_NONBLOCK)
        .open(path)?;
    // SAFETY: flock on a descriptor this function owns; no memory is passed.
    if unsafe { libc::flock(port.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } != 0 {
        let e = io::Error::last_os_error();
        return Err(if e.raw_os_error() == Some(libc::EWOULDBLOCK) {
            io::Error::new(
                io::ErrorKind::ResourceBusy,
                "held by another process (its exclusive lock: another stim-driver, or a \
                 `stim-driver probe`); one process at a time drives a stimulator",
            )
        } else {
            e
        });
    }
    // SAFETY: TIOCEXCL takes no argument; the descriptor is this function's own.
    if unsafe { libc::ioctl(port.as_raw_fd(), libc::TIOCEXCL) } != 0 {
        return Err(io::Error::last_os_error());
    }
    let mut t = tcgetattr(&port)?;
    line_settings(&mut t)?;
    match tcsetattr(&port, SetArg::TCSANOW, &t) {
        Ok(()) => {}
        // A pseudo-terminal (the virtual RehaStim 2, tests) has no parity: Linux refuses a
        // request whose only change is PARENB. Everything else is set without it.
        Err(nix::errno::Errno::EINVAL) if is_pty(&port) => {
            t.control_flags.remove(ControlFlags::PARENB);
            tcsetattr(&port, SetArg::TCSANOW, &t)?;
        }
        Err(e) => return Err(e.into()),
    }
    Ok(port)
}

/// The latency timer of the FTDI USB-serial converter behind `device`, ms, read from
/// sysfs under `sys_root` (`/sys`): `class/tty/<ttyUSBn>/device/latency_timer`, `device`'s
/// symbolic links (a udev name such as `/dev/rehastim2`) followed. `None` when there is no
/// such file (not an FTDI adapter, a pty). The protocol description asks for 1 ms (§2.1);
/// the driver's default of 16 ms would hold each of the device's answers up to that long.
pub fn ftdi_latency_timer_ms(sys_root: &Path, device: &Path) -> Option<u32> {
    let real = std::fs::canonicalize(device).ok()?;
    let name = real.file_name()?;
    let path = sys_root
        .join("class/tty")
        .join(name)
        .join("device/latency_timer");
    std::fs::read_to_string(path).ok()?.trim().parse().ok()
}

/// Whether `port` is a pseudo-terminal's slave (`/dev/pts/N`).
fn is_pty(port: &File) -> bool {
    nix::unistd::ttyname(port).is_ok_and(|p| p.starts_with("/dev/pts/"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use fes_can::{Config, Heartbeat, Nmt, NmtState, Pulse};
    use fes_sciencemode::{DecodeError, Decoder};
    use nix::sys::termios::{LocalFlags, cfgetispeed, cfgetospeed};

    const RETRY: RetryPolicy = RetryPolicy {
        budget_ns: 0,
        interval_ns: 0,
    };

    fn frame(m: CanMessage) -> Frame {
        m.encode_for(&Nodes::DEFAULT).unwrap()
    }

    fn pulse(channel: u8, amplitude_100ua: u16, width_us: u16) -> Frame {
        frame(CanMessage::Pulse(Pulse {
            seq: 1,
            alive_counter: 0,
            channel,
            amplitude_100ua,
            width_us,
        }))
    }

    fn written(tx: &ScienceModeTx<Vec<u8>>) -> Vec<Result<Packet, DecodeError>> {
        Decoder::new().feed(tx.port()).collect()
    }

    #[test]
    fn driver_frames_become_the_sciencemode_commands_with_the_same_effect() {
        let mut tx = ScienceModeTx::new(Vec::new(), Nodes::DEFAULT, RETRY);
        let stop = frame(CanMessage::Nmt(Nmt {
            command: NmtCommand::Stop,
            node: Nodes::DEFAULT.stim(),
        }));
        let start = frame(CanMessage::Nmt(Nmt {
            command: NmtCommand::Start,
            node: Nodes::DEFAULT.stim(),
        }));
        let heartbeat = frame(CanMessage::HostHeartbeat(Heartbeat {
            state: NmtState::Operational,
        }));
        for f in [
            heartbeat,
            start,
            pulse(0, 200, 200),
            pulse(7, 1260, 500),
            stop,
        ] {
            tx.send(&f).unwrap();
        }
        assert_eq!(
            written(&tx),
            [
                Ok(Packet::new(0, Message::Watchdog)),
                // NMT start: nothing on the line, no packet number used.
                Ok(Packet::new(
                    1,
                    Message::SinglePulse(SinglePulse {
                        channel: 0,
                        pulse_width_us: 200,
                        current_ma: 20
                    })
                )),
                Ok(Packet::new(
                    2,
                    Message::SinglePulse(SinglePulse {
                        channel: 7,
                        pulse_width_us: 500,
                        current_ma: 126
                    })
                )),
                Ok(Packet::new(3, Message::StopChannelListMode)),
            ]
        );
        assert_eq!(tx.next_number(), 4);
    }

    #[test]
    fn a_pulse_the_device_cannot_carry_exactly_is_refused_not_rounded() {
        let mut tx = ScienceModeTx::new(Vec::new(), Nodes::DEFAULT, RETRY);
        let invalid = Err(TxError::Failed {
            errno: libc::EINVAL,
        });
        // 20.5 mA (not a whole mA), 21 mA (odd: the device's steps are 2 mA), 127 mA,
        // 501 us, channel 9 (index 8).
        for f in [
            pulse(0, 205, 200),
            pulse(0, 210, 200),
            pulse(0, 1270, 200),
            pulse(0, 200, 501),
            pulse(8, 200, 200),
        ] {
            assert_eq!(tx.send(&f), invalid, "{f}");
        }
        // CONFIG has no counterpart: accepted, nothing written.
        let config = frame(CanMessage::Config(Config {
            config_id: 1,
            page: fes_can::ConfigPage::OutputLimits {
                max_amplitude_100ua: 300,
                max_width_us: 400,
                min_ipi_ms: 10,
            },
        }));
        assert!(tx.send(&config).is_ok());
        assert!(tx.port().is_empty());
    }

    /// A writer that takes at most `chunk` bytes per call and fails with `EAGAIN` on every
    /// other call.
    struct Stingy {
        out: Vec<u8>,
        chunk: usize,
        calls: u32,
        errno: Option<i32>,
    }

    impl Write for Stingy {
        fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
            self.calls += 1;
            if let Some(e) = self.errno {
                return Err(io::Error::from_raw_os_error(e));
            }
            if self.calls.is_multiple_of(2) {
                return Err(io::Error::from_raw_os_error(libc::EAGAIN));
            }
            let n = buf.len().min(self.chunk);
            self.out.extend_from_slice(&buf[..n]);
            Ok(n)
        }
        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn short_writes_and_a_full_line_are_finished_within_the_budget_and_a_dead_port_reported() {
        let retry = RetryPolicy {
            budget_ns: 50_000_000,
            interval_ns: 10_000,
        };
        let stingy = Stingy {
            out: Vec::new(),
            chunk: 3,
            calls: 0,
            errno: None,
        };
        let mut tx = ScienceModeTx::new(stingy, Nodes::DEFAULT, retry);
        let done = tx.send(&pulse(1, 300, 250)).unwrap();
        assert!(done.retries >= 3, "{done:?}");
        let out: Vec<_> = Decoder::new().feed(&tx.port().out).collect();
        assert_eq!(
            out,
            [Ok(Packet::new(
                0,
                Message::SinglePulse(SinglePulse {
                    channel: 1,
                    pulse_width_us: 250,
                    current_ma: 30
                })
            ))]
        );
        // The USB adapter unplugged: ENODEV is a link down, EIO a failure (both trip).
        for (errno, expected) in [
            (
                libc::ENODEV,
                TxError::LinkDown {
                    errno: libc::ENODEV,
                },
            ),
            (libc::EIO, TxError::Failed { errno: libc::EIO }),
        ] {
            let dead = Stingy {
                out: Vec::new(),
                chunk: 64,
                calls: 0,
                errno: Some(errno),
            };
            let mut tx = ScienceModeTx::new(dead, Nodes::DEFAULT, retry);
            assert_eq!(tx.send(&pulse(0, 200, 200)), Err(expected));
            // A failed packet does not use up a number.
            assert_eq!(tx.next_number(), 0);
        }
    }

    #[test]
    fn with_a_receive_side_init_is_answered_state_reported_and_a_hung_up_port_is_link_down() {
        let link = Arc::new(SerialLink::new());
        let mut tx = ScienceModeTx::with_link(Vec::new(), Nodes::DEFAULT, RETRY, link.clone(), 0);
        let heartbeat = frame(CanMessage::HostHeartbeat(Heartbeat {
            state: NmtState::PreOperational,
        }));
        // Before the handshake: a Watchdog; then InitAck (the Init's number) before the
        // next frame, and GetStimulationMode in place of the Watchdog.
        tx.send(&heartbeat).unwrap();
        link.init_received(42);
        tx.send(&heartbeat).unwrap();
        assert!(link.handshake_done());
        let start = frame(CanMessage::Nmt(Nmt {
            command: NmtCommand::Start,
            node: Nodes::DEFAULT.stim(),
        }));
        tx.send(&start).unwrap();
        assert_eq!(link.last_commanded(), Commanded::Operational);
        let config = frame(CanMessage::Config(Config {
            config_id: 9,
            page: fes_can::ConfigPage::OutputLimits {
                max_amplitude_100ua: 300,
                max_width_us: 400,
                min_ipi_ms: 10,
            },
        }));
        tx.send(&config).unwrap();
        assert_eq!(link.config_id(), 9);
        assert_eq!(
            written(&tx),
            [
                Ok(Packet::new(0, Message::Watchdog)),
                Ok(Packet::new(
                    42,
                    Message::InitAck {
                        result: AckResult::Ok
                    }
                )),
                Ok(Packet::new(1, Message::GetStimulationMode)),
            ]
        );
        // The device answers the mode query.
        assert!(link.answer_received(1));
        // The device end hung up: EIO is the link down (without a receive side, a failure).
        let dead = |errno| Stingy {
            out: Vec::new(),
            chunk: 64,
            calls: 0,
            errno: Some(errno),
        };
        let mut tx = ScienceModeTx::with_link(dead(libc::EIO), Nodes::DEFAULT, RETRY, link, 0);
        assert_eq!(
            tx.send(&pulse(0, 200, 200)),
            Err(TxError::LinkDown { errno: libc::EIO })
        );
        let mut tx = ScienceModeTx::new(dead(libc::EIO), Nodes::DEFAULT, RETRY);
        assert_eq!(
            tx.send(&pulse(0, 200, 200)),
            Err(TxError::Failed { errno: libc::EIO })
        );
    }

    #[test]
    fn with_a_receive_side_each_command_waits_for_the_answer_to_the_last() {
        // §2.3 / §5.1: a command sent while the device still processes the last one is
        // answered -8 busy and not executed. The host sends one and waits.
        // (Before the handshake, so that a host heartbeat is a Watchdog, not a mode query.)
        let link = Arc::new(SerialLink::new());
        let mut tx =
            ScienceModeTx::with_link(Vec::new(), Nodes::DEFAULT, RETRY, link.clone(), u64::MAX);
        let heartbeat = frame(CanMessage::HostHeartbeat(Heartbeat {
            state: NmtState::Operational,
        }));
        let stop = frame(CanMessage::Nmt(Nmt {
            command: NmtCommand::Stop,
            node: Nodes::DEFAULT.stim(),
        }));
        tx.send(&pulse(0, 200, 200)).unwrap();
        // Unanswered: a pulse and a stop are not written (Busy, to be tried again), a
        // keep-alive is skipped (the pulse fed the device's watchdog).
        assert_eq!(tx.send(&pulse(1, 200, 200)), Err(TxError::Busy));
        assert_eq!(tx.send(&stop), Err(TxError::Busy));
        assert!(tx.send(&heartbeat).is_ok());
        assert_eq!(written(&tx).len(), 1);
        // An answer to another packet number frees nothing; the pulse's own does.
        assert!(!link.answer_received(5));
        assert_eq!(tx.send(&pulse(1, 200, 200)), Err(TxError::Busy));
        assert!(link.answer_received(0));
        tx.send(&pulse(1, 200, 200)).unwrap();
        assert!(link.answer_received(1));
        // A Watchdog has no answer (§4.2): nothing is awaited after it.
        tx.send(&heartbeat).unwrap();
        tx.send(&stop).unwrap();
        let numbers: Vec<_> = written(&tx)
            .into_iter()
            .map(|p| {
                let p = p.unwrap();
                (p.number, p.message.command())
            })
            .collect();
        assert_eq!(
            numbers,
            [
                (0, fes_sciencemode::Command::SinglePulse),
                (1, fes_sciencemode::Command::SinglePulse),
                (2, fes_sciencemode::Command::Watchdog),
                (3, fes_sciencemode::Command::StopChannelListMode),
            ]
        );
        // A command whose write failed awaits nothing.
        assert!(link.answer_received(3));
        let dead = Stingy {
            out: Vec::new(),
            chunk: 64,
            calls: 0,
            errno: Some(libc::EIO),
        };
        let mut tx = ScienceModeTx::with_link(dead, Nodes::DEFAULT, RETRY, link.clone(), 0);
        assert!(tx.send(&pulse(0, 200, 200)).is_err());
        assert!(!link.awaiting(fes_rt::rt::clock::monotonic_ns(), u64::MAX));
    }

    #[test]
    fn the_mode_query_waits_a_poll_period_after_the_last_status_answer() {
        // A SinglePulse acknowledged with result 0 tells the mode (§3.6 Fig. 4) and the
        // device's liveness: a query then would only hold the line a pulse may need.
        let link = Arc::new(SerialLink::new());
        link.init_acknowledged();
        let poll_ns = 30_000_000;
        let mut tx =
            ScienceModeTx::with_link(Vec::new(), Nodes::DEFAULT, RETRY, link.clone(), poll_ns);
        let heartbeat = frame(CanMessage::HostHeartbeat(Heartbeat {
            state: NmtState::Operational,
        }));
        let pause = || std::thread::sleep(std::time::Duration::from_nanos(poll_ns + 5_000_000));
        tx.send(&heartbeat).unwrap();
        assert!(link.answer_received(0));
        pause();
        link.status_answered();
        tx.send(&heartbeat).unwrap();
        pause();
        tx.send(&heartbeat).unwrap();
        let commands: Vec<_> = written(&tx)
            .into_iter()
            .map(|p| p.unwrap().message.command())
            .collect();
        use fes_sciencemode::Command::{GetStimulationMode, Watchdog};
        assert_eq!(commands, [GetStimulationMode, Watchdog, GetStimulationMode]);
    }

    #[test]
    fn with_a_contraction_ahead_the_query_waits_two_periods_after_the_last_answer() {
        // A pulse must not wait behind a query: while a contraction runs or a scheduled
        // one is near (StimTick FLAG_CONTRACTION_AHEAD), the query waits until two periods
        // have passed since the last answer (the stimulator timeout allows that).
        let link = Arc::new(SerialLink::new());
        link.init_acknowledged();
        let poll_ns = 20_000_000;
        let mut tx =
            ScienceModeTx::with_link(Vec::new(), Nodes::DEFAULT, RETRY, link.clone(), poll_ns);
        let heartbeat = frame(CanMessage::HostHeartbeat(Heartbeat {
            state: NmtState::Operational,
        }));
        let ms = |n: u64| std::thread::sleep(std::time::Duration::from_millis(n));
        tx.send(&heartbeat).unwrap(); // the first query
        assert!(link.answer_received(0));
        link.status_answered();
        tx.contraction_ahead(true);
        tx.send(&heartbeat).unwrap(); // the answer seen: a Watchdog
        ms(25);
        tx.send(&heartbeat).unwrap(); // one period passed, contraction ahead: a Watchdog
        ms(20);
        tx.send(&heartbeat).unwrap(); // two periods: the query (packet 3)
        assert!(link.answer_received(3));
        link.status_answered();
        tx.contraction_ahead(false);
        tx.send(&heartbeat).unwrap(); // the answer seen: a Watchdog
        ms(25);
        tx.send(&heartbeat).unwrap(); // at rest, one period: the query (packet 5)
        assert!(link.answer_received(5));
        link.status_answered();
        tx.send(&heartbeat).unwrap(); // the answer seen: a Watchdog
        // A CONFIG (or an NMT command) waits for a STATUS showing it: the query goes with
        // the next heartbeat, whatever the period.
        let config = frame(CanMessage::Config(Config {
            config_id: 3,
            page: fes_can::ConfigPage::OutputLimits {
                max_amplitude_100ua: 300,
                max_width_us: 400,
                min_ipi_ms: 10,
            },
        }));
        tx.send(&config).unwrap();
        tx.send(&heartbeat).unwrap();
        let commands: Vec<_> = written(&tx)
            .into_iter()
            .map(|p| p.unwrap().message.command())
            .collect();
        use fes_sciencemode::Command::{GetStimulationMode as Q, Watchdog as W};
        assert_eq!(commands, [Q, W, W, Q, W, Q, W, Q]);
    }

    #[test]
    fn the_ftdi_latency_timer_is_read_through_the_udev_name() {
        // §2.1: the FTDI latency timer should be 1 ms. A fake sysfs and /dev.
        let scratch = fes_testkit::Scratch::new("ftdi-latency");
        let dir = scratch.path();
        let timer = dir.join("sys/class/tty/ttyUSB7/device");
        std::fs::create_dir_all(&timer).unwrap();
        std::fs::create_dir_all(dir.join("dev")).unwrap();
        std::fs::write(dir.join("dev/ttyUSB7"), b"").unwrap();
        std::os::unix::fs::symlink(dir.join("dev/ttyUSB7"), dir.join("dev/rehastim2")).unwrap();
        std::fs::write(timer.join("latency_timer"), b"16\n").unwrap();
        let sys = dir.join("sys");
        assert_eq!(
            ftdi_latency_timer_ms(&sys, &dir.join("dev/rehastim2")),
            Some(16)
        );
        std::fs::write(timer.join("latency_timer"), b"1\n").unwrap();
        assert_eq!(
            ftdi_latency_timer_ms(&sys, &dir.join("dev/ttyUSB7")),
            Some(1)
        );
        // No such adapter (a pty, another converter): nothing to say.
        std::fs::write(dir.join("dev/ttyS0"), b"").unwrap();
        assert_eq!(ftdi_latency_timer_ms(&sys, &dir.join("dev/ttyS0")), None);
    }

    #[test]
    fn the_port_is_owned_by_the_process_that_opened_it() {
        // A pseudo-terminal stands in for /dev/ttyUSB0, open to everyone (0666) so that
        // only the exclusivity can refuse.
        let pty = nix::pty::openpty(None, None).unwrap();
        let path = nix::unistd::ttyname(&pty.slave).unwrap();
        std::fs::set_permissions(&path, std::os::unix::fs::PermissionsExt::from_mode(0o666))
            .unwrap();
        let port = open_serial(&path).unwrap();
        // Another driver or probe (the advisory lock), root or not.
        let second = open_serial(&path).expect_err("a second open_serial");
        assert_eq!(second.kind(), io::ErrorKind::ResourceBusy, "{second}");
        // Any other unprivileged process (the tty's exclusive mode): root may open an
        // exclusive tty, so the open is tried by a child that has dropped to nobody.
        let c_path = std::ffi::CString::new(path.as_os_str().as_encoded_bytes()).unwrap();
        let errno = if nix::unistd::geteuid().is_root() {
            // SAFETY: the child calls only async-signal-safe functions (setgid, setuid,
            // open, _exit) on memory prepared before the fork.
            match unsafe { libc::fork() } {
                // SAFETY: in the forked child, as above: async-signal-safe calls only.
                0 => unsafe {
                    let code = if libc::setgid(65534) != 0 || libc::setuid(65534) != 0 {
                        3
                    } else if libc::open(c_path.as_ptr(), libc::O_RDWR | libc::O_NOCTTY) >= 0 {
                        1
                    } else if *libc::__errno_location() == libc::EBUSY {
                        0
                    } else {
                        2
                    };
                    libc::_exit(code)
                },
                pid => {
                    assert!(pid > 0, "fork");
                    let mut status = 0;
                    // SAFETY: waits for the child just forked; `status` is a local.
                    assert_eq!(unsafe { libc::waitpid(pid, &mut status, 0) }, pid);
                    assert!(libc::WIFEXITED(status));
                    match libc::WEXITSTATUS(status) {
                        0 => libc::EBUSY,
                        1 => 0,
                        code => panic!("the unprivileged child could not try (exit {code})"),
                    }
                }
            }
        } else {
            std::fs::OpenOptions::new()
                .read(true)
                .write(true)
                .open(&path)
                .err()
                .and_then(|e| e.raw_os_error())
                .unwrap_or(0)
        };
        assert_eq!(errno, libc::EBUSY, "an unprivileged open was not refused");
        // Closed, the lock is free again (the exclusive mode stays while another
        // descriptor holds the tty, here the pty's own, so only root can show it).
        drop(port);
        if nix::unistd::geteuid().is_root() {
            drop(open_serial(&path).unwrap());
        }
    }

    #[test]
    fn open_serial_sets_the_protocols_line_settings() {
        // A pseudo-terminal stands in for /dev/ttyUSB0.
        let pty = nix::pty::openpty(None, None).unwrap();
        let path = nix::unistd::ttyname(&pty.slave).unwrap();
        // What is requested: 8E1, no flow control, raw.
        let mut t = tcgetattr(&pty.slave).unwrap();
        line_settings(&mut t).unwrap();
        assert!(
            t.control_flags
                .contains(ControlFlags::CS8 | ControlFlags::PARENB)
        );
        assert!(
            !t.control_flags
                .intersects(ControlFlags::CSTOPB | ControlFlags::CRTSCTS | ControlFlags::PARODD)
        );
        assert!(
            !t.input_flags
                .intersects(InputFlags::IXON | InputFlags::IXOFF)
        );
        // What the device file holds after open_serial (a pty has no parity and always
        // reads back CS8 without PARENB, so only speed, size and raw mode are checked).
        let port = open_serial(&path).unwrap();
        let t = tcgetattr(&port).unwrap();
        assert_eq!(cfgetispeed(&t), BaudRate::B460800);
        assert_eq!(cfgetospeed(&t), BaudRate::B460800);
        assert!(t.control_flags.contains(ControlFlags::CS8));
        assert!(
            !t.control_flags
                .intersects(ControlFlags::CSTOPB | ControlFlags::CRTSCTS)
        );
        assert!(
            !t.input_flags
                .intersects(InputFlags::IXON | InputFlags::IXOFF)
        );
        assert!(
            !t.local_flags
                .intersects(LocalFlags::ICANON | LocalFlags::ECHO)
        );
        // And a packet written there arrives on the other side unchanged.
        let mut tx = ScienceModeTx::new(port, Nodes::DEFAULT, RETRY);
        tx.send(&pulse(2, 400, 300)).unwrap();
        let mut master = File::from(pty.master);
        let mut buf = [0u8; MAX_PACKET_LEN];
        let n = std::io::Read::read(&mut master, &mut buf).unwrap();
        let out: Vec<_> = Decoder::new().feed(&buf[..n]).collect();
        assert_eq!(
            out,
            [Ok(Packet::new(
                0,
                Message::SinglePulse(SinglePulse {
                    channel: 2,
                    pulse_width_us: 300,
                    current_ma: 40
                })
            ))]
        );
    }
}
