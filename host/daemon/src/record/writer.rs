//! The recorder: a writer thread fed by a queue bounded in bytes, writing whole chunks and fsyncing them.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{channel, Receiver, RecvTimeoutError, Sender};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use mcap::records::MessageHeader;
use mcap::write::NoSeek;
use serde::Serialize;

use super::messages::{self, channel_table, Kind};
use super::{RecordError, RecordFailure};
use crate::pipeline::PublishedReading;
use nusense_capture::FramePixels;

/// How long a chunk may stay open by default: a power cut loses at most this much (plus the time the disk takes
/// to complete the fsync), a SIGKILL at most the same (the kernel keeps what was written).
pub const DEFAULT_FLUSH_INTERVAL: Duration = Duration::from_millis(500);
/// Chunks close at this size even before the interval: bounds the in-memory chunk.
pub const DEFAULT_CHUNK_BYTES: u64 = 1024 * 1024;
/// Items waiting for the writer thread, in bytes (JPEG bytes for frames that came compressed, raw RGB bytes for
/// frames the writer must still compress); beyond it items are dropped and counted, never blocking capture.
pub const DEFAULT_QUEUE_BYTES: u64 = 32 * 1024 * 1024;

#[derive(Clone, Debug)]
pub struct RecorderOptions {
    /// A chunk is closed when it grows past this many bytes...
    pub chunk_bytes: u64,
    /// ...or when it has been open this long, whichever comes first. Each close is followed by an fsync.
    pub flush_interval: Duration,
    /// Bytes waiting for the writer thread before new items are dropped.
    pub queue_bytes: u64,
    /// The sensor and its configuration: the camera calibration channel and the file's metadata records.
    pub sensor: Option<SensorContext>,
}

/// What a recording says about the sensor that made it.
#[derive(Clone, Debug)]
pub struct SensorContext {
    pub config: nusense_estimator::SensorConfig,
    /// Identity of the sensor and of the source (serial numbers, device, frame size...), as metadata key/values.
    pub identity: BTreeMap<String, String>,
}

impl SensorContext {
    /// The MCAP metadata records: `nusense.sensor` (identity), `nusense.config` (the whole configuration as
    /// JSON) and `nusense.calibration` (the lens and the force calibration, each as JSON).
    fn metadata(&self) -> Vec<mcap::records::Metadata> {
        let json = |value: serde_json::Result<String>| value.unwrap_or_else(|e| format!("not serialisable: {e}"));
        let mut identity = self.identity.clone();
        identity.insert("nusense_version".into(), env!("CARGO_PKG_VERSION").into());
        vec![
            mcap::records::Metadata {
                name: "nusense.sensor".into(),
                metadata: identity,
            },
            mcap::records::Metadata {
                name: "nusense.config".into(),
                metadata: BTreeMap::from([("json".into(), json(serde_json::to_string(&self.config)))]),
            },
            mcap::records::Metadata {
                name: "nusense.calibration".into(),
                metadata: BTreeMap::from([
                    ("lens".into(), json(serde_json::to_string(&self.config.camera))),
                    ("force".into(), json(serde_json::to_string(&self.config.calibration))),
                ]),
            },
        ]
    }
}

impl Default for RecorderOptions {
    fn default() -> Self {
        Self {
            chunk_bytes: DEFAULT_CHUNK_BYTES,
            flush_interval: DEFAULT_FLUSH_INTERVAL,
            queue_bytes: DEFAULT_QUEUE_BYTES,
            sensor: None,
        }
    }
}

impl RecorderOptions {
    /// The most memory the recorder holds: the queue, the open chunk (it closes once it passes `chunk_bytes`,
    /// so it can exceed it by one message) and the file buffer.
    pub fn memory_bound_bytes(&self, largest_message_bytes: u64) -> u64 {
        self.queue_bytes + self.chunk_bytes + largest_message_bytes + FILE_BUFFER_BYTES as u64
    }
}

const FILE_BUFFER_BYTES: usize = 64 * 1024;

/// What goes into a recording. JSON payloads are serialised once by the producer and shared.
#[derive(Clone, Debug)]
pub enum RecordItem {
    /// The frame as the source delivered it: a camera's JPEG is recorded as it is; only a source without one
    /// (YUYV, the simulator) has the writer thread compress it, keeping that cost off the capture path.
    Frame {
        frame_id: u64,
        capture_time_us: u64,
        pixels: FramePixels,
    },
    /// The published reading: its JSON on the reading channel, and its annotations over the frame.
    Reading(Arc<PublishedReading>),
    Telemetry {
        time_us: u64,
        json: Arc<str>,
    },
}

impl RecordItem {
    /// What the item holds in memory while it waits: what the queue bound counts.
    fn queued_bytes(&self) -> u64 {
        let bytes = match self {
            RecordItem::Frame { pixels, .. } => pixels.byte_len(),
            RecordItem::Reading(published) => {
                let corners = published.message.estimate.as_ref().map_or(0, |e| e.shear_field.len());
                published.json.len() + corners * std::mem::size_of::<nusense_estimator::ShearVector>()
            }
            RecordItem::Telemetry { json, .. } => json.len(),
        };
        bytes as u64 + std::mem::size_of::<RecordItem>() as u64
    }
}

#[derive(Debug, Default)]
pub struct RecordStats {
    pub frames: AtomicU64,
    pub readings: AtomicU64,
    pub telemetry: AtomicU64,
    /// Items dropped because the disk could not keep up (the queue was full).
    pub dropped: AtomicU64,
    /// Bytes waiting for the writer thread now.
    pub queued_bytes: AtomicU64,
    /// Bytes known to be on the disk (written and fsynced).
    pub synced_bytes: AtomicU64,
}

#[derive(Clone, Debug, Serialize)]
pub struct RecordSummary {
    pub path: String,
    pub frames: u64,
    pub readings: u64,
    pub telemetry: u64,
    pub dropped: u64,
}

/// Writes a recording on its own thread; producers never block on the disk.
pub struct Recorder {
    path: PathBuf,
    sender: Option<Sender<RecordItem>>,
    stats: Arc<RecordStats>,
    failure: Arc<Mutex<Option<RecordFailure>>>,
    queue_bytes: u64,
    thread: Option<JoinHandle<()>>,
}

/// Where the chunks go: a file (fsynced, and cut back to its last whole chunk when a write fails) or, in tests,
/// any writer.
pub(crate) struct Destination {
    pub(crate) writer: Box<dyn Write + Send>,
    pub(crate) file: Option<File>,
}

impl Destination {
    fn create(path: &Path) -> Result<Self, RecordError> {
        let create_error = |source| RecordError::Create {
            path: path.display().to_string(),
            source,
        };
        let file = File::create(path).map_err(create_error)?;
        // The file's name must survive a power cut too, not only its bytes.
        if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
            if let Ok(dir) = File::open(parent) {
                let _ = dir.sync_all();
            }
        }
        let handle = file.try_clone().map_err(create_error)?;
        Ok(Self {
            writer: Box::new(file),
            file: Some(handle),
        })
    }
}

impl Recorder {
    pub fn create(path: &Path, options: RecorderOptions) -> Result<Self, RecordError> {
        let destination = Destination::create(path)?;
        Self::start(path, destination, options)
    }

    pub(crate) fn start(path: &Path, destination: Destination, options: RecorderOptions) -> Result<Self, RecordError> {
        let path_text = path.display().to_string();
        let Destination { writer, file } = destination;
        let mut writer = write_options(options.chunk_bytes)
            .create(NoSeek::new(BufWriter::with_capacity(FILE_BUFFER_BYTES, writer)))
            .map_err(|source| RecordError::from_mcap(&path_text, source))?;
        let mcap_error = |source| RecordError::from_mcap(&path_text, source);
        let mut channels = Vec::new();
        for spec in channel_table() {
            let schema_id = writer
                .add_schema(&spec.schema.name, &spec.schema.encoding, &spec.schema.data)
                .map_err(mcap_error)?;
            channels.push(
                writer
                    .add_channel(schema_id, spec.topic, &spec.message_encoding, &BTreeMap::new())
                    .map_err(mcap_error)?,
            );
        }
        for metadata in options.sensor.iter().flat_map(SensorContext::metadata) {
            writer.write_metadata(&metadata).map_err(mcap_error)?;
        }
        // Schemas and channels reach the disk before any message, so even a file killed in its first chunk
        // tells a reader what it holds.
        writer
            .flush()
            .map_err(|source| RecordError::from_mcap(&path_text, source))?;
        let mut durable = Durable { file, synced_len: 0 };
        durable.sync().map_err(|source| RecordError::Create {
            path: path_text.clone(),
            source,
        })?;
        let (sender, receiver) = channel();
        let stats = Arc::new(RecordStats::default());
        stats.synced_bytes.store(durable.synced_len, Ordering::Relaxed);
        let failure = Arc::new(Mutex::new(None));
        let state = WriterThread {
            writer: Some(writer),
            channels,
            durable,
            options: options.clone(),
            stats: stats.clone(),
            failure: failure.clone(),
            path: path_text.clone(),
            sequences: [0; 5],
            calibrated_size: None,
            unsynced: false,
        };
        let thread = std::thread::Builder::new()
            .name("recorder".into())
            .spawn(move || state.run(receiver))
            .map_err(|source| RecordError::Create {
                path: path_text,
                source,
            })?;
        Ok(Self {
            path: path.to_path_buf(),
            sender: Some(sender),
            stats,
            failure,
            queue_bytes: options.queue_bytes,
            thread: Some(thread),
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn stats(&self) -> &Arc<RecordStats> {
        &self.stats
    }

    /// Why the recording stopped on its own (the disk filled up, a write failed), if it did.
    pub fn failure(&self) -> Option<RecordFailure> {
        self.failure.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }

    /// Queues an item; when the queue already holds its bound in bytes, the item is dropped and counted.
    pub fn record(&self, item: RecordItem) {
        let Some(sender) = &self.sender else { return };
        let bytes = item.queued_bytes();
        let queued = self.stats.queued_bytes.fetch_add(bytes, Ordering::AcqRel);
        if queued + bytes > self.queue_bytes || sender.send(item).is_err() {
            self.stats.queued_bytes.fetch_sub(bytes, Ordering::AcqRel);
            self.stats.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Writes what is queued, the summary and the footer. A recording that stopped on its own returns why.
    pub fn finish(mut self) -> Result<RecordSummary, RecordError> {
        self.stop()
    }

    fn stop(&mut self) -> Result<RecordSummary, RecordError> {
        self.sender = None;
        if let Some(thread) = self.thread.take() {
            thread.join().map_err(|_| RecordError::WriterGone)?;
        }
        if let Some(failure) = self.failure() {
            return Err(RecordError::Stopped(failure));
        }
        Ok(RecordSummary {
            path: self.path.display().to_string(),
            frames: self.stats.frames.load(Ordering::Relaxed),
            readings: self.stats.readings.load(Ordering::Relaxed),
            telemetry: self.stats.telemetry.load(Ordering::Relaxed),
            dropped: self.stats.dropped.load(Ordering::Relaxed),
        })
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        if self.thread.is_some() {
            if let Err(error) = self.stop() {
                tracing::warn!("recording {} did not finish cleanly: {error}", self.path.display());
            }
        }
    }
}

/// The options every writer of recordings uses. Seeking disabled makes the mcap crate build each chunk in
/// memory and write it whole (header, length and CRC final), so no placeholder length ever reaches the disk and
/// a file cut at any byte is a prefix of a valid MCAP file.
pub(crate) fn write_options(chunk_bytes: u64) -> mcap::WriteOptions {
    mcap::WriteOptions::new()
        .profile("nusense")
        .chunk_size(Some(chunk_bytes))
        .disable_seeking(true)
}

pub(crate) type McapFileWriter = mcap::Writer<NoSeek<BufWriter<Box<dyn Write + Send>>>>;

/// The file behind the writer, for fsync and for cutting a failed write back off.
struct Durable {
    file: Option<File>,
    /// File length at the last successful fsync: a whole number of records.
    synced_len: u64,
}

impl Durable {
    fn sync(&mut self) -> std::io::Result<()> {
        if let Some(file) = &self.file {
            file.sync_data()?;
            self.synced_len = file.metadata()?.len();
        }
        Ok(())
    }

    /// After a failed write: drop whatever part of a record reached the file, so that it ends on a whole chunk.
    fn cut_back(&mut self) {
        if let Some(file) = &self.file {
            if file.set_len(self.synced_len).and_then(|()| file.sync_data()).is_err() {
                tracing::warn!("cannot cut the recording back to its last whole chunk; readers stop there anyway");
            }
        }
    }
}

struct WriterThread {
    writer: Option<McapFileWriter>,
    /// Channel ids by [`Kind`].
    channels: Vec<u16>,
    durable: Durable,
    options: RecorderOptions,
    stats: Arc<RecordStats>,
    failure: Arc<Mutex<Option<RecordFailure>>>,
    path: String,
    sequences: [u32; 5],
    /// The frame size the last calibration message was for.
    calibrated_size: Option<(u32, u32)>,
    /// Bytes were handed to the writer since the last fsync.
    unsynced: bool,
}

impl WriterThread {
    fn run(mut self, receiver: Receiver<RecordItem>) {
        let mut last_flush = Instant::now();
        loop {
            let wait = self.options.flush_interval.saturating_sub(last_flush.elapsed());
            match receiver.recv_timeout(wait) {
                Ok(item) => {
                    let bytes = item.queued_bytes();
                    let result = self.write(item);
                    self.stats.queued_bytes.fetch_sub(bytes, Ordering::AcqRel);
                    if let Err(error) = result {
                        return self.fail(error, receiver);
                    }
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => break,
            }
            if last_flush.elapsed() >= self.options.flush_interval {
                if let Err(error) = self.flush() {
                    return self.fail(error, receiver);
                }
                last_flush = Instant::now();
            }
        }
        if let Err(error) = self.finish() {
            self.fail(error, receiver);
        }
    }

    fn write(&mut self, item: RecordItem) -> Result<(), std::io::Error> {
        match item {
            RecordItem::Frame {
                frame_id,
                capture_time_us,
                pixels,
            } => {
                let (jpeg, size) = match &pixels {
                    // A camera's bytes are recorded as they came, even a frame that does not decode.
                    FramePixels::Jpeg(jpeg) => (jpeg.clone(), pixels.dimensions().ok()),
                    FramePixels::Rgb(image) => (
                        Arc::new(encode_jpeg(image, FRAME_JPEG_QUALITY)),
                        Some(image.dimensions()),
                    ),
                    FramePixels::Yuyv { .. } => match pixels.to_rgb() {
                        Ok(image) => (
                            Arc::new(encode_jpeg(&image, FRAME_JPEG_QUALITY)),
                            Some(image.dimensions()),
                        ),
                        Err(error) => {
                            tracing::warn!("recording: frame {frame_id} is not recorded: {error}");
                            self.stats.dropped.fetch_add(1, Ordering::Relaxed);
                            return Ok(());
                        }
                    },
                };
                if let (Some(sensor), Some(size)) =
                    (&self.options.sensor, size.filter(|s| self.calibrated_size != Some(*s)))
                {
                    let calibration = messages::calibration(capture_time_us, &sensor.config, size.0, size.1);
                    self.calibrated_size = Some(size);
                    let sequence = self.next_sequence(Kind::Calibration);
                    self.put(Kind::Calibration, sequence, capture_time_us, &calibration)?;
                }
                self.put(
                    Kind::Frame,
                    frame_id as u32,
                    capture_time_us,
                    &messages::frame(capture_time_us, &jpeg),
                )?;
                self.stats.frames.fetch_add(1, Ordering::Relaxed);
            }
            RecordItem::Reading(published) => {
                let frame_id = published.message.frame_id as u32;
                let time_us = published.message.capture_time_us;
                if let Some(annotations) = messages::annotations(&published) {
                    self.put(Kind::Annotations, frame_id, time_us, &annotations)?;
                }
                self.put(Kind::Reading, frame_id, time_us, &messages::reading(&published))?;
                self.stats.readings.fetch_add(1, Ordering::Relaxed);
            }
            RecordItem::Telemetry { time_us, json } => {
                let sequence = self.next_sequence(Kind::Telemetry);
                self.put(Kind::Telemetry, sequence, time_us, &messages::telemetry(&json))?;
                self.stats.telemetry.fetch_add(1, Ordering::Relaxed);
            }
        }
        Ok(())
    }

    fn next_sequence(&mut self, kind: Kind) -> u32 {
        let slot = &mut self.sequences[kind as usize];
        *slot = slot.wrapping_add(1);
        *slot
    }

    fn put(&mut self, kind: Kind, sequence: u32, time_us: u64, data: &[u8]) -> Result<(), std::io::Error> {
        let header = MessageHeader {
            channel_id: self.channels[kind as usize],
            sequence,
            log_time: time_us.saturating_mul(1000),
            publish_time: time_us.saturating_mul(1000),
        };
        let writer = self.writer.as_mut().ok_or_else(writer_gone)?;
        writer.write_to_known_channel(&header, data).map_err(into_io)?;
        self.unsynced = true;
        Ok(())
    }

    /// Closes the open chunk, writes it whole and fsyncs: the crash-safety point.
    fn flush(&mut self) -> Result<(), std::io::Error> {
        if !self.unsynced {
            return Ok(());
        }
        self.writer.as_mut().ok_or_else(writer_gone)?.flush().map_err(into_io)?;
        self.durable.sync()?;
        self.stats
            .synced_bytes
            .store(self.durable.synced_len, Ordering::Relaxed);
        self.unsynced = false;
        Ok(())
    }

    fn finish(&mut self) -> Result<(), std::io::Error> {
        let mut writer = self.writer.take().ok_or_else(writer_gone)?;
        writer.finish().map_err(into_io)?;
        // The BufWriter flushes when the writer drops; only then is everything in the file.
        let mut inner = writer.into_inner().into_inner();
        inner.flush()?;
        drop(inner);
        self.durable.sync()?;
        self.stats
            .synced_bytes
            .store(self.durable.synced_len, Ordering::Relaxed);
        Ok(())
    }

    /// A write failed: stop for good, keep the file ending on its last whole chunk, and say why.
    fn fail(mut self, error: std::io::Error, receiver: Receiver<RecordItem>) {
        // Dropping the writer tries to finish the file; whatever of that reaches the disk is cut off below.
        drop(self.writer.take());
        self.durable.cut_back();
        let failure = RecordFailure::from_io(&self.path, self.durable.synced_len, &error);
        tracing::error!("{failure}");
        *self.failure.lock().unwrap_or_else(|e| e.into_inner()) = Some(failure);
        // Producers may still be queueing: release what they hold and count it as lost.
        drop(receiver);
        self.stats.queued_bytes.store(0, Ordering::Release);
    }
}

fn into_io(error: mcap::McapError) -> std::io::Error {
    match error {
        mcap::McapError::Io(io) => io,
        other => std::io::Error::other(other),
    }
}

fn writer_gone() -> std::io::Error {
    std::io::Error::other("the recording was already closed")
}

/// Quality of frames the recorder compresses itself (sources without JPEG): the lattice corners must survive it.
const FRAME_JPEG_QUALITY: u8 = 90;

/// Encodes an RGB frame as JPEG.
pub fn encode_jpeg(image: &image::RgbImage, quality: u8) -> Vec<u8> {
    let mut bytes = Vec::new();
    let encoder = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, quality);
    // Writing to a Vec cannot fail for an RGB8 image of valid size.
    if let Err(error) = image.write_with_encoder(encoder) {
        tracing::warn!("cannot encode a frame as JPEG: {error}");
    }
    bytes
}
