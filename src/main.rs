//! The `leman` command line: parses arguments and calls the library. One file per subcommand in
//! `src/cmd/`.

mod cmd;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// leman: build and animate elastically deformable layered characters in head-tracked stereo.
#[derive(Debug, Parser)]
#[command(
    name = "leman",
    version,
    about,
    long_about = None,
    args_conflicts_with_subcommands = true
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    /// With no subcommand, `leman [OPTIONS]` is `leman run [OPTIONS]`.
    #[command(flatten)]
    run: cmd::run::Args,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Open the workstation on the default character (the default when no command is given).
    Run(cmd::run::Args),
    /// List serial ports and HID devices, marking supported trackers and 3D mice.
    Devices(cmd::devices::Args),
    /// Record live devices into a session file until Ctrl-C.
    Record(cmd::record::Args),
    /// Decode a raw byte capture or a session with one protocol.
    Decode(cmd::decode::Args),
    /// Replay a recorded session through the whole app, in a window or headless.
    Replay(cmd::replay::Args),
    /// Screen calibration: touch the corners, fit from recorded corners, or check a profile.
    Calibrate(cmd::calibrate::Args),
    /// Run a character's simulation headless and print a Table-1 style report.
    Simulate(cmd::simulate::Args),
}

/// Runs the command; an error is printed as its message and its causes, one per line, with
/// exit status 1 (130 for a simulation stopped by Ctrl-C, the status a shell gives SIGINT).
/// (Returning the error from `main` would print its `Debug` form, which adds a stack trace
/// whenever `RUST_BACKTRACE` is set: noise under a message meant for the user.)
fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("Error: {err}");
            let causes = untold_causes(&err);
            if !causes.is_empty() {
                eprintln!("\nCaused by:");
                for (i, cause) in causes.iter().enumerate() {
                    eprintln!("    {i}: {cause}");
                }
            }
            if err.is::<cmd::simulate::Interrupted>() {
                ExitCode::from(130)
            } else {
                ExitCode::FAILURE
            }
        }
    }
}

/// The causes of `err` that its message does not already tell, outermost first.
///
/// Some of the library's errors name their cause in their own message (`cannot read character
/// file F: Is a directory`), so that a user interface showing only the message shows why, and
/// also return it as their source. Printing every link of the chain would then say the cause
/// twice; a cause whose text ends the message printed just before it is left out.
fn untold_causes(err: &anyhow::Error) -> Vec<String> {
    let mut told = err.to_string();
    let mut causes = Vec::new();
    for cause in err.chain().skip(1) {
        let text = cause.to_string();
        if !told.ends_with(&text) {
            causes.push(text.clone());
        }
        told = text;
    }
    causes
}

fn run() -> anyhow::Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .init();
    let cli = Cli::parse();
    match cli.command.unwrap_or(Command::Run(cli.run)) {
        Command::Run(args) => cmd::run::run(args),
        Command::Devices(args) => cmd::devices::run(args),
        Command::Record(args) => cmd::record::run(args),
        Command::Decode(args) => cmd::decode::run(args),
        Command::Replay(args) => cmd::replay::run(args),
        Command::Calibrate(args) => cmd::calibrate::run(args),
        Command::Simulate(args) => cmd::simulate::run(args),
    }
}
