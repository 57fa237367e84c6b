//! `nusense serve`: the daemon. With no options it runs on the simulator (a virtual LED board and the
//! simulated camera) and says so. SIGINT, SIGTERM and SIGHUP stop it cleanly: WebSocket clients are told, the
//! recording is finished (summary and footer written), the board is left as it is, and the exit code is 0.
//!
//! With `--sensors N` (simulator only) the daemon runs N sensors, each with its own virtual board and serial; with
//! `--sensor camera=...,board=...` repeated, one sensor per pair of real devices. All of them are on Zenoh and
//! ROS 2, the first on the HTTP API, the dashboard and Foxglove.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{anyhow, bail, Context};
use nusense_daemon::api::{self, AccessPolicy, AppState, RecordingsDir};
use nusense_daemon::foxglove_live::FoxgloveLive;
use nusense_daemon::pipeline::{BoardChoice, FrameChoice, PipelineHandle};
use nusense_daemon::zenoh_out::{self, ZenohOut, ZenohSensor};
use nusense_ros2::{sensor_token, DiscoveryRange, Ros2Out, Ros2Settings};
use tokio::signal::unix::{signal, SignalKind};

use super::common::{describe_start, init_logging, sensor_sources, source_config, start_sensors, Sensor, SourceArgs};
use super::pairing::SensorSpec;

pub const DEFAULT_PORT: u16 = 8750;

#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    pub source: SourceArgs,
    /// Address (and TCP port) to listen on; port 0 picks a free one. Anything but loopback requires a token.
    #[arg(long, value_name = "ADDR:PORT", default_value_t = SocketAddr::from(([127, 0, 0, 1], DEFAULT_PORT)))]
    pub listen: SocketAddr,
    /// Another name the daemon answers to in the Host header (besides the address it listens on, and localhost
    /// on loopback), e.g. a reverse proxy's or this machine's DNS name. Repeatable.
    #[arg(long, value_name = "NAME")]
    pub allow_host: Vec<String>,
    /// Token every request must carry (Authorization: Bearer, ?token=, or the dashboard's cookie after opening
    /// /?token=...); required with a non-loopback --listen.
    #[arg(long, env = "NUSENSE_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// Folder the API records into; recording names are relative to it [default: $XDG_DATA_HOME/nusense/recordings,
    /// i.e. ~/.local/share/nusense/recordings].
    #[arg(long, value_name = "DIR")]
    pub recordings: Option<PathBuf>,
    /// Also serve the sensor to the Foxglove app (Foxglove WebSocket protocol) on ADDR, 127.0.0.1:8765 when
    /// given alone. Loopback only: the protocol has no authentication (reach it from elsewhere through SSH).
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = "127.0.0.1:8765")]
    pub foxglove: Option<SocketAddr>,
    /// Also publish each sensor as ROS 2 topics (/nusense/<serial>/wrench, image/compressed, contacts) over DDS,
    /// in ROS_DOMAIN_ID (0 when unset), to this machine only unless ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET
    /// (docs/integrations/ros2.md).
    #[arg(long)]
    pub ros2: bool,
    /// Simulated sensors to run, each with its own virtual LED board (and serial number). All are on Zenoh and
    /// ROS 2; the HTTP API, the dashboard and Foxglove serve the first.
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..=64),
          conflicts_with_all = ["camera", "replay", "board"])]
    pub sensors: u16,
    /// One sensor of real devices: its camera (a V4L2 device path or the camera's USB serial number; or
    /// replay=DIR|FILE.mcap instead) and its LED board (a serial device path or the board's USB serial number).
    /// Repeat for several sensors, each its own pipeline, Zenoh keys and ROS 2 topics; the HTTP API, the dashboard
    /// and Foxglove serve the first. Each device is matched among those attached; a missing or shared one is refused.
    #[arg(long = "sensor", value_name = "camera=CAMERA,board=BOARD",
          conflicts_with_all = ["camera", "replay", "board", "sim", "sensors"])]
    pub paired: Vec<SensorSpec>,
    /// Publish every sensor on Zenoh under nusense/<serial>/ (docs/integrations/zenoh.md): a peer listening on
    /// ENDPOINT, tcp/127.0.0.1:7447 when given alone, loopback only, no multicast scouting. Port 0 takes a free
    /// port; the daemon prints the endpoint it listens on ("Zenoh listening on ...").
    #[arg(long, value_name = "ENDPOINT", num_args = 0..=1, default_missing_value = zenoh_out::DEFAULT_ENDPOINT)]
    pub zenoh: Option<String>,
    /// Publish on Zenoh with this Zenoh configuration (JSON5) instead, e.g. to connect to a router or to listen
    /// beyond this machine (Zenoh's own access control then applies, not the daemon's).
    #[arg(long, value_name = "FILE", conflicts_with = "zenoh")]
    pub zenoh_config: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    init_logging();
    let token = access_token(&args)?;
    let recordings_dir = match args.recordings.clone() {
        Some(dir) => dir,
        None => RecordingsDir::default_location()
            .context("no folder for recordings: neither XDG_DATA_HOME nor HOME is set; pass --recordings DIR")?,
    };
    let zenoh_config = match (&args.zenoh, &args.zenoh_config) {
        (_, Some(file)) => Some(zenoh_out::config_from_file(file)?),
        (Some(endpoint), None) => Some(zenoh_out::loopback_peer_config(endpoint)?),
        (None, None) => None,
    };
    let sources = sensor_sources(&args.source, args.sensors, &args.paired)?;
    // Every sensor of one daemon is simulated, or none is.
    let config = source_config(args.source.config.as_ref(), &sources[0].0)?;
    describe_sources(&sources, args.paired.is_empty());
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    // Signals are caught from here on, before anything needs finishing: a SIGTERM during start-up is a clean stop.
    let stop = runtime.block_on(async { StopSignals::install() })?;
    let sensors = start_sensors(&args.source, &config, &sources)?;
    let handle = sensors[0].pipeline.handle();
    let scene = sensors[0].scene.clone();
    // Each sensor's name on Zenoh and ROS 2, asked before the async runtime takes over this thread: a real board
    // may take a moment to connect and say it.
    let serials: Vec<anyhow::Result<String>> = match args.ros2 || zenoh_config.is_some() {
        true => sensors.iter().map(Sensor::serial_number).collect(),
        false => Vec::new(),
    };
    let ros2: Vec<Ros2Out> = match args.ros2 {
        true => sensors
            .iter()
            .zip(&serials)
            .map(|(sensor, serial)| start_ros2(&sensor.pipeline.handle(), serial))
            .collect::<anyhow::Result<_>>()?,
        false => Vec::new(),
    };
    runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind(args.listen)
            .await
            .with_context(|| format!("listening on {}", args.listen))?;
        let local = listener.local_addr()?;
        let _foxglove = match args.foxglove {
            Some(addr) => {
                let live = FoxgloveLive::start(handle.clone(), config, addr).await?;
                eprintln!("nusense serve: Foxglove WebSocket at ws://{}/", live.addr());
                Some(live)
            }
            None => None,
        };
        let access = AccessPolicy::new(local, &args.allow_host, token.as_deref());
        let state = AppState::new(handle, scene, access, RecordingsDir::new(recordings_dir.clone()));
        let zenoh = match zenoh_config {
            Some(zenoh_config) => Some(start_zenoh(zenoh_config, &sensors, &serials, &state).await?),
            None => None,
        };
        eprintln!(
            "nusense serve: dashboard at http://{local}/  (API under /api/v1/, recordings in {}; stop with Ctrl-C)",
            recordings_dir.display()
        );
        api::serve(listener, state, async move {
            let name = stop.wait().await;
            eprintln!("nusense serve: {name}: stopping");
        })
        .await
        .context("serving HTTP")?;
        // Zenoh clients see every sensor's liveliness end before the sensors stop.
        if let Some(zenoh) = zenoh {
            zenoh.close().await;
        }
        anyhow::Ok(())
    })?;
    // The nodes leave the DDS domain, then capture and estimation stop and the recordings are finished (their
    // summary and footer).
    drop(ros2);
    drop(sensors);
    eprintln!("nusense serve: stopped");
    Ok(ExitCode::SUCCESS)
}

/// The token requests must carry, if any. Refuses to listen beyond loopback without one, and Foxglove beyond
/// loopback at all (its protocol has no authentication).
fn access_token(args: &Args) -> anyhow::Result<Option<String>> {
    let token = args.token.clone().filter(|t| !t.is_empty());
    if !args.listen.ip().is_loopback() && token.is_none() {
        bail!(
            "listening on {} (beyond this machine) requires a token: pass --token or set NUSENSE_TOKEN",
            args.listen
        );
    }
    if let Some(addr) = args.foxglove.filter(|a| !a.ip().is_loopback()) {
        bail!("--foxglove {addr}: the Foxglove server has no authentication, so it listens on loopback only");
    }
    Ok(token)
}

/// Says on stderr what each sensor runs on; `simulated`: the sensors are the simulator's, all alike.
fn describe_sources(sources: &[(FrameChoice, BoardChoice)], simulated: bool) {
    match sources {
        [(frames, board)] => eprintln!("{}", describe_start(frames, board)),
        [(frames, board), ..] if simulated => eprintln!(
            "{}; {} sensors, each its own simulated camera and virtual board",
            describe_start(frames, board),
            sources.len()
        ),
        several => {
            for (i, (frames, board)) in several.iter().enumerate() {
                eprintln!("{} (sensor {})", describe_start(frames, board), i + 1);
            }
        }
    }
}

/// Every sensor on Zenoh, named by its board's serial number: the first through `state`, the others through
/// their own API state.
async fn start_zenoh(
    zenoh_config: zenoh_out::Config,
    sensors: &[Sensor],
    serials: &[anyhow::Result<String>],
    state: &AppState,
) -> anyhow::Result<ZenohOut> {
    let mut served = Vec::new();
    for (i, (sensor, serial)) in sensors.iter().zip(serials).enumerate() {
        let api = match i {
            0 => state.clone(),
            _ => state.for_sensor(sensor.pipeline.handle(), sensor.scene.clone()),
        };
        let serial = serial
            .as_ref()
            .map_err(|why| anyhow!("--zenoh names each sensor by its LED board's serial number: {why:#}"))?;
        served.push(ZenohSensor {
            serial: serial.clone(),
            api,
        });
    }
    let serials: Vec<String> = served.iter().map(|s| s.serial.clone()).collect();
    let zenoh = ZenohOut::start(zenoh_config, served).await?;
    eprintln!("nusense serve: on Zenoh as nusense/{{{}}}/", serials.join(","));
    // Its own line, endpoints separated by spaces, before the dashboard's: clients (and the tests, which pass port
    // 0) read the port the system gave from it.
    match zenoh.listening_on().await {
        endpoints if endpoints.is_empty() => eprintln!("nusense serve: Zenoh listens nowhere"),
        endpoints => eprintln!("nusense serve: Zenoh listening on {}", endpoints.join(" ")),
    }
    Ok(zenoh)
}

/// The sensor's ROS 2 node, named after its board's serial number; a sensor without one is `unknown`.
fn start_ros2(handle: &PipelineHandle, serial: &anyhow::Result<String>) -> anyhow::Result<Ros2Out> {
    let settings = Ros2Settings::from_env()?;
    let serial = match serial {
        Ok(serial) => serial.as_str(),
        Err(why) => {
            eprintln!("nusense serve: ROS 2: {why:#}, so the sensor is named `unknown`");
            ""
        }
    };
    let ros2 = Ros2Out::start(handle.clone(), &sensor_token(serial), settings)?;
    let range = match ros2.settings().range {
        DiscoveryRange::Localhost => "this machine only",
        DiscoveryRange::Subnet => "the local network",
    };
    let topics = ros2.topics();
    eprintln!(
        "nusense serve: ROS 2 in domain {} ({range}): {} {} {} (frame {})",
        ros2.settings().domain_id,
        topics.wrench,
        topics.image,
        topics.contacts,
        topics.frame_id
    );
    Ok(ros2)
}

/// The signals that ask a daemon to stop: Ctrl-C, `systemctl stop` / `kill`, and a closed terminal.
struct StopSignals {
    interrupt: tokio::signal::unix::Signal,
    terminate: tokio::signal::unix::Signal,
    hangup: tokio::signal::unix::Signal,
}

impl StopSignals {
    fn install() -> anyhow::Result<Self> {
        let install = |kind: SignalKind, name: &str| signal(kind).with_context(|| format!("catching {name}"));
        Ok(Self {
            interrupt: install(SignalKind::interrupt(), "SIGINT")?,
            terminate: install(SignalKind::terminate(), "SIGTERM")?,
            hangup: install(SignalKind::hangup(), "SIGHUP")?,
        })
    }

    /// The name of the first signal that arrives.
    async fn wait(mut self) -> &'static str {
        tokio::select! {
            _ = self.interrupt.recv() => "SIGINT",
            _ = self.terminate.recv() => "SIGTERM",
            _ = self.hangup.recv() => "SIGHUP",
        }
    }
}
