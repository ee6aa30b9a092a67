//! Intrusion detection on the driver's own transmit identifiers.
//!
//! The driver is the only legitimate sender of NMT, PULSE, CONFIG and the host heartbeat
//! ([`OWN_KINDS`]). The receive thread ([`crate::bus`]) therefore also accepts frames on
//! those identifiers, and every one of them that the driver did not write itself is an
//! intrusion: another sender on the bus (a local user's CAN_RAW socket, a foreign node).
//! The forward path trips on it ([`crate::fault::Fault::Intrusion`]) in every mode.
//!
//! Telling the driver's own frames from foreign ones:
//!
//! * **SocketCAN.** A CAN_RAW socket never receives its own frames
//!   (`CAN_RAW_RECV_OWN_MSGS` is off), but the driver writes through a separate transmit
//!   socket ([`crate::tx::SocketTx`]), and the kernel loops every locally sent frame back to
//!   the host's other CAN_RAW sockets (`CAN_RAW_LOOPBACK`, which must stay on: on `vcan` it
//!   is how the frames reach a local stimulator). So the receive socket sees every frame the
//!   driver writes, in the order written. The forward thread records each frame in a
//!   [`SentLog`] *before* writing it (the echo may arrive before the write returns); the
//!   receive thread's [`SentMatcher`] consumes one logged frame per echo, in order. A frame
//!   on an own identifier that matches no logged frame not yet consumed is foreign. A
//!   foreign frame identical to one the driver wrote (a replayed heartbeat) consumes that
//!   entry, and then the driver's own echo of it finds none: detected one echo later.
//! * **Host bus** ([`fes_hostbus`]). A station never receives frames sent as itself (its
//!   bound socket or a [`fes_hostbus::HostBus::sender`] for it): every frame on an own
//!   identifier that reaches the driver's station is foreign, no log is consulted.
//!
//! Limits, stated: the log holds the last [`SENT_LOG_CAPACITY`] frames; a receive thread
//! more than that many frames behind the forward thread (about a second of traffic) can no
//! longer match its echoes and reports them as intrusions (a false trip, never a missed
//! one). A frame the receive socket drops (its queue full) is skipped over, so a foreign
//! frame identical to a dropped echo would pass unnoticed. Detection is not prevention: a
//! forged PULSE may reach the stimulator before the driver's NMT stop does (the measured
//! bound is in docs/safety.md); the private bus (docs/deployment.md: the CAN interface
//! in a network namespace only the driver joins) is what keeps other senders off.
//!
//! Hot-path rules: [`SentLog::record`] (forward thread) is wait-free, allocation-free and
//! lock-free: a per-slot sequence lock over atomics. [`SentMatcher::matches`] (receive
//! thread) only reads.

use std::sync::atomic::{AtomicU64, Ordering, fence};

use fes_can::{Frame, MessageKind, Nodes};

use crate::tx::{CanTx, TxDone, TxError};

/// The message kinds only the driver sends.
pub const OWN_KINDS: [MessageKind; 4] = [
    MessageKind::Nmt,
    MessageKind::Pulse,
    MessageKind::Config,
    MessageKind::HostHeartbeat,
];

/// The own message kind identifier `id` carries with `nodes`, if it is one of [`OWN_KINDS`].
pub fn own_kind(nodes: &Nodes, id: u16) -> Option<MessageKind> {
    OWN_KINDS.into_iter().find(|&k| nodes.id_of(k) == id)
}

/// Frames the [`SentLog`] remembers.
pub const SENT_LOG_CAPACITY: usize = 1024;

/// One logged frame: a sequence word (odd while being written; `2 * (index + 1)` once
/// frame `index` is complete), the identifier and length, and the data.
#[derive(Debug, Default)]
struct Slot {
    seq: AtomicU64,
    head: AtomicU64,
    data: AtomicU64,
}

/// The frames the driver wrote most recently, for the receive thread to recognise their
/// echoes (module documentation). One writer (the forward thread), one reader.
#[derive(Debug)]
pub struct SentLog {
    slots: Box<[Slot]>,
    written: AtomicU64,
}

impl Default for SentLog {
    fn default() -> Self {
        Self::new()
    }
}

fn head_of(frame: &Frame) -> u64 {
    (u64::from(frame.id) << 8) | u64::from(frame.dlc)
}

fn data_of(dlc: u8, data: &[u8; 8]) -> u64 {
    // Bytes past the length do not count.
    let mut d = [0u8; 8];
    let n = usize::from(dlc.min(8));
    d[..n].copy_from_slice(&data[..n]);
    u64::from_le_bytes(d)
}

impl SentLog {
    /// An empty log (allocated here, once, before the hot path).
    pub fn new() -> Self {
        Self {
            slots: (0..SENT_LOG_CAPACITY).map(|_| Slot::default()).collect(),
            written: AtomicU64::new(0),
        }
    }

    /// Frames recorded since the start.
    pub fn written(&self) -> u64 {
        self.written.load(Ordering::Acquire)
    }

    /// Records `frame` as about to be written (forward thread only). Never blocks.
    pub fn record(&self, frame: &Frame) {
        let index = self.written.load(Ordering::Relaxed);
        let slot = &self.slots[(index % SENT_LOG_CAPACITY as u64) as usize];
        slot.seq.store(2 * index + 1, Ordering::Relaxed);
        fence(Ordering::Release);
        slot.head.store(head_of(frame), Ordering::Relaxed);
        slot.data
            .store(data_of(frame.dlc, &frame.data), Ordering::Relaxed);
        slot.seq.store(2 * (index + 1), Ordering::Release);
        self.written.store(index + 1, Ordering::Release);
    }

    /// Frame `index`, if it is still in the log and was read consistently.
    fn get(&self, index: u64) -> Option<(u64, u64)> {
        let slot = &self.slots[(index % SENT_LOG_CAPACITY as u64) as usize];
        let s1 = slot.seq.load(Ordering::Acquire);
        if s1 != 2 * (index + 1) {
            return None;
        }
        let head = slot.head.load(Ordering::Relaxed);
        let data = slot.data.load(Ordering::Relaxed);
        fence(Ordering::Acquire);
        (slot.seq.load(Ordering::Relaxed) == s1).then_some((head, data))
    }
}

/// The receive thread's position in a [`SentLog`]: the oldest logged frame whose echo has
/// not been seen.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct SentMatcher {
    next: u64,
}

impl SentMatcher {
    /// A matcher at the start of the log.
    pub const fn new() -> Self {
        Self { next: 0 }
    }

    /// Whether the received frame (`id`, `data[..len]`) is the echo of a frame the driver
    /// logged and whose echo was not seen yet; if so, that entry (and any older one whose
    /// echo never came) is consumed. A `false` is an intrusion.
    pub fn matches(&mut self, log: &SentLog, id: u16, data: &[u8; 8], len: usize) -> bool {
        let Ok(dlc) = u8::try_from(len) else {
            return false;
        };
        let head = (u64::from(id) << 8) | u64::from(dlc);
        let bytes = data_of(dlc, data);
        let end = log.written();
        let start = self.next.max(end.saturating_sub(SENT_LOG_CAPACITY as u64));
        for index in start..end {
            if log.get(index) == Some((head, bytes)) {
                self.next = index + 1;
                return true;
            }
        }
        false
    }
}

/// A [`CanTx`] that records every frame in a [`SentLog`] before writing it.
#[derive(Debug)]
pub struct LoggingTx<'a, T> {
    inner: T,
    log: &'a SentLog,
}

impl<'a, T: CanTx> LoggingTx<'a, T> {
    /// Writes through `inner`, logging to `log`.
    pub fn new(inner: T, log: &'a SentLog) -> Self {
        Self { inner, log }
    }

    /// The transmit side it wraps.
    pub fn inner(&self) -> &T {
        &self.inner
    }
}

impl<T: CanTx> CanTx for LoggingTx<'_, T> {
    fn send(&mut self, frame: &Frame) -> Result<TxDone, TxError> {
        self.log.record(frame);
        self.inner.send(frame)
    }

    fn contraction_ahead(&mut self, ahead: bool) {
        self.inner.contraction_ahead(ahead);
    }
}

/// STATUS frames over which [`StimulatorStreams`] counts anomalies.
pub const STATUS_ANOMALY_WINDOW: u32 = 16;
/// Anomalies among the last [`STATUS_ANOMALY_WINDOW`] STATUS frames that make a second
/// sender.
pub const STATUS_ANOMALIES: u32 = 3;

/// A second sender of the stimulator's own sequenced streams (FORCE, STATUS): the
/// stimulator numbers them (FORCE `seq` +1 per frame, 16 bits; STATUS `counter` +1 per
/// frame, 4 bits), so frames from anyone else interleaved with its own repeat a number or
/// step back, whatever numbers the forger chooses (a forger one ahead makes the
/// stimulator's next frame a repeat; one far ahead makes it step back).
///
/// Frames the receive queue drops (a stalled reader) only ever skip numbers forward, so:
///
/// * FORCE: a repeat or a step back (a difference of 0 or at least 2^15, which dropped
///   frames would need 33 s of loss to make) is a second sender, at once;
/// * STATUS: 16 numbers wrap in 160 ms, so one drop of a backlog may land on any number;
///   a repeat or a step back of 1-4 counts as an anomaly, and
///   [`STATUS_ANOMALIES`] among the last [`STATUS_ANOMALY_WINDOW`] frames are a second
///   sender (a forger in step with the stimulator makes one every frame; separate
///   backlog drops within 160 ms cannot happen, each needs a stall of about half a second).
///
/// The stimulator's boot-up heartbeat restarts both numberings ([`Self::boot_up`]). Limits,
/// stated: a single forged STATUS with a plausible counter passes (what it could claim, a
/// state or a pulse count, trips the driver or is corrected by the next genuine STATUS); a
/// forger that replaces the stimulator's frames entirely (the stimulator silent) is not a
/// second sender: the stimulator-silence watchdog does not see it either. The private bus
/// (docs/deployment.md) is the mitigation; this is detection.
#[derive(Debug, Clone, Default)]
pub struct StimulatorStreams {
    force: Option<u16>,
    status: Option<u8>,
    /// One bit per STATUS frame of the window, most recent lowest: an anomaly.
    status_anomalies: u32,
}

impl StimulatorStreams {
    /// No frame seen yet.
    pub const fn new() -> Self {
        Self {
            force: None,
            status: None,
            status_anomalies: 0,
        }
    }

    /// The stimulator announced its boot-up: its numberings start again.
    pub fn boot_up(&mut self) {
        *self = Self::new();
    }

    /// Judges one decoded frame of the stimulator: the kind of a FORCE or STATUS out of
    /// its numbering (a second sender), else `None`; a boot-up heartbeat restarts both
    /// numberings.
    pub fn judge(&mut self, m: &fes_can::Message) -> Option<MessageKind> {
        match m {
            fes_can::Message::Force(f) if !self.force(f.seq) => Some(MessageKind::Force),
            fes_can::Message::Status(s) if !self.status(s.counter) => Some(MessageKind::Status),
            fes_can::Message::StimHeartbeat(h) if h.state == fes_can::NmtState::BootUp => {
                self.boot_up();
                None
            }
            _ => None,
        }
    }

    /// A FORCE frame numbered `seq`: `false` when it repeats or steps back.
    pub fn force(&mut self, seq: u16) -> bool {
        let in_step = self
            .force
            .is_none_or(|last| !matches!(seq.wrapping_sub(last), 0 | 0x8000..));
        self.force = Some(seq);
        in_step
    }

    /// A STATUS frame with `counter` (4 bits): `false` when the anomalies in the window
    /// reach [`STATUS_ANOMALIES`].
    pub fn status(&mut self, counter: u8) -> bool {
        let anomaly = self
            .status
            .is_some_and(|last| matches!(counter.wrapping_sub(last) & 0xF, 0 | 12..=15));
        self.status = Some(counter & 0xF);
        let window = (1u32 << STATUS_ANOMALY_WINDOW) - 1;
        self.status_anomalies = ((self.status_anomalies << 1) | u32::from(anomaly)) & window;
        self.status_anomalies.count_ones() < STATUS_ANOMALIES
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(id: u16, payload: &[u8]) -> Frame {
        let mut data = [0u8; 8];
        data[..payload.len()].copy_from_slice(payload);
        Frame {
            id,
            dlc: payload.len() as u8,
            data,
        }
    }

    fn echo(m: &mut SentMatcher, log: &SentLog, f: &Frame) -> bool {
        m.matches(log, f.id, &f.data, usize::from(f.dlc))
    }

    #[test]
    fn own_kinds_are_the_hosts_transmit_identifiers() {
        let n = Nodes::DEFAULT;
        assert_eq!(own_kind(&n, 0x000), Some(MessageKind::Nmt));
        assert_eq!(own_kind(&n, 0x110), Some(MessageKind::Pulse));
        assert_eq!(own_kind(&n, 0x310), Some(MessageKind::Config));
        assert_eq!(own_kind(&n, 0x701), Some(MessageKind::HostHeartbeat));
        for stim in [0x090, 0x190, 0x290, 0x710, 0x111] {
            assert_eq!(own_kind(&n, stim), None, "{stim:#x}");
        }
    }

    #[test]
    fn echoes_of_logged_frames_match_once_in_order_and_foreign_ones_never() {
        let log = SentLog::new();
        let mut m = SentMatcher::new();
        let hb = frame(0x701, &[0x05]);
        let pulse = frame(0x110, &[1, 2, 3, 4, 5, 6, 7, 8]);
        // Nothing logged: anything is foreign.
        assert!(!echo(&mut m, &log, &hb));
        log.record(&hb);
        log.record(&pulse);
        log.record(&hb);
        assert!(echo(&mut m, &log, &hb));
        assert!(echo(&mut m, &log, &pulse));
        assert!(echo(&mut m, &log, &hb));
        // Every entry consumed: a further identical heartbeat is foreign.
        assert!(!echo(&mut m, &log, &hb));
        // A frame differing in one data byte, or in length, is foreign.
        log.record(&pulse);
        let mut forged = pulse;
        forged.data[7] ^= 1;
        assert!(!echo(&mut m, &log, &forged));
        assert!(!echo(&mut m, &log, &frame(0x110, &[1, 2, 3, 4, 5, 6, 7])));
        assert!(echo(&mut m, &log, &pulse));
    }

    #[test]
    fn a_replayed_frame_is_caught_by_the_echo_it_displaces() {
        let log = SentLog::new();
        let mut m = SentMatcher::new();
        let hb = frame(0x701, &[0x05]);
        log.record(&hb);
        // A foreign copy arrives first and takes the entry...
        assert!(echo(&mut m, &log, &hb));
        // ...so the driver's own echo finds none.
        assert!(!echo(&mut m, &log, &hb));
    }

    #[test]
    fn a_lost_echo_is_skipped_and_a_lapped_reader_reports_not_misses() {
        let log = SentLog::new();
        let mut m = SentMatcher::new();
        let a = frame(0x000, &[0x02, 0x10]);
        let b = frame(0x701, &[0x04]);
        log.record(&a);
        log.record(&b);
        // The echo of `a` was dropped: `b` still matches, `a` is gone.
        assert!(echo(&mut m, &log, &b));
        assert!(!echo(&mut m, &log, &a));
        // A reader more than the capacity behind cannot match the overwritten frames.
        let old = frame(0x310, &[9; 8]);
        log.record(&old);
        for k in 0..SENT_LOG_CAPACITY {
            log.record(&frame(0x110, &(k as u64).to_le_bytes()));
        }
        assert!(!echo(&mut m, &log, &old));
        let last = frame(0x110, &((SENT_LOG_CAPACITY - 1) as u64).to_le_bytes());
        assert!(echo(&mut m, &log, &last));
    }

    #[test]
    fn a_concurrent_writer_and_reader_agree() {
        // The forward thread writes while the receive thread matches the echoes (kept
        // within the log's capacity of each other): every echo matches, none is torn.
        let log = SentLog::new();
        let seen = AtomicU64::new(0);
        let n = 100_000u64;
        std::thread::scope(|s| {
            s.spawn(|| {
                let mut m = SentMatcher::new();
                for k in 0..n {
                    while log.written() <= k {
                        std::hint::spin_loop();
                    }
                    let f = frame(0x110, &k.to_le_bytes());
                    assert!(echo(&mut m, &log, &f), "echo {k} not matched");
                    seen.store(k + 1, Ordering::Release);
                }
            });
            for k in 0..n {
                while k >= seen.load(Ordering::Acquire) + SENT_LOG_CAPACITY as u64 / 2 {
                    std::hint::spin_loop();
                }
                log.record(&frame(0x110, &k.to_le_bytes()));
            }
        });
    }

    #[test]
    fn logging_tx_logs_before_it_writes() {
        let log = SentLog::new();
        let mut tx = LoggingTx::new(crate::tx::CountingSink::new(0x110), &log);
        let f = frame(0x110, &[1; 8]);
        tx.send(&f).unwrap();
        assert_eq!((log.written(), tx.inner().pulses), (1, 1));
        // A failed write stays logged (harmless: an entry nobody echoes is skipped).
        let mut failing = crate::tx::CountingSink::new(0x110);
        failing.fail_with = Some(TxError::Failed { errno: 5 });
        let mut tx = LoggingTx::new(failing, &log);
        assert!(tx.send(&f).is_err());
        assert_eq!(log.written(), 2);
    }

    #[test]
    fn a_forced_repeat_or_step_back_is_a_second_force_sender_and_drops_are_not() {
        let mut s = StimulatorStreams::new();
        for seq in [7u16, 8, 9, 300, 301, 30_000, 60_000, 65_535, 0, 1] {
            assert!(s.force(seq), "dropped frames skip forward: {seq}");
        }
        assert!(!s.force(1), "a repeat");
        assert!(s.force(2));
        assert!(!s.force(0), "a step back");
        // A forger one ahead: the stimulator's own next frame repeats it.
        let mut s = StimulatorStreams::new();
        assert!(s.force(100));
        assert!(s.force(101), "the forged frame, one ahead, passes");
        assert!(!s.force(101), "the stimulator's own 101 is the repeat");
        // A boot-up restarts the numbering.
        s.boot_up();
        assert!(s.force(0));
    }

    #[test]
    fn status_anomalies_trip_at_three_in_sixteen_and_one_backlog_drop_does_not() {
        let mut s = StimulatorStreams::new();
        // Normal: +1 mod 16, and a drop that lands anywhere (here a repeat) once.
        for k in 0..40u8 {
            assert!(s.status(k % 16), "in step: {k}");
        }
        assert!(
            s.status(39 % 16),
            "one anomaly (a backlog drop) is not a sender"
        );
        for k in 40..80u8 {
            assert!(s.status(k % 16), "in step: {k}");
        }
        // A forger in step: every stimulator frame repeats the forged number.
        let mut s = StimulatorStreams::new();
        assert!(s.status(4));
        assert!(s.status(5)); // forged
        assert!(s.status(5)); // the stimulator's: anomaly 1
        assert!(s.status(6)); // forged
        assert!(s.status(6)); // anomaly 2
        assert!(s.status(7)); // forged
        assert!(!s.status(7), "the third anomaly in 16 frames");
        // Anomalies older than the window no longer count.
        let mut s = StimulatorStreams::new();
        assert!(s.status(0));
        assert!(s.status(0));
        assert!(s.status(15));
        for k in 0..16u8 {
            assert!(s.status(k), "in step: {k}");
        }
        assert!(s.status(15), "the earlier two left the window");
    }
}
