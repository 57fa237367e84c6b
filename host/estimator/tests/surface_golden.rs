//! The B-spline surface against values computed by another implementation (SciPy's NdBSpline, cross-checked
//! in the generator against 1-D BSpline curves), and degree 1 against bilinear interpolation written out here.
//! Regenerate the data with `python3 tests/golden/make_surface_golden.py`.

use nusense_estimator::surface::{BSplineSurface, ControlNet};
use serde_json::Value;

const TOLERANCE: f64 = 1e-9;

fn golden() -> Value {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/golden/surface_golden.json");
    let text = std::fs::read_to_string(path).expect("golden data is committed beside this test");
    serde_json::from_str(&text).expect("golden data is JSON")
}

fn numbers(v: &Value) -> Vec<f64> {
    v.as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect()
}

fn surface_of(case: &Value) -> BSplineSurface {
    let rows = case["rows"].as_u64().unwrap() as usize;
    let cols = case["cols"].as_u64().unwrap() as usize;
    let points: Vec<[f64; 2]> = case["control_points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            let p = numbers(p);
            [p[0], p[1]]
        })
        .collect();
    let net = ControlNet::from_points(rows, cols, points).unwrap();
    BSplineSurface::new(
        net,
        case["degree_u"].as_u64().unwrap() as usize,
        case["degree_v"].as_u64().unwrap() as usize,
    )
    .unwrap()
}

#[test]
fn matches_scipy_for_every_golden_case() {
    let data = golden();
    let cases = data["cases"].as_array().unwrap();
    let mut degrees_seen = std::collections::BTreeSet::new();
    let mut checked = 0;
    for case in cases {
        let surface = surface_of(case);
        let label = format!(
            "case seed {} ({} x {}, degrees {}, {})",
            case["seed"], case["rows"], case["cols"], case["degree_u"], case["degree_v"]
        );
        degrees_seen.insert((case["degree_u"].as_u64().unwrap(), case["degree_v"].as_u64().unwrap()));
        for (ours, theirs) in [
            (surface.knots_u().knots(), numbers(&case["knots_u"])),
            (surface.knots_v().knots(), numbers(&case["knots_v"])),
        ] {
            assert_eq!(ours.len(), theirs.len(), "{label}: knot count");
            for (a, b) in ours.iter().zip(&theirs) {
                assert!((a - b).abs() < 1e-15, "{label}: knots {ours:?} vs {theirs:?}");
            }
        }
        for sample in case["samples"].as_array().unwrap() {
            let s = numbers(sample);
            let (u, v, x, y) = (s[0], s[1], s[2], s[3]);
            let (p, valid) = surface.evaluate_checked(u, v).unwrap();
            assert!(valid, "{label}: a fully valid net has only valid samples");
            assert!(
                (p[0] - x).abs() < TOLERANCE && (p[1] - y).abs() < TOLERANCE,
                "{label}: S({u}, {v}) = {p:?}, SciPy {:?}",
                [x, y]
            );
            assert_eq!(surface.evaluate(u, v), p);
            checked += 1;
        }
    }
    for wanted in [(1, 1), (2, 2), (3, 3), (2, 3)] {
        assert!(degrees_seen.contains(&wanted), "no golden case of degrees {wanted:?}");
    }
    assert!(checked > 1000, "only {checked} golden samples");
}

/// Bilinear interpolation of a rows x cols net over [0, 1]^2, nodes evenly spaced.
fn bilinear(points: &[[f64; 2]], rows: usize, cols: usize, u: f64, v: f64) -> [f64; 2] {
    let fu = u * (rows - 1) as f64;
    let fv = v * (cols - 1) as f64;
    let i = (fu.floor() as usize).min(rows - 2);
    let j = (fv.floor() as usize).min(cols - 2);
    let (tu, tv) = (fu - i as f64, fv - j as f64);
    let at = |r: usize, c: usize| points[r * cols + c];
    std::array::from_fn(|k| {
        let top = at(i, j)[k] * (1.0 - tv) + at(i, j + 1)[k] * tv;
        let bottom = at(i + 1, j)[k] * (1.0 - tv) + at(i + 1, j + 1)[k] * tv;
        top * (1.0 - tu) + bottom * tu
    })
}

#[test]
fn degree_one_is_bilinear_interpolation() {
    let (rows, cols) = (11, 15);
    // A deliberately uneven net (no lattice symmetry to hide an index mix-up).
    let points: Vec<[f64; 2]> = (0..rows * cols)
        .map(|i| {
            let (r, c) = ((i / cols) as f64, (i % cols) as f64);
            [
                80.0 * c + 7.0 * (1.3 * r + 0.7 * c).sin(),
                80.0 * r + 5.0 * (0.9 * c - 0.4 * r).cos() + 0.3 * c * c,
            ]
        })
        .collect();
    let surface = BSplineSurface::new(ControlNet::from_points(rows, cols, points.clone()).unwrap(), 1, 1).unwrap();
    let steps = 97;
    for a in 0..=steps {
        for b in 0..=steps {
            let (u, v) = (a as f64 / steps as f64, b as f64 / steps as f64);
            let p = surface.evaluate(u, v);
            let q = bilinear(&points, rows, cols, u, v);
            // Same interpolation, different arithmetic: agreement to rounding error of values ~1000.
            assert!(
                (p[0] - q[0]).abs() < 1e-10 && (p[1] - q[1]).abs() < 1e-10,
                "S({u}, {v}) = {p:?}, bilinear {q:?}"
            );
        }
    }
    // At the nodes the surface passes through the control points.
    for r in 0..rows {
        for c in 0..cols {
            let p = surface.evaluate(r as f64 / (rows - 1) as f64, c as f64 / (cols - 1) as f64);
            let q = points[r * cols + c];
            assert!(
                (p[0] - q[0]).abs() < 1e-10 && (p[1] - q[1]).abs() < 1e-10,
                "node ({r}, {c}): {p:?} vs {q:?}"
            );
        }
    }
}

#[test]
fn a_missing_control_point_only_marks_the_samples_it_supports() {
    let data = golden();
    let case = data["cases"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["degree_u"] == 2 && c["degree_v"] == 2)
        .unwrap();
    let full = surface_of(case);
    let (rows, cols) = (full.net().rows(), full.net().cols());
    let missing = (2, 3);
    let points: Vec<Option<[f64; 2]>> = (0..rows * cols)
        .map(|i| {
            if (i / cols, i % cols) == missing {
                None
            } else {
                full.net().point(i / cols, i % cols)
            }
        })
        .collect();
    let masked = BSplineSurface::new(ControlNet::from_options(rows, cols, &points).unwrap(), 2, 2).unwrap();
    let (ku, kv) = (full.knots_u().knots().to_vec(), full.knots_v().knots().to_vec());
    let steps = 40;
    let (mut flagged, mut clean) = (0, 0);
    for a in 0..=steps {
        for b in 0..=steps {
            let (u, v) = (a as f64 / steps as f64, b as f64 / steps as f64);
            let (p, valid) = masked.evaluate_checked(u, v).unwrap();
            // N_{i,p} is non-zero only on [k_i, k_{i+p+1}): the point supports samples inside that box.
            let inside = |t: f64, k: &[f64], i: usize| t > k[i] && t < k[i + 3];
            let supported = inside(u, &ku, missing.0) && inside(v, &kv, missing.1);
            assert_eq!(!valid, supported, "({u}, {v})");
            if valid {
                assert_eq!(
                    p,
                    full.evaluate(u, v),
                    "a valid sample must not depend on the missing point"
                );
                clean += 1;
            } else {
                flagged += 1;
            }
        }
    }
    assert!(flagged > 0 && clean > flagged);
}
