//! One module per subcommand: its clap `Args` and a `run` that returns the process exit code.
//! These are the binary's edge: they turn library errors into `anyhow` with context.

pub mod analyze;
pub mod bench;
pub mod bootloader;
pub mod calibrate;
mod common;
pub mod devices;
pub mod hil;
pub mod info;
pub mod led;
mod pairing;
pub mod record;
pub mod replay;
pub mod report;
pub mod serve;
pub mod sim;
