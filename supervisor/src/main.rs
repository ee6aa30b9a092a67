//! `supervisor`: the operator's command line (identification now; bench commands later).
//!
//! One variant of [`Command`] per subcommand, each dispatched to `cmd::<name>::run`.
use clap::{Parser, Subcommand};

mod cmd;

/// FES controller supervisor.
#[derive(Debug, Parser)]
#[command(name = "supervisor", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Identify a Local Model Network from a data set (thesis 5.3, 5.4, App. B).
    Identify(cmd::identify::Args),
    /// Fit every network size of one structure and choose the size (Figs. 5.13-5.21).
    Sweep(cmd::sweep::Args),
    /// The thesis's Tables 5.1 and 5.2 on a data set.
    Compare(cmd::compare::Args),
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Identify(args) => cmd::identify::run(args),
        Command::Sweep(args) => cmd::sweep::run(args),
        Command::Compare(args) => cmd::compare::run(args),
    }
}
