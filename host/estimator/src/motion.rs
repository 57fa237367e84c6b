//! Camera and pad motion between the rest frame and a frame: what it is, how it is removed, and how it is reported.
//!
//! A camera that moves against a flat pattern sees it through a homography of the pattern's plane, whatever its
//! motion (roll, tilt, shift, or a change of distance or focus), once the lens is undone. So every corner is mapped
//! to pad mm through the rest frame's pad map (lens and pose), and a homography of the pad plane, fitted jointly
//! with the tractions by [`crate::inverse`], takes the motion. A similarity of the raw image, removed first, would be
//! exact for a roll about the optical axis alone: a fisheye's raw image does not scale or shift as a whole, and a
//! change of distance of 1 mm then read a 5 N press 10 % off, 3 mm missed it, and a 2 mm shift missed presses (the
//! corners' scatter about the motion 3-10 times a still camera's). The raw similarity stays the tracker's, to find
//! the squares again after a jump ([`fit_raw_similarity`]).

use nusense_geometry::{Point2, Similarity};

use crate::reading::CameraMotion;

/// Rounds of the robust similarity fit (each leaves out the pairs the previous fit explains worst).
const ROBUST_ROUNDS: usize = 4;
/// A pair is left out when it misses the fit by more than this many robust sigmas (a press moves its corners)...
const OUTLIER_SIGMAS: f64 = 3.0;
/// ...but never fewer than this fraction of the pairs is kept (a press never covers most of the pattern).
const MIN_KEPT_FRACTION: f64 = 0.5;

/// The least-squares similarity over the pairs with `keep` set; a usable one only (points that spread, a finite map).
fn fit_kept(pairs: &[(Point2, Point2)], keep: &[bool]) -> Option<Similarity> {
    let kept: Vec<(Point2, Point2)> = pairs.iter().zip(keep).filter(|(_, &k)| k).map(|(p, _)| *p).collect();
    if kept.len() < 2 {
        return None;
    }
    let fitted = Similarity::fit(kept.iter())?;
    (fitted.scale > 0.0 && fitted.matrix().iter().all(|v| v.is_finite())).then_some(fitted)
}

/// The similarity of raw px that moves the rest frame's corners (`pairs.0`) onto this frame's (`pairs.1`), fitted on
/// the pairs that move rigidly: each round leaves out those the previous fit misses by more than
/// `OUTLIER_SIGMAS` robust sigmas (the corners a press moves).
pub fn fit_raw_similarity(pairs: &[(Point2, Point2)]) -> Option<Similarity> {
    let mut keep = vec![true; pairs.len()];
    let mut fit = fit_kept(pairs, &keep)?;
    for _ in 1..ROBUST_ROUNDS {
        let misses: Vec<f64> = pairs
            .iter()
            .map(|(a, b)| {
                let q = fit.apply(*a);
                (q[0] - b[0]).hypot(q[1] - b[1])
            })
            .collect();
        let mut sorted = misses.clone();
        sorted.sort_unstable_by(f64::total_cmp);
        // The median miss of a 2-D Gaussian is 1.1774 sigma.
        let sigma = sorted[sorted.len() / 2] / 1.1774;
        let mut order: Vec<usize> = (0..pairs.len()).collect();
        order.sort_unstable_by(|&i, &j| misses[i].total_cmp(&misses[j]));
        let least_kept = ((pairs.len() as f64) * MIN_KEPT_FRACTION).ceil() as usize;
        let next: Vec<bool> = {
            let mut next = vec![false; pairs.len()];
            for (rank, &i) in order.iter().enumerate() {
                next[i] = rank < least_kept || misses[i] <= OUTLIER_SIGMAS * sigma;
            }
            next
        };
        if next == keep {
            break;
        }
        keep = next;
        fit = fit_kept(pairs, &keep)?;
    }
    Some(fit)
}

/// The motion as users see it, from the rest frame's corners in raw px and where the whole fitted motion puts them:
/// rotation and scale of the least-squares similarity between the two, and the pad centre's shift.
pub fn camera_motion(pairs: &[(Point2, Point2)], centre_rest: Point2, centre_now: Point2) -> CameraMotion {
    let Some(similarity) = fit_kept(pairs, &vec![true; pairs.len()]) else {
        return CameraMotion::NONE;
    };
    let shift_px = [centre_now[0] - centre_rest[0], centre_now[1] - centre_rest[1]];
    let motion = CameraMotion {
        rotation_deg: similarity.rotation.to_degrees(),
        shift_px,
        scale: similarity.scale,
    };
    let finite = motion.rotation_deg.is_finite() && motion.scale.is_finite() && shift_px.iter().all(|v| v.is_finite());
    if finite {
        motion
    } else {
        CameraMotion::NONE
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn moved(angle_deg: f64, scale: f64, shift: Point2, about: Point2, p: Point2) -> Point2 {
        let (s, c) = angle_deg.to_radians().sin_cos();
        let (x, y) = (p[0] - about[0], p[1] - about[1]);
        [
            about[0] + scale * (c * x - s * y) + shift[0],
            about[1] + scale * (s * x + c * y) + shift[1],
        ]
    }

    fn grid() -> Vec<Point2> {
        (0..15)
            .flat_map(|i| (0..11).map(move |j| [200.0 + 40.0 * i as f64, 150.0 + 40.0 * j as f64]))
            .collect()
    }

    #[test]
    fn a_roll_about_any_centre_is_recovered_exactly() {
        let about = [512.0, 384.0];
        let pairs: Vec<(Point2, Point2)> = grid()
            .into_iter()
            .map(|p| (p, moved(4.5, 1.003, [3.0, -2.0], about, p)))
            .collect();
        let fit = fit_raw_similarity(&pairs).unwrap();
        assert!(
            (fit.rotation.to_degrees() - 4.5).abs() < 1e-9,
            "{}",
            fit.rotation.to_degrees()
        );
        assert!((fit.scale - 1.003).abs() < 1e-12);
        for (a, b) in &pairs {
            let q = fit.apply(*a);
            assert!((q[0] - b[0]).abs() < 1e-9 && (q[1] - b[1]).abs() < 1e-9);
        }
        let reported = camera_motion(&pairs, about, moved(4.5, 1.003, [3.0, -2.0], about, about));
        assert!((reported.rotation_deg - 4.5).abs() < 1e-9);
        assert!((reported.shift_px[0] - 3.0).abs() < 1e-9 && (reported.shift_px[1] + 2.0).abs() < 1e-9);
    }

    #[test]
    fn a_press_does_not_pull_the_camera_motion() {
        // A press pushes the corners within 60 px of (420, 300) outwards by up to 4 px; the camera rolled 2 deg.
        let about = [512.0, 384.0];
        let press = [420.0, 300.0];
        let pairs: Vec<(Point2, Point2)> = grid()
            .into_iter()
            .map(|p| {
                let (dx, dy) = (p[0] - press[0], p[1] - press[1]);
                let r = dx.hypot(dy);
                let push = if r > 0.0 && r < 60.0 {
                    4.0 * (1.0 - r / 60.0) / r
                } else {
                    0.0
                };
                let pressed = [p[0] + push * dx, p[1] + push * dy];
                (p, moved(2.0, 1.0, [0.0, 0.0], about, pressed))
            })
            .collect();
        let plain = fit_kept(&pairs, &vec![true; pairs.len()]).unwrap();
        let robust = fit_raw_similarity(&pairs).unwrap();
        let error = |s: &Similarity| (s.rotation.to_degrees() - 2.0).abs();
        assert!(error(&robust) < 1e-9, "robust fit off by {} deg", error(&robust));
        assert!(
            error(&plain) > 1e-4,
            "the press should pull a plain fit ({} deg)",
            error(&plain)
        );
    }
}
