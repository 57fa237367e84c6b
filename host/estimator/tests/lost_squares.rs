//! What following the lattice costs when squares are lost and stay lost (ink gone from the pad after the rest frame,
//! or something covering part of it), seen by the validation sensor (`nusense_sim::validation`) at 1024x768.
//!
//! The tracker measures every square again from the lattice's rigid motion when the camera jumped or a square
//! slipped onto a neighbour. A square that is simply gone is neither: it must not make every frame of a damaged pad
//! pay for a second measurement, while a camera jump on that pad must still be followed.

use nusense_estimator::detection::{Detection, FastTracker};
use nusense_estimator::SensorConfig;
use nusense_sim::validation::{CameraMotion, Case, CaseKind, ValidationRenderer};
use nusense_sim::{Damage, Scene};

const SIZE: (u32, u32) = (1024, 768);

fn damaged_case(name: &str, roll_deg: f64, seed: u64) -> Case {
    let scene = Scene {
        damage: vec![Damage::Missing {
            centre_mm: [9.0, -5.0],
            radius_mm: 4.0,
        }],
        ..Scene::rest()
    };
    Case {
        camera_motion: (roll_deg != 0.0).then_some(CameraMotion {
            rotation_deg: [0.0, 0.0, roll_deg],
            shift_mm: [0.0, 0.0],
        }),
        ..Case::still(name, CaseKind::Damaged, SIZE, scene, seed)
    }
}

fn lost_since_reference(reference: &Detection, frame: &Detection) -> usize {
    reference
        .squares
        .iter()
        .zip(&frame.squares)
        .filter(|(r, f)| r.is_some() && f.is_none())
        .count()
}

#[test]
fn squares_lost_on_a_damaged_pad_cost_no_second_measurement_and_a_jump_still_does() {
    let renderer = ValidationRenderer::new(SIZE).unwrap();
    let reference_frame = renderer.reference(7).unwrap();
    let config = SensorConfig::default();
    let (mut tracker, reference) =
        FastTracker::from_reference(&reference_frame, config.pad, config.thresholds).unwrap();
    assert_eq!(
        reference.squares.iter().flatten().count(),
        config.pad.yellow_count(),
        "the intact rest frame shows every square"
    );
    let mut lost_when_still = None;
    for seed in 30..34 {
        let (frame, _) = renderer.render(&damaged_case("still", 0.0, seed)).unwrap();
        let detection = tracker.track(&frame).unwrap();
        let lost = lost_since_reference(&reference, &detection);
        assert!(
            lost > 0,
            "seed {seed}: the missing ink hides squares the rest frame had"
        );
        assert_eq!(
            detection.measurement_passes, 1,
            "seed {seed}: a still camera over a damaged pad ({lost} squares lost) is measured once per frame"
        );
        lost_when_still = Some(lost);
    }
    let (frame, _) = renderer.render(&damaged_case("rolled", 4.5, 40)).unwrap();
    let detection = tracker.track(&frame).unwrap();
    assert_eq!(
        detection.measurement_passes, 2,
        "a 4.5 deg roll of the camera is re-measured from the lattice's rigid motion"
    );
    assert!(!detection.recovered, "a roll within half a cell needs no full search");
    assert_eq!(
        Some(lost_since_reference(&reference, &detection)),
        lost_when_still,
        "after the roll only the squares under the missing ink are missing"
    );
}
