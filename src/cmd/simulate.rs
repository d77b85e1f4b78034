//! `leman simulate`.

/// Arguments of `leman simulate`.
#[derive(Debug, Default, clap::Args)]
pub struct Args {}

/// Runs `leman simulate`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("leman simulate is not built yet")
}
