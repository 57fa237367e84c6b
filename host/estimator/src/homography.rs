//! Plane-to-plane homography (DLT with Hartley normalisation, least squares), used to map the lattice's
//! undistorted corners onto the pad in mm.

use nusense_geometry::Point2;

use crate::linalg::solve_small as solve;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Homography {
    h: [[f64; 3]; 3],
}

fn normaliser(points: &[Point2]) -> [[f64; 3]; 3] {
    let n = points.len() as f64;
    let mx = points.iter().map(|p| p[0]).sum::<f64>() / n;
    let my = points.iter().map(|p| p[1]).sum::<f64>() / n;
    let spread = points.iter().map(|p| (p[0] - mx).hypot(p[1] - my)).sum::<f64>() / n;
    let s = if spread > 0.0 {
        std::f64::consts::SQRT_2 / spread
    } else {
        1.0
    };
    [[s, 0.0, -s * mx], [0.0, s, -s * my], [0.0, 0.0, 1.0]]
}

fn apply(m: &[[f64; 3]; 3], p: Point2) -> Option<Point2> {
    let w = m[2][0] * p[0] + m[2][1] * p[1] + m[2][2];
    if w.abs() < 1e-12 {
        return None;
    }
    let q = [
        (m[0][0] * p[0] + m[0][1] * p[1] + m[0][2]) / w,
        (m[1][0] * p[0] + m[1][1] * p[1] + m[1][2]) / w,
    ];
    (q[0].is_finite() && q[1].is_finite()).then_some(q)
}

fn determinant(h: &[[f64; 3]; 3]) -> f64 {
    h[0][0] * (h[1][1] * h[2][2] - h[1][2] * h[2][1]) - h[0][1] * (h[1][0] * h[2][2] - h[1][2] * h[2][0])
        + h[0][2] * (h[1][0] * h[2][1] - h[1][1] * h[2][0])
}

fn mul(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut c = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            c[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    c
}

fn invert_similarity(t: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let s = t[0][0];
    [
        [1.0 / s, 0.0, -t[0][2] / s],
        [0.0, 1.0 / s, -t[1][2] / s],
        [0.0, 0.0, 1.0],
    ]
}

impl Homography {
    /// Least-squares fit from at least four point pairs; `None` when degenerate.
    pub fn fit(from: &[Point2], to: &[Point2]) -> Option<Self> {
        if from.len() != to.len() || from.len() < 4 {
            return None;
        }
        let (tf, tt) = (normaliser(from), normaliser(to));
        let mut ata = [[0.0; 8]; 8];
        let mut atb = [0.0; 8];
        for (&p, &q) in from.iter().zip(to) {
            let p = apply(&tf, p)?;
            let q = apply(&tt, q)?;
            let rows = [
                ([p[0], p[1], 1.0, 0.0, 0.0, 0.0, -p[0] * q[0], -p[1] * q[0]], q[0]),
                ([0.0, 0.0, 0.0, p[0], p[1], 1.0, -p[0] * q[1], -p[1] * q[1]], q[1]),
            ];
            for (row, rhs) in rows {
                for i in 0..8 {
                    for j in 0..8 {
                        ata[i][j] += row[i] * row[j];
                    }
                    atb[i] += row[i] * rhs;
                }
            }
        }
        let x = solve(ata, atb)?;
        let hn = [[x[0], x[1], x[2]], [x[3], x[4], x[5]], [x[6], x[7], 1.0]];
        let h = mul(&invert_similarity(&tt), &mul(&hn, &tf));
        h.iter().flatten().all(|v| v.is_finite()).then_some(Self { h })
    }

    pub fn apply(&self, p: Point2) -> Option<Point2> {
        apply(&self.h, p)
    }

    /// Row-major, scaled so that the last entry is 1.
    pub fn matrix(&self) -> [f64; 9] {
        let s = self.h[2][2];
        let s = if s.abs() > 1e-300 { s } else { 1.0 };
        let mut m = [0.0; 9];
        for (k, v) in m.iter_mut().enumerate() {
            *v = self.h[k / 3][k % 3] / s;
        }
        m
    }

    /// From a row-major matrix; `None` if it is not finite or not invertible.
    pub fn from_matrix(m: [f64; 9]) -> Option<Self> {
        let h = [[m[0], m[1], m[2]], [m[3], m[4], m[5]], [m[6], m[7], m[8]]];
        let valid = m.iter().all(|v| v.is_finite()) && determinant(&h).abs() > 1e-300;
        valid.then_some(Self { h })
    }

    pub fn inverse(&self) -> Option<Self> {
        let h = &self.h;
        let det = determinant(h);
        if !(det.abs() > 1e-300) {
            return None;
        }
        let cofactor = |r0: usize, r1: usize, c0: usize, c1: usize| h[r0][c0] * h[r1][c1] - h[r0][c1] * h[r1][c0];
        let inv = [
            [
                cofactor(1, 2, 1, 2) / det,
                -cofactor(0, 2, 1, 2) / det,
                cofactor(0, 1, 1, 2) / det,
            ],
            [
                -cofactor(1, 2, 0, 2) / det,
                cofactor(0, 2, 0, 2) / det,
                -cofactor(0, 1, 0, 2) / det,
            ],
            [
                cofactor(1, 2, 0, 1) / det,
                -cofactor(0, 2, 0, 1) / det,
                cofactor(0, 1, 0, 1) / det,
            ],
        ];
        Self::from_matrix([
            inv[0][0], inv[0][1], inv[0][2], inv[1][0], inv[1][1], inv[1][2], inv[2][0], inv[2][1], inv[2][2],
        ])
    }

    /// `self` after `first`: p -> self(first(p)).
    pub fn after(&self, first: &Self) -> Self {
        Self {
            h: mul(&self.h, &first.h),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_a_perspective_map() {
        let truth = [[1.2, 0.1, 5.0], [-0.05, 0.9, -3.0], [1e-4, -2e-4, 1.0]];
        let from: Vec<Point2> = (0..5)
            .flat_map(|i| (0..4).map(move |j| [i as f64 * 50.0, j as f64 * 40.0]))
            .collect();
        let to: Vec<Point2> = from.iter().map(|&p| apply(&truth, p).unwrap()).collect();
        let h = Homography::fit(&from, &to).unwrap();
        for (&p, &q) in from.iter().zip(&to) {
            let r = h.apply(p).unwrap();
            assert!((r[0] - q[0]).abs() < 1e-8 && (r[1] - q[1]).abs() < 1e-8);
        }
        assert!(Homography::fit(&from[..3], &to[..3]).is_none());
    }
}
