//! `nusense serve`: the daemon. With no options it runs on the simulator (a virtual LED board and the
//! simulated camera) and says so.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{bail, Context};
use nusense_daemon::api::{self, AppState};
use nusense_daemon::foxglove_live::FoxgloveLive;
use nusense_daemon::pipeline::{open_sources, Pipeline, PipelineOptions};

use super::common::{board_choice, describe_start, frame_choice, init_logging, load_config, SourceArgs};

pub const DEFAULT_PORT: u16 = 8750;

#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    pub source: SourceArgs,
    /// Address to listen on. Anything but loopback requires a token.
    #[arg(long, value_name = "ADDR")]
    pub listen: Option<SocketAddr>,
    /// Token every request must carry (Authorization: Bearer, or ?token=); required with a non-loopback --listen.
    #[arg(long, env = "NUSENSE_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// Folder for recordings started from the API without a path.
    #[arg(long, value_name = "DIR")]
    pub recordings: Option<PathBuf>,
    /// Also serve the sensor to the Foxglove app (Foxglove WebSocket protocol) on ADDR, 127.0.0.1:8765 when
    /// given alone. Loopback only: the protocol has no authentication (reach it from elsewhere through SSH).
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = "127.0.0.1:8765")]
    pub foxglove: Option<SocketAddr>,
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    init_logging();
    let listen = args
        .listen
        .unwrap_or_else(|| SocketAddr::from(([127, 0, 0, 1], DEFAULT_PORT)));
    let token = args.token.clone().filter(|t| !t.is_empty());
    if !listen.ip().is_loopback() && token.is_none() {
        bail!("listening on {listen} (beyond this machine) requires a token: pass --token or set NUSENSE_TOKEN");
    }
    if let Some(addr) = args.foxglove.filter(|a| !a.ip().is_loopback()) {
        bail!("--foxglove {addr}: the Foxglove server has no authentication, so it listens on loopback only");
    }
    let config = load_config(args.source.config.as_ref())?;
    let frames = frame_choice(&args.source);
    let board = board_choice(&args.source, &frames);
    eprintln!("{}", describe_start(&frames, &board));
    let sources = open_sources(&frames, &board).context("opening the frame source and LED board")?;
    let pipeline = Pipeline::start(
        sources.frames,
        sources.board,
        PipelineOptions::new(config.clone(), args.source.mode),
    )?;
    let pipeline_handle = pipeline.handle();
    let mut state = AppState::new(pipeline.handle(), sources.scene, token);
    if let Some(dir) = &args.recordings {
        state.recordings_dir = dir.clone();
    }
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    runtime.block_on(async move {
        let listener = tokio::net::TcpListener::bind(listen)
            .await
            .with_context(|| format!("listening on {listen}"))?;
        let local = listener.local_addr()?;
        let _foxglove = match args.foxglove {
            Some(addr) => {
                let live = FoxgloveLive::start(pipeline_handle, config, addr).await?;
                eprintln!("nusense serve: Foxglove WebSocket at ws://{}/", live.addr());
                Some(live)
            }
            None => None,
        };
        eprintln!("nusense serve: dashboard at http://{local}/  (API under /api/, stop with Ctrl-C)");
        api::serve(listener, state, async {
            let _ = tokio::signal::ctrl_c().await;
        })
        .await
        .context("serving HTTP")
    })?;
    drop(pipeline);
    Ok(ExitCode::SUCCESS)
}
