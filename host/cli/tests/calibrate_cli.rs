//! `nusense calibrate` end to end: files in, fit out, config updated in place.

use std::process::Command;

fn nusense() -> Command {
    Command::new(env!("CARGO_BIN_EXE_nusense"))
}

/// A `--pairs` file of (gamma, force) rows, as a user exports it.
fn pairs_file(path: &std::path::Path, pairs: impl IntoIterator<Item = (f64, f64)>) {
    let mut csv = String::from("gamma,force_n\n");
    for (gamma, force) in pairs {
        csv += &format!("{gamma},{force}\n");
    }
    std::fs::write(path, csv).unwrap();
}

#[test]
fn fits_pairs_and_writes_the_config_keeping_other_keys() {
    let dir = tempfile::tempdir().unwrap();
    let pairs = dir.path().join("pairs.csv");
    // F = 2.5 gamma - 0.4 with small deterministic wiggle, and one slipped measurement.
    pairs_file(
        &pairs,
        (0..30).map(|i| {
            let gamma = 0.3 + 0.1 * f64::from(i);
            let wiggle = 0.02 * ((f64::from(i) * 2.399).sin());
            let force = if i == 17 { 9.0 } else { 2.5 * gamma - 0.4 + wiggle };
            (gamma, force)
        }),
    );
    let config = dir.path().join("sensor.toml");
    std::fs::write(&config, "# bench sensor\n[surface]\ndegree_u = 2\n").unwrap();

    let out = nusense()
        .args(["calibrate", "--json", "--pairs"])
        .arg(&pairs)
        .arg("--config")
        .arg(&config)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let a = report["a"].as_f64().unwrap();
    let b = report["b"].as_f64().unwrap();
    assert!((a - 2.5).abs() < 0.03 && (b + 0.4).abs() < 0.06, "{report}");
    assert_eq!(report["outliers"], 1);
    let lo = report["a_interval"][0].as_f64().unwrap();
    let hi = report["a_interval"][1].as_f64().unwrap();
    assert!(lo < a && a < hi);

    let written = std::fs::read_to_string(&config).unwrap();
    assert!(
        written.contains("# bench sensor") && written.contains("degree_u = 2"),
        "{written}"
    );
    let parsed = nusense_estimator::SensorConfig::from_toml_str(&written).unwrap();
    assert_eq!((parsed.calibration.a, parsed.calibration.b), (a, b));
}

#[test]
fn aligns_a_session_with_a_force_log() {
    let dir = tempfile::tempdir().unwrap();
    let readings = dir.path().join("readings.jsonl");
    let log = dir.path().join("ft.csv");
    // The F/T log runs at 1 kHz on its own clock, 0.25 s behind the readings' clock.
    let mut ft = String::from("timestamp_us,fx,fy,fz,tx,ty,tz\n");
    for ms in 0..3000 {
        let t = f64::from(ms) / 1e3;
        let force = 1.0 + 2.0 * (t * 1.7).sin().abs();
        ft += &format!("{},0.01,0.02,{},0,0,0\n", ms * 1000, -force);
    }
    std::fs::write(&log, ft).unwrap();
    let mut lines = String::new();
    for k in 0..50 {
        let t_log = 0.05 + 0.055 * f64::from(k);
        let force = 1.0 + 2.0 * (t_log * 1.7).sin().abs();
        let gamma = (force + 1.14) / 3.09;
        lines += &format!(
            "{{\"frame\":\"f{k}.jpg\",\"ok\":true,\"gamma\":{gamma},\"timestamp_s\":{}}}\n",
            t_log + 0.25
        );
    }
    lines += "{\"frame\":\"bad.jpg\",\"ok\":false,\"error\":\"no pattern\",\"gamma\":null}\n";
    std::fs::write(&readings, lines).unwrap();

    let out = nusense()
        .args(["calibrate", "--json", "--time-offset-s", "0.25", "--readings"])
        .arg(&readings)
        .arg("--ft-log")
        .arg(&log)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!((report["a"].as_f64().unwrap() - 3.09).abs() < 0.01, "{report}");
    assert!((report["b"].as_f64().unwrap() + 1.14).abs() < 0.01, "{report}");
    assert_eq!(report["readings_dropped"], 1);
    assert_eq!(report["points"], 50);
}

#[test]
fn degenerate_or_missing_input_fails_with_a_reason() {
    let dir = tempfile::tempdir().unwrap();
    let pairs = dir.path().join("flat.csv");
    std::fs::write(&pairs, "gamma,force\n1,1\n1,2\n1,3\n").unwrap();
    let out = nusense().args(["calibrate", "--pairs"]).arg(&pairs).output().unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("gamma does not vary"));
    let out = nusense().args(["calibrate"]).output().unwrap();
    assert!(!out.status.success());
    let out = nusense()
        .args(["calibrate", "--pairs", "/nonexistent/pairs.csv"])
        .output()
        .unwrap();
    assert!(!out.status.success());
}

#[test]
fn a_line_that_falls_with_gamma_is_not_written_into_the_config() {
    let dir = tempfile::tempdir().unwrap();
    let pairs = dir.path().join("falling.csv");
    pairs_file(
        &pairs,
        (0..20).map(|i| {
            let gamma = 0.2 + 0.1 * f64::from(i);
            (gamma, 6.0 - 1.5 * gamma)
        }),
    );
    let config = dir.path().join("sensor.toml");
    let original = "# bench sensor\n[calibration]\na = 7.5\nb = -0.2\n";
    std::fs::write(&config, original).unwrap();
    let out = nusense()
        .args(["calibrate", "--pairs"])
        .arg(&pairs)
        .arg("--config")
        .arg(&config)
        .output()
        .unwrap();
    assert!(!out.status.success(), "a falling line was accepted");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("does not rise with gamma"), "{stderr}");
    assert_eq!(
        std::fs::read_to_string(&config).unwrap(),
        original,
        "the config was changed"
    );
    // --dry-run still shows the fit, and writes nothing.
    let out = nusense()
        .args(["calibrate", "--json", "--dry-run", "--pairs"])
        .arg(&pairs)
        .arg("--config")
        .arg(&config)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!((report["a"].as_f64().unwrap() + 1.5).abs() < 0.01, "{report}");
    assert_eq!(std::fs::read_to_string(&config).unwrap(), original);
}

#[test]
fn a_malformed_probe_position_in_the_log_fails_with_its_line_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let readings = dir.path().join("readings.jsonl");
    let log = dir.path().join("ft.csv");
    let mut ft = String::from("timestamp,fx,fy,fz,x_mm,y_mm\n");
    let mut lines = String::new();
    for k in 0..20 {
        let t = 0.1 * f64::from(k);
        let force = 1.0 + 0.2 * f64::from(k);
        let x = if k == 7 { "abc".to_string() } else { "1.5".to_string() };
        ft += &format!("{t},0,0,{force},{x},-2\n");
        lines += &format!("{{\"ok\":true,\"gamma\":{},\"t\":{t}}}\n", (force + 1.14) / 3.09);
    }
    std::fs::write(&log, ft).unwrap();
    std::fs::write(&readings, lines).unwrap();
    let config = dir.path().join("sensor.toml");
    std::fs::write(&config, "# untouched\n").unwrap();
    let out = nusense()
        .args(["calibrate", "--readings"])
        .arg(&readings)
        .arg("--ft-log")
        .arg(&log)
        .arg("--config")
        .arg(&config)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("line 9") && stderr.contains("x_mm") && !stderr.contains("panicked"),
        "{stderr}"
    );
    assert_eq!(std::fs::read_to_string(&config).unwrap(), "# untouched\n");
}
