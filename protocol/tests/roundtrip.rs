//! Every message, over all its fields, survives postcard and the full framing unchanged.

mod common;

use common::*;
use nusense_protocol::framing::{self, FrameDecoder, MAX_FRAME_LEN, MAX_PAYLOAD_LEN};
use nusense_protocol::*;
use postcard::experimental::max_size::MaxSize;
use proptest::prelude::*;
use serde::{de::DeserializeOwned, Serialize};
use std::fmt::Debug;

/// postcard alone, then the frame through a fresh stream decoder fed in one piece.
fn assert_round_trip<T>(message: &T) -> Result<(), TestCaseError>
where
    T: Serialize + DeserializeOwned + PartialEq + Debug + Clone + MaxSize,
{
    let payload = postcard::to_stdvec(message).unwrap();
    prop_assert!(
        payload.len() <= T::POSTCARD_MAX_SIZE,
        "{} > bound {}",
        payload.len(),
        T::POSTCARD_MAX_SIZE
    );
    prop_assert!(payload.len() <= MAX_PAYLOAD_LEN);
    prop_assert_eq!(&postcard::from_bytes::<T>(&payload).unwrap(), message);

    let frame = frame(message);
    prop_assert!(frame.len() <= MAX_FRAME_LEN);
    prop_assert_eq!(
        frame.iter().position(|&b| b == 0),
        Some(frame.len() - 1),
        "0x00 only as the delimiter"
    );

    let mut body = frame[..frame.len() - 1].to_vec();
    prop_assert_eq!(&framing::decode_frame::<T>(&mut body).unwrap(), message);

    let mut decoder: FrameDecoder = FrameDecoder::new();
    let mut decoded = Vec::new();
    decoder.feed::<T>(&frame, |m| decoded.push(m));
    prop_assert_eq!(decoded, vec![Ok(message.clone())]);
    prop_assert_eq!(
        decoder.counters(),
        LinkCounters {
            frames_ok: 1,
            ..LinkCounters::default()
        }
    );
    Ok(())
}

proptest! {
    #![proptest_config(proptest_config(512))]

    #[test]
    fn request_round_trips(message in request()) {
        assert_round_trip(&message)?;
    }

    #[test]
    fn board_message_round_trips(message in board_message()) {
        assert_round_trip(&message)?;
    }

    #[test]
    fn response_round_trips(message in response()) {
        assert_round_trip(&message)?;
    }

    #[test]
    fn telemetry_round_trips(message in telemetry()) {
        assert_round_trip(&message)?;
    }

    #[test]
    fn status_round_trips(message in status()) {
        assert_round_trip(&message)?;
    }

    #[test]
    fn device_info_round_trips(message in device_info()) {
        assert_round_trip(&message)?;
    }

    #[test]
    fn device_error_round_trips(message in device_error()) {
        assert_round_trip(&message)?;
    }

    /// NaN is excluded from the equality tests above; its bits must still travel unchanged.
    #[test]
    fn float_bits_survive_including_nan(bits in any::<u32>(), temperature_bits in any::<u32>()) {
        let mut telemetry = Telemetry::default();
        telemetry.channels[2].measured_ma = f32::from_bits(bits);
        telemetry.temperature_c = f32::from_bits(temperature_bits);
        let mut body = frame(&telemetry);
        body.pop();
        let back: Telemetry = framing::decode_frame(&mut body).unwrap();
        prop_assert_eq!(back.channels[2].measured_ma.to_bits(), bits);
        prop_assert_eq!(back.temperature_c.to_bits(), temperature_bits);
    }

    /// The Display text is what a person sees: it must name both versions and say what to update.
    #[test]
    fn version_mismatch_reads_in_plain_words(device in any::<u16>(), host in any::<u16>()) {
        prop_assume!(device != host);
        let text = DeviceError::VersionMismatch { device, host }.to_string();
        let expected_prefix = format!("board speaks protocol v{device} but this host speaks v{host}");
        prop_assert!(text.starts_with(&expected_prefix), "{}", text);
        let update = if device < host { "update the firmware" } else { "update the host" };
        prop_assert!(text.contains(update), "{}", text);
    }
}

#[test]
fn every_device_error_has_a_sentence() {
    let errors = [
        DeviceError::UnknownRequest,
        DeviceError::BadArgument(Argument::CurrentMa),
        DeviceError::Busy,
        DeviceError::FaultActive { channel: Side::Bottom },
        DeviceError::VersionMismatch { device: 2, host: 1 },
        DeviceError::Storage,
        DeviceError::NotHandshaken,
    ];
    for error in errors {
        let text = error.to_string();
        assert!(text.len() > 20 && !text.contains("Debug"), "{error:?}: {text}");
    }
    assert_eq!(
        DeviceError::VersionMismatch { device: 2, host: 1 }.to_string(),
        "board speaks protocol v2 but this host speaks v1: update the host so that both speak the same version"
    );
    assert!(DeviceError::FaultActive { channel: Side::Bottom }
        .to_string()
        .contains("bottom"));
    assert!(DeviceError::BadArgument(Argument::RampMs)
        .to_string()
        .contains("ramp time"));
}

#[test]
fn frame_size_bounds_are_reported() {
    // Printed so that CI logs and the README keep the real numbers in view.
    println!(
        "MAX_PAYLOAD_LEN = {MAX_PAYLOAD_LEN}, MAX_FRAME_LEN = {MAX_FRAME_LEN} \
         (Request <= {}, BoardMessage <= {}, DeviceInfo <= {}, Status <= {}, Telemetry <= {})",
        Request::POSTCARD_MAX_SIZE,
        BoardMessage::POSTCARD_MAX_SIZE,
        DeviceInfo::POSTCARD_MAX_SIZE,
        Status::POSTCARD_MAX_SIZE,
        Telemetry::POSTCARD_MAX_SIZE
    );
    assert_eq!(
        MAX_PAYLOAD_LEN,
        Request::POSTCARD_MAX_SIZE.max(BoardMessage::POSTCARD_MAX_SIZE)
    );
    assert_eq!(MAX_FRAME_LEN, framing::max_frame_len(MAX_PAYLOAD_LEN));
}
