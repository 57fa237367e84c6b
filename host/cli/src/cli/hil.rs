//! `nusense hil`: the hardware-in-the-loop check suite against a board on a port, the QEMU firmware image, or
//! the virtual board.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use nusense_hil::emulator::QemuOptions;
use nusense_hil::{run_suite, CheckResult, HilOptions, HilTarget};

#[derive(clap::Args)]
#[command(group(clap::ArgGroup::new("target").required(true).args(["port", "emulated", "virtual_board"])))]
pub struct Args {
    /// Serial device of a real board (USB CDC-ACM, e.g. /dev/ttyACM0 or /dev/serial/by-id/...).
    #[arg(long, value_name = "PATH")]
    port: Option<String>,
    /// Camera looking at the pad (a /dev/video path or the camera's USB serial number); only with --port.
    #[arg(long, value_name = "DEV", requires = "port")]
    camera: Option<String>,
    /// Run against the QEMU firmware image (built if needed) with the simulated camera.
    #[arg(long)]
    emulated: bool,
    /// Run against the virtual board (the firmware core behind a pty) with the simulated camera.
    #[arg(long = "virtual")]
    virtual_board: bool,
    /// With --emulated: use this ELF instead of building firmware/images.
    #[arg(long, value_name = "ELF", requires = "emulated")]
    firmware_elf: Option<PathBuf>,
    /// With --emulated: use the image already built, do not run cargo.
    #[arg(long, requires = "emulated")]
    no_build: bool,
    /// The QEMU binary.
    #[arg(long, default_value = "qemu-system-arm", requires = "emulated")]
    qemu: PathBuf,
    /// LED setpoints for the ramp and brightness checks, in mA.
    #[arg(long, value_delimiter = ',', default_value = "25,50,75,100")]
    setpoints: Vec<u16>,
    /// Telemetry period for the rate and jitter check, in ms.
    #[arg(long, default_value_t = 10)]
    telemetry_period_ms: u16,
    /// Pings for the latency percentiles.
    #[arg(long)]
    pings: Option<usize>,
    /// p99 round-trip latency above which the latency check fails, in ms.
    #[arg(long, default_value_t = 50.0)]
    max_p99_latency_ms: f64,
    /// Shorter windows and fewer pings (same checks and limits).
    #[arg(long)]
    quick: bool,
    /// One JSON object with every check's numbers instead of text.
    #[arg(long)]
    json: bool,
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let mut options = if args.quick {
        HilOptions::quick()
    } else {
        HilOptions::default()
    };
    anyhow::ensure!(!args.setpoints.is_empty(), "--setpoints needs at least one current");
    anyhow::ensure!(
        args.setpoints.iter().all(|&s| s > 0),
        "--setpoints must be positive currents in mA"
    );
    options.setpoints_ma = args.setpoints;
    options.telemetry_period_ms = args.telemetry_period_ms;
    options.max_p99_latency_ms = args.max_p99_latency_ms;
    if let Some(pings) = args.pings {
        options.pings = pings.max(1);
    }

    let target = if let Some(path) = args.port {
        HilTarget::Port {
            path,
            camera: args.camera,
        }
    } else if args.emulated {
        HilTarget::Emulated {
            elf: args.firmware_elf,
            build: !args.no_build,
            qemu: QemuOptions {
                program: args.qemu,
                ..QemuOptions::default()
            },
        }
    } else {
        HilTarget::Virtual
    };
    if !args.json {
        eprintln!(
            "nusense hil: starting the target{}",
            if args.emulated {
                " (building the QEMU image if needed)"
            } else {
                ""
            }
        );
    }
    let mut running = target.start().context("cannot start the board under test")?;
    if !args.json {
        println!("target: {}", running.description);
        if let Some(camera) = &running.camera {
            println!("camera: {}", camera.describe());
        }
    }
    let json = args.json;
    let mut print = |result: &CheckResult| {
        if !json {
            println!("{:<4} {:<18} {}", result.verdict.label(), result.name, result.summary);
            let _ = std::io::stdout().flush();
        }
    };
    let report = run_suite(&mut running, &options, &mut print);
    drop(running);
    if json {
        println!("{}", serde_json::to_string(&report)?);
        eprintln!("{}", report.summary_line());
    } else {
        println!("{}", report.summary_line());
    }
    Ok(if report.all_passed() {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}
