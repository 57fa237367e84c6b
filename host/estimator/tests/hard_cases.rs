//! Hard cases for the estimator (the default mode, the traction inverse), on frames made by the simulated sensor
//! (nusense-sim) at a quarter of the real resolution.
//!
//! Every case states what a correct sensor reports: contact or not, where, how much force (after one calibration of
//! the modulus's scale on a single central press, as a user would calibrate), and the camera motion. A refusal
//! (`NoPattern`, `TooFewPoints`) fails the case wherever the frame holds the answer; nothing may panic, and no
//! reading may carry a NaN or an infinity.

use std::sync::OnceLock;

use image::RgbImage;
use nusense_estimator::calibration::{fit_force_line, CalibrationError, CalibrationSample, FitOptions};
use nusense_estimator::surface::{BSplineSurface, ControlNet, SurfaceError};
use nusense_estimator::{EstimateError, Estimator, Mode, Reading, SensorConfig, SurfaceConfig};
use nusense_sim::{Contact, Damage, GroundTruth, Occlusion, Renderer, Scene, SensorModel};

/// A quarter of the real 2048 x 1536 frame: about 20 px per cell, small enough for a quick test.
const WIDTH: u32 = 512;
const HEIGHT: u32 = 384;
const NOMINAL: [f32; 4] = [100.0; 4];
/// Contact location tolerance for a single clear press, pad mm (the cell pitch is 3.3 mm).
const LOCATION_MM: f64 = 1.0;
/// Force tolerance after one calibration, as a fraction of the true force.
const FORCE_FRACTION: f64 = 0.2;

fn model() -> SensorModel {
    SensorModel::real(WIDTH, HEIGHT)
}

fn renderer() -> &'static Renderer {
    static RENDERER: OnceLock<Renderer> = OnceLock::new();
    RENDERER.get_or_init(|| Renderer::new(model()).expect("the real sensor model is valid"))
}

fn render_with(renderer: &Renderer, scene: &Scene, leds: [f32; 4], seed: u64) -> (RgbImage, GroundTruth) {
    renderer.render(scene, leds, seed).expect("the scene is valid")
}

fn render(scene: &Scene, seed: u64) -> (RgbImage, GroundTruth) {
    render_with(renderer(), scene, NOMINAL, seed)
}

fn reference() -> &'static RgbImage {
    static FRAME: OnceLock<RgbImage> = OnceLock::new();
    FRAME.get_or_init(|| render(&Scene::rest(), 1).0)
}

fn estimator() -> Estimator {
    Estimator::new(SensorConfig::default(), Mode::Inverse, reference()).expect("the simulated rest frame is measurable")
}

fn press(position_mm: [f64; 2], force_n: f64) -> Scene {
    Scene::with_contact(Contact::sphere(5.0, position_mm, force_n))
}

/// The one calibration: true / reported force of a 6 N press at the centre (the modulus's scale).
fn force_scale() -> f64 {
    static SCALE: OnceLock<f64> = OnceLock::new();
    *SCALE.get_or_init(|| {
        let (frame, _) = render(&press([0.0, 0.0], 6.0), 100);
        let reading = estimator().estimate(&frame).expect("a central press is measurable");
        6.0 / reading.force_n()
    })
}

fn distance(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// No NaN or infinity anywhere in a reading, and the invariants every reading keeps.
fn assert_sound(reading: &Reading, case: &str) {
    assert!(
        reading.numbers().iter().all(|v| v.is_finite()),
        "{case}: a reading carries a non-finite value: {reading:?}"
    );
    if let Some(angle) = reading.edge_angle_deg() {
        assert!(
            (0.0..180.0).contains(&angle),
            "{case}: edge angle {angle} outside [0, 180)"
        );
    }
    assert!(
        (0.0..=1.0).contains(&reading.edge_confidence()),
        "{case}: edge confidence"
    );
    assert!(
        reading.counts.points_detected <= reading.counts.points_expected,
        "{case}: more points than the lattice has"
    );
    assert!(reading.force_n() >= 0.0, "{case}: negative force");
}

/// A frame holding one press at `truth_mm` of `force_n`: it must be measured, the press found within
/// `location_mm` with its calibrated force within `FORCE_FRACTION`.
fn expect_press(
    estimator: &mut Estimator,
    frame: &RgbImage,
    truth_mm: [f64; 2],
    force_n: f64,
    location_mm: f64,
    case: &str,
) -> Reading {
    let reading = estimator
        .estimate(frame)
        .unwrap_or_else(|e| panic!("{case}: refused a measurable frame: {e}"));
    assert_sound(&reading, case);
    assert!(
        reading.is_contact(),
        "{case}: the press was not detected: {:?}",
        reading.test
    );
    let at = reading.contact_mm().expect("a contact has a location");
    let off = distance(at, truth_mm);
    assert!(
        off <= location_mm,
        "{case}: contact at {at:.2?} mm, truth {truth_mm:?}: {off:.2} mm off"
    );
    let force = reading.force_n() * force_scale();
    assert!(
        (force - force_n).abs() <= FORCE_FRACTION * force_n,
        "{case}: {force:.2} N (calibrated) for a {force_n} N press"
    );
    reading
}

/// A frame without any press: measured, no contact, no force, no edge.
fn expect_rest(estimator: &mut Estimator, frame: &RgbImage, case: &str) -> Reading {
    let reading = estimator
        .estimate(frame)
        .unwrap_or_else(|e| panic!("{case}: refused a measurable frame: {e}"));
    assert_sound(&reading, case);
    assert!(
        !reading.is_contact(),
        "{case}: contact reported without a press: {:?} at {:?}",
        reading.test,
        reading.contact_mm()
    );
    assert_eq!(reading.force_n(), 0.0, "{case}: force without contact");
    assert_eq!(reading.edge_angle_deg(), None, "{case}: an edge without contact");
    reading
}

#[test]
fn rest_frame_with_other_noise_is_no_contact_and_no_motion() {
    let (frame, _) = render(&Scene::rest(), 2);
    let reading = expect_rest(&mut estimator(), &frame, "rest");
    assert_eq!(
        reading.counts.points_detected, reading.counts.points_expected,
        "all corners of a clean rest frame"
    );
    let motion = reading.camera_motion;
    assert!(
        motion.rotation_deg.abs() < 0.02 && motion.shift_px.iter().all(|v| v.abs() < 0.1),
        "{motion:?}"
    );
}

#[test]
fn press_one_cell_from_the_border() {
    // The pad is 53 x 40 mm: this press sits about one cell from the right and bottom borders.
    let truth = [22.0, 15.5];
    let (frame, _) = render(&press(truth, 6.0), 3);
    expect_press(&mut estimator(), &frame, truth, 6.0, LOCATION_MM, "press at the border");
}

#[test]
fn two_presses_are_two_contacts_with_their_own_forces() {
    let (left, right) = ([-12.0, 0.0], [12.0, 0.0]);
    let scene = Scene {
        contacts: vec![Contact::sphere(5.0, left, 4.0), Contact::sphere(5.0, right, 2.5)],
        ..Scene::default()
    };
    let (frame, _) = render(&scene, 4);
    let reading = estimator().estimate(&frame).expect("two presses are measurable");
    assert_sound(&reading, "two presses");
    let contacts = reading.contacts();
    assert_eq!(contacts.len(), 2, "{contacts:?}");
    for (contact, (truth, force)) in contacts.iter().zip([(left, 4.0), (right, 2.5)]) {
        assert!(
            distance(contact.centre_mm, truth) <= LOCATION_MM,
            "{contact:?} vs {truth:?}"
        );
        let calibrated = contact.force_n * force_scale();
        assert!(
            (calibrated - force).abs() <= FORCE_FRACTION * force,
            "{calibrated:.2} N for {force} N"
        );
    }
    assert!((reading.force_n() - contacts.iter().map(|c| c.force_n).sum::<f64>()).abs() < 1e-9);
}

#[test]
fn two_presses_ten_mm_apart_are_both_listed() {
    let (left, right) = ([-5.0, 3.0], [5.0, 3.0]);
    let scene = Scene {
        contacts: vec![Contact::sphere(3.0, left, 3.0), Contact::sphere(3.0, right, 2.0)],
        ..Scene::default()
    };
    let (frame, _) = render(&scene, 14);
    let reading = estimator().estimate(&frame).expect("two presses are measurable");
    let contacts = reading.contacts();
    assert_eq!(contacts.len(), 2, "{contacts:?}");
    for (contact, (truth, force)) in contacts.iter().zip([(left, 3.0), (right, 2.0)]) {
        assert!(
            distance(contact.centre_mm, truth) <= LOCATION_MM,
            "{contact:?} vs {truth:?}"
        );
        let calibrated = contact.force_n * force_scale();
        assert!(
            (calibrated - force).abs() <= FORCE_FRACTION * force,
            "{calibrated:.2} N for {force} N"
        );
    }
}

#[test]
fn pad_torn_before_the_reference_still_measures_the_rest() {
    // The pad was already torn when the reference was taken: those corners are masked, the rest measure.
    let tear = Damage::Missing {
        centre_mm: [10.0, 6.0],
        radius_mm: 4.0,
    };
    let rest = Scene {
        damage: vec![tear.clone()],
        ..Scene::default()
    };
    let (torn_reference, _) = render(&rest, 1);
    let truth = [-10.0, -5.0];
    let (frame, _) = render(
        &Scene {
            damage: vec![tear],
            ..press(truth, 6.0)
        },
        5,
    );
    let mut estimator =
        Estimator::new(SensorConfig::default(), Mode::Inverse, &torn_reference).expect("most of the pad is intact");
    assert!(
        estimator.reference_lattice().corners_found() < 165,
        "the tear hides some corners"
    );
    let reading = expect_press(&mut estimator, &frame, truth, 6.0, LOCATION_MM, "torn pad");
    assert!(
        reading.counts.points_valid < reading.counts.points_expected,
        "torn corners must be masked"
    );
}

#[test]
#[ignore = "known failure: the squares ink lost or smeared after the reference leaves partly inked have their \
            centroids, and so their corners, biased, not masked (with a still camera the tracker flags a square's \
            unexplained area change only where the light on its middle changed, and ink lost at a square's edge leaves \
            its middle as it was): each damage alone reads as a contact far above the test's threshold (missing ink: \
            statistic 39273 against 457, 0.52 N calibrated at (8.3, 5.0) mm; the smear: 23277, 0.47 N at (-11.9, \
            -6.3) mm, measured on 1eb76fe); both together, with the still camera's flags: 55964 at (8.3, 5.0) mm"]
fn ink_lost_after_the_reference_is_not_a_press() {
    let scene = Scene {
        damage: vec![
            Damage::Missing {
                centre_mm: [8.0, 4.0],
                radius_mm: 4.0,
            },
            Damage::Smeared {
                centre_mm: [-12.0, -6.0],
                radius_mm: 5.0,
                smear_mm: 1.5,
            },
        ],
        ..Scene::default()
    };
    let (frame, _) = render(&scene, 6);
    let reading = expect_rest(&mut estimator(), &frame, "torn after the reference");
    assert!(
        reading.counts.points_detected < reading.counts.points_expected,
        "the missing ink hides corners"
    );
}

#[test]
fn leds_at_twenty_percent() {
    let truth = [3.0, -4.0];
    let mut estimator = estimator();
    let (dim_rest, _) = render_with(renderer(), &Scene::rest(), [20.0; 4], 7);
    expect_rest(&mut estimator, &dim_rest, "low light, rest");
    let (dim_press, _) = render_with(renderer(), &press(truth, 6.0), [20.0; 4], 7);
    expect_press(&mut estimator, &dim_press, truth, 6.0, LOCATION_MM, "low light, press");
}

#[test]
fn one_led_side_drifting_is_not_a_press() {
    let mut estimator = estimator();
    for (k, leds) in [
        [100.0, 120.0, 100.0, 100.0],
        [100.0, 100.0, 70.0, 100.0],
        [60.0, 100.0, 100.0, 130.0],
    ]
    .iter()
    .enumerate()
    {
        let (frame, _) = render_with(renderer(), &Scene::rest(), *leds, 20 + k as u64);
        expect_rest(&mut estimator, &frame, &format!("LED drift {leds:?}"));
    }
}

/// One LED side at 150 %, the others nominal (the rest frame's): that side's yellow clips in red and green while
/// its blue still grows, so the squares there pale towards white (the tracker counts such pixels as the yellow they
/// are: see tests/uneven_light.rs), more where the glare adds to the light. Before the tracker flagged such squares
/// on a still camera too, rest frames
/// under this light read as contacts of 0.5-0.8 N on the validation sensor. The light is no press, and a press under
/// it is still found where it is, with its force.
#[test]
fn one_led_side_much_brighter_is_not_a_press_and_a_press_under_it_is_measured() {
    let leds = [100.0, 150.0, 100.0, 100.0];
    let mut estimator = estimator();
    for seed in 30..33 {
        let (frame, _) = render_with(renderer(), &Scene::rest(), leds, seed);
        expect_rest(&mut estimator, &frame, &format!("LEDs {leds:?}, rest, seed {seed}"));
    }
    for (k, truth) in [[6.0, -4.0], [14.0, 6.0]].into_iter().enumerate() {
        let (frame, _) = render_with(renderer(), &press(truth, 6.0), leds, 40 + k as u64);
        expect_press(
            &mut estimator,
            &frame,
            truth,
            6.0,
            LOCATION_MM,
            &format!("LEDs {leds:?}, press at {truth:?}"),
        );
    }
}

#[test]
fn saturated_exposure() {
    // Over-exposed so that the yellow squares clip at 255 in every channel; the red keeps some contrast.
    let bright = Renderer::new(SensorModel {
        exposure: 1.8,
        ..model()
    })
    .unwrap();
    let truth = [-6.0, 5.0];
    let (frame, _) = render_with(&bright, &press(truth, 6.0), NOMINAL, 8);
    let saturated = frame.pixels().filter(|p| p.0.contains(&255)).count();
    assert!(
        saturated * 5 > frame.pixels().len(),
        "the case needs a saturated frame ({saturated} px at 255)"
    );
    expect_press(&mut estimator(), &frame, truth, 6.0, LOCATION_MM, "saturation");
}

#[test]
fn heavy_noise() {
    let noisy = Renderer::new(SensorModel {
        noise_sigma: 25.0,
        ..model()
    })
    .unwrap();
    let mut estimator = estimator();
    let (rest, _) = render_with(&noisy, &Scene::rest(), NOMINAL, 9);
    let reading = expect_rest(&mut estimator, &rest, "heavy noise, rest");
    assert!(
        reading.test.noise_mm > SensorConfig::default().inverse.noise_floor_mm,
        "the noise is measured: {:?}",
        reading.test
    );
    let truth = [5.0, 3.0];
    let (frame, _) = render_with(&noisy, &press(truth, 6.0), NOMINAL, 9);
    expect_press(&mut estimator, &frame, truth, 6.0, 1.5, "heavy noise, press");
}

#[test]
fn jpeg_frames() {
    let jpeg = Renderer::new(SensorModel {
        jpeg_quality: Some(60),
        ..model()
    })
    .unwrap();
    let mut estimator = estimator();
    let (rest, _) = render_with(&jpeg, &Scene::rest(), NOMINAL, 15);
    expect_rest(&mut estimator, &rest, "JPEG q60, rest");
    let truth = [-8.0, 8.0];
    let (frame, _) = render_with(&jpeg, &press(truth, 3.0), NOMINAL, 15);
    expect_press(&mut estimator, &frame, truth, 3.0, LOCATION_MM, "JPEG q60, press");
}

fn moved_camera(degrees: f64, shift_mm: [f64; 2]) -> Renderer {
    let mut moved = model();
    moved.pose.rotation_deg[2] += degrees;
    moved.pose.shift_mm[0] += shift_mm[0];
    moved.pose.shift_mm[1] += shift_mm[1];
    Renderer::new(moved).unwrap()
}

#[test]
fn camera_rotated_and_shifted_is_measured_and_removed() {
    for degrees in [3.0, -5.0] {
        let moved = moved_camera(degrees, [0.8, -0.5]);
        let mut estimator = estimator();
        let case = format!("camera turned {degrees} deg");
        // A rigid motion of the whole pattern is not a press; it is measured.
        let (rest, _) = render_with(&moved, &Scene::rest(), NOMINAL, 10);
        let reading = expect_rest(&mut estimator, &rest, &case);
        let motion = reading.camera_motion;
        assert!((motion.rotation_deg - degrees).abs() <= 0.2, "{case}: {motion:?}");
        assert!(
            motion.shift_px[0].hypot(motion.shift_px[1]) > 2.0,
            "{case}: the shift is seen: {motion:?}"
        );
        // The press through the moved camera is where it is on the pad, with its force.
        let truth = [-4.0, 6.0];
        let (frame, _) = render_with(&moved, &press(truth, 6.0), NOMINAL, 10);
        let reading = expect_press(&mut estimator, &frame, truth, 6.0, LOCATION_MM, &case);
        assert!(
            (reading.camera_motion.rotation_deg - degrees).abs() <= 0.2,
            "{case}: {:?}",
            reading.camera_motion
        );
        // Removed before the shear is measured: the compensated gamma is the unmoved one, the paper's is not.
        let (still, _) = render(&press(truth, 6.0), 10);
        let unmoved = Estimator::new(SensorConfig::default(), Mode::Inverse, reference())
            .unwrap()
            .estimate(&still)
            .unwrap();
        assert!(
            (reading.gamma.gamma / unmoved.gamma.gamma - 1.0).abs() < 0.1,
            "{case}: {:?} vs {:?}",
            reading.gamma,
            unmoved.gamma
        );
        assert!(
            reading.gamma.gamma_uncompensated > 2.0 * unmoved.gamma.gamma,
            "{case}: {:?}",
            reading.gamma
        );
    }
}

#[test]
fn a_camera_that_stays_moved_re_tares_by_itself() {
    let moved = moved_camera(2.0, [0.5, 0.0]);
    let mut estimator = estimator();
    let frames = SensorConfig::default().retare.frames;
    let mut retared_at = None;
    // After the re-tare the rest frames are what they are to an estimator built on the new rest frame: the noise test
    // itself (which every mode's contact rests on, not only the reading's last step) finds nothing. Before
    // the re-tare built its tracker afresh, its statistic was 544-684 against a threshold of 457 on these frames.
    let quiet = |reading: &Reading, case: &str| {
        assert!(
            reading.test.statistic <= reading.test.threshold,
            "{case}: the noise test finds a contact: {:?}",
            reading.test
        );
    };
    for k in 0..frames + 2 {
        let (rest, _) = render_with(&moved, &Scene::rest(), NOMINAL, 30 + u64::from(k));
        let reading = expect_rest(&mut estimator, &rest, "moved camera at rest");
        if reading.retared {
            retared_at.get_or_insert(k);
        }
        if retared_at.is_some_and(|at| k > at) {
            quiet(&reading, "moved camera at rest, re-tared");
        }
    }
    assert_eq!(retared_at, Some(frames - 1), "re-tare after {frames} frames");
    assert_eq!(estimator.retare_count(), 1);
    // After the re-tare the moved camera is the rest position: no motion, and presses measure as before.
    let (rest, _) = render_with(&moved, &Scene::rest(), NOMINAL, 99);
    let reading = expect_rest(&mut estimator, &rest, "after the re-tare");
    quiet(&reading, "after the re-tare");
    assert!(
        reading.camera_motion.rotation_deg.abs() < 0.05,
        "{:?}",
        reading.camera_motion
    );
    let truth = [6.0, -6.0];
    let (frame, _) = render_with(&moved, &press(truth, 5.0), NOMINAL, 98);
    expect_press(
        &mut estimator,
        &frame,
        truth,
        5.0,
        LOCATION_MM,
        "press after the re-tare",
    );
}

#[test]
fn partial_occlusion() {
    let occlusion = Occlusion {
        centre_mm: [-15.0, 8.0],
        radius_mm: 6.0,
        colour: [12, 10, 10],
    };
    let truth = [8.0, -2.0];
    let (frame, _) = render(
        &Scene {
            occlusions: vec![occlusion],
            ..press(truth, 6.0)
        },
        11,
    );
    let reading = expect_press(&mut estimator(), &frame, truth, 6.0, LOCATION_MM, "partial occlusion");
    assert!(
        reading.counts.points_detected < reading.counts.points_expected,
        "occluded corners cannot be found"
    );
}

/// The direction a reading gives its push (degrees, pad frame), and how far it is from `angle_deg` (signed, within
/// +-180).
fn push_direction(reading: &Reading, angle_deg: f64) -> (f64, f64) {
    let v = reading
        .touch
        .as_ref()
        .and_then(|t| t.force_vector_n)
        .expect("the inverse gives a force vector");
    let found = v[1].atan2(v[0]).to_degrees();
    (found, (found - angle_deg + 180.0).rem_euclid(360.0) - 180.0)
}

#[test]
fn a_press_with_a_tangential_push_reports_its_direction() {
    for angle in [0.0f64, 130.0, 250.0] {
        let mut contact = Contact::sphere(5.0, [2.0, 1.0], 5.0);
        let (s, c) = angle.to_radians().sin_cos();
        contact.tangential_force_n = [1.5 * c, 1.5 * s];
        let (frame, _) = render(&Scene::with_contact(contact), 16);
        let reading = expect_press(&mut estimator(), &frame, [2.0, 1.0], 5.0, LOCATION_MM, "shear");
        let (found, off) = push_direction(&reading, angle);
        assert!(off.abs() <= 5.0, "push at {angle} deg read at {found:.1} deg");
    }
}

/// A firm press pushed sideways by 40 % of its load (a grip's friction) moves the whole pad, not only the corners
/// near it: on this sensor's unbounded pad the corners' scatter about the motion alone is 0.12-0.14 mm, 40 times a
/// rest frame's. Taken for noise, it hid the press: no contact at 4 of these 8 angles for the sphere and 4 of 8 for
/// the flat punch. Each is found, as one contact where it is, with its force and the push's direction. The punch's
/// pressure centre reads up to 0.94 mm from its centre (the sphere's 0.51 mm), hence its wider bound.
#[test]
fn a_firm_press_pushed_sideways_is_found_in_every_direction() {
    let truth = [2.0, 1.0];
    for (shape, location_mm) in [("8 mm sphere", LOCATION_MM), ("3 mm flat punch", 1.5)] {
        for angle in [0.0f64, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0] {
            let mut contact = if shape == "8 mm sphere" {
                Contact::sphere(8.0, truth, 10.0)
            } else {
                Contact::flat_punch(3.0, truth, 10.0)
            };
            let (s, c) = angle.to_radians().sin_cos();
            contact.tangential_force_n = [4.0 * c, 4.0 * s];
            let (frame, _) = render(&Scene::with_contact(contact), 40);
            let case = format!("{shape}, 10 N pushed by 4 N at {angle} deg");
            let reading = expect_press(&mut estimator(), &frame, truth, 10.0, location_mm, &case);
            assert_eq!(reading.contacts().len(), 1, "{case}: {:?}", reading.contacts());
            let (found, off) = push_direction(&reading, angle);
            assert!(off.abs() <= 5.0, "{case}: the push read at {found:.1} deg");
        }
    }
}

/// `elastic.tangential_force_scale` (what `nusense calibrate` fits from pushes) multiplies the push's fx, fy and the
/// torque, total and per contact, and leaves the contact, its place and its normal force as they were;
/// `elastic.torque_scale`, when set, multiplies the torque instead.
#[test]
fn the_tangential_and_torque_scales_scale_shear_and_torque_only() {
    let mut contact = Contact::sphere(5.0, [-3.0, 2.0], 5.0);
    contact.tangential_force_n = [1.2, -0.8];
    contact.torsion_nmm = 10.0;
    let (frame, _) = render(&Scene::with_contact(contact), 17);
    let plain = estimator().estimate(&frame).expect("a push is measurable");
    let mut config = SensorConfig::default();
    config.elastic.tangential_force_scale = 0.4;
    let scaled = Estimator::new(config, Mode::Inverse, reference())
        .expect("the simulated rest frame is measurable")
        .estimate(&frame)
        .expect("a push is measurable");
    let (plain, scaled) = (
        plain.touch.expect("a 5 N push is a contact"),
        scaled.touch.expect("the same contact"),
    );
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * (1.0 + a.abs());
    let v = plain.force_vector_n.expect("the inverse gives a force vector");
    let w = scaled.force_vector_n.expect("the inverse gives a force vector");
    assert!(v[0].hypot(v[1]) > 0.5, "the push is measured: {v:?}");
    assert!(
        close(w[0], 0.4 * v[0]) && close(w[1], 0.4 * v[1]) && w[2] == v[2],
        "{v:?} -> {w:?}"
    );
    let (t, u) = (
        plain.torque_nmm.expect("a torque"),
        scaled.torque_nmm.expect("a torque"),
    );
    assert!(t.abs() > 1.0 && close(u, 0.4 * t), "torque {t} -> {u}");
    assert_eq!(plain.force_n, scaled.force_n);
    assert_eq!(plain.others.len(), scaled.others.len());
    for (a, b) in plain.contacts().zip(scaled.contacts()) {
        assert_eq!(
            (a.centre_mm, a.force_n, a.area_mm2),
            (b.centre_mm, b.force_n, b.area_mm2)
        );
        let (v, w) = (a.force_vector_n.expect("a vector"), b.force_vector_n.expect("a vector"));
        assert!(
            close(w[0], 0.4 * v[0]) && close(w[1], 0.4 * v[1]) && w[2] == v[2],
            "{v:?} -> {w:?}"
        );
        let (t, u) = (a.torque_nmm.expect("a torque"), b.torque_nmm.expect("a torque"));
        assert!(close(u, 0.4 * t), "contact torque {t} -> {u}");
    }

    // A torque scale of its own (`elastic.torque_scale`, what `nusense calibrate` fits from twists) takes the torque
    // from the tangential scale, total and per contact, and nothing else.
    let mut config = SensorConfig::default();
    config.elastic.tangential_force_scale = 0.4;
    config.elastic.torque_scale = Some(0.7);
    let twisted = Estimator::new(config, Mode::Inverse, reference())
        .expect("the simulated rest frame is measurable")
        .estimate(&frame)
        .expect("a push is measurable")
        .touch
        .expect("the same contact");
    assert_eq!(twisted.force_vector_n, scaled.force_vector_n);
    assert!(
        close(twisted.torque_nmm.expect("a torque"), 0.7 * t),
        "torque {t} -> {twisted:?}"
    );
    for (a, b) in plain.contacts().zip(twisted.contacts()) {
        assert_eq!(a.force_n, b.force_n);
        let (t, u) = (a.torque_nmm.expect("a torque"), b.torque_nmm.expect("a torque"));
        assert!(close(u, 0.7 * t), "contact torque {t} -> {u}");
    }
}

#[test]
fn force_so_large_that_corners_move_more_than_half_a_cell() {
    let truth = [0.0, 0.0];
    let mut contact = Contact::sphere(8.0, truth, 30.0);
    contact.tangential_force_n = [12.0, 0.0];
    let (frame, ground) = render(&Scene::with_contact(contact), 12);
    let pad = SensorConfig::default().pad;
    let pitch_mm = pad.pitch_x_mm().min(pad.pitch_y_mm());
    let largest = ground
        .corners
        .iter()
        .map(|c| distance(c.displaced_mm, c.rest_mm))
        .fold(0.0, f64::max);
    assert!(
        largest > 0.5 * pitch_mm,
        "the case needs corners moving > half a cell: largest {largest:.2} mm"
    );
    let reading = estimator().estimate(&frame).expect("a huge press is measurable");
    assert_sound(&reading, "huge force");
    assert!(reading.is_contact(), "huge force: not detected");
    let at = reading.contact_mm().unwrap();
    assert!(distance(at, truth) <= 2.0, "huge force: contact at {at:.2?} mm");
    let force = reading.force_n() * force_scale();
    assert!(force > 20.0, "huge force read as {force:.1} N");
    let v = reading.touch.as_ref().and_then(|t| t.force_vector_n).unwrap();
    assert!(v[0] > 0.0 && v[1].abs() < 0.3 * v[0], "the push is along +x: {v:?}");
}

#[test]
fn round_contact_has_no_edge_direction_but_an_edge_has_one() {
    let (round, _) = render(&Scene::with_contact(Contact::flat_punch(4.0, [0.0, 0.0], 6.0)), 13);
    let reading = expect_press(&mut estimator(), &round, [0.0, 0.0], 6.0, LOCATION_MM, "round contact");
    assert_eq!(
        reading.edge_angle_deg(),
        None,
        "a round contact has no direction (confidence {})",
        reading.edge_confidence()
    );
    for angle in [30.0, 105.0] {
        let (edge, _) = render(
            &Scene::with_contact(Contact::edge(20.0, 1.0, angle, [0.0, 0.0], 8.0)),
            13,
        );
        let reading = estimator().estimate(&edge).expect("a central edge press is measurable");
        assert_sound(&reading, "edge contact");
        let found = reading
            .edge_angle_deg()
            .unwrap_or_else(|| panic!("no edge direction: {:?}", reading.edge_confidence()));
        let off = (found - angle).rem_euclid(180.0);
        assert!(off.min(180.0 - off) <= 2.0, "edge at {found:.1} deg, truth {angle} deg");
    }
}

/// Fast mode lists one contact and takes the edge direction from the whole shear field, which two round presses side
/// by side make as elongated as an edge, along the pair (all six of the quick validation set's pairs, and every pair
/// here, read one before the two-press test). A correct sensor gives two fingertips no edge direction, and still gives
/// an edge its own (within 5 deg here; 3.6 deg at worst measured). The test is split_pair's (two round loads beat the
/// best line by 3 sigma), which does not find every pair on this sensor from stage 1's loads: 10 mm pairs of 3 mm
/// spheres about the centre along 0, 15, 75, 90, 120, 150 deg, or 4 N ones along 135 deg, read one with point loads
/// (the line explained more), and the 135 deg one still does with the loads spread as the line's (0 to 120 deg no
/// longer do; 150 not checked; the inverse, from
/// stage 2's, lists every such pair: `two_presses_ten_mm_apart_are_two_contacts_at_every_angle`).
#[test]
fn fast_mode_gives_two_round_presses_no_edge_direction_and_an_edge_its_own() {
    let mut fast = Estimator::new(SensorConfig::default(), Mode::Fast, reference()).unwrap();
    for (k, (mid, direction, forces)) in [
        ([-5.0, 3.0], 0.0, [3.0, 2.0]),
        ([-3.0, -4.0], 90.0, [3.5, 2.5]),
        ([0.0, 0.0], 30.0, [3.0, 3.0]),
        ([0.0, 0.0], 45.0, [4.0, 4.0]),
        ([0.0, 0.0], 60.0, [3.0, 3.0]),
    ]
    .into_iter()
    .enumerate()
    {
        let (c, s) = (
            f64::cos(f64::to_radians(direction)),
            f64::sin(f64::to_radians(direction)),
        );
        let scene = Scene {
            contacts: vec![
                Contact::sphere(3.0, [mid[0] - 5.0 * c, mid[1] - 5.0 * s], forces[0]),
                Contact::sphere(3.0, [mid[0] + 5.0 * c, mid[1] + 5.0 * s], forces[1]),
            ],
            ..Scene::default()
        };
        let (frame, _) = render(&scene, 40 + k as u64);
        let reading = fast.estimate(&frame).expect("two presses are measurable");
        let case = format!("two presses 10 mm apart about {mid:?} along {direction} deg");
        assert_sound(&reading, &case);
        assert!(reading.is_contact(), "{case}: no contact");
        assert_eq!(
            reading.edge_angle_deg(),
            None,
            "{case}: two fingertips are no edge (confidence {})",
            reading.edge_confidence()
        );
    }
    for (k, angle) in [30.0, 75.0, 105.0, 160.0].into_iter().enumerate() {
        let (edge, _) = render(
            &Scene::with_contact(Contact::edge(20.0, 1.0, angle, [2.0, -1.0], 6.0)),
            50 + k as u64,
        );
        let reading = fast.estimate(&edge).expect("an edge press is measurable");
        let found = reading
            .edge_angle_deg()
            .unwrap_or_else(|| panic!("edge at {angle} deg: no direction ({})", reading.edge_confidence()));
        let off = (found - angle).rem_euclid(180.0);
        assert!(off.min(180.0 - off) <= 5.0, "edge at {found:.1} deg, truth {angle} deg");
    }
}

#[test]
fn light_touches_down_to_half_a_newton_are_contacts() {
    // The target is 0.5 N at the noise of the real 2048 x 1536 frames. The contact test never assumes less noise
    // than a fraction of a pixel, so the floor grows as the frame shrinks: this case runs at half the real
    // resolution (at a quarter, 512 x 384, the floor is about 0.7 N), still coarser than the target's frames.
    let half = Renderer::new(SensorModel::real(1024, 768)).unwrap();
    let (rest, _) = render_with(&half, &Scene::rest(), NOMINAL, 1);
    let mut estimator = Estimator::new(SensorConfig::default(), Mode::Inverse, &rest).unwrap();
    for (k, force) in [0.5, 1.0, 2.0].into_iter().enumerate() {
        let truth = [-3.0, 4.0];
        let (frame, _) = render_with(&half, &press(truth, force), NOMINAL, 40 + k as u64);
        let reading = estimator.estimate(&frame).expect("a light press is measurable");
        assert_sound(&reading, "light touch");
        assert!(
            reading.test.detection_floor_n <= 0.5,
            "{force} N: floor {:?}",
            reading.test
        );
        assert!(reading.is_contact(), "{force} N not detected: {:?}", reading.test);
        let at = reading.contact_mm().unwrap();
        assert!(distance(at, truth) <= 1.5, "{force} N at {at:.2?}");
        let calibrated = reading.force_n() * force_scale();
        assert!(
            (calibrated - force).abs() <= 0.3 * force.max(1.0),
            "{force} N read as {calibrated:.2} N (calibrated)"
        );
    }
    let (rest, _) = render_with(&half, &Scene::rest(), NOMINAL, 49);
    expect_rest(&mut estimator, &rest, "half resolution, rest");
}

fn samples(pairs: &[(f64, f64)]) -> Vec<CalibrationSample> {
    pairs
        .iter()
        .map(|&(gamma, force_n)| CalibrationSample { gamma, force_n })
        .collect()
}

#[test]
fn calibration_with_duplicate_points() {
    let options = FitOptions::default();
    let same = samples(&[(1.0, 2.0); 6]);
    assert!(matches!(
        fit_force_line(&same, &options),
        Err(CalibrationError::TooFewPoints { .. })
    ));
    let two = samples(&[(1.0, 2.0), (1.0, 2.0), (2.0, 5.0), (2.0, 5.0), (1.0, 2.0)]);
    assert!(matches!(
        fit_force_line(&two, &options),
        Err(CalibrationError::TooFewPoints { .. })
    ));
    let vertical = samples(&[(1.5, 1.0), (1.5, 2.0), (1.5, 3.0), (1.5, 4.0)]);
    assert!(matches!(
        fit_force_line(&vertical, &options),
        Err(CalibrationError::GammaConstant { .. }) | Err(CalibrationError::TooFewPoints { .. })
    ));
    let mixed = samples(&[(1.0, 2.0), (1.0, 2.0), (2.0, 5.0), (3.0, 8.0), (3.0, 8.0), (4.0, 11.0)]);
    let fit = fit_force_line(&mixed, &options).expect("four distinct collinear points");
    assert!(
        (fit.a - 3.0).abs() < 1e-6 && (fit.b + 1.0).abs() < 1e-6,
        "a {} b {}",
        fit.a,
        fit.b
    );
}

#[test]
fn calibration_with_exactly_collinear_points() {
    let line = samples(&[(0.5, 0.405), (1.0, 1.95), (1.5, 3.495), (2.0, 5.04), (2.5, 6.585)]);
    let fit = fit_force_line(&line, &FitOptions::default()).expect("collinear points are a perfect line");
    assert!(
        (fit.a - 3.09).abs() < 1e-9 && (fit.b + 1.14).abs() < 1e-9,
        "a {} b {}",
        fit.a,
        fit.b
    );
    for value in [fit.a_std_error, fit.b_std_error, fit.residual_scale_n]
        .into_iter()
        .chain(fit.a_interval)
        .chain(fit.b_interval)
    {
        assert!(value.is_finite(), "collinear fit: non-finite value in {fit:?}");
    }
    assert!(fit.a_interval[0] <= fit.a && fit.a <= fit.a_interval[1], "{fit:?}");
    let mut bad = line.clone();
    bad[2].gamma = f64::NAN;
    assert!(matches!(
        fit_force_line(&bad, &FitOptions::default()),
        Err(CalibrationError::NotFinite { index: 2, .. })
    ));
}

#[test]
fn smallest_control_net_two_by_two() {
    let corners = vec![[0.0, 0.0], [10.0, 0.0], [0.0, 20.0], [10.0, 20.0]];
    let net = ControlNet::from_points(2, 2, corners).unwrap();
    let surface = BSplineSurface::new(net.clone(), 1, 1).expect("degree 1 on 2 x 2 is the bilinear patch");
    for (u, v) in [(0.0, 0.0), (0.25, 0.5), (1.0, 1.0), (0.7, 0.1)] {
        let p = surface.evaluate(u, v);
        assert!(
            (p[0] - 10.0 * v).abs() < 1e-12 && (p[1] - 20.0 * u).abs() < 1e-12,
            "({u}, {v}) -> {p:?}"
        );
    }
    let grid = surface.sample_grid(0.5).unwrap();
    assert!(grid.points.iter().flatten().all(|v| v.is_finite()));
    assert!(matches!(
        BSplineSurface::new(net.clone(), 3, 3),
        Err(SurfaceError::DegreeTooHigh { .. })
    ));
    let holey =
        ControlNet::from_options(2, 2, &[Some([0.0, 0.0]), None, Some([0.0, 20.0]), Some([10.0, 20.0])]).unwrap();
    let surface = BSplineSurface::new(holey, 1, 1).unwrap();
    let (point, valid) = surface.evaluate_checked(0.5, 0.5).unwrap();
    assert!(!valid && point.iter().all(|v| v.is_finite()));
    assert!(matches!(
        surface.evaluate_checked(1.5, 0.0),
        Err(SurfaceError::OutOfDomain { .. })
    ));
}

#[test]
fn estimator_with_a_surface_degree_the_lattice_cannot_carry_is_a_typed_error() {
    let mut config = SensorConfig::default();
    config.surface = SurfaceConfig {
        degree_u: 20,
        degree_v: 1,
        ..config.surface
    };
    match Estimator::new(config, Mode::Inverse, reference()) {
        Ok(_) => panic!("degree 20 on 12 corner rows was accepted"),
        Err(error) => assert!(
            matches!(error, EstimateError::Surface(_) | EstimateError::Config(_)),
            "{error}"
        ),
    }
}

#[test]
fn every_mode_reads_the_same_press_with_the_same_contact_decision() {
    // Fast and inverse share detection, motion removal and the contact test; they differ in how force is made.
    let truth = [4.0, -2.0];
    let (frame, _) = render(&press(truth, 6.0), 17);
    let mut fast = Estimator::new(SensorConfig::default(), Mode::Fast, reference()).unwrap();
    let reading = fast.estimate(&frame).unwrap();
    assert_sound(&reading, "fast mode");
    assert!(reading.is_contact());
    assert!(
        distance(reading.contact_mm().unwrap(), truth) <= 1.5,
        "{:?}",
        reading.contact_mm()
    );
    assert_eq!(
        reading.touch.as_ref().unwrap().force_vector_n,
        None,
        "the fast mode has no force vector"
    );
    assert!(reading.pressure_map.is_none());
}

/// Issue 12's target "two contacts 10 mm apart both listed, each force within 20 %", at every angle: pairs of 3 mm
/// spheres 10 mm apart about the pad's centre, along 0 to 168 deg in steps of 12, at equal and unequal forces. Each
/// press must be listed (the nearest listed contact within `PAIR_LOCATION_MM` of it and within `FORCE_FRACTION` of its
/// force once calibrated), as two contacts, with no edge direction (two fingertips are not an edge along the pair).
/// With unspread point loads in `InverseModel::pair_against_line`, 10 of the 15 failed: 9 read as one contact, 8 with
/// the pair's direction, and the pair along 0 deg listed as two but given a direction.
#[test]
fn two_presses_ten_mm_apart_are_two_contacts_at_every_angle() {
    /// Each press of a pair is located within this of its centre (the pad's cells are 3.3 mm apart).
    const PAIR_LOCATION_MM: f64 = 1.5;
    let mut failures = Vec::new();
    let angles: Vec<f64> = (0..15).map(|k| 12.0 * k as f64).collect();
    for (k, &direction) in angles.iter().enumerate() {
        let forces = [[3.0, 3.0], [3.5, 2.5], [2.5, 4.0]][k % 3];
        let (c, s) = (direction.to_radians().cos(), direction.to_radians().sin());
        let centres = [[-5.0 * c, -5.0 * s], [5.0 * c, 5.0 * s]];
        let scene = Scene {
            contacts: vec![
                Contact::sphere(3.0, centres[0], forces[0]),
                Contact::sphere(3.0, centres[1], forces[1]),
            ],
            ..Scene::default()
        };
        let (frame, _) = render(&scene, 60 + k as u64);
        let reading = estimator().estimate(&frame).expect("two presses are measurable");
        let case = format!("two presses 10 mm apart along {direction} deg ({forces:?} N)");
        assert_sound(&reading, &case);
        let listed: Vec<([f64; 2], f64)> = reading
            .contacts()
            .iter()
            .map(|c| (c.centre_mm, c.force_n * force_scale()))
            .collect();
        let missed: Vec<usize> = (0..2)
            .filter(|&i| {
                !listed.iter().any(|(at, force)| {
                    distance(*at, centres[i]) <= PAIR_LOCATION_MM
                        && (force - forces[i]).abs() <= FORCE_FRACTION * forces[i]
                })
            })
            .collect();
        let edge = reading.edge_angle_deg();
        if listed.len() != 2 || !missed.is_empty() || edge.is_some() {
            failures.push(format!("{case}: listed {listed:.2?}, edge {edge:?}"));
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {} pairs not read as two contacts:\n{}",
        failures.len(),
        angles.len(),
        failures.join("\n")
    );
}
