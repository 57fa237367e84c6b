//! `nusense record OUT.mcap`: runs the pipeline headless and records frames, readings and board telemetry.
//! `nusense record --recover IN.mcap OUT.mcap`: rewrites a recording that was cut short with its summary.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use nusense_capture::SourceInfo;
use nusense_daemon::pipeline::{open_sources, Pipeline, PipelineHandle};
use nusense_daemon::record::{recover, RecorderOptions, SensorContext, DEFAULT_FLUSH_INTERVAL};

use super::common::{
    board_choice, board_serial_number, describe_start, frame_choice, init_logging, pipeline_options, source_config,
    SourceArgs,
};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// The recording to write (MCAP).
    #[arg(required_unless_present = "recover")]
    pub output: Option<PathBuf>,
    /// Rewrite IN, a recording cut short (killed recorder, power loss, full disk), as OUT: every message up to
    /// its last whole chunk, with the summary and indexes that seeking readers (Foxglove) need. OUT must not exist.
    #[arg(long, num_args = 2, value_names = ["IN", "OUT"], conflicts_with = "output")]
    pub recover: Option<Vec<PathBuf>>,
    #[command(flatten)]
    pub source: SourceArgs,
    /// Stop after this many seconds (default: until Ctrl-C, or until a replay ends).
    #[arg(long, value_name = "SECONDS")]
    pub duration: Option<f64>,
    /// Stop once this many frames have been measured (each recorded with its reading).
    #[arg(long, value_name = "N")]
    pub frames: Option<u64>,
    /// Longest time a chunk stays open before it is written and fsynced: what a crash or power cut loses at most.
    #[arg(long, value_name = "MS", default_value_t = DEFAULT_FLUSH_INTERVAL.as_millis() as u64)]
    pub flush_ms: u64,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    init_logging();
    if let Some(paths) = &args.recover {
        return run_recover(&paths[0], &paths[1], args.json);
    }
    let Some(output) = args.output.clone() else {
        anyhow::bail!("name the recording to write, or give --recover IN OUT");
    };
    if output.extension().and_then(|e| e.to_str()) != Some("mcap") {
        anyhow::bail!("the recording's file name must end in .mcap (got {})", output.display());
    }
    let frames = frame_choice(&args.source);
    let config = source_config(args.source.config.as_ref(), &frames)?;
    let board = board_choice(&args.source, &frames);
    eprintln!(
        "{}",
        describe_start(&frames, &board).replacen("nusense serve", "nusense record", 1)
    );
    let sources = open_sources(&frames, &board).context("opening the frame source and LED board")?;
    let mut identity = source_identity(&sources.frames.info(), &args.source);
    let pipeline = Pipeline::start(
        sources.frames,
        sources.board,
        pipeline_options(&args.source, config.clone()),
    )?;
    let handle = pipeline.handle();
    // The board names the sensor (as on Zenoh and ROS 2), so a recording says which sensor made it. A board that
    // does not connect in time does not stop the recording: its file then says nothing of the board.
    match board_serial_number(handle.board().as_ref()) {
        Ok(Some(serial)) => {
            identity.insert("board_serial".to_string(), serial);
        }
        Ok(None) => {}
        Err(error) => eprintln!("nusense record: recording without the board's serial number: {error:#}"),
    }
    let sensor = SensorContext { config, identity };
    let options = RecorderOptions {
        flush_interval: Duration::from_millis(args.flush_ms.max(10)),
        sensor: Some(sensor),
        ..Default::default()
    };
    handle
        .start_recording(&output, options)
        .with_context(|| format!("creating {}", output.display()))?;
    eprintln!("nusense record: writing {} (stop with Ctrl-C)", output.display());

    let interrupted = ctrl_c_flag()?;
    let started = Instant::now();
    wait_until_done(&handle, &args, started, &interrupted);
    let summary = handle
        .stop_recording()
        .with_context(|| format!("recording {}", output.display()))?;
    drop(pipeline);
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!(
            "recorded {}: {} frames, {} readings, {} telemetry messages ({} dropped) in {:.1} s",
            summary.path,
            summary.frames,
            summary.readings,
            summary.telemetry,
            summary.dropped,
            started.elapsed().as_secs_f64()
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// What the recording says of its frame source, in its sensor metadata.
fn source_identity(source: &SourceInfo, args: &SourceArgs) -> BTreeMap<String, String> {
    BTreeMap::from([
        ("source_kind".to_string(), source.kind.to_string()),
        ("source".to_string(), source.name.clone()),
        ("width".to_string(), source.width.to_string()),
        ("height".to_string(), source.height.to_string()),
        ("fps".to_string(), source.fps.to_string()),
        ("mode".to_string(), args.mode.to_string()),
    ])
}

/// Set once Ctrl-C (SIGINT) arrives; the recording then stops cleanly.
fn ctrl_c_flag() -> anyhow::Result<Arc<AtomicBool>> {
    let interrupted = Arc::new(AtomicBool::new(false));
    let flag = interrupted.clone();
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
    std::thread::spawn(move || {
        runtime.block_on(async {
            let _ = tokio::signal::ctrl_c().await;
        });
        flag.store(true, Ordering::Relaxed);
    });
    Ok(interrupted)
}

/// Returns once the recording is to stop: interrupted, enough frames or time, the source ended, or the recording
/// failed.
fn wait_until_done(handle: &PipelineHandle, args: &Args, started: Instant, interrupted: &AtomicBool) {
    let deadline = args
        .duration
        .filter(|d| d.is_finite() && *d > 0.0)
        .map(Duration::from_secs_f64);
    loop {
        std::thread::sleep(Duration::from_millis(20));
        let status = handle.status();
        // Counted in measured frames, not captured ones: the estimator's first frame (building the rest frame's
        // model) can take longer than a burst of captures, and a recording of frames without their readings
        // would be cut short of what was asked.
        let done_frames = args.frames.is_some_and(|n| status.frames_processed >= n);
        let done_time = deadline.is_some_and(|d| started.elapsed() >= d);
        let source_ended = status.capture_finished
            && status.frames_processed >= status.frames_captured.saturating_sub(status.frames_dropped);
        let failed = status.recording.as_ref().is_some_and(|r| r.failure.is_some());
        if interrupted.load(Ordering::Relaxed) || done_frames || done_time || source_ended || failed {
            return;
        }
    }
}

fn run_recover(input: &Path, output: &Path, json: bool) -> anyhow::Result<ExitCode> {
    let summary = recover(input, output).with_context(|| format!("recovering {}", input.display()))?;
    if json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        let cut = match &summary.stopped_by {
            Some(reason) => format!("; the input stopped early: {reason}"),
            None => String::new(),
        };
        println!(
            "recovered {} -> {}: {} messages on {} channels, {} metadata records{cut}",
            summary.input, summary.output, summary.messages, summary.channels, summary.metadata
        );
    }
    Ok(ExitCode::SUCCESS)
}
