//! Command dispatch over the real framing: handshake, every request, errors for malformed and unknown input,
//! telemetry cadence, actions; property tests that no input makes the board panic or misbehave.

mod common;

use common::Bench;
use nusense_firmware_core::limits::{MAX_CURRENT_MA, MAX_RAMP_MS, MAX_TOTAL_CURRENT_MA, MIN_TELEMETRY_PERIOD_MS};
use nusense_firmware_core::{Action, BoardConfig, ConfigRecord, Controller};
use nusense_protocol::framing::{encode, FrameDecoder, MAX_FRAME_LEN};
use nusense_protocol::{
    Argument, BoardMessage, Channel, DeviceError, Reply, Request, RequestBody, Response, Side, PROTOCOL_VERSION,
    SCHEMA_FINGERPRINT,
};
use proptest::prelude::*;

#[test]
fn handshake_is_required_and_checks_the_version() {
    let mut bench = Bench::new();
    assert_eq!(
        bench.request(RequestBody::GetStatus).result,
        Err(DeviceError::NotHandshaken)
    );
    let set = RequestBody::SetLed {
        channel: Channel::All,
        current_ma: 100,
        enabled: true,
    };
    assert_eq!(bench.request(set.clone()).result, Err(DeviceError::NotHandshaken));
    assert_eq!(
        bench.request(RequestBody::Ping { nonce: 9 }).result,
        Ok(Reply::Pong { nonce: 9 })
    );
    match bench.request(RequestBody::GetInfo).result {
        Ok(Reply::Info(info)) => {
            assert_eq!(info.protocol_version, PROTOCOL_VERSION);
            assert_eq!(info.max_current_ma, MAX_CURRENT_MA);
            assert_eq!(info.channel_count, 4);
            assert_eq!(info.mcu_uid, [7; 12]);
            assert_eq!(info.git_hash.as_str(), "abcdef012345");
        }
        other => panic!("info: {other:?}"),
    }
    let wrong = bench.request(RequestBody::Hello {
        protocol_version: PROTOCOL_VERSION + 1,
    });
    assert_eq!(
        wrong.result,
        Err(DeviceError::VersionMismatch {
            device: PROTOCOL_VERSION,
            host: PROTOCOL_VERSION + 1
        })
    );
    assert_eq!(bench.request(set.clone()).result, Err(DeviceError::NotHandshaken));
    let hello = bench.request(RequestBody::Hello {
        protocol_version: PROTOCOL_VERSION,
    });
    assert_eq!(
        hello.result,
        Ok(Reply::Hello {
            protocol_version: PROTOCOL_VERSION,
            schema: SCHEMA_FINGERPRINT,
        })
    );
    assert_eq!(bench.request(set.clone()).result, Ok(Reply::Ack));

    // A new connection must shake hands again; the LEDs keep their state.
    bench.controller.on_link_reset();
    assert_eq!(
        bench.request(RequestBody::GetStatus).result,
        Err(DeviceError::NotHandshaken)
    );
    assert_eq!(bench.controller.config().enabled, [true; 4]);
}

#[test]
fn arguments_out_of_range_are_refused_by_name() {
    let mut bench = Bench::connected();
    assert_eq!(
        bench.request(RequestBody::SetRamp { ms: MAX_RAMP_MS + 1 }).result,
        Err(DeviceError::BadArgument(Argument::RampMs))
    );
    assert_eq!(
        bench
            .request(RequestBody::StreamTelemetry {
                period_ms: MIN_TELEMETRY_PERIOD_MS - 1
            })
            .result,
        Err(DeviceError::BadArgument(Argument::PeriodMs))
    );
    assert_eq!(bench.request(RequestBody::SetRamp { ms: 300 }).result, Ok(Reply::Ack));
    match bench.request(RequestBody::GetStatus).result {
        Ok(Reply::Status(s)) => assert_eq!(s.ramp_ms, 300),
        other => panic!("{other:?}"),
    }
}

/// A request with a tag this firmware does not know: a frame with a valid CRC whose body is not a RequestBody.
fn unknown_request_frame(seq: u16, tag: u8) -> Vec<u8> {
    #[derive(serde::Serialize)]
    struct Foreign {
        seq: u16,
        tag: u8,
        payload: [u8; 3],
    }
    let mut buf = [0u8; MAX_FRAME_LEN];
    encode(
        &Foreign {
            seq,
            tag,
            payload: [1, 2, 3],
        },
        &mut buf,
    )
    .unwrap()
    .to_vec()
}

#[test]
fn unknown_requests_are_answered_with_an_error_that_carries_their_seq() {
    let mut bench = Bench::connected();
    bench.send_bytes(&unknown_request_frame(0x1234, 200));
    let r = bench.responses.pop().expect("an answer");
    assert_eq!(r.seq, 0x1234);
    assert_eq!(r.result, Err(DeviceError::UnknownRequest));

    // A known request with bytes after it is not guessed at either.
    #[derive(serde::Serialize)]
    struct Padded {
        request: Request,
        extra: u32,
    }
    let mut buf = [0u8; MAX_FRAME_LEN];
    let frame = encode(
        &Padded {
            request: Request {
                seq: 77,
                body: RequestBody::GetStatus,
            },
            extra: 5,
        },
        &mut buf,
    )
    .unwrap();
    bench.send_bytes(frame);
    let r = bench.responses.pop().expect("an answer");
    assert_eq!((r.seq, r.result), (77, Err(DeviceError::UnknownRequest)));

    match bench.request(RequestBody::GetStatus).result {
        Ok(Reply::Status(s)) => assert_eq!(s.counters.unknown_tag, 2),
        other => panic!("{other:?}"),
    }
}

#[test]
fn damaged_frames_are_counted_and_the_link_recovers() {
    let mut bench = Bench::connected();
    let mut buf = [0u8; MAX_FRAME_LEN];
    let good = encode(
        &Request {
            seq: 5,
            body: RequestBody::Ping { nonce: 1 },
        },
        &mut buf,
    )
    .unwrap()
    .to_vec();
    let mut corrupted = good.clone();
    corrupted[3] ^= 0x40;
    bench.send_bytes(&corrupted);
    bench.send_bytes(&[0x55; 600]); // longer than any frame, no delimiter
    bench.send_bytes(&[0x00]);
    assert!(
        bench.responses.is_empty(),
        "nothing to answer: no sequence number survives"
    );
    // Byte by byte, the next good frame is understood.
    for b in &good {
        bench.send_bytes(std::slice::from_ref(b));
    }
    assert_eq!(
        bench.responses.pop().map(|r| r.result),
        Some(Ok(Reply::Pong { nonce: 1 }))
    );
    match bench.request(RequestBody::GetStatus).result {
        Ok(Reply::Status(s)) => {
            assert_eq!(s.counters.bad_crc + s.counters.bad_cobs, 1);
            assert_eq!(s.counters.oversize, 1);
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn telemetry_streams_at_the_requested_period_and_stops() {
    let mut bench = Bench::connected();
    assert_eq!(
        bench.request(RequestBody::StreamTelemetry { period_ms: 20 }).result,
        Ok(Reply::Ack)
    );
    bench.run_ms(1_000);
    let n = bench.telemetry.len();
    assert!((49..=51).contains(&n), "{n} frames in 1 s at 20 ms");
    let gaps: Vec<u64> = bench
        .telemetry
        .windows(2)
        .map(|w| w[1].uptime_us - w[0].uptime_us)
        .collect();
    // The first frame goes out at the first poll after the request, then the cadence is exact.
    assert!(gaps[1..].iter().all(|&g| g == 20_000), "{gaps:?}");
    assert_eq!(
        bench.request(RequestBody::StreamTelemetry { period_ms: 0 }).result,
        Ok(Reply::Ack)
    );
    bench.telemetry.clear();
    bench.run_ms(200);
    assert!(bench.telemetry.is_empty());
}

/// Feeds what the controller wrote for `complete_save_config` through a host decoder.
fn complete_save(bench: &mut Bench, saved: bool) -> Vec<BoardMessage> {
    let mut out = Vec::new();
    bench
        .controller
        .complete_save_config(saved, &mut |f: &[u8]| out.extend_from_slice(f));
    let mut decoder: FrameDecoder = FrameDecoder::new();
    let mut got = Vec::new();
    decoder.feed::<BoardMessage>(&out, |m| got.push(m.unwrap()));
    got
}

fn ack(seq: u16) -> BoardMessage {
    BoardMessage::Response(Response {
        seq,
        result: Ok(Reply::Ack),
    })
}

#[test]
fn save_config_waits_for_the_flash_and_reports_failure() {
    let mut bench = Bench::connected();
    let r = bench.request(RequestBody::SetLed {
        channel: Channel::One(Side::Right),
        current_ma: 80,
        enabled: true,
    });
    assert_eq!(r.result, Ok(Reply::Ack));
    let seq = bench.next_seq();
    bench.send(&Request {
        seq,
        body: RequestBody::SaveConfig { request_id: 11 },
    });
    assert!(bench.responses.is_empty(), "no answer before the flash write");
    let saved = match bench.actions.pop() {
        Some(Action::SaveConfig { config, request_id: 11 }) => config,
        other => panic!("{other:?}"),
    };
    assert_eq!(saved, bench.controller.config());
    assert_eq!(saved.setpoints_ma[1], 80);
    assert!(saved.enabled[1] && !saved.enabled[0]);
    // Another save while one is in flight is refused.
    assert_eq!(
        bench.request(RequestBody::SaveConfig { request_id: 12 }).result,
        Err(DeviceError::Busy)
    );
    assert_eq!(complete_save(&mut bench, true), vec![ack(seq)]);

    let seq = bench.next_seq();
    bench.send(&Request {
        seq,
        body: RequestBody::SaveConfig { request_id: 13 },
    });
    assert!(matches!(
        bench.actions.pop(),
        Some(Action::SaveConfig { request_id: 13, .. })
    ));
    assert_eq!(
        complete_save(&mut bench, false),
        vec![BoardMessage::Response(Response {
            seq,
            result: Err(DeviceError::Storage)
        })]
    );
}

/// The host retries a save whose reply it did not get in time with a new sequence number and the same request
/// id: the board writes once and answers the retry.
#[test]
fn a_retried_save_is_written_once() {
    let mut bench = Bench::connected();
    let first = bench.next_seq();
    bench.send(&Request {
        seq: first,
        body: RequestBody::SaveConfig { request_id: 77 },
    });
    assert_eq!(bench.actions.len(), 1);
    // The retry arrives while the flash is still busy with the first attempt: no second write, and the answer
    // goes to the retry (the host has given up on the first sequence number).
    let retry = bench.next_seq();
    bench.send(&Request {
        seq: retry,
        body: RequestBody::SaveConfig { request_id: 77 },
    });
    assert_eq!(bench.actions.len(), 1, "{:?}", bench.actions);
    assert!(bench.responses.is_empty());
    assert_eq!(complete_save(&mut bench, true), vec![ack(retry)]);
    // A retry after the write completed (its reply was lost) is answered at once, again without a write.
    assert_eq!(
        bench.request(RequestBody::SaveConfig { request_id: 77 }).result,
        Ok(Reply::Ack)
    );
    assert_eq!(bench.actions.len(), 1);
    // A new request id is a new save.
    let seq = bench.next_seq();
    bench.send(&Request {
        seq,
        body: RequestBody::SaveConfig { request_id: 78 },
    });
    assert_eq!(bench.actions.len(), 2);

    // After a reboot the id of the stored record is remembered, so a retry that crosses a reset is not written
    // either.
    let controller = Controller::new(common::identity(), BoardConfig::default()).with_saved_request_id(Some(78));
    let mut bench = Bench::around(controller);
    bench.handshake();
    assert_eq!(
        bench.request(RequestBody::SaveConfig { request_id: 78 }).result,
        Ok(Reply::Ack)
    );
    assert!(bench.actions.is_empty());
}

#[test]
fn a_saved_config_comes_back_at_boot() {
    let record = ConfigRecord {
        config: BoardConfig {
            setpoints_ma: [100, 100, 90, 0],
            enabled: [true, true, true, false],
            ramp_ms: 20,
            ..BoardConfig::default()
        },
        sequence: 3,
        request_id: 9,
    };
    let restored = ConfigRecord::from_bytes(&record.to_bytes()).unwrap();
    let mut bench = Bench::with(restored.config, Default::default());
    bench.run_ms(150);
    let i = bench.true_current_ma();
    assert!(
        (i[2] - 90.0).abs() < 1.8 && (i[0] - 100.0).abs() < 2.0 && i[3] == 0.0,
        "{i:?}"
    );
}

#[test]
fn reset_and_bootloader_are_acked_then_handed_to_the_glue() {
    let mut bench = Bench::connected();
    assert_eq!(bench.request(RequestBody::Reset).result, Ok(Reply::Ack));
    assert_eq!(bench.actions.pop(), Some(Action::Reset));
    assert_eq!(bench.request(RequestBody::EnterBootloader).result, Ok(Reply::Ack));
    assert_eq!(bench.actions.pop(), Some(Action::EnterBootloader));
}

fn any_body() -> impl Strategy<Value = RequestBody> {
    let channel = prop_oneof![Just(Channel::All), (0usize..4).prop_map(|i| Channel::One(Side::ALL[i])),];
    prop_oneof![
        any::<u16>().prop_map(|v| RequestBody::Hello { protocol_version: v }),
        Just(RequestBody::GetInfo),
        Just(RequestBody::GetStatus),
        (channel, any::<u16>(), any::<bool>()).prop_map(|(channel, current_ma, enabled)| {
            RequestBody::SetLed {
                channel,
                current_ma,
                enabled,
            }
        }),
        any::<u16>().prop_map(|ms| RequestBody::SetRamp { ms }),
        any::<u16>().prop_map(|period_ms| RequestBody::StreamTelemetry { period_ms }),
        Just(RequestBody::ClearFaults),
        Just(RequestBody::Ping { nonce: 3 }),
        any::<u16>().prop_map(|total_ma| RequestBody::SetCurrentBudget { total_ma }),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    /// Arbitrary bytes, in arbitrary chunks, interleaved with control steps: no panic, duties always in range,
    /// and the board still answers a good request afterwards.
    #[test]
    fn random_bytes_never_panic_and_the_link_survives(
        chunks in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..300), 0..8)
    ) {
        let mut bench = Bench::connected();
        for chunk in &chunks {
            bench.send_bytes(chunk);
            let duty = bench.step();
            prop_assert!(duty.iter().all(|d| (0.0..=1.0).contains(d)));
        }
        bench.send_bytes(&[0x00]);
        prop_assert_eq!(bench.request(RequestBody::Ping { nonce: 11 }).result, Ok(Reply::Pong { nonce: 11 }));
    }

    /// Any sequence of well-formed requests: each is answered with its own seq, and whatever the host asks, no
    /// setpoint and no current ever exceeds the hard limit, nor the strings together the USB budget.
    #[test]
    fn any_requests_are_answered_and_never_drive_past_the_limit(
        bodies in proptest::collection::vec(any_body(), 1..20)
    ) {
        let mut bench = Bench::connected();
        for body in bodies {
            bench.request(body);
            bench.run_ms(5);
            prop_assert!(bench.controller.config().setpoints_ma.iter().all(|&s| s <= MAX_CURRENT_MA));
            prop_assert!(bench.true_current_ma().iter().all(|&c| c <= f32::from(MAX_CURRENT_MA) * 1.02));
            let total: f32 = bench.true_current_ma().iter().sum();
            prop_assert!(total <= f32::from(MAX_TOTAL_CURRENT_MA) * 1.02, "{} mA in total", total);
        }
    }

    /// Measurements that no ADC would produce (NaN, infinities, negative) never drive a channel past the limit
    /// and never put a NaN on the wire.
    #[test]
    fn hostile_measurements_are_survived(
        samples in proptest::collection::vec(
            (proptest::array::uniform4(any::<f32>()), any::<f32>(), any::<f32>()), 1..50)
    ) {
        let mut bench = Bench::connected();
        bench.request(RequestBody::SetLed { channel: Channel::All, current_ma: 100, enabled: true });
        for (current_ma, supply_mv, temperature_c) in samples {
            bench.now_us += 1_000;
            let m = nusense_firmware_core::Measurements { current_ma, supply_mv, temperature_c };
            let duty = bench.controller.control_step(bench.now_us, &m);
            prop_assert!(duty.iter().all(|d| (0.0..=1.0).contains(d)));
        }
        match bench.request(RequestBody::GetStatus).result {
            Ok(Reply::Status(s)) => {
                prop_assert!(s.temperature_c.is_finite());
                prop_assert!(s.channels.iter().all(|c| c.measured_ma.is_finite() && c.duty.is_finite()));
            }
            other => prop_assert!(false, "{:?}", other),
        }
    }
}
