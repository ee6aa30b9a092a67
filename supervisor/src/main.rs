//! `supervisor`: the operator's command line and the supervisor daemon.
//!
//! One variant of [`Command`] per subcommand, each dispatched to its module's `run`.
use clap::{Parser, Subcommand};

mod cli;

/// FES controller supervisor.
#[derive(Debug, Parser)]
#[command(name = "supervisor", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run the supervisor daemon: references, outer loop, health, recording, control socket.
    Run(cli::run::Args),
    /// Hold a constant reference force (operator client).
    Set(cli::client::SetArgs),
    /// Run a reference profile: constant, steps, ramps, cardiac (operator client).
    Profile(cli::client::ProfileArgs),
    /// Stop stimulation at once and disarm the driver (operator client).
    Stop(cli::client::SocketArgs),
    /// Arm the driver; clears a fault once its cause is gone (operator client).
    Arm(cli::client::SocketArgs),
    /// Show the daemon's state (operator client).
    Status(cli::client::StatusArgs),
    /// End-to-end bench: sim-muscle, stim-driver, rt-core and the supervisor on vcan.
    Bench(cli::bench::Args),
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Run(args) => cli::run::run(args),
        Command::Set(args) => cli::client::set(args),
        Command::Profile(args) => cli::client::profile(args),
        Command::Stop(args) => cli::client::stop(args),
        Command::Arm(args) => cli::client::arm(args),
        Command::Status(args) => cli::client::status(args),
        Command::Bench(args) => cli::bench::run(args),
    }
}
