//! Recordings: frames (JPEG), readings and board telemetry as MCAP channels with JSON schemas.
//!
//! Written in chunks that are closed at least every [`RecorderOptions::flush_interval`], so that a recorder
//! killed without warning (SIGKILL, power loss) leaves a file whose every closed chunk a linear MCAP reader
//! recovers: at most the last chunk is lost. [`read_recording`] is that tolerant reader.

mod reader;
mod writer;

pub use reader::{read_recording, Recording, RecordedFrame, RecordedMessage};
pub use writer::{encode_jpeg, RecordItem, RecordStats, Recorder, RecorderOptions, RecordSummary};

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
