//! `test-stimulator`: the virtual stimulator (`fes_virtual_stimulator`) for protocol tests
//! and bench checks. By default it drives the deterministic charge-integrator plant
//! (FORCE = delivered charge, 1 N per uC), so a test sees every applied pulse;
//! `--plant fast|slow` drives the Ding muscle preset instead.
//! Takes the stimulator's options (`--iface`, limits, watchdog, `--record`, ...).

use anyhow::Context as _;
use clap::Parser;
use fes_virtual_stimulator::plant::Plant;
use fes_virtual_stimulator::{StimulatorArgs, run, test_plant::ChargeIntegrator};
use sim_muscle::muscle::{Muscle, MuscleConfig};
use sim_muscle::plant::OnDevice;
use sim_muscle::preset::Preset;

/// The virtual stimulator with a test plant.
#[derive(Parser, Debug)]
#[command(name = "test-stimulator", version)]
struct Cli {
    /// The plant: `charge` (charge integrator) or a muscle preset (`fast`, `slow`).
    #[arg(long, default_value = "charge")]
    plant: String,
    #[command(flatten)]
    args: StimulatorArgs,
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    let plant: Box<dyn Plant> = if cli.plant == "charge" {
        Box::new(ChargeIntegrator::new())
    } else {
        let preset: Preset = cli
            .plant
            .parse()
            .with_context(|| format!("--plant {}", cli.plant))?;
        Box::new(OnDevice(
            Muscle::new(MuscleConfig::preset(preset)).context("building the muscle model")?,
        ))
    };
    run(cli.args, plant)
}
