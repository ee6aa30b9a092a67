//! Host-side helpers for protocol tests on a CAN interface: a [`Tap`] that records every
//! frame with its arrival time, a [`HostPort`] that sends host frames with correct alive
//! counters and sequence numbers, and a [`HeartbeatSender`] that can be paused to trip
//! the stimulator's watchdog.

use std::io;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use fes_can::{
    AliveCounter, DecodeError, Frame, Heartbeat, Message, Nmt, NmtCommand, NmtState, Nodes, Pulse,
    StimLimits,
};
use socketcan::{CanFrame, CanSocket, EmbeddedFrame, Frame as _, Socket, StandardId};

/// One received frame.
#[derive(Debug, Clone, PartialEq)]
pub struct RxFrame {
    /// When the tap read it.
    pub at: Instant,
    /// Identifier (with SocketCAN's flag bits for extended / remote frames).
    pub id: u32,
    /// Payload.
    pub data: Vec<u8>,
    /// The payload decoded with the default nodes.
    pub message: Result<Message, DecodeError>,
}

impl RxFrame {
    /// The decoded message, if it decoded.
    pub fn msg(&self) -> Option<&Message> {
        self.message.as_ref().ok()
    }

    /// `cansend` syntax (`110#0102...`).
    pub fn to_cansend(&self) -> String {
        let mut s = format!("{:03X}#", self.id);
        for b in &self.data {
            s.push_str(&format!("{b:02X}"));
        }
        s
    }
}

/// How long the tap's reads wait before checking whether to stop.
const READ_TIMEOUT: Duration = Duration::from_millis(20);

/// Records every frame on an interface, in order, with timestamps.
pub struct Tap {
    frames: Arc<Mutex<Vec<RxFrame>>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Tap {
    /// Starts recording `iface` (a CAN interface, or `hostbus:<dir>` as its tap station).
    pub fn open(iface: &str) -> io::Result<Self> {
        if let Some(dir) = fes_hostbus::bus_dir(iface) {
            // The tap station of a host bus: every data frame the driver and the
            // stimulator send.
            use fes_hostbus::{HostBus, Station};
            let bus = HostBus::open(dir, Station::Tap, Some(READ_TIMEOUT))?;
            return Self::record("hostbus-tap", move || match bus.recv() {
                Ok(Some(r)) if !r.frame.is_error() => {
                    Ok(Some((r.frame.can_id, r.frame.payload().to_vec())))
                }
                Ok(_) => Ok(None),
                Err(e) if e.kind() == io::ErrorKind::InvalidData => Ok(None),
                Err(e) => Err(e),
            });
        }
        let socket = CanSocket::open(iface)?;
        socket.set_read_timeout(READ_TIMEOUT)?;
        Self::record("can-tap", move || match socket.read_frame() {
            Ok(frame) => {
                use fes_hostbus::{EFF_FLAG, RTR_FLAG};
                let id = frame.raw_id()
                    | if frame.is_extended() { EFF_FLAG } else { 0 }
                    | if matches!(frame, CanFrame::Remote(_)) {
                        RTR_FLAG
                    } else {
                        0
                    };
                Ok(Some((id, frame.data().to_vec())))
            }
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                ) =>
            {
                Ok(None)
            }
            Err(e) => Err(e),
        })
    }

    /// Records what `read` returns (identifier with flag bits, payload; `None`: nothing
    /// this time) on a thread named `name`, until dropped or a read fails.
    fn record(
        name: &str,
        mut read: impl FnMut() -> io::Result<Option<(u32, Vec<u8>)>> + Send + 'static,
    ) -> io::Result<Self> {
        let frames = Arc::new(Mutex::new(Vec::new()));
        let stop = Arc::new(AtomicBool::new(false));
        let (f, s) = (frames.clone(), stop.clone());
        let thread = std::thread::Builder::new()
            .name(name.into())
            .spawn(move || {
                while !s.load(Ordering::Relaxed) {
                    match read() {
                        Ok(Some((id, data))) => {
                            let at = Instant::now();
                            let message = fes_can::decode(id, &data);
                            f.lock()
                                .unwrap_or_else(PoisonError::into_inner)
                                .push(RxFrame {
                                    at,
                                    id,
                                    data,
                                    message,
                                });
                        }
                        Ok(None) => {}
                        Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                        Err(_) => break,
                    }
                }
            })?;
        Ok(Self {
            frames,
            stop,
            thread: Some(thread),
        })
    }

    /// A copy of everything received so far.
    pub fn frames(&self) -> Vec<RxFrame> {
        self.frames
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }

    /// Number of frames received so far.
    pub fn len(&self) -> usize {
        self.frames
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .len()
    }

    /// True when nothing was received yet.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Waits up to `timeout` for a frame at index `>= from` satisfying `pred`; returns its
    /// index and a copy.
    pub fn wait_for(
        &self,
        from: usize,
        timeout: Duration,
        pred: impl Fn(&RxFrame) -> bool,
    ) -> Option<(usize, RxFrame)> {
        let deadline = Instant::now() + timeout;
        loop {
            {
                let frames = self.frames.lock().unwrap_or_else(PoisonError::into_inner);
                if let Some(i) = (from..frames.len()).find(|&i| pred(&frames[i])) {
                    return Some((i, frames[i].clone()));
                }
            }
            if Instant::now() >= deadline {
                return None;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    }

    /// Waits for a decoded message at index `>= from` that `pick` accepts.
    pub fn wait_msg<T>(
        &self,
        from: usize,
        timeout: Duration,
        pick: impl Fn(&Message) -> Option<T>,
    ) -> Option<(usize, Instant, T)> {
        let (i, f) = self.wait_for(from, timeout, |f| {
            f.msg().is_some_and(|m| pick(m).is_some())
        })?;
        let m = f.msg().and_then(&pick)?;
        Some((i, f.at, m))
    }
}

impl Drop for Tap {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn write(socket: &CanSocket, f: &Frame) -> io::Result<()> {
    let id = StandardId::new(f.id)
        .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "identifier above 0x7FF"))?;
    let frame = CanFrame::new(id, f.payload())
        .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "payload over 8 bytes"))?;
    socket.write_frame(&frame)
}

fn encode(m: &Message, nodes: &Nodes) -> io::Result<Frame> {
    m.encode_for(nodes)
        .map_err(|e| io::Error::new(io::ErrorKind::InvalidInput, e))
}

/// The host's side of the protocol, for scripted tests.
pub struct HostPort {
    socket: CanSocket,
    nodes: Nodes,
    alive: AliveCounter,
    seq: u16,
}

impl HostPort {
    /// Opens `iface` with the default nodes.
    pub fn open(iface: &str) -> io::Result<Self> {
        Ok(Self {
            socket: CanSocket::open(iface)?,
            nodes: Nodes::DEFAULT,
            alive: AliveCounter::new(),
            seq: 0,
        })
    }

    /// Sends a message.
    pub fn send(&self, m: &Message) -> io::Result<Frame> {
        let f = encode(m, &self.nodes)?;
        write(&self.socket, &f)?;
        Ok(f)
    }

    /// Sends a raw frame.
    pub fn send_frame(&self, f: &Frame) -> io::Result<()> {
        write(&self.socket, f)
    }

    /// Sends NMT `command` to the stimulator.
    pub fn nmt(&self, command: NmtCommand) -> io::Result<Frame> {
        self.send(&Message::Nmt(Nmt {
            command,
            node: self.nodes.stim(),
        }))
    }

    /// Sends both CONFIG pages of `limits` under `config_id`.
    pub fn configure(&self, limits: &StimLimits, config_id: u8) -> io::Result<()> {
        for page in limits.to_pages(config_id) {
            self.send(&Message::Config(page))?;
        }
        Ok(())
    }

    /// The next pulse with fresh counters (advances them; nothing is sent).
    pub fn next_pulse(&mut self, amplitude_100ua: u16, width_us: u16) -> Pulse {
        self.seq = self.seq.wrapping_add(1);
        Pulse {
            seq: self.seq,
            alive_counter: self.alive.next_value(),
            channel: 0,
            amplitude_100ua,
            width_us,
        }
    }

    /// Sends a well-formed pulse.
    pub fn pulse(&mut self, amplitude_100ua: u16, width_us: u16) -> io::Result<(Pulse, Frame)> {
        let p = self.next_pulse(amplitude_100ua, width_us);
        let f = self.send(&Message::Pulse(p))?;
        Ok((p, f))
    }

    /// Encodes (without sending) the pulse the next [`HostPort::pulse`] would send, with the
    /// CRC byte XORed with `crc_xor`; the counters do not advance, as the stimulator must
    /// drop the frame without learning from it.
    pub fn corrupt_pulse_frame(
        &self,
        amplitude_100ua: u16,
        width_us: u16,
        crc_xor: u8,
    ) -> io::Result<(Pulse, Frame)> {
        let mut alive = self.alive;
        let p = Pulse {
            seq: self.seq.wrapping_add(1),
            alive_counter: alive.next_value(),
            channel: 0,
            amplitude_100ua,
            width_us,
        };
        let mut f = encode(&Message::Pulse(p), &self.nodes)?;
        f.data[7] ^= crc_xor;
        Ok((p, f))
    }
}

#[derive(Debug, Default)]
struct BeatState {
    paused: bool,
    last_sent: Option<Instant>,
    sent: u64,
}

/// Sends the host heartbeat periodically from its own thread.
pub struct HeartbeatSender {
    state: Arc<Mutex<BeatState>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl HeartbeatSender {
    /// Starts sending `HOST_HEARTBEAT (operational)` on `iface` every `period`.
    pub fn start(iface: &str, period: Duration) -> io::Result<Self> {
        let socket = CanSocket::open(iface)?;
        let frame = encode(
            &Message::HostHeartbeat(Heartbeat {
                state: NmtState::Operational,
            }),
            &Nodes::DEFAULT,
        )?;
        let state = Arc::new(Mutex::new(BeatState::default()));
        let stop = Arc::new(AtomicBool::new(false));
        let (st, sp) = (state.clone(), stop.clone());
        let thread = std::thread::Builder::new()
            .name("host-heartbeat".into())
            .spawn(move || {
                let start = Instant::now();
                let mut n: u32 = 0;
                while !sp.load(Ordering::Relaxed) {
                    {
                        let mut s = st.lock().unwrap_or_else(PoisonError::into_inner);
                        // Stamped before the write: the frame cannot reach the
                        // stimulator earlier, so a watchdog measured from this stamp is
                        // never short (stamped after it, a write held up 1.5 ms in a UML
                        // guest made a 250 ms watchdog look like 248.5 ms).
                        let at = Instant::now();
                        if !s.paused && write(&socket, &frame).is_ok() {
                            s.last_sent = Some(at);
                            s.sent += 1;
                        }
                    }
                    n += 1;
                    let next = start + period * n;
                    std::thread::sleep(next.saturating_duration_since(Instant::now()));
                }
            })?;
        Ok(Self {
            state,
            stop,
            thread: Some(thread),
        })
    }

    /// Stops sending; returns when the last heartbeat went out (none follows): the instant
    /// just before its write.
    pub fn pause(&self) -> Option<Instant> {
        let mut s = self.state.lock().unwrap_or_else(PoisonError::into_inner);
        s.paused = true;
        s.last_sent
    }

    /// Sends again.
    pub fn resume(&self) {
        self.state
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .paused = false;
    }

    /// Heartbeats sent so far.
    pub fn sent(&self) -> u64 {
        self.state
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .sent
    }
}

impl Drop for HeartbeatSender {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// A host bus with only a tap station on it, for proving that a process refused bad input
/// before it put anything on the bus: start the process on
/// [`SilentBus::iface`], then [`SilentBus::assert_silent`].
pub struct SilentBus {
    dir: std::path::PathBuf,
    tap: fes_hostbus::HostBus,
}

impl SilentBus {
    /// A fresh bus in a temporary directory named after `tag` and this process.
    pub fn new(tag: &str) -> Self {
        use fes_hostbus::{HostBus, Station};
        let dir = std::env::temp_dir().join(format!("fes-silent-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let tap = HostBus::open(&dir, Station::Tap, None).expect("the tap station");
        Self { dir, tap }
    }

    /// The interface name to give the process under test.
    pub fn iface(&self) -> String {
        format!("{}{}", fes_hostbus::SCHEME, self.dir.display())
    }

    /// Panics naming `case` if a frame reached the tap or a driver or stimulator station
    /// was opened.
    pub fn assert_silent(&self, case: &str) {
        use fes_hostbus::Station;
        std::thread::sleep(Duration::from_millis(20));
        if let Some(r) = self.tap.recv().expect("tap read") {
            panic!("{case}: a frame reached the bus: {:?}", r.frame);
        }
        for s in [Station::Driver, Station::Stimulator] {
            assert!(
                !self.dir.join(s.file_name()).exists(),
                "{case}: the {s:?} station was opened"
            );
        }
    }
}

impl Drop for SilentBus {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}
