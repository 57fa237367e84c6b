//! `nusense replay IN.mcap|DIR`: runs recorded frames (or a folder of images) through the estimator, as fast
//! as it goes; the first frame is the rest frame. Prints a table, or with --json one reading message per line
//! (`nusense_daemon::ReadingMessage`, as the daemon and `analyze --json` write them).

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Context;
use nusense_capture::{unix_time_us, CaptureError, Frame, FrameSource, ImageFolder};
use nusense_daemon::record::McapReplay;
use nusense_daemon::{ReadingMessage, SCHEMA_VERSION};
use nusense_estimator::{Estimator, Mode, Reading};

use super::common::{load_config, EXIT_SOME_FRAMES_FAILED};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// An MCAP recording (from `nusense record` or the API) or a folder of PNG/JPEG frames.
    pub input: PathBuf,
    /// Sensor configuration (TOML).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Estimator variant: inverse (the traction inverse), fast or paper (the paper's gamma line).
    #[arg(long, default_value_t = Mode::default())]
    pub mode: Mode,
    /// One JSON object per frame instead of a table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let config = load_config(args.config.as_ref())?;
    let mut source = open_frames(&args.input)?;
    let mut estimator: Option<Estimator> = None;
    let mut frames = 0usize;
    let mut failures = 0usize;
    let started = Instant::now();
    if !args.json {
        println!(
            "{:>6} {:>8} {:>9} {:>10} {:>16} {:>8} {:>9}",
            "frame", "contact", "force N", "gamma", "contact mm", "edge °", "points"
        );
    }
    loop {
        let frame = match source.next_frame() {
            Ok(frame) => frame,
            Err(CaptureError::EndOfStream) => break,
            Err(error) => return Err(error).context("reading frames"),
        };
        let index = frames;
        frames += 1;
        // A frame that does not decode (a truncated JPEG) is a failed frame, not the end of the replay.
        let image = frame.to_rgb().map_err(|source| CaptureError::Decode {
            origin: format!("frame {index} of {}", args.input.display()),
            source,
        });
        if estimator.is_none() {
            let rest = image.as_ref().map_err(|error| anyhow::anyhow!("{error}"));
            estimator = Some(
                Estimator::new(config.clone(), args.mode, rest?)
                    .with_context(|| format!("frame {index} cannot be the rest frame"))?,
            );
        }
        let Some(estimator) = estimator.as_mut() else {
            continue;
        };
        let result = image
            .map_err(|error| error.to_string())
            .and_then(|image| estimator.estimate(&image).map_err(|error| error.to_string()));
        failures += usize::from(result.is_err());
        if args.json {
            let message = reading_message(index, &frame, result);
            println!(
                "{}",
                serde_json::to_string(&message).context("cannot write a reading as JSON")?
            );
        } else {
            println!("{}", table_row(index, &result));
        }
    }
    if frames == 0 {
        anyhow::bail!("{} holds no frames", args.input.display());
    }
    eprintln!(
        "nusense replay: {frames} frames ({failures} without an estimate) in {:.2} s",
        started.elapsed().as_secs_f64()
    );
    Ok(if failures == 0 {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(EXIT_SOME_FRAMES_FAILED)
    })
}

/// The frames of a folder of images or of an MCAP recording, as fast as they can be read.
fn open_frames(input: &Path) -> anyhow::Result<Box<dyn FrameSource>> {
    if input.is_dir() {
        return Ok(Box::new(ImageFolder::open(input, f64::INFINITY, false)?.unpaced()));
    }
    let replay = McapReplay::open(input, false)?.unpaced();
    if replay.truncated {
        eprintln!(
            "nusense replay: {} was cut short (its recorder was killed); replaying what survived",
            input.display()
        );
    }
    Ok(Box::new(replay))
}

/// The frame's reading as the daemon publishes it; the rest frame is frame 0.
fn reading_message(index: usize, frame: &Frame, result: Result<Reading, String>) -> ReadingMessage {
    let (estimate, error) = match result {
        Ok(reading) => (Some(reading), None),
        Err(error) => (None, Some(error)),
    };
    ReadingMessage {
        schema_version: SCHEMA_VERSION,
        frame_id: index as u64,
        file: None,
        capture_time_us: frame.capture_time_us,
        processed_time_us: unix_time_us(),
        latency_ms: frame.captured_at.elapsed().as_secs_f64() * 1e3,
        queue_ms: 0.0,
        reference_frame_id: Some(0),
        estimate,
        error,
        led: None,
    }
}

/// The frame's line of the table (see the header in [`run`]).
fn table_row(index: usize, result: &Result<Reading, String>) -> String {
    match result {
        Ok(r) => format!(
            "{:>6} {:>8} {:>9.3} {:>10.5} {:>16} {:>8} {:>4}/{:<4}",
            index,
            if r.is_contact() { "yes" } else { "no" },
            r.force_n(),
            r.gamma.gamma,
            r.contact_mm()
                .map(|c| format!("{:.1}, {:.1}", c[0], c[1]))
                .unwrap_or_else(|| "-".into()),
            r.edge_angle_deg()
                .map(|a| format!("{a:.1}"))
                .unwrap_or_else(|| "-".into()),
            r.counts.points_detected,
            r.counts.points_expected
        ),
        Err(error) => format!("{index:>6} error: {error}"),
    }
}
