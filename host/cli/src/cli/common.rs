//! What several subcommands share: the frame-source options of `serve` and `record`, loading the sensor
//! config, logging.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use nusense_capture::{
    CameraSelector, PixelFormat, SceneControl, V4l2Options, SIM_DEFAULT_FPS, SIM_DEFAULT_HEIGHT, SIM_DEFAULT_WIDTH,
};
use nusense_daemon::pipeline::{
    open_sources, Board, BoardChoice, BoardKind, DecodeScale, FrameChoice, Pipeline, PipelineOptions, Stages,
};
use nusense_estimator::{Mode, SensorConfig};

use super::pairing::{pair, Device, DeviceName, Frames, SensorSpec};

/// Exit code of `analyze` and `replay` when some frames could not be measured (the others were).
pub const EXIT_SOME_FRAMES_FAILED: u8 = 2;

/// Where frames and LED control come from, and how they are estimated (shared with `nusense record`).
#[derive(clap::Args, Debug)]
pub struct SourceArgs {
    /// Serial device of the LED board (e.g. /dev/ttyACM0, /dev/serial/by-id/...). Without it: the virtual board
    /// on the simulator, no board with --camera or --replay.
    #[arg(long, value_name = "PATH")]
    pub board: Option<String>,
    /// Camera: a V4L2 device path or the camera's USB serial number.
    #[arg(long, value_name = "DEVICE|SERIAL", conflicts_with_all = ["replay", "sim"])]
    pub camera: Option<String>,
    /// Replay a folder of frames or an MCAP recording instead of a live camera.
    #[arg(long, value_name = "DIR|FILE.mcap", conflicts_with = "sim")]
    pub replay: Option<PathBuf>,
    /// Run on the simulated sensor (the default when neither --camera nor --replay is given).
    #[arg(long)]
    pub sim: bool,
    /// Sensor configuration (TOML); the default fits the real sensor, or the simulated one on the simulator.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Estimator variant: inverse (the traction inverse), fast or paper (the paper's gamma line).
    #[arg(long, default_value_t = Mode::default())]
    pub mode: Mode,
    /// Frame width and height for the camera or the simulator.
    #[arg(long, default_value_t = SIM_DEFAULT_WIDTH)]
    pub width: u32,
    #[arg(long, default_value_t = SIM_DEFAULT_HEIGHT)]
    pub height: u32,
    /// Frames per second for the camera, the simulator, or a folder replay.
    #[arg(long, default_value_t = SIM_DEFAULT_FPS)]
    pub fps: f64,
    /// Camera pixel format, mjpeg or yuyv (default: MJPEG when offered, else YUYV).
    #[arg(long)]
    pub pixel_format: Option<PixelFormat>,
    /// Start the replay over when it ends.
    #[arg(long = "loop")]
    pub looping: bool,
    /// Scale the estimator's frames are decoded at: auto (1/2 of a 2048-px frame, full size up to 2047 px and in
    /// paper mode), or 1, 2, 4, 8 for 1/n of the frame's width and height.
    #[arg(long, default_value = "auto", value_name = "auto|1|2|4|8")]
    pub decode_scale: DecodeScale,
    /// Decode whole frames for the estimator, not only the pattern's region.
    #[arg(long)]
    pub decode_whole: bool,
    /// Decode and estimate each frame on one thread, one after the other, instead of overlapping the two: the
    /// daemon as it was before, kept as the pipeline benchmark's baseline.
    #[arg(long, hide = true)]
    pub one_thread: bool,
}

/// The pipeline the source options ask for.
pub fn pipeline_options(args: &SourceArgs, config: SensorConfig) -> PipelineOptions {
    let mut options = PipelineOptions::new(config, args.mode);
    options.decode_scale = args.decode_scale;
    options.decode_region = !args.decode_whole;
    if args.one_thread {
        options.stages = Stages::OneThread;
    }
    options
}

/// What the frame-source options of `serve` and `record` select.
pub fn frame_choice(args: &SourceArgs) -> FrameChoice {
    if let Some(camera) = &args.camera {
        camera_choice(args, CameraSelector::parse(camera))
    } else if let Some(path) = &args.replay {
        FrameChoice::Replay {
            path: path.clone(),
            fps: args.fps,
            looping: args.looping,
        }
    } else {
        FrameChoice::Simulator {
            width: args.width,
            height: args.height,
            fps: args.fps,
        }
    }
}

/// A V4L2 camera with the source options' size, rate and pixel format.
fn camera_choice(args: &SourceArgs, selector: CameraSelector) -> FrameChoice {
    FrameChoice::Camera {
        selector,
        options: V4l2Options {
            width: args.width,
            height: args.height,
            fps: args.fps.round().clamp(1.0, 1000.0) as u32,
            format: args.pixel_format,
        },
    }
}

pub fn board_choice(args: &SourceArgs, frames: &FrameChoice) -> BoardChoice {
    match (&args.board, frames) {
        (Some(port), _) => BoardChoice::Port(port.clone()),
        (None, FrameChoice::Simulator { .. }) => BoardChoice::Virtual,
        (None, _) => BoardChoice::None,
    }
}

/// One sensor of the daemon: its running pipeline and, on the simulator, its scene.
pub struct Sensor {
    pub pipeline: Pipeline,
    pub scene: Option<SceneControl>,
}

/// What each sensor of the daemon runs on: `--sensors N` simulated ones (each its own virtual board), one per
/// `--sensor` (its camera or replay, and its board, found among the attached devices), or the one the source
/// options describe.
pub fn sensor_sources(
    args: &SourceArgs,
    count: u16,
    paired: &[SensorSpec],
) -> anyhow::Result<Vec<(FrameChoice, BoardChoice)>> {
    if !paired.is_empty() {
        return paired_sources(args, paired);
    }
    let frames = frame_choice(args);
    let board = board_choice(args, &frames);
    if count > 1 && !matches!((&frames, &board), (FrameChoice::Simulator { .. }, BoardChoice::Virtual)) {
        bail!("--sensors runs several simulated sensors (--sim without --board); real ones are each a --sensor");
    }
    Ok(vec![(frames, board); usize::from(count)])
}

/// One sensor per `--sensor`, its devices matched against the cameras and boards attached now.
fn paired_sources(args: &SourceArgs, specs: &[SensorSpec]) -> anyhow::Result<Vec<(FrameChoice, BoardChoice)>> {
    let cameras: Vec<Device> = nusense_capture::list_cameras()
        .into_iter()
        .map(|camera| Device {
            path: camera.path,
            serial: camera.usb_serial,
        })
        .collect();
    // Boards named by path need no listing: a machine whose serial ports cannot be listed still runs them.
    let boards: Vec<Device> = match nusense_board::discover() {
        Ok(boards) => boards
            .into_iter()
            .map(|board| Device {
                path: board.path,
                serial: board.serial_number,
            })
            .collect(),
        Err(_) if specs.iter().all(|spec| matches!(spec.board, DeviceName::Path(_))) => Vec::new(),
        Err(error) => return Err(error).context("listing the LED boards attached"),
    };
    Ok(pair(specs, &cameras, &boards)?
        .into_iter()
        .map(|sensor| {
            let frames = match sensor.frames {
                Frames::Camera(DeviceName::Path(path)) => camera_choice(args, CameraSelector::Path(path.into())),
                Frames::Camera(DeviceName::Serial(serial)) => camera_choice(args, CameraSelector::Serial(serial)),
                Frames::Replay(path) => FrameChoice::Replay {
                    path,
                    fps: args.fps,
                    looping: args.looping,
                },
            };
            (frames, BoardChoice::Port(sensor.board_path))
        })
        .collect())
}

/// Opens the sources and starts the pipeline of each sensor.
pub fn start_sensors(
    args: &SourceArgs,
    config: &SensorConfig,
    sources: &[(FrameChoice, BoardChoice)],
) -> anyhow::Result<Vec<Sensor>> {
    sources
        .iter()
        .enumerate()
        .map(|(i, (frames, board))| {
            let sources = open_sources(frames, board)
                .with_context(|| format!("opening the frame source and LED board of sensor {}", i + 1))?;
            let pipeline = Pipeline::start(sources.frames, sources.board, pipeline_options(args, config.clone()))?;
            Ok(Sensor {
                pipeline,
                scene: sources.scene,
            })
        })
        .collect()
}

/// How long a real board gets to connect and say its serial number, which names the sensor.
const SERIAL_PATIENCE: Duration = Duration::from_secs(10);

impl Sensor {
    /// The sensor's identity wherever the daemon publishes it (its Zenoh keys, its ROS 2 names, the status): its
    /// LED board's USB serial number, waiting for a real board's first connection. The error says why there is
    /// none. It blocks: call it before the async runtime takes the thread.
    pub fn serial_number(&self) -> anyhow::Result<String> {
        board_serial_number(self.pipeline.handle().board().as_ref())?
            .ok_or_else(|| anyhow::anyhow!("this sensor has no LED board (--board)"))
    }
}

/// The LED board's USB serial number, waiting for a real board's first connection; `None` without a board. The
/// error says the board did not connect in time. It blocks.
pub fn board_serial_number(board: &dyn Board) -> anyhow::Result<Option<String>> {
    let started = Instant::now();
    loop {
        if let Some(serial) = board.serial_number() {
            return Ok(Some(serial));
        }
        if board.status().kind == BoardKind::None {
            return Ok(None);
        }
        if started.elapsed() > SERIAL_PATIENCE {
            bail!("its LED board did not connect within {} s", SERIAL_PATIENCE.as_secs());
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The sensor configuration of `serve` and `record`: the file given, or else the default of the sensor the frames
/// come from. The simulated sensor has its own calibration; the real sensor's would read its forces 5x low.
pub fn source_config(path: Option<&PathBuf>, frames: &FrameChoice) -> anyhow::Result<SensorConfig> {
    match (path, frames) {
        (None, FrameChoice::Simulator { .. }) => SensorConfig::from_toml_str(nusense_sim::SENSOR_CONFIG_TOML)
            .context("the simulated sensor's built-in configuration"),
        (path, _) => load_config(path),
    }
}

pub fn load_config(path: Option<&PathBuf>) -> anyhow::Result<SensorConfig> {
    match path {
        Some(path) => {
            SensorConfig::load(path).with_context(|| format!("loading the sensor configuration {}", path.display()))
        }
        None => Ok(SensorConfig::default()),
    }
}

/// Start-up message in plain words: what runs, from where, and where to look.
pub fn describe_start(frames: &FrameChoice, board: &BoardChoice) -> String {
    let camera = match frames {
        FrameChoice::Simulator { width, height, fps } => {
            format!("on the SIMULATOR: no camera, a simulated sensor renders {width}x{height} frames at {fps} fps")
        }
        FrameChoice::Camera { selector, options } => {
            format!(
                "on camera {selector:?} at {}x{} {} fps",
                options.width, options.height, options.fps
            )
        }
        FrameChoice::Replay { path, .. } => format!("replaying {}", path.display()),
    };
    let board = match board {
        BoardChoice::Virtual => {
            "a virtual LED board (the firmware's logic with simulated LEDs, over a pty)".to_string()
        }
        BoardChoice::Port(port) => format!("the LED board on {port}"),
        BoardChoice::None => "no LED board".to_string(),
    };
    format!("nusense serve: running {camera}, with {board}")
}

/// What is logged unless RUST_LOG says otherwise. RustDDS (serve --ros2) warns about 30 times a second that its
/// discovery messages have no locator for readers reachable on loopback only, which is the daemon's default range
/// and nothing a user can act on; its errors still show, and RUST_LOG=info shows everything.
const DEFAULT_LOG_FILTER: &str = "info,rustdds=error";

/// Logs to stderr; RUST_LOG overrides the level.
pub fn init_logging() {
    let _ = tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| DEFAULT_LOG_FILTER.into()),
        )
        .with_writer(std::io::stderr)
        .try_init();
}
