//! What a process does when one of its threads panics: its safe move first, then abort.
//!
//! A panic is a bug, and a process of the stimulation chain must not go on with one thread
//! dead: the driver's report thread, panicking alone, froze its liveness checks while the
//! forward thread kept sending pulses (issue 19, item 6). Every process installs
//! [`install`] at start: the hook logs the panic (the journal at `crit`-like `error`, and
//! stderr), runs the process's safe move (the driver: NMT stop on its bus), and aborts the
//! whole process, so the rest of the chain sees it gone (the driver's and the stimulator's
//! watchdogs, the supervisor's health). The release profile also sets `panic = "abort"`;
//! the hook aborts in every profile, so the debug builds the tests run behave the same.

use std::sync::{Arc, OnceLock};

/// The process's safe move, set once its configuration is known (before that, a panic
/// only aborts).
type SafeMove = Arc<dyn Fn() + Send + Sync>;

static SAFE_MOVE: OnceLock<SafeMove> = OnceLock::new();

/// Installs the hook for process `name` (the log's subject).
pub fn install(name: &'static str) {
    std::panic::set_hook(Box::new(move |info| {
        let thread = std::thread::current();
        let thread = thread.name().unwrap_or("unnamed");
        let at = super::clock::monotonic_ns();
        let text = format!(
            "{name}: thread {thread} panicked at CLOCK_MONOTONIC {at} ns: {info}; aborting the process"
        );
        tracing::error!("{text}");
        eprintln!("{text}");
        if let Some(safe_move) = SAFE_MOVE.get() {
            safe_move();
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
