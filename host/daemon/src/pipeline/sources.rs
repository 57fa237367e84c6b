//! Choosing where frames and LED control come from, shared by `serve`, `record` and `replay`.

use std::path::PathBuf;
use std::sync::Arc;

use nusense_board::virtual_board::VirtualBoard;
use nusense_board::{BoardTarget, SupervisedLink, SupervisorOptions};
use nusense_capture::{
    CameraSelector, CaptureError, FrameSource, ImageFolder, SceneControl, SimulatedCamera, V4l2Camera, V4l2Options,
};

use crate::record::McapReplay;

use super::{Board, LinkedBoard, NoBoard};

/// Where frames come from.
#[derive(Clone, Debug)]
pub enum FrameChoice {
    /// The simulated sensor, lit by the (virtual or real) board's LED currents.
    Simulator { width: u32, height: u32, fps: f64 },
    Camera {
        selector: CameraSelector,
        options: V4l2Options,
    },
    /// A folder of images or an `.mcap` recording.
    Replay { path: PathBuf, fps: f64, looping: bool },
}

/// Which board controls the LEDs.
#[derive(Clone, Debug)]
pub enum BoardChoice {
    /// The virtual board (firmware logic + simulated LEDs) behind a pty.
    Virtual,
    Port(String),
    None,
}

#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    #[error(transparent)]
    Capture(#[from] CaptureError),
    #[error("cannot start the virtual LED board: {0}")]
    VirtualBoard(String),
}

pub struct Sources {
    pub frames: Box<dyn FrameSource>,
    pub board: Arc<dyn Board>,
    /// Present on the simulator: lets the API change the simulated contact.
    pub scene: Option<SceneControl>,
}

pub fn open_sources(frames: &FrameChoice, board: &BoardChoice) -> Result<Sources, SourceError> {
    let board: Arc<dyn Board> = match board {
        BoardChoice::Virtual => {
            let virtual_board = VirtualBoard::spawn_pty().map_err(|e| SourceError::VirtualBoard(e.to_string()))?;
            let link = SupervisedLink::spawn(
                BoardTarget::Path(virtual_board.path().to_string()),
                SupervisorOptions::default(),
            );
            Arc::new(LinkedBoard::new(link, Some(virtual_board)))
        }
        BoardChoice::Port(path) => {
            let link = SupervisedLink::spawn(BoardTarget::Path(path.clone()), SupervisorOptions::default());
            Arc::new(LinkedBoard::new(link, None))
        }
        BoardChoice::None => Arc::new(NoBoard),
    };
    let (frames, scene): (Box<dyn FrameSource>, Option<SceneControl>) = match frames {
        FrameChoice::Simulator { width, height, fps } => {
            let lighting = board.clone();
            let camera = SimulatedCamera::new(*width, *height, *fps, Arc::new(move || lighting.led_currents_ma()))?;
            let scene = camera.scene_control();
            (Box::new(camera), Some(scene))
        }
        FrameChoice::Camera { selector, options } => {
            (Box::new(V4l2Camera::open(selector.clone(), options.clone())?), None)
        }
        FrameChoice::Replay { path, fps, looping } => {
            if path.is_dir() {
                (Box::new(ImageFolder::open(path, *fps, *looping)?), None)
            } else {
                (Box::new(McapReplay::open(path, *looping)?), None)
            }
        }
    };
    Ok(Sources { frames, board, scene })
}
