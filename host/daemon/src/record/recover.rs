//! Rewriting a recording that was cut short (its writer killed, the machine's power lost, the disk full) into a
//! finished file: every message up to the last whole chunk, the metadata, and a summary with chunk and message
//! indexes, so that seeking readers (the Foxglove app) open it at once.

use std::collections::HashMap;
use std::fs::File;
use std::io::{BufWriter, Seek, Write};
use std::path::Path;

use mcap::records::MessageHeader;
use mcap::write::NoSeek;
use mcap::McapResult;
use serde::Serialize;

use super::writer::{write_options, DEFAULT_CHUNK_BYTES};
use super::{ChannelInfo, RecordError, RecordingReader};

#[derive(Clone, Debug, Serialize)]
pub struct RecoverSummary {
    pub input: String,
    pub output: String,
    pub messages: u64,
    pub channels: usize,
    pub metadata: usize,
    /// The input had no footer (it was cut short): what followed its last whole chunk is not in the output.
    pub input_truncated: bool,
    /// Why reading the input stopped before its footer.
    pub stopped_by: Option<String>,
}

/// Writes `output` (which must not exist) from what `input` holds.
pub fn recover(input: &Path, output: &Path) -> Result<RecoverSummary, RecordError> {
    let output_text = output.display().to_string();
    if input
        .canonicalize()
        .ok()
        .is_some_and(|i| output.canonicalize().ok() == Some(i))
    {
        return Err(RecordError::RecoverInPlace { path: output_text });
    }
    let mut reader = RecordingReader::open(input)?;
    let create_error = |source| RecordError::Create {
        path: output_text.clone(),
        source,
    };
    let mut next = reader.next_message();
    // A recording cut before its first message keeps its channels, as plain records: in a chunk they would make a
    // chunk (and a chunk index) that holds no message.
    let options = write_options(DEFAULT_CHUNK_BYTES).use_chunks(next.is_some());
    let file = File::create_new(output).map_err(create_error)?;
    let sync_handle = file.try_clone().map_err(create_error)?;
    let mut writer = options
        .create(NoSeek::new(BufWriter::new(file)))
        .map_err(|source| RecordError::from_mcap(&output_text, source))?;
    let mcap_error = |source| RecordError::from_mcap(&output_text, source);
    let mut ids = IdMap::default();
    let mut metadata_written = 0;
    let mut messages = 0u64;
    while let Some(message) = next.take() {
        // Metadata in file order, before the messages that followed it.
        for metadata in &reader.metadata[metadata_written..] {
            writer
                .write_metadata(&mcap::records::Metadata {
                    name: metadata.name.clone(),
                    metadata: metadata.metadata.clone(),
                })
                .map_err(mcap_error)?;
        }
        metadata_written = reader.metadata.len();
        let channel_id = ids.channel(&mut writer, &message.channel).map_err(mcap_error)?;
        let header = MessageHeader {
            channel_id,
            sequence: message.sequence,
            log_time: message.log_time_ns,
            publish_time: message.publish_time_ns,
        };
        writer
            .write_to_known_channel(&header, &message.data)
            .map_err(mcap_error)?;
        messages += 1;
        next = reader.next_message();
    }
    for metadata in &reader.metadata[metadata_written..] {
        writer
            .write_metadata(&mcap::records::Metadata {
                name: metadata.name.clone(),
                metadata: metadata.metadata.clone(),
            })
            .map_err(mcap_error)?;
    }
    // Channels that never carried a message still belong in the summary.
    // Channels that never carried a message still belong in the summary.
    let mut silent: Vec<_> = reader.channels().cloned().collect();
    silent.sort_by_key(|c| c.id);
    for channel in silent {
        ids.channel(&mut writer, &channel).map_err(mcap_error)?;
    }
    writer.finish().map_err(mcap_error)?;
    let mut buffered = writer.into_inner().into_inner();
    buffered.flush().map_err(create_error)?;
    drop(buffered);
    sync_handle.sync_all().map_err(create_error)?;
    Ok(RecoverSummary {
        input: input.display().to_string(),
        output: output_text,
        messages,
        channels: ids.channels.len(),
        metadata: reader.metadata.len(),
        input_truncated: reader.truncated(),
        stopped_by: reader.stopped_by.clone(),
    })
}

/// Input schema and channel ids to the output's, each registered on first use.
#[derive(Default)]
struct IdMap {
    schemas: HashMap<u16, u16>,
    channels: HashMap<u16, u16>,
}

impl IdMap {
    fn channel<W: Write + Seek>(&mut self, writer: &mut mcap::Writer<W>, channel: &ChannelInfo) -> McapResult<u16> {
        if let Some(id) = self.channels.get(&channel.id) {
            return Ok(*id);
        }
        let schema_id = match &channel.schema {
            None => 0,
            Some(schema) => match self.schemas.get(&schema.id) {
                Some(id) => *id,
                None => {
                    let id = writer.add_schema(&schema.name, &schema.encoding, &schema.data)?;
                    self.schemas.insert(schema.id, id);
                    id
                }
            },
        };
        let id = writer.add_channel(schema_id, &channel.topic, &channel.message_encoding, &channel.metadata)?;
        self.channels.insert(channel.id, id);
        Ok(id)
    }
}
