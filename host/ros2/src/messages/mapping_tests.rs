//! Reading -> message mapping: units (mm -> m, N mm -> N m, mm^2 -> m^2), stamps from the capture time, the moment
//! about the pad frame's origin, and what is published for frames without contact or without a measurement.

use nusense_daemon::SCHEMA_VERSION;
use nusense_estimator::{CameraMotion, ContactTest, EdgeReading, GammaReading, LatticeCounts, Mode, Reading, Touch};

use super::*;

const FRAME: &str = "nusense_VB0001_pad";

fn region(centre_mm: [f64; 2], force: [f64; 3], torque_nmm: f64) -> ContactRegion {
    ContactRegion {
        centre_px: [1000.0, 760.0],
        centre_undistorted_px: [995.0, 758.0],
        centre_mm,
        force_n: force[2],
        force_vector_n: Some(force),
        torque_nmm: Some(torque_nmm),
        area_mm2: Some(30.0),
    }
}

fn estimate(mode: Mode, touch: Option<Touch>) -> Reading {
    Reading {
        mode,
        touch,
        test: ContactTest {
            statistic: 900.0,
            threshold: 60.0,
            p_value: 0.0,
            noise_mm: 0.01,
            detection_floor_n: 0.1,
        },
        camera_motion: CameraMotion::NONE,
        gamma: GammaReading {
            gamma: 1.0,
            gamma_uncompensated: 1.0,
            samples_used: 10,
            samples_total: 10,
        },
        force_model_n: 1.95,
        contact_score_mm: 0.3,
        pressure_map: None,
        counts: LatticeCounts {
            points_detected: 165,
            points_expected: 165,
            squares_detected: 96,
            squares_expected: 96,
            points_valid: 165,
            points_implausible: 0,
        },
        recovered: false,
        retared: false,
        retare_count: 0,
        shear_field: vec![],
        elapsed_ms: 1.0,
    }
}

fn message(estimate: Option<Reading>) -> ReadingMessage {
    ReadingMessage {
        schema_version: SCHEMA_VERSION,
        frame_id: 7,
        file: None,
        capture_time_us: 1_700_000_000_250_000,
        processed_time_us: 1_700_000_000_260_000,
        latency_ms: 10.0,
        queue_ms: 0.0,
        reference_frame_id: Some(0),
        error: estimate.is_none().then(|| "no pattern".to_owned()),
        estimate,
        led: None,
    }
}

/// Two contacts with the traction inverse: 3 N at (10, -5) mm and 1 N at (-6, 3) mm, with shear.
fn inverse_touch() -> Touch {
    let strong = region([10.0, -5.0], [0.2, -0.1, 3.0], 0.6);
    let weak = region([-6.0, 3.0], [-0.05, 0.15, 1.0], -0.2);
    Touch {
        strongest: strong,
        others: vec![weak],
        force_n: 4.0,
        force_vector_n: Some([0.15, 0.05, 4.0]),
        // about the centre of pressure (6, -3) mm
        torque_nmm: Some(0.9),
        edge: EdgeReading {
            angle_deg: None,
            confidence: 0.0,
        },
    }
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-12 * (1.0 + b.abs())
}

#[test]
fn the_stamp_is_the_capture_time_and_the_frame_is_the_sensors_pad() {
    let wrench = wrench(&message(Some(estimate(Mode::Inverse, None))), &frame_id("VB0001")).unwrap();
    assert_eq!(wrench.header.frame_id, FRAME);
    assert_eq!(
        wrench.header.stamp,
        Time {
            sec: 1_700_000_000,
            nanosec: 250_000_000
        }
    );
}

#[test]
fn no_contact_is_a_zero_wrench_and_an_empty_cloud() {
    let reading = message(Some(estimate(Mode::Fast, None)));
    let wrench = wrench(&reading, FRAME).unwrap();
    assert_eq!(wrench.wrench.force, Vector3::ZERO);
    assert_eq!(wrench.wrench.torque, Vector3::ZERO);
    let cloud = contacts(&reading, FRAME).unwrap();
    assert_eq!((cloud.width, cloud.row_step, cloud.data.0.len()), (0, 0, 0));
    assert!(cloud.is_dense);
}

#[test]
fn a_frame_without_a_measurement_publishes_nothing() {
    let reading = message(None);
    assert_eq!(wrench(&reading, FRAME), None);
    assert_eq!(contacts(&reading, FRAME), None);
}

#[test]
fn the_inverse_wrench_is_in_newtons_and_newton_metres_about_the_pad_centre() {
    let wrench = wrench(&message(Some(estimate(Mode::Inverse, Some(inverse_touch())))), FRAME).unwrap();
    assert_eq!(
        wrench.wrench.force,
        Vector3 {
            x: 0.15,
            y: 0.05,
            z: 4.0
        }
    );
    // Centre of pressure: (3 * (10, -5) + 1 * (-6, 3)) / 4 = (6, -3) mm = (0.006, -0.003) m.
    let (cx, cy) = (0.006, -0.003);
    let torque = wrench.wrench.torque;
    assert!(close(torque.x, cy * 4.0), "{torque:?}");
    assert!(close(torque.y, -cx * 4.0), "{torque:?}");
    assert!(close(torque.z, cx * 0.05 - cy * 0.15 + 0.0009), "{torque:?}");
}

#[test]
fn the_moment_equals_the_sum_over_contacts_of_r_cross_f_plus_their_twists() {
    // Each contact's own moment about the origin, summed, must equal the total's: a check of the lever arm and of
    // the sign convention that does not restate the formula. With the twist of the total about the centre of
    // pressure chosen consistent with the contacts' (the estimator sums over cells, which these regions stand for).
    let touch = inverse_touch();
    let [fx, fy, _] = touch.force_vector_n.unwrap();
    let (cx, cy) = (6.0, -3.0);
    let twist_about_cop_nmm: f64 = touch
        .contacts()
        .map(|c| {
            let f = c.force_vector_n.unwrap();
            c.torque_nmm.unwrap() + (c.centre_mm[0] - cx) * f[1] - (c.centre_mm[1] - cy) * f[0]
        })
        .sum();
    let touch = Touch {
        torque_nmm: Some(twist_about_cop_nmm),
        force_vector_n: Some([fx, fy, 4.0]),
        ..touch
    };
    let expected_z_nmm: f64 = touch
        .contacts()
        .map(|c| {
            let f = c.force_vector_n.unwrap();
            c.torque_nmm.unwrap() + c.centre_mm[0] * f[1] - c.centre_mm[1] * f[0]
        })
        .sum();
    let expected_x_nmm: f64 = touch.contacts().map(|c| c.centre_mm[1] * c.force_n).sum();
    let expected_y_nmm: f64 = touch.contacts().map(|c| -c.centre_mm[0] * c.force_n).sum();
    let wrench = wrench(&message(Some(estimate(Mode::Inverse, Some(touch)))), FRAME).unwrap();
    let torque = wrench.wrench.torque;
    assert!(
        close(torque.x, expected_x_nmm * 1e-3),
        "{torque:?} vs {expected_x_nmm} N mm"
    );
    assert!(
        close(torque.y, expected_y_nmm * 1e-3),
        "{torque:?} vs {expected_y_nmm} N mm"
    );
    assert!(
        close(torque.z, expected_z_nmm * 1e-3),
        "{torque:?} vs {expected_z_nmm} N mm"
    );
}

#[test]
fn modes_without_the_inverse_publish_the_normal_force_and_nan_for_what_they_do_not_measure() {
    let mut contact = region([10.0, -5.0], [0.0, 0.0, 2.0], 0.0);
    contact.force_vector_n = None;
    contact.torque_nmm = None;
    contact.area_mm2 = None;
    let touch = Touch {
        strongest: contact,
        others: vec![],
        force_n: 2.0,
        force_vector_n: None,
        torque_nmm: None,
        edge: EdgeReading {
            angle_deg: Some(30.0),
            confidence: 0.8,
        },
    };
    let reading = message(Some(estimate(Mode::Fast, Some(touch))));
    let w = wrench(&reading, FRAME).unwrap().wrench;
    assert!(w.force.x.is_nan() && w.force.y.is_nan(), "{w:?}");
    assert_eq!(w.force.z, 2.0);
    // The normal force at (10, -5) mm still has a lever arm: only the twist about z is unknown.
    assert!(
        close(w.torque.x, -0.005 * 2.0) && close(w.torque.y, -0.010 * 2.0),
        "{w:?}"
    );
    assert!(w.torque.z.is_nan(), "{w:?}");

    let cloud = contacts(&reading, FRAME).unwrap();
    assert!(!cloud.is_dense);
    let point: Vec<f32> = cloud
        .data
        .0
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect();
    assert_eq!(point.len(), CONTACT_FIELDS.len());
    assert_eq!(&point[..3], &[0.010, -0.005, 0.0]);
    assert!(point[3].is_nan() && point[4].is_nan() && point[6].is_nan() && point[7].is_nan());
    assert_eq!(point[5], 2.0);
}

#[test]
fn every_contact_is_a_point_in_metres_newtons_and_square_metres_strongest_first() {
    let reading = message(Some(estimate(Mode::Inverse, Some(inverse_touch()))));
    let cloud = contacts(&reading, FRAME).unwrap();
    assert_eq!(
        (cloud.height, cloud.width, cloud.point_step, cloud.row_step),
        (1, 2, 32, 64)
    );
    assert!(cloud.is_dense);
    let names: Vec<&str> = cloud.fields.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(names, CONTACT_FIELDS);
    let offsets: Vec<u32> = cloud.fields.iter().map(|f| f.offset).collect();
    assert_eq!(offsets, [0, 4, 8, 12, 16, 20, 24, 28]);
    let values: Vec<f32> = cloud
        .data
        .0
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect();
    let expected: [[f64; 8]; 2] = [
        [0.010, -0.005, 0.0, 0.2, -0.1, 3.0, 0.0006, 30e-6],
        [-0.006, 0.003, 0.0, -0.05, 0.15, 1.0, -0.0002, 30e-6],
    ];
    for (got, want) in values.chunks_exact(8).zip(expected) {
        for (g, w) in got.iter().zip(want) {
            assert_eq!(*g, w as f32, "{got:?} vs {want:?}");
        }
    }
}

#[test]
fn times_split_into_seconds_and_nanoseconds() {
    assert_eq!(Time::from_unix_us(0), Time { sec: 0, nanosec: 0 });
    assert_eq!(
        Time::from_unix_us(1_999_999),
        Time {
            sec: 1,
            nanosec: 999_999_000
        }
    );
    // Past 2038 the int32 seconds of builtin_interfaces/Time saturate instead of wrapping to 1901.
    assert_eq!(Time::from_unix_us(3_000_000_000_000_000).sec, i32::MAX);
}
