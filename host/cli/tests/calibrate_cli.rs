//! `nusense calibrate` end to end: files in, fit out, config updated in place.

use std::process::Command;

use nusense_estimator::calibration::push_normal::corrected_normal_n;

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

/// What a push adds to the model's normal force in [`push_session`]'s references: this times the push squared over the
/// normal force (`calibration::push_normal`).
const TRUE_SHARE: f64 = 0.12;
/// Reference normal force per N of the model's (the modulus fit's scale) in [`push_session`].
const NORMAL_SCALE: f64 = 0.75;
/// The model's force vectors [fx, fy, fz] (before the tangential scale and the share): plain presses, then pushes of
/// a quarter to nearly half their load.
const PRESSES: [[f64; 3]; 5] = [
    [0.0, 0.0, 2.0],
    [0.0, 0.0, 3.5],
    [0.0, 0.0, 5.0],
    [0.0, 0.0, 6.5],
    [0.0, 0.0, 8.0],
];
const PUSHES: [[f64; 3]; 3] = [[1.5, 0.0, 4.0], [0.0, -1.2, 5.0], [0.9, 1.2, 3.5]];

/// A session of inverse-mode readings of `model` force vectors as the estimator reports them with a tangential force
/// scale of `scale` and a push normal share of `share` (the normal force less `share` times the push squared over it,
/// fx and fy times `scale`), and its force/torque log (the force on the sensor, fz down): each reference normal force
/// is [`NORMAL_SCALE`] times the model's less what [`TRUE_SHARE`] says its push added, held for +-0.1 s around its
/// reading.
fn push_session(dir: &std::path::Path, model: &[[f64; 3]], scale: f64, share: f64) -> [std::path::PathBuf; 2] {
    let time_of = |k: usize| 1.0 + 0.5 * k as f64;
    let mut lines = String::new();
    let mut references = Vec::new();
    for (k, &[fx, fy, fz]) in model.iter().enumerate() {
        let force_n = corrected_normal_n([fx, fy, fz], share);
        let reference = [
            0.6 * fx,
            0.6 * fy,
            NORMAL_SCALE * corrected_normal_n([fx, fy, fz], TRUE_SHARE),
        ];
        let gamma = reference[2] / 3.0;
        lines += &format!(
            "{{\"schema_version\":1,\"frame_id\":{k},\"capture_time_us\":{},\"estimate\":{{\"mode\":\"inverse\",\
             \"contact\":true,\"gamma\":{gamma},\"force_n\":{force_n},\"force_vector_n\":[{},{},{force_n}]}}}}\n",
            (time_of(k) * 1e6).round() as u64,
            scale * fx,
            scale * fy
        );
        references.push(reference);
    }
    let mut log = String::from("timestamp,fx,fy,fz\n");
    for i in 0..(time_of(model.len()) * 200.0) as usize {
        let t = i as f64 / 200.0;
        let held = (0..model.len()).find(|&k| (t - time_of(k)).abs() <= 0.1);
        let [fx, fy, fz] = held.map_or([0.0; 3], |k| references[k]);
        log += &format!("{t},{fx},{fy},{}\n", -fz);
    }
    let paths = [dir.join("readings.jsonl"), dir.join("ft.csv")];
    std::fs::write(&paths[0], lines).unwrap();
    std::fs::write(&paths[1], log).unwrap();
    paths
}

/// `nusense calibrate ARGS... --readings READINGS --ft-log LOG --config CONFIG`, which must succeed; its stdout.
fn calibrate_session(args: &[&str], [readings, log]: &[std::path::PathBuf; 2], config: &std::path::Path) -> String {
    let out = nusense()
        .arg("calibrate")
        .args(args)
        .arg("--readings")
        .arg(readings)
        .arg("--ft-log")
        .arg(log)
        .arg("--config")
        .arg(config)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).unwrap()
}

/// Pushes that read their normal force too high by a share of their push fit that share, from readings made with no
/// share and with another share and tangential scale already set (their normal force gets its share back, their push
/// is taken in the model's terms), and it is written into the config.
#[test]
fn a_sessions_pushes_fit_the_share_of_their_push_read_as_normal_force() {
    let model: Vec<[f64; 3]> = PRESSES.iter().chain(&PUSHES).copied().collect();
    for (share, scale) in [(0.0, 1.0), (0.3, 2.5)] {
        let dir = tempfile::tempdir().unwrap();
        let session = push_session(dir.path(), &model, scale, share);
        let config = dir.path().join("sensor.toml");
        std::fs::write(
            &config,
            format!("# bench sensor\n[elastic]\npush_normal_share = {share}\ntangential_force_scale = {scale}\n"),
        )
        .unwrap();
        let report: serde_json::Value =
            serde_json::from_str(&calibrate_session(&["--json"], &session, &config)).unwrap();
        // The presses are most of the session and read exactly: the modulus fit's scale is theirs.
        assert_eq!(report["modulus"]["scale"], NORMAL_SCALE, "{report}");
        let push_normal = &report["push_normal"];
        assert!(report["push_normal_left_alone"].is_null(), "{report}");
        assert_eq!(push_normal["pushes"], PUSHES.len(), "{report}");
        assert_eq!(push_normal["push_normal_share_before"], share, "{report}");
        let fitted = push_normal["push_normal_share"].as_f64().unwrap();
        assert!(
            (fitted - TRUE_SHARE).abs() < 1e-9,
            "from share {share}, scale {scale}: {fitted}"
        );
        let written = nusense_estimator::SensorConfig::load(&config).unwrap();
        // serde_json parses floats to within an ulp or so (no `float_roundtrip`): the report's value is not bit for
        // bit the one written.
        assert!((written.elastic.push_normal_share - fitted).abs() < 1e-12, "{fitted}");
        assert!(std::fs::read_to_string(&config).unwrap().starts_with("# bench sensor"));
    }
}

/// A session of plain presses, or with one push, leaves `elastic.push_normal_share` as it was and says why; the
/// normal calibrations still stand.
#[test]
fn a_session_without_pushes_leaves_the_push_normal_share_alone() {
    let original = "# bench sensor\n[elastic]\npush_normal_share = 0.05\n";
    for (model, found) in [
        (PRESSES.to_vec(), 0),
        (PRESSES.iter().chain(&PUSHES[..1]).copied().collect::<Vec<_>>(), 1),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let session = push_session(dir.path(), &model, 1.0, 0.05);
        let config = dir.path().join("sensor.toml");
        std::fs::write(&config, original).unwrap();
        let report: serde_json::Value =
            serde_json::from_str(&calibrate_session(&["--json"], &session, &config)).unwrap();
        assert!(
            report["push_normal"].is_null() && report["modulus"].is_object(),
            "{report}"
        );
        let why = report["push_normal_left_alone"].as_str().unwrap();
        assert_eq!(
            why,
            format!("{found} inverse-mode readings pushed by a tenth of their load or more, 2 needed")
        );
        let written = nusense_estimator::SensorConfig::load(&config).unwrap();
        assert_eq!(written.elastic.push_normal_share, 0.05);
        assert_eq!(
            written.elastic.shear_modulus_kpa,
            report["modulus"]["shear_modulus_kpa"]
        );
        std::fs::write(&config, original).unwrap();
        let text = calibrate_session(&["--dry-run"], &session, &config);
        assert!(
            text.contains(&format!(
                "push normal share: {why}; elastic.push_normal_share left at 0.0500"
            )),
            "{text}"
        );
        assert_eq!(std::fs::read_to_string(&config).unwrap(), original);
    }
}
