//! A recording killed with SIGKILL keeps everything but at most its last chunk: `nusense record` is spawned on
//! the simulator, killed mid-write, and read back with the tolerant linear reader.

mod daemon_common;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Top-level MCAP records of a file: (opcode, body length) of every whole record, and the bytes after the last
/// whole record (a record cut off by the kill).
fn top_level_records(bytes: &[u8]) -> (Vec<(u8, usize)>, usize) {
    const MAGIC_LEN: usize = 8;
    assert_eq!(&bytes[..MAGIC_LEN], mcap::MAGIC, "starts with the MCAP magic");
    let mut records = Vec::new();
    let mut at = MAGIC_LEN;
    while at + 9 <= bytes.len() {
        let opcode = bytes[at];
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap());
        // A record being written when the kill came still carries its placeholder length.
        if len > (bytes.len() - at - 9) as u64 {
            break;
        }
        let len = len as usize;
        records.push((opcode, len));
        at += 9 + len;
    }
    (records, bytes.len() - at)
}

fn frames_in(path: &Path) -> usize {
    nusense_daemon::record::read_recording(path)
        .map(|r| r.frames().len())
        .unwrap_or(0)
}

#[test]
fn sigkilled_recording_keeps_all_but_its_last_chunk() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("killed.mcap");
    let flush_ms = 200;
    let mut child = Command::new(daemon_common::nusense_binary())
        .args([
            "record",
            path.to_str().unwrap(),
            "--sim",
            "--width",
            "320",
            "--height",
            "240",
            "--fps",
            "15",
        ])
        .args(["--flush-ms", &flush_ms.to_string()])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn nusense record");

    // Wait until several chunks have been closed, then note what a reader sees while the recorder still runs.
    let deadline = Instant::now() + Duration::from_secs(120);
    let mut seen_before_kill = 0;
    while Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(100));
        seen_before_kill = frames_in(&path);
        if seen_before_kill >= 10 {
            break;
        }
        if let Ok(Some(status)) = child.try_wait() {
            panic!("nusense record exited early: {status}");
        }
    }
    assert!(seen_before_kill >= 10, "no frames reached the disk while recording");
    // Let it write into an open chunk, then kill it without warning.
    std::thread::sleep(Duration::from_millis(flush_ms / 2));
    unsafe {
        libc::kill(child.id() as i32, libc::SIGKILL);
    }
    let status = child.wait().unwrap();
    assert!(!status.success());

    let bytes = std::fs::read(&path).unwrap();
    assert!(
        !bytes.ends_with(mcap::MAGIC),
        "a killed recorder never wrote the footer"
    );
    let (records, cut_tail) = top_level_records(&bytes);
    const CHUNK: u8 = 0x06;
    let chunks = records.iter().filter(|(op, _)| *op == CHUNK).count();
    assert!(chunks >= 2, "several chunks were closed: {records:?}");
    // What is lost is at most the chunk being written when the kill came (the recorder's chunk bound, 512 KiB).
    assert!(
        cut_tail <= 512 * 1024 + 64 * 1024,
        "{cut_tail} bytes after the last whole record"
    );

    let recording = nusense_daemon::record::read_recording(&path).expect("tolerant reader");
    assert!(recording.truncated);
    let frames = recording.frames();
    assert!(
        frames.len() >= seen_before_kill,
        "frames on disk before the kill survive it ({} < {seen_before_kill})",
        frames.len()
    );
    // Frames survive in capture order with no holes: everything up to the last whole chunk is there.
    for pair in frames.windows(2) {
        assert_eq!(
            pair[1].frame_id,
            pair[0].frame_id + 1,
            "a frame is missing in the middle"
        );
    }
    for frame in [&frames[0], &frames[frames.len() - 1]] {
        image::load_from_memory(&frame.jpeg).expect("surviving frames decode");
    }
    let readings = recording.on_topic(nusense_daemon::record::READING_TOPIC).count();
    assert!(readings > 0);

    // Replay reads the truncated file back.
    let replay = nusense_daemon::record::McapReplay::open(&path, false).expect("replay opens a killed recording");
    assert!(replay.truncated);
    assert_eq!(replay.len(), frames.len());
}
