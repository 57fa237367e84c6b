//! What the inverse's unit tests share: the default model, deterministic noise, and loads laid on the cells.

use std::sync::Arc;

use nusense_geometry::Point2;

use super::{InverseModel, MOTION_PARAMETERS};
use crate::config::SensorConfig;

pub(super) fn model() -> Arc<InverseModel> {
    InverseModel::shared(&SensorConfig::default(), None).unwrap()
}

/// Deterministic unit-variance pseudo-Gaussian draws (xorshift, sum of 12 uniforms), the same on every run.
pub(super) fn pseudo_gauss(seed: u64) -> impl FnMut() -> f64 {
    let mut state = seed;
    move || {
        let mut sum = 0.0;
        for _ in 0..12 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            sum += (state >> 11) as f64 / (1u64 << 53) as f64;
        }
        sum - 6.0
    }
}

/// A small camera motion: a shift of 0.05 in x and a shear (of the motion basis's units).
pub(super) fn camera_moved() -> [f64; MOTION_PARAMETERS] {
    let mut motion = [0.0; MOTION_PARAMETERS];
    motion[0] = 0.05;
    motion[3] = 0.002;
    motion
}

/// Displacements of `forces` (per cell), plus a camera motion.
pub(super) fn field(model: &InverseModel, forces: &[(usize, [f64; 3])], motion: [f64; MOTION_PARAMETERS]) -> Vec<f64> {
    let mut t = vec![0.0; 3 * model.cells.len()];
    for (j, f) in forces {
        for k in 0..3 {
            t[3 * j + k] += f[k];
        }
    }
    let mut d = vec![0.0; model.observations];
    model.a.mul_vec(&t, &mut d);
    for (i, p) in model.points_mm.iter().enumerate() {
        let m = model.motion_field(&motion, *p);
        d[2 * i] += m[0];
        d[2 * i + 1] += m[1];
    }
    d
}

pub(super) fn cell_at(model: &InverseModel, p: Point2) -> usize {
    (0..model.cells.len())
        .min_by(|&a, &b| {
            let da = (model.cells[a].centre_mm[0] - p[0]).hypot(model.cells[a].centre_mm[1] - p[1]);
            let db = (model.cells[b].centre_mm[0] - p[0]).hypot(model.cells[b].centre_mm[1] - p[1]);
            da.total_cmp(&db)
        })
        .unwrap()
}

/// A force at the grid node at (row, col) (an interior corner), shared equally by the four cells that meet there:
/// the smallest load stage 2's node unknowns represent exactly.
pub(super) fn node_press(model: &InverseModel, row: usize, col: usize, force: [f64; 3]) -> Vec<(usize, [f64; 3])> {
    let cols = usize::from(model.pad.cols);
    model
        .node_cells(row * (cols + 1) + col)
        .into_iter()
        .map(|j| (j, force.map(|f| f / 4.0)))
        .collect()
}

/// The interior node nearest `p` (mm).
pub(super) fn node_at(model: &InverseModel, p: Point2) -> (usize, usize) {
    let pad = &model.pad;
    let col = ((p[0] + pad.width_mm / 2.0) / pad.pitch_x_mm()).round() as usize;
    let row = ((p[1] + pad.height_mm / 2.0) / pad.pitch_y_mm()).round() as usize;
    (
        row.clamp(1, usize::from(pad.rows) - 1),
        col.clamp(1, usize::from(pad.cols) - 1),
    )
}

/// A round press of `force_n` N (normal) over a disc of `radius_mm` about `centre` with Hertz's pressure
/// (sqrt(1 - r^2/a^2)), laid on the cells as points 0.25 mm apart each shared bilinearly among the four cell
/// centres around it ([`InverseModel::line_shape`] of a point): a sphere's contact, where it falls on the grid.
pub(super) fn hertz_press(
    model: &InverseModel,
    centre: Point2,
    radius_mm: f64,
    force_n: f64,
) -> Vec<(usize, [f64; 3])> {
    let step = 0.25;
    let reach = (radius_mm / step).ceil() as i32;
    let mut dense = vec![0.0; model.cells.len()];
    let mut point = Vec::new();
    for i in -reach..=reach {
        for j in -reach..=reach {
            let (x, y) = (f64::from(i) * step, f64::from(j) * step);
            let r2 = (x * x + y * y) / (radius_mm * radius_mm);
            if r2 < 1.0 {
                model.line_shape(
                    [centre[0] + x, centre[1] + y],
                    0.0,
                    0.0,
                    0.0,
                    &mut Vec::new(),
                    &mut point,
                );
                for &(k, share) in &point {
                    dense[k] += (1.0 - r2).sqrt() * share;
                }
            }
        }
    }
    let total: f64 = dense.iter().sum();
    dense
        .into_iter()
        .enumerate()
        .filter(|&(_, w)| w > 0.0)
        .map(|(k, w)| (k, [0.0, 0.0, force_n * w / total]))
        .collect()
}
