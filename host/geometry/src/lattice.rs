//! The pad's colour layer: a checkerboard of yellow squares on red, `rows x cols` cells over
//! `width_mm x height_mm` (the real pad: 12 x 16 cells, 53 x 40 mm; cell (0, 0), top-left as the camera sees it,
//! is yellow). Control points are the interior corners, where four cells meet.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::Point2;

/// Index of a cell of the checkerboard: `row` in `0..rows`, `col` in `0..cols`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize, JsonSchema)]
pub struct SquareIndex {
    pub row: u16,
    pub col: u16,
}

/// Index of an interior corner: `row` in `0..rows-1`, `col` in `0..cols-1`; corner (r, c) is the point shared by
/// cells (r, c), (r, c+1), (r+1, c) and (r+1, c+1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize, JsonSchema)]
pub struct CornerIndex {
    pub row: u16,
    pub col: u16,
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PadGeometry {
    /// Cells along y (down).
    pub rows: u16,
    /// Cells along x (right).
    pub cols: u16,
    /// Extent of the checkerboard along x.
    pub width_mm: f64,
    /// Extent of the checkerboard along y.
    pub height_mm: f64,
    /// Whether cell (0, 0) is yellow; the squares alternate from there.
    pub top_left_yellow: bool,
}

impl Default for PadGeometry {
    fn default() -> Self {
        Self {
            rows: 12,
            cols: 16,
            width_mm: 53.0,
            height_mm: 40.0,
            top_left_yellow: true,
        }
    }
}

impl PadGeometry {
    pub fn pitch_x_mm(&self) -> f64 {
        self.width_mm / f64::from(self.cols)
    }

    pub fn pitch_y_mm(&self) -> f64 {
        self.height_mm / f64::from(self.rows)
    }

    pub fn corner_rows(&self) -> u16 {
        self.rows.saturating_sub(1)
    }

    pub fn corner_cols(&self) -> u16 {
        self.cols.saturating_sub(1)
    }

    /// 165 on the real pad.
    pub fn corner_count(&self) -> usize {
        usize::from(self.corner_rows()) * usize::from(self.corner_cols())
    }

    /// 96 on the real pad.
    pub fn yellow_count(&self) -> usize {
        self.yellow_squares().count()
    }

    pub fn is_yellow(&self, cell: SquareIndex) -> bool {
        (cell.row + cell.col).is_multiple_of(2) == self.top_left_yellow
    }

    /// Row-major.
    pub fn corners(&self) -> impl Iterator<Item = CornerIndex> + '_ {
        (0..self.corner_rows()).flat_map(move |row| (0..self.corner_cols()).map(move |col| CornerIndex { row, col }))
    }

    /// The two yellow squares that meet diagonally at an interior corner, the upper first. The fast tracker takes the
    /// corner as the midpoint of their centroids.
    pub fn corner_squares(&self, CornerIndex { row, col }: CornerIndex) -> [SquareIndex; 2] {
        if self.is_yellow(SquareIndex { row, col }) {
            [
                SquareIndex { row, col },
                SquareIndex {
                    row: row + 1,
                    col: col + 1,
                },
            ]
        } else {
            [SquareIndex { row, col: col + 1 }, SquareIndex { row: row + 1, col }]
        }
    }

    /// Row-major.
    pub fn yellow_squares(&self) -> impl Iterator<Item = SquareIndex> + '_ {
        (0..self.rows)
            .flat_map(move |row| (0..self.cols).map(move |col| SquareIndex { row, col }))
            .filter(move |&cell| self.is_yellow(cell))
    }

    /// Position of an interior corner on the undeformed pad, in pad mm.
    pub fn corner_mm(&self, corner: CornerIndex) -> Point2 {
        [
            (f64::from(corner.col) + 1.0) * self.pitch_x_mm() - self.width_mm / 2.0,
            (f64::from(corner.row) + 1.0) * self.pitch_y_mm() - self.height_mm / 2.0,
        ]
    }

    /// Centre of a cell on the undeformed pad, in pad mm.
    pub fn square_centre_mm(&self, cell: SquareIndex) -> Point2 {
        [
            (f64::from(cell.col) + 0.5) * self.pitch_x_mm() - self.width_mm / 2.0,
            (f64::from(cell.row) + 0.5) * self.pitch_y_mm() - self.height_mm / 2.0,
        ]
    }

    /// Row-major position of a corner in a dense `corner_rows x corner_cols` array.
    pub fn corner_slot(&self, corner: CornerIndex) -> usize {
        usize::from(corner.row) * usize::from(self.corner_cols()) + usize::from(corner.col)
    }

    pub fn contains_mm(&self, p: Point2) -> bool {
        p[0].abs() <= self.width_mm / 2.0 && p[1].abs() <= self.height_mm / 2.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn real_pad_counts() {
        let pad = PadGeometry::default();
        assert_eq!(pad.yellow_count(), 96);
        assert_eq!(pad.corner_count(), 165);
        assert!(pad.is_yellow(SquareIndex { row: 0, col: 0 }));
        assert!(!pad.is_yellow(SquareIndex { row: 0, col: 1 }));
    }

    #[test]
    fn each_corner_joins_two_yellow_squares_across_it() {
        for top_left_yellow in [true, false] {
            let pad = PadGeometry {
                top_left_yellow,
                ..PadGeometry::default()
            };
            for corner in pad.corners() {
                let [upper, lower] = pad.corner_squares(corner);
                assert!(pad.is_yellow(upper) && pad.is_yellow(lower), "{corner:?}");
                // Diagonal neighbours, one on each side of the corner in both directions.
                let centre = pad.corner_mm(corner);
                let (a, b) = (pad.square_centre_mm(upper), pad.square_centre_mm(lower));
                assert!(((a[0] + b[0]) / 2.0 - centre[0]).abs() < 1e-12, "{corner:?}");
                assert!(((a[1] + b[1]) / 2.0 - centre[1]).abs() < 1e-12, "{corner:?}");
                assert!(a[1] < centre[1] && b[1] > centre[1] && (a[0] - centre[0]) * (b[0] - centre[0]) < 0.0);
            }
        }
    }

    #[test]
    fn corner_grid_is_centred() {
        let pad = PadGeometry::default();
        let centre = pad.corner_mm(CornerIndex { row: 5, col: 7 });
        assert!(centre[0].abs() < 1e-12 && centre[1].abs() < 1e-12);
        let first = pad.corner_mm(CornerIndex { row: 0, col: 0 });
        let last = pad.corner_mm(CornerIndex { row: 10, col: 14 });
        assert!((first[0] + last[0]).abs() < 1e-12 && (first[1] + last[1]).abs() < 1e-12);
        assert_eq!(pad.corner_slot(CornerIndex { row: 10, col: 14 }), 164);
    }
}
