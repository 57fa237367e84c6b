//! The contact test on the validation sensor (`nusense_sim::validation`: another lens and pose, a layered pad,
//! glare, vignetting, shot noise, JPEG): a light press is a contact and a rest frame is none, under LED drift and
//! camera motion, at the smallest and the largest frame the daemon captures. The test decides from the noise each
//! frame shows (issue 12, item 4: detection floor 0.5 N, no contact on rest frames).

use image::RgbImage;
use nusense_estimator::calibration::{fit_force_line, CalibrationSample, FitOptions};
use nusense_estimator::{Estimator, Mode, ReadingJson, SensorConfig, Touch};
use nusense_sim::validation::{CameraMotion, Case, CaseKind, ValidationRenderer};
use nusense_sim::{Contact, Scene, NOMINAL_LED_CURRENT_MA};

/// The validation set's seed (its rest frame's noise).
const SET_SEED: u64 = 7;
/// LED drift of the rest frames against the rest frame every case is measured against, as the validation set's.
const REST_DRIFT: f64 = 0.08;
const PRESS_DRIFT: f64 = 0.03;

/// Uniform in [-1, 1], deterministic (xorshift).
struct Draw(u64);

impl Draw {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }

    fn leds(&mut self, drift: f64) -> [f32; 4] {
        std::array::from_fn(|_| NOMINAL_LED_CURRENT_MA * (1.0 + drift * self.next()) as f32)
    }
}

fn case(size: (u32, u32), scene: Scene, camera_motion: Option<CameraMotion>, leds: [f32; 4], seed: u64) -> Case {
    Case {
        name: format!("case_{seed}"),
        kind: if scene.contacts.is_empty() {
            CaseKind::Rest
        } else {
            CaseKind::Floor
        },
        size,
        scene,
        camera_motion,
        led_currents_ma: leds,
        seed,
    }
}

/// The validation sensor's config as `nusense calibrate` leaves it: the gamma line F = a gamma + b fitted (robustly, as
/// calibrate fits it) on 5 mm sphere presses of 1-8 N around the pad's centre, measured in fast mode. The real
/// sensor's default line (3.09 gamma - 1.14) reads this sensor's light presses below zero, and the gamma modes' floor
/// is stated in the line's newtons.
fn calibrated(renderer: &ValidationRenderer, reference: &RgbImage) -> SensorConfig {
    let size = (reference.width(), reference.height());
    let mut config = SensorConfig::default();
    let mut estimator = Estimator::new(config.clone(), Mode::Fast, reference).expect("the rest frame measures");
    let presses = [
        (1.0, [0.0, 0.0]),
        (2.5, [3.0, -2.0]),
        (4.0, [-4.0, 2.0]),
        (6.0, [2.0, 3.0]),
        (8.0, [-2.0, -3.0]),
    ];
    let samples: Vec<CalibrationSample> = presses
        .iter()
        .enumerate()
        .map(|(k, &(force_n, at))| {
            let scene = Scene::with_contact(Contact::sphere(5.0, at, force_n));
            let (frame, _) = renderer
                .render(&case(size, scene, None, [NOMINAL_LED_CURRENT_MA; 4], 300 + k as u64))
                .expect("the frame renders");
            let reading = estimator.estimate(&frame).expect("a calibration press is measurable");
            CalibrationSample {
                gamma: reading.gamma.gamma,
                force_n,
            }
        })
        .collect();
    let fit = fit_force_line(&samples, &FitOptions::default()).expect("the presses fit a line");
    config.calibration.a = fit.a;
    config.calibration.b = fit.b;
    config
}

/// Rest frames (LED drift up to 8 % per side; every other one with the camera rolled up to 5 degrees, tilted up to
/// 1 and shifted up to 1 mm) measured in `mode`: the frames that read as a contact.
fn false_contacts(size: (u32, u32), mode: Mode, frames: usize, draw: &mut Draw) -> Vec<String> {
    let renderer = ValidationRenderer::new(size).expect("the validation sensor renders");
    let reference = renderer.reference(SET_SEED).expect("the rest frame renders");
    let mut estimator = Estimator::new(SensorConfig::default(), mode, &reference).expect("the rest frame measures");
    let mut found = Vec::new();
    for k in 0..frames {
        let motion = (k % 2 == 1).then(|| CameraMotion {
            rotation_deg: [draw.next(), draw.next(), 5.0 * draw.next()],
            shift_mm: [draw.next(), draw.next()],
        });
        let leds = draw.leds(REST_DRIFT);
        let (frame, _) = renderer
            .render(&case(size, Scene::rest(), motion, leds, 100 + k as u64))
            .expect("the frame renders");
        let reading = estimator.estimate(&frame).expect("a rest frame is measurable");
        if reading.is_contact() {
            found.push(format!(
                "rest frame {k} (camera {motion:?}, LEDs {leds:?}): {:?}",
                reading.test
            ));
        }
    }
    found
}

fn distance_mm(found: [f64; 2], at: [f64; 2]) -> f64 {
    (found[0] - at[0]).hypot(found[1] - at[1])
}

#[test]
fn rest_frames_under_led_drift_noise_jpeg_and_camera_motion_are_no_contact_at_2048x1536() {
    let mut draw = Draw(0x2048_1536);
    let found = false_contacts((2048, 1536), Mode::Inverse, 8, &mut draw);
    assert!(
        found.is_empty(),
        "{} false contacts:\n{}",
        found.len(),
        found.join("\n")
    );
}

#[test]
fn rest_frames_under_led_drift_noise_jpeg_and_camera_motion_are_no_contact_at_640x480() {
    let mut draw = Draw(0x640_480);
    for mode in [Mode::Fast, Mode::Inverse] {
        let found = false_contacts((640, 480), mode, 8, &mut draw);
        assert!(
            found.is_empty(),
            "{mode}: {} false contacts:\n{}",
            found.len(),
            found.join("\n")
        );
    }
}

#[test]
fn half_a_newton_is_a_contact_where_it_presses() {
    let size = (1024, 768);
    let renderer = ValidationRenderer::new(size).expect("the validation sensor renders");
    let reference = renderer.reference(SET_SEED).expect("the rest frame renders");
    let config = calibrated(&renderer, &reference);
    let mut draw = Draw(0x05);
    for mode in [Mode::Fast, Mode::Inverse] {
        let mut estimator = Estimator::new(config.clone(), mode, &reference).expect("the rest frame measures");
        for (k, (at, tip)) in [
            ([5.0, -3.0], Contact::sphere(5.0, [5.0, -3.0], 0.5)),
            ([-15.0, 8.0], Contact::flat_punch(3.0, [-15.0, 8.0], 0.5)),
            ([12.0, 9.0], Contact::sphere(5.0, [12.0, 9.0], 0.5)),
        ]
        .into_iter()
        .enumerate()
        {
            let leds = draw.leds(PRESS_DRIFT);
            let (frame, _) = renderer
                .render(&case(size, Scene::with_contact(tip), None, leds, 200 + k as u64))
                .expect("the frame renders");
            let reading = estimator.estimate(&frame).expect("a light press is measurable");
            assert!(
                reading.test.detection_floor_n <= 0.5,
                "{mode}: floor above 0.5 N: {:?}",
                reading.test
            );
            assert!(
                reading.is_contact(),
                "{mode}: 0.5 N at {at:?} not detected: {:?}",
                reading.test
            );
            // The line's force for 0.5 N (the inverse's newtons are the uncalibrated model's: not this test's).
            if mode == Mode::Fast {
                let force = reading.force_n();
                assert!(force > 0.0 && force <= 1.0, "{mode}: 0.5 N at {at:?} read {force:.2} N");
            }
            // Where: the traction map's contact (the fast mode's divergence centre of so light a press is off by
            // up to about 4 mm, which is not this test's question).
            if mode == Mode::Inverse {
                let found = reading.contact_mm().expect("a contact has a position");
                assert!(
                    distance_mm(found, at) <= 2.0,
                    "{mode}: 0.5 N at {at:?} found at {found:.1?}"
                );
            }
        }
    }
}

/// In the gamma modes the floor is a force in the line's newtons, and a reading the line puts below it, or at or
/// below zero, is no contact: never a contact of 0 N or less. With the real sensor's default line on the validation
/// sensor (a line it was not calibrated with), a 0.5 N press the noise test finds reads below zero on the line; with
/// the sensor's own line the same press is a contact, and a 2 N press reads its force.
#[test]
fn in_the_gamma_mode_a_force_below_the_floor_is_no_contact_never_a_negative_one() {
    let size = (1024, 768);
    let renderer = ValidationRenderer::new(size).expect("the validation sensor renders");
    let reference = renderer.reference(SET_SEED).expect("the rest frame renders");
    let render = |force_n: f64, seed: u64| {
        let scene = if force_n > 0.0 {
            Scene::with_contact(Contact::sphere(5.0, [5.0, -3.0], force_n))
        } else {
            Scene::rest()
        };
        renderer
            .render(&case(size, scene, None, [NOMINAL_LED_CURRENT_MA; 4], seed))
            .expect("the frame renders")
            .0
    };
    let (rest, light, firm) = (render(0.0, 400), render(0.5, 401), render(2.0, 402));

    let mut uncalibrated =
        Estimator::new(SensorConfig::default(), Mode::Fast, &reference).expect("the rest frame measures");
    for (name, frame) in [("rest frame", &rest), ("0.5 N", &light)] {
        let reading = uncalibrated.estimate(frame).expect("the frame is measurable");
        let json = ReadingJson::from(reading.clone());
        assert!(!reading.is_contact(), "{name}: {:?}", reading.touch);
        assert!(!json.contact && json.contacts.is_empty() && json.contact_mm.is_none());
        assert_eq!(json.force_n, 0.0, "{name}");
        // What no contact keeps: gamma, the line's value as it is, and the displacements.
        assert!(reading.gamma.gamma > 0.0, "{name}");
        assert!(
            reading.force_model_n < 0.0,
            "{name}: the line reads {}",
            reading.force_model_n
        );
        assert!(json.shear_field.iter().any(|s| s.displacement_mm.is_some()), "{name}");
        if name == "0.5 N" {
            assert!(
                reading.test.statistic > reading.test.threshold,
                "the noise test finds the press (its line force is what is below the floor): {:?}",
                reading.test
            );
        }
    }

    let config = calibrated(&renderer, &reference);
    let mut estimator = Estimator::new(config, Mode::Fast, &reference).expect("the rest frame measures");
    let reading = estimator.estimate(&rest).expect("the rest frame is measurable");
    assert!(!reading.is_contact() && reading.force_n() == 0.0, "{:?}", reading.touch);
    for (force_n, frame) in [(0.5, &light), (2.0, &firm)] {
        let reading = estimator.estimate(frame).expect("the press is measurable");
        assert!(reading.is_contact(), "{force_n} N: {:?}", reading.test);
        let found = reading.force_n();
        assert!(
            (found - force_n).abs() <= 0.25 * force_n.max(2.0),
            "{force_n} N read {found:.2} N"
        );
    }
}

/// The inverse lists the light presses the noise test finds, as the fast mode does: the test decides contact, and
/// stage 2 only describes it. Before, stage 2 picked its loaded cells at no less than 0.08 px of noise (5.8 µm at
/// 1024x768, 8.6 µm at 640x480, against the 1.3-1.9 and 3.5-4.2 µm the test measures on these frames), found none
/// under a press this light and listed no contact: on the quick validation set 0.2 N was detected 0 of 3 times and
/// 0.3 N 1 of 3 by the inverse, 3 of 3 each by the fast mode. Each press here must be one contact, where it presses,
/// and the same sensor's rest frames (LED drift, half with the camera moved) none.
/// Presses each contact of `presses` on the validation sensor at `size` (LEDs drifting as in the validation set's
/// presses, frame seeds from `first_seed`), asserts that the noise test finds it and that the inverse lists a contact,
/// and hands that contact to `check` with the press's name and position (mm); then asserts that four of the same
/// sensor's rest frames are no contact.
fn inverse_touches(
    size: (u32, u32),
    presses: impl IntoIterator<Item = (String, Contact)>,
    first_seed: u64,
    draw: &mut Draw,
    mut check: impl FnMut(&str, [f64; 2], &Touch),
) {
    let renderer = ValidationRenderer::new(size).expect("the validation sensor renders");
    let reference = renderer.reference(SET_SEED).expect("the rest frame renders");
    let mut estimator =
        Estimator::new(SensorConfig::default(), Mode::Inverse, &reference).expect("the rest frame measures");
    for (seed, (name, tip)) in (first_seed..).zip(presses) {
        let name = format!("{name}, {}x{}", size.0, size.1);
        let at = tip.position_mm;
        let leds = draw.leds(PRESS_DRIFT);
        let (frame, _) = renderer
            .render(&case(size, Scene::with_contact(tip), None, leds, seed))
            .expect("the frame renders");
        let reading = estimator.estimate(&frame).expect("a light press is measurable");
        assert!(
            reading.test.statistic > reading.test.threshold,
            "{name}: the noise test misses it: {:?}",
            reading.test
        );
        let touch = reading
            .touch
            .as_ref()
            .unwrap_or_else(|| panic!("{name}: no contact listed"));
        check(&name, at, touch);
    }
    let found = false_contacts(size, Mode::Inverse, 4, draw);
    assert!(
        found.is_empty(),
        "{}x{}: {} false contacts:\n{}",
        size.0,
        size.1,
        found.len(),
        found.join("\n")
    );
}

#[test]
fn the_inverse_lists_the_light_presses_the_test_finds_and_no_rest_frame() {
    let mut draw = Draw(0x0_3);
    for (size, force_n) in [((1024, 768), 0.3), ((640, 480), 0.5)] {
        let presses = [
            Contact::sphere(5.0, [4.0, -2.0], force_n),
            Contact::flat_punch(3.0, [-20.0, -12.0], force_n),
            Contact::sphere(5.0, [18.0, 10.0], force_n),
            Contact::flat_punch(3.0, [-9.0, 13.0], force_n),
        ]
        .map(|tip| (format!("{force_n} N at {:?}", tip.position_mm), tip));
        inverse_touches(size, presses, 500, &mut draw, |name, at, touch| {
            assert!(touch.others.is_empty(), "{name}: {} more contacts", touch.others.len());
            let found = touch.strongest.centre_mm;
            assert!(distance_mm(found, at) <= 2.0, "{name}: found at {found:.1?}");
            assert!(touch.force_n > 0.0, "{name}: {} N", touch.force_n);
        });
    }
}

/// A light long edge is a contact for the inverse, as it is for the fast mode. A 20 x 1 mm edge spreads its load
/// over a line of cells, so that no single cell's stage 1 pressure clears its noise (at 0.5 N the best cell held 1.17
/// of its sigmas) although the noise test finds the press; before, stage 2 then picked no cell, or a fragment of the
/// line that fell below the floor, and the inverse listed no contact up to 1.5 N (the fast mode: 0.3 N). Each edge
/// here must be one contact, where it presses, with a force in the pad model's newtons within the bounds below; the
/// same sensor's rest frames none.
#[test]
fn the_inverse_lists_a_light_long_edge_where_it_presses() {
    let mut draw = Draw(0xED6E);
    for (size, force_n) in [((1024, 768), 0.75), ((640, 480), 1.0)] {
        let edges = [
            (0.0, [0.0, 0.0]),
            (45.0, [0.0, 0.0]),
            (90.0, [0.0, 0.0]),
            (0.0, [-8.0, 5.0]),
            (45.0, [7.0, -4.0]),
            (90.0, [10.0, 3.0]),
        ]
        .map(|(angle_deg, at)| {
            let name = format!("{force_n} N edge at {angle_deg} deg, {at:?}");
            (name, Contact::edge(20.0, 1.0, angle_deg, at, force_n))
        });
        inverse_touches(size, edges, 700, &mut draw, |name, at, touch| {
            let found = touch.strongest.centre_mm;
            assert!(distance_mm(found, at) <= 2.5, "{name}: found at {found:.1?}");
            assert!(
                touch.force_n >= 0.35 * force_n && touch.force_n <= 1.5 * force_n,
                "{name}: {:.2} N",
                touch.force_n
            );
        });
    }
}

/// The statistic divides by the noise the frame itself shows, a sample of its corners: a frame whose corners happen
/// to scatter little reads a rest frame's explained residual as more significant. Against a threshold that took that
/// noise as known, rest frames of the daemon's simulated sensor (`serve --sim`: the real sensor's model and config,
/// 640x480) read as contacts about 4 times in 10,000, with statistics of 460-478 against 457.5, where the test allows
/// one in a million (`inverse.false_alarm_probability`); the dashboard's browser test once drew a contact marker at
/// rest. These rest frames were such contacts (each against the rest frame before it in the list, the LEDs at 100 mA).
#[test]
fn a_rest_frame_whose_corners_scatter_little_is_no_contact() {
    let (width, height) = (640, 480);
    let renderer = nusense_sim::Renderer::new(nusense_sim::SensorModel::real(width, height)).expect("the real model");
    let config = SensorConfig::from_toml_str(nusense_sim::SENSOR_CONFIG_TOML).expect("the simulator's sensor config");
    let rest = |seed: u64| {
        renderer
            .render(&Scene::rest(), [100.0; 4], seed)
            .expect("a rest frame")
            .0
    };
    for (reference_seed, frame_seeds) in [(1000, &[1012, 1270][..]), (3, &[15][..])] {
        let mut estimator =
            Estimator::new(config.clone(), Mode::Inverse, &rest(reference_seed)).expect("a rest frame to measure from");
        for &seed in frame_seeds {
            let reading = estimator.estimate(&rest(seed)).expect("a rest frame is measurable");
            assert!(
                !reading.is_contact(),
                "rest frame {seed} against {reference_seed}: contact, statistic {:.1} against {:.1} at noise {:.2} um",
                reading.test.statistic,
                reading.test.threshold,
                reading.test.noise_mm * 1e3
            );
        }
    }
}
