//! Lattice indices from topology: the yellow squares of a checkerboard form a lattice whose nearest neighbours
//! are the four diagonal ones. Walking that lattice from a central square gives every square a relative (row,
//! col); the walk follows the local step vectors, so the fisheye's changing scale across the frame is no
//! obstacle and nothing depends on sorting points into rows.

use std::collections::VecDeque;

use nusense_geometry::Point2;

use super::median;

/// Relative index of a square: `row` and `col` steps from the seed square (row + col is always even).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RelativeIndex {
    pub row: i32,
    pub col: i32,
}

pub struct Indexed {
    /// Per input point: its relative index, if the walk reached it.
    pub indices: Vec<Option<RelativeIndex>>,
    /// Global diagonal steps: `down_right` is (+1 row, +1 col), `up_right` is (-1 row, +1 col).
    pub down_right: Point2,
    pub up_right: Point2,
    /// Points reached twice with different indices (the walk keeps the first).
    pub conflicts: usize,
}

fn dist2(a: Point2, b: Point2) -> f64 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)
}

/// `None` when the points do not form a diagonal lattice (fewer than 5 points or no two step directions).
pub fn index_lattice(points: &[Point2]) -> Option<Indexed> {
    if points.len() < 5 {
        return None;
    }
    let step = median_nearest_distance(points);
    let (down_right, up_right) = diagonal_steps(points, step)?;
    let seed = nearest_to_centroid(points)?;
    let (indices, conflicts) = walk_lattice(points, seed, down_right, up_right);
    Some(Indexed {
        indices,
        down_right,
        up_right,
        conflicts,
    })
}

/// The median over points of the distance to each one's nearest other point: one diagonal step.
fn median_nearest_distance(points: &[Point2]) -> f64 {
    let mut nearest: Vec<f64> = points
        .iter()
        .enumerate()
        .map(|(i, &p)| {
            points
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .map(|(_, &q)| dist2(p, q))
                .fold(f64::MAX, f64::min)
                .sqrt()
        })
        .collect();
    median(&mut nearest)
}

/// The global diagonal steps (down-right, up-right): the component-wise medians of the vectors between points
/// about one `step` apart, each turned to point right; `None` unless both directions have two vectors or more.
fn diagonal_steps(points: &[Point2], step: f64) -> Option<(Point2, Point2)> {
    let (mut dr, mut ur) = (Vec::new(), Vec::new());
    for (i, &p) in points.iter().enumerate() {
        for &q in &points[i + 1..] {
            let mut v = [q[0] - p[0], q[1] - p[1]];
            let len = v[0].hypot(v[1]);
            if len < 0.7 * step || len > 1.35 * step {
                continue;
            }
            if v[0] < 0.0 {
                v = [-v[0], -v[1]];
            }
            if v[1] > 0.0 {
                dr.push(v);
            } else {
                ur.push(v);
            }
        }
    }
    if dr.len() < 2 || ur.len() < 2 {
        return None;
    }
    let component_median = |vs: &[Point2]| {
        let mut xs: Vec<f64> = vs.iter().map(|v| v[0]).collect();
        let mut ys: Vec<f64> = vs.iter().map(|v| v[1]).collect();
        [median(&mut xs), median(&mut ys)]
    };
    Some((component_median(&dr), component_median(&ur)))
}

/// The point nearest the points' centroid: the walk's seed, where the lattice is least distorted.
fn nearest_to_centroid(points: &[Point2]) -> Option<usize> {
    let n = points.len();
    let centre = [
        points.iter().map(|p| p[0]).sum::<f64>() / n as f64,
        points.iter().map(|p| p[1]).sum::<f64>() / n as f64,
    ];
    (0..n).min_by(|&a, &b| dist2(points[a], centre).total_cmp(&dist2(points[b], centre)))
}

/// Breadth-first walk from `seed` by the four diagonal steps; returns each point's relative index (if reached)
/// and the count of points reached again with a different index.
fn walk_lattice(
    points: &[Point2],
    seed: usize,
    down_right: Point2,
    up_right: Point2,
) -> (Vec<Option<RelativeIndex>>, usize) {
    let n = points.len();
    let mut indices = vec![None; n];
    // Each reached point carries the local step vectors it was reached with.
    let mut local = vec![(down_right, up_right); n];
    indices[seed] = Some(RelativeIndex { row: 0, col: 0 });
    let mut queue = VecDeque::from([seed]);
    let mut conflicts = 0;
    while let Some(i) = queue.pop_front() {
        let Some(here) = indices[i] else { continue };
        let (l_dr, l_ur) = local[i];
        let moves = [
            (l_dr, 1, 1, true),
            ([-l_dr[0], -l_dr[1]], -1, -1, true),
            (l_ur, -1, 1, false),
            ([-l_ur[0], -l_ur[1]], 1, -1, false),
        ];
        for (v, d_row, d_col, along_dr) in moves {
            let Some(j) = point_at_step(points, i, v) else {
                continue;
            };
            let index = RelativeIndex {
                row: here.row + d_row,
                col: here.col + d_col,
            };
            match indices[j] {
                Some(existing) if existing != index => conflicts += 1,
                Some(_) => {}
                None => {
                    indices[j] = Some(index);
                    let sign = if d_col > 0 { 1.0 } else { -1.0 };
                    let measured = [
                        sign * (points[j][0] - points[i][0]),
                        sign * (points[j][1] - points[i][1]),
                    ];
                    local[j] = if along_dr { (measured, l_ur) } else { (l_dr, measured) };
                    queue.push_back(j);
                }
            }
        }
    }
    (indices, conflicts)
}

/// The point other than `i` nearest to point `i` moved by `v`, if within 30 % of the step's length.
fn point_at_step(points: &[Point2], i: usize, v: Point2) -> Option<usize> {
    let predicted = [points[i][0] + v[0], points[i][1] + v[1]];
    let tolerance2 = 0.3f64.powi(2) * (v[0] * v[0] + v[1] * v[1]);
    let j = (0..points.len())
        .filter(|&j| j != i)
        .min_by(|&a, &b| dist2(points[a], predicted).total_cmp(&dist2(points[b], predicted)))?;
    if dist2(points[j], predicted) > tolerance2 {
        return None;
    }
    Some(j)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn indexes_a_distorted_checkerboard_without_sorting() {
        // Yellow cells of a 6 x 8 board under a gentle barrel warp and a 10 degree rotation.
        let mut points = Vec::new();
        let mut truth = Vec::new();
        let (s, c) = (10f64.to_radians().sin(), 10f64.to_radians().cos());
        for row in 0..6i32 {
            for col in 0..8i32 {
                if (row + col) % 2 != 0 {
                    continue;
                }
                let (x, y) = (f64::from(col) - 3.5, f64::from(row) - 2.5);
                let k = 1.0 - 0.01 * (x * x + y * y);
                let (x, y) = (x * k * 40.0, y * k * 40.0);
                points.push([500.0 + c * x - s * y, 400.0 + s * x + c * y]);
                truth.push((row, col));
            }
        }
        // A shuffled order must not matter.
        points.reverse();
        truth.reverse();
        let indexed = index_lattice(&points).unwrap();
        assert_eq!(indexed.conflicts, 0);
        let first = indexed.indices[0].unwrap();
        for (index, &(row, col)) in indexed.indices.iter().zip(&truth) {
            let index = index.unwrap();
            assert_eq!(
                (index.row - first.row, index.col - first.col),
                (row - truth[0].0, col - truth[0].1)
            );
        }
    }
}
