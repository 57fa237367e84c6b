//! The messages' bytes as DDS sends them (the 4-byte CDR encapsulation header, then the CDR body, encoded by the
//! same RustDDS serializer the publishers use) against golden bytes of the real ROS 2 types: ROS 2 Jazzy's
//! message definitions encoded by the pure-Python `rosbags` package (0.11.9), an implementation that shares no
//! code with ours. testdata/generate_golden.py made the files from the same values as below.

use std::sync::Arc;

use ros2_client::dds::rustdds::no_key::SerializerAdapter;
use ros2_client::dds::rustdds::{CDRSerializerAdapter, SerializedPayload};
use serde::Serialize;

use super::*;

/// What a DataWriter puts in a DATA submessage's payload: encapsulation header and CDR body.
fn wire_bytes<M: Serialize>(message: &M) -> Vec<u8> {
    let body = CDRSerializerAdapter::<M>::to_bytes(message).expect("CDR of a plain struct");
    let payload = SerializedPayload::new_from_bytes(CDRSerializerAdapter::<M>::output_encoding(), body);
    ros2_client::dds::rustdds::bytes::Bytes::from(payload).to_vec()
}

fn golden(name: &str) -> Vec<u8> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("testdata")
        .join(name);
    std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn assert_bytes(name: &str, ours: &[u8]) {
    let theirs = golden(name);
    assert!(
        ours == theirs.as_slice(),
        "{name}: our CDR differs from rosbags' (ROS 2 Jazzy)\n ours:   {ours:02x?}\n theirs: {theirs:02x?}"
    );
}

const FRAME_ID: &str = "nusense_VB0001_pad";
const CAPTURE_TIME_US: u64 = 1_795_456_500_123_456;

fn contact(centre_mm: [f64; 2], force_n: f64, vector: Option<[f64; 3]>, torque_nmm: Option<f64>) -> ContactRegion {
    ContactRegion {
        centre_px: [0.0, 0.0],
        centre_undistorted_px: [0.0, 0.0],
        centre_mm,
        force_n,
        force_vector_n: vector,
        torque_nmm,
        area_mm2: vector.map(|_| 30.0),
    }
}

#[test]
fn time_matches_rosbags() {
    assert_bytes("time.cdr", &wire_bytes(&Time::from_unix_us(CAPTURE_TIME_US)));
}

#[test]
fn header_matches_rosbags() {
    assert_bytes("header.cdr", &wire_bytes(&header(CAPTURE_TIME_US, FRAME_ID)));
}

#[test]
fn wrench_stamped_matches_rosbags() {
    let message = WrenchStamped {
        header: header(CAPTURE_TIME_US, FRAME_ID),
        wrench: Wrench {
            force: Vector3 {
                x: 0.25,
                y: -0.5,
                z: 3.75,
            },
            torque: Vector3 {
                x: 0.0375,
                y: 0.01875,
                z: -0.000125,
            },
        },
    };
    assert_bytes("wrench_stamped.cdr", &wire_bytes(&message));
}

#[test]
fn compressed_image_matches_rosbags() {
    let jpeg = Arc::new(vec![0xFF, 0xD8, 0xFF, 0xE0, 0x00, 0xFF, 0xD9]);
    assert_bytes(
        "compressed_image.cdr",
        &wire_bytes(&compressed_image(jpeg, CAPTURE_TIME_US, FRAME_ID)),
    );
}

#[test]
fn contacts_cloud_matches_rosbags() {
    let contacts = [
        contact([12.5, -4.0], 2.5, Some([0.125, -0.25, 2.5]), Some(0.5)),
        contact([-2.0, 7.5], 1.25, None, None),
    ];
    let cloud = contact_cloud(contacts.iter(), header(CAPTURE_TIME_US, FRAME_ID));
    assert_bytes("contacts.cdr", &wire_bytes(&cloud));
}
