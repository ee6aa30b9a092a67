//! `supervisor run --config supervisor.toml`: the daemon.

use std::path::PathBuf;

use anyhow::Context;
use supervisor::config::{EXAMPLE, SupervisorConfig};
use supervisor::daemon;

/// Arguments of `supervisor run`.
#[derive(Debug, clap::Args)]
#[command(
    after_help = "The configuration (schema fes-supervisor/1) is documented key by key in \
deploy/etc/fes/supervisor.toml; --print-example-config prints it. The operator commands \
(set, profile, stop, arm, status) talk to this daemon over its control socket."
)]
pub struct Args {
    /// Configuration file (TOML, schema "fes-supervisor/1").
    #[arg(long, default_value = "/etc/fes/supervisor.toml")]
    pub config: PathBuf,
    /// Validate the configuration and exit.
    #[arg(long)]
    pub check: bool,
    /// Print the complete default configuration and exit.
    #[arg(long)]
    pub print_example_config: bool,
}

/// Runs the daemon until SIGINT/SIGTERM.
pub fn run(args: Args) -> anyhow::Result<()> {
    // A panicking thread aborts the daemon: the driver's supervisor watch sees its node
    // dead and stops the stimulator.
    fes_rt::rt::panic::install("supervisor");
    if args.print_example_config {
        print!("{EXAMPLE}");
        return Ok(());
    }
    let cfg = SupervisorConfig::load(&args.config)?;
    if args.check {
        println!("{}: ok", args.config.display());
        return Ok(());
    }
    // The journal with priorities under systemd, stderr otherwise; the filter is RUST_LOG.
    fes_rt::rt::logging::init("supervisor");
    let stop = fes_rt::rt::signals::install_stop_handler().context("signal handlers")?;
    let outcome = daemon::run(&cfg, stop, |socket| {
        tracing::info!("supervisor ready; control socket {}", socket.display());
        eprintln!("supervisor: ready (control socket {})", socket.display());
    })?;
    for d in &outcome.recordings {
        eprintln!("supervisor: recording {}", d.display());
    }
    match outcome.fault {
        Some(f) => {
            eprintln!("supervisor: stopped with fault: {f}");
            std::process::exit(fes_rt::rt::exit::Exit::Fault.code().into());
        }
        None => {
            eprintln!("supervisor: stopped");
            Ok(())
        }
    }
}
