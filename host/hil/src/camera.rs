//! What the "camera brightness follows LED current" check looks through: a real sensor camera (V4L2), or the
//! simulated sensor fed with the currents the board reports it is driving.

use image::RgbImage;
use nusense_protocol::Side;
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
    #[error("the simulated camera has no light reading yet (the emulator's light channel is silent)")]
    NoLight,
    #[error("the simulated camera got no light reading for board time {0} us (the emulator's light channel stopped)")]
    NoLightSince(u64),
    #[error("the camera's frame does not decode: {0}")]
    Decode(#[from] nusense_capture::DecodeError),
}

/// Mean image brightness for the LEDs as they are now, seen from outside the board: never from what the board
/// reports.
pub trait BrightnessProbe {
    fn describe(&self) -> String;
    /// Mean luma (0..=255) of what the camera sees now.
    fn brightness(&mut self) -> Result<f64, CameraProbeError>;
    /// Mean luma of the light at board time `uptime_us` or later (the time of the telemetry frame that showed the
    /// state to look at): what a camera fed from the board's side sees lags, and must not be read before that
    /// moment has reached it. A camera that looks at the pad itself sees the present, which is later.
    fn brightness_since(&mut self, uptime_us: u64) -> Result<f64, CameraProbeError> {
        let _ = uptime_us;
        self.brightness()
    }
    /// The string current that gives `luma` with only `side` lit, when this camera is calibrated in milliamps
    /// (the simulated one is: it knows its renderer); `None` for an uncalibrated camera, which can only compare
    /// the sides with each other.
    fn current_ma(&mut self, side: Side, luma: f64) -> Result<Option<f64>, CameraProbeError>;
}

/// Where the simulated camera's light comes from: the strings' true currents (Top, Right, Bottom, Left), from
/// the simulated plant itself, not from the board's telemetry; `None` until known. Given a board time, the light
/// at that time or later (a source that is always current may ignore it); `None` if it never came.
pub type LightSource = Box<dyn Fn(Option<u64>) -> Option<[f32; 4]> + Send>;

/// Currents at which the simulated camera calibrates each side (piecewise linear between them).
const CALIBRATION_MA: [f32; 6] = [0.0, 25.0, 50.0, 75.0, 100.0, 130.0];

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

/// The simulated sensor at rest (no contact), lit with the strings' true currents from its [`LightSource`].
pub struct SimulatedCameraProbe {
    renderer: Renderer,
    frames: u64,
    light: LightSource,
    /// Per side: mean luma at each of [`CALIBRATION_MA`] with only that side lit (rendered once, on first use).
    calibration: Option<[[f64; CALIBRATION_MA.len()]; 4]>,
}

impl SimulatedCameraProbe {
    /// A small frame is enough for a mean brightness.
    pub fn new(width: u32, height: u32, light: LightSource) -> Result<Self, CameraProbeError> {
        Ok(Self {
            renderer: Renderer::new(SensorModel::real(width, height))?,
            frames: 0,
            light,
            calibration: None,
        })
    }

    fn render_luma(&mut self, currents_ma: [f32; 4]) -> Result<f64, CameraProbeError> {
        // A new noise seed per frame, like a real camera's sensor noise.
        self.frames += 1;
        let (frame, _) = self.renderer.render(&Scene::rest(), currents_ma, self.frames)?;
        mean_luma(&frame).ok_or(CameraProbeError::EmptyFrame)
    }

    fn calibrated(&mut self) -> Result<[[f64; CALIBRATION_MA.len()]; 4], CameraProbeError> {
        if let Some(calibration) = self.calibration {
            return Ok(calibration);
        }
        let mut calibration = [[0.0; CALIBRATION_MA.len()]; 4];
        for side in Side::ALL {
            for (point, &ma) in calibration[side.index()].iter_mut().zip(&CALIBRATION_MA) {
                let mut currents = [0.0; 4];
                currents[side.index()] = ma;
                *point = self.render_luma(currents)?;
            }
        }
        self.calibration = Some(calibration);
        Ok(calibration)
    }
}

impl BrightnessProbe for SimulatedCameraProbe {
    fn describe(&self) -> String {
        let model = self.renderer.model();
        format!("simulated sensor camera {}x{} (nusense-sim)", model.width, model.height)
    }

    fn brightness(&mut self) -> Result<f64, CameraProbeError> {
        let currents = (self.light)(None).ok_or(CameraProbeError::NoLight)?;
        self.render_luma(currents)
    }

    fn brightness_since(&mut self, uptime_us: u64) -> Result<f64, CameraProbeError> {
        let currents = (self.light)(Some(uptime_us)).ok_or(CameraProbeError::NoLightSince(uptime_us))?;
        self.render_luma(currents)
    }

    fn current_ma(&mut self, side: Side, luma: f64) -> Result<Option<f64>, CameraProbeError> {
        let curve = self.calibrated()?[side.index()];
        // Piecewise linear between the calibration points; beyond the last, the last segment extended.
        let segment = (1..curve.len()).find(|&i| luma <= curve[i]).unwrap_or(curve.len() - 1);
        let (l0, l1) = (curve[segment - 1], curve[segment]);
        let (m0, m1) = (
            f64::from(CALIBRATION_MA[segment - 1]),
            f64::from(CALIBRATION_MA[segment]),
        );
        if l1 <= l0 {
            return Ok(None);
        }
        Ok(Some(m0 + (luma - l0) * (m1 - m0) / (l1 - l0)))
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

    fn current_ma(&mut self, _side: Side, _luma: f64) -> Result<Option<f64>, CameraProbeError> {
        Ok(None)
    }

    fn brightness(&mut self) -> Result<f64, CameraProbeError> {
        for _ in 0..STALE_FRAMES {
            self.camera.next_frame()?;
        }
        let mut total = 0.0;
        for _ in 0..AVERAGED_FRAMES {
            let frame = self.camera.next_frame()?;
            total += mean_luma(&frame.to_rgb()?).ok_or(CameraProbeError::EmptyFrame)?;
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
    fn the_simulated_camera_sees_the_true_light_and_reads_it_back_in_milliamps() {
        let light = std::sync::Arc::new(std::sync::Mutex::new([20.0f32; 4]));
        let source = light.clone();
        let mut probe = SimulatedCameraProbe::new(80, 60, Box::new(move |_| Some(*source.lock().unwrap()))).unwrap();
        let dim = probe.brightness().unwrap();
        *light.lock().unwrap() = [100.0; 4];
        let bright = probe.brightness().unwrap();
        assert!(bright > dim * 1.2, "dim {dim}, bright {bright}");
        for (side, ma) in [(Side::Top, 100.0f32), (Side::Left, 60.0), (Side::Bottom, 110.0)] {
            let mut currents = [0.0; 4];
            currents[side.index()] = ma;
            *light.lock().unwrap() = currents;
            let luma = probe.brightness().unwrap();
            let estimate = probe.current_ma(side, luma).unwrap().unwrap();
            assert!(
                (estimate - f64::from(ma)).abs() < 0.05 * f64::from(ma),
                "{side}: {ma} mA read back as {estimate}"
            );
        }
    }
}
