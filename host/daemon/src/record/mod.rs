//! Recordings: frames (the camera's JPEG), camera calibration, annotations, readings and board telemetry as MCAP
//! channels, with the Foxglove SDK's schemas where one fits (see `messages`).
//!
//! Crash safety: each chunk is built in memory and written whole (no placeholder length ever reaches the disk),
//! then fsynced, at least every [`RecorderOptions::flush_interval`] (500 ms by default). A recorder killed
//! without warning (SIGKILL) or a machine that loses power leaves a file that is a prefix of a valid MCAP file:
//! every MCAP reader reads it up to its last whole chunk, so at most the last interval is lost.
//! [`recover`] rewrites such a file with its summary and indexes.
//!
//! Memory: the queue between producers and the writer thread is bounded in bytes
//! ([`RecorderOptions::queue_bytes`]), the open chunk by [`RecorderOptions::chunk_bytes`]; replay streams from
//! disk a chunk at a time.

pub(crate) mod messages;
mod reader;
mod recover;
mod replay;
mod writer;

pub use messages::SHEAR_DRAW_GAIN;
pub(crate) use messages::{channel_table, Kind};
/// What [`RecordItem::Frame`] holds: the frame as its source delivered it.
pub use nusense_capture::FramePixels;
pub use reader::{
    ends_finished, read_recording, ChannelInfo, RecordedFrame, RecordedMessage, RecordedMetadata, Recording,
    RecordingReader, SchemaInfo,
};
pub use recover::{recover, RecoverSummary};
pub use replay::McapReplay;
pub use writer::{
    encode_jpeg, RecordItem, RecordStats, RecordSummary, Recorder, RecorderOptions, SensorContext, DEFAULT_CHUNK_BYTES,
    DEFAULT_FLUSH_INTERVAL, DEFAULT_QUEUE_BYTES,
};

/// Camera frames, as `foxglove.CompressedImage` so that Foxglove and other MCAP viewers show them.
pub const FRAME_TOPIC: &str = "/camera/image";
/// The fisheye lens for the frames' size, as `foxglove.CameraCalibration`; again whenever the size changes.
pub const CALIBRATION_TOPIC: &str = "/camera/calibration";
/// Each reading drawn over its frame, as `foxglove.ImageAnnotations`: lattice corners, shear vectors, contact and
/// force.
pub const ANNOTATIONS_TOPIC: &str = "/camera/annotations";
/// One [`crate::ReadingMessage`] per processed frame.
pub const READING_TOPIC: &str = "/nusense/reading";
/// Board telemetry (LED channels, temperature, supply) as the board reported it.
pub const TELEMETRY_TOPIC: &str = "/nusense/board";

#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("cannot create recording {path}: {source}")]
    Create { path: String, source: std::io::Error },
    #[error("cannot open recording {path}: {source}")]
    Open { path: String, source: std::io::Error },
    #[error("MCAP error in {path}: {source}")]
    Mcap { path: String, source: mcap::McapError },
    #[error("{path} is not an MCAP recording (it does not start with the MCAP magic)")]
    NotMcap { path: String },
    #[error("recover writes a new file; {path} is the recording being recovered")]
    RecoverInPlace { path: String },
    #[error("the recorder's writer thread stopped unexpectedly")]
    WriterGone,
    #[error(transparent)]
    Stopped(RecordFailure),
}

impl RecordError {
    fn from_mcap(path: &str, source: mcap::McapError) -> Self {
        match source {
            mcap::McapError::Io(source) => RecordError::Create {
                path: path.to_string(),
                source,
            },
            source => RecordError::Mcap {
                path: path.to_string(),
                source,
            },
        }
    }
}

/// Why a recording stopped on its own while running, as the daemon shows it.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, thiserror::Error)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum RecordFailure {
    #[error(
        "the disk holding {path} is full: the recording stopped; the file keeps its first {kept_bytes} bytes \
         (every chunk written before), and `nusense record --recover` gives it a summary"
    )]
    DiskFull { path: String, kept_bytes: u64 },
    #[error(
        "cannot write {path} ({message}): the recording stopped; the file keeps its first {kept_bytes} bytes, and \
         `nusense record --recover` gives it a summary"
    )]
    Write {
        path: String,
        kept_bytes: u64,
        message: String,
    },
}

impl RecordFailure {
    fn from_io(path: &str, kept_bytes: u64, error: &std::io::Error) -> Self {
        let path = path.to_string();
        // ENOSPC and EDQUOT, as std names them.
        let disk_full = matches!(
            error.kind(),
            std::io::ErrorKind::StorageFull | std::io::ErrorKind::QuotaExceeded
        );
        if disk_full {
            RecordFailure::DiskFull { path, kept_bytes }
        } else {
            RecordFailure::Write {
                path,
                kept_bytes,
                message: error.to_string(),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use std::io::Write;
    use std::sync::{Arc, Mutex};
    use std::time::Duration;

    use super::writer::Destination;
    use super::*;

    /// Noise, so that the chunks' compression cannot shrink it away.
    fn image() -> Arc<image::RgbImage> {
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        Arc::new(image::RgbImage::from_fn(32, 24, |_, _| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            image::Rgb([state as u8, (state >> 8) as u8, (state >> 16) as u8])
        }))
    }

    fn published(frame_id: u64, time_us: u64) -> Arc<crate::pipeline::PublishedReading> {
        let message = crate::ReadingMessage {
            schema_version: crate::reading::SCHEMA_VERSION,
            frame_id,
            file: None,
            capture_time_us: time_us,
            processed_time_us: time_us + 5000,
            latency_ms: 5.0,
            queue_ms: 0.1,
            reference_frame_id: Some(0),
            estimate: None,
            error: Some("no rest frame yet".into()),
            led: None,
        };
        let json = serde_json::to_string(&message).unwrap();
        Arc::new(crate::pipeline::PublishedReading { message, json })
    }

    fn record_frames(recorder: &Recorder, frames: u64) {
        for frame_id in 0..frames {
            let time_us = 1_700_000_000_000_000 + frame_id * 33_333;
            recorder.record(RecordItem::Frame {
                frame_id,
                capture_time_us: time_us,
                pixels: nusense_capture::FramePixels::Rgb(image()),
            });
            recorder.record(RecordItem::Reading(published(frame_id, time_us)));
        }
    }

    #[test]
    fn frames_readings_and_telemetry_round_trip_with_their_schemas() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("roundtrip.mcap");
        let recorder = Recorder::create(&path, RecorderOptions::default()).unwrap();
        record_frames(&recorder, 3);
        recorder.record(RecordItem::Telemetry {
            time_us: 1_700_000_000_000_000,
            json: "{\"telemetry\":{}}".into(),
        });
        let summary = recorder.finish().unwrap();
        assert_eq!(
            (summary.frames, summary.readings, summary.telemetry, summary.dropped),
            (3, 3, 1, 0)
        );

        let recording = read_recording(&path).unwrap();
        assert!(!recording.truncated, "{:?}", recording.stopped_by);
        let frames = recording.frames();
        assert_eq!(frames.iter().map(|f| f.frame_id).collect::<Vec<_>>(), vec![0, 1, 2]);
        assert_eq!(frames[1].capture_time_us, 1_700_000_000_033_333);
        let decoded = image::load_from_memory(&frames[0].jpeg).unwrap();
        assert_eq!((decoded.width(), decoded.height()), (32, 24));
        let first_frame = recording.on_topic(FRAME_TOPIC).next().unwrap();
        assert_eq!(first_frame.schema_name(), Some("foxglove.CompressedImage"));
        assert_eq!(recording.on_topic(READING_TOPIC).count(), 3);
        assert_eq!(recording.on_topic(TELEMETRY_TOPIC).count(), 1);
    }

    #[test]
    fn a_file_that_is_not_mcap_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("not.mcap");
        std::fs::write(&path, b"hello, not an mcap file").unwrap();
        assert!(matches!(read_recording(&path), Err(RecordError::NotMcap { .. })));
        assert!(matches!(
            read_recording(&dir.path().join("missing.mcap")),
            Err(RecordError::Open { .. })
        ));
    }

    /// A writer that takes `capacity` bytes, then fails as a full disk does.
    struct SmallDisk {
        written: Arc<Mutex<Vec<u8>>>,
        capacity: usize,
    }

    impl Write for SmallDisk {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            let mut written = self.written.lock().unwrap();
            let room = self.capacity - written.len();
            if room == 0 {
                return Err(std::io::Error::from(std::io::ErrorKind::StorageFull));
            }
            let n = buf.len().min(room);
            written.extend_from_slice(&buf[..n]);
            Ok(n)
        }

        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn a_full_disk_stops_the_recording_with_a_typed_error_and_producers_never_block() {
        let written = Arc::new(Mutex::new(Vec::new()));
        let destination = Destination {
            writer: Box::new(SmallDisk {
                written: written.clone(),
                capacity: 16 * 1024,
            }),
            file: None,
        };
        let options = RecorderOptions {
            chunk_bytes: 4 * 1024,
            ..Default::default()
        };
        let recorder = Recorder::start(std::path::Path::new("small.mcap"), destination, options).unwrap();
        record_frames(&recorder, 200);
        let deadline = std::time::Instant::now() + Duration::from_secs(30);
        while recorder.failure().is_none() && std::time::Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(10));
        }
        assert!(
            matches!(recorder.failure(), Some(RecordFailure::DiskFull { ref path, .. }) if path == "small.mcap"),
            "{:?}",
            recorder.failure()
        );
        // Recording on after the failure neither blocks nor grows memory: items are dropped and counted.
        let dropped_before = recorder.stats().dropped.load(std::sync::atomic::Ordering::Relaxed);
        record_frames(&recorder, 10);
        let stats = recorder.stats();
        assert_eq!(
            stats.dropped.load(std::sync::atomic::Ordering::Relaxed),
            dropped_before + 20
        );
        assert_eq!(stats.queued_bytes.load(std::sync::atomic::Ordering::Relaxed), 0);
        match recorder.finish() {
            Err(RecordError::Stopped(RecordFailure::DiskFull { .. })) => {}
            other => panic!("finish reports the full disk: {other:?}"),
        }
        assert_eq!(written.lock().unwrap().len(), 16 * 1024);
    }

    #[test]
    fn the_queue_is_bounded_in_bytes() {
        // A writer that never returns until released: everything queues.
        struct Stalled(Arc<(Mutex<bool>, std::sync::Condvar)>);
        impl Write for Stalled {
            fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
                let (lock, released) = &*self.0;
                let mut go = lock.lock().unwrap();
                while !*go {
                    go = released.wait(go).unwrap();
                }
                Ok(buf.len())
            }
            fn flush(&mut self) -> std::io::Result<()> {
                Ok(())
            }
        }
        let gate = Arc::new((Mutex::new(true), std::sync::Condvar::new()));
        let destination = Destination {
            writer: Box::new(Stalled(gate.clone())),
            file: None,
        };
        let jpeg = Arc::new(vec![0xAB; 100_000]);
        let options = RecorderOptions {
            chunk_bytes: 1,
            queue_bytes: 1_000_000,
            flush_interval: Duration::from_secs(3600),
            sensor: None,
        };
        let recorder = Recorder::start(std::path::Path::new("stalled.mcap"), destination, options).unwrap();
        *gate.0.lock().unwrap() = false;
        for frame_id in 0..40 {
            recorder.record(RecordItem::Frame {
                frame_id,
                capture_time_us: frame_id,
                pixels: nusense_capture::FramePixels::Jpeg(jpeg.clone()),
            });
        }
        let stats = recorder.stats();
        let queued = stats.queued_bytes.load(std::sync::atomic::Ordering::Relaxed);
        let dropped = stats.dropped.load(std::sync::atomic::Ordering::Relaxed);
        assert!(queued <= 1_000_000, "{queued} bytes queued");
        // At most one frame is inside the stalled writer, at most nine wait (ten would pass the bound).
        assert!((30..=31).contains(&dropped), "{dropped} dropped");
        *gate.0.lock().unwrap() = true;
        gate.1.notify_all();
        let summary = recorder.finish().unwrap();
        assert_eq!(summary.frames + summary.dropped, 40);
    }

    #[test]
    fn the_foxglove_layout_names_only_channels_that_are_published() {
        fn topics(value: &serde_json::Value, found: &mut Vec<String>) {
            fn take(text: &str, found: &mut Vec<String>) {
                if text.starts_with('/') {
                    found.push(text.split('.').next().unwrap_or(text).to_string());
                }
            }
            match value {
                serde_json::Value::String(text) => take(text, found),
                serde_json::Value::Array(items) => items.iter().for_each(|v| topics(v, found)),
                serde_json::Value::Object(map) => {
                    for (key, value) in map {
                        take(key, found);
                        topics(value, found);
                    }
                }
                _ => {}
            }
        }
        let layout: serde_json::Value =
            serde_json::from_str(include_str!("../../../../docs/foxglove/nusense-layout.json")).unwrap();
        let mut found = Vec::new();
        topics(&layout, &mut found);
        let published: Vec<_> = channel_table().iter().map(|c| c.topic.to_string()).collect();
        assert!(found.len() >= 5, "{found:?}");
        for topic in &found {
            assert!(
                published.contains(topic),
                "the layout shows {topic}, which is not published"
            );
        }
    }
}
