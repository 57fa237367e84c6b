//! Small dense linear algebra for the hot path: fixed-size solves and row-major matrix-vector products. The
//! precomputations (factorisations, eigen-decompositions) use nalgebra; per frame, a few products over contiguous
//! rows are all that is needed and are written here so the loops stay simple and vectorisable.

/// Solves the n x n system `a x = b` by Gaussian elimination with partial pivoting; `None` if singular.
pub fn solve_small<const N: usize>(mut a: [[f64; N]; N], mut b: [f64; N]) -> Option<[f64; N]> {
    for col in 0..N {
        let pivot = (col..N).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if !(a[pivot][col].abs() > 1e-12) {
            return None;
        }
        a.swap(col, pivot);
        b.swap(col, pivot);
        let pivot_row = a[col];
        for row in col + 1..N {
            let f = a[row][col] / pivot_row[col];
            for (x, p) in a[row][col..].iter_mut().zip(&pivot_row[col..]) {
                *x -= f * p;
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

/// A dense row-major matrix.
#[derive(Clone, Debug, PartialEq)]
pub struct Dense {
    pub rows: usize,
    pub cols: usize,
    pub data: Vec<f64>,
}

impl Dense {
    pub fn from_nalgebra(m: &nalgebra::DMatrix<f64>) -> Self {
        let (rows, cols) = m.shape();
        let mut data = Vec::with_capacity(rows * cols);
        for r in 0..rows {
            for c in 0..cols {
                data.push(m[(r, c)]);
            }
        }
        Self { rows, cols, data }
    }

    #[inline]
    pub fn row(&self, r: usize) -> &[f64] {
        &self.data[r * self.cols..(r + 1) * self.cols]
    }

    #[inline]
    pub fn at(&self, r: usize, c: usize) -> f64 {
        self.data[r * self.cols + c]
    }

    /// out = self * x.
    pub fn mul_vec(&self, x: &[f64], out: &mut [f64]) {
        debug_assert!(x.len() == self.cols && out.len() == self.rows);
        for (r, o) in out.iter_mut().enumerate() {
            *o = dot(self.row(r), x);
        }
    }

    /// out = selfᵀ * x.
    pub fn mul_transposed_vec(&self, x: &[f64], out: &mut [f64]) {
        debug_assert!(x.len() == self.rows && out.len() == self.cols);
        out.iter_mut().for_each(|o| *o = 0.0);
        for (r, &xr) in x.iter().enumerate() {
            if xr != 0.0 {
                for (o, &a) in out.iter_mut().zip(self.row(r)) {
                    *o += a * xr;
                }
            }
        }
    }
}

/// Dot product with four accumulators (lets the compiler vectorise without reassociating a single sum).
#[inline]
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [0.0; 4];
    let chunks = n / 4;
    for i in 0..chunks {
        for k in 0..4 {
            acc[k] += a[4 * i + k] * b[4 * i + k];
        }
    }
    let mut sum = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    for i in 4 * chunks..n {
        sum += a[i] * b[i];
    }
    sum
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn products_match_nalgebra() {
        let m = nalgebra::DMatrix::from_fn(7, 5, |r, c| {
            (r as f64 + 1.0) * 0.3 - c as f64 * 0.7 + (r * c) as f64 * 0.01
        });
        let dense = Dense::from_nalgebra(&m);
        let x: Vec<f64> = (0..5).map(|i| i as f64 - 1.5).collect();
        let y: Vec<f64> = (0..7).map(|i| 0.5 * i as f64).collect();
        let mut out = vec![0.0; 7];
        dense.mul_vec(&x, &mut out);
        let expected = &m * nalgebra::DVector::from_column_slice(&x);
        assert!(out.iter().zip(expected.iter()).all(|(a, b)| (a - b).abs() < 1e-12));
        let mut out = vec![0.0; 5];
        dense.mul_transposed_vec(&y, &mut out);
        let expected = m.transpose() * nalgebra::DVector::from_column_slice(&y);
        assert!(out.iter().zip(expected.iter()).all(|(a, b)| (a - b).abs() < 1e-12));
        assert!(solve_small([[0.0, 0.0], [0.0, 0.0]], [1.0, 1.0]).is_none());
    }
}
