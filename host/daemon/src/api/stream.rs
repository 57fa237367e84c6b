//! `WS /api/v1/stream`: reading messages ([`crate::ReadingMessage`]) as JSON text, one per frame (or every N-th
//! with `?every=N`).
//!
//! Each client reads from its own cursor into the pipeline's bounded broadcast buffer. A client that cannot
//! keep up misses the readings it fell behind by (counted per client and in total) and never holds up the
//! pipeline or the other clients; one whose socket stays blocked past `send_timeout` is disconnected (counted).
//! When the daemon stops, every client gets a close frame ("going away").

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use axum::extract::rejection::QueryRejection;
use axum::extract::ws::{close_code, CloseFrame, Message, WebSocket, WebSocketUpgrade};
use axum::extract::{Query, State};
use axum::http::StatusCode;
use axum::response::Response;
use futures_util::{SinkExt, StreamExt};
use serde::{Deserialize, Serialize};
use tokio::sync::broadcast::error::RecvError;

use super::{ApiError, AppState};

#[derive(Clone, Copy, Debug)]
pub struct StreamOptions {
    /// A client whose socket accepts nothing for this long is disconnected.
    pub send_timeout: Duration,
}

impl Default for StreamOptions {
    fn default() -> Self {
        Self {
            send_timeout: Duration::from_secs(5),
        }
    }
}

#[derive(Debug, Default)]
pub struct StreamStats {
    clients: AtomicU64,
    connections: AtomicU64,
    sent: AtomicU64,
    /// Readings slow clients missed because they fell behind the broadcast buffer.
    dropped: AtomicU64,
    /// Clients cut off because their socket stayed blocked.
    disconnected_slow: AtomicU64,
}

#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
pub struct StreamStatsSnapshot {
    pub clients: u64,
    pub connections: u64,
    pub sent: u64,
    pub dropped: u64,
    pub disconnected_slow: u64,
}

impl StreamStats {
    pub fn snapshot(&self) -> StreamStatsSnapshot {
        StreamStatsSnapshot {
            clients: self.clients.load(Ordering::Relaxed),
            connections: self.connections.load(Ordering::Relaxed),
            sent: self.sent.load(Ordering::Relaxed),
            dropped: self.dropped.load(Ordering::Relaxed),
            disconnected_slow: self.disconnected_slow.load(Ordering::Relaxed),
        }
    }
}

#[derive(Debug, Deserialize)]
pub struct StreamQuery {
    /// Send every N-th reading (1 = all).
    every: Option<u32>,
    /// Accepted here so that token-carrying URLs parse; the auth layer checks it.
    #[allow(dead_code)]
    token: Option<String>,
}

const MAX_EVERY: u32 = 10_000;

pub async fn upgrade(
    State(state): State<AppState>,
    query: Result<Query<StreamQuery>, QueryRejection>,
    ws: WebSocketUpgrade,
) -> Result<Response, ApiError> {
    let Query(query) = query?;
    let every = query.every.unwrap_or(1);
    if every == 0 || every > MAX_EVERY {
        return Err(ApiError::new(
            StatusCode::BAD_REQUEST,
            format!("every must be between 1 and {MAX_EVERY}, not {every}"),
        ));
    }
    // Subscribe before the upgrade completes so the client misses nothing published after its request.
    let readings = state.pipeline.subscribe();
    let stats = state.stream.clone();
    let options = state.stream_options;
    let closing = state.closing.subscribe();
    Ok(ws.on_upgrade(move |socket| serve_client(socket, readings, every, stats, options, closing)))
}

async fn serve_client(
    socket: WebSocket,
    mut readings: tokio::sync::broadcast::Receiver<Arc<crate::pipeline::PublishedReading>>,
    every: u32,
    stats: Arc<StreamStats>,
    options: StreamOptions,
    mut closing: tokio::sync::watch::Receiver<bool>,
) {
    stats.clients.fetch_add(1, Ordering::Relaxed);
    stats.connections.fetch_add(1, Ordering::Relaxed);
    let (mut sink, mut incoming) = socket.split();
    let mut seen: u64 = 0;
    loop {
        tokio::select! {
            reading = readings.recv() => match reading {
                Ok(reading) => {
                    seen += 1;
                    if !(seen - 1).is_multiple_of(every as u64) {
                        continue;
                    }
                    let send = sink.send(Message::Text(reading.json.clone().into()));
                    match tokio::time::timeout(options.send_timeout, send).await {
                        Ok(Ok(())) => {
                            stats.sent.fetch_add(1, Ordering::Relaxed);
                        }
                        Ok(Err(_)) => break,
                        Err(_) => {
                            stats.disconnected_slow.fetch_add(1, Ordering::Relaxed);
                            tracing::info!("stream: disconnected a client that accepted nothing for {:?}", options.send_timeout);
                            break;
                        }
                    }
                }
                Err(RecvError::Lagged(missed)) => {
                    stats.dropped.fetch_add(missed, Ordering::Relaxed);
                }
                Err(RecvError::Closed) => break,
            },
            message = incoming.next() => match message {
                // Clients have nothing to say; pings are answered by axum, anything else is ignored.
                Some(Ok(Message::Close(_))) | None | Some(Err(_)) => break,
                Some(Ok(_)) => {}
            },
            _ = closing.changed() => {
                let goodbye = Message::Close(Some(CloseFrame {
                    code: close_code::AWAY,
                    reason: "the daemon is stopping".into(),
                }));
                let _ = tokio::time::timeout(options.send_timeout, sink.send(goodbye)).await;
                break;
            }
        }
    }
    stats.clients.fetch_sub(1, Ordering::Relaxed);
}
