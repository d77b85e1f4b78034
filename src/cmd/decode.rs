//! `leman decode`.

/// Arguments of `leman decode`.
#[derive(Debug, Default, clap::Args)]
pub struct Args {}

/// Runs `leman decode`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("leman decode is not built yet")
}
