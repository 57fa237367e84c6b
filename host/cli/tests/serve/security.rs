//! One test per attack of issue 15, each against the real daemon: before the fix every one of them succeeded.

use futures_util::StreamExt;
use serde_json::{json, Value};

use crate::daemon::{json_of, Daemon, Options};

/// DNS rebinding: a page on evil.example re-points its name at 127.0.0.1 and reads the daemon as "its own"
/// origin; the only trace is the Host header.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_rebound_host_name_is_refused_and_the_daemons_own_names_are_served() {
    let daemon = Daemon::start(Options::sim(160, 120, 10.0).arg("--allow-host").arg("sensor.lab"));
    daemon.wait_reading("at all", |_| true).await;
    for path in [
        "/api/v1/status",
        "/api/v1/reading",
        "/api/v1/frame.jpg",
        "/",
        "/api/status",
    ] {
        for host in ["evil.example", "evil.example:80", "127.0.0.1.evil.example"] {
            let response = daemon
                .http
                .get(daemon.url(path))
                .header("host", host)
                .send()
                .await
                .unwrap();
            let (code, body) = json_of(response).await;
            assert_eq!(code, 403, "{path} with Host {host}: {body}");
            assert!(body["error"].as_str().unwrap().contains("--allow-host"), "{body}");
        }
    }
    let port = daemon.addr.port();
    for host in [
        format!("127.0.0.1:{port}"),
        format!("localhost:{port}"),
        format!("sensor.lab:{port}"),
    ] {
        let response = daemon
            .http
            .get(daemon.url("/api/v1/status"))
            .header("host", &host)
            .send()
            .await
            .unwrap();
        assert_eq!(response.status().as_u16(), 200, "Host {host}");
    }
}

/// A page elsewhere posts to the daemon (no CORS needed for a "simple" request): refused, and nothing happens.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cross_site_requests_that_change_state_are_refused() {
    let daemon = Daemon::start(Options::sim(160, 120, 10.0));
    daemon.wait_reading("at all", |_| true).await;
    let tares_before = daemon.status().await["pipeline"]["tares"].clone();
    let cross_site = [
        ("POST", "/api/v1/tare", Value::Null),
        ("POST", "/api/tare", Value::Null),
        ("PUT", "/api/v1/led", json!({ "all": 0 })),
        ("POST", "/api/v1/record", json!({ "action": "start" })),
        ("PUT", "/api/v1/sim/scene", json!({ "script": true })),
    ];
    for (method, path, body) in &cross_site {
        for origin in ["http://evil.example", "null", "http://127.0.0.1:1"] {
            let response = daemon
                .http
                .request(method.parse().unwrap(), daemon.url(path))
                .header("origin", origin)
                .header("content-type", "text/plain")
                .body(body.to_string())
                .send()
                .await
                .unwrap();
            let (code, reply) = json_of(response).await;
            assert_eq!(code, 403, "{method} {path} from {origin}: {reply}");
        }
    }
    let status = daemon.status().await;
    assert_eq!(status["pipeline"]["tares"], tares_before, "no tare happened");
    assert!(status["pipeline"]["recording"].is_null(), "no recording started");
    // A fetch without Origin but marked cross-site by the browser is refused as well.
    let response = daemon
        .http
        .post(daemon.url("/api/v1/tare"))
        .header("sec-fetch-site", "cross-site")
        .send()
        .await
        .unwrap();
    assert_eq!(response.status().as_u16(), 403);

    // The daemon's own page may.
    let response = daemon
        .http
        .post(daemon.url("/api/v1/tare"))
        .header("origin", daemon.origin())
        .send()
        .await
        .unwrap();
    assert_eq!(response.status().as_u16(), 202);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_websocket_from_another_origin_is_refused() {
    use tokio_tungstenite::tungstenite::client::IntoClientRequest;
    let daemon = Daemon::start(Options::sim(160, 120, 10.0));
    let mut request = daemon.ws_url("/api/v1/stream").into_client_request().unwrap();
    request
        .headers_mut()
        .insert("origin", "http://evil.example".parse().unwrap());
    match tokio_tungstenite::connect_async(request).await {
        Err(tokio_tungstenite::tungstenite::Error::Http(response)) => assert_eq!(response.status().as_u16(), 403),
        Err(other) => panic!("refused, but not with 403: {other}"),
        Ok(_) => panic!("a page on evil.example opened the reading stream"),
    }
    let mut request = daemon.ws_url("/api/v1/stream").into_client_request().unwrap();
    request.headers_mut().insert("origin", daemon.origin().parse().unwrap());
    let (mut ws, _) = tokio_tungstenite::connect_async(request)
        .await
        .expect("the dashboard's own origin");
    let message = tokio::time::timeout(crate::daemon::PATIENCE, ws.next())
        .await
        .expect("a reading");
    assert!(message.unwrap().unwrap().is_text());
}

/// With --token the dashboard must work: `/?token=` sets a cookie (and leaves the address bar), then the page's
/// CSS, JS, API calls and WebSocket carry it. A wrong or missing token gets 401; the cookie does not excuse a
/// cross-site request.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn with_a_token_the_dashboard_works_through_its_cookie() {
    let daemon = Daemon::start(Options::sim(160, 120, 10.0).arg("--token").arg("s3cret token"));
    for path in ["/", "/dashboard.js", "/dashboard.css", "/api/v1/status"] {
        let (code, body) = daemon.get(path).await;
        assert_eq!(code, 401, "{path} without the token: {body}");
    }
    let response = daemon.http.get(daemon.url("/?token=wrong")).send().await.unwrap();
    assert_eq!(response.status().as_u16(), 401);

    let response = daemon
        .http
        .get(daemon.url("/?token=s3cret%20token"))
        .send()
        .await
        .unwrap();
    assert_eq!(response.status().as_u16(), 303, "the token leaves the address bar");
    assert_eq!(response.headers()["location"], "/");
    let cookie = response.headers()["set-cookie"].to_str().unwrap().to_string();
    assert!(
        cookie.contains("HttpOnly") && cookie.contains("SameSite=Strict"),
        "{cookie}"
    );
    let cookie = cookie.split(';').next().unwrap().to_string();

    for path in ["/", "/dashboard.js", "/dashboard.css", "/api/v1/status"] {
        let response = daemon
            .http
            .get(daemon.url(path))
            .header("cookie", &cookie)
            .send()
            .await
            .unwrap();
        assert_eq!(response.status().as_u16(), 200, "{path} with the cookie");
    }
    let mut request =
        tokio_tungstenite::tungstenite::client::IntoClientRequest::into_client_request(daemon.ws_url("/api/v1/stream"))
            .unwrap();
    request.headers_mut().insert("cookie", cookie.parse().unwrap());
    request.headers_mut().insert("origin", daemon.origin().parse().unwrap());
    tokio_tungstenite::connect_async(request)
        .await
        .expect("the page's WebSocket with its cookie");

    let tare = |origin: String| {
        daemon
            .http
            .post(daemon.url("/api/v1/tare"))
            .header("cookie", &cookie)
            .header("origin", origin)
            .send()
    };
    assert_eq!(tare(daemon.origin()).await.unwrap().status().as_u16(), 202);
    assert_eq!(tare("http://evil.example".into()).await.unwrap().status().as_u16(), 403);
    let response = daemon
        .http
        .get(daemon.url("/api/v1/status"))
        .header("cookie", format!("nusense_token_{}=00", daemon.addr.port()))
        .send()
        .await
        .unwrap();
    assert_eq!(response.status().as_u16(), 401, "a stale cookie");
    // Programs send the token itself.
    let response = daemon
        .http
        .post(daemon.url("/api/v1/tare"))
        .bearer_auth("s3cret token")
        .send()
        .await
        .unwrap();
    assert_eq!(response.status().as_u16(), 202);
}

/// `POST /api/v1/record` wrote anywhere (absolute paths, `..`) and truncated existing files.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn recordings_stay_in_their_folder_and_never_overwrite_unasked() {
    let daemon = Daemon::start(Options::sim(160, 120, 10.0));
    let outside = tempfile::tempdir().unwrap();
    let target = outside.path().join("x.mcap");
    let escapes = [
        (target.display().to_string(), 400),
        ("../x.mcap".to_string(), 400),
        ("a/../../x.mcap".to_string(), 400),
        ("notes.txt".to_string(), 422),
    ];
    for (path, expected) in &escapes {
        let (code, body) = daemon
            .send("POST", "/api/v1/record", json!({ "action": "start", "path": path }))
            .await;
        assert_eq!(code, *expected, "{path}: {body}");
        assert!(body["error"].as_str().unwrap().len() > 20, "a clear message: {body}");
    }
    assert!(!target.exists());
    assert!(!daemon.data_home.path().join("nusense/x.mcap").exists());

    let recordings = daemon.default_recordings();
    std::fs::create_dir_all(&recordings).unwrap();
    std::fs::write(recordings.join("precious.mcap"), b"an earlier session").unwrap();
    let (code, body) = daemon
        .send(
            "POST",
            "/api/v1/record",
            json!({ "action": "start", "path": "precious.mcap" }),
        )
        .await;
    assert_eq!(code, 409, "{body}");
    assert!(body["error"].as_str().unwrap().contains("overwrite"), "{body}");
    assert_eq!(
        std::fs::read(recordings.join("precious.mcap")).unwrap(),
        b"an earlier session"
    );

    let (code, body) = daemon
        .send(
            "POST",
            "/api/v1/record",
            json!({ "action": "start", "path": "precious.mcap", "overwrite": true }),
        )
        .await;
    assert_eq!(code, 200, "{body}");
    assert_eq!(body["recording"]["path"], json!("precious.mcap"));
    let (code, body) = daemon.send("POST", "/api/v1/record", json!({ "action": "stop" })).await;
    assert_eq!(code, 200, "{body}");
    let recording = nusense_daemon::record::read_recording(&recordings.join("precious.mcap")).unwrap();
    assert!(!recording.truncated, "a finished recording replaced the old file");

    let (code, body) = daemon
        .send("POST", "/api/v1/record", json!({ "action": "start" }))
        .await;
    assert_eq!(code, 200, "{body}");
    let file = body["recording"]["file"].as_str().unwrap().to_string();
    assert!(file.starts_with(recordings.to_str().unwrap()), "{file}");
    daemon.send("POST", "/api/v1/record", json!({ "action": "stop" })).await;
}
