//! Hard cases for the estimator, on frames made by the simulated sensor (nusense-sim) at a modest resolution.
//!
//! Every case states what is accepted: either a reading within the stated tolerance, or a typed "cannot
//! estimate" error whose reason fits the case. Nothing may panic, and no reading may carry a NaN or infinity.
//! Fast mode is held to the tolerances; paper mode (the published pipeline) is run on the same frames and held
//! to robustness only (finite reading or typed error), since the published method is not expected to cope.

use std::sync::OnceLock;

use image::RgbImage;
use nusense_estimator::calibration::{
    fit_force_line, CalibrationError, CalibrationSample, FitOptions,
};
use nusense_estimator::surface::{BSplineSurface, ControlNet, SurfaceError};
use nusense_estimator::{EstimateError, Estimator, Mode, Reading, SensorConfig, SurfaceConfig};
use nusense_sim::{Contact, Damage, GroundTruth, Occlusion, Renderer, Scene, SensorModel};

/// A quarter of the real 2048 x 1536 frame: about 20 px per cell, small enough for a quick test.
const WIDTH: u32 = 512;
const HEIGHT: u32 = 384;
const NOMINAL: [f32; 4] = [100.0; 4];
/// Contact location tolerance for a single clear press, pad mm (the cell pitch is about 3.3 mm).
const LOCATION_TOLERANCE_MM: f64 = 3.0;

fn model() -> SensorModel {
    SensorModel::real(WIDTH, HEIGHT)
}

fn renderer() -> &'static Renderer {
    static RENDERER: OnceLock<Renderer> = OnceLock::new();
    RENDERER.get_or_init(|| Renderer::new(model()).expect("the real sensor model is valid"))
}

fn render_with(
    renderer: &Renderer,
    scene: &Scene,
    leds: [f32; 4],
    seed: u64,
) -> (RgbImage, GroundTruth) {
    renderer
        .render(scene, leds, seed)
        .expect("the scene is valid")
}

fn render(scene: &Scene, seed: u64) -> (RgbImage, GroundTruth) {
    render_with(renderer(), scene, NOMINAL, seed)
}

fn reference() -> &'static RgbImage {
    static FRAME: OnceLock<RgbImage> = OnceLock::new();
    FRAME.get_or_init(|| render(&Scene::rest(), 1).0)
}

fn estimator(mode: Mode) -> Estimator {
    Estimator::new(SensorConfig::default(), mode, reference())
        .expect("the simulated rest frame is measurable")
}

/// No NaN or infinity anywhere in a reading.
fn assert_finite(reading: &Reading, case: &str) {
    let mut values = vec![
        reading.gamma,
        reading.force_n,
        reading.force_model_n,
        reading.edge_confidence,
        reading.contact_score_mm,
        reading.elapsed_ms,
    ];
    values.extend(reading.contact_px.into_iter().flatten());
    values.extend(reading.contact_undistorted_px.into_iter().flatten());
    values.extend(reading.contact_mm.into_iter().flatten());
    values.extend(reading.edge_angle_deg);
    for vector in &reading.shear_field {
        values.extend(vector.reference_px.into_iter().flatten());
        values.extend(vector.current_px.into_iter().flatten());
        values.extend(vector.displacement_mm.into_iter().flatten());
    }
    assert!(
        values.iter().all(|v| v.is_finite()),
        "{case}: a reading carries a non-finite value: {reading:?}"
    );
    if let Some(angle) = reading.edge_angle_deg {
        assert!(
            (0.0..180.0).contains(&angle),
            "{case}: edge angle {angle} outside [0, 180)"
        );
    }
    assert!(
        reading.edge_confidence >= 0.0 && reading.edge_confidence <= 1.0,
        "{case}: edge confidence"
    );
    assert!(
        reading.points_detected <= reading.points_expected,
        "{case}: more points than the lattice has"
    );
}

/// Errors that honestly say "cannot estimate this frame".
fn is_cannot_estimate(error: &EstimateError) -> bool {
    matches!(
        error,
        EstimateError::NoPattern { .. } | EstimateError::TooFewPoints { .. }
    )
}

fn distance(a: [f64; 2], b: [f64; 2]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
}

/// Runs paper mode on the same frame: a finite reading or a typed error, nothing else.
fn paper_mode_survives(frame: &RgbImage, case: &str) {
    let Ok(mut paper) = Estimator::new(SensorConfig::default(), Mode::Paper, reference()) else {
        // Paper mode failing on the rest frame itself is reported by its own test below.
        return;
    };
    match paper.estimate(frame) {
        Ok(reading) => assert_finite(&reading, &format!("{case} (paper mode)")),
        Err(error) => assert!(
            !error.to_string().is_empty(),
            "{case} (paper mode): an error without a reason"
        ),
    }
}

/// A fast-mode reading of `frame` that must locate a single press at `truth_mm` within `tolerance_mm`,
/// or say with a typed error that it cannot.
fn expect_contact_near(
    frame: &RgbImage,
    truth_mm: [f64; 2],
    tolerance_mm: f64,
    case: &str,
) -> Option<Reading> {
    let mut fast = estimator(Mode::Fast);
    match fast.estimate(frame) {
        Ok(reading) => {
            assert_finite(&reading, case);
            assert!(
                reading.contact,
                "{case}: the press was not detected: score {} mm",
                reading.contact_score_mm
            );
            let at = reading
                .contact_mm
                .unwrap_or_else(|| panic!("{case}: contact without a location"));
            let error = distance(at, truth_mm);
            assert!(
                error <= tolerance_mm,
                "{case}: contact at {at:.2?} mm, truth {truth_mm:?} mm: {error:.2} mm off (tolerance {tolerance_mm} mm)"
            );
            assert!(
                reading.force_n > 0.0,
                "{case}: a detected press with force {} N",
                reading.force_n
            );
            paper_mode_survives(frame, case);
            Some(reading)
        }
        Err(error) => {
            assert!(
                is_cannot_estimate(&error),
                "{case}: unexpected error kind: {error}"
            );
            paper_mode_survives(frame, case);
            None
        }
    }
}

/// A fast-mode reading of a frame without any press: no contact, no force, no edge (or a typed error).
fn expect_no_contact(frame: &RgbImage, case: &str) -> Option<Reading> {
    let mut fast = estimator(Mode::Fast);
    let result = fast.estimate(frame);
    paper_mode_survives(frame, case);
    match result {
        Ok(reading) => {
            assert_finite(&reading, case);
            assert!(
                !reading.contact,
                "{case}: contact reported without a press (score {} mm, at {:?} mm)",
                reading.contact_score_mm, reading.contact_mm
            );
            assert_eq!(reading.force_n, 0.0, "{case}: force without contact");
            assert_eq!(
                reading.edge_angle_deg, None,
                "{case}: an edge without contact"
            );
            Some(reading)
        }
        Err(error) => {
            assert!(
                is_cannot_estimate(&error),
                "{case}: unexpected error kind: {error}"
            );
            None
        }
    }
}

fn press(position_mm: [f64; 2], force_n: f64) -> Scene {
    Scene::with_contact(Contact::sphere(5.0, position_mm, force_n))
}

#[test]
fn no_contact_other_noise_seed() {
    let (frame, _) = render(&Scene::rest(), 2);
    let reading =
        expect_no_contact(&frame, "no contact").expect("a clean rest frame must be measurable");
    assert_eq!(
        reading.points_detected, reading.points_expected,
        "all corners of a clean rest frame"
    );
    // Noise alone moves the corners far less than a press: gamma stays well under that of a 6 N press.
    let (pressed, _) = render(&press([0.0, 0.0], 6.0), 2);
    let pressed_gamma = estimator(Mode::Fast).estimate(&pressed).unwrap().gamma;
    assert!(
        reading.gamma < 0.2 * pressed_gamma,
        "rest gamma {} vs pressed {pressed_gamma}",
        reading.gamma
    );
}

#[test]
fn contact_at_the_pad_border() {
    // The pad is 53 x 40 mm: this press sits about one cell from the right and bottom borders.
    let truth = [22.0, 15.5];
    let (frame, _) = render(&press(truth, 6.0), 3);
    expect_contact_near(&frame, truth, 4.0, "contact at the border");
}

#[test]
fn two_contacts() {
    let (left, right) = ([-12.0, 0.0], [12.0, 0.0]);
    let scene = Scene {
        contacts: vec![
            Contact::sphere(5.0, left, 4.0),
            Contact::sphere(5.0, right, 4.0),
        ],
        ..Scene::default()
    };
    let (frame, _) = render(&scene, 4);
    let mut fast = estimator(Mode::Fast);
    match fast.estimate(&frame) {
        Ok(reading) => {
            assert_finite(&reading, "two contacts");
            assert!(reading.contact, "two 4 N presses not detected");
            // One reported location: either press, or between them (the load's centre).
            let at = reading.contact_mm.expect("a location");
            let nearest = [left, right, [0.0, 0.0]]
                .iter()
                .map(|&p| distance(at, p))
                .fold(f64::MAX, f64::min);
            assert!(nearest <= 4.0, "two contacts located at {at:.2?} mm");
            // Two presses shear more of the pad than one of them.
            let (single, _) = render(&press(left, 4.0), 4);
            let single_gamma = estimator(Mode::Fast).estimate(&single).unwrap().gamma;
            assert!(
                reading.gamma > single_gamma,
                "two presses gamma {} <= one press {single_gamma}",
                reading.gamma
            );
        }
        Err(error) => assert!(is_cannot_estimate(&error), "two contacts: {error}"),
    }
    paper_mode_survives(&frame, "two contacts");
}

#[test]
fn torn_pad_missing_ink_in_reference_and_frame() {
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
    let pressed = Scene {
        damage: vec![tear],
        ..press(truth, 6.0)
    };
    let (frame, _) = render(&pressed, 5);
    match Estimator::new(SensorConfig::default(), Mode::Fast, &torn_reference) {
        Ok(mut fast) => {
            assert!(
                fast.reference_lattice().corners_found() < 165,
                "the tear hides some corners"
            );
            match fast.estimate(&frame) {
                Ok(reading) => {
                    assert_finite(&reading, "torn pad");
                    assert!(reading.contact, "torn pad: press not detected");
                    let at = reading.contact_mm.expect("a location");
                    assert!(
                        distance(at, truth) <= LOCATION_TOLERANCE_MM,
                        "torn pad: contact at {at:.2?} mm"
                    );
                    assert!(
                        reading.points_valid < reading.points_expected,
                        "torn corners must be masked"
                    );
                }
                Err(error) => assert!(is_cannot_estimate(&error), "torn pad: {error}"),
            }
        }
        Err(error) => assert!(is_cannot_estimate(&error), "torn reference: {error}"),
    }
}

#[test]
fn torn_pad_after_the_reference_is_not_a_press() {
    // Ink lost (or smeared) since the reference: corners vanish or blur, nothing presses.
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
    if let Some(reading) = expect_no_contact(&frame, "torn after the reference") {
        assert!(
            reading.points_detected < reading.points_expected,
            "the missing ink hides corners"
        );
    }
}

#[test]
fn low_light_leds_at_twenty_percent() {
    let truth = [3.0, -4.0];
    let (dim_rest, _) = render_with(renderer(), &Scene::rest(), [20.0; 4], 7);
    expect_no_contact(&dim_rest, "low light, rest");
    let (dim_press, _) = render_with(renderer(), &press(truth, 6.0), [20.0; 4], 7);
    expect_contact_near(&dim_press, truth, LOCATION_TOLERANCE_MM, "low light, press");
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
    let saturated = frame
        .pixels()
        .filter(|p| p.0.iter().any(|&c| c == 255))
        .count();
    assert!(
        saturated * 5 > frame.pixels().len(),
        "the case needs a saturated frame ({saturated} px at 255)"
    );
    expect_contact_near(&frame, truth, LOCATION_TOLERANCE_MM, "saturation");
}

#[test]
fn extreme_saturation_is_measured_or_refused() {
    // Three times the exposure: yellow clips to white and red to (255, 228, 255); only the green channel keeps
    // a little contrast. A reading must still find the press, or the estimator must say it cannot measure;
    // a confident "no contact" is a silent wrong answer.
    let blinding = Renderer::new(SensorModel {
        exposure: 3.0,
        ..model()
    })
    .unwrap();
    let truth = [-6.0, 5.0];
    let (frame, _) = render_with(&blinding, &press(truth, 6.0), NOMINAL, 8);
    expect_contact_near(&frame, truth, LOCATION_TOLERANCE_MM, "extreme saturation");
}

#[test]
fn heavy_noise() {
    let noisy = Renderer::new(SensorModel {
        noise_sigma: 25.0,
        ..model()
    })
    .unwrap();
    let (rest, _) = render_with(&noisy, &Scene::rest(), NOMINAL, 9);
    expect_no_contact(&rest, "heavy noise, rest");
    let truth = [5.0, 3.0];
    let (frame, _) = render_with(&noisy, &press(truth, 6.0), NOMINAL, 9);
    expect_contact_near(&frame, truth, LOCATION_TOLERANCE_MM, "heavy noise, press");
}

fn moved_camera() -> Renderer {
    let mut moved = model();
    moved.pose.rotation_deg[2] += 3.0;
    moved.pose.shift_mm[0] += 0.8;
    moved.pose.shift_mm[1] -= 0.5;
    Renderer::new(moved).unwrap()
}

#[test]
fn camera_rotated_three_degrees_and_shifted() {
    let moved = moved_camera();
    // A rigid motion of the whole pattern is not a press.
    let (rest, _) = render_with(&moved, &Scene::rest(), NOMINAL, 10);
    expect_no_contact(&rest, "camera moved, rest");
    let truth = [-4.0, 6.0];
    let (frame, _) = render_with(&moved, &press(truth, 6.0), NOMINAL, 10);
    expect_contact_near(&frame, truth, LOCATION_TOLERANCE_MM, "camera moved, press");
}

#[test]
fn partial_occlusion() {
    let occlusion = Occlusion {
        centre_mm: [-15.0, 8.0],
        radius_mm: 6.0,
        colour: [12, 10, 10],
    };
    let truth = [8.0, -2.0];
    let scene = Scene {
        occlusions: vec![occlusion],
        ..press(truth, 6.0)
    };
    let (frame, _) = render(&scene, 11);
    if let Some(reading) =
        expect_contact_near(&frame, truth, LOCATION_TOLERANCE_MM, "partial occlusion")
    {
        assert!(
            reading.points_detected < reading.points_expected,
            "occluded corners cannot be found"
        );
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
    let mut fast = estimator(Mode::Fast);
    match fast.estimate(&frame) {
        Ok(reading) => {
            assert_finite(&reading, "huge force");
            assert!(reading.contact, "huge force: not detected");
            let at = reading.contact_mm.expect("a location");
            // The pad slides under the tangential load, so the shear centre sits off the press; within 2 cells.
            assert!(
                distance(at, truth) <= 2.0 * pitch_mm,
                "huge force: contact at {at:.2?} mm"
            );
            let (moderate, _) = render(&press(truth, 6.0), 12);
            let moderate_gamma = estimator(Mode::Fast).estimate(&moderate).unwrap().gamma;
            assert!(
                reading.gamma > moderate_gamma,
                "huge force gamma {} <= 6 N gamma {moderate_gamma}",
                reading.gamma
            );
        }
        Err(error) => assert!(is_cannot_estimate(&error), "huge force: {error}"),
    }
    paper_mode_survives(&frame, "huge force");
}

#[test]
fn round_contact_has_no_edge_direction_but_an_edge_has_one() {
    let (round, _) = render(
        &Scene::with_contact(Contact::flat_punch(4.0, [0.0, 0.0], 6.0)),
        13,
    );
    let reading = expect_contact_near(&round, [0.0, 0.0], LOCATION_TOLERANCE_MM, "round contact")
        .expect("a central round press is measurable");
    assert_eq!(
        reading.edge_angle_deg, None,
        "a round contact has no direction (confidence {})",
        reading.edge_confidence
    );
    // The contrast case, so that the above cannot pass by never reporting edges.
    let angle = 30.0;
    let (edge, _) = render(
        &Scene::with_contact(Contact::edge(20.0, 1.0, angle, [0.0, 0.0], 8.0)),
        13,
    );
    let reading = estimator(Mode::Fast)
        .estimate(&edge)
        .expect("a central edge press is measurable");
    assert_finite(&reading, "edge contact");
    let found = reading
        .edge_angle_deg
        .unwrap_or_else(|| panic!("no edge direction: {reading:?}"));
    let off = (found - angle).rem_euclid(180.0);
    assert!(
        off.min(180.0 - off) <= 15.0,
        "edge at {found:.1} deg, truth {angle} deg"
    );
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
    // One point repeated: no line.
    let same = samples(&[(1.0, 2.0); 6]);
    assert!(matches!(
        fit_force_line(&same, &options),
        Err(CalibrationError::TooFewPoints { .. })
    ));
    // Two distinct points, each repeated: still not enough to fit and judge a line.
    let two = samples(&[(1.0, 2.0), (1.0, 2.0), (2.0, 5.0), (2.0, 5.0), (1.0, 2.0)]);
    assert!(matches!(
        fit_force_line(&two, &options),
        Err(CalibrationError::TooFewPoints { .. })
    ));
    // Every gamma the same, forces different: the force is not a function of gamma.
    let vertical = samples(&[(1.5, 1.0), (1.5, 2.0), (1.5, 3.0), (1.5, 4.0)]);
    assert!(matches!(
        fit_force_line(&vertical, &options),
        Err(CalibrationError::GammaConstant { .. }) | Err(CalibrationError::TooFewPoints { .. })
    ));
    // Duplicates among good points: the line is still found.
    let mixed = samples(&[
        (1.0, 2.0),
        (1.0, 2.0),
        (2.0, 5.0),
        (3.0, 8.0),
        (3.0, 8.0),
        (4.0, 11.0),
    ]);
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
    // Zero residuals: the robust scale is 0. The fit must give the line and finite (degenerate) intervals.
    let line = samples(&[
        (0.5, 0.405),
        (1.0, 1.95),
        (1.5, 3.495),
        (2.0, 5.04),
        (2.5, 6.585),
    ]);
    let fit =
        fit_force_line(&line, &FitOptions::default()).expect("collinear points are a perfect line");
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
        assert!(
            value.is_finite(),
            "collinear fit: non-finite value in {fit:?}"
        );
    }
    assert!(
        fit.a_interval[0] <= fit.a && fit.a <= fit.a_interval[1],
        "{fit:?}"
    );
    // A non-finite point is named, not fitted.
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
    let surface =
        BSplineSurface::new(net.clone(), 1, 1).expect("degree 1 on 2 x 2 is the bilinear patch");
    // Degree 1 on a 2 x 2 net is bilinear interpolation: u runs along rows (y here), v along columns (x).
    for (u, v) in [(0.0, 0.0), (0.25, 0.5), (1.0, 1.0), (0.7, 0.1)] {
        let p = surface.evaluate(u, v);
        assert!(
            (p[0] - 10.0 * v).abs() < 1e-12 && (p[1] - 20.0 * u).abs() < 1e-12,
            "({u}, {v}) -> {p:?}"
        );
    }
    let grid = surface.sample_grid(0.5).unwrap();
    assert!(grid.points.iter().flatten().all(|v| v.is_finite()));
    // Degree 3 needs 4 points a side: a typed error, not a panic.
    assert!(matches!(
        BSplineSurface::new(net.clone(), 3, 3),
        Err(SurfaceError::DegreeTooHigh { .. })
    ));
    // A missing corner: samples that rest on it say so.
    let holey = ControlNet::from_options(
        2,
        2,
        &[
            Some([0.0, 0.0]),
            None,
            Some([0.0, 20.0]),
            Some([10.0, 20.0]),
        ],
    )
    .unwrap();
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
    // 12 x 16 corners cannot carry degree 20: refused up front, not at the first frame.
    let mut config = SensorConfig::default();
    config.surface = SurfaceConfig {
        degree_u: 20,
        degree_v: 1,
        ..config.surface
    };
    match Estimator::new(config, Mode::Fast, reference()) {
        Ok(_) => panic!("degree 20 on 12 corner rows was accepted"),
        Err(error) => assert!(
            matches!(error, EstimateError::Surface(_) | EstimateError::Config(_)),
            "unexpected error kind: {error}"
        ),
    }
}

#[test]
fn paper_mode_on_the_simulated_rest_frame() {
    // The published pipeline on a clean frame at this size: a reading or a typed reason, never a panic.
    match Estimator::new(SensorConfig::default(), Mode::Paper, reference()) {
        Ok(mut paper) => {
            let (frame, _) = render(&Scene::rest(), 2);
            match paper.estimate(&frame) {
                Ok(reading) => assert_finite(&reading, "paper mode rest"),
                Err(error) => assert!(!error.to_string().is_empty()),
            }
        }
        Err(error) => assert!(!error.to_string().is_empty()),
    }
}
