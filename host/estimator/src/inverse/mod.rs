//! Tractions from displacements: the model-based inverse (GelSlim 2.0's inverse-FEM idea, with an analytic kernel
//! of the bonded layer in place of a mesh).
//!
//! The pattern's in-plane displacement d (pad mm, two per corner) is linear in the tractions on the pad's surface:
//! d = B m + A t + e. t holds the force (fx, fy, fz; N) on each cell of a coarse grid (the pattern's own cells,
//! 3.3 mm), A is the elastic response ([`crate::elastic`]), m the camera/pad motion left after compensation (a
//! linearised homography, unpenalised: B's columns are the rigid, affine and perspective displacement fields) and e
//! the corners' noise (sigma per axis).
//!
//! **Stage 1, every frame, a fixed linear operator.** With a Gaussian prior t ~ N(0, tau^2) per component the MAP
//! estimate is universal kriging: [C B; Bᵀ 0] [y; m] = [d; 0] with C = A Aᵀ + lambda I, then t = Aᵀ y. The
//! regularisation rule is that prior: lambda = (noise / tau)^2, both from the sensor config (never per frame). The
//! system's inverse is precomputed once per sensor config, so a frame costs two matrix-vector products; corners
//! missing from a frame are handled exactly by a capacitance correction on the rows they leave (the solution is
//! forced to vanish there), not by refactoring.
//!
//! **The contact test.** "Rigid motion and noise only" (H0: t = 0) against "tractions present": the statistic is the
//! fit's improvement E = RSS0 - RSS1 in units of the noise. Under H0, E / sigma^2 = eᵀ Q e / sigma^2 with Q known from
//! the operator, a weighted sum of chi-squares, taken as g chi^2_h (Satterthwaite: matching mean and variance). sigma
//! is this frame's own noise: the scatter of its corners about the motion-only fit, the mean square of the corners with
//! the largest quarter censored ([`InverseModel::rigid_scatter_mm`]), or the median corner's if larger. That is a
//! sample too, the first exactly as precise as a sum of 1.5 n squares for n corners (see `NoiseEstimate::censored_of`),
//! so the statistic E / sigma_hat^2 is taken as g h F(h, m) with m those degrees of freedom, and contact is when it
//! exceeds that distribution's 1 - alpha quantile (alpha: `inverse.false_alarm_probability`; a noise given rather than
//! measured, such as the configured floor, is known: chi-square). With the chi-square's quantile for every noise, a
//! frame whose corners happened to scatter little read rest frames as contacts about 4 times in 10,000 on the simulated
//! sensor. That scatter holds every error the motion does not explain, the smooth ones from lighting and JPEG included,
//! which the traction fit's own residuals cannot show (it explains them away); a contact moves a minority of the
//! corners, which the censoring leaves out. A load heavy enough to move most of the corners breaks that (its far field
//! is no noise): the scatter is then measured again on the corners away from the cells stage 1 finds loaded at the
//! median corner's scatter (which such a load inflates less). When none clears it but the test finds a contact, away
//! from the cells of the line shapes that explain a load better than a square patch (a long edge's), if the corners
//! there scatter less than half as much; when none clears it and the test finds no contact, at the scatter about the
//! motion and one compact load (which explains such a load's far field). A press pushed sideways moves even the far
//! corners; when that compact load explains most of the scatter the test used, the test is taken at the scatter it
//! leaves (a rest frame's errors, spread over the pad, it barely explains). Several presses at once move every corner
//! and no one load explains their far fields: up to four compact loads at once do, judged at a stricter share (the
//! frame picks their places). The corners that a change of light alone moves (glare: found once per rest frame, see
//! the estimator) are left out of the test. The detection floor in N follows from the same threshold: the force of a
//! press at the pad's centre whose expected E equals it.
//!
//! **Stage 2, only when the test says contact.** Friction acts only where something touches, and pressure only pushes:
//! the tractions are re-estimated on the cells where stage 1 finds pressure above its own noise (and a ring around
//! them), with normal pressure >= 0 (an active-set solve of the small problem, from precomputed Gram blocks). A
//! contact's shear is one (fx, fy) spread like its stage 1 pressure, and on a pushed one a second spread like stage 1's
//! shear along the push (`InverseModel::shear_along_push`). Contacts are the watershed regions of that pressure (a
//! maximum on the outermost cells that stands out of the noise beside a contact is the border's, not the contact's: see
//! `InverseModel::border_bump`), each above the detection floor where it is (the floor at the centre scaled by how much
//! less a press of its shape there moves the corners, see [`InverseModel::floor_scale`]); force vectors, torque,
//! centres and areas come from it (the layered model's centres from the contact's cells split in four, see
//! `InverseModel::quarter_centres`), and each contact's force vector also holds the shear of its group's cells that
//! stage 2 left without pressure (`InverseModel::give_shear_beside`; its torque is its own cells'). A long light
//! contact loads no single cell above its noise: when those cells hold no contact, stage 2 is solved again with the
//! cells of the line shapes a matched filter finds significant and better explained as a line than as a square patch;
//! there the fragments a line's pressure breaks into are one contact unless the dip between them is significant, and a
//! group of cells is judged against the floor as a whole, by its unbiased least-squares force (see
//! `InverseModel::contacts`). When they do hold contacts, a light long one may have only its stronger part among them:
//! stage 2 is solved again with the cells of the line shapes through the strongest contact that explain the
//! displacements better than its own pressure does (`InverseModel::lines_extending`). Two regions side by side are one
//! long contact when a straight line load explains them better than two round loads by the test's margin and the
//! pressure between them is more than two round presses leave there (`InverseModel::join_cut_lines`: the cell map cuts
//! some 20 mm edges of the validation pad into lumps about 10 mm apart); after the last pass, all the contacts of one
//! loaded group are one when a line explains their union so (`InverseModel::join_long_groups`: pairwise, the lumps of a
//! 30 mm edge can each fail the other tests). The edge direction (second moments of the pressure) comes from a second
//! solve with the pressure's unknowns on the grid's nodes instead of its cells, which has no checkerboard noise (see
//! `PressureBasis`); with `inverse.edge_from_line`, when those moments give a direction, it is the direction of the
//! straight line load that best explains the displacements (see `InverseModel::edge_line`).
//!
//! The parts, one file each: `build` (the model, once per sensor config and camera view), `stage1` (the motion,
//! stage 1 and the contact test), `noise` (the noise estimate, the F and normal quantiles), `constrained` (stage 2's
//! solve with pressure >= 0), `stage2` (its passes), `regions` (its contacts), `forces` (a contact's force against
//! the floor, its neighbours' far field and the border), `lines` and `pairs` (line loads, two presses against one
//! line), `moments` (the edge direction), `edge_line` (the edge's line load).

use nusense_geometry::{PadGeometry, Point2};

use crate::elastic::Cell;
use crate::linalg::{Dense, PackedSymmetric};

mod build;
mod constrained;
mod edge_line;
mod forces;
mod lines;
mod moments;
mod noise;
mod pairs;
mod regions;
mod stage1;
mod stage2;
#[cfg(test)]
mod test_support;

pub use moments::Moments;
pub use noise::{f_quantile, f_upper_tail, normal_quantile};
pub use stage1::{Stage1, TestOutcome};
pub use stage2::Stage2;

/// Columns of the motion basis: translation (2), linear (4), perspective (2).
pub const MOTION_PARAMETERS: usize = 8;
/// Stage 1 pressure above this many of its own noise sigmas marks a cell as loaded.
const SUPPORT_SIGMAS: f64 = 3.0;

/// Everything precomputed for one sensor config.
#[derive(Debug)]
pub struct InverseModel {
    pad: PadGeometry,
    cells: Vec<Cell>,
    /// Observations: 2 per observed point (x, y) at `points_mm`.
    observations: usize,
    /// The observed points' nominal positions, pad mm: the corners in `corner_slot` order (with `inverse.observe =
    /// "squares"` or [`InverseModel::observing_squares`], the yellow squares' centres in `PadGeometry::yellow_squares`
    /// order).
    points_mm: Vec<Point2>,
    /// A (obs x 3 cells) and its transpose, row-major.
    a: Dense,
    a_t: Dense,
    /// B (obs x P) and its transpose.
    b: Dense,
    b_t: Dense,
    /// The first `observations` columns of the kriging system's inverse, (obs + P) x obs, and its transpose (stage
    /// 1's correction for missing corners reads its columns).
    s: Dense,
    s_t: Dense,
    /// The pressure rows of `a_t` (cells x obs): all stage 1 computes of the tractions.
    a_t_pressure: Dense,
    lambda: f64,
    /// BᵀB over all observations (stage 2 subtracts missing rows).
    gram_bb: Dense,
    /// The Gram matrix over all observations of the columns the contact test's load fits are made of: the motion
    /// basis's, then every cell's three tractions' (cell j's traction k at `MOTION_PARAMETERS + 3 j + k`). A fit's
    /// normal equations are read off it rather than summed over the corners every frame (see
    /// `InverseModel::load_fit_normal_matrix`).
    fit_gram: PackedSymmetric,
    /// Expected share of each corner's residual |e|^2 under H0, per sigma^2.
    residual_share: Vec<f64>,
    /// Noise (per sigma) of each cell's stage 1 pressure.
    pressure_noise: Vec<f64>,
    /// Satterthwaite parameters of E / sigma^2 under H0.
    test_scale: f64,
    test_dof: f64,
    /// E per sigma^2 of a 1 N press on the central cells (E scales with the force squared).
    reference_explained: f64,
    /// E per sigma^2 of unit pressures on any two cells, cells x cells: Gᵀ Q G with G the pressure columns of A
    /// (E of a 1 N press of any shape w is wᵀ this w).
    pressure_explained: Dense,
    /// The matched filter of a pressure shape: G0 = A_pᵀ P0 A_p (cells x cells) with A_p the pressure columns of A
    /// and P0 the projection off the motion basis: a shape w's least-squares amplitude in displacements d with
    /// motion-only residuals r is wᵀ A_pᵀ r / wᵀ G0 w, its noise sigma / sqrt(wᵀ G0 w).
    matched_gram: Dense,
    /// The line shapes (see `build::LINE_LENGTHS_CELLS`) and the square ones, each with its sqrt(wᵀ G0 w) (unit load
    /// per cell).
    line_shapes: Vec<(Vec<usize>, f64)>,
    block_shapes: Vec<(Vec<usize>, f64)>,
    /// A line shape picks its cells above this many sigmas: the cell test's false-pick rate per cell
    /// ([`SUPPORT_SIGMAS`]), shared among the line shapes through a cell.
    line_sigmas: f64,
    /// Normalisation length of the motion basis, mm.
    motion_length_mm: f64,
    false_alarm_probability: f64,
    /// Per cell: the corners (index, distance from the cell's centre in mm) within
    /// [`NEAR_TABLE_REACH_CELLS`](build::NEAR_TABLE_REACH_CELLS) of it, for [`InverseModel::near_loads`] (the same
    /// distances it would compute, once per sensor rather than thousands per frame).
    corners_near_cell: Vec<Vec<(usize, f64)>>,
    /// What sliding walls at the frame add to the response, 3 per cell x observations (see
    /// [`Self::border_doubt`]).
    images_t: Dense,
    /// The layered model's quarter cells, for the contacts' centres (see [`Self::quarter_centres`]).
    quarters: Option<Quarters>,
    /// The pressure response of a finer grid, for the edge's straight line load (see [`Self::edge_line`]), when
    /// the config asks for it (`inverse.edge_from_line`).
    fine: Option<FineGrid>,
}

/// Cells of the fine grid per cell of the pattern, each way.
const FINE_PER_CELL: usize = 4;

/// The pattern's cells split into [`FINE_PER_CELL`] x [`FINE_PER_CELL`] (row-major over the whole grid), with the
/// pressure rows of their response (parallax included): a point load between their centres is shared bilinearly
/// among the four around it, close to exact at a quarter of a pitch (the kernel at the pattern's depth varies over
/// about a pitch).
#[derive(Debug)]
struct FineGrid {
    /// The first fine cell's centre and the step between centres, mm.
    origin_mm: Point2,
    step_mm: Point2,
    cols: usize,
    rows: usize,
    /// fine cells x observations.
    pressure_t: Dense,
}

/// Each cell's four quarters (cell-major: cell j's are 4 j .. 4 j + 4).
#[derive(Debug)]
struct Quarters {
    /// The pressure rows of the quarters' response (parallax included), quarters x observations.
    pressure_t: Dense,
    centres_mm: Vec<Point2>,
}

/// One contact region from stage 2.
#[derive(Clone, Debug, PartialEq)]
pub struct Region {
    pub centre_mm: Point2,
    pub force_vector_n: [f64; 3],
    /// About `centre_mm`, from +x towards +y, N mm.
    pub torque_nmm: f64,
    pub area_mm2: f64,
    /// Cells and their (fx, fy, fz).
    pub cells: Vec<(usize, [f64; 3])>,
    /// The detection floor where this region is, in units of the floor at the pad's centre (see
    /// [`InverseModel::floor_scale`]).
    pub floor_scale: f64,
}

impl Region {
    /// Whether more than half of the region's pressure (negative pressure counted as none) lies on the cells `on`
    /// picks.
    pub(super) fn mostly_on(&self, on: impl Fn(usize) -> bool) -> bool {
        let (on_picked, all) = self.cells.iter().fold((0.0, 0.0), |(picked, all), &(j, f)| {
            let pressure = f[2].max(0.0);
            (if on(j) { picked + pressure } else { picked }, all + pressure)
        });
        on_picked > 0.5 * all
    }
}

/// A cell and its (fx, fy, fz), N.
type Traction = (usize, [f64; 3]);

/// A frame's displacements (2 per corner, mm), the corners used, and stage 2's tractions (3 per cell, N).
#[derive(Clone, Copy)]
struct Observed<'a> {
    d: &'a [f64],
    valid: &'a [bool],
    tractions: &'a [f64],
}

impl InverseModel {
    pub fn cells(&self) -> &[Cell] {
        &self.cells
    }

    pub fn pad(&self) -> &PadGeometry {
        &self.pad
    }

    /// The points whose displacements the model observes, nominal pad mm: the corners, or the yellow squares (see
    /// `inverse.observe`).
    pub fn observed_points_mm(&self) -> &[Point2] {
        &self.points_mm
    }

    /// Pressure in kPa on the cell grid (row-major), from tractions.
    pub fn pressure_kpa(&self, tractions: &[f64]) -> Vec<f64> {
        let area = self.pad.pitch_x_mm() * self.pad.pitch_y_mm();
        (0..self.cells.len())
            .map(|j| tractions[3 * j + 2] / area * 1e3)
            .collect()
    }
}

/// The 3 x 3 block around (r, c) inside the grid, the cell itself included.
fn neighbourhood(r: isize, c: isize, rows: usize, cols: usize) -> impl Iterator<Item = (usize, usize)> {
    (-1..=1)
        .flat_map(move |dr| (-1..=1).map(move |dc| (r + dr, c + dc)))
        .filter_map(move |(nr, nc)| {
            (nr >= 0 && nc >= 0 && (nr as usize) < rows && (nc as usize) < cols).then_some((nr as usize, nc as usize))
        })
}
