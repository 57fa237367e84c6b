//! `nusense record OUT.mcap`: runs the pipeline headless and records frames, readings and board telemetry.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use nusense_daemon::pipeline::{open_sources, Pipeline, PipelineOptions};
use nusense_daemon::record::RecorderOptions;

use super::common::{board_choice, describe_start, frame_choice, init_logging, load_config, SourceArgs};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// The recording to write (MCAP).
    pub output: PathBuf,
    #[command(flatten)]
    pub source: SourceArgs,
    /// Stop after this many seconds (default: until Ctrl-C, or until a replay ends).
    #[arg(long, value_name = "SECONDS")]
    pub duration: Option<f64>,
    /// Stop after this many frames have been captured.
    #[arg(long, value_name = "N")]
    pub frames: Option<u64>,
    /// Longest time a chunk stays open: what a crash can lose at most.
    #[arg(long, value_name = "MS", default_value_t = 500)]
    pub flush_ms: u64,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    init_logging();
    if args.output.extension().and_then(|e| e.to_str()) != Some("mcap") {
        anyhow::bail!(
            "the recording's file name must end in .mcap (got {})",
            args.output.display()
        );
    }
    let config = load_config(args.source.config.as_ref())?;
    let frames = frame_choice(&args.source);
    let board = board_choice(&args.source, &frames);
    eprintln!(
        "{}",
        describe_start(&frames, &board).replacen("nusense serve", "nusense record", 1)
    );
    let sources = open_sources(&frames, &board).context("opening the frame source and LED board")?;
    let pipeline = Pipeline::start(
        sources.frames,
        sources.board,
        PipelineOptions::new(config, args.source.mode),
    )?;
    let handle = pipeline.handle();
    let options = RecorderOptions {
        flush_interval: Duration::from_millis(args.flush_ms.max(10)),
        ..Default::default()
    };
    handle
        .start_recording(&args.output, options)
        .with_context(|| format!("creating {}", args.output.display()))?;
    eprintln!("nusense record: writing {} (stop with Ctrl-C)", args.output.display());

    let interrupted = Arc::new(AtomicBool::new(false));
    let flag = interrupted.clone();
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
    let _signal = std::thread::spawn(move || {
        runtime.block_on(async {
            let _ = tokio::signal::ctrl_c().await;
        });
        flag.store(true, Ordering::Relaxed);
    });
    let started = Instant::now();
    let deadline = args
        .duration
        .filter(|d| d.is_finite() && *d > 0.0)
        .map(Duration::from_secs_f64);
    loop {
        std::thread::sleep(Duration::from_millis(20));
        let status = handle.status();
        let done_frames = args.frames.is_some_and(|n| status.frames_captured >= n);
        let done_time = deadline.is_some_and(|d| started.elapsed() >= d);
        let source_ended = status.capture_finished
            && status.frames_processed >= status.frames_captured.saturating_sub(status.frames_dropped);
        if interrupted.load(Ordering::Relaxed) || done_frames || done_time || source_ended {
            break;
        }
    }
    let summary = handle.stop_recording()?;
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
