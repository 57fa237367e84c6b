//! The estimator: a rest frame found once, then every frame measured against it, stage by stage
//! (detection -> registration -> surface and gamma -> force -> contact -> edge). Only detection differs between
//! the modes; everything after it is shared.

use std::str::FromStr;
use std::time::Instant;

use image::RgbImage;
use nusense_geometry::{CornerIndex, Point2};
use serde::{Deserialize, Serialize};

use crate::config::SensorConfig;
use crate::contact::{divergence_centre, fit_affine_motion, norm, AffineMotion, FieldPoint};
use crate::detection::FastTracker;
use crate::edge::{edge_direction, EdgeEstimate};
use crate::error::EstimateError;
use crate::force::force;
use crate::lattice::{CornerObservation, Lattice, SquareObservation};
use crate::pad_map::{camera_for, PadMapping};
use crate::paper::PaperDetector;
use crate::registration::{register, Registration};
use crate::shear::{gamma, ShearSampler};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Our pipeline: colour, topology and tracking; points undistorted, never pixels.
    Fast,
    /// The sensor authors' published pipeline and parameters.
    Paper,
}

impl FromStr for Mode {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "fast" => Ok(Self::Fast),
            "paper" => Ok(Self::Paper),
            other => Err(format!("unknown mode `{other}`; allowed: fast, paper")),
        }
    }
}

impl std::fmt::Display for Mode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Fast => "fast",
            Self::Paper => "paper",
        })
    }
}

/// One lattice corner's motion.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ShearVector {
    pub index: CornerIndex,
    pub reference_px: Option<Point2>,
    pub current_px: Option<Point2>,
    /// Motion on the pad since the reference, mm; `None` when either frame missed the corner.
    pub displacement_mm: Option<Point2>,
    /// Seen in both frames with a plausible motion (only valid corners enter the surface).
    pub valid: bool,
}

#[derive(Clone, Debug, Serialize)]
pub struct Reading {
    pub contact: bool,
    pub contact_px: Option<[f64; 2]>,
    pub contact_undistorted_px: Option<[f64; 2]>,
    pub contact_mm: Option<[f64; 2]>,
    /// alpha * sum ||s - s_ref|| over `samples_used` samples, in paper px (see `pad_map`).
    pub gamma: f64,
    /// 0 without contact, else a * gamma + b as it is (see `force`).
    pub force_n: f64,
    /// a * gamma + b whether or not there is contact.
    pub force_model_n: f64,
    pub edge_angle_deg: Option<f64>,
    pub edge_confidence: f64,
    /// Corners found in this frame.
    pub points_detected: usize,
    pub points_expected: usize,
    pub squares_detected: usize,
    pub squares_expected: usize,
    /// Corners seen in both frames with a plausible motion.
    pub points_valid: usize,
    /// Corners seen in both frames but masked as implausible.
    pub points_implausible: usize,
    pub samples_used: usize,
    pub samples_total: usize,
    /// Third-largest local (non-affine) corner shear, mm: the contact decision's statistic.
    pub contact_score_mm: f64,
    /// The fast tracker had to search the whole frame again.
    pub recovered: bool,
    pub shear_field: Vec<ShearVector>,
    pub elapsed_ms: f64,
}

struct FrameLattice {
    lattice: Lattice,
    /// Squares the detector found (paper mode: quadrilaterals accepted, indexed or not).
    squares_found: usize,
    recovered: bool,
}

enum Detector {
    Fast(FastTracker),
    Paper(Box<PaperDetector>),
}

pub struct Estimator {
    config: SensorConfig,
    mode: Mode,
    detector: Detector,
    mapping: PadMapping,
    reference: Lattice,
    reference_paper_px: Vec<Point2>,
    sampler: ShearSampler,
}

/// A contact moves many corners; one mis-tracked square moves at most a few (an edge square two). The contact
/// statistic is the residual shear of the corner ranked this high.
const CONTACT_SUPPORT: usize = 3;

/// An edge direction needs at least this fraction of the corners around the sheared region.
const MIN_EDGE_COVERAGE: f64 = 0.9;

/// Fewer valid corners than this fraction of the lattice is not a measurement.
const MIN_VALID_FRACTION: f64 = 0.25;

impl Estimator {
    /// Finds the lattice in the rest frame once; frames are then measured against it.
    pub fn new(config: SensorConfig, mode: Mode, reference: &RgbImage) -> Result<Self, EstimateError> {
        config.validate()?;
        let (width, height) = reference.dimensions();
        let pad = config.pad;
        let (detector, squares, corners) = match mode {
            Mode::Fast => {
                let (tracker, detection) = FastTracker::from_reference(reference, pad, config.thresholds)?;
                (Detector::Fast(tracker), detection.squares, detection.corners)
            }
            Mode::Paper => {
                let detector = PaperDetector::new(&config, width, height)?;
                let (squares, corners, _) = paper_points(&detector, reference, &config)?;
                (Detector::Paper(Box::new(detector)), squares, corners)
            }
        };
        let camera = camera_for(&config, width, height)?;
        let undistorted: Vec<Option<Point2>> =
            corners.iter().map(|c| c.and_then(|p| camera.undistort_px(p))).collect();
        let mapping = PadMapping::new(camera, &pad, &undistorted)?;
        let reference = build_lattice(&config, &mapping, squares, &corners);
        let needed = min_valid(&config);
        if reference.corners_found() < needed {
            return Err(EstimateError::TooFewPoints { found: reference.corners_found(), needed });
        }
        let reference_paper_px: Vec<Point2> = reference
            .corners
            .iter()
            .map(|c| c.undistorted_px.map(|p| mapping.to_paper(p)).unwrap_or([0.0, 0.0]))
            .collect();
        let reference_valid: Vec<bool> = reference.corners.iter().map(|c| c.undistorted_px.is_some()).collect();
        let sampler = ShearSampler::new(
            usize::from(pad.corner_rows()),
            usize::from(pad.corner_cols()),
            &config.surface,
            &reference_paper_px,
            &reference_valid,
        )?;
        Ok(Self { config, mode, detector, mapping, reference, reference_paper_px, sampler })
    }

    pub fn reference_lattice(&self) -> &Lattice {
        &self.reference
    }

    pub fn config(&self) -> &SensorConfig {
        &self.config
    }

    pub fn mode(&self) -> Mode {
        self.mode
    }

    pub fn mapping(&self) -> &PadMapping {
        &self.mapping
    }

    /// The lattice of a frame (detection only: no registration against the reference).
    pub fn detect(&mut self, frame: &RgbImage) -> Result<Lattice, EstimateError> {
        Ok(self.detect_frame(frame)?.lattice)
    }

    fn detect_frame(&mut self, frame: &RgbImage) -> Result<FrameLattice, EstimateError> {
        let (squares, corners, squares_found, recovered) = match &mut self.detector {
            Detector::Fast(tracker) => {
                let d = tracker.track(frame)?;
                let found = d.squares.iter().filter(|s| s.is_some()).count();
                (d.squares, d.corners, found, d.recovered)
            }
            Detector::Paper(detector) => {
                let (squares, corners, quads) = paper_points(detector, frame, &self.config)?;
                (squares, corners, quads, false)
            }
        };
        let lattice = build_lattice(&self.config, &self.mapping, squares, &corners);
        Ok(FrameLattice { lattice, squares_found, recovered })
    }

    pub fn estimate(&mut self, frame: &RgbImage) -> Result<Reading, EstimateError> {
        let started = Instant::now();
        let (width, height) = frame.dimensions();
        let (expected_width, expected_height) = (self.mapping.camera().width(), self.mapping.camera().height());
        if (width, height) != (expected_width, expected_height) {
            return Err(EstimateError::FrameSizeMismatch {
                expected_width,
                expected_height,
                found_width: width,
                found_height: height,
            });
        }
        let FrameLattice { lattice, squares_found, recovered } = self.detect_frame(frame)?;
        let registration = register(&self.reference, &lattice, self.config.thresholds.max_displacement_cells);
        let needed = min_valid(&self.config);
        if registration.valid_count() < needed {
            return Err(EstimateError::TooFewPoints { found: registration.valid_count(), needed });
        }
        let mut reading = self.measure(&lattice, &registration)?;
        reading.recovered = recovered;
        reading.squares_detected = squares_found;
        reading.elapsed_ms = started.elapsed().as_secs_f64() * 1e3;
        Ok(reading)
    }

    /// Everything after detection: surfaces, gamma, force, contact, edge.
    fn measure(&self, lattice: &Lattice, registration: &Registration) -> Result<Reading, EstimateError> {
        let valid: Vec<bool> = registration.corners.iter().map(|c| c.valid).collect();
        let current_paper_px: Vec<Point2> = lattice
            .corners
            .iter()
            .zip(&valid)
            .map(|(c, &ok)| if ok { c.undistorted_px.map(|p| self.mapping.to_paper(p)) } else { None })
            .map(|p| p.unwrap_or([0.0, 0.0]))
            .collect();
        let samples = self.sampler.sample(&current_paper_px, &valid)?;
        let gamma = gamma(&samples, self.config.calibration.alpha);

        // Contact: the local shear field after removing the pad's overall (affine) motion.
        let field: Vec<FieldPoint> = valid
            .iter()
            .enumerate()
            .filter(|(_, &ok)| ok)
            .map(|(i, _)| FieldPoint {
                position: self.reference_paper_px[i],
                displacement: sub(current_paper_px[i], self.reference_paper_px[i]),
            })
            .collect();
        let motion = fit_affine_motion(&field).unwrap_or(AffineMotion::ZERO);
        let residuals: Vec<Point2> = field.iter().map(|p| motion.residual(p)).collect();
        let mut residual_mm: Vec<f64> = field
            .iter()
            .zip(&residuals)
            .map(|(p, r)| self.paper_shift_to_mm(p.position, *r).unwrap_or(0.0))
            .collect();
        residual_mm.sort_unstable_by(|a, b| b.total_cmp(a));
        let contact_score_mm = residual_mm.get(CONTACT_SUPPORT - 1).copied().unwrap_or(0.0);
        let contact = contact_score_mm > self.config.thresholds.contact_shear_mm;

        let (mut contact_px, mut contact_undistorted_px, mut contact_mm) = (None, None, None);
        let mut edge = EdgeEstimate::NONE;
        if contact {
            if let Some(centre) = divergence_centre(&field, &residuals) {
                let undistorted = self.mapping.from_paper(centre);
                contact_undistorted_px = Some(undistorted);
                contact_px = self.mapping.distort(undistorted);
                contact_mm = self.mapping.undistorted_to_mm(undistorted);
            }
            let sheared: Vec<(Point2, f64)> = self
                .sampler
                .reference_samples()
                .iter()
                .zip(&samples.displacement)
                .zip(&samples.valid)
                .filter(|(_, &ok)| ok)
                .filter_map(|((&at, &d), _)| {
                    let local = norm(sub(d, motion.predict(at)));
                    let mm = self.mapping.undistorted_to_mm(self.mapping.from_paper(at))?;
                    Some((mm, local))
                })
                .collect();
            let thresholds = &self.config.thresholds;
            edge = edge_direction(&sheared, thresholds.edge_sample_fraction, thresholds.edge_min_confidence);
            let coverage = self.coverage(&registration.corners, edge.region_centre_mm, edge.region_radius_mm);
            edge = edge.with_coverage(coverage, MIN_EDGE_COVERAGE, thresholds.edge_min_confidence);
        }
        let force = force(&self.config.calibration, gamma, contact);
        let shear_field = registration
            .corners
            .iter()
            .map(|c| ShearVector {
                index: c.index,
                reference_px: c.reference_raw,
                current_px: c.current_raw,
                displacement_mm: c.displacement_mm,
                valid: c.valid,
            })
            .collect();
        let reading = Reading {
            contact,
            contact_px,
            contact_undistorted_px,
            contact_mm,
            gamma,
            force_n: force.force_n,
            force_model_n: force.model_n,
            edge_angle_deg: edge.angle_deg,
            edge_confidence: edge.confidence,
            points_detected: lattice.corners_found(),
            points_expected: self.config.pad.corner_count(),
            squares_detected: lattice.squares_found(),
            squares_expected: self.config.pad.yellow_count(),
            points_valid: registration.valid_count(),
            points_implausible: registration.implausible,
            samples_used: samples.used(),
            samples_total: samples.total(),
            contact_score_mm,
            recovered: false,
            shear_field,
            elapsed_ms: 0.0,
        };
        if !reading_is_finite(&reading) {
            return Err(EstimateError::NoPattern { reason: "the measurement is not finite (degenerate lattice)".into() });
        }
        Ok(reading)
    }

    /// Fraction of the corners within `radius_mm` (plus one cell) of `centre_mm` that are valid, judged on the
    /// pad's nominal corner positions so that missing corners count too.
    fn coverage(&self, corners: &[crate::registration::RegisteredCorner], centre_mm: Point2, radius_mm: f64) -> f64 {
        let pad = &self.config.pad;
        let reach = radius_mm + pad.pitch_x_mm().max(pad.pitch_y_mm());
        let (mut seen, mut all) = (0usize, 0usize);
        for corner in corners {
            let at = pad.corner_mm(corner.index);
            if (at[0] - centre_mm[0]).hypot(at[1] - centre_mm[1]) <= reach {
                all += 1;
                seen += usize::from(corner.valid);
            }
        }
        if all == 0 {
            0.0
        } else {
            seen as f64 / all as f64
        }
    }

    /// Length in mm of a shift `d` (paper px) at `at` (paper px).
    fn paper_shift_to_mm(&self, at: Point2, d: Point2) -> Option<f64> {
        let a = self.mapping.undistorted_to_mm(self.mapping.from_paper(at))?;
        let b = self.mapping.undistorted_to_mm(self.mapping.from_paper([at[0] + d[0], at[1] + d[1]]))?;
        Some(norm(sub(b, a)))
    }
}

fn sub(a: Point2, b: Point2) -> Point2 {
    [a[0] - b[0], a[1] - b[1]]
}

fn min_valid(config: &SensorConfig) -> usize {
    ((config.pad.corner_count() as f64 * MIN_VALID_FRACTION).ceil() as usize).max(8)
}

fn finite(p: &Option<Point2>) -> bool {
    p.is_none_or(|p| p[0].is_finite() && p[1].is_finite())
}

fn reading_is_finite(r: &Reading) -> bool {
    r.gamma.is_finite()
        && r.force_n.is_finite()
        && r.force_model_n.is_finite()
        && r.edge_confidence.is_finite()
        && r.contact_score_mm.is_finite()
        && r.edge_angle_deg.is_none_or(f64::is_finite)
        && finite(&r.contact_px)
        && finite(&r.contact_undistorted_px)
        && finite(&r.contact_mm)
        && r.shear_field.iter().all(|s| finite(&s.reference_px) && finite(&s.current_px) && finite(&s.displacement_mm))
}

/// Squares and corners (raw px, by slot) from the published pipeline, and its count of quadrilaterals.
#[allow(clippy::type_complexity)]
fn paper_points(
    detector: &PaperDetector,
    frame: &RgbImage,
    config: &SensorConfig,
) -> Result<(Vec<Option<Point2>>, Vec<Option<Point2>>, usize), EstimateError> {
    let detection = detector.detect(frame)?;
    let pad = &config.pad;
    let mut corners = vec![None; pad.corner_count()];
    for p in &detection.points {
        if p.index.row < pad.corner_rows() && p.index.col < pad.corner_cols() {
            corners[pad.corner_slot(p.index)] = Some(p.raw_px);
        }
    }
    let slots: Vec<_> = pad.yellow_squares().collect();
    let mut squares = vec![None; slots.len()];
    for s in &detection.squares {
        if let Some(slot) = s.index.and_then(|i| slots.binary_search(&i).ok()) {
            squares[slot] = Some(s.centre_raw_px);
        }
    }
    Ok((squares, corners, detection.squares_found))
}

fn build_lattice(
    config: &SensorConfig,
    mapping: &PadMapping,
    squares: Vec<Option<Point2>>,
    corners: &[Option<Point2>],
) -> Lattice {
    let pad = config.pad;
    let squares = pad
        .yellow_squares()
        .zip(squares)
        .map(|(index, raw_px)| SquareObservation { index, raw_px })
        .collect();
    let corners = pad
        .corners()
        .zip(corners)
        .map(|(index, &raw_px)| {
            let undistorted_px = raw_px.and_then(|p| mapping.undistort(p));
            let mm = undistorted_px.and_then(|p| mapping.undistorted_to_mm(p));
            // A corner is found only if it makes it through every frame: raw, undistorted and pad.
            let found = mm.is_some();
            CornerObservation {
                index,
                raw_px: raw_px.filter(|_| found),
                undistorted_px: undistorted_px.filter(|_| found),
                mm,
            }
        })
        .collect();
    Lattice { pad, squares, corners }
}
