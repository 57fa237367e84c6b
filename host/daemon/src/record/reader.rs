use std::path::Path;

use base64::Engine;
use mcap::read::{MessageStream, Options};

use super::{RecordError, FRAME_TOPIC};

/// One message of a recording, any topic.
#[derive(Clone, Debug)]
pub struct RecordedMessage {
    pub topic: String,
    pub schema_name: Option<String>,
    pub sequence: u32,
    /// Microseconds since the Unix epoch.
    pub time_us: u64,
    pub data: Vec<u8>,
}

#[derive(Clone, Debug)]
pub struct RecordedFrame {
    pub frame_id: u32,
    pub capture_time_us: u64,
    pub jpeg: Vec<u8>,
}

/// Everything a recording holds, in file order.
#[derive(Clone, Debug, Default)]
pub struct Recording {
    pub messages: Vec<RecordedMessage>,
    /// The file ended before its footer (the recorder was killed): what follows the last whole chunk is gone.
    pub truncated: bool,
    /// Why reading stopped early, when it did.
    pub stopped_by: Option<String>,
}

impl Recording {
    pub fn on_topic<'a>(&'a self, topic: &'a str) -> impl Iterator<Item = &'a RecordedMessage> + 'a {
        self.messages.iter().filter(move |m| m.topic == topic)
    }

    /// The frames, with their JPEG bytes decoded from the foxglove.CompressedImage JSON.
    pub fn frames(&self) -> Vec<RecordedFrame> {
        #[derive(serde::Deserialize)]
        struct Image {
            data: String,
        }
        self.on_topic(FRAME_TOPIC)
            .filter_map(|m| {
                let image: Image = serde_json::from_slice(&m.data).ok()?;
                let jpeg = base64::engine::general_purpose::STANDARD.decode(image.data).ok()?;
                Some(RecordedFrame {
                    frame_id: m.sequence,
                    capture_time_us: m.time_us,
                    jpeg,
                })
            })
            .collect()
    }
}

/// Reads a recording linearly and keeps everything up to the first damaged or missing record, so that a
/// recording cut short by a crash yields all its closed chunks.
pub fn read_recording(path: &Path) -> Result<Recording, RecordError> {
    let path_text = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|source| RecordError::Open {
        path: path_text.clone(),
        source,
    })?;
    if !bytes.starts_with(mcap::MAGIC) {
        return Err(RecordError::Empty { path: path_text });
    }
    let stream = MessageStream::new_with_options(&bytes, Options::IgnoreEndMagic.into()).map_err(|source| {
        RecordError::Mcap {
            path: path_text.clone(),
            source,
        }
    })?;
    let mut recording = Recording::default();
    for message in stream {
        match message {
            Ok(message) => recording.messages.push(RecordedMessage {
                topic: message.channel.topic.clone(),
                schema_name: message.channel.schema.as_ref().map(|s| s.name.clone()),
                sequence: message.sequence,
                time_us: message.log_time / 1000,
                data: message.data.into_owned(),
            }),
            Err(error) => {
                recording.truncated = true;
                recording.stopped_by = Some(error.to_string());
                break;
            }
        }
    }
    // A clean file ends with the footer and magic; without them the writer never finished.
    if !bytes.ends_with(mcap::MAGIC) {
        recording.truncated = true;
    }
    Ok(recording)
}
