//! One exit-code convention for every binary of the project (README "Exit codes").
//!
//! | code | meaning | systemd |
//! |---|---|---|
//! | 0 | done | |
//! | 1 | refused or failed: bad configuration or input, missing real-time rights, a refused command, a check that did not pass; the same call fails the same way again | `RestartPreventExitStatus=1 2` |
//! | 2 | usage: the command line was not understood (clap's own code) | not restarted |
//! | 3 | unreachable: the daemon (the supervisor's control socket) could not be reached | |
//! | 4 | fault: a daemon failed while running, after a valid start (a restart may cure it) | `Restart=on-failure` restarts |
//!
//! Signals are the shell's `128 + n`; no binary uses another code.

use std::process::ExitCode;

/// An exit status of the convention above.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Exit {
    /// 0: done.
    Done = 0,
    /// 1: refused or failed; retrying the same call fails the same way.
    Failed = 1,
    /// 2: the command line was not understood.
    Usage = 2,
    /// 3: the daemon could not be reached.
    Unreachable = 3,
    /// 4: a daemon failed while running.
    Fault = 4,
}

impl Exit {
    /// The numeric code.
    pub const fn code(self) -> u8 {
        self as u8
    }
}

impl From<Exit> for ExitCode {
    fn from(e: Exit) -> Self {
        ExitCode::from(e.code())
    }
}

#[cfg(test)]
mod tests {
    use super::Exit;

    #[test]
    fn codes_are_the_documented_ones_and_usage_is_clap_s() {
        let codes = [
            Exit::Done,
            Exit::Failed,
            Exit::Usage,
            Exit::Unreachable,
            Exit::Fault,
        ]
        .map(Exit::code);
        assert_eq!(codes, [0, 1, 2, 3, 4]);
        // clap exits with 2 on a usage error: the convention's Usage is that code.
        let err = clap::Error::new(clap::error::ErrorKind::UnknownArgument);
        assert_eq!(err.exit_code(), i32::from(Exit::Usage.code()));
    }
}
