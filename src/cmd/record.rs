//! `leman record`.

/// Arguments of `leman record`.
#[derive(Debug, Default, clap::Args)]
pub struct Args {}

/// Runs `leman record`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("leman record is not built yet")
}
