//! `nusense serve --replay DIR` with a truncated and a corrupt JPEG among good frames: each bad frame is a typed
//! decode error, counted in the status and named in its problems, and the daemon goes on measuring the frames
//! after it.

use crate::daemon::{press_at, render_folder, rest, Daemon, Options};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn truncated_and_corrupt_frames_are_counted_and_the_daemon_goes_on() {
    let folder = tempfile::tempdir().unwrap();
    render_folder(folder.path(), 640, 480, &[rest(), press_at(4.0, [0.0, 0.0])]);
    let (rest_frame, good) = (
        std::fs::read(folder.path().join("000.jpg")).unwrap(),
        std::fs::read(folder.path().join("001.jpg")).unwrap(),
    );
    // Cut in the middle of the entropy-coded data, and a marker out of sequence in the middle of it.
    let truncated = good[..good.len() / 2].to_vec();
    let mut corrupt = good.clone();
    let middle = corrupt.len() / 2;
    corrupt[middle..middle + 2].copy_from_slice(&[0xFF, 0xD3]);
    // Three rest frames first: a debug build takes seconds for the first (the rest frame's model), and the queue
    // drops the oldest frames while it does, never the bad ones that come after.
    for (i, bytes) in [&rest_frame, &rest_frame, &rest_frame, &truncated, &corrupt, &good]
        .into_iter()
        .enumerate()
    {
        std::fs::write(folder.path().join(format!("{i:03}.jpg")), bytes).unwrap();
    }

    let mut daemon = Daemon::start(Options::new(&[
        "--replay",
        folder.path().to_str().unwrap(),
        "--fps",
        "1",
    ]));
    // The frame after the bad ones is measured: the press.
    let reading = daemon.wait_reading("of frame 5", |r| r["frame_id"] == 5).await;
    assert!(reading["estimate"]["contact"] == true, "{reading}");

    let status = daemon.status().await;
    let pipeline = &status["pipeline"];
    assert_eq!(pipeline["frames_captured"], 6, "{status}");
    let decode = &pipeline["decode"];
    assert_eq!(decode["errors"], 2, "{status}");
    let last = decode["last_error"].as_str().unwrap_or_default();
    assert!(last.contains("frame 4") && last.contains("corrupt JPEG"), "{last}");
    let problems = status["problems"].to_string();
    assert!(problems.contains("2 frames did not decode"), "{problems}");
    assert!(daemon.exited().is_none(), "the daemon is still running");
}
