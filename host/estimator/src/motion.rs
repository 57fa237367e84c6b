//! Camera and pad motion between the rest frame and a frame: what it is (a homography of the pad plane, fitted
//! jointly with the tractions by [`crate::inverse`]), how it is removed, and how it is reported.

use nusense_geometry::Point2;

use crate::homography::Homography;
use crate::pad_map::PadMapping;
use crate::reading::CameraMotion;

/// The similarity closest (least squares) to `motion` over `points` (pad mm): rotation (rad), scale and the
/// image of the origin.
pub fn closest_similarity(motion: &Homography, points: &[Point2]) -> Option<(f64, f64, Point2)> {
    let moved: Vec<Point2> = points.iter().map(|&p| motion.apply(p)).collect::<Option<_>>()?;
    let n = points.len() as f64;
    if points.len() < 2 {
        return None;
    }
    let mean = |v: &[Point2]| {
        [
            v.iter().map(|p| p[0]).sum::<f64>() / n,
            v.iter().map(|p| p[1]).sum::<f64>() / n,
        ]
    };
    let (c, c2) = (mean(points), mean(&moved));
    let (mut a, mut b, mut norm) = (0.0, 0.0, 0.0);
    for (p, q) in points.iter().zip(&moved) {
        let (x, y) = (p[0] - c[0], p[1] - c[1]);
        let (u, v) = (q[0] - c2[0], q[1] - c2[1]);
        a += x * u + y * v;
        b += x * v - y * u;
        norm += x * x + y * y;
    }
    if !(norm > 0.0) {
        return None;
    }
    let (a, b) = (a / norm, b / norm);
    let (scale, rotation) = (a.hypot(b), b.atan2(a));
    let origin = motion.apply([0.0, 0.0])?;
    Some((rotation, scale, origin))
}

/// The motion as users see it: rotation and scale of the pattern, and the pad centre's shift in raw px.
pub fn camera_motion(motion: &Homography, points: &[Point2], mapping: &PadMapping) -> CameraMotion {
    let Some((rotation, scale, origin)) = closest_similarity(motion, points) else {
        return CameraMotion::NONE;
    };
    let shift_px = match (mapping.mm_to_raw([0.0, 0.0]), mapping.mm_to_raw(origin)) {
        (Some(a), Some(b)) => [b[0] - a[0], b[1] - a[1]],
        _ => [0.0, 0.0],
    };
    let motion = CameraMotion {
        rotation_deg: rotation.to_degrees(),
        shift_px,
        scale,
    };
    let finite = motion.rotation_deg.is_finite() && motion.scale.is_finite() && shift_px.iter().all(|v| v.is_finite());
    if finite {
        motion
    } else {
        CameraMotion::NONE
    }
}

/// The largest displacement `motion` gives any of `points`, mm.
pub fn largest_displacement_mm(motion: &Homography, points: &[Point2]) -> f64 {
    points
        .iter()
        .filter_map(|&p| motion.apply(p).map(|q| (q[0] - p[0]).hypot(q[1] - p[1])))
        .fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_rotation_scale_and_shift() {
        let (angle, scale, shift) = (3f64.to_radians(), 1.01, [0.7, -0.4]);
        let (s, c) = angle.sin_cos();
        let h = Homography::from_matrix([
            scale * c,
            -scale * s,
            shift[0],
            scale * s,
            scale * c,
            shift[1],
            0.0,
            0.0,
            1.0,
        ])
        .unwrap();
        let points: Vec<Point2> = (0..5)
            .flat_map(|i| (0..4).map(move |j| [i as f64 * 10.0 - 20.0, j as f64 * 8.0 - 12.0]))
            .collect();
        let (rotation, found_scale, origin) = closest_similarity(&h, &points).unwrap();
        assert!((rotation - angle).abs() < 1e-12 && (found_scale - scale).abs() < 1e-12);
        assert!((origin[0] - shift[0]).abs() < 1e-12 && (origin[1] - shift[1]).abs() < 1e-12);
        assert!(largest_displacement_mm(&h, &points) > 1.0);
    }
}
