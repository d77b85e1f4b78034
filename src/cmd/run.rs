//! `leman run`.

/// Arguments of `leman run`.
#[derive(Debug, Default, clap::Args)]
pub struct Args {}

/// Runs `leman run`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("leman run is not built yet")
}
