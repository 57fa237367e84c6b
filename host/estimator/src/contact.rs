//! Contact decision and location from the corner displacement field.
//!
//! The whole pad moving together (a camera shift, a slow drift, a uniform tangential load) is not a contact:
//! an affine motion is fitted robustly to the field and removed, and contact is declared when the local
//! residual of at least two corners exceeds the configured shear in mm. The contact centre is where the
//! residual field diverges from: a normal press pushes the pattern radially around it, so every sheared
//! corner's residual lies on a line through the centre; the centre is the weighted least-squares intersection
//! of those lines (the peak of ||displacement|| is on the annulus around it, not at the centre).

use nusense_geometry::Point2;

use crate::linalg::solve_small as solve;

/// One corner of the field: reference position and motion, both in paper px.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FieldPoint {
    pub position: Point2,
    pub displacement: Point2,
}

/// d = A p + t.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AffineMotion {
    x: [f64; 3],
    y: [f64; 3],
}

impl AffineMotion {
    pub const ZERO: Self = Self {
        x: [0.0; 3],
        y: [0.0; 3],
    };

    pub fn predict(&self, p: Point2) -> Point2 {
        [
            self.x[0] * p[0] + self.x[1] * p[1] + self.x[2],
            self.y[0] * p[0] + self.y[1] * p[1] + self.y[2],
        ]
    }

    pub fn residual(&self, point: &FieldPoint) -> Point2 {
        let m = self.predict(point.position);
        [point.displacement[0] - m[0], point.displacement[1] - m[1]]
    }
}

/// Iteratively reweighted least squares: corners in the contact move far from the pad's overall motion and
/// get small weights, so they do not drag the fit. `None` with fewer than 6 points or a degenerate layout.
pub fn fit_affine_motion(points: &[FieldPoint]) -> Option<AffineMotion> {
    if points.len() < 6 {
        return None;
    }
    let centre = [
        points.iter().map(|p| p.position[0]).sum::<f64>() / points.len() as f64,
        points.iter().map(|p| p.position[1]).sum::<f64>() / points.len() as f64,
    ];
    let mut weights = vec![1.0; points.len()];
    let mut motion = AffineMotion::ZERO;
    for _ in 0..5 {
        let mut ata = [[0.0; 3]; 3];
        let (mut bx, mut by) = ([0.0; 3], [0.0; 3]);
        for (p, &w) in points.iter().zip(&weights) {
            let row = [p.position[0] - centre[0], p.position[1] - centre[1], 1.0];
            for i in 0..3 {
                for j in 0..3 {
                    ata[i][j] += w * row[i] * row[j];
                }
                bx[i] += w * row[i] * p.displacement[0];
                by[i] += w * row[i] * p.displacement[1];
            }
        }
        let x = solve(ata, bx)?;
        let y = solve(ata, by)?;
        // Back from centred coordinates: t' = t - A c.
        motion = AffineMotion {
            x: [x[0], x[1], x[2] - x[0] * centre[0] - x[1] * centre[1]],
            y: [y[0], y[1], y[2] - y[0] * centre[0] - y[1] * centre[1]],
        };
        let mut residuals: Vec<f64> = points.iter().map(|p| norm(motion.residual(p))).collect();
        let scale = {
            let mut sorted = residuals.clone();
            sorted.sort_unstable_by(f64::total_cmp);
            1.5 * sorted[sorted.len() / 2] + 1e-3
        };
        for (w, r) in weights.iter_mut().zip(residuals.iter_mut()) {
            // Huber weights.
            *w = if *r <= scale { 1.0 } else { scale / *r };
        }
    }
    Some(motion)
}

pub fn norm(v: Point2) -> f64 {
    v[0].hypot(v[1])
}

/// Where the residual field diverges from, paper px; `None` without sheared corners.
pub fn divergence_centre(points: &[FieldPoint], residuals: &[Point2]) -> Option<Point2> {
    let peak = residuals.iter().map(|&r| norm(r)).fold(0.0, f64::max);
    if !(peak > 0.0) {
        return None;
    }
    let mut m = [[0.0; 2]; 2];
    let mut b = [0.0; 2];
    let (mut sw, mut sx, mut sy) = (0.0, 0.0, 0.0);
    for (p, &r) in points.iter().zip(residuals) {
        let len = norm(r);
        if len < 0.3 * peak {
            continue;
        }
        let w = len * len;
        // The line through p along r: n . (c - p) = 0 with n normal to r.
        let n = [-r[1] / len, r[0] / len];
        let np = n[0] * p.position[0] + n[1] * p.position[1];
        for i in 0..2 {
            for j in 0..2 {
                m[i][j] += w * n[i] * n[j];
            }
            b[i] += w * n[i] * np;
        }
        sw += w;
        sx += w * p.position[0];
        sy += w * p.position[1];
    }
    if sw <= 0.0 {
        return None;
    }
    let centroid = [sx / sw, sy / sw];
    // Lines all parallel (a pure slide) have no intersection: fall back to the centroid of the shear.
    let trace = m[0][0] + m[1][1];
    let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
    let smaller_eigen = trace / 2.0 - ((trace / 2.0).powi(2) - det).max(0.0).sqrt();
    if smaller_eigen < 0.05 * trace {
        return Some(centroid);
    }
    let centre = solve(m, b)?;
    // An intersection far outside the sheared region is a poorly conditioned fit, not a centre.
    let spread = (points
        .iter()
        .zip(residuals)
        .filter(|(_, &r)| norm(r) >= 0.3 * peak)
        .map(|(p, &r)| {
            norm(r).powi(2) * ((p.position[0] - centroid[0]).powi(2) + (p.position[1] - centroid[1]).powi(2))
        })
        .sum::<f64>()
        / sw)
        .sqrt();
    if norm([centre[0] - centroid[0], centre[1] - centroid[1]]) > 2.0 * spread.max(1.0) {
        return Some(centroid);
    }
    Some(centre)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn radial_field(centre: Point2, shift: Point2) -> Vec<FieldPoint> {
        let mut points = Vec::new();
        for r in 0..11 {
            for c in 0..15 {
                let p = [200.0 + 100.0 * c as f64, 150.0 + 100.0 * r as f64];
                let d = [p[0] - centre[0], p[1] - centre[1]];
                let dist = norm(d).max(1e-9);
                // An annulus of outward motion peaking 150 px from the centre.
                let magnitude = 15.0 * (-((dist - 150.0) / 80.0).powi(2)).exp();
                points.push(FieldPoint {
                    position: p,
                    displacement: [shift[0] + magnitude * d[0] / dist, shift[1] + magnitude * d[1] / dist],
                });
            }
        }
        points
    }

    #[test]
    fn finds_the_centre_of_a_radial_field_despite_a_uniform_shift() {
        let centre = [930.0, 640.0];
        let points = radial_field(centre, [7.0, -3.0]);
        let motion = fit_affine_motion(&points).unwrap();
        let residuals: Vec<Point2> = points.iter().map(|p| motion.residual(p)).collect();
        let found = divergence_centre(&points, &residuals).unwrap();
        assert!(norm([found[0] - centre[0], found[1] - centre[1]]) < 10.0, "{found:?}");
    }

    #[test]
    fn a_rigid_shift_leaves_no_residual() {
        let points: Vec<FieldPoint> = radial_field([0.0, 0.0], [0.0, 0.0])
            .into_iter()
            .map(|p| FieldPoint {
                position: p.position,
                displacement: [4.0, 2.5],
            })
            .collect();
        let motion = fit_affine_motion(&points).unwrap();
        assert!(points.iter().all(|p| norm(motion.residual(p)) < 1e-9));
    }
}
