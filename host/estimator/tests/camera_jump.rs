//! The camera jumps between two frames (a knock, or frames dropped during a creep) and jumps back, seen by the
//! validation sensor (`nusense_sim::validation`: another lens and pose than the estimator assumes) at 1024x768.
//! Near the border a 4.5 deg roll moves the squares most of a tracking window; a tracker that follows each square
//! from where it was last seen slips onto neighbours there, and keeps the slip: the still camera afterwards then
//! reads as turned by a fraction of a degree, with a phantom contact. And the sensor's glare stays where it is in
//! the image while the pattern turns under it: the squares it moves into or out of the glare change their yellow
//! area, and their centroids, by an amount no motion model predicts, which the contact test must not take for
//! tractions.

use nusense_estimator::detection::FastTracker;
use nusense_estimator::motion::fit_raw_similarity;
use nusense_estimator::{Estimator, Mode, SensorConfig};
use nusense_sim::validation::{CameraMotion, Case, CaseKind, ValidationRenderer};
use nusense_sim::{Contact, Scene};

const SIZE: (u32, u32) = (1024, 768);
/// A square the tracker does not flag follows the camera's rigid motion this closely, px: the squares away from the
/// glare miss it by 0.29 px at most after a 4.5 deg roll (the lens is not a similarity), those near it by 0.59.
const RIGID_MISS_PX: f64 = 0.7;

fn rest_case(name: &str, roll_deg: f64, seed: u64) -> Case {
    Case {
        camera_motion: (roll_deg != 0.0).then_some(CameraMotion {
            rotation_deg: [0.0, 0.0, roll_deg],
            shift_mm: [0.0, 0.0],
        }),
        ..Case::still(name, CaseKind::Rest, SIZE, Scene::rest(), seed)
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
            // Turned or back where the rest frame was taken, nothing touches.
            assert!(
                !reading.is_contact(),
                "{}: phantom contact {:?}",
                case.name,
                reading.test
            );
        }
    }
}

#[test]
fn a_turned_camera_at_rest_is_no_contact() {
    let renderer = ValidationRenderer::new(SIZE).unwrap();
    let reference = renderer.reference(7).unwrap();
    let mut estimator = Estimator::new(SensorConfig::default(), Mode::Inverse, &reference).unwrap();
    let (frame, _) = renderer.render(&rest_case("roll 4.5 at rest", 4.5, 20)).unwrap();
    let reading = estimator.estimate(&frame).unwrap();
    assert!(!reading.is_contact(), "phantom contact {:?}", reading.test);
}

/// The same jumps seen by the tracker alone: every square followed, and each on the camera's rigid motion (a robust
/// similarity of the raw image over the squares) within [`RIGID_MISS_PX`] unless flagged as relit, with at most an
/// eighth of the squares flagged; back home none is. The glare stays fixed in the image while the squares turn under
/// it: while a clipped pixel's yellowness counted rather than its being yellow ink (before the tracker's
/// `yellow_bin`), the squares near the glare missed the motion by 0.7-9.3 px after these rolls (all of them flagged,
/// 8 squares a roll); since, they miss it by 0.07-0.59 px (the others by 0.29 px at most), and 0 or 2 are flagged.
#[test]
fn squares_moved_under_the_glare_follow_the_camera_or_are_flagged() {
    let renderer = ValidationRenderer::new(SIZE).unwrap();
    let reference = renderer.reference(7).unwrap();
    let config = SensorConfig::default();
    let (mut tracker, rest) = FastTracker::from_reference(&reference, config.pad, config.thresholds).unwrap();
    for (k, roll) in [4.5, 0.0, -4.5, 0.0].into_iter().enumerate() {
        let (frame, _) = renderer
            .render(&rest_case(&format!("roll {roll}"), roll, 20 + k as u64))
            .unwrap();
        let detection = tracker.track(&frame).unwrap();
        assert_eq!(
            detection.squares.iter().flatten().count(),
            config.pad.yellow_count(),
            "roll {roll}: every square followed"
        );
        let pairs: Vec<_> = rest
            .squares
            .iter()
            .zip(&detection.squares)
            .filter_map(|(a, b)| Some(((*a)?, (*b)?)))
            .collect();
        let motion = fit_raw_similarity(&pairs).expect("a rigid motion");
        for (slot, ((at_rest, now), relit)) in rest
            .squares
            .iter()
            .zip(&detection.squares)
            .zip(&detection.relit)
            .enumerate()
        {
            let (Some(at_rest), Some(now)) = (at_rest, now) else {
                continue;
            };
            let expected = motion.apply(*at_rest);
            let miss = (now[0] - expected[0]).hypot(now[1] - expected[1]);
            assert!(
                *relit || miss <= RIGID_MISS_PX,
                "roll {roll}: square {slot} at {at_rest:.1?} misses the camera's motion by {miss:.2} px, unflagged"
            );
        }
        let relit = detection.relit.iter().filter(|&&r| r).count();
        if roll == 0.0 {
            assert_eq!(relit, 0, "roll {roll}: back under the rest frame's light");
        } else {
            assert!(
                relit <= config.pad.yellow_count() / 8,
                "roll {roll}: {relit} squares flagged; at most those near the two glare spots should be"
            );
        }
    }
}

/// The camera shifted 2 mm along both axes since the rest frame (a knock): each yellow square then lies nearer the
/// rest frame's next one diagonally (0.6 of a cell along each axis), and choosing the squares' indices by nearness
/// alone numbered the whole lattice one cell off. Every press was read a cell away, 3.4-6.8 mm, and the camera's
/// shift as about (-19, -17) px against the true (26, 27), with nothing else amiss but some 25 fewer corners. The
/// full search sees the pattern from edge to edge, so its indices are the pad's; measured at the fix: the shift
/// within 1.4 px of the image's, presses 0.02-0.12 mm from the truth.
#[test]
fn a_camera_shifted_more_than_half_a_cell_diagonally_keeps_every_square_s_index() {
    let renderer = ValidationRenderer::new(SIZE).unwrap();
    let reference = renderer.reference(7).unwrap();
    for (k, shift_mm) in [[2.0, 2.0], [-2.0, 2.0]].into_iter().enumerate() {
        let motion = CameraMotion {
            rotation_deg: [0.0, 0.0, 0.0],
            shift_mm,
        };
        let case = |name: &str, scene: Scene, seed: u64| Case {
            camera_motion: Some(motion),
            ..Case::still(
                format!("shift {shift_mm:?}: {name}"),
                CaseKind::CameraMotion,
                SIZE,
                scene,
                seed,
            )
        };
        let rest = case("at rest", Scene::rest(), 40 + k as u64);
        let (frame, truth) = renderer.render(&rest).unwrap();
        let mut estimator = Estimator::new(SensorConfig::default(), Mode::Inverse, &reference).unwrap();
        let reading = estimator.estimate(&frame).unwrap();
        let seen = truth.camera_motion.expect("a moved camera").1.shift_px;
        let found = reading.camera_motion.shift_px;
        assert!(
            (found[0] - seen[0]).hypot(found[1] - seen[1]) < 3.0,
            "{}: the camera shifted {found:?} px, the image {seen:?}",
            rest.name
        );
        assert!(
            !reading.is_contact(),
            "{}: phantom contact {:?}",
            rest.name,
            reading.test
        );
        for (j, at) in [[0.0, 0.0], [11.0, -6.5]].into_iter().enumerate() {
            let press = case(
                &format!("3 N at {at:?}"),
                Scene::with_contact(Contact::sphere(5.0, at, 3.0)),
                50 + 2 * k as u64 + j as u64,
            );
            let (frame, _) = renderer.render(&press).unwrap();
            let mut estimator = Estimator::new(SensorConfig::default(), Mode::Inverse, &reference).unwrap();
            let reading = estimator.estimate(&frame).unwrap();
            let contacts = reading.contacts();
            assert_eq!(contacts.len(), 1, "{}: contacts {contacts:?}", press.name);
            let read = contacts[0].centre_mm;
            let off = (read[0] - at[0]).hypot(read[1] - at[1]);
            assert!(off < 0.5, "{}: read at {read:?}, {off:.2} mm off", press.name);
        }
    }
}
