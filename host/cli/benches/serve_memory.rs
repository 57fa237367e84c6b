//! Resident memory of `nusense serve` (the real binary) over a long run at 2048x1536 with recording on, a
//! WebSocket client reading every reading and a dashboard-like client fetching frames: the daemon must stay under
//! 200 MB. Prints a table (one row a minute), the peak, and PASS or FAIL.
//!
//!     cargo bench -p nusense --bench serve_memory                      (10 minutes, the simulator)
//!     cargo bench -p nusense --bench serve_memory -- --minutes 3 --replay DIR   (a folder of JPEG frames, as an
//!                                                                       MJPEG camera delivers them)
//!
//! The recording goes to a temporary folder that is removed afterwards.

#[path = "../tests/serve/daemon.rs"]
mod daemon;

use std::time::{Duration, Instant};

use daemon::{Daemon, Options};
use futures_util::StreamExt;
use serde_json::json;

const LIMIT_MB: f64 = 200.0;
const WIDTH: u32 = 2048;
const HEIGHT: u32 = 1536;

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
    let replay = value_of("--replay");
    let recordings = tempfile::tempdir().expect("temp dir");
    let mut options = match &replay {
        Some(dir) => Options::new(&["--replay", dir, "--loop", "--fps", "15"]),
        None => Options::sim(WIDTH, HEIGHT, 15.0),
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

        let source = replay.as_deref().unwrap_or("the simulator");
        println!("nusense serve at {WIDTH}x{HEIGHT} on {source}, recording, 1 stream + 1 frame viewer, {minutes} min");
        println!("| minute | RSS MB | peak MB | frames processed | recorded | recorder dropped | file MB |");
        println!("|-------:|-------:|--------:|-----------------:|---------:|-----------------:|--------:|");
        let started = Instant::now();
        let duration = Duration::from_secs_f64(minutes * 60.0);
        let mut peak: f64 = 0.0;
        let mut next_row = Duration::ZERO;
        while started.elapsed() < duration {
            tokio::time::sleep(Duration::from_millis(250)).await;
            let rss = rss_mb(pid).expect("the daemon is running");
            peak = peak.max(rss);
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
        viewer.abort();
        reader.abort();
        let passed = peak < LIMIT_MB;
        println!(
            "peak resident memory {peak:.1} MB over {minutes} min: {} (limit {LIMIT_MB} MB)",
            if passed { "PASS" } else { "FAIL" }
        );
        passed
    });
    std::process::exit(if passed { 0 } else { 1 });
}
