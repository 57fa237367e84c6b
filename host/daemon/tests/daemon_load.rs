//! Bounded load on loopback: 50 WebSocket clients at once without the pipeline dropping frames, and a client
//! that stops reading is dropped or decimated (and counted) while the others keep up.

mod daemon_common;

use std::collections::BTreeSet;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use daemon_common::{start, DaemonSetup};
use futures_util::StreamExt;
use serde_json::Value;

const CLIENTS: usize = 50;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn fifty_clients_keep_up_and_a_stalled_client_is_cut_off_and_counted() {
    let daemon = start(DaemonSetup {
        width: 320,
        height: 240,
        fps: 15.0,
        broadcast_len: 16,
        send_timeout: Duration::from_secs(1),
        ..Default::default()
    })
    .await;
    // Wait for the pipeline to run.
    daemon
        .wait_reading(Duration::from_secs(60), |_| true)
        .await
        .expect("first reading");

    let seen: Vec<Arc<Mutex<BTreeSet<u64>>>> = (0..CLIENTS).map(|_| Arc::default()).collect();
    let mut readers = Vec::new();
    for ids in &seen {
        let (ws, _) = tokio_tungstenite::connect_async(daemon.ws_url("/api/stream"))
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

    // The stalled client: a tiny receive window and it never reads, so the daemon's socket backs up.
    let socket = tokio::net::TcpSocket::new_v4().unwrap();
    socket.set_recv_buffer_size(4096).unwrap();
    let stream = socket.connect(daemon.addr).await.unwrap();
    let (stalled, _) = tokio_tungstenite::client_async(daemon.ws_url("/api/stream"), stream)
        .await
        .expect("stalled client");

    let status_before = daemon.handle.status();
    let window_start = status_before.frames_processed;
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        tokio::time::sleep(Duration::from_millis(100)).await;
        let stream_stats = daemon.state.stream.snapshot();
        let processed = daemon.handle.status().frames_processed;
        let stalled_counted = stream_stats.dropped > 0 || stream_stats.disconnected_slow > 0;
        if (stalled_counted && processed >= window_start + 45) || Instant::now() > deadline {
            break;
        }
    }
    let status_after = daemon.handle.status();
    let stream_stats = daemon.state.stream.snapshot();
    assert!(
        stream_stats.dropped > 0 || stream_stats.disconnected_slow > 0,
        "the stalled client was neither decimated nor disconnected: {stream_stats:?}"
    );
    assert_eq!(
        status_after.frames_dropped, status_before.frames_dropped,
        "the pipeline dropped frames with {CLIENTS} clients connected"
    );
    let window: Vec<u64> =
        (status_before.frames_captured..status_after.frames_processed.min(status_after.frames_captured)).collect();
    assert!(window.len() >= 30, "too short a window: {} frames", window.len());
    // Allow the last few frames still in flight to the clients.
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
        "load: {CLIENTS} clients, {} frames each, stream stats {stream_stats:?}",
        window.len()
    );
    drop(stalled);
    for reader in readers {
        reader.abort();
    }
    daemon.stop().await;
}
