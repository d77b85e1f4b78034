//! `leman replay`.

/// Arguments of `leman replay`.
#[derive(Debug, Default, clap::Args)]
pub struct Args {}

/// Runs `leman replay`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("leman replay is not built yet")
}
