//! `nusense sim`: render scenes and the paper's sweeps from the synthetic sensor, with ground truth.
//!
//! Every run writes a folder in the layout of `nusense_sim::dataset`: `reference.png` (the pad at rest under the
//! same sensor, LEDs and seed), `NAME.png` + `NAME.json` per frame, and `manifest.json`.
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Context;
use clap::{Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use nusense_sim::dataset;
use nusense_sim::sweep::{self, SweepFrame};
use nusense_sim::{Renderer, SceneFile, SensorOverrides};

#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render the frames of a scene file (TOML).
    Render {
        /// Scene file: [sensor] overrides, led_currents_ma, seed, and [[contacts]] or [[frames]].
        #[arg(long)]
        scene: PathBuf,
        /// Output folder (created if missing).
        #[arg(long)]
        out: PathBuf,
        /// Print a JSON summary instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Record a scripted session (MCAP, F/T log, ground truth) for `nusense report`.
    Session(super::report::SessionArgs),
    /// Render one of the paper's experiments.
    Sweep {
        #[arg(value_enum)]
        kind: SweepKind,
        /// Output folder (created if missing).
        #[arg(long)]
        out: PathBuf,
        #[command(flatten)]
        sensor: SensorArgs,
        /// Print a JSON summary instead of text.
        #[arg(long)]
        json: bool,
    },
}

#[derive(Clone, Copy, ValueEnum)]
enum SweepKind {
    /// 24 sphere presses at 6 N on a 6 x 4 grid, 6.4 mm x 7 mm apart.
    Positions,
    /// 0.5 to 8 N in 0.5 N steps at the centre, sphere then flat punch.
    Forces,
    /// An edge at 0, 15, ... 165 degrees through the centre at 8 N.
    Edges,
    /// All three.
    All,
}

#[derive(clap::Args)]
struct SensorArgs {
    #[arg(long, default_value_t = 640)]
    width: u32,
    /// Default: 3/4 of the width.
    #[arg(long)]
    height: Option<u32>,
    /// Encode and decode each frame as JPEG at this quality (1-100), like a webcam's MJPEG.
    #[arg(long)]
    jpeg_quality: Option<u8>,
    /// Per-pixel noise, 8-bit levels (default: the real sensor's).
    #[arg(long)]
    noise_sigma: Option<f32>,
    /// Current of all four LED sides, mA.
    #[arg(long, default_value_t = nusense_sim::NOMINAL_LED_CURRENT_MA)]
    led_ma: f32,
    /// Seed of the first frame; frame k uses seed + k + 1, the reference frame the seed itself.
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    match args.command {
        Command::Session(args) => super::report::simulate(args),
        Command::Render { scene, out, json } => {
            let file = SceneFile::load(&scene)?;
            let frames: Vec<SweepFrame> = file
                .scenes()
                .into_iter()
                .enumerate()
                .map(|(k, scene)| SweepFrame {
                    name: format!("frame_{k:04}"),
                    scene,
                })
                .collect();
            write_dataset(&file.sensor, file.led_currents_ma, file.seed, &frames, &out, json)
        }
        Command::Sweep {
            kind,
            out,
            sensor,
            json,
        } => {
            let frames = match kind {
                SweepKind::Positions => sweep::positions(),
                SweepKind::Forces => sweep::forces(),
                SweepKind::Edges => sweep::edges(),
                SweepKind::All => {
                    let mut all = sweep::positions();
                    all.extend(sweep::forces());
                    all.extend(sweep::edges());
                    all
                }
            };
            let overrides = SensorOverrides {
                width: Some(sensor.width),
                height: sensor.height,
                jpeg_quality: sensor.jpeg_quality,
                noise_sigma: sensor.noise_sigma,
                ..SensorOverrides::default()
            };
            write_dataset(&overrides, [sensor.led_ma; 4], sensor.seed, &frames, &out, json)
        }
    }
}

fn write_dataset(
    overrides: &SensorOverrides,
    led_currents_ma: [f32; 4],
    seed: u64,
    frames: &[SweepFrame],
    out: &Path,
    json: bool,
) -> anyhow::Result<ExitCode> {
    let start = Instant::now();
    let renderer = Renderer::new(overrides.sensor_model()).context("invalid sensor settings")?;
    let progress = if json {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(frames.len() as u64 + 1)
    };
    progress.set_style(
        ProgressStyle::with_template("{spinner} [{elapsed_precise}] {bar:40} {pos}/{len} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut started_any = false;
    let manifest = dataset::write_dataset(&renderer, led_currents_ma, seed, frames, out, &mut |name| {
        if started_any {
            progress.inc(1);
        }
        started_any = true;
        progress.set_message(name.to_owned());
    })
    .with_context(|| format!("writing the dataset to {}", out.display()))?;
    progress.finish_and_clear();

    let seconds = start.elapsed().as_secs_f64();
    if json {
        let summary = serde_json::json!({
            "out": out,
            "frames": frames.len(),
            "width": manifest.sensor.width,
            "height": manifest.sensor.height,
            "seconds": seconds,
        });
        println!("{summary}");
    } else {
        println!(
            "wrote {} frames + reference ({} x {}) to {} in {seconds:.1} s",
            frames.len(),
            manifest.sensor.width,
            manifest.sensor.height,
            out.display()
        );
    }
    Ok(ExitCode::SUCCESS)
}
