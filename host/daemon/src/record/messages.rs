//! What each channel of a recording holds and how its messages are encoded: the one place that knows.

use std::collections::BTreeMap;
use std::io::Write;

use base64::Engine;
use serde::Serialize;

use super::{FRAME_TOPIC, READING_TOPIC, TELEMETRY_TOPIC};

/// A message ready for the writer.
pub(crate) struct Encoded {
    pub(crate) channel_id: u16,
    pub(crate) data: Vec<u8>,
}

/// The channels of a recording, registered with its writer.
pub(crate) struct ChannelSet {
    frame: u16,
    reading: u16,
    telemetry: u16,
}

impl ChannelSet {
    pub(crate) fn register<W: Write + std::io::Seek>(writer: &mut mcap::Writer<W>) -> Result<Self, mcap::McapError> {
        let mut channel = |topic: &str, schema_name: &str, schema: &str| -> Result<u16, mcap::McapError> {
            let schema_id = writer.add_schema(schema_name, "jsonschema", schema.as_bytes())?;
            writer.add_channel(schema_id, topic, "json", &BTreeMap::new())
        };
        Ok(Self {
            frame: channel(FRAME_TOPIC, "foxglove.CompressedImage", FRAME_SCHEMA)?,
            reading: channel(READING_TOPIC, "nusense.Reading", READING_SCHEMA)?,
            telemetry: channel(TELEMETRY_TOPIC, "nusense.BoardTelemetry", TELEMETRY_SCHEMA)?,
        })
    }

    pub(crate) fn frame(&self, capture_time_us: u64, jpeg: &[u8]) -> Encoded {
        #[derive(Serialize)]
        struct CompressedImage<'a> {
            timestamp: Timestamp,
            frame_id: &'a str,
            data: String,
            format: &'a str,
        }
        let message = CompressedImage {
            timestamp: Timestamp::from_us(capture_time_us),
            frame_id: "camera",
            data: base64::engine::general_purpose::STANDARD.encode(jpeg),
            format: "jpeg",
        };
        Encoded {
            channel_id: self.frame,
            data: serde_json::to_vec(&message).unwrap_or_default(),
        }
    }

    /// The reading channel's encoding: the daemon's reading message as it serialised it.
    pub(crate) fn reading(&self, json: &str) -> Encoded {
        Encoded {
            channel_id: self.reading,
            data: json.as_bytes().to_vec(),
        }
    }

    pub(crate) fn telemetry(&self, json: &str) -> Encoded {
        Encoded {
            channel_id: self.telemetry,
            data: json.as_bytes().to_vec(),
        }
    }
}

#[derive(Serialize)]
struct Timestamp {
    sec: u64,
    nsec: u32,
}

impl Timestamp {
    fn from_us(time_us: u64) -> Self {
        Self {
            sec: time_us / 1_000_000,
            nsec: (time_us % 1_000_000) as u32 * 1000,
        }
    }
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
