//! Accepted pulses waiting for the tick they are applied at, in tick order.
//!
//! A hardware stimulator's CAN controller receives a frame when it is on the wire, and the
//! pulse is applied at the next tick of its own 1 ms loop. The virtual stimulator reads
//! frames when its loop runs; after a stall of its process it reads several at once. It
//! therefore schedules each pulse by the frame's arrival time (the kernel's receive
//! timestamp): several pulses can wait at once, each for its own tick, and the catch-up
//! after the stall applies them at those ticks (`Stimulator::tick`).

use fes_can::Pulse;

/// Most pulses that can wait at once: a stall of 64 ms at 1 kHz.
pub const PENDING_CAPACITY: usize = 64;

/// The queue (fixed capacity, no allocation).
#[derive(Debug, Clone)]
pub struct PendingPulses {
    ticks: [u64; PENDING_CAPACITY],
    pulses: [Option<Pulse>; PENDING_CAPACITY],
    len: usize,
}

impl Default for PendingPulses {
    fn default() -> Self {
        Self::new()
    }
}

impl PendingPulses {
    /// An empty queue.
    pub const fn new() -> Self {
        Self {
            ticks: [0; PENDING_CAPACITY],
            pulses: [None; PENDING_CAPACITY],
            len: 0,
        }
    }

    /// The ticks of the waiting pulses, oldest first.
    pub fn ticks(&self) -> &[u64] {
        &self.ticks[..self.len]
    }

    /// True when nothing waits.
    pub const fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Queues `pulse` for `tick`; `false` (not queued) when full or when `tick` is before
    /// the newest waiting pulse's (the queue stays in tick order).
    pub fn push(&mut self, tick: u64, pulse: Pulse) -> bool {
        if self.len == PENDING_CAPACITY || self.ticks().last().is_some_and(|&t| t > tick) {
            return false;
        }
        self.ticks[self.len] = tick;
        self.pulses[self.len] = Some(pulse);
        self.len += 1;
        true
    }

    /// Removes and returns the oldest pulse if it is due at or before `tick`.
    pub fn take_due(&mut self, tick: u64) -> Option<Pulse> {
        if self.len == 0 || self.ticks[0] > tick {
            return None;
        }
        let p = self.pulses[0];
        self.ticks.copy_within(1..self.len, 0);
        self.pulses.copy_within(1..self.len, 0);
        self.len -= 1;
        self.pulses[self.len] = None;
        p
    }

    /// Removes and returns the oldest pulse whatever its tick (cancelling).
    pub fn pop(&mut self) -> Option<Pulse> {
        self.ticks().first().copied().and_then(|t| self.take_due(t))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pulse(seq: u16) -> Pulse {
        Pulse {
            seq,
            amplitude_100ua: 100,
            width_us: 200,
            channel: 0,
            alive_counter: 0,
        }
    }

    #[test]
    fn keeps_tick_order_and_capacity() {
        let mut q = PendingPulses::new();
        assert!(q.is_empty());
        assert!(q.push(5, pulse(1)));
        assert!(q.push(5, pulse(2)), "equal ticks keep arrival order");
        assert!(!q.push(4, pulse(3)), "an earlier tick is refused");
        assert!(q.push(9, pulse(4)));
        assert_eq!(q.ticks(), &[5, 5, 9]);
        assert_eq!(q.take_due(4), None);
        assert_eq!(q.take_due(5).map(|p| p.seq), Some(1));
        assert_eq!(q.take_due(5).map(|p| p.seq), Some(2));
        assert_eq!(q.take_due(8), None);
        assert_eq!(q.take_due(100).map(|p| p.seq), Some(4));
        assert!(q.is_empty());
        for k in 0..PENDING_CAPACITY as u64 {
            assert!(q.push(k, pulse(k as u16)));
        }
        assert!(!q.push(1000, pulse(0)), "full");
        assert_eq!(q.pop().map(|p| p.seq), Some(0));
        assert_eq!(q.ticks().len(), PENDING_CAPACITY - 1);
    }
}
