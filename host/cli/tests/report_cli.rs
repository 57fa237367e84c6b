//! `nusense sim session` and `nusense report` end to end, as a user runs them: the real binary writes a short
//! simulated session (MCAP through the daemon's recorder, the F/T log, the ground truth), then reports on it;
//! the report's figures are checked against the session's truth.

use std::collections::HashMap;
use std::path::Path;
use std::process::Command;

use nusense_estimator::calibration::{fit_force_line, CalibrationSample, FitOptions};
use serde_json::Value;

fn nusense() -> Command {
    Command::new(env!("CARGO_BIN_EXE_nusense"))
}

/// Runs `nusense ARGS`, which must succeed, and parses what it printed as JSON.
fn run_json(args: &[&str], paths: &[&Path]) -> Value {
    let mut command = nusense();
    command.args(args);
    for path in paths {
        command.arg(path);
    }
    let out = command.output().unwrap();
    assert!(
        out.status.success(),
        "nusense {args:?} {paths:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "nusense {args:?}: not JSON ({e}): {}",
            String::from_utf8_lossy(&out.stdout)
        )
    })
}

/// `nusense sim session KIND --out DIR --json`: the truth it printed, after checking it matches truth.json.
fn session(kind: &str, dir: &Path) -> Value {
    let printed = run_json(&["sim", "session", kind, "--json", "--out"], &[dir]);
    let written: Value = serde_json::from_str(&std::fs::read_to_string(dir.join("truth.json")).unwrap()).unwrap();
    assert_eq!(printed, written);
    printed
}

fn number(value: &Value) -> f64 {
    value.as_f64().unwrap_or_else(|| panic!("not a number: {value}"))
}

#[test]
fn calibration_report_finds_the_sessions_clock_offset_and_force_line() {
    let dir = tempfile::tempdir().unwrap();
    let truth = session("calibration", dir.path());
    let recording = dir.path().join("session.mcap");
    let out = dir.path().join("report");
    let report = run_json(
        &["report", "calibration", "--json"],
        &[
            &recording,
            Path::new("--ft"),
            &dir.path().join("ft.csv"),
            Path::new("--out"),
            &out,
        ],
    );
    let result = &report["result"];

    let offset = number(&result["clock"]["offset_s"]);
    let true_offset = number(&truth["ft_offset_s"]);
    let frame = number(&truth["frame_interval_s"]);
    assert!(
        (offset - true_offset).abs() < frame,
        "offset {offset} s, truth {true_offset} s"
    );

    // The line this session really has: each recorded reading's gamma against the force applied at its frame.
    let applied: HashMap<u64, f64> = truth["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| (f["frame_id"].as_u64().unwrap(), number(&f["applied_n"])))
        .collect();
    let (readings, _) = nusense_experiments::load_readings(&recording).unwrap();
    let min_force = number(&result["min_force_n"]);
    let exact: Vec<CalibrationSample> = readings
        .iter()
        .map(|r| CalibrationSample {
            gamma: r.gamma,
            force_n: applied[&r.frame_id],
        })
        .filter(|s| s.force_n >= min_force)
        .collect();
    let true_line = fit_force_line(&exact, &FitOptions::default()).unwrap();
    let slope = number(&result["fit"]["a"]);
    let intercept = number(&result["fit"]["b"]);
    eprintln!(
        "offset {offset:.4} s (truth {true_offset}), a {slope:.4} (truth {:.4}), b {intercept:.4} (truth {:.4})",
        true_line.a, true_line.b
    );
    assert!(
        (slope - true_line.a).abs() < 0.03 * true_line.a,
        "slope {slope} against {}",
        true_line.a
    );
    // Over the fitted range the two lines agree to well under the F/T noise's effect on a single pair.
    for force in [min_force, 8.0] {
        let gamma = (force - true_line.b) / true_line.a;
        let gap = (slope * gamma + intercept - force).abs();
        assert!(gap < 0.15, "the fitted line is {gap} N off the true one at {force} N");
    }

    // What the user gets on disk: the Markdown with its plots next to it, and the JSON that was printed.
    let markdown = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(markdown.contains(&format!("{offset:+.4} s")), "{markdown}");
    for plot in markdown.split("](").skip(1).filter_map(|s| s.split(')').next()) {
        let svg = std::fs::read_to_string(out.join(plot)).unwrap_or_else(|e| panic!("{plot}: {e}"));
        assert!(svg.starts_with("<svg"), "{plot}");
    }
    let written: Value = serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(written, report);
}

#[test]
fn repeatability_report_counts_the_sessions_touches_where_they_were() {
    let dir = tempfile::tempdir().unwrap();
    let truth = session("repeatability", dir.path());
    let out = dir.path().join("report");
    let report = run_json(
        &["report", "repeatability", "--json"],
        &[&dir.path().join("session.mcap"), Path::new("--out"), &out],
    );
    let touches = report["result"]["touches"].as_array().unwrap();
    let true_touches = truth["touches"].as_array().unwrap();
    assert_eq!(touches.len(), true_touches.len());
    for (found, truth) in touches.iter().zip(true_touches) {
        let p = [number(&found["position_mm"][0]), number(&found["position_mm"][1])];
        let t = [number(&truth["position_mm"][0]), number(&truth["position_mm"][1])];
        let error = (p[0] - t[0]).hypot(p[1] - t[1]);
        eprintln!("touch at {p:.3?}, truth {t:.3?}: {error:.3} mm");
        assert!(error < 0.6, "{p:?} against {t:?}");
    }
    // The script moves the touches along x: the report's drift follows the scripted one.
    let xs: Vec<f64> = true_touches.iter().map(|t| number(&t["position_mm"][0])).collect();
    let n = xs.len() as f64;
    let (mean_k, mean_x) = ((n - 1.0) / 2.0, xs.iter().sum::<f64>() / n);
    let true_drift = xs
        .iter()
        .enumerate()
        .map(|(k, x)| (k as f64 - mean_k) * (x - mean_x))
        .sum::<f64>()
        / (0..xs.len()).map(|k| (k as f64 - mean_k).powi(2)).sum::<f64>();
    let drift = number(&report["result"]["position_x_mm"]["drift_per_touch"]);
    eprintln!("x drift {drift:.4} mm per touch (truth {true_drift:.4})");
    assert!((drift - true_drift).abs() < 0.1, "{drift} against {true_drift}");
}
