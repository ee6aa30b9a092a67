//! `fes`: the workbench. Everything offline or on the bench: identification, analysis,
//! controller design, optimal stimulation patterns and the end-to-end bench. One variant
//! of [`Command`] per subcommand, each dispatched to its `cmd::<name>` module. The safety
//! daemon and its operator client are the `supervisor` binary.
use clap::{Parser, Subcommand};

mod cmd;

/// FES workbench: identify, analyse, design, optimal patterns and the bench.
#[derive(Debug, Parser)]
#[command(name = "fes", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Data sets from elsewhere: `fes dataset import` turns a CSV of force and
    /// stimulation into a data set.
    Dataset(cmd::dataset::Args),
    /// Identify a Local Model Network from a data set (thesis 5.3, 5.4, App. B).
    Identify(cmd::identify::Args),
    /// Fit every network size of one structure and choose the size (Figs. 5.13-5.21).
    Sweep(cmd::sweep::Args),
    /// The thesis's Tables 5.1 and 5.2 on a data set.
    Compare(cmd::compare::Args),
    /// Static analysis, force-frequency curve, stability report and validation of a model
    /// (thesis 2.4, 5.4.3; Figs. 5.24-5.28).
    Analyse(cmd::analyse::Args),
    /// Modify a model: replace unstable local eigenvalues and re-estimate that unit's
    /// offsets (thesis 5.4.3, Tables 5.3-5.4, Fig. 5.32).
    Modify(cmd::modify::Args),
    /// Design the Local Controller Network by pole placement (thesis 6.5.3, Tables 6.1/6.2).
    Design(cmd::design::Args),
    /// The pattern generator's loop variants side by side on step references
    /// (docs/control.md "Variants").
    LcnVariants(cmd::lcn_variants::Args),
    /// Optimal stimulation patterns: FTI/FTIpP, random, trains, iterative and LCN methods
    /// (thesis ch. 6).
    Osp(cmd::osp::Args),
    /// End-to-end bench: sim-muscle, stim-driver, rt-core and the supervisor on vcan.
    Bench(cmd::bench::Args),
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Dataset(args) => cmd::dataset::run(args),
        Command::Identify(args) => cmd::identify::run(args),
        Command::Sweep(args) => cmd::sweep::run(args),
        Command::Compare(args) => cmd::compare::run(args),
        Command::Analyse(args) => cmd::analyse::run(args),
        Command::Modify(args) => cmd::modify::run(args),
        Command::Design(args) => cmd::design::run(args),
        Command::Osp(args) => cmd::osp::run(args),
        Command::LcnVariants(args) => cmd::lcn_variants::run(args),
        Command::Bench(args) => cmd::bench::run(args),
    };
    match result {
        Ok(()) => fes_rt::rt::exit::Exit::Done.into(),
        Err(e) => {
            // The format of anyhow's own `main` report: the error and its causes.
            eprintln!("Error: {e:?}");
            fes_rt::rt::exit::Exit::Failed.into()
        }
    }
}
