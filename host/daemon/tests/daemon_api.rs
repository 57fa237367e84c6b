//! The daemon's HTTP/WebSocket API against a daemon on the simulator (virtual board over a pty), on loopback.

mod daemon_common;

use std::time::Duration;

use daemon_common::{press, rest, start, DaemonSetup};
use futures_util::StreamExt;
use serde_json::{json, Value};

async fn json_of(response: reqwest::Response) -> (u16, Value) {
    let status = response.status().as_u16();
    let text = response.text().await.expect("body");
    (status, serde_json::from_str(&text).unwrap_or(Value::String(text)))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn readings_status_frames_and_contact_changes() {
    let daemon = start(DaemonSetup::default()).await;
    let http = reqwest::Client::new();

    let rest_reading = daemon.settle(rest(), true).await;
    let led = &rest_reading["led"];
    assert!(led.is_object(), "readings carry the board's LED state: {rest_reading}");
    assert!(rest_reading["capture_time_us"].as_u64().unwrap() <= rest_reading["processed_time_us"].as_u64().unwrap());
    assert!(rest_reading["latency_ms"].as_f64().unwrap() >= 0.0);
    let rest_estimate = &rest_reading["estimate"];
    assert_eq!(rest_estimate["contact"], json!(false), "{rest_estimate}");

    let pressed = daemon.settle(press(4.0), false).await;
    let pressed_estimate = &pressed["estimate"];
    assert!(
        pressed_estimate["gamma"].as_f64().unwrap() > rest_estimate["gamma"].as_f64().unwrap(),
        "pressing shears the pad: rest {rest_estimate} pressed {pressed_estimate}"
    );
    assert_eq!(pressed_estimate["contact"], json!(true), "{pressed_estimate}");

    let (code, status) = json_of(http.get(daemon.url("/api/status")).send().await.unwrap()).await;
    assert_eq!(code, 200);
    assert_eq!(status["simulator"], json!(true));
    assert_eq!(status["camera"]["width"], json!(640));
    assert!(status["pipeline"]["frames_processed"].as_u64().unwrap() >= 2);
    assert_eq!(status["board"]["connected"], json!(true), "{status}");

    let (code, reading) = json_of(http.get(daemon.url("/api/reading")).send().await.unwrap()).await;
    assert_eq!(code, 200);
    assert!(reading["frame_id"].as_u64().unwrap() >= pressed["frame_id"].as_u64().unwrap());

    for path in ["/api/frame.jpg", "/api/frame.jpg?overlay=1"] {
        let response = http.get(daemon.url(path)).send().await.unwrap();
        assert_eq!(response.status().as_u16(), 200, "{path}");
        assert_eq!(response.headers()["content-type"], "image/jpeg");
        let bytes = response.bytes().await.unwrap();
        let image = image_dimensions(&bytes);
        assert_eq!(image, (640, 480), "{path}");
    }
    let (code, body) = json_of(http.get(daemon.url("/api/frame.jpg?overlay=7")).send().await.unwrap()).await;
    assert_eq!(code, 400, "{body}");
    daemon.stop().await;
}

/// Width and height from a JPEG's SOF marker (enough to know the daemon served a whole frame).
fn image_dimensions(jpeg: &[u8]) -> (u32, u32) {
    assert!(jpeg.starts_with(&[0xFF, 0xD8]), "not a JPEG");
    let mut i = 2;
    while i + 9 < jpeg.len() {
        if jpeg[i] != 0xFF {
            i += 1;
            continue;
        }
        let marker = jpeg[i + 1];
        let len = u16::from_be_bytes([jpeg[i + 2], jpeg[i + 3]]) as usize;
        if (0xC0..=0xC3).contains(&marker) {
            let h = u16::from_be_bytes([jpeg[i + 5], jpeg[i + 6]]) as u32;
            let w = u16::from_be_bytes([jpeg[i + 7], jpeg[i + 8]]) as u32;
            return (w, h);
        }
        i += 2 + len;
    }
    panic!("no SOF marker");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn led_commands_reach_the_board_and_bad_requests_get_4xx() {
    let daemon = start(DaemonSetup {
        width: 320,
        height: 240,
        ..Default::default()
    })
    .await;
    let http = reqwest::Client::new();
    let put = |body: String| {
        http.put(daemon.url("/api/led"))
            .header("content-type", "application/json")
            .body(body)
            .send()
    };

    let (code, body) = json_of(put(json!({ "top": 121 }).to_string()).await.unwrap()).await;
    assert_eq!(code, 422, "{body}");
    assert!(body["error"].as_str().unwrap().contains("120 mA"), "{body}");
    let (code, body) = json_of(put("{not json".into()).await.unwrap()).await;
    assert_eq!(code, 400, "{body}");
    assert!(body["error"].is_string());
    let (code, body) = json_of(put(json!({ "middle": 10 }).to_string()).await.unwrap()).await;
    assert_eq!(code, 422, "unknown side: {body}");
    let (code, body) = json_of(put(json!({}).to_string()).await.unwrap()).await;
    assert_eq!(code, 422, "nothing to set: {body}");

    let (code, body) = json_of(
        put(json!({ "top": 60, "right": 70, "bottom": 80, "left": 90 }).to_string())
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(code, 200, "{body}");
    let reading = daemon
        .wait_reading(Duration::from_secs(10), |r| {
            r["led"]["setpoint_ma"] == json!([60, 70, 80, 90])
        })
        .await
        .expect("readings report the new LED setpoints");
    let measured = reading["led"]["measured_ma"].as_array().unwrap().clone();
    assert_eq!(measured.len(), 4);

    for (path, method) in [
        ("/api/stream?every=0", "GET"),
        ("/api/nothing", "GET"),
        ("/api/tare", "GET"),
    ] {
        let response = http
            .request(method.parse().unwrap(), daemon.url(path))
            .send()
            .await
            .unwrap();
        assert!(response.status().is_client_error(), "{path}: {}", response.status());
    }
    let (code, body) = json_of(
        http.put(daemon.url("/api/sim/scene"))
            .json(&json!({ "scene": { "contacts": "many" } }))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(code, 422, "{body}");
    let (code, body) = json_of(
        http.post(daemon.url("/api/record"))
            .json(&json!({ "action": "stop" }))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(code, 409, "{body}");
    let (code, _) = json_of(http.post(daemon.url("/api/tare")).send().await.unwrap()).await;
    assert_eq!(code, 202);
    daemon.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_token_guards_every_request_including_websockets() {
    let daemon = start(DaemonSetup {
        width: 320,
        height: 240,
        token: Some("s3cret".into()),
        ..Default::default()
    })
    .await;
    let http = reqwest::Client::new();
    assert_eq!(
        http.get(daemon.url("/api/status"))
            .send()
            .await
            .unwrap()
            .status()
            .as_u16(),
        401
    );
    assert_eq!(http.get(daemon.url("/")).send().await.unwrap().status().as_u16(), 401);
    let wrong = http
        .get(daemon.url("/api/status"))
        .bearer_auth("guess")
        .send()
        .await
        .unwrap();
    assert_eq!(wrong.status().as_u16(), 401);
    assert_eq!(
        http.get(daemon.url("/api/status"))
            .bearer_auth("s3cret")
            .send()
            .await
            .unwrap()
            .status()
            .as_u16(),
        200
    );
    assert_eq!(
        http.get(daemon.url("/api/status?token=s3cret"))
            .send()
            .await
            .unwrap()
            .status()
            .as_u16(),
        200
    );

    assert!(
        tokio_tungstenite::connect_async(daemon.ws_url("/api/stream"))
            .await
            .is_err(),
        "WebSocket without the token"
    );
    let (mut ws, _) = tokio_tungstenite::connect_async(daemon.ws_url("/api/stream?token=s3cret"))
        .await
        .expect("with the token");
    let message = tokio::time::timeout(Duration::from_secs(30), ws.next())
        .await
        .expect("a reading in time")
        .unwrap()
        .unwrap();
    let reading: Value = serde_json::from_str(message.to_text().unwrap()).unwrap();
    assert!(reading["frame_id"].is_u64());
    daemon.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn recording_toggled_through_the_api_reads_back() {
    let daemon = start(DaemonSetup {
        width: 320,
        height: 240,
        ..Default::default()
    })
    .await;
    let http = reqwest::Client::new();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("api.mcap");
    let (code, body) = json_of(
        http.post(daemon.url("/api/record"))
            .json(&json!({ "action": "start", "path": path }))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(code, 200, "{body}");
    let (code, body) = json_of(
        http.post(daemon.url("/api/record"))
            .json(&json!({ "action": "start", "path": path }))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(code, 409, "a second recording: {body}");
    let from = daemon.handle.latest_frame().map(|f| f.frame_id).unwrap_or(0);
    daemon
        .wait_reading(Duration::from_secs(30), |r| {
            r["frame_id"].as_u64().unwrap_or(0) >= from + 5
        })
        .await
        .expect("frames");
    let (code, body) = json_of(
        http.post(daemon.url("/api/record"))
            .json(&json!({ "action": "stop" }))
            .send()
            .await
            .unwrap(),
    )
    .await;
    assert_eq!(code, 200, "{body}");
    let frames = body["recorded"]["frames"].as_u64().unwrap();
    assert!(frames >= 3, "{body}");

    let recording = nusense_daemon::record::read_recording(&path).unwrap();
    assert!(!recording.truncated);
    let recorded = recording.frames();
    assert_eq!(recorded.len() as u64, frames);
    let first = image::load_from_memory(&recorded[0].jpeg).expect("recorded frames are JPEG");
    assert_eq!((first.width(), first.height()), (320, 240));
    let readings: Vec<Value> = recording
        .on_topic(nusense_daemon::record::READING_TOPIC)
        .map(|m| serde_json::from_slice(&m.data).unwrap())
        .collect();
    assert!(!readings.is_empty());
    assert!(readings
        .iter()
        .all(|r| r["frame_id"].is_u64() && r.get("estimate").is_some()));
    assert!(
        recording.on_topic(nusense_daemon::record::TELEMETRY_TOPIC).count() > 0,
        "board telemetry is recorded"
    );
    daemon.stop().await;
}
