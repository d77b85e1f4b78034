//! `leman devices`.

/// Arguments of `leman devices`.
#[derive(Debug, Default, clap::Args)]
pub struct Args {}

/// Runs `leman devices`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("leman devices is not built yet")
}
