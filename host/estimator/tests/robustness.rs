//! The fast mode away from the two pristine real frames: lower resolutions, noise, JPEG, other lighting, small
//! camera shifts and rotations, a smeared part of the pad. All perturbations are made here from the real frames,
//! at half resolution to keep the tests quick.

use std::path::PathBuf;
use std::sync::OnceLock;

use image::{imageops, Rgb, RgbImage};
use nusense_estimator::{EstimateError, Estimator, Mode, SensorConfig};

fn load(name: &str) -> RgbImage {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/real");
    image::open(dir.join(name))
        .expect("the real frames ship in host/estimator/tests/data/real")
        .to_rgb8()
}

fn scaled(image: &RgbImage, divisor: u32) -> RgbImage {
    imageops::resize(
        image,
        image.width() / divisor,
        image.height() / divisor,
        imageops::FilterType::Triangle,
    )
}

fn half_pair() -> &'static (RgbImage, RgbImage) {
    static PAIR: OnceLock<(RgbImage, RgbImage)> = OnceLock::new();
    PAIR.get_or_init(|| {
        (
            scaled(&load("reference_fisheye.jpg"), 2),
            scaled(&load("touch_fisheye.jpg"), 2),
        )
    })
}

/// A small deterministic generator (xorshift), so noise is the same on every run.
struct Noise(u64);

impl Noise {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Roughly Gaussian (sum of uniforms), standard deviation `sigma`.
    fn gauss(&mut self, sigma: f64) -> f64 {
        ((0..4).map(|_| self.next()).sum::<f64>() - 2.0) * sigma * (3.0f64).sqrt()
    }
}

fn with_noise(image: &RgbImage, sigma: f64, seed: u64) -> RgbImage {
    let mut noise = Noise(seed | 1);
    let mut out = image.clone();
    for p in out.pixels_mut() {
        for c in p.0.iter_mut() {
            *c = (f64::from(*c) + noise.gauss(sigma)).round().clamp(0.0, 255.0) as u8;
        }
    }
    out
}

/// The image moved by (dx, dy) px and turned by `degrees` about its centre (bilinear, black outside).
fn moved(image: &RgbImage, dx: f64, dy: f64, degrees: f64) -> RgbImage {
    let (w, h) = image.dimensions();
    let (s, c) = degrees.to_radians().sin_cos();
    let (cx, cy) = (f64::from(w) / 2.0, f64::from(h) / 2.0);
    RgbImage::from_fn(w, h, |x, y| {
        // Inverse map: output pixel centre to source position.
        let (px, py) = (f64::from(x) + 0.5 - cx - dx, f64::from(y) + 0.5 - cy - dy);
        let (sx, sy) = (c * px + s * py + cx - 0.5, -s * px + c * py + cy - 0.5);
        let (x0, y0) = (sx.floor(), sy.floor());
        if x0 < 0.0 || y0 < 0.0 || x0 + 1.0 >= f64::from(w) || y0 + 1.0 >= f64::from(h) {
            return Rgb([0, 0, 0]);
        }
        let (fx, fy) = (sx - x0, sy - y0);
        let at = |xx: f64, yy: f64| image.get_pixel(xx as u32, yy as u32).0;
        let (a, b, cc, d) = (at(x0, y0), at(x0 + 1.0, y0), at(x0, y0 + 1.0), at(x0 + 1.0, y0 + 1.0));
        Rgb(std::array::from_fn(|k| {
            let v = f64::from(a[k]) * (1.0 - fx) * (1.0 - fy)
                + f64::from(b[k]) * fx * (1.0 - fy)
                + f64::from(cc[k]) * (1.0 - fx) * fy
                + f64::from(d[k]) * fx * fy;
            v.round() as u8
        }))
    })
}

fn jpeg(image: &RgbImage, quality: u8) -> RgbImage {
    let mut bytes = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, quality)
        .encode_image(image)
        .unwrap();
    image::load_from_memory(&bytes).unwrap().to_rgb8()
}

/// Contact box of the issue, (1000, 750) +/- 40 px of the 2048-px frame, scaled to the frame.
fn assert_contact_in_box(undistorted: [f64; 2], width: u32) {
    let s = f64::from(width) / 2048.0;
    let [x, y] = undistorted;
    assert!(
        (x / s - 1000.0).abs() <= 40.0 && (y / s - 750.0).abs() <= 40.0,
        "contact at ({x}, {y}) in a {width}-px frame"
    );
}

#[test]
fn works_at_half_and_quarter_resolution_with_the_same_gamma_scale() {
    let full = Estimator::new(SensorConfig::default(), Mode::Fast, &load("reference_fisheye.jpg"))
        .unwrap()
        .estimate(&load("touch_fisheye.jpg"))
        .unwrap();
    for divisor in [2, 4] {
        let (reference, touch) = if divisor == 2 {
            half_pair().clone()
        } else {
            (scaled(&half_pair().0, 2), scaled(&half_pair().1, 2))
        };
        let mut estimator = Estimator::new(SensorConfig::default(), Mode::Fast, &reference).unwrap();
        assert_eq!(estimator.reference_lattice().squares_found(), 96, "1/{divisor}");
        assert_eq!(estimator.reference_lattice().corners_found(), 165, "1/{divisor}");
        let reading = estimator.estimate(&touch).unwrap();
        assert_eq!(reading.counts.points_detected, 165, "1/{divisor}");
        assert!(reading.is_contact(), "1/{divisor}");
        assert_contact_in_box(reading.strongest().unwrap().centre_undistorted_px, touch.width());
        // gamma is measured in paper px, so it does not scale with the resolution.
        assert!(
            (reading.gamma.gamma / full.gamma.gamma - 1.0).abs() < 0.15,
            "1/{divisor}: gamma {} vs {}",
            reading.gamma.gamma,
            full.gamma.gamma
        );
    }
}

#[test]
fn noise_on_the_rest_frame_is_not_a_contact() {
    let (reference, _) = half_pair();
    let mut estimator = Estimator::new(SensorConfig::default(), Mode::Inverse, reference).unwrap();
    for seed in 1..=3 {
        let reading = estimator.estimate(&with_noise(reference, 8.0, seed)).unwrap();
        assert!(
            !reading.is_contact(),
            "seed {seed}: score {} mm",
            reading.contact_score_mm
        );
        assert_eq!(reading.counts.points_detected, 165);
        assert!(reading.gamma.gamma < 0.1, "gamma {}", reading.gamma.gamma);
    }
}

#[test]
fn a_camera_shift_or_rotation_is_measured_and_removed() {
    let (reference, touch) = half_pair();
    let mut estimator = Estimator::new(SensorConfig::default(), Mode::Inverse, reference).unwrap();
    let still = estimator.estimate(touch).unwrap();
    let still_at = still.contact_mm().unwrap();
    for (dx, dy, degrees) in [(5.0, -3.0, 0.0), (0.0, 0.0, 1.5), (-4.0, 2.0, -1.0), (3.0, 3.0, 5.0)] {
        let case = format!("shift ({dx}, {dy}) px, rotation {degrees} deg");
        let reading = estimator.estimate(&moved(reference, dx, dy, degrees)).unwrap();
        assert!(!reading.is_contact(), "{case}: {:?}", reading.test);
        assert!(
            reading.counts.points_detected >= 160,
            "{case}: {}",
            reading.counts.points_detected
        );
        let motion = reading.camera_motion;
        assert!((motion.rotation_deg - degrees).abs() <= 0.2, "{case}: {motion:?}");
        // The image turns about its centre, so the pad centre's shift is the given one plus the turn's.
        if degrees == 0.0 {
            assert!(
                (motion.shift_px[0] - dx).abs() <= 0.5 && (motion.shift_px[1] - dy).abs() <= 0.5,
                "{case}: {motion:?}"
            );
        }
        // The touch through the same moved camera: the same place on the pad, the same force.
        let reading = estimator.estimate(&moved(touch, dx, dy, degrees)).unwrap();
        assert!(reading.is_contact(), "{case}");
        let at = reading.contact_mm().unwrap();
        assert!(
            (at[0] - still_at[0]).hypot(at[1] - still_at[1]) <= 0.5,
            "{case}: {at:?} vs {still_at:?}"
        );
        assert!(
            (reading.force_n() / still.force_n() - 1.0).abs() <= 0.1,
            "{case}: {} vs {} N",
            reading.force_n(),
            still.force_n()
        );
    }
}

#[test]
fn other_lighting_and_jpeg_keep_the_lattice_and_the_contact() {
    let (reference, touch) = half_pair();
    let mut estimator = Estimator::new(SensorConfig::default(), Mode::Fast, reference).unwrap();
    let dim = RgbImage::from_fn(touch.width(), touch.height(), |x, y| {
        // 55 % of the light with a left-to-right gradient.
        let k = 0.4 + 0.3 * f64::from(x) / f64::from(touch.width());
        Rgb(touch.get_pixel(x, y).0.map(|c| (f64::from(c) * k).round() as u8))
    });
    for (name, frame) in [("dim", dim), ("jpeg q40", jpeg(touch, 40))] {
        let reading = estimator.estimate(&frame).unwrap();
        assert_eq!(reading.counts.points_detected, 165, "{name}");
        assert!(reading.is_contact(), "{name}");
        assert_contact_in_box(reading.strongest().unwrap().centre_undistorted_px, touch.width());
    }
}

#[test]
fn a_smeared_part_of_the_pad_is_masked_and_counted() {
    let (reference, touch) = half_pair();
    let mut estimator = Estimator::new(SensorConfig::default(), Mode::Fast, reference).unwrap();
    // A grey smear over the pad's top-left (about 3 x 3 cells), away from the contact.
    let mut smeared = touch.clone();
    let lattice = estimator.reference_lattice();
    let anchor = lattice
        .corner(nusense_geometry::CornerIndex { row: 1, col: 1 })
        .unwrap()
        .raw_px
        .unwrap();
    for y in 0..smeared.height() {
        for x in 0..smeared.width() {
            if (f64::from(x) - anchor[0]).hypot(f64::from(y) - anchor[1]) < 60.0 {
                smeared.put_pixel(x, y, Rgb([90, 80, 85]));
            }
        }
    }
    let reading = estimator.estimate(&smeared).unwrap();
    assert!(
        reading.counts.squares_detected < 96 && reading.counts.squares_detected > 80,
        "{}",
        reading.counts.squares_detected
    );
    assert!(
        reading.counts.points_detected < 165,
        "{}",
        reading.counts.points_detected
    );
    assert_eq!(
        reading.shear_field.iter().filter(|s| s.valid).count(),
        reading.counts.points_valid
    );
    assert!(reading.gamma.samples_used < reading.gamma.samples_total);
    assert!(reading.is_contact());
    assert_contact_in_box(reading.strongest().unwrap().centre_undistorted_px, touch.width());
    // The next clean frame is complete again.
    assert_eq!(estimator.estimate(touch).unwrap().counts.points_detected, 165);
}

#[test]
fn a_jump_of_more_than_half_a_cell_is_recovered_by_a_full_search() {
    let (reference, touch) = half_pair();
    let mut estimator = Estimator::new(SensorConfig::default(), Mode::Fast, reference).unwrap();
    let cell = estimator
        .reference_lattice()
        .square(nusense_geometry::SquareIndex { row: 6, col: 8 })
        .unwrap()[0]
        - estimator
            .reference_lattice()
            .square(nusense_geometry::SquareIndex { row: 6, col: 6 })
            .unwrap()[0];
    // The camera jumps by 0.7 cell to the right: windows centred on the old squares would lock onto the wrong ones.
    let jumped = moved(touch, 0.35 * cell, 0.0, 0.0);
    let reading = estimator.estimate(&jumped).unwrap();
    assert!(reading.recovered);
    assert_eq!(reading.counts.points_detected, 165);
    assert!(reading.is_contact());
}

#[test]
fn frames_without_the_pattern_are_typed_errors() {
    let (reference, _) = half_pair();
    let mut estimator = Estimator::new(SensorConfig::default(), Mode::Fast, reference).unwrap();
    let grey = RgbImage::from_pixel(reference.width(), reference.height(), Rgb([120, 120, 120]));
    assert!(matches!(
        estimator.estimate(&grey),
        Err(EstimateError::NoPattern { .. } | EstimateError::TooFewPoints { .. })
    ));
    assert!(matches!(
        Estimator::new(SensorConfig::default(), Mode::Fast, &grey),
        Err(EstimateError::NoPattern { .. } | EstimateError::TooFewPoints { .. })
    ));
    // After a bad frame the estimator still measures good ones.
    assert!(estimator.estimate(reference).unwrap().counts.points_detected == 165);
}
