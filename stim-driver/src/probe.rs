//! `stim-driver probe`: how long a RehaStim 2 takes to answer, measured with harmless
//! commands, and the `[transport] min_interval_ms` that follows.
//!
//! The protocol description gives only bounds ("responses within 100 ms, on average under
//! 20 ms", §2.3); the device's firmware and the USB adapter's latency timer decide what a
//! rig sees. The probe takes the serial port, waits for the device's Init and answers it
//! (§5.2), then sends GetStimulationMode (and, when asked, SinglePulse with 0 mA and 0 us:
//! the device's own answer path for a pulse, with no charge) one at a time, each after the
//! answer to the last, as the driver does, and times each answer. Every command feeds the
//! device's 1200 ms watchdog; nothing starts stimulation, and the device falls back to
//! announcing Init 1.2 s after the probe ends (§5.2). The driver must not be running: the
//! port is the probe's alone while it runs.

use std::fs::File;
use std::io::{self, Read, Write};
use std::os::fd::AsRawFd as _;
use std::path::Path;
use std::time::{Duration, Instant};

use fes_sciencemode::{AckResult, Decoder, MAX_PACKET_LEN, Message, Packet, SinglePulse};

use crate::serial_rx::ANSWER_TIMEOUT_MS;
use crate::serial_tx::open_serial;

/// What to send.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProbeSettings {
    /// Commands to time.
    pub commands: u32,
    /// Every other command a SinglePulse of 0 mA and 0 us on channel 0 (no charge).
    pub zero_pulses: bool,
    /// How long to wait for the device's Init.
    pub init_timeout: Duration,
    /// Pause after each answer before the next command.
    pub gap: Duration,
}

impl Default for ProbeSettings {
    fn default() -> Self {
        Self {
            commands: 200,
            zero_pulses: false,
            init_timeout: Duration::from_secs(3),
            gap: Duration::from_millis(2),
        }
    }
}

/// What the probe measured.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ProbeReport {
    /// Answer times of the commands answered with result 0, ms, sorted.
    pub answer_ms: Vec<f64>,
    /// Commands answered -8 busy (§5.1): the device was still processing something.
    pub busy: u32,
    /// Commands answered with another error (their code).
    pub errors: Vec<i8>,
    /// Commands with no answer within the answer timeout.
    pub lost: u32,
    /// Packets the device sent unasked (MOTOmed information), skipped.
    pub information: u32,
}

impl ProbeReport {
    /// The `q`-quantile (0..=1) of the answer times, ms (nearest rank).
    pub fn quantile_ms(&self, q: f64) -> Option<f64> {
        let n = self.answer_ms.len();
        if n == 0 {
            return None;
        }
        let rank = ((q * n as f64).ceil() as usize).clamp(1, n);
        Some(self.answer_ms[rank - 1])
    }

    /// The `[transport] min_interval_ms` these answers ask for: the 90th percentile of
    /// the answer times, rounded up to a whole ms. A pulse closer to the last than the
    /// device's answer waits for it; at this interval nine in ten are not held back, and
    /// the rarer, slower answers (up to 100 ms, §2.3) are what the lateness bound and the
    /// reports of late pulses are for: an interval that covered them would forbid every
    /// train above 10 Hz.
    pub fn min_interval_ms(&self) -> Option<u32> {
        self.quantile_ms(0.9).map(|p| (p.ceil() as u32).max(1))
    }
}

/// Why the probe could not measure.
#[derive(Debug, thiserror::Error)]
pub enum ProbeError {
    /// The port could not be opened or used.
    #[error("{path}: {source}")]
    Port {
        /// The device path.
        path: String,
        /// The I/O error.
        #[source]
        source: io::Error,
    },
    /// No Init from the device.
    #[error(
        "no Init from the device within {0:?}: is it switched on, in ScienceMode, and is no other program (stim-driver) using the port?"
    )]
    NoInit(Duration),
}

/// The serial line, read with a deadline.
struct Line {
    port: File,
    decoder: Decoder,
    buf: [u8; 256],
    pending: std::collections::VecDeque<Packet>,
}

impl Line {
    /// The next decodable packet before `deadline` (undecodable bytes are skipped: the
    /// codec resynchronises on the next start byte).
    fn next(&mut self, deadline: Instant) -> io::Result<Option<Packet>> {
        loop {
            if let Some(p) = self.pending.pop_front() {
                return Ok(Some(p));
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(None);
            }
            let ms = (deadline - now).as_millis().clamp(1, 1000) as libc::c_int;
            let mut pfd = libc::pollfd {
                fd: self.port.as_raw_fd(),
                events: libc::POLLIN,
                revents: 0,
            };
            // SAFETY: one valid pollfd for the call; the descriptor is owned by `port`.
            let rc = unsafe { libc::poll(&mut pfd, 1, ms) };
            if rc < 0 {
                let e = io::Error::last_os_error();
                if e.kind() == io::ErrorKind::Interrupted {
                    continue;
                }
                return Err(e);
            }
            if rc == 0 {
                continue;
            }
            match self.port.read(&mut self.buf) {
                Ok(0) => return Err(io::Error::from(io::ErrorKind::UnexpectedEof)),
                Ok(n) => {
                    let (decoder, pending) = (&mut self.decoder, &mut self.pending);
                    pending.extend(decoder.feed(&self.buf[..n]).filter_map(Result::ok));
                }
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {}
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
    }

    fn send(&mut self, packet: Packet) -> io::Result<()> {
        let mut buf = [0u8; MAX_PACKET_LEN];
        let n = packet
            .encode(&mut buf)
            .map_err(|e| io::Error::new(io::ErrorKind::InvalidInput, e))?;
        let mut written = 0;
        let deadline = Instant::now() + Duration::from_millis(100);
        while written < n {
            match self.port.write(&buf[written..n]) {
                Ok(k) => written += k,
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
                    ) && Instant::now() < deadline =>
                {
                    std::thread::sleep(Duration::from_micros(200));
                }
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }
}

/// Runs the probe on the serial device `path` (see the module documentation); `progress`
/// is called after each command with the number done.
pub fn probe(
    path: &Path,
    settings: &ProbeSettings,
    mut progress: impl FnMut(u32),
) -> Result<ProbeReport, ProbeError> {
    let port_err = |source: io::Error| ProbeError::Port {
        path: path.display().to_string(),
        source,
    };
    let port = open_serial(path).map_err(port_err)?;
    let mut line = Line {
        port,
        decoder: Decoder::new(),
        buf: [0; 256],
        pending: std::collections::VecDeque::new(),
    };
    // §5.2: the device announces itself with Init until the host answers InitAck.
    let deadline = Instant::now() + settings.init_timeout;
    let init = loop {
        match line.next(deadline).map_err(port_err)? {
            Some(Packet {
                number,
                message: Message::Init { .. },
            }) => break number,
            Some(_) => {}
            None => return Err(ProbeError::NoInit(settings.init_timeout)),
        }
    };
    line.send(Packet::new(
        init,
        Message::InitAck {
            result: AckResult::Ok,
        },
    ))
    .map_err(port_err)?;
    let mut report = ProbeReport::default();
    let mut number = 0u8;
    let timeout = Duration::from_millis(u64::from(ANSWER_TIMEOUT_MS));
    for k in 0..settings.commands {
        let message = if settings.zero_pulses && k % 2 == 1 {
            Message::SinglePulse(SinglePulse {
                channel: 0,
                pulse_width_us: 0,
                current_ma: 0,
            })
        } else {
            Message::GetStimulationMode
        };
        let sent = Instant::now();
        line.send(Packet::new(number, message)).map_err(port_err)?;
        let deadline = sent + timeout;
        loop {
            match line.next(deadline).map_err(port_err)? {
                None => {
                    report.lost += 1;
                    break;
                }
                Some(p) if p.message.is_motomed_information() => report.information += 1,
                Some(p) if p.message.is_answer() && p.number == number => {
                    match p.message.ack_result() {
                        Some(AckResult::Ok) => {
                            report.answer_ms.push(sent.elapsed().as_secs_f64() * 1e3)
                        }
                        Some(AckResult::BusyError) => report.busy += 1,
                        Some(r) => report.errors.push(r.code()),
                        None => report.errors.push(0),
                    }
                    break;
                }
                // An answer to an earlier command, or the device's Init again: not ours.
                Some(_) => {}
            }
        }
        number = number.wrapping_add(1);
        progress(k + 1);
        std::thread::sleep(settings.gap);
    }
    report.answer_ms.sort_by(f64::total_cmp);
    Ok(report)
}
