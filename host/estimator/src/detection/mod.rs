//! Fast lattice detection ("model only what the scene needs").
//!
//! Reference frame (once, at tare): a small yellowness map of the whole frame, Otsu, yellow blobs, lattice
//! indices from topology ([`indexing`]), then every square refined at full resolution inside its own cell
//! ([`window`]). Every later frame: each square is searched only inside its cell around where it was last seen;
//! the yellow/not-yellow split comes from those windows' own histogram (Otsu), so lighting may change. A full
//! search runs again only when tracking fails (many squares lost, or the pattern moved more than half a cell).
//!
//! Corners come from the squares: interior corner (r, c) is where the two yellow cells of its 2 x 2 block touch,
//! taken as the midpoint of their centres. That is exact wherever the pad and lens map the 2 x 2 block affinely
//! (the lens' curvature over one cell shifts it by far less than a pixel) and needs no extra pixel access.

pub mod blobs;
pub mod indexing;
pub mod window;
pub mod yellowness;

use image::RgbImage;
use nusense_geometry::{PadGeometry, Point2, Similarity, SquareIndex};

use crate::config::Thresholds;
use crate::error::EstimateError;
use blobs::find_square_blobs;
use indexing::index_lattice;
use window::{add_to_histogram, centroid, mean_brightness, mean_membership, CellFrame, Pixels, Window};
use yellowness::{otsu, Histogram, Membership, YellownessMap};

/// Every square's sub-pixel centroid (raw px) and area (px^2), in the pad's square order; `None` where the square
/// could not be measured.
type Measurements = Vec<Option<(Point2, f64)>>;

/// Half-size of a square's search window in cell units: the square (about 0.8 cell) plus room for motion,
/// while the diagonal neighbours (from 0.5 + their gap) stay outside.
const WINDOW_HALF: f64 = 0.55;
/// Width of the small map used by the full-frame search.
const SEARCH_MAP_WIDTH: usize = 512;
/// A tracked square whose yellow area differs from the reference by more than these factors is not trusted.
const AREA_RATIO_RANGE: (f64, f64) = (0.45, 2.2);
/// Most centroid passes per square (one in a steady scene, a few after a fast move).
const MAX_PASSES: usize = 5;
/// A tracked square further than this many cells from where the lattice's rigid motion puts it is measured again
/// from there: its window may have locked onto a neighbour after the camera jumped (a press moves a square much
/// less than this).
const RELOCK_CELLS: f64 = 0.35;
/// The camera jumped when its rigid motion moved some square this many cells since the last frame.
const JUMP_CELLS: f64 = 0.1;
/// A square whose yellow area changed by more than this many robust standard deviations (over the frame's squares)
/// beyond what its lattice neighbours' spacing explains is not trusted: see `FastTracker::relit_squares`.
const RELIT_SIGMAS: f64 = 5.0;
/// With the camera still, a square's light changed when the brightness of its middle (the patch within
/// [`CENTRE_HALF`] cells of its centroid, all yellow ink) departs from the rest frame's by more than this fraction. The
/// patch's mean over its pixels moves by well under 0.1 % with the sensor's noise, and a press moves the patch with the
/// ink, so only the light changes it; a change this small clips nothing that was not clipped already.
const LIGHT_CHANGE: f64 = 0.02;
/// MAD to standard deviation for a normal distribution.
pub(crate) const MAD_TO_SIGMA: f64 = 1.4826;
/// Samples across a cell the centroid needs; more pixels than this add time, not precision.
const SAMPLES_PER_CELL: f64 = 36.0;
/// A found centroid must sit on yellow: the mean membership within CENTRE_HALF cells of it at least this. The
/// patch lies well inside a square (about 0.4 cell each side), so a true centroid's patch is all ink (where the LEDs'
/// glare clips a square's middle white, its pixels still count as yellow: see `window::yellow_bin`); a blend of two
/// diagonal squares sits on the lines and red between them, where only the patch's far corners (a few percent) reach
/// any yellow.
const MIN_CENTRE_MEMBERSHIP: f32 = 0.25;
const CENTRE_HALF: f64 = 0.15;
/// A square's window with more of its pixels clipped white than this holds no square: the yellow and the
/// lines between cells take about two thirds of a window, so beyond this the red around the square is clipped too.
const MAX_CLIPPED_FRACTION: f64 = 0.95;
/// The same for the pattern as a whole: beyond this the frame is refused as over-exposed.
const MAX_CLIPPED_PATTERN_FRACTION: f64 = 0.9;
/// A lost square is searched again from its neighbours' motion up to this many times (each round can use
/// squares found in the round before).
const NEIGHBOUR_ROUNDS: usize = 3;
/// Neighbours within this many rows and columns vote on a lost square's position...
const NEIGHBOUR_REACH: u32 = 2;
/// ...and at least this many must have been found.
const MIN_NEIGHBOURS: usize = 3;
/// A square lies within this many cells (along each lattice direction) of where its neighbours' motion, continued
/// into it, puts it, even under a press that moves the pad by two cells (a 30 N press with 12 N of shear: 0.35 at
/// most); a window settled on a diagonal neighbour instead lies 0.6 to 1.2 cells off (the same press). See
/// `FastTracker::settle_large_moves`.
const TREND_CELLS: f64 = 0.6;
/// Two squares' centroids are at least this many cells apart: diagonal neighbours in the checkerboard lie a cell
/// apart along both lattice directions, 0.7 where that press compresses the pad most.
const TAKEN_CELLS: f64 = 0.5;

#[derive(Clone, Debug)]
struct SquareModel {
    index: SquareIndex,
    reference: Option<Point2>,
    reference_area: f64,
    /// Mean R + G + B of the square's middle in the rest frame (see [`LIGHT_CHANGE`]); 0 where unknown.
    reference_brightness: f64,
    /// The square's cell and its search window ([`WINDOW_HALF`]).
    window: Window,
}

impl SquareModel {
    fn cell(&self) -> &CellFrame {
        self.window.cell()
    }
}

/// What one frame's detection found.
#[derive(Clone, Debug, PartialEq)]
pub struct Detection {
    /// Per yellow square (row-major `PadGeometry::yellow_squares` order), raw px.
    pub squares: Vec<Option<Point2>>,
    /// Per interior corner (`PadGeometry::corner_slot` order), raw px.
    pub corners: Vec<Option<Point2>>,
    /// Whether this frame needed a full-frame search.
    pub recovered: bool,
    /// Times the squares were measured in this frame: 1 in a steady scene, 2 when the tracker re-measured them
    /// from the lattice's rigid motion (the camera jumped or a square slipped), one more after a full search.
    pub measurement_passes: u32,
    /// Per square (the order of `squares`): found, but under another light than in the rest frame (the camera's
    /// motion moved it into or out of the glare or the vignetting, or the LEDs changed and it clips), which biases its
    /// centroid by an amount no motion model predicts.
    pub relit: Vec<bool>,
}

/// The fast detector with its tracking state.
#[derive(Clone, Debug)]
pub struct FastTracker {
    pad: PadGeometry,
    width: u32,
    height: u32,
    stride: usize,
    squares: Vec<SquareModel>,
    previous: Vec<Option<Point2>>,
    /// Yellow area of each square in the last frame (for a re-tare).
    previous_area: Vec<Option<f64>>,
    /// The lattice's rigid motion (raw px, from the reference) in the last frame.
    last_motion: Similarity,
    thresholds: Thresholds,
}

fn sub(a: Point2, b: Point2) -> Point2 {
    [a[0] - b[0], a[1] - b[1]]
}

fn lerp_mid(a: Point2, b: Point2) -> Point2 {
    [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0]
}

/// Minimum frame side the search works on (a cell must stay several pixels wide).
pub const MIN_FRAME_SIDE: u32 = 64;

impl FastTracker {
    /// Finds the whole lattice in the reference frame.
    pub fn from_reference(
        frame: &RgbImage,
        pad: PadGeometry,
        thresholds: Thresholds,
    ) -> Result<(Self, Detection), EstimateError> {
        let (width, height) = frame.dimensions();
        if width < MIN_FRAME_SIDE || height < MIN_FRAME_SIDE {
            return Err(EstimateError::FrameTooSmall {
                width,
                height,
                min: MIN_FRAME_SIDE,
            });
        }
        let coarse = full_search(frame, &pad)?;
        let found = coarse.iter().filter(|p| p.is_some()).count();
        let needed = pad.yellow_count().div_ceil(2);
        if found < needed {
            return Err(EstimateError::TooFewPoints { found, needed });
        }
        let mut tracker = Self::on_coarse_squares(pad, (width, height), thresholds, &coarse)?;
        let squares_px = tracker.settle_reference(frame, &coarse)?;
        let corners = corners_from_squares(&pad, &squares_px);
        let relit = vec![false; squares_px.len()];
        Ok((
            tracker,
            Detection {
                squares: squares_px,
                corners,
                recovered: false,
                measurement_passes: 1,
                relit,
            },
        ))
    }

    /// A tracker whose cells (and the sampling stride) come from the full search's coarse squares; the squares
    /// have no reference yet. A square without a cell of its own borrows another's, so that it is still searched.
    fn on_coarse_squares(
        pad: PadGeometry,
        (width, height): (u32, u32),
        thresholds: Thresholds,
        coarse: &[Option<Point2>],
    ) -> Result<Self, EstimateError> {
        let cells = local_cells(&pad, coarse)?;
        let mut steps: Vec<f64> = cells.iter().flatten().map(CellFrame::min_step).collect();
        let stride = ((median(&mut steps) / SAMPLES_PER_CELL).round() as usize).max(1);
        let any_cell = cells
            .iter()
            .flatten()
            .next()
            .copied()
            .ok_or_else(|| EstimateError::NoPattern {
                reason: "no square has lattice neighbours".into(),
            })?;
        let squares: Vec<SquareModel> = pad
            .yellow_squares()
            .zip(&cells)
            .map(|(index, cell)| SquareModel {
                index,
                reference: None,
                reference_area: 0.0,
                reference_brightness: 0.0,
                window: Window::new(cell.unwrap_or(any_cell), WINDOW_HALF),
            })
            .collect();
        Ok(Self {
            pad,
            width,
            height,
            stride,
            squares,
            previous: coarse.to_vec(),
            previous_area: Vec::new(),
            last_motion: Similarity::IDENTITY,
            thresholds,
        })
    }

    /// Measures the reference frame's squares from the coarse ones, refreshes the cells from them and measures
    /// again; the squares' reference positions, areas and brightness are then set, and the frame is the last
    /// tracked one. Returns the reference squares (raw px).
    fn settle_reference(
        &mut self,
        frame: &RgbImage,
        coarse: &[Option<Point2>],
    ) -> Result<Vec<Option<Point2>>, EstimateError> {
        let measured = self.measure(frame, coarse, None)?;
        let mut squares_px = Vec::with_capacity(measured.len());
        for (model, m) in self.squares.iter_mut().zip(&measured) {
            model.reference = m.map(|(p, _)| p);
            model.reference_area = m.map(|(_, a)| a).unwrap_or(0.0);
            squares_px.push(model.reference);
        }
        // Refresh the cells from the refined reference so later windows follow the lens exactly.
        self.refresh_cells(&squares_px)?;
        // Measure the reference again with those cells, from where the first pass ended, as every later frame is
        // measured: the reference is then where tracking the rest frame itself puts its squares, so that the same
        // frame again has no displacement (with the coarse cells' reference, its corners sat up to a few tenths of
        // a pixel off, which the contact test, judging by each frame's own noise, took for a load).
        let measured = self.measure(frame, &squares_px, None)?;
        squares_px.clear();
        for (model, m) in self.squares.iter_mut().zip(&measured) {
            if let Some((p, a)) = m {
                model.reference = Some(*p);
                model.reference_area = *a;
            }
            squares_px.push(model.reference);
        }
        self.note_reference_brightness(frame);
        self.previous = squares_px.clone();
        self.previous_area = measured.iter().map(|m| m.map(|(_, a)| a)).collect();
        Ok(squares_px)
    }

    /// Each referenced square's middle brightness in the reference frame (see [`LIGHT_CHANGE`]).
    fn note_reference_brightness(&mut self, frame: &RgbImage) {
        let px = Pixels {
            raw: frame.as_raw(),
            width: self.width as usize,
            height: self.height as usize,
        };
        for model in &mut self.squares {
            if let Some(p) = model.reference {
                model.reference_brightness = mean_brightness(&px, p, model.cell(), CENTRE_HALF, self.stride);
            }
        }
    }

    /// Makes the last tracked frame the reference: squares found there keep their new position and area (and the
    /// cells follow them); squares it missed keep the old reference. The frame is not kept, so the squares' light in
    /// it is unknown: until the next rest frame, only the camera's motion flags relit squares.
    pub fn adopt_last_frame_as_reference(&mut self) -> Result<(), EstimateError> {
        self.last_motion = Similarity::IDENTITY;
        for ((model, p), a) in self.squares.iter_mut().zip(&self.previous).zip(&self.previous_area) {
            if let (Some(p), Some(a)) = (p, a) {
                model.reference = Some(*p);
                model.reference_area = *a;
            }
            model.reference_brightness = 0.0;
        }
        let squares: Vec<Option<Point2>> = self.squares.iter().map(|m| m.reference).collect();
        self.refresh_cells(&squares)
    }

    /// Gives every square the cell (and search window) that [`local_cells`] finds for it with the squares at
    /// `squares`, one place for the rule the reference and a re-tare both follow; where that cell is degenerate, the
    /// square keeps the one it had rather than searching in no cell.
    fn refresh_cells(&mut self, squares: &[Option<Point2>]) -> Result<(), EstimateError> {
        for (model, cell) in self.squares.iter_mut().zip(local_cells(&self.pad, squares)?) {
            if let Some(cell) = cell {
                model.window = Window::new(cell, WINDOW_HALF);
            }
        }
        Ok(())
    }

    pub fn frame_size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// Finds the lattice in a later frame, predicting from the previous one.
    pub fn track(&mut self, frame: &RgbImage) -> Result<Detection, EstimateError> {
        let predicted = self.predictions();
        let mut measured = self.measure(frame, &predicted, Some(&predicted))?;
        let mut measurement_passes = 1;
        if let Some(relocked) = self.relock(frame, &measured)? {
            measured = relocked;
            measurement_passes += 1;
        }
        let mut recovered = false;
        if self.tracking_failed(&measured, &predicted) {
            if let Ok(coarse) = full_search(frame, &self.pad) {
                if let Some(aligned) = self.align_to_reference(&coarse) {
                    measured = self.measure(frame, &aligned, Some(&aligned))?;
                    recovered = true;
                    measurement_passes += 1;
                }
            }
        }
        let relit = self.relit_squares(frame, &measured);
        let squares: Vec<Option<Point2>> = measured.iter().map(|m| m.map(|(p, _)| p)).collect();
        self.previous = squares.clone();
        self.previous_area = measured.iter().map(|m| m.map(|(_, a)| a)).collect();
        let corners = corners_from_squares(&self.pad, &squares);
        Ok(Detection {
            squares,
            corners,
            recovered,
            measurement_passes,
            relit,
        })
    }

    /// The squares seen under another light than in the rest frame. Glare and vignetting belong to the camera, not the
    /// pad: once the camera has moved against the pad, a square seen through another part of the light than in the rest
    /// frame has its yellow area, and with it its centroid, biased, and the bias differs from square to square, so no
    /// motion model removes it. A still camera sees the same when the light itself changes unevenly: with one LED side
    /// brighter, the yellow on that side clips in red and green while its blue still grows, and the pixels across a
    /// square's edge that clip then but not in the rest frame weigh differently (while a clipped pixel's yellowness
    /// counted, rather than its being yellow ink, see `window::yellow_bin`, whole squares lost membership unevenly and
    /// their centroids moved by up to a few px: validation sensor at 1024x768, one side at 150 %, rest frames read as
    /// contacts of 0.8 N while only a camera's motion flagged squares). The area shows both: the pad's deformation
    /// changes a square's area together with its spacing to its diagonal neighbours, a change of light changes the area
    /// alone. A square whose area change departs from its neighbours' spacing by more than [`RELIT_SIGMAS`] robust
    /// standard deviations over the frame is flagged, if the camera moved or the light on the square's middle changed
    /// by more than [`LIGHT_CHANGE`] against the frame's typical change (the median square's). The light's condition
    /// keeps a press under a still camera and even light from being flagged: the spacing explains a press's area
    /// change only to first order, which is beyond the few hundredths of a still frame's robust spread (a 5 N press at
    /// the validation pad's centre then went undetected). A change of light that is even over the pattern (all LEDs
    /// alike, the exposure) changes every square's area alike and is no change against the typical one; judged
    /// against the rest frame instead, it flagged a press's squares (every LED at 90 % or 110 % split a 3 N press
    /// beside the validation sensor's glare into two contacts on most noise seeds: tests/uneven_light.rs). A press
    /// changes areas as well (the pattern sinks towards the camera under it), so a flag does not drop the square: the
    /// contact test leaves it out (see [`Detection::relit`]).
    fn relit_squares(&self, frame: &RgbImage, measured: &[Option<(Point2, f64)>]) -> Vec<bool> {
        let moved = self.squares.iter().any(|model| {
            model.reference.is_some_and(|r| {
                sub(self.last_motion.apply(r), r)[0].hypot(sub(self.last_motion.apply(r), r)[1])
                    / model.cell().min_step()
                    > JUMP_CELLS
            })
        });
        let slot_of = |row: i32, col: i32| -> Option<usize> {
            let index = SquareIndex {
                row: u16::try_from(row).ok()?,
                col: u16::try_from(col).ok()?,
            };
            self.squares.binary_search_by_key(&index, |m| m.index).ok()
        };
        let unexplained: Vec<Option<f64>> = self
            .squares
            .iter()
            .zip(measured)
            .map(|(model, m)| {
                let ((at, area), reference) = ((*m)?, model.reference?);
                if model.reference_area <= 0.0 {
                    return None;
                }
                let spacing: Vec<f64> = [(-1, -1), (-1, 1), (1, -1), (1, 1)]
                    .into_iter()
                    .filter_map(|(dr, dc)| {
                        let n = slot_of(i32::from(model.index.row) + dr, i32::from(model.index.col) + dc)?;
                        let ((other, _), other_reference) = (measured[n]?, self.squares[n].reference?);
                        let now = sub(other, at)[0].hypot(sub(other, at)[1]);
                        let then = sub(other_reference, reference)[0].hypot(sub(other_reference, reference)[1]);
                        (now > 0.0 && then > 0.0).then(|| 2.0 * (now / then).ln())
                    })
                    .collect();
                if spacing.len() < 2 {
                    return None;
                }
                let explained = spacing.iter().sum::<f64>() / spacing.len() as f64;
                Some((area / model.reference_area).ln() - explained)
            })
            .collect();
        let mut values: Vec<f64> = unexplained.iter().flatten().copied().collect();
        if values.len() < MIN_NEIGHBOURS * 3 {
            return vec![false; measured.len()];
        }
        let centre = median(&mut values);
        let mut deviations: Vec<f64> = values.iter().map(|v| (v - centre).abs()).collect();
        let limit = RELIT_SIGMAS * MAD_TO_SIGMA * median(&mut deviations);
        let outlier: Vec<bool> = unexplained
            .iter()
            .map(|u| u.is_some_and(|u| (u - centre).abs() > limit))
            .collect();
        // The light matters only for an outlier with the camera still: most frames measure no square's light.
        if moved || !outlier.contains(&true) {
            return outlier;
        }
        let px = Pixels {
            raw: frame.as_raw(),
            width: frame.width() as usize,
            height: frame.height() as usize,
        };
        // The light on each square's middle against the rest frame's, and the frame's typical change: a change of light
        // that is even over the pattern (all LEDs alike, the exposure) changes no square's light against the others'.
        let light_ratio: Vec<Option<f64>> = self
            .squares
            .iter()
            .zip(measured)
            .map(|(model, m)| {
                let (at, _) = (*m)?;
                (model.reference_brightness > 0.0).then(|| {
                    mean_brightness(&px, at, model.cell(), CENTRE_HALF, self.stride) / model.reference_brightness
                })
            })
            .collect();
        let mut ratios: Vec<f64> = light_ratio.iter().flatten().copied().collect();
        let typical = if ratios.is_empty() { 1.0 } else { median(&mut ratios) };
        outlier
            .iter()
            .zip(&light_ratio)
            .map(|(&outlier, ratio)| outlier && ratio.is_some_and(|r| (r / typical - 1.0).abs() > LIGHT_CHANGE))
            .collect()
    }

    /// Where each square is expected: where it was last seen, else its reference position moved by the median
    /// motion of the squares that were seen.
    fn predictions(&self) -> Vec<Option<Point2>> {
        let mut dx = Vec::new();
        let mut dy = Vec::new();
        for (model, prev) in self.squares.iter().zip(&self.previous) {
            if let (Some(r), Some(p)) = (model.reference, prev) {
                dx.push(p[0] - r[0]);
                dy.push(p[1] - r[1]);
            }
        }
        let shift = if dx.is_empty() {
            [0.0, 0.0]
        } else {
            [median(&mut dx), median(&mut dy)]
        };
        self.squares
            .iter()
            .zip(&self.previous)
            .map(|(model, prev)| prev.or(model.reference.map(|r| [r[0] + shift[0], r[1] + shift[1]])))
            .collect()
    }

    /// Measures the lattice again when the camera jumped since the last frame or a found square slipped (a lost one
    /// does not count: see below): the lattice's rigid motion is a robust similarity of the raw image fitted on every
    /// square against its reference (a camera's roll is exactly that), so the squares still locked on correctly
    /// outvote those that slipped onto a neighbour, and every square is measured again from where that motion puts
    /// it. Windows started far from their square (a jump) may stop before they settle, or settle on a neighbour;
    /// started there, they settle where a frame of a still camera would. `None` when neither happened (the usual
    /// case, a damaged or partly covered pad included: one measurement per frame).
    fn relock(
        &mut self,
        frame: &RgbImage,
        measured: &[Option<(Point2, f64)>],
    ) -> Result<Option<Measurements>, EstimateError> {
        let pairs: Vec<(Point2, Point2)> = self
            .squares
            .iter()
            .zip(measured)
            .filter_map(|(model, m)| Some((model.reference?, m.as_ref()?.0)))
            .collect();
        let Some(motion) = crate::motion::fit_raw_similarity(&pairs) else {
            return Ok(None);
        };
        let last = std::mem::replace(&mut self.last_motion, motion);
        let expected: Vec<Option<Point2>> = self
            .squares
            .iter()
            .map(|m| m.reference.map(|r| motion.apply(r)))
            .collect();
        let cells =
            |a: Point2, b: Point2, model: &SquareModel| sub(a, b)[0].hypot(sub(a, b)[1]) / model.cell().min_step();
        let jumped = self
            .squares
            .iter()
            .zip(&expected)
            .any(|(model, e)| match (e, model.reference) {
                (Some(e), Some(r)) => cells(*e, last.apply(r), model) > JUMP_CELLS,
                _ => false,
            });
        // A square that is simply gone (ink lost, something covering it) slipped nowhere: measuring the others
        // again would not find it, and on a damaged pad would double every frame's cost. When a jump lost it, the
        // squares still found show the jump.
        let slipped = self
            .squares
            .iter()
            .zip(measured)
            .zip(&expected)
            .any(|((model, m), e)| match (m, e) {
                (Some((m, _)), Some(e)) => cells(*m, *e, model) > RELOCK_CELLS,
                _ => false,
            });
        if !(jumped || slipped) {
            return Ok(None);
        }
        let again = self.measure(frame, &expected, Some(&expected))?;
        let merged = measured
            .iter()
            .zip(again)
            .zip(self.squares.iter().zip(&expected))
            .map(|((first, second), (model, e))| match (first, second, e) {
                (_, Some(second), _) => Some(second),
                // Found only from afar, nowhere near the rigid motion: a neighbour, not this square.
                (Some((p, _)), None, Some(e)) if cells(*p, *e, model) > RELOCK_CELLS => None,
                (first, None, _) => *first,
            })
            .collect();
        Ok(Some(merged))
    }

    fn tracking_failed(&self, measured: &[Option<(Point2, f64)>], predicted: &[Option<Point2>]) -> bool {
        let expected = self.squares.iter().filter(|m| m.reference.is_some()).count().max(1);
        let found = measured.iter().filter(|m| m.is_some()).count();
        let lost_fraction = 1.0 - found as f64 / expected as f64;
        let mut moves: Vec<f64> = measured
            .iter()
            .zip(predicted)
            .zip(&self.squares)
            .filter_map(|((m, p), model)| {
                let (m, p) = (m.as_ref()?.0, (*p)?);
                Some(sub(m, p)[0].hypot(sub(m, p)[1]) / model.cell().min_step())
            })
            .collect();
        let median_move = if moves.is_empty() { 0.0 } else { median(&mut moves) };
        lost_fraction > self.thresholds.recovery_lost_fraction || median_move > 0.5
    }

    /// Gives the full search's squares the reference's indices: of the whole-lattice index offsets that keep the most
    /// of them on the pad, the one that puts them nearest to where the reference saw the same squares.
    ///
    /// Nearest alone is not enough: the yellow squares repeat one cell away diagonally, so a camera that moved more
    /// than half a cell along both axes since the reference (2 mm diagonally on the validation sensor) brings each
    /// square nearer the reference's next one, and every contact was then read a cell off (3.4-6.8 mm) with nothing
    /// to show for it but some 25 fewer corners. Where the full search saw the pattern from edge to edge its indices
    /// are the pad's own, and any other offset pushes a row or a column of squares off the pad; where it saw less,
    /// several offsets keep every square on it, and the reference decides among them as before.
    fn align_to_reference(&self, coarse: &[Option<Point2>]) -> Option<Vec<Option<Point2>>> {
        // `coarse` is indexed as if its first row/column were the pad's; try shifting it by whole cells.
        let (rows, cols) = (i32::from(self.pad.rows), i32::from(self.pad.cols));
        let slot_of = |r: i32, c: i32| -> Option<usize> {
            if r < 0 || c < 0 || r >= rows || c >= cols {
                return None;
            }
            let index = SquareIndex {
                row: r as u16,
                col: c as u16,
            };
            self.squares.binary_search_by_key(&index, |m| m.index).ok()
        };
        let mut best: Option<(f64, usize, i32, i32)> = None;
        for dr in -3..=3 {
            for dc in -3..=3 {
                if (dr + dc) % 2 != 0 {
                    continue;
                }
                let mut distances = Vec::new();
                let mut on_pad = 0;
                for (model, found) in self.squares.iter().zip(coarse) {
                    let (Some(p), Some(slot)) = (
                        found,
                        slot_of(i32::from(model.index.row) + dr, i32::from(model.index.col) + dc),
                    ) else {
                        continue;
                    };
                    on_pad += 1;
                    if let Some(r) = self.squares[slot].reference {
                        distances.push(sub(*p, r)[0].hypot(sub(*p, r)[1]));
                    }
                }
                if distances.len() < 4 {
                    continue;
                }
                let cost = median(&mut distances);
                if best.is_none_or(|(c, n, _, _)| on_pad > n || (on_pad == n && cost < c)) {
                    best = Some((cost, on_pad, dr, dc));
                }
            }
        }
        let (_, _, dr, dc) = best?;
        let mut aligned = vec![None; self.squares.len()];
        for (model, found) in self.squares.iter().zip(coarse) {
            if let Some(slot) = slot_of(i32::from(model.index.row) + dr, i32::from(model.index.col) + dc) {
                aligned[slot] = *found;
            }
        }
        Some(aligned)
    }

    /// Sub-pixel centroid and area of every square around its predicted position. A square whose window could
    /// not settle on it (lost, or caught between two squares after a large motion) is searched again where its
    /// lattice neighbours say it is, since the pattern moves smoothly.
    fn measure(
        &self,
        frame: &RgbImage,
        predicted: &[Option<Point2>],
        check_area: Option<&[Option<Point2>]>,
    ) -> Result<Measurements, EstimateError> {
        let (width, height) = frame.dimensions();
        if (width, height) != (self.width, self.height) {
            return Err(EstimateError::FrameSizeMismatch {
                expected_width: self.width,
                expected_height: self.height,
                found_width: width,
                found_height: height,
            });
        }
        let px = Pixels {
            raw: frame.as_raw(),
            width: width as usize,
            height: height as usize,
        };
        let mut histogram = Histogram::default();
        let (mut visited, mut clipped) = (0usize, 0usize);
        for (model, p) in self.squares.iter().zip(predicted) {
            if let Some(p) = p {
                let (v, c) = add_to_histogram(&px, *p, model.cell(), WINDOW_HALF, self.stride * 3, &mut histogram);
                visited += v;
                clipped += c;
            }
        }
        // Yellow may clip (its own pixels stay yellow against the red); once the red clips as well, most of the
        // pattern is one white and no centroid means anything.
        let clipped_fraction = clipped as f64 / visited.max(1) as f64;
        if clipped_fraction > MAX_CLIPPED_PATTERN_FRACTION {
            return Err(EstimateError::NoPattern {
                reason: format!(
                    "over-exposed: {:.0}% of the pattern's pixels are clipped white in every channel (at most {:.0}% \
                     can be measured), so yellow and red cannot be told apart; lower the exposure or the LED current",
                    clipped_fraction * 100.0,
                    MAX_CLIPPED_PATTERN_FRACTION * 100.0
                ),
            });
        }
        let Some(split) = otsu(&histogram).filter(|s| s.contrast() >= 8.0) else {
            return Err(EstimateError::NoPattern {
                reason: "no yellow/red contrast where the pattern should be".into(),
            });
        };
        let membership = Membership::from(split.ramp());
        let check_area = check_area.is_some();
        let outcomes: Vec<Option<SquareOutcome>> = self
            .squares
            .iter()
            .zip(predicted)
            .map(|(model, p)| p.map(|start| self.measure_square(&px, model, start, &membership, check_area)))
            .collect();
        let mut result: Measurements = outcomes
            .iter()
            .map(|o| match o {
                Some(SquareOutcome::Found(at, area)) => Some((*at, *area)),
                _ => None,
            })
            .collect();
        let retry: Vec<bool> = outcomes
            .iter()
            .map(|o| matches!(o, Some(SquareOutcome::Lost)))
            .collect();
        for _ in 0..NEIGHBOUR_ROUNDS {
            let mut progress = false;
            let snapshot = result.clone();
            for (slot, model) in self.squares.iter().enumerate() {
                if !retry[slot] || result[slot].is_some() {
                    continue;
                }
                let Some(start) = self.neighbour_prediction(slot, predicted, &snapshot) else {
                    continue;
                };
                if let SquareOutcome::Found(at, area) = self.measure_square(&px, model, start, &membership, check_area)
                {
                    result[slot] = Some((at, area));
                    progress = true;
                }
            }
            if !progress {
                break;
            }
        }
        if check_area && retry.iter().zip(&result).any(|(&lost, m)| lost && m.is_none()) {
            self.settle_large_moves(&px, &membership, &retry, &mut result);
        }
        Ok(result)
    }

    /// Squares a press moved much further than their neighbours predicted (a heavy press with shear moves the pad
    /// under it by two cells, its neighbours by one to one and a half): their windows, started where the rest of
    /// the lattice put them, either lose them (more than [`WINDOW_HALF`] from the start) or settle on a diagonal
    /// neighbour. The pad's motion is smooth on the scale of a cell, so continued from the neighbours' motion
    /// (`trend_prediction`) it puts a square within [`TREND_CELLS`] of where it is: a found square further than
    /// that is another square (it is dropped), and a lost square is searched again from there, and kept when it
    /// lands within that distance and on no square already found (within [`TAKEN_CELLS`]). Runs only when some
    /// square was lost (a damaged pad loses squares too, but its neighbours agree with each other: nothing is
    /// dropped there, and each lost square costs at most [`NEIGHBOUR_ROUNDS`] more windows).
    fn settle_large_moves(&self, px: &Pixels, membership: &Membership, lost: &[bool], result: &mut Measurements) {
        let mut search: Vec<bool> = lost.iter().zip(result.iter()).map(|(&l, m)| l && m.is_none()).collect();
        let snapshot = result.clone();
        for slot in 0..result.len() {
            let Some((at, _)) = snapshot[slot] else { continue };
            let Some(trend) = self.trend_prediction(slot, &snapshot) else {
                continue;
            };
            let miss = self.squares[slot].cell().to_cell(sub(at, trend));
            if miss[0].abs().max(miss[1].abs()) > TREND_CELLS {
                result[slot] = None;
                search[slot] = true;
            }
        }
        for _ in 0..NEIGHBOUR_ROUNDS {
            let snapshot = result.clone();
            let mut progress = false;
            for (slot, model) in self.squares.iter().enumerate() {
                if !search[slot] || result[slot].is_some() {
                    continue;
                }
                let Some(start) = self.trend_prediction(slot, &snapshot) else {
                    continue;
                };
                let SquareOutcome::Found(at, area) =
                    self.measure_square_within(px, model, start, membership, true, TREND_CELLS)
                else {
                    continue;
                };
                let taken = result.iter().flatten().any(|(other, _)| {
                    let gap = model.cell().to_cell(sub(*other, at));
                    gap[0].abs().max(gap[1].abs()) < TAKEN_CELLS
                });
                if !taken {
                    result[slot] = Some((at, area));
                    progress = true;
                }
            }
            if !progress {
                break;
            }
        }
    }

    /// Where a square is if the pad's motion continues smoothly into it from its nearest found lattice neighbours
    /// (the diagonal ones and those two cells along its row and column): along each of those eight directions, the
    /// motion of the neighbour one step away extrapolated linearly with the one two steps away (the neighbour's own
    /// motion alone when that one is not found), and the square's reference moved by the median of those. A
    /// straight extrapolation follows the motion up towards its peak under a press, where the neighbours' plain
    /// motion falls short of it. `None` with fewer than [`MIN_NEIGHBOURS`] directions.
    fn trend_prediction(&self, slot: usize, measured: &[Option<(Point2, f64)>]) -> Option<Point2> {
        let model = &self.squares[slot];
        let own = model.reference?;
        let (row, col) = (i32::from(model.index.row), i32::from(model.index.col));
        let motion = |steps: i32, (dr, dc): (i32, i32)| -> Option<Point2> {
            let (r, c) = (
                u16::try_from(row + steps * dr).ok()?,
                u16::try_from(col + steps * dc).ok()?,
            );
            let n = self
                .squares
                .binary_search_by_key(&SquareIndex { row: r, col: c }, |m| m.index)
                .ok()?;
            Some(sub(measured[n]?.0, self.squares[n].reference?))
        };
        let (mut dx, mut dy) = (Vec::with_capacity(8), Vec::with_capacity(8));
        for direction in [(-1, -1), (-1, 1), (1, -1), (1, 1), (0, -2), (0, 2), (-2, 0), (2, 0)] {
            let Some(near) = motion(1, direction) else { continue };
            let d = match motion(2, direction) {
                Some(far) => [2.0 * near[0] - far[0], 2.0 * near[1] - far[1]],
                None => near,
            };
            dx.push(d[0]);
            dy.push(d[1]);
        }
        if dx.len() < MIN_NEIGHBOURS {
            return None;
        }
        Some([own[0] + median(&mut dx), own[1] + median(&mut dy)])
    }

    /// One square's centroid from a window starting at `start` (raw px).
    fn measure_square(
        &self,
        px: &Pixels,
        model: &SquareModel,
        start: Point2,
        membership: &Membership,
        check_area: bool,
    ) -> SquareOutcome {
        self.measure_square_within(px, model, start, membership, check_area, WINDOW_HALF)
    }

    /// [`Self::measure_square`], accepting a centroid up to `reach` cells from `start`.
    fn measure_square_within(
        &self,
        px: &Pixels,
        model: &SquareModel,
        start: Point2,
        membership: &Membership,
        check_area: bool,
        reach: f64,
    ) -> SquareOutcome {
        // The window holds the whole square with room to spare, but a square that moved since the last frame may
        // be clipped by it: re-centre on the pixel nearest the centroid until that pixel stops changing. In a
        // steady scene that is one pass, and the result depends on the image alone.
        let mut centre = [start[0].round(), start[1].round()];
        let mut last = None;
        for _ in 0..MAX_PASSES {
            let Some(found) = centroid(px, centre, &model.window, self.stride, membership) else {
                return SquareOutcome::Lost;
            };
            let next = [found.at[0].round(), found.at[1].round()];
            let step = (next[0] - centre[0]).abs().max((next[1] - centre[1]).abs());
            last = Some((found, step));
            if step == 0.0 {
                break;
            }
            centre = next;
        }
        let Some((found, last_step)) = last else {
            return SquareOutcome::Lost;
        };
        // A window still travelling after the last pass was caught between two squares and is slowly leaving one
        // of them: its centroid is a blend of both.
        if last_step > 1.0 {
            return SquareOutcome::Lost;
        }
        if found.clipped_fraction > MAX_CLIPPED_FRACTION {
            return SquareOutcome::Clipped;
        }
        let offset = model.cell().to_cell(sub(found.at, start));
        if offset[0].abs() > reach || offset[1].abs() > reach {
            return SquareOutcome::Lost;
        }
        if mean_membership(px, found.at, model.cell(), CENTRE_HALF, self.stride, &membership.table)
            < MIN_CENTRE_MEMBERSHIP
        {
            return SquareOutcome::Lost;
        }
        if check_area && model.reference_area > 0.0 {
            let ratio = found.area / model.reference_area;
            if ratio < AREA_RATIO_RANGE.0 || ratio > AREA_RATIO_RANGE.1 {
                return SquareOutcome::Lost;
            }
        }
        SquareOutcome::Found(found.at, found.area)
    }

    /// Where a square is, judged by how far its measured lattice neighbours (up to two cells away) landed from
    /// their own predictions: the square's prediction moved by the median of those misses.
    fn neighbour_prediction(
        &self,
        slot: usize,
        predicted: &[Option<Point2>],
        measured: &[Option<(Point2, f64)>],
    ) -> Option<Point2> {
        let here = self.squares[slot].index;
        let own = predicted[slot]?;
        let (mut dx, mut dy) = (Vec::new(), Vec::new());
        for (other, (p, m)) in self.squares.iter().zip(predicted.iter().zip(measured)) {
            let (Some(p), Some((m, _))) = (p, m) else { continue };
            let near = other.index != here
                && i32::from(other.index.row).abs_diff(i32::from(here.row)) <= NEIGHBOUR_REACH
                && i32::from(other.index.col).abs_diff(i32::from(here.col)) <= NEIGHBOUR_REACH;
            if near {
                dx.push(m[0] - p[0]);
                dy.push(m[1] - p[1]);
            }
        }
        if dx.len() < MIN_NEIGHBOURS {
            return None;
        }
        let shift = [median(&mut dx), median(&mut dy)];
        Some([own[0] + shift[0], own[1] + shift[1]])
    }
}

/// How the search for one square ended.
#[derive(Clone, Copy, Debug, PartialEq)]
enum SquareOutcome {
    Found(Point2, f64),
    /// Not found where predicted (or not trusted): worth a search where its neighbours say it is.
    Lost,
    /// The window is clipped white: nothing to find in it, here or nearby.
    Clipped,
}

/// The element a sort would put in the middle (the upper one of an even count); reorders `values`.
pub(crate) fn median(values: &mut [f64]) -> f64 {
    *values.select_nth_unstable_by(values.len() / 2, f64::total_cmp).1
}

/// Full-frame search: coarse square centres by lattice index (row-major `yellow_squares` order). The absolute
/// index comes from the lattice's extent: the pad's rows and columns must all be seen for an unambiguous index;
/// with fewer, the found block is centred on the pad.
fn full_search(frame: &RgbImage, pad: &PadGeometry) -> Result<Vec<Option<Point2>>, EstimateError> {
    let factor = (frame.width() as usize / SEARCH_MAP_WIDTH).max(1);
    let map = YellownessMap::new(frame, factor);
    let Some((blobs, _)) = find_square_blobs(&map, pad.yellow_count()) else {
        return Err(EstimateError::NoPattern {
            reason: "no yellow squares in the frame".into(),
        });
    };
    let points: Vec<Point2> = blobs.iter().map(|b| b.centre).collect();
    let Some(indexed) = index_lattice(&points) else {
        return Err(EstimateError::NoPattern {
            reason: "the yellow blobs do not form a checkerboard lattice".into(),
        });
    };
    let reached: Vec<(usize, indexing::RelativeIndex)> = indexed
        .indices
        .iter()
        .enumerate()
        .filter_map(|(i, x)| x.map(|x| (i, x)))
        .collect();
    let needed = pad.yellow_count().div_ceil(2);
    if reached.len() < needed {
        return Err(EstimateError::TooFewPoints {
            found: reached.len(),
            needed,
        });
    }
    let (min_r, max_r) = reached
        .iter()
        .fold((i32::MAX, i32::MIN), |(a, b), (_, x)| (a.min(x.row), b.max(x.row)));
    let (min_c, max_c) = reached
        .iter()
        .fold((i32::MAX, i32::MIN), |(a, b), (_, x)| (a.min(x.col), b.max(x.col)));
    let (rows, cols) = (i32::from(pad.rows), i32::from(pad.cols));
    if max_r - min_r >= rows || max_c - min_c >= cols {
        return Err(EstimateError::NoPattern {
            reason: format!(
                "the lattice found spans {} x {} cells, more than the pad's {} x {}",
                max_r - min_r + 1,
                max_c - min_c + 1,
                rows,
                cols
            ),
        });
    }
    let mut row_offset = -min_r + (rows - 1 - (max_r - min_r)) / 2;
    let mut col_offset = -min_c + (cols - 1 - (max_c - min_c)) / 2;
    // The seed square is yellow, so its absolute index must have the parity of a yellow cell.
    let seed_yellow = pad.is_yellow(SquareIndex {
        row: row_offset.rem_euclid(2) as u16,
        col: col_offset.rem_euclid(2) as u16,
    });
    if !seed_yellow {
        if max_c - min_c < cols - 1 {
            col_offset += if col_offset + max_c < cols - 1 { 1 } else { -1 };
        } else if max_r - min_r < rows - 1 {
            row_offset += if row_offset + max_r < rows - 1 { 1 } else { -1 };
        } else {
            return Err(EstimateError::NoPattern {
                reason: "the lattice's corner squares are not where the pad's yellow squares are".into(),
            });
        }
    }
    let mut squares = vec![None; pad.yellow_count()];
    let slots: Vec<SquareIndex> = pad.yellow_squares().collect();
    for (i, x) in reached {
        let (r, c) = (x.row + row_offset, x.col + col_offset);
        if r < 0 || c < 0 || r >= rows || c >= cols {
            continue;
        }
        if let Ok(slot) = slots.binary_search(&SquareIndex {
            row: r as u16,
            col: c as u16,
        }) {
            squares[slot] = Some(points[i]);
        }
    }
    Ok(squares)
}

/// Local column and row steps at every square, from its found neighbours (two cells away along a row or a
/// column, or one diagonal step), falling back to the lattice-wide median.
fn local_cells(pad: &PadGeometry, squares: &[Option<Point2>]) -> Result<Vec<Option<CellFrame>>, EstimateError> {
    let slots: Vec<SquareIndex> = pad.yellow_squares().collect();
    let at = |r: i32, c: i32| -> Option<Point2> {
        if r < 0 || c < 0 {
            return None;
        }
        let slot = slots
            .binary_search(&SquareIndex {
                row: r as u16,
                col: c as u16,
            })
            .ok()?;
        squares[slot]
    };
    let mean = |vs: &[Point2]| -> Option<Point2> {
        (!vs.is_empty()).then(|| {
            let n = vs.len() as f64;
            [
                vs.iter().map(|v| v[0]).sum::<f64>() / n,
                vs.iter().map(|v| v[1]).sum::<f64>() / n,
            ]
        })
    };
    // Diagonal neighbours: one column step plus (down-right) or minus (up-right) one row step.
    let steps = |r: i32, c: i32| -> (Option<Point2>, Option<Point2>) {
        let Some(here) = at(r, c) else { return (None, None) };
        let mut down_right = Vec::new();
        let mut up_right = Vec::new();
        if let Some(n) = at(r + 1, c + 1) {
            down_right.push(sub(n, here));
        }
        if let Some(n) = at(r - 1, c - 1) {
            down_right.push(sub(here, n));
        }
        if let Some(n) = at(r - 1, c + 1) {
            up_right.push(sub(n, here));
        }
        if let Some(n) = at(r + 1, c - 1) {
            up_right.push(sub(here, n));
        }
        match (mean(&down_right), mean(&up_right)) {
            (Some(d), Some(u)) => (Some(lerp_mid(d, u)), Some([(d[0] - u[0]) / 2.0, (d[1] - u[1]) / 2.0])),
            _ => (None, None),
        }
    };
    let local: Vec<Option<CellFrame>> = slots
        .iter()
        .map(|s| match steps(i32::from(s.row), i32::from(s.col)) {
            (Some(c), Some(r)) => CellFrame::new(c, r),
            _ => None,
        })
        .collect();
    let valid: Vec<&CellFrame> = local.iter().flatten().collect();
    if valid.is_empty() {
        return Err(EstimateError::NoPattern {
            reason: "no square has lattice neighbours".into(),
        });
    }
    let mut cx: Vec<f64> = valid.iter().map(|c| c.col_step[0]).collect();
    let mut cy: Vec<f64> = valid.iter().map(|c| c.col_step[1]).collect();
    let mut rx: Vec<f64> = valid.iter().map(|c| c.row_step[0]).collect();
    let mut ry: Vec<f64> = valid.iter().map(|c| c.row_step[1]).collect();
    let fallback = CellFrame::new([median(&mut cx), median(&mut cy)], [median(&mut rx), median(&mut ry)]);
    Ok(local.into_iter().map(|c| c.or(fallback)).collect())
}

/// Interior corners from the yellow squares: the midpoint of the two yellow cells of each corner's 2 x 2 block.
pub fn corners_from_squares(pad: &PadGeometry, squares: &[Option<Point2>]) -> Vec<Option<Point2>> {
    let slots: Vec<SquareIndex> = pad.yellow_squares().collect();
    let at = |square: SquareIndex| -> Option<Point2> {
        let slot = slots.binary_search(&square).ok()?;
        squares.get(slot).copied().flatten()
    };
    pad.corners()
        .map(|corner| {
            let [a, b] = pad.corner_squares(corner);
            Some(lerp_mid(at(a)?, at(b)?))
        })
        .collect()
}
