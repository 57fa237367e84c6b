//! A daemon on the simulator, in process, on a loopback port: shared by the daemon_* and dashboard tests.
#![allow(dead_code)]

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use nusense_capture::SceneControl;
use nusense_daemon::api::{self, AppState};
use nusense_daemon::pipeline::{open_sources, BoardChoice, FrameChoice, Pipeline, PipelineHandle, PipelineOptions};
use nusense_estimator::{Mode, SensorConfig};
use nusense_sim::{Contact, Scene};

pub struct TestDaemon {
    pub addr: SocketAddr,
    pub pipeline: Pipeline,
    pub handle: PipelineHandle,
    pub scene: SceneControl,
    pub state: AppState,
    server: tokio::task::JoinHandle<()>,
    shutdown: Option<tokio::sync::oneshot::Sender<()>>,
}

pub struct DaemonSetup {
    pub width: u32,
    pub height: u32,
    pub fps: f64,
    pub token: Option<String>,
    pub broadcast_len: usize,
    pub send_timeout: Duration,
}

impl Default for DaemonSetup {
    fn default() -> Self {
        Self {
            width: 640,
            height: 480,
            fps: 15.0,
            token: None,
            broadcast_len: 64,
            send_timeout: Duration::from_secs(5),
        }
    }
}

/// The rest scene: nothing touches the pad.
pub fn rest() -> Scene {
    Scene::default()
}

/// A sphere pressing at the pad centre and dragging along +x (as a finger does when it pushes an object).
pub fn press(force_n: f64) -> Scene {
    let mut contact = Contact::sphere(6.0, [0.0, 0.0], force_n);
    contact.tangential_force_n = [0.4 * force_n, 0.0];
    let mut scene = Scene::default();
    scene.contacts.push(contact);
    scene
}

/// Starts a daemon: simulated camera lit by an in-process virtual board, holding the rest scene.
pub async fn start(setup: DaemonSetup) -> TestDaemon {
    // The same path as `nusense serve` with no options: the virtual board behind a pty, the simulated camera.
    let frames = FrameChoice::Simulator {
        width: setup.width,
        height: setup.height,
        fps: setup.fps,
    };
    let sources = open_sources(&frames, &BoardChoice::Virtual).expect("simulator and virtual board");
    let scene = sources.scene.expect("the simulator has a scene control");
    scene.hold(rest()).expect("rest scene");
    let mut options = PipelineOptions::new(SensorConfig::default(), Mode::Fast);
    options.broadcast_len = setup.broadcast_len;
    let pipeline = Pipeline::start(sources.frames, sources.board, options).expect("pipeline");
    let handle = pipeline.handle();
    let mut state = AppState::new(handle.clone(), Some(scene.clone()), setup.token.clone());
    state.stream_options.send_timeout = setup.send_timeout;
    state.recordings_dir = std::env::temp_dir();
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind loopback");
    let addr = listener.local_addr().expect("local addr");
    let (shutdown, stopped) = tokio::sync::oneshot::channel::<()>();
    let served = state.clone();
    let server = tokio::spawn(async move {
        api::serve(listener, served, async {
            let _ = stopped.await;
        })
        .await
        .expect("serve");
    });
    TestDaemon {
        addr,
        pipeline,
        handle,
        scene,
        state,
        server,
        shutdown: Some(shutdown),
    }
}

impl TestDaemon {
    pub fn url(&self, path: &str) -> String {
        format!("http://{}{}", self.addr, path)
    }

    pub fn ws_url(&self, path: &str) -> String {
        format!("ws://{}{}", self.addr, path)
    }

    /// Waits for a reading newer than `after_frame` that satisfies `accept`; returns it as JSON.
    pub async fn wait_reading(
        &self,
        timeout: Duration,
        mut accept: impl FnMut(&serde_json::Value) -> bool,
    ) -> Option<serde_json::Value> {
        let deadline = Instant::now() + timeout;
        while Instant::now() < deadline {
            if let Some(latest) = self.handle.latest_reading() {
                let json: serde_json::Value = serde_json::from_str(&latest.json).expect("reading JSON");
                if accept(&json) {
                    return Some(json);
                }
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        None
    }

    /// Holds `scene`, takes the next frame as the rest frame when `tare`, and returns the first reading of a
    /// frame captured after the change.
    pub async fn settle(&self, scene: Scene, tare: bool) -> serde_json::Value {
        self.scene.hold(scene).expect("valid scene");
        // The frame being rendered when the scene changed may still show the old one: wait one frame past it.
        let from = self.handle.latest_frame().map(|f| f.frame_id + 2).unwrap_or(0);
        if tare {
            // The frame already in the queue may predate the scene; tare on a frame that shows it.
            self.wait_reading(Duration::from_secs(30), |r| r["frame_id"].as_u64().unwrap_or(0) >= from)
                .await;
            self.handle.request_tare();
        }
        let from = self.handle.latest_frame().map(|f| f.frame_id + 2).unwrap_or(0);
        self.wait_reading(Duration::from_secs(30), |r| {
            r["frame_id"].as_u64().unwrap_or(0) >= from && r["estimate"].is_object()
        })
        .await
        .expect("a reading with an estimate after the scene change")
    }

    pub async fn stop(mut self) {
        if let Some(shutdown) = self.shutdown.take() {
            let _ = shutdown.send(());
        }
        let _ = self.server.await;
    }
}

/// The `nusense` binary of this build (another package's binary, so cargo does not hand it to these tests):
/// next to the test executable's target directory, built on demand.
pub fn nusense_binary() -> std::path::PathBuf {
    static BUILT: std::sync::OnceLock<std::path::PathBuf> = std::sync::OnceLock::new();
    BUILT
        .get_or_init(|| {
            let exe = std::env::current_exe().expect("test executable");
            // target/<profile>/deps/<test> -> target/<profile>
            let profile_dir = exe
                .parent()
                .and_then(|deps| deps.parent())
                .expect("target dir")
                .to_path_buf();
            let target_dir = profile_dir.parent().expect("target root").to_path_buf();
            let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
            let status = std::process::Command::new(cargo)
                .args(["build", "-p", "nusense", "--bin", "nusense"])
                .arg("--target-dir")
                .arg(&target_dir)
                .status()
                .expect("run cargo build");
            assert!(status.success(), "cargo build -p nusense failed");
            target_dir.join("debug").join("nusense")
        })
        .clone()
}
