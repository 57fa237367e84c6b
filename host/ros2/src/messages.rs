//! The ROS 2 messages a reading becomes, laid out field for field as the ROS 2 IDL defines them (so that CDR, the
//! DDS wire encoding, of these structs is the ROS type's encoding; golden_tests.rs checks that against another
//! implementation), and the mapping from a reading to them. Hardware-free: no DDS here.
//!
//! Units are ROS's (REP 103): metres, newtons, newton-metres, seconds. Frame: the pad frame of the readings,
//! origin at the pad centre on the pattern layer, x right and y down as the camera sees the pad, z into the pad
//! (away from the camera), which is right-handed like a camera's optical frame.

use std::sync::Arc;

use nusense_daemon::ReadingMessage;
use nusense_estimator::ContactRegion;
use serde::{Serialize, Serializer};

/// `builtin_interfaces/msg/Time`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub(crate) struct Time {
    pub sec: i32,
    pub nanosec: u32,
}

impl Time {
    /// Microseconds since the Unix epoch; `sec` saturates in 2038 as ROS 2's own `int32` does.
    pub(crate) fn from_unix_us(us: u64) -> Self {
        Self {
            sec: i32::try_from(us / 1_000_000).unwrap_or(i32::MAX),
            nanosec: (us % 1_000_000) as u32 * 1000,
        }
    }
}

/// `std_msgs/msg/Header`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub(crate) struct Header {
    pub stamp: Time,
    pub frame_id: String,
}

/// `geometry_msgs/msg/Vector3`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub(crate) struct Vector3 {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

impl Vector3 {
    const ZERO: Self = Self { x: 0.0, y: 0.0, z: 0.0 };
}

/// `geometry_msgs/msg/Wrench`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub(crate) struct Wrench {
    pub force: Vector3,
    pub torque: Vector3,
}

/// `geometry_msgs/msg/WrenchStamped`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub(crate) struct WrenchStamped {
    pub header: Header,
    pub wrench: Wrench,
}

/// A `sequence<uint8>` shared with the frame it came from: the camera's JPEG goes out as it is, not copied into
/// the message.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Octets(pub Arc<Vec<u8>>);

impl Serialize for Octets {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        // CDR writes bytes as a sequence<octet>: a u32 length and the bytes.
        serializer.serialize_bytes(&self.0)
    }
}

/// `sensor_msgs/msg/CompressedImage`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub(crate) struct CompressedImage {
    pub header: Header,
    pub format: String,
    pub data: Octets,
}

/// `sensor_msgs/msg/PointField`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub(crate) struct PointField {
    pub name: String,
    pub offset: u32,
    pub datatype: u8,
    pub count: u32,
}

impl PointField {
    /// `sensor_msgs/msg/PointField.FLOAT32`.
    const FLOAT32: u8 = 7;
}

/// `sensor_msgs/msg/PointCloud2`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub(crate) struct PointCloud2 {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    pub fields: Vec<PointField>,
    pub is_bigendian: bool,
    pub point_step: u32,
    pub row_step: u32,
    pub data: Octets,
    pub is_dense: bool,
}

/// The contacts cloud's fields, float32 each, in this order: centre (m), force on the pad (N), moment about the
/// pad normal through the centre (N m), loaded area (m^2). NaN where the estimator's mode does not measure it.
pub(crate) const CONTACT_FIELDS: [&str; 8] = ["x", "y", "z", "fx", "fy", "fz", "tz", "area"];

const MM: f64 = 1e-3;
const MM2: f64 = 1e-6;

/// The frame every message of one sensor is stamped with.
pub(crate) fn frame_id(sensor: &str) -> String {
    format!("nusense_{sensor}_pad")
}

/// The header of a frame captured at `capture_time_us`.
pub(crate) fn header(capture_time_us: u64, frame_id: &str) -> Header {
    Header {
        stamp: Time::from_unix_us(capture_time_us),
        frame_id: frame_id.to_owned(),
    }
}

/// The force the pad carries and its moment about the pad frame's origin; `None` when the frame could not be
/// measured (no estimate: nothing is published rather than a made-up zero).
///
/// Without contact the wrench is zero (nothing above the detection floor). With the traction inverse
/// (`--mode inverse`) every component is measured: the moment is that of the force acting at the centre of
/// pressure plus the measured twist about the normal there. Modes without it measure only the normal force:
/// fx, fy and the twist are NaN (not measured), the moment's x and y come from the contact's centre.
pub(crate) fn wrench(reading: &ReadingMessage, frame_id: &str) -> Option<WrenchStamped> {
    let estimate = reading.estimate.as_ref()?;
    let header = header(reading.capture_time_us, frame_id);
    let Some(touch) = &estimate.touch else {
        return Some(WrenchStamped {
            header,
            wrench: Wrench {
                force: Vector3::ZERO,
                torque: Vector3::ZERO,
            },
        });
    };
    let [fx, fy, fz] = touch.force_vector_n.unwrap_or([f64::NAN, f64::NAN, touch.force_n]);
    let centre = centre_of_pressure_m(touch.contacts());
    let twist = touch
        .torque_nmm
        .map_or(if touch.force_vector_n.is_some() { 0.0 } else { f64::NAN }, |t| t * MM);
    Some(WrenchStamped {
        header,
        wrench: Wrench {
            force: Vector3 { x: fx, y: fy, z: fz },
            // r x F with r = (cx, cy, 0) on the pad surface, plus the twist about the normal.
            torque: Vector3 {
                x: centre[1] * fz,
                y: -centre[0] * fz,
                z: centre[0] * fy - centre[1] * fx + twist,
            },
        },
    })
}

/// The normal-force-weighted mean of the contacts' centres, m: the estimator's centre of pressure.
fn centre_of_pressure_m<'a>(contacts: impl Iterator<Item = &'a ContactRegion>) -> [f64; 2] {
    let (mut weight, mut x, mut y) = (0.0, 0.0, 0.0);
    for contact in contacts {
        weight += contact.force_n;
        x += contact.force_n * contact.centre_mm[0];
        y += contact.force_n * contact.centre_mm[1];
    }
    if weight > 0.0 {
        [x / weight * MM, y / weight * MM]
    } else {
        [0.0, 0.0]
    }
}

/// The camera's JPEG as it came, stamped with its capture time.
pub(crate) fn compressed_image(jpeg: Arc<Vec<u8>>, capture_time_us: u64, frame_id: &str) -> CompressedImage {
    CompressedImage {
        header: header(capture_time_us, frame_id),
        format: "jpeg".to_owned(),
        data: Octets(jpeg),
    }
}

/// Every contact of the reading, strongest first, as one point each; an empty cloud without contact (so that a
/// subscriber sees the contact end), `None` when the frame could not be measured.
pub(crate) fn contacts(reading: &ReadingMessage, frame_id: &str) -> Option<PointCloud2> {
    let estimate = reading.estimate.as_ref()?;
    Some(contact_cloud(
        estimate.touch.iter().flat_map(|touch| touch.contacts()),
        header(reading.capture_time_us, frame_id),
    ))
}

fn contact_cloud<'a>(contacts: impl Iterator<Item = &'a ContactRegion>, header: Header) -> PointCloud2 {
    let point_step = 4 * CONTACT_FIELDS.len() as u32;
    let mut data = Vec::new();
    let mut width = 0;
    for contact in contacts {
        let [fx, fy, fz] = contact.force_vector_n.unwrap_or([f64::NAN, f64::NAN, contact.force_n]);
        let point = [
            contact.centre_mm[0] * MM,
            contact.centre_mm[1] * MM,
            0.0,
            fx,
            fy,
            fz,
            contact.torque_nmm.map_or(f64::NAN, |t| t * MM),
            contact.area_mm2.map_or(f64::NAN, |a| a * MM2),
        ];
        // PointCloud2's float32 fields: the precision ROS tools (RViz, PCL) expect.
        data.extend(point.iter().flat_map(|&v| (v as f32).to_le_bytes()));
        width += 1;
    }
    let is_dense = data
        .chunks_exact(4)
        .all(|v| f32::from_le_bytes([v[0], v[1], v[2], v[3]]).is_finite());
    PointCloud2 {
        header,
        height: 1,
        width,
        fields: CONTACT_FIELDS
            .iter()
            .zip(0..)
            .map(|(name, i)| PointField {
                name: (*name).to_owned(),
                offset: 4 * i,
                datatype: PointField::FLOAT32,
                count: 1,
            })
            .collect(),
        is_bigendian: false,
        point_step,
        row_step: point_step * width,
        data: Octets(Arc::new(data)),
        is_dense,
    }
}

#[cfg(test)]
#[path = "messages/golden_tests.rs"]
mod golden_tests;

#[cfg(test)]
#[path = "messages/mapping_tests.rs"]
mod mapping_tests;
