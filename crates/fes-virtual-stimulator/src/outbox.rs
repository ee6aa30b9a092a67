//! A fixed-capacity queue of frames the state machine wants sent.

use fes_can::Frame;

/// Frames produced by one call into the state machine; never grows.
#[derive(Debug, Clone)]
pub struct Outbox<const N: usize = 16> {
    frames: [Frame; N],
    len: usize,
    dropped: u64,
}

impl<const N: usize> Default for Outbox<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Outbox<N> {
    /// An empty outbox.
    pub const fn new() -> Self {
        Self {
            frames: [Frame {
                id: 0,
                dlc: 0,
                data: [0; 8],
            }; N],
            len: 0,
            dropped: 0,
        }
    }

    /// Queues `frame`; when full the frame is dropped and counted.
    pub fn push(&mut self, frame: Frame) {
        if self.len < N {
            self.frames[self.len] = frame;
            self.len += 1;
        } else {
            self.dropped += 1;
        }
    }

    /// The queued frames, oldest first.
    pub fn frames(&self) -> &[Frame] {
        &self.frames[..self.len]
    }

    /// Empties the queue (keeps the drop count).
    pub fn clear(&mut self) {
        self.len = 0;
    }

    /// Frames dropped because the outbox was full, since creation.
    pub const fn dropped(&self) -> u64 {
        self.dropped
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_order_and_counts_overflow() {
        let mut o: Outbox<2> = Outbox::new();
        for id in 1..=3 {
            o.push(Frame {
                id,
                dlc: 0,
                data: [0; 8],
            });
        }
        let ids: Vec<u16> = o.frames().iter().map(|f| f.id).collect();
        assert_eq!(ids, [1, 2]);
        assert_eq!(o.dropped(), 1);
        o.clear();
        assert!(o.frames().is_empty());
    }
}
