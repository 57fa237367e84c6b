//! The dashboard in headless Chromium (Debian's chromium + chromedriver, driven over WebDriver's HTTP API)
//! against `nusense serve` on the simulator, checked by the pixels of a screenshot as well as by the page: the
//! camera shows (not a black panel), the lattice is drawn over it, and the contact marker sits over the contact
//! where the simulator pressed; a full disk is said in words.

use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::daemon::{contact_px, press_at, rest, Daemon, Options};
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
        let created = post_json(&http, &format!("{base}/session"), &capabilities).await;
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
        post_json(&self.http, &url, &body).await["value"].clone()
    }

    async fn goto(&self, url: &str) {
        self.command("url", json!({ "url": url })).await;
    }

    async fn eval(&self, script: &str) -> Value {
        self.command("execute/sync", json!({ "script": script, "args": [] }))
            .await
    }

    /// The viewport as pixels.
    async fn screenshot(&self) -> image::RgbaImage {
        let url = format!("{}/session/{}/screenshot", self.base, self.session);
        let answer: Value = self.http.get(url).send().await.unwrap().json().await.unwrap();
        let png = base64::Engine::decode(
            &base64::engine::general_purpose::STANDARD,
            answer["value"].as_str().expect("a screenshot"),
        )
        .unwrap();
        image::load_from_memory(&png).expect("a PNG").to_rgba8()
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
        // Killing chromedriver alone leaves its browser running, adopted by init, after every test: ending the
        // WebDriver session quits the browser first.
        quit_session(&self.base, &self.session);
        let _ = self.process.kill();
        let _ = self.process.wait();
    }
}

/// A WebDriver command: POST `body` as JSON, the answer as JSON.
async fn post_json(http: &reqwest::Client, url: &str, body: &Value) -> Value {
    http.post(url).json(body).send().await.unwrap().json().await.unwrap()
}

/// `DELETE /session/{id}` over a plain socket, since `drop` cannot await.
fn quit_session(base: &str, session: &str) {
    use std::io::{Read, Write};
    let Some(addr) = base.strip_prefix("http://") else {
        return;
    };
    let Ok(mut stream) = std::net::TcpStream::connect(addr) else {
        return;
    };
    let _ = stream.set_read_timeout(Some(Duration::from_secs(20)));
    let request =
        format!("DELETE /session/{session} HTTP/1.1\r\nHost: {addr}\r\nContent-Length: 0\r\nConnection: close\r\n\r\n");
    if stream.write_all(request.as_bytes()).is_ok() {
        // The answer comes once the browser has quit.
        let _ = stream.read_to_end(&mut Vec::new());
    }
}

const PAGE_STATE: &str = "return { frame: document.getElementById('frame-id').textContent, \
    force: document.getElementById('force').textContent, contact: document.getElementById('contact').textContent, \
    gamma: document.getElementById('gamma').textContent, live: document.getElementById('connection').textContent, \
    image: document.getElementById('frame').naturalWidth, overlay: document.getElementById('overlay').dataset.frameId, \
    problems: document.getElementById('problems').hidden };";

/// Where the picture is on screen, in screenshot pixels.
struct Rect {
    x: f64,
    y: f64,
    width: f64,
    height: f64,
}

impl Rect {
    fn pixels<'a>(&'a self, shot: &'a image::RgbaImage) -> impl Iterator<Item = (f64, f64, [u8; 4])> + 'a {
        let (x0, y0) = (self.x.ceil() as u32, self.y.ceil() as u32);
        let (x1, y1) = ((self.x + self.width) as u32, (self.y + self.height) as u32);
        (y0..y1.min(shot.height()))
            .flat_map(move |y| (x0..x1.min(shot.width())).map(move |x| (x, y)))
            .map(|(x, y)| (x as f64, y as f64, shot.get_pixel(x, y).0))
    }
}

async fn element_rect(driver: &Driver, id: &str) -> Rect {
    let r = driver
        .eval(&format!(
            "const r = document.getElementById('{id}').getBoundingClientRect(); const s = window.devicePixelRatio; \
             return [r.x * s, r.y * s, r.width * s, r.height * s];"
        ))
        .await;
    let v: Vec<f64> = r.as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    Rect {
        x: v[0],
        y: v[1],
        width: v[2],
        height: v[3],
    }
}

fn is_marker(p: [u8; 4]) -> bool {
    p[0] > 190 && p[1] < 90 && p[2] > 190
}

fn is_lattice(p: [u8; 4]) -> bool {
    p[1] > 190 && p[0] < 120 && p[2] < 170
}

/// The pad's yellow squares, as the camera shows them.
fn is_pad_yellow(p: [u8; 4]) -> bool {
    p[0] > 120 && p[1] > 100 && (p[2] as i32) < p[1] as i32 - 40
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn dashboard_shows_the_camera_with_its_overlay_and_follows_the_contact() {
    const WIDTH: u32 = 640;
    const HEIGHT: u32 = 480;
    // With a token: the page must work through the cookie it gets from /?token=.
    let daemon = Daemon::start(Options::sim(WIDTH, HEIGHT, 10.0).token("dashboard-token"));
    let resting = daemon.settle(&rest(), true).await;
    assert_eq!(resting["estimate"]["contact"], json!(false));

    let driver = Driver::start().await;
    driver.goto(&daemon.url("/?token=dashboard-token")).await;
    let before = driver
        .wait_for(PAGE_STATE, Duration::from_secs(60), |s| {
            s["live"] == json!("live")
                && s["contact"] == json!("no")
                && s["force"].as_str().is_some_and(|f| f.parse::<f64>().is_ok())
                && s["image"].as_u64() == Some(WIDTH as u64)
                && s["overlay"].as_str().is_some_and(|f| !f.is_empty())
        })
        .await;
    assert_eq!(before["problems"], json!(true), "no problems shown at rest: {before}");
    let url = driver.eval("return location.href;").await;
    assert!(
        !url.as_str().unwrap().contains("token"),
        "the token left the address bar: {url}"
    );

    // The camera panel shows the pad: many yellow squares, and the green lattice over them.
    let shot = driver.screenshot().await;
    let frame = element_rect(&driver, "frame").await;
    let pixels: Vec<_> = frame.pixels(&shot).collect();
    let yellow = pixels.iter().filter(|(_, _, p)| is_pad_yellow(*p)).count();
    let lattice = pixels.iter().filter(|(_, _, p)| is_lattice(*p)).count();
    assert!(
        yellow * 10 > pixels.len(),
        "the camera region is blank: {yellow} yellow pixels of {}",
        pixels.len()
    );
    assert!(
        lattice > 1000,
        "the lattice is not drawn over the picture: {lattice} green pixels"
    );
    assert_eq!(
        pixels.iter().filter(|(_, _, p)| is_marker(*p)).count(),
        0,
        "no contact marker at rest"
    );

    // Press left of centre: the marker appears where the simulator pressed.
    let mut scene = press_at(4.0, [-9.0, 5.0]);
    // A straight press: a drag moves the shear centre off the contact, which is the estimator's business.
    scene.contacts[0].tangential_force_n = [0.0, 0.0];
    let truth = contact_px(WIDTH, HEIGHT, &scene);
    daemon.settle(&scene, false).await;
    let pressed = driver
        .wait_for(PAGE_STATE, Duration::from_secs(60), |s| s["contact"] == json!("yes"))
        .await;
    assert_ne!(pressed["frame"], before["frame"], "frames advance");
    assert_ne!(
        pressed["gamma"], before["gamma"],
        "the shear shown changes: {before} -> {pressed}"
    );
    // A frame shown after the press, with its own overlay.
    let pressed_frame: u64 = pressed["frame"]
        .as_str()
        .unwrap()
        .split(' ')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    driver
        .wait_for(PAGE_STATE, Duration::from_secs(30), |s| {
            s["overlay"].as_str().and_then(|f| f.parse::<u64>().ok()) > Some(pressed_frame)
        })
        .await;
    let shot = driver.screenshot().await;
    let marker: Vec<(f64, f64)> = frame
        .pixels(&shot)
        .filter(|(_, _, p)| is_marker(*p))
        .map(|(x, y, _)| (x, y))
        .collect();
    assert!(marker.len() > 30, "no contact marker drawn: {} pixels", marker.len());
    let n = marker.len() as f64;
    let centre_screen = (
        marker.iter().map(|m| m.0).sum::<f64>() / n,
        marker.iter().map(|m| m.1).sum::<f64>() / n,
    );
    let centre_px = [
        (centre_screen.0 - frame.x) * WIDTH as f64 / frame.width,
        (centre_screen.1 - frame.y) * HEIGHT as f64 / frame.height,
    ];
    let miss = ((centre_px[0] - truth[0]).powi(2) + (centre_px[1] - truth[1]).powi(2)).sqrt();
    // Within the contact: about 2.5 mm on the pad at this size (the sphere's contact radius is larger).
    assert!(
        miss < 20.0,
        "the marker is at {centre_px:?} px, the contact at {truth:?} px ({miss:.1} px apart)"
    );
    // And exactly where the shown frame's reading puts it.
    let shown = driver
        .eval("return document.getElementById('overlay').dataset.frameId;")
        .await;
    let (_, reading) = daemon.get("/api/v1/reading").await;
    if reading["frame_id"].as_u64() == shown.as_str().and_then(|id| id.parse().ok()) {
        let c = &reading["estimate"]["contact_px"];
        let (cx, cy) = (c[0].as_f64().unwrap(), c[1].as_f64().unwrap());
        assert!(
            (cx - centre_px[0]).hypot(cy - centre_px[1]) < 3.0,
            "marker {centre_px:?}, reading {c}"
        );
    }
    assert!(
        centre_px[0] < WIDTH as f64 / 2.0,
        "pressed left of centre: {centre_px:?}"
    );

    // The force plot drew its line.
    let chart = element_rect(&driver, "force-chart").await;
    let line = chart
        .pixels(&shot)
        .filter(|(_, _, p)| p[2] > 200 && p[1] > 150 && p[0] < 120)
        .count();
    assert!(line > 50, "force plot line: {line} pixels");

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
    let leds = driver.text("led-table").await;
    assert!(
        leds.contains("top") && leds.contains("mA"),
        "LED currents shown: {leds}"
    );
    // The board line names the sensor as its Zenoh keys and ROS 2 names do: by its board's serial number.
    let serial = daemon.status().await["serial_number"]
        .as_str()
        .expect("the virtual board's serial number in the status")
        .to_owned();
    let board_line = driver.text("board-state").await;
    assert!(
        board_line.starts_with(&format!("virtual board {serial} on ")),
        "{board_line}"
    );

    // Release: the contact disappears again.
    daemon
        .send("PUT", "/api/v1/sim/scene", json!({ "scene": rest() }))
        .await;
    driver
        .wait_for(PAGE_STATE, Duration::from_secs(60), |s| s["contact"] == json!("no"))
        .await;
}

/// The `.error` colour of the page's style (#ff8a80), as text anti-aliasing leaves its cores.
fn is_error_text(p: [u8; 4]) -> bool {
    p[0] > 220 && (110..170).contains(&p[1]) && (100..160).contains(&p[2])
}

/// A disk that fills up while the dashboard records: the page says so in words, in red, from the status's
/// `recording_failure` (the recording panel, beside the problems banner), and its readings go on.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn dashboard_says_in_words_that_the_disk_is_full_and_keeps_showing_readings() {
    let mut options = Options::sim(320, 240, 15.0);
    options.small_disk_kib = Some(256);
    let daemon = Daemon::start(options);
    let driver = Driver::start().await;
    driver.goto(&daemon.url("/")).await;
    driver
        .wait_for(PAGE_STATE, Duration::from_secs(60), |s| s["live"] == json!("live"))
        .await;

    // Recording started from the page, as a user does.
    driver
        .eval(
            "document.getElementById('record-name').value = 'big.mcap'; \
             document.getElementById('record').click(); return true;",
        )
        .await;
    const RECORD_STATE: &str = "const e = document.getElementById('record-state'); \
        return { text: e.textContent, class: e.className };";
    let shown = driver
        .wait_for(RECORD_STATE, Duration::from_secs(60), |s| {
            s["text"].as_str().is_some_and(|t| t.contains("the disk is full"))
        })
        .await;
    let status = daemon.status().await;
    let failure = &status["pipeline"]["recording_failure"];
    assert_eq!(failure["disk_full"], json!(true), "{status}");
    // The words are the recording failure's own (the problems banner carries other words).
    assert_eq!(
        shown["text"].as_str().unwrap(),
        format!("stopped: the disk is full — {}", failure["error"].as_str().unwrap()),
        "{shown}"
    );
    assert_eq!(shown["class"], json!("error"), "{shown}");
    assert_eq!(
        driver.text("record").await,
        "Start recording",
        "the page knows nothing records now"
    );
    let problems = driver
        .eval("const p = document.getElementById('problems'); return p.hidden ? null : p.textContent;")
        .await;
    assert!(
        problems
            .as_str()
            .is_some_and(|p| p.contains("recording stopped: the disk is full")),
        "problems banner: {problems}"
    );

    // And a user sees it: the panel's words are drawn in the error colour.
    driver
        .eval("document.getElementById('record-state').scrollIntoView(); return true;")
        .await;
    let shot = driver.screenshot().await;
    let words = element_rect(&driver, "record-state").await;
    let red = words.pixels(&shot).filter(|(_, _, p)| is_error_text(*p)).count();
    assert!(red > 100, "the failure is not drawn in red: {red} pixels");

    // The readings go on after the disk filled.
    let frame_id = |s: &Value| {
        s["frame"]
            .as_str()
            .and_then(|f| f.split(' ').next()?.parse::<u64>().ok())
    };
    let then = frame_id(&driver.eval(PAGE_STATE).await).expect("the page shows a frame id");
    driver
        .wait_for(PAGE_STATE, Duration::from_secs(60), |s| {
            s["live"] == json!("live") && frame_id(s) > Some(then + 5)
        })
        .await;
}
