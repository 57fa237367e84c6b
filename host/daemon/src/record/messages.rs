//! What each channel holds and how its messages are encoded: the one place that knows, shared by the recorder
//! (MCAP) and the live Foxglove server. Images, calibration and annotations use the Foxglove SDK's own typed
//! schemas (protobuf); the reading and the board telemetry are nusense's JSON messages with their JSON Schemas.

use std::sync::Arc;

use foxglove::messages::{
    points_annotation, CameraCalibration, CircleAnnotation, Color, CompressedImage, ImageAnnotations, Point2,
    PointsAnnotation, TextAnnotation, Timestamp,
};
use foxglove::{Encode, Schema};
use nusense_estimator::SensorConfig;

use super::{ANNOTATIONS_TOPIC, CALIBRATION_TOPIC, FRAME_TOPIC, READING_TOPIC, TELEMETRY_TOPIC};
use crate::pipeline::PublishedReading;

/// The optical frame every image-space message refers to.
pub(crate) const CAMERA_FRAME_ID: &str = "camera";
/// Shear vectors are drawn this many times their length, so that a tenth of a pixel shows.
pub const SHEAR_DRAW_GAIN: f64 = 10.0;

/// The channels, in the order they are registered; indexes into [`channel_table`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Kind {
    Frame = 0,
    Calibration = 1,
    Annotations = 2,
    Reading = 3,
    Telemetry = 4,
}

pub(crate) struct ChannelSpec {
    pub(crate) topic: &'static str,
    pub(crate) schema: Schema,
    pub(crate) message_encoding: String,
}

fn typed<T: Encode>(topic: &'static str) -> ChannelSpec {
    ChannelSpec {
        topic,
        schema: T::get_schema().expect("the SDK's message types carry their schema"),
        message_encoding: T::get_message_encoding(),
    }
}

fn json(topic: &'static str, name: &str, schema: Vec<u8>) -> ChannelSpec {
    ChannelSpec {
        topic,
        schema: Schema::new(name, "jsonschema", schema),
        message_encoding: "json".into(),
    }
}

/// Every channel a recording and the live server carry, in [`Kind`] order (a channel's index is its kind).
pub(crate) fn channel_table() -> Vec<ChannelSpec> {
    vec![
        typed::<CompressedImage>(FRAME_TOPIC),
        typed::<CameraCalibration>(CALIBRATION_TOPIC),
        typed::<ImageAnnotations>(ANNOTATIONS_TOPIC),
        json(
            READING_TOPIC,
            "nusense.Reading",
            crate::reading::reading_schema_json().into_bytes(),
        ),
        json(
            TELEMETRY_TOPIC,
            "nusense.BoardTelemetry",
            TELEMETRY_SCHEMA.as_bytes().to_vec(),
        ),
    ]
}

fn encode<T: Encode>(message: &T) -> Vec<u8> {
    let mut buf = Vec::with_capacity(message.encoded_len().unwrap_or(256));
    // Encoding only fails for want of room, and a Vec grows.
    let _ = message.encode(&mut buf);
    buf
}

fn timestamp(time_us: u64) -> Option<Timestamp> {
    let sec = u32::try_from(time_us / 1_000_000).unwrap_or(u32::MAX);
    Some(Timestamp::new(sec, (time_us % 1_000_000) as u32 * 1000))
}

/// The camera's JPEG, as it came.
pub(crate) fn frame(capture_time_us: u64, jpeg: &[u8]) -> Vec<u8> {
    encode(&CompressedImage {
        timestamp: timestamp(capture_time_us),
        frame_id: CAMERA_FRAME_ID.into(),
        data: foxglove::bytes::Bytes::copy_from_slice(jpeg),
        format: "jpeg".into(),
    })
}

/// The lens for frames of `width x height`: the sensor's fisheye (Kannala-Brandt) model scaled to that size.
pub(crate) fn calibration(time_us: u64, config: &SensorConfig, width: u32, height: u32) -> Vec<u8> {
    let lens = config.camera.scaled_to(width, height);
    encode(&CameraCalibration {
        timestamp: timestamp(time_us),
        frame_id: CAMERA_FRAME_ID.into(),
        width,
        height,
        distortion_model: "kannala_brandt".into(),
        d: lens.distortion.to_vec(),
        k: vec![lens.fx, 0.0, lens.cx, 0.0, lens.fy, lens.cy, 0.0, 0.0, 1.0],
        r: vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p: vec![
            lens.fx, 0.0, lens.cx, 0.0, 0.0, lens.fy, lens.cy, 0.0, 0.0, 0.0, 1.0, 0.0,
        ],
    })
}

fn color(r: f64, g: f64, b: f64) -> Option<Color> {
    Some(Color { r, g, b, a: 1.0 })
}

fn point([x, y]: [f64; 2]) -> Point2 {
    Point2 { x, y }
}

/// The reading drawn over its frame, in raw px: the lattice corners found (green, or red where masked as
/// implausible), each corner's shear from the rest frame (yellow, drawn [`SHEAR_DRAW_GAIN`] times its length), and
/// the contact with its force. `None` for a frame without an estimate.
pub(crate) fn annotations(published: &PublishedReading) -> Option<Vec<u8>> {
    let reading = &published.message;
    let estimate = reading.estimate.as_ref()?;
    let stamp = timestamp(reading.capture_time_us);
    let (mut valid, mut masked, mut shear) = (Vec::new(), Vec::new(), Vec::new());
    for corner in &estimate.shear_field {
        let Some(current) = corner.current_px else { continue };
        if corner.valid {
            valid.push(point(current));
        } else {
            masked.push(point(current));
        }
        if let (true, Some(reference)) = (corner.valid, corner.reference_px) {
            shear.push(point(reference));
            shear.push(point([
                reference[0] + SHEAR_DRAW_GAIN * (current[0] - reference[0]),
                reference[1] + SHEAR_DRAW_GAIN * (current[1] - reference[1]),
            ]));
        }
    }
    let points =
        |kind: points_annotation::Type, points: Vec<Point2>, outline: Option<Color>, thickness: f64| PointsAnnotation {
            timestamp: stamp,
            r#type: kind as i32,
            points,
            outline_color: outline,
            thickness,
            ..Default::default()
        };
    let mut message = ImageAnnotations {
        timestamp: stamp,
        points: vec![
            points(points_annotation::Type::Points, valid, color(0.1, 0.9, 0.2), 4.0),
            points(points_annotation::Type::Points, masked, color(0.9, 0.1, 0.1), 4.0),
            points(points_annotation::Type::LineList, shear, color(1.0, 0.85, 0.0), 2.0),
        ],
        ..Default::default()
    };
    for region in estimate.contacts() {
        let contact = region.centre_px;
        message.circles.push(CircleAnnotation {
            timestamp: stamp,
            position: Some(point(contact)),
            diameter: 40.0,
            thickness: 3.0,
            outline_color: color(0.1, 0.6, 1.0),
            ..Default::default()
        });
        message.texts.push(TextAnnotation {
            timestamp: stamp,
            position: Some(point([contact[0] + 24.0, contact[1] - 24.0])),
            text: format!("{:.2} N", region.force_n),
            font_size: 18.0,
            text_color: color(1.0, 1.0, 1.0),
            background_color: Some(Color {
                r: 0.0,
                g: 0.0,
                b: 0.0,
                a: 0.6,
            }),
            ..Default::default()
        });
    }
    Some(encode(&message))
}

/// The reading channel's encoding: the daemon's one reading message as the pipeline serialised it; its schema is
/// the one served at `/api/v1/schema` ([`crate::reading::reading_schema_json`]).
pub(crate) fn reading(published: &Arc<PublishedReading>) -> Vec<u8> {
    published.json.as_bytes().to_vec()
}

pub(crate) fn telemetry(json: &str) -> Vec<u8> {
    json.as_bytes().to_vec()
}

const TELEMETRY_SCHEMA: &str = r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "nusense.BoardTelemetry",
  "description": "LED board telemetry as the board reported it: per channel (Top, Right, Bottom, Left) setpoint and measured current in mA, duty, enable and fault flags; temperature in degrees C, supply in mV",
  "type": "object"
}"#;
