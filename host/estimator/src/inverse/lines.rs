//! Line loads: the matched filter of a pressure shape, the straight line shapes stage 2 picks loaded cells by, and
//! the fit of a straight, uniform line load at any angle and position.

use nusense_geometry::Point2;

use super::moments::{MOMENT_FLOOR_FRACTION, ROUND_EXTENT_PITCHES};
use super::{InverseModel, Observed, Region};

/// [`InverseModel::fit_line_to`]'s points along a line (mm apart), its most rounds, and the angle step (degrees) at
/// which it stops.
pub(super) const LINE_SAMPLE_MM: f64 = 0.5;
const LINE_FIT_ROUNDS: usize = 200;
pub(super) const LINE_FIT_ANGLE_TOLERANCE_DEG: f64 = 0.1;

/// The spread (mm, the radius of [`InverseModel::line_shape`]'s hexagon) of the line and round loads
/// [`InverseModel::pair_against_line`] compares: the line's fit starts it at this many grid pitches and keeps it within
/// 0 and this many. Started at 0, a lone step up can score lower before the other parameters follow, and the fit
/// stayed at 0 on two of tests/hard_cases.rs' pairs.
const SHAPE_SPREAD_START_PITCHES: f64 = 0.5;
const SHAPE_SPREAD_MAX_PITCHES: f64 = 2.0;
/// [`InverseModel::elongation`]'s second level (a fraction of the region's peak pressure) for a core that is round at
/// [`MOMENT_FLOOR_FRACTION`]: two presses side by side whose blur the cell map shows as one peak are elongated only
/// where the weaker's pressure counts, and above 30 % of the stronger's peak it hardly does (each cell weighs its
/// pressure less the floor, and the weaker of a 2 N and a 6 N press peaks at about a third of the other). The full
/// validation set's 5.7 N and 2.1 N spheres 10 mm apart were round at 30 % (and at 20 %) and elongated at 10 %; of the
/// 691 regions `split_pair` judged on both validation sets, the second level adds only that pair, one round press (the
/// pair fit's points then 3.7 mm apart, too close to be split) and one light edge (a line explains it better). Not the
/// only level: the low pressure around a contact (the solve's noise ring, the blur's tails) rounds some cores at 10 %
/// that are elongated at 30 % (two 20 mm edges and a 0.8 N edge of the validation sets, and the broad low sheets the
/// layered model's misfit leaves in `the_layered_model_places_a_press_within_a_cell`).
const WEAKER_PRESS_FLOOR_FRACTION: f64 = 0.1;
/// A spread point: the centre and a unit hexagon around it, an even share each.
const SPREAD_HEXAGON: [Point2; 7] = [
    [0.0, 0.0],
    [1.0, 0.0],
    [0.5, 0.866_025_403_784_438_6],
    [-0.5, 0.866_025_403_784_438_6],
    [-1.0, 0.0],
    [-0.5, -0.866_025_403_784_438_6],
    [0.5, -0.866_025_403_784_438_6],
];

/// A place `at` (in grid steps from the first of `n` nodes) as the node below it and the fraction of a step beyond it,
/// clamped to the grid (the last step's far end at most): the bilinear shares of a point between nodes.
pub(super) fn bilinear_split(at: f64, n: usize) -> (usize, f64) {
    let clamped = at.clamp(0.0, (n - 1) as f64);
    // Not negative, so the cast truncates as `floor` would (NaN to 0 either way), without a libm call: on x86-64
    // without SSE4.1, `floor` is a function call, most of a line's cost. Below n (a u16 or a few times one), the cast
    // through u32 is the same, in fewer instructions than a u64's.
    let low = (clamped as u32 as usize).min(n.saturating_sub(2));
    (low, clamped - low as f64)
}

/// A uniform load along a straight segment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct LineLoad {
    pub(super) centre_mm: Point2,
    /// Degrees from +x towards +y, in [0, 180).
    pub(super) angle_deg: f64,
    pub(super) length_mm: f64,
    /// Each of its points spread over a hexagon of this radius, mm (see [`InverseModel::line_shape`]).
    pub(super) spread_mm: f64,
}

/// A load shape's (cell, share) correlation with the matched filter's `matched` correlations of the frame.
pub(super) fn shape_correlation(shape: &[(usize, f64)], matched: &[f64]) -> f64 {
    shape.iter().map(|(j, w)| w * matched[*j]).sum()
}

/// Maximises `score` from `start` by a pattern search: each parameter stepped both ways in turn (each trial put back
/// in its domain by `constrain`), the steps halved when none improves, until `converged` says the steps are small
/// enough.
pub(super) fn pattern_search<const N: usize>(
    start: [f64; N],
    mut steps: [f64; N],
    converged: impl Fn(&[f64; N]) -> bool,
    constrain: impl Fn(&mut [f64; N]),
    score: &mut impl FnMut(&[f64; N]) -> f64,
) -> ([f64; N], f64) {
    let mut best = start;
    let mut best_score = score(&best);
    for _ in 0..LINE_FIT_ROUNDS {
        let mut improved = false;
        for k in 0..N {
            for sign in [1.0, -1.0] {
                let mut trial = best;
                trial[k] += sign * steps[k];
                constrain(&mut trial);
                let trial_score = score(&trial);
                if trial_score > best_score {
                    (best, best_score, improved) = (trial, trial_score, true);
                    break;
                }
            }
        }
        if !improved {
            steps.iter_mut().for_each(|s| *s *= 0.5);
            if converged(&steps) {
                break;
            }
        }
    }
    (best, best_score)
}

impl InverseModel {
    /// The line load along a region's second moments' major axis, through its centre, as long as its core, when the
    /// core is elongated (longer than wide by more than [`ROUND_EXTENT_PITCHES`]): where [`Self::fit_line_to`] starts.
    /// The core is taken at two levels: above [`MOMENT_FLOOR_FRACTION`] of the peak (the edge direction's core) and,
    /// when that is round, above [`WEAKER_PRESS_FLOOR_FRACTION`] (see there).
    pub(super) fn elongation(&self, region: &Region) -> Option<LineLoad> {
        let all = self.second_moments(region, 0.0)?;
        let pitch = self.pad.pitch_x_mm().max(self.pad.pitch_y_mm());
        [MOMENT_FLOOR_FRACTION, WEAKER_PRESS_FLOOR_FRACTION]
            .into_iter()
            .find_map(|fraction| {
                let (major, minor) = self.second_moments(region, fraction)?.axes();
                let (length_mm, width_mm) = ((12.0 * major).sqrt(), (12.0 * minor).sqrt());
                (length_mm - width_mm > ROUND_EXTENT_PITCHES * pitch).then_some(length_mm)
            })
            .map(|length_mm| LineLoad {
                centre_mm: all.centre,
                angle_deg: all.angle_deg(),
                length_mm,
                spread_mm: SHAPE_SPREAD_START_PITCHES * self.pad.pitch_x_mm().min(self.pad.pitch_y_mm()),
            })
    }

    /// [`Self::matched`] of the displacements less those of stage 2's tractions but the pressure on `cells`
    /// (sorted).
    pub(super) fn matched_without(&self, observed: Observed, cells: &[usize]) -> Vec<f64> {
        self.matched(&self.displacements_without(observed, cells), observed.valid)
    }

    /// The displacements of `observed` less those of stage 2's tractions but the pressure on `cells` (sorted).
    pub(super) fn displacements_without(&self, observed: Observed, cells: &[usize]) -> Vec<f64> {
        // Only the support's cells carry tractions: their columns of A, not all of it.
        let mut rest = observed.d.to_vec();
        for (component, &t) in observed.tractions.iter().enumerate() {
            let fitted = component % 3 == 2 && cells.binary_search(&(component / 3)).is_ok();
            if t != 0.0 && !fitted {
                for (r, a) in rest.iter_mut().zip(self.a_t.row(component)) {
                    *r -= t * a;
                }
            }
        }
        rest
    }

    /// The straight, uniform line load (centre, direction, length, spread) that explains the most of a normal load in
    /// the displacements whose [`Self::matched`] correlations are `matched`: the one whose least-squares fit, the
    /// motion free, lowers the residuals most, i.e. the largest (wᵀ A_pᵀ r)² / wᵀ G0 w over line shapes w (see
    /// `matched_gram`), searched from `start`; and that explained sum of squares (mm^2). A line is laid on the cells by
    /// bilinear shares of points 0.5 mm apart along it, each spread over a disc (see [`Self::line_shape`]), so it may
    /// lie at any angle and position. The spread is fitted because the model's load is sharper than what a press
    /// shows it (the contact's own size, the cover's blur and the model's error of the pad all spread it): on
    /// tests/hard_cases.rs' sensor the best line over two 3 mm spheres 10 mm apart spreads 3.5-4.1 mm, over a 20 mm
    /// edge 3.1-3.7 mm, and on the validation sensor's edges 0-2.3 mm.
    pub(super) fn fit_line_to(&self, matched: &[f64], start: LineLoad) -> (LineLoad, f64) {
        let pitch = self.pad.pitch_x_mm().min(self.pad.pitch_y_mm());
        let (mut dense, mut shape) = (Vec::new(), Vec::new());
        let mut score = |p: &[f64; 5]| -> f64 {
            self.line_shape([p[0], p[1]], p[2], p[3], p[4], &mut dense, &mut shape);
            let correlation = shape_correlation(&shape, matched);
            let energy = self.matched_product(&shape, &shape);
            if correlation > 0.0 && energy > 0.0 {
                correlation * correlation / energy
            } else {
                0.0
            }
        };
        let longest = self.pad.width_mm.max(self.pad.height_mm);
        let (best, best_score) = pattern_search(
            [
                start.centre_mm[0],
                start.centre_mm[1],
                start.angle_deg,
                start.length_mm,
                start.spread_mm,
            ],
            [0.25 * pitch, 0.25 * pitch, 4.0, 0.5 * pitch, 0.25 * pitch],
            |steps| steps[2] < LINE_FIT_ANGLE_TOLERANCE_DEG,
            |trial| {
                trial[3] = trial[3].clamp(pitch, longest);
                trial[4] = trial[4].clamp(0.0, SHAPE_SPREAD_MAX_PITCHES * pitch);
            },
            &mut score,
        );
        let line = LineLoad {
            centre_mm: [best[0], best[1]],
            angle_deg: best[2].rem_euclid(180.0) % 180.0,
            length_mm: best[3],
            spread_mm: best[4],
        };
        (line, best_score)
    }

    /// Sum over `u`'s and `v`'s cells of their shares times the matched filter's Gram entry (see `matched_gram`).
    pub(super) fn matched_product(&self, u: &[(usize, f64)], v: &[(usize, f64)]) -> f64 {
        u.iter()
            .map(|(j, wj)| {
                let row = self.matched_gram.row(*j);
                wj * v.iter().map(|(k, wk)| wk * row[*k]).sum::<f64>()
            })
            .sum()
    }

    /// A unit line load (centre, degrees, length in mm) on the cells: each of points 0.5 mm apart along it shared
    /// bilinearly among the four cell centres around it (clamped to the outermost cells' centres), as (cell,
    /// share); with `spread_mm` > 0 each point is first spread evenly over itself and a hexagon of points that far
    /// around it (a disc's coarse stand-in: the cells are 3.3 mm apart).
    /// The shares are summed in `dense` (one per cell, all zero or empty on entry and left all zero): a search
    /// that lays many shapes passes the same buffer, so that each shape reads back and clears only the cells its
    /// points reach.
    pub(super) fn line_shape(
        &self,
        centre: Point2,
        angle_deg: f64,
        length_mm: f64,
        spread_mm: f64,
        dense: &mut Vec<f64>,
        shape: &mut Vec<(usize, f64)>,
    ) {
        let (cols, rows) = (usize::from(self.pad.cols), usize::from(self.pad.rows));
        let origin = self.cells[0].centre_mm;
        let (px, py) = (self.pad.pitch_x_mm(), self.pad.pitch_y_mm());
        let points = (length_mm / LINE_SAMPLE_MM).ceil().max(2.0) as usize;
        let (c, s) = (angle_deg.to_radians().cos(), angle_deg.to_radians().sin());
        let spread: &[Point2] = if spread_mm > 0.0 {
            &SPREAD_HEXAGON
        } else {
            &[[0.0, 0.0]]
        };
        let weight = 1.0 / (points * spread.len()) as f64;
        let along = |i: usize| ((i as f64 + 0.5) / points as f64 - 0.5) * length_mm;
        let cell_x = |t: f64, offset: &Point2| (centre[0] + t * c + spread_mm * offset[0] - origin[0]) / px;
        let cell_y = |t: f64, offset: &Point2| (centre[1] + t * s + spread_mm * offset[1] - origin[1]) / py;
        // The rows and columns of the cells the points reach (each point's lower left of its four): every rounded
        // step above is monotonic in t, so with each offset a point's row and column lie between those of the first
        // and last points with that offset.
        let (mut rows_reached, mut cols_reached) = ((usize::MAX, 0), (usize::MAX, 0));
        for t in [along(0), along(points - 1)] {
            for offset in spread {
                let (col, row) = (
                    bilinear_split(cell_x(t, offset), cols).0,
                    bilinear_split(cell_y(t, offset), rows).0,
                );
                rows_reached = (rows_reached.0.min(row), rows_reached.1.max(row));
                cols_reached = (cols_reached.0.min(col), cols_reached.1.max(col));
            }
        }
        dense.resize(self.cells.len(), 0.0);
        for i in 0..points {
            let t = along(i);
            for offset in spread {
                let (col, fx) = bilinear_split(cell_x(t, offset), cols);
                let (row, fy) = bilinear_split(cell_y(t, offset), rows);
                let below = row * cols + col;
                let (low, high) = dense[below..below + cols + 2].split_at_mut(cols);
                low[0] += weight * (1.0 - fx) * (1.0 - fy);
                low[1] += weight * fx * (1.0 - fy);
                high[0] += weight * (1.0 - fx) * fy;
                high[1] += weight * fx * fy;
            }
        }
        shape.clear();
        for row in rows_reached.0..=rows_reached.1 + 1 {
            let first = row * cols + cols_reached.0;
            for (j, w) in (first..=first + cols_reached.1 + 1 - cols_reached.0).zip(&mut dense[first..]) {
                if *w > 0.0 {
                    shape.push((j, *w));
                }
                *w = 0.0;
            }
        }
    }

    /// A_pᵀ r (per cell) with r the motion-only residuals of `d` (2 per corner, mm) over the corners `valid`: the
    /// matched filter's correlations (see `matched_gram`).
    pub(super) fn matched(&self, d: &[f64], valid: &[bool]) -> Vec<f64> {
        let (d0, _) = self.masked(d, valid);
        let residuals = self.rigid_residuals(&d0, valid);
        let mut matched = vec![0.0; self.cells.len()];
        self.a_t_pressure.mul_vec(&residuals, &mut matched);
        matched
    }

    /// The least-squares normal force of a region's pressure shape (its cells' fz) in the displacements whose
    /// [`Self::matched`] correlations are `matched`, and its noise per mm of corner noise (N / mm). Unlike stage 2's
    /// own force, which its prior and p >= 0 pull low near the floor, it has no bias, so it is what a whole group is
    /// judged by against the floor.
    pub(super) fn matched_fit(&self, matched: &[f64], cells: &[(usize, [f64; 3])]) -> (f64, f64) {
        let total: f64 = cells.iter().map(|(_, f)| f[2].max(0.0)).sum();
        if !(total > 0.0) {
            return (0.0, f64::INFINITY);
        }
        let w: Vec<(usize, f64)> = cells.iter().map(|(j, f)| (*j, f[2].max(0.0) / total)).collect();
        let correlation = shape_correlation(&w, matched);
        let energy = self.matched_product(&w, &w);
        if energy > 0.0 {
            (correlation / energy, energy.sqrt().recip())
        } else {
            (0.0, f64::INFINITY)
        }
    }

    /// The cells of the line loads at noise `noise_mm` in displacements with [`Self::matched`] correlations
    /// `matched`: a line
    /// shape's cells when its matched filter (see `matched_gram`) finds its load above [`Self::line_sigmas`] and
    /// above every square shape's (1 to 3 cells a side) on its cells, i.e. when a line explains the load better than
    /// any round patch there. A long contact spreads its load over a line of cells, none of which need clear its
    /// noise alone (stage 1's per-cell test is the matched filter of a single cell, blurred by the prior); a round
    /// one is best explained by a square, so this leaves its cells to the per-cell test.
    pub(super) fn line_loads(&self, matched: &[f64], noise_mm: f64) -> Vec<bool> {
        self.line_loads_beyond(matched, noise_mm, None)
    }

    /// The cells, none of `contacts`' (stage 2's, strongest first, their tractions in `observed`, solved on
    /// `support`), by which line loads carry the strongest further: those of the line shapes through one of its
    /// cells that [`Self::line_loads`] picks, in the displacements with the support's shear taken off (the shapes
    /// are pressure), and that explain them better than the contact's own pressure does. A long light contact's
    /// stronger part clears the per-cell test and the rest of it does not; on the validation sensor such edges read
    /// 0.3-0.7 of their force (20 mm at 1 N, 30 mm at 2 N) at a part of the line 2-10 mm from its centre
    /// (tests/light_edges.rs). A round contact's own pressure explains it better than a line through it; through
    /// the weaker contacts, lines grew phantoms over lost ink (tried).
    pub(super) fn lines_extending(
        &self,
        contacts: &[Region],
        observed: Observed,
        support: &[usize],
        noise_mm: f64,
    ) -> Vec<bool> {
        let Some(strongest) = contacts.first() else {
            return vec![false; self.cells.len()];
        };
        let matched = self.matched_without(observed, support);
        let (force, noise_per_mm) = self.matched_fit(&matched, &strongest.cells);
        let mut through = vec![false; self.cells.len()];
        for (j, _) in &strongest.cells {
            through[*j] = true;
        }
        let significance = force / (noise_mm * noise_per_mm);
        let mut lines = self.line_loads_beyond(&matched, noise_mm, Some((&through, significance)));
        for (j, _) in contacts.iter().flat_map(|c| &c.cells) {
            lines[*j] = false;
        }
        lines
    }

    /// [`Self::line_loads`], of only the line shapes through a cell of `beyond.0` (per cell) whose load is more
    /// significant than `beyond.1` sigmas when given.
    fn line_loads_beyond(&self, matched: &[f64], noise_mm: f64, beyond: Option<(&[bool], f64)>) -> Vec<bool> {
        let cells = self.cells.len();
        let mut picked = vec![false; cells];
        if !(noise_mm > 0.0) {
            return picked;
        }
        let z = |(shape, norm): &(Vec<usize>, f64)| shape.iter().map(|&j| matched[j]).sum::<f64>() / (noise_mm * norm);
        let mut best_block = vec![f64::NEG_INFINITY; cells];
        for block in &self.block_shapes {
            let zb = z(block);
            for &j in &block.0 {
                best_block[j] = best_block[j].max(zb);
            }
        }
        for line in &self.line_shapes {
            let zl = z(line);
            let carries = beyond.is_none_or(|(through, least)| zl > least && line.0.iter().any(|&j| through[j]));
            if carries && zl > self.line_sigmas && line.0.iter().all(|&j| zl > best_block[j]) {
                for &j in &line.0 {
                    picked[j] = true;
                }
            }
        }
        picked
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inverse::test_support::{camera_moved, field, model};

    #[test]
    fn line_shape_is_the_same_in_a_reused_buffer() {
        // A search passes one buffer to every shape it lays: each must read as if laid in a fresh one, at any angle,
        // spread and position (the grid's edges clamp the points), and leave the buffer clear.
        let model = model();
        let mut dense = Vec::new();
        let (mut reused, mut fresh) = (Vec::new(), Vec::new());
        for (k, (angle, length, spread)) in [
            (0.0, 18.0, 0.0),
            (33.0, 12.5, 1.7),
            (97.0, 0.0, 3.3),
            (152.0, 40.0, 6.6),
        ]
        .into_iter()
        .enumerate()
        {
            for centre in [[-3.0, 2.0], [11.0, -7.5], [-30.0, 25.0]] {
                let centre = [centre[0] + 0.37 * k as f64, centre[1] - 0.21 * k as f64];
                model.line_shape(centre, angle, length, spread, &mut dense, &mut reused);
                model.line_shape(centre, angle, length, spread, &mut Vec::new(), &mut fresh);
                assert!(!fresh.is_empty());
                assert_eq!(reused, fresh);
                assert!(dense.iter().all(|&w| w == 0.0));
            }
        }
    }

    /// A 6 N line load laid on the cells as [`InverseModel::line_shape`] lays it (so the model explains it exactly),
    /// at angles off the grid's, under a camera motion: [`InverseModel::fit_line_to`] finds its direction and centre
    /// to within its steps from a start 5 deg and 1 mm off, and stage 2 keeps it one contact (no pair of round loads
    /// explains it better).
    #[test]
    fn a_line_load_is_fitted_at_angles_off_the_grid_and_not_split() {
        let model = model();
        let valid = vec![true; model.observations / 2];
        let motion = camera_moved();
        for (angle, centre) in [
            (12.0, [-3.0, 2.0]),
            (33.0, [4.0, -1.0]),
            (71.0, [1.0, 1.5]),
            (152.0, [-5.0, -2.0]),
        ] {
            let mut shape = Vec::new();
            model.line_shape(centre, angle, 18.0, 0.0, &mut Vec::new(), &mut shape);
            // The bilinear shares keep the line's force and centre.
            let total: f64 = shape.iter().map(|s| s.1).sum();
            let mean_x: f64 = shape.iter().map(|(j, w)| w * model.cells[*j].centre_mm[0]).sum();
            assert!((total - 1.0).abs() < 1e-12 && (mean_x - centre[0]).abs() < 1e-9);
            let load: Vec<(usize, [f64; 3])> = shape.iter().map(|&(j, w)| (j, [0.0, 0.0, 6.0 * w])).collect();
            let d = field(&model, &load, motion);
            let start = LineLoad {
                centre_mm: [centre[0] + 1.0, centre[1]],
                angle_deg: angle + 5.0,
                length_mm: 15.0,
                spread_mm: 0.0,
            };
            let (line, _) = model.fit_line_to(&model.matched(&d, &valid), start);
            assert!((line.angle_deg - angle).abs() < 0.2, "{angle} deg: found {line:?}");
            assert!(
                (line.centre_mm[0] - centre[0]).hypot(line.centre_mm[1] - centre[1]) < 0.2,
                "{line:?}"
            );
            let stage = model.stage1(&d, &valid);
            let stage2 = model.stage2(&d, &valid, &stage, 0.002, 0.1);
            assert_eq!(stage2.regions.len(), 1, "{angle} deg: {:?}", stage2.regions);
        }
    }
}
