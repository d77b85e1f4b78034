//! `leman calibrate`.

/// Arguments of `leman calibrate`.
#[derive(Debug, Default, clap::Args)]
pub struct Args {}

/// Runs `leman calibrate`.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("leman calibrate is not built yet")
}
