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
            squares: pad.yellow_squares().map(|index| SquareObservation { index, raw_px: None }).collect(),
            corners: pad
                .corners()
                .map(|index| CornerObservation { index, raw_px: None, undistorted_px: None, mm: None })
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
        self.square_slot(index).and_then(|slot| self.squares.get(slot)).and_then(|s| s.raw_px)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn square_slots_follow_row_major_order() {
        for top_left_yellow in [true, false] {
            let pad = PadGeometry { rows: 5, cols: 6, top_left_yellow, ..PadGeometry::default() };
            let lattice = Lattice::empty(pad);
            for (slot, s) in lattice.squares.iter().enumerate() {
                assert_eq!(lattice.square_slot(s.index), Some(slot));
            }
        }
    }
}
