//! Issue 16's ROS 2 evidence: `nusense serve --sim --ros2`, the real binary, publishes to a DDS subscriber in a
//! process of its own that shares no code with it: Eclipse Cyclone DDS from Python (`ros2_subscriber.py`, run by
//! the project's .venv), with the ROS 2 types declared there as rosidl maps them to DDS. The wrenches it receives
//! must be the readings the daemon's WebSocket stream sends for the same frames, matched by their capture time.

use std::collections::HashMap;
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex};

use base64::Engine;
use futures_util::StreamExt;
use serde_json::Value;

use crate::daemon::{jpeg_dimensions, press_at, rest, venv_python, Daemon, Options, PATIENCE};

/// Wrenches each of the subscriber's two readers (reliable, best effort) must take.
const WRENCHES: usize = 8;

/// The topics and frame from the daemon's start-up line: `ROS 2 in domain D (...): WRENCH IMAGE CONTACTS (frame F)`.
fn announced(log: &str) -> (String, String, String) {
    let line = log
        .lines()
        .find(|l| l.contains("ROS 2 in domain"))
        .unwrap_or_else(|| panic!("no ROS 2 line in the daemon's log:\n{log}"));
    let names = line.split("): ").nth(1).expect("topics after the range");
    let words: Vec<&str> = names.split_whitespace().collect();
    let frame = words[4].trim_end_matches(')');
    (words[0].to_owned(), words[1].to_owned(), frame.to_owned())
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * (1.0 + b.abs())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_dds_subscriber_in_another_process_receives_each_frames_wrench_and_image() {
    // A domain of this test's own, so that other runs on the machine are not in it.
    let domain = 100 + std::process::id() % 100;
    let daemon = Daemon::start(
        Options::sim(640, 480, 8.0)
            .arg("--mode")
            .arg("inverse")
            .arg("--ros2")
            .env("ROS_DOMAIN_ID", &domain.to_string()),
    );
    let (wrench_topic, image_topic, frame) = announced(&daemon.log());
    assert!(
        wrench_topic.starts_with("/nusense/") && wrench_topic.ends_with("/wrench"),
        "{wrench_topic}"
    );
    assert!(
        daemon
            .log()
            .contains(&format!("ROS 2 in domain {domain} (this machine only)")),
        "localhost is the default range:\n{}",
        daemon.log()
    );
    daemon.settle(&rest(), true).await;
    daemon.settle(&press_at(4.0, [6.0, -5.0]), false).await;

    // Every reading the daemon publishes, by capture time, as its WebSocket stream sends them. The stream is
    // subscribed before the DDS subscriber starts, so each frame that subscriber can be sent is among them; it
    // misses none while the client reads (it keeps 64 readings for a slow one, and counts any it skips). Polling
    // GET /api/v1/reading instead saw only the readings that were current when a poll landed: on a loaded machine
    // a poll came late now and then, and the frame the image came from was not among those seen.
    let (stream, _) = tokio_tungstenite::connect_async(daemon.ws_url("/api/v1/stream"))
        .await
        .expect("open the reading stream");
    let readings: Arc<Mutex<HashMap<u64, Value>>> = Arc::default();
    let (latest_tx, mut latest) = tokio::sync::watch::channel(0u64);
    let collector = {
        let readings = readings.clone();
        tokio::spawn(async move {
            let (_, mut incoming) = stream.split();
            while let Some(Ok(message)) = incoming.next().await {
                if !message.is_text() {
                    continue;
                }
                let text = message.to_text().expect("a text message");
                let reading: Value = serde_json::from_str(text).expect("a reading");
                let capture_time_us = reading["capture_time_us"].as_u64().expect("capture_time_us");
                readings.lock().unwrap().insert(capture_time_us, reading);
                latest_tx.send_modify(|latest| *latest = (*latest).max(capture_time_us));
            }
        })
    };

    let subscriber = Command::new(venv_python("Cyclone DDS for the ROS 2 test"))
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/serve/ros2_subscriber.py"))
        .args(["--domain", &domain.to_string(), "--topic", &wrench_topic])
        .args(["--count", &WRENCHES.to_string(), "--timeout", "100", "--localhost"])
        .args(["--image-topic", &image_topic, "--images", "1"])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start the Cyclone DDS subscriber");
    let output = tokio::task::spawn_blocking(move || subscriber.wait_with_output())
        .await
        .unwrap()
        .expect("subscriber output");
    assert!(
        output.status.success(),
        "the subscriber received too little: {}\ndaemon:\n{}",
        String::from_utf8_lossy(&output.stderr),
        daemon.log()
    );

    let samples: Vec<Value> = String::from_utf8(output.stdout)
        .unwrap()
        .lines()
        .map(|line| serde_json::from_str(line).unwrap())
        .collect();
    let stamp =
        |sample: &Value| sample["sec"].as_u64().unwrap() * 1_000_000 + sample["nanosec"].as_u64().unwrap() / 1000;
    // The stream may deliver a reading a moment after DDS did: wait until it has passed the newest stamp received.
    let newest = samples.iter().map(stamp).max().expect("samples");
    tokio::time::timeout(PATIENCE, latest.wait_for(|&latest| latest >= newest))
        .await
        .unwrap_or_else(|_| {
            panic!(
                "the stream never reached the frame captured at {newest} us\n{}",
                daemon.log()
            )
        })
        .expect("the stream stays open");
    collector.abort();
    let websocket = daemon.status().await["websocket"].clone();
    assert_eq!(
        websocket["dropped"],
        serde_json::json!(0),
        "the stream skipped readings, so the frames cannot all be checked: {websocket}"
    );
    let readings = readings.lock().unwrap().clone();

    let mut matched: HashMap<&str, usize> = HashMap::new();
    for sample in &samples {
        let reader = sample["reader"].as_str().unwrap();
        assert_eq!(sample["frame_id"], frame.as_str(), "{sample}");
        let capture_time_us = stamp(sample);
        if reader == "image" {
            assert_eq!(sample["format"], "jpeg");
            let jpeg = base64::engine::general_purpose::STANDARD
                .decode(sample["data"].as_str().unwrap())
                .unwrap();
            assert_eq!(
                jpeg_dimensions(&jpeg),
                (640, 480),
                "a whole frame, reassembled from its fragments"
            );
            assert!(
                readings.contains_key(&capture_time_us),
                "the image's stamp is a frame's capture time"
            );
            *matched.entry(reader).or_default() += 1;
            continue;
        }
        let reading = readings
            .get(&capture_time_us)
            .unwrap_or_else(|| panic!("the wrench's stamp is a frame's capture time: {sample}"));
        let estimate = &reading["estimate"];
        assert_eq!(estimate["contact"], Value::Bool(true), "{reading}");
        let http_force: Vec<f64> = estimate["force_vector_n"]
            .as_array()
            .unwrap_or_else(|| panic!("inverse mode has a force vector: {reading}"))
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let dds_force: Vec<f64> = sample["force"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(
            dds_force, http_force,
            "frame {}: {sample} vs {reading}",
            reading["frame_id"]
        );
        // The moment's x and y: the normal force at the centre of pressure, in metres.
        let contacts = estimate["contacts"].as_array().unwrap();
        let weight: f64 = contacts.iter().map(|c| c["force_n"].as_f64().unwrap()).sum();
        let centre_m = |k: usize| {
            contacts
                .iter()
                .map(|c| c["force_n"].as_f64().unwrap() * c["centre_mm"][k].as_f64().unwrap())
                .sum::<f64>()
                / weight
                * 1e-3
        };
        let torque = &sample["torque"];
        assert!(
            close(torque[0].as_f64().unwrap(), centre_m(1) * http_force[2]),
            "{sample} vs {reading}"
        );
        assert!(
            close(torque[1].as_f64().unwrap(), -centre_m(0) * http_force[2]),
            "{sample} vs {reading}"
        );
        assert!(http_force[2] > 1.0, "a press of 4 N: {reading}");
        *matched.entry(reader).or_default() += 1;
    }
    for reader in ["reliable", "best_effort"] {
        assert!(
            matched.get(reader).copied().unwrap_or(0) >= WRENCHES,
            "{reader}: {matched:?} of {} samples ({} readings streamed)",
            samples.len(),
            readings.len()
        );
    }
    assert_eq!(matched.get("image"), Some(&1), "{matched:?}");

    // Leaving the DDS domain does not hold up a clean stop.
    let status = daemon.stop_with(libc::SIGTERM);
    assert!(status.success(), "{status:?}");
}
