//! Webcams also deliver 16:9 frames: some scale the sensor's 4:3 image to them (the pixels are then not square),
//! others keep its middle rows. Either way the rest frame is of the same shape, so the pad map fitted on it (see
//! `PadMapping::fit`) takes whatever the lens model scaled to the frame gets wrong, and a press must read as it does
//! in the 4:3 frame: one contact where it is, with the same force. Frames of the validation sensor
//! (`nusense_sim::validation`: another lens, pose and pad than the estimator assumes, with glare, noise and JPEG).

use image::{imageops, RgbImage};
use nusense_estimator::{Estimator, Mode, Reading, SensorConfig};
use nusense_sim::{Contact, Renderer, Scene, SensorModel, NOMINAL_LED_CURRENT_MA};

const LEDS: [f32; 4] = [NOMINAL_LED_CURRENT_MA; 4];
/// Three presses: the centre, and two halfway to the pattern's edges (its rows stay in a 16:9 crop).
const PRESSES: [[f64; 2]; 3] = [[0.0, 0.0], [12.0, -8.0], [-15.0, 10.0]];
const FORCE_N: f64 = 4.0;
/// Measured when written: 0.07-0.58 mm from the truth (the 4:3 frame: 0.06-0.47; the validation pad reads 0.33 mm RMS
/// on its quick set) and 0.978-1.002 of the 4:3 frame's force. A frame the lens or the map got wrong reads
/// millimetres off, or not at all.
const LOCATION_MM: f64 = 0.8;
const FORCE_SHARE: f64 = 0.05;

fn renderer(width: u32, height: u32) -> Renderer {
    Renderer::new(SensorModel::validation(width, height)).unwrap()
}

fn frame(renderer: &Renderer, scene: &Scene, seed: u64) -> RgbImage {
    renderer.render(scene, LEDS, seed).unwrap().0
}

/// The middle `height` rows.
fn middle_rows(image: &RgbImage, height: u32) -> RgbImage {
    let top = (image.height() - height) / 2;
    imageops::crop_imm(image, 0, top, image.width(), height).to_image()
}

/// Each press read through `shape` (the frame as the camera delivers it) by an estimator built on the rest frame of
/// that shape, and a rest frame with other noise.
fn readings(renderer: &Renderer, shape: impl Fn(RgbImage) -> RgbImage) -> (Reading, Vec<Reading>) {
    let reference = shape(frame(renderer, &Scene::rest(), 1));
    let mut estimator = Estimator::new(SensorConfig::default(), Mode::Inverse, &reference).unwrap();
    let rest = estimator.estimate(&shape(frame(renderer, &Scene::rest(), 2))).unwrap();
    let presses = PRESSES
        .iter()
        .zip(10..)
        .map(|(&at, seed)| {
            let scene = Scene::with_contact(Contact::sphere(5.0, at, FORCE_N));
            estimator.estimate(&shape(frame(renderer, &scene, seed))).unwrap()
        })
        .collect();
    (rest, presses)
}

fn assert_like_four_by_three(shape_name: &str, rest: &Reading, presses: &[Reading], four_by_three: &[Reading]) {
    assert!(
        !rest.is_contact(),
        "{shape_name}: a rest frame reads a contact: {:?}",
        rest.contacts()
    );
    for ((reading, reference), truth) in presses.iter().zip(four_by_three).zip(PRESSES) {
        let contacts = reading.contacts();
        assert_eq!(
            contacts.len(),
            1,
            "{shape_name}, press at {truth:?}: contacts {contacts:?}"
        );
        let at = contacts[0].centre_mm;
        let off = (at[0] - truth[0]).hypot(at[1] - truth[1]);
        assert!(
            off < LOCATION_MM,
            "{shape_name}, press at {truth:?}: read at {at:?}, {off:.2} mm off"
        );
        let ratio = reading.force_n() / reference.force_n();
        assert!(
            (ratio - 1.0).abs() < FORCE_SHARE,
            "{shape_name}, press at {truth:?}: {:.2} N against {:.2} N in the 4:3 frame",
            reading.force_n(),
            reference.force_n()
        );
    }
}

fn four_by_three() -> Vec<Reading> {
    let (rest, presses) = readings(&renderer(1280, 960), |f| f);
    assert!(!rest.is_contact(), "4:3: a rest frame reads a contact");
    presses
}

#[test]
fn a_sixteen_by_nine_frame_scaled_from_the_sensor_reads_as_the_four_by_three_one() {
    let (rest, presses) = readings(&renderer(1280, 720), |f| f);
    assert_like_four_by_three("scaled to 1280x720", &rest, &presses, &four_by_three());
}

#[test]
fn a_sixteen_by_nine_crop_of_the_sensor_reads_as_the_four_by_three_one() {
    let (rest, presses) = readings(&renderer(1280, 960), |f| middle_rows(&f, 720));
    assert_like_four_by_three("cropped to 1280x720", &rest, &presses, &four_by_three());
}
