//! Stage 1 and the contact test (see the module notes of [`super`]): the motion and the tractions' pressure by the
//! precomputed kriging operator, the frame's own noise, and the test of "rigid motion and noise only".

use nalgebra::{DMatrix, DVector};
use nusense_geometry::Point2;

use super::build::NEAR_TABLE_REACH_CELLS;
use super::noise::NoiseEstimate;
use super::{f_quantile, f_upper_tail, neighbourhood, normal_quantile, InverseModel, MOTION_PARAMETERS};
use crate::linalg::{dot, dot_each, gram};

/// The noise estimate leaves out this fraction of the corners with the largest residuals...
const NOISE_TRIM: f64 = 0.05;
/// ...which lowers the mean of the rest to this fraction of the full mean (for chi-square with 1 or 2 degrees of
/// freedom: 0.81 and 0.84; a corner's 2-D residual lies between the two).
const TRIMMED_MEAN_RATIO: f64 = 0.83;

/// The contact test's noise leaves out the corners this many cells or less from a load stage 1 finds.
pub(super) const MEASURED_NOISE_REACH_CELLS: f64 = 3.0;

/// The contact test is taken at the scatter the motion and one compact load leave when that load explains more than
/// this share of the far corners' squared scatter (see [`InverseModel::measured_test_and_loads_of`]).
const FAR_FIELD_VARIANCE_SHARE: f64 = 0.5;
/// ... and at the scatter the motion and a load on the cells of the line shapes leave when that load explains more
/// than this share (see the same function).
const LINE_FAR_FIELD_VARIANCE_SHARE: f64 = 0.8;
/// The compact loads the contact test fits at once when one does not explain the far field (see the same function):
/// up to four presses at once, as the fingers of a hand hold an object.
const MAX_COMPACT_LOADS: usize = 4;
/// Compact loads where stage 1 finds its most significant pressures (see [`InverseModel::compact_loads`]).
struct CompactLoads {
    /// Each load's cells: the 3 x 3 block around one of the most significant cells.
    blocks: Vec<Vec<usize>>,
    /// Per corner, whether it lies within [`MEASURED_NOISE_REACH_CELLS`] of a load's centre cell.
    near: Vec<bool>,
}

impl CompactLoads {
    /// Every load's cells, ascending.
    fn support(&self) -> Vec<usize> {
        let mut support: Vec<usize> = self.blocks.iter().flatten().copied().collect();
        support.sort_unstable();
        support
    }
}

/// A load fitted with the motion (see [`InverseModel::scatter_about_load`]).
#[derive(Clone, Copy)]
struct FittedLoad<'a> {
    /// Its cells, and which of their tractions (0, 1, 2: x, y, normal) are free on each.
    cells: &'a [usize],
    axes: &'a [usize],
    /// Blocks of its cells that carry one shear (x, y) alike, each.
    shared_shear: &'a [Vec<usize>],
}

/// Which corners judge a load's fit (see [`InverseModel::scatter_about_load`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Judged {
    /// Those away from it only.
    FarCorners,
    /// Those away from it, or every corner when it leaves too few away (a line across the pad, loads all over it).
    FarOrEveryCorner,
}
/// A load fit's columns (see `InverseModel::load_fit_columns`).
struct LoadFitColumns {
    /// (the model's fit column, the fit's column it adds to), ascending: each of the fit's columns is the sum of its
    /// parts (one, or a shared-shear block's cells' shear along one axis).
    parts: Vec<(usize, usize)>,
    /// How many: the motion's first, then the load's.
    columns: usize,
    /// The prior on each of the load's columns (lambda per cell it spans).
    prior: Vec<f64>,
}

/// The model's fit column of cell `j`'s traction `axis` (0, 1, 2: x, y, normal; see `InverseModel::fit_gram`).
fn traction_column(j: usize, axis: usize) -> usize {
    MOTION_PARAMETERS + 3 * j + axis
}

/// Fewer corners than this do not make a noise estimate.
const MIN_NOISE_CORNERS: usize = 10;

/// Stage 1's result for one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Stage1 {
    /// (fx, fy, fz) per cell, N, of which only fz is computed (fx and fy are 0): its pressure picks the loaded cells
    /// and is one of stage 2's shapes of the shear, and the tangential rows would double its cost (stage 2 reads
    /// the shear of the loaded cells alone from the residuals, see `InverseModel::shear_along_push`).
    pub tractions: Vec<f64>,
    /// Motion parameters (see [`InverseModel::motion_field`]).
    pub motion: [f64; MOTION_PARAMETERS],
    /// Per corner: residual after the fit (mm), `None` where the corner was not used.
    pub residuals: Vec<Option<Point2>>,
    /// Residual sums of squares of the rigid-only and the traction fit, mm^2.
    pub rss_rigid: f64,
    pub rss_full: f64,
}

/// The contact test's verdict.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TestOutcome {
    /// E / sigma^2.
    pub statistic: f64,
    /// The 1 - alpha quantile of its distribution under "no contact".
    pub threshold: f64,
    /// Probability of a statistic at least this large without contact.
    pub p_value: f64,
    /// The noise used, mm (1 sigma per axis per corner).
    pub noise_mm: f64,
    /// Normal force at the pad's centre whose expected statistic equals the threshold, N.
    pub detection_floor_n: f64,
    pub contact: bool,
}

fn motion_rows(p: Point2, length: f64) -> [[f64; MOTION_PARAMETERS]; 2] {
    let (x, y) = (p[0] / length, p[1] / length);
    [
        [
            1.0,
            0.0,
            x * length,
            y * length,
            0.0,
            0.0,
            -x * x * length,
            -x * y * length,
        ],
        [
            0.0,
            1.0,
            0.0,
            0.0,
            x * length,
            y * length,
            -x * y * length,
            -y * y * length,
        ],
    ]
}

pub(super) fn motion_basis(points: &[Point2], length: f64) -> DMatrix<f64> {
    let mut b = DMatrix::zeros(2 * points.len(), MOTION_PARAMETERS);
    for (i, &p) in points.iter().enumerate() {
        let rows = motion_rows(p, length);
        for k in 0..MOTION_PARAMETERS {
            b[(2 * i, k)] = rows[0][k];
            b[(2 * i + 1, k)] = rows[1][k];
        }
    }
    b
}

impl InverseModel {
    /// Displacement (mm) that motion parameters `m` give the pad point `p` (mm).
    pub fn motion_field(&self, m: &[f64; MOTION_PARAMETERS], p: Point2) -> Point2 {
        let row = motion_rows(p, self.motion_length_mm);
        [dot(&row[0], m), dot(&row[1], m)]
    }

    /// The motion as a homography of pad mm (its linearisation is `motion_field`), row-major.
    pub fn motion_homography(&self, m: &[f64; MOTION_PARAMETERS]) -> [f64; 9] {
        let l = self.motion_length_mm;
        // x' = x + m0 + m2 x + m3 y - (m6 x + m7 y) x (in units of l), y' likewise: a homography with perspective
        // row (m6 / l, m7 / l) to first order.
        [1.0 + m[2], m[3], m[0], m[4], 1.0 + m[5], m[1], m[6] / l, m[7] / l, 1.0]
    }

    /// Stage 1 (see the module notes). `d`: 2 per corner, mm; `valid`: per corner.
    pub fn stage1(&self, d: &[f64], valid: &[bool]) -> Stage1 {
        let (d0, missing) = self.masked(d, valid);
        let mut x = vec![0.0; self.observations + MOTION_PARAMETERS];
        self.s.mul_vec(&d0, &mut x);
        self.correct_missing(&mut x, &missing);
        let mut pressure = vec![0.0; self.cells.len()];
        self.a_t_pressure.mul_vec(&x[..self.observations], &mut pressure);
        self.stage1_result(&x, pressure, &d0, valid)
    }

    /// [`Self::stage1`] of the same displacements over two sets of corners (each result bit for bit what `stage1`
    /// gives): the operators are read once for both, a frame's two stage 1 solves (the motion's and the contact
    /// test's) being otherwise two passes over about 1.4 MB, and when the sets are the same it is solved once.
    pub fn stage1_pair(&self, d: &[f64], first: &[bool], second: &[bool]) -> (Stage1, Stage1) {
        if first == second {
            let stage = self.stage1(d, first);
            return (stage.clone(), stage);
        }
        let n = self.observations;
        let ((d0_a, missing_a), (d0_b, missing_b)) = (self.masked(d, first), self.masked(d, second));
        let (mut x_a, mut x_b) = (vec![0.0; n + MOTION_PARAMETERS], vec![0.0; n + MOTION_PARAMETERS]);
        self.s.mul_vec_pair([&d0_a, &d0_b], [&mut x_a, &mut x_b]);
        self.correct_missing(&mut x_a, &missing_a);
        self.correct_missing(&mut x_b, &missing_b);
        let (mut pressure_a, mut pressure_b) = (vec![0.0; self.cells.len()], vec![0.0; self.cells.len()]);
        self.a_t_pressure
            .mul_vec_pair([&x_a[..n], &x_b[..n]], [&mut pressure_a, &mut pressure_b]);
        (
            self.stage1_result(&x_a, pressure_a, &d0_a, first),
            self.stage1_result(&x_b, pressure_b, &d0_b, second),
        )
    }

    /// `d` zeroed on the rows of the corners not `valid`, and those rows.
    pub(super) fn masked(&self, d: &[f64], valid: &[bool]) -> (Vec<f64>, Vec<usize>) {
        let mut d0 = d.to_vec();
        let missing: Vec<usize> = (0..self.observations).filter(|&r| !valid[r / 2]).collect();
        for &r in &missing {
            d0[r] = 0.0;
        }
        (d0, missing)
    }

    /// Capacitance correction of the kriging solution `x` for the `missing` rows: find z on them so that the
    /// solution vanishes there.
    fn correct_missing(&self, x: &mut [f64], missing: &[usize]) {
        if missing.is_empty() {
            return;
        }
        let k = missing.len();
        let s_mm = DMatrix::from_fn(k, k, |i, j| self.s.at(missing[i], missing[j]));
        let rhs = DVector::from_fn(k, |i, _| -x[missing[i]]);
        if let Some(z) = s_mm.lu().solve(&rhs) {
            for (j, &col) in missing.iter().enumerate() {
                for (xr, s) in x.iter_mut().zip(self.s_t.row(col)) {
                    *xr += s * z[j];
                }
            }
        }
        for &r in missing {
            x[r] = 0.0;
        }
    }

    /// Stage 1's result from the corrected kriging solution `x` and its pressure.
    fn stage1_result(&self, x: &[f64], pressure: Vec<f64>, d0: &[f64], valid: &[bool]) -> Stage1 {
        let n = self.observations;
        let (y, m) = x.split_at(n);
        let mut tractions = vec![0.0; self.a_t.rows];
        for (j, p) in pressure.into_iter().enumerate() {
            tractions[3 * j + 2] = p;
        }
        let motion: [f64; MOTION_PARAMETERS] = std::array::from_fn(|i| m[i]);
        let residuals: Vec<Option<Point2>> = (0..n / 2)
            .map(|i| valid[i].then(|| [self.lambda * y[2 * i], self.lambda * y[2 * i + 1]]))
            .collect();
        let rss_full: f64 = residuals.iter().flatten().map(|r| r[0] * r[0] + r[1] * r[1]).sum();
        Stage1 {
            tractions,
            motion,
            residuals,
            rss_rigid: self.rigid_rss(d0, valid),
            rss_full,
        }
    }

    /// Residual sum of squares of the motion basis alone, over valid corners.
    fn rigid_rss(&self, d0: &[f64], valid: &[bool]) -> f64 {
        self.rigid_residuals(d0, valid).iter().map(|v| v * v).sum()
    }

    /// Residuals of the motion basis alone (2 per corner, mm; zero on invalid corners). `d0` is zero where invalid.
    pub(super) fn rigid_residuals(&self, d0: &[f64], valid: &[bool]) -> Vec<f64> {
        let btb = self.motion_gram(valid);
        let mut btd = vec![0.0; MOTION_PARAMETERS];
        self.b_t.mul_vec(d0, &mut btd);
        let m = btb.cholesky().map(|c| c.solve(&DVector::from_column_slice(&btd)));
        (0..self.observations)
            .map(|r| match &m {
                Some(m) if valid[r / 2] => d0[r] - dot(self.b.row(r), m.as_slice()),
                Some(_) => 0.0,
                None => d0[r],
            })
            .collect()
    }

    /// BᵀB over the corners `valid`.
    pub(super) fn motion_gram(&self, valid: &[bool]) -> DMatrix<f64> {
        let mut btb = self.gram_bb_nalgebra();
        for r in (0..self.observations).filter(|&r| !valid[r / 2]) {
            let row = self.b.row(r);
            for i in 0..MOTION_PARAMETERS {
                for j in 0..MOTION_PARAMETERS {
                    btb[(i, j)] -= row[i] * row[j];
                }
            }
        }
        btb
    }

    fn gram_bb_nalgebra(&self) -> DMatrix<f64> {
        DMatrix::from_row_slice(MOTION_PARAMETERS, MOTION_PARAMETERS, &self.gram_bb.data)
    }

    /// This frame's noise (mm per axis): the corners' residuals after stage 1, each against its expected share
    /// under H0 (the fit absorbs part of the noise, more in some places than others), the largest 5 % trimmed (a
    /// corner the tracker mis-placed), and, when stage 1 finds pressure, without the corners next to it (the model
    /// is least exact there).
    pub fn frame_noise_mm(&self, stage: &Stage1, floor_mm: f64) -> f64 {
        let first = self.trimmed_noise(stage, &[]);
        let excluded = self.near_loads(stage, first.max(floor_mm), 1.5);
        if excluded.is_empty() {
            return first;
        }
        self.trimmed_noise(stage, &excluded)
    }

    /// The corners (ascending) within `reach_cells` of a cell where stage 1 finds pressure above its noise at
    /// `noise_mm` (the loaded groups), none without such a cell.
    fn near_loads(&self, stage: &Stage1, noise_mm: f64, reach_cells: f64) -> Vec<usize> {
        self.near_loads_and(stage, noise_mm, reach_cells, &[])
    }

    /// [`Self::near_loads`] with the cells `also` (per cell; empty: none) loaded as well.
    fn near_loads_and(&self, stage: &Stage1, noise_mm: f64, reach_cells: f64, also: &[bool]) -> Vec<usize> {
        let groups = self.loaded_groups_and(stage, noise_mm, also);
        if groups.is_empty() {
            return Vec::new();
        }
        let reach = reach_cells * self.pad.pitch_x_mm().max(self.pad.pitch_y_mm());
        // Every caller asks for at most the table's reach; a larger one would silently miss corners.
        assert!(
            reach_cells <= NEAR_TABLE_REACH_CELLS,
            "near_loads asked for {reach_cells} cells, its table holds {NEAR_TABLE_REACH_CELLS}"
        );
        // Every corner within the reach of a loaded cell, from the distances the table holds.
        let mut is_near = vec![false; self.observations / 2];
        for &j in groups.iter().flatten() {
            for &(i, distance) in &self.corners_near_cell[j] {
                is_near[i] |= distance <= reach;
            }
        }
        (0..is_near.len()).filter(|&i| is_near[i]).collect()
    }

    fn trimmed_noise(&self, stage: &Stage1, excluded: &[usize]) -> f64 {
        let mut normalised: Vec<(f64, f64)> = stage
            .residuals
            .iter()
            .zip(&self.residual_share)
            .enumerate()
            .filter(|(i, _)| excluded.binary_search(i).is_err())
            .filter_map(|(_, (r, &share))| r.map(|r| (r[0] * r[0] + r[1] * r[1], share)))
            .collect();
        if normalised.len() < MIN_NOISE_CORNERS {
            return 0.0;
        }
        normalised.sort_unstable_by(|a, b| (a.0 / a.1.max(1e-300)).total_cmp(&(b.0 / b.1.max(1e-300))));
        let keep = ((normalised.len() as f64) * (1.0 - NOISE_TRIM)).ceil() as usize;
        let (sum, share) = normalised[..keep]
            .iter()
            .fold((0.0, 0.0), |(s, g), (r, share)| (s + r, g + share));
        if !(share > 0.0) {
            return 0.0;
        }
        (sum / share / TRIMMED_MEAN_RATIO).sqrt()
    }

    /// The contact test on a frame's displacements `d` (2 per corner, mm) over the corners `valid`, at the noise the
    /// frame itself shows: the corners' scatter about the motion-only fit ([`Self::rigid_scatter_mm`]), never below
    /// `floor_mm`.
    pub fn measured_test(&self, d: &[f64], valid: &[bool], floor_mm: f64) -> TestOutcome {
        self.measured_test_and_loads(d, valid, floor_mm).0
    }

    /// [`Self::measured_test`], and the corners (ascending) within `MEASURED_NOISE_REACH_CELLS` of a load that its
    /// stage 1 on `valid` finds (the corners its noise leaves out).
    pub fn measured_test_and_loads(&self, d: &[f64], valid: &[bool], floor_mm: f64) -> (TestOutcome, Vec<usize>) {
        self.measured_test_and_loads_of(&self.stage1(d, valid), d, valid, floor_mm)
    }

    /// [`Self::measured_test_and_loads`] given its stage 1 on `valid` (`stage1(d, valid)`, e.g. from
    /// [`Self::stage1_pair`]).
    pub fn measured_test_and_loads_of(
        &self,
        stage: &Stage1,
        d: &[f64],
        valid: &[bool],
        floor_mm: f64,
    ) -> (TestOutcome, Vec<usize>) {
        let measured = self.rigid_scatter(d, valid).floored(floor_mm);
        let scatter = measured.median_mm;
        // A heavy load moves more than half the corners: its far field is no noise. The scatter is measured again
        // without the corners near the cells stage 1 finds loaded at that first estimate (with the motion fitted to
        // the others).
        let mut near = self.near_loads(stage, scatter, MEASURED_NOISE_REACH_CELLS);
        let found_at_scatter = self.test_estimated(stage, measured).contact;
        if near.is_empty() && found_at_scatter {
            // A long load spreads over a line of cells, none of which clears that estimate, and moves most of the
            // corners: a 30 mm edge on the validation sensor raised the median corner's scatter with its force (4.8,
            // 9.3 and 13.6 um at 1, 2 and 3 N, about 1.5 um still), so the test's statistic barely grew with it (some
            // edges of 1 N were missed) and the reported noise and detection floor did. When the test finds a contact
            // all the same, the cells of the line shapes that explain a load better than any square patch (see
            // `line_loads`) stand for its cells if the corners away from them scatter less by the same margin as the
            // compact load's below. Only then: the line shapes also pick cells on a rest frame, by chance (leaving
            // their corners out lowered a still one's scatter 1.47 -> 1.27 um) or along the smooth errors of a camera
            // shift (a real pair's rest frame shifted by (5, -3) px: 4.44 -> 2.24 um, a contact at 1277 against 457).
            let lines = self.line_loads(&self.matched(d, valid), scatter);
            if lines.iter().any(|&l| l) {
                let along = self.near_loads_and(stage, scatter, MEASURED_NOISE_REACH_CELLS, &lines);
                let unexplained = 1.0 - FAR_FIELD_VARIANCE_SHARE;
                if self
                    .scatter_away_from(d, valid, &along)
                    .is_some_and(|away| away.median_mm * away.median_mm < unexplained * scatter * scatter)
                {
                    near = along;
                }
            }
        }
        let mut compact = None;
        if near.is_empty() && !found_at_scatter {
            // A load heavy enough to move most of the corners inflates that first estimate so much that none of its
            // cells clears it, and the test finds no contact (a 30 N press with 12 N of shear: 0.40 mm). Its cells
            // are looked for again at the scatter left once the motion and one compact load are fitted
            // ([`Self::compact_scatter`]), which explains such a load's far field; a rest frame's errors, spread
            // over the pad, barely lower it.
            compact = self.compact_scatter(stage, d, valid).map(|c| c.floored(floor_mm));
            if let Some(compact) = compact.filter(|c| c.median_mm < scatter) {
                near = self.near_loads(stage, compact.median_mm, MEASURED_NOISE_REACH_CELLS);
            }
        }
        let noise = if near.is_empty() {
            measured
        } else {
            self.scatter_away_from(d, valid, &near)
                .map_or(measured, |away| away.floored(floor_mm))
        };
        let outcome = self.test_estimated(stage, noise);
        if outcome.contact {
            return (outcome, near);
        }
        // A load's far field can still reach the far corners: a press pushed sideways moves the whole pad (10 N
        // with 4 N of shear on a half-space pad: their scatter about the motion 0.12-0.14 mm, 40 times a rest
        // frame's, and no contact). When the motion and one compact load explain more than
        // `FAR_FIELD_VARIANCE_SHARE` of the squared scatter (the median corner's) where the test's noise came from,
        // on the corners away from that load, the scatter was the load's and not noise, and the test is taken at what
        // the compact fit leaves. One compact load explains little of a rest frame's errors, spread over the pad: at
        // most 37 % of the squared scatter over the validation sets' rest frames and rest frames under camera motion
        // and uneven light.
        let compact = compact.or_else(|| self.compact_scatter(stage, d, valid));
        if let Some((rescued, left)) = self.rescued_at(stage, compact, noise, FAR_FIELD_VARIANCE_SHARE, floor_mm) {
            if near.is_empty() {
                near = self.near_loads(stage, left.median_mm, MEASURED_NOISE_REACH_CELLS);
            }
            return (rescued, near);
        }
        // A long load moves most of the corners and no compact one explains its far field: a 30 mm edge at 135 deg
        // through (0.82, 1.82) mm on the validation sensor scattered them by 17, 28 and 46 um at 3, 5 and 8 N (a rest
        // frame: 1.5 um), and was no contact at any force. The line shapes (see `line_loads`) pick its cells at that
        // scatter all the same, and their pressure (the shapes are pressure) is judged as the compact load is, at a
        // stricter share: the frame itself says where the line lies, so by chance it explains more of a rest frame's
        // errors than a compact load (at most 46 % of the far corners' squared scatter over 360 rest frames of three
        // sensors, with camera moves, uneven light and JPEG), where that edge's explains 95-97 %.
        if near.is_empty() {
            let lines = self.line_loads(&self.matched(d, valid), noise.median_mm);
            let support: Vec<usize> = (0..lines.len()).filter(|&j| lines[j]).collect();
            if !support.is_empty() {
                let along = self.near_loads_and(stage, noise.median_mm, MEASURED_NOISE_REACH_CELLS, &lines);
                let mut is_along = vec![false; valid.len()];
                for &i in &along {
                    is_along[i] = true;
                }
                // A line across the pad can reach nearly every corner, leaving too few far from it to judge by (a 30 mm
                // edge at 135 deg through (-12, 8) mm on the validation sensor at 2 N: 144 of 155 within reach, and no
                // contact at a scatter of 9.3 um). Every corner judges it then: its own corners, where the fit is least
                // exact, only raise the scatter left (the censored estimate counts the worst quarter only as being
                // large), and the line's pressure, a few dozen unknowns against 2 per corner, absorbs little of the
                // noise (that edge: 91 % explained over every corner; 68 of 1440 rest frames of the same three sensors,
                // with camera moves, uneven light and JPEG, came this far, and their line loads explained at most 50 %).
                let line_load = FittedLoad {
                    cells: &support,
                    axes: &[2],
                    shared_shear: &[],
                };
                let left = self.scatter_about_load(line_load, &is_along, Judged::FarOrEveryCorner, d, valid);
                if let Some((rescued, _)) = self.rescued_at(stage, left, noise, LINE_FAR_FIELD_VARIANCE_SHARE, floor_mm)
                {
                    return (rescued, along);
                }
            }
        }
        // Several presses at once move every corner: three 5 mm spheres 12-24 mm apart on the validation sensor
        // scattered them by 24-113 um (their far fields), no single compact load explained that, and 8 of 12 such
        // scenes read no contact (four in a square, every one). `MAX_COMPACT_LOADS` compact loads at stage 1's most
        // significant cells (a 3 x 3 block each, apart; pressure per cell and one shear per block, as a pushed press
        // moves the whole pad further) explain 89-99 % of it for two to four presses, pushed sideways or not (judged
        // by every corner when the loads' reach leaves too few far ones; the loads a scene has fewer presses than
        // take up noise). They are judged as the line's load is, at its stricter share: the frame picks their places,
        // so by chance they explain more of a rest frame's errors than one compact load, at most 62 % over 5440 rest
        // frames (1440 of three sensors, with camera moves, uneven light and JPEG; 4000 of the daemon's simulated
        // sensor; p99 44 %). Every frame with no contact comes this far: the fits read their normal equations off the
        // model's `fit_gram` (see `load_fit_normal_matrix`), which brought a rest frame of the validation sensor from
        // 1.15-1.18 to 0.98-0.99 ms median at 1024x768 (`estimate_profile rest`).
        if let Some(loads) = self.compact_loads(stage, MAX_COMPACT_LOADS) {
            let fitted = FittedLoad {
                cells: &loads.support(),
                axes: &[2],
                shared_shear: &loads.blocks,
            };
            let left = self.scatter_about_load(fitted, &loads.near, Judged::FarOrEveryCorner, d, valid);
            if let Some((rescued, left)) = self.rescued_at(stage, left, noise, LINE_FAR_FIELD_VARIANCE_SHARE, floor_mm)
            {
                return (
                    rescued,
                    self.near_loads(stage, left.median_mm, MEASURED_NOISE_REACH_CELLS),
                );
            }
        }
        (outcome, near)
    }

    /// The contact test's rescue by a load's fit: taken at `left` (the scatter the fit leaves, floored at `floor_mm`)
    /// when the fit explains more than `share` of the squared scatter the test's `noise` came from, and kept, with
    /// that scatter, when it then finds a contact.
    fn rescued_at(
        &self,
        stage: &Stage1,
        left: Option<NoiseEstimate>,
        noise: NoiseEstimate,
        share: f64,
        floor_mm: f64,
    ) -> Option<(TestOutcome, NoiseEstimate)> {
        let left = left?.floored(floor_mm);
        if !(left.median_mm * left.median_mm < (1.0 - share) * noise.median_mm * noise.median_mm) {
            return None;
        }
        let rescued = self.test_estimated(stage, left);
        rescued.contact.then_some((rescued, left))
    }

    /// The scatter about the motion-only fit ([`Self::rigid_scatter_mm`]) of the corners `valid` but those `near`
    /// (ascending), the motion fitted to them; `None` when too few are left.
    fn scatter_away_from(&self, d: &[f64], valid: &[bool], near: &[usize]) -> Option<NoiseEstimate> {
        let far: Vec<bool> = (0..valid.len())
            .map(|i| valid[i] && near.binary_search(&i).is_err())
            .collect();
        (far.iter().filter(|&&v| v).count() >= 2 * MIN_NOISE_CORNERS).then(|| self.rigid_scatter(d, &far))
    }

    /// The corners' scatter about the motion and one compact load, mm per axis: tractions (all three components) on
    /// the 3 x 3 cells around where stage 1 finds its most significant pressure are fitted jointly with the motion
    /// to every corner `valid`, and the scatter is that of the corners farther than [`MEASURED_NOISE_REACH_CELLS`]
    /// from that load (see [`Self::scatter_about_load`]). `None` with too few such corners or a singular fit.
    fn compact_scatter(&self, stage: &Stage1, d: &[f64], valid: &[bool]) -> Option<NoiseEstimate> {
        let load = self.compact_loads(stage, 1)?;
        let cells = load.support();
        let fitted = FittedLoad {
            cells: &cells,
            axes: &[0, 1, 2],
            shared_shear: &[],
        };
        self.scatter_about_load(fitted, &load.near, Judged::FarCorners, d, valid)
    }

    /// `count` compact loads where stage 1 finds its most significant pressures: the 3 x 3 blocks around its `count`
    /// most significant cells whose blocks do not overlap. `None` when the grid holds fewer such blocks.
    fn compact_loads(&self, stage: &Stage1, count: usize) -> Option<CompactLoads> {
        let (cols, rows) = (usize::from(self.pad.cols), usize::from(self.pad.rows));
        let significance = |j: usize| stage.tractions[3 * j + 2] / self.pressure_noise[j];
        let mut candidates: Vec<usize> = (0..self.cells.len())
            .filter(|&j| self.pressure_noise[j] > 0.0)
            .collect();
        candidates.sort_by(|&a, &b| significance(b).total_cmp(&significance(a)));
        let row_col = |j: usize| ((j / cols) as isize, (j % cols) as isize);
        let mut peaks: Vec<usize> = Vec::with_capacity(count);
        for j in candidates {
            if peaks.len() == count {
                break;
            }
            let (r, c) = row_col(j);
            // 3 x 3 blocks apart: their centres at least three cells apart along a row or a column.
            if peaks.iter().all(|&p| {
                let (pr, pc) = row_col(p);
                (pr - r).abs().max((pc - c).abs()) >= 3
            }) {
                peaks.push(j);
            }
        }
        if peaks.len() < count {
            return None;
        }
        let blocks: Vec<Vec<usize>> = peaks
            .iter()
            .map(|&p| {
                let (r, c) = row_col(p);
                neighbourhood(r, c, rows, cols).map(|(r, c)| r * cols + c).collect()
            })
            .collect();
        let reach = MEASURED_NOISE_REACH_CELLS * self.pad.pitch_x_mm().max(self.pad.pitch_y_mm());
        let mut near = vec![false; self.observations / 2];
        for &p in &peaks {
            for &(i, distance) in &self.corners_near_cell[p] {
                near[i] |= distance <= reach;
            }
        }
        Some(CompactLoads { blocks, near })
    }

    /// The corners' scatter about the motion and `load`, mm per axis: its cells' tractions along its axes, and one
    /// shear (x, y) alike on the cells of each of its shared-shear blocks (the prior that of as many cells), fitted
    /// jointly with the motion to every corner `valid`, the scatter that of the corners
    /// not `near` (per corner), taken as [`Self::rigid_scatter_mm`] takes it. The load is fitted mostly to its own
    /// corners, so the far ones judge whether its far field is what scattered them. With too few far corners, that
    /// of every corner when `judged` says so, else `None`; `None` too for a singular fit.
    fn scatter_about_load(
        &self,
        load: FittedLoad,
        near: &[bool],
        judged: Judged,
        d: &[f64],
        valid: &[bool],
    ) -> Option<NoiseEstimate> {
        let (d0, missing) = self.masked(d, valid);
        let residuals = self.load_fit_residuals(load, &d0, &missing)?;
        let squares_where = |judging: &dyn Fn(usize) -> bool| -> Vec<f64> {
            (0..valid.len())
                .filter(|&i| valid[i] && judging(i))
                .map(|i| residuals[2 * i].powi(2) + residuals[2 * i + 1].powi(2))
                .collect()
        };
        let mut squares = squares_where(&|i| !near[i]);
        if squares.len() < 2 * MIN_NOISE_CORNERS && judged == Judged::FarOrEveryCorner {
            squares = squares_where(&|_| true);
        }
        if squares.len() < 2 * MIN_NOISE_CORNERS {
            return None;
        }
        let estimate = NoiseEstimate::censored_of(&mut squares);
        estimate.mm.is_finite().then_some(estimate)
    }

    /// The residuals (2 per corner, mm) of `load` fitted jointly with the motion to `d0` (2 per corner, mm, zero on
    /// the `missing` rows) by least squares over the rows not missing, its tractions under their prior (see
    /// [`Self::scatter_about_load`]); on the missing rows they are not meaningful. `None` for a singular fit.
    fn load_fit_residuals(&self, load: FittedLoad, d0: &[f64], missing: &[usize]) -> Option<Vec<f64>> {
        let fit = self.load_fit_columns(load);
        let mut normal = self.load_fit_normal_matrix(&fit, missing);
        for (i, p) in fit.prior.iter().enumerate() {
            normal[(MOTION_PARAMETERS + i, MOTION_PARAMETERS + i)] += p;
        }
        // d0 is zero on the missing rows, so the full columns project it as the masked ones would.
        let rows: Vec<&[f64]> = fit.parts.iter().map(|&(c, _)| self.fit_column(c)).collect();
        let mut part_projected = vec![0.0; rows.len()];
        dot_each(&rows, d0, &mut part_projected);
        let mut projected = DVector::<f64>::zeros(fit.columns);
        for (&(_, column), v) in fit.parts.iter().zip(&part_projected) {
            projected[column] += v;
        }
        let solution = normal.cholesky()?.solve(&projected);
        let mut residuals = d0.to_vec();
        for (&(_, column), row) in fit.parts.iter().zip(&rows) {
            let x = solution[column];
            for (r, v) in residuals.iter_mut().zip(row.iter()) {
                *r -= x * v;
            }
        }
        Some(residuals)
    }

    /// `load`'s fit columns (see [`Self::load_fit_residuals`]): the motion basis, each support cell's axes, each
    /// shared-shear block's two, as the model's fit columns (see `fit_gram`) they sum.
    fn load_fit_columns(&self, load: FittedLoad) -> LoadFitColumns {
        let mut parts: Vec<(usize, usize)> = (0..MOTION_PARAMETERS).map(|i| (i, i)).collect();
        for &j in load.cells {
            for &axis in load.axes {
                parts.push((traction_column(j, axis), parts.len()));
            }
        }
        let mut columns = parts.len();
        let mut prior = vec![self.lambda; columns - MOTION_PARAMETERS];
        for block in load.shared_shear {
            for axis in 0..2 {
                parts.extend(block.iter().map(|&j| (traction_column(j, axis), columns)));
                prior.push(self.lambda * block.len() as f64);
                columns += 1;
            }
        }
        parts.sort_unstable();
        LoadFitColumns { parts, columns, prior }
    }

    /// The Gram matrix over the rows not `missing` of `fit`'s columns: sums of `fit_gram`'s entries, less the
    /// missing rows' products (the same sums as over the rows, in another order: equal to within rounding). Every
    /// frame's fits read it so rather than summing products over the corners (about 330 rows per entry): on a frame
    /// with no contact the contact test fits one compact load (35 columns) and four (52), and often the line shapes'
    /// load. The parts ascending, each pair's entry is read from the later part's row of `fit_gram`, so that the
    /// reads run forward along each row.
    fn load_fit_normal_matrix(&self, fit: &LoadFitColumns, missing: &[usize]) -> DMatrix<f64> {
        let mut normal = DMatrix::<f64>::zeros(fit.columns, fit.columns);
        for (i, &(p, u)) in fit.parts.iter().enumerate() {
            let row = self.fit_gram.row_to_diagonal(p);
            for &(q, v) in &fit.parts[..i] {
                normal[(u, v)] += row[q];
                normal[(v, u)] += row[q];
            }
            normal[(u, u)] += row[p];
        }
        if !missing.is_empty() {
            let mut rows = DMatrix::<f64>::zeros(missing.len(), fit.columns);
            for (m, &r) in missing.iter().enumerate() {
                for &(c, column) in &fit.parts {
                    rows[(m, column)] += self.fit_column_at(r, c);
                }
            }
            normal -= gram(&rows);
        }
        normal
    }

    /// The model's fit column `c` (see `fit_gram`): one value per observation.
    fn fit_column(&self, c: usize) -> &[f64] {
        if c < MOTION_PARAMETERS {
            self.b_t.row(c)
        } else {
            self.a_t.row(c - MOTION_PARAMETERS)
        }
    }

    /// Row `r` of the model's fit column `c`.
    fn fit_column_at(&self, r: usize, c: usize) -> f64 {
        if c < MOTION_PARAMETERS {
            self.b.at(r, c)
        } else {
            self.a.at(r, c - MOTION_PARAMETERS)
        }
    }

    /// The corners' scatter about the motion-only fit, mm per axis, with the largest `NOISE_CENSORED_SHARE` of
    /// them censored (see `NoiseEstimate::censored_of`), so that a contact (a minority of the corners) barely counts,
    /// while every error the motion does not explain (lighting, JPEG, the tracker) does, smooth ones included.
    pub fn rigid_scatter_mm(&self, d: &[f64], valid: &[bool]) -> f64 {
        self.rigid_scatter(d, valid).mm
    }

    /// [`Self::rigid_scatter_mm`] with its degrees of freedom (0 mm, known, below [`MIN_NOISE_CORNERS`]).
    fn rigid_scatter(&self, d: &[f64], valid: &[bool]) -> NoiseEstimate {
        let (d0, _) = self.masked(d, valid);
        let residuals = self.rigid_residuals(&d0, valid);
        let mut squares: Vec<f64> = (0..self.observations / 2)
            .filter(|&i| valid[i])
            .map(|i| residuals[2 * i].powi(2) + residuals[2 * i + 1].powi(2))
            .collect();
        if squares.len() < MIN_NOISE_CORNERS {
            return NoiseEstimate::known(0.0);
        }
        NoiseEstimate::censored_of(&mut squares)
    }

    /// The contact test for a stage 1 result, at a known noise `noise_mm`.
    pub fn test(&self, stage: &Stage1, noise_mm: f64) -> TestOutcome {
        self.test_estimated(stage, NoiseEstimate::known(noise_mm))
    }

    /// The contact test at a noise measured on the frame itself. The statistic divides by that estimate, which is
    /// itself a sample: a frame whose corners happen to scatter little reads every rest frame's explained residual
    /// as more significant. The threshold is therefore that of the ratio (an F distribution), not of the explained
    /// residual over a known noise (chi-square): with the chi-square's, rest frames on the simulated sensor at
    /// 640x480 read as contacts 3-5 times in 10,000 (statistics of 460-478 against a threshold of 457.5, their noise
    /// estimates 1.3-3.3 of their own standard deviations low), where `inverse.false_alarm_probability` says 1 in a
    /// million.
    fn test_estimated(&self, stage: &Stage1, noise: NoiseEstimate) -> TestOutcome {
        self.verdict(stage.rss_rigid - stage.rss_full, noise)
    }

    /// The test's verdict on an explained residual `explained` (mm^2) at `noise`: divided by the larger of its
    /// censored and its median scatter. The corners do not all scatter alike, and on some rest frames the three
    /// quarters that scatter least happen to scatter less than the median says: divided by the censored scatter alone,
    /// the worst of 40,000 rest frames of the daemon's simulated sensor came to 0.90 of the threshold (0.80 with the
    /// median alone, and with the larger of the two). Dividing by more only lowers the statistic, so the F threshold at
    /// the censored scatter's degrees of freedom still bounds the false alarms.
    fn verdict(&self, explained: f64, noise: NoiseEstimate) -> TestOutcome {
        let noise_mm = noise.mm.max(noise.median_mm);
        let sigma2 = (noise_mm * noise_mm).max(1e-24);
        let explained = explained.max(0.0);
        let statistic = explained / sigma2;
        let z = normal_quantile(1.0 - self.false_alarm_probability);
        // explained / sigma^2 is test_scale chi-square(test_dof) (Satterthwaite); over an estimate of sigma^2 with
        // `noise.dof` degrees of freedom, test_scale test_dof F(test_dof, noise.dof).
        let per_dof = self.test_scale * self.test_dof;
        let threshold = per_dof * f_quantile(self.test_dof, noise.dof, z);
        let p_value = f_upper_tail(self.test_dof, noise.dof, statistic / per_dof);
        let detection_floor_n = (threshold / (self.reference_explained / sigma2)).sqrt();
        TestOutcome {
            statistic,
            threshold,
            p_value,
            noise_mm,
            detection_floor_n,
            contact: statistic > threshold && statistic.is_finite(),
        }
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::{DMatrix, DVector};

    use super::{FittedLoad, InverseModel, MAX_COMPACT_LOADS, MOTION_PARAMETERS};
    use crate::inverse::test_support::{cell_at, field, model, node_at, node_press, pseudo_gauss};
    use crate::linalg::dot;

    /// A load fit's normal matrix and residuals as summed over the valid corners' rows, product by product: what
    /// `load_fit_residuals` reads off the model's Gram instead.
    fn fit_summed_over_rows(
        model: &InverseModel,
        load: FittedLoad,
        d0: &[f64],
        valid: &[bool],
    ) -> (DMatrix<f64>, Vec<f64>) {
        let masked = |column: Vec<f64>| -> Vec<f64> {
            column
                .iter()
                .enumerate()
                .map(|(r, &v)| if valid[r / 2] { v } else { 0.0 })
                .collect()
        };
        let mut columns: Vec<Vec<f64>> = (0..MOTION_PARAMETERS)
            .map(|i| masked(model.b_t.row(i).to_vec()))
            .collect();
        for &j in load.cells {
            for &axis in load.axes {
                columns.push(masked(model.a_t.row(3 * j + axis).to_vec()));
            }
        }
        let mut prior = vec![model.lambda; columns.len() - MOTION_PARAMETERS];
        for block in load.shared_shear {
            for axis in 0..2 {
                let mut column = vec![0.0; model.observations];
                for &j in block {
                    for (c, &v) in column.iter_mut().zip(model.a_t.row(3 * j + axis)) {
                        *c += v;
                    }
                }
                columns.push(masked(column));
                prior.push(model.lambda * block.len() as f64);
            }
        }
        let n = columns.len();
        let gram = DMatrix::from_fn(n, n, |i, k| dot(&columns[i], &columns[k]));
        let mut normal = gram.clone();
        for (i, p) in (MOTION_PARAMETERS..n).zip(&prior) {
            normal[(i, i)] += p;
        }
        let projected = DVector::from_fn(n, |i, _| dot(&columns[i], d0));
        let solution = normal.cholesky().unwrap().solve(&projected);
        let mut residuals = d0.to_vec();
        for (column, &x) in columns.iter().zip(solution.iter()) {
            for (r, v) in residuals.iter_mut().zip(column) {
                *r -= x * v;
            }
        }
        (gram, residuals)
    }

    #[test]
    fn load_fits_read_off_the_gram_are_the_fits_summed_over_the_valid_corners() {
        let model = model();
        let motion = [0.3, -0.2, 0.01, 0.03, -0.02, 0.01, 0.002, 0.001];
        // Three pushed presses apart, and noise.
        let mut forces = Vec::new();
        for (at, force) in [
            ([-12.0, -6.0], [1.0, 0.5, 4.0]),
            ([10.0, 4.0], [-0.5, 1.0, 3.0]),
            ([0.0, 10.0], [0.0, 0.0, 2.0]),
        ] {
            let (row, col) = node_at(&model, at);
            forces.extend(node_press(&model, row, col, force));
        }
        let mut gauss = pseudo_gauss(4242);
        let d: Vec<f64> = field(&model, &forces, motion)
            .iter()
            .map(|v| v + 0.002 * gauss())
            .collect();
        // Corners missing under the first press (the fit's own columns lose their largest rows there) and here and
        // there over the pad.
        let under = model.cells[cell_at(&model, [-12.0, -6.0])].centre_mm;
        let corners: Vec<_> = model.pad.corners().map(|c| model.pad.corner_mm(c)).collect();
        let valid: Vec<bool> = corners
            .iter()
            .enumerate()
            .map(|(i, p)| (p[0] - under[0]).hypot(p[1] - under[1]) > 4.0 && i % 7 != 3)
            .collect();
        let missing_corners = valid.iter().filter(|&&v| !v).count();
        assert!((25..60).contains(&missing_corners), "{missing_corners}");
        let stage = model.stage1(&d, &valid);
        let one = model.compact_loads(&stage, 1).unwrap();
        let several = model.compact_loads(&stage, MAX_COMPACT_LOADS).unwrap();
        let line: Vec<usize> = (3..12).map(|c| 5 * usize::from(model.pad.cols) + c).collect();
        let (one_cells, several_cells) = (one.support(), several.support());
        let loads = [
            FittedLoad {
                cells: &one_cells,
                axes: &[0, 1, 2],
                shared_shear: &[],
            },
            FittedLoad {
                cells: &several_cells,
                axes: &[2],
                shared_shear: &several.blocks,
            },
            FittedLoad {
                cells: &line,
                axes: &[2],
                shared_shear: &[],
            },
        ];
        let (d0, missing) = model.masked(&d, &valid);
        for load in loads {
            let (summed, expected) = fit_summed_over_rows(&model, load, &d0, &valid);
            let read = model.load_fit_normal_matrix(&model.load_fit_columns(load), &missing);
            // Each entry within rounding of the larger of its row's and column's diagonal entries.
            for i in 0..summed.nrows() {
                for k in 0..summed.ncols() {
                    let scale = (summed[(i, i)] * summed[(k, k)]).sqrt();
                    assert!(
                        (read[(i, k)] - summed[(i, k)]).abs() <= 1e-13 * scale,
                        "entry ({i}, {k}) of {} columns: {} against {}",
                        summed.nrows(),
                        read[(i, k)],
                        summed[(i, k)]
                    );
                }
            }
            let residuals = model.load_fit_residuals(load, &d0, &missing).unwrap();
            let valid_rows = (0..model.observations).filter(|&r| valid[r / 2]);
            let rms = (valid_rows.clone().map(|r| expected[r].powi(2)).sum::<f64>()
                / valid_rows.clone().count() as f64)
                .sqrt();
            let worst = valid_rows
                .map(|r| (residuals[r] - expected[r]).abs())
                .fold(0.0, f64::max);
            assert!(
                worst <= 1e-10 * rms,
                "{} columns: residuals differ by {worst} against an rms of {rms}",
                summed.nrows()
            );
        }
    }

    #[test]
    fn motion_alone_is_not_a_contact_and_the_noise_estimate_is_unbiased() {
        let model = model();
        let motion = [1.0, -0.5, 0.02, 0.08, -0.08, 0.02, 0.004, 0.003];
        let mut d = field(&model, &[], motion);
        // Deterministic pseudo-noise, sigma 0.01 mm.
        let mut gauss = pseudo_gauss(12345);
        for v in d.iter_mut() {
            *v += 0.01 * gauss();
        }
        let valid = vec![true; model.observations / 2];
        let stage = model.stage1(&d, &valid);
        let noise = model.frame_noise_mm(&stage, 0.0);
        let mean = (stage.rss_full / model.residual_share.iter().sum::<f64>()).sqrt();
        assert!((noise / 0.01 - 1.0).abs() < 0.25, "{noise} (mean-based {mean})");
        let outcome = model.test(&stage, noise);
        assert!(!outcome.contact && outcome.p_value > 1e-4, "{outcome:?}");
        // The floor scales with the noise.
        let quieter = model.test(&stage, noise / 5.0);
        assert!(
            (quieter.detection_floor_n * 5.0 / outcome.detection_floor_n - 1.0).abs() < 1e-9,
            "{outcome:?}"
        );
    }

    #[test]
    fn a_heavy_press_does_not_pass_for_noise_about_the_motion_and_one_compact_load() {
        let model = model();
        let motion = [1.0, -0.5, 0.02, 0.08, -0.08, 0.02, 0.004, 0.003];
        let mut gauss = pseudo_gauss(777);
        let noise: Vec<f64> = (0..model.observations).map(|_| 0.01 * gauss()).collect();
        let valid = vec![true; model.observations / 2];
        let noisy = |forces: &[(usize, [f64; 3])]| -> Vec<f64> {
            field(&model, forces, motion)
                .iter()
                .zip(&noise)
                .map(|(d, e)| d + e)
                .collect()
        };
        // Motion and noise only: the compact load explains nothing of it, so both scatters are the noise.
        let rest = noisy(&[]);
        let stage = model.stage1(&rest, &valid);
        let compact = model.compact_scatter(&stage, &rest, &valid).unwrap().mm;
        assert!((compact / 0.01 - 1.0).abs() < 0.25, "{compact}");
        assert!(!model.measured_test(&rest, &valid, 0.0).contact);
        // A 30 N press with 12 N of shear moves every corner far beyond the noise; about the motion and that
        // one load the far corners scatter as the noise does.
        let (row, col) = node_at(&model, [0.0, 0.0]);
        let heavy = noisy(&node_press(&model, row, col, [12.0, 0.0, 30.0]));
        let stage = model.stage1(&heavy, &valid);
        let scatter = model.rigid_scatter_mm(&heavy, &valid);
        let compact = model.compact_scatter(&stage, &heavy, &valid).unwrap().mm;
        assert!(scatter > 5.0 * 0.01, "{scatter}");
        assert!(compact < 2.0 * 0.01, "{compact} against a rigid scatter of {scatter}");
        assert!(model.measured_test(&heavy, &valid, 0.0).contact);
    }
}
