//! The contact test on the validation sensor (`nusense_sim::validation`: another lens and pose, a layered pad,
//! glare, vignetting, shot noise, JPEG): a light press is a contact and a rest frame is none, under LED drift and
//! camera motion, at the smallest and the largest frame the daemon captures. The test decides from the noise each
//! frame shows (issue 12, item 4: detection floor 0.5 N, no contact on rest frames).

use nusense_estimator::{Estimator, Mode, SensorConfig};
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
    let mut draw = Draw(0x05);
    for mode in [Mode::Fast, Mode::Inverse] {
        let mut estimator = Estimator::new(SensorConfig::default(), mode, &reference).expect("the rest frame measures");
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
            // Where: the traction map's contact (the fast mode's divergence centre of so light a press is off by
            // up to about 4 mm, which is not this test's question).
            if mode == Mode::Inverse {
                let found = reading.contact_mm().expect("a contact has a position");
                let off = (found[0] - at[0]).hypot(found[1] - at[1]);
                assert!(off <= 2.0, "{mode}: 0.5 N at {at:?} found at {found:.1?}");
            }
        }
    }
}
