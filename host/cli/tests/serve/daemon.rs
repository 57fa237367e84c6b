//! The real `nusense serve`, started as a user starts it (the binary cargo built for these tests), on a loopback
//! port of its own choosing, with its own XDG data folder; and the HTTP helpers the tests share.
#![allow(dead_code)]

use std::io::{BufRead, BufReader};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use nusense_sim::{Contact, Scene};
use serde_json::{json, Value};

/// A slow, shared machine: starting, the first frame and scene changes get this long.
pub const PATIENCE: Duration = Duration::from_secs(120);

pub struct Daemon {
    child: Option<Child>,
    pub addr: SocketAddr,
    /// The Zenoh endpoints it said it listens on ("Zenoh listening on ..."), when started with `--zenoh`.
    pub zenoh: Vec<String>,
    log: Arc<Mutex<String>>,
    /// Holds the daemon's XDG_DATA_HOME (its default recordings folder lives there).
    pub data_home: tempfile::TempDir,
    pub http: reqwest::Client,
    /// The token it was started with; the helpers below send it.
    pub token: Option<String>,
}

/// How to start it: `serve` plus these arguments (`--listen 127.0.0.1:0` is added unless given).
pub struct Options {
    pub args: Vec<String>,
    /// Runs the daemon under `unshare --mount --map-root-user`, with a tmpfs of this many KiB mounted on its
    /// recordings folder: a disk that fills up, without touching the machine's disks.
    pub small_disk_kib: Option<u64>,
    pub token: Option<String>,
    /// Environment variables set for the daemon only.
    pub env: Vec<(String, String)>,
}

impl Options {
    pub fn new(args: &[&str]) -> Self {
        Self {
            args: args.iter().map(|a| a.to_string()).collect(),
            small_disk_kib: None,
            token: None,
            env: Vec::new(),
        }
    }

    /// The simulator at a small size, so that tests spend their time on the daemon rather than on rendering.
    pub fn sim(width: u32, height: u32, fps: f64) -> Self {
        Self::new(&[
            "--sim",
            "--width",
            &width.to_string(),
            "--height",
            &height.to_string(),
            "--fps",
            &fps.to_string(),
        ])
    }

    pub fn arg(mut self, arg: impl Into<String>) -> Self {
        self.args.push(arg.into());
        self
    }

    pub fn env(mut self, name: &str, value: &str) -> Self {
        self.env.push((name.into(), value.into()));
        self
    }

    pub fn token(mut self, token: &str) -> Self {
        self.args.extend(["--token".into(), token.into()]);
        self.token = Some(token.into());
        self
    }
}

pub fn binary() -> &'static str {
    env!("CARGO_BIN_EXE_nusense")
}

impl Daemon {
    pub fn start(options: Options) -> Self {
        let data_home = tempfile::tempdir().expect("temp dir");
        let mut args: Vec<String> = vec!["serve".into()];
        args.extend(options.args.iter().cloned());
        if !args.iter().any(|a| a == "--listen") {
            args.extend(["--listen".into(), "127.0.0.1:0".into()]);
        }
        let mut command = match options.small_disk_kib {
            None => Command::new(binary()),
            Some(kib) => {
                let recordings = data_home.path().join("small-disk");
                std::fs::create_dir_all(&recordings).unwrap();
                args.extend(["--recordings".into(), recordings.display().to_string()]);
                let mut command = Command::new("unshare");
                command.args(["--mount", "--map-root-user", "sh", "-c"]).arg(format!(
                    "mount -t tmpfs -o size={kib}k tmpfs '{}' && exec \"$0\" \"$@\"",
                    recordings.display()
                ));
                command.arg(binary());
                command
            }
        };
        command
            .args(&args)
            .env("XDG_DATA_HOME", data_home.path())
            .env("RUST_LOG", "info")
            .env_remove("NUSENSE_TOKEN")
            .envs(options.env.iter().map(|(k, v)| (k, v)))
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        let mut child = command.spawn().expect("start nusense serve");
        let stderr = child.stderr.take().expect("stderr");
        let log = Arc::new(Mutex::new(String::new()));
        let (address_tx, address_rx) = std::sync::mpsc::channel();
        let thread_log = log.clone();
        std::thread::spawn(move || {
            // The daemon says where it listens on Zenoh before where its dashboard is.
            let mut zenoh = Vec::new();
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                if let Some(rest) = line.split("Zenoh listening on ").nth(1) {
                    zenoh = rest.split_whitespace().map(str::to_owned).collect();
                }
                if let Some(rest) = line.split("dashboard at http://").nth(1) {
                    let addr = rest.split('/').next().unwrap_or_default().to_string();
                    let _ = address_tx.send((addr, std::mem::take(&mut zenoh)));
                }
                let mut log = thread_log.lock().unwrap();
                log.push_str(&line);
                log.push('\n');
            }
        });
        let (addr, zenoh) = match address_rx.recv_timeout(PATIENCE) {
            Ok((addr, zenoh)) => (addr.parse().expect("listen address"), zenoh),
            Err(_) => {
                let _ = child.kill();
                panic!("nusense serve {args:?} did not start:\n{}", log.lock().unwrap());
            }
        };
        Self {
            child: Some(child),
            addr,
            zenoh,
            log,
            data_home,
            http: reqwest::Client::builder()
                .redirect(reqwest::redirect::Policy::none())
                .build()
                .unwrap(),
            token: options.token,
        }
    }

    pub fn url(&self, path: &str) -> String {
        format!("http://{}{}", self.addr, path)
    }

    pub fn ws_url(&self, path: &str) -> String {
        format!("ws://{}{}", self.addr, path)
    }

    /// The daemon's own origin, as its dashboard's requests carry it.
    pub fn origin(&self) -> String {
        format!("http://{}", self.addr)
    }

    /// The Zenoh endpoint to connect to: the first it listens on (panics when it listens on none).
    pub fn zenoh_endpoint(&self) -> &str {
        match self.zenoh.first() {
            Some(endpoint) => endpoint,
            None => panic!("the daemon said no Zenoh endpoint it listens on:\n{}", self.log()),
        }
    }

    pub fn pid(&self) -> u32 {
        self.child.as_ref().expect("running").id()
    }

    pub fn log(&self) -> String {
        self.log.lock().unwrap().clone()
    }

    pub fn default_recordings(&self) -> PathBuf {
        self.data_home.path().join("nusense").join("recordings")
    }

    /// Sends `signal` and waits for the process to end.
    pub fn stop_with(mut self, signal: i32) -> ExitStatus {
        let mut child = self.child.take().expect("running");
        // SAFETY: a signal to our own child process.
        unsafe {
            libc::kill(child.id() as i32, signal);
        }
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            if let Some(status) = child.try_wait().expect("wait") {
                // Let the reader thread take the last lines.
                std::thread::sleep(Duration::from_millis(100));
                return status;
            }
            if Instant::now() > deadline {
                let _ = child.kill();
                panic!(
                    "nusense serve did not stop within 30 s of signal {signal}:\n{}",
                    self.log()
                );
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    pub fn exited(&mut self) -> Option<ExitStatus> {
        self.child.as_mut().and_then(|c| c.try_wait().ok().flatten())
    }

    fn authorised(&self, request: reqwest::RequestBuilder) -> reqwest::RequestBuilder {
        match &self.token {
            Some(token) => request.bearer_auth(token),
            None => request,
        }
    }

    pub async fn get(&self, path: &str) -> (u16, Value) {
        let request = self.authorised(self.http.get(self.url(path)));
        json_of(request.send().await.expect("GET")).await
    }

    pub async fn send(&self, method: &str, path: &str, body: Value) -> (u16, Value) {
        let request = self.http.request(method.parse().unwrap(), self.url(path)).json(&body);
        json_of(self.authorised(request).send().await.expect("request")).await
    }

    pub async fn status(&self) -> Value {
        let (code, status) = self.get("/api/v1/status").await;
        assert_eq!(code, 200, "{status}");
        status
    }

    /// Polls `/api/v1/reading` until `accept` holds (panics after [`PATIENCE`]).
    pub async fn wait_reading(&self, what: &str, mut accept: impl FnMut(&Value) -> bool) -> Value {
        let deadline = Instant::now() + PATIENCE;
        let mut last = Value::Null;
        while Instant::now() < deadline {
            let (code, reading) = self.get("/api/v1/reading").await;
            if code == 200 && accept(&reading) {
                return reading;
            }
            last = reading;
            tokio::time::sleep(Duration::from_millis(30)).await;
        }
        let mut last = last.to_string();
        last.truncate(600);
        panic!("no reading {what}; last: {last}...\n{}", self.log());
    }

    /// Polls `/api/v1/status` until `accept` holds.
    pub async fn wait_status(&self, what: &str, mut accept: impl FnMut(&Value) -> bool) -> Value {
        let deadline = Instant::now() + PATIENCE;
        loop {
            let status = self.status().await;
            if accept(&status) {
                return status;
            }
            assert!(
                Instant::now() < deadline,
                "status never {what}: {status}\n{}",
                self.log()
            );
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    pub async fn frames_captured(&self) -> u64 {
        self.status().await["pipeline"]["frames_captured"].as_u64().unwrap()
    }

    /// Holds `scene` on the simulator, takes a frame that shows it as the rest frame when `tare`, and returns the
    /// first reading of a frame rendered after the change.
    pub async fn settle(&self, scene: &Scene, tare: bool) -> Value {
        let (code, body) = self.send("PUT", "/api/v1/sim/scene", json!({ "scene": scene })).await;
        assert_eq!(code, 200, "{body}");
        // The frame being rendered when the scene changed may still show the old one.
        let from = self.frames_captured().await + 1;
        if tare {
            self.wait_reading("after the scene change", |r| r["frame_id"].as_u64() >= Some(from))
                .await;
            let (_, before) = self.get("/api/v1/reading").await;
            let old_rest = before["reference_frame_id"].as_u64();
            let (code, body) = self.send("POST", "/api/v1/tare", json!(null)).await;
            assert_eq!(code, 202, "{body}");
            return self
                .wait_reading("on the new rest frame", |r| {
                    r["reference_frame_id"].as_u64() > old_rest && r["estimate"].is_object()
                })
                .await;
        }
        self.wait_reading("with an estimate after the scene change", |r| {
            r["frame_id"].as_u64() >= Some(from) && r["estimate"].is_object()
        })
        .await
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

pub async fn json_of(response: reqwest::Response) -> (u16, Value) {
    let status = response.status().as_u16();
    let text = response.text().await.expect("body");
    (status, serde_json::from_str(&text).unwrap_or(Value::String(text)))
}

/// The rest scene: nothing touches the pad.
/// The pipeline's frame counters in a status, as the benchmarks print them.
pub fn pipeline_counters(status: &Value) -> String {
    let pipeline = &status["pipeline"];
    format!(
        "pipeline: {} frames captured, {} processed, {} dropped (drop-oldest), {} estimate errors",
        pipeline["frames_captured"],
        pipeline["frames_processed"],
        pipeline["frames_dropped"],
        pipeline["estimate_errors"]
    )
}

pub fn rest() -> Scene {
    Scene::default()
}

/// A sphere pressing at `at_mm` and dragging along +x (as a finger does when it pushes an object).
pub fn press_at(force_n: f64, at_mm: [f64; 2]) -> Scene {
    let mut contact = Contact::sphere(6.0, at_mm, force_n);
    contact.tangential_force_n = [0.4 * force_n, 0.0];
    let mut scene = Scene::default();
    scene.contacts.push(contact);
    scene
}

pub fn press(force_n: f64) -> Scene {
    press_at(force_n, [0.0, 0.0])
}

/// Width and height from a JPEG's SOF marker (enough to know a whole frame was served).
pub fn jpeg_dimensions(jpeg: &[u8]) -> (u32, u32) {
    let image = image::load_from_memory_with_format(jpeg, image::ImageFormat::Jpeg).expect("a JPEG");
    (image.width(), image.height())
}

/// Nominal LED current the virtual board starts with, mA per string.
pub const NOMINAL_MA: f32 = 100.0;

/// Renders `scenes` with the simulator into `dir` as JPEG files 000.jpg, 001.jpg, ... (a folder to replay).
pub fn render_folder(dir: &Path, width: u32, height: u32, scenes: &[Scene]) {
    let renderer = nusense_sim::Renderer::new(nusense_sim::SensorModel::real(width, height)).expect("renderer");
    for (i, scene) in scenes.iter().enumerate() {
        let (image, _) = renderer.render(scene, [NOMINAL_MA; 4], i as u64).expect("render");
        image.save(dir.join(format!("{i:03}.jpg"))).expect("save frame");
    }
}

/// Where the simulator draws a scene's (first) contact in a frame of this size, raw px.
pub fn contact_px(width: u32, height: u32, scene: &Scene) -> [f64; 2] {
    let renderer = nusense_sim::Renderer::new(nusense_sim::SensorModel::real(width, height)).expect("renderer");
    let truth = renderer.ground_truth(scene, [NOMINAL_MA; 4], 0).expect("ground truth");
    truth.contacts[0].centre_px
}

/// A Zenoh session of this process that reaches the daemon's loopback endpoint only (no listening, no multicast
/// scouting), as a client on the same machine would.
pub async fn zenoh_client(endpoint: &str) -> zenoh::Session {
    let mut config = zenoh::Config::default();
    for (key, value) in [
        ("mode", r#""peer""#.to_string()),
        ("connect/endpoints", format!(r#"["{endpoint}"]"#)),
        ("listen/endpoints", "[]".into()),
        ("scouting/multicast/enabled", "false".into()),
    ] {
        config.insert_json5(key, &value).unwrap();
    }
    zenoh::open(config).await.expect("open a Zenoh session")
}

/// One query's first reply, as JSON; `None` when none came within 30 s (a session whose connection is not up yet
/// gets none). Panics on an error reply.
pub async fn zenoh_query(session: &zenoh::Session, key: &str, payload: Option<&str>) -> Option<Value> {
    let mut get = session.get(key).timeout(Duration::from_secs(30));
    if let Some(payload) = payload {
        get = get.payload(payload.to_owned());
    }
    let replies = get.await.expect("send the query");
    let reply = replies.recv_async().await.ok()?;
    let sample = reply.result().unwrap_or_else(|e| panic!("{key}: {e:?}"));
    Some(serde_json::from_slice(&sample.payload().to_bytes()).expect("a JSON reply"))
}

/// The project's .venv interpreter (`scripts/setup test` creates it); `needed_for` says what the test needs from it.
pub fn venv_python(needed_for: &str) -> PathBuf {
    let venv = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../.venv/bin/python");
    assert!(
        venv.exists(),
        "{} is missing: `scripts/setup test` creates it ({needed_for})",
        venv.display()
    );
    venv
}
