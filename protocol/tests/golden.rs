//! Golden vectors: the full framed bytes of one message of every variant, committed in
//! tests/golden/frames.txt. Any change of the wire format (field order, an enum reordered, another CRC or
//! COBS variant) fails here. When the change is intended (and PROTOCOL_VERSION bumped), regenerate with
//!
//!     NUSENSE_BLESS=1 cargo test -p nusense-protocol --test golden
//!
//! and commit the new file with the change.

mod common;

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;

use common::*;
use nusense_protocol::framing::{self, FrameDecoder};
use nusense_protocol::*;
use proptest::prelude::*;

fn golden_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/golden/frames.txt")
}

fn text<const N: usize>(s: &str) -> heapless::String<N> {
    s.try_into().expect("sample text fits")
}

/// One fixed message per variant, with distinctive non-zero values so that a swapped or dropped field shows.
fn request_samples() -> Vec<Request> {
    let bodies = [
        RequestBody::Hello {
            protocol_version: PROTOCOL_VERSION,
        },
        RequestBody::GetInfo,
        RequestBody::GetStatus,
        RequestBody::SetLed {
            channel: Channel::One(Side::Left),
            current_ma: 150,
            enabled: true,
        },
        RequestBody::SetLed {
            channel: Channel::All,
            current_ma: 300,
            enabled: false,
        },
        RequestBody::SetRamp { ms: 250 },
        RequestBody::StreamTelemetry { period_ms: 20 },
        RequestBody::ClearFaults,
        RequestBody::SaveConfig {
            request_id: 0x5AFE_0001,
        },
        RequestBody::Reset,
        RequestBody::EnterBootloader,
        RequestBody::Ping { nonce: 0xC0FF_EE42 },
        RequestBody::SetCurrentBudget { total_ma: 360 },
    ];
    bodies
        .into_iter()
        .zip(1u16..)
        .map(|(body, seq)| Request { seq: seq * 257, body })
        .collect()
}

fn sample_channels() -> [ChannelState; CHANNEL_COUNT] {
    let mut channels = [ChannelState::default(); CHANNEL_COUNT];
    for (i, channel) in channels.iter_mut().enumerate() {
        let i16 = i as u16;
        channel.setpoint_ma = 100 + 25 * i16;
        channel.measured_ma = 99.5 + 25.0 * i as f32;
        channel.duty = 0.125 * (i + 1) as f32;
        channel.enabled = i != 2;
        channel.faults = FaultFlags {
            open_string: i == 1,
            over_current: i == 2,
            over_temperature: i == 3,
            under_voltage: i == 3,
        };
    }
    channels
}

fn sample_counters() -> LinkCounters {
    LinkCounters {
        bad_cobs: 1,
        bad_crc: 2,
        oversize: 3,
        unknown_tag: 4,
        frames_ok: 123_456,
    }
}

fn sample_loop_timing() -> LoopTiming {
    LoopTiming {
        steps: 40,
        period_mean_us: 500.25,
        period_min_us: 488,
        period_max_us: 517,
    }
}

fn board_samples() -> Vec<BoardMessage> {
    let info = DeviceInfo {
        protocol_version: PROTOCOL_VERSION,
        firmware_version: text("0.1.0"),
        git_hash: text("3ce39fa0a1b2"),
        board_id: text("nusense-f411"),
        mcu_uid: [0x30, 0x00, 0x45, 0x00, 0x12, 0x51, 0x33, 0x33, 0x37, 0x38, 0x39, 0x41],
        channel_count: CHANNEL_COUNT as u8,
        max_current_ma: 500,
        max_total_current_ma: 440,
    };
    let status = Status {
        uptime_us: 12_345_678_901,
        channels: sample_channels(),
        temperature_c: 36.75,
        supply_mv: 5012,
        ramp_ms: 250,
        telemetry_period_ms: 20,
        counters: sample_counters(),
        power: PowerState::Suspended,
        current_budget_ma: 400,
        loop_timing: sample_loop_timing(),
    };
    let results = [
        Ok(Reply::Ack),
        Ok(Reply::Info(info)),
        Ok(Reply::Status(status)),
        Ok(Reply::Pong { nonce: 0xC0FF_EE42 }),
        Ok(Reply::Hello {
            protocol_version: PROTOCOL_VERSION,
            // A fixed value, not SCHEMA_FINGERPRINT: the vector must not follow the types it is meant to freeze.
            schema: 0x0123_4567_89AB_CDEF,
        }),
        Err(DeviceError::UnknownRequest),
        Err(DeviceError::BadArgument(Argument::CurrentMa)),
        Err(DeviceError::Busy),
        Err(DeviceError::FaultActive { channel: Side::Right }),
        Err(DeviceError::VersionMismatch { device: 1, host: 2 }),
        Err(DeviceError::Storage),
        Err(DeviceError::NotHandshaken),
    ];
    let mut messages: Vec<BoardMessage> = results
        .into_iter()
        .zip(1u16..)
        .map(|(result, seq)| BoardMessage::Response(Response { seq: seq * 257, result }))
        .collect();
    messages.push(BoardMessage::Telemetry(Telemetry {
        uptime_us: 98_765_432,
        channels: sample_channels(),
        temperature_c: -5.5,
        supply_mv: 4875,
        counters: sample_counters(),
        loop_timing: sample_loop_timing(),
    }));
    messages
}

fn to_hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn from_hex(hex: &str) -> Vec<u8> {
    assert_eq!(hex.len() % 2, 0, "odd hex length");
    (0..hex.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&hex[i..i + 2], 16).expect("hex digit"))
        .collect()
}

/// name -> full frame (hex) of every sample.
fn current_vectors() -> BTreeMap<&'static str, String> {
    let mut vectors = BTreeMap::new();
    for request in request_samples() {
        let previous = vectors.insert(request_variant(&request), to_hex(&frame(&request)));
        assert!(previous.is_none(), "two samples for {}", request_variant(&request));
    }
    for message in board_samples() {
        let previous = vectors.insert(board_variant(&message), to_hex(&frame(&message)));
        assert!(previous.is_none(), "two samples for {}", board_variant(&message));
    }
    vectors.insert(FINGERPRINT_ENTRY, format!("{SCHEMA_FINGERPRINT:016x}"));
    vectors
}

/// The fingerprint is frozen with the frames: a type changed without a bless (and a version bump) fails here.
const FINGERPRINT_ENTRY: &str = "schema/fingerprint";

fn read_golden() -> BTreeMap<String, String> {
    let path = golden_path();
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| {
        panic!(
            "{}: {e}; create it with NUSENSE_BLESS=1 cargo test -p nusense-protocol --test golden",
            path.display()
        )
    });
    text.lines()
        .filter(|line| !line.trim().is_empty() && !line.starts_with('#'))
        .map(|line| {
            let (name, hex) = line.split_once(' ').expect("line is `name hex`");
            (name.to_string(), hex.trim().to_string())
        })
        .collect()
}

#[test]
fn wire_format_matches_golden_vectors() {
    let current = current_vectors();
    if std::env::var_os("NUSENSE_BLESS").is_some_and(|v| v == "1") {
        let mut text = String::from(
            "# Golden frames of nusense-protocol: `variant hex-of-the-full-frame` (COBS body + 0x00).\n\
             # Regenerate only for an intended wire change: NUSENSE_BLESS=1 cargo test -p nusense-protocol --test golden\n",
        );
        for (name, hex) in &current {
            text.push_str(&format!("{name} {hex}\n"));
        }
        std::fs::create_dir_all(golden_path().parent().unwrap()).unwrap();
        std::fs::write(golden_path(), text).unwrap();
        eprintln!("blessed {} vectors into {}", current.len(), golden_path().display());
        return;
    }
    let golden = read_golden();
    let current_names: BTreeSet<&str> = current.keys().copied().collect();
    let golden_names: BTreeSet<&str> = golden.keys().map(String::as_str).collect();
    assert_eq!(current_names, golden_names, "the set of variants changed");
    for (name, hex) in &current {
        assert_eq!(
            hex, &golden[*name],
            "wire format of {name} changed; if intended, bump PROTOCOL_VERSION and bless (see this file's header)"
        );
    }
}

/// The committed bytes decode to the samples: the decoder side of the format is frozen too.
#[test]
fn golden_vectors_decode_to_the_samples() {
    if std::env::var_os("NUSENSE_BLESS").is_some() {
        return;
    }
    let golden = read_golden();
    for request in request_samples() {
        let bytes = from_hex(&golden[request_variant(&request)]);
        let mut decoder: FrameDecoder = FrameDecoder::new();
        let mut got = Vec::new();
        decoder.feed::<Request>(&bytes, |m| got.push(m));
        assert_eq!(got, vec![Ok(request)]);
    }
    for message in board_samples() {
        let mut bytes = from_hex(&golden[board_variant(&message)]);
        assert_eq!(bytes.pop(), Some(framing::DELIMITER));
        assert_eq!(framing::decode_frame::<BoardMessage>(&mut bytes), Ok(message));
    }
}

/// The handshake's bytes as protocol v1 wrote them (its golden file): a v1 host's Hello still decodes, so this
/// board can answer it with a `VersionMismatch` that the v1 host decodes too, and both sides name both versions.
#[test]
fn the_handshake_of_an_older_version_still_decodes() {
    let mut v1_hello = from_hex("0381020501baea2201");
    assert_eq!(
        framing::decode_frame::<Request>(&mut v1_hello),
        Ok(Request {
            seq: 257,
            body: RequestBody::Hello { protocol_version: 1 }
        })
    );
    let mut v1_mismatch = from_hex("010b8a1401040102564687ff");
    assert_eq!(
        framing::decode_frame::<BoardMessage>(&mut v1_mismatch),
        Ok(BoardMessage::Response(Response {
            seq: 2570,
            result: Err(DeviceError::VersionMismatch { device: 1, host: 2 })
        }))
    );
    // And this version's mismatch answer is byte for byte what v1 would send for the same numbers.
    let answer = BoardMessage::Response(Response {
        seq: 2570,
        result: Err(DeviceError::VersionMismatch { device: 1, host: 2 }),
    });
    assert_eq!(to_hex(&frame(&answer)), "010b8a1401040102564687ff00");
}

/// A hand-checked vector, independent of the blessed file: Ping, seq 1, nonce 1.
/// postcard: seq varint 01, tag 0a, nonce varint 01; CRC-32/ISO-HDLC of [01 0a 01] little-endian; COBS; 00.
#[test]
fn ping_frame_is_built_as_documented() {
    let request = Request {
        seq: 1,
        body: RequestBody::Ping { nonce: 1 },
    };
    let payload = postcard::to_stdvec(&request).unwrap();
    assert_eq!(payload, [0x01, 0x0a, 0x01]);
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&payload);
    let mut body = payload.clone();
    body.extend_from_slice(&crc.to_le_bytes());
    assert!(
        !body.contains(&0),
        "this sample has no zero, so COBS is one code byte in front"
    );
    let mut expected = vec![body.len() as u8 + 1];
    expected.extend_from_slice(&body);
    expected.push(0);
    assert_eq!(frame(&request), expected);
}

proptest! {
    #![proptest_config(proptest_config(256))]

    /// Every variant the strategies can produce has a golden vector.
    #[test]
    fn every_variant_has_a_golden_sample(request in request(), message in board_message()) {
        let current = current_vectors();
        prop_assert!(current.contains_key(request_variant(&request)), "{}", request_variant(&request));
        prop_assert!(current.contains_key(board_variant(&message)), "{}", board_variant(&message));
    }
}
