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

    /// [`Self::mul_vec`] of two vectors in one pass over the matrix (read from memory once rather than twice); each
    /// output is bit for bit what `mul_vec` gives it.
    pub fn mul_vec_pair(&self, x: [&[f64]; 2], out: [&mut [f64]; 2]) {
        debug_assert!(x.iter().all(|x| x.len() == self.cols));
        let [first, second] = out;
        debug_assert!(first.len() == self.rows && second.len() == self.rows);
        for (r, (a, b)) in first.iter_mut().zip(second.iter_mut()).enumerate() {
            let row = self.row(r);
            *a = dot(row, x[0]);
            *b = dot(row, x[1]);
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

/// Dot product summed in exactly the order of nalgebra's `Matrix::dot` on a column (eight accumulators over the
/// chunks of eight, combined as (0 + 4), (1 + 5), (2 + 6), (3 + 7) into a running sum, then the tail one by one),
/// on plain slices: products rewritten with it give bit for bit what nalgebra gave, without its generic indexing.
#[inline]
pub fn dot_nalgebra_order(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len(), "dot of slices of different lengths");
    let mut acc = [0.0f64; 8];
    let (a8, b8) = (a.chunks_exact(8), b.chunks_exact(8));
    let (a_tail, b_tail) = (a8.remainder(), b8.remainder());
    for (ca, cb) in a8.zip(b8) {
        for k in 0..8 {
            acc[k] += ca[k] * cb[k];
        }
    }
    let mut res = 0.0;
    res += acc[0] + acc[4];
    res += acc[1] + acc[5];
    res += acc[2] + acc[6];
    res += acc[3] + acc[7];
    for (x, y) in a_tail.iter().zip(b_tail) {
        res += x * y;
    }
    res
}

/// `mᵀ m` bit for bit as nalgebra's `m.tr_mul(&m)` computes it, in half the work: each entry is the same
/// [`dot_nalgebra_order`] of two columns, and a product of two columns is symmetric in them (x * y == y * x in
/// floating point), so only the upper triangle is summed and mirrored.
pub fn gram(m: &nalgebra::DMatrix<f64>) -> nalgebra::DMatrix<f64> {
    let (rows, n) = m.shape();
    let data = m.as_slice();
    let column = |k: usize| &data[k * rows..(k + 1) * rows];
    let mut out = nalgebra::DMatrix::zeros(n, n);
    for i in 0..n {
        for j in i..n {
            let v = dot_nalgebra_order(column(i), column(j));
            out[(i, j)] = v;
            out[(j, i)] = v;
        }
    }
    out
}

/// `mᵀ v` bit for bit as nalgebra's `m.tr_mul(&v)` computes it.
pub fn tr_mul_vec(m: &nalgebra::DMatrix<f64>, v: &[f64]) -> nalgebra::DVector<f64> {
    let (rows, n) = m.shape();
    let data = m.as_slice();
    nalgebra::DVector::from_fn(n, |k, _| dot_nalgebra_order(&data[k * rows..(k + 1) * rows], v))
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
        let other: Vec<f64> = (0..5).map(|i| (i as f64 * 0.37).sin()).collect();
        let mut single = vec![0.0; 7];
        dense.mul_vec(&other, &mut single);
        let (mut first, mut second) = (vec![0.0; 7], vec![0.0; 7]);
        dense.mul_vec_pair([&x, &other], [&mut first, &mut second]);
        assert!(first.iter().zip(&out).all(|(a, b)| a.to_bits() == b.to_bits()));
        assert!(second.iter().zip(&single).all(|(a, b)| a.to_bits() == b.to_bits()));
        let mut out = vec![0.0; 5];
        dense.mul_transposed_vec(&y, &mut out);
        let expected = m.transpose() * nalgebra::DVector::from_column_slice(&y);
        assert!(out.iter().zip(expected.iter()).all(|(a, b)| (a - b).abs() < 1e-12));
        assert!(solve_small([[0.0, 0.0], [0.0, 0.0]], [1.0, 1.0]).is_none());
    }

    #[test]
    fn gram_and_transposed_products_are_nalgebras_bit_for_bit() {
        // Lengths around the unrolling (8) and values whose sums round differently in another order.
        for rows in [1usize, 7, 8, 9, 23, 330] {
            let m = nalgebra::DMatrix::from_fn(rows, 6, |r, c| {
                ((r * 7 + c * 13) as f64 * 0.618_033_988).sin() * 10f64.powi((r % 5) as i32 - 2)
            });
            let v: Vec<f64> = (0..rows).map(|r| (r as f64 * 1.3).cos() / 3.0).collect();
            let expected = m.tr_mul(&m);
            let found = gram(&m);
            assert!(expected
                .iter()
                .zip(found.iter())
                .all(|(a, b)| a.to_bits() == b.to_bits()));
            let expected = m.tr_mul(&nalgebra::DVector::from_column_slice(&v));
            let found = tr_mul_vec(&m, &v);
            assert!(expected
                .iter()
                .zip(found.iter())
                .all(|(a, b)| a.to_bits() == b.to_bits()));
        }
    }
}
