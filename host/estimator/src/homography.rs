//! Plane-to-plane homography (DLT with Hartley normalisation, least squares), used to map the lattice's
//! undistorted corners onto the pad in mm.

use nusense_geometry::Point2;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Homography {
    h: [[f64; 3]; 3],
}

/// Solves the n x n system `a x = b` by Gaussian elimination with partial pivoting; `None` if singular.
pub fn solve<const N: usize>(mut a: [[f64; N]; N], mut b: [f64; N]) -> Option<[f64; N]> {
    for col in 0..N {
        let pivot = (col..N).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if !(a[pivot][col].abs() > 1e-12) {
            return None;
        }
        a.swap(col, pivot);
        b.swap(col, pivot);
        for row in col + 1..N {
            let f = a[row][col] / a[col][col];
            for k in col..N {
                a[row][k] -= f * a[col][k];
            }
            b[row] -= f * b[col];
        }
    }
    let mut x = [0.0; N];
    for row in (0..N).rev() {
        let s: f64 = (row + 1..N).map(|k| a[row][k] * x[k]).sum();
        x[row] = (b[row] - s) / a[row][row];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

fn normaliser(points: &[Point2]) -> [[f64; 3]; 3] {
    let n = points.len() as f64;
    let mx = points.iter().map(|p| p[0]).sum::<f64>() / n;
    let my = points.iter().map(|p| p[1]).sum::<f64>() / n;
    let spread = points.iter().map(|p| (p[0] - mx).hypot(p[1] - my)).sum::<f64>() / n;
    let s = if spread > 0.0 { std::f64::consts::SQRT_2 / spread } else { 1.0 };
    [[s, 0.0, -s * mx], [0.0, s, -s * my], [0.0, 0.0, 1.0]]
}

fn apply(m: &[[f64; 3]; 3], p: Point2) -> Option<Point2> {
    let w = m[2][0] * p[0] + m[2][1] * p[1] + m[2][2];
    if w.abs() < 1e-12 {
        return None;
    }
    let q = [(m[0][0] * p[0] + m[0][1] * p[1] + m[0][2]) / w, (m[1][0] * p[0] + m[1][1] * p[1] + m[1][2]) / w];
    (q[0].is_finite() && q[1].is_finite()).then_some(q)
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
    [[1.0 / s, 0.0, -t[0][2] / s], [0.0, 1.0 / s, -t[1][2] / s], [0.0, 0.0, 1.0]]
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
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_a_perspective_map() {
        let truth = [[1.2, 0.1, 5.0], [-0.05, 0.9, -3.0], [1e-4, -2e-4, 1.0]];
        let from: Vec<Point2> = (0..5).flat_map(|i| (0..4).map(move |j| [i as f64 * 50.0, j as f64 * 40.0])).collect();
        let to: Vec<Point2> = from.iter().map(|&p| apply(&truth, p).unwrap()).collect();
        let h = Homography::fit(&from, &to).unwrap();
        for (&p, &q) in from.iter().zip(&to) {
            let r = h.apply(p).unwrap();
            assert!((r[0] - q[0]).abs() < 1e-8 && (r[1] - q[1]).abs() < 1e-8);
        }
        assert!(Homography::fit(&from[..3], &to[..3]).is_none());
    }
}
