//! systemd integration: `READY=1` once the driver is up, `WATCHDOG=1` only while the forward
//! thread makes progress, `STOPPING=1` on the way out. Outside systemd (no `NOTIFY_SOCKET`)
//! every call does nothing.

use std::time::{Duration, Instant};

use sd_notify::NotifyState;

/// The service manager connection.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Systemd {
    notify: bool,
    watchdog: Option<Duration>,
}

impl Systemd {
    /// Reads `NOTIFY_SOCKET` and `WATCHDOG_USEC` from the environment.
    pub fn from_env() -> Self {
        Self {
            notify: std::env::var_os("NOTIFY_SOCKET").is_some(),
            watchdog: sd_notify::watchdog_enabled(),
        }
    }

    /// True under systemd with a notify socket.
    pub fn is_active(&self) -> bool {
        self.notify
    }

    /// The watchdog interval systemd asked for (`WatchdogSec=`), if any.
    pub fn watchdog_interval(&self) -> Option<Duration> {
        if self.notify { self.watchdog } else { None }
    }

    fn send(&self, state: &[NotifyState]) {
        if self.notify {
            // A lost notification is not a driver fault; systemd acts on its absence.
            let _ = sd_notify::notify(state);
        }
    }

    /// `READY=1` with a status line.
    pub fn ready(&self, status: &str) {
        self.send(&[NotifyState::Ready, NotifyState::Status(status)]);
    }

    /// `STATUS=...`.
    pub fn status(&self, status: &str) {
        self.send(&[NotifyState::Status(status)]);
    }

    /// `WATCHDOG=1`.
    pub fn watchdog(&self) {
        self.send(&[NotifyState::Watchdog]);
    }

    /// `STOPPING=1`.
    pub fn stopping(&self) {
        self.send(&[NotifyState::Stopping]);
    }
}

/// Decides when to send `WATCHDOG=1`: every half interval, and only if the forward thread's
/// progress counter moved since the last keep-alive.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WatchdogFeeder {
    every: Duration,
    last_sent: Option<Instant>,
    last_progress: u64,
}

impl WatchdogFeeder {
    /// A feeder for systemd's `interval` (it sends every `interval / 2`).
    pub fn new(interval: Duration) -> Self {
        Self {
            every: interval / 2,
            last_sent: None,
            last_progress: 0,
        }
    }

    /// True when a keep-alive is due at `now` and `progress` has advanced since the last one
    /// (the caller then sends it).
    pub fn due(&mut self, now: Instant, progress: u64) -> bool {
        let time = self
            .last_sent
            .is_none_or(|t| now.duration_since(t) >= self.every);
        if time && progress != self.last_progress {
            self.last_sent = Some(now);
            self.last_progress = progress;
            true
        } else {
            false
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keep_alive_only_with_progress_and_at_half_the_interval() {
        let t0 = Instant::now();
        let ms = Duration::from_millis;
        let mut f = WatchdogFeeder::new(ms(2000));
        assert!(!f.due(t0, 0), "no progress yet");
        assert!(f.due(t0, 5));
        assert!(!f.due(t0 + ms(999), 9), "not before half the interval");
        assert!(f.due(t0 + ms(1000), 9));
        // The forward thread is stuck: no keep-alive, however long.
        assert!(!f.due(t0 + ms(5000), 9));
        assert!(f.due(t0 + ms(5001), 10));
    }

    #[test]
    fn outside_systemd_nothing_is_sent() {
        let s = Systemd {
            notify: false,
            watchdog: Some(Duration::from_secs(1)),
        };
        assert_eq!(s.watchdog_interval(), None);
        s.ready("x");
        s.watchdog();
    }
}
