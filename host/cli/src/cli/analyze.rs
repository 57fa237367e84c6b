//! `nusense analyze --reference REF FRAME... [--config FILE] [--mode inverse|fast|paper] [--json]`
//!
//! Measures every frame against the reference frame. With `--json`, one JSON object per frame per line (fields
//! below); a frame that cannot be read or measured gets `ok: false` and its `error`, and the others still run.
//! Exit code: 0 when every frame was measured, 2 when some frame failed, 1 when nothing could run (config or
//! reference unusable).

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use nusense_capture::read_image_file;
use nusense_estimator::{CameraMotion, ContactRegion, ContactTest, Estimator, Mode, Reading, ReadingJson};

use super::common::load_config;
use serde::Serialize;

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
    /// Estimator variant: inverse (the traction inverse: force vector, every contact), fast or paper (the paper's
    /// gamma line).
    #[arg(long, default_value_t = Mode::default())]
    mode: Mode,
    /// One JSON object per frame per line.
    #[arg(long)]
    json: bool,
}

/// One output line. Field names are an interface other tools rely on.
#[derive(Serialize)]
struct FrameReport {
    frame: String,
    ok: bool,
    error: Option<String>,
    mode: Mode,
    contact: Option<bool>,
    contact_px: Option<[f64; 2]>,
    contact_undistorted_px: Option<[f64; 2]>,
    contact_mm: Option<[f64; 2]>,
    gamma: Option<f64>,
    force_n: Option<f64>,
    force_model_n: Option<f64>,
    edge_angle_deg: Option<f64>,
    edge_confidence: Option<f64>,
    points_detected: Option<usize>,
    points_expected: Option<usize>,
    points_valid: Option<usize>,
    squares_detected: Option<usize>,
    squares_expected: Option<usize>,
    samples_used: Option<usize>,
    samples_total: Option<usize>,
    elapsed_ms: Option<f64>,
    gamma_uncompensated: Option<f64>,
    force_vector_n: Option<[f64; 3]>,
    torque_nmm: Option<f64>,
    contacts: Option<Vec<ContactRegion>>,
    camera_motion: Option<CameraMotion>,
    contact_test: Option<ContactTest>,
}

impl FrameReport {
    fn failed(frame: &Path, mode: Mode, error: String) -> Self {
        Self {
            frame: frame.display().to_string(),
            ok: false,
            error: Some(error),
            mode,
            contact: None,
            contact_px: None,
            contact_undistorted_px: None,
            contact_mm: None,
            gamma: None,
            force_n: None,
            force_model_n: None,
            edge_angle_deg: None,
            edge_confidence: None,
            points_detected: None,
            points_expected: None,
            points_valid: None,
            squares_detected: None,
            squares_expected: None,
            samples_used: None,
            samples_total: None,
            elapsed_ms: None,
            gamma_uncompensated: None,
            force_vector_n: None,
            torque_nmm: None,
            contacts: None,
            camera_motion: None,
            contact_test: None,
        }
    }

    fn measured(frame: &Path, mode: Mode, r: &Reading) -> Self {
        let r = ReadingJson::from(r.clone());
        Self {
            frame: frame.display().to_string(),
            ok: true,
            error: None,
            mode,
            contact: Some(r.contact),
            contact_px: r.contact_px,
            contact_undistorted_px: r.contact_undistorted_px,
            contact_mm: r.contact_mm,
            gamma: Some(r.gamma),
            force_n: Some(r.force_n),
            force_model_n: Some(r.force_model_n),
            edge_angle_deg: r.edge_angle_deg,
            edge_confidence: Some(r.edge_confidence),
            points_detected: Some(r.points_detected),
            points_expected: Some(r.points_expected),
            points_valid: Some(r.points_valid),
            squares_detected: Some(r.squares_detected),
            squares_expected: Some(r.squares_expected),
            samples_used: Some(r.samples_used),
            samples_total: Some(r.samples_total),
            elapsed_ms: Some(r.elapsed_ms),
            gamma_uncompensated: Some(r.gamma_uncompensated),
            force_vector_n: r.force_vector_n,
            torque_nmm: r.torque_nmm,
            contacts: Some(r.contacts),
            camera_motion: Some(r.camera_motion),
            contact_test: Some(r.contact_test),
        }
    }

    fn human(&self) -> String {
        if let Some(error) = &self.error {
            return format!("{}: FAILED: {error}", self.frame);
        }
        let point = |p: Option<[f64; 2]>, unit: &str| match p {
            Some([x, y]) => format!("({x:.1}, {y:.1}) {unit}"),
            None => "-".to_string(),
        };
        format!(
            "{}: contact {} at {} / {} / {}; gamma {:.4}, force {:.2} N (line {:.2} N); edge {} (confidence {:.2}); \
             corners {}/{} ({} valid), squares {}/{}, samples {}/{}; {:.2} ms",
            self.frame,
            if self.contact == Some(true) { "yes" } else { "no" },
            point(self.contact_px, "raw px"),
            point(self.contact_undistorted_px, "undistorted px"),
            point(self.contact_mm, "mm"),
            self.gamma.unwrap_or(0.0),
            self.force_n.unwrap_or(0.0),
            self.force_model_n.unwrap_or(0.0),
            self.edge_angle_deg
                .map(|a| format!("{a:.1} deg"))
                .unwrap_or_else(|| "none".into()),
            self.edge_confidence.unwrap_or(0.0),
            self.points_detected.unwrap_or(0),
            self.points_expected.unwrap_or(0),
            self.points_valid.unwrap_or(0),
            self.squares_detected.unwrap_or(0),
            self.squares_expected.unwrap_or(0),
            self.samples_used.unwrap_or(0),
            self.samples_total.unwrap_or(0),
            self.elapsed_ms.unwrap_or(0.0),
        )
    }
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let config = load_config(args.config.as_ref())?;
    let mode = args.mode;
    let reference = read_image_file(&args.reference).context("reference frame")?.image;
    let mut estimator = Estimator::new(config, mode, &reference)
        .with_context(|| format!("reference frame {}", args.reference.display()))?;
    let mut all_ok = true;
    for frame in &args.frames {
        let report = match read_image_file(frame) {
            Err(error) => FrameReport::failed(frame, mode, error.to_string()),
            Ok(captured) => match estimator.estimate(&captured.image) {
                Ok(reading) => FrameReport::measured(frame, mode, &reading),
                Err(error) => FrameReport::failed(frame, mode, error.to_string()),
            },
        };
        all_ok &= report.ok;
        if args.json {
            println!(
                "{}",
                serde_json::to_string(&report).context("cannot serialise a report")?
            );
        } else {
            println!("{}", report.human());
        }
    }
    Ok(if all_ok { ExitCode::SUCCESS } else { ExitCode::from(2) })
}
