//! Bad frames and bad configs: typed errors that say what is wrong, never a panic or a NaN.

use std::path::PathBuf;

use image::{imageops, Rgb, RgbImage};
use nusense_estimator::{ConfigError, EstimateError, Estimator, Mode, SensorConfig};

fn quarter_reference() -> RgbImage {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/real");
    let full = image::open(dir.join("reference_fisheye.jpg")).unwrap().to_rgb8();
    imageops::resize(&full, 512, 384, imageops::FilterType::Triangle)
}

#[test]
fn a_frame_of_another_size_is_a_size_mismatch() {
    let reference = quarter_reference();
    let mut estimator = Estimator::new(SensorConfig::default(), Mode::Fast, &reference).unwrap();
    let other = imageops::resize(&reference, 500, 384, imageops::FilterType::Nearest);
    match estimator.estimate(&other) {
        Err(EstimateError::FrameSizeMismatch {
            expected_width: 512,
            expected_height: 384,
            found_width: 500,
            found_height: 384,
        }) => {}
        other => panic!("{other:?}"),
    }
}

#[test]
fn tiny_empty_and_patternless_frames_are_typed_errors() {
    let config = SensorConfig::default();
    assert!(matches!(
        Estimator::new(config.clone(), Mode::Fast, &RgbImage::new(0, 0)),
        Err(EstimateError::FrameTooSmall { .. })
    ));
    assert!(matches!(
        Estimator::new(config.clone(), Mode::Fast, &RgbImage::new(20, 10)),
        Err(EstimateError::FrameTooSmall { .. })
    ));
    let black = RgbImage::new(512, 384);
    assert!(matches!(
        Estimator::new(config.clone(), Mode::Fast, &black),
        Err(EstimateError::NoPattern { .. } | EstimateError::TooFewPoints { .. })
    ));
    // A few yellow squares are not a lattice of the pad.
    let mut few = RgbImage::from_pixel(512, 384, Rgb([150, 40, 90]));
    for (cx, cy) in [(100u32, 100u32), (140, 140), (180, 100)] {
        for y in cy - 12..cy + 12 {
            for x in cx - 12..cx + 12 {
                few.put_pixel(x, y, Rgb([220, 220, 40]));
            }
        }
    }
    assert!(matches!(
        Estimator::new(config, Mode::Fast, &few),
        Err(EstimateError::NoPattern { .. } | EstimateError::TooFewPoints { .. })
    ));
}

#[test]
fn most_of_the_pad_hidden_is_too_few_points() {
    let reference = quarter_reference();
    let mut estimator = Estimator::new(SensorConfig::default(), Mode::Fast, &reference).unwrap();
    let mut hidden = reference.clone();
    for y in 0..384 {
        for x in 0..400 {
            hidden.put_pixel(x, y, Rgb([20, 20, 20]));
        }
    }
    match estimator.estimate(&hidden) {
        Err(EstimateError::TooFewPoints { found, needed }) => assert!(found < needed),
        Err(EstimateError::NoPattern { .. }) => {}
        other => panic!("{other:?}"),
    }
}

#[test]
fn config_errors_name_the_key() {
    let cases = [
        ("[calibration]\nalpha = 0.0\n", "calibration.alpha"),
        ("[surface]\ndegree_u = 11\n", "surface.degree_u"),
        ("[surface]\ndegree_v = 0\n", "surface.degree_v"),
        ("[surface]\nuv_step = -1.0\n", "surface.uv_step"),
        ("[thresholds]\ncontact_shear_mm = -0.1\n", "thresholds.contact_shear_mm"),
        ("[thresholds]\nedge_min_confidence = 1.5\n", "thresholds.edge_min_confidence"),
        ("[roi]\nx = 2000\n", "roi.x"),
        ("[camera]\nwidth = 2048\nheight = 1536\nfx = -1.0\nfy = 2048.0\ncx = 1024.0\ncy = 768.0\ndistortion = [-0.28, 0.07, 0.0, 0.0]\n", "camera.fx"),
        ("[camera]\nwidth = 2048\nheight = 1536\nfx = 2048.0\nfy = 2048.0\ncx = 1024.0\ncy = 768.0\ndistortion = [-3.0, 0.0, 0.0, 0.0]\n", "camera.distortion"),
    ];
    for (text, key) in cases {
        let error = SensorConfig::from_toml_str(text).unwrap_err();
        assert_eq!(error.key(), Some(key), "{text}");
        assert!(error.to_string().contains(key), "{error}");
    }
    // Unknown keys and wrong types are parse errors that quote the key.
    let error = SensorConfig::from_toml_str("[calibration]\nslope = 3.0\n").unwrap_err();
    assert!(
        matches!(error, ConfigError::Parse { .. }) && error.to_string().contains("slope"),
        "{error}"
    );
    let error = SensorConfig::from_toml_str("[surface]\ndegree_u = \"two\"\n").unwrap_err();
    assert!(error.to_string().contains("degree_u"), "{error}");
}

#[test]
fn config_files_name_the_file() {
    let dir = std::env::temp_dir().join(format!("nusense-estimator-config-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("sensor.toml");
    std::fs::write(&path, "[calibration]\na = 2.0\nb = -0.5\n").unwrap();
    let config = SensorConfig::load(&path).unwrap();
    assert_eq!((config.calibration.a, config.calibration.b), (2.0, -0.5));
    std::fs::write(&path, "[force]\na = 2.0\n").unwrap();
    let error = SensorConfig::load(&path).unwrap_err();
    assert!(
        error.to_string().contains("sensor.toml") && error.to_string().contains("force"),
        "{error}"
    );
    let missing = SensorConfig::load(dir.join("missing.toml")).unwrap_err();
    assert!(matches!(missing, ConfigError::Io { .. }));
    std::fs::remove_dir_all(&dir).unwrap();
}
