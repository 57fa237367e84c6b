//! The simulated sensor's shipped configuration (`nusense_sim::SENSOR_CONFIG_TOML`, what `serve --sim` estimates
//! with): fitted again here as a user calibrates a sensor, so it cannot drift from the simulator.

use std::sync::OnceLock;

use image::RgbImage;
use nusense_estimator::calibration::{fit_force_line, CalibrationSample, FitOptions};
use nusense_estimator::{Estimator, Mode, Reading, SensorConfig};
use nusense_sim::{Contact, Renderer, Scene, SensorModel, SENSOR_CONFIG_TOML};

/// The daemon's default simulated frame size.
const WIDTH: u32 = 640;
const HEIGHT: u32 = 480;
const NOMINAL: [f32; 4] = [100.0; 4];
/// The calibration presses: 5 mm sphere at the centre over the paper's range.
const CALIBRATION_N: [f64; 8] = [1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0];

fn renderer() -> &'static Renderer {
    static RENDERER: OnceLock<Renderer> = OnceLock::new();
    RENDERER.get_or_init(|| Renderer::new(SensorModel::real(WIDTH, HEIGHT)).expect("the real sensor model is valid"))
}

fn rest() -> &'static RgbImage {
    static FRAME: OnceLock<RgbImage> = OnceLock::new();
    FRAME.get_or_init(|| renderer().render(&Scene::rest(), NOMINAL, 1).expect("rest renders").0)
}

fn press(position_mm: [f64; 2], force_n: f64, seed: u64) -> RgbImage {
    let scene = Scene::with_contact(Contact::sphere(5.0, position_mm, force_n));
    renderer().render(&scene, NOMINAL, seed).expect("the press renders").0
}

fn shipped() -> SensorConfig {
    SensorConfig::from_toml_str(SENSOR_CONFIG_TOML).expect("the shipped configuration parses")
}

fn readings(config: &SensorConfig, mode: Mode, forces: &[f64], position_mm: [f64; 2]) -> Vec<Reading> {
    let mut estimator = Estimator::new(config.clone(), mode, rest()).expect("the rest frame is measurable");
    forces
        .iter()
        .enumerate()
        .map(|(i, &f)| {
            estimator
                .estimate(&press(position_mm, f, 10 + i as u64))
                .expect("a press is measurable")
        })
        .collect()
}

#[test]
fn the_shipped_calibration_is_what_the_simulators_presses_give() {
    let shipped = shipped();
    // The line, fitted by `nusense calibrate`'s fit on the gamma the fast mode measures.
    let fast = readings(&shipped, Mode::Fast, &CALIBRATION_N, [0.0, 0.0]);
    let samples: Vec<CalibrationSample> = fast
        .iter()
        .zip(CALIBRATION_N)
        .map(|(r, force_n)| CalibrationSample {
            gamma: r.gamma.gamma,
            force_n,
        })
        .collect();
    let fit = fit_force_line(&samples, &FitOptions::default()).expect("the presses give a line");
    assert!(
        (fit.a / shipped.calibration.a - 1.0).abs() < 0.03 && (fit.b - shipped.calibration.b).abs() < 0.1,
        "fitted F = {:.3} gamma {:+.3}, shipped {} gamma {:+}",
        fit.a,
        fit.b,
        shipped.calibration.a,
        shipped.calibration.b
    );
    // The inverse's modulus: true over reported force, least squares through the origin.
    let inverse = readings(&shipped, Mode::Inverse, &CALIBRATION_N, [0.0, 0.0]);
    let (tr, rr) = inverse.iter().zip(CALIBRATION_N).fold((0.0, 0.0), |(tr, rr), (r, f)| {
        (tr + f * r.force_n(), rr + r.force_n().powi(2))
    });
    assert!(
        (tr / rr - 1.0).abs() < 0.03,
        "the inverse reads the presses {:.3}x their force with the shipped modulus",
        rr / tr
    );
    // So each press reads its force in both modes.
    for ((f, fast), inverse) in CALIBRATION_N.iter().zip(&fast).zip(&inverse) {
        assert!(fast.is_contact() && inverse.is_contact(), "{f} N: no contact");
        assert!(
            (fast.force_n() - f).abs() < 0.1 * f + 0.1,
            "fast reads {f} N as {:.2} N",
            fast.force_n()
        );
        assert!(
            (inverse.force_n() - f).abs() < 0.15 * f + 0.1,
            "the inverse reads {f} N as {:.2} N",
            inverse.force_n()
        );
    }
}
