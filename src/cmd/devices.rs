//! `leman devices`: lists serial ports and HID devices, marking supported 3D mice.

use leman::devices::enumerate::{format_text, list_devices};

/// Arguments of `leman devices`.
#[derive(Debug, Default, clap::Args)]
pub struct Args {
    /// Print one JSON object: {"serial": [...], "serial_error", "hid": [...], "hid_error",
    /// "notes": [...]} (see README).
    #[arg(long)]
    pub json: bool,
}

/// Runs `leman devices`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let list = list_devices();
    if args.json {
        println!("{}", serde_json::to_string_pretty(&list)?);
    } else {
        print!("{}", format_text(&list));
    }
    Ok(())
}
