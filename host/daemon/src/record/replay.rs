//! Replay of the frames of an MCAP recording, paced by their recorded capture times, streamed from disk.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use super::{ends_finished, RecordedFrame, RecordingReader};

use nusense_capture::{jpeg_dimensions, CaptureError, Frame, FramePixels, FrameSource, SourceInfo};

/// Frames read ahead to learn the frame rate before the first is handed out.
const LOOKAHEAD_FRAMES: usize = 8;

pub struct McapReplay {
    path: PathBuf,
    reader: RecordingReader,
    lookahead: VecDeque<RecordedFrame>,
    looping: bool,
    /// Capture time of the first frame of the recording, and the wall-clock instant it maps to in this pass.
    first_us: u64,
    pass_start: Option<Instant>,
    size: (u32, u32),
    fps: f64,
    paced: bool,
    /// The recording was cut short (its writer was killed); replay still plays what survived.
    pub truncated: bool,
}

impl McapReplay {
    pub fn open(path: &Path, looping: bool) -> Result<Self, CaptureError> {
        let path_text = path.display().to_string();
        let recording_error = |error: super::RecordError| CaptureError::Recording {
            path: path_text.clone(),
            message: error.to_string(),
        };
        let truncated = !ends_finished(path).map_err(recording_error)?;
        let mut reader = RecordingReader::open(path).map_err(recording_error)?;
        let mut lookahead = VecDeque::new();
        while lookahead.len() < LOOKAHEAD_FRAMES {
            match next_recorded_frame(&mut reader) {
                Some(frame) => lookahead.push_back(frame),
                None => break,
            }
        }
        let first = lookahead
            .front()
            .ok_or_else(|| CaptureError::Empty(path_text.clone()))?;
        let size = jpeg_dimensions(&first.jpeg).map_err(|source| CaptureError::Decode {
            origin: path_text.clone(),
            source,
        })?;
        let first_us = first.capture_time_us;
        let span_s = lookahead
            .back()
            .map(|last| last.capture_time_us.saturating_sub(first_us))
            .unwrap_or(0) as f64
            / 1e6;
        let fps = if lookahead.len() > 1 && span_s > 0.0 {
            (lookahead.len() - 1) as f64 / span_s
        } else {
            30.0
        };
        Ok(Self {
            path: path.to_path_buf(),
            size,
            reader,
            lookahead,
            looping,
            first_us,
            pass_start: None,
            fps,
            paced: true,
            truncated,
        })
    }

    /// Hands out frames as fast as they are asked for (batch processing rather than live replay).
    pub fn unpaced(mut self) -> Self {
        self.paced = false;
        self
    }

    fn next_recorded(&mut self) -> Result<Option<RecordedFrame>, CaptureError> {
        if let Some(frame) = self.lookahead.pop_front() {
            return Ok(Some(frame));
        }
        if let Some(frame) = next_recorded_frame(&mut self.reader) {
            return Ok(Some(frame));
        }
        if !self.looping {
            return Ok(None);
        }
        self.reader = RecordingReader::open(&self.path).map_err(|error| CaptureError::Recording {
            path: self.path.display().to_string(),
            message: error.to_string(),
        })?;
        self.pass_start = None;
        Ok(next_recorded_frame(&mut self.reader))
    }
}

fn next_recorded_frame(reader: &mut RecordingReader) -> Option<RecordedFrame> {
    reader.by_ref().find_map(|message| message.frame())
}

impl FrameSource for McapReplay {
    fn info(&self) -> SourceInfo {
        SourceInfo {
            kind: "replay",
            name: self.path.display().to_string(),
            width: self.size.0,
            height: self.size.1,
            fps: self.fps,
        }
    }

    fn next_frame(&mut self) -> Result<Frame, CaptureError> {
        let Some(frame) = self.next_recorded()? else {
            return Err(CaptureError::EndOfStream);
        };
        let pass_start = *self.pass_start.get_or_insert_with(Instant::now);
        let due = pass_start + Duration::from_micros(frame.capture_time_us.saturating_sub(self.first_us));
        let now = Instant::now();
        if self.paced && due > now {
            std::thread::sleep(due - now);
        }
        Ok(Frame::now(FramePixels::Jpeg(Arc::new(frame.jpeg))))
    }
}
