//! Building an inverse model: once per sensor config and camera view, with what does not depend on the view built
//! once per pad and elastic config, and both kept for reuse.

use std::sync::{Arc, Mutex};

use nalgebra::DMatrix;
use nusense_geometry::{PadGeometry, Point2, SquareIndex};

use super::stage1::{motion_basis, MEASURED_NOISE_REACH_CELLS};
use super::{normal_quantile, FineGrid, InverseModel, Quarters, FINE_PER_CELL, MOTION_PARAMETERS, SUPPORT_SIGMAS};
use crate::config::{ElasticModel, ObservedPoints, SensorConfig};
use crate::elastic::{
    image_matrix, normal_stack, parallax_shifts, Border, CameraView, Cell, ElasticError, PadResponse, PointKernel,
};
use crate::linalg::{gram, Dense, PackedSymmetric};

/// Lengths (cells) of the line shapes stage 2 also picks its loaded cells by, along the grid's rows, columns and
/// diagonals, and the sides (cells) of the square shapes a line must explain better than.
const LINE_LENGTHS_CELLS: [usize; 2] = [3, 5];
const BLOCK_SIDES_CELLS: [usize; 3] = [1, 2, 3];

/// With `inverse.observe = "squares"`, each square is the mean motion of this many points per side over its cell:
/// on the validation sets' presses (host/bench/examples/localisation_budget.rs) 3 x 3 located better than the
/// centres alone on the full set with the pad as built, and the mean over the cell is what a centroid measures.
const SQUARE_PROBES_PER_SIDE: usize = 3;

/// [`InverseModel::near_loads`] looks its distances up in a table built for reaches up to this many cells, the
/// largest it is asked for.
pub(super) const NEAR_TABLE_REACH_CELLS: f64 = MEASURED_NOISE_REACH_CELLS;

/// Models kept for reuse (a daemon re-tares often; tests build many estimators of a few configs).
static MODELS: Mutex<Vec<(String, Arc<InverseModel>)>> = Mutex::new(Vec::new());
/// What a model needs that does not depend on where the camera is: the layer's kernel (its spectral tables take
/// most of a model's build) and the in-plane response. A re-tare after the camera moved builds a model for a new
/// view, and only the parallax and the solve's matrices are made again.
static VIEW_FREE_PARTS: Mutex<Vec<(String, Arc<ViewFreeParts>)>> = Mutex::new(Vec::new());
const CACHE_SIZE: usize = 4;

/// The entry of `cache` under `key`, built by `build` if absent; the oldest entry goes when the cache is full.
fn cached<T, E>(
    cache: &Mutex<Vec<(String, Arc<T>)>>,
    key: String,
    build: impl FnOnce() -> Result<T, E>,
) -> Result<Arc<T>, E> {
    let mut cache = cache.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((_, value)) = cache.iter().find(|(k, _)| *k == key) {
        return Ok(value.clone());
    }
    let value = Arc::new(build()?);
    if cache.len() >= CACHE_SIZE {
        cache.remove(0);
    }
    cache.push((key, value.clone()));
    Ok(value)
}

/// What a model observes, 2 numbers per point.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Observation {
    /// The interior corners, in `PadGeometry::corner_slot` order: the estimator's.
    Corners,
    /// The yellow squares, each as the mean motion of n x n points over its cell (see [`square_probes`]).
    Squares { probes_per_side: usize },
}

struct ViewFreeParts {
    kernel: PointKernel,
    /// The kernel whose normal displacement the parallax sees, when it is not `kernel`'s (see
    /// [`crate::elastic::normal_stack`]).
    normal: Option<PointKernel>,
    /// The observed points' nominal positions: the corners, or the yellow squares' centres (see [`Observation`]).
    points: Vec<Point2>,
    /// Where the responses are taken: the points, or with `elastic.tracker_averaging` the two yellow squares' centres
    /// of each corner in turn (see [`corner_square_centres`]), or points spread over each square (see
    /// [`square_probes`]).
    observations: Vec<Point2>,
    /// How many consecutive observation points make one observed point, averaged (1: none; 2 with
    /// `elastic.tracker_averaging`, one per square).
    probes: usize,
    cells: Vec<Cell>,
    /// The in-plane response without the parallax.
    response: PadResponse,
    /// What sliding walls at the frame add to it (see [`crate::elastic::image_matrix`]), transposed: 3 per cell x
    /// observations.
    images_t: Dense,
    /// The layered model's quarter cells (each cell's four, cell-major) and their in-plane response without the
    /// parallax; none for the other models (see [`InverseModel::quarter_centres`]).
    quarters: Option<(Vec<Cell>, PadResponse)>,
    /// The fine grid's cells (see [`FineGrid`]) and their in-plane response without the parallax, when the config
    /// asks for the edge's line load (`inverse.edge_from_line`).
    fine: Option<(Vec<Cell>, PadResponse)>,
}

impl ViewFreeParts {
    fn shared(config: &SensorConfig, observed: Observation) -> Result<Arc<Self>, ElasticError> {
        let key = format!(
            "{:?}|{:?}|{}|{observed:?}",
            config.pad, config.elastic, config.inverse.edge_from_line
        );
        cached(&VIEW_FREE_PARTS, key, || Self::new(config, observed))
    }

    fn new(config: &SensorConfig, observed: Observation) -> Result<Self, ElasticError> {
        let pad = config.pad;
        let kernel = PointKernel::new(&config.elastic)?;
        let normal = normal_stack(&config.elastic)
            .map(|stack| PointKernel::new(&stack))
            .transpose()?;
        let points: Vec<Point2> = match observed {
            Observation::Corners => pad.corners().map(|c| pad.corner_mm(c)).collect(),
            Observation::Squares { .. } => pad.yellow_squares().map(|c| pad.square_centre_mm(c)).collect(),
        };
        let size = [pad.pitch_x_mm(), pad.pitch_y_mm()];
        let cells: Vec<Cell> = (0..pad.rows)
            .flat_map(|row| (0..pad.cols).map(move |col| SquareIndex { row, col }))
            .map(|cell| Cell {
                centre_mm: pad.square_centre_mm(cell),
                size_mm: size,
            })
            .collect();
        let frame = [
            pad.width_mm / 2.0 + config.elastic.border_margin_mm,
            pad.height_mm / 2.0 + config.elastic.border_margin_mm,
        ];
        let border = match (
            config.elastic.model,
            config.elastic.bonded_border,
            config.elastic.sliding_walls,
        ) {
            (ElasticModel::BondedLayer | ElasticModel::Layered, true, _) => Border::Clamped(frame),
            (ElasticModel::BondedLayer | ElasticModel::Layered, false, true) => Border::Sliding(frame),
            _ => Border::None,
        };
        let (observations, probes) = match observed {
            Observation::Squares { probes_per_side } => {
                let n = probes_per_side.max(1);
                (square_probes(&pad, n), n * n)
            }
            Observation::Corners if config.elastic.tracker_averaging => (corner_square_centres(&pad), 2),
            Observation::Corners => (points.clone(), 1),
        };
        let response = PadResponse::new(&kernel, &observations, &cells, border)?;
        let images = image_matrix(&kernel, &observations, &cells, frame);
        let images_t = Dense::from_nalgebra(&observed_at_points(images, probes).transpose());
        let quarters = if config.elastic.model == ElasticModel::Layered {
            let quarters: Vec<Cell> = cells
                .iter()
                .flat_map(|cell| {
                    let size = [cell.size_mm[0] / 2.0, cell.size_mm[1] / 2.0];
                    [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)].map(|(sx, sy)| Cell {
                        centre_mm: [
                            cell.centre_mm[0] + sx * size[0] / 2.0,
                            cell.centre_mm[1] + sy * size[1] / 2.0,
                        ],
                        size_mm: size,
                    })
                })
                .collect();
            let response = PadResponse::new(&kernel, &observations, &quarters, border)?;
            Some((quarters, response))
        } else {
            None
        };
        let fine = if config.inverse.edge_from_line {
            let fine_cells = fine_cells(&cells, size);
            let response = PadResponse::new(&kernel, &observations, &fine_cells, border)?;
            Some((fine_cells, response))
        } else {
            None
        };
        Ok(Self {
            kernel,
            normal,
            points,
            observations,
            probes,
            cells,
            response,
            images_t,
            quarters,
            fine,
        })
    }

    /// The in-plane response, the layered model's quarters' and the fine grid's pressure response (if any) as the
    /// camera at `view` sees them: with the parallax of the pattern's normal displacement through a gel of
    /// `refractive_index` (none without a view or an index).
    fn seen_from(
        &self,
        view: Option<CameraView>,
        refractive_index: f64,
    ) -> (PadResponse, Option<Quarters>, Option<FineGrid>) {
        let ViewFreeParts {
            kernel,
            normal,
            observations,
            probes,
            cells,
            ..
        } = self;
        let mut response = self.response.clone();
        let mut quarters = self.quarters.clone();
        let mut fine = self.fine.clone();
        let n = refractive_index;
        if let (Some(view), true) = (view, n > 0.0) {
            let shifts = parallax_shifts(&view, n, observations);
            let normal = normal.as_ref().unwrap_or(kernel);
            response.add_parallax(normal, observations, cells, &shifts);
            if let Some((cells, response)) = &mut quarters {
                response.add_parallax(normal, observations, cells, &shifts);
            }
            if let Some((cells, response)) = &mut fine {
                response.add_parallax(normal, observations, cells, &shifts);
            }
        }
        for (_, response) in quarters.iter_mut().chain(fine.iter_mut()) {
            response.matrix = observed_at_points(std::mem::take(&mut response.matrix), *probes);
        }
        response.matrix = observed_at_points(response.matrix, *probes);
        let fine = fine.map(|(fine_cells, response)| {
            let (cols, rows) = fine_extent(cells, cells[0].size_mm);
            FineGrid {
                origin_mm: fine_cells[0].centre_mm,
                step_mm: fine_cells[0].size_mm,
                cols,
                rows,
                pressure_t: Dense::from_nalgebra(&DMatrix::from_fn(
                    fine_cells.len(),
                    response.matrix.nrows(),
                    |j, r| response.matrix[(r, 3 * j + 2)],
                )),
            }
        });
        let quarters = quarters.map(|(cells, response)| Quarters {
            pressure_t: Dense::from_nalgebra(&DMatrix::from_fn(cells.len(), response.matrix.nrows(), |j, r| {
                response.matrix[(r, 3 * j + 2)]
            })),
            centres_mm: cells.iter().map(|q| q.centre_mm).collect(),
        });
        (response, quarters, fine)
    }
}

/// Each interior corner's two yellow squares' centres in turn (row-major), where `elastic.tracker_averaging` takes a
/// model's responses.
fn corner_square_centres(pad: &PadGeometry) -> Vec<Point2> {
    pad.corners()
        .flat_map(|corner| pad.corner_squares(corner).map(|square| pad.square_centre_mm(square)))
        .collect()
}

/// Each yellow square's `n` x `n` points spread evenly over its cell (row-major within a square, squares in
/// `PadGeometry::yellow_squares` order), where [`Observation::Squares`] takes a model's responses.
fn square_probes(pad: &PadGeometry, n: usize) -> Vec<Point2> {
    let size = [pad.pitch_x_mm(), pad.pitch_y_mm()];
    let offset = move |k: usize| (k as f64 + 0.5) / n as f64 - 0.5;
    pad.yellow_squares()
        .flat_map(|square| {
            let c = pad.square_centre_mm(square);
            (0..n * n).map(move |k| [c[0] + offset(k % n) * size[0], c[1] + offset(k / n) * size[1]])
        })
        .collect()
}

/// A response taken at the model's observation points as its observed points see them: each `probes` consecutive
/// points' rows (x and y) averaged into one point's (with `elastic.tracker_averaging`, a corner's two squares; with
/// [`Observation::Squares`], a square's probes).
fn observed_at_points(matrix: DMatrix<f64>, probes: usize) -> DMatrix<f64> {
    if probes == 1 {
        return matrix;
    }
    let points = matrix.nrows() / (2 * probes);
    DMatrix::from_fn(2 * points, matrix.ncols(), |r, c| {
        let (point, axis) = (r / 2, r % 2);
        (0..probes)
            .map(|k| matrix[(2 * (probes * point + k) + axis, c)])
            .sum::<f64>()
            / probes as f64
    })
}

/// The fine grid's cells: the pattern's `cells` (row-major, `size` apart) each split into [`FINE_PER_CELL`] x
/// [`FINE_PER_CELL`], row-major over the whole grid.
fn fine_cells(cells: &[Cell], size: Point2) -> Vec<Cell> {
    let step = [size[0] / FINE_PER_CELL as f64, size[1] / FINE_PER_CELL as f64];
    let first = [
        cells[0].centre_mm[0] - 0.5 * (size[0] - step[0]),
        cells[0].centre_mm[1] - 0.5 * (size[1] - step[1]),
    ];
    let (cols, rows) = fine_extent(cells, size);
    (0..rows)
        .flat_map(|row| (0..cols).map(move |col| (row, col)))
        .map(|(row, col)| Cell {
            centre_mm: [first[0] + col as f64 * step[0], first[1] + row as f64 * step[1]],
            size_mm: step,
        })
        .collect()
}

/// The fine grid's columns and rows (see [`fine_cells`]).
fn fine_extent(cells: &[Cell], size: Point2) -> (usize, usize) {
    let last = cells[cells.len() - 1].centre_mm;
    let count = |from: f64, to: f64, pitch: f64| ((to - from) / pitch).round() as usize + 1;
    (
        count(cells[0].centre_mm[0], last[0], size[0]) * FINE_PER_CELL,
        count(cells[0].centre_mm[1], last[1], size[1]) * FINE_PER_CELL,
    )
}

/// Distance (mm) from a corner to a cell's centre, as [`InverseModel::near_loads`] compares it with its reach.
fn corner_to_cell_mm(corner: Point2, centre: Point2) -> f64 {
    (corner[0] - centre[0]).hypot(corner[1] - centre[1])
}

/// The line shapes of [`LINE_LENGTHS_CELLS`] along rows, columns and both diagonals, wholly inside a rows x cols grid
/// (cells row-major).
fn line_shapes(rows: usize, cols: usize) -> Vec<Vec<usize>> {
    let mut shapes = Vec::new();
    for length in LINE_LENGTHS_CELLS {
        for (dr, dc) in [(0isize, 1isize), (1, 0), (1, 1), (1, -1)] {
            for r in 0..rows as isize {
                for c in 0..cols as isize {
                    let shape: Vec<usize> = (0..length as isize)
                        .map(|k| (r + k * dr, c + k * dc))
                        .filter(|&(r, c)| r >= 0 && c >= 0 && (r as usize) < rows && (c as usize) < cols)
                        .map(|(r, c)| r as usize * cols + c as usize)
                        .collect();
                    if shape.len() == length {
                        shapes.push(shape);
                    }
                }
            }
        }
    }
    shapes
}

/// The square shapes of [`BLOCK_SIDES_CELLS`] wholly inside a rows x cols grid (cells row-major).
fn block_shapes(rows: usize, cols: usize) -> Vec<Vec<usize>> {
    let mut shapes = Vec::new();
    for side in BLOCK_SIDES_CELLS {
        for r in 0..(rows + 1).saturating_sub(side) {
            for c in 0..(cols + 1).saturating_sub(side) {
                shapes.push(
                    (r..r + side)
                        .flat_map(|r| (c..c + side).map(move |c| r * cols + c))
                        .collect(),
                );
            }
        }
    }
    shapes
}

impl InverseModel {
    /// The model for `config`, built once per distinct pad, elastic and inverse configuration and camera view in
    /// this process.
    /// `view`: where the camera is (from the rest frame's map), for the parallax of the pattern's normal
    /// displacement; `None` leaves it out.
    pub fn shared(config: &SensorConfig, view: Option<CameraView>) -> Result<Arc<Self>, ElasticError> {
        let key = format!("{:?}|{:?}|{:?}|{:?}", config.pad, config.elastic, config.inverse, view);
        cached(&MODELS, key, || Self::new(config, view))
    }

    /// The model of `config`, observing the points `inverse.observe` names.
    pub fn new(config: &SensorConfig, view: Option<CameraView>) -> Result<Self, ElasticError> {
        let observed = match config.inverse.observe {
            ObservedPoints::Corners => Observation::Corners,
            ObservedPoints::Squares => Observation::Squares {
                probes_per_side: SQUARE_PROBES_PER_SIDE,
            },
        };
        Self::observing(config, view, observed)
    }

    /// A diagnostic: the model observing the yellow squares' centroids (each the mean motion of `probes_per_side` x
    /// `probes_per_side` points over its cell; 1: its centre) in place of the corners, 2 per square in
    /// `PadGeometry::yellow_squares` order, whatever `inverse.observe` says (the estimator's, with `inverse.observe =
    /// "squares"`, is this with [`SQUARE_PROBES_PER_SIDE`]). The fast tracker measures the squares, and its corners
    /// are their midpoints, which carry less (see `elastic.tracker_averaging`). What it gives:
    /// host/bench/examples/localisation_budget.rs and docs/benchmarks/validation-quick.md.
    pub fn observing_squares(
        config: &SensorConfig,
        view: Option<CameraView>,
        probes_per_side: usize,
    ) -> Result<Self, ElasticError> {
        Self::observing(config, view, Observation::Squares { probes_per_side })
    }

    fn observing(config: &SensorConfig, view: Option<CameraView>, observed: Observation) -> Result<Self, ElasticError> {
        let pad = config.pad;
        let parts = ViewFreeParts::shared(config, observed)?;
        let ViewFreeParts { points, cells, .. } = &*parts;
        let (response, quarters, fine) = parts.seen_from(view, config.elastic.gel_refractive_index);
        let a = response.matrix;
        let observations = a.nrows();
        let motion_length_mm = (pad.width_mm.max(pad.height_mm)) / 2.0;
        let b = motion_basis(points, motion_length_mm);
        let lambda = (config.inverse.noise_mm / config.inverse.traction_prior_n).powi(2);
        let s = kriging_columns(&a, &b, lambda)?;
        let test = TestOperators::new(&a, &b, &s, lambda, cells.len())?;
        let (line_shapes, block_shapes) =
            shape_filters(&test.matched_gram, usize::from(pad.rows), usize::from(pad.cols));

        let mut model = Self {
            pad,
            a_t: Dense::from_nalgebra(&a.transpose()),
            b_t: Dense::from_nalgebra(&b.transpose()),
            gram_bb: Dense::from_nalgebra(&test.btb),
            fit_gram: fit_gram(&a, &b),
            a: Dense::from_nalgebra(&a),
            b: Dense::from_nalgebra(&b),
            s: Dense::from_nalgebra(&s),
            s_t: Dense::from_nalgebra(&s.transpose()),
            a_t_pressure: Dense::from_nalgebra(&DMatrix::from_fn(cells.len(), observations, |j, r| a[(r, 3 * j + 2)])),
            cells: cells.clone(),
            observations,
            points_mm: points.clone(),
            lambda,
            residual_share: test.residual_share,
            pressure_noise: test.pressure_noise,
            test_scale: test.trace_sq / test.trace,
            test_dof: test.trace * test.trace / test.trace_sq,
            reference_explained: 0.0,
            pressure_explained: Dense::from_nalgebra(&test.pressure_explained),
            matched_gram: Dense::from_nalgebra(&test.matched_gram),
            line_shapes,
            block_shapes,
            line_sigmas: line_sigmas(),
            motion_length_mm,
            false_alarm_probability: config.inverse.false_alarm_probability,
            corners_near_cell: Vec::new(),
            images_t: parts.images_t.clone(),
            quarters,
            fine,
        };
        let table_reach = NEAR_TABLE_REACH_CELLS * pad.pitch_x_mm().max(pad.pitch_y_mm());
        model.corners_near_cell = corners_near_cells(&model.cells, &model.points_mm, table_reach);
        let d = model.central_press_mm();
        let stage = model.stage1(&d, &vec![true; observations / 2]);
        model.reference_explained = stage.rss_rigid - stage.rss_full;
        if !(model.reference_explained > 0.0) {
            return Err(ElasticError::Degenerate("a press at the centre explains nothing"));
        }
        Ok(model)
    }

    /// The cells whose centres are nearest the pad's centre (four on an even grid).
    fn central_cells(&self) -> Vec<usize> {
        let distance = |c: &Cell| c.centre_mm[0].hypot(c.centre_mm[1]);
        let nearest = self.cells.iter().map(distance).fold(f64::MAX, f64::min);
        (0..self.cells.len())
            .filter(|&j| distance(&self.cells[j]) <= nearest + 1e-9)
            .collect()
    }

    /// The displacements (mm, 2 per corner, noise-free) of a 1 N press spread over the cells nearest the pad's
    /// centre: the press the detection floor is stated for.
    pub fn central_press_mm(&self) -> Vec<f64> {
        let central = self.central_cells();
        let mut press = vec![0.0; 3 * self.cells.len()];
        for &j in &central {
            press[3 * j + 2] = 1.0 / central.len() as f64;
        }
        let mut d = vec![0.0; self.observations];
        self.a.mul_vec(&press, &mut d);
        d
    }
}

/// The Gram matrix of [B A] over every observation (see `InverseModel::fit_gram`).
fn fit_gram(a: &DMatrix<f64>, b: &DMatrix<f64>) -> PackedSymmetric {
    let columns = DMatrix::from_fn(a.nrows(), MOTION_PARAMETERS + a.ncols(), |r, c| {
        if c < MOTION_PARAMETERS {
            b[(r, c)]
        } else {
            a[(r, c - MOTION_PARAMETERS)]
        }
    });
    PackedSymmetric::from_nalgebra(&gram(&columns))
}

/// The first `observations` columns of the kriging system's inverse ([C B; Bᵀ 0] with C = A Aᵀ + lambda I, see the
/// module notes), (obs + P) x obs.
fn kriging_columns(a: &DMatrix<f64>, b: &DMatrix<f64>, lambda: f64) -> Result<DMatrix<f64>, ElasticError> {
    let observations = a.nrows();
    let mut k = DMatrix::zeros(observations + MOTION_PARAMETERS, observations + MOTION_PARAMETERS);
    let c = a * a.transpose();
    k.view_mut((0, 0), (observations, observations)).copy_from(&c);
    for i in 0..observations {
        k[(i, i)] += lambda;
    }
    k.view_mut((0, observations), (observations, MOTION_PARAMETERS))
        .copy_from(b);
    k.view_mut((observations, 0), (MOTION_PARAMETERS, observations))
        .copy_from(&b.transpose());
    let inverse = k
        .try_inverse()
        .ok_or(ElasticError::Degenerate("the kriging system is singular"))?;
    Ok(inverse.columns(0, observations).into_owned())
}

/// What the contact test and the matched filter read off the kriging operator, for the fields of [`InverseModel`]
/// of the same names.
struct TestOperators {
    /// BᵀB.
    btb: DMatrix<f64>,
    residual_share: Vec<f64>,
    pressure_noise: Vec<f64>,
    pressure_explained: DMatrix<f64>,
    matched_gram: DMatrix<f64>,
    /// The trace of Q and the sum of its entries' squares, for the Satterthwaite parameters.
    trace: f64,
    trace_sq: f64,
}

impl TestOperators {
    /// From A, B, the kriging columns `s` ([`kriging_columns`]) and lambda, over `cells` cells.
    fn new(
        a: &DMatrix<f64>,
        b: &DMatrix<f64>,
        s: &DMatrix<f64>,
        lambda: f64,
        cells: usize,
    ) -> Result<Self, ElasticError> {
        let observations = a.nrows();
        let s11 = s.rows(0, observations).into_owned();

        // The test: Q = P0 - lambda^2 S11^2 with P0 the projection off the motion basis.
        let btb = b.transpose() * b;
        let btb_inv = btb
            .clone()
            .try_inverse()
            .ok_or(ElasticError::Degenerate("the motion basis is degenerate"))?;
        let p0 = DMatrix::identity(observations, observations) - b * &btb_inv * b.transpose();
        let s11_sq = &s11 * &s11;
        let q = &p0 - &s11_sq * (lambda * lambda);
        let trace = q.trace();
        let trace_sq = q.iter().map(|v| v * v).sum::<f64>();
        if !(trace > 0.0 && trace_sq > 0.0) {
            return Err(ElasticError::Degenerate(
                "the tractions explain nothing beyond the motion",
            ));
        }
        let residual_share = (0..observations / 2)
            .map(|i| lambda * lambda * (s11_sq[(2 * i, 2 * i)] + s11_sq[(2 * i + 1, 2 * i + 1)]))
            .collect();
        let pressure_columns = DMatrix::from_fn(observations, cells, |r, j| a[(r, 3 * j + 2)]);
        let pressure_explained = pressure_columns.transpose() * &q * &pressure_columns;
        let operator = a.transpose() * &s11;
        let pressure_noise = (0..cells).map(|j| operator.row(3 * j + 2).norm()).collect();
        let matched_gram = pressure_columns.transpose() * &p0 * &pressure_columns;
        Ok(Self {
            btb,
            residual_share,
            pressure_noise,
            pressure_explained,
            matched_gram,
            trace,
            trace_sq,
        })
    }
}

/// The line shapes and the square ones on a rows x cols grid, each with its sqrt(wᵀ G0 w) (G0: `matched_gram`),
/// those of none left out.
#[allow(clippy::type_complexity)]
fn shape_filters(
    matched_gram: &DMatrix<f64>,
    rows: usize,
    cols: usize,
) -> (Vec<(Vec<usize>, f64)>, Vec<(Vec<usize>, f64)>) {
    let shape_norm = |shape: &[usize]| {
        shape
            .iter()
            .flat_map(|&i| shape.iter().map(move |&j| (i, j)))
            .map(|(i, j)| matched_gram[(i, j)])
            .sum::<f64>()
            .max(0.0)
            .sqrt()
    };
    let with_norms = |shapes: Vec<Vec<usize>>| -> Vec<(Vec<usize>, f64)> {
        shapes
            .into_iter()
            .map(|shape| {
                let norm = shape_norm(&shape);
                (shape, norm)
            })
            .filter(|(_, norm)| *norm > 0.0)
            .collect()
    };
    (
        with_norms(line_shapes(rows, cols)),
        with_norms(block_shapes(rows, cols)),
    )
}

/// The sigmas above which a line shape picks its cells: the cell test's false-pick rate per cell
/// ([`SUPPORT_SIGMAS`]), shared among the line shapes through a cell.
fn line_sigmas() -> f64 {
    let lines_per_cell = (LINE_LENGTHS_CELLS.iter().sum::<usize>() * 4) as f64;
    let cell_false_pick = 0.5 * libm::erfc(SUPPORT_SIGMAS / std::f64::consts::SQRT_2);
    normal_quantile(1.0 - cell_false_pick / lines_per_cell)
}

/// Per cell: the corners (index, distance from the cell's centre in mm) within `table_reach` mm of it.
fn corners_near_cells(cells: &[Cell], corners: &[Point2], table_reach: f64) -> Vec<Vec<(usize, f64)>> {
    cells
        .iter()
        .map(|cell| {
            corners
                .iter()
                .map(|&p| corner_to_cell_mm(p, cell.centre_mm))
                .enumerate()
                .filter(|&(_, distance)| distance <= table_reach)
                .collect()
        })
        .collect()
}
