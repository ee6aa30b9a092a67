//! Kernel transmit timestamps of PULSE frames (`SO_TIMESTAMPING`), where the kernel gives
//! them.
//!
//! The transmit socket asks for software transmit stamps (`SOF_TIMESTAMPING_TX_SOFTWARE |
//! SOF_TIMESTAMPING_SOFTWARE`); a CAN driver that calls `skb_tx_timestamp` (vcan does since
//! Linux 6.1, real controllers through the echo skb) then queues a copy of each sent frame
//! with its stamp (CLOCK_REALTIME) on the socket's error queue. The report thread reads that
//! queue non-blockingly through a duplicate of the socket's descriptor, recognises PULSE
//! frames by identifier and sequence number, and converts the stamp to CLOCK_MONOTONIC. The
//! forward thread never touches the error queue.

use std::io;
use std::os::fd::{AsRawFd, BorrowedFd, OwnedFd, RawFd};

use fes_rt::rt::clock::monotonic_ns;
use socketcan::{CanSocket, SocketOptions};

/// Asks the kernel for software transmit timestamps on `socket`.
pub fn enable(socket: &CanSocket) -> io::Result<()> {
    socket.set_timestamping(libc::SOF_TIMESTAMPING_TX_SOFTWARE | libc::SOF_TIMESTAMPING_SOFTWARE)
}

/// One transmitted frame with its kernel timestamp.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TxStamp {
    /// CAN identifier (with SocketCAN's flag bits).
    pub id: u32,
    /// Data length.
    pub dlc: u8,
    /// Data.
    pub data: [u8; 8],
    /// The stamp, CLOCK_REALTIME ns.
    pub realtime_ns: u64,
}

impl TxStamp {
    /// The stamp on CLOCK_MONOTONIC, using the offset between the two clocks now (both are
    /// read back to back; the offset only moves with clock steps and slewing).
    pub fn monotonic_ns(&self) -> u64 {
        let offset = realtime_ns().saturating_sub(monotonic_ns());
        self.realtime_ns.saturating_sub(offset)
    }
}

fn realtime_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_REALTIME always exists.
    unsafe { libc::clock_gettime(libc::CLOCK_REALTIME, &mut ts) };
    timespec_ns(&ts)
}

fn timespec_ns(ts: &libc::timespec) -> u64 {
    (ts.tv_sec as u64) * 1_000_000_000 + ts.tv_nsec as u64
}

/// Reads transmit stamps from a socket's error queue, never blocking.
#[derive(Debug)]
pub struct TxStampReader {
    fd: OwnedFd,
}

impl TxStampReader {
    /// A reader on a duplicate of `fd` (so it stays valid whatever the socket's owner does).
    pub fn new(fd: RawFd) -> io::Result<Self> {
        // SAFETY: `fd` is an open socket owned by the caller for the duration of this call.
        let borrowed = unsafe { BorrowedFd::borrow_raw(fd) };
        Ok(Self {
            fd: borrowed.try_clone_to_owned()?,
        })
    }

    /// The next stamped frame, or `None` when the error queue is empty.
    pub fn read(&self) -> io::Result<Option<TxStamp>> {
        // SAFETY: can_frame is plain data; all zero is a valid value.
        let mut frame: libc::can_frame = unsafe { std::mem::zeroed() };
        // u64 elements keep the control buffer aligned for cmsghdr.
        let mut control = [0u64; 64];
        let mut iov = libc::iovec {
            iov_base: (&raw mut frame).cast(),
            iov_len: size_of::<libc::can_frame>(),
        };
        // SAFETY: msghdr is plain data; all zero is a valid empty header, filled below.
        let mut msg: libc::msghdr = unsafe { std::mem::zeroed() };
        msg.msg_iov = &mut iov;
        msg.msg_iovlen = 1;
        msg.msg_control = control.as_mut_ptr().cast();
        msg.msg_controllen = size_of_val(&control);
        // SAFETY: `msg` points to live buffers (`frame`, `control`) of the stated sizes for
        // the duration of the call.
        let n = unsafe {
            libc::recvmsg(
                self.fd.as_raw_fd(),
                &mut msg,
                libc::MSG_ERRQUEUE | libc::MSG_DONTWAIT,
            )
        };
        if n < 0 {
            let e = io::Error::last_os_error();
            return if e.kind() == io::ErrorKind::WouldBlock {
                Ok(None)
            } else {
                Err(e)
            };
        }
        let mut stamp = None;
        // SAFETY: the CMSG_* helpers walk the control buffer the kernel just filled, within
        // `msg_controllen`; each header is checked for the expected level, type and length
        // before its data is read (unaligned read: CMSG_DATA need not be 8-aligned).
        unsafe {
            let mut cmsg = libc::CMSG_FIRSTHDR(&msg);
            while !cmsg.is_null() {
                let c = &*cmsg;
                let need = libc::CMSG_LEN(3 * size_of::<libc::timespec>() as u32) as usize;
                if c.cmsg_level == libc::SOL_SOCKET
                    && c.cmsg_type == libc::SO_TIMESTAMPING
                    && c.cmsg_len >= need
                {
                    let ts: libc::timespec =
                        std::ptr::read_unaligned(libc::CMSG_DATA(cmsg).cast::<libc::timespec>());
                    if ts.tv_sec != 0 || ts.tv_nsec != 0 {
                        stamp = Some(timespec_ns(&ts));
                    }
                }
                cmsg = libc::CMSG_NXTHDR(&msg, cmsg);
            }
        }
        Ok(stamp.map(|realtime_ns| TxStamp {
            id: frame.can_id,
            dlc: frame.can_dlc.min(8),
            data: frame.data,
            realtime_ns,
        }))
    }
}

/// Remembers the StimTick publish time of recent pulses by PULSE sequence number, to pair
/// them with their transmit stamps (a fixed ring; old entries are overwritten).
#[derive(Debug, Clone)]
pub struct PulseTimes {
    slots: Box<[(u16, u64)]>,
}

impl Default for PulseTimes {
    fn default() -> Self {
        Self::new()
    }
}

impl PulseTimes {
    const SLOTS: usize = 1024;

    /// An empty ring.
    pub fn new() -> Self {
        Self {
            slots: vec![(0, 0); Self::SLOTS].into_boxed_slice(),
        }
    }

    /// Remembers pulse `seq` published at `t_publish_ns`.
    pub fn insert(&mut self, seq: u16, t_publish_ns: u64) {
        self.slots[usize::from(seq) % Self::SLOTS] = (seq, t_publish_ns);
    }

    /// The publish time of pulse `seq`, if still remembered.
    pub fn take(&mut self, seq: u16) -> Option<u64> {
        let slot = &mut self.slots[usize::from(seq) % Self::SLOTS];
        if slot.0 == seq && slot.1 != 0 {
            let t = slot.1;
            slot.1 = 0;
            Some(t)
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pulse_times_pair_once_and_forget_overwritten() {
        let mut p = PulseTimes::new();
        p.insert(5, 100);
        p.insert(5 + 1024, 200);
        assert_eq!(p.take(5), None, "overwritten by a later pulse");
        assert_eq!(p.take(5 + 1024), Some(200));
        assert_eq!(p.take(5 + 1024), None, "paired once");
    }

    #[test]
    fn an_empty_error_queue_reads_none() {
        let s = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        let r = TxStampReader::new(s.as_raw_fd()).unwrap();
        assert_eq!(r.read().unwrap(), None);
    }

    #[test]
    fn clocks_convert() {
        let s = TxStamp {
            id: 0,
            dlc: 0,
            data: [0; 8],
            realtime_ns: realtime_ns(),
        };
        let m = monotonic_ns();
        assert!(s.monotonic_ns().abs_diff(m) < 5_000_000);
    }
}
