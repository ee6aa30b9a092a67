//! The receive side: one normal-priority thread that reads the stimulator's frames and the
//! CAN error frames, watches the interface's link state, republishes FORCE as
//! [`ForceSample`] on iceoryx2, and hands STATUS, EMCY, heartbeats, error frames and link
//! changes to the forward thread through a preallocated lock-free queue.
//!
//! On the host bus (`hostbus:<dir>`, [`fes_hostbus`]) it holds the driver station's
//! socket and applies the same identifier filter itself; error frames there are the ones
//! a tap injects, and the link is always up.
//!
//! Its socket accepts exactly FORCE, STATUS, EMCY and the stimulator heartbeat (standard
//! data frames), the driver's own transmit identifiers (NMT, PULSE, CONFIG, host heartbeat:
//! each such frame the driver did not write is an intrusion, [`crate::intrusion`]; FORCE
//! and STATUS out of the stimulator's own numbering are one too,
//! [`crate::intrusion::StimulatorStreams`]) plus
//! every error frame (`CAN_RAW_ERR_FILTER` = all), so bus-off,
//! error-passive and controller problems arrive as frames. A read failing with `ENETDOWN`
//! and the interface flags (`SIOCGIFFLAGS`: up and running), polled every
//! [`LINK_CHECK_NS`], tell when the link goes down and comes back.

use std::io;
use std::os::fd::{AsRawFd, RawFd};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use crossbeam::queue::ArrayQueue;
use fes_can::{Force, Message, MessageKind, Nodes};
use fes_hostbus::{self as hostbus, HostBus, Station};
use fes_rt::msg::PortError;
use fes_rt::msg::port;
use fes_rt::msg::service::ServiceError;
use fes_rt::msg::{Contract, ForceSample};
use fes_rt::rt::clock::monotonic_ns;
use fes_rt::rt::node::create_node;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::prelude::ipc;
use socketcan::errors::{CanError, ControllerProblems};
use socketcan::{
    CanErrorFrame, CanFilter, CanFrame, CanSocket, EmbeddedFrame, Frame as _, Socket, SocketOptions,
};

use crate::event::{BusErrorKind, BusEvent, SharedStatus};
use crate::intrusion::{OWN_KINDS, SentLog, SentMatcher, StimulatorStreams, own_kind};

/// How often the interface flags are read, ns.
pub const LINK_CHECK_NS: u64 = 10_000_000;
/// Read timeout of the receive socket (the longest the thread sleeps).
pub const READ_TIMEOUT: Duration = Duration::from_millis(5);

/// The event a decoded stimulator message gives the forward thread: STATUS, EMCY and the
/// stimulator's heartbeat; `None` for the rest (FORCE is republished on iceoryx2 instead,
/// host messages are not the stimulator's).
pub fn forward_event(message: &Message) -> Option<BusEvent> {
    match message {
        Message::Status(s) => Some(BusEvent::Status(*s)),
        Message::Emcy(e) => Some(BusEvent::Emcy(*e)),
        Message::StimHeartbeat(h) => Some(BusEvent::StimHeartbeat(h.state)),
        Message::ConfigApplied(c) => Some(BusEvent::ConfigApplied(*c)),
        _ => None,
    }
}

/// Classifies a CAN error frame (the most severe condition it reports).
pub fn classify_error_frame(frame: CanErrorFrame) -> BusErrorKind {
    let class = frame.error_bits();
    let error = CanError::from(frame);
    if error.is_bus_off() {
        return BusErrorKind::BusOff;
    }
    if error.is_restarted() {
        return BusErrorKind::Restarted;
    }
    if let Some(p) = error.controller() {
        if p.intersects(ControllerProblems::RX_PASSIVE | ControllerProblems::TX_PASSIVE) {
            return BusErrorKind::ErrorPassive;
        }
        if p.intersects(ControllerProblems::RX_OVERFLOW | ControllerProblems::TX_OVERFLOW) {
            return BusErrorKind::Overflow;
        }
        if p.intersects(ControllerProblems::RX_WARNING | ControllerProblems::TX_WARNING) {
            return BusErrorKind::ErrorWarning;
        }
        if p.contains(ControllerProblems::ACTIVE) {
            return BusErrorKind::ErrorActive;
        }
    }
    BusErrorKind::Other { class }
}

/// Whether interface `iface` is up and running (`IFF_UP` and `IFF_RUNNING`), read with
/// `SIOCGIFFLAGS` through the socket `fd`.
pub fn link_is_up(fd: RawFd, iface: &str) -> io::Result<bool> {
    // SAFETY: `ifreq` is a plain C struct (a name array and a union of plain data): all
    // zero bytes is a valid value.
    let mut request: libc::ifreq = unsafe { std::mem::zeroed() };
    let name = iface.as_bytes();
    if name.is_empty() || name.len() >= request.ifr_name.len() {
        return Err(io::Error::from(io::ErrorKind::InvalidInput));
    }
    for (dst, &src) in request.ifr_name.iter_mut().zip(name) {
        *dst = src as libc::c_char;
    }
    // SAFETY: SIOCGIFFLAGS reads the NUL-terminated name from `request` and writes the
    // flags into its union; `request` is valid and outlives the call.
    let rc = unsafe { libc::ioctl(fd, libc::SIOCGIFFLAGS, &mut request) };
    if rc < 0 {
        return Err(io::Error::last_os_error());
    }
    // SAFETY: after a successful SIOCGIFFLAGS the kernel has written `ifru_flags`.
    let flags = i32::from(unsafe { request.ifr_ifru.ifru_flags });
    Ok(flags & libc::IFF_UP != 0 && flags & libc::IFF_RUNNING != 0)
}

/// Settings of the receive thread.
#[derive(Debug, Clone, PartialEq)]
pub struct BusSettings {
    /// Interface.
    pub iface: String,
    /// Node ids.
    pub nodes: Nodes,
    /// The muscle's maximal force, N (normalises `ForceSample.force`).
    pub max_force_n: f64,
    /// iceoryx2 service-name prefix.
    pub prefix: String,
}

/// Counters of the receive thread (one writer, relaxed).
#[derive(Debug, Default)]
pub struct BusCounters {
    /// Data frames received.
    pub frames: AtomicU64,
    /// ForceSamples published.
    pub forces_published: AtomicU64,
    /// FORCE frames whose force was outside ForceSample's valid range (not published).
    pub forces_invalid: AtomicU64,
    /// FORCE frames missing (gaps in their `seq`).
    pub forces_lost: AtomicU64,
    /// Frames that failed to decode.
    pub decode_errors: AtomicU64,
    /// CAN error frames.
    pub error_frames: AtomicU64,
    /// Failed reads (other than timeouts).
    pub read_errors: AtomicU64,
    /// Failed ForceSample publishes.
    pub publish_errors: AtomicU64,
    /// Bus events dropped because the queue to the forward thread was full.
    pub events_lost: AtomicU64,
    /// Echoes of the driver's own frames recognised (SocketCAN: the transmit socket's
    /// frames looped back to the receive socket).
    pub own_echoes: AtomicU64,
    /// Frames on the driver's own identifiers that it did not write.
    pub intrusions: AtomicU64,
    /// ScienceMode only: information packets a RehaStim 2 sends unasked with a MOTOmed
    /// attached (ActualValues every 20 ms, PhaseResult, MotomedCommandDone, MotomedError;
    /// §3.5 of the protocol description), decoded and skipped.
    pub information_packets: AtomicU64,
}

impl BusCounters {
    fn bump(c: &AtomicU64) {
        c.fetch_add(1, Ordering::Relaxed);
    }
}

/// The receive thread failed to start or run.
#[derive(Debug, thiserror::Error)]
pub enum BusError {
    /// The interface could not be opened or configured.
    #[error("CAN interface {iface:?}: {what}: {source}")]
    Socket {
        /// Interface.
        iface: String,
        /// Which step.
        what: &'static str,
        /// The OS error.
        source: io::Error,
    },
    /// iceoryx2.
    #[error(transparent)]
    Service(#[from] ServiceError),
    /// The ForceSample publisher could not be made.
    #[error(transparent)]
    Port(#[from] PortError),
    /// The receive thread's iceoryx2 node could not be made.
    #[error("receive thread: {0}")]
    Ipc(#[from] fes_rt::rt::node::RunError),
}

/// The message kinds the receive socket accepts: the stimulator's, and the driver's own
/// ([`OWN_KINDS`], for intrusion detection).
const ACCEPTED: [MessageKind; 9] = [
    MessageKind::Force,
    MessageKind::Status,
    MessageKind::Emcy,
    MessageKind::StimHeartbeat,
    MessageKind::ConfigApplied,
    OWN_KINDS[0],
    OWN_KINDS[1],
    OWN_KINDS[2],
    OWN_KINDS[3],
];

/// The receive socket: the stimulator's frames and every error frame, on a CAN interface
/// or on the host bus ([`fes_hostbus`]).
enum RxSocket {
    Can(CanSocket),
    Host(HostBus),
}

/// One read.
enum Rx {
    /// A standard data frame that passed the filter: identifier and payload.
    Data(u16, [u8; 8], usize),
    /// An error frame, classified.
    Error(BusErrorKind),
    /// Nothing before the timeout, or a frame to ignore.
    Nothing,
}

fn open_socket(settings: &BusSettings) -> Result<RxSocket, BusError> {
    let err = |what| {
        let iface = settings.iface.clone();
        move |source| BusError::Socket {
            iface,
            what,
            source,
        }
    };
    if let Some(dir) = hostbus::bus_dir(&settings.iface) {
        let bus =
            HostBus::open(dir, Station::Driver, Some(READ_TIMEOUT)).map_err(err("host bus"))?;
        if let Some(w) = bus.queue_warning() {
            tracing::warn!("{w}");
        }
        return Ok(RxSocket::Host(bus));
    }
    let socket = CanSocket::open(&settings.iface).map_err(err("open"))?;
    // Match the 11-bit identifier and require the EFF and RTR flags clear.
    let mask = 0x7FF | libc::CAN_EFF_FLAG | libc::CAN_RTR_FLAG;
    let filters: Vec<CanFilter> = ACCEPTED
        .into_iter()
        .map(|k| CanFilter::new(u32::from(settings.nodes.id_of(k)), mask))
        .collect();
    socket
        .set_filters(&filters)
        .map_err(err("receive filters"))?;
    socket
        .set_error_filter_accept_all()
        .map_err(err("error-frame filter"))?;
    socket
        .set_read_timeout(READ_TIMEOUT)
        .map_err(err("read timeout"))?;
    Ok(RxSocket::Can(socket))
}

impl RxSocket {
    /// Reads one frame, waiting at most [`READ_TIMEOUT`].
    fn read(&self, nodes: &Nodes) -> io::Result<Rx> {
        match self {
            RxSocket::Can(socket) => match socket.read_frame() {
                Ok(CanFrame::Error(e)) => Ok(Rx::Error(classify_error_frame(e))),
                Ok(CanFrame::Data(frame)) => {
                    let mut data = [0u8; 8];
                    let n = frame.data().len().min(8);
                    data[..n].copy_from_slice(&frame.data()[..n]);
                    Ok(Rx::Data(frame.raw_id() as u16, data, n))
                }
                Ok(CanFrame::Remote(_)) => Ok(Rx::Nothing),
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::WouldBlock
                            | io::ErrorKind::TimedOut
                            | io::ErrorKind::Interrupted
                    ) =>
                {
                    Ok(Rx::Nothing)
                }
                Err(e) => Err(e),
            },
            RxSocket::Host(bus) => match bus.recv() {
                Ok(Some(r)) if r.frame.is_error() => {
                    let class = r.frame.can_id & !hostbus::ERR_FLAG;
                    Ok(CanErrorFrame::new_error(class, r.frame.payload())
                        .map_or(Rx::Error(BusErrorKind::Other { class }), |e| {
                            Rx::Error(classify_error_frame(e))
                        }))
                }
                Ok(Some(r)) => Ok(match r.frame.standard_id() {
                    // The same filter as the CAN socket's.
                    Some(id) if ACCEPTED.iter().any(|k| nodes.id_of(*k) == id) => {
                        Rx::Data(id, r.frame.data, r.frame.payload().len())
                    }
                    _ => Rx::Nothing,
                }),
                Ok(None) => Ok(Rx::Nothing),
                Err(e) if e.kind() == io::ErrorKind::Interrupted => Ok(Rx::Nothing),
                Err(e) => Err(e),
            },
        }
    }

    /// Whether a frame on one of the driver's own identifiers can be the driver's own
    /// (SocketCAN loops the transmit socket's frames back to this one; on the host bus a
    /// station never receives frames sent as itself).
    fn echoes_own_frames(&self) -> bool {
        matches!(self, RxSocket::Can(_))
    }

    /// The interface's link state (the host bus is always up).
    fn link_is_up(&self, iface: &str) -> Option<bool> {
        match self {
            RxSocket::Can(socket) => link_is_up(socket.as_raw_fd(), iface).ok(),
            RxSocket::Host(_) => None,
        }
    }
}

/// Republishes the stimulator's FORCE frames as [`ForceSample`]s, counting the frames the
/// stimulator numbered but this socket never saw.
struct ForceRepublisher {
    publisher: Publisher<ipc::Service, ForceSample, ()>,
    /// The last ForceSample's `seq`.
    seq: u64,
    /// The last FORCE frame's `seq`.
    last_frame_seq: Option<u16>,
}

impl ForceRepublisher {
    fn publish(&mut self, f: &Force, max_force_n: f64, stim_seq: u64, counters: &BusCounters) {
        if let Some(last) = self.last_frame_seq {
            let gap = f.seq.wrapping_sub(last).wrapping_sub(1);
            if gap > 0 && gap < 0x8000 {
                counters
                    .forces_lost
                    .fetch_add(u64::from(gap), Ordering::Relaxed);
            }
        }
        self.last_frame_seq = Some(f.seq);
        let force_n = f.force_n();
        let sample = ForceSample {
            seq: self.seq + 1,
            t_ns: monotonic_ns(),
            stim_seq,
            force_n,
            force: force_n / max_force_n,
        };
        if sample.validate().is_err() {
            BusCounters::bump(&counters.forces_invalid);
        } else if self.publisher.send_copy(sample).is_ok() {
            self.seq += 1;
            BusCounters::bump(&counters.forces_published);
        } else {
            self.seq += 1;
            BusCounters::bump(&counters.publish_errors);
        }
    }
}

/// Runs the receive thread until `stop` is set. `on_ready` is called once the socket and
/// the ForceSample publisher exist. `sent` is the log of the frames the forward thread
/// writes ([`crate::intrusion`]).
pub fn run_bus(
    settings: &BusSettings,
    to_forward: &ArrayQueue<BusEvent>,
    status: &SharedStatus,
    counters: &BusCounters,
    sent: &SentLog,
    stop: &AtomicBool,
    on_ready: impl FnOnce(),
) -> Result<(), BusError> {
    let socket = open_socket(settings)?;
    let mut echoes = SentMatcher::new();
    let node = create_node("stim-driver-bus")?;
    let publisher = port::publisher::<ForceSample>(&node, &settings.prefix)?;
    on_ready();

    let push = |e: BusEvent| {
        if to_forward.push(e).is_err() {
            BusCounters::bump(&counters.events_lost);
        }
    };
    let mut link_up = true;
    let mut next_link_check = 0u64;
    let mut forces = ForceRepublisher {
        publisher,
        seq: 0,
        last_frame_seq: None,
    };
    let mut streams = StimulatorStreams::new();
    while !stop.load(Ordering::Relaxed) {
        let now = monotonic_ns();
        if now >= next_link_check {
            next_link_check = now + LINK_CHECK_NS;
            if let Some(up) = socket.link_is_up(&settings.iface)
                && up != link_up
            {
                link_up = up;
                push(if up {
                    BusEvent::LinkUp
                } else {
                    BusEvent::LinkDown
                });
            }
        }
        match socket.read(&settings.nodes) {
            Ok(Rx::Error(kind)) => {
                BusCounters::bump(&counters.error_frames);
                push(BusEvent::BusError(kind));
            }
            Ok(Rx::Data(id, data, len)) => {
                BusCounters::bump(&counters.frames);
                if let Some(kind) = own_kind(&settings.nodes, id) {
                    if socket.echoes_own_frames() && echoes.matches(sent, id, &data, len) {
                        BusCounters::bump(&counters.own_echoes);
                    } else {
                        BusCounters::bump(&counters.intrusions);
                        push(BusEvent::Intrusion { cob_id: id, kind });
                    }
                    continue;
                }
                match settings.nodes.decode(u32::from(id), &data[..len]) {
                    Ok(message) => {
                        if let Some(kind) = streams.judge(&message) {
                            // A second sender of FORCE or STATUS: not published (the
                            // closed loop must not act on it), and the driver trips.
                            BusCounters::bump(&counters.intrusions);
                            push(BusEvent::Intrusion { cob_id: id, kind });
                        } else if let Message::Force(f) = message {
                            let stim_seq = status.load().last_pulse_tick_seq;
                            forces.publish(&f, settings.max_force_n, stim_seq, counters);
                        } else if let Some(event) = forward_event(&message) {
                            push(event);
                        }
                    }
                    Err(_) => BusCounters::bump(&counters.decode_errors),
                }
            }
            Ok(Rx::Nothing) => {}
            Err(e) if e.kind() == io::ErrorKind::InvalidData => {
                // A host-bus datagram that is not a CAN frame.
                BusCounters::bump(&counters.decode_errors);
            }
            Err(e) => {
                BusCounters::bump(&counters.read_errors);
                if matches!(
                    e.raw_os_error(),
                    Some(libc::ENETDOWN) | Some(libc::ENODEV) | Some(libc::ENXIO)
                ) && link_up
                {
                    link_up = false;
                    push(BusEvent::LinkDown);
                }
                // Do not spin on a failing socket.
                std::thread::sleep(READ_TIMEOUT);
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(class: u32, data: &[u8]) -> CanErrorFrame {
        CanErrorFrame::new_error(class, data).unwrap()
    }

    #[test]
    fn error_frames_are_classified_by_linux_can_error_h() {
        // Classes: CAN_ERR_CRTL 0x4, CAN_ERR_BUSOFF 0x40, CAN_ERR_RESTARTED 0x100,
        // CAN_ERR_ACK 0x20; controller byte 1: 0x01 rx overflow, 0x04 rx warning,
        // 0x10 rx passive, 0x40 active.
        assert_eq!(classify_error_frame(frame(0x40, &[])), BusErrorKind::BusOff);
        assert_eq!(
            classify_error_frame(frame(0x100, &[])),
            BusErrorKind::Restarted
        );
        assert_eq!(
            classify_error_frame(frame(0x4, &[0, 0x10])),
            BusErrorKind::ErrorPassive
        );
        assert_eq!(
            classify_error_frame(frame(0x4, &[0, 0x01])),
            BusErrorKind::Overflow
        );
        assert_eq!(
            classify_error_frame(frame(0x4, &[0, 0x04])),
            BusErrorKind::ErrorWarning
        );
        assert_eq!(
            classify_error_frame(frame(0x4, &[0, 0x40])),
            BusErrorKind::ErrorActive
        );
        assert_eq!(
            classify_error_frame(frame(0x20, &[])),
            BusErrorKind::Other { class: 0x20 }
        );
        // Bus-off wins over a controller problem in the same frame.
        assert_eq!(
            classify_error_frame(frame(0x44, &[0, 0x10])),
            BusErrorKind::BusOff
        );
    }

    #[test]
    fn link_flags_of_the_loopback_interface() {
        // The host has no CAN, but the ioctl is generic: "lo" is up and running.
        let s = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        assert!(link_is_up(s.as_raw_fd(), "lo").unwrap());
        assert!(link_is_up(s.as_raw_fd(), "no-such-if0").is_err());
        assert!(link_is_up(s.as_raw_fd(), "").is_err());
    }
}
