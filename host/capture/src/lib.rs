//! Where frames come from: a V4L2 camera, a recording (image folder or MCAP), or the simulated sensor, and how
//! they are decoded ([`decode`]). Every source hands out frames as the camera delivered them (MJPEG, YUYV, or RGB
//! for sources that have nothing else) with the time they were captured; decoding is left to whoever knows how
//! much of the frame it needs. Pacing (the camera's own clock, the recording's timestamps or the simulator's frame
//! rate) is the source's business.

pub mod decode;
mod folder;
mod simulated;
mod v4l2;

use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use image::RgbImage;
use serde::Serialize;

pub use decode::{
    jpeg_dimensions, rgb_to_yuyv, yuyv_to_rgb, DecodeError, DecodeOptions, DecodedFrame, Decoder, PixelRect, Scale,
};
pub use folder::ImageFolder;
pub use simulated::{SceneControl, SimulatedCamera, SIM_DEFAULT_FPS, SIM_DEFAULT_HEIGHT, SIM_DEFAULT_WIDTH};
pub use v4l2::{list_cameras, CameraInfo, CameraSelector, PixelFormat, V4l2Camera, V4l2Options};

/// A frame's pixels as the source delivered them.
#[derive(Clone, Debug)]
pub enum FramePixels {
    /// An MJPEG camera's frame or a JPEG file, kept as bytes: recording writes them as they are, and decoding
    /// takes only what is needed.
    Jpeg(Arc<Vec<u8>>),
    /// A YUYV 4:2:2 camera frame.
    Yuyv {
        bytes: Arc<Vec<u8>>,
        width: u32,
        height: u32,
    },
    /// Sources with nothing else (the simulator, PNG files).
    Rgb(Arc<RgbImage>),
}

impl FramePixels {
    /// Width and height of the frame (a JPEG's from its header, without decoding).
    pub fn dimensions(&self) -> Result<(u32, u32), DecodeError> {
        match self {
            FramePixels::Jpeg(bytes) => jpeg_dimensions(bytes),
            FramePixels::Yuyv { width, height, .. } => Ok((*width, *height)),
            FramePixels::Rgb(image) => Ok(image.dimensions()),
        }
    }

    /// The compressed frame, when the source delivered one.
    pub fn jpeg(&self) -> Option<&Arc<Vec<u8>>> {
        match self {
            FramePixels::Jpeg(bytes) => Some(bytes),
            _ => None,
        }
    }

    /// The whole frame at full size, in RGB (the dashboard's picture, a frame to analyse offline).
    pub fn to_rgb(&self) -> Result<RgbImage, DecodeError> {
        match self {
            FramePixels::Rgb(image) => Ok(image.as_ref().clone()),
            pixels => Ok(Decoder::new().decode(pixels, &DecodeOptions::FULL)?.image),
        }
    }

    /// Bytes as delivered (what "bytes to reading" starts from).
    pub fn byte_len(&self) -> usize {
        match self {
            FramePixels::Jpeg(bytes) | FramePixels::Yuyv { bytes, .. } => bytes.len(),
            FramePixels::Rgb(image) => image.as_raw().len(),
        }
    }
}

/// One frame as captured.
#[derive(Clone, Debug)]
pub struct Frame {
    pub pixels: FramePixels,
    /// When the frame was captured on the monotonic clock: the driver's buffer timestamp for a V4L2 camera
    /// (`CLOCK_MONOTONIC`, the clock `Instant` reads), else when the source produced it. Latency is measured
    /// from here.
    pub captured_at: Instant,
    /// The same moment on the wall clock, microseconds since the Unix epoch (what goes on the wire).
    pub capture_time_us: u64,
}

impl Frame {
    /// A frame captured now.
    pub fn now(pixels: FramePixels) -> Self {
        Self::captured_ago(pixels, Duration::ZERO)
    }

    /// A frame captured `age` ago (a driver timestamp older than the moment the frame was dequeued).
    pub fn captured_ago(pixels: FramePixels, age: Duration) -> Self {
        let now = Instant::now();
        Self {
            pixels,
            captured_at: now.checked_sub(age).unwrap_or(now),
            capture_time_us: unix_time_us().saturating_sub(age.as_micros() as u64),
        }
    }

    /// The whole frame at full size, in RGB.
    pub fn to_rgb(&self) -> Result<RgbImage, DecodeError> {
        self.pixels.to_rgb()
    }
}

/// What a source is, for `/api/status` and start-up messages.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct SourceInfo {
    /// "camera", "replay" or "simulator".
    pub kind: &'static str,
    /// Device path, file or folder, or a description of the simulated sensor.
    pub name: String,
    pub width: u32,
    pub height: u32,
    pub fps: f64,
}

#[derive(Debug, thiserror::Error)]
pub enum CaptureError {
    #[error("cannot open camera {device}: {source}")]
    Open { device: String, source: std::io::Error },
    #[error("no V4L2 camera with USB serial number {serial} (seen: {seen})")]
    NoCameraWithSerial { serial: String, seen: String },
    #[error("camera {device} does not offer MJPEG or YUYV at {width}x{height} (it offers {offered})")]
    UnsupportedFormat {
        device: String,
        width: u32,
        height: u32,
        offered: String,
    },
    #[error("camera {device} stopped delivering frames: {source}")]
    Vanished { device: String, source: std::io::Error },
    #[error("cannot decode a frame from {origin}: {source}")]
    Decode { origin: String, source: DecodeError },
    #[error("cannot read the image {origin}: {message}")]
    Image { origin: String, message: String },
    #[error("cannot read {path}: {source}")]
    Io { path: String, source: std::io::Error },
    #[error("no frames in {0}")]
    Empty(String),
    #[error("cannot read recording {path}: {message}")]
    Recording { path: String, message: String },
    #[error("the simulated sensor failed: {0}")]
    Simulator(String),
    #[error("the recording or folder has no more frames")]
    EndOfStream,
}

impl CaptureError {
    /// A source that failed this way may come back (a camera unplugged and replugged); the capture loop
    /// reports it and retries instead of giving up.
    pub fn is_transient(&self) -> bool {
        matches!(
            self,
            CaptureError::Vanished { .. } | CaptureError::Open { .. } | CaptureError::NoCameraWithSerial { .. }
        )
    }
}

/// A source of frames. `next_frame` blocks until the next frame is due.
pub trait FrameSource: Send {
    fn info(&self) -> SourceInfo;
    fn next_frame(&mut self) -> Result<Frame, CaptureError>;
    /// Re-open after a transient error (a camera that vanished). Sources that cannot vanish do nothing.
    fn reopen(&mut self) -> Result<(), CaptureError> {
        Ok(())
    }
}

pub fn unix_time_us() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_micros() as u64)
        .unwrap_or(0)
}

/// Reads an image file as a frame captured now: a JPEG's bytes as they are (nothing decoded), any other format
/// `image` knows (by its content) decoded to RGB.
pub fn read_image_file(path: &std::path::Path) -> Result<Frame, CaptureError> {
    let origin = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|source| CaptureError::Io {
        path: origin.clone(),
        source,
    })?;
    if bytes.starts_with(&[0xFF, 0xD8]) {
        jpeg_dimensions(&bytes).map_err(|source| CaptureError::Decode { origin, source })?;
        return Ok(Frame::now(FramePixels::Jpeg(Arc::new(bytes))));
    }
    let image = image::load_from_memory(&bytes)
        .map_err(|e| CaptureError::Image {
            origin,
            message: e.to_string(),
        })?
        .to_rgb8();
    Ok(Frame::now(FramePixels::Rgb(Arc::new(image))))
}

/// Reads an image file and decodes all of it to RGB (a rest frame, a frame to analyse offline).
pub fn read_image_rgb(path: &std::path::Path) -> Result<RgbImage, CaptureError> {
    read_image_file(path)?.to_rgb().map_err(|source| CaptureError::Decode {
        origin: path.display().to_string(),
        source,
    })
}
