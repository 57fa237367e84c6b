//! Where a pushed contact is read, on frames of the validation sensor (`nusense_sim::validation`: a stiff skin over
//! soft gel, which the estimator reads through one equivalent layer).
//!
//! A push's pressure centre reads behind the push, in proportion to the push: the equivalent layer explains part of
//! the pad's shear response with pressure. `elastic.push_centre_shift_mm`, fitted on pushes at one known place
//! (`calibration::push_centre`), moves each contact's centre along its own push; pushes elsewhere and in other
//! directions then read nearer their places, and nothing but the centres moves.

use nusense_estimator::calibration::push_centre::{fit_push_centre_shift, PushCentreSample};
use nusense_estimator::{Estimator, Mode, Reading, SensorConfig};
use nusense_sim::validation::{Case, CaseKind, ValidationRenderer};
use nusense_sim::{Contact, Scene, NOMINAL_LED_CURRENT_MA};

const SIZE: (u32, u32) = (640, 480);

/// A 4 N press of a 5 mm sphere at `at` pushed by 1.6 N towards `angle_deg`.
fn pushed(renderer: &ValidationRenderer, at: [f64; 2], angle_deg: f64, seed: u64) -> image::RgbImage {
    let mut contact = Contact::sphere(5.0, at, 4.0);
    let (s, c) = angle_deg.to_radians().sin_cos();
    contact.tangential_force_n = [1.6 * c, 1.6 * s];
    let case = Case {
        name: "push".into(),
        kind: CaseKind::Tangential,
        size: SIZE,
        scene: Scene::with_contact(contact),
        camera_motion: None,
        led_currents_ma: [NOMINAL_LED_CURRENT_MA; 4],
        seed,
    };
    renderer.render(&case).unwrap().0
}

fn read(estimator: &mut Estimator, frame: &image::RgbImage) -> Reading {
    let reading = estimator.estimate(frame).expect("a push is measurable");
    assert!(reading.is_contact(), "a 4 N push was not detected: {:?}", reading.test);
    reading
}

fn distance(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

#[test]
fn a_shift_fitted_at_one_place_brings_pushes_elsewhere_to_their_places() {
    let renderer = ValidationRenderer::new(SIZE).unwrap();
    let reference = renderer.reference(7).unwrap();
    let with_shift = |shift_mm: f64| {
        let mut config = SensorConfig::default();
        config.elastic.push_centre_shift_mm = shift_mm;
        Estimator::new(config, Mode::Inverse, &reference).unwrap()
    };
    let fitted_at = [2.0, 1.0];
    let samples: Vec<PushCentreSample> = [0.0, 90.0, 180.0, 270.0]
        .iter()
        .enumerate()
        .map(|(k, &angle)| {
            let reading = read(
                &mut with_shift(0.0),
                &pushed(&renderer, fitted_at, angle, 70 + k as u64),
            );
            PushCentreSample {
                model_force_vector_n: reading.touch.as_ref().and_then(|t| t.force_vector_n).unwrap(),
                read_centre_mm: reading.contact_mm().unwrap(),
                true_centre_mm: fitted_at,
            }
        })
        .collect();
    let shift = fit_push_centre_shift(&samples).expect("four pushes of two fifths of their load");
    let (mut before, mut after) = (Vec::new(), Vec::new());
    let elsewhere = [
        ([-12.0, 6.0], 45.0),
        ([10.0, -7.0], 160.0),
        ([-6.0, -9.0], 300.0),
        ([14.0, 8.0], 225.0),
    ];
    for (k, (at, angle)) in elsewhere.into_iter().enumerate() {
        let frame = pushed(&renderer, at, angle, 80 + k as u64);
        let (a, b) = (read(&mut with_shift(0.0), &frame), read(&mut with_shift(shift), &frame));
        before.push(distance(a.contact_mm().unwrap(), at));
        after.push(distance(b.contact_mm().unwrap(), at));
        // Each contact's centre moved by the shift times its own push over load; nothing else moved.
        assert_eq!(a.contacts().len(), b.contacts().len());
        for (ca, cb) in a.contacts().iter().zip(b.contacts()) {
            let [fx, fy, fz] = ca.force_vector_n.unwrap();
            let expected = [ca.centre_mm[0] + shift * fx / fz, ca.centre_mm[1] + shift * fy / fz];
            assert!(
                distance(cb.centre_mm, expected) < 1e-9,
                "{:?} -> {:?}",
                ca.centre_mm,
                cb.centre_mm
            );
            assert_eq!(
                (ca.force_n, ca.force_vector_n, ca.area_mm2),
                (cb.force_n, cb.force_vector_n, cb.area_mm2)
            );
        }
        let (ta, tb) = (a.touch.as_ref().unwrap(), b.touch.as_ref().unwrap());
        assert_eq!((ta.force_n, ta.force_vector_n), (tb.force_n, tb.force_vector_n));
        assert_eq!((a.pressure_map, a.test), (b.pressure_map, b.test));
    }
    eprintln!("shift {shift:.3} mm; before {before:.2?} after {after:.2?}");
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    assert!(shift > 0.0, "the centre reads behind the push: shift {shift}");
    assert!(
        rms(&after) < 0.6 * rms(&before) && after.iter().all(|&d| d <= 0.8),
        "pushes elsewhere: {before:.2?} mm before the shift, {after:.2?} after"
    );
}
