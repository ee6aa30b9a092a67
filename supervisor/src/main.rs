//! `supervisor`: the supervisor daemon and the operator's command line for it.
//!
//! The live runtime (`run`) and the operator client (`set`, `profile`, `stop`, `arm`,
//! `status`): one variant of [`Command`] per subcommand, each dispatched to its
//! `cmd::<name>` module. Offline model work and the bench are the workbench's (`fes`).
use clap::{Parser, Subcommand};

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
    /// Stop stimulation at once and disarm the driver (operator client).
    Stop(cmd::client::SocketArgs),
    /// Arm the driver; clears a fault once its cause is gone (operator client).
    Arm(cmd::client::SocketArgs),
    /// Show the daemon's state (operator client).
    Status(cmd::client::StatusArgs),
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Run(args) => cmd::run::run(args),
        Command::Set(args) => cmd::client::set(args),
        Command::Profile(args) => cmd::client::profile(args),
        Command::Stop(args) => cmd::client::stop(args),
        Command::Arm(args) => cmd::client::arm(args),
        Command::Status(args) => cmd::client::status(args),
    }
}
