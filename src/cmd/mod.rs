//! One module per subcommand: its clap `Args` and a `run` that calls the library and prints.

pub mod calibrate;
pub mod decode;
pub mod devices;
pub mod record;
pub mod replay;
pub mod run;
pub mod simulate;

/// Refuses an existing output file `path` (given by `flag`) unless `overwrite`: a repeated
/// command must not replace an earlier recording.
pub(crate) fn refuse_existing(
    flag: &str,
    path: &std::path::Path,
    overwrite: bool,
) -> anyhow::Result<()> {
    use anyhow::Context as _;
    let exists = path
        .try_exists()
        .with_context(|| format!("cannot tell whether {flag} {} exists", path.display()))?;
    if exists && !overwrite {
        anyhow::bail!(
            "{flag} {} already exists: name a new file, or add --overwrite to replace it",
            path.display()
        );
    }
    Ok(())
}
