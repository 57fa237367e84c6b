//! A V4L2 camera (the `v4l` crate): MJPEG or YUYV, chosen by device path or USB serial number.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use serde::Serialize;
use v4l::buffer::{Flags, Metadata, Type};
use v4l::io::mmap::Stream;
use v4l::io::traits::CaptureStream;
use v4l::video::Capture;
use v4l::{Device, FourCC};

use super::{CaptureError, Frame, FramePixels, FrameSource, SourceInfo};

/// Which camera: a device node, or the USB serial number of the camera (stable across replugging and
/// re-enumeration, unlike /dev/videoN).
#[derive(Clone, Debug, PartialEq)]
pub enum CameraSelector {
    Path(PathBuf),
    Serial(String),
}

impl CameraSelector {
    /// `/dev/...` or any existing path is a device; anything else is a serial number.
    pub fn parse(text: &str) -> Self {
        if text.starts_with('/') || Path::new(text).exists() {
            CameraSelector::Path(PathBuf::from(text))
        } else {
            CameraSelector::Serial(text.to_string())
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum PixelFormat {
    Mjpeg,
    Yuyv,
}

impl std::str::FromStr for PixelFormat {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "mjpeg" | "mjpg" => Ok(Self::Mjpeg),
            "yuyv" => Ok(Self::Yuyv),
            other => Err(format!("unknown pixel format `{other}`; allowed: mjpeg, yuyv")),
        }
    }
}

#[derive(Clone, Debug)]
pub struct V4l2Options {
    pub width: u32,
    pub height: u32,
    pub fps: u32,
    /// None: MJPEG when offered, else YUYV.
    pub format: Option<PixelFormat>,
}

impl Default for V4l2Options {
    fn default() -> Self {
        Self {
            width: 640,
            height: 480,
            fps: 30,
            format: None,
        }
    }
}

/// A capture node found under /sys/class/video4linux.
#[derive(Clone, Debug, Serialize)]
pub struct CameraInfo {
    pub path: String,
    pub name: String,
    pub usb_serial: Option<String>,
}

/// Lists V4L2 capture nodes with their names and USB serial numbers.
pub fn list_cameras() -> Vec<CameraInfo> {
    let Ok(entries) = std::fs::read_dir("/sys/class/video4linux") else {
        return Vec::new();
    };
    let mut cameras: Vec<CameraInfo> = entries
        .filter_map(|e| e.ok())
        .filter_map(|entry| {
            let node = entry.file_name().to_string_lossy().to_string();
            if !node.starts_with("video") {
                return None;
            }
            let sys = entry.path();
            let name = std::fs::read_to_string(sys.join("name"))
                .unwrap_or_default()
                .trim()
                .to_string();
            Some(CameraInfo {
                path: format!("/dev/{node}"),
                name,
                usb_serial: usb_serial_of(&sys),
            })
        })
        .collect();
    cameras.sort_by(|a, b| a.path.cmp(&b.path));
    cameras
}

/// The `serial` attribute of the USB device a video node hangs off (the node's device is a USB interface,
/// whose parent is the device).
fn usb_serial_of(sys_node: &Path) -> Option<String> {
    let mut dir = std::fs::canonicalize(sys_node.join("device")).ok()?;
    for _ in 0..3 {
        if let Ok(serial) = std::fs::read_to_string(dir.join("serial")) {
            return Some(serial.trim().to_string());
        }
        dir = dir.parent()?.to_path_buf();
    }
    None
}

pub struct V4l2Camera {
    selector: CameraSelector,
    options: V4l2Options,
    device_path: String,
    open: Option<OpenCamera>,
}

struct OpenCamera {
    // Field order matters: the stream must be dropped (streaming stopped, buffers unmapped) before the device.
    stream: Stream<'static>,
    _device: Device,
    format: PixelFormat,
    width: u32,
    height: u32,
    fps: f64,
}

impl V4l2Camera {
    pub fn open(selector: CameraSelector, options: V4l2Options) -> Result<Self, CaptureError> {
        let mut camera = Self {
            device_path: describe(&selector),
            selector,
            options,
            open: None,
        };
        camera.reopen()?;
        Ok(camera)
    }

    fn resolve(&self) -> Result<PathBuf, CaptureError> {
        match &self.selector {
            CameraSelector::Path(path) => Ok(path.clone()),
            CameraSelector::Serial(serial) => {
                let cameras = list_cameras();
                // A UVC camera has several nodes (video and metadata); the first capture-capable one wins.
                cameras
                    .iter()
                    .filter(|c| c.usb_serial.as_deref() == Some(serial.as_str()))
                    .map(|c| PathBuf::from(&c.path))
                    .find(|p| {
                        Device::with_path(p)
                            .and_then(|d| d.query_caps())
                            .is_ok_and(|caps| caps.capabilities.contains(v4l::capability::Flags::VIDEO_CAPTURE))
                    })
                    .ok_or_else(|| CaptureError::NoCameraWithSerial {
                        serial: serial.clone(),
                        seen: cameras
                            .iter()
                            .map(|c| format!("{} ({})", c.path, c.usb_serial.as_deref().unwrap_or("no serial")))
                            .collect::<Vec<_>>()
                            .join(", "),
                    })
            }
        }
    }
}

fn describe(selector: &CameraSelector) -> String {
    match selector {
        CameraSelector::Path(p) => p.display().to_string(),
        CameraSelector::Serial(s) => format!("camera with serial {s}"),
    }
}

fn open_camera(path: &Path, options: &V4l2Options) -> Result<OpenCamera, CaptureError> {
    let device_name = path.display().to_string();
    let open_error = |source| CaptureError::Open {
        device: device_name.clone(),
        source,
    };
    let device = Device::with_path(path).map_err(open_error)?;
    let offered: Vec<FourCC> = device
        .enum_formats()
        .map_err(open_error)?
        .into_iter()
        .map(|d| d.fourcc)
        .collect();
    let mjpeg = FourCC::new(b"MJPG");
    let yuyv = FourCC::new(b"YUYV");
    let wanted: Vec<(PixelFormat, FourCC)> = match options.format {
        Some(PixelFormat::Mjpeg) => vec![(PixelFormat::Mjpeg, mjpeg)],
        Some(PixelFormat::Yuyv) => vec![(PixelFormat::Yuyv, yuyv)],
        None => vec![(PixelFormat::Mjpeg, mjpeg), (PixelFormat::Yuyv, yuyv)],
    };
    let unsupported = || CaptureError::UnsupportedFormat {
        device: device_name.clone(),
        width: options.width,
        height: options.height,
        offered: offered.iter().map(|f| f.to_string()).collect::<Vec<_>>().join(", "),
    };
    let (format, fourcc) = wanted
        .into_iter()
        .find(|(_, f)| offered.contains(f))
        .ok_or_else(unsupported)?;
    let mut requested = device.format().map_err(open_error)?;
    requested.width = options.width;
    requested.height = options.height;
    requested.fourcc = fourcc;
    let granted = device.set_format(&requested).map_err(open_error)?;
    if granted.fourcc != fourcc {
        return Err(unsupported());
    }
    let params = device
        .set_params(&v4l::video::capture::Parameters::with_fps(options.fps.max(1)))
        .map_err(open_error)?;
    let fps = if params.interval.numerator > 0 {
        params.interval.denominator as f64 / params.interval.numerator as f64
    } else {
        options.fps as f64
    };
    let mut stream = Stream::with_buffers(&device, Type::VideoCapture, 4).map_err(open_error)?;
    // A camera that stops answering for this long has vanished (unplugged, or the driver hung).
    stream.set_timeout(Duration::from_secs(2));
    Ok(OpenCamera {
        stream,
        _device: device,
        format,
        width: granted.width,
        height: granted.height,
        fps,
    })
}

impl FrameSource for V4l2Camera {
    fn info(&self) -> SourceInfo {
        let (width, height, fps) = self.open.as_ref().map(|o| (o.width, o.height, o.fps)).unwrap_or((
            self.options.width,
            self.options.height,
            self.options.fps as f64,
        ));
        SourceInfo {
            kind: "camera",
            name: self.device_path.clone(),
            width,
            height,
            fps,
        }
    }

    fn next_frame(&mut self) -> Result<Frame, CaptureError> {
        let device = self.device_path.clone();
        let Some(open) = self.open.as_mut() else {
            return Err(CaptureError::Vanished {
                device,
                source: std::io::Error::new(std::io::ErrorKind::NotConnected, "camera is not open"),
            });
        };
        // The buffer goes back to the driver on the next dequeue, so its bytes are copied out (a memcpy of the
        // frame: `nusense bench` measures it as the floor).
        let result = open.stream.next().map(|(buf, meta)| {
            (
                buf[..(meta.bytesused as usize).min(buf.len())].to_vec(),
                buffer_age(meta),
            )
        });
        let (bytes, age) = match result {
            Ok(frame) => frame,
            Err(source) => {
                self.open = None;
                return Err(CaptureError::Vanished { device, source });
            }
        };
        let pixels = match open.format {
            PixelFormat::Mjpeg => FramePixels::Jpeg(Arc::new(bytes)),
            PixelFormat::Yuyv => FramePixels::Yuyv {
                bytes: Arc::new(bytes),
                width: open.width,
                height: open.height,
            },
        };
        Ok(Frame::captured_ago(pixels, age))
    }

    fn reopen(&mut self) -> Result<(), CaptureError> {
        self.open = None;
        let path = self.resolve()?;
        self.device_path = path.display().to_string();
        self.open = Some(open_camera(&path, &self.options)?);
        Ok(())
    }
}

/// How long ago the driver stamped the buffer. UVC stamps `CLOCK_MONOTONIC` (the clock `Instant` reads) at the
/// start of the frame's exposure or at its end of transfer; a driver whose timestamps are on another clock gives
/// zero (the frame is taken as captured when dequeued) rather than a wrong age.
fn buffer_age(meta: &Metadata) -> Duration {
    if meta.flags & Flags::TIMESTAMP_MASK != Flags::TIMESTAMP_MONOTONIC {
        return Duration::ZERO;
    }
    let mut now = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime writes the timespec it is given.
    if unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut now) } != 0 {
        return Duration::ZERO;
    }
    let now_us = now.tv_sec as i128 * 1_000_000 + now.tv_nsec as i128 / 1_000;
    let stamped_us = meta.timestamp.sec as i128 * 1_000_000 + meta.timestamp.usec as i128;
    // A stamp from the future or from long ago is not this frame's.
    match now_us - stamped_us {
        age @ 0..=10_000_000 => Duration::from_micros(age as u64),
        _ => Duration::ZERO,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn selector_tells_paths_from_serials() {
        assert_eq!(
            CameraSelector::parse("/dev/video0"),
            CameraSelector::Path("/dev/video0".into())
        );
        assert_eq!(CameraSelector::parse("SN1234"), CameraSelector::Serial("SN1234".into()));
    }
}
