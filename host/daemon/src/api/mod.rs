//! The daemon's HTTP/WebSocket API and the dashboard it serves.
//!
//! Every error is a JSON body `{"error": "..."}` with a 4xx/5xx status that says whose fault it was.

mod auth;
mod overlay;
mod stream;

use std::path::PathBuf;
use std::sync::Arc;

use axum::body::Body;
use axum::extract::rejection::{JsonRejection, QueryRejection};
use axum::extract::{Query, State};
use axum::http::{header, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post, put};
use axum::{Json, Router};
use serde::Deserialize;

use crate::pipeline::{BoardError, LedCommand, PipelineError, PipelineHandle};
use crate::record::{encode_jpeg, RecorderOptions};
use nusense_capture::SceneControl;

pub use overlay::draw_overlay;
pub use stream::{StreamStats, StreamStatsSnapshot};

/// What the handlers share.
#[derive(Clone)]
pub struct AppState {
    pub pipeline: PipelineHandle,
    /// Present when the frames come from the simulator: the API can then change the simulated contact.
    pub scene: Option<SceneControl>,
    /// Required on every request when set (the daemon listens beyond loopback).
    pub token: Option<Arc<str>>,
    /// Where `POST /api/record` puts recordings that are not given a path.
    pub recordings_dir: PathBuf,
    pub stream: Arc<StreamStats>,
    pub stream_options: stream::StreamOptions,
}

impl AppState {
    pub fn new(pipeline: PipelineHandle, scene: Option<SceneControl>, token: Option<String>) -> Self {
        Self {
            pipeline,
            scene,
            token: token.map(Into::into),
            recordings_dir: std::env::temp_dir(),
            stream: Arc::new(StreamStats::default()),
            stream_options: stream::StreamOptions::default(),
        }
    }
}

pub fn router(state: AppState) -> Router {
    Router::new()
        .route("/", get(crate::dashboard::index))
        .route("/dashboard.js", get(crate::dashboard::script))
        .route("/dashboard.css", get(crate::dashboard::style))
        .route("/api/status", get(status))
        .route("/api/reading", get(reading))
        .route("/api/stream", get(stream::upgrade))
        .route("/api/tare", post(tare))
        .route("/api/led", put(set_led))
        .route("/api/frame.jpg", get(frame_jpeg))
        .route("/api/record", post(record))
        .route("/api/sim/scene", get(get_scene).put(put_scene))
        .fallback(|| async { ApiError::new(StatusCode::NOT_FOUND, "no such endpoint; see GET /api/status") })
        .layer(axum::middleware::from_fn_with_state(state.clone(), auth::require_token))
        .with_state(state)
}

#[derive(Debug)]
pub struct ApiError {
    status: StatusCode,
    message: String,
}

impl ApiError {
    pub fn new(status: StatusCode, message: impl Into<String>) -> Self {
        Self {
            status,
            message: message.into(),
        }
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        (self.status, Json(serde_json::json!({ "error": self.message }))).into_response()
    }
}

impl From<JsonRejection> for ApiError {
    fn from(rejection: JsonRejection) -> Self {
        Self::new(rejection.status(), rejection.body_text())
    }
}

impl From<QueryRejection> for ApiError {
    fn from(rejection: QueryRejection) -> Self {
        Self::new(StatusCode::BAD_REQUEST, rejection.body_text())
    }
}

async fn status(State(state): State<AppState>) -> Json<serde_json::Value> {
    let pipeline = state.pipeline.status();
    Json(serde_json::json!({
        "version": env!("CARGO_PKG_VERSION"),
        "protocol_version": nusense_protocol::PROTOCOL_VERSION,
        "simulator": state.scene.is_some(),
        "camera": pipeline.source,
        "pipeline": pipeline,
        "board": state.pipeline.board().status(),
        "websocket": state.stream.snapshot(),
    }))
}

async fn reading(State(state): State<AppState>) -> Result<Response, ApiError> {
    let latest = state.pipeline.latest_reading().ok_or_else(|| {
        ApiError::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "no reading yet: the first frame has not been processed",
        )
    })?;
    Ok(([(header::CONTENT_TYPE, "application/json")], latest.json.clone()).into_response())
}

async fn tare(State(state): State<AppState>) -> (StatusCode, Json<serde_json::Value>) {
    state.pipeline.request_tare();
    (
        StatusCode::ACCEPTED,
        Json(serde_json::json!({ "tare": "the next frame becomes the rest frame" })),
    )
}

/// `PUT /api/led`: currents in mA per side, or `all`; `enabled` switches the addressed channels.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct LedBody {
    top: Option<u16>,
    right: Option<u16>,
    bottom: Option<u16>,
    left: Option<u16>,
    all: Option<u16>,
    enabled: Option<bool>,
}

async fn set_led(
    State(state): State<AppState>,
    body: Result<Json<LedBody>, JsonRejection>,
) -> Result<Json<serde_json::Value>, ApiError> {
    let Json(body) = body?;
    let per_side = [body.top, body.right, body.bottom, body.left];
    let current_ma = match body.all {
        Some(_) if per_side.iter().any(Option::is_some) => {
            return Err(ApiError::new(
                StatusCode::UNPROCESSABLE_ENTITY,
                "give either `all` or per-side currents, not both",
            ))
        }
        Some(all) => [Some(all); 4],
        None => per_side,
    };
    if current_ma.iter().all(Option::is_none) && body.enabled.is_none() {
        return Err(ApiError::new(
            StatusCode::UNPROCESSABLE_ENTITY,
            "nothing to set: give currents in mA as `top`, `right`, `bottom`, `left` or `all`, and/or `enabled`",
        ));
    }
    let command = LedCommand {
        current_ma,
        enabled: body.enabled,
    };
    command
        .validate()
        .map_err(|e| ApiError::new(StatusCode::UNPROCESSABLE_ENTITY, e.to_string()))?;
    let board = state.pipeline.board().clone();
    let result = tokio::task::spawn_blocking(move || board.set_leds(&command))
        .await
        .map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()))?;
    match result {
        Ok(()) => Ok(Json(serde_json::json!({ "board": state.pipeline.board().status() }))),
        Err(e @ BoardError::AboveLimit { .. }) => Err(ApiError::new(StatusCode::UNPROCESSABLE_ENTITY, e.to_string())),
        Err(e @ BoardError::NoBoard) => Err(ApiError::new(StatusCode::SERVICE_UNAVAILABLE, e.to_string())),
        Err(e @ BoardError::Link(_)) => Err(ApiError::new(StatusCode::BAD_GATEWAY, e.to_string())),
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct FrameQuery {
    #[serde(default)]
    overlay: Option<u8>,
}

async fn frame_jpeg(
    State(state): State<AppState>,
    query: Result<Query<FrameQuery>, QueryRejection>,
) -> Result<Response, ApiError> {
    let Query(query) = query?;
    let overlay = match query.overlay {
        None | Some(0) => false,
        Some(1) => true,
        Some(other) => {
            return Err(ApiError::new(
                StatusCode::BAD_REQUEST,
                format!("overlay must be 0 or 1, not {other}"),
            ))
        }
    };
    let frame = state
        .pipeline
        .latest_frame()
        .ok_or_else(|| ApiError::new(StatusCode::SERVICE_UNAVAILABLE, "no frame yet"))?;
    let reading = if overlay { state.pipeline.latest_reading() } else { None };
    let bytes = tokio::task::spawn_blocking(move || match (&frame.jpeg, overlay) {
        (Some(jpeg), false) => jpeg.as_ref().clone(),
        _ => {
            let mut image = frame.image.as_ref().clone();
            if let Some(estimate) = reading.as_ref().and_then(|r| r.reading.estimate.as_ref()) {
                draw_overlay(&mut image, estimate);
            }
            encode_jpeg(&image, 85)
        }
    })
    .await
    .map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()))?;
    Ok((
        [
            (header::CONTENT_TYPE, "image/jpeg"),
            (header::CACHE_CONTROL, "no-store"),
        ],
        Body::from(bytes),
    )
        .into_response())
}

#[derive(Debug, Deserialize)]
#[serde(rename_all = "lowercase")]
enum RecordAction {
    Start,
    Stop,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RecordBody {
    action: RecordAction,
    /// File name for `start`; relative names go into the daemon's recordings folder.
    path: Option<PathBuf>,
}

async fn record(
    State(state): State<AppState>,
    body: Result<Json<RecordBody>, JsonRejection>,
) -> Result<Json<serde_json::Value>, ApiError> {
    let Json(body) = body?;
    let pipeline = state.pipeline.clone();
    match body.action {
        RecordAction::Start => {
            let path = match body.path {
                Some(path) if path.is_absolute() => path,
                Some(path) => state.recordings_dir.join(path),
                None => state
                    .recordings_dir
                    .join(format!("nusense-{}.mcap", nusense_capture::unix_time_us() / 1000)),
            };
            if path.extension().and_then(|e| e.to_str()) != Some("mcap") {
                return Err(ApiError::new(
                    StatusCode::UNPROCESSABLE_ENTITY,
                    "the recording's file name must end in .mcap",
                ));
            }
            let started = path.clone();
            tokio::task::spawn_blocking(move || pipeline.start_recording(&path, RecorderOptions::default()))
                .await
                .map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()))?
                .map_err(pipeline_error)?;
            Ok(Json(serde_json::json!({ "recording": started })))
        }
        RecordAction::Stop => {
            let summary = tokio::task::spawn_blocking(move || pipeline.stop_recording())
                .await
                .map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()))?
                .map_err(pipeline_error)?;
            Ok(Json(serde_json::json!({ "recorded": summary })))
        }
    }
}

fn pipeline_error(error: PipelineError) -> ApiError {
    let status = match error {
        PipelineError::AlreadyRecording(_) | PipelineError::NotRecording => StatusCode::CONFLICT,
        PipelineError::Record(_) => StatusCode::UNPROCESSABLE_ENTITY,
        PipelineError::Thread(..) => StatusCode::INTERNAL_SERVER_ERROR,
    };
    ApiError::new(status, error.to_string())
}

fn scene_control(state: &AppState) -> Result<&SceneControl, ApiError> {
    state.scene.as_ref().ok_or_else(|| {
        ApiError::new(
            StatusCode::NOT_FOUND,
            "the daemon is not running on the simulator (start it with --sim)",
        )
    })
}

async fn get_scene(State(state): State<AppState>) -> Result<Json<serde_json::Value>, ApiError> {
    Ok(Json(scene_control(&state)?.describe()))
}

/// Body: `{"scene": <nusense_sim::Scene>}` holds that scene; `{"script": true}` resumes the demo animation.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneBody {
    scene: Option<serde_json::Value>,
    script: Option<bool>,
}

async fn put_scene(
    State(state): State<AppState>,
    body: Result<Json<SceneBody>, JsonRejection>,
) -> Result<Json<serde_json::Value>, ApiError> {
    let control = scene_control(&state)?;
    let Json(body) = body?;
    match (body.scene, body.script) {
        (Some(scene), None | Some(false)) => {
            control
                .hold_json(scene)
                .map_err(|e| ApiError::new(StatusCode::UNPROCESSABLE_ENTITY, e))?;
        }
        (None, Some(true)) => control.resume_script(),
        _ => {
            return Err(ApiError::new(
                StatusCode::UNPROCESSABLE_ENTITY,
                "give either {\"scene\": {...}} to hold a scene or {\"script\": true} to resume the animation",
            ))
        }
    }
    Ok(Json(control.describe()))
}

/// Serves the API on `listener` until `shutdown` resolves.
pub async fn serve(
    listener: tokio::net::TcpListener,
    state: AppState,
    shutdown: impl std::future::Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    use axum::serve::ListenerExt;
    // Readings are small frames sent as they happen: Nagle's algorithm would hold one back behind the last
    // one's ACK, which is latency the stream exists to avoid.
    let listener = listener.tap_io(|tcp| {
        if let Err(error) = tcp.set_nodelay(true) {
            tracing::warn!("could not disable Nagle's algorithm on a client socket: {error}");
        }
    });
    axum::serve(listener, router(state))
        .with_graceful_shutdown(shutdown)
        .await
}
