use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use base64::Engine;
use mcap::records::MessageHeader;
use serde::Serialize;

use super::{RecordError, FRAME_SCHEMA, FRAME_TOPIC, READING_SCHEMA, READING_TOPIC, TELEMETRY_SCHEMA, TELEMETRY_TOPIC};

#[derive(Clone, Debug)]
pub struct RecorderOptions {
    /// A chunk is closed when it grows past this many bytes...
    pub chunk_bytes: u64,
    /// ...or when it has been open this long, whichever comes first: the most a crash can lose.
    pub flush_interval: Duration,
    /// Items waiting for the disk; beyond this they are dropped and counted rather than stalling the pipeline.
    pub queue_len: usize,
}

impl Default for RecorderOptions {
    fn default() -> Self {
        Self {
            chunk_bytes: 512 * 1024,
            flush_interval: Duration::from_millis(500),
            queue_len: 256,
        }
    }
}

/// What goes into a recording. JSON payloads are serialised once by the producer and shared.
#[derive(Clone, Debug)]
pub enum RecordItem {
    /// The writer thread encodes `image` when the source gave no JPEG, keeping that cost off the capture path.
    Frame {
        frame_id: u64,
        capture_time_us: u64,
        image: Arc<image::RgbImage>,
        jpeg: Option<Arc<Vec<u8>>>,
    },
    Reading {
        frame_id: u64,
        time_us: u64,
        json: Arc<str>,
    },
    Telemetry {
        time_us: u64,
        json: Arc<str>,
    },
}

#[derive(Debug, Default)]
pub struct RecordStats {
    pub frames: AtomicU64,
    pub readings: AtomicU64,
    pub telemetry: AtomicU64,
    /// Items dropped because the disk could not keep up.
    pub dropped: AtomicU64,
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
    sender: Option<SyncSender<RecordItem>>,
    stats: Arc<RecordStats>,
    thread: Option<JoinHandle<Result<(), RecordError>>>,
}

impl Recorder {
    pub fn create(path: &Path, options: RecorderOptions) -> Result<Self, RecordError> {
        let path_text = path.display().to_string();
        let file = File::create(path).map_err(|source| RecordError::Create {
            path: path_text.clone(),
            source,
        })?;
        let mcap_error = |source| RecordError::Mcap {
            path: path_text.clone(),
            source,
        };
        let mut writer = mcap::WriteOptions::new()
            .profile("nusense")
            .chunk_size(Some(options.chunk_bytes))
            .create(BufWriter::new(file))
            .map_err(mcap_error)?;
        let mut channel = |topic: &str, schema_name: &str, schema: &str| -> Result<u16, RecordError> {
            let schema_id = writer
                .add_schema(schema_name, "jsonschema", schema.as_bytes())
                .map_err(mcap_error)?;
            writer
                .add_channel(schema_id, topic, "json", &BTreeMap::new())
                .map_err(mcap_error)
        };
        let channels = Channels {
            frame: channel(FRAME_TOPIC, "foxglove.CompressedImage", FRAME_SCHEMA)?,
            reading: channel(READING_TOPIC, "nusense.Reading", READING_SCHEMA)?,
            telemetry: channel(TELEMETRY_TOPIC, "nusense.BoardTelemetry", TELEMETRY_SCHEMA)?,
        };
        // Schemas and channels reach the disk before any message, so even a file killed in its first chunk
        // tells a reader what it holds.
        writer.flush().map_err(mcap_error)?;
        let (sender, receiver) = sync_channel(options.queue_len.max(1));
        let stats = Arc::new(RecordStats::default());
        let thread_stats = stats.clone();
        let thread_path = path_text.clone();
        let thread = std::thread::Builder::new()
            .name("recorder".into())
            .spawn(move || write_loop(writer, channels, receiver, options, thread_stats, thread_path))
            .map_err(|source| RecordError::Create {
                path: path_text,
                source,
            })?;
        Ok(Self {
            path: path.to_path_buf(),
            sender: Some(sender),
            stats,
            thread: Some(thread),
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn stats(&self) -> &Arc<RecordStats> {
        &self.stats
    }

    /// Queues an item; when the writer is behind, the item is dropped and counted.
    pub fn record(&self, item: RecordItem) {
        let Some(sender) = &self.sender else { return };
        match sender.try_send(item) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) | Err(TrySendError::Disconnected(_)) => {
                self.stats.dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// Writes what is queued, the summary and the footer.
    pub fn finish(mut self) -> Result<RecordSummary, RecordError> {
        self.stop()
    }

    fn stop(&mut self) -> Result<RecordSummary, RecordError> {
        self.sender = None;
        if let Some(thread) = self.thread.take() {
            thread.join().map_err(|_| RecordError::WriterGone)??;
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

struct Channels {
    frame: u16,
    reading: u16,
    telemetry: u16,
}

#[derive(Serialize)]
struct CompressedImage<'a> {
    timestamp: Timestamp,
    frame_id: &'a str,
    data: String,
    format: &'a str,
}

#[derive(Serialize)]
struct Timestamp {
    sec: u64,
    nsec: u32,
}

fn write_loop(
    mut writer: mcap::Writer<BufWriter<File>>,
    channels: Channels,
    receiver: Receiver<RecordItem>,
    options: RecorderOptions,
    stats: Arc<RecordStats>,
    path: String,
) -> Result<(), RecordError> {
    let mcap_error = |source| RecordError::Mcap {
        path: path.clone(),
        source,
    };
    let mut last_flush = Instant::now();
    let mut sequence = [0u32; 3];
    loop {
        let wait = options.flush_interval.saturating_sub(last_flush.elapsed());
        let item = match receiver.recv_timeout(wait) {
            Ok(item) => Some(item),
            Err(RecvTimeoutError::Timeout) => None,
            Err(RecvTimeoutError::Disconnected) => break,
        };
        if let Some(item) = item {
            let (channel, slot, time_us, payload, counter) = match item {
                RecordItem::Frame {
                    frame_id,
                    capture_time_us,
                    image,
                    jpeg,
                } => {
                    let jpeg = match jpeg {
                        Some(jpeg) => jpeg,
                        None => Arc::new(encode_jpeg(&image, FRAME_JPEG_QUALITY)),
                    };
                    let message = CompressedImage {
                        timestamp: Timestamp {
                            sec: capture_time_us / 1_000_000,
                            nsec: (capture_time_us % 1_000_000) as u32 * 1000,
                        },
                        frame_id: "camera",
                        data: base64::engine::general_purpose::STANDARD.encode(jpeg.as_slice()),
                        format: "jpeg",
                    };
                    let json = serde_json::to_vec(&message).unwrap_or_default();
                    sequence[0] = frame_id as u32;
                    (channels.frame, 0, capture_time_us, json, &stats.frames)
                }
                RecordItem::Reading {
                    frame_id,
                    time_us,
                    json,
                } => {
                    sequence[1] = frame_id as u32;
                    (channels.reading, 1, time_us, json.as_bytes().to_vec(), &stats.readings)
                }
                RecordItem::Telemetry { time_us, json } => {
                    sequence[2] = sequence[2].wrapping_add(1);
                    (
                        channels.telemetry,
                        2,
                        time_us,
                        json.as_bytes().to_vec(),
                        &stats.telemetry,
                    )
                }
            };
            let header = MessageHeader {
                channel_id: channel,
                sequence: sequence[slot],
                log_time: time_us.saturating_mul(1000),
                publish_time: time_us.saturating_mul(1000),
            };
            writer.write_to_known_channel(&header, &payload).map_err(mcap_error)?;
            counter.fetch_add(1, Ordering::Relaxed);
        }
        if last_flush.elapsed() >= options.flush_interval {
            // Closes the open chunk and pushes it to the file: the crash-safety point.
            writer.flush().map_err(mcap_error)?;
            last_flush = Instant::now();
        }
    }
    writer.finish().map_err(mcap_error)?;
    Ok(())
}

/// Quality of frames the recorder compresses itself: the lattice corners must survive it.
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
