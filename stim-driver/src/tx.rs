//! Writing frames: the [`CanTx`] seam between the driver's logic and the bus.
//!
//! [`SocketTx`] is the SocketCAN implementation: a non-blocking raw socket that never
//! receives (its filter drops everything, so its receive queue cannot fill), on which a
//! full transmit queue (`ENOBUFS`, `EAGAIN`) is retried within a short, configured budget
//! and then dropped and reported, so the forward path never blocks on the bus.
//! [`CountingSink`] stands in for the bus in benchmarks and tests, and [`DatagramTx`] (a
//! Unix socket pair) in the latency suite's forward-path measurement on hosts without CAN.
//! [`HostBusTx`] writes to the host bus ([`fes_hostbus`], an interface named
//! `hostbus:<dir>`), and [`BusTx`] is whichever of the two the configured interface names.

use std::io;
use std::os::fd::{AsRawFd, RawFd};

use fes_can::Frame;
use fes_hostbus::{self as hostbus, HostBus, RawFrame, Station};
use fes_rt::rt::clock::{monotonic_ns, sleep_until};
use socketcan::{CanFrame, CanSocket, EmbeddedFrame, Socket, SocketOptions, StandardId};

/// A write that did not put the frame in the kernel's transmit queue.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum TxError {
    /// The transmit queue stayed full for the whole retry budget; the frame was dropped.
    #[error("transmit queue full: frame dropped after {attempts} attempts")]
    Dropped {
        /// Writes tried.
        attempts: u32,
    },
    /// The interface is down or gone (`ENETDOWN`, `ENODEV`, `ENXIO`).
    #[error("CAN interface down (errno {errno})")]
    LinkDown {
        /// errno.
        errno: i32,
    },
    /// The stimulator has not yet answered the transport's previous command (ScienceMode
    /// 2 is stop-and-wait: a command sent meanwhile would be answered -8 busy and not
    /// executed). Nothing was written; the caller may try again once it has answered.
    #[error("stimulator busy with the previous command: not written yet")]
    Busy,
    /// Any other failure.
    #[error("CAN write failed (errno {errno})")]
    Failed {
        /// errno.
        errno: i32,
    },
}

/// A frame written: how many times the transmit queue was found full first, and when the
/// write returned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TxDone {
    /// Retries after `ENOBUFS`/`EAGAIN`.
    pub retries: u32,
    /// CLOCK_MONOTONIC when the successful write returned, ns.
    pub written_ns: u64,
    /// Time spent in the write call(s), ns.
    pub write_ns: u64,
}

/// Where the driver's frames go. Implementations must not block beyond their own bounded
/// retry budget, allocate, or lock.
pub trait CanTx {
    /// Writes one frame.
    fn send(&mut self, frame: &Frame) -> Result<TxDone, TxError>;

    /// Whether pulses may come soon: the newest StimTick's
    /// `FLAG_CONTRACTION_AHEAD` (a contraction running, or a scheduled one starting within
    /// `StimTick::CONTRACTION_AHEAD_MS`). A transport that carries one command at a time
    /// keeps its line free of optional traffic meanwhile. A bus needs nothing (default).
    fn contraction_ahead(&mut self, _ahead: bool) {}
}

/// How long a full transmit queue is retried.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RetryPolicy {
    /// Total time allowed for one frame, ns (0 = one attempt).
    pub budget_ns: u64,
    /// Pause between attempts, ns.
    pub interval_ns: u64,
}

/// The classification of a write's errno.
fn classify(errno: i32) -> Classified {
    match errno {
        libc::ENOBUFS | libc::EAGAIN => Classified::QueueFull,
        libc::ENETDOWN | libc::ENODEV | libc::ENXIO | libc::ENETUNREACH => Classified::LinkDown,
        _ => Classified::Other,
    }
}

enum Classified {
    QueueFull,
    LinkDown,
    Other,
}

/// Converts a protocol frame to a SocketCAN frame (standard identifier, DLC <= 8).
pub fn to_can_frame(frame: &Frame) -> Option<CanFrame> {
    let id = StandardId::new(frame.id)?;
    CanFrame::new(id, frame.payload())
}

/// The SocketCAN transmit side (see the module documentation).
#[derive(Debug)]
pub struct SocketTx {
    socket: CanSocket,
    retry: RetryPolicy,
}

impl SocketTx {
    /// Opens `iface` for sending only: non-blocking, receive filter "drop all".
    pub fn open(iface: &str, retry: RetryPolicy) -> io::Result<Self> {
        let socket = CanSocket::open(iface)?;
        socket.set_filter_drop_all()?;
        socket.set_error_filter_drop_all()?;
        socket.set_nonblocking(true)?;
        Ok(Self { socket, retry })
    }

    /// The socket's file descriptor (for reading transmit timestamps from its error queue).
    pub fn raw_fd(&self) -> RawFd {
        self.socket.as_raw_fd()
    }

    /// The underlying socket.
    pub fn socket(&self) -> &CanSocket {
        &self.socket
    }
}

impl CanTx for SocketTx {
    fn send(&mut self, frame: &Frame) -> Result<TxDone, TxError> {
        let Some(can_frame) = to_can_frame(frame) else {
            return Err(TxError::Failed {
                errno: libc::EINVAL,
            });
        };
        let socket = &self.socket;
        write_with_retry(&self.retry, || {
            socket
                .write_frame(&can_frame)
                .map_err(|e| e.raw_os_error().unwrap_or(libc::EIO))
        })
    }
}

/// Calls `write` (one attempt; `Err(errno)` on failure) until it succeeds, retrying a full
/// transmit queue (`ENOBUFS`, `EAGAIN`) every `retry.interval_ns` within `retry.budget_ns`.
pub(crate) fn write_with_retry(
    retry: &RetryPolicy,
    mut write: impl FnMut() -> Result<(), i32>,
) -> Result<TxDone, TxError> {
    let start = monotonic_ns();
    let deadline = start + retry.budget_ns;
    let mut attempts = 0u32;
    let mut write_ns = 0;
    loop {
        attempts += 1;
        let before = monotonic_ns();
        let result = write();
        let after = monotonic_ns();
        write_ns += after - before;
        match result {
            Ok(()) => {
                return Ok(TxDone {
                    retries: attempts - 1,
                    written_ns: after,
                    write_ns,
                });
            }
            Err(errno) => match classify(errno) {
                Classified::LinkDown => return Err(TxError::LinkDown { errno }),
                Classified::Other => return Err(TxError::Failed { errno }),
                Classified::QueueFull => {
                    let next = after + retry.interval_ns;
                    if next > deadline {
                        return Err(TxError::Dropped { attempts });
                    }
                    sleep_until(next);
                }
            },
        }
    }
}

/// The host-bus transmit side: one datagram per station, never blocking (like vcan, a
/// station that is absent or behind misses the frame; see [`fes_hostbus`]).
#[derive(Debug)]
pub struct HostBusTx {
    bus: HostBus,
    retry: RetryPolicy,
}

impl HostBusTx {
    /// Sends through `bus` (a [`HostBus::sender`] for the driver station: the receive
    /// thread holds the driver's bound socket, [`crate::bus`]).
    pub fn new(bus: HostBus, retry: RetryPolicy) -> Self {
        Self { bus, retry }
    }
}

impl CanTx for HostBusTx {
    fn send(&mut self, frame: &Frame) -> Result<TxDone, TxError> {
        let Some(raw) = RawFrame::data(frame.id, frame.payload()) else {
            return Err(TxError::Failed {
                errno: libc::EINVAL,
            });
        };
        let bus = &self.bus;
        write_with_retry(&self.retry, || {
            bus.send(&raw)
                .map_err(|e| e.raw_os_error().unwrap_or(libc::EIO))
        })
    }
}

/// The driver's transmit side on the interface it was configured with.
#[derive(Debug)]
pub enum BusTx {
    /// A SocketCAN interface.
    Can(SocketTx),
    /// The host bus.
    Host(HostBusTx),
    /// ScienceMode 2 on a serial line ([`crate::serial_tx`]).
    Serial(crate::serial_tx::ScienceModeTx<std::fs::File>),
}

impl BusTx {
    /// Opens `iface`: `hostbus:<dir>` joins the host bus as a send-only driver station
    /// (the receive thread holds the driver's bound socket), anything else is a CAN
    /// interface.
    pub fn open(iface: &str, retry: RetryPolicy) -> io::Result<Self> {
        match hostbus::bus_dir(iface) {
            Some(dir) => Ok(Self::Host(HostBusTx::new(
                HostBus::sender(dir, Some(Station::Driver))?,
                retry,
            ))),
            None => Ok(Self::Can(SocketTx::open(iface, retry)?)),
        }
    }
}

impl CanTx for BusTx {
    fn send(&mut self, frame: &Frame) -> Result<TxDone, TxError> {
        match self {
            Self::Can(t) => t.send(frame),
            Self::Host(t) => t.send(frame),
            Self::Serial(t) => t.send(frame),
        }
    }
}

/// Bytes of a frame on a [`DatagramTx`]: identifier (2, little-endian), DLC, 8 data bytes.
pub const DATAGRAM_LEN: usize = 11;

/// A bus stand-in for measuring the forward path on a host without CAN: frames go as
/// [`DATAGRAM_LEN`]-byte datagrams over a non-blocking Unix `SOCK_SEQPACKET` socket pair,
/// with the same retry policy and timing as [`SocketTx`] (one system call per frame into a
/// kernel queue, as a CAN write). The other end is a [`DatagramPeer`].
#[derive(Debug)]
pub struct DatagramTx {
    fd: std::os::fd::OwnedFd,
    retry: RetryPolicy,
}

/// The receiving end of a [`DatagramTx`] (where a virtual stimulator reads the frames).
#[derive(Debug)]
pub struct DatagramPeer {
    fd: std::os::fd::OwnedFd,
}

/// A connected pair: the driver's transmit side and the stimulator's end.
pub fn datagram_bus(retry: RetryPolicy) -> io::Result<(DatagramTx, DatagramPeer)> {
    use nix::sys::socket::{AddressFamily, SockFlag, SockType, socketpair};
    let (a, b) = socketpair(
        AddressFamily::Unix,
        SockType::SeqPacket,
        None,
        SockFlag::SOCK_NONBLOCK | SockFlag::SOCK_CLOEXEC,
    )
    .map_err(io::Error::from)?;
    Ok((DatagramTx { fd: a, retry }, DatagramPeer { fd: b }))
}

impl CanTx for DatagramTx {
    fn send(&mut self, frame: &Frame) -> Result<TxDone, TxError> {
        if frame.dlc > 8 || frame.id > 0x7FF {
            return Err(TxError::Failed {
                errno: libc::EINVAL,
            });
        }
        let mut bytes = [0u8; DATAGRAM_LEN];
        bytes[..2].copy_from_slice(&frame.id.to_le_bytes());
        bytes[2] = frame.dlc;
        bytes[3..].copy_from_slice(&frame.data);
        let fd = self.fd.as_raw_fd();
        write_with_retry(&self.retry, || {
            // SAFETY: `bytes` is a live buffer of DATAGRAM_LEN bytes; `fd` is owned by self.
            let n = unsafe { libc::send(fd, bytes.as_ptr().cast(), bytes.len(), 0) };
            if n == DATAGRAM_LEN as isize {
                Ok(())
            } else if n < 0 {
                Err(io::Error::last_os_error()
                    .raw_os_error()
                    .unwrap_or(libc::EIO))
            } else {
                Err(libc::EIO)
            }
        })
    }
}

impl DatagramPeer {
    /// The next frame, if one is queued (never blocks; `None` also once the transmit side
    /// is closed). A datagram of the wrong size or with an impossible identifier or DLC is
    /// an `InvalidData` error.
    pub fn try_recv(&self) -> io::Result<Option<Frame>> {
        let mut bytes = [0u8; DATAGRAM_LEN + 1];
        // SAFETY: `bytes` is a live, writable buffer of its length; `fd` is owned by self.
        let n = unsafe {
            libc::recv(
                self.fd.as_raw_fd(),
                bytes.as_mut_ptr().cast(),
                bytes.len(),
                libc::MSG_DONTWAIT,
            )
        };
        if n < 0 {
            let e = io::Error::last_os_error();
            return match e.kind() {
                io::ErrorKind::WouldBlock => Ok(None),
                _ => Err(e),
            };
        }
        if n == 0 {
            // The transmit side is closed (a SOCK_SEQPACKET end of stream).
            return Ok(None);
        }
        let id = u16::from_le_bytes([bytes[0], bytes[1]]);
        let dlc = bytes[2];
        if n != DATAGRAM_LEN as isize || id > 0x7FF || dlc > 8 {
            return Err(io::Error::new(
                io::ErrorKind::InvalidData,
                format!("bad datagram: {n} bytes, id {id:#x}, dlc {dlc}"),
            ));
        }
        let mut data = [0u8; 8];
        data.copy_from_slice(&bytes[3..DATAGRAM_LEN]);
        Ok(Some(Frame { id, dlc, data }))
    }
}

/// A bus stand-in that counts frames (and can be told to fail), for benchmarks and tests.
#[derive(Debug, Clone, Default)]
pub struct CountingSink {
    /// Frames accepted.
    pub frames: u64,
    /// Pulse frames accepted (by identifier).
    pub pulses: u64,
    /// The last frame accepted.
    pub last: Option<Frame>,
    /// When set, every send fails with this error.
    pub fail_with: Option<TxError>,
    /// The PULSE identifier to count.
    pub pulse_id: u16,
}

impl CountingSink {
    /// A sink counting PULSE frames of `pulse_id`.
    pub fn new(pulse_id: u16) -> Self {
        Self {
            pulse_id,
            ..Self::default()
        }
    }
}

impl CanTx for CountingSink {
    fn send(&mut self, frame: &Frame) -> Result<TxDone, TxError> {
        if let Some(e) = self.fail_with {
            return Err(e);
        }
        self.frames += 1;
        if frame.id == self.pulse_id {
            self.pulses += 1;
        }
        self.last = Some(*frame);
        Ok(TxDone {
            retries: 0,
            written_ns: 0,
            write_ns: 0,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errnos_are_classified() {
        assert!(matches!(classify(libc::ENOBUFS), Classified::QueueFull));
        assert!(matches!(classify(libc::EAGAIN), Classified::QueueFull));
        assert!(matches!(classify(libc::ENETDOWN), Classified::LinkDown));
        assert!(matches!(classify(libc::ENODEV), Classified::LinkDown));
        assert!(matches!(classify(libc::EIO), Classified::Other));
    }

    #[test]
    fn datagram_bus_carries_frames_exactly_and_reports_a_full_queue() {
        let retry = RetryPolicy {
            budget_ns: 0,
            interval_ns: 0,
        };
        let (mut tx, rx) = datagram_bus(retry).unwrap();
        assert!(rx.try_recv().unwrap().is_none());
        let f = Frame {
            id: 0x210,
            dlc: 3,
            data: [9, 8, 7, 0, 0, 0, 0, 0],
        };
        let done = tx.send(&f).unwrap();
        assert_eq!(done.retries, 0);
        assert!(done.written_ns > 0);
        assert_eq!(rx.try_recv().unwrap(), Some(f));
        assert!(rx.try_recv().unwrap().is_none());
        // Nobody reads: the queue fills and, with no retry budget, the frame is dropped.
        let mut sent = 0u64;
        let error = loop {
            match tx.send(&f) {
                Ok(_) => sent += 1,
                Err(e) => break e,
            }
            assert!(sent < 1_000_000, "the queue never filled");
        };
        assert_eq!(error, TxError::Dropped { attempts: 1 });
        let mut received = 0u64;
        while let Some(g) = rx.try_recv().unwrap() {
            assert_eq!(g, f);
            received += 1;
        }
        assert_eq!(received, sent);
        // Impossible frames are refused before the write.
        let bad = Frame { id: 0x800, ..f };
        assert!(matches!(tx.send(&bad), Err(TxError::Failed { .. })));
        // A closed peer: the write fails with a clear errno, not a hang.
        let (tx2, rx2) = datagram_bus(retry).unwrap();
        drop(rx);
        assert!(matches!(tx.send(&f), Err(TxError::Failed { .. })));
        // A closed transmit side reads as nothing queued.
        drop(tx2);
        assert_eq!(rx2.try_recv().unwrap(), None);
    }

    #[test]
    fn frames_convert_exactly() {
        let f = Frame {
            id: 0x110,
            dlc: 8,
            data: [1, 2, 3, 4, 5, 6, 7, 8],
        };
        let c = to_can_frame(&f).unwrap();
        assert_eq!(socketcan::Frame::raw_id(&c), 0x110);
        assert_eq!(c.data(), &f.data);
        let bad = Frame { id: 0x800, ..f };
        assert!(to_can_frame(&bad).is_none());
    }
}
