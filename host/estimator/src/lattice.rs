//! The pattern's lattice as found in one frame: every yellow square and every interior corner by index, in raw
//! px, with the corners also undistorted and mapped to pad mm. Missing points are `None`, never guessed.

use nusense_geometry::{CornerIndex, PadGeometry, Point2, SquareIndex};
use serde::Serialize;

#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SquareObservation {
    pub index: SquareIndex,
    /// Centre of the yellow square (yellowness-weighted centroid), raw px.
    pub raw_px: Option<Point2>,
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct CornerObservation {
    pub index: CornerIndex,
    pub raw_px: Option<Point2>,
    pub undistorted_px: Option<Point2>,
    pub mm: Option<Point2>,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Lattice {
    pub pad: PadGeometry,
    /// One entry per yellow square, in `PadGeometry::yellow_squares` (row-major) order.
    pub squares: Vec<SquareObservation>,
    /// One entry per interior corner, at `PadGeometry::corner_slot`.
    pub corners: Vec<CornerObservation>,
}

impl Lattice {
    /// A lattice with nothing found yet.
    pub fn empty(pad: PadGeometry) -> Self {
        Self {
            pad,
            squares: pad
                .yellow_squares()
                .map(|index| SquareObservation { index, raw_px: None })
                .collect(),
            corners: pad
                .corners()
                .map(|index| CornerObservation {
                    index,
                    raw_px: None,
                    undistorted_px: None,
                    mm: None,
                })
                .collect(),
        }
    }

    pub fn squares_found(&self) -> usize {
        self.squares.iter().filter(|s| s.raw_px.is_some()).count()
    }

    pub fn corners_found(&self) -> usize {
        self.corners.iter().filter(|c| c.raw_px.is_some()).count()
    }

    pub fn corner(&self, index: CornerIndex) -> Option<&CornerObservation> {
        if index.row < self.pad.corner_rows() && index.col < self.pad.corner_cols() {
            self.corners.get(self.pad.corner_slot(index))
        } else {
            None
        }
    }

    /// Slot of a yellow square in `squares` (yellow squares alternate, so half a row per row).
    pub fn square_slot(&self, index: SquareIndex) -> Option<usize> {
        if index.row >= self.pad.rows || index.col >= self.pad.cols || !self.pad.is_yellow(index) {
            return None;
        }
        self.squares.binary_search_by_key(&index, |s| s.index).ok()
    }

    pub fn square(&self, index: SquareIndex) -> Option<Point2> {
        self.square_slot(index)
            .and_then(|slot| self.squares.get(slot))
            .and_then(|s| s.raw_px)
    }

    /// Where the pattern is: the raw-px box (min, max) around the squares found, grown on every side by
    /// `margin_cells` times the lattice's cell size (measured from those squares). A later frame needs only
    /// this part decoded. `None` with fewer than two squares in distinct rows and columns.
    pub fn region_px(&self, margin_cells: f64) -> Option<(Point2, Point2)> {
        let found: Vec<(SquareIndex, Point2)> =
            self.squares.iter().filter_map(|s| Some((s.index, s.raw_px?))).collect();
        let span = |axis: usize| {
            let key = |(i, _): &(SquareIndex, Point2)| if axis == 0 { i.col } else { i.row };
            let first = found.iter().min_by_key(|s| key(s))?;
            let last = found.iter().max_by_key(|s| key(s))?;
            let cells = f64::from(key(last) - key(first));
            (cells > 0.0).then(|| (last.1[axis] - first.1[axis]).abs() / cells)
        };
        let cell = span(0)?.max(span(1)?);
        let margin = margin_cells * cell;
        let (mut min, mut max) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for (_, p) in &found {
            for axis in 0..2 {
                min[axis] = min[axis].min(p[axis] - margin);
                max[axis] = max[axis].max(p[axis] + margin);
            }
        }
        Some((min, max))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn square_slots_follow_row_major_order() {
        for top_left_yellow in [true, false] {
            let pad = PadGeometry {
                rows: 5,
                cols: 6,
                top_left_yellow,
                ..PadGeometry::default()
            };
            let lattice = Lattice::empty(pad);
            for (slot, s) in lattice.squares.iter().enumerate() {
                assert_eq!(lattice.square_slot(s.index), Some(slot));
            }
        }
    }
}
