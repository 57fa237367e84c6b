//! `nusense analyze` as a user runs it on the real pair: one reading message per frame, in the default mode unless
//! `--mode` says otherwise, with the README's figures for that pair.

use std::path::PathBuf;
use std::process::Command;

use serde_json::Value;

fn real_frames() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../estimator/tests/data/real")
}

/// The estimate of each frame, from `analyze --json` run with `args` before the frames.
fn analyze(args: &[&str]) -> Vec<Value> {
    let dir = real_frames();
    let out = Command::new(env!("CARGO_BIN_EXE_nusense"))
        .arg("analyze")
        .args(args)
        .arg("--json")
        .arg("--reference")
        .arg(dir.join("reference_fisheye.jpg"))
        .arg(dir.join("touch_fisheye.jpg"))
        .output()
        .expect("nusense runs");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|line| serde_json::from_str::<Value>(line).expect("one JSON message per line")["estimate"].clone())
        .collect()
}

fn numbers(array: &Value) -> Vec<f64> {
    array
        .as_array()
        .expect("an array")
        .iter()
        .map(|v| v.as_f64().expect("a number"))
        .collect()
}

#[test]
fn analyze_measures_the_real_press_in_the_same_default_mode_as_serve() {
    let readings = analyze(&[]);
    assert_eq!(readings.len(), 1, "one message for the one frame");
    let touch = &readings[0];
    // The same default as `serve` and `replay` (Mode::default), not a default of its own.
    assert_eq!(touch["mode"], nusense_estimator::Mode::default().to_string());
    assert_eq!(touch["mode"], "inverse");
    assert_eq!(touch["contact"], true);
    // The README's figures for this pair: contact about 3 mm left of and 2.4 mm below the pad's centre, a force
    // vector along the normal from the uncalibrated pad model, no edge for a round tip. (8.96 N at (-3.11, 2.32) mm
    // before the model saw the parallax of the pattern's normal displacement; 9.09 N, gamma 0.753, before 64b24df left
    // the camera's motion (a 0.9 px shift and a scale of 1.003 here) to stage 1's homography of the pad plane; 9.00 N
    // at (-3.08, 2.39) mm, gamma 0.744, before the tracker counted a pixel clipped in red and green as yellow ink.)
    let contact_mm = numbers(&touch["contact_mm"]);
    assert!(
        (contact_mm[0] + 3.00).abs() < 0.05 && (contact_mm[1] - 2.40).abs() < 0.05,
        "{contact_mm:?}"
    );
    let force = numbers(&touch["force_vector_n"]);
    assert!((force[2] - 8.98).abs() < 0.05, "{force:?}");
    assert!(force[0].hypot(force[1]) < 0.05 * force[2], "a normal press: {force:?}");
    assert_eq!(touch["force_n"].as_f64().unwrap(), force[2]);
    assert!(touch["edge"].is_null());
}

#[test]
fn analyze_in_fast_mode_gives_the_papers_line_on_gamma() {
    let readings = analyze(&["--mode", "fast"]);
    let touch = &readings[0];
    assert_eq!(touch["mode"], "fast");
    let gamma = touch["gamma"].as_f64().unwrap();
    assert!((gamma - 0.731).abs() < 0.005, "{gamma}");
    let force = touch["force_n"].as_f64().unwrap();
    assert!(
        (force - (3.09 * gamma - 1.14)).abs() < 1e-9,
        "F = 3.09 gamma - 1.14: {force} for gamma {gamma}"
    );
    assert!(
        touch["force_vector_n"].is_null(),
        "the gamma modes give no force vector"
    );
}
