//! `vcan-run`: runs a command where a CAN interface is available (native vcan, the
//! interface in `CAN_IFACE`, or a User-Mode Linux guest), with `CAN_IFACE` and
//! `FES_VCAN_IFACE` set to the interface; exits with the command's status.
//!
//! ```text
//! vcan-run -- candump -n 1 vcan0
//! vcan-run -c 'ip -details link show "$CAN_IFACE"'
//! ```
//!
//! Exit status: the command's; 125 when no CAN environment could be set up.

use clap::Parser;
use fes_testkit::vcan::{self, GuestCommand};

/// Run a command with a CAN interface available (native vcan or a User-Mode Linux guest).
#[derive(Parser, Debug)]
#[command(name = "vcan-run", version)]
struct Cli {
    /// Run this shell command (`sh -c`) instead of PROGRAM ARGS.
    #[arg(short = 'c', long = "command", conflicts_with = "argv")]
    script: Option<String>,
    /// Time limit for the whole run in seconds (also FES_VCAN_TIMEOUT_S; default 300).
    #[arg(long)]
    timeout_s: Option<u64>,
    /// Only print which environment would be used.
    #[arg(long)]
    describe: bool,
    /// The program and its arguments.
    #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
    argv: Vec<String>,
}

const HARNESS_FAILED: i32 = 125;

fn main() {
    let cli = Cli::parse();
    if cli.describe {
        match vcan::describe() {
            Ok(d) => {
                println!("{d}");
                return;
            }
            Err(e) => {
                eprintln!("vcan-run: {e}");
                std::process::exit(HARNESS_FAILED);
            }
        }
    }
    let cmd = match (&cli.script, cli.argv.is_empty()) {
        (Some(s), _) => GuestCommand::shell(s),
        (None, false) => GuestCommand::new(cli.argv.clone()),
        (None, true) => {
            eprintln!(
                "vcan-run: nothing to run; give `-- PROGRAM ARGS...` or `-c 'shell command'`"
            );
            std::process::exit(2);
        }
    };
    let mut cmd = match cmd {
        Ok(c) => c,
        Err(e) => {
            eprintln!("vcan-run: {e}");
            std::process::exit(HARNESS_FAILED);
        }
    };
    if let Some(t) = cli.timeout_s {
        if t == 0 {
            eprintln!("vcan-run: --timeout-s must be positive");
            std::process::exit(2);
        }
        cmd.timeout = std::time::Duration::from_secs(t);
    }
    match vcan::run_command(&cmd, &mut |line| println!("{line}")) {
        Ok(outcome) => std::process::exit(outcome.status),
        Err(e) => {
            eprintln!("vcan-run: {e}");
            std::process::exit(HARNESS_FAILED);
        }
    }
}
