//! What the suite runs against, started and kept alive for the duration of the run.

use std::path::PathBuf;

use nusense_board::virtual_board::VirtualBoardOptions;

use crate::emulator::{EmulatorError, QemuBoard, QemuImage, QemuOptions};
use crate::light::LightMeter;
use nusense_board::virtual_board::{VirtualBoard, VirtualBoardError};

use super::camera::{BrightnessProbe, CameraProbeError, LightSource, SimulatedCameraProbe, V4l2CameraProbe};

/// Size of the simulated camera's frames: enough for a mean brightness, cheap to render.
const SIMULATED_CAMERA_SIZE: (u32, u32) = (160, 120);

#[derive(Clone, Debug)]
pub enum HilTarget {
    /// A board on a serial device, with a camera (device path or USB serial) when one is attached.
    Port { path: String, camera: Option<String> },
    /// The firmware's core on a host thread behind a pty, with the simulated camera.
    Virtual,
    /// A virtual board built with these options (a miscalibrated sense path, another plant), e.g. to show that
    /// a board whose measurements are wrong fails the camera check.
    VirtualWith(Box<VirtualBoardOptions>),
    /// The QEMU firmware image, with the simulated camera. `elf` overrides the image; `build` builds it first.
    Emulated {
        elf: Option<PathBuf>,
        build: bool,
        qemu: QemuOptions,
    },
}

#[derive(Debug, thiserror::Error)]
pub enum TargetError {
    #[error(transparent)]
    Emulator(#[from] EmulatorError),
    #[error(transparent)]
    VirtualBoard(#[from] VirtualBoardError),
    #[error("cannot read the emulator's light channel {path}: {cause}")]
    Light { path: String, cause: serialport::Error },
    #[error("cannot open the camera: {0}")]
    Camera(#[from] CameraProbeError),
}

/// Whose clock the timing checks judge rates by.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BoardClock {
    /// A board on a crystal, or the virtual board on the host's clock: rates are judged against wall time.
    WallClock,
    /// An emulator, whose clock runs as fast as the host lets it: rates are judged against the board's own
    /// clock (its telemetry timestamps), and how much slower than wall time it ran is reported.
    Emulated,
}

/// A started target: its serial path, its camera, and whatever must stay alive while the checks run.
pub struct RunningTarget {
    pub description: String,
    pub port: String,
    pub camera: Option<Box<dyn BrightnessProbe>>,
    pub clock: BoardClock,
    // Held for their Drop: the virtual board stops and QEMU is killed when the target goes.
    _virtual_board: Option<VirtualBoard>,
    _qemu: Option<QemuBoard>,
    _light: Option<LightMeter>,
}

impl HilTarget {
    pub fn start(&self) -> Result<RunningTarget, TargetError> {
        match self {
            HilTarget::Port { path, camera } => {
                let camera = match camera {
                    Some(device) => Some(Box::new(V4l2CameraProbe::open(device)?) as Box<dyn BrightnessProbe>),
                    None => None,
                };
                Ok(RunningTarget {
                    description: format!("board on {path}"),
                    port: path.clone(),
                    camera,
                    clock: BoardClock::WallClock,
                    _virtual_board: None,
                    _qemu: None,
                    _light: None,
                })
            }
            HilTarget::Virtual => start_virtual(VirtualBoardOptions::default()),
            HilTarget::VirtualWith(options) => start_virtual((**options).clone()),
            HilTarget::Emulated { elf, build, qemu } => {
                let image = match elf {
                    Some(elf) => QemuImage::at(elf.clone())?,
                    None => {
                        let cwd = std::env::current_dir().unwrap_or_else(|_| PathBuf::from("."));
                        let workspace = QemuImage::find_images_workspace(&cwd)?;
                        if *build {
                            QemuImage::build(&workspace)?
                        } else {
                            QemuImage::prebuilt(&workspace)?
                        }
                    }
                };
                let board = QemuBoard::start(&image, qemu)?;
                let light = LightMeter::open(board.light_pty_path()).map_err(|cause| TargetError::Light {
                    path: board.light_pty_path().to_owned(),
                    cause,
                })?;
                Ok(RunningTarget {
                    description: format!(
                        "QEMU {} image {} (pid {}) on {}",
                        crate::emulator::QEMU_MACHINE,
                        image.elf.display(),
                        board.pid(),
                        board.pty_path()
                    ),
                    port: board.pty_path().to_owned(),
                    camera: Some(simulated_camera(Box::new(light.source()))?),
                    clock: BoardClock::Emulated,
                    _virtual_board: None,
                    _qemu: Some(board),
                    _light: Some(light),
                })
            }
        }
    }
}

fn start_virtual(options: VirtualBoardOptions) -> Result<RunningTarget, TargetError> {
    let board = VirtualBoard::spawn_pty_with(options)?;
    let currents = board.led_currents();
    Ok(RunningTarget {
        description: format!("virtual board (firmware core behind a pty) on {}", board.path()),
        port: board.path().to_owned(),
        camera: Some(simulated_camera(Box::new(move |_| Some(currents.get())))?),
        clock: BoardClock::WallClock,
        _virtual_board: Some(board),
        _qemu: None,
        _light: None,
    })
}

/// The simulated camera, lit by the strings' true currents (never by what the board reports).
fn simulated_camera(light: LightSource) -> Result<Box<dyn BrightnessProbe>, CameraProbeError> {
    let (width, height) = SIMULATED_CAMERA_SIZE;
    Ok(Box::new(SimulatedCameraProbe::new(width, height, light)?))
}
