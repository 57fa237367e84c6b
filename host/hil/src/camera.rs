//! What the "camera brightness follows LED current" check looks through: a real sensor camera (V4L2), or the
//! simulated sensor fed with the currents the board reports it is driving.

use image::RgbImage;
use nusense_sim::{Renderer, Scene, SensorModel};

use nusense_capture::{CameraSelector, FrameSource, V4l2Camera, V4l2Options};

#[derive(Debug, thiserror::Error)]
pub enum CameraProbeError {
    #[error("the camera failed: {0}")]
    Capture(#[from] nusense_capture::CaptureError),
    #[error("the simulated sensor cannot be built: {0}")]
    Model(#[from] nusense_sim::ModelError),
    #[error("the simulated sensor cannot render: {0}")]
    Render(#[from] nusense_sim::RenderError),
    #[error("the frame is empty")]
    EmptyFrame,
}

/// Mean image brightness for the LEDs as they are now.
pub trait BrightnessProbe {
    fn describe(&self) -> String;
    /// Mean luma (0..=255) of what the camera sees now. `measured_ma` is what the board's telemetry says the
    /// strings carry (Top, Right, Bottom, Left); a real camera sees the light itself and ignores it.
    fn brightness(&mut self, measured_ma: [f32; 4]) -> Result<f64, CameraProbeError>;
}

/// Mean Rec. 601 luma of a frame.
pub fn mean_luma(frame: &RgbImage) -> Option<f64> {
    let pixels = u64::from(frame.width()) * u64::from(frame.height());
    if pixels == 0 {
        return None;
    }
    let sum: f64 = frame
        .pixels()
        .map(|p| 0.299 * f64::from(p[0]) + 0.587 * f64::from(p[1]) + 0.114 * f64::from(p[2]))
        .sum();
    Some(sum / pixels as f64)
}

/// The simulated sensor at rest (no contact), lit with the measured currents.
pub struct SimulatedCameraProbe {
    renderer: Renderer,
    frames: u64,
}

impl SimulatedCameraProbe {
    /// A small frame is enough for a mean brightness.
    pub fn new(width: u32, height: u32) -> Result<Self, CameraProbeError> {
        Ok(Self {
            renderer: Renderer::new(SensorModel::real(width, height))?,
            frames: 0,
        })
    }
}

impl BrightnessProbe for SimulatedCameraProbe {
    fn describe(&self) -> String {
        let model = self.renderer.model();
        format!("simulated sensor camera {}x{} (nusense-sim)", model.width, model.height)
    }

    fn brightness(&mut self, measured_ma: [f32; 4]) -> Result<f64, CameraProbeError> {
        // A new noise seed per frame, like a real camera's sensor noise.
        self.frames += 1;
        let (frame, _) = self.renderer.render(&Scene::rest(), measured_ma, self.frames)?;
        mean_luma(&frame).ok_or(CameraProbeError::EmptyFrame)
    }
}

/// A V4L2 camera looking at the pad.
pub struct V4l2CameraProbe {
    camera: V4l2Camera,
    name: String,
}

/// Frames thrown away after a change of light: the driver's queue still holds frames exposed before it.
const STALE_FRAMES: usize = 4;
/// Frames averaged per measurement.
const AVERAGED_FRAMES: usize = 3;

impl V4l2CameraProbe {
    /// `device` is a /dev/video path or the camera's USB serial number.
    pub fn open(device: &str) -> Result<Self, CameraProbeError> {
        let camera = V4l2Camera::open(CameraSelector::parse(device), V4l2Options::default())?;
        Ok(Self {
            camera,
            name: device.to_owned(),
        })
    }
}

impl BrightnessProbe for V4l2CameraProbe {
    fn describe(&self) -> String {
        format!("camera {}", self.name)
    }

    fn brightness(&mut self, _measured_ma: [f32; 4]) -> Result<f64, CameraProbeError> {
        for _ in 0..STALE_FRAMES {
            self.camera.next_frame()?;
        }
        let mut total = 0.0;
        for _ in 0..AVERAGED_FRAMES {
            let frame = self.camera.next_frame()?;
            total += mean_luma(&frame.image).ok_or(CameraProbeError::EmptyFrame)?;
        }
        Ok(total / AVERAGED_FRAMES as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_luma_of_uniform_frames() {
        let white = RgbImage::from_pixel(4, 3, image::Rgb([255, 255, 255]));
        assert!((mean_luma(&white).unwrap() - 255.0).abs() < 1e-9);
        let black = RgbImage::new(4, 3);
        assert_eq!(mean_luma(&black), Some(0.0));
        assert_eq!(mean_luma(&RgbImage::new(0, 0)), None);
    }

    #[test]
    fn the_simulated_camera_gets_brighter_with_more_current() {
        let mut probe = SimulatedCameraProbe::new(80, 60).unwrap();
        let dim = probe.brightness([20.0; 4]).unwrap();
        let bright = probe.brightness([100.0; 4]).unwrap();
        assert!(bright > dim * 1.2, "dim {dim}, bright {bright}");
    }
}
