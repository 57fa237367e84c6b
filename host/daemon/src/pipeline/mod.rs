//! The live pipeline: a capture thread feeds a bounded drop-oldest queue, an estimator thread turns frames
//! into readings, and readings are published (latest value, a broadcast for WebSocket clients, the recorder).
//!
//! The first frame, and the first frame after a tare, is the rest frame the estimator measures against.

mod board;
mod queue;
mod sources;
mod stats;

use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, RwLock};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use image::RgbImage;
use nusense_estimator::{Estimator, Mode, Reading, SensorConfig};
use serde::Serialize;
use tokio::sync::broadcast;

use crate::record::{RecordError, RecordFailure, RecordItem, RecordSummary, Recorder, RecorderOptions};
use nusense_capture::{unix_time_us, CaptureError, FrameSource, SourceInfo};

pub use board::{Board, BoardError, LedCommand, LedState, LinkedBoard, NoBoard, LED_LIMIT_MA};
pub use queue::DropOldestQueue;
pub use sources::{open_sources, BoardChoice, FrameChoice, SourceError, Sources};
pub use stats::{summarise, LatencySummary, LatencyWindow};

/// One processed frame, as served by the API and recorded.
#[derive(Clone, Debug, Serialize)]
pub struct DaemonReading {
    pub frame_id: u64,
    /// Microseconds since the Unix epoch.
    pub capture_time_us: u64,
    pub processed_time_us: u64,
    /// Capture to published reading.
    pub latency_ms: f64,
    /// Time the frame waited for the estimator.
    pub queue_ms: f64,
    /// The rest frame the estimate is measured against.
    pub reference_frame_id: Option<u64>,
    pub estimate: Option<Reading>,
    /// Why there is no estimate for this frame.
    pub error: Option<String>,
    pub led: Option<LedState>,
}

/// A reading with its JSON, serialised once for every consumer.
#[derive(Debug)]
pub struct PublishedReading {
    pub reading: DaemonReading,
    pub json: String,
}

/// The most recent frame, for `/api/frame.jpg`.
#[derive(Clone, Debug)]
pub struct FrameSnapshot {
    pub frame_id: u64,
    pub capture_time_us: u64,
    pub image: Arc<RgbImage>,
    pub jpeg: Option<Arc<Vec<u8>>>,
}

#[derive(Clone)]
pub struct PipelineOptions {
    pub config: SensorConfig,
    pub mode: Mode,
    /// Frames waiting for the estimator; beyond this the oldest is dropped (and counted).
    pub queue_len: usize,
    /// Readings a WebSocket client may fall behind by before it misses some.
    pub broadcast_len: usize,
}

impl PipelineOptions {
    pub fn new(config: SensorConfig, mode: Mode) -> Self {
        Self {
            config,
            mode,
            queue_len: 2,
            broadcast_len: 64,
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    #[error("cannot start the {0} thread: {1}")]
    Thread(&'static str, std::io::Error),
    #[error(transparent)]
    Record(#[from] RecordError),
    #[error("a recording is already running ({0})")]
    AlreadyRecording(String),
    #[error("no recording is running")]
    NotRecording,
}

#[derive(Debug, Default)]
struct Counters {
    frames_captured: AtomicU64,
    frames_processed: AtomicU64,
    capture_errors: AtomicU64,
    estimate_errors: AtomicU64,
    tares: AtomicU64,
}

#[derive(Clone, Debug, Default, Serialize)]
struct CaptureState {
    running: bool,
    /// The source ended (a recording played to its end).
    finished: bool,
    last_error: Option<String>,
    reconnects: u64,
}

struct Shared {
    source_info: Mutex<SourceInfo>,
    capture_state: Mutex<CaptureState>,
    queue: DropOldestQueue<QueuedFrame>,
    counters: Counters,
    latency: Mutex<LatencyWindow>,
    latest_reading: RwLock<Option<Arc<PublishedReading>>>,
    latest_frame: RwLock<Option<FrameSnapshot>>,
    readings: broadcast::Sender<Arc<PublishedReading>>,
    tare_requested: AtomicBool,
    stop: AtomicBool,
    recorder: Mutex<Option<Recorder>>,
    board: Arc<dyn Board>,
    mode: Mode,
    started: Instant,
}

struct QueuedFrame {
    frame_id: u64,
    captured_at: Instant,
    capture_time_us: u64,
    image: Arc<RgbImage>,
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
        let (readings, _) = broadcast::channel(options.broadcast_len.max(1));
        let shared = Arc::new(Shared {
            source_info: Mutex::new(source.info()),
            capture_state: Mutex::new(CaptureState {
                running: true,
                ..Default::default()
            }),
            queue: DropOldestQueue::new(options.queue_len),
            counters: Counters::default(),
            latency: Mutex::new(LatencyWindow::new(1024)),
            latest_reading: RwLock::new(None),
            latest_frame: RwLock::new(None),
            readings,
            tare_requested: AtomicBool::new(false),
            stop: AtomicBool::new(false),
            recorder: Mutex::new(None),
            board: board.clone(),
            mode: options.mode,
            started: Instant::now(),
        });
        let mut threads = Vec::new();
        let capture_shared = shared.clone();
        threads.push(
            std::thread::Builder::new()
                .name("capture".into())
                .spawn(move || capture_loop(source, &capture_shared))
                .map_err(|e| PipelineError::Thread("capture", e))?,
        );
        let estimate_shared = shared.clone();
        threads.push(
            std::thread::Builder::new()
                .name("estimator".into())
                .spawn(move || estimate_loop(options.config, options.mode, &estimate_shared))
                .map_err(|e| PipelineError::Thread("estimator", e))?,
        );
        if let Some(telemetry) = board.telemetry() {
            let telemetry_shared = shared.clone();
            threads.push(
                std::thread::Builder::new()
                    .name("telemetry".into())
                    .spawn(move || telemetry_loop(telemetry, &telemetry_shared))
                    .map_err(|e| PipelineError::Thread("telemetry", e))?,
            );
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
        if let Some(recorder) = self
            .handle
            .shared
            .recorder
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .take()
        {
            if let Err(error) = recorder.finish() {
                tracing::warn!("recording did not finish cleanly: {error}");
            }
        }
    }
}

fn capture_loop(mut source: Box<dyn FrameSource>, shared: &Shared) {
    let mut next_id: u64 = 0;
    let mut backoff = Duration::from_millis(250);
    while !shared.stop.load(Ordering::Relaxed) {
        match source.next_frame() {
            Ok(frame) => {
                backoff = Duration::from_millis(250);
                let frame_id = next_id;
                next_id += 1;
                shared.counters.frames_captured.fetch_add(1, Ordering::Relaxed);
                let image = Arc::new(frame.image);
                let jpeg = frame.jpeg.map(Arc::new);
                if let Some(recorder) = shared.recorder.lock().unwrap_or_else(|e| e.into_inner()).as_ref() {
                    recorder.record(RecordItem::Frame {
                        frame_id,
                        capture_time_us: frame.capture_time_us,
                        image: image.clone(),
                        jpeg: jpeg.clone(),
                    });
                }
                *shared.latest_frame.write().unwrap_or_else(|e| e.into_inner()) = Some(FrameSnapshot {
                    frame_id,
                    capture_time_us: frame.capture_time_us,
                    image: image.clone(),
                    jpeg,
                });
                shared.queue.push(QueuedFrame {
                    frame_id,
                    captured_at: frame.captured_at,
                    capture_time_us: frame.capture_time_us,
                    image,
                });
            }
            Err(CaptureError::EndOfStream) => {
                let mut state = shared.capture_state.lock().unwrap_or_else(|e| e.into_inner());
                state.running = false;
                state.finished = true;
                tracing::info!("capture: the source has no more frames");
                return;
            }
            Err(error) if error.is_transient() => {
                shared.counters.capture_errors.fetch_add(1, Ordering::Relaxed);
                tracing::warn!("capture: {error}; retrying in {} ms", backoff.as_millis());
                {
                    let mut state = shared.capture_state.lock().unwrap_or_else(|e| e.into_inner());
                    state.running = false;
                    state.last_error = Some(error.to_string());
                }
                sleep_unless_stopped(backoff, shared);
                backoff = (backoff * 2).min(Duration::from_secs(2));
                match source.reopen() {
                    Ok(()) => {
                        let mut state = shared.capture_state.lock().unwrap_or_else(|e| e.into_inner());
                        state.running = true;
                        state.reconnects += 1;
                        *shared.source_info.lock().unwrap_or_else(|e| e.into_inner()) = source.info();
                        tracing::info!("capture: {} is back", source.info().name);
                    }
                    Err(error) => {
                        shared
                            .capture_state
                            .lock()
                            .unwrap_or_else(|e| e.into_inner())
                            .last_error = Some(error.to_string());
                    }
                }
            }
            Err(error) => {
                // A frame that does not decode is lost; the next one may be fine.
                shared.counters.capture_errors.fetch_add(1, Ordering::Relaxed);
                shared
                    .capture_state
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .last_error = Some(error.to_string());
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

fn estimate_loop(config: SensorConfig, mode: Mode, shared: &Shared) {
    let mut estimator: Option<Estimator> = None;
    let mut reference_frame_id = None;
    while !shared.stop.load(Ordering::Relaxed) {
        let Some(frame) = shared.queue.pop_timeout(Duration::from_millis(50)) else {
            continue;
        };
        let dequeued_at = Instant::now();
        let mut error = None;
        if shared.tare_requested.swap(false, Ordering::Relaxed) {
            estimator = None;
        }
        if estimator.is_none() {
            match Estimator::new(config.clone(), mode, &frame.image) {
                Ok(new_estimator) => {
                    estimator = Some(new_estimator);
                    reference_frame_id = Some(frame.frame_id);
                    shared.counters.tares.fetch_add(1, Ordering::Relaxed);
                }
                Err(e) => error = Some(format!("no rest frame yet: {e}")),
            }
        }
        let estimate = match estimator.as_mut().map(|estimator| estimator.estimate(&frame.image)) {
            Some(Ok(reading)) => Some(reading),
            Some(Err(e)) => {
                error = Some(e.to_string());
                None
            }
            None => None,
        };
        if error.is_some() {
            shared.counters.estimate_errors.fetch_add(1, Ordering::Relaxed);
        }
        shared.counters.frames_processed.fetch_add(1, Ordering::Relaxed);
        let latency = frame.captured_at.elapsed();
        let reading = DaemonReading {
            frame_id: frame.frame_id,
            capture_time_us: frame.capture_time_us,
            processed_time_us: unix_time_us(),
            latency_ms: latency.as_secs_f64() * 1e3,
            queue_ms: dequeued_at.duration_since(frame.captured_at).as_secs_f64() * 1e3,
            reference_frame_id,
            estimate,
            error,
            led: shared.board.led_state(),
        };
        shared
            .latency
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(reading.latency_ms);
        publish(shared, reading);
    }
}

fn publish(shared: &Shared, reading: DaemonReading) {
    let json = serde_json::to_string(&reading).unwrap_or_else(|e| {
        // Only a non-finite number could fail here, and the estimator promises none; say so rather than panic.
        serde_json::json!({ "frame_id": reading.frame_id, "error": format!("reading not serialisable: {e}") })
            .to_string()
    });
    let published = Arc::new(PublishedReading { reading, json });
    if let Some(recorder) = shared.recorder.lock().unwrap_or_else(|e| e.into_inner()).as_ref() {
        recorder.record(RecordItem::Reading(published.clone()));
    }
    *shared.latest_reading.write().unwrap_or_else(|e| e.into_inner()) = Some(published.clone());
    // No subscribers is fine: nobody is watching.
    let _ = shared.readings.send(published);
}

fn telemetry_loop(telemetry: std::sync::mpsc::Receiver<String>, shared: &Shared) {
    while !shared.stop.load(Ordering::Relaxed) {
        match telemetry.recv_timeout(Duration::from_millis(100)) {
            Ok(json) => {
                if let Some(recorder) = shared.recorder.lock().unwrap_or_else(|e| e.into_inner()).as_ref() {
                    recorder.record(RecordItem::Telemetry {
                        time_us: unix_time_us(),
                        json: json.into(),
                    });
                }
            }
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
    /// Frames the estimator could not keep up with (drop-oldest queue).
    pub frames_dropped: u64,
    pub capture_errors: u64,
    pub estimate_errors: u64,
    pub tares: u64,
    pub latency_ms: LatencySummary,
    pub recording: Option<RecordingStatus>,
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
        self.shared
            .latest_reading
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    pub fn latest_frame(&self) -> Option<FrameSnapshot> {
        self.shared
            .latest_frame
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    /// The next frame becomes the rest frame.
    pub fn request_tare(&self) {
        self.shared.tare_requested.store(true, Ordering::Relaxed);
    }

    pub fn board(&self) -> &Arc<dyn Board> {
        &self.shared.board
    }

    pub fn frames_dropped(&self) -> u64 {
        self.shared.queue.dropped()
    }

    pub fn frames_processed(&self) -> u64 {
        self.shared.counters.frames_processed.load(Ordering::Relaxed)
    }

    pub fn start_recording(&self, path: &Path, options: RecorderOptions) -> Result<(), PipelineError> {
        let mut slot = self.shared.recorder.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(recorder) = slot.as_ref() {
            return Err(PipelineError::AlreadyRecording(recorder.path().display().to_string()));
        }
        *slot = Some(Recorder::create(path, options)?);
        Ok(())
    }

    pub fn stop_recording(&self) -> Result<RecordSummary, PipelineError> {
        let recorder = self.shared.recorder.lock().unwrap_or_else(|e| e.into_inner()).take();
        Ok(recorder.ok_or(PipelineError::NotRecording)?.finish()?)
    }

    pub fn status(&self) -> PipelineStatus {
        let shared = &self.shared;
        let capture = shared.capture_state.lock().unwrap_or_else(|e| e.into_inner()).clone();
        let recording = shared
            .recorder
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .as_ref()
            .map(|r| {
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
        PipelineStatus {
            source: shared.source_info.lock().unwrap_or_else(|e| e.into_inner()).clone(),
            capture_running: capture.running,
            capture_finished: capture.finished,
            capture_error: capture.last_error,
            capture_reconnects: capture.reconnects,
            mode: shared.mode,
            uptime_s: shared.started.elapsed().as_secs_f64(),
            frames_captured: shared.counters.frames_captured.load(Ordering::Relaxed),
            frames_processed: shared.counters.frames_processed.load(Ordering::Relaxed),
            frames_dropped: shared.queue.dropped(),
            capture_errors: shared.counters.capture_errors.load(Ordering::Relaxed),
            estimate_errors: shared.counters.estimate_errors.load(Ordering::Relaxed),
            tares: shared.counters.tares.load(Ordering::Relaxed),
            latency_ms: shared.latency.lock().unwrap_or_else(|e| e.into_inner()).summary(),
            recording,
        }
    }
}
