//! Child processes of a test die with it: a test that panics must not leave a driver or a
//! publisher running (it would hold its iceoryx2 services and load the machine for the
//! tests after it).

use std::os::unix::process::CommandExt;
use std::process::Command;

/// Makes the child SIGKILLed when the thread that spawns it exits (`PR_SET_PDEATHSIG`):
/// a test thread that panics takes its children with it.
pub fn dies_with_parent(cmd: &mut Command) -> &mut Command {
    // SAFETY: the closure runs between fork and exec and only calls prctl(2), which is
    // async-signal-safe; it touches no memory of the parent.
    unsafe {
        cmd.pre_exec(|| {
            if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        })
    }
}
