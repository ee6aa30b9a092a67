//! `supervisor`: the supervisor daemon and the operator's command line for it.
//!
//! The live runtime (`run`) and the operator client (`set`, `profile`, `stop`, `arm`,
//! `status`): one variant of [`Command`] per subcommand, each dispatched to its
//! `cmd::<name>` module. Offline model work and the bench are the workbench's (`fes`).
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use fes_rt::rt::exit::Exit;
use supervisor::control::ClientError;

mod cmd;

/// FES controller supervisor: the safety daemon and its operator client.
#[derive(Debug, Parser)]
#[command(name = "supervisor", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run the supervisor daemon: references, outer loop, health, recording, control socket.
    Run(cmd::run::Args),
    /// Hold a constant reference force (operator client).
    Set(cmd::client::SetArgs),
    /// Run a reference profile: constant, steps, ramps, cardiac (operator client).
    Profile(cmd::client::ProfileArgs),
    /// Stop stimulation at once and disarm the driver, then wait (up to --timeout-s) for
    /// the driver's acknowledgement: exit 0 once acknowledged, 4 with an alarm when it is
    /// missing (operator client).
    Stop(cmd::client::SocketArgs),
    /// Arm the driver and wait for its acknowledgement (exit 1 refused, 4 missing); clears
    /// a fault once its cause is gone (operator client).
    Arm(cmd::client::SocketArgs),
    /// Show the daemon's state (operator client).
    Status(cmd::client::StatusArgs),
    /// Wait while stimulation runs; the exit status says how it ended: 0 stopped by the
    /// operator (or --for-s passed), 4 stopped by a fault (an unplanned stop: the alarm is
    /// printed on stderr), 3 the daemon stopped answering (operator client).
    Watch(cmd::client::WatchArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Run(args) => cmd::run::run(args),
        Command::Set(args) => cmd::client::set(args),
        Command::Profile(args) => cmd::client::profile(args),
        Command::Stop(args) => cmd::client::stop(args),
        Command::Arm(args) => cmd::client::arm(args),
        Command::Status(args) => cmd::client::status(args),
        Command::Watch(args) => return watch(&args),
    };
    match result {
        Ok(()) => Exit::Done.into(),
        Err(e) => {
            // The format of anyhow's own `main` report: the error and its causes.
            eprintln!("Error: {e:?}");
            exit_for(&e).into()
        }
    }
}

/// `supervisor watch`: 0 planned end, 4 unplanned stop (the alarm on stderr), 3 the
/// daemon gone, 2 bad options.
fn watch(args: &cmd::client::WatchArgs) -> ExitCode {
    use cmd::client::{WatchEnd, WatchError};
    match cmd::client::watch(args) {
        Ok(WatchEnd::Planned) => Exit::Done.into(),
        Ok(WatchEnd::Unplanned(fault)) => {
            eprintln!("ALARM: unplanned stop: {fault}");
            Exit::Fault.into()
        }
        Err(e @ (WatchError::Gone(_) | WatchError::Unreachable(_))) => {
            eprintln!("{e}");
            Exit::Unreachable.into()
        }
        Err(e @ WatchError::Usage(_)) => {
            eprintln!("Error: {e}");
            Exit::Usage.into()
        }
    }
}

/// The exit code of a failed command: 3 when no daemon answered at the socket (the
/// operator's stop did not reach anything: a script must not read that as "refused"),
/// 4 when the driver did not acknowledge a stop or an arm (or a fault overtook it), 1
/// otherwise (README "Exit codes").
fn exit_for(e: &anyhow::Error) -> Exit {
    let unreachable = e.chain().any(|c| {
        matches!(
            c.downcast_ref::<ClientError>(),
            Some(ClientError::Connect { .. })
        )
    });
    if unreachable {
        Exit::Unreachable
    } else if let Some(o) = e
        .chain()
        .find_map(|c| c.downcast_ref::<cmd::client::OrderError>())
    {
        o.exit()
    } else {
        Exit::Failed
    }
}
