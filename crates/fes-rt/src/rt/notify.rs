//! systemd service notification (`sd_notify(3)`) for the FES processes.
//!
//! A process that systemd starts with `Type=notify` tells the manager over the datagram
//! socket named by `NOTIFY_SOCKET` that it is up (`READY=1`), what it is doing
//! (`STATUS=...`), that it is stopping (`STOPPING=1`) and, when the unit sets
//! `WatchdogSec=`, that it is alive (`WATCHDOG=1`) at least once per watchdog period;
//! otherwise systemd kills it (`WatchdogSignal=`, SIGABRT by default) and applies the
//! unit's `Restart=` policy.
//!
//! Here *alive* means *the real-time loop makes progress*. The loop only bumps an atomic
//! counter (its tick count); a normal-priority thread ([`run_progress_notifier`]) reads
//! it every quarter watchdog period and feeds the watchdog only when the counter has
//! advanced since its previous look ([`ProgressWatch`]). `READY=1` goes out at the first
//! advance, i.e. once the loop really runs. A loop that stalls (a stuck tick source, a
//! priority inversion, a starved core) stops the feeding within one check period, so
//! systemd acts between `WatchdogSec` and 1.25 × `WatchdogSec` after the stall began.
//! The real-time thread never makes a system call for any of this.
//!
//! Every process of the stack uses it the same way (rt-core, stim-driver, supervisor):
//!
//! ```no_run
//! use std::sync::atomic::{AtomicBool, AtomicU64};
//! use fes_rt::rt::notify::{NotifierSettings, ServiceManager, run_progress_notifier};
//!
//! # fn main() -> Result<(), fes_rt::rt::notify::NotifyError> {
//! let manager = ServiceManager::from_env()?; // once, at start-up (validates the variables)
//! let progress = AtomicU64::new(0); // the loop: progress.fetch_add(1, Relaxed) per cycle
//! let stop = AtomicBool::new(false); // set when the loop ends
//! std::thread::scope(|s| {
//!     s.spawn(|| {
//!         let settings = NotifierSettings::for_watchdog(manager.watchdog());
//!         run_progress_notifier(&manager, &settings, &progress, &[&stop], |ticks| {
//!             format!("running, {ticks} cycles")
//!         })
//!     });
//!     // ... start the loop, which bumps `progress`; set `stop` when it ends ...
//! });
//! # Ok(())
//! # }
//! ```
//!
//! Outside systemd (`NOTIFY_SOCKET` unset) every call is a no-op, so the same binary runs
//! from a shell or a test.

use std::ffi::OsStr;
use std::os::unix::ffi::OsStrExt;
use std::os::unix::net::{SocketAddr, UnixDatagram};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use sd_notify::NotifyState;

/// Environment variable naming the manager's notification socket.
pub const ENV_NOTIFY_SOCKET: &str = "NOTIFY_SOCKET";
/// Environment variable with the watchdog period, µs.
pub const ENV_WATCHDOG_USEC: &str = "WATCHDOG_USEC";
/// Environment variable with the pid the watchdog period is meant for.
pub const ENV_WATCHDOG_PID: &str = "WATCHDOG_PID";

/// Why notification could not be set up or a message not sent.
#[derive(Debug, thiserror::Error)]
pub enum NotifyError {
    /// `WATCHDOG_USEC` is not a positive whole number of microseconds.
    #[error("{ENV_WATCHDOG_USEC}={value:?} is not a positive whole number of microseconds")]
    BadWatchdogUsec {
        /// The variable's value.
        value: String,
    },
    /// `WATCHDOG_PID` is not a process id.
    #[error("{ENV_WATCHDOG_PID}={value:?} is not a process id")]
    BadWatchdogPid {
        /// The variable's value.
        value: String,
    },
    /// `NOTIFY_SOCKET` is neither an absolute path nor an abstract address (`@name`).
    #[error(
        "{ENV_NOTIFY_SOCKET}={value:?} is neither an absolute socket path nor an abstract \
         address (@name)"
    )]
    BadSocketAddress {
        /// The variable's value.
        value: String,
    },
    /// The notification socket could not be created or connected.
    #[error("cannot connect to the service manager's socket {address:?}: {source}")]
    Connect {
        /// The socket address.
        address: String,
        /// The system's reason.
        source: std::io::Error,
    },
    /// A notification could not be sent.
    #[error("cannot notify the service manager: {source}")]
    Send {
        /// The system's reason.
        source: std::io::Error,
    },
}

/// The service manager's notification channel, read once from the environment at
/// start-up. Without `NOTIFY_SOCKET` it is absent and every notification is a no-op.
#[derive(Debug)]
pub struct ServiceManager {
    /// Connected datagram socket to the manager, if there is one.
    socket: Option<UnixDatagram>,
    /// Watchdog period asked for by the manager (`WatchdogSec=`).
    watchdog: Option<Duration>,
}

impl ServiceManager {
    /// No service manager: notifications are dropped.
    pub fn absent() -> Self {
        Self {
            socket: None,
            watchdog: None,
        }
    }

    /// Reads `NOTIFY_SOCKET`, `WATCHDOG_USEC` and `WATCHDOG_PID` (call once, at start-up)
    /// and connects to the manager's socket.
    pub fn from_env() -> Result<Self, NotifyError> {
        let watchdog = watchdog_period(
            std::env::var_os(ENV_WATCHDOG_USEC).as_deref(),
            std::env::var_os(ENV_WATCHDOG_PID).as_deref(),
            std::process::id(),
        )?;
        match std::env::var_os(ENV_NOTIFY_SOCKET) {
            Some(address) if !address.is_empty() => Self::connect(&address, watchdog),
            _ => Ok(Self {
                socket: None,
                watchdog,
            }),
        }
    }

    /// Connects to the manager's socket at `address` (an absolute path, or `@name` for an
    /// abstract address) with the given watchdog period.
    pub fn connect(address: &OsStr, watchdog: Option<Duration>) -> Result<Self, NotifyError> {
        let connect_err = |source| NotifyError::Connect {
            address: address.to_string_lossy().into_owned(),
            source,
        };
        let bytes = address.as_bytes();
        let addr = match bytes.first() {
            Some(b'/') => SocketAddr::from_pathname(address).map_err(connect_err)?,
            Some(b'@') => {
                use std::os::linux::net::SocketAddrExt;
                SocketAddr::from_abstract_name(&bytes[1..]).map_err(connect_err)?
            }
            _ => {
                return Err(NotifyError::BadSocketAddress {
                    value: address.to_string_lossy().into_owned(),
                });
            }
        };
        let socket = UnixDatagram::unbound().map_err(connect_err)?;
        socket.connect_addr(&addr).map_err(connect_err)?;
        Ok(Self {
            socket: Some(socket),
            watchdog,
        })
    }

    /// True when a service manager listens (the process runs under systemd).
    pub fn is_present(&self) -> bool {
        self.socket.is_some()
    }

    /// The watchdog period the manager asked for (`WatchdogSec=`), if any.
    pub fn watchdog(&self) -> Option<Duration> {
        self.watchdog
    }

    /// Sends `states` in one datagram (a no-op without a manager).
    pub fn notify(&self, states: &[NotifyState<'_>]) -> Result<(), NotifyError> {
        let Some(socket) = &self.socket else {
            return Ok(());
        };
        let message = message(states);
        let sent = socket
            .send(message.as_bytes())
            .map_err(|source| NotifyError::Send { source })?;
        if sent != message.len() {
            return Err(NotifyError::Send {
                source: std::io::Error::new(std::io::ErrorKind::WriteZero, "datagram truncated"),
            });
        }
        Ok(())
    }

    /// `READY=1` with a status line.
    pub fn ready(&self, status: &str) -> Result<(), NotifyError> {
        self.notify(&[NotifyState::Ready, NotifyState::Status(status)])
    }

    /// `STOPPING=1` with a status line.
    pub fn stopping(&self, status: &str) -> Result<(), NotifyError> {
        self.notify(&[NotifyState::Stopping, NotifyState::Status(status)])
    }
}

/// The datagram text: one `KEY=value` line per state. A status containing a line break
/// would end its assignment early, so line breaks in it become spaces.
fn message(states: &[NotifyState<'_>]) -> String {
    let mut text = String::new();
    for state in states {
        let line = state.to_string();
        text.push_str(&line.replace(['\n', '\r'], " "));
        text.push('\n');
    }
    text
}

/// The watchdog period from `WATCHDOG_USEC` / `WATCHDOG_PID` as `sd_watchdog_enabled(3)`
/// reads them: none when `WATCHDOG_USEC` is unset, or when `WATCHDOG_PID` names another
/// process (the variables were inherited from a parent). Malformed values are errors.
pub fn watchdog_period(
    usec: Option<&OsStr>,
    pid: Option<&OsStr>,
    own_pid: u32,
) -> Result<Option<Duration>, NotifyError> {
    let Some(usec) = usec else {
        return Ok(None);
    };
    let text = usec.to_string_lossy();
    let micros = text
        .parse::<u64>()
        .ok()
        .filter(|&us| us > 0)
        .ok_or_else(|| NotifyError::BadWatchdogUsec {
            value: text.clone().into_owned(),
        })?;
    if let Some(pid) = pid {
        let text = pid.to_string_lossy();
        let pid = text.parse::<u32>().ok().filter(|&p| p > 0).ok_or_else(|| {
            NotifyError::BadWatchdogPid {
                value: text.clone().into_owned(),
            }
        })?;
        if pid != own_pid {
            return Ok(None);
        }
    }
    Ok(Some(Duration::from_micros(micros)))
}

/// What one look at the loop's progress counter found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Progress {
    /// The loop has not completed a cycle yet.
    NotStarted,
    /// The first cycle(s) completed since the previous look: the process is up.
    Started,
    /// The counter advanced since the previous look.
    Advancing,
    /// No cycle completed since the previous look.
    Stalled,
}

/// Compares successive readings of a loop's progress counter (cycles completed).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ProgressWatch {
    last: u64,
    started: bool,
}

impl ProgressWatch {
    /// A watch that has seen no cycle yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Records the counter's current value and says what changed since the previous call.
    pub fn observe(&mut self, count: u64) -> Progress {
        let advanced = count > self.last;
        self.last = self.last.max(count);
        match (advanced, self.started) {
            (true, false) => {
                self.started = true;
                Progress::Started
            }
            (true, true) => Progress::Advancing,
            (false, false) => Progress::NotStarted,
            (false, true) => Progress::Stalled,
        }
    }
}

/// How often [`run_progress_notifier`] looks at the counter and reports its status.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NotifierSettings {
    /// Interval between looks at the progress counter.
    pub check_period: Duration,
    /// Interval between `STATUS=` updates while the loop advances.
    pub status_period: Duration,
}

impl NotifierSettings {
    /// Shortest check period (a very short `WatchdogSec=` is not worth a busier thread).
    pub const MIN_CHECK_PERIOD: Duration = Duration::from_millis(5);
    /// Check period without a watchdog (only `READY=1` and the status depend on it).
    pub const NO_WATCHDOG_CHECK_PERIOD: Duration = Duration::from_millis(100);

    /// Checks every quarter of the watchdog period (systemd asks for a feed at least every
    /// half), every 100 ms without one; status about once a second.
    pub fn for_watchdog(watchdog: Option<Duration>) -> Self {
        let check_period = watchdog
            .map(|w| (w / 4).max(Self::MIN_CHECK_PERIOD))
            .unwrap_or(Self::NO_WATCHDOG_CHECK_PERIOD);
        Self {
            check_period,
            status_period: Duration::from_secs(1).max(check_period),
        }
    }
}

/// What [`run_progress_notifier`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct NotifierOutcome {
    /// `READY=1` was sent (the loop completed at least one cycle).
    pub ready: bool,
    /// `WATCHDOG=1` messages sent.
    pub feeds: u64,
    /// Looks that found the loop stalled (the watchdog was not fed).
    pub stalled_checks: u64,
    /// Messages that could not be sent (a missing manager is not an error).
    pub send_errors: u64,
}

/// Runs on a normal-priority thread until any flag in `stop` is set: every
/// `settings.check_period` it reads `progress` (cycles the loop has completed); at the
/// first advance it sends `READY=1`; at every look that finds an advance it sends
/// `WATCHDOG=1` (when the manager set a watchdog); while the loop does not advance it
/// sends nothing but one `STATUS=` line saying so, so that systemd's watchdog fires.
/// `status(cycles)` gives the status text (sent with `READY=1`, then every
/// `settings.status_period`). Ends with `STOPPING=1`. Send failures are counted, not
/// fatal: a vanished manager cannot be helped, and the watchdog covers the rest.
pub fn run_progress_notifier(
    manager: &ServiceManager,
    settings: &NotifierSettings,
    progress: &AtomicU64,
    stop: &[&AtomicBool],
    mut status: impl FnMut(u64) -> String,
) -> NotifierOutcome {
    let stopping = || stop.iter().any(|s| s.load(Ordering::Relaxed));
    let mut outcome = NotifierOutcome::default();
    let mut watch = ProgressWatch::new();
    let mut since_status = Duration::ZERO;
    let mut stall_reported = false;
    while !stopping() {
        std::thread::sleep(settings.check_period);
        if stopping() {
            break;
        }
        since_status += settings.check_period;
        let cycles = progress.load(Ordering::Relaxed);
        match watch.observe(cycles) {
            Progress::NotStarted => {}
            Progress::Started => {
                let text = status(cycles);
                let mut states = vec![NotifyState::Ready, NotifyState::Status(&text)];
                if manager.watchdog().is_some() {
                    states.push(NotifyState::Watchdog);
                    outcome.feeds += 1;
                }
                count(manager.notify(&states), &mut outcome);
                outcome.ready = true;
                since_status = Duration::ZERO;
            }
            Progress::Advancing => {
                let text;
                let mut states = Vec::with_capacity(2);
                if manager.watchdog().is_some() {
                    states.push(NotifyState::Watchdog);
                    outcome.feeds += 1;
                }
                if stall_reported || since_status >= settings.status_period {
                    text = status(cycles);
                    states.push(NotifyState::Status(&text));
                    since_status = Duration::ZERO;
                    stall_reported = false;
                }
                if !states.is_empty() {
                    count(manager.notify(&states), &mut outcome);
                }
            }
            Progress::Stalled => {
                outcome.stalled_checks += 1;
                if !stall_reported {
                    let text = format!(
                        "real-time loop stalled: no cycle completed in {} ms (after {cycles} \
                         cycles); watchdog not fed",
                        settings.check_period.as_millis()
                    );
                    count(manager.notify(&[NotifyState::Status(&text)]), &mut outcome);
                    stall_reported = true;
                }
            }
        }
    }
    count(
        manager.stopping(&format!(
            "stopping after {} cycles",
            progress.load(Ordering::Relaxed)
        )),
        &mut outcome,
    );
    outcome
}

/// Counts a failed send.
fn count(result: Result<(), NotifyError>, outcome: &mut NotifierOutcome) {
    if result.is_err() {
        outcome.send_errors += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Instant;

    fn os(s: &str) -> Option<&OsStr> {
        Some(OsStr::new(s))
    }

    #[test]
    fn watchdog_period_follows_sd_watchdog_enabled() {
        assert_eq!(watchdog_period(None, None, 7).unwrap(), None);
        assert_eq!(
            watchdog_period(os("2000000"), None, 7).unwrap(),
            Some(Duration::from_secs(2))
        );
        assert_eq!(
            watchdog_period(os("1500"), os("7"), 7).unwrap(),
            Some(Duration::from_micros(1500))
        );
        // Inherited from a parent: not ours.
        assert_eq!(watchdog_period(os("1500"), os("8"), 7).unwrap(), None);
        for bad in ["", "0", "-5", "2s", "1e6"] {
            assert!(
                matches!(
                    watchdog_period(os(bad), None, 7),
                    Err(NotifyError::BadWatchdogUsec { .. })
                ),
                "{bad:?}"
            );
        }
        assert!(matches!(
            watchdog_period(os("1000"), os("x"), 7),
            Err(NotifyError::BadWatchdogPid { .. })
        ));
    }

    #[test]
    fn progress_watch_reports_start_advance_and_stall() {
        let mut w = ProgressWatch::new();
        assert_eq!(w.observe(0), Progress::NotStarted);
        assert_eq!(w.observe(0), Progress::NotStarted);
        assert_eq!(w.observe(3), Progress::Started);
        assert_eq!(w.observe(9), Progress::Advancing);
        assert_eq!(w.observe(9), Progress::Stalled);
        assert_eq!(w.observe(9), Progress::Stalled);
        assert_eq!(w.observe(10), Progress::Advancing);
        // A counter never goes back; a smaller reading is no progress.
        assert_eq!(w.observe(4), Progress::Stalled);
        assert_eq!(w.observe(10), Progress::Stalled);
        assert_eq!(w.observe(11), Progress::Advancing);
    }

    #[test]
    fn check_period_is_a_quarter_of_the_watchdog() {
        let s = NotifierSettings::for_watchdog(Some(Duration::from_secs(2)));
        assert_eq!(s.check_period, Duration::from_millis(500));
        assert_eq!(s.status_period, Duration::from_secs(1));
        let s = NotifierSettings::for_watchdog(Some(Duration::from_millis(8)));
        assert_eq!(s.check_period, NotifierSettings::MIN_CHECK_PERIOD);
        let s = NotifierSettings::for_watchdog(None);
        assert_eq!(s.check_period, NotifierSettings::NO_WATCHDOG_CHECK_PERIOD);
        let s = NotifierSettings::for_watchdog(Some(Duration::from_secs(20)));
        assert_eq!(s.status_period, Duration::from_secs(5));
    }

    #[test]
    fn absent_manager_drops_notifications() {
        let m = ServiceManager::absent();
        assert!(!m.is_present());
        m.ready("x").unwrap();
        m.stopping("y").unwrap();
    }

    #[test]
    fn bad_socket_addresses_are_rejected() {
        assert!(matches!(
            ServiceManager::connect(OsStr::new("relative/notify"), None),
            Err(NotifyError::BadSocketAddress { .. })
        ));
        assert!(matches!(
            ServiceManager::connect(OsStr::new("/nonexistent-dir/notify"), None),
            Err(NotifyError::Connect { .. })
        ));
    }

    #[test]
    fn status_line_breaks_do_not_split_the_assignment() {
        assert_eq!(
            message(&[NotifyState::Ready, NotifyState::Status("a\nb")]),
            "READY=1\nSTATUS=a b\n"
        );
    }

    /// A fake manager: a datagram socket the notifier sends to.
    struct FakeManager {
        _dir: fes_testkit::Scratch,
        socket: UnixDatagram,
        path: std::path::PathBuf,
    }

    impl FakeManager {
        fn new(tag: &str) -> Self {
            let dir = fes_testkit::Scratch::new(&format!("rt-notify-{tag}"));
            let path = dir.join("notify");
            let socket = UnixDatagram::bind(&path).unwrap();
            socket
                .set_read_timeout(Some(Duration::from_millis(50)))
                .unwrap();
            Self {
                _dir: dir,
                socket,
                path,
            }
        }

        /// Every datagram received until `until`, with its arrival time.
        fn collect(&self, until: Instant) -> Vec<(Instant, String)> {
            let mut out = Vec::new();
            let mut buf = [0u8; 4096];
            while Instant::now() < until {
                if let Ok(n) = self.socket.recv(&mut buf) {
                    out.push((
                        Instant::now(),
                        String::from_utf8_lossy(&buf[..n]).into_owned(),
                    ));
                }
            }
            out
        }
    }

    /// The notifier against a fake manager and a counter driven by the test: READY once
    /// the counter moves, WATCHDOG=1 only while it moves, STOPPING=1 at the end.
    #[test]
    fn feeds_the_watchdog_only_while_the_counter_advances() {
        let fake = FakeManager::new("feed");
        let watchdog = Duration::from_millis(200);
        let manager = ServiceManager::connect(fake.path.as_os_str(), Some(watchdog)).unwrap();
        let settings = NotifierSettings::for_watchdog(Some(watchdog));
        let progress = AtomicU64::new(0);
        let stop = AtomicBool::new(false);
        let advance = AtomicBool::new(false);
        let t0 = Instant::now();
        let (messages, outcome, phases) = std::thread::scope(|s| {
            let notifier = s.spawn(|| {
                run_progress_notifier(&manager, &settings, &progress, &[&stop], |n| {
                    format!("{n} cycles")
                })
            });
            // The "loop": advances every 1 ms while `advance` is set.
            let looper = s.spawn(|| {
                while !stop.load(Ordering::Relaxed) {
                    if advance.load(Ordering::Relaxed) {
                        progress.fetch_add(1, Ordering::Relaxed);
                    }
                    std::thread::sleep(Duration::from_millis(1));
                }
            });
            // 0-300 ms not started; 300-1300 ms running; 1300-2300 ms stalled.
            let mut messages = fake.collect(t0 + Duration::from_millis(300));
            advance.store(true, Ordering::Relaxed);
            let started = Instant::now();
            messages.extend(fake.collect(t0 + Duration::from_millis(1300)));
            advance.store(false, Ordering::Relaxed);
            let stalled = Instant::now();
            messages.extend(fake.collect(t0 + Duration::from_millis(2300)));
            stop.store(true, Ordering::Relaxed);
            let outcome = notifier.join().unwrap();
            looper.join().unwrap();
            messages.extend(fake.collect(Instant::now() + Duration::from_millis(100)));
            (messages, outcome, (started, stalled))
        });
        let (started, stalled) = phases;
        for (t, m) in &messages {
            eprintln!("{:>6} ms {m:?}", (*t - t0).as_millis());
        }
        let ready: Vec<_> = messages
            .iter()
            .filter(|(_, m)| m.contains("READY=1"))
            .collect();
        assert_eq!(ready.len(), 1, "exactly one READY=1");
        assert!(ready[0].0 >= started, "READY=1 only after the loop ran");
        assert!(ready[0].1.contains("STATUS="), "READY carries a status");
        let feeds: Vec<Instant> = messages
            .iter()
            .filter(|(_, m)| m.lines().any(|l| l == "WATCHDOG=1"))
            .map(|(t, _)| *t)
            .collect();
        assert!(feeds.iter().all(|&t| t >= started), "no feed before start");
        // While running: fed at least every half watchdog period (checks every 50 ms; allow
        // one missed look for scheduling noise on a loaded machine).
        let running: Vec<Instant> = feeds.iter().copied().filter(|&t| t <= stalled).collect();
        assert!(running.len() >= 10, "{} feeds while running", running.len());
        for pair in running.windows(2) {
            assert!(
                pair[1] - pair[0] <= watchdog / 2 + Duration::from_millis(50),
                "feed gap {:?} while running",
                pair[1] - pair[0]
            );
        }
        // After the stall began: at most the one look that still saw the last cycles.
        let late: Vec<_> = feeds
            .iter()
            .filter(|&&t| t > stalled + settings.check_period + Duration::from_millis(20))
            .collect();
        assert!(late.is_empty(), "{} feeds during the stall", late.len());
        assert!(
            messages
                .iter()
                .any(|(t, m)| *t > stalled && m.contains("stalled")),
            "the stall is reported in STATUS"
        );
        let last = &messages.last().unwrap().1;
        assert!(last.starts_with("STOPPING=1\n"), "{last:?}");
        assert!(outcome.ready);
        assert!(outcome.stalled_checks >= 15, "{outcome:?}");
        assert_eq!(outcome.send_errors, 0);
    }
}
