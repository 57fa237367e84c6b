//! The real sensor's pair of frames (tests/data/real): counts, contact, and the rest frame against itself.

use std::path::PathBuf;
use std::sync::OnceLock;

use image::RgbImage;
use nusense_estimator::{Estimator, Mode, SensorConfig};

fn real_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/real")
}

fn load(name: &str) -> RgbImage {
    image::open(real_dir().join(name))
        .expect("the real frames ship in host/estimator/tests/data/real")
        .to_rgb8()
}

fn reference() -> &'static RgbImage {
    static FRAME: OnceLock<RgbImage> = OnceLock::new();
    FRAME.get_or_init(|| load("reference_fisheye.jpg"))
}

fn touch() -> &'static RgbImage {
    static FRAME: OnceLock<RgbImage> = OnceLock::new();
    FRAME.get_or_init(|| load("touch_fisheye.jpg"))
}

#[test]
fn fast_mode_finds_every_square_and_corner_on_both_frames() {
    let mut estimator = Estimator::new(SensorConfig::default(), Mode::Fast, reference()).unwrap();
    let rest = estimator.reference_lattice().clone();
    assert_eq!(rest.squares_found(), 96);
    assert_eq!(rest.corners_found(), 165);
    let reading = estimator.estimate(touch()).unwrap();
    assert_eq!(reading.counts.squares_detected, 96);
    assert_eq!(reading.counts.points_detected, 165);
    assert_eq!(reading.counts.points_expected, 165);
    assert_eq!(
        reading.counts.points_valid, 165,
        "no corner of the real touch frame is implausible"
    );
}

#[test]
fn fast_mode_finds_the_contact_near_the_published_centre() {
    let mut estimator = Estimator::new(SensorConfig::default(), Mode::Fast, reference()).unwrap();
    let reading = estimator.estimate(touch()).unwrap();
    assert!(reading.is_contact(), "{reading:?}");
    let [x, y] = reading.strongest().unwrap().centre_undistorted_px;
    assert!(
        (x - 1000.0).abs() <= 40.0 && (y - 750.0).abs() <= 40.0,
        "contact at ({x}, {y}) undistorted px"
    );
    assert!(
        reading.gamma.gamma > 0.0 && reading.force_n() > 0.0,
        "{} {}",
        reading.gamma.gamma,
        reading.force_n()
    );
    // The contact in mm lies on the pad, near its centre (the press was "near the centre of the pad").
    let [mx, my] = reading.contact_mm().unwrap();
    assert!(mx.abs() < 10.0 && my.abs() < 10.0, "({mx}, {my}) mm");
    assert_eq!(reading.gamma.samples_total, 67 * 67);
    assert_eq!(reading.gamma.samples_used, 67 * 67);
}

#[test]
fn the_rest_frame_against_itself_is_no_contact() {
    let mut estimator = Estimator::new(SensorConfig::default(), Mode::Fast, reference()).unwrap();
    let reading = estimator.estimate(reference()).unwrap();
    assert!(!reading.is_contact());
    // The same pixels give the same centroids up to where the search window starts (1e-3 of gamma is about
    // 0.003 N, far below anything a touch produces).
    assert!(reading.gamma.gamma.abs() < 1e-3, "gamma {}", reading.gamma.gamma);
    assert_eq!(reading.force_n(), 0.0);
    assert_eq!(reading.contact_px(), None);
    assert_eq!(reading.edge_angle_deg(), None);
}

/// The rest frame again, in fast and inverse modes, and the same frame shifted 200 px (a tare after the camera was
/// knocked): every corner is where the rest lattice has it, to a micrometre, so the contact test, which judges by
/// each frame's own noise, has nothing to find.
#[test]
fn the_rest_frame_again_has_no_displacement_at_any_corner() {
    let shifted = |rest: &RgbImage, dx: u32| {
        let mut moved = RgbImage::new(rest.width(), rest.height());
        for (x, y, p) in rest.enumerate_pixels() {
            if x + dx < rest.width() {
                moved.put_pixel(x + dx, y, *p);
            }
        }
        moved
    };
    let half = image::imageops::resize(
        reference(),
        reference().width() / 2,
        reference().height() / 2,
        image::imageops::FilterType::Triangle,
    );
    let frames = [
        ("rest frame", reference().clone()),
        ("shifted rest frame", shifted(reference(), 300)),
        ("rest frame at 1/2", half.clone()),
        ("shifted rest frame at 1/2", shifted(&half, 150)),
    ];
    for mode in [Mode::Fast, Mode::Inverse] {
        for (what, frame) in &frames {
            let mut estimator = Estimator::new(SensorConfig::default(), mode, frame).unwrap();
            let reading = estimator.estimate(frame).unwrap();
            let worst_um = reading
                .shear_field
                .iter()
                .filter_map(|v| v.displacement_mm)
                .map(|[dx, dy]| dx.hypot(dy) * 1e3)
                .fold(0.0, f64::max);
            assert!(worst_um <= 1.0, "{mode} {what}: a corner moved {worst_um:.2} um");
            assert!(!reading.is_contact(), "{mode} {what}: {:?}", reading.test);
        }
    }
}

/// The target is a detection floor of 0.5 N at the real sensor's noise. The test measures that noise on the frame's
/// corners away from the press, and its threshold grows as that sample gets less precise (an F quantile): taken as
/// the median corner's scatter (as precise as 0.96 squares per corner) the floor was 0.46 N; with the threshold of
/// the scatter with the largest quarter of the corners censored (1.5 per corner) it was 0.415 N (0.414 N at c5114ae).
#[test]
fn the_inverse_detects_well_under_half_a_newton_on_the_real_touch_frame() {
    let mut estimator = Estimator::new(SensorConfig::default(), Mode::Inverse, reference()).unwrap();
    let reading = estimator.estimate(touch()).unwrap();
    assert!(reading.is_contact(), "{:?}", reading.test);
    assert!(reading.test.detection_floor_n <= 0.43, "{:?}", reading.test);
}

#[test]
fn paper_mode_finds_the_same_contact_with_the_published_pipeline() {
    let mut estimator = Estimator::new(SensorConfig::default(), Mode::Paper, reference()).unwrap();
    let rest = estimator.reference_lattice().corners_found();
    let reading = estimator.estimate(touch()).unwrap();
    // The published method misses squares and corners on this pair; whatever it misses is masked and counted.
    assert!(
        rest <= 165
            && reading.counts.points_detected <= 165
            && reading.counts.points_valid <= reading.counts.points_detected
    );
    assert!(reading.gamma.samples_used <= reading.gamma.samples_total);
    assert!(reading.is_contact());
    let [x, y] = reading.strongest().unwrap().centre_undistorted_px;
    assert!(
        (x - 1000.0).abs() <= 40.0 && (y - 750.0).abs() <= 40.0,
        "contact at ({x}, {y}) undistorted px"
    );
    assert!(reading.gamma.gamma > 0.0);
}
