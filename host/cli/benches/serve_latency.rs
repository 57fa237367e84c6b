//! Frame -> WebSocket latency of `nusense serve` (the real binary) on the simulator (640x480, 30 fps): a loopback
//! WebSocket client stamps each reading on arrival; the table splits the latency into the estimator's time and
//! the daemon's own.
//!
//!     cargo bench -p nusense --bench serve_latency            (optionally: -- FRAMES)

#[path = "../tests/serve/daemon.rs"]
mod daemon;

use std::time::Duration;

use daemon::{pipeline_counters, press, Daemon, Options};
use futures_util::StreamExt;
use nusense_capture::unix_time_us;
use nusense_daemon::pipeline::summarise;
use serde_json::Value;

fn main() {
    let frames: usize = std::env::args().skip(1).find_map(|a| a.parse().ok()).unwrap_or(300);
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    runtime.block_on(async move {
        let daemon = Daemon::start(Options::sim(640, 480, 30.0));
        daemon.settle(&press(3.0), true).await;
        let (ws, _) = tokio_tungstenite::connect_async(daemon.ws_url("/api/v1/stream"))
            .await
            .expect("connect");
        let (_, mut incoming) = ws.split();
        let mut to_ws = Vec::new();
        let mut to_published = Vec::new();
        let mut estimator = Vec::new();
        let mut daemon_own = Vec::new();
        let mut with_estimate = 0;
        while to_ws.len() < frames {
            let message = tokio::time::timeout(Duration::from_secs(30), incoming.next())
                .await
                .expect("reading")
                .unwrap()
                .unwrap();
            let arrived = unix_time_us();
            let Ok(text) = message.to_text() else { continue };
            let reading: Value = serde_json::from_str(text).unwrap();
            let latency_ms = arrived.saturating_sub(reading["capture_time_us"].as_u64().unwrap()) as f64 / 1e3;
            to_ws.push(latency_ms);
            to_published.push(reading["latency_ms"].as_f64().unwrap_or(f64::NAN));
            if let Some(elapsed) = reading["estimate"]["elapsed_ms"].as_f64() {
                with_estimate += 1;
                estimator.push(elapsed);
                daemon_own.push(latency_ms - elapsed);
            }
        }
        let status = daemon.status().await;
        println!(
            "nusense serve latency, simulator 640x480 at 30 fps, {frames} readings ({with_estimate} with an estimate)"
        );
        println!("| stage                                   |  p50 ms |  p99 ms |  max ms |");
        println!("|-----------------------------------------|--------:|--------:|--------:|");
        for (name, samples) in [
            ("frame -> WebSocket client (total)", to_ws),
            ("frame -> reading published", to_published),
            ("estimator (Reading::elapsed_ms)", estimator),
            ("daemon's own (total - estimator)", daemon_own),
        ] {
            let s = summarise(samples);
            println!("| {name:<39} | {:>7.2} | {:>7.2} | {:>7.2} |", s.p50, s.p99, s.max);
        }
        println!("{}", pipeline_counters(&status));
    });
}
