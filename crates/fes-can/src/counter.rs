//! Freshness of PULSE frames: the 4-bit alive counter and the 16-bit sequence number.
//!
//! The two have different jobs. The **alive counter** is a link-level check (AUTOSAR E2E
//! style): the sender adds 1 modulo 16 on every PULSE frame it transmits, and the receiver
//! rejects a frame whose counter is not the previous one + 1, which catches repeated
//! (stale) and lost frames. The **sequence number** names the pulse (the host's tick
//! number, say): EMCY frames quote it, and it must move forward in serial-number
//! arithmetic (RFC 1982), gaps allowed, so a replayed or reordered pulse is refused even
//! when its counter happens to fit.
//!
//! Validation is a separate, stateful step ([`AliveCheck`], [`SequenceCheck`]), not part
//! of `decode`, which stays a pure function of one frame.

/// Modulus of the alive counter (it is 4 bits wide).
pub const ALIVE_MODULUS: u8 = 16;

/// Sender side of the alive counter: yields 0, 1, ..., 15, 0, ...
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct AliveCounter {
    next: u8,
}

impl AliveCounter {
    /// A counter whose first value is 0.
    pub const fn new() -> Self {
        Self { next: 0 }
    }

    /// The counter value for the next frame; advances the counter.
    pub fn next_value(&mut self) -> u8 {
        let v = self.next;
        self.next = (self.next + 1) % ALIVE_MODULUS;
        v
    }
}

/// The alive counter of a frame was not the expected one.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("alive counter {received} received, {expected} expected (stale, repeated or lost frame)")]
pub struct AliveError {
    /// The counter value the receiver expected.
    pub expected: u8,
    /// The counter value the frame carried.
    pub received: u8,
}

/// Receiver side of the alive counter.
///
/// The first frame after [`AliveCheck::reset`] is accepted whatever its counter. After
/// that a frame must carry the previous counter + 1 (mod 16). A mismatching frame is
/// rejected and the check re-synchronises on it, so one lost frame costs exactly one
/// rejected frame, while a repeated frame (same counter) never resynchronises anything.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct AliveCheck {
    expected: Option<u8>,
}

impl AliveCheck {
    /// A check that accepts any counter on its first frame.
    pub const fn new() -> Self {
        Self { expected: None }
    }

    /// Forgets the history (on entering operational state).
    pub fn reset(&mut self) {
        self.expected = None;
    }

    /// The counter the next frame must carry, if known.
    pub const fn expected(&self) -> Option<u8> {
        self.expected
    }

    /// Checks `received` (taken modulo 16) and advances.
    pub fn check(&mut self, received: u8) -> Result<(), AliveError> {
        let received = received % ALIVE_MODULUS;
        let result = match self.expected {
            Some(expected) if expected != received => Err(AliveError { expected, received }),
            _ => Ok(()),
        };
        self.expected = Some((received + 1) % ALIVE_MODULUS);
        result
    }
}

/// True when `new` is ahead of `last` in 16-bit serial-number arithmetic (RFC 1982):
/// `new - last` (mod 2^16) is in `1..=32767`.
pub const fn seq_is_newer(new: u16, last: u16) -> bool {
    let d = new.wrapping_sub(last);
    d != 0 && d < 0x8000
}

/// A sequence number did not move forward.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("sequence number {received} is not newer than {last} (replayed or reordered frame)")]
pub struct SequenceError {
    /// The last accepted sequence number.
    pub last: u16,
    /// The sequence number the frame carried.
    pub received: u16,
}

/// Receiver side of the sequence number: each one must be newer than the last accepted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SequenceCheck {
    last: Option<u16>,
}

impl SequenceCheck {
    /// A check that accepts any sequence number first.
    pub const fn new() -> Self {
        Self { last: None }
    }

    /// Forgets the history.
    pub fn reset(&mut self) {
        self.last = None;
    }

    /// The last accepted sequence number.
    pub const fn last(&self) -> Option<u16> {
        self.last
    }

    /// Accepts `seq` if it is newer than the last accepted one (and remembers it).
    pub fn check(&mut self, seq: u16) -> Result<(), SequenceError> {
        match self.last {
            Some(last) if !seq_is_newer(seq, last) => Err(SequenceError {
                last,
                received: seq,
            }),
            _ => {
                self.last = Some(seq);
                Ok(())
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sender_wraps_after_fifteen() {
        let mut c = AliveCounter::new();
        let v: Vec<u8> = (0..34).map(|_| c.next_value()).collect();
        let expected: Vec<u8> = (0..34u8).map(|i| i % 16).collect();
        assert_eq!(v, expected);
    }

    #[test]
    fn receiver_accepts_a_sender_stream_across_wraps() {
        let mut tx = AliveCounter::new();
        let mut rx = AliveCheck::new();
        for _ in 0..100 {
            assert_eq!(rx.check(tx.next_value()), Ok(()));
        }
    }

    #[test]
    fn repeated_frame_is_rejected_and_does_not_resync() {
        let mut rx = AliveCheck::new();
        rx.check(5).unwrap();
        assert_eq!(
            rx.check(5),
            Err(AliveError {
                expected: 6,
                received: 5
            })
        );
        assert_eq!(
            rx.check(5),
            Err(AliveError {
                expected: 6,
                received: 5
            })
        );
        assert_eq!(rx.check(6), Ok(()));
    }

    #[test]
    fn lost_frame_costs_exactly_one_rejection() {
        let mut rx = AliveCheck::new();
        rx.check(14).unwrap();
        // 15 lost on the bus.
        assert_eq!(
            rx.check(0),
            Err(AliveError {
                expected: 15,
                received: 0
            })
        );
        assert_eq!(rx.check(1), Ok(()));
    }

    #[test]
    fn reset_accepts_anything_first() {
        let mut rx = AliveCheck::new();
        rx.check(3).unwrap();
        rx.reset();
        assert_eq!(rx.check(11), Ok(()));
        assert_eq!(rx.expected(), Some(12));
    }

    #[test]
    fn serial_number_arithmetic() {
        assert!(seq_is_newer(1, 0));
        assert!(seq_is_newer(0, 65535));
        assert!(seq_is_newer(32767, 0));
        assert!(!seq_is_newer(32768, 0));
        assert!(!seq_is_newer(0, 0));
        assert!(!seq_is_newer(65535, 0));
    }

    #[test]
    fn sequence_check_allows_gaps_refuses_replays() {
        let mut s = SequenceCheck::new();
        s.check(65530).unwrap();
        s.check(3).unwrap(); // wrapped, gap of 9
        assert_eq!(
            s.check(3),
            Err(SequenceError {
                last: 3,
                received: 3
            })
        );
        assert_eq!(
            s.check(2),
            Err(SequenceError {
                last: 3,
                received: 2
            })
        );
        assert_eq!(s.last(), Some(3));
        s.check(4).unwrap();
    }
}
