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
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2.
            unsafe { self.mul_vecs_avx2([x], [out]) };
            return;
        }
        for (r, o) in out.iter_mut().enumerate() {
            *o = dot(self.row(r), x);
        }
    }

    /// [`Self::mul_vec`] of two vectors in one pass over the matrix (read from memory once rather than twice); each
    /// output is bit for bit what `mul_vec` gives it.
    pub fn mul_vec_pair(&self, x: [&[f64]; 2], out: [&mut [f64]; 2]) {
        debug_assert!(x.iter().all(|x| x.len() == self.cols));
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2.
            unsafe { self.mul_vecs_avx2(x, out) };
            return;
        }
        let [first, second] = out;
        debug_assert!(first.len() == self.rows && second.len() == self.rows);
        for (r, (a, b)) in first.iter_mut().zip(second.iter_mut()).enumerate() {
            let row = self.row(r);
            *a = dot(row, x[0]);
            *b = dot(row, x[1]);
        }
    }

    /// [`Self::mul_vec`] of `K` vectors in one pass over the matrix with AVX2 (see [`rows_dot_avx2`]): every output
    /// is bit for bit what `mul_vec` gives it.
    ///
    /// # Safety
    /// The processor has AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn mul_vecs_avx2<const K: usize>(&self, x: [&[f64]; K], out: [&mut [f64]; K]) {
        assert!(x.iter().all(|x| x.len() == self.cols) && out.iter().all(|o| o.len() == self.rows));
        // SAFETY: the processor has AVX2.
        unsafe { rows_dot_avx2((0..self.rows).map(|r| self.row(r)), x, out) }
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

/// [`dot`] of each of `rows` with `x`, into `out`: bit for bit what `dot` gives each, with AVX2 where the processor
/// has it (checked at run time, see [`rows_dot_avx2`]).
pub fn dot_each(rows: &[&[f64]], x: &[f64], out: &mut [f64]) {
    assert!(rows.iter().all(|row| row.len() == x.len()) && out.len() == rows.len());
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the processor has AVX2.
        unsafe { rows_dot_avx2(rows.iter().copied(), [x], [out]) };
        return;
    }
    for (o, row) in out.iter_mut().zip(rows) {
        *o = dot(row, x);
    }
}

/// [`dot`] of each row with each of `K` vectors, in one pass over the rows, with AVX2: `dot`'s four accumulators are
/// the lanes of one vector, combined as `dot` combines them, then its tail; the same operations in the same order (no
/// fused multiply-add), so every output is bit for bit what `dot` gives it. Every row and every `x` is as long as
/// `x[0]`, and every `out` holds a value per row.
///
/// # Safety
/// The processor has AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn rows_dot_avx2<'a, const K: usize>(
    rows: impl Iterator<Item = &'a [f64]>,
    x: [&[f64]; K],
    out: [&mut [f64]; K],
) {
    use std::arch::x86_64::*;
    let n = x.first().map_or(0, |x| x.len());
    assert!(x.iter().all(|x| x.len() == n));
    let chunks = n / 4;
    for (r, row) in rows.enumerate() {
        assert!(row.len() == n && out.iter().all(|o| r < o.len()));
        let mut acc = [_mm256_setzero_pd(); K];
        for c in 0..chunks {
            // SAFETY: chunk c's four values lie in the row and in every x (4 * chunks <= n, checked above).
            unsafe {
                let a = _mm256_loadu_pd(row.as_ptr().add(4 * c));
                for k in 0..K {
                    acc[k] = _mm256_add_pd(acc[k], _mm256_mul_pd(a, _mm256_loadu_pd(x[k].as_ptr().add(4 * c))));
                }
            }
        }
        for k in 0..K {
            let mut lanes = [0.0f64; 4];
            // SAFETY: `lanes` holds four f64.
            unsafe { _mm256_storeu_pd(lanes.as_mut_ptr(), acc[k]) };
            let mut sum = (lanes[0] + lanes[1]) + (lanes[2] + lanes[3]);
            for i in 4 * chunks..n {
                sum += row[i] * x[k][i];
            }
            out[k][r] = sum;
        }
    }
}

/// A symmetric matrix stored as its lower triangle, row by row: entry (i, k), k <= i, at i (i + 1) / 2 + k (half
/// the bytes of the square).
#[derive(Clone, Debug, PartialEq)]
pub struct PackedSymmetric {
    pub n: usize,
    pub data: Vec<f64>,
}

impl PackedSymmetric {
    /// The lower triangle of the symmetric `m`.
    pub fn from_nalgebra(m: &nalgebra::DMatrix<f64>) -> Self {
        let n = m.nrows();
        assert_eq!(n, m.ncols(), "a symmetric matrix is square");
        let data = (0..n).flat_map(|i| (0..=i).map(move |k| m[(i, k)])).collect();
        Self { n, data }
    }

    /// Row i's entries up to the diagonal: (i, 0), ..., (i, i), contiguous.
    #[inline]
    pub fn row_to_diagonal(&self, i: usize) -> &[f64] {
        &self.data[i * (i + 1) / 2..i * (i + 1) / 2 + i + 1]
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
///
/// On a processor with AVX2 (checked at run time) four entries of a row are summed at once, each in the same order
/// (see `gram_avx2`).
pub fn gram(m: &nalgebra::DMatrix<f64>) -> nalgebra::DMatrix<f64> {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the processor has AVX2.
        return unsafe { gram_avx2(m) };
    }
    gram_plain(m)
}

fn gram_plain(m: &nalgebra::DMatrix<f64>) -> nalgebra::DMatrix<f64> {
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

/// [`gram_plain`] with AVX2: the eight accumulators of [`dot_nalgebra_order`] are two vectors of four, and four
/// columns j are summed against column i at once (its chunks read once for the four); every entry is the same
/// additions and multiplications in the same order (no fused multiply-add), so every bit is the same.
///
/// # Safety
/// The processor has AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn gram_avx2(m: &nalgebra::DMatrix<f64>) -> nalgebra::DMatrix<f64> {
    use std::arch::x86_64::*;
    let (rows, n) = m.shape();
    let data = m.as_slice();
    let column = |k: usize| &data[k * rows..(k + 1) * rows];
    let chunks = rows / 8;
    let mut out = nalgebra::DMatrix::zeros(n, n);
    // The scalar finish of one entry: the accumulators combined as dot_nalgebra_order combines them, then the tail.
    let finish = |lo: __m256d, hi: __m256d, a: &[f64], b: &[f64]| {
        let mut pairs = [0.0f64; 4];
        // SAFETY: `pairs` holds four f64.
        unsafe { _mm256_storeu_pd(pairs.as_mut_ptr(), _mm256_add_pd(lo, hi)) };
        let mut res = 0.0;
        res += pairs[0];
        res += pairs[1];
        res += pairs[2];
        res += pairs[3];
        for (x, y) in a[8 * chunks..].iter().zip(&b[8 * chunks..]) {
            res += x * y;
        }
        res
    };
    for i in 0..n {
        let a = column(i);
        let mut j = i;
        while j + 4 <= n {
            let b: [&[f64]; 4] = std::array::from_fn(|t| column(j + t));
            let mut lo = [_mm256_setzero_pd(); 4];
            let mut hi = [_mm256_setzero_pd(); 4];
            for c in 0..chunks {
                // SAFETY: chunk c's eight values lie in every column (8 * chunks <= rows).
                unsafe {
                    let (a_lo, a_hi) = (
                        _mm256_loadu_pd(a.as_ptr().add(8 * c)),
                        _mm256_loadu_pd(a.as_ptr().add(8 * c + 4)),
                    );
                    for t in 0..4 {
                        let p = b[t].as_ptr().add(8 * c);
                        lo[t] = _mm256_add_pd(lo[t], _mm256_mul_pd(a_lo, _mm256_loadu_pd(p)));
                        hi[t] = _mm256_add_pd(hi[t], _mm256_mul_pd(a_hi, _mm256_loadu_pd(p.add(4))));
                    }
                }
            }
            for t in 0..4 {
                let v = finish(lo[t], hi[t], a, b[t]);
                out[(i, j + t)] = v;
                out[(j + t, i)] = v;
            }
            j += 4;
        }
        while j < n {
            let b = column(j);
            let (mut lo, mut hi) = (_mm256_setzero_pd(), _mm256_setzero_pd());
            for c in 0..chunks {
                // SAFETY: as above.
                unsafe {
                    let p = b.as_ptr().add(8 * c);
                    lo = _mm256_add_pd(
                        lo,
                        _mm256_mul_pd(_mm256_loadu_pd(a.as_ptr().add(8 * c)), _mm256_loadu_pd(p)),
                    );
                    hi = _mm256_add_pd(
                        hi,
                        _mm256_mul_pd(_mm256_loadu_pd(a.as_ptr().add(8 * c + 4)), _mm256_loadu_pd(p.add(4))),
                    );
                }
            }
            let v = finish(lo, hi, a, b);
            out[(i, j)] = v;
            out[(j, i)] = v;
            j += 1;
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

/// Cholesky in place of the leading m x m lower triangle of column-major `l` (column stride `n`), in nalgebra's
/// order: column j updated by each column k < j in increasing k (`l_ij += (-l_jk) l_ik`), then the square root of
/// its diagonal and the division of the rest by it. `false` where a diagonal is not positive (nalgebra's `None`).
#[inline(always)]
fn factorise(l: &mut [f64], n: usize, m: usize) -> bool {
    for j in 0..m {
        let (done, rest) = l.split_at_mut(j * n);
        let column = &mut rest[j..m];
        for k in 0..j {
            let factor = -done[k * n + j];
            for (x, &y) in column.iter_mut().zip(&done[k * n + j..k * n + m]) {
                *x += factor * y;
            }
        }
        let diagonal = column[0];
        if !(diagonal > 0.0) {
            return false;
        }
        let denom = diagonal.sqrt();
        column[0] = denom;
        for x in &mut column[1..] {
            *x /= denom;
        }
    }
    true
}

/// [`factorise`] compiled for AVX2: its loops are element-wise (no sum reordered, no fused multiply-add), so the
/// wider vectors give the same bits.
///
/// # Safety
/// The processor has AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn factorise_avx2(l: &mut [f64], n: usize, m: usize) -> bool {
    factorise(l, n, m)
}

/// The Cholesky factor `L` (`L Lᵀ = H_SS`) of a symmetric positive definite matrix `H` restricted to an ordered set
/// `S` of its indices, kept up to date as `S` changes, for an active-set solve that would otherwise factorise
/// `H_SS` from scratch (O(m³)) at every step: an index joins at the end of `S` (one forward substitution, O(m²)) and
/// one leaves by deleting its row and column of `L` and folding its column below the diagonal back into the
/// trailing block (a rank-one update by plane rotations, O(m²)).
///
/// Bit for bit: a factor made by [`Self::new`] is nalgebra's; [`Self::push`] appends exactly the row that
/// nalgebra's factorisation of `S` with the new index last would end with (the same products summed in the same
/// order); [`Self::solve_mut`] is nalgebra's `Cholesky::solve` on the same factor. [`Self::remove`] is where the
/// bits part from a factorisation from scratch: the rotations are backward stable (the updated factor is the exact
/// factor of `H_SS` plus a perturbation of order m ε ‖H_SS‖ per removal) but round differently.
#[derive(Clone, Debug)]
pub struct UpdatedCholesky {
    /// Column stride of `l`: the full matrix's dimension (the most `S` can hold).
    n: usize,
    /// `S`, in the factor's order.
    index: Vec<usize>,
    /// Column-major n x n: `L[i][j]` (i >= j, both below `index.len()`) at `j * n + i`.
    l: Vec<f64>,
    /// Scratch for the column folded back in by `remove`.
    spill: Vec<f64>,
}

impl UpdatedCholesky {
    /// `H_SS` factorised from scratch with `S = index` in that order: nalgebra's Cholesky (each column j updated by
    /// the columns before it in increasing order, `l_ij += (-l_jk) l_ik`, then its square root of the diagonal and
    /// its division) bit for bit, on plain column slices of the factor (nalgebra's views cost ~100 instructions per
    /// pair of columns, more than their arithmetic at these sizes); `None` where nalgebra's fails (a diagonal not
    /// positive: not numerically positive definite).
    pub fn new(h: &nalgebra::DMatrix<f64>, index: Vec<usize>) -> Option<Self> {
        let n = h.nrows();
        let m = index.len();
        let mut l = vec![0.0; n * n];
        for (j, &c) in index.iter().enumerate() {
            let source = h.column(c);
            let source = source.as_slice();
            for (x, &r) in l[j * n + j..j * n + m].iter_mut().zip(&index[j..]) {
                *x = source[r];
            }
        }
        #[cfg(target_arch = "x86_64")]
        let factorised = if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2.
            unsafe { factorise_avx2(&mut l, n, m) }
        } else {
            factorise(&mut l, n, m)
        };
        #[cfg(not(target_arch = "x86_64"))]
        let factorised = factorise(&mut l, n, m);
        if !factorised {
            return None;
        }
        Some(Self {
            n,
            index,
            l,
            spill: Vec::with_capacity(n),
        })
    }

    /// `S` in the factor's order.
    pub fn index(&self) -> &[usize] {
        &self.index
    }

    /// `L[i][j]` (zero above the diagonal), for the tests that check the factor.
    #[cfg(test)]
    pub fn at(&self, i: usize, j: usize) -> f64 {
        if i < j {
            0.0
        } else {
            self.l[j * self.n + i]
        }
    }

    /// Appends index `v` to `S`. `false`, the factor unchanged, where `H` on `S` and `v` is not numerically positive
    /// definite (the new diagonal's square would not be positive: where nalgebra's factorisation fails too).
    pub fn push(&mut self, h: &nalgebra::DMatrix<f64>, v: usize) -> bool {
        let (n, m) = (self.n, self.index.len());
        assert!(m < n, "every index is already in the factor");
        // The new row y solves L y = H_Sv, column by column as nalgebra's factorisation builds it:
        // y_k = (H_kv + Σ_{j<k} (-y_j) L_kj) / L_kk, the sum in increasing j.
        let mut y: Vec<f64> = self.index.iter().map(|&i| h[(i, v)]).collect();
        self.forward_substitute(&mut y);
        let mut diagonal = h[(v, v)];
        for &yj in &y {
            diagonal += -yj * yj;
        }
        if !(diagonal > 0.0) {
            return false;
        }
        for (j, &yj) in y.iter().enumerate() {
            self.l[j * n + m] = yj;
        }
        self.l[m * n + m] = diagonal.sqrt();
        self.index.push(v);
        true
    }

    /// Removes the index at position `p` of `S`.
    pub fn remove(&mut self, p: usize) {
        let (n, m) = (self.n, self.index.len());
        assert!(p < m, "no position {p} in a factor of {m}");
        // Without row p, L's trailing block L22 must become the factor of L22 L22ᵀ + x xᵀ, x being column p below
        // the diagonal: one plane rotation per column turns [L22 | x] into [L22' | 0].
        self.spill.clear();
        self.spill.extend_from_slice(&self.l[p * n + p + 1..p * n + m]);
        for k in p + 1..m {
            let x = &mut self.spill[k - p - 1..];
            let (lkk, xk) = (self.l[k * n + k], x[0]);
            let r = (lkk * lkk + xk * xk).sqrt();
            let (c, s) = (lkk / r, xk / r);
            self.l[k * n + k] = r;
            for (lik, xi) in self.l[k * n + k + 1..k * n + m].iter_mut().zip(&mut x[1..]) {
                let (a, b) = (*lik, *xi);
                *lik = c * a + s * b;
                *xi = c * b - s * a;
            }
        }
        // Delete row p and column p: columns before p lose their row p; the trailing block moves up and left.
        for j in 0..p {
            self.l.copy_within(j * n + p + 1..j * n + m, j * n + p);
        }
        for j in p..m - 1 {
            self.l.copy_within((j + 1) * n + j + 1..(j + 1) * n + m, j * n + j);
        }
        self.index.remove(p);
    }

    /// The leading `k` x `k` block of `H_SS⁻¹`: its first `k` columns solved for, each bit for bit that column of
    /// nalgebra's `Cholesky::inverse` (which solves for every column of the identity the same way).
    pub fn inverse_block(&self, k: usize) -> nalgebra::DMatrix<f64> {
        let m = self.index.len();
        assert!(k <= m, "a block of {k} from a factor of {m}");
        let mut out = nalgebra::DMatrix::zeros(k, k);
        let mut column = vec![0.0; m];
        for c in 0..k {
            column.iter_mut().for_each(|x| *x = 0.0);
            column[c] = 1.0;
            self.solve_mut(&mut column);
            out.column_mut(c).copy_from_slice(&column[..k]);
        }
        out
    }

    /// Solves `L y = b` in place, column by column (`y_i = b_i / L_ii`, then `b_r += (-y_i) L_ri` below it), as
    /// nalgebra's solve and factorisation both do.
    fn forward_substitute(&self, b: &mut [f64]) {
        let (n, m) = (self.n, self.index.len());
        for i in 0..m {
            let bi = b[i] / self.l[i * n + i];
            b[i] = bi;
            for (t, &lri) in b[i + 1..].iter_mut().zip(&self.l[i * n + i + 1..i * n + m]) {
                *t += -bi * lri;
            }
        }
    }

    /// Solves `H_SS x = b` in place (`b` and `x` in the order of `S`), as nalgebra's `Cholesky::solve_mut` does.
    pub fn solve_mut(&self, b: &mut [f64]) {
        let (n, m) = (self.n, self.index.len());
        assert_eq!(b.len(), m, "right-hand side of the wrong length");
        self.forward_substitute(b);
        for i in (0..m).rev() {
            let dot = dot_nalgebra_order(&self.l[i * n + i + 1..i * n + m], &b[i + 1..]);
            b[i] = (b[i] - dot) / self.l[i * n + i];
        }
    }
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
        // mul_vec (vectorised where the processor allows) is `dot` of each row, bit for bit, at every length around
        // the four lanes.
        for cols in [1usize, 3, 4, 5, 8, 13, 330] {
            let m = Dense {
                rows: 9,
                cols,
                data: (0..9 * cols)
                    .map(|i| ((i * 37) as f64 * 0.618).sin() * 10f64.powi((i % 7) as i32 - 3))
                    .collect(),
            };
            let v: Vec<f64> = (0..cols).map(|i| (i as f64 * 1.7).cos() / 7.0).collect();
            let w: Vec<f64> = (0..cols).map(|i| (i as f64 * 0.3).sin() * 3.0).collect();
            let (mut one, mut a, mut b) = (vec![0.0; 9], vec![0.0; 9], vec![0.0; 9]);
            m.mul_vec(&v, &mut one);
            m.mul_vec_pair([&v, &w], [&mut a, &mut b]);
            for r in 0..9 {
                assert_eq!(one[r].to_bits(), dot(m.row(r), &v).to_bits());
                assert_eq!(a[r].to_bits(), dot(m.row(r), &v).to_bits());
                assert_eq!(b[r].to_bits(), dot(m.row(r), &w).to_bits());
            }
        }
        let mut out = vec![0.0; 5];
        dense.mul_transposed_vec(&y, &mut out);
        let expected = m.transpose() * nalgebra::DVector::from_column_slice(&y);
        assert!(out.iter().zip(expected.iter()).all(|(a, b)| (a - b).abs() < 1e-12));
        assert!(solve_small([[0.0, 0.0], [0.0, 0.0]], [1.0, 1.0]).is_none());
    }

    #[test]
    fn gram_and_transposed_products_are_nalgebras_bit_for_bit() {
        // Lengths around the unrolling (8) and values whose sums round differently in another order.
        for (rows, cols) in [
            (1usize, 6usize),
            (7, 6),
            (8, 6),
            (9, 6),
            (23, 6),
            (330, 6),
            (17, 11),
            (330, 45),
        ] {
            let m = nalgebra::DMatrix::from_fn(rows, cols, |r, c| {
                ((r * 7 + c * 13) as f64 * 0.618_033_988).sin() * 10f64.powi((r % 5) as i32 - 2)
            });
            let v: Vec<f64> = (0..rows).map(|r| (r as f64 * 1.3).cos() / 3.0).collect();
            let expected = m.tr_mul(&m);
            let found = gram(&m);
            assert!(expected
                .iter()
                .zip(found.iter())
                .all(|(a, b)| a.to_bits() == b.to_bits()));
            assert!(gram_plain(&m)
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

    /// Deterministic uniform draws in [-1, 1) (xorshift), the same on every run.
    fn uniform(seed: u64) -> impl FnMut() -> f64 {
        let mut state = seed;
        move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 52) as f64 - 1.0
        }
    }

    /// `aᵀ a` of a 40 x n design whose columns `near` are copies of column 0 plus `spread` times noise: a Gram matrix
    /// whose condition number grows as spread⁻².
    fn gram_of_near_collinear(n: usize, near: &[usize], spread: f64, seed: u64) -> nalgebra::DMatrix<f64> {
        let mut draw = uniform(seed);
        let mut a = nalgebra::DMatrix::from_fn(40, n, |_, _| draw());
        for &j in near {
            for r in 0..40 {
                a[(r, j)] = a[(r, 0)] + spread * draw();
            }
        }
        a.tr_mul(&a)
    }

    fn restricted(h: &nalgebra::DMatrix<f64>, index: &[usize]) -> nalgebra::DMatrix<f64> {
        nalgebra::DMatrix::from_fn(index.len(), index.len(), |i, j| h[(index[i], index[j])])
    }

    fn factor_matrix(f: &UpdatedCholesky) -> nalgebra::DMatrix<f64> {
        let m = f.index().len();
        nalgebra::DMatrix::from_fn(m, m, |i, j| f.at(i, j))
    }

    #[test]
    fn an_updated_cholesky_made_and_grown_is_nalgebras_factor_and_solve_bit_for_bit() {
        let h = gram_of_near_collinear(13, &[4], 1e-3, 3);
        // Made from scratch, in any order, the factor is nalgebra's.
        for index in [(0..13).collect::<Vec<usize>>(), vec![12, 3, 5, 0, 4, 9], vec![6]] {
            let made = UpdatedCholesky::new(&h, index.clone()).unwrap();
            let l = restricted(&h, &index).cholesky().unwrap().l();
            assert!(factor_matrix(&made)
                .iter()
                .zip(l.iter())
                .all(|(a, b)| a.to_bits() == b.to_bits()));
        }
        // Pushed one by one from nothing, the whole factor is nalgebra's.
        let mut whole = UpdatedCholesky::new(&h, Vec::new()).unwrap();
        for v in 0..13 {
            assert!(whole.push(&h, v));
        }
        let l = h.clone().cholesky().unwrap().l();
        assert!(factor_matrix(&whole)
            .iter()
            .zip(l.iter())
            .all(|(a, b)| a.to_bits() == b.to_bits()));
        let order = [7usize, 2, 11, 0, 5, 12, 4, 9, 1];
        let mut factor = UpdatedCholesky::new(&h, order[..4].to_vec()).unwrap();
        for &v in &order[4..] {
            assert!(factor.push(&h, v));
        }
        assert_eq!(factor.index(), &order);
        let fresh = restricted(&h, &order).cholesky().unwrap();
        let l = fresh.l();
        for i in 0..order.len() {
            for j in 0..=i {
                assert_eq!(factor.at(i, j).to_bits(), l[(i, j)].to_bits(), "L[{i}][{j}]");
            }
        }
        let mut draw = uniform(5);
        let b: Vec<f64> = (0..order.len()).map(|_| draw()).collect();
        let mut found = b.clone();
        factor.solve_mut(&mut found);
        let expected = fresh.solve(&nalgebra::DVector::from_column_slice(&b));
        assert!(found
            .iter()
            .zip(expected.iter())
            .all(|(a, b)| a.to_bits() == b.to_bits()));
        let inverse = fresh.inverse();
        let block = factor.inverse_block(5);
        assert!(block
            .iter()
            .zip(inverse.view((0, 0), (5, 5)).iter())
            .all(|(a, b)| a.to_bits() == b.to_bits()));
        // An index that makes the set indefinite (column 2 again, with half its diagonal) is refused, as nalgebra's
        // factorisation refuses it, and leaves the factor as it was.
        let mut indefinite = h.clone();
        indefinite.set_row(3, &h.row(2));
        indefinite.set_column(3, &h.column(2));
        indefinite[(3, 3)] = 0.5 * h[(2, 2)];
        assert!(restricted(&indefinite, &[0, 1, 2, 3]).cholesky().is_none());
        assert!(UpdatedCholesky::new(&indefinite, vec![0, 1, 2, 3]).is_none());
        let mut factor = UpdatedCholesky::new(&indefinite, vec![0, 1, 2]).unwrap();
        let before = factor_matrix(&factor);
        assert!(!factor.push(&indefinite, 3));
        assert_eq!(factor.index(), &[0, 1, 2]);
        assert_eq!(factor_matrix(&factor), before);
    }

    /// After every push and remove, on ill-conditioned sets (columns within 1e-4 and 1e-6 of each other) and with
    /// one column added and removed again and again: the updated factor reproduces H_SS to a backward error of a few
    /// units of rounding per update (whatever the conditioning), and stands as close to a fresh factorisation as the
    /// condition number allows (perturbation theory of the Cholesky factor: ‖ΔL‖_F ≤ κ₂(H) ‖ΔH‖_F / ‖H‖₂ ‖L‖₂ / √2
    /// to first order, ΔH both factors' backward errors; taken twice for the second order).
    #[test]
    fn an_updated_cholesky_stays_a_factor_of_the_set_through_ill_conditioned_pushes_and_removes() {
        let n = 12;
        for (spread, seed) in [(1e-2, 11u64), (1e-4, 12), (1e-6, 13)] {
            let h = gram_of_near_collinear(n, &[3, 7, 8], spread, seed);
            let mut factor = UpdatedCholesky::new(&h, vec![0, 1, 2, 3, 5, 7, 9, 11]).unwrap();
            let mut draw = uniform(seed + 100);
            let mut updates = 0usize;
            let mut worst_kappa: f64 = 0.0;
            for step in 0..400 {
                let m = factor.index().len();
                if step % 2 == 0 && step < 200 {
                    // The same column (collinear with 0, 7, 8) out and back in, from wherever it stands.
                    if let Some(p) = factor.index().iter().position(|&j| j == 3) {
                        factor.remove(p);
                    } else {
                        assert!(factor.push(&h, 3));
                    }
                } else if (draw() > 0.0 && m > 1) || m == n {
                    let p = ((draw() + 1.0) * 0.5 * m as f64) as usize % m;
                    factor.remove(p);
                } else {
                    let outside: Vec<usize> = (0..n).filter(|i| !factor.index().contains(i)).collect();
                    let v = outside[((draw() + 1.0) * 0.5 * outside.len() as f64) as usize % outside.len()];
                    assert!(factor.push(&h, v));
                }
                updates += 1;
                let index = factor.index().to_vec();
                let hs = restricted(&h, &index);
                let m = index.len() as f64;
                let eigen = hs.clone().symmetric_eigen().eigenvalues;
                let (lo, hi) = (eigen.min(), eigen.max());
                assert!(lo > 0.0);
                let kappa = hi / lo;
                worst_kappa = worst_kappa.max(kappa);
                let l = factor_matrix(&factor);
                let backward = (&l * l.transpose() - &hs).norm();
                let unit = m * f64::EPSILON * hi;
                assert!(
                    backward <= 4.0 * (updates as f64 + 1.0) * unit,
                    "spread {spread}, step {step}: ‖L Lᵀ - H_SS‖ = {backward:e}, {} units",
                    backward / unit
                );
                let fresh = hs.clone().cholesky().unwrap().l();
                let fresh_backward = (&fresh * fresh.transpose() - &hs).norm();
                let allowed = 2.0 * kappa * (backward + fresh_backward) / hi * hi.sqrt() / 2f64.sqrt();
                let forward = (&l - &fresh).norm();
                assert!(
                    forward <= allowed.max(4.0 * f64::EPSILON * fresh.norm()),
                    "spread {spread}, step {step}: κ {kappa:e}, ‖L - L_fresh‖ = {forward:e} > {allowed:e}"
                );
            }
            // The sets were as ill-conditioned as intended.
            assert!(worst_kappa > 0.1 / (spread * spread), "κ only {worst_kappa:e}");
        }
    }
}
