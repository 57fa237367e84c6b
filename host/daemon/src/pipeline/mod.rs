//! The live pipeline: a capture thread feeds a bounded drop-oldest queue with the camera's bytes, a decode thread
//! decodes each frame (only the scale and region the estimator reads) into a second drop-oldest queue, and an
//! estimator thread turns it into a reading and publishes it (latest value, a broadcast for WebSocket clients,
//! the recorder): decoding a frame overlaps with estimating the one before (`stages`, which also keeps the
//! one-thread arrangement as a baseline). Frames dropped in front of each stage are counted. Latency is measured
//! from the frame's capture timestamp, decoding included, and kept per stage.
//!
//! The first frame, and the first frame after a tare, is the rest frame the estimator measures against: it is
//! decoded whole at the decode scale, and later frames only inside the pattern's region around its lattice
//! (whole again after a frame that could not be measured, in case the pattern left the region); `stages` says
//! how a tare stays ordered with the frames already decoded. The whole frame is decoded at full size only when
//! someone asks for the picture (`/api/v1/frame.jpg`, Foxglove); recordings keep the camera's JPEG bytes as they
//! came.
//!
//! A recording that fails (a full disk) stops by itself: the pipeline keeps running and publishing, and the
//! failure stays in the status until the next recording starts.

mod board;
#[cfg(test)]
mod decode_tests;
mod queue;
mod sources;
mod stages;
mod stats;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError, RwLock};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use nusense_board::BoardEvent;
use nusense_estimator::{Mode, SensorConfig};
use serde::Serialize;
use tokio::sync::broadcast;

use crate::reading::{ReadingMessage, SCHEMA_VERSION};
use crate::record::{RecordError, RecordFailure, RecordItem, RecordSummary, Recorder, RecorderOptions};
use nusense_capture::{unix_time_us, CaptureError, FramePixels, FrameSource, PixelRect, Scale, SourceInfo};
use stages::{DecodePlan, DecodeStage, DecodedItem, EstimateStage};

pub use board::{
    serial_number_of, Board, BoardError, BoardKind, BoardStatus, LedCommand, LedState, LinkedBoard, NoBoard,
    LED_LIMIT_MA,
};
pub use queue::DropOldestQueue;
pub use sources::{open_sources, BoardChoice, FrameChoice, SourceError, Sources};
pub use stages::Stages;
pub use stats::{summarise, LatencySummary, LatencyWindow};

/// A reading with its JSON, serialised once for every consumer.
#[derive(Debug)]
pub struct PublishedReading {
    pub message: ReadingMessage,
    pub json: String,
}

/// A frame the estimator has finished with and its reading: the picture and the numbers of the same instant,
/// for `/api/v1/frame.jpg` and its overlay.
#[derive(Clone, Debug)]
pub struct ProcessedFrame {
    pub frame_id: u64,
    /// The frame as the camera delivered it (its JPEG bytes, when it sent JPEG): decoded whole only when the
    /// picture is asked for.
    pub pixels: FramePixels,
    pub reading: Arc<PublishedReading>,
}

/// Readings kept for the latency summary in `/api/v1/status`.
const LATENCY_WINDOW: usize = 1024;
/// First wait before reopening a source that vanished (a camera unplugged); doubles up to [`REOPEN_BACKOFF_MAX`].
const REOPEN_BACKOFF_MIN: Duration = Duration::from_millis(250);
/// Longest wait between attempts to reopen a source, so that a replugged camera is back within this long.
const REOPEN_BACKOFF_MAX: Duration = Duration::from_secs(2);
/// How long the estimator and telemetry threads wait for work before they look at the stop flag again.
const POLL_INTERVAL: Duration = Duration::from_millis(50);

/// A poisoned lock only says another thread panicked while holding it; what it guards is still the latest
/// state we have, and a daemon that keeps serving is worth more than one that stops.
fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The scale frames are decoded at for the estimator.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum DecodeScale {
    /// The smallest scale that keeps the decoded frame at least [`MIN_DECODED_WIDTH`] px wide (1/2 for a
    /// 2048x1536 frame, full size at 640x480); full size for the paper's pipeline, whose parameters are in px.
    Auto,
    Fixed(Scale),
}

/// Narrowest decoded frame the fast tracker is given: at 1024 px across the pattern's cells are still about 45 px
/// wide, and `nusense bench` shows the lattice at 1/2 of a 2048-px frame within 0.1 px of the full decode's.
pub const MIN_DECODED_WIDTH: u32 = 1024;

impl DecodeScale {
    pub fn for_frame(self, mode: Mode, width: u32) -> Scale {
        match (self, mode) {
            (DecodeScale::Fixed(scale), _) => scale,
            (DecodeScale::Auto, Mode::Paper) => Scale::Full,
            (DecodeScale::Auto, _) => Scale::ALL
                .into_iter()
                .rev()
                .find(|scale| width / scale.divisor() >= MIN_DECODED_WIDTH)
                .unwrap_or(Scale::Full),
        }
    }
}

impl std::str::FromStr for DecodeScale {
    type Err = String;

    /// `auto`, or a scale as [`Scale`] reads it (`2`, `1/2`, ...).
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        match text.trim() {
            "auto" => Ok(DecodeScale::Auto),
            other => other.parse().map(DecodeScale::Fixed),
        }
    }
}

#[derive(Clone)]
pub struct PipelineOptions {
    pub config: SensorConfig,
    pub mode: Mode,
    /// Frames waiting for each stage (decoding, estimating); beyond this the oldest is dropped (and counted).
    pub queue_len: usize,
    /// Readings a WebSocket client may fall behind by before it misses some.
    pub broadcast_len: usize,
    pub decode_scale: DecodeScale,
    /// Decode only the pattern's region of frames after the rest frame (fast and inverse modes: the paper's
    /// detector searches its own region of interest).
    pub decode_region: bool,
    pub stages: Stages,
}

impl PipelineOptions {
    pub fn new(config: SensorConfig, mode: Mode) -> Self {
        Self {
            config,
            mode,
            queue_len: 2,
            broadcast_len: 64,
            decode_scale: DecodeScale::Auto,
            decode_region: true,
            stages: Stages::Overlapped,
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    #[error("cannot start the {0} thread")]
    Thread(&'static str, #[source] std::io::Error),
    #[error(transparent)]
    Record(#[from] RecordError),
    #[error("a recording is already running ({0})")]
    AlreadyRecording(String),
    #[error("no recording is running")]
    NotRecording,
}

/// A message the pipeline could not write as JSON. serde_json writes a non-finite number as `null` and the
/// messages are derived structs with string keys, so this is not expected to happen; should a change to a type
/// ever make it happen, the message is logged, counted in the status (`encode_errors`) and not sent, rather than
/// sent empty.
#[derive(Debug, thiserror::Error)]
#[error("the {what} could not be written as JSON")]
pub struct EncodeError {
    what: &'static str,
    #[source]
    source: serde_json::Error,
}

#[derive(Debug, Default)]
struct Counters {
    frames_captured: AtomicU64,
    frames_processed: AtomicU64,
    capture_errors: AtomicU64,
    decode_errors: AtomicU64,
    estimate_errors: AtomicU64,
    encode_errors: AtomicU64,
    tares: AtomicU64,
}

/// How the estimator's frames are decoded now, and the frames that did not decode.
#[derive(Clone, Debug, Default, Serialize)]
pub struct DecodeStatus {
    /// Frame px per decoded px along each axis (1, 2, 4 or 8); `None` before the first frame.
    pub scale: Option<Scale>,
    /// The part of the frame decoded (full-size raw px); `None`: the whole frame.
    pub region: Option<PixelRect>,
    /// Frames that did not decode (a truncated or corrupt JPEG, a short YUYV buffer); each is skipped.
    pub errors: u64,
    pub last_error: Option<String>,
}

/// Each stage's share of the latency over the latest frames, ms.
struct StageWindows {
    capture_to_decode: LatencyWindow,
    decode_to_estimate: LatencyWindow,
    estimate_to_publish: LatencyWindow,
}

/// Per-stage latency percentiles for the status.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct StageLatency {
    /// Capture timestamp to the frame decoded (queueing and decoding).
    pub capture_to_decode: LatencySummary,
    pub decode_to_estimate: LatencySummary,
    /// Serialising, recording and broadcasting the reading.
    pub estimate_to_publish: LatencySummary,
}

#[derive(Clone, Debug, Default, Serialize)]
struct CaptureState {
    running: bool,
    /// The source ended (a recording played to its end).
    finished: bool,
    last_error: Option<String>,
    reconnects: u64,
}

/// The recorder, and how the last recording ended when it ended by itself.
#[derive(Default)]
struct RecordingSlot {
    active: Option<Recorder>,
    failed: Option<RecordingFailure>,
}

/// Why a recording stopped without being asked to.
#[derive(Clone, Debug, Serialize)]
pub struct RecordingFailure {
    pub path: String,
    /// What went wrong, in words, with its causes.
    pub error: String,
    /// The disk (or the recordings folder's filesystem) is full.
    pub disk_full: bool,
    /// Microseconds since the Unix epoch.
    pub time_us: u64,
}

struct Shared {
    source_info: Mutex<SourceInfo>,
    capture_state: Mutex<CaptureState>,
    /// Captured frames waiting for the decoder.
    queue: DropOldestQueue<QueuedFrame>,
    /// Decoded frames waiting for the estimator ([`Stages::Overlapped`]).
    decoded: DropOldestQueue<DecodedItem>,
    /// How the estimator wants frames decoded; written by the estimate stage only.
    plan: Mutex<DecodePlan>,
    counters: Counters,
    latency: Mutex<LatencyWindow>,
    stage_latency: Mutex<StageWindows>,
    decode: Mutex<DecodeStatus>,
    latest: RwLock<Option<ProcessedFrame>>,
    readings: broadcast::Sender<Arc<PublishedReading>>,
    /// Tares asked for so far (each makes a later frame the rest frame; see [`stages`]).
    tares_requested: AtomicU64,
    stop: AtomicBool,
    recording: Mutex<RecordingSlot>,
    board: Arc<dyn Board>,
    mode: Mode,
    stages: Stages,
    started: Instant,
}

impl Shared {
    fn new(source_info: SourceInfo, board: Arc<dyn Board>, options: &PipelineOptions) -> Self {
        let (readings, _) = broadcast::channel(options.broadcast_len.max(1));
        Self {
            source_info: Mutex::new(source_info),
            capture_state: Mutex::new(CaptureState {
                running: true,
                ..Default::default()
            }),
            queue: DropOldestQueue::new(options.queue_len),
            decoded: DropOldestQueue::new(options.queue_len),
            plan: Mutex::new(DecodePlan::default()),
            counters: Counters::default(),
            latency: Mutex::new(LatencyWindow::new(LATENCY_WINDOW)),
            stage_latency: Mutex::new(StageWindows {
                capture_to_decode: LatencyWindow::new(LATENCY_WINDOW),
                decode_to_estimate: LatencyWindow::new(LATENCY_WINDOW),
                estimate_to_publish: LatencyWindow::new(LATENCY_WINDOW),
            }),
            decode: Mutex::new(DecodeStatus::default()),
            latest: RwLock::new(None),
            readings,
            tares_requested: AtomicU64::new(0),
            stop: AtomicBool::new(false),
            recording: Mutex::new(RecordingSlot::default()),
            board,
            mode: options.mode,
            stages: options.stages,
            started: Instant::now(),
        }
    }

    /// Frames dropped in front of each stage.
    fn dropped(&self) -> StageDrops {
        StageDrops {
            decode: self.queue.dropped(),
            estimate: self.decoded.dropped(),
        }
    }

    /// Hands an item to the recorder, if one runs. A recorder whose writer stopped (a full disk, an I/O error)
    /// is finished here and its failure kept for the status: recording ends, the pipeline goes on.
    fn record(&self, item: impl FnOnce() -> RecordItem) {
        self.record_if_some(|| Some(item()));
    }

    /// [`Shared::record`] for an item that may fail to be made (`None`: nothing is recorded).
    fn record_if_some(&self, item: impl FnOnce() -> Option<RecordItem>) {
        let mut slot = lock(&self.recording);
        let Some(recorder) = slot.active.as_ref() else {
            return;
        };
        if recorder.failure().is_none() {
            if let Some(item) = item() {
                recorder.record(item);
            }
            return;
        }
        let Some(recorder) = slot.active.take() else {
            return;
        };
        let path = recorder.path().display().to_string();
        let failure = match recorder.finish() {
            Err(RecordError::Stopped(failure)) => RecordingFailure {
                path,
                disk_full: matches!(failure, RecordFailure::DiskFull { .. }),
                error: failure.to_string(),
                time_us: unix_time_us(),
            },
            Err(error) => RecordingFailure {
                path,
                disk_full: false,
                error: error_chain(&error),
                time_us: unix_time_us(),
            },
            Ok(_) => RecordingFailure {
                path,
                disk_full: false,
                error: "the recorder stopped writing".into(),
                time_us: unix_time_us(),
            },
        };
        tracing::error!("recording {} stopped: {}", failure.path, failure.error);
        slot.failed = Some(failure);
    }

    fn latest(&self) -> Option<ProcessedFrame> {
        self.latest.read().unwrap_or_else(PoisonError::into_inner).clone()
    }
}

/// An error and its causes, outermost first ("MCAP error in x.mcap: I/O error: No space left on device").
pub fn error_chain(error: &(dyn std::error::Error + 'static)) -> String {
    let mut text = error.to_string();
    let mut source = error.source();
    while let Some(cause) = source {
        let cause_text = cause.to_string();
        if !text.contains(&cause_text) {
            text.push_str(": ");
            text.push_str(&cause_text);
        }
        source = cause.source();
    }
    text
}

struct QueuedFrame {
    frame_id: u64,
    captured_at: Instant,
    capture_time_us: u64,
    pixels: FramePixels,
}

/// Cheap to clone; what the API holds.
#[derive(Clone)]
pub struct PipelineHandle {
    shared: Arc<Shared>,
}

/// Owns the threads; dropping it stops them.
pub struct Pipeline {
    handle: PipelineHandle,
    threads: Vec<JoinHandle<()>>,
}

impl Pipeline {
    pub fn start(
        source: Box<dyn FrameSource>,
        board: Arc<dyn Board>,
        options: PipelineOptions,
    ) -> Result<Self, PipelineError> {
        let shared = Arc::new(Shared::new(source.info(), board.clone(), &options));
        let mut threads = Vec::new();
        let mut spawn = |name: &'static str, run: Box<dyn FnOnce(&Shared) + Send>| -> Result<(), PipelineError> {
            let thread_shared = shared.clone();
            let thread = std::thread::Builder::new()
                .name(name.into())
                .spawn(move || run(&thread_shared))
                .map_err(|e| PipelineError::Thread(name, e))?;
            threads.push(thread);
            Ok(())
        };
        spawn("capture", Box::new(move |shared: &Shared| capture_loop(source, shared)))?;
        let decode = DecodeStage::new(options.mode, options.decode_scale);
        let decode_region = options.decode_region && options.mode != Mode::Paper;
        let estimate = EstimateStage::new(options.config, options.mode, decode_region);
        match options.stages {
            Stages::Overlapped => {
                spawn("decode", Box::new(move |shared: &Shared| decode.run(shared)))?;
                spawn("estimator", Box::new(move |shared: &Shared| estimate.run(shared)))?;
            }
            Stages::OneThread => spawn(
                "estimator",
                Box::new(move |shared: &Shared| stages::run_one_thread(decode, estimate, shared)),
            )?,
        }
        if let Some(events) = board.events() {
            spawn(
                "telemetry",
                Box::new(move |shared: &Shared| telemetry_loop(events, shared)),
            )?;
        }
        Ok(Self {
            handle: PipelineHandle { shared },
            threads,
        })
    }

    pub fn handle(&self) -> PipelineHandle {
        self.handle.clone()
    }
}

impl Drop for Pipeline {
    fn drop(&mut self) {
        self.handle.shared.stop.store(true, Ordering::Relaxed);
        for thread in self.threads.drain(..) {
            let _ = thread.join();
        }
        let recorder = lock(&self.handle.shared.recording).active.take();
        if let Some(recorder) = recorder {
            match recorder.finish() {
                Ok(summary) => tracing::info!(
                    "recording {} finished: {} frames, {} readings",
                    summary.path,
                    summary.frames,
                    summary.readings
                ),
                Err(error) => tracing::error!("recording did not finish cleanly: {}", error_chain(&error)),
            }
        }
    }
}

fn capture_loop(mut source: Box<dyn FrameSource>, shared: &Shared) {
    let mut next_id: u64 = 0;
    let mut backoff = REOPEN_BACKOFF_MIN;
    while !shared.stop.load(Ordering::Relaxed) {
        match source.next_frame() {
            Ok(frame) => {
                backoff = REOPEN_BACKOFF_MIN;
                let frame_id = next_id;
                next_id += 1;
                shared.counters.frames_captured.fetch_add(1, Ordering::Relaxed);
                shared.record(|| RecordItem::Frame {
                    frame_id,
                    capture_time_us: frame.capture_time_us,
                    pixels: frame.pixels.clone(),
                });
                shared.queue.push(QueuedFrame {
                    frame_id,
                    captured_at: frame.captured_at,
                    capture_time_us: frame.capture_time_us,
                    pixels: frame.pixels,
                });
            }
            Err(CaptureError::EndOfStream) => {
                let mut state = lock(&shared.capture_state);
                state.running = false;
                state.finished = true;
                tracing::info!("capture: the source has no more frames");
                return;
            }
            Err(error) if error.is_transient() => {
                shared.counters.capture_errors.fetch_add(1, Ordering::Relaxed);
                tracing::warn!("capture: {error}; retrying in {} ms", backoff.as_millis());
                {
                    let mut state = lock(&shared.capture_state);
                    state.running = false;
                    state.last_error = Some(error.to_string());
                }
                sleep_unless_stopped(backoff, shared);
                backoff = (backoff * 2).min(REOPEN_BACKOFF_MAX);
                match source.reopen() {
                    Ok(()) => {
                        let mut state = lock(&shared.capture_state);
                        state.running = true;
                        state.reconnects += 1;
                        *lock(&shared.source_info) = source.info();
                        tracing::info!("capture: {} is back", source.info().name);
                    }
                    Err(error) => {
                        lock(&shared.capture_state).last_error = Some(error.to_string());
                    }
                }
            }
            Err(error) => {
                // A frame that cannot be read is lost; the next one may be fine.
                shared.counters.capture_errors.fetch_add(1, Ordering::Relaxed);
                lock(&shared.capture_state).last_error = Some(error.to_string());
                tracing::warn!("capture: {error}");
            }
        }
    }
}

fn sleep_unless_stopped(duration: Duration, shared: &Shared) {
    let until = Instant::now() + duration;
    while Instant::now() < until && !shared.stop.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(20).min(until.saturating_duration_since(Instant::now())));
    }
}

/// `value` as JSON; a failure is logged and counted in `counter` (see [`EncodeError`]).
fn encode_json<T: Serialize>(value: &T, what: &'static str, counter: &AtomicU64) -> Result<String, EncodeError> {
    serde_json::to_string(value).map_err(|source| {
        let error = EncodeError { what, source };
        counter.fetch_add(1, Ordering::Relaxed);
        tracing::error!("{}", error_chain(&error));
        error
    })
}

fn publish(shared: &Shared, frame: QueuedFrame, mut message: ReadingMessage) {
    let encode_errors = &shared.counters.encode_errors;
    let json = match encode_json(&message, "reading", encode_errors) {
        Ok(json) => json,
        Err(error) => {
            // The estimate is the one part made elsewhere (the estimator's crate, through its flat wire form):
            // publish the frame without it, saying why, so that clients still see the frame go by.
            message.estimate = None;
            message.error = Some(error_chain(&error));
            match encode_json(&message, "reading without its estimate", encode_errors) {
                Ok(json) => json,
                // Nothing is published for this frame; it is counted in the status.
                Err(_) => return,
            }
        }
    };
    let published = Arc::new(PublishedReading { message, json });
    shared.record(|| RecordItem::Reading(published.clone()));
    *shared.latest.write().unwrap_or_else(PoisonError::into_inner) = Some(ProcessedFrame {
        frame_id: frame.frame_id,
        pixels: frame.pixels,
        reading: published.clone(),
    });
    // No subscribers is fine: nobody is watching.
    let _ = shared.readings.send(published);
}

/// Board telemetry as it arrives, into the recording (typed, timestamped, serialised once here).
fn telemetry_loop(events: std::sync::mpsc::Receiver<BoardEvent>, shared: &Shared) {
    #[derive(Serialize)]
    struct TimedTelemetry<'a> {
        schema_version: u32,
        time_us: u64,
        telemetry: &'a nusense_protocol::Telemetry,
    }
    while !shared.stop.load(Ordering::Relaxed) {
        match events.recv_timeout(POLL_INTERVAL) {
            Ok(BoardEvent::Telemetry(telemetry)) => {
                let time_us = unix_time_us();
                shared.record_if_some(|| {
                    let message = TimedTelemetry {
                        schema_version: SCHEMA_VERSION,
                        time_us,
                        telemetry: &telemetry,
                    };
                    let json = encode_json(&message, "board telemetry", &shared.counters.encode_errors).ok()?;
                    Some(RecordItem::Telemetry {
                        time_us,
                        json: json.into(),
                    })
                });
            }
            Ok(_) => {}
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {}
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => return,
        }
    }
}

/// Pipeline statistics for `/api/status`.
#[derive(Clone, Debug, Serialize)]
pub struct PipelineStatus {
    pub source: SourceInfo,
    pub capture_running: bool,
    pub capture_finished: bool,
    pub capture_error: Option<String>,
    pub capture_reconnects: u64,
    pub mode: Mode,
    pub uptime_s: f64,
    pub frames_captured: u64,
    pub frames_processed: u64,
    /// Frames a stage could not keep up with (drop-oldest queues), all stages together.
    pub frames_dropped: u64,
    pub frames_dropped_by_stage: StageDrops,
    /// Whether decoding and estimation overlap.
    pub stages: Stages,
    pub capture_errors: u64,
    pub estimate_errors: u64,
    /// Readings and telemetry messages that could not be written as JSON ([`EncodeError`]): logged, not sent.
    pub encode_errors: u64,
    pub tares: u64,
    /// Capture timestamp to reading, decoding included.
    pub latency_ms: LatencySummary,
    pub stage_latency_ms: StageLatency,
    pub decode: DecodeStatus,
    /// The recording running now.
    pub recording: Option<RecordingStatus>,
    /// How the last recording failed, when it stopped by itself (cleared when the next one starts).
    pub recording_failure: Option<RecordingFailure>,
}

/// Frames dropped in front of each stage because it was still busy with earlier ones.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct StageDrops {
    /// Captured frames the decoder did not get to.
    pub decode: u64,
    /// Decoded frames the estimator did not get to ([`Stages::Overlapped`] only).
    pub estimate: u64,
}

impl StageDrops {
    pub fn total(&self) -> u64 {
        self.decode + self.estimate
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct RecordingStatus {
    pub path: String,
    pub frames: u64,
    pub readings: u64,
    pub telemetry: u64,
    pub dropped: u64,
    /// Bytes waiting for the disk (bounded by the recorder's queue).
    pub queued_bytes: u64,
    /// The recording stopped on its own (disk full, write error): why, for the status and the dashboard.
    pub failure: Option<RecordFailure>,
}

impl PipelineHandle {
    /// Readings from now on. A receiver that falls `broadcast_len` behind skips the oldest (it learns how many).
    pub fn subscribe(&self) -> broadcast::Receiver<Arc<PublishedReading>> {
        self.shared.readings.subscribe()
    }

    pub fn latest_reading(&self) -> Option<Arc<PublishedReading>> {
        self.shared.latest().map(|processed| processed.reading)
    }

    /// The newest frame that has its reading, with that reading.
    pub fn latest_processed(&self) -> Option<ProcessedFrame> {
        self.shared.latest()
    }

    /// The next frame becomes the rest frame.
    pub fn request_tare(&self) {
        self.shared.tares_requested.fetch_add(1, Ordering::Release);
    }

    pub fn board(&self) -> &Arc<dyn Board> {
        &self.shared.board
    }

    pub fn frames_dropped(&self) -> u64 {
        self.shared.dropped().total()
    }

    pub fn frames_processed(&self) -> u64 {
        self.shared.counters.frames_processed.load(Ordering::Relaxed)
    }

    pub fn start_recording(&self, path: &Path, options: RecorderOptions) -> Result<(), PipelineError> {
        let mut slot = lock(&self.shared.recording);
        if let Some(recorder) = slot.active.as_ref() {
            return Err(PipelineError::AlreadyRecording(recorder.path().display().to_string()));
        }
        slot.active = Some(Recorder::create(path, options)?);
        slot.failed = None;
        Ok(())
    }

    pub fn stop_recording(&self) -> Result<RecordSummary, PipelineError> {
        let recorder = lock(&self.shared.recording).active.take();
        Ok(recorder.ok_or(PipelineError::NotRecording)?.finish()?)
    }

    /// The file being recorded to now.
    pub fn recording_path(&self) -> Option<PathBuf> {
        lock(&self.shared.recording)
            .active
            .as_ref()
            .map(|recorder| recorder.path().to_path_buf())
    }

    pub fn status(&self) -> PipelineStatus {
        let shared = &self.shared;
        let capture = lock(&shared.capture_state).clone();
        let slot = lock(&shared.recording);
        let recording_failure = slot.failed.clone();
        let recording = slot.active.as_ref().map(|r| {
            let stats = r.stats();
            RecordingStatus {
                path: r.path().display().to_string(),
                frames: stats.frames.load(Ordering::Relaxed),
                readings: stats.readings.load(Ordering::Relaxed),
                telemetry: stats.telemetry.load(Ordering::Relaxed),
                dropped: stats.dropped.load(Ordering::Relaxed),
                queued_bytes: stats.queued_bytes.load(Ordering::Relaxed),
                failure: r.failure(),
            }
        });
        drop(slot);
        PipelineStatus {
            source: lock(&shared.source_info).clone(),
            capture_running: capture.running,
            capture_finished: capture.finished,
            capture_error: capture.last_error,
            capture_reconnects: capture.reconnects,
            mode: shared.mode,
            uptime_s: shared.started.elapsed().as_secs_f64(),
            frames_captured: shared.counters.frames_captured.load(Ordering::Relaxed),
            frames_processed: shared.counters.frames_processed.load(Ordering::Relaxed),
            frames_dropped: shared.dropped().total(),
            frames_dropped_by_stage: shared.dropped(),
            stages: shared.stages,
            capture_errors: shared.counters.capture_errors.load(Ordering::Relaxed),
            estimate_errors: shared.counters.estimate_errors.load(Ordering::Relaxed),
            encode_errors: shared.counters.encode_errors.load(Ordering::Relaxed),
            tares: shared.counters.tares.load(Ordering::Relaxed),
            latency_ms: lock(&shared.latency).summary(),
            stage_latency_ms: {
                let stages = lock(&shared.stage_latency);
                StageLatency {
                    capture_to_decode: stages.capture_to_decode.summary(),
                    decode_to_estimate: stages.decode_to_estimate.summary(),
                    estimate_to_publish: stages.estimate_to_publish.summary(),
                }
            },
            decode: DecodeStatus {
                errors: shared.counters.decode_errors.load(Ordering::Relaxed),
                ..lock(&shared.decode).clone()
            },
            recording,
            recording_failure,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A value whose serialisation fails, as a future type with a non-string map key or a failing
    /// `Serialize` would.
    struct Unwritable;

    impl Serialize for Unwritable {
        fn serialize<S: serde::Serializer>(&self, _: S) -> Result<S::Ok, S::Error> {
            Err(serde::ser::Error::custom("no JSON for this"))
        }
    }

    fn message(latency_ms: f64) -> ReadingMessage {
        ReadingMessage {
            schema_version: SCHEMA_VERSION,
            frame_id: 7,
            file: None,
            capture_time_us: 1,
            processed_time_us: 2,
            latency_ms,
            queue_ms: f64::INFINITY,
            reference_frame_id: Some(0),
            estimate: None,
            error: None,
            led: None,
        }
    }

    #[test]
    fn a_message_that_cannot_be_written_is_a_typed_error_and_counted_never_an_empty_string() {
        let counter = AtomicU64::new(0);
        let error = encode_json(&Unwritable, "reading", &counter).unwrap_err();
        assert_eq!(counter.load(Ordering::Relaxed), 1);
        assert_eq!(
            error_chain(&error),
            "the reading could not be written as JSON: no JSON for this"
        );
        encode_json(&Unwritable, "board telemetry", &counter).unwrap_err();
        assert_eq!(counter.load(Ordering::Relaxed), 2);
    }

    /// Why the error is not expected: serde_json writes a non-finite number as null instead of failing.
    #[test]
    fn non_finite_numbers_are_written_as_null() {
        let counter = AtomicU64::new(0);
        let json = encode_json(&message(f64::NAN), "reading", &counter).unwrap();
        let value: serde_json::Value = serde_json::from_str(&json).unwrap();
        assert_eq!(value["latency_ms"], serde_json::Value::Null);
        assert_eq!(value["queue_ms"], serde_json::Value::Null);
        assert_eq!(value["frame_id"], 7);
        assert_eq!(counter.load(Ordering::Relaxed), 0);
    }
}
