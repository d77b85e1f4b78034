//! One module per subcommand: its clap `Args` and a `run` that calls the library and prints.

pub mod calibrate;
pub mod decode;
pub mod devices;
pub mod record;
pub mod replay;
pub mod run;
pub mod simulate;
