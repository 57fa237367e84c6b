//! The versioned API on the simulator: readings, status, frames, LED commands, the schema, old paths, 4xx.

use std::time::Duration;

use futures_util::StreamExt;
use serde_json::{json, Value};

use crate::daemon::{jpeg_dimensions, press, rest, Daemon, Options};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn readings_status_and_frames_follow_the_simulated_contact() {
    let daemon = Daemon::start(Options::sim(640, 480, 15.0));

    let resting = daemon.settle(&rest(), true).await;
    assert_eq!(resting["schema_version"], json!(1), "{resting}");
    assert!(
        resting["led"].is_object(),
        "readings carry the board's LED state: {resting}"
    );
    assert_eq!(resting["led"]["faults"], json!([[], [], [], []]), "{resting}");
    assert!(resting["capture_time_us"].as_u64().unwrap() <= resting["processed_time_us"].as_u64().unwrap());
    assert_eq!(resting["estimate"]["contact"], json!(false), "{resting}");

    let pressed = daemon.settle(&press(4.0), false).await;
    let estimate = &pressed["estimate"];
    assert_eq!(estimate["contact"], json!(true), "{estimate}");
    assert!(
        estimate["gamma"].as_f64().unwrap() > resting["estimate"]["gamma"].as_f64().unwrap(),
        "pressing shears the pad: rest {resting} pressed {estimate}"
    );

    let status = daemon.status().await;
    assert_eq!(status["schema_version"], json!(1));
    assert_eq!(status["simulator"], json!(true));
    assert_eq!(status["camera"]["width"], json!(640));
    assert_eq!(status["board"]["kind"], json!("virtual"), "{status}");
    assert_eq!(status["board"]["connected"], json!(true), "{status}");
    assert_eq!(status["problems"], json!([]), "{status}");
    assert_eq!(status["zenoh"], Value::Null, "not on Zenoh without --zenoh: {status}");
    // Capture to reading in three parts, each with its percentiles over the same frames.
    let stages = &status["pipeline"]["stage_latency_ms"];
    let samples = stages["capture_to_decode"]["samples"].as_u64().unwrap_or(0);
    assert!(samples > 0, "{stages}");
    for stage in ["capture_to_decode", "decode_to_estimate", "estimate_to_publish"] {
        let summary = &stages[stage];
        assert_eq!(summary["samples"].as_u64(), Some(samples), "{stage}: {stages}");
        let [p50, p99, max] = ["p50", "p99", "max"].map(|p| summary[p].as_f64().unwrap_or(f64::NAN));
        assert!(0.0 <= p50 && p50 <= p99 && p99 <= max, "{stage}: {summary}");
    }
    assert_eq!(
        status["recordings_dir"].as_str().unwrap(),
        daemon.default_recordings().to_str().unwrap(),
        "recordings go to $XDG_DATA_HOME/nusense/recordings by default"
    );

    // The picture and its id; the reading of that id is the one the overlay was drawn from.
    for path in ["/api/v1/frame.jpg", "/api/v1/frame.jpg?overlay=1"] {
        let response = daemon.http.get(daemon.url(path)).send().await.unwrap();
        assert_eq!(response.status().as_u16(), 200, "{path}");
        assert_eq!(response.headers()["content-type"], "image/jpeg");
        let frame_id: u64 = response.headers()["x-nusense-frame-id"]
            .to_str()
            .unwrap()
            .parse()
            .unwrap();
        assert!(
            frame_id >= pressed["frame_id"].as_u64().unwrap(),
            "{path}: frame {frame_id}"
        );
        assert_eq!(jpeg_dimensions(&response.bytes().await.unwrap()), (640, 480), "{path}");
    }
    let (code, body) = daemon.get("/api/v1/frame.jpg?overlay=7").await;
    assert_eq!(code, 400, "{body}");
    assert_eq!(
        body["schema_version"],
        json!(1),
        "errors are versioned messages too: {body}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_stream_sends_versioned_readings_and_the_schema_is_the_committed_one() {
    let daemon = Daemon::start(Options::sim(320, 240, 15.0));
    let (mut ws, _) = tokio_tungstenite::connect_async(daemon.ws_url("/api/v1/stream"))
        .await
        .expect("a program (no Origin) may open the stream");
    let message = tokio::time::timeout(crate::daemon::PATIENCE, ws.next())
        .await
        .expect("a reading in time")
        .unwrap()
        .unwrap();
    let reading: Value = serde_json::from_str(message.to_text().unwrap()).unwrap();
    assert_eq!(reading["schema_version"], json!(1), "{reading}");
    assert!(reading["frame_id"].is_u64());

    let response = daemon.http.get(daemon.url("/api/v1/schema")).send().await.unwrap();
    assert_eq!(response.status().as_u16(), 200);
    let served = response.text().await.unwrap();
    let committed = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../daemon/schema/reading.schema.json"
    ))
    .unwrap();
    assert_eq!(served, committed, "the served schema is the committed file");
    let schema: Value = serde_json::from_str(&served).unwrap();
    for key in reading.as_object().unwrap().keys() {
        assert!(schema["properties"].get(key).is_some(), "{key} is not in the schema");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn old_paths_redirect_to_v1_and_led_commands_reach_the_board() {
    let daemon = Daemon::start(Options::sim(320, 240, 15.0));

    let response = daemon.http.get(daemon.url("/api/status?x=1")).send().await.unwrap();
    assert_eq!(response.status().as_u16(), 308);
    assert_eq!(response.headers()["location"], "/api/v1/status?x=1");
    let response = daemon.http.post(daemon.url("/api/tare")).send().await.unwrap();
    assert_eq!(response.status().as_u16(), 308, "a redirect keeps the method");
    let (code, body) = daemon.get("/api/v1/nothing").await;
    assert_eq!(code, 404, "{body}");

    let (code, body) = daemon.send("PUT", "/api/v1/led", json!({ "top": 121 })).await;
    assert_eq!(code, 422, "{body}");
    assert!(body["error"].as_str().unwrap().contains("120 mA"), "{body}");
    let bad_json = daemon
        .http
        .put(daemon.url("/api/v1/led"))
        .header("content-type", "application/json")
        .body("{not json")
        .send()
        .await
        .unwrap();
    assert_eq!(bad_json.status().as_u16(), 400);
    let (code, body) = daemon.send("PUT", "/api/v1/led", json!({ "middle": 10 })).await;
    assert_eq!(code, 422, "unknown side: {body}");
    let (code, body) = daemon.send("PUT", "/api/v1/led", json!({})).await;
    assert_eq!(code, 422, "nothing to set: {body}");

    let (code, body) = daemon
        .send(
            "PUT",
            "/api/v1/led",
            json!({ "top": 60, "right": 70, "bottom": 80, "left": 90 }),
        )
        .await;
    assert_eq!(code, 200, "{body}");
    assert_eq!(body["schema_version"], json!(1));
    let reading = daemon
        .wait_reading("with the new setpoints", |r| {
            r["led"]["setpoint_ma"] == json!([60, 70, 80, 90])
        })
        .await;
    // The virtual board regulates towards the setpoints: measured currents follow within a few mA.
    tokio::time::sleep(Duration::from_millis(500)).await;
    let (_, reading_later) = daemon.get("/api/v1/reading").await;
    let measured: Vec<f64> = reading_later["led"]["measured_ma"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    for (got, want) in measured.iter().zip([60.0, 70.0, 80.0, 90.0]) {
        assert!((got - want).abs() < 5.0, "measured {measured:?} after {reading}");
    }

    let (code, body) = daemon
        .send("PUT", "/api/v1/sim/scene", json!({ "scene": { "contacts": "many" } }))
        .await;
    assert_eq!(code, 422, "{body}");
    let (code, body) = daemon.send("POST", "/api/v1/record", json!({ "action": "stop" })).await;
    assert_eq!(code, 409, "{body}");
    let (code, body) = daemon.get("/api/v1/stream?every=0").await;
    assert!((400..500).contains(&code), "{body}");
    let (code, _) = daemon.get("/api/v1/tare").await;
    assert_eq!(code, 405);
}
