//! `nusense serve --zenoh`: every sensor of the daemon on Zenoh, under `nusense/<serial>/` ([`keys`]): readings,
//! contacts and board telemetry published as they happen, the camera's JPEG published only while someone
//! subscribes, status, LED and tare as queryables answering as the HTTP API does (one [`crate::commands`] and one
//! [`crate::api::status_message`] for both), and a liveliness token per sensor so clients see sensors come and go.
//!
//! By default the session is a peer that listens on one loopback endpoint and neither scouts by multicast nor
//! answers multicast scouting: nothing beyond this machine can reach it (Zenoh has no authentication of its own
//! here). A Zenoh configuration file (JSON5) replaces that, e.g. to connect to a router.

pub mod keys;

use std::net::SocketAddr;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use serde::Serialize;
use tokio::sync::broadcast::error::RecvError;
use tokio::task::JoinHandle;
use zenoh::bytes::Encoding;
use zenoh::liveliness::LivelinessToken;
use zenoh::pubsub::Publisher;
use zenoh::query::{Query, Queryable};
use zenoh::{Session, Wait};

/// The Zenoh configuration this module builds and takes, re-exported so that its callers need not depend on zenoh.
pub use zenoh::Config;

use crate::api::{status_message, versioned, AppState};
use crate::commands::{apply_led_request, tare};
use crate::pipeline::{PipelineHandle, PublishedReading};
use crate::record::encode_jpeg;
use nusense_board::BoardEvent;

pub use keys::{KeyError, SensorKeys, ALL_ALIVE};

/// Where the daemon listens when `--zenoh` is given alone.
pub const DEFAULT_ENDPOINT: &str = "tcp/127.0.0.1:7447";
/// Quality of frames compressed for Zenoh when the source gave no JPEG of its own.
const FRAME_JPEG_QUALITY: u8 = 85;

#[derive(Debug, thiserror::Error)]
pub enum ZenohError {
    #[error(
        "Zenoh endpoint {endpoint:?} is not a loopback TCP or UDP address (like {DEFAULT_ENDPOINT}): Zenoh has no \
         authentication here, so the daemon listens on this machine only; to reach other machines, pass a Zenoh \
         configuration with --zenoh-config"
    )]
    NotLoopback { endpoint: String },
    #[error("cannot read the Zenoh configuration {path}: {cause}")]
    ConfigFile { path: String, cause: zenoh::Error },
    #[error("cannot set {key} in the Zenoh configuration: {cause}")]
    ConfigKey { key: &'static str, cause: zenoh::Error },
    #[error("cannot open the Zenoh session: {cause}")]
    Open { cause: zenoh::Error },
    #[error("cannot declare {what} on Zenoh: {cause}")]
    Declare { what: String, cause: zenoh::Error },
    #[error(transparent)]
    Key(#[from] KeyError),
}

/// The session configuration of `--zenoh [ENDPOINT]`: a peer listening on `endpoint` (loopback only), with
/// multicast scouting off both ways.
pub fn loopback_peer_config(endpoint: &str) -> Result<Config, ZenohError> {
    let not_loopback = || ZenohError::NotLoopback {
        endpoint: endpoint.to_owned(),
    };
    let (protocol, address) = endpoint.split_once('/').ok_or_else(not_loopback)?;
    let address: SocketAddr = address.parse().map_err(|_| not_loopback())?;
    if !matches!(protocol, "tcp" | "udp") || !address.ip().is_loopback() {
        return Err(not_loopback());
    }
    let mut config = Config::default();
    let mut set = |key: &'static str, value: String| {
        config
            .insert_json5(key, &value)
            .map_err(|cause| ZenohError::ConfigKey { key, cause })
    };
    set("mode", r#""peer""#.into())?;
    set("listen/endpoints", format!(r#"["{endpoint}"]"#))?;
    set("connect/endpoints", "[]".into())?;
    // Multicast would announce the daemon to (and let it join) every Zenoh node on the local networks.
    set("scouting/multicast/enabled", "false".into())?;
    Ok(config)
}

/// A Zenoh configuration file (JSON5, Zenoh's own format), used as it is.
pub fn config_from_file(path: &Path) -> Result<Config, ZenohError> {
    Config::from_file(path).map_err(|cause| ZenohError::ConfigFile {
        path: path.display().to_string(),
        cause,
    })
}

/// One sensor to serve: its serial names its keys, its API state answers status and commands.
pub struct ZenohSensor {
    pub serial: String,
    pub api: AppState,
}

/// The running Zenoh side; [`ZenohOut::close`] (or dropping it) withdraws every sensor's liveliness.
pub struct ZenohOut {
    session: Session,
    /// One per sensor; undeclared when dropped, and by the session's close.
    tokens: Vec<LivelinessToken>,
    tasks: Vec<JoinHandle<()>>,
    telemetry_stop: Arc<AtomicBool>,
    telemetry_threads: Vec<std::thread::JoinHandle<()>>,
}

impl ZenohOut {
    /// Opens the session and declares every sensor's keys. Call it within a multi-threaded Tokio runtime.
    pub async fn start(config: Config, sensors: Vec<ZenohSensor>) -> Result<Self, ZenohError> {
        let session = zenoh::open(config).await.map_err(|cause| ZenohError::Open { cause })?;
        let mut out = Self {
            session,
            tokens: Vec::new(),
            tasks: Vec::new(),
            telemetry_stop: Arc::new(AtomicBool::new(false)),
            telemetry_threads: Vec::new(),
        };
        // Every sensor's status says where the session listens, from its first answer on.
        let listening_on = out.listening_on().await;
        for sensor in &sensors {
            sensor.api.set_zenoh_listening_on(listening_on.clone());
        }
        for sensor in sensors {
            out.serve_sensor(sensor).await?;
        }
        Ok(out)
    }

    async fn serve_sensor(&mut self, sensor: ZenohSensor) -> Result<(), ZenohError> {
        let keys = SensorKeys::new(&sensor.serial)?;
        let session = &self.session;
        let declare_error = |what: String| move |cause: zenoh::Error| ZenohError::Declare { what, cause };
        let json_publisher = |key: String| async move {
            session
                .declare_publisher(key.clone())
                .encoding(Encoding::APPLICATION_JSON)
                .await
                .map_err(declare_error(format!("publisher {key}")))
        };
        let reading = json_publisher(keys.reading()).await?;
        let contacts = json_publisher(keys.contacts()).await?;
        let telemetry = json_publisher(keys.telemetry()).await?;
        let frame = session
            .declare_publisher(keys.frame())
            .encoding(Encoding::IMAGE_JPEG)
            .await
            .map_err(declare_error(format!("publisher {}", keys.frame())))?;
        // Frames are large: encoded and sent only while a subscriber matches.
        let frames_wanted = Arc::new(AtomicBool::new(false));
        let wanted = frames_wanted.clone();
        frame
            .matching_listener()
            .callback(move |status| wanted.store(status.matching(), Ordering::Relaxed))
            .background()
            .await
            .map_err(declare_error(format!("matching listener of {}", keys.frame())))?;
        let queryable = |key: String| async move {
            session
                .declare_queryable(key.clone())
                .await
                .map_err(declare_error(format!("queryable {key}")))
        };
        let status_queries = queryable(keys.status()).await?;
        let led_queries = queryable(keys.led()).await?;
        let tare_queries = queryable(keys.tare()).await?;
        let frame_queries = queryable(keys.frame()).await?;
        let token = session
            .liveliness()
            .declare_token(keys.alive())
            .await
            .map_err(declare_error(format!("liveliness token {}", keys.alive())))?;
        self.tokens.push(token);

        let pipeline = sensor.api.pipeline.clone();
        let readings = pipeline.subscribe();
        self.tasks.push(tokio::spawn(publish_readings(
            pipeline.clone(),
            readings,
            Publishers {
                reading,
                contacts,
                frame,
            },
            frames_wanted,
        )));
        let api = sensor.api;
        self.tasks.push(tokio::spawn(answer(status_queries, move |_| {
            Ok(json(&status_message(&api)))
        })));
        let board = pipeline.board().clone();
        self.tasks.push(tokio::spawn(answer_blocking(led_queries, move |body| {
            apply_led_request(&board, body)
                .map(|reply| json(&versioned(reply)))
                .map_err(|error| {
                    json(&versioned(ErrorMessage {
                        error: error.to_string(),
                    }))
                })
        })));
        let tare_pipeline = pipeline.clone();
        self.tasks.push(tokio::spawn(answer(tare_queries, move |_| {
            Ok(json(&versioned(tare(&tare_pipeline))))
        })));
        self.tasks
            .push(tokio::spawn(answer_frames(frame_queries, pipeline.clone())));
        if let Some(events) = pipeline.board().events() {
            let stop = self.telemetry_stop.clone();
            let board = pipeline.board().clone();
            let thread = std::thread::Builder::new()
                .name(format!("zenoh telemetry {}", keys.serial()))
                .spawn(move || publish_telemetry(events, board, telemetry, &stop))
                .map_err(|e| ZenohError::Declare {
                    what: "the telemetry thread".into(),
                    cause: e.into(),
                })?;
            self.telemetry_threads.push(thread);
        }
        tracing::info!(
            "zenoh: serving sensor {} under nusense/{}/",
            keys.serial(),
            keys.serial()
        );
        Ok(())
    }

    /// The endpoints the session listens on, as bound: a port 0 in `--zenoh` (or the configuration) is here the port
    /// the system gave, so a client connects to a port nobody could take first. Empty when it listens nowhere.
    pub async fn listening_on(&self) -> Vec<String> {
        let locators = self.session.info().locators().await;
        locators.iter().map(ToString::to_string).collect()
    }

    /// Withdraws every sensor (liveliness tokens undeclared, clients told at once) and closes the session.
    pub async fn close(mut self) {
        self.stop_tasks();
        self.tokens.clear();
        if let Err(error) = self.session.close().await {
            tracing::warn!("zenoh: closing the session: {error}");
        }
    }

    fn stop_tasks(&mut self) {
        for task in self.tasks.drain(..) {
            task.abort();
        }
        self.telemetry_stop.store(true, Ordering::Relaxed);
        for thread in self.telemetry_threads.drain(..) {
            let _ = thread.join();
        }
    }
}

impl Drop for ZenohOut {
    fn drop(&mut self) {
        self.stop_tasks();
    }
}

/// The error reply of a query, as the HTTP API words its errors.
#[derive(Serialize)]
struct ErrorMessage {
    error: String,
}

fn json<T: Serialize>(value: &T) -> Vec<u8> {
    // The messages are derived structs with string keys and serde_json writes non-finite numbers as null.
    serde_json::to_vec(value).unwrap_or_default()
}

struct Publishers {
    reading: Publisher<'static>,
    contacts: Publisher<'static>,
    frame: Publisher<'static>,
}

/// The `contacts` message: a reading's contacts, strongest first, with what identifies its frame.
#[derive(Serialize)]
struct ContactsMessage<'a> {
    schema_version: u32,
    frame_id: u64,
    capture_time_us: u64,
    contacts: &'a [nusense_estimator::ContactRegion],
}

async fn publish_readings(
    pipeline: PipelineHandle,
    mut readings: tokio::sync::broadcast::Receiver<Arc<PublishedReading>>,
    publishers: Publishers,
    frames_wanted: Arc<AtomicBool>,
) {
    loop {
        let published = match readings.recv().await {
            Ok(published) => published,
            // Behind the sensor: skip to the newest readings rather than fall further behind.
            Err(RecvError::Lagged(missed)) => {
                tracing::warn!("zenoh: {missed} readings skipped (publishing fell behind)");
                continue;
            }
            Err(RecvError::Closed) => return,
        };
        let message = &published.message;
        if let Err(error) = publishers.reading.put(published.json.as_bytes()).await {
            tracing::warn!("zenoh: publishing a reading: {error}");
        }
        let contacts = message.estimate.as_ref().map(|r| r.contacts()).unwrap_or_default();
        let contacts = ContactsMessage {
            schema_version: message.schema_version,
            frame_id: message.frame_id,
            capture_time_us: message.capture_time_us,
            contacts: &contacts,
        };
        if let Err(error) = publishers.contacts.put(json(&contacts)).await {
            tracing::warn!("zenoh: publishing contacts: {error}");
        }
        if frames_wanted.load(Ordering::Relaxed) {
            if let Some(jpeg) = latest_jpeg(&pipeline, Some(message.frame_id)).await {
                if let Err(error) = publishers.frame.put(jpeg.as_slice()).await {
                    tracing::warn!("zenoh: publishing a frame: {error}");
                }
            }
        }
    }
}

/// The newest processed frame as JPEG (the camera's own bytes when it sent JPEG), if it is `frame_id` (any
/// frame when `None`).
async fn latest_jpeg(pipeline: &PipelineHandle, frame_id: Option<u64>) -> Option<Arc<Vec<u8>>> {
    let frame = pipeline
        .latest_processed()
        .filter(|f| frame_id.is_none_or(|id| id == f.frame_id))?;
    if let Some(jpeg) = frame.pixels.jpeg() {
        return Some(jpeg.clone());
    }
    let pixels = frame.pixels;
    tokio::task::spawn_blocking(move || pixels.to_rgb().map(|image| encode_jpeg(&image, FRAME_JPEG_QUALITY)))
        .await
        .ok()?
        .ok()
        .map(Arc::new)
}

/// Answers each query on `queryable` with `handle(payload)`: `Ok` JSON as a reply, `Err` JSON as an error reply.
async fn answer<F>(queryable: Queryable<zenoh::handlers::FifoChannelHandler<Query>>, handle: F)
where
    F: Fn(&[u8]) -> Result<Vec<u8>, Vec<u8>> + Send + 'static,
{
    while let Ok(query) = queryable.recv_async().await {
        let payload = query.payload().map(|p| p.to_bytes().into_owned()).unwrap_or_default();
        send_reply(&query, handle(&payload)).await;
    }
}

/// [`answer`] for handlers that wait on the board: they run off the runtime's workers.
async fn answer_blocking<F>(queryable: Queryable<zenoh::handlers::FifoChannelHandler<Query>>, handle: F)
where
    F: Fn(&[u8]) -> Result<Vec<u8>, Vec<u8>> + Send + Sync + 'static,
{
    let handle = Arc::new(handle);
    while let Ok(query) = queryable.recv_async().await {
        let payload = query.payload().map(|p| p.to_bytes().into_owned()).unwrap_or_default();
        let handle = handle.clone();
        let Ok(result) = tokio::task::spawn_blocking(move || handle(&payload)).await else {
            continue;
        };
        send_reply(&query, result).await;
    }
}

async fn send_reply(query: &Query, result: Result<Vec<u8>, Vec<u8>>) {
    let sent = match result {
        Ok(body) => {
            query
                .reply(query.key_expr().clone(), body)
                .encoding(Encoding::APPLICATION_JSON)
                .await
        }
        Err(body) => query.reply_err(body).encoding(Encoding::APPLICATION_JSON).await,
    };
    if let Err(error) = sent {
        tracing::warn!("zenoh: answering {}: {error}", query.key_expr());
    }
}

/// The `frame` queryable: the newest processed frame's JPEG, or an error before the first frame.
async fn answer_frames(queryable: Queryable<zenoh::handlers::FifoChannelHandler<Query>>, pipeline: PipelineHandle) {
    while let Ok(query) = queryable.recv_async().await {
        let sent = match latest_jpeg(&pipeline, None).await {
            Some(jpeg) => {
                query
                    .reply(query.key_expr().clone(), jpeg.as_slice())
                    .encoding(Encoding::IMAGE_JPEG)
                    .await
            }
            None => {
                let error = versioned(ErrorMessage {
                    error: "no frame yet".into(),
                });
                query.reply_err(json(&error)).encoding(Encoding::APPLICATION_JSON).await
            }
        };
        if let Err(error) = sent {
            tracing::warn!("zenoh: answering {}: {error}", query.key_expr());
        }
    }
}

/// The board part of the status, published each time the board reports telemetry.
fn publish_telemetry(
    events: std::sync::mpsc::Receiver<BoardEvent>,
    board: Arc<dyn crate::pipeline::Board>,
    publisher: Publisher<'static>,
    stop: &AtomicBool,
) {
    while !stop.load(Ordering::Relaxed) {
        match events.recv_timeout(std::time::Duration::from_millis(100)) {
            Ok(BoardEvent::Telemetry(_)) => {
                if let Err(error) = publisher.put(json(&versioned(board.status()))).wait() {
                    tracing::warn!("zenoh: publishing telemetry: {error}");
                }
            }
            Ok(_) | Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {}
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => return,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_session_listens_on_loopback_only_and_does_not_scout() {
        let config = loopback_peer_config("tcp/127.0.0.1:7447").unwrap();
        let get = |key: &str| -> serde_json::Value { serde_json::from_str(&config.get_json(key).unwrap()).unwrap() };
        assert_eq!(get("mode"), "peer");
        assert_eq!(get("listen/endpoints"), serde_json::json!(["tcp/127.0.0.1:7447"]));
        assert_eq!(get("connect/endpoints"), serde_json::json!([]));
        assert_eq!(get("scouting/multicast/enabled"), false);
        assert!(loopback_peer_config("udp/[::1]:7447").is_ok());
    }

    #[test]
    fn endpoints_beyond_this_machine_need_a_config_file() {
        for endpoint in [
            "tcp/0.0.0.0:7447",
            "tcp/192.168.1.2:7447",
            "tcp/[::]:7447",
            "tls/127.0.0.1:7447",
            "7447",
        ] {
            let error = loopback_peer_config(endpoint).unwrap_err();
            assert!(
                matches!(&error, ZenohError::NotLoopback { endpoint: e } if e == endpoint),
                "{endpoint}: {error}"
            );
            assert!(error.to_string().contains("--zenoh-config"), "{error}");
        }
    }
}
