//! Bounded load on loopback: 50 WebSocket clients at once and one that never reads. The pipeline drops no frame,
//! every reading client gets every reading, and the stalled client is cut off (or decimated) and counted.

use std::collections::BTreeSet;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use futures_util::StreamExt;
use serde_json::Value;

use crate::daemon::{Daemon, Options};

const CLIENTS: usize = 50;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn fifty_clients_keep_up_and_a_stalled_client_is_dropped_and_counted() {
    let daemon = Daemon::start(Options::sim(320, 240, 15.0));
    daemon.wait_reading("at all", |_| true).await;

    let seen: Vec<Arc<Mutex<BTreeSet<u64>>>> = (0..CLIENTS).map(|_| Arc::default()).collect();
    let mut readers = Vec::new();
    for ids in &seen {
        let (ws, _) = tokio_tungstenite::connect_async(daemon.ws_url("/api/v1/stream"))
            .await
            .expect("connect");
        let ids = ids.clone();
        readers.push(tokio::spawn(async move {
            let (_, mut incoming) = ws.split();
            while let Some(Ok(message)) = incoming.next().await {
                if let Ok(text) = message.to_text() {
                    let reading: Value = serde_json::from_str(text).expect("JSON reading");
                    ids.lock()
                        .unwrap()
                        .insert(reading["frame_id"].as_u64().expect("frame id"));
                }
            }
        }));
    }

    // The stalled client: a tiny receive window and it never reads, so the daemon's socket to it backs up.
    let socket = tokio::net::TcpSocket::new_v4().unwrap();
    socket.set_recv_buffer_size(4096).unwrap();
    let stream = socket.connect(daemon.addr).await.unwrap();
    let (stalled, _) = tokio_tungstenite::client_async(daemon.ws_url("/api/v1/stream"), stream)
        .await
        .expect("stalled client");

    let before = daemon.status().await["pipeline"].clone();
    let window_start = before["frames_captured"].as_u64().unwrap();
    let deadline = Instant::now() + Duration::from_secs(90);
    let (after, stream_stats) = loop {
        tokio::time::sleep(Duration::from_millis(200)).await;
        let status = daemon.status().await;
        let ws = status["websocket"].clone();
        let stalled_counted = ws["dropped"].as_u64() > Some(0) || ws["disconnected_slow"].as_u64() > Some(0);
        let processed = status["pipeline"]["frames_processed"].as_u64().unwrap();
        if (stalled_counted && processed >= window_start + 45) || Instant::now() > deadline {
            break (status["pipeline"].clone(), ws);
        }
    };
    assert!(
        stream_stats["dropped"].as_u64() > Some(0) || stream_stats["disconnected_slow"].as_u64() > Some(0),
        "the stalled client was neither decimated nor disconnected: {stream_stats}"
    );
    assert_eq!(
        after["frames_dropped"], before["frames_dropped"],
        "the pipeline dropped frames with {CLIENTS} clients connected"
    );
    let window: Vec<u64> = (window_start..after["frames_processed"].as_u64().unwrap()).collect();
    assert!(window.len() >= 30, "too short a window: {} frames", window.len());
    // The last few readings may still be on their way.
    tokio::time::sleep(Duration::from_millis(500)).await;
    for (client, ids) in seen.iter().enumerate() {
        let ids = ids.lock().unwrap();
        let missing: Vec<u64> = window.iter().filter(|id| !ids.contains(id)).copied().collect();
        assert!(
            missing.is_empty(),
            "client {client} missed frames {missing:?} while the stalled client backed up"
        );
    }
    println!(
        "load: {CLIENTS} clients, {} frames each, stream stats {stream_stats}",
        window.len()
    );
    drop(stalled);
    for reader in readers {
        reader.abort();
    }
}
