//! The simulated camera: nusense-sim renders the pad under the current scene (the demo animation, or a
//! scene held by the API) lit by the LED currents the board reports, at a fixed frame rate.

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use nusense_geometry::PadGeometry;
use nusense_sim::{Renderer, Scene, SensorModel};

use super::{CaptureError, Frame, FramePixels, FrameSource, SourceInfo};

pub const SIM_DEFAULT_WIDTH: u32 = 640;
pub const SIM_DEFAULT_HEIGHT: u32 = 480;
pub const SIM_DEFAULT_FPS: f64 = 30.0;

/// LED currents (mA; Top, Right, Bottom, Left) lighting the pad now.
pub type LedCurrents = Arc<dyn Fn() -> [f32; 4] + Send + Sync>;

#[derive(Clone, Debug)]
enum SceneMode {
    /// The demo animation, timed from when the script (re)started.
    Script {
        since: Instant,
    },
    Hold(Scene),
}

/// Shared switch between the demo animation and a scene held by the API; cheap to clone.
#[derive(Clone)]
pub struct SceneControl {
    mode: Arc<Mutex<SceneMode>>,
    pad: PadGeometry,
}

impl SceneControl {
    pub fn new(pad: PadGeometry) -> Self {
        Self {
            mode: Arc::new(Mutex::new(SceneMode::Script { since: Instant::now() })),
            pad,
        }
    }

    /// Holds `scene` (after validating it against the pad) until another scene or the script replaces it.
    pub fn hold(&self, scene: Scene) -> Result<(), nusense_sim::SceneError> {
        scene.validate(&self.pad)?;
        *self.lock() = SceneMode::Hold(scene);
        Ok(())
    }

    /// [`Self::hold`] for a scene given as JSON; the error says what is wrong with it.
    pub fn hold_json(&self, scene: serde_json::Value) -> Result<(), String> {
        let scene: Scene = serde_json::from_value(scene).map_err(|e| format!("not a scene: {e}"))?;
        self.hold(scene).map_err(|e| e.to_string())
    }

    /// Restarts the demo animation from its beginning.
    pub fn resume_script(&self) {
        *self.lock() = SceneMode::Script { since: Instant::now() };
    }

    pub fn current_scene(&self) -> Scene {
        match &*self.lock() {
            SceneMode::Script { since } => nusense_sim::script::scene_at(since.elapsed().as_secs_f64()),
            SceneMode::Hold(scene) => scene.clone(),
        }
    }

    pub fn describe(&self) -> serde_json::Value {
        let scripted = matches!(&*self.lock(), SceneMode::Script { .. });
        serde_json::json!({ "mode": if scripted { "script" } else { "hold" }, "scene": self.current_scene() })
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, SceneMode> {
        self.mode.lock().unwrap_or_else(|e| e.into_inner())
    }
}

pub struct SimulatedCamera {
    renderer: Renderer,
    control: SceneControl,
    led_currents: LedCurrents,
    period: Duration,
    next_due: Option<Instant>,
    frames: u64,
    size: (u32, u32),
}

impl SimulatedCamera {
    pub fn new(width: u32, height: u32, fps: f64, led_currents: LedCurrents) -> Result<Self, CaptureError> {
        let model = SensorModel::real(width, height);
        let control = SceneControl::new(model.pad);
        let renderer = Renderer::new(model).map_err(|e| CaptureError::Simulator(e.to_string()))?;
        let fps = if fps.is_finite() && fps > 0.0 {
            fps
        } else {
            SIM_DEFAULT_FPS
        };
        Ok(Self {
            renderer,
            control,
            led_currents,
            period: Duration::from_secs_f64(1.0 / fps),
            next_due: None,
            frames: 0,
            size: (width, height),
        })
    }

    pub fn scene_control(&self) -> SceneControl {
        self.control.clone()
    }
}

impl FrameSource for SimulatedCamera {
    fn info(&self) -> SourceInfo {
        SourceInfo {
            kind: "simulator",
            name: "simulated NUSense sensor (nusense-sim)".into(),
            width: self.size.0,
            height: self.size.1,
            fps: 1.0 / self.period.as_secs_f64(),
        }
    }

    fn next_frame(&mut self) -> Result<Frame, CaptureError> {
        // Frames are due on a fixed clock, like a camera's; when rendering falls behind, the clock restarts
        // rather than bursting to catch up.
        let now = Instant::now();
        let due = match self.next_due {
            Some(due) if due > now => {
                std::thread::sleep(due - now);
                due
            }
            _ => now,
        };
        self.next_due = Some(due + self.period);
        let scene = self.control.current_scene();
        let currents = (self.led_currents)();
        let (image, _truth) = self
            .renderer
            .render(&scene, currents, self.frames)
            .map_err(|e| CaptureError::Simulator(e.to_string()))?;
        self.frames += 1;
        // Stamped when the frame exists, as a camera driver stamps it on arrival.
        Ok(Frame::now(FramePixels::Rgb(Arc::new(image))))
    }
}
