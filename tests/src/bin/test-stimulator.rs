//! `test-stimulator`: the virtual stimulator (`sim_muscle::stimulator`) driving the
//! deterministic charge-integrator plant (FORCE = delivered charge, 1 N per uC), for
//! protocol tests and bench checks that must not depend on a muscle model.
//! Takes the stimulator's options (`--iface`, limits, watchdog, `--record`, ...).

use clap::Parser;
use sim_muscle::stimulator::{StimulatorArgs, run, test_plant::ChargeIntegrator};

/// The virtual stimulator with the charge-integrator test plant.
#[derive(Parser, Debug)]
#[command(name = "test-stimulator", version)]
struct Cli {
    #[command(flatten)]
    args: StimulatorArgs,
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    run(cli.args, Box::new(ChargeIntegrator::new()))
}
