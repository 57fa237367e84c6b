//! Issue 18's evidence: recordings that every MCAP reader opens after a crash.
//!
//! `nusense record` is killed with SIGKILL at 20 random moments, and a finished recording is cut at 20 random byte
//! offsets. Every result is read by the `mcap` crate's reader (in this process) and by the reference Python reader
//! (another process, from the project's .venv): each must read exactly the messages of the file's whole chunks,
//! in order. `nusense record --recover` must turn each into a finished file whose summary counts those messages
//! and through whose chunk index a seeking reader reads them all.

use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

use mcap::records::{op, Record};
use rand::{Rng, SeedableRng};

use crate::support::{nusense, python_reports, record_command};

const RUNS: usize = 20;
const FLUSH_MS: u64 = 100;
/// The recorder's chunk bound (1 MiB) plus one message: the most a cut can leave after the last whole record.
const MOST_LOST_BYTES: u64 = 1024 * 1024 + 256 * 1024;

/// One message as the file's whole chunks hold it: (channel id, sequence, log time).
type MessageKey = (u16, u32, u64);

/// What a cut file must yield, found without any MCAP reader: walk the top-level records by their length fields,
/// and open each whole chunk record on its own.
struct WholeChunks {
    messages: Vec<MessageKey>,
    chunks: usize,
    /// Bytes after the last whole record.
    tail: u64,
}

fn whole_chunks(bytes: &[u8]) -> WholeChunks {
    let magic_len = mcap::MAGIC.len().min(bytes.len());
    assert_eq!(
        &bytes[..magic_len],
        &mcap::MAGIC[..magic_len],
        "starts with (a prefix of) the MCAP magic"
    );
    let mut messages = Vec::new();
    let mut chunks = 0;
    let mut at = mcap::MAGIC.len().min(bytes.len());
    while at + 9 <= bytes.len() {
        let opcode = bytes[at];
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap());
        if len > (bytes.len() - at - 9) as u64 {
            // The record the cut went through carries its true length: nothing on disk is a placeholder.
            assert!(
                len <= MOST_LOST_BYTES,
                "record 0x{opcode:02x} at {at} claims {len} bytes (a placeholder length reached the disk)"
            );
            break;
        }
        let body = &bytes[at + 9..at + 9 + len as usize];
        if opcode == op::CHUNK {
            let Record::Chunk { header, data } = mcap::parse_record(opcode, body).expect("whole chunk parses") else {
                unreachable!()
            };
            chunks += 1;
            for record in mcap::read::ChunkReader::new(header, &data).expect("chunk opens") {
                if let Record::Message { header, .. } = record.expect("whole chunk's records parse") {
                    messages.push((header.channel_id, header.sequence, header.log_time));
                }
            }
        }
        if opcode == op::FOOTER {
            at += 9 + len as usize;
            break;
        }
        at += 9 + len as usize;
    }
    WholeChunks {
        messages,
        chunks,
        tail: (bytes.len() - at) as u64,
    }
}

/// The messages the `mcap` crate's reader yields (the standard linear reader, the end magic not required).
fn mcap_crate_messages(bytes: &[u8]) -> Vec<MessageKey> {
    if bytes.len() < mcap::MAGIC.len() {
        return Vec::new();
    }
    let options = mcap::read::Options::IgnoreEndMagic.into();
    let Ok(stream) = mcap::MessageStream::new_with_options(bytes, options) else {
        return Vec::new();
    };
    stream
        .map_while(Result::ok)
        .map(|m| (m.channel.id, m.sequence, m.log_time))
        .collect()
}

fn spawn_recorder(path: &Path, extra: &[&str]) -> Child {
    record_command(path, &["--flush-ms", &FLUSH_MS.to_string()])
        .args(extra)
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn nusense record")
}

fn recover(input: &Path) -> PathBuf {
    let output = input.with_extension("recovered.mcap");
    let status = nusense()
        .args(["record", "--recover"])
        .args([input, &output])
        .stdout(Stdio::null())
        .status()
        .expect("run nusense record --recover");
    assert!(status.success(), "--recover {}", input.display());
    output
}

#[test]
fn killed_and_cut_recordings_read_to_their_last_whole_chunk_in_every_reader() {
    let seed: u64 = std::env::var("NUSENSE_CRASH_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| nusense_capture::unix_time_us() ^ u64::from(std::process::id()));
    eprintln!("crash test seed {seed} (NUSENSE_CRASH_SEED={seed} repeats the cut offsets)");
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let dir = tempfile::tempdir().unwrap();
    let mut files = Vec::new();

    // 20 recorders killed at random moments of their recording.
    for run in 0..RUNS {
        let path = dir.path().join(format!("killed-{run:02}.mcap"));
        let mut child = spawn_recorder(&path, &[]);
        // The recording has begun once its schemas and channels are on disk.
        let deadline = Instant::now() + Duration::from_secs(120);
        while std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0) < 1024 {
            assert!(Instant::now() < deadline, "recording {run} never started");
            assert!(child.try_wait().unwrap().is_none(), "nusense record exited early");
            std::thread::sleep(Duration::from_millis(10));
        }
        std::thread::sleep(Duration::from_millis(rng.gen_range(0..2000)));
        unsafe {
            libc::kill(child.id() as i32, libc::SIGKILL);
        }
        assert!(!child.wait().unwrap().success());
        files.push(path);
    }

    // A finished recording cut at 20 random byte offsets.
    let finished = dir.path().join("finished.mcap");
    let status = spawn_recorder(&finished, &["--frames", "45"]).wait().unwrap();
    assert!(status.success());
    let bytes = std::fs::read(&finished).unwrap();
    assert!(bytes.ends_with(mcap::MAGIC));
    let all = whole_chunks(&bytes);
    for run in 0..RUNS {
        let offset = rng.gen_range(0..bytes.len());
        let path = dir.path().join(format!("cut-{run:02}-at-{offset}.mcap"));
        std::fs::write(&path, &bytes[..offset]).unwrap();
        files.push(path);
    }

    let recovered: Vec<PathBuf> = files.iter().map(|f| recover(f)).collect();
    let mut python_files = files.clone();
    python_files.extend(recovered.iter().cloned());
    let reports = python_reports(&python_files, false);

    eprintln!(
        "{:<28} {:>9} {:>6} {:>7} {:>9} {:>7} {:>10}",
        "file", "bytes", "chunks", "in whole", "mcap-rs", "python", "recovered"
    );
    let mut totals = (0usize, 0usize, 0usize, 0u64);
    for (file, recovered) in files.iter().zip(&recovered) {
        let bytes = std::fs::read(file).unwrap();
        let expected = whole_chunks(&bytes);
        let name = file.file_name().unwrap().to_string_lossy().to_string();
        // At most the chunk being written is lost.
        assert!(
            expected.tail <= MOST_LOST_BYTES,
            "{name}: {} bytes after the last whole record",
            expected.tail
        );

        // The mcap crate streams a chunk's records as it decompresses them, so from a chunk the cut went through it
        // may also read the messages that arrived whole: genuine ones, in order, as in the finished file.
        let rust = mcap_crate_messages(&bytes);
        assert_eq!(
            &rust[..expected.messages.len().min(rust.len())],
            &expected.messages[..],
            "{name}: the mcap crate reads every whole chunk's message, in order"
        );
        if name.starts_with("cut-") {
            assert_eq!(
                &all.messages[..rust.len()],
                &rust[..],
                "{name}: and only messages the file really holds"
            );
        }

        let report = &reports[file];
        let python_count = report["messages"].as_u64().unwrap() as usize;
        assert_eq!(
            python_count,
            expected.messages.len(),
            "{name}: the Python reader reads every whole chunk's message: {report}"
        );
        assert_eq!(
            report["last_log_time"].as_u64(),
            expected.messages.last().map(|m| m.2),
            "{name}: and the same last one"
        );

        // The recovered file: a summary that counts them, an index a seeking reader uses, the same messages.
        let recovered_bytes = std::fs::read(recovered).unwrap();
        let summary = mcap::Summary::read(&recovered_bytes)
            .expect("recovered summary reads")
            .expect("recovered file has a summary");
        let stats = summary.stats.as_ref().expect("statistics");
        assert_eq!(
            stats.message_count as usize,
            expected.messages.len(),
            "{name}: recovered statistics"
        );
        assert_eq!(
            summary.chunk_indexes.is_empty(),
            expected.messages.is_empty(),
            "{name}: chunk index"
        );
        let keys = |messages: &[MessageKey]| messages.iter().map(|m| (m.1, m.2)).collect::<Vec<_>>();
        let recovered_messages: Vec<_> = mcap::MessageStream::new(&recovered_bytes)
            .unwrap()
            .map(|m| m.expect("recovered file reads whole"))
            .map(|m| (m.sequence, m.log_time))
            .collect();
        assert_eq!(
            recovered_messages,
            keys(&expected.messages),
            "{name}: recovered messages"
        );
        let recovered_report = &reports[recovered];
        assert_eq!(
            recovered_report["summary"]["message_count"].as_u64(),
            Some(expected.messages.len() as u64),
            "{name}: Python reads the recovered summary: {recovered_report}"
        );
        assert_eq!(
            recovered_report["indexed_messages"].as_u64(),
            Some(expected.messages.len() as u64),
            "{name}: Python's seeking reader reads every message through the index: {recovered_report}"
        );
        assert!(recovered_report["stopped_by"].is_null(), "{recovered_report}");

        eprintln!(
            "{name:<28} {:>9} {:>6} {:>7} {:>9} {:>7} {:>10}",
            bytes.len(),
            expected.chunks,
            expected.messages.len(),
            rust.len(),
            python_count,
            stats.message_count
        );
        totals.0 += expected.messages.len();
        totals.1 += rust.len();
        totals.2 += python_count;
        totals.3 += stats.message_count;
    }
    eprintln!(
        "{} files; messages in whole chunks {}, read by the mcap crate {}, by Python {}, in the recovered files {}",
        files.len(),
        totals.0,
        totals.1,
        totals.2,
        totals.3
    );
    // Not vacuous: the killed recorders had written frames, and the cuts kept part of the finished file.
    let killed_with_frames = files[..RUNS]
        .iter()
        .filter(|f| reports[*f]["topics"]["/camera/image"].as_u64().unwrap_or(0) > 0)
        .count();
    assert!(
        killed_with_frames >= RUNS / 2,
        "only {killed_with_frames} killed recordings held frames"
    );
    assert!(totals.0 > all.messages.len(), "the files held messages");
}
