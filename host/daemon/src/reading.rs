//! The one reading message: what `nusense analyze --json` prints, `/api/v1/reading` returns, `/api/v1/stream`
//! sends and recordings store, one per frame. Its JSON Schema is generated from these types, served at
//! `/api/v1/schema` and committed as `host/daemon/schema/reading.schema.json` (a test keeps the two equal).

use nusense_estimator::Reading;
use schemars::JsonSchema;
use serde::Serialize;

use crate::pipeline::LedState;

/// Version of every message's layout: raised when a field is removed or changes meaning (new fields may appear
/// without it, so clients ignore keys they do not know).
pub const SCHEMA_VERSION: u32 = 1;

/// One frame, measured.
#[derive(Clone, Debug, Serialize, JsonSchema)]
#[schemars(title = "nusense.Reading")]
pub struct ReadingMessage {
    /// Always [`SCHEMA_VERSION`].
    pub schema_version: u32,
    /// Frames counted from 0 since the source started (`analyze`: the frame's place on the command line).
    pub frame_id: u64,
    /// The image file the frame was read from, when it came from one given by name (`analyze`).
    pub file: Option<String>,
    /// When the frame was captured (or read from its file), microseconds since the Unix epoch.
    pub capture_time_us: u64,
    /// When the reading was ready, microseconds since the Unix epoch.
    pub processed_time_us: u64,
    /// Capture to reading, decoding and estimation included, ms.
    pub latency_ms: f64,
    /// Time the frame waited for the estimator, ms.
    pub queue_ms: f64,
    /// The rest frame the estimate is measured against (`analyze`: none, the reference is a file).
    pub reference_frame_id: Option<u64>,
    /// The estimator's measurement; absent when this frame could not be measured (see `error`).
    // The estimator's Reading gains its own schema soon; until then the schema describes it as an object.
    #[schemars(with = "Option<serde_json::Map<String, serde_json::Value>>")]
    pub estimate: Option<Reading>,
    /// Why there is no estimate for this frame, in words.
    pub error: Option<String>,
    /// The LED board's state when the reading was made; absent without a board.
    pub led: Option<LedState>,
}

/// The reading message's JSON Schema, pretty-printed as it is committed.
pub fn reading_schema_json() -> String {
    let schema = schemars::schema_for!(ReadingMessage);
    // A schema of plain derived types always serialises.
    let mut text = serde_json::to_string_pretty(&schema).unwrap_or_default();
    text.push('\n');
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    const COMMITTED: &str = include_str!("../schema/reading.schema.json");

    /// Fails when the types change and the committed schema was not regenerated: run this test with BLESS=1 to
    /// rewrite `host/daemon/schema/reading.schema.json`, and review the diff (a removed or renamed field needs a
    /// new SCHEMA_VERSION).
    #[test]
    fn committed_schema_matches_the_types() {
        let generated = reading_schema_json();
        if std::env::var_os("BLESS").is_some() {
            let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("schema/reading.schema.json");
            std::fs::write(&path, &generated).expect("write the schema");
            return;
        }
        assert!(
            generated == COMMITTED,
            "host/daemon/schema/reading.schema.json is out of date: run `BLESS=1 cargo test -p nusense-daemon \
             committed_schema_matches_the_types` and commit the result"
        );
    }

    #[test]
    fn the_schema_names_every_field_a_reading_carries() {
        let schema: serde_json::Value = serde_json::from_str(&reading_schema_json()).unwrap();
        let properties = schema["properties"].as_object().unwrap();
        let message = ReadingMessage {
            schema_version: SCHEMA_VERSION,
            frame_id: 3,
            file: None,
            capture_time_us: 1,
            processed_time_us: 2,
            latency_ms: 1.0,
            queue_ms: 0.0,
            reference_frame_id: Some(0),
            estimate: None,
            error: Some("no rest frame yet".into()),
            led: Some(LedState::default()),
        };
        let json = serde_json::to_value(&message).unwrap();
        for key in json.as_object().unwrap().keys() {
            assert!(properties.contains_key(key), "{key} is missing from the schema");
        }
        assert_eq!(schema["properties"]["schema_version"]["type"], "integer");
        assert!(schema["$defs"]["LedState"].is_object(), "{schema}");
    }
}
