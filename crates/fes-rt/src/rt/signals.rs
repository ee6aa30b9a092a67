//! SIGINT / SIGTERM as a stop request: the handler only stores to an atomic flag
//! (async-signal-safe); the loops poll it once per tick.

use std::sync::atomic::{AtomicBool, Ordering};

use nix::sys::signal::{SaFlags, SigAction, SigHandler, SigSet, Signal, sigaction};

static STOP_REQUESTED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_stop_signal(_: libc::c_int) {
    STOP_REQUESTED.store(true, Ordering::SeqCst);
}

/// Installs the SIGINT and SIGTERM handlers and returns the flag they set.
pub fn install_stop_handler() -> Result<&'static AtomicBool, nix::Error> {
    let action = SigAction::new(
        SigHandler::Handler(on_stop_signal),
        SaFlags::empty(),
        SigSet::empty(),
    );
    for signal in [Signal::SIGINT, Signal::SIGTERM] {
        // SAFETY: the handler only performs an atomic store, which is async-signal-safe, and
        // it replaces no handler whose invariants anything relies on.
        unsafe { sigaction(signal, &action) }?;
    }
    Ok(&STOP_REQUESTED)
}
