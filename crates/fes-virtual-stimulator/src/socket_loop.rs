//! The thin adapter between a SocketCAN interface (or the host bus, `hostbus:<dir>`,
//! [`fes_hostbus`]) and the state machine: a 1 ms
//! absolute-time loop that drains received frames into [`Stimulator::on_frame`], runs
//! [`Stimulator::tick`] and sends what the machine produced.
//!
//! Each frame is handed over with its arrival time: the kernel's receive timestamp
//! (`SO_TIMESTAMPNS`, CLOCK_REALTIME) mapped onto CLOCK_MONOTONIC ([`arrival_ns`]), so a
//! stall of this process (a loaded host, a User-Mode Linux guest) does not make pulses
//! that arrived properly spaced look like a burst. Without a timestamp, or with one that
//! cannot be right (in the future, or older than [`MAX_RX_AGE_NS`]: CLOCK_REALTIME was
//! stepped), the read time is used.

use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::Context as _;
use fes_can::{ErrorCode, Message, MessageKind, Nodes, decode};
use fes_hostbus::{self as hostbus, HostBus, RawFrame, Station};
use nix::errno::Errno;
use socketcan::{CanFilter, CanFrame, CanSocket, EmbeddedFrame, Frame as _, Socket, SocketOptions};

use super::clock::{monotonic_ns, sleep_until};
use super::machine::{Settings, Stimulator, TICK_NS, Tick, TickReport};
use super::outbox::Outbox;
use super::record::{Recorder, TickRecord};
use crate::plant::Plant;

/// The oldest receive timestamp believed, ns: older means CLOCK_REALTIME was stepped
/// between the frame's arrival and its read (a stall this long is also a watchdog fault).
pub const MAX_RX_AGE_NS: u64 = 1_000_000_000;

/// A frame's arrival on CLOCK_MONOTONIC: the receive timestamp `rx_real_ns`
/// (CLOCK_REALTIME) taken back from the two clocks read together at the read
/// (`real_now_ns`, `mono_now_ns`). Falls back to `mono_now_ns` (see the module docs).
pub fn arrival_ns(rx_real_ns: Option<u64>, real_now_ns: u64, mono_now_ns: u64) -> u64 {
    match rx_real_ns {
        Some(rx) if rx <= real_now_ns && real_now_ns - rx <= MAX_RX_AGE_NS => {
            mono_now_ns.saturating_sub(real_now_ns - rx)
        }
        _ => mono_now_ns,
    }
}

fn unix_ns(t: std::time::SystemTime) -> Option<u64> {
    t.duration_since(std::time::UNIX_EPOCH)
        .ok()
        .and_then(|d| u64::try_from(d.as_nanos()).ok())
}

/// What a run did, for the final log line and tests.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RunSummary {
    /// Ticks run.
    pub ticks: u64,
    /// Ticks skipped because the loop woke more than a period late.
    pub missed_ticks: u64,
    /// Largest wake-up lateness behind the deadline slept for, ns.
    pub max_late_ns: u64,
    /// Frames received (data frames, all identifiers that passed the socket filter).
    pub frames_rx: u64,
    /// Frames sent.
    pub frames_tx: u64,
    /// Frames that could not be sent (transmit queue full, bus down).
    pub tx_errors: u64,
    /// Pulses applied.
    pub pulses_delivered: u32,
    /// Records dropped by the recorder.
    pub records_dropped: u64,
}

// Linux CAN error-frame classes and controller-status bits (linux/can/error.h).
const CAN_ERR_CRTL: u32 = 0x0000_0004;
const CAN_ERR_BUSOFF: u32 = 0x0000_0040;
const CAN_ERR_RESTARTED: u32 = 0x0000_0100;
const CAN_ERR_CRTL_RX_OVERFLOW: u8 = 0x01;
const CAN_ERR_CRTL_TX_OVERFLOW: u8 = 0x02;
const CAN_ERR_CRTL_RX_PASSIVE: u8 = 0x10;
const CAN_ERR_CRTL_TX_PASSIVE: u8 = 0x20;

/// The EMCY code for a SocketCAN error frame (`class`: the error class bits of its
/// identifier; `data`: its payload, byte 1 holding the controller status).
pub fn classify_error_frame(class: u32, data: &[u8]) -> ErrorCode {
    let ctrl = data.get(1).copied().unwrap_or(0);
    if class & CAN_ERR_RESTARTED != 0 {
        ErrorCode::BusOffRecovered
    } else if class & CAN_ERR_BUSOFF != 0 {
        ErrorCode::Communication
    } else if class & CAN_ERR_CRTL != 0
        && ctrl & (CAN_ERR_CRTL_RX_OVERFLOW | CAN_ERR_CRTL_TX_OVERFLOW) != 0
    {
        ErrorCode::CanOverrun
    } else if class & CAN_ERR_CRTL != 0
        && ctrl & (CAN_ERR_CRTL_RX_PASSIVE | CAN_ERR_CRTL_TX_PASSIVE) != 0
    {
        ErrorCode::CanErrorPassive
    } else {
        ErrorCode::Communication
    }
}

/// The message kinds the stimulator consumes.
const ACCEPTED: [MessageKind; 4] = [
    MessageKind::Nmt,
    MessageKind::Pulse,
    MessageKind::Config,
    MessageKind::HostHeartbeat,
];

/// The stimulator's socket: a CAN interface, or the stimulator station of the host bus
/// (`hostbus:<dir>`, [`fes_hostbus`]: frames in the same `struct can_frame` layout,
/// the same identifier filter applied here, error frames only as a tap injects them).
#[derive(Debug)]
enum StimSocket {
    Can(CanSocket),
    Host(HostBus),
}

/// One read.
enum Rx {
    /// An error frame: its class bits and payload.
    Error(u32, [u8; 8]),
    /// A standard data frame that passed the filter, with its arrival (CLOCK_MONOTONIC).
    Data(u16, [u8; 8], usize, u64),
    /// A frame to ignore (extended, remote, filtered out).
    Skip,
}

/// Opens `iface` with a filter for the frames the stimulator consumes (NMT, its PULSE and
/// CONFIG, the host heartbeat; standard data frames only) plus error frames.
fn open_socket(iface: &str, nodes: &Nodes) -> anyhow::Result<StimSocket> {
    if let Some(dir) = hostbus::bus_dir(iface) {
        let bus = HostBus::open(dir, Station::Stimulator, None)
            .with_context(|| format!("joining the host bus {iface:?}"))?;
        tracing::warn!(
            iface,
            "the host bus (Unix datagrams, no CAN): for tests and benches on hosts without SocketCAN"
        );
        if let Some(w) = bus.queue_warning() {
            tracing::warn!("{w}");
        }
        return Ok(StimSocket::Host(bus));
    }
    let socket = CanSocket::open(iface).with_context(|| {
        format!("opening CAN interface {iface:?} (does it exist and is it up? see docs/vcan.md)")
    })?;
    // Match the 11-bit identifier and require the EFF and RTR flags clear.
    let mask = 0x7FF | hostbus::EFF_FLAG | hostbus::RTR_FLAG;
    let filters: Vec<CanFilter> = ACCEPTED
        .into_iter()
        .map(|k| CanFilter::new(u32::from(nodes.id_of(k)), mask))
        .collect();
    socket
        .set_filters(&filters)
        .context("setting the CAN receive filters")?;
    socket
        .set_error_filter_accept_all()
        .context("enabling CAN error frames")?;
    socket
        .set_nonblocking(true)
        .context("making the CAN socket non-blocking")?;
    if let Err(e) = socket.set_recv_timestamp(true) {
        tracing::warn!("no kernel receive timestamps ({e}): frames are timed when read");
    }
    Ok(StimSocket::Can(socket))
}

fn real_now_ns() -> u64 {
    unix_ns(std::time::SystemTime::now()).unwrap_or(0)
}

impl StimSocket {
    /// Reads one frame without blocking: `Ok(None)` when none is queued.
    fn read(&self, nodes: &Nodes) -> std::io::Result<Option<Rx>> {
        match self {
            StimSocket::Can(socket) => match socket.read_frame_with_timestamps() {
                Ok((CanFrame::Error(e), _)) => {
                    let mut data = [0u8; 8];
                    let n = e.data().len().min(8);
                    data[..n].copy_from_slice(&e.data()[..n]);
                    Ok(Some(Rx::Error(e.error_bits(), data)))
                }
                Ok((frame, stamps)) => {
                    if frame.is_extended() || frame.is_remote_frame() {
                        return Ok(Some(Rx::Skip));
                    }
                    let at = arrival_ns(
                        stamps.socket.and_then(unix_ns),
                        real_now_ns(),
                        monotonic_ns(),
                    );
                    let mut data = [0u8; 8];
                    let n = frame.data().len().min(8);
                    data[..n].copy_from_slice(&frame.data()[..n]);
                    Ok(Some(Rx::Data(frame.raw_id() as u16, data, n, at)))
                }
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => Ok(None),
                Err(e) => Err(e),
            },
            StimSocket::Host(bus) => match bus.recv() {
                Ok(Some(r)) if r.frame.is_error() => Ok(Some(Rx::Error(
                    r.frame.can_id & !hostbus::ERR_FLAG,
                    r.frame.data,
                ))),
                Ok(Some(r)) => Ok(Some(match r.frame.standard_id() {
                    Some(id) if ACCEPTED.iter().any(|k| nodes.id_of(*k) == id) => {
                        let at = arrival_ns(r.rx_realtime_ns, real_now_ns(), monotonic_ns());
                        Rx::Data(id, r.frame.data, r.frame.payload().len(), at)
                    }
                    _ => Rx::Skip,
                })),
                Ok(None) => Ok(None),
                // A datagram that is not a CAN frame: dropped, as a controller drops a
                // malformed frame.
                Err(e) if e.kind() == std::io::ErrorKind::InvalidData => Ok(Some(Rx::Skip)),
                Err(e) => Err(e),
            },
        }
    }

    /// Writes one frame.
    fn write(&self, f: &fes_can::Frame) -> std::io::Result<()> {
        let invalid = || std::io::Error::from(std::io::ErrorKind::InvalidInput);
        match self {
            StimSocket::Can(socket) => {
                let id = socketcan::StandardId::new(f.id).ok_or_else(invalid)?;
                let frame = CanFrame::new(id, f.payload()).ok_or_else(invalid)?;
                socket.write_frame(&frame)
            }
            StimSocket::Host(bus) => {
                bus.send(&RawFrame::data(f.id, f.payload()).ok_or_else(invalid)?)
            }
        }
    }
}

/// Sends everything in `out`; counts failures (the frame is lost, the machine is told at
/// the next tick).
fn flush(socket: &StimSocket, out: &mut Outbox, stim_nodes: &Nodes, summary: &mut RunSummary) {
    for f in out.frames() {
        match socket.write(f) {
            Ok(()) => summary.frames_tx += 1,
            Err(_) => summary.tx_errors += 1,
        }
        if f.id == stim_nodes.id_of(MessageKind::Emcy)
            && let Ok(Message::Emcy(e)) = decode(u32::from(f.id), f.payload())
        {
            if e.code == ErrorCode::NoError {
                tracing::info!(state = %e.state, "EMCY: fault cleared");
            } else {
                tracing::warn!(code = %e.code, seq = e.seq, detail = e.detail, state = %e.state, "EMCY");
            }
        }
    }
    out.clear();
}

/// Runs the stimulator on `iface` until `stop` is set: 1 ms absolute-time ticks on
/// CLOCK_MONOTONIC; on stop (or a socket or clock failure, which is then returned),
/// output off and a final STATUS.
pub fn run_loop(
    iface: &str,
    settings: Settings,
    plant: &mut dyn Plant,
    stop: &AtomicBool,
    mut recorder: Option<Recorder>,
    max_ticks: Option<u64>,
) -> anyhow::Result<RunSummary> {
    let socket = open_socket(iface, &settings.nodes)?;
    let mut summary = RunSummary::default();
    let mut out = Outbox::new();
    let boot_ns = monotonic_ns();
    let mut stim = Stimulator::new(settings, boot_ns, &mut out);
    flush(&socket, &mut out, &settings.nodes, &mut summary);
    tracing::info!(iface, node = settings.nodes.stim(), limits = ?settings.ceiling, "stimulator pre-operational");

    let t0 = boot_ns + TICK_NS;
    let mut k: u64 = 0;
    let mut tx_errors_reported = 0;
    let mut state = stim.state();
    // A failure ends the loop but not before the orderly shutdown below.
    let mut failure: Option<anyhow::Error> = None;
    while !stop.load(Ordering::Relaxed) && max_ticks.is_none_or(|m| k < m) {
        let deadline = t0 + k * TICK_NS;
        match sleep_until(deadline) {
            Ok(()) => {}
            Err(Errno::EINTR) => continue,
            Err(e) => {
                failure = Some(anyhow::Error::new(e).context("clock_nanosleep failed"));
                break;
            }
        }
        let now = monotonic_ns();
        let late_ns = now.saturating_sub(deadline);
        summary.max_late_ns = summary.max_late_ns.max(late_ns);
        // Woke more than a period late: skip the missed periods, keep the phase.
        let late_k = now.saturating_sub(t0) / TICK_NS;
        if late_k > k {
            k = late_k;
        }
        let nominal = t0 + k * TICK_NS;

        if let Err(e) = read_frames(&socket, &settings.nodes, &mut stim, &mut out, &mut summary) {
            failure = Some(e.context(format!("reading from {iface}")));
            break;
        }
        report_tx_errors(&mut stim, &summary, &mut tx_errors_reported, &mut out);
        let report = stim.tick(
            Tick {
                index: k,
                nominal_ns: nominal,
                now_ns: now,
            },
            plant,
            &mut out,
        );
        flush(&socket, &mut out, &settings.nodes, &mut summary);
        if report.state != state {
            tracing::info!(from = %state, to = %report.state, tick = k, "state");
            state = report.state;
        }
        if let Some(r) = recorder.as_mut() {
            record_tick(r, &stim, t0, now, late_ns, k, &report);
        }
        summary.ticks += 1;
        k += 1;
    }

    stim.shutdown(&mut out);
    flush(&socket, &mut out, &settings.nodes, &mut summary);
    summary.missed_ticks = stim.diagnostics().missed_ticks;
    summary.pulses_delivered = stim.pulses_delivered();
    if let Some(r) = recorder.take() {
        summary.records_dropped = r.finish()?;
    }
    tracing::info!(?summary, "stimulator stopped");
    match failure {
        Some(e) => Err(e),
        None => Ok(summary),
    }
}

/// Hands the stimulator every frame received since the last tick, flushing its answers
/// after each; a read failure (other than EINTR) is returned.
fn read_frames(
    socket: &StimSocket,
    nodes: &Nodes,
    stim: &mut Stimulator,
    out: &mut Outbox,
    summary: &mut RunSummary,
) -> Result<(), anyhow::Error> {
    loop {
        match socket.read(nodes) {
            Ok(Some(Rx::Error(class, data))) => {
                let code = classify_error_frame(class, &data);
                stim.on_bus_error(code, (class & 0xFFFF) as u16, out);
            }
            Ok(Some(Rx::Data(id, data, len, at))) => {
                summary.frames_rx += 1;
                stim.on_frame(at, u32::from(id), &data[..len], out);
            }
            Ok(Some(Rx::Skip)) => {}
            Ok(None) => return Ok(()),
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(anyhow::Error::new(e)),
        }
        flush(socket, out, nodes, summary);
    }
}

/// Frames the transmit queue refused since the last report become one EMCY (CAN overrun)
/// with their number.
fn report_tx_errors(
    stim: &mut Stimulator,
    summary: &RunSummary,
    tx_errors_reported: &mut u64,
    out: &mut Outbox,
) {
    if summary.tx_errors > *tx_errors_reported {
        let lost = summary.tx_errors - *tx_errors_reported;
        *tx_errors_reported = summary.tx_errors;
        stim.on_bus_error(
            ErrorCode::CanOverrun,
            u16::try_from(lost).unwrap_or(u16::MAX),
            out,
        );
    }
}

/// The record's rows for tick `k`: one per pulse applied at the ticks the loop missed, then
/// the tick's own.
fn record_tick(
    r: &mut Recorder,
    stim: &Stimulator,
    t0: u64,
    now: u64,
    late_ns: u64,
    k: u64,
    report: &TickReport,
) {
    // Pulses applied at ticks the loop missed (a stall) get their own rows, so the record
    // lists every delivered pulse at the tick it was applied, in the state it was applied
    // in (operational: a pulse is only ever applied then; `report.state` is the state now,
    // after the catch-up).
    for c in stim.caught_up() {
        r.push(TickRecord {
            tick: c.tick,
            nominal_ns: t0 + c.tick * TICK_NS,
            late_ns: now.saturating_sub(t0 + c.tick * TICK_NS),
            state: fes_can::StimState::Stimulating,
            force_n: c.force_n,
            pulse: Some((c.pulse.seq, c.pulse.amplitude_ma(), c.pulse.width_us)),
        });
    }
    r.push(TickRecord {
        tick: k,
        nominal_ns: t0 + k * TICK_NS,
        late_ns,
        state: report.state,
        force_n: report.force_n,
        pulse: report
            .applied
            .map(|p| (p.seq, p.amplitude_ma(), p.width_us)),
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arrival_times_come_from_the_receive_timestamp_or_the_read() {
        let (real, mono) = (1_700_000_000_000_000_000, 5_000_000_000);
        // 40 ms before the read, on the realtime clock: 40 ms before on the monotonic one.
        assert_eq!(
            arrival_ns(Some(real - 40_000_000), real, mono),
            mono - 40_000_000
        );
        assert_eq!(arrival_ns(Some(real), real, mono), mono);
        // No timestamp, one from the future, one too old (the clock was stepped): read time.
        assert_eq!(arrival_ns(None, real, mono), mono);
        assert_eq!(arrival_ns(Some(real + 1), real, mono), mono);
        assert_eq!(arrival_ns(Some(real - MAX_RX_AGE_NS - 1), real, mono), mono);
        assert_eq!(
            arrival_ns(Some(real - MAX_RX_AGE_NS), real, mono),
            mono - MAX_RX_AGE_NS
        );
    }

    #[test]
    fn error_frames_map_to_canopen_codes() {
        assert_eq!(
            classify_error_frame(CAN_ERR_CRTL, &[0, CAN_ERR_CRTL_RX_OVERFLOW]),
            ErrorCode::CanOverrun
        );
        assert_eq!(
            classify_error_frame(CAN_ERR_CRTL, &[0, CAN_ERR_CRTL_TX_PASSIVE]),
            ErrorCode::CanErrorPassive
        );
        assert_eq!(
            classify_error_frame(CAN_ERR_RESTARTED, &[]),
            ErrorCode::BusOffRecovered
        );
        assert_eq!(
            classify_error_frame(CAN_ERR_BUSOFF, &[]),
            ErrorCode::Communication
        );
        assert_eq!(
            classify_error_frame(CAN_ERR_CRTL, &[]),
            ErrorCode::Communication
        );
    }

    #[test]
    fn a_missing_interface_is_a_clear_error() {
        let e = open_socket("nosuchcan9", &Nodes::DEFAULT).unwrap_err();
        assert!(format!("{e:#}").contains("nosuchcan9"), "{e:#}");
        let e = open_socket("hostbus:relative/dir", &Nodes::DEFAULT).unwrap_err();
        assert!(format!("{e:#}").contains("not an absolute path"), "{e:#}");
    }
}
