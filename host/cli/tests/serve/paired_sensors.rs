//! Several sensors of real devices in one daemon, without hardware: `serve --sensor replay=DIR,board=PTY` twice,
//! each a folder of rendered frames paired with a virtual LED board on a pty of its own (the firmware's logic
//! behind a serial device, as a real board is). A Zenoh session in this process (the daemon is another) finds
//! both sensors named by their own boards' serial numbers, readings from each, and an LED command for one sensor
//! reaching that sensor's board and not the other's.

use std::collections::{BTreeMap, BTreeSet};
use std::time::Duration;

use nusense_board::virtual_board::VirtualBoard;
use serde_json::{json, Value};

use crate::daemon::{press, render_folder, rest, zenoh_client, zenoh_query, Daemon, Options, PATIENCE};

/// The reply to a query the daemon must answer (the session already receives its readings).
async fn query(session: &zenoh::Session, key: &str, payload: Option<&str>) -> Value {
    zenoh_query(session, key, payload)
        .await
        .unwrap_or_else(|| panic!("no reply on {key}"))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_replays_paired_with_two_boards_are_two_sensors_named_and_commanded_by_their_boards() {
    let boards = [
        VirtualBoard::spawn_pty().expect("a virtual board"),
        VirtualBoard::spawn_pty().expect("a virtual board"),
    ];
    let serials = [boards[0].serial_number(), boards[1].serial_number()];
    assert_ne!(serials[0], serials[1]);
    let folders = [tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap()];
    render_folder(folders[0].path(), 160, 120, &[rest(), press(3.0)]);
    render_folder(folders[1].path(), 160, 120, &[rest(), rest()]);
    let mut options = Options::new(&["--fps", "10", "--loop", "--zenoh", "tcp/127.0.0.1:0"]);
    for (folder, board) in folders.iter().zip(&boards) {
        options = options
            .arg("--sensor")
            .arg(format!("replay={},board={}", folder.path().display(), board.path()));
    }
    let daemon = Daemon::start(options);
    assert!(
        daemon
            .log()
            .contains(&format!("on Zenoh as nusense/{{{},{}}}/", serials[0], serials[1])),
        "each sensor is named by its own board, in the order given:\n{}",
        daemon.log()
    );

    let session = zenoh_client(daemon.zenoh_endpoint()).await;
    let subscriber = session
        .declare_subscriber("nusense/*/reading")
        .await
        .expect("subscribe");
    let mut readings: BTreeMap<String, usize> = BTreeMap::new();
    let deadline = tokio::time::Instant::now() + PATIENCE;
    while readings.len() < 2 || readings.values().any(|&n| n < 3) {
        let sample = tokio::time::timeout_at(deadline, subscriber.recv_async())
            .await
            .unwrap_or_else(|_| panic!("readings so far {readings:?}\n{}", daemon.log()))
            .expect("the subscriber is open");
        let reading: Value = serde_json::from_slice(&sample.payload().to_bytes()).expect("a JSON reading");
        assert_eq!(reading["schema_version"], json!(1), "{reading}");
        let serial = sample.key_expr().as_str().split('/').nth(1).unwrap().to_owned();
        *readings.entry(serial).or_default() += 1;
    }
    assert_eq!(
        readings.keys().cloned().collect::<BTreeSet<_>>(),
        serials.iter().cloned().collect::<BTreeSet<_>>()
    );
    for serial in &serials {
        let status = query(&session, &format!("nusense/{serial}/status"), None).await;
        assert_eq!(status["serial_number"], json!(serial), "{status}");
        assert_eq!(status["board"]["connected"], json!(true), "{status}");
    }

    // The second sensor's LEDs to 40 mA: its own board follows, the first one's keeps its current.
    let before = boards[0].led_currents_ma();
    let reply = query(&session, &format!("nusense/{}/led", serials[1]), Some(r#"{"all": 40}"#)).await;
    assert!(reply["board"].is_object(), "{reply}");
    let settled = tokio::time::Instant::now() + Duration::from_secs(30);
    while boards[1].led_currents_ma().iter().any(|ma| (ma - 40.0).abs() > 2.0) {
        assert!(
            tokio::time::Instant::now() < settled,
            "the second board's LEDs stay at {:?} mA",
            boards[1].led_currents_ma()
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    for (was, is) in before.iter().zip(boards[0].led_currents_ma()) {
        assert!(
            (was - is).abs() <= 2.0,
            "the first board moved: {before:?} -> {:?}",
            boards[0].led_currents_ma()
        );
    }
    assert!(
        before.iter().all(|ma| (ma - 40.0).abs() > 20.0),
        "the first board started at {before:?} mA, too close to 40 mA to tell the boards apart"
    );

    session.close().await.ok();
    let status = daemon.stop_with(libc::SIGTERM);
    assert!(status.success(), "{status:?}");
}
