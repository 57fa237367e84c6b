//! proptest strategies over every field of every message, shared by the integration tests.
#![allow(dead_code)]

use nusense_protocol::*;
use proptest::prelude::*;

/// Floats without NaN: NaN != NaN would make equality-based round-trip checks meaningless; NaN bit patterns
/// are covered by the "any bytes" tests instead.
pub fn float() -> impl Strategy<Value = f32> {
    use proptest::num::f32::*;
    POSITIVE | NEGATIVE | NORMAL | SUBNORMAL | ZERO | INFINITE
}

/// Any text of at most `N` bytes (multi-byte characters included).
pub fn text<const N: usize>() -> impl Strategy<Value = heapless::String<N>> {
    prop::collection::vec(any::<char>(), 0..=N).prop_map(|chars| {
        let mut s = heapless::String::<N>::new();
        for c in chars {
            if s.push(c).is_err() {
                break;
            }
        }
        s
    })
}

pub fn side() -> impl Strategy<Value = Side> {
    prop_oneof![Just(Side::Top), Just(Side::Right), Just(Side::Bottom), Just(Side::Left)]
}

pub fn channel() -> impl Strategy<Value = Channel> {
    prop_oneof![side().prop_map(Channel::One), Just(Channel::All)]
}

pub fn request_body() -> impl Strategy<Value = RequestBody> {
    prop_oneof![
        any::<u16>().prop_map(|protocol_version| RequestBody::Hello { protocol_version }),
        Just(RequestBody::GetInfo),
        Just(RequestBody::GetStatus),
        (channel(), any::<u16>(), any::<bool>()).prop_map(|(channel, current_ma, enabled)| {
            RequestBody::SetLed {
                channel,
                current_ma,
                enabled,
            }
        }),
        any::<u16>().prop_map(|ms| RequestBody::SetRamp { ms }),
        any::<u16>().prop_map(|period_ms| RequestBody::StreamTelemetry { period_ms }),
        Just(RequestBody::ClearFaults),
        any::<u32>().prop_map(|request_id| RequestBody::SaveConfig { request_id }),
        any::<u16>().prop_map(|total_ma| RequestBody::SetCurrentBudget { total_ma }),
        Just(RequestBody::Reset),
        Just(RequestBody::EnterBootloader),
        any::<u32>().prop_map(|nonce| RequestBody::Ping { nonce }),
    ]
}

pub fn request() -> impl Strategy<Value = Request> {
    (any::<u16>(), request_body()).prop_map(|(seq, body)| Request { seq, body })
}

pub fn device_info() -> impl Strategy<Value = DeviceInfo> {
    (
        any::<u16>(),
        text::<VERSION_TEXT_LEN>(),
        text::<GIT_HASH_LEN>(),
        text::<BOARD_ID_LEN>(),
        any::<[u8; 12]>(),
        any::<u8>(),
        any::<[u16; 2]>(),
    )
        .prop_map(
            |(
                protocol_version,
                firmware_version,
                git_hash,
                board_id,
                mcu_uid,
                channel_count,
                [max_current_ma, max_total_current_ma],
            )| {
                DeviceInfo {
                    protocol_version,
                    firmware_version,
                    git_hash,
                    board_id,
                    mcu_uid,
                    channel_count,
                    max_current_ma,
                    max_total_current_ma,
                }
            },
        )
}

pub fn fault_flags() -> impl Strategy<Value = FaultFlags> {
    any::<[bool; 4]>().prop_map(
        |[open_string, over_current, over_temperature, under_voltage]| FaultFlags {
            open_string,
            over_current,
            over_temperature,
            under_voltage,
        },
    )
}

pub fn channel_state() -> impl Strategy<Value = ChannelState> {
    (any::<u16>(), float(), float(), any::<bool>(), fault_flags()).prop_map(
        |(setpoint_ma, measured_ma, duty, enabled, faults)| ChannelState {
            setpoint_ma,
            measured_ma,
            duty,
            enabled,
            faults,
        },
    )
}

pub fn channels() -> impl Strategy<Value = [ChannelState; CHANNEL_COUNT]> {
    [channel_state(), channel_state(), channel_state(), channel_state()]
}

pub fn link_counters() -> impl Strategy<Value = LinkCounters> {
    any::<[u32; 5]>().prop_map(|[bad_cobs, bad_crc, oversize, unknown_tag, frames_ok]| LinkCounters {
        bad_cobs,
        bad_crc,
        oversize,
        unknown_tag,
        frames_ok,
    })
}

pub fn power_state() -> impl Strategy<Value = PowerState> {
    prop_oneof![
        Just(PowerState::Unconfigured),
        Just(PowerState::Configured),
        Just(PowerState::Suspended),
    ]
}

pub fn loop_timing() -> impl Strategy<Value = LoopTiming> {
    (any::<u32>(), float(), any::<[u32; 2]>()).prop_map(|(steps, period_mean_us, [period_min_us, period_max_us])| {
        LoopTiming {
            steps,
            period_mean_us,
            period_min_us,
            period_max_us,
        }
    })
}

pub fn status() -> impl Strategy<Value = Status> {
    (
        any::<u64>(),
        channels(),
        float(),
        any::<[u16; 4]>(),
        link_counters(),
        power_state(),
        loop_timing(),
    )
        .prop_map(
            |(
                uptime_us,
                channels,
                temperature_c,
                [supply_mv, ramp_ms, telemetry_period_ms, current_budget_ma],
                counters,
                power,
                loop_timing,
            )| Status {
                uptime_us,
                channels,
                temperature_c,
                supply_mv,
                ramp_ms,
                telemetry_period_ms,
                counters,
                power,
                current_budget_ma,
                loop_timing,
            },
        )
}

pub fn telemetry() -> impl Strategy<Value = Telemetry> {
    (
        any::<u64>(),
        channels(),
        float(),
        any::<u16>(),
        link_counters(),
        loop_timing(),
    )
        .prop_map(
            |(uptime_us, channels, temperature_c, supply_mv, counters, loop_timing)| Telemetry {
                uptime_us,
                channels,
                temperature_c,
                supply_mv,
                counters,
                loop_timing,
            },
        )
}

pub fn argument() -> impl Strategy<Value = Argument> {
    prop_oneof![
        Just(Argument::CurrentMa),
        Just(Argument::RampMs),
        Just(Argument::PeriodMs),
        Just(Argument::Channel),
    ]
}

pub fn device_error() -> impl Strategy<Value = DeviceError> {
    prop_oneof![
        Just(DeviceError::UnknownRequest),
        argument().prop_map(DeviceError::BadArgument),
        Just(DeviceError::Busy),
        side().prop_map(|channel| DeviceError::FaultActive { channel }),
        any::<(u16, u16)>().prop_map(|(device, host)| DeviceError::VersionMismatch { device, host }),
        Just(DeviceError::Storage),
        Just(DeviceError::NotHandshaken),
    ]
}

pub fn reply() -> impl Strategy<Value = Reply> {
    prop_oneof![
        Just(Reply::Ack),
        device_info().prop_map(Reply::Info),
        status().prop_map(Reply::Status),
        any::<u32>().prop_map(|nonce| Reply::Pong { nonce }),
        any::<(u16, u64)>().prop_map(|(protocol_version, schema)| Reply::Hello {
            protocol_version,
            schema
        }),
    ]
}

pub fn response() -> impl Strategy<Value = Response> {
    (
        any::<u16>(),
        prop_oneof![reply().prop_map(Ok), device_error().prop_map(Err)],
    )
        .prop_map(|(seq, result)| Response { seq, result })
}

pub fn board_message() -> impl Strategy<Value = BoardMessage> {
    prop_oneof![
        response().prop_map(BoardMessage::Response),
        telemetry().prop_map(BoardMessage::Telemetry),
    ]
}

/// Name of the variant a message is, down to the innermost enum. The matches are exhaustive on purpose: a new
/// variant does not compile until it has a name here, and then the golden test demands a vector for it.
pub fn request_variant(request: &Request) -> &'static str {
    match request.body {
        RequestBody::Hello { .. } => "request/hello",
        RequestBody::GetInfo => "request/get_info",
        RequestBody::GetStatus => "request/get_status",
        RequestBody::SetLed {
            channel: Channel::One(_),
            ..
        } => "request/set_led/one",
        RequestBody::SetLed {
            channel: Channel::All, ..
        } => "request/set_led/all",
        RequestBody::SetRamp { .. } => "request/set_ramp",
        RequestBody::StreamTelemetry { .. } => "request/stream_telemetry",
        RequestBody::ClearFaults => "request/clear_faults",
        RequestBody::SaveConfig { .. } => "request/save_config",
        RequestBody::Reset => "request/reset",
        RequestBody::EnterBootloader => "request/enter_bootloader",
        RequestBody::Ping { .. } => "request/ping",
        RequestBody::SetCurrentBudget { .. } => "request/set_current_budget",
    }
}

pub fn board_variant(message: &BoardMessage) -> &'static str {
    match message {
        BoardMessage::Telemetry(_) => "board/telemetry",
        BoardMessage::Response(response) => match response.result {
            Ok(Reply::Ack) => "board/reply/ack",
            Ok(Reply::Info(_)) => "board/reply/info",
            Ok(Reply::Status(_)) => "board/reply/status",
            Ok(Reply::Pong { .. }) => "board/reply/pong",
            Ok(Reply::Hello { .. }) => "board/reply/hello",
            Err(DeviceError::UnknownRequest) => "board/error/unknown_request",
            Err(DeviceError::BadArgument(_)) => "board/error/bad_argument",
            Err(DeviceError::Busy) => "board/error/busy",
            Err(DeviceError::FaultActive { .. }) => "board/error/fault_active",
            Err(DeviceError::VersionMismatch { .. }) => "board/error/version_mismatch",
            Err(DeviceError::Storage) => "board/error/storage",
            Err(DeviceError::NotHandshaken) => "board/error/not_handshaken",
        },
    }
}

/// Encodes one message into an owned frame.
pub fn frame<T: serde::Serialize>(message: &T) -> Vec<u8> {
    let mut buf = [0u8; framing::MAX_FRAME_LEN];
    framing::encode(message, &mut buf)
        .expect("every message fits MAX_FRAME_LEN")
        .to_vec()
}

/// proptest settings of these tests: failing cases are kept next to the test files
/// (tests/proptest-regressions/<test>.txt) and replayed first on the next run.
pub fn proptest_config(cases: u32) -> proptest::test_runner::Config {
    proptest::test_runner::Config {
        cases,
        failure_persistence: Some(Box::new(proptest::test_runner::FileFailurePersistence::WithSource(
            "proptest-regressions",
        ))),
        ..proptest::test_runner::Config::default()
    }
}
