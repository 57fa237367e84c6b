//! Where frames come from: a V4L2 camera, a recording (image folder or MCAP), or the simulated sensor.
//! Every source hands out RGB frames in raw px with the time they were captured; pacing (the camera's own
//! clock, the recording's timestamps or the simulator's frame rate) is the source's business.

mod folder;
mod simulated;
mod v4l2;

use std::time::{Instant, SystemTime, UNIX_EPOCH};

use image::RgbImage;
use serde::Serialize;

pub use folder::ImageFolder;
pub use simulated::{SceneControl, SimulatedCamera, SIM_DEFAULT_FPS, SIM_DEFAULT_HEIGHT, SIM_DEFAULT_WIDTH};
pub use v4l2::{list_cameras, CameraInfo, CameraSelector, PixelFormat, V4l2Camera, V4l2Options};

/// One frame as captured.
#[derive(Clone, Debug)]
pub struct CapturedImage {
    pub image: RgbImage,
    /// The frame's compressed form when the source already has one (MJPEG cameras, recordings), so that
    /// recording and `/api/frame.jpg` do not encode it again.
    pub jpeg: Option<Vec<u8>>,
    pub captured_at: Instant,
    /// Capture time on the wall clock, microseconds since the Unix epoch (what goes on the wire).
    pub capture_time_us: u64,
}

impl CapturedImage {
    /// A frame captured now.
    pub fn now(image: RgbImage, jpeg: Option<Vec<u8>>) -> Self {
        Self {
            image,
            jpeg,
            captured_at: Instant::now(),
            capture_time_us: unix_time_us(),
        }
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
    #[error("cannot decode a frame from {origin}: {message}")]
    Decode { origin: String, message: String },
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
    fn next_frame(&mut self) -> Result<CapturedImage, CaptureError>;
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

/// Reads an image file (JPEG, PNG, or any format `image` knows by its content) as a frame captured now; a JPEG's
/// bytes are kept so that recording it does not encode it again.
pub fn read_image_file(path: &std::path::Path) -> Result<CapturedImage, CaptureError> {
    let origin = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|source| CaptureError::Io {
        path: origin.clone(),
        source,
    })?;
    if bytes.starts_with(&[0xFF, 0xD8]) {
        let image = decode_jpeg(&bytes, &origin)?;
        return Ok(CapturedImage::now(image, Some(bytes)));
    }
    let image = image::load_from_memory(&bytes)
        .map_err(|e| CaptureError::Decode {
            origin,
            message: e.to_string(),
        })?
        .to_rgb8();
    Ok(CapturedImage::now(image, None))
}

/// Decodes a JPEG to RGB.
pub fn decode_jpeg(bytes: &[u8], origin: &str) -> Result<RgbImage, CaptureError> {
    image::load_from_memory_with_format(bytes, image::ImageFormat::Jpeg)
        .map(|img| img.to_rgb8())
        .map_err(|e| CaptureError::Decode {
            origin: origin.to_string(),
            message: e.to_string(),
        })
}
