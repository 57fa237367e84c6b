//! Resident memory of `nusense serve` (the real binary) over a long run at 2048x1536 with recording on, a
//! WebSocket client reading every reading and a dashboard-like client fetching frames: the daemon must stay under
//! 200 MB. Prints a table (one row a minute), the peak and median, and PASS or FAIL.
//!
//!     cargo bench -p nusense --bench serve_memory             (10 minutes)
//!     cargo bench -p nusense --bench serve_memory -- --minutes 3 --replay DIR   (your own folder of JPEG frames)
//!     cargo bench -p nusense --bench serve_memory -- --live-sim                 (`serve --sim` itself)
//!
//! By default the frames are the simulator's demo animation, rendered once at 2048x1536 before the daemon starts
//! and served by `serve --replay DIR --loop` as JPEG files: the daemon then does what it does with an MJPEG camera
//! (decode each frame, estimate, record the camera's own JPEG) and nothing else. `--live-sim` runs the simulator
//! inside the daemon instead; its renderer keeps per-pixel maps of the lens and lighting (40 bytes a pixel, 126 MB
//! at 2048x1536) that no camera-fed daemon has, so that run measures the simulator as much as the daemon.
//!
//! The frames and the recording go to temporary folders that are removed afterwards.

#[path = "../tests/serve/daemon.rs"]
mod daemon;

use std::time::{Duration, Instant};

use daemon::{pipeline_counters, render_folder, Daemon, Options};
use futures_util::StreamExt;
use serde_json::json;

const LIMIT_MB: f64 = 200.0;
const WIDTH: u32 = 2048;
const HEIGHT: u32 = 1536;
const FPS: f64 = 15.0;
/// Frames of the demo animation rendered for the default run: one every half second of its 20 s loop (rest,
/// press, hold, slide, release, an edge at four angles).
const DEMO_FRAMES: usize = 40;

/// Resident set size of a process, MB (VmRSS of /proc/PID/status).
fn rss_mb(pid: u32) -> Option<f64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let kb: f64 = status
        .lines()
        .find_map(|line| line.strip_prefix("VmRSS:"))?
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    Some(kb / 1024.0)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let value_of = |flag: &str| {
        args.iter()
            .position(|a| a == flag)
            .and_then(|i| args.get(i + 1))
            .cloned()
    };
    let minutes: f64 = value_of("--minutes").and_then(|m| m.parse().ok()).unwrap_or(10.0);
    let live_sim = args.iter().any(|a| a == "--live-sim");
    let rendered = tempfile::tempdir().expect("temp dir");
    let (replay, source) = match value_of("--replay") {
        Some(dir) => (Some(dir.clone()), dir),
        None if live_sim => (None, "the simulator inside the daemon (serve --sim)".to_string()),
        None => {
            let started = Instant::now();
            let scenes: Vec<_> = (0..DEMO_FRAMES)
                .map(|i| nusense_sim::script::scene_at(i as f64 * nusense_sim::script::PERIOD_S / DEMO_FRAMES as f64))
                .collect();
            render_folder(rendered.path(), WIDTH, HEIGHT, &scenes);
            let bytes: u64 = std::fs::read_dir(rendered.path())
                .unwrap()
                .map(|e| e.unwrap().metadata().unwrap().len())
                .sum();
            println!(
                "rendered {DEMO_FRAMES} frames of the simulator's demo in {:.0} s, {:.0} kB a JPEG on average",
                started.elapsed().as_secs_f64(),
                bytes as f64 / DEMO_FRAMES as f64 / 1e3
            );
            let dir = rendered.path().display().to_string();
            (
                Some(dir),
                "the simulator's demo as JPEG files (serve --replay --loop)".to_string(),
            )
        }
    };
    let recordings = tempfile::tempdir().expect("temp dir");
    let fps = FPS.to_string();
    let mut options = match &replay {
        Some(dir) => Options::new(&["--replay", dir, "--loop", "--fps", &fps]),
        None => Options::sim(WIDTH, HEIGHT, FPS),
    };
    options = options.arg("--recordings").arg(recordings.path().display().to_string());
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let passed = runtime.block_on(async move {
        let daemon = Daemon::start(options);
        let pid = daemon.pid();
        daemon.wait_reading("at all", |_| true).await;
        let (code, body) = daemon
            .send(
                "POST",
                "/api/v1/record",
                json!({ "action": "start", "path": "memory.mcap" }),
            )
            .await;
        assert_eq!(code, 200, "{body}");
        let (ws, _) = tokio_tungstenite::connect_async(daemon.ws_url("/api/v1/stream"))
            .await
            .expect("stream");
        let reader = tokio::spawn(async move {
            let (_, mut incoming) = ws.split();
            while let Some(Ok(_)) = incoming.next().await {}
        });
        let frames_url = daemon.url("/api/v1/frame.jpg");
        let http = daemon.http.clone();
        let viewer = tokio::spawn(async move {
            loop {
                if let Ok(response) = http.get(&frames_url).send().await {
                    let _ = response.bytes().await;
                }
                tokio::time::sleep(Duration::from_millis(150)).await;
            }
        });

        let status = daemon.status().await;
        let camera = &status["camera"];
        println!(
            "nusense serve, {}x{} at {FPS} fps from {source}, recording, 1 stream + 1 frame viewer, {minutes} min",
            camera["width"], camera["height"]
        );
        println!("| minute | RSS MB | peak MB | frames processed | recorded | recorder dropped | file MB |");
        println!("|-------:|-------:|--------:|-----------------:|---------:|-----------------:|--------:|");
        let started = Instant::now();
        let duration = Duration::from_secs_f64(minutes * 60.0);
        let mut peak: f64 = 0.0;
        let mut samples = Vec::new();
        let mut next_row = Duration::ZERO;
        while started.elapsed() < duration {
            tokio::time::sleep(Duration::from_millis(250)).await;
            let rss = rss_mb(pid).expect("the daemon is running");
            peak = peak.max(rss);
            samples.push(rss);
            if started.elapsed() >= next_row {
                let status = daemon.status().await;
                let pipeline = &status["pipeline"];
                let recording = &pipeline["recording"];
                let file_mb = std::fs::metadata(recordings.path().join("memory.mcap"))
                    .map(|m| m.len() as f64 / 1e6)
                    .unwrap_or(0.0);
                println!(
                    "| {:>6.1} | {rss:>6.1} | {peak:>7.1} | {:>16} | {:>8} | {:>16} | {file_mb:>7.1} |",
                    started.elapsed().as_secs_f64() / 60.0,
                    pipeline["frames_processed"],
                    recording["frames"],
                    recording["dropped"],
                );
                next_row += Duration::from_secs(60);
            }
        }
        let (code, summary) = daemon.send("POST", "/api/v1/record", json!({ "action": "stop" })).await;
        println!("recording: {code} {summary}");
        let file_mb =
            std::fs::metadata(recordings.path().join("memory.mcap")).map_or(f64::NAN, |m| m.len() as f64 / 1e6);
        println!("recording file: {file_mb:.1} MB");
        viewer.abort();
        reader.abort();
        let status = daemon.status().await;
        println!("{}", pipeline_counters(&status));
        samples.sort_by(f64::total_cmp);
        let median = samples.get(samples.len() / 2).copied().unwrap_or(f64::NAN);
        let passed = peak < LIMIT_MB;
        println!(
            "resident memory over {minutes} min ({} samples, every 250 ms): median {median:.1} MB, peak {peak:.1} MB: \
             {} (limit {LIMIT_MB} MB)",
            samples.len(),
            if passed { "PASS" } else { "FAIL" }
        );
        passed
    });
    std::process::exit(if passed { 0 } else { 1 });
}
