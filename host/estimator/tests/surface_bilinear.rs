//! Degree (1, 1) with clamped uniform knots is bilinear interpolation of the control net, exactly.

use nusense_estimator::surface::{BSplineSurface, ControlNet, SurfaceError};

fn net(rows: usize, cols: usize) -> Vec<[f64; 2]> {
    // Irregular values, so that no symmetry hides an indexing mistake.
    (0..rows * cols)
        .map(|i| {
            [
                (i as f64 * 7.3).sin() * 50.0 + i as f64,
                (i as f64 * 3.1).cos() * 20.0 - i as f64,
            ]
        })
        .collect()
}

#[test]
fn degree_one_reproduces_bilinear_interpolation() {
    let (rows, cols) = (11, 15);
    let points = net(rows, cols);
    let surface = BSplineSurface::new(ControlNet::from_points(rows, cols, points.clone()).unwrap(), 1, 1).unwrap();
    for iu in 0..=37 {
        for iv in 0..=41 {
            let (u, v) = (iu as f64 / 37.0, iv as f64 / 41.0);
            // Control point (i, j) sits at u = i / (rows - 1), v = j / (cols - 1).
            let (gu, gv) = (u * (rows - 1) as f64, v * (cols - 1) as f64);
            let (i, j) = ((gu.floor() as usize).min(rows - 2), (gv.floor() as usize).min(cols - 2));
            let (fu, fv) = (gu - i as f64, gv - j as f64);
            let p = |r: usize, c: usize| points[r * cols + c];
            let expected: Vec<f64> = (0..2)
                .map(|k| {
                    (1.0 - fu) * (1.0 - fv) * p(i, j)[k]
                        + (1.0 - fu) * fv * p(i, j + 1)[k]
                        + fu * (1.0 - fv) * p(i + 1, j)[k]
                        + fu * fv * p(i + 1, j + 1)[k]
                })
                .collect();
            let got = surface.evaluate(u, v);
            assert!(
                (got[0] - expected[0]).abs() < 1e-9 && (got[1] - expected[1]).abs() < 1e-9,
                "({u}, {v}): {got:?} vs {expected:?}"
            );
        }
    }
    // At the nodes the surface passes through the control points.
    for r in 0..rows {
        for c in 0..cols {
            let got = surface.evaluate(r as f64 / (rows - 1) as f64, c as f64 / (cols - 1) as f64);
            let want = points[r * cols + c];
            assert!((got[0] - want[0]).abs() < 1e-9 && (got[1] - want[1]).abs() < 1e-9);
        }
    }
}

#[test]
fn higher_degrees_keep_a_constant_net() {
    // The basis is a partition of unity at every degree, so a constant net gives that constant everywhere.
    // (Values of higher degrees against another implementation are the golden-data tests.)
    for (p, q) in [(2, 2), (3, 3), (2, 5), (10, 14)] {
        let surface =
            BSplineSurface::new(ControlNet::from_points(11, 15, vec![[3.5, -2.0]; 165]).unwrap(), p, q).unwrap();
        let grid = surface.sample_grid(0.05).unwrap();
        assert!(grid
            .points
            .iter()
            .all(|s| (s[0] - 3.5).abs() < 1e-9 && (s[1] + 2.0).abs() < 1e-9));
        assert_eq!(grid.valid_count(), grid.points.len());
    }
}

#[test]
fn samples_rest_only_on_valid_points() {
    let (rows, cols) = (11, 15);
    let mut valid = vec![true; rows * cols];
    valid[5 * cols + 7] = false;
    let surface = BSplineSurface::new(ControlNet::new(rows, cols, net(rows, cols), valid).unwrap(), 1, 1).unwrap();
    let grid = surface.sample_grid(0.015).unwrap();
    assert_eq!(grid.points.len(), 67 * 67);
    for ((k, ok), _) in grid.rests_on_valid.iter().enumerate().zip(&grid.points) {
        let (u, v) = (grid.u_values[k / 67], grid.v_values[k % 67]);
        // Degree 1: the missing point (5, 7) weighs samples strictly inside the cells around it.
        let (gu, gv) = (u * 10.0, v * 14.0);
        let touches = (gu - 5.0).abs() < 1.0 && (gv - 7.0).abs() < 1.0;
        assert_eq!(*ok, !touches, "sample ({u}, {v})");
    }
    let (point, ok) = surface.evaluate_checked(0.5, 0.5).unwrap();
    assert!(!ok && point.iter().all(|v| v.is_finite()));
}

#[test]
fn bad_nets_and_degrees_are_typed_errors() {
    assert!(matches!(
        ControlNet::from_points(0, 3, vec![]),
        Err(SurfaceError::EmptyNet { .. })
    ));
    assert!(matches!(
        ControlNet::from_points(2, 3, vec![[0.0; 2]; 5]),
        Err(SurfaceError::SizeMismatch { .. })
    ));
    assert!(matches!(
        ControlNet::from_points(2, 2, vec![[f64::NAN, 0.0]; 4]),
        Err(SurfaceError::NotFinite { .. })
    ));
    let ok = || ControlNet::from_points(3, 4, vec![[0.0; 2]; 12]).unwrap();
    assert!(matches!(
        BSplineSurface::new(ok(), 3, 1),
        Err(SurfaceError::DegreeTooHigh { .. })
    ));
    assert!(matches!(
        BSplineSurface::new(ok(), 0, 1),
        Err(SurfaceError::DegreeZero { .. })
    ));
    assert!(BSplineSurface::new(ok(), 2, 3).is_ok());
    let s = BSplineSurface::new(ok(), 1, 1).unwrap();
    assert!(matches!(
        s.evaluate_checked(1.5, 0.0),
        Err(SurfaceError::OutOfDomain { .. })
    ));
    assert!(matches!(s.sample_grid(0.0), Err(SurfaceError::BadStep(_))));
    assert!(s.evaluate(f64::NAN, 2.0).iter().all(|v| v.is_finite()));
}
