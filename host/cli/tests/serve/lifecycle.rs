//! The daemon left running next to a robot: stopped by a signal, its board unplugged, its disk full.

use std::time::{Duration, Instant};

use nusense_board::virtual_board::{VirtualBoard, VirtualBoardOptions};
use serde_json::json;

use crate::daemon::{Daemon, Options, NOMINAL_MA};

/// SIGTERM (systemd stop), SIGINT (Ctrl-C) and SIGHUP (a closed terminal) each stop the daemon with exit 0 and a
/// finished recording (summary and footer written: the reader finds it whole).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_stop_signal_finishes_the_recording_and_exits_0() {
    for (signal, name) in [
        (libc::SIGTERM, "SIGTERM"),
        (libc::SIGINT, "SIGINT"),
        (libc::SIGHUP, "SIGHUP"),
    ] {
        let recordings = tempfile::tempdir().unwrap();
        let daemon = Daemon::start(
            Options::sim(160, 120, 15.0)
                .arg("--recordings")
                .arg(recordings.path().display().to_string()),
        );
        let (code, body) = daemon
            .send(
                "POST",
                "/api/v1/record",
                json!({ "action": "start", "path": "run.mcap" }),
            )
            .await;
        assert_eq!(code, 200, "{body}");
        daemon
            .wait_status("recording a few frames", |s| {
                s["pipeline"]["recording"]["frames"].as_u64() >= Some(3)
            })
            .await;
        let status = daemon.stop_with(signal);
        assert!(status.success(), "{name}: exit {status:?}");
        let recording = nusense_daemon::record::read_recording(&recordings.path().join("run.mcap")).unwrap();
        assert!(!recording.truncated, "{name}: the recording was not finished");
        assert!(
            recording.frames().len() >= 3,
            "{name}: {} frames",
            recording.frames().len()
        );
    }
}

/// The daemon on a board of its own (a virtual board behind a pty, like a USB board at a stable path): pulling
/// the cable shows in the status and the readings go on; plugging it back reconnects within 2 s; a SIGTERM then
/// leaves the LEDs as the board has them configured.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_unplugged_board_reconnects_within_2_s_and_a_stop_leaves_its_leds_on() {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("ttyNUSENSE");
    let mut board = VirtualBoard::spawn_pty_with(VirtualBoardOptions {
        link_path: Some(link.clone()),
        ..Default::default()
    })
    .unwrap();
    let daemon = Daemon::start(
        Options::sim(160, 120, 15.0)
            .arg("--board")
            .arg(link.display().to_string()),
    );
    daemon
        .wait_status("with the board connected", |s| s["board"]["connected"] == json!(true))
        .await;
    assert_eq!(daemon.status().await["board"]["kind"], json!("serial"));

    for round in 0..3 {
        board.unplug();
        let status = daemon
            .wait_status("showing the board gone", |s| s["board"]["connected"] == json!(false))
            .await;
        assert!(
            status["problems"]
                .as_array()
                .unwrap()
                .iter()
                .any(|p| p.as_str().unwrap().starts_with("LED board")),
            "the loss is said in words: {status}"
        );
        let frame = daemon.frames_captured().await;
        daemon
            .wait_reading("while the board is away", |r| r["frame_id"].as_u64() > Some(frame + 2))
            .await;

        board.replug().unwrap();
        let plugged = Instant::now();
        loop {
            let status = daemon.status().await;
            if status["board"]["connected"] == json!(true) {
                break;
            }
            assert!(
                plugged.elapsed() < Duration::from_secs(2),
                "round {round}: not reconnected 2 s after the replug: {}",
                status["board"]
            );
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        println!("round {round}: reconnected {:?} after the replug", plugged.elapsed());
    }
    let reading = daemon
        .wait_reading("with the LED state of the board back", |r| r["led"].is_object())
        .await;
    assert_eq!(
        reading["led"]["setpoint_ma"],
        json!([100, 100, 100, 100]),
        "{}",
        reading["led"]
    );

    let status = daemon.stop_with(libc::SIGTERM);
    assert!(status.success(), "{status:?}");
    tokio::time::sleep(Duration::from_millis(300)).await;
    for current in board.led_currents_ma() {
        assert!(
            (current - NOMINAL_MA).abs() < 10.0,
            "the daemon's stop changed the LEDs: {:?} mA",
            board.led_currents_ma()
        );
    }
}

/// A disk that fills up mid-recording: the recording stops cleanly and says so (status, problems), the
/// readings keep coming, and the next recording attempt gets a clear error.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_full_disk_stops_the_recording_and_the_readings_go_on() {
    let mut options = Options::sim(320, 240, 15.0);
    options.small_disk_kib = Some(256);
    let daemon = Daemon::start(options);
    let (code, body) = daemon
        .send(
            "POST",
            "/api/v1/record",
            json!({ "action": "start", "path": "big.mcap" }),
        )
        .await;
    assert_eq!(code, 200, "{body}");
    let status = daemon
        .wait_status("reporting the full disk", |s| {
            s["pipeline"]["recording_failure"]["disk_full"] == json!(true)
        })
        .await;
    assert!(status["pipeline"]["recording"].is_null(), "{status}");
    let problems = status["problems"].to_string();
    assert!(problems.contains("the disk is full"), "{problems}");
    let failure = status["pipeline"]["recording_failure"]["error"].as_str().unwrap();
    assert!(failure.contains("is full"), "{failure}");

    let frame = daemon.frames_captured().await;
    daemon
        .wait_reading("after the disk filled", |r| {
            r["frame_id"].as_u64() > Some(frame + 5) && r["estimate"].is_object()
        })
        .await;
    let (code, body) = daemon.send("POST", "/api/v1/record", json!({ "action": "stop" })).await;
    assert_eq!(code, 409, "nothing is recording any more: {body}");
    let status = daemon.stop_with(libc::SIGTERM);
    assert!(status.success(), "{status:?}");
}
