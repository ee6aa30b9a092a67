//! `supervisor compare` (being written).
/// Arguments.
#[derive(Debug, clap::Args)]
pub struct Args {}
/// Runs it.
pub fn run(_: Args) -> anyhow::Result<()> {
    anyhow::bail!("not yet")
}
