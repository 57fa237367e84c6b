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
        // The session measures with the simulated sensor's own calibration, so its peaks are in newtons of the
        // force applied (the real sensor's default line read these 6 N touches as 1.3 N).
        let (peak, true_peak) = (number(&found["peak_force_n"]), number(&truth["peak_n"]));
        eprintln!("peak {peak:.3} N, truth {true_peak:.3} N");
        assert!(
            (peak - true_peak).abs() < 0.15 * true_peak,
            "peak {peak} N against {true_peak} N"
        );
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

/// The loop of `pairs` (reference force, value) as the report measures it, % of the values' full scale.
fn loop_percent(pairs: &[(f64, f64)]) -> f64 {
    nusense_experiments::hysteresis::cycles(pairs)
        .iter()
        .map(|c| c.hysteresis_percent)
        .fold(0.0, f64::max)
}

#[test]
fn hysteresis_report_measures_the_loop_the_viscoelastic_pad_traces() {
    let dir = tempfile::tempdir().unwrap();
    let truth = session("hysteresis", dir.path());
    let frames = truth["frames"].as_array().unwrap();
    // The loop the pad itself traces: its deformation (as a force) against the applied force.
    let pad_loop: Vec<(f64, f64)> = frames
        .iter()
        .map(|f| (number(&f["applied_n"]), number(&f["deformation_n"])))
        .collect();
    let pad_percent = loop_percent(&pad_loop);
    assert!(
        pad_percent > 10.0,
        "the session injects a visible loop: {pad_percent} %"
    );

    let recording = dir.path().join("session.mcap");
    let ft = dir.path().join("ft.csv");
    let offset = format!("{}", number(&truth["ft_offset_s"]));
    let report = run_json(
        &["report", "hysteresis", "--json", "--clock-offset", &offset, "--ft"],
        &[&ft, &recording, Path::new("--out"), &dir.path().join("report")],
    );
    let result = &report["result"];
    let measured = number(&result["max_percent"]);
    let cycles = result["cycles"].as_array().unwrap().len();
    eprintln!("hysteresis {measured:.2} % of full scale (the pad's loop {pad_percent:.2} %), {cycles} cycles");
    assert_eq!(cycles, nusense_experiments::hysteresis::cycles(&pad_loop).len());
    assert!(
        (measured - pad_percent).abs() < 2.0,
        "{measured} % against the pad's {pad_percent} %"
    );

    // Without the rig's clock offset the report cross-correlates, which takes the pad's lag for clock offset:
    // the offset comes out early by that lag and the loop shrinks, and the report says so.
    let correlated = run_json(
        &["report", "hysteresis", "--json", "--ft"],
        &[&ft, &recording, Path::new("--out"), &dir.path().join("correlated")],
    );
    let found = number(&correlated["result"]["clock_offset_s"]);
    let shrunk = number(&correlated["result"]["max_percent"]);
    eprintln!("cross-correlated: offset {found:.4} s (truth {offset}), hysteresis {shrunk:.2} %");
    assert!(found < number(&truth["ft_offset_s"]) - 0.02, "{found}");
    assert!(shrunk < measured - 5.0, "{shrunk} against {measured}");
    let markdown = std::fs::read_to_string(dir.path().join("correlated/report.md")).unwrap();
    assert!(markdown.contains("lower bound"), "{markdown}");
}

#[test]
fn damage_report_counts_the_lattice_points_the_missing_ink_costs() {
    use nusense_experiments::session::{ink_kept, DAMAGE_CENTRE_MM, DAMAGE_RADIUS_MM, MIN_INK_FOUND};

    let dir = tempfile::tempdir().unwrap();
    let truth = session("damage", dir.path());
    let report = run_json(
        &["report", "damage", "--json", "--intact"],
        &[
            &dir.path().join("intact.mcap"),
            &dir.path().join("damaged.mcap"),
            Path::new("--out"),
            &dir.path().join("report"),
        ],
    );
    let result = &report["result"];
    let lost = number(&result["points_lost"]);
    let true_lost = truth["damage"]["corners_lost"].as_u64().unwrap() as f64;
    let in_disc = truth["damage"]["corners_in_disc"].as_u64().unwrap() as f64;
    eprintln!("lost {lost} lattice points (truth {true_lost}; {in_disc} corners lie inside the disc)");
    assert_eq!(number(&result["intact"]["points_detected"]), 165.0);
    assert_eq!(lost, true_lost);
    assert_eq!(
        result["touches"].as_array().unwrap().len(),
        truth["touches"].as_array().unwrap().len()
    );

    // The truth does not hinge on the detector's exact ink threshold: every square the disc reaches is either
    // (nearly) gone or keeps most of its ink. And it tells the corner rule from the disc's: 7 corners go where
    // the disc holds 6, as two whole squares take their corners beyond the disc with them.
    let model = nusense_sim::SensorModel::real(160, 120);
    let reached: Vec<f64> = model
        .pad
        .yellow_squares()
        .map(|s| ink_kept(&model, s, DAMAGE_CENTRE_MM, DAMAGE_RADIUS_MM))
        .filter(|&k| k < 1.0)
        .collect();
    assert!(reached.iter().all(|k| !(0.05..=0.65).contains(k)), "{reached:?}");
    assert_eq!(reached.iter().filter(|&&k| k < MIN_INK_FOUND).count(), 2, "{reached:?}");
    assert_eq!((true_lost, in_disc), (7.0, 6.0));
}

#[test]
fn a_lattice_point_goes_with_either_of_its_two_yellow_squares() {
    use nusense_experiments::session::corners_lost;

    let model = nusense_sim::SensorModel::real(160, 120);
    // The yellow square nearest the pad's centre, and a disc that just covers it: its four corners go, though
    // they lie just outside the disc, and no other (the diagonal squares' ink starts further out).
    let square = model
        .pad
        .yellow_squares()
        .min_by(|&a, &b| {
            let r = |s| {
                let p = model.pad.square_centre_mm(s);
                p[0].hypot(p[1])
            };
            r(a).total_cmp(&r(b))
        })
        .unwrap();
    let centre = model.pad.square_centre_mm(square);
    let half_diagonal = 0.5 * model.yellow_fill * model.pad.pitch_x_mm().hypot(model.pad.pitch_y_mm());
    assert_eq!(corners_lost(&model, centre, half_diagonal + 0.01), 4);
    // A speck of missing ink costs nothing: the square's centroid is still found.
    assert_eq!(corners_lost(&model, centre, 0.3), 0);
}

#[test]
fn localisation_report_locates_each_touch_where_the_estimator_saw_its_hold() {
    let dir = tempfile::tempdir().unwrap();
    let truth = session("localisation", dir.path());
    let recording = dir.path().join("session.mcap");
    let report = run_json(
        &["report", "localisation", "--json", "--targets"],
        &[
            &dir.path().join("targets.csv"),
            &recording,
            Path::new("--out"),
            &dir.path().join("report"),
        ],
    );
    let found = report["result"]["targets"].as_array().unwrap();
    let touches = truth["touches"].as_array().unwrap();
    assert_eq!(found.len(), touches.len());
    assert_eq!(report["result"]["unlocated"], 0);

    // The estimator's contacts over the frames where the full force was applied (the truth's hold): the report
    // must give each touch that location, whatever the estimator's own error against the target.
    let (readings, _) = nusense_experiments::load_readings(&recording).unwrap();
    let frames: HashMap<u64, &Value> = truth["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| (f["frame_id"].as_u64().unwrap(), f))
        .collect();
    for (target, touch) in found.iter().zip(touches) {
        let (start, end, peak) = (
            number(&touch["start_s"]),
            number(&touch["end_s"]),
            number(&touch["peak_n"]),
        );
        let hold: Vec<[f64; 2]> = readings
            .iter()
            .filter(|r| {
                let f = frames[&r.frame_id];
                let t = number(&f["time_s"]);
                t >= start && t <= end && (number(&f["applied_n"]) - peak).abs() < 1e-9
            })
            .filter_map(|r| r.contact_mm)
            .collect();
        assert!(hold.len() >= 4, "{hold:?}");
        let n = hold.len() as f64;
        let expected = [
            hold.iter().map(|p| p[0]).sum::<f64>() / n,
            hold.iter().map(|p| p[1]).sum::<f64>() / n,
        ];
        let measured = [number(&target["measured_mm"][0]), number(&target["measured_mm"][1])];
        let gap = (measured[0] - expected[0]).hypot(measured[1] - expected[1]);
        eprintln!(
            "target {}: reported {measured:.3?}, the hold's mean {expected:.3?} ({gap:.3} mm apart)",
            touch["position_mm"]
        );
        assert!(gap < 0.15, "{measured:?} against the hold's {expected:?}");
    }
}
