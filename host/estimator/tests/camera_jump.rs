//! The camera jumps between two frames (a knock, or frames dropped during a creep) and jumps back, seen by the
//! validation sensor (`nusense_sim::validation`: another lens and pose than the estimator assumes) at 1024x768.
//! Near the border a 4.5 deg roll moves the squares most of a tracking window; a tracker that follows each square
//! from where it was last seen slips onto neighbours there, and keeps the slip: the still camera afterwards then
//! reads as turned by a fraction of a degree, with a phantom contact.

use nusense_estimator::{Estimator, Mode, SensorConfig};
use nusense_sim::validation::{CameraMotion, Case, CaseKind, ValidationRenderer};
use nusense_sim::{Scene, NOMINAL_LED_CURRENT_MA};

const SIZE: (u32, u32) = (1024, 768);

fn rest_case(name: &str, roll_deg: f64, seed: u64) -> Case {
    Case {
        name: name.into(),
        kind: CaseKind::Rest,
        size: SIZE,
        scene: Scene::rest(),
        camera_motion: (roll_deg != 0.0).then_some(CameraMotion {
            rotation_deg: [0.0, 0.0, roll_deg],
            shift_mm: [0.0, 0.0],
        }),
        led_currents_ma: [NOMINAL_LED_CURRENT_MA; 4],
        seed,
    }
}

#[test]
fn a_camera_that_jumps_and_jumps_back_is_followed_both_ways() {
    let renderer = ValidationRenderer::new(SIZE).unwrap();
    let reference = renderer.reference(7).unwrap();
    for mode in [Mode::Fast, Mode::Inverse] {
        let mut estimator = Estimator::new(SensorConfig::default(), mode, &reference).unwrap();
        for (k, roll) in [4.5, 0.0, -4.5, 0.0].into_iter().enumerate() {
            let case = rest_case(&format!("{mode} roll {roll}"), roll, 20 + k as u64);
            let (frame, truth) = renderer.render(&case).unwrap();
            let reading = estimator
                .estimate(&frame)
                .unwrap_or_else(|e| panic!("{}: refused: {e}", case.name));
            let seen = truth.camera_motion.map_or(0.0, |(_, image)| image.rotation_deg);
            let found = reading.camera_motion.rotation_deg;
            assert!(
                (found - seen).abs() <= 0.05,
                "{}: rotation {found:.3} deg, the image turned {seen:.3}",
                case.name
            );
            assert_eq!(
                reading.counts.points_valid, reading.counts.points_expected,
                "{}: every corner followed",
                case.name
            );
            if roll == 0.0 {
                // Back where the rest frame was taken: nothing touches and nothing moved.
                assert!(
                    !reading.is_contact(),
                    "{}: phantom contact {:?}",
                    case.name,
                    reading.test
                );
            }
        }
    }
}

#[test]
#[ignore = "known failure (issue 12): a 4.5 deg roll of the validation sensor at rest leaves a non-rigid field the \
            contact test takes for tractions (statistic 8689 against a threshold of 457); rigid in the raw image, it is \
            not through the plate and gel this sensor renders, which the pad map does not model"]
fn a_turned_camera_at_rest_is_no_contact() {
    let renderer = ValidationRenderer::new(SIZE).unwrap();
    let reference = renderer.reference(7).unwrap();
    let mut estimator = Estimator::new(SensorConfig::default(), Mode::Inverse, &reference).unwrap();
    let (frame, _) = renderer.render(&rest_case("roll 4.5 at rest", 4.5, 20)).unwrap();
    let reading = estimator.estimate(&frame).unwrap();
    assert!(!reading.is_contact(), "phantom contact {:?}", reading.test);
}
