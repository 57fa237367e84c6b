//! Registration by lattice index: each corner of the frame against the same corner of the rest frame. A corner
//! is used only when both frames saw it and its motion is plausible: not beyond the configured number of cells,
//! and not far from what its lattice neighbours did (a lone jump is a detection error, not a deformation).

use nusense_geometry::{CornerIndex, PadGeometry, Point2};

use crate::lattice::Lattice;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RegisteredCorner {
    pub index: CornerIndex,
    pub reference_raw: Option<Point2>,
    pub current_raw: Option<Point2>,
    pub reference_mm: Option<Point2>,
    /// Motion on the pad since the reference, mm (both frames saw the corner).
    pub displacement_mm: Option<Point2>,
    /// Seen in both frames and plausible.
    pub valid: bool,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Registration {
    pub corners: Vec<RegisteredCorner>,
    /// Corners seen in both frames.
    pub matched: usize,
    /// Matched corners masked as implausible.
    pub implausible: usize,
}

impl Registration {
    pub fn valid_count(&self) -> usize {
        self.corners.iter().filter(|c| c.valid).count()
    }
}

/// A neighbour-inconsistent corner moved this many cells differently from the median of its neighbours.
const NEIGHBOUR_DISAGREEMENT_CELLS: f64 = 0.6;

/// The farthest a point may move on the pad and still be the same point, mm: `max_displacement_cells` of the
/// shorter pitch.
fn reach_mm(pad: &PadGeometry, max_displacement_cells: f64) -> f64 {
    max_displacement_cells * pad.pitch_x_mm().min(pad.pitch_y_mm())
}

pub fn register(reference: &Lattice, current: &Lattice, max_displacement_cells: f64) -> Registration {
    let pad: &PadGeometry = &reference.pad;
    let cell_mm = pad.pitch_x_mm().min(pad.pitch_y_mm());
    let reach_mm = reach_mm(pad, max_displacement_cells);
    let mut corners: Vec<RegisteredCorner> = reference
        .corners
        .iter()
        .zip(&current.corners)
        .map(|(r, c)| {
            let displacement_mm = match (r.mm, c.mm) {
                (Some(a), Some(b)) => Some([b[0] - a[0], b[1] - a[1]]),
                _ => None,
            };
            let plausible = displacement_mm.is_some_and(|d| d[0].hypot(d[1]) <= reach_mm);
            RegisteredCorner {
                index: r.index,
                reference_raw: r.raw_px,
                current_raw: c.raw_px,
                reference_mm: r.mm,
                displacement_mm,
                valid: plausible,
            }
        })
        .collect();
    let matched = corners.iter().filter(|c| c.displacement_mm.is_some()).count();
    // Neighbour consistency, judged against the motions before this pass so the order does not matter.
    let snapshot = corners.clone();
    let (rows, cols) = (i32::from(pad.corner_rows()), i32::from(pad.corner_cols()));
    for corner in corners.iter_mut().filter(|c| c.valid) {
        let Some(d) = corner.displacement_mm else { continue };
        let (r, c) = (i32::from(corner.index.row), i32::from(corner.index.col));
        // At most 8 neighbours: on the stack, not two allocations per corner and frame.
        let (mut dx, mut dy, mut n) = ([0.0; 8], [0.0; 8], 0);
        for (nr, nc) in [
            (r - 1, c),
            (r + 1, c),
            (r, c - 1),
            (r, c + 1),
            (r - 1, c - 1),
            (r + 1, c + 1),
            (r - 1, c + 1),
            (r + 1, c - 1),
        ] {
            if nr < 0 || nc < 0 || nr >= rows || nc >= cols {
                continue;
            }
            let neighbour = &snapshot[(nr * cols + nc) as usize];
            if let (true, Some(nd)) = (neighbour.valid, neighbour.displacement_mm) {
                dx[n] = nd[0];
                dy[n] = nd[1];
                n += 1;
            }
        }
        if n < 3 {
            continue;
        }
        let mid = |v: &mut [f64]| {
            v.sort_unstable_by(f64::total_cmp);
            v[v.len() / 2]
        };
        let (mx, my) = (mid(&mut dx[..n]), mid(&mut dy[..n]));
        if (d[0] - mx).hypot(d[1] - my) > NEIGHBOUR_DISAGREEMENT_CELLS * cell_mm {
            corner.valid = false;
        }
    }
    let implausible = corners
        .iter()
        .filter(|c| c.displacement_mm.is_some() && !c.valid)
        .count();
    Registration {
        corners,
        matched,
        implausible,
    }
}

/// The yellow squares' registration (`PadGeometry::yellow_squares` order) beside the corners' (`corners`): a square is
/// used when both frames found it (`reference_mm`, `current_mm`: pad mm), it moved no further than
/// `max_displacement_cells`, and no corner built from it was found implausible (a square the tracker lost to its
/// neighbour's place moves both its corners against their neighbours).
pub fn register_squares(
    pad: &PadGeometry,
    reference_mm: &[Option<Point2>],
    current_mm: &[Option<Point2>],
    corners: &Registration,
    max_displacement_cells: f64,
) -> Vec<bool> {
    let slots: Vec<_> = pad.yellow_squares().collect();
    let mut doubted = vec![false; slots.len()];
    for corner in corners
        .corners
        .iter()
        .filter(|c| c.displacement_mm.is_some() && !c.valid)
    {
        for square in pad.corner_squares(corner.index) {
            if let Ok(slot) = slots.binary_search(&square) {
                doubted[slot] = true;
            }
        }
    }
    let reach_mm = reach_mm(pad, max_displacement_cells);
    reference_mm
        .iter()
        .zip(current_mm)
        .zip(doubted)
        .map(|((rest, now), doubted)| {
            !doubted
                && rest
                    .zip(*now)
                    .is_some_and(|(r, n)| (n[0] - r[0]).hypot(n[1] - r[1]) <= reach_mm)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use nusense_geometry::CornerIndex;

    use super::*;

    /// A square is registered when both frames found it within reach and none of its corners was found implausible.
    #[test]
    fn a_square_is_registered_when_found_in_reach_and_its_corners_are_plausible() {
        let pad = PadGeometry::default();
        let squares: Vec<_> = pad.yellow_squares().collect();
        let rest: Vec<Option<Point2>> = squares.iter().map(|&s| Some(pad.square_centre_mm(s))).collect();
        let mut now = rest.clone();
        now[1] = None;
        now[2] = now[2].map(|p| [p[0] + 2.6 * pad.pitch_x_mm(), p[1]]);
        let implausible = CornerIndex { row: 3, col: 4 };
        let corners = Registration {
            corners: pad
                .corners()
                .map(|index| RegisteredCorner {
                    index,
                    reference_raw: None,
                    current_raw: None,
                    reference_mm: None,
                    displacement_mm: Some([0.0, 0.0]),
                    valid: index != implausible,
                })
                .collect(),
            matched: pad.corner_count(),
            implausible: 1,
        };
        let valid = register_squares(&pad, &rest, &now, &corners, 2.5);
        let doubted: Vec<usize> = pad
            .corner_squares(implausible)
            .iter()
            .map(|s| squares.binary_search(s).unwrap())
            .collect();
        for (slot, &ok) in valid.iter().enumerate() {
            let expected = slot != 1 && slot != 2 && !doubted.contains(&slot);
            assert_eq!(ok, expected, "square {slot}");
        }
        assert_eq!(valid.iter().filter(|&&v| !v).count(), 4);
    }
}
