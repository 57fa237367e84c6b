//! Reading recordings from disk a chunk at a time (memory bounded by the largest chunk, not the file), tolerant of
//! files cut short: everything up to the last whole chunk is read, and where and why reading stopped is kept.

use std::collections::{BTreeMap, HashMap, VecDeque};
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use base64::Engine;
use mcap::records::{op, Record};
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};

use super::{RecordError, FRAME_TOPIC};

/// A record longer than this is taken for a garbled length, not allocated.
const RECORD_LENGTH_LIMIT: usize = 256 * 1024 * 1024;

#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SchemaInfo {
    pub id: u16,
    pub name: String,
    pub encoding: String,
    pub data: Vec<u8>,
}

#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ChannelInfo {
    pub id: u16,
    pub topic: String,
    pub message_encoding: String,
    pub metadata: BTreeMap<String, String>,
    pub schema: Option<Arc<SchemaInfo>>,
}

/// One message of a recording, any topic.
#[derive(Clone, Debug)]
pub struct RecordedMessage {
    pub channel: Arc<ChannelInfo>,
    pub sequence: u32,
    /// Nanoseconds since the Unix epoch.
    pub log_time_ns: u64,
    pub publish_time_ns: u64,
    pub data: Vec<u8>,
}

impl RecordedMessage {
    pub fn topic(&self) -> &str {
        &self.channel.topic
    }

    pub fn schema_name(&self) -> Option<&str> {
        self.channel.schema.as_ref().map(|s| s.name.as_str())
    }

    /// Microseconds since the Unix epoch.
    pub fn time_us(&self) -> u64 {
        self.log_time_ns / 1000
    }

    /// The camera frame this message carries, if it is one (either format nusense has written).
    pub fn frame(&self) -> Option<RecordedFrame> {
        if self.channel.topic != FRAME_TOPIC {
            return None;
        }
        let jpeg = match self.channel.message_encoding.as_str() {
            // The first recordings: foxglove.CompressedImage as JSON, the JPEG in base64.
            "json" => {
                #[derive(serde::Deserialize)]
                struct Image {
                    data: String,
                }
                let image: Image = serde_json::from_slice(&self.data).ok()?;
                base64::engine::general_purpose::STANDARD.decode(image.data).ok()?
            }
            "protobuf" if self.schema_name() == Some("foxglove.CompressedImage") => {
                let image = <foxglove::messages::CompressedImage as foxglove::Decode>::decode(&self.data[..]).ok()?;
                image.data.to_vec()
            }
            _ => return None,
        };
        Some(RecordedFrame {
            frame_id: self.sequence,
            capture_time_us: self.time_us(),
            jpeg,
        })
    }
}

#[derive(Clone, Debug)]
pub struct RecordedFrame {
    pub frame_id: u32,
    pub capture_time_us: u64,
    pub jpeg: Vec<u8>,
}

/// A metadata record of a recording (sensor identity, configuration, calibration).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RecordedMetadata {
    pub name: String,
    pub metadata: BTreeMap<String, String>,
}

/// Streams the messages of a recording from disk, one chunk in memory at a time.
pub struct RecordingReader {
    file: File,
    path: PathBuf,
    linear: LinearReader,
    schemas: HashMap<u16, Arc<SchemaInfo>>,
    channels: HashMap<u16, Arc<ChannelInfo>>,
    pending: VecDeque<RecordedMessage>,
    /// Metadata records met so far, in file order.
    pub metadata: Vec<RecordedMetadata>,
    /// The footer was read: the writer finished the file.
    pub finished: bool,
    /// Why reading stopped before the footer (a file cut short, or damaged), once it has.
    pub stopped_by: Option<String>,
    done: bool,
}

impl RecordingReader {
    pub fn open(path: &Path) -> Result<Self, RecordError> {
        let path_text = path.display().to_string();
        let mut file = File::open(path).map_err(|source| RecordError::Open {
            path: path_text.clone(),
            source,
        })?;
        let mut magic = Vec::with_capacity(mcap::MAGIC.len());
        (&mut file)
            .take(mcap::MAGIC.len() as u64)
            .read_to_end(&mut magic)
            .map_err(|source| RecordError::Open {
                path: path_text.clone(),
                source,
            })?;
        let read = magic.len();
        if magic[..] != mcap::MAGIC[..read] {
            return Err(RecordError::NotMcap { path: path_text });
        }
        file.seek(SeekFrom::Start(0)).map_err(|source| RecordError::Open {
            path: path_text.clone(),
            source,
        })?;
        let options = LinearReaderOptions::default()
            .with_emit_chunks(true)
            .with_record_length_limit(RECORD_LENGTH_LIMIT);
        // A file cut inside its magic is a recording that never got its first record: empty, and cut short.
        let cut_in_magic = read < magic.len();
        Ok(Self {
            file,
            path: path.to_path_buf(),
            linear: LinearReader::new_with_options(options),
            schemas: HashMap::new(),
            channels: HashMap::new(),
            pending: VecDeque::new(),
            metadata: Vec::new(),
            finished: false,
            stopped_by: cut_in_magic.then(|| "the file ends inside the MCAP magic (it was cut short)".to_string()),
            done: cut_in_magic,
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The reader stopped before the footer: the file was cut short (its writer was killed) or is damaged.
    pub fn truncated(&self) -> bool {
        self.done && !self.finished
    }

    /// The next message in file order; `None` at the end of the file or at the first record that is cut off or
    /// damaged (then `stopped_by` says which).
    pub fn next_message(&mut self) -> Option<RecordedMessage> {
        loop {
            if let Some(message) = self.pending.pop_front() {
                return Some(message);
            }
            if self.done {
                return None;
            }
            if let Err(reason) = self.advance() {
                self.stop(reason);
            }
        }
    }

    /// The channels met so far.
    pub fn channels(&self) -> impl Iterator<Item = &Arc<ChannelInfo>> {
        self.channels.values()
    }

    fn stop(&mut self, reason: String) {
        self.done = true;
        if !self.finished {
            self.stopped_by = Some(reason);
        }
    }

    /// Reads the next top-level record; a chunk is read whole and its messages queued.
    fn advance(&mut self) -> Result<(), String> {
        let (opcode, body) = loop {
            match self.linear.next_event() {
                None => {
                    self.done = true;
                    return Ok(());
                }
                Some(Err(error)) => return Err(describe(error)),
                Some(Ok(LinearReadEvent::ReadRequest(need))) => {
                    let read = self
                        .file
                        .read(self.linear.insert(need))
                        .map_err(|e| format!("read error: {e}"))?;
                    self.linear.notify_read(read);
                }
                Some(Ok(LinearReadEvent::Record { opcode, data })) => break (opcode, data.to_vec()),
            }
        };
        let record = mcap::parse_record(opcode, &body).map_err(describe)?;
        match record {
            Record::Chunk { header, data } => {
                let records = mcap::read::ChunkReader::new(header, &data).map_err(describe)?;
                // The whole chunk is checked before any of it is used: a chunk is read entirely or not at all.
                let records = records.collect::<Result<Vec<_>, _>>().map_err(describe)?;
                for record in records {
                    self.take(record)?;
                }
            }
            Record::Footer(_) => self.finished = true,
            other => self.take(other)?,
        }
        Ok(())
    }

    fn take(&mut self, record: Record<'_>) -> Result<(), String> {
        match record {
            Record::Schema { header, data } => {
                self.schemas.insert(
                    header.id,
                    Arc::new(SchemaInfo {
                        id: header.id,
                        name: header.name,
                        encoding: header.encoding,
                        data: data.into_owned(),
                    }),
                );
            }
            Record::Channel(channel) => {
                let schema = match channel.schema_id {
                    0 => None,
                    id => Some(
                        self.schemas
                            .get(&id)
                            .cloned()
                            .ok_or_else(|| format!("channel {} names unknown schema {id}", channel.topic))?,
                    ),
                };
                self.channels.insert(
                    channel.id,
                    Arc::new(ChannelInfo {
                        id: channel.id,
                        topic: channel.topic,
                        message_encoding: channel.message_encoding,
                        metadata: channel.metadata,
                        schema,
                    }),
                );
            }
            Record::Message { header, data } => {
                let channel = self
                    .channels
                    .get(&header.channel_id)
                    .cloned()
                    .ok_or_else(|| format!("message on unknown channel {}", header.channel_id))?;
                self.pending.push_back(RecordedMessage {
                    channel,
                    sequence: header.sequence,
                    log_time_ns: header.log_time,
                    publish_time_ns: header.publish_time,
                    data: data.into_owned(),
                });
            }
            Record::Metadata(metadata) => self.metadata.push(RecordedMetadata {
                name: metadata.name,
                metadata: metadata.metadata,
            }),
            _ => {}
        }
        Ok(())
    }
}

impl Iterator for RecordingReader {
    type Item = RecordedMessage;

    fn next(&mut self) -> Option<RecordedMessage> {
        self.next_message()
    }
}

fn describe(error: mcap::McapError) -> String {
    match error {
        mcap::McapError::UnexpectedEof => "the file ends before its footer (it was cut short)".into(),
        mcap::McapError::RecordTooLarge { opcode, len } if opcode == op::CHUNK && len == u64::MAX => {
            "the last chunk was never closed (its length is still the writer's placeholder)".into()
        }
        other => other.to_string(),
    }
}

/// Everything a recording holds, in file order (for tests and small files; replay streams instead).
#[derive(Clone, Debug, Default)]
pub struct Recording {
    pub messages: Vec<RecordedMessage>,
    pub metadata: Vec<RecordedMetadata>,
    /// The file ended before its footer (the recorder was killed): what follows the last whole chunk is gone.
    pub truncated: bool,
    /// Why reading stopped early, when it did.
    pub stopped_by: Option<String>,
}

impl Recording {
    pub fn on_topic<'a>(&'a self, topic: &'a str) -> impl Iterator<Item = &'a RecordedMessage> + 'a {
        self.messages.iter().filter(move |m| m.topic() == topic)
    }

    /// The frames, with their JPEG bytes.
    pub fn frames(&self) -> Vec<RecordedFrame> {
        self.messages.iter().filter_map(RecordedMessage::frame).collect()
    }
}

/// Reads a whole recording into memory, keeping everything up to the first cut-off or damaged record.
pub fn read_recording(path: &Path) -> Result<Recording, RecordError> {
    let mut reader = RecordingReader::open(path)?;
    let messages: Vec<_> = reader.by_ref().collect();
    Ok(Recording {
        messages,
        truncated: reader.truncated(),
        stopped_by: reader.stopped_by.take(),
        metadata: std::mem::take(&mut reader.metadata),
    })
}

/// Whether a recording ends with the MCAP magic (its writer finished it), without reading it.
pub fn ends_finished(path: &Path) -> Result<bool, RecordError> {
    let open_error = |source| RecordError::Open {
        path: path.display().to_string(),
        source,
    };
    let mut file = File::open(path).map_err(open_error)?;
    let len = file.metadata().map_err(open_error)?.len();
    if len < 2 * mcap::MAGIC.len() as u64 {
        return Ok(false);
    }
    let mut tail = [0u8; 8];
    file.seek(SeekFrom::End(-8)).map_err(open_error)?;
    file.read_exact(&mut tail).map_err(open_error)?;
    Ok(tail == *mcap::MAGIC)
}
