//! The virtual RehaStim 2 ([`super::rehastim2`]) on a pseudo-terminal: the host opens the
//! pty's slave side as it would the device's `/dev/ttyUSB0` (ScienceMode 2's line settings,
//! 460 800 baud 8E1, no flow control, raw mode), and the device runs a 1 ms absolute-time
//! loop on the master side: drain the bytes received into the decoder, run the tick, write
//! the answers.
//!
//! The pty's path is published as a symbolic link (`--pty-link`); every pulse and event
//! goes to a CSV log (`--pulse-log`): `t_ms,event,channel,width_us,current_ma,source,applied,detail`
//! with `event` one of `pulse`, `watchdog` (detail: silence in ms) and `bad_packet`
//! (detail: the decode error).

use std::fs::File;
use std::io::{BufWriter, ErrorKind, Read as _, Write as _};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use fes_sciencemode::{DecodeError, Decoder};
use nix::fcntl::{FcntlArg, FdFlag, OFlag, fcntl};
use nix::pty::openpty;
use nix::sys::termios::{
    BaudRate, ControlFlags, SetArg, cfmakeraw, cfsetspeed, tcgetattr, tcsetattr,
};

use super::clock::{monotonic_ns, sleep_until};
use super::rehastim2::{Event, PulseSource, Rehastim2, Rehastim2Settings, TICK_NS, TestFault};
use crate::plant::Plant;
use fes_rt::msg::{Contract as _, ForceSample};

/// `sim-muscle rehastim2 --processing-ms`'s default, ms: the device as HASOMED documents it
/// (answers on average under 20 ms, §2.3; 5-15 ms here, 3 % at 100 ms). The library's
/// [`Rehastim2Settings::DEFAULT`] answers at once, for tests of everything else.
pub const DOCUMENTED_PROCESSING_MS: u16 = 10;

/// Command-line options of the virtual RehaStim 2 (`sim-muscle rehastim2 ...`).
#[derive(Debug, Clone, clap::Args)]
pub struct Rehastim2Args {
    /// Publish the pty's slave path as this symbolic link (replaced if present); the host
    /// opens it as it would the device's serial port.
    #[arg(long)]
    pub pty_link: PathBuf,
    /// Write every pulse and event to this CSV file.
    #[arg(long)]
    pub pulse_log: Option<PathBuf>,
    /// The device's watchdog (§2.3: 1200 ms): after this much silence from the host,
    /// stimulation stops, every mode is reset and the device announces Init again, ms.
    #[arg(long, default_value_t = Rehastim2Settings::DEFAULT.watchdog_ms)]
    pub watchdog_ms: u16,
    /// Period of the Init announcement until the host answers, ms (§2.3
    /// InitRepetitionTime: 500).
    #[arg(long, default_value_t = Rehastim2Settings::DEFAULT.init_period_ms)]
    pub init_period_ms: u16,
    /// The channel (1..=8) whose muscle the plant models; pulses on others are logged only.
    #[arg(long, default_value_t = Rehastim2Settings::DEFAULT.muscle_channel)]
    pub muscle_channel: u8,
    /// Stop by itself after this many seconds (default: run until SIGINT/SIGTERM).
    #[arg(long)]
    pub duration_s: Option<f64>,
    /// The device's latency in executing a command, ms (0: the next 1 ms tick; a real
    /// RehaStim 2 takes 10-24 ms): each packet is acted on and answered this much later.
    #[arg(long, default_value_t = Rehastim2Settings::DEFAULT.latency_ms)]
    pub latency_ms: u16,
    /// Inject a fault for tests of a host: `electrode:N` (StimulationError instead of the
    /// (N+1)-th single pulse), `parameter-error:N` (that pulse acknowledged with a parameter
    /// error), `silent:N` (nothing answered from that pulse on).
    #[arg(long, value_name = "KIND:N")]
    pub test_fault: Option<TestFault>,
    /// A MOTOmed attached: send ActualValues every 20 ms once connected (§2.3, §4.4), as
    /// a real RehaStim 2 does unasked.
    #[arg(long)]
    pub motomed: bool,
    /// The device's mean time to process a command, ms (0: every command answered at
    /// once). Each command with an acknowledgement takes 0.5..1.5 x this, a few per cent
    /// 100 ms (§2.3: "responses within 100 ms, on average under 20 ms"), and a command
    /// arriving meanwhile is answered -8 busy (§5.1). The default is the document's device.
    #[arg(long, default_value_t = DOCUMENTED_PROCESSING_MS)]
    pub processing_ms: u16,
    /// Publish the muscle's force every tick as iceoryx2 ForceSamples under this service
    /// prefix, as the rig's separate force sensor would (a RehaStim 2 measures no force;
    /// on CAN the driver publishes the stimulator's FORCE frames). Needs `--force-max-n`.
    #[arg(long, value_name = "PREFIX", requires = "force_max_n")]
    pub force_prefix: Option<String>,
    /// The muscle's maximal force, N: `ForceSample.force = force_n / max_n` (the driver's
    /// `[force] max_n` on CAN).
    #[arg(long, value_name = "N", requires = "force_prefix")]
    pub force_max_n: Option<f64>,
}

/// Why the virtual RehaStim 2 could not run.
#[derive(Debug, thiserror::Error)]
pub enum PtyError {
    /// An option is out of range.
    #[error("{0}")]
    Options(String),
    /// Opening or configuring the pseudo-terminal failed.
    #[error("{what}")]
    Pty {
        /// What was being done.
        what: &'static str,
        /// The system's error.
        #[source]
        source: nix::Error,
    },
    /// The ForceSample publisher (`--force-prefix`) could not be made.
    #[error("{what}")]
    Ipc {
        /// What was being made.
        what: &'static str,
        /// iceoryx2's error.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// A file (the link, the log, the pty) could not be used.
    #[error("{what} {}", path.display())]
    Io {
        /// What was being done.
        what: &'static str,
        /// The file.
        path: PathBuf,
        /// The system's error.
        #[source]
        source: std::io::Error,
    },
}

fn pty_err(what: &'static str) -> impl FnOnce(nix::Error) -> PtyError {
    move |source| PtyError::Pty { what, source }
}

fn io_err(what: &'static str, path: &Path) -> impl FnOnce(std::io::Error) -> PtyError {
    let path = path.to_owned();
    move |source| PtyError::Io { what, path, source }
}

impl Rehastim2Args {
    /// The validated device settings.
    pub fn settings(&self) -> Result<Rehastim2Settings, PtyError> {
        if !(1..=fes_sciencemode::limits::CHANNELS).contains(&self.muscle_channel) {
            return Err(PtyError::Options(format!(
                "--muscle-channel {} is not a channel 1..=8",
                self.muscle_channel
            )));
        }
        if self.latency_ms > 1000 {
            return Err(PtyError::Options(format!(
                "--latency-ms {} must be at most 1000",
                self.latency_ms
            )));
        }
        if self.watchdog_ms == 0 || self.init_period_ms == 0 {
            return Err(PtyError::Options(
                "--watchdog-ms and --init-period-ms must be positive".into(),
            ));
        }
        Ok(Rehastim2Settings {
            watchdog_ms: self.watchdog_ms,
            init_period_ms: self.init_period_ms,
            muscle_channel: self.muscle_channel,
            test_fault: self.test_fault,
            latency_ms: self.latency_ms,
            motomed_actual_values: self.motomed,
            processing_mean_ms: self.processing_ms,
        })
    }

    fn max_ticks(&self) -> Result<Option<u64>, PtyError> {
        match self.duration_s {
            None => Ok(None),
            Some(d) if d.is_finite() && d > 0.0 && d < 1e7 => Ok(Some((d * 1000.0).round() as u64)),
            Some(d) => Err(PtyError::Options(format!(
                "--duration-s {d} must be a positive number of seconds"
            ))),
        }
    }
}

/// The force sensor's stand-in: ForceSamples on iceoryx2 (`--force-prefix`).
struct ForceOut {
    /// Sends one sample (the node and the publisher live in the closure).
    send: Box<dyn FnMut(ForceSample) -> bool>,
    max_n: f64,
    seq: u64,
}

impl ForceOut {
    fn open(prefix: &str, max_n: f64) -> Result<Self, PtyError> {
        if !(max_n.is_finite() && max_n > 0.0) {
            return Err(PtyError::Options(format!(
                "--force-max-n {max_n} must be a positive number of newtons"
            )));
        }
        let node =
            fes_rt::rt::node::create_node("sim-muscle-rehastim2").map_err(|e| PtyError::Ipc {
                what: "the iceoryx2 node for ForceSample",
                source: Box::new(e),
            })?;
        let publisher =
            fes_rt::msg::port::publisher::<ForceSample>(&node, prefix).map_err(|e| {
                PtyError::Ipc {
                    what: "the ForceSample publisher",
                    source: Box::new(e),
                }
            })?;
        Ok(Self {
            send: Box::new(move |sample| {
                let _node = &node;
                publisher.send_copy(sample).is_ok()
            }),
            max_n,
            seq: 0,
        })
    }

    /// Publishes `force_n` now; a value ForceSample cannot carry is skipped, as the
    /// driver skips such a FORCE frame.
    fn publish(&mut self, force_n: f64) {
        let sample = ForceSample {
            seq: self.seq + 1,
            t_ns: monotonic_ns(),
            // The pulse that caused it is the driver's to know; no driver publishes here.
            stim_seq: 0,
            force_n,
            force: force_n / self.max_n,
        };
        if sample.validate().is_ok() && (self.send)(sample) {
            self.seq += 1;
        }
    }
}

/// What a run did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PtyRunSummary {
    /// Ticks run.
    pub ticks: u64,
    /// Packets received and decoded.
    pub packets_rx: u64,
    /// Byte sequences that did not decode.
    pub bad_packets: u64,
    /// Pulses fired (all channels).
    pub pulses: u64,
    /// Answer bytes dropped because the pty's buffer was full (nobody reading).
    pub tx_dropped: u64,
    /// -8 busy acknowledgements sent (§5.1).
    pub busy_sent: u64,
    /// Commands that took the slow processing time (`--processing-ms`).
    pub slow_commands: u64,
    /// -3 wrong-mode acknowledgements sent.
    pub wrong_mode_sent: u64,
}

/// The pty pair, the slave side configured as the device's serial line.
struct Pty {
    master: File,
    /// Held open so the master never sees a hang-up while no host has the port open.
    _slave: std::os::fd::OwnedFd,
    path: PathBuf,
}

fn open_pty() -> Result<Pty, PtyError> {
    let pair = openpty(None, None).map_err(pty_err("openpty"))?;
    // Raw mode at the protocol's settings: 460 800 baud, 8 data bits, even parity, one stop
    // bit, no flow control. Raw mode also ends the echo, which would send the device's own
    // packets back to it.
    let mut t = tcgetattr(&pair.slave).map_err(pty_err("tcgetattr"))?;
    cfmakeraw(&mut t);
    cfsetspeed(&mut t, BaudRate::B460800).map_err(pty_err("cfsetspeed"))?;
    t.control_flags |= ControlFlags::CS8 | ControlFlags::PARENB | ControlFlags::CLOCAL;
    t.control_flags &= !(ControlFlags::CSTOPB | ControlFlags::CRTSCTS | ControlFlags::PARODD);
    tcsetattr(&pair.slave, SetArg::TCSANOW, &t).map_err(pty_err("tcsetattr"))?;
    let path = nix::unistd::ttyname(&pair.slave).map_err(pty_err("ttyname"))?;
    let flags = fcntl(&pair.master, FcntlArg::F_GETFL).map_err(pty_err("fcntl F_GETFL"))?;
    fcntl(
        &pair.master,
        FcntlArg::F_SETFL(OFlag::from_bits_truncate(flags) | OFlag::O_NONBLOCK),
    )
    .map_err(pty_err("fcntl O_NONBLOCK"))?;
    // Close-on-exec: a process this one starts (a host under test, run from the same test
    // process) must not inherit the device's end, or the device switched off would leave
    // its pty open and the host would never see the hang-up.
    for fd in [&pair.master, &pair.slave] {
        fcntl(fd, FcntlArg::F_SETFD(FdFlag::FD_CLOEXEC)).map_err(pty_err("fcntl FD_CLOEXEC"))?;
    }
    Ok(Pty {
        master: File::from(pair.master),
        _slave: pair.slave,
        path,
    })
}

fn write_event(log: &mut impl std::io::Write, e: &Event) -> std::io::Result<()> {
    match *e {
        Event::Pulse {
            tick,
            channel,
            width_us,
            current_ma,
            source,
            applied,
        } => {
            let source = match source {
                PulseSource::Single => "single",
                PulseSource::ChannelList => "channel_list",
            };
            writeln!(
                log,
                "{tick},pulse,{channel},{width_us},{current_ma},{source},{},",
                u8::from(applied)
            )
        }
        Event::WatchdogExpired { tick, silent_ms } => {
            writeln!(log, "{tick},watchdog,,,,,,{silent_ms}")
        }
        Event::BadPacket { tick, error } => {
            writeln!(
                log,
                "{tick},bad_packet,,,,,,{}",
                error.to_string().replace(',', ";")
            )
        }
    }
}

/// The pulse log being written and its path (for the error messages).
type PulseLog = (BufWriter<File>, PathBuf);

/// Runs the virtual RehaStim 2 on a new pty until `stop` is set (or `--duration-s`).
pub fn run_rehastim2_until(
    args: &Rehastim2Args,
    plant: &mut dyn Plant,
    stop: &AtomicBool,
) -> Result<PtyRunSummary, PtyError> {
    let settings = args.settings()?;
    let max_ticks = args.max_ticks()?;
    if (plant.ts() - 1e-3).abs() > 1e-12 {
        return Err(PtyError::Options(format!(
            "the muscle model samples at {} s; the device runs a 1 ms loop and needs Ts = 0.001 s",
            plant.ts()
        )));
    }
    let mut log = open_pulse_log(args.pulse_log.as_deref())?;
    let mut pty = open_pty()?;
    let _ = std::fs::remove_file(&args.pty_link);
    std::os::unix::fs::symlink(&pty.path, &args.pty_link)
        .map_err(io_err("linking the pty as", &args.pty_link))?;
    tracing::info!(
        "virtual RehaStim 2 on {} (link {})",
        pty.path.display(),
        args.pty_link.display()
    );

    let mut force_out = match (&args.force_prefix, args.force_max_n) {
        (Some(prefix), Some(max_n)) => Some(ForceOut::open(prefix, max_n)?),
        _ => None,
    };
    let mut device = Rehastim2::new(settings);
    let mut decoder = Decoder::new();
    let mut out = Vec::with_capacity(4096);
    let mut summary = PtyRunSummary::default();
    let mut deadline = monotonic_ns();
    while !stop.load(Ordering::Relaxed) && max_ticks.is_none_or(|m| summary.ticks < m) {
        deadline += TICK_NS;
        read_packets(
            &mut pty.master,
            &mut decoder,
            &mut device,
            &mut out,
            &mut summary,
        );
        device.tick(plant, &mut out);
        summary.ticks += 1;
        if let Some(f) = force_out.as_mut() {
            f.publish(device.force_n());
        }
        write_answers(&mut pty.master, &mut out, &mut summary);
        account_events(&mut device, &mut summary, log.as_mut())?;
        deadline = sleep_to(deadline, stop);
    }
    if let Some((mut w, p)) = log {
        w.flush().map_err(io_err("writing the pulse log", &p))?;
    }
    let _ = std::fs::remove_file(&args.pty_link);
    Ok(summary)
}

/// Creates the pulse log at `path` (if any) with its header line.
fn open_pulse_log(path: Option<&Path>) -> Result<Option<PulseLog>, PtyError> {
    let Some(p) = path else {
        return Ok(None);
    };
    let mut w = BufWriter::new(File::create(p).map_err(io_err("creating the pulse log", p))?);
    writeln!(
        w,
        "t_ms,event,channel,width_us,current_ma,source,applied,detail"
    )
    .map_err(io_err("writing the pulse log", p))?;
    Ok(Some((w, p.to_path_buf())))
}

/// Hands the device every packet the host wrote since the last tick (the master side is
/// non-blocking: it reads until nothing is left).
fn read_packets(
    master: &mut File,
    decoder: &mut Decoder,
    device: &mut Rehastim2,
    out: &mut Vec<u8>,
    summary: &mut PtyRunSummary,
) {
    let mut rx = [0u8; 512];
    loop {
        match master.read(&mut rx) {
            Ok(0) => break,
            Ok(n) => {
                for r in decoder.feed(&rx[..n]) {
                    match r {
                        Ok(p) => {
                            summary.packets_rx += 1;
                            device.on_packet(p, out);
                        }
                        Err(DecodeError::UnknownCommand { number, command }) => {
                            summary.bad_packets += 1;
                            device.on_unknown_command(number, command, out);
                        }
                        Err(e) => {
                            summary.bad_packets += 1;
                            device.on_decode_error(e);
                        }
                    }
                }
            }
            Err(e) if e.kind() == ErrorKind::WouldBlock => break,
            Err(e) if e.kind() == ErrorKind::Interrupted => continue,
            // EIO: no slave open (cannot happen while we hold one); treat as no data.
            Err(_) => break,
        }
    }
}

/// Writes the device's answers to the host; what the pty does not take is dropped and
/// counted.
fn write_answers(master: &mut File, out: &mut Vec<u8>, summary: &mut PtyRunSummary) {
    if !out.is_empty() {
        match master.write(out) {
            Ok(n) => summary.tx_dropped += (out.len() - n) as u64,
            Err(_) => summary.tx_dropped += out.len() as u64,
        }
        out.clear();
    }
}

/// Takes the device's counters and events into the summary, the log (tracing) and the
/// pulse log.
fn account_events(
    device: &mut Rehastim2,
    summary: &mut PtyRunSummary,
    mut log: Option<&mut PulseLog>,
) -> Result<(), PtyError> {
    let mut wrote = false;
    summary.busy_sent = device.busy_sent();
    summary.slow_commands = device.slow_commands();
    summary.wrong_mode_sent = device.wrong_mode_sent();
    for e in device.drain_events() {
        match e {
            Event::Pulse { .. } => summary.pulses += 1,
            Event::WatchdogExpired { silent_ms, .. } => tracing::warn!(
                "watchdog: {silent_ms} ms without a packet from the host: stimulation stopped, modes reset, Init again"
            ),
            Event::BadPacket { error, .. } => tracing::warn!("bad packet: {error}"),
        }
        if let Some((w, p)) = log.as_deref_mut() {
            write_event(w, &e).map_err(io_err("writing the pulse log", p))?;
            wrote = true;
        }
    }
    if wrote && let Some((w, p)) = log {
        w.flush().map_err(io_err("writing the pulse log", p))?;
    }
    Ok(())
}

/// Sleeps until `deadline` (or `stop`); returns the deadline to count the next tick from:
/// after a stall longer than a tick, now (run on from now, no catch-up burst).
fn sleep_to(deadline: u64, stop: &AtomicBool) -> u64 {
    while sleep_until(deadline).is_err() {
        if stop.load(Ordering::Relaxed) {
            break;
        }
    }
    let now = monotonic_ns();
    if now > deadline + TICK_NS {
        now
    } else {
        deadline
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_plant::ChargeIntegrator;
    use fes_sciencemode::{AckResult, MAX_PACKET_LEN, Message, Packet, SinglePulse};
    use std::os::unix::fs::OpenOptionsExt as _;
    use std::time::{Duration, Instant};

    fn write_packet(port: &mut File, p: Packet) {
        let mut buf = [0u8; MAX_PACKET_LEN];
        let n = p.encode(&mut buf).unwrap();
        port.write_all(&buf[..n]).unwrap();
    }

    fn read_packet(port: &mut File, decoder: &mut Decoder) -> Packet {
        let deadline = Instant::now() + Duration::from_secs(5);
        let mut b = [0u8; 1];
        loop {
            assert!(Instant::now() < deadline, "no packet from the device");
            if port.read(&mut b).unwrap() == 1
                && let Some(r) = decoder.push(b[0])
            {
                return r.unwrap();
            }
        }
    }

    #[test]
    fn a_host_on_the_pty_connects_and_fires_a_pulse() {
        let dir = fes_testkit::Scratch::new("rehastim2-pty");
        let args = Rehastim2Args {
            pty_link: dir.join("tty"),
            pulse_log: Some(dir.join("pulses.csv")),
            watchdog_ms: 1000,
            init_period_ms: 50,
            muscle_channel: 1,
            duration_s: Some(20.0),
            test_fault: None,
            latency_ms: 0,
            motomed: false,
            processing_ms: 0,
            force_prefix: None,
            force_max_n: None,
        };
        let stop = AtomicBool::new(false);
        std::thread::scope(|s| {
            let device = s.spawn(|| {
                let mut plant = ChargeIntegrator::new();
                run_rehastim2_until(&args, &mut plant, &stop)
            });
            let deadline = Instant::now() + Duration::from_secs(5);
            while !args.pty_link.exists() {
                assert!(Instant::now() < deadline, "no pty link");
                std::thread::sleep(Duration::from_millis(5));
            }
            let mut port = std::fs::OpenOptions::new()
                .read(true)
                .write(true)
                .custom_flags(nix::libc::O_NOCTTY)
                .open(&args.pty_link)
                .unwrap();
            let mut decoder = Decoder::new();
            let init = read_packet(&mut port, &mut decoder);
            assert!(
                matches!(init.message, Message::Init { version: 1 }),
                "{init:?}"
            );
            write_packet(
                &mut port,
                Packet::new(
                    init.number,
                    Message::InitAck {
                        result: AckResult::Ok,
                    },
                ),
            );
            // Inits already on their way are still read; then the pulse's ack.
            write_packet(
                &mut port,
                Packet::new(
                    1,
                    Message::SinglePulse(SinglePulse {
                        channel: 0,
                        pulse_width_us: 300,
                        current_ma: 30,
                    }),
                ),
            );
            let ack = loop {
                let p = read_packet(&mut port, &mut decoder);
                if !matches!(p.message, Message::Init { .. }) {
                    break p;
                }
            };
            assert_eq!(
                ack,
                Packet::new(
                    1,
                    Message::SinglePulseAck {
                        result: AckResult::Ok
                    }
                )
            );
            std::thread::sleep(Duration::from_millis(20));
            stop.store(true, Ordering::Relaxed);
            let summary = device.join().unwrap().unwrap();
            assert_eq!(summary.pulses, 1);
            assert_eq!(summary.bad_packets, 0);
        });
        let log = std::fs::read_to_string(dir.join("pulses.csv")).unwrap();
        let rows: Vec<&str> = log.lines().skip(1).collect();
        assert_eq!(rows.len(), 1, "{log}");
        assert!(rows[0].ends_with(",pulse,1,300,30,single,1,"), "{log}");
        assert!(!args.pty_link.exists());
    }
}
