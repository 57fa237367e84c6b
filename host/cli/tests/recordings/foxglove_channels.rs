//! Issue 16's Foxglove evidence, each with a consumer in a process of its own:
//! - `nusense record` writes a recording whose every message the reference Python reader decodes against the
//!   schema stored in the file (protobuf via mcap-protobuf-support, JSON via its JSON Schema), and whose every
//!   message the Foxglove SDK's own types decode here; the metadata records name the sensor and its calibration;
//!   `nusense replay` replays it, and a recording of the first format (JSON frames) too.
//! - `nusense serve --foxglove` serves the same channels to a Foxglove WebSocket client.

use std::collections::{BTreeMap, BTreeSet};
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::Stdio;
use std::time::{Duration, Instant};

use foxglove::messages::{CameraCalibration, CompressedImage, ImageAnnotations};
use foxglove::Decode;
use futures_util::{SinkExt, StreamExt};
use nusense_daemon::record::{ANNOTATIONS_TOPIC, CALIBRATION_TOPIC, FRAME_TOPIC, READING_TOPIC, TELEMETRY_TOPIC};

use crate::support::{nusense, python_reports, record_command, HEIGHT, WIDTH};

const FRAMES: u64 = 20;

fn is_jpeg(bytes: &[u8]) -> bool {
    bytes.starts_with(&[0xFF, 0xD8]) && bytes.ends_with(&[0xFF, 0xD9])
}

/// Decodes one message with the Foxglove SDK's type for its schema (or as JSON), checking what it must hold.
fn check_message(schema: &str, data: &[u8], width: u32, height: u32) {
    match schema {
        "foxglove.CompressedImage" => {
            let image = CompressedImage::decode(data).expect("CompressedImage decodes");
            assert_eq!((image.format.as_str(), image.frame_id.as_str()), ("jpeg", "camera"));
            assert!(is_jpeg(&image.data), "the frame is a whole JPEG");
            let decoded = image::load_from_memory(&image.data).expect("JPEG decodes");
            assert_eq!((decoded.width(), decoded.height()), (width, height));
        }
        "foxglove.CameraCalibration" => {
            let calibration = CameraCalibration::decode(data).expect("CameraCalibration decodes");
            assert_eq!((calibration.width, calibration.height), (width, height));
            assert_eq!(calibration.distortion_model, "kannala_brandt");
            assert_eq!(
                (calibration.k.len(), calibration.d.len(), calibration.p.len()),
                (9, 4, 12)
            );
            // The principal point lies inside the frame it describes.
            assert!(calibration.k[2] > 0.0 && calibration.k[2] < f64::from(width));
            assert!(calibration.k[5] > 0.0 && calibration.k[5] < f64::from(height));
        }
        "foxglove.ImageAnnotations" => {
            let annotations = ImageAnnotations::decode(data).expect("ImageAnnotations decodes");
            let corners: usize = annotations.points.iter().map(|p| p.points.len()).sum();
            assert!(corners > 100, "the lattice's corners are drawn ({corners} points)");
            for point in annotations.points.iter().flat_map(|p| &p.points) {
                assert!(
                    point.x >= -1.0 && point.x <= f64::from(width) + 1.0,
                    "{point:?} in the frame"
                );
            }
        }
        "nusense.Reading" | "nusense.BoardTelemetry" => {
            serde_json::from_slice::<serde_json::Value>(data).expect("JSON message parses");
        }
        other => panic!("unexpected schema {other}"),
    }
}

#[test]
fn a_recording_carries_foxglove_schemas_that_every_reader_decodes() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("foxglove.mcap");
    let mut recorder = record_command(&path, &["--frames", &FRAMES.to_string()])
        .spawn()
        .unwrap();
    // The simulator's virtual board is named after the process that runs it (see `nusense_board`'s
    // `virtual_identity`): "VB" and the process id, as hex, then a counter.
    let board_serial_prefix = format!("5642{:08X}", recorder.id());
    assert!(recorder.wait().unwrap().success());

    // The reference Python reader, in its own process: every message decodes against the file's own schema.
    let reports = python_reports(std::slice::from_ref(&path), true);
    assert_eq!(reports.len(), 1, "one JSON report: {reports:?}");
    let report = &reports[&path];
    assert!(report["stopped_by"].is_null(), "{report}");
    assert_eq!(report["decoded"], report["messages"], "{report}");
    assert_eq!(report["indexed_messages"], report["messages"], "{report}");
    assert_eq!(report["summary"]["metadata_indexes"], 3, "{report}");
    let topics = &report["topics"];
    for topic in [
        FRAME_TOPIC,
        CALIBRATION_TOPIC,
        ANNOTATIONS_TOPIC,
        READING_TOPIC,
        TELEMETRY_TOPIC,
    ] {
        assert!(
            topics[topic].as_u64().unwrap_or(0) > 0,
            "{topic} carries messages: {report}"
        );
    }
    assert!(topics[FRAME_TOPIC].as_u64().unwrap() >= FRAMES, "{report}");

    // The mcap crate reads it, and the Foxglove SDK's own types decode every message.
    let bytes = std::fs::read(&path).unwrap();
    let mut schemas = BTreeSet::new();
    let mut count = 0;
    for message in mcap::MessageStream::new(&bytes).unwrap() {
        let message = message.unwrap();
        let schema = message.channel.schema.as_ref().expect("every channel has a schema");
        check_message(&schema.name, &message.data, WIDTH, HEIGHT);
        schemas.insert(schema.name.clone());
        count += 1;
    }
    assert_eq!(Some(count), report["messages"].as_u64());
    assert_eq!(schemas.len(), 5, "{schemas:?}");

    // Metadata: the sensor's identity, configuration and calibration.
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let metadata: BTreeMap<String, BTreeMap<String, String>> = summary
        .metadata_indexes
        .iter()
        .map(|index| {
            let record = mcap::read::metadata(&bytes, index).unwrap();
            (record.name, record.metadata)
        })
        .collect();
    assert_eq!(metadata["nusense.sensor"]["source_kind"], "simulator");
    assert_eq!(metadata["nusense.sensor"]["width"], "320");
    let board_serial = &metadata["nusense.sensor"]["board_serial"];
    assert!(
        board_serial.len() == 24 && board_serial.starts_with(&board_serial_prefix),
        "the virtual board of process {} is {board_serial}",
        &board_serial_prefix[4..]
    );
    let config: serde_json::Value = serde_json::from_str(&metadata["nusense.config"]["json"]).unwrap();
    assert!(config["camera"]["fx"].as_f64().unwrap() > 0.0);
    let lens: serde_json::Value = serde_json::from_str(&metadata["nusense.calibration"]["lens"]).unwrap();
    assert_eq!(lens, config["camera"]);

    // It replays.
    let replay = nusense()
        .args(["replay", path.to_str().unwrap(), "--json"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&replay.stdout);
    assert!(
        stdout.lines().count() as u64 >= FRAMES,
        "replay reads every frame: {}",
        String::from_utf8_lossy(&replay.stderr)
    );

    // Recorded again from that file, with no board: the sensor's metadata names none.
    let again = dir.path().join("again.mcap");
    let status = nusense()
        .arg("record")
        .arg(&again)
        .args(["--replay", path.to_str().unwrap(), "--frames", "3"])
        .stdout(Stdio::null())
        .status()
        .unwrap();
    assert!(status.success());
    let bytes = std::fs::read(&again).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let sensor = summary
        .metadata_indexes
        .iter()
        .map(|index| mcap::read::metadata(&bytes, index).unwrap())
        .find(|record| record.name == "nusense.sensor")
        .expect("nusense.sensor metadata");
    assert_eq!(sensor.metadata["source_kind"], "replay", "{:?}", sensor.metadata);
    assert!(!sensor.metadata.contains_key("board_serial"), "{:?}", sensor.metadata);
}

#[test]
fn a_recording_of_the_first_format_still_replays() {
    // The first recordings: foxglove.CompressedImage as JSON with the JPEG in base64, written with seeking chunks.
    use base64::Engine;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("first-format.mcap");
    let jpeg =
        std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("../estimator/tests/data/real/reference_fisheye.jpg"))
            .expect("the real rest frame");
    {
        let mut writer = mcap::Writer::new(std::io::BufWriter::new(std::fs::File::create(&path).unwrap())).unwrap();
        let schema = writer
            .add_schema("foxglove.CompressedImage", "jsonschema", b"{}")
            .unwrap();
        let channel = writer
            .add_channel(schema, FRAME_TOPIC, "json", &BTreeMap::new())
            .unwrap();
        for frame_id in 0..5u32 {
            let time_ns = 1_700_000_000_000_000_000 + u64::from(frame_id) * 33_000_000;
            let json = serde_json::json!({
                "timestamp": {"sec": time_ns / 1_000_000_000, "nsec": time_ns % 1_000_000_000},
                "frame_id": "camera",
                "data": base64::engine::general_purpose::STANDARD.encode(&jpeg),
                "format": "jpeg",
            });
            let header = mcap::records::MessageHeader {
                channel_id: channel,
                sequence: frame_id,
                log_time: time_ns,
                publish_time: time_ns,
            };
            writer
                .write_to_known_channel(&header, json.to_string().as_bytes())
                .unwrap();
        }
        writer.finish().unwrap();
    }
    let replay = nusense()
        .args(["replay", path.to_str().unwrap(), "--json"])
        .output()
        .unwrap();
    assert_eq!(String::from_utf8_lossy(&replay.stdout).lines().count(), 5, "{replay:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn serve_foxglove_streams_the_channels_to_a_websocket_client() {
    let mut child = nusense()
        .args([
            "serve",
            "--sim",
            "--width",
            &WIDTH.to_string(),
            "--height",
            &HEIGHT.to_string(),
            "--listen",
            "127.0.0.1:0",
        ])
        .args(["--foxglove", "127.0.0.1:0"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stderr = BufReader::new(child.stderr.take().unwrap());
    let (found, lines) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in stderr.lines().map_while(Result::ok) {
            if let Some(rest) = line.split("Foxglove WebSocket at ws://").nth(1) {
                let _ = found.send(rest.trim_end_matches('/').to_string());
            }
        }
    });
    let addr = lines
        .recv_timeout(Duration::from_secs(120))
        .expect("serve announces the Foxglove server");
    assert!(addr.starts_with("127.0.0.1:"), "loopback: {addr}");

    use tokio_tungstenite::tungstenite::client::IntoClientRequest;
    let mut request = format!("ws://{addr}/").into_client_request().unwrap();
    request
        .headers_mut()
        .insert("Sec-WebSocket-Protocol", "foxglove.sdk.v1".parse().unwrap());
    let (mut socket, _) = tokio_tungstenite::connect_async(request).await.expect("connect");

    let mut channels: BTreeMap<u64, (String, String)> = BTreeMap::new();
    let mut received: BTreeMap<String, usize> = BTreeMap::new();
    let mut ops = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(120);
    // The calibration comes once per subscription (and again when the frame size changes), the rest per frame.
    let wanted = [
        (FRAME_TOPIC, 3),
        (CALIBRATION_TOPIC, 1),
        (ANNOTATIONS_TOPIC, 3),
        (READING_TOPIC, 3),
    ];
    while wanted.iter().any(|(t, n)| received.get(*t).copied().unwrap_or(0) < *n) {
        assert!(
            Instant::now() < deadline,
            "received only {received:?} from {channels:?} (ops {ops:?})"
        );
        let message = match tokio::time::timeout(Duration::from_secs(30), socket.next()).await {
            Ok(Some(Ok(message))) => message,
            other => panic!("the server stopped sending: {other:?}; ops {ops:?}, received {received:?}"),
        };
        match message {
            tokio_tungstenite::tungstenite::Message::Text(text) => {
                let value: serde_json::Value = serde_json::from_str(&text).unwrap();
                ops.push(value["op"].as_str().unwrap_or("?").to_string());
                if value["op"] == "advertise" {
                    let mut subscriptions = Vec::new();
                    for channel in value["channels"].as_array().unwrap() {
                        let id = channel["id"].as_u64().unwrap();
                        let topic = channel["topic"].as_str().unwrap().to_string();
                        let schema = channel["schemaName"].as_str().unwrap().to_string();
                        channels.insert(id, (topic, schema));
                        subscriptions.push(serde_json::json!({"id": id, "channelId": id}));
                    }
                    let subscribe = serde_json::json!({"op": "subscribe", "subscriptions": subscriptions});
                    socket
                        .send(tokio_tungstenite::tungstenite::Message::Text(
                            subscribe.to_string().into(),
                        ))
                        .await
                        .unwrap();
                }
            }
            tokio_tungstenite::tungstenite::Message::Binary(bytes) => {
                // Message data: opcode 1, subscription id (u32 LE, = the channel id here), log time (u64 LE).
                assert_eq!(bytes[0], 1, "message data");
                let subscription = u32::from_le_bytes(bytes[1..5].try_into().unwrap()) as u64;
                let (topic, schema) = channels[&subscription].clone();
                check_message(&schema, &bytes[13..], WIDTH, HEIGHT);
                *received.entry(topic).or_default() += 1;
            }
            _ => {}
        }
    }
    let advertised: BTreeSet<&str> = channels.values().map(|(t, _)| t.as_str()).collect();
    assert!(advertised.contains(TELEMETRY_TOPIC), "{advertised:?}");
    let _ = child.kill();
    let _ = child.wait();
}
