//! `supervisor bench` (being written).

/// Arguments of `supervisor bench`.
#[derive(Debug, clap::Args)]
pub struct Args {}

/// Runs the bench.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("supervisor bench: not assembled yet")
}
