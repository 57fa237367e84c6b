//! The daemon's HTTP/WebSocket API (version 1, under `/api/v1/`) and the dashboard it serves.
//!
//! Every JSON message carries `schema_version` ([`crate::SCHEMA_VERSION`]). Errors are `{"schema_version": 1,
//! "error": "..."}` with a 4xx/5xx status that says whose fault it was. The first paths, without `v1/`,
//! redirect (308, method and body kept) to their `/api/v1/` equivalent. `guard` decides who may ask.

mod guard;
mod overlay;
mod recordings;
mod stream;

use std::path::PathBuf;
use std::sync::{Arc, Mutex, OnceLock, PoisonError};

use axum::body::{Body, Bytes};
use axum::extract::rejection::{JsonRejection, QueryRejection};
use axum::extract::{Path as UrlPath, Query, State};
use axum::http::{header, HeaderMap, StatusCode, Uri};
use axum::response::{IntoResponse, Redirect, Response};
use axum::routing::{any, get, post, put};
use axum::{Json, Router};
use serde::{Deserialize, Serialize};

use crate::commands::{apply_led_request, LedReply, TareReply};
use crate::pipeline::{error_chain, BoardStatus, PipelineError, PipelineHandle, PipelineStatus, ProcessedFrame};
use crate::record::{encode_jpeg, RecordSummary, RecorderOptions};
use crate::SCHEMA_VERSION;
use nusense_capture::{SceneControl, SourceInfo};

pub use guard::AccessPolicy;
pub use overlay::draw_overlay;
pub use recordings::{RecordingPathError, RecordingsDir};
pub use stream::{StreamOptions, StreamStats, StreamStatsSnapshot};

/// The frame id of `/api/v1/frame.jpg`'s picture (the overlay and the reading of the same id describe it).
pub const FRAME_ID_HEADER: &str = "x-nusense-frame-id";
/// Its capture time, microseconds since the Unix epoch.
pub const CAPTURE_TIME_HEADER: &str = "x-nusense-capture-time-us";
/// Quality of the frames the API encodes itself (sources without a JPEG of their own, overlays): for viewing.
const VIEW_JPEG_QUALITY: u8 = 85;

/// What the handlers share.
#[derive(Clone)]
pub struct AppState {
    pub pipeline: PipelineHandle,
    /// Present when the frames come from the simulator: the API can then change the simulated contact.
    pub scene: Option<SceneControl>,
    pub access: Arc<AccessPolicy>,
    pub recordings: RecordingsDir,
    pub stream: Arc<StreamStats>,
    pub stream_options: StreamOptions,
    /// The last picture encoded for `/api/v1/frame.jpg`, per overlay setting, so that clients asking for the same
    /// frame share one encoding.
    encoded: Arc<Mutex<[Option<EncodedFrame>; 2]>>,
    /// Set once when the daemon stops: WebSocket clients are told goodbye instead of waiting on a dead stream.
    closing: tokio::sync::watch::Sender<bool>,
    /// The daemon's Zenoh side once it is up (one session for every sensor, so shared by [`Self::for_sensor`]):
    /// unset without `--zenoh`.
    zenoh: Arc<OnceLock<ZenohStatus>>,
}

#[derive(Clone)]
struct EncodedFrame {
    frame_id: u64,
    jpeg: Arc<Vec<u8>>,
}

impl AppState {
    pub fn new(
        pipeline: PipelineHandle,
        scene: Option<SceneControl>,
        access: AccessPolicy,
        recordings: RecordingsDir,
    ) -> Self {
        Self {
            pipeline,
            scene,
            access: Arc::new(access),
            recordings,
            stream: Arc::new(StreamStats::default()),
            stream_options: StreamOptions::default(),
            encoded: Arc::default(),
            closing: tokio::sync::watch::Sender::new(false),
            zenoh: Arc::default(),
        }
    }

    /// The same access and recordings folder for another sensor of the daemon (its own stream counters): what
    /// answers that sensor's status and commands over Zenoh.
    pub fn for_sensor(&self, pipeline: PipelineHandle, scene: Option<SceneControl>) -> Self {
        Self {
            pipeline,
            scene,
            access: self.access.clone(),
            recordings: self.recordings.clone(),
            stream: Arc::new(StreamStats::default()),
            stream_options: self.stream_options,
            encoded: Arc::default(),
            closing: tokio::sync::watch::Sender::new(false),
            zenoh: self.zenoh.clone(),
        }
    }

    /// Says in the status of this sensor (and of every sensor made from it by [`Self::for_sensor`]) that the daemon
    /// is on Zenoh, listening on `listening_on` (endpoints as bound: a port 0 asked for is the port given). Once:
    /// later calls change nothing.
    pub fn set_zenoh_listening_on(&self, listening_on: Vec<String>) {
        let _ = self.zenoh.set(ZenohStatus { listening_on });
    }
}

pub fn router(state: AppState) -> Router {
    let v1 = Router::new()
        .route("/status", get(status))
        .route("/reading", get(reading))
        .route("/stream", get(stream::upgrade))
        .route("/tare", post(tare))
        .route("/led", put(set_led))
        .route("/frame.jpg", get(frame_jpeg))
        .route("/record", post(record))
        .route("/schema", get(schema))
        .route("/sim/scene", get(get_scene).put(put_scene))
        .fallback(|| async { ApiError::new(StatusCode::NOT_FOUND, "no such endpoint; see GET /api/v1/status") });
    Router::new()
        .route("/", get(crate::dashboard::index))
        .route("/dashboard.js", get(crate::dashboard::script))
        .route("/dashboard.css", get(crate::dashboard::style))
        .nest("/api/v1", v1)
        .route("/api/{*rest}", any(redirect_to_v1))
        .fallback(|| async { ApiError::new(StatusCode::NOT_FOUND, "no such page; the API is under /api/v1/") })
        .layer(axum::middleware::from_fn_with_state(state.clone(), guard::guard))
        .with_state(state)
}

/// A JSON reply: the message's own fields beside `schema_version`.
#[derive(Serialize)]
pub struct Versioned<T> {
    schema_version: u32,
    #[serde(flatten)]
    body: T,
}

/// `body` beside `schema_version`, as every message of the API and of Zenoh carries it.
pub fn versioned<T: Serialize>(body: T) -> Versioned<T> {
    Versioned {
        schema_version: SCHEMA_VERSION,
        body,
    }
}

fn reply<T: Serialize>(body: T) -> Json<Versioned<T>> {
    Json(versioned(body))
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

    fn internal(error: impl std::fmt::Display) -> Self {
        Self::new(StatusCode::INTERNAL_SERVER_ERROR, error.to_string())
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        #[derive(Serialize)]
        struct ErrorMessage {
            error: String,
        }
        (self.status, reply(ErrorMessage { error: self.message })).into_response()
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

/// `/api/<path>` was the API before it had versions: the same request, under `/api/v1/`.
async fn redirect_to_v1(UrlPath(rest): UrlPath<String>, uri: Uri) -> Result<Redirect, ApiError> {
    if rest == "v1" || rest.starts_with("v1/") {
        return Err(ApiError::new(
            StatusCode::NOT_FOUND,
            "no such endpoint; see GET /api/v1/status",
        ));
    }
    let query = uri.query().map(|q| format!("?{q}")).unwrap_or_default();
    Ok(Redirect::permanent(&format!("/api/v1/{rest}{query}")))
}

/// `GET /api/v1/status`.
#[derive(Serialize)]
pub struct StatusMessage {
    pub version: &'static str,
    pub protocol_version: u16,
    pub simulator: bool,
    /// The sensor's identity: its LED board's USB serial number (its MCU's unique id in upper-case hex), the
    /// `<serial>` of its Zenoh keys and, as a ROS name token, of its ROS 2 names; none without a board (or before
    /// a real board's first connection).
    pub serial_number: Option<String>,
    pub camera: SourceInfo,
    pub pipeline: PipelineStatus,
    pub board: BoardStatus,
    pub websocket: StreamStatsSnapshot,
    /// The daemon's Zenoh side; null without `--zenoh` / `--zenoh-config`.
    pub zenoh: Option<ZenohStatus>,
    /// Where `POST /api/v1/record` writes; names are relative to it.
    pub recordings_dir: String,
    pub token_required: bool,
    /// What is wrong now, in words (empty when all is well): what the dashboard shows in red.
    pub problems: Vec<String>,
}

async fn status(State(state): State<AppState>) -> Json<Versioned<StatusMessage>> {
    Json(status_message(&state))
}

/// The `zenoh` part of the status.
#[derive(Clone, Debug, Serialize)]
pub struct ZenohStatus {
    /// The endpoints the daemon's Zenoh session listens on, as bound (`tcp/127.0.0.1:40517`; a port 0 asked for
    /// is the port the system gave): what a client connects to. Empty when a `--zenoh-config` opens no listener.
    pub listening_on: Vec<String>,
}

/// What `GET /api/v1/status` answers (and the Zenoh queryable `nusense/<serial>/status`).
pub fn status_message(state: &AppState) -> Versioned<StatusMessage> {
    let pipeline = state.pipeline.status();
    let board = state.pipeline.board().status();
    let latest_error = state.pipeline.latest_reading().and_then(|r| r.message.error.clone());
    versioned(StatusMessage {
        version: env!("CARGO_PKG_VERSION"),
        protocol_version: nusense_protocol::PROTOCOL_VERSION,
        simulator: state.scene.is_some(),
        serial_number: state.pipeline.board().serial_number(),
        camera: pipeline.source.clone(),
        problems: problems(&pipeline, &board, latest_error),
        pipeline,
        board,
        websocket: state.stream.snapshot(),
        zenoh: state.zenoh.get().cloned(),
        recordings_dir: state.recordings.root().display().to_string(),
        token_required: state.access.token_required(),
    })
}

fn problems(pipeline: &PipelineStatus, board: &BoardStatus, latest_error: Option<String>) -> Vec<String> {
    let mut problems = Vec::new();
    if let Some(failure) = &pipeline.recording_failure {
        problems.push(if failure.disk_full {
            format!("recording stopped: the disk is full ({})", failure.path)
        } else {
            format!("recording stopped: {}", failure.error)
        });
    }
    if !pipeline.capture_running && !pipeline.capture_finished {
        let why = pipeline.capture_error.as_deref().unwrap_or("no frames");
        problems.push(format!("camera: {why}"));
    }
    if pipeline.capture_finished {
        problems.push("the replay has ended: no new frames".into());
    }
    let link = board.link.as_ref();
    if !board.connected && link.is_some() {
        let why = link
            .and_then(|l| l.last_error.as_deref())
            .unwrap_or("not connected yet");
        problems.push(format!("LED board: {why}"));
    }
    if let Some(led) = link.and_then(|l| l.telemetry.as_ref()).filter(|_| board.connected) {
        let faulty = crate::pipeline::LedState::from_telemetry(led);
        for (side, faults) in ["top", "right", "bottom", "left"].iter().zip(&faulty.faults) {
            if !faults.is_empty() {
                problems.push(format!("LED string {side}: {}", faults.join(", ").replace('_', " ")));
            }
        }
    }
    if let Some(error) = latest_error {
        problems.push(format!("estimator: {error}"));
    }
    if pipeline.decode.errors > 0 {
        problems.push(format!(
            "camera: {} frames did not decode and were skipped (last: {})",
            pipeline.decode.errors,
            pipeline.decode.last_error.as_deref().unwrap_or("unknown")
        ));
    }
    if pipeline.encode_errors > 0 {
        problems.push(format!(
            "{} messages could not be written as JSON and were not sent (see the daemon's log)",
            pipeline.encode_errors
        ));
    }
    problems
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

/// `GET /api/v1/schema`: the reading message's JSON Schema.
async fn schema() -> Response {
    (
        [(header::CONTENT_TYPE, "application/schema+json")],
        crate::reading::reading_schema_json(),
    )
        .into_response()
}

async fn tare(State(state): State<AppState>) -> (StatusCode, Json<Versioned<TareReply>>) {
    (StatusCode::ACCEPTED, reply(crate::commands::tare(&state.pipeline)))
}

/// `PUT /api/v1/led`: currents in mA per side, or `all`; `enabled` switches the addressed channels (checked in
/// [`crate::commands`], the same as over Zenoh). JSON only: a web page cannot send that without the browser
/// asking first.
async fn set_led(
    State(state): State<AppState>,
    headers: HeaderMap,
    body: Bytes,
) -> Result<Json<Versioned<LedReply>>, ApiError> {
    if !is_json(&headers) {
        return Err(ApiError::new(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "Expected request with `Content-Type: application/json`",
        ));
    }
    let board = state.pipeline.board().clone();
    let result = tokio::task::spawn_blocking(move || apply_led_request(&board, &body))
        .await
        .map_err(ApiError::internal)?;
    result.map(reply).map_err(|error| {
        let status = StatusCode::from_u16(error.http_status()).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR);
        ApiError::new(status, error.to_string())
    })
}

/// `Content-Type: application/json` (or `application/...+json`), parameters such as `charset` allowed.
fn is_json(headers: &HeaderMap) -> bool {
    let Some(mime) = headers.get(header::CONTENT_TYPE).and_then(|v| v.to_str().ok()) else {
        return false;
    };
    let essence = mime.split(';').next().unwrap_or_default().trim().to_ascii_lowercase();
    essence == "application/json" || (essence.starts_with("application/") && essence.ends_with("+json"))
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct FrameQuery {
    #[serde(default)]
    overlay: Option<u8>,
    /// Accepted so that token-carrying URLs parse; the guard checks it.
    #[allow(dead_code)]
    token: Option<String>,
}

/// `GET /api/v1/frame.jpg[?overlay=1]`: the newest frame that has its reading, as JPEG; with `overlay=1` that
/// reading's lattice, shear and contact drawn on it. The frame's id is in the `x-nusense-frame-id` header.
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
        .latest_processed()
        .ok_or_else(|| ApiError::new(StatusCode::SERVICE_UNAVAILABLE, "no frame yet"))?;
    let frame_id = frame.frame_id;
    let capture_time_us = frame.reading.message.capture_time_us;
    let jpeg = encoded_frame(&state, frame, overlay).await?;
    Ok((
        [
            (header::CONTENT_TYPE, "image/jpeg".to_string()),
            (header::CACHE_CONTROL, "no-store".to_string()),
            (header::HeaderName::from_static(FRAME_ID_HEADER), frame_id.to_string()),
            (
                header::HeaderName::from_static(CAPTURE_TIME_HEADER),
                capture_time_us.to_string(),
            ),
        ],
        Body::from(jpeg.as_ref().clone()),
    )
        .into_response())
}

async fn encoded_frame(state: &AppState, frame: ProcessedFrame, overlay: bool) -> Result<Arc<Vec<u8>>, ApiError> {
    let slot = usize::from(overlay);
    let cached = state.encoded.lock().unwrap_or_else(PoisonError::into_inner)[slot].clone();
    if let Some(cached) = cached.filter(|c| c.frame_id == frame.frame_id) {
        return Ok(cached.jpeg);
    }
    let frame_id = frame.frame_id;
    // The estimator decoded only part of the frame: the whole picture is decoded here, for whoever looks.
    let jpeg = tokio::task::spawn_blocking(move || match (frame.pixels.jpeg(), overlay) {
        (Some(jpeg), false) => Ok(jpeg.clone()),
        _ => {
            let mut image = frame.pixels.to_rgb()?;
            if let (true, Some(estimate)) = (overlay, frame.reading.message.estimate.as_ref()) {
                draw_overlay(&mut image, estimate);
            }
            Ok::<_, nusense_capture::DecodeError>(Arc::new(encode_jpeg(&image, VIEW_JPEG_QUALITY)))
        }
    })
    .await
    .map_err(ApiError::internal)?
    .map_err(ApiError::internal)?;
    state.encoded.lock().unwrap_or_else(PoisonError::into_inner)[slot] = Some(EncodedFrame {
        frame_id,
        jpeg: jpeg.clone(),
    });
    Ok(jpeg)
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
    /// File name for `start`, relative to the recordings folder (default: `nusense-<unix ms>.mcap`).
    path: Option<PathBuf>,
    /// Replace an existing recording of that name.
    #[serde(default)]
    overwrite: bool,
}

#[derive(Serialize)]
#[serde(rename_all = "lowercase")]
enum RecordReply {
    Recording { path: String, file: String },
    Recorded(RecordSummary),
}

async fn record(
    State(state): State<AppState>,
    body: Result<Json<RecordBody>, JsonRejection>,
) -> Result<Json<Versioned<RecordReply>>, ApiError> {
    let Json(body) = body?;
    let pipeline = state.pipeline.clone();
    match body.action {
        RecordAction::Start => {
            if let Some(running) = pipeline.recording_path() {
                return Err(ApiError::new(
                    StatusCode::CONFLICT,
                    format!("a recording is already running ({})", running.display()),
                ));
            }
            let name = body
                .path
                .unwrap_or_else(|| PathBuf::from(format!("nusense-{}.mcap", nusense_capture::unix_time_us() / 1000)));
            let recordings = state.recordings.clone();
            let overwrite = body.overwrite;
            let started_name = name.display().to_string();
            let file = tokio::task::spawn_blocking(move || -> Result<PathBuf, ApiError> {
                let file = recordings.create(&name, overwrite).map_err(recording_path_error)?;
                if let Err(error) = pipeline.start_recording(&file, RecorderOptions::default()) {
                    // The empty file is ours (created just now, or truncated on request): leave nothing behind.
                    let _ = std::fs::remove_file(&file);
                    return Err(pipeline_error(error));
                }
                Ok(file)
            })
            .await
            .map_err(ApiError::internal)??;
            Ok(reply(RecordReply::Recording {
                path: started_name,
                file: file.display().to_string(),
            }))
        }
        RecordAction::Stop => {
            let summary = tokio::task::spawn_blocking(move || pipeline.stop_recording())
                .await
                .map_err(ApiError::internal)?
                .map_err(pipeline_error)?;
            Ok(reply(RecordReply::Recorded(summary)))
        }
    }
}

fn recording_path_error(error: RecordingPathError) -> ApiError {
    let status = match &error {
        RecordingPathError::Exists { .. } => StatusCode::CONFLICT,
        RecordingPathError::Extension { .. } => StatusCode::UNPROCESSABLE_ENTITY,
        RecordingPathError::Create { source, .. } if source.kind() == std::io::ErrorKind::StorageFull => {
            StatusCode::INSUFFICIENT_STORAGE
        }
        RecordingPathError::Create { .. } => StatusCode::INTERNAL_SERVER_ERROR,
        RecordingPathError::Absolute { .. }
        | RecordingPathError::ParentDir { .. }
        | RecordingPathError::Escapes { .. }
        | RecordingPathError::Empty { .. } => StatusCode::BAD_REQUEST,
    };
    ApiError::new(status, error_chain(&error))
}

fn pipeline_error(error: PipelineError) -> ApiError {
    let status = match error {
        PipelineError::AlreadyRecording(_) | PipelineError::NotRecording => StatusCode::CONFLICT,
        PipelineError::Record(_) => StatusCode::UNPROCESSABLE_ENTITY,
        PipelineError::Thread(..) => StatusCode::INTERNAL_SERVER_ERROR,
    };
    ApiError::new(status, error_chain(&error))
}

fn scene_control(state: &AppState) -> Result<&SceneControl, ApiError> {
    state.scene.as_ref().ok_or_else(|| {
        ApiError::new(
            StatusCode::NOT_FOUND,
            "the daemon is not running on the simulator (start it with --sim)",
        )
    })
}

async fn get_scene(State(state): State<AppState>) -> Result<Json<Versioned<serde_json::Value>>, ApiError> {
    Ok(reply(scene_control(&state)?.describe()))
}

/// Body: `{"scene": <nusense_sim::Scene>}` holds that scene; `{"script": true}` resumes the demo animation.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneBody {
    scene: Option<nusense_sim::Scene>,
    script: Option<bool>,
}

async fn put_scene(
    State(state): State<AppState>,
    body: Result<Json<SceneBody>, JsonRejection>,
) -> Result<Json<Versioned<serde_json::Value>>, ApiError> {
    let control = scene_control(&state)?;
    let Json(body) = body?;
    match (body.scene, body.script) {
        (Some(scene), None | Some(false)) => {
            control
                .hold(scene)
                .map_err(|e| ApiError::new(StatusCode::UNPROCESSABLE_ENTITY, error_chain(&e)))?;
        }
        (None, Some(true)) => control.resume_script(),
        _ => {
            return Err(ApiError::new(
                StatusCode::UNPROCESSABLE_ENTITY,
                "give either {\"scene\": {...}} to hold a scene or {\"script\": true} to resume the animation",
            ))
        }
    }
    Ok(reply(control.describe()))
}

/// Serves the API on `listener` until `shutdown` resolves; then WebSocket clients get a close frame and the
/// server waits for requests in flight.
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
    let closing = state.closing.clone();
    axum::serve(listener, router(state))
        .with_graceful_shutdown(async move {
            shutdown.await;
            closing.send_replace(true);
        })
        .await
}
