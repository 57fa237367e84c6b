//! Replay of the frames of an MCAP recording, paced by their recorded capture times.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use super::{read_recording, RecordedFrame};

use nusense_capture::{decode_jpeg, CaptureError, CapturedImage, FrameSource, SourceInfo};

pub struct McapReplay {
    path: PathBuf,
    frames: Vec<RecordedFrame>,
    next: usize,
    looping: bool,
    /// Wall-clock instant that corresponds to the first frame's capture time in this pass.
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
        let recording = read_recording(path).map_err(|e| CaptureError::Recording {
            path: path_text.clone(),
            message: e.to_string(),
        })?;
        let frames = recording.frames();
        let first = frames.first().ok_or_else(|| CaptureError::Empty(path_text.clone()))?;
        let image = decode_jpeg(&first.jpeg, &path_text)?;
        let span_s = frames
            .last()
            .map(|l| l.capture_time_us.saturating_sub(first.capture_time_us))
            .unwrap_or(0) as f64
            / 1e6;
        let fps = if frames.len() > 1 && span_s > 0.0 {
            (frames.len() - 1) as f64 / span_s
        } else {
            30.0
        };
        Ok(Self {
            path: path.to_path_buf(),
            size: image.dimensions(),
            frames,
            next: 0,
            looping,
            pass_start: None,
            fps,
            paced: true,
            truncated: recording.truncated,
        })
    }

    /// Hands out frames as fast as they are asked for (batch processing rather than live replay).
    pub fn unpaced(mut self) -> Self {
        self.paced = false;
        self
    }

    pub fn len(&self) -> usize {
        self.frames.len()
    }

    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }
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

    fn next_frame(&mut self) -> Result<CapturedImage, CaptureError> {
        if self.next >= self.frames.len() {
            if !self.looping {
                return Err(CaptureError::EndOfStream);
            }
            self.next = 0;
            self.pass_start = None;
        }
        let first_us = self.frames[0].capture_time_us;
        let frame = &self.frames[self.next];
        self.next += 1;
        let pass_start = *self.pass_start.get_or_insert_with(Instant::now);
        let due = pass_start + Duration::from_micros(frame.capture_time_us.saturating_sub(first_us));
        let now = Instant::now();
        if self.paced && due > now {
            std::thread::sleep(due - now);
        }
        let image = decode_jpeg(&frame.jpeg, &self.path.display().to_string())?;
        Ok(CapturedImage::now(image, Some(frame.jpeg.clone())))
    }
}
