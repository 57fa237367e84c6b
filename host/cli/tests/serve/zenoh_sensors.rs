//! `nusense serve --sim --sensors 2 --zenoh --ros2` with a separate process as the consumer: the Python Zenoh
//! client of the project's .venv (zenoh_consumer.py beside this file) receives both sensors' readings at once,
//! queries status, sets LEDs, tares, gets the HTTP API's error texts for bad LED bodies, and sees both sensors'
//! liveliness end when the daemon stops; each sensor's ROS 2 names carry the serial of its Zenoh keys.

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};

use serde_json::{json, Value};

use crate::daemon::{venv_python, zenoh_client, zenoh_query, Daemon, Options, PATIENCE};

/// A serial as a ROS name token: a ROS 2 name must not start with a digit, hence `sn_` before a serial that does
/// (serials are hex, so nothing else changes).
fn ros2_token(serial: &str) -> String {
    match serial.starts_with(|c: char| c.is_ascii_digit()) {
        true => format!("sn_{serial}"),
        false => serial.to_owned(),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_separate_zenoh_process_sees_two_sensors_commands_them_and_sees_them_go() {
    // ROS 2 on as well (in a DDS domain of this test's own): both ways out at once, naming the sensor alike.
    let domain = 100 + std::process::id() % 100;
    let daemon = Daemon::start(
        Options::sim(160, 120, 10.0)
            .arg("--sensors")
            .arg("2")
            .arg("--zenoh")
            .arg("tcp/127.0.0.1:0")
            .arg("--ros2")
            .env("ROS_DOMAIN_ID", &domain.to_string()),
    );
    daemon
        .wait_reading("with the board's LED state", |r| r["led"].is_object())
        .await;
    let first_serial: String = daemon.status().await["board"]["link"]["info"]["mcu_uid"]
        .as_array()
        .expect("the virtual board's identity")
        .iter()
        .map(|byte| format!("{:02X}", byte.as_u64().unwrap()))
        .collect();
    // One identity everywhere: the status (and the dashboard) say it, and the ROS 2 names carry it.
    assert_eq!(daemon.status().await["serial_number"], json!(first_serial));
    // What the HTTP API answers to bad LED bodies: Zenoh must answer the same, word for word.
    let mut http_errors = Vec::new();
    for body in [
        json!({ "top": 121 }),
        json!({ "middle": 10 }),
        json!({}),
        json!({ "all": 5, "left": 5 }),
    ] {
        let (code, reply) = daemon.send("PUT", "/api/v1/led", body.clone()).await;
        assert_eq!(code, 422, "{reply}");
        http_errors.push(json!([body, reply["error"]]));
    }
    assert!(
        http_errors[0][1].as_str().unwrap().contains("above the 120 mA limit"),
        "{http_errors:?}"
    );

    let schema = Path::new(env!("CARGO_MANIFEST_DIR")).join("../daemon/schema/reading.schema.json");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/serve/zenoh_consumer.py");
    let mut consumer = Command::new(venv_python("eclipse-zenoh for this test"))
        .arg(script)
        .args(["--connect", daemon.zenoh_endpoint(), "--sensors", "2", "--schema"])
        .arg(schema)
        .arg("--http-errors")
        .arg(Value::Array(http_errors.clone()).to_string())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start the Python consumer");
    let stdout = BufReader::new(consumer.stdout.take().unwrap());
    let mut events = stdout
        .lines()
        .map_while(Result::ok)
        .map(|line| serde_json::from_str::<Value>(&line).unwrap_or_else(|e| panic!("consumer said {line:?}: {e}")));
    let Some(checked) = events.next() else {
        let output = consumer.wait_with_output().unwrap();
        panic!(
            "the consumer failed: {}\ndaemon log:\n{}",
            String::from_utf8_lossy(&output.stderr),
            daemon.log()
        );
    };
    assert_eq!(checked["event"], "checked", "{checked}");
    let serials: Vec<&str> = checked["serials"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s.as_str().unwrap())
        .collect();
    assert_eq!(serials.len(), 2, "{checked}");
    assert_ne!(serials[0], serials[1]);
    assert!(
        serials.contains(&first_serial.as_str()),
        "the HTTP API's sensor ({first_serial}) is one of the Zenoh sensors: {checked}"
    );
    // Each sensor is on ROS 2 too, named after the serial of its Zenoh keys.
    for serial in &serials {
        let topic = format!("/nusense/{}/wrench ", ros2_token(serial));
        assert!(
            daemon
                .log()
                .lines()
                .any(|l| l.contains(&format!("ROS 2 in domain {domain} (this machine only): {topic}"))),
            "{topic}\n{}",
            daemon.log()
        );
    }
    let expected_errors: Vec<&Value> = http_errors.iter().map(|pair| &pair[1]).collect();
    let got_errors: Vec<&Value> = checked["led_errors"].as_array().unwrap().iter().collect();
    assert_eq!(got_errors, expected_errors);

    let ready = events.next().expect("ready_to_stop");
    assert_eq!(ready["event"], "ready_to_stop");
    let status = daemon.stop_with(libc::SIGTERM);
    assert!(status.success(), "{status:?}");
    let gone = events.next().expect("the consumer saw the sensors go");
    assert_eq!(gone, json!({ "event": "gone", "serials": serials }));
    let output = consumer.wait_with_output().unwrap();
    assert!(
        output.status.success(),
        "consumer: {}",
        String::from_utf8_lossy(&output.stderr)
    );
}

/// `--zenoh tcp/127.0.0.1:0`: the system gives the port, and the daemon says which one, so a client (and every test
/// here) connects to a port nobody could take first, rather than to one found free and passed on.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_zenoh_endpoint_on_port_0_is_reported_as_the_port_bound_and_reaches_the_sensor() {
    let daemon = Daemon::start(Options::sim(160, 120, 10.0).arg("--zenoh").arg("tcp/127.0.0.1:0"));
    assert_eq!(daemon.zenoh.len(), 1, "one endpoint asked for:\n{}", daemon.log());
    let endpoint = daemon.zenoh_endpoint();
    let port: u16 = endpoint
        .strip_prefix("tcp/127.0.0.1:")
        .and_then(|port| port.parse().ok())
        .unwrap_or_else(|| panic!("a loopback TCP endpoint with its port: {endpoint}"));
    assert_ne!(port, 0, "the port the system gave, not the 0 asked for");

    let http_status = daemon
        .wait_status("with the board's serial", |s| s["serial_number"].is_string())
        .await;
    // The status says the same endpoint as the log line: a client can ask the daemon where to connect.
    assert_eq!(
        http_status["zenoh"],
        json!({ "listening_on": [endpoint] }),
        "{http_status}"
    );
    let serial = http_status["serial_number"].as_str().unwrap().to_owned();
    let session = zenoh_client(endpoint).await;
    let deadline = tokio::time::Instant::now() + PATIENCE;
    // The first query may leave before the connection is up (no reply then): ask again until one comes.
    let status: Value = loop {
        if let Some(status) = zenoh_query(&session, &format!("nusense/{serial}/status"), None).await {
            break status;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "no status over Zenoh at {endpoint}:\n{}",
            daemon.log()
        );
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
    };
    assert_eq!(status["serial_number"], json!(serial), "{status}");
    assert_eq!(status["zenoh"], http_status["zenoh"], "{status}");
}
