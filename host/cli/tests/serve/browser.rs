//! The dashboard in headless Chromium (Debian's chromium + chromedriver, driven over WebDriver's HTTP API)
//! against a daemon on the simulator: readings appear on the page and change when the simulated contact does.

use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::daemon::{press, rest, Daemon, Options};
use serde_json::{json, Value};

const CHROMIUM: &str = "/usr/bin/chromium";
const CHROMEDRIVER: &str = "/usr/bin/chromedriver";

struct Driver {
    process: Child,
    base: String,
    session: String,
    http: reqwest::Client,
    _profile: tempfile::TempDir,
}

impl Driver {
    async fn start() -> Self {
        for path in [CHROMIUM, CHROMEDRIVER] {
            assert!(
                std::path::Path::new(path).exists(),
                "{path} is missing: run scripts/setup test (installs chromium chromium-driver)"
            );
        }
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let process = Command::new(CHROMEDRIVER)
            .arg(format!("--port={port}"))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("start chromedriver");
        let base = format!("http://127.0.0.1:{port}");
        let http = reqwest::Client::new();
        let deadline = Instant::now() + Duration::from_secs(20);
        loop {
            if let Ok(response) = http.get(format!("{base}/status")).send().await {
                let status: Value = response.json().await.unwrap_or_default();
                if status["value"]["ready"] == json!(true) {
                    break;
                }
            }
            assert!(Instant::now() < deadline, "chromedriver did not become ready");
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
        let profile = tempfile::tempdir().unwrap();
        let args = vec![
            "--headless".to_string(),
            "--no-sandbox".into(),
            "--disable-gpu".into(),
            "--disable-quic".into(),
            "--no-first-run".into(),
            "--disable-background-networking".into(),
            "--disable-component-update".into(),
            "--disable-sync".into(),
            "--disable-dev-shm-usage".into(),
            "--window-size=1280,1024".into(),
            format!("--user-data-dir={}", profile.path().display()),
        ];
        let capabilities = json!({ "capabilities": { "alwaysMatch": {
            "browserName": "chrome",
            "goog:chromeOptions": { "binary": CHROMIUM, "args": args }
        }}});
        let created: Value = http
            .post(format!("{base}/session"))
            .json(&capabilities)
            .send()
            .await
            .unwrap()
            .json()
            .await
            .unwrap();
        let session = created["value"]["sessionId"]
            .as_str()
            .unwrap_or_else(|| panic!("no session: {created}"))
            .to_string();
        Self {
            process,
            base,
            session,
            http,
            _profile: profile,
        }
    }

    async fn command(&self, path: &str, body: Value) -> Value {
        let url = format!("{}/session/{}/{path}", self.base, self.session);
        let answer: Value = self
            .http
            .post(url)
            .json(&body)
            .send()
            .await
            .unwrap()
            .json()
            .await
            .unwrap();
        answer["value"].clone()
    }

    async fn goto(&self, url: &str) {
        self.command("url", json!({ "url": url })).await;
    }

    async fn eval(&self, script: &str) -> Value {
        self.command("execute/sync", json!({ "script": script, "args": [] }))
            .await
    }

    async fn text(&self, id: &str) -> String {
        let value = self
            .eval(&format!(
                "const e = document.getElementById('{id}'); return e ? e.textContent : null;"
            ))
            .await;
        value.as_str().unwrap_or_default().to_string()
    }

    /// Polls until `accept` holds for the page's state, which `script` returns.
    async fn wait_for(&self, script: &str, timeout: Duration, accept: impl Fn(&Value) -> bool) -> Value {
        let deadline = Instant::now() + timeout;
        loop {
            let value = self.eval(script).await;
            if accept(&value) {
                return value;
            }
            assert!(
                Instant::now() < deadline,
                "the page never reached the expected state; last: {value}"
            );
            tokio::time::sleep(Duration::from_millis(200)).await;
        }
    }
}

impl Drop for Driver {
    fn drop(&mut self) {
        let _ = self.process.kill();
        let _ = self.process.wait();
    }
}

const PAGE_STATE: &str = "return { frame: document.getElementById('frame-id').textContent, \
    force: document.getElementById('force').textContent, contact: document.getElementById('contact').textContent, \
    gamma: document.getElementById('gamma').textContent, live: document.getElementById('connection').textContent, \
    image: document.getElementById('frame').naturalWidth };";

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn dashboard_shows_live_readings_that_follow_the_simulated_contact() {
    let daemon = Daemon::start(Options::sim(640, 480, 10.0));
    let resting = daemon.settle(&rest(), true).await;
    assert_eq!(resting["estimate"]["contact"], json!(false));

    let driver = Driver::start().await;
    driver.goto(&daemon.url("/")).await;
    let before = driver
        .wait_for(PAGE_STATE, Duration::from_secs(60), |s| {
            s["live"] == json!("live")
                && s["contact"] == json!("no")
                && s["force"].as_str().is_some_and(|f| f.parse::<f64>().is_ok())
                && s["image"].as_u64() == Some(640)
        })
        .await;

    // Press: the page must show the contact and a different force/shear.
    daemon
        .send("PUT", "/api/v1/sim/scene", json!({ "scene": press(4.0) }))
        .await;
    let after = driver
        .wait_for(PAGE_STATE, Duration::from_secs(60), |s| s["contact"] == json!("yes"))
        .await;
    assert_ne!(after["frame"], before["frame"], "frames advance");
    assert_ne!(
        after["gamma"], before["gamma"],
        "the shear shown changes with the contact: {before} -> {after}"
    );

    // The heat map was drawn (some non-background pixels).
    let painted = driver
        .eval("const c = document.getElementById('heatmap'); const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data; \
               let n = 0; for (let i = 3; i < d.length; i += 4) if (d[i] > 0) n++; return n;")
        .await;
    assert!(painted.as_u64().unwrap_or(0) > 1000, "heat map painted: {painted}");

    // LED controls: a current above the limit is refused with the daemon's message.
    driver
        .eval("const f = document.getElementById('led-form'); f.elements['top'].value = '130'; f.requestSubmit(); return true;")
        .await;
    let message = driver
        .wait_for(
            "return document.getElementById('led-message').textContent;",
            Duration::from_secs(10),
            |m| m.as_str().is_some_and(|m| !m.is_empty()),
        )
        .await;
    assert!(message.as_str().unwrap().contains("120 mA"), "{message}");
    assert_eq!(driver.text("led-message").await, message.as_str().unwrap());

    // Release: the contact disappears again.
    daemon
        .send("PUT", "/api/v1/sim/scene", json!({ "scene": rest() }))
        .await;
    driver
        .wait_for(PAGE_STATE, Duration::from_secs(60), |s| s["contact"] == json!("no"))
        .await;
    drop(driver);
}
