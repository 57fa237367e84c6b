//! A long contact's direction from the straight, uniform line load that best explains its displacements, laid on the
//! fine grid (see [`super::FineGrid`]) rather than on the pattern's cells (`inverse.edge_from_line`).
//!
//! The second moments of the pressure map read a line through the 3.3 mm cells with an error that depends on where
//! the line crosses between the corners (docs/benchmarks/validation-full.md, "Edge direction"). The line load is
//! fitted to the displacements themselves, with the motion free and one amplitude, so its angle is continuous and
//! depends on the map only through where the search starts. Every corner counts: fitted only on the corners within 5,
//! 8 or 12 mm of the line, the quick validation set's edges read 3.9, 2.2 and 1.8 deg mean instead of 1.6.

use super::lines::{bilinear_split, pattern_search, LineLoad, LINE_FIT_ANGLE_TOLERANCE_DEG, LINE_SAMPLE_MM};
use super::{FineGrid, InverseModel, Observed, MOTION_PARAMETERS};
use crate::linalg::dot;

/// The projection P0 off the motion basis over the valid corners, as the line's score needs it.
struct MotionProjection<'a> {
    model: &'a InverseModel,
    /// BᵀB over the valid corners.
    gram: nalgebra::Cholesky<f64, nalgebra::Dyn>,
}

impl<'a> MotionProjection<'a> {
    fn new(model: &'a InverseModel, valid: &[bool]) -> Option<Self> {
        Some(Self {
            model,
            gram: model.motion_gram(valid).cholesky()?,
        })
    }

    /// aᵀ P0 a for a field `a` that is zero on the invalid corners' rows.
    fn energy(&self, a: &[f64]) -> f64 {
        let mut bta = nalgebra::DVector::zeros(MOTION_PARAMETERS);
        self.model.b_t.mul_vec(a, bta.as_mut_slice());
        dot(a, a) - bta.dot(&self.gram.solve(&bta))
    }
}

impl InverseModel {
    /// The straight, uniform line load (centre, angle, length) whose least-squares fit, the motion free, explains the
    /// most of `observed` less every traction of stage 2 but the pressure on `cells` (sorted): the largest
    /// (rᵀ a)² / aᵀ P0 a, with r those displacements' residuals off the motion and a the line's field, searched from
    /// `start`. `None` without the fine grid (`inverse.edge_from_line` off) or when the valid corners cannot fix the
    /// motion.
    pub(super) fn edge_line(&self, observed: Observed, cells: &[usize], start: LineLoad) -> Option<LineLoad> {
        let grid = self.fine.as_ref()?;
        let (d0, _) = self.masked(&self.displacements_without(observed, cells), observed.valid);
        let residuals = self.rigid_residuals(&d0, observed.valid);
        let projection = MotionProjection::new(self, observed.valid)?;
        let pitch = self.pad.pitch_x_mm().min(self.pad.pitch_y_mm());
        let longest = self.pad.width_mm.max(self.pad.height_mm);
        let mut weights = vec![0.0; grid.cols * grid.rows];
        let mut field = vec![0.0; self.observations];
        let mut score = |p: &[f64; 4]| -> f64 {
            grid.line_field([p[0], p[1]], p[2], p[3], &mut weights, &mut field);
            for (r, v) in field.iter_mut().enumerate() {
                if !observed.valid[r / 2] {
                    *v = 0.0;
                }
            }
            let correlation = dot(&residuals, &field);
            let energy = projection.energy(&field);
            if correlation > 0.0 && energy > 0.0 {
                correlation * correlation / energy
            } else {
                0.0
            }
        };
        let (best, _) = pattern_search(
            [start.centre_mm[0], start.centre_mm[1], start.angle_deg, start.length_mm],
            [0.25 * pitch, 0.25 * pitch, 4.0, 0.5 * pitch],
            |steps| steps[2] < LINE_FIT_ANGLE_TOLERANCE_DEG,
            |trial| trial[3] = trial[3].clamp(pitch, longest),
            &mut score,
        );
        Some(LineLoad {
            centre_mm: [best[0], best[1]],
            angle_deg: best[2].rem_euclid(180.0) % 180.0,
            length_mm: best[3],
            spread_mm: 0.0,
        })
    }
}

impl FineGrid {
    /// The field (2 per corner, mm) of a unit line load (centre, degrees, length in mm): points [`LINE_SAMPLE_MM`]
    /// apart along it, each shared bilinearly among the four fine cells' centres around it (clamped to the
    /// outermost). `weights` (one per fine cell) is all zero on entry and left so.
    fn line_field(&self, centre: [f64; 2], angle_deg: f64, length_mm: f64, weights: &mut [f64], field: &mut [f64]) {
        let points = (length_mm / LINE_SAMPLE_MM).ceil().max(2.0) as usize;
        let (c, s) = (angle_deg.to_radians().cos(), angle_deg.to_radians().sin());
        let share = 1.0 / points as f64;
        let mut touched: Vec<usize> = Vec::with_capacity(4 * points);
        for i in 0..points {
            let t = ((i as f64 + 0.5) / points as f64 - 0.5) * length_mm;
            let (col, fx) = bilinear_split((centre[0] + t * c - self.origin_mm[0]) / self.step_mm[0], self.cols);
            let (row, fy) = bilinear_split((centre[1] + t * s - self.origin_mm[1]) / self.step_mm[1], self.rows);
            let below = row * self.cols + col;
            for (j, w) in [
                (below, (1.0 - fx) * (1.0 - fy)),
                (below + 1, fx * (1.0 - fy)),
                (below + self.cols, (1.0 - fx) * fy),
                (below + self.cols + 1, fx * fy),
            ] {
                if weights[j] == 0.0 {
                    touched.push(j);
                }
                weights[j] += share * w;
            }
        }
        field.fill(0.0);
        for j in touched {
            let w = std::mem::take(&mut weights[j]);
            if w != 0.0 {
                for (f, a) in field.iter_mut().zip(self.pressure_t.row(j)) {
                    *f += w * a;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::SensorConfig;
    use crate::inverse::test_support::{camera_moved, field};

    /// A 6 N line load laid on the fine grid as [`FineGrid::line_field`] lays it (so the model explains it exactly),
    /// at angles off the grid's and across cell boundaries, under a camera motion: [`InverseModel::edge_line`] finds
    /// its direction and centre from a start 5 deg, 1 mm and 3 mm of length off. Without the fine grid (the default
    /// config) there is no line.
    #[test]
    fn a_line_load_on_the_fine_grid_is_found_at_any_angle() {
        let mut config = SensorConfig::default();
        config.inverse.edge_from_line = true;
        let model = InverseModel::shared(&config, None).unwrap();
        let grid = model.fine.as_ref().expect("edge_from_line builds the fine grid");
        let valid = vec![true; model.observations / 2];
        let motion = camera_moved();
        for (angle, centre) in [
            (12.0, [-3.0, 2.0]),
            (33.0, [4.3, -1.1]),
            (86.0, [1.0, 1.5]),
            (152.0, [-5.2, -2.4]),
        ] {
            let mut d = field(&model, &[], motion);
            let mut line = vec![0.0; model.observations];
            grid.line_field(centre, angle, 18.0, &mut vec![0.0; grid.cols * grid.rows], &mut line);
            d.iter_mut().zip(&line).for_each(|(d, l)| *d += 6.0 * l);
            let tractions = vec![0.0; 3 * model.cells.len()];
            let observed = Observed {
                d: &d,
                valid: &valid,
                tractions: &tractions,
            };
            let start = LineLoad {
                centre_mm: [centre[0] + 1.0, centre[1]],
                angle_deg: angle + 5.0,
                length_mm: 15.0,
                spread_mm: 0.0,
            };
            let found = model.edge_line(observed, &[], start).expect("a line");
            assert!((found.angle_deg - angle).abs() < 0.2, "{angle} deg: found {found:?}");
            assert!(
                (found.centre_mm[0] - centre[0]).hypot(found.centre_mm[1] - centre[1]) < 0.2,
                "{centre:?}: found {found:?}"
            );
            let default = crate::inverse::test_support::model();
            assert_eq!(default.edge_line(observed, &[], start), None);
        }
    }
}
