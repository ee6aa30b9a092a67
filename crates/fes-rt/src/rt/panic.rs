//! What a process does when one of its threads panics: its safe move first, then abort.
//!
//! A panic is a bug, and a process of the stimulation chain must not go on with one thread
//! dead: the driver's report thread, panicking alone, froze its liveness checks while the
//! forward thread kept sending pulses. Every process installs
//! [`install`] at start: the hook runs the process's safe move (the driver: NMT stop on its
//! bus) first, then logs the panic (the journal at `error`, and stderr) for at most
//! [`LOG_GRACE`], and aborts the whole process, so the rest of the chain sees it gone (the
//! driver's and the stimulator's watchdogs, the supervisor's health). Nothing that can
//! block comes before the safe move: a full stderr pipe or a stalled journal would hold the
//! panicking thread while the others go on (the forward thread pulsing), so the log is
//! written by a helper thread the hook waits for only that long. The release profile also
//! sets `panic = "abort"`; the hook aborts in every profile, so the debug builds the tests
//! run behave the same.

use std::sync::{Arc, OnceLock};
use std::time::Duration;

/// How long the hook waits for its log line to be written before it aborts anyway.
pub const LOG_GRACE: Duration = Duration::from_millis(100);

/// The process's safe move, set once its configuration is known (before that, a panic
/// only aborts).
type SafeMove = Arc<dyn Fn() + Send + Sync>;

static SAFE_MOVE: OnceLock<SafeMove> = OnceLock::new();

/// Installs the hook for process `name` (the log's subject).
pub fn install(name: &'static str) {
    std::panic::set_hook(Box::new(move |info| {
        let at = super::clock::monotonic_ns();
        if let Some(safe_move) = SAFE_MOVE.get() {
            safe_move();
        }
        let thread = std::thread::current();
        let thread = thread.name().unwrap_or("unnamed");
        let text = format!(
            "{name}: thread {thread} panicked at CLOCK_MONOTONIC {at} ns: {info}; safe move \
             done; aborting the process"
        );
        let (done, written) = std::sync::mpsc::channel();
        let logger = std::thread::Builder::new()
            .name("panic-log".into())
            .spawn(move || {
                tracing::error!("{text}");
                eprintln!("{text}");
                let _ = done.send(());
            });
        if logger.is_ok() {
            let _ = written.recv_timeout(LOG_GRACE);
        }
        std::process::abort();
    }));
}

/// Sets the safe move the hook runs before it aborts (once; a second call is ignored and
/// returns false). It runs on the panicking thread, in a process that is about to die:
/// keep it short and make it not panic.
pub fn set_safe_move(safe_move: impl Fn() + Send + Sync + 'static) -> bool {
    SAFE_MOVE.set(Arc::new(safe_move)).is_ok()
}

#[cfg(test)]
mod tests {
    use std::io::Write;
    use std::os::unix::process::ExitStatusExt;
    use std::process::{Command, Stdio};
    use std::time::{Duration, Instant};

    /// Set in the child run of [`a_blocked_stderr_delays_neither_the_safe_move_nor_the_abort`].
    const CHILD: &str = "FES_RT_PANIC_HOOK_CHILD_MARKER";

    /// The child's part: the hook installed, a safe move that creates the marker file,
    /// stderr filled to the brim (a pipe nobody reads), then a panic.
    fn child(marker: &str) -> ! {
        super::install("panic-hook-test");
        let marker = marker.to_owned();
        super::set_safe_move(move || {
            let _ = std::fs::write(&marker, b"safe move\n");
        });
        // Fill the pipe without blocking, then make it blocking again, as a stderr is.
        // SAFETY: fcntl on fd 2, which this process owns; no memory is passed.
        let flags = unsafe { libc::fcntl(2, libc::F_GETFL) };
        // SAFETY: as above.
        unsafe { libc::fcntl(2, libc::F_SETFL, flags | libc::O_NONBLOCK) };
        let chunk = [b'x'; 4096];
        let mut err = std::io::stderr();
        while err.write(&chunk).is_ok() {}
        // SAFETY: as above.
        unsafe { libc::fcntl(2, libc::F_SETFL, flags) };
        panic!("the test's panic");
    }

    /// The hook's order: a panicking process whose stderr is a full pipe (nobody reads it)
    /// still runs its safe move and aborts, within the log's grace time, instead of
    /// hanging in the log write while its other threads go on. With the log written
    /// before the safe move (the hook's earlier order) the child hangs and no marker
    /// appears.
    #[test]
    fn a_blocked_stderr_delays_neither_the_safe_move_nor_the_abort() {
        if let Ok(marker) = std::env::var(CHILD) {
            child(&marker);
        }
        let dir = fes_testkit::Scratch::new("rt-panic");
        let marker = dir.join("safe-move");
        let mut c = Command::new(std::env::current_exe().unwrap())
            .args([
                "rt::panic::tests::a_blocked_stderr_delays_neither_the_safe_move_nor_the_abort",
                "--exact",
                "--nocapture",
                "--test-threads=1",
            ])
            .env(CHILD, &marker)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let start = Instant::now();
        let status = loop {
            if let Some(s) = c.try_wait().unwrap() {
                break Some(s);
            }
            if start.elapsed() > Duration::from_secs(10) {
                let _ = c.kill();
                let _ = c.wait();
                break None;
            }
            std::thread::sleep(Duration::from_millis(10));
        };
        let safe_move = std::fs::read_to_string(&marker).is_ok();
        let status = status.expect("the panicking child hung (its log write blocked)");
        assert_eq!(status.signal(), Some(libc::SIGABRT), "{status:?}");
        assert!(safe_move, "the safe move did not run");
    }
}
