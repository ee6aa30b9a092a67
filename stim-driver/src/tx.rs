//! Writing frames: the [`CanTx`] seam between the driver's logic and the bus.
//!
//! [`SocketTx`] is the SocketCAN implementation: a non-blocking raw socket that never
//! receives (its filter drops everything, so its receive queue cannot fill), on which a
//! full transmit queue (`ENOBUFS`, `EAGAIN`) is retried within a short, configured budget
//! and then dropped and reported, so the forward path never blocks on the bus.
//! [`CountingSink`] stands in for the bus in benchmarks and tests.

use std::io;
use std::os::fd::{AsRawFd, RawFd};

use fes_can::Frame;
use rt_core::rt::clock::{monotonic_ns, sleep_until};
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
        let start = monotonic_ns();
        let deadline = start + self.retry.budget_ns;
        let mut attempts = 0u32;
        let mut write_ns = 0;
        loop {
            attempts += 1;
            let before = monotonic_ns();
            let result = self.socket.write_frame(&can_frame);
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
                Err(e) => {
                    let errno = e.raw_os_error().unwrap_or(libc::EIO);
                    match classify(errno) {
                        Classified::LinkDown => return Err(TxError::LinkDown { errno }),
                        Classified::Other => return Err(TxError::Failed { errno }),
                        Classified::QueueFull => {
                            let next = after + self.retry.interval_ns;
                            if next > deadline {
                                return Err(TxError::Dropped { attempts });
                            }
                            sleep_until(next);
                        }
                    }
                }
            }
        }
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
