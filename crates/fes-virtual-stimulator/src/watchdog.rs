//! The heartbeat consumer: the host's heartbeat must arrive within the watchdog time
//! while the stimulator is operational.

/// Host-heartbeat watchdog (times in ns of CLOCK_MONOTONIC).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HeartbeatWatchdog {
    timeout_ns: u64,
    last_ns: u64,
}

impl HeartbeatWatchdog {
    /// A watchdog with `timeout_ms`, fed at `now_ns`.
    pub const fn new(timeout_ms: u16, now_ns: u64) -> Self {
        Self {
            timeout_ns: timeout_ms as u64 * 1_000_000,
            last_ns: now_ns,
        }
    }

    /// Changes the timeout (a new configuration).
    pub fn set_timeout(&mut self, timeout_ms: u16) {
        self.timeout_ns = u64::from(timeout_ms) * 1_000_000;
    }

    /// A heartbeat arrived at `now_ns` (also used to re-arm on entering operational).
    pub fn feed(&mut self, now_ns: u64) {
        self.last_ns = now_ns;
    }

    /// `Some(elapsed_ns)` when more than the timeout has passed since the last feed.
    pub fn expired(&self, now_ns: u64) -> Option<u64> {
        let elapsed = now_ns.saturating_sub(self.last_ns);
        (elapsed > self.timeout_ns).then_some(elapsed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn expires_strictly_after_the_timeout() {
        let mut w = HeartbeatWatchdog::new(100, 1_000);
        assert_eq!(w.expired(1_000 + 100_000_000), None);
        assert_eq!(w.expired(1_000 + 100_000_001), Some(100_000_001));
        w.feed(50_000_000);
        assert_eq!(w.expired(150_000_000), None);
        w.set_timeout(20);
        assert_eq!(w.expired(70_000_001), Some(20_000_001));
    }
}
