//! Tensor-product B-spline surface over a control net of 2-D points (the lattice corners), with clamped uniform
//! knots and any degree up to net size - 1 (The NURBS Book, algorithms A2.1 and A2.2).
//!
//! Conventions (the golden data of the tests follows them): the net has `rows x cols` points stored row-major;
//! `u` runs along the rows (first index, degree `p`), `v` along the columns (second index, degree `q`), both in
//! [0, 1]. This is geomdl's `ctrlpts2d[u][v]` layout. Clamped uniform knots for n + 1 points and degree p:
//! p + 1 zeros, the interior knots j / (n - p + 1) for j = 1..=n-p, p + 1 ones.
//!
//! Control points may be invalid (a lattice corner that was not found). A sample "rests on valid points" when
//! every control point with a non-zero basis weight at that sample is valid; only such samples are meaningful.

use nusense_geometry::Point2;
use thiserror::Error;

#[derive(Debug, Error, Clone, PartialEq)]
pub enum SurfaceError {
    #[error("the control net is empty ({rows} x {cols})")]
    EmptyNet { rows: usize, cols: usize },
    #[error("the control net has {rows} x {cols} slots but {points} points and {mask} mask entries were given")]
    SizeMismatch {
        rows: usize,
        cols: usize,
        points: usize,
        mask: usize,
    },
    #[error("degree {degree} along {axis} needs at least {} control points, the net has {points}", degree + 1)]
    DegreeTooHigh {
        axis: &'static str,
        degree: usize,
        points: usize,
    },
    #[error("degree must be at least 1 along {axis}")]
    DegreeZero { axis: &'static str },
    #[error("control point {index} is valid but not finite")]
    NotFinite { index: usize },
    #[error("the uv step {0} must be finite and in (0, 1]")]
    BadStep(f64),
    #[error("the parameter ({u}, {v}) lies outside [0, 1] x [0, 1]")]
    OutOfDomain { u: f64, v: f64 },
}

const NEGLIGIBLE_WEIGHT: f64 = 1e-12;

/// `rows x cols` control points, row-major, with a validity mask.
#[derive(Clone, Debug, PartialEq)]
pub struct ControlNet {
    rows: usize,
    cols: usize,
    points: Vec<Point2>,
    valid: Vec<bool>,
}

impl ControlNet {
    /// Invalid points may hold any value (they never enter a sample that rests on valid points).
    pub fn new(rows: usize, cols: usize, points: Vec<Point2>, valid: Vec<bool>) -> Result<Self, SurfaceError> {
        if rows == 0 || cols == 0 {
            return Err(SurfaceError::EmptyNet { rows, cols });
        }
        if points.len() != rows * cols || valid.len() != rows * cols {
            return Err(SurfaceError::SizeMismatch {
                rows,
                cols,
                points: points.len(),
                mask: valid.len(),
            });
        }
        if let Some(index) = points
            .iter()
            .zip(&valid)
            .position(|(p, &ok)| ok && !(p[0].is_finite() && p[1].is_finite()))
        {
            return Err(SurfaceError::NotFinite { index });
        }
        // Invalid slots are zeroed so that no NaN can leak through a zero basis weight.
        let points = points
            .iter()
            .zip(&valid)
            .map(|(&p, &ok)| if ok { p } else { [0.0, 0.0] })
            .collect();
        Ok(Self {
            rows,
            cols,
            points,
            valid,
        })
    }

    /// A net where missing points are `None`.
    pub fn from_options(rows: usize, cols: usize, points: &[Option<Point2>]) -> Result<Self, SurfaceError> {
        let valid = points.iter().map(Option::is_some).collect();
        let points = points.iter().map(|p| p.unwrap_or([0.0, 0.0])).collect();
        Self::new(rows, cols, points, valid)
    }

    /// A fully valid net.
    pub fn from_points(rows: usize, cols: usize, points: Vec<Point2>) -> Result<Self, SurfaceError> {
        let valid = vec![true; points.len()];
        Self::new(rows, cols, points, valid)
    }

    pub fn rows(&self) -> usize {
        self.rows
    }

    pub fn cols(&self) -> usize {
        self.cols
    }

    pub fn point(&self, row: usize, col: usize) -> Option<Point2> {
        let i = row * self.cols + col;
        (row < self.rows && col < self.cols && self.valid[i]).then(|| self.points[i])
    }

    pub fn valid_count(&self) -> usize {
        self.valid.iter().filter(|&&v| v).count()
    }
}

/// The non-zero basis functions of one parameter value: `first` is the index of the first control point they
/// weight, `weights` has degree + 1 entries.
#[derive(Clone, Debug, PartialEq)]
pub struct BasisSpan {
    pub first: usize,
    pub weights: Vec<f64>,
}

/// A clamped uniform knot vector for `points` control points of degree `degree`.
#[derive(Clone, Debug, PartialEq)]
pub struct KnotVector {
    degree: usize,
    knots: Vec<f64>,
}

impl KnotVector {
    pub fn clamped_uniform(degree: usize, points: usize, axis: &'static str) -> Result<Self, SurfaceError> {
        if degree == 0 {
            return Err(SurfaceError::DegreeZero { axis });
        }
        if points < degree + 1 {
            return Err(SurfaceError::DegreeTooHigh { axis, degree, points });
        }
        let n = points - 1;
        let interior = n - degree;
        let mut knots = vec![0.0; degree + 1];
        knots.extend((1..=interior).map(|j| j as f64 / (interior + 1) as f64));
        knots.extend(std::iter::repeat_n(1.0, degree + 1));
        Ok(Self { degree, knots })
    }

    pub fn knots(&self) -> &[f64] {
        &self.knots
    }

    pub fn degree(&self) -> usize {
        self.degree
    }

    fn control_points(&self) -> usize {
        self.knots.len() - self.degree - 1
    }

    /// A2.1: the knot span holding `t` (t = 1 belongs to the last non-empty span).
    fn span(&self, t: f64) -> usize {
        let n = self.control_points() - 1;
        let p = self.degree;
        if t >= self.knots[n + 1] {
            return n;
        }
        if t <= self.knots[p] {
            return p;
        }
        let (mut low, mut high) = (p, n + 1);
        let mut mid = (low + high) / 2;
        while t < self.knots[mid] || t >= self.knots[mid + 1] {
            if t < self.knots[mid] {
                high = mid;
            } else {
                low = mid;
            }
            mid = (low + high) / 2;
        }
        mid
    }

    /// A2.2: the degree + 1 non-zero basis functions at `t` in [0, 1].
    pub fn basis(&self, t: f64) -> BasisSpan {
        let p = self.degree;
        let span = self.span(t);
        let mut weights = vec![0.0; p + 1];
        let mut left = vec![0.0; p + 1];
        let mut right = vec![0.0; p + 1];
        weights[0] = 1.0;
        for j in 1..=p {
            left[j] = t - self.knots[span + 1 - j];
            right[j] = self.knots[span + j] - t;
            let mut saved = 0.0;
            for r in 0..j {
                let denominator = right[r + 1] + left[j - r];
                let temp = if denominator == 0.0 {
                    0.0
                } else {
                    weights[r] / denominator
                };
                weights[r] = saved + right[r + 1] * temp;
                saved = left[j - r] * temp;
            }
            weights[j] = saved;
        }
        BasisSpan {
            first: span - p,
            weights,
        }
    }
}

/// A B-spline surface of degree (p, q) over a [`ControlNet`].
#[derive(Clone, Debug, PartialEq)]
pub struct BSplineSurface {
    net: ControlNet,
    knots_u: KnotVector,
    knots_v: KnotVector,
}

/// Samples of a surface on a regular uv grid, u-major (all v for the first u, then the next u).
#[derive(Clone, Debug, PartialEq)]
pub struct SampleGrid {
    pub u_values: Vec<f64>,
    pub v_values: Vec<f64>,
    pub points: Vec<Point2>,
    /// Whether each sample rests only on valid control points.
    pub rests_on_valid: Vec<bool>,
}

impl SampleGrid {
    pub fn valid_count(&self) -> usize {
        self.rests_on_valid.iter().filter(|&&v| v).count()
    }
}

/// The parameter values 0, step, 2 step, ... below 1 (numpy's `arange(0, 1, step)`, the paper's sampling),
/// computed as multiples of the step so that they do not drift.
pub fn uv_values(step: f64) -> Result<Vec<f64>, SurfaceError> {
    if !(step.is_finite() && step > 0.0 && step <= 1.0) {
        return Err(SurfaceError::BadStep(step));
    }
    let count = (1.0 / step - 1e-9).ceil().max(1.0) as usize;
    Ok((0..count).map(|i| i as f64 * step).collect())
}

impl BSplineSurface {
    /// `degree_u` along the rows, `degree_v` along the columns.
    pub fn new(net: ControlNet, degree_u: usize, degree_v: usize) -> Result<Self, SurfaceError> {
        let knots_u = KnotVector::clamped_uniform(degree_u, net.rows, "u (rows)")?;
        let knots_v = KnotVector::clamped_uniform(degree_v, net.cols, "v (columns)")?;
        Ok(Self { net, knots_u, knots_v })
    }

    pub fn net(&self) -> &ControlNet {
        &self.net
    }

    pub fn knots_u(&self) -> &KnotVector {
        &self.knots_u
    }

    pub fn knots_v(&self) -> &KnotVector {
        &self.knots_v
    }

    /// The surface point at (u, v), and whether it rests only on valid control points.
    pub fn evaluate_checked(&self, u: f64, v: f64) -> Result<(Point2, bool), SurfaceError> {
        if !((0.0..=1.0).contains(&u) && (0.0..=1.0).contains(&v)) {
            return Err(SurfaceError::OutOfDomain { u, v });
        }
        Ok(self.combine(&self.knots_u.basis(u), &self.knots_v.basis(v)))
    }

    /// The surface point at (u, v) in [0, 1]^2 (clamped into the domain); invalid control points count as
    /// absent, see [`Self::evaluate_checked`] to know whether the point is meaningful.
    pub fn evaluate(&self, u: f64, v: f64) -> Point2 {
        let clamp = |t: f64| if t.is_finite() { t.clamp(0.0, 1.0) } else { 0.0 };
        self.combine(&self.knots_u.basis(clamp(u)), &self.knots_v.basis(clamp(v)))
            .0
    }

    fn combine(&self, bu: &BasisSpan, bv: &BasisSpan) -> (Point2, bool) {
        let mut point = [0.0, 0.0];
        let mut valid = true;
        for (a, &wu) in bu.weights.iter().enumerate() {
            for (b, &wv) in bv.weights.iter().enumerate() {
                let w = wu * wv;
                // Round-off leaves weights of 1e-17 where the basis is zero in exact arithmetic (at knots);
                // such a point does not carry the sample.
                if w.abs() < NEGLIGIBLE_WEIGHT {
                    continue;
                }
                let i = (bu.first + a) * self.net.cols + bv.first + b;
                valid &= self.net.valid[i];
                point[0] += w * self.net.points[i][0];
                point[1] += w * self.net.points[i][1];
            }
        }
        (point, valid)
    }

    /// Samples on the grid `uv_values(step) x uv_values(step)` (the paper: step 0.015, 67 x 67).
    pub fn sample_grid(&self, step: f64) -> Result<SampleGrid, SurfaceError> {
        let values = uv_values(step)?;
        Ok(self.sample_on(&SampleBasis::new(&self.knots_u, &self.knots_v, &values, &values)))
    }

    /// Samples with precomputed basis functions (the per-frame path: the knots never change). Each sample is
    /// `Self::combine` of its u and v spans, term by term in the same order from the basis's precomputed terms,
    /// so the result is the same to the bit.
    pub fn sample_on(&self, basis: &SampleBasis) -> SampleGrid {
        let mut points = Vec::with_capacity(basis.len());
        let mut rests_on_valid = Vec::with_capacity(points.capacity());
        let mut start = 0;
        for &end in &basis.term_ends {
            let mut point = [0.0, 0.0];
            let mut valid = true;
            for term in &basis.terms[start..end as usize] {
                let i = term.row as usize * self.net.cols + term.col as usize;
                valid &= self.net.valid[i];
                point[0] += term.weight * self.net.points[i][0];
                point[1] += term.weight * self.net.points[i][1];
            }
            points.push(point);
            rests_on_valid.push(valid);
            start = end as usize;
        }
        SampleGrid {
            u_values: basis.u_values.clone(),
            v_values: basis.v_values.clone(),
            points,
            rests_on_valid,
        }
    }
}

/// Basis functions of a fixed uv grid, computed once.
#[derive(Clone, Debug, PartialEq)]
pub struct SampleBasis {
    u_values: Vec<f64>,
    v_values: Vec<f64>,
    /// Every sample's terms (u-major samples; within a sample the order of [`BSplineSurface::combine`]), with the
    /// negligible ones left out: a sample costs a few multiply-adds, not a pass over both spans.
    terms: Vec<SampleTerm>,
    /// Where each sample's terms end in `terms`.
    term_ends: Vec<u32>,
}

/// One control point's weight in one sample.
#[derive(Clone, Copy, Debug, PartialEq)]
struct SampleTerm {
    row: u32,
    col: u32,
    weight: f64,
}

impl SampleBasis {
    pub fn new(knots_u: &KnotVector, knots_v: &KnotVector, u_values: &[f64], v_values: &[f64]) -> Self {
        let u: Vec<BasisSpan> = u_values.iter().map(|&t| knots_u.basis(t.clamp(0.0, 1.0))).collect();
        let v: Vec<BasisSpan> = v_values.iter().map(|&t| knots_v.basis(t.clamp(0.0, 1.0))).collect();
        let (mut terms, mut term_ends) = (Vec::new(), Vec::with_capacity(u.len() * v.len()));
        for bu in &u {
            for bv in &v {
                for (a, &wu) in bu.weights.iter().enumerate() {
                    for (b, &wv) in bv.weights.iter().enumerate() {
                        let weight = wu * wv;
                        // As in `combine`: round-off weights at knots do not carry the sample.
                        if weight.abs() >= NEGLIGIBLE_WEIGHT {
                            terms.push(SampleTerm {
                                row: (bu.first + a) as u32,
                                col: (bv.first + b) as u32,
                                weight,
                            });
                        }
                    }
                }
                term_ends.push(terms.len() as u32);
            }
        }
        Self {
            u_values: u_values.to_vec(),
            v_values: v_values.to_vec(),
            terms,
            term_ends,
        }
    }

    /// For a `rows x cols` net with degrees (p, q) on the grid `uv_values(step)` in both directions.
    pub fn for_net(
        rows: usize,
        cols: usize,
        degree_u: usize,
        degree_v: usize,
        step: f64,
    ) -> Result<Self, SurfaceError> {
        let ku = KnotVector::clamped_uniform(degree_u, rows, "u (rows)")?;
        let kv = KnotVector::clamped_uniform(degree_v, cols, "v (columns)")?;
        let values = uv_values(step)?;
        Ok(Self::new(&ku, &kv, &values, &values))
    }

    /// Visits every sample of two nets of the same shape at once, in sample order: the two points, each bit for bit
    /// the one [`BSplineSurface::sample_on`] gives, and whether the sample rests only on points valid in `first`.
    pub fn for_each_pair(&self, first: &ControlNet, second: &ControlNet, mut f: impl FnMut(Point2, Point2, bool)) {
        assert!(
            first.rows == second.rows && first.cols == second.cols,
            "two nets of different shapes"
        );
        let mut start = 0;
        for &end in &self.term_ends {
            let (mut a, mut b) = ([0.0, 0.0], [0.0, 0.0]);
            let mut valid = true;
            for term in &self.terms[start..end as usize] {
                let i = term.row as usize * first.cols + term.col as usize;
                valid &= first.valid[i];
                a[0] += term.weight * first.points[i][0];
                a[1] += term.weight * first.points[i][1];
                b[0] += term.weight * second.points[i][0];
                b[1] += term.weight * second.points[i][1];
            }
            f(a, b, valid);
            start = end as usize;
        }
    }

    pub fn len(&self) -> usize {
        self.term_ends.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn knots_are_clamped_uniform() {
        let k = KnotVector::clamped_uniform(2, 5, "u").unwrap();
        assert_eq!(k.knots(), &[0.0, 0.0, 0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0, 1.0, 1.0]);
        assert!(KnotVector::clamped_uniform(5, 5, "u").is_err());
        assert!(KnotVector::clamped_uniform(4, 5, "u").is_ok());
    }

    #[test]
    fn basis_is_a_partition_of_unity() {
        for degree in 1..=4 {
            let k = KnotVector::clamped_uniform(degree, 7, "u").unwrap();
            for i in 0..=100 {
                let b = k.basis(i as f64 / 100.0);
                let sum: f64 = b.weights.iter().sum();
                assert!((sum - 1.0).abs() < 1e-12, "degree {degree} t {i}: {sum}");
                assert!(b.first + degree < 7);
            }
        }
    }

    #[test]
    fn paper_grid_has_67_values() {
        let v = uv_values(0.015).unwrap();
        assert_eq!(v.len(), 67);
        assert!((v[66] - 0.99).abs() < 1e-12);
    }
}
