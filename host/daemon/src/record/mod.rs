//! Recordings: frames (JPEG), readings and board telemetry as MCAP channels with JSON schemas.
//!
//! Written in chunks that are closed at least every [`RecorderOptions::flush_interval`], so that a recorder
//! killed without warning (SIGKILL, power loss) leaves a file whose every closed chunk a linear MCAP reader
//! recovers: at most the last chunk is lost. [`read_recording`] is that tolerant reader.

mod reader;
mod replay;
mod writer;

pub use reader::{read_recording, RecordedFrame, RecordedMessage, Recording};
pub use replay::McapReplay;
pub use writer::{encode_jpeg, RecordItem, RecordStats, RecordSummary, Recorder, RecorderOptions};

/// Frames, as `foxglove.CompressedImage` so that Foxglove and other MCAP viewers show them.
pub const FRAME_TOPIC: &str = "/camera/image";
/// One [`crate::pipeline::DaemonReading`] per processed frame.
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
    #[error("the recorder's writer thread stopped unexpectedly")]
    WriterGone,
    #[error("recording {path} holds no messages (not an MCAP file, or nothing was written before it ended)")]
    Empty { path: String },
}

const FRAME_SCHEMA: &str = r#"{
  "title": "foxglove.CompressedImage",
  "type": "object",
  "properties": {
    "timestamp": {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}},
    "frame_id": {"type": "string"},
    "data": {"type": "string", "contentEncoding": "base64"},
    "format": {"type": "string"}
  }
}"#;

const READING_SCHEMA: &str = r#"{
  "title": "nusense.Reading",
  "description": "One processed frame: timestamps in microseconds since the Unix epoch, estimator outputs (force N, contact in raw px, undistorted px and pad mm, edge angle in degrees, shear field per lattice corner) and the LED state",
  "type": "object",
  "properties": {
    "frame_id": {"type": "integer"},
    "capture_time_us": {"type": "integer"},
    "processed_time_us": {"type": "integer"},
    "latency_ms": {"type": "number"},
    "estimate": {"type": ["object", "null"]},
    "error": {"type": ["string", "null"]},
    "led": {"type": ["object", "null"]}
  }
}"#;

const TELEMETRY_SCHEMA: &str = r#"{
  "title": "nusense.BoardTelemetry",
  "description": "LED board telemetry: per channel (Top, Right, Bottom, Left) setpoint and measured current in mA, duty, enable and fault flags; temperature in degrees C, supply in mV",
  "type": "object",
  "properties": {
    "time_us": {"type": "integer"},
    "telemetry": {"type": "object"}
  }
}"#;

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;

    #[test]
    fn frames_readings_and_telemetry_round_trip_with_their_schemas() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("roundtrip.mcap");
        let recorder = Recorder::create(&path, RecorderOptions::default()).unwrap();
        let image = Arc::new(image::RgbImage::from_fn(32, 24, |x, y| {
            image::Rgb([(x * 8) as u8, (y * 10) as u8, 128])
        }));
        for frame_id in 0..3u64 {
            let time_us = 1_700_000_000_000_000 + frame_id * 33_333;
            recorder.record(RecordItem::Frame {
                frame_id,
                capture_time_us: time_us,
                image: image.clone(),
                jpeg: None,
            });
            recorder.record(RecordItem::Reading {
                frame_id,
                time_us,
                json: format!("{{\"frame_id\":{frame_id}}}").into(),
            });
        }
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
        assert_eq!(first_frame.schema_name.as_deref(), Some("foxglove.CompressedImage"));
        assert_eq!(recording.on_topic(READING_TOPIC).count(), 3);
        assert_eq!(recording.on_topic(TELEMETRY_TOPIC).count(), 1);
    }

    #[test]
    fn a_file_that_is_not_mcap_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("not.mcap");
        std::fs::write(&path, b"hello, not an mcap file").unwrap();
        assert!(matches!(read_recording(&path), Err(RecordError::Empty { .. })));
        assert!(matches!(
            read_recording(&dir.path().join("missing.mcap")),
            Err(RecordError::Open { .. })
        ));
    }
}
