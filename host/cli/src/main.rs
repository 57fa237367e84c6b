//! The `nusense` command. Each subcommand lives in its own module under `cli/`; this file only parses and
//! dispatches, and is the one place where errors become exit codes.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod cli;

#[derive(Parser)]
#[command(
    name = "nusense",
    version,
    about = "NUSense optical tactile sensor: board, camera, estimator, daemon"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the daemon: device link, capture, live estimation, HTTP/WebSocket API and dashboard.
    Serve(cli::serve::Args),
    /// List attached boards and cameras.
    Devices(cli::devices::Args),
    /// Show a board's identity and status.
    Info(cli::info::Args),
    /// Set LED currents on a board.
    Led(cli::led::Args),
    /// Restart a board into its DFU bootloader for flashing without a debug probe.
    Bootloader(cli::bootloader::Args),
    /// Record frames, readings and telemetry to an MCAP file.
    Record(cli::record::Args),
    /// Replay a recording (or a folder of frames) through the estimator.
    Replay(cli::replay::Args),
    /// Estimate shear, force, contact and edge for frames against a reference frame.
    Analyze(cli::analyze::Args),
    /// Fit the force calibration (F = a * gamma + b) and write it to the sensor config.
    Calibrate(cli::calibrate::Args),
    /// The paper's experiments from a recording: calibration, hysteresis, repeatability, localisation, damage.
    Report(cli::report::Args),
    /// The synthetic sensor: render scenes and sweeps with ground truth.
    Sim(cli::sim::Args),
    /// Measure every estimator variant's speed against its error.
    Bench(cli::bench::Args),
    /// Hardware-in-the-loop checks against a board (or the emulated firmware).
    Hil(cli::hil::Args),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Serve(args) => cli::serve::run(args),
        Command::Devices(args) => cli::devices::run(args),
        Command::Info(args) => cli::info::run(args),
        Command::Led(args) => cli::led::run(args),
        Command::Bootloader(args) => cli::bootloader::run(args),
        Command::Record(args) => cli::record::run(args),
        Command::Replay(args) => cli::replay::run(args),
        Command::Analyze(args) => cli::analyze::run(args),
        Command::Calibrate(args) => cli::calibrate::run(args),
        Command::Report(args) => cli::report::run(args),
        Command::Sim(args) => cli::sim::run(args),
        Command::Bench(args) => cli::bench::run(args),
        Command::Hil(args) => cli::hil::run(args),
    };
    match result {
        Ok(code) => code,
        Err(error) => {
            eprintln!("nusense: {error:#}");
            ExitCode::FAILURE
        }
    }
}
