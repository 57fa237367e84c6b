//! The stream decoder on a hostile link: frames split and merged at random, garbage between them, bits flipped.
//! It must never panic, never hand out a message that was not sent, resynchronise at the next 0x00, and count
//! every frame it drops by kind.

mod common;

use common::*;
use nusense_protocol::framing::{FrameDecoder, WireError, MAX_FRAME_LEN};
use nusense_protocol::*;
use proptest::prelude::*;

type Decoded<T> = Vec<Result<T, WireError>>;

/// Feeds `stream` in chunks of the given sizes (cycled), collecting every callback.
fn feed_chunked<T: serde::de::DeserializeOwned, const N: usize>(
    decoder: &mut FrameDecoder<N>,
    stream: &[u8],
    chunk_sizes: &[usize],
) -> Decoded<T> {
    let mut results = Vec::new();
    let mut rest = stream;
    let mut sizes = chunk_sizes.iter().copied().cycle();
    while !rest.is_empty() {
        let size = sizes.next().unwrap_or(rest.len()).clamp(1, rest.len());
        let (chunk, tail) = rest.split_at(size);
        decoder.feed::<T>(chunk, |m| results.push(m));
        rest = tail;
    }
    results
}

fn error_total(c: &LinkCounters) -> u32 {
    c.bad_cobs + c.bad_crc + c.oversize + c.unknown_tag
}

/// The counters agree one-to-one with what the callback reported.
fn assert_counters_match<T>(counters: LinkCounters, results: &Decoded<T>) {
    let count = |kind: WireError| results.iter().filter(|r| matches!(r, Err(e) if *e == kind)).count() as u32;
    assert_eq!(counters.frames_ok, results.iter().filter(|r| r.is_ok()).count() as u32);
    assert_eq!(counters.bad_cobs, count(WireError::BadCobs));
    assert_eq!(counters.bad_crc, count(WireError::BadCrc));
    assert_eq!(counters.oversize, count(WireError::Oversize));
    assert_eq!(counters.unknown_tag, count(WireError::UnknownTag));
}

/// How one frame is damaged on its way.
#[derive(Clone, Debug)]
struct Damage {
    /// Bytes inserted before the frame (may contain 0x00).
    garbage: Vec<u8>,
    /// (byte index modulo frame length, bit) to flip, the delimiter included.
    flips: Vec<(usize, u8)>,
}

fn damage() -> impl Strategy<Value = Damage> {
    let garbage = prop_oneof![
        3 => Just(Vec::new()),
        1 => prop::collection::vec(any::<u8>(), 1..40),
        1 => prop::collection::vec(1u8..=255, 1..300), // no delimiter inside, sometimes oversize
    ];
    let flips = prop_oneof![
        3 => Just(Vec::new()),
        1 => prop::collection::vec((any::<usize>(), 0u8..8), 1..4),
    ];
    (garbage, flips).prop_map(|(garbage, flips)| Damage { garbage, flips })
}

proptest! {
    #![proptest_config(proptest_config(512))]

    /// Only splitting and merging: every frame arrives, in order, whatever the chunk boundaries.
    #[test]
    fn clean_stream_in_any_chunks_yields_every_message(
        messages in prop::collection::vec(board_message(), 1..16),
        chunk_sizes in prop::collection::vec(1usize..300, 1..20),
    ) {
        let stream: Vec<u8> = messages.iter().flat_map(frame).collect();
        let mut decoder: FrameDecoder = FrameDecoder::new();
        let results: Decoded<BoardMessage> = feed_chunked(&mut decoder, &stream, &chunk_sizes);
        let expected: Decoded<BoardMessage> = messages.iter().cloned().map(Ok).collect();
        prop_assert_eq!(&results, &expected);
        prop_assert_eq!(decoder.counters(), LinkCounters { frames_ok: messages.len() as u32, ..LinkCounters::default() });
    }

    /// Garbage and bit flips: no false message, every intact frame that starts right after a 0x00 arrives,
    /// and the counters add up.
    #[test]
    fn damaged_stream_never_yields_a_corrupted_message(
        sent in prop::collection::vec((board_message(), damage()), 1..16),
        chunk_sizes in prop::collection::vec(1usize..200, 1..20),
    ) {
        let mut stream = Vec::new();
        // Indices of frames that are intact and begin right after a delimiter (or at the very start).
        let mut must_arrive = Vec::new();
        for (index, (message, damage)) in sent.iter().enumerate() {
            stream.extend_from_slice(&damage.garbage);
            let original = frame(message);
            let mut bytes = original.clone();
            for &(at, bit) in &damage.flips {
                let at = at % bytes.len();
                bytes[at] ^= 1 << bit;
            }
            let after_delimiter = stream.last().is_none_or(|&b| b == 0);
            if bytes == original && after_delimiter {
                must_arrive.push(index);
            }
            stream.extend_from_slice(&bytes);
        }

        let mut decoder: FrameDecoder = FrameDecoder::new();
        let results: Decoded<BoardMessage> = feed_chunked(&mut decoder, &stream, &chunk_sizes);

        // Every message handed out was sent, in sending order (a subsequence of `sent`).
        let mut next = 0;
        let mut arrived = Vec::new();
        for message in results.iter().filter_map(|r| r.as_ref().ok()) {
            let position = sent[next..].iter().position(|(m, _)| m == message);
            prop_assert!(position.is_some(), "decoder produced a message that was not sent (or out of order): {:?}", message);
            next += position.unwrap();
            arrived.push(next);
            next += 1;
        }
        for index in &must_arrive {
            prop_assert!(arrived.contains(index), "intact frame {} after a delimiter was lost", index);
        }
        assert_counters_match(decoder.counters(), &results);
    }

    /// Any bytes at all, in any chunks, for both directions and for a tiny buffer: no panic, and the
    /// counters still agree with the callbacks.
    #[test]
    fn any_bytes_never_panic(
        bytes in prop::collection::vec(any::<u8>(), 0..2048),
        chunk_sizes in prop::collection::vec(1usize..400, 1..10),
    ) {
        let mut board: FrameDecoder = FrameDecoder::new();
        let results: Decoded<BoardMessage> = feed_chunked(&mut board, &bytes, &chunk_sizes);
        assert_counters_match(board.counters(), &results);

        let mut host: FrameDecoder = FrameDecoder::new();
        let results: Decoded<Request> = feed_chunked(&mut host, &bytes, &chunk_sizes);
        assert_counters_match(host.counters(), &results);

        let mut tiny = FrameDecoder::<3>::new();
        let results: Decoded<Request> = feed_chunked(&mut tiny, &bytes, &chunk_sizes);
        assert_counters_match(tiny.counters(), &results);
        prop_assert_eq!(tiny.counters().frames_ok, 0);
    }
}

fn counters(decoder_bytes: &[u8]) -> (Decoded<Request>, LinkCounters) {
    let mut decoder: FrameDecoder = FrameDecoder::new();
    let mut results = Vec::new();
    decoder.feed::<Request>(decoder_bytes, |m| results.push(m));
    (results, decoder.counters())
}

fn ping(seq: u16) -> Request {
    Request {
        seq,
        body: RequestBody::Ping {
            nonce: u32::from(seq) * 3,
        },
    }
}

/// Builds a frame around an arbitrary payload with a correct CRC.
fn frame_payload(payload: &[u8]) -> Vec<u8> {
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(payload);
    let mut body = payload.to_vec();
    body.extend_from_slice(&crc.to_le_bytes());
    let mut out = vec![0u8; body.len() + body.len() / 254 + 2];
    let n = cobs::encode(&body, &mut out);
    out.truncate(n);
    out.push(0);
    out
}

#[test]
fn each_error_kind_is_counted_and_the_next_frame_still_arrives() {
    let good = frame(&ping(9));

    // bad COBS: the code byte promises 4 bytes, the frame ends after 1.
    let mut stream = vec![0x05, 0x11, 0x00];
    // bad CRC: one payload bit flipped inside an otherwise valid frame.
    let mut corrupted = frame(&ping(1));
    corrupted[2] ^= 0x10;
    stream.extend_from_slice(&corrupted);
    // too short to hold a CRC: COBS-decodes to one byte.
    stream.extend_from_slice(&[0x02, 0x7f, 0x00]);
    // oversize: longer than the buffer before a delimiter.
    stream.extend(std::iter::repeat_n(0x42, MAX_FRAME_LEN + 10));
    stream.push(0);
    // unknown tag: a correct CRC around a request tag this protocol does not have.
    stream.extend_from_slice(&frame_payload(&[0x01, 0x7f]));
    // bytes left over after a complete message.
    let mut trailing = postcard::to_stdvec(&ping(2)).unwrap();
    trailing.push(0x55);
    stream.extend_from_slice(&frame_payload(&trailing));
    // empty frames are idle filler, not errors.
    stream.extend_from_slice(&[0, 0, 0]);
    stream.extend_from_slice(&good);

    let (results, c) = counters(&stream);
    assert_eq!(
        results,
        vec![
            Err(WireError::BadCobs),
            Err(WireError::BadCrc),
            Err(WireError::BadCrc),
            Err(WireError::Oversize),
            Err(WireError::UnknownTag),
            Err(WireError::UnknownTag),
            Ok(ping(9)),
        ]
    );
    assert_eq!(
        c,
        LinkCounters {
            bad_cobs: 1,
            bad_crc: 2,
            oversize: 1,
            unknown_tag: 2,
            frames_ok: 1
        }
    );
}

#[test]
fn oversize_garbage_without_delimiter_is_dropped_across_many_chunks() {
    let mut decoder = FrameDecoder::<16>::new();
    let mut results: Decoded<Request> = Vec::new();
    for _ in 0..100 {
        decoder.feed::<Request>(&[0xAA; 7], |m| results.push(m));
    }
    assert!(results.is_empty(), "nothing is reported before the delimiter");
    decoder.feed::<Request>(&[0], |m| results.push(m));
    decoder.feed::<Request>(&frame(&ping(3)), |m| results.push(m));
    assert_eq!(results, vec![Err(WireError::Oversize), Ok(ping(3))]);
    assert_eq!(
        decoder.counters().oversize,
        1,
        "one oversize frame counts once, however long"
    );
}

#[test]
fn a_frame_of_exactly_the_buffer_size_is_accepted() {
    let frame = frame(&ping(4));
    // 3 payload bytes + 4 CRC bytes + 1 COBS code byte; the delimiter is not stored.
    assert_eq!(frame.len() - 1, 8);
    let mut results: Decoded<Request> = Vec::new();
    let mut fits = FrameDecoder::<8>::new();
    let mut too_small = FrameDecoder::<7>::new();
    fits.feed::<Request>(&frame, |m| results.push(m));
    too_small.feed::<Request>(&frame, |m| results.push(m));
    assert_eq!(results, vec![Ok(ping(4)), Err(WireError::Oversize)]);
}

#[test]
fn clear_drops_a_half_frame_but_keeps_counters() {
    let frame = frame(&ping(5));
    let mut decoder: FrameDecoder = FrameDecoder::new();
    let mut results: Decoded<Request> = Vec::new();
    decoder.feed::<Request>(&frame, |m| results.push(m));
    decoder.feed::<Request>(&frame[..4], |m| results.push(m));
    decoder.clear();
    decoder.feed::<Request>(&frame, |m| results.push(m));
    assert_eq!(results, vec![Ok(ping(5)), Ok(ping(5))]);
    assert_eq!(decoder.counters().frames_ok, 2);
    assert_eq!(error_total(&decoder.counters()), 0);
}

#[test]
fn largest_messages_pass_the_default_decoder() {
    let text = |n: usize| "~".repeat(n);
    let info = DeviceInfo {
        protocol_version: u16::MAX,
        firmware_version: text(VERSION_TEXT_LEN).as_str().try_into().unwrap(),
        git_hash: text(GIT_HASH_LEN).as_str().try_into().unwrap(),
        board_id: text(BOARD_ID_LEN).as_str().try_into().unwrap(),
        mcu_uid: [0xFF; 12],
        channel_count: u8::MAX,
        max_current_ma: u16::MAX,
        max_total_current_ma: u16::MAX,
    };
    let flags = FaultFlags {
        open_string: true,
        over_current: true,
        over_temperature: true,
        under_voltage: true,
    };
    let channel = ChannelState {
        setpoint_ma: u16::MAX,
        measured_ma: f32::MAX,
        duty: 1.0,
        enabled: true,
        faults: flags,
    };
    let counters = LinkCounters {
        bad_cobs: u32::MAX,
        bad_crc: u32::MAX,
        oversize: u32::MAX,
        unknown_tag: u32::MAX,
        frames_ok: u32::MAX,
    };
    let loop_timing = LoopTiming {
        steps: u32::MAX,
        period_mean_us: f32::MAX,
        period_min_us: u32::MAX,
        period_max_us: u32::MAX,
    };
    let status = Status {
        uptime_us: u64::MAX,
        channels: [channel; CHANNEL_COUNT],
        temperature_c: f32::MIN,
        supply_mv: u16::MAX,
        ramp_ms: u16::MAX,
        telemetry_period_ms: u16::MAX,
        counters,
        power: PowerState::Suspended,
        current_budget_ma: u16::MAX,
        loop_timing,
    };
    let messages = vec![
        BoardMessage::Response(Response {
            seq: u16::MAX,
            result: Ok(Reply::Info(info)),
        }),
        BoardMessage::Response(Response {
            seq: u16::MAX,
            result: Ok(Reply::Status(status)),
        }),
        BoardMessage::Telemetry(Telemetry {
            uptime_us: u64::MAX,
            channels: [channel; CHANNEL_COUNT],
            temperature_c: f32::MAX,
            supply_mv: u16::MAX,
            counters,
            loop_timing,
        }),
    ];
    let stream: Vec<u8> = messages.iter().flat_map(frame).collect();
    let longest = messages.iter().map(|m| frame(m).len()).max().unwrap();
    println!("longest frame of the largest messages: {longest} bytes (MAX_FRAME_LEN = {MAX_FRAME_LEN})");
    let mut decoder: FrameDecoder = FrameDecoder::new();
    let results: Decoded<BoardMessage> = feed_chunked(&mut decoder, &stream, &[1]);
    assert_eq!(results, messages.into_iter().map(Ok).collect::<Vec<_>>());
}
