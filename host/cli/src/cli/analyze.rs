//! `nusense analyze --reference REF FRAME... [--config FILE] [--mode inverse|fast|paper] [--json]`
//!
//! Measures every frame against the reference frame. With `--json`, one reading message per frame per line: the
//! same `nusense_daemon::ReadingMessage` the daemon's API, stream and recordings carry (schema at
//! `/api/v1/schema`, committed in host/daemon/schema/reading.schema.json), with `frame_id` the frame's place on
//! the command line and `file` its path. A frame that cannot be read or measured has no `estimate` and says why
//! in `error`; the others still run.
//! Exit code: 0 when every frame was measured, 2 when some frame failed, 1 when nothing could run (config or
//! reference unusable).

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Context;
use nusense_capture::{read_image_rgb, unix_time_us};
use nusense_daemon::{ReadingMessage, SCHEMA_VERSION};
use nusense_estimator::{Estimator, Mode, Reading};

use super::common::{load_config, EXIT_SOME_FRAMES_FAILED};

#[derive(clap::Args)]
pub struct Args {
    /// The rest frame (no contact) every frame is measured against.
    #[arg(long, value_name = "REF")]
    reference: PathBuf,
    /// Frames to measure, in order (the fast mode tracks the lattice from one to the next).
    #[arg(value_name = "FRAME", required = true)]
    frames: Vec<PathBuf>,
    /// Sensor config (TOML); every value defaults to the real sensor.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Estimator variant: inverse (the traction inverse), fast or paper (the paper's gamma line).
    #[arg(long, default_value_t = Mode::default())]
    mode: Mode,
    /// One JSON object per frame per line.
    #[arg(long)]
    json: bool,
}

/// Measures one frame file; the message says why when it could not.
fn measure(estimator: &mut Estimator, frame_id: u64, path: &Path) -> ReadingMessage {
    let started = Instant::now();
    let capture_time_us = unix_time_us();
    let (estimate, error) = match read_image_rgb(path) {
        Err(error) => (None, Some(error.to_string())),
        Ok(image) => match estimator.estimate(&image) {
            Ok(reading) => (Some(reading), None),
            Err(error) => (None, Some(error.to_string())),
        },
    };
    ReadingMessage {
        schema_version: SCHEMA_VERSION,
        frame_id,
        file: Some(path.display().to_string()),
        capture_time_us,
        processed_time_us: unix_time_us(),
        latency_ms: started.elapsed().as_secs_f64() * 1e3,
        queue_ms: 0.0,
        reference_frame_id: None,
        estimate,
        error,
        led: None,
    }
}

fn human(message: &ReadingMessage) -> String {
    let frame = message.file.as_deref().unwrap_or("?");
    let r: &Reading = match (&message.estimate, &message.error) {
        (Some(reading), _) => reading,
        (None, error) => return format!("{frame}: FAILED: {}", error.as_deref().unwrap_or("no estimate")),
    };
    // The flat view of the reading: the same fields `--json` prints.
    let r = nusense_estimator::ReadingJson::from(r.clone());
    let point = |p: Option<[f64; 2]>, unit: &str| match p {
        Some([x, y]) => format!("({x:.1}, {y:.1}) {unit}"),
        None => "-".to_string(),
    };
    format!(
        "{frame}: contact {} at {} / {} / {}; gamma {:.4}, force {:.2} N (line {:.2} N); edge {} (confidence {:.2}); \
         corners {}/{} ({} valid), squares {}/{}, samples {}/{}; {:.2} ms",
        if r.contact { "yes" } else { "no" },
        point(r.contact_px, "raw px"),
        point(r.contact_undistorted_px, "undistorted px"),
        point(r.contact_mm, "mm"),
        r.gamma,
        r.force_n,
        r.force_model_n,
        r.edge_angle_deg
            .map(|a| format!("{a:.1} deg"))
            .unwrap_or_else(|| "none".into()),
        r.edge_confidence,
        r.points_detected,
        r.points_expected,
        r.points_valid,
        r.squares_detected,
        r.squares_expected,
        r.samples_used,
        r.samples_total,
        r.elapsed_ms,
    )
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let config = load_config(args.config.as_ref())?;
    let mode = args.mode;
    let reference = read_image_rgb(&args.reference).context("reference frame")?;
    let mut estimator = Estimator::new(config, mode, &reference)
        .with_context(|| format!("reference frame {}", args.reference.display()))?;
    let mut all_ok = true;
    for (frame_id, frame) in (0u64..).zip(&args.frames) {
        let message = measure(&mut estimator, frame_id, frame);
        all_ok &= message.estimate.is_some();
        if args.json {
            println!(
                "{}",
                serde_json::to_string(&message).context("cannot write a reading as JSON")?
            );
        } else {
            println!("{}", human(&message));
        }
    }
    Ok(if all_ok {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(EXIT_SOME_FRAMES_FAILED)
    })
}
