//! `nusense serve --replay DIR`: a folder of frames whose contact jumps from side to side every frame, replayed
//! at 30 fps. `/api/v1/frame.jpg?overlay=1` must draw each picture's own reading: the contact cross where the
//! reading of that frame id (collected from the stream) puts it, never where a neighbouring frame's does.

use serde_json::json;

use crate::daemon::{press_at, render_folder, rest, Daemon, Options};

const WIDTH: u32 = 640;
const HEIGHT: u32 = 480;

/// Whether the overlay's magenta contact cross is drawn at `at` (raw px): its four arms, sampled 5 to 12 px out.
fn cross_at(image: &image::RgbImage, at: [f64; 2]) -> bool {
    let magenta = |x: f64, y: f64| {
        let (x, y) = (x.round() as i64, y.round() as i64);
        if x < 0 || y < 0 || x >= image.width() as i64 || y >= image.height() as i64 {
            return false;
        }
        let p = image.get_pixel(x as u32, y as u32);
        p[0] > 160 && p[2] > 160 && p[1] < 120
    };
    let samples: Vec<bool> = (5..=12)
        .flat_map(|d| {
            let d = d as f64;
            [(d, 0.0), (-d, 0.0), (0.0, d), (0.0, -d)]
        })
        .map(|(dx, dy)| magenta(at[0] + dx, at[1] + dy))
        .collect();
    samples.iter().filter(|&&m| m).count() * 4 >= samples.len() * 3
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn each_frame_is_served_with_its_own_overlay_on_a_folder_replay() {
    let folder = tempfile::tempdir().unwrap();
    // 0: rest (the first frame is the rest frame), 1: pressed left, 2: pressed right; then again, looping.
    render_folder(
        folder.path(),
        WIDTH,
        HEIGHT,
        &[rest(), press_at(4.0, [-12.0, 0.0]), press_at(4.0, [12.0, 0.0])],
    );
    let daemon = Daemon::start(Options::new(&[
        "--replay",
        folder.path().to_str().unwrap(),
        "--loop",
        "--fps",
        "30",
    ]));
    let status = daemon
        .wait_status("replaying", |s| s["pipeline"]["frames_processed"].as_u64() >= Some(6))
        .await;
    assert_eq!(status["camera"]["kind"], json!("replay"), "{status}");
    assert_eq!(status["board"]["kind"], json!("none"));

    // Every reading, by frame id, as the stream publishes them.
    let readings = std::sync::Arc::new(std::sync::Mutex::new(std::collections::HashMap::new()));
    let (ws, _) = tokio_tungstenite::connect_async(daemon.ws_url("/api/v1/stream"))
        .await
        .unwrap();
    let collected = readings.clone();
    let collector = tokio::spawn(async move {
        use futures_util::StreamExt;
        let (_, mut incoming) = ws.split();
        while let Some(Ok(message)) = incoming.next().await {
            let reading: serde_json::Value = serde_json::from_str(message.to_text().unwrap()).unwrap();
            let id = reading["frame_id"].as_u64().unwrap();
            let contact = reading["estimate"]["contact_px"]
                .as_array()
                .map(|p| [p[0].as_f64().unwrap(), p[1].as_f64().unwrap()]);
            collected.lock().unwrap().insert(id, contact);
        }
    });

    let mut seen = [0; 3];
    let mut checked = 0;
    for _ in 0..40 {
        let response = daemon
            .http
            .get(daemon.url("/api/v1/frame.jpg?overlay=1"))
            .send()
            .await
            .unwrap();
        assert_eq!(response.status().as_u16(), 200);
        let frame_id: u64 = response.headers()["x-nusense-frame-id"]
            .to_str()
            .unwrap()
            .parse()
            .unwrap();
        let jpeg = response.bytes().await.unwrap();
        seen[(frame_id % 3) as usize] += 1;
        let image = image::load_from_memory(&jpeg).expect("JPEG").to_rgb8();
        // The reading of this very frame (it was published before its picture could be served).
        tokio::time::sleep(std::time::Duration::from_millis(37)).await;
        let readings = readings.lock().unwrap().clone();
        let Some(contact) = readings.get(&frame_id).copied() else {
            continue;
        };
        checked += 1;
        if let Some(c) = contact {
            assert!(
                cross_at(&image, c),
                "frame {frame_id}: no cross where its reading has the contact, {c:?}"
            );
        }
        // No cross where any other frame's reading had its contact (unless it is this frame's place too).
        for other in readings.values().flatten() {
            let same_place = contact.is_some_and(|c| (c[0] - other[0]).hypot(c[1] - other[1]) < 30.0);
            assert!(
                same_place || !cross_at(&image, *other),
                "frame {frame_id} (contact {contact:?}) carries another frame's cross at {other:?}"
            );
        }
    }
    collector.abort();
    assert!(
        checked >= 20,
        "only {checked} pictures could be matched with their readings"
    );
    assert!(seen.iter().all(|&n| n > 0), "every file was seen: {seen:?}");
}
