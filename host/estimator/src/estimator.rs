//! The estimator: a rest frame found once, then every frame measured against it, stage by stage:
//! detection -> registration by lattice index -> displacements in pad mm -> camera motion fitted jointly with the
//! tractions and removed -> the contact test -> the mode's outputs (the traction inverse's force vector, contacts
//! and pressure map, or the paper's gamma line) -> gamma for comparison. Modes differ in detection (`paper`) and
//! in what turns the compensated displacements into force, location and edge (`fast`, `paper`: the paper's gamma
//! line and shear field; `inverse`: the traction map); motion removal and the contact test are shared.

use std::str::FromStr;
use std::sync::Arc;
use std::time::Instant;

use image::RgbImage;
use nusense_geometry::Point2;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::config::{ObservedPoints, SensorConfig};
use crate::contact::{divergence_centre, fit_affine_motion, norm, AffineMotion, FieldPoint};
use crate::detection::{corners_from_squares, median, FastTracker, MAD_TO_SIGMA};
use crate::edge::{edge_direction, EdgeEstimate};
use crate::error::EstimateError;
use crate::force::force;
use crate::homography::Homography;
use crate::inverse::{InverseModel, Stage1, Stage2, TestOutcome, MOTION_PARAMETERS};
use crate::lattice::{CornerObservation, Lattice, SquareObservation};
use crate::motion::camera_motion;
use crate::pad_map::{camera_for, PadMapping};
use crate::paper::PaperDetector;
use crate::reading::{
    CameraMotion, ContactRegion, ContactTest, EdgeReading, GammaReading, LatticeCounts, PressureMap, Reading,
    ShearVector, Touch,
};
use crate::registration::{register, register_squares, Registration};
use crate::shear::{gamma, ShearSampler, ShearSamples};

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Fast detection; force from the paper's gamma line, location from the shear field.
    Fast,
    /// The sensor authors' published detection and force line.
    Paper,
    /// Fast detection and the traction inverse: force vector, torque, every contact, pressure map. The default:
    /// on the validation set (docs/benchmarks/validation-*.md) it is ahead of `fast` on every accuracy figure and
    /// detects as light a press as `fast` does, round, flat or a long edge (docs/benchmarks/validation-quick.md).
    #[default]
    Inverse,
}

impl Mode {
    pub const ALL: [Self; 3] = [Self::Fast, Self::Paper, Self::Inverse];
}

impl FromStr for Mode {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "fast" => Ok(Self::Fast),
            "paper" => Ok(Self::Paper),
            "inverse" => Ok(Self::Inverse),
            other => Err(format!("unknown mode `{other}`; allowed: fast, paper, inverse")),
        }
    }
}

impl std::fmt::Display for Mode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Fast => "fast",
            Self::Paper => "paper",
            Self::Inverse => "inverse",
        })
    }
}

struct FrameLattice {
    lattice: Lattice,
    /// Squares the detector found (paper mode: quadrilaterals accepted, indexed or not).
    squares_found: usize,
    recovered: bool,
    /// Per observed point (the model's: `inverse.observe`): a square seen under another light than in the rest frame
    /// (the camera moved, or the LEDs changed unevenly: see [`crate::detection::Detection::relit`]), or a corner built
    /// from one; the contact test leaves these points out.
    relit: Vec<bool>,
}

enum Detector {
    Fast(FastTracker),
    Paper(Box<PaperDetector>),
}

/// The rest frame as the measurement sees it.
struct Rest {
    lattice: Lattice,
    mapping: PadMapping,
    /// Each corner in pad mm (nominal grid position where the rest frame missed it).
    corners_mm: Vec<Point2>,
    /// The model's observed points (`inverse.observe`: the corners, or the yellow squares) in pad mm, where the rest
    /// frame found them; `points_mm` has the nominal position where it did not.
    points_found_mm: Vec<Option<Point2>>,
    points_mm: Vec<Point2>,
    /// Each of `corners_mm` in raw px (`None` outside the camera's view): where motion removal starts from.
    corners_raw: Vec<Option<Point2>>,
    /// The pad's centre in raw px: the camera motion is reported about it.
    centre_raw: Option<Point2>,
    /// Each corner in paper px (zero where missed; masked by validity).
    paper_px: Vec<Point2>,
    sampler: ShearSampler,
    /// The least noise the contact test assumes, mm (`inverse.noise_floor_mm`).
    noise_floor_mm: f64,
    /// The least noise stage 2 of the inverse assumes when it picks the loaded cells, mm (`inverse.support_floor_px`
    /// on this map, and `noise_floor_mm`).
    support_floor_mm: f64,
    /// The gamma (camera motion removed) of a 1 N press at the pad's centre as the pad model sees it, noise-free: the
    /// press the contact test's detection floor is stated for, so the floor press's gamma is the floor times this (see
    /// [`Estimator::line_touch`]).
    gamma_per_n: f64,
    /// Per observed point: moved by a change of light alone (see [`Estimator::light_sensitive_points`]); the contact
    /// test leaves these points out.
    light_sensitive: Vec<bool>,
}

pub struct Estimator {
    config: SensorConfig,
    mode: Mode,
    detector: Detector,
    rest: Rest,
    model: Arc<InverseModel>,
    /// Consecutive frames with motion and without contact.
    moved_frames: u32,
    retare_count: u64,
}

/// Fewer valid corners than this fraction of the lattice is not a measurement.
const MIN_VALID_FRACTION: f64 = 0.25;
/// ...and never fewer than the motion model has parameters (with room to judge them).
const MIN_VALID_CORNERS: usize = 2 * MOTION_PARAMETERS;
/// A contact moves many corners; one mis-tracked square moves at most a few (an edge square two). The contact
/// score is the local shear of the corner ranked this high.
const CONTACT_SUPPORT: usize = 3;
/// The published (paper) detector's corners further than this many cells from their rest position are masked as
/// implausible, whatever `thresholds.max_displacement_cells` allows the tracker (see `Estimator::estimate`).
const PAPER_MAX_DISPLACEMENT_CELLS: f64 = 1.5;
/// An edge direction (fast and paper modes) needs at least this fraction of the corners around the sheared region.
const MIN_EDGE_COVERAGE: f64 = 0.9;

/// Cells around the rest lattice's squares that later frames may need: room for the pad's motion under a press
/// and for the tracker's windows (0.55 cell around each square).
pub const PATTERN_REGION_MARGIN_CELLS: f64 = 1.5;

impl Estimator {
    /// Finds the lattice in the rest frame once; frames are then measured against it.
    pub fn new(config: SensorConfig, mode: Mode, reference: &RgbImage) -> Result<Self, EstimateError> {
        config.validate()?;
        let (width, height) = reference.dimensions();
        let pad = config.pad;
        let (detector, squares, corners) = match mode {
            Mode::Fast | Mode::Inverse => {
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
        let (rest, model) = Rest::new(&config, camera, squares, &corners)?;
        let mut estimator = Self {
            config,
            mode,
            detector,
            rest,
            model,
            moved_frames: 0,
            retare_count: 0,
        };
        estimator.rest.light_sensitive = estimator.light_sensitive_points(reference);
        Ok(estimator)
    }

    pub fn reference_lattice(&self) -> &Lattice {
        &self.rest.lattice
    }

    /// The part of later frames the fast tracker reads, px of the rest frame (min, max): the rest lattice's box
    /// grown by [`PATTERN_REGION_MARGIN_CELLS`]. Decoding only this part of a frame gives the same reading
    /// (`nusense bench` measures the difference). `None` when the rest lattice is too sparse to say.
    pub fn pattern_region_px(&self) -> Option<(Point2, Point2)> {
        self.rest.lattice.region_px(PATTERN_REGION_MARGIN_CELLS)
    }

    pub fn config(&self) -> &SensorConfig {
        &self.config
    }

    pub fn mode(&self) -> Mode {
        self.mode
    }

    pub fn mapping(&self) -> &PadMapping {
        &self.rest.mapping
    }

    /// Re-tares since the estimator was built (persistent motion without contact; see `RetareConfig`).
    pub fn retare_count(&self) -> u64 {
        self.retare_count
    }

    pub fn inverse_model(&self) -> &InverseModel {
        &self.model
    }

    /// The lattice of a frame (detection only: no registration against the reference).
    pub fn detect(&mut self, frame: &RgbImage) -> Result<Lattice, EstimateError> {
        Ok(self.detect_frame(frame)?.lattice)
    }

    fn detect_frame(&mut self, frame: &RgbImage) -> Result<FrameLattice, EstimateError> {
        let pad = self.config.pad;
        let observe = self.config.inverse.observe;
        let (squares, corners, squares_found, recovered, relit) = match &mut self.detector {
            Detector::Fast(tracker) => {
                let d = tracker.track(frame)?;
                let found = d.squares.iter().filter(|s| s.is_some()).count();
                let relit = match observe {
                    ObservedPoints::Squares => d.relit.clone(),
                    ObservedPoints::Corners => {
                        // A corner is the midpoint of two squares: without the relit ones, those it loses are relit.
                        let trusted: Vec<Option<Point2>> = d
                            .squares
                            .iter()
                            .zip(&d.relit)
                            .map(|(s, &relit)| s.filter(|_| !relit))
                            .collect();
                        corners_from_squares(&pad, &trusted)
                            .iter()
                            .zip(&d.corners)
                            .map(|(trusted, found)| trusted.is_none() && found.is_some())
                            .collect()
                    }
                };
                (d.squares, d.corners, found, d.recovered, relit)
            }
            Detector::Paper(detector) => {
                let (squares, corners, quads) = paper_points(detector, frame, &self.config)?;
                let points = match observe {
                    ObservedPoints::Squares => squares.len(),
                    ObservedPoints::Corners => corners.len(),
                };
                (squares, corners, quads, false, vec![false; points])
            }
        };
        let lattice = build_lattice(&self.config, &self.rest.mapping, squares, &corners);
        Ok(FrameLattice {
            lattice,
            squares_found,
            recovered,
            relit,
        })
    }

    pub fn estimate(&mut self, frame: &RgbImage) -> Result<Reading, EstimateError> {
        let started = Instant::now();
        let (width, height) = frame.dimensions();
        let camera = self.rest.mapping.camera();
        let (expected_width, expected_height) = (camera.width(), camera.height());
        if (width, height) != (expected_width, expected_height) {
            return Err(EstimateError::FrameSizeMismatch {
                expected_width,
                expected_height,
                found_width: width,
                found_height: height,
            });
        }
        let FrameLattice {
            lattice,
            squares_found,
            recovered,
            relit,
        } = self.detect_frame(frame)?;
        // The tracker carries each square's identity from frame to frame, so a corner it finds 2.5 cells away has
        // moved that far (a heavy press). The published detector indexes every frame's lattice afresh: when the
        // camera has moved, a corner it puts more than PAPER_MAX_DISPLACEMENT_CELLS away is more likely given
        // another square's index than moved (allowed to 2.5 cells, it measured six more camera-moved frames of the
        // full validation set, each with its rotation wrong by up to 4 deg).
        let max_displacement_cells = match self.mode {
            Mode::Paper => self
                .config
                .thresholds
                .max_displacement_cells
                .min(PAPER_MAX_DISPLACEMENT_CELLS),
            Mode::Fast | Mode::Inverse => self.config.thresholds.max_displacement_cells,
        };
        let registration = register(&self.rest.lattice, &lattice, max_displacement_cells);
        let needed = min_valid(&self.config);
        if registration.valid_count() < needed {
            return Err(EstimateError::TooFewPoints {
                found: registration.valid_count(),
                needed,
            });
        }
        let points = self.observed_points(&lattice, &registration, max_displacement_cells, relit);
        let (mut reading, moved_mm) = self.measure(&lattice, &registration, &points)?;
        reading.recovered = recovered;
        reading.counts.squares_detected = squares_found;
        reading.retared = self.follow_motion(&reading, moved_mm, &lattice, frame)?;
        reading.retare_count = self.retare_count;
        reading.elapsed_ms = started.elapsed().as_secs_f64() * 1e3;
        Ok(reading)
    }

    /// Everything after detection and registration.
    /// Also returns the largest displacement the camera motion gave a corner, mm.
    fn measure(
        &self,
        lattice: &Lattice,
        registration: &Registration,
        points: &FramePoints,
    ) -> Result<(Reading, f64), EstimateError> {
        let valid: Vec<bool> = registration.corners.iter().map(|c| c.valid).collect();
        let (motion, outcome, near_loads) = self.motion_and_test(lattice, &valid, points)?;
        let gammas = self.paper_gammas(lattice, &motion, &valid)?;
        let line = force(&self.config.calibration, gammas.compensated);

        let mut local: Vec<f64> = (0..valid.len())
            .filter(|&i| valid[i])
            .map(|i| motion.displacement[2 * i].hypot(motion.displacement[2 * i + 1]))
            .collect();
        local.sort_unstable_by(|a, b| b.total_cmp(a));
        let contact_score_mm = local.get(CONTACT_SUPPORT - 1).copied().unwrap_or(0.0);

        let (touch, pressure_map) = if self.mode == Mode::Inverse {
            let steady: Vec<bool> = (0..points.valid.len())
                .map(|i| points.valid[i] && !self.rest.light_sensitive.get(i).copied().unwrap_or(false))
                .collect();
            self.inverse_touch(&motion, &points.valid, &steady, &near_loads, &outcome)
        } else {
            let field = PaperField {
                compensated_paper_px: &gammas.compensated_paper_px,
                samples: &gammas.samples,
            };
            (
                self.line_touch(&field, &motion, &valid, &outcome, line.model_n, registration),
                None,
            )
        };
        let reading = Reading {
            mode: self.mode,
            touch,
            test: ContactTest {
                statistic: outcome.statistic,
                threshold: outcome.threshold,
                p_value: outcome.p_value,
                noise_mm: outcome.noise_mm,
                detection_floor_n: outcome.detection_floor_n,
            },
            camera_motion: motion.reported,
            gamma: GammaReading {
                gamma: gammas.compensated,
                gamma_uncompensated: gammas.uncompensated,
                samples_used: gammas.samples.used(),
                samples_total: gammas.samples.total(),
            },
            force_model_n: line.model_n,
            contact_score_mm,
            pressure_map,
            counts: LatticeCounts {
                points_detected: lattice.corners_found(),
                points_expected: self.config.pad.corner_count(),
                squares_detected: lattice.squares_found(),
                squares_expected: self.config.pad.yellow_count(),
                points_valid: registration.valid_count(),
                points_implausible: registration.implausible,
            },
            recovered: false,
            retared: false,
            retare_count: self.retare_count,
            shear_field: shear_field(registration, &motion.displacement, &valid),
            elapsed_ms: 0.0,
        };
        if reading.numbers().iter().any(|v| !v.is_finite()) {
            return Err(EstimateError::NoPattern {
                reason: "the measurement is not finite (degenerate lattice)".into(),
            });
        }
        Ok((reading, motion.largest_mm))
    }

    /// The camera's motion removed, and the contact test on what is left (its verdict, and the observed points within
    /// reach of the loads it found). `valid`: the corners registered.
    fn motion_and_test(
        &self,
        lattice: &Lattice,
        valid: &[bool],
        points: &FramePoints,
    ) -> Result<(Compensated, TestOutcome, Vec<usize>), EstimateError> {
        // The contact test leaves out the corners a change of light biases (after a camera move, or under the LEDs'
        // drift where the frame clips): their bias is no traction, while a contact moves many corners besides them.
        // Its noise is what this frame's corners show about the motion-only fit; the floor and everything measured
        // once it says contact use every corner.
        let tested_valid: Vec<bool> = (0..points.valid.len())
            .map(|i| points.valid[i] && !points.relit[i] && !self.rest.light_sensitive.get(i).copied().unwrap_or(false))
            .collect();
        let (motion, tested_stage) = self.remove_motion(lattice, valid, points, &tested_valid)?;
        // The published detector keeps the noise the fast tracker was first judged by (its residuals after stage 1,
        // never below the configured floors): its corners' scatter on rest frames is not measured.
        let (outcome, near_loads) = match self.mode {
            Mode::Paper => (
                self.model.test(&tested_stage, self.support_noise_mm(&motion.stage)),
                Vec::new(),
            ),
            Mode::Fast | Mode::Inverse => self.model.measured_test_and_loads_of(
                &tested_stage,
                &motion.data,
                &tested_valid,
                self.rest.noise_floor_mm,
            ),
        };
        Ok((motion, outcome, near_loads))
    }

    /// The paper's gamma on the B-spline surface's samples, with the camera's motion removed and as the paper has it
    /// (without).
    fn paper_gammas(
        &self,
        lattice: &Lattice,
        motion: &Compensated,
        valid: &[bool],
    ) -> Result<PaperGammas, EstimateError> {
        let uncompensated_paper_px: Vec<Point2> = lattice
            .corners
            .iter()
            .zip(valid)
            .map(|(c, &ok)| {
                if ok {
                    c.undistorted_px.map(|p| self.rest.mapping.to_paper(p))
                } else {
                    None
                }
            })
            .map(|p| p.unwrap_or([0.0, 0.0]))
            .collect();
        let compensated_paper_px: Vec<Point2> = (0..valid.len())
            .map(|i| {
                let at = [
                    self.rest.corners_mm[i][0] + motion.displacement[2 * i],
                    self.rest.corners_mm[i][1] + motion.displacement[2 * i + 1],
                ];
                let p = if valid[i] {
                    self.rest.mapping.mm_to_undistorted(at)
                } else {
                    None
                };
                p.map(|p| self.rest.mapping.to_paper(p)).unwrap_or([0.0, 0.0])
            })
            .collect();
        let (samples, compensated, uncompensated) = self.rest.sampler.sample_with_gammas(
            &compensated_paper_px,
            &uncompensated_paper_px,
            valid,
            self.config.calibration.alpha,
        )?;
        Ok(PaperGammas {
            compensated_paper_px,
            samples,
            compensated,
            uncompensated,
        })
    }

    /// Camera motion removed (see [`crate::motion`]): the frame's observed points (the model's) are mapped to pad mm
    /// through the rest frame's pad map, and a homography of the pad plane fitted jointly with the tractions takes the
    /// motion (the deformation is then measured in the rest frame's pad axes, not turned with the camera), then
    /// removed from the corners (`valid`: those registered). Also returns stage 1 on the same data over the points
    /// `tested` (the contact test's), solved with the motion's.
    fn remove_motion(
        &self,
        lattice: &Lattice,
        valid: &[bool],
        points: &FramePoints,
        tested: &[bool],
    ) -> Result<(Compensated, Stage1), EstimateError> {
        let rest = &self.rest.corners_mm;
        let mapping = &self.rest.mapping;
        let degenerate = || EstimateError::NoPattern {
            reason: "the pad's motion is degenerate".into(),
        };
        let rest_raw = &self.rest.corners_raw;
        // Each point through the rest frame's pad map as it is (the lattice's and `points`' positions in pad mm), the
        // camera's motion left whole to stage 1's homography of the pad plane (see crate::motion).
        let data = moved_mm(points.mm.iter().copied(), &self.rest.points_mm, &points.valid);
        let (stage, tested_stage) = self.model.stage1_pair(&data, &points.valid, tested);
        let fine = Homography::from_matrix(self.model.motion_homography(&stage.motion)).ok_or_else(degenerate)?;
        let mut displacement = moved_mm(lattice.corners.iter().map(|c| c.mm), rest, valid);
        for (i, r) in rest.iter().enumerate() {
            let m = self.model.motion_field(&stage.motion, *r);
            displacement[2 * i] -= m[0];
            displacement[2 * i + 1] -= m[1];
        }
        // Where the motion puts each rest corner.
        let moved_raw = |mm: Point2| fine.apply(mm).and_then(|q| mapping.mm_to_raw(q));
        let mut reported_pairs = Vec::with_capacity(rest.len());
        let mut largest_mm: f64 = 0.0;
        for (&r, from) in rest.iter().zip(rest_raw) {
            let Some((from, to)) = from.zip(moved_raw(r)) else {
                continue;
            };
            reported_pairs.push((from, to));
            if let Some(q) = mapping.raw_to_mm(to) {
                largest_mm = largest_mm.max((q[0] - r[0]).hypot(q[1] - r[1]));
            }
        }
        let reported = match self.rest.centre_raw.zip(moved_raw([0.0, 0.0])) {
            Some((from, to)) => camera_motion(&reported_pairs, from, to),
            None => CameraMotion::NONE,
        };
        let compensated = Compensated {
            data,
            data_valid: points.valid.clone(),
            displacement,
            stage,
            reported,
            largest_mm,
        };
        Ok((compensated, tested_stage))
    }

    /// Contact from the traction inverse.
    fn inverse_touch(
        &self,
        motion: &Compensated,
        all_valid: &[bool],
        steady: &[bool],
        near_loads: &[usize],
        outcome: &TestOutcome,
    ) -> (Option<Touch>, Option<PressureMap>) {
        let cells = self.model.cells();
        let zero_map = self.pressure_map(&vec![0.0; 3 * cells.len()]);
        if !outcome.contact {
            return (None, Some(zero_map));
        }
        // The squares the rest frame's light probe found under the glare change their yellow area, and so move their
        // corners, whenever the light on them changes: under the LEDs' drift, and above all once the camera has moved
        // (the glare is fixed in the image, the pattern moves under it). Their displacement is no traction far from a
        // load: the tractions are solved for without them, but for those within reach of a load the contact test's
        // corners show (`near_loads`; its stage 1 leaves them out too). On the validation sensor they made phantom
        // contacts at the pad's corners, which put a press's force 38-62 % over once the camera had moved
        // (tests/camera_moved_force.rs).
        let valid: Vec<bool> = (0..all_valid.len())
            .map(|i| all_valid[i] && (steady[i] || near_loads.binary_search(&i).is_ok()))
            .collect();
        let (mut kept, tractions, edge_region, edge_line_deg) = self.listed_contacts(motion, &valid, outcome);
        if kept.is_empty() {
            return (None, Some(zero_map));
        }
        let pressure_n = self.calibrate_pushes(&mut kept);
        let contacts: Vec<ContactRegion> = kept.iter().filter_map(|r| self.region_at(r)).collect();
        if contacts.is_empty() {
            return (None, Some(zero_map));
        }
        let touch = self.touch_of(&kept, contacts, &pressure_n, edge_region.as_ref(), edge_line_deg);
        (Some(touch), Some(self.pressure_map(&tractions)))
    }

    /// Stage 2's contacts (strongest first, each beside the strongest holding its own), the tractions of those
    /// listed (3 per cell, N) and the strongest's shape for its edge direction.
    fn listed_contacts(
        &self,
        motion: &Compensated,
        valid: &[bool],
        outcome: &TestOutcome,
    ) -> (
        Vec<crate::inverse::Region>,
        Vec<f64>,
        Option<crate::inverse::Region>,
        Option<f64>,
    ) {
        // Stage 2 picks the loaded cells at the noise its own fit leaves (corners near the loads left out), never
        // below its floor (`inverse.noise_floor_px`), as before the test measured its noise. Its regions are contacts
        // above the floor at that noise; the strongest is one above the test's floor too (the test found a contact),
        // which is lower for a light press and higher for a heavy one (whose far field the scatter about the motion
        // takes for noise).
        let noise_mm = self.support_noise_mm(&motion.stage);
        let others_floor_n = self.model.test(&motion.stage, noise_mm).detection_floor_n;
        let min_force_n = outcome.detection_floor_n.min(others_floor_n);
        let mut described = self
            .model
            .stage2(&motion.data, valid, &motion.stage, noise_mm, min_force_n);
        // The test decides contact, as in the gamma modes; stage 2 only describes it. A press the test finds can be
        // too light for any cell's pressure to clear that floor (0.08 px is 5.8 µm at 1024x768 on the validation
        // sensor, where the test measures 1.3-1.9 µm): stage 2 then picks its cells at the noise the test measured,
        // and its strongest region must still clear the test's floor where it is. Only then: a frame that has a
        // contact at the floor keeps the description it had (with the lower noise every frame's support would take
        // in the glare's and the model's small errors: tried, force over the pad 0.44 -> 0.71 N on the quick set).
        if described.regions.is_empty() && outcome.noise_mm < noise_mm {
            described = self
                .model
                .stage2(&motion.data, valid, &motion.stage, outcome.noise_mm, min_force_n);
        }
        let Stage2 {
            regions: mut kept,
            mut tractions,
            edge_region,
            edge_line_deg,
            ..
        } = described;
        // Each contact beside the strongest must hold its own at the others' floor (`InverseModel::holds_its_own`),
        // judged against stage 2's tractions as found, before any is left out.
        let found = tractions.clone();
        let mut rank = 0;
        kept.retain(|region| {
            rank += 1;
            let floor_n = others_floor_n * region.floor_scale;
            let listed = rank == 1 || self.model.holds_its_own(&motion.data, valid, &found, region, floor_n);
            if !listed {
                for (j, _) in &region.cells {
                    tractions[3 * j..3 * j + 3].fill(0.0);
                }
            }
            listed
        });
        (kept, tractions, edge_region, edge_line_deg)
    }

    /// What the calibration pushes taught, applied to each contact: its centre moved along its push, and what the
    /// push adds to its normal force taken off. Returns each contact's normal force as the solve found it.
    fn calibrate_pushes(&self, kept: &mut [crate::inverse::Region]) -> Vec<f64> {
        let most_mm = crate::calibration::push_centre::most_shift_mm(&self.config.pad);
        // The contacts' centre is weighed by the pressure the solve found: what a push adds to a load is taken off
        // its force, not moved.
        let pressure_n: Vec<f64> = kept.iter().map(|r| r.force_vector_n[2]).collect();
        for region in kept.iter_mut() {
            region.centre_mm = crate::calibration::push_centre::shifted_centre(
                region.centre_mm,
                region.force_vector_n,
                self.config.elastic.push_centre_shift_mm,
                most_mm,
            );
            // After the shift: both are fitted on the model's force vector as the solve gives it.
            region.force_vector_n[2] = crate::calibration::push_normal::corrected_normal_n(
                region.force_vector_n,
                self.config.elastic.push_normal_share,
            );
        }
        pressure_n
    }

    /// The reading's touch from the listed contacts (`kept`, and `contacts` as the reading lists them, both
    /// strongest first, not empty): the total force vector, the torque about their pressure-weighted centre
    /// (`pressure_n`: each one's normal force as solved) and the strongest's edge direction (`edge_line_deg`: its
    /// line load's, with `inverse.edge_from_line`).
    fn touch_of(
        &self,
        kept: &[crate::inverse::Region],
        contacts: Vec<ContactRegion>,
        pressure_n: &[f64],
        edge_region: Option<&crate::inverse::Region>,
        edge_line_deg: Option<f64>,
    ) -> Touch {
        let cells = self.model.cells();
        let shear = self.config.elastic.tangential_force_scale;
        let force: [f64; 3] = std::array::from_fn(|k| kept.iter().map(|r| r.force_vector_n[k]).sum());
        let total_pressure_n: f64 = pressure_n.iter().sum();
        let centre: [f64; 2] = std::array::from_fn(|axis| {
            kept.iter()
                .zip(pressure_n)
                .map(|(r, p)| p * r.centre_mm[axis])
                .sum::<f64>()
                / total_pressure_n
        });
        let torque = self.config.elastic.torque_factor()
            * kept
                .iter()
                .flat_map(|r| &r.cells)
                .map(|(j, f)| {
                    let p = cells[*j].centre_mm;
                    (p[0] - centre[0]) * f[1] - (p[1] - centre[1]) * f[0]
                })
                .sum::<f64>();
        let moments = edge_region.map(|region| self.model.moments(region, self.config.thresholds.edge_min_confidence));
        let edge = moments.map_or(
            EdgeReading {
                angle_deg: None,
                confidence: 0.0,
            },
            |m| EdgeReading {
                // The moments decide whether the contact has a direction; the line load, when asked for, gives it.
                angle_deg: m.angle_deg.map(|a| edge_line_deg.unwrap_or(a)),
                confidence: m.confidence,
            },
        );
        let mut contacts = contacts.into_iter();
        let strongest = contacts.next().expect("checked non-empty above");
        Touch {
            strongest,
            others: contacts.collect(),
            force_n: force[2],
            force_vector_n: Some(sheared(force, shear)),
            torque_nmm: Some(torque),
            edge,
        }
    }

    fn region_at(&self, region: &crate::inverse::Region) -> Option<ContactRegion> {
        let undistorted = self.rest.mapping.mm_to_undistorted(region.centre_mm)?;
        Some(ContactRegion {
            centre_px: self.rest.mapping.distort(undistorted)?,
            centre_undistorted_px: undistorted,
            centre_mm: region.centre_mm,
            force_n: region.force_vector_n[2],
            force_vector_n: Some(sheared(
                region.force_vector_n,
                self.config.elastic.tangential_force_scale,
            )),
            torque_nmm: Some(region.torque_nmm * self.config.elastic.torque_factor()),
            area_mm2: Some(region.area_mm2),
        })
    }

    fn pressure_map(&self, tractions: &[f64]) -> PressureMap {
        let pad = &self.config.pad;
        PressureMap {
            origin_mm: self.model.cells()[0].centre_mm,
            step_mm: [pad.pitch_x_mm(), pad.pitch_y_mm()],
            cols: usize::from(pad.cols),
            rows: usize::from(pad.rows),
            kpa: self.model.pressure_kpa(tractions),
        }
    }

    /// Contact from the paper's gamma line (modes `fast` and `paper`): the force is the line's value, located where
    /// the shear field diverges from. A force below the detection floor, in the line's own newtons, is no contact,
    /// never a negative or zero force.
    fn line_touch(
        &self,
        field: &PaperField,
        motion: &Compensated,
        valid: &[bool],
        outcome: &TestOutcome,
        line_n: f64,
        registration: &Registration,
    ) -> Option<Touch> {
        // The noise test decides whether anything departs from rigid motion; the line says how much force that is.
        // The test's floor is a force at the pad's centre in the pad model's newtons, which are not the line's (the
        // model's modulus and the line are calibrated apart, or not at all), so it is not compared with the line's
        // force as it stands: it is carried over as the gamma the floor press gives (the model's central press,
        // noise-free, through this rest frame's sampler: its displacement is fixed by the noise and the test alone,
        // whatever the modulus), and the line's force at that gamma is the floor in the line's newtons. A reading
        // the line puts below it, or at or below zero (an offset b the line reaches before the floor), is lighter
        // than the lightest press the sensor can tell from noise by the line's own reckoning: no contact, not a
        // clamped or negative force. gamma and the displacements are still reported (`force_model_n` keeps the
        // line's value as it is). With a line fitted to this sensor the floor sits near the test's; with another
        // sensor's line (the real sensor's default on a simulated pad) light presses read no contact, which is why
        // every estimator of a sensor whose line is known is built with it.
        let floor_gamma = outcome.detection_floor_n * self.rest.gamma_per_n;
        let floor_line_n = force(&self.config.calibration, floor_gamma).model_n;
        // Written so that a NaN on either side is below, not above.
        let above_floor = line_n > 0.0 && line_n >= floor_line_n;
        if !outcome.contact || !above_floor {
            return None;
        }
        let points: Vec<FieldPoint> = (0..valid.len())
            .filter(|&i| valid[i])
            .map(|i| FieldPoint {
                position: self.rest.paper_px[i],
                displacement: sub(field.compensated_paper_px[i], self.rest.paper_px[i]),
            })
            .collect();
        let affine = fit_affine_motion(&points).unwrap_or(AffineMotion::ZERO);
        let residuals: Vec<Point2> = points.iter().map(|p| affine.residual(p)).collect();
        let centre = divergence_centre(&points, &residuals)?;
        let undistorted = self.rest.mapping.from_paper(centre);
        let strongest = ContactRegion {
            centre_px: self.rest.mapping.distort(undistorted)?,
            centre_undistorted_px: undistorted,
            centre_mm: self.rest.mapping.undistorted_to_mm(undistorted)?,
            force_n: line_n,
            force_vector_n: None,
            torque_nmm: None,
            area_mm2: None,
        };
        let edge = self.shear_edge(field.samples, &affine, registration, motion);
        Some(Touch {
            strongest,
            others: Vec::new(),
            force_n: line_n,
            force_vector_n: None,
            torque_nmm: None,
            edge: EdgeReading {
                angle_deg: edge.angle_deg,
                confidence: edge.confidence,
            },
        })
    }

    /// The shear field's principal axis (modes `fast` and `paper`). None when the loads stage 1 finds are two presses
    /// ([`InverseModel::stage1_loads_are_two_presses`], at stage 2's noise): the field of two round presses side by
    /// side is elongated along the pair, and two fingertips are not an edge (issue 12: none for round contacts).
    fn shear_edge(
        &self,
        samples: &ShearSamples,
        affine: &AffineMotion,
        registration: &Registration,
        motion: &Compensated,
    ) -> EdgeEstimate {
        let sheared: Vec<(Point2, f64)> = self
            .rest
            .sampler
            .reference_samples()
            .iter()
            .zip(&samples.displacement)
            .zip(&samples.valid)
            .filter(|(_, &ok)| ok)
            .filter_map(|((&at, &d), _)| {
                let local = norm(sub(d, affine.predict(at)));
                let mm = self.rest.mapping.undistorted_to_mm(self.rest.mapping.from_paper(at))?;
                Some((mm, local))
            })
            .collect();
        let thresholds = &self.config.thresholds;
        let edge = edge_direction(
            &sheared,
            thresholds.edge_sample_fraction,
            thresholds.edge_min_confidence,
        );
        let coverage = self.coverage(&registration.corners, edge.region_centre_mm, edge.region_radius_mm);
        let edge = edge.with_coverage(coverage, MIN_EDGE_COVERAGE, thresholds.edge_min_confidence);
        // The two-press test costs two pattern searches: only a direction that would be reported is put to it.
        let two_presses = edge.angle_deg.is_some()
            && self.model.stage1_loads_are_two_presses(
                &motion.stage,
                &motion.data,
                &motion.data_valid,
                self.support_noise_mm(&motion.stage),
            );
        EdgeEstimate {
            angle_deg: edge.angle_deg.filter(|_| !two_presses),
            ..edge
        }
    }

    /// The noise stage 2 picks its loaded cells at (and the published detector's contact test uses): what the frame's
    /// stage 1 fit leaves, never below the support floor (`inverse.noise_floor_px`).
    fn support_noise_mm(&self, stage: &Stage1) -> f64 {
        let floor_mm = self.rest.support_floor_mm;
        self.model.frame_noise_mm(stage, floor_mm).max(floor_mm)
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

    /// The observed points (the model's) a change of light moves: the rest frame is tracked again with every pixel
    /// 10 % darker and 10 % brighter. Chromaticity does not change with the light except where the frame clips
    /// (glare, highlights), so a square there changes shape and it and its corners move, while the rest of the lattice
    /// stays put; the LEDs' drift does the same to those squares in later frames, a bias that is no traction and that
    /// a light press cannot be told from. Each point's largest shift (pad mm) against the lattice's robust spread:
    /// beyond [`LIGHT_SIGMAS`] it is left out of the contact test (a press moves many points besides these).
    fn light_sensitive_points(&self, reference: &RgbImage) -> Vec<bool> {
        let (config, rest) = (&self.config, &self.rest);
        let count = rest.points_mm.len();
        let mut shift = vec![0.0f64; count];
        for factor in LIGHT_PROBE {
            // Each of the 256 levels scaled once, then looked up (per byte, the rounding is a library call).
            let level: [u8; 256] =
                std::array::from_fn(|v| (f32::from(v as u8) * factor).round().clamp(0.0, 255.0) as u8);
            let mut probe = reference.clone();
            for c in probe.iter_mut() {
                *c = level[usize::from(*c)];
            }
            // A copy of the tracker as it stands on this rest frame (just built, or just re-tared onto it): the
            // probe is measured as the next frame would be, with no second full-frame search.
            let found = match &self.detector {
                Detector::Fast(tracker) => tracker.clone().track(&probe).map(|d| (d.squares, d.corners)),
                Detector::Paper(detector) => paper_points(detector, &probe, config).map(|p| (p.0, p.1)),
            };
            let Ok((squares, corners)) = found else {
                continue;
            };
            let points = match config.inverse.observe {
                ObservedPoints::Corners => corners,
                ObservedPoints::Squares => squares,
            };
            for (i, (c, r)) in points.iter().zip(&rest.points_found_mm).enumerate() {
                let moved = c.zip(*r).and_then(|(c, r)| rest.mapping.raw_to_mm(c).map(|m| (m, r)));
                if let Some((m, r)) = moved {
                    shift[i] = shift[i].max((m[0] - r[0]).hypot(m[1] - r[1]));
                }
            }
        }
        let mut moved: Vec<f64> = shift.iter().copied().filter(|v| *v > 0.0).collect();
        if moved.len() < count / 2 {
            return vec![false; count];
        }
        let centre = median(&mut moved);
        let mut deviations: Vec<f64> = moved.iter().map(|v| (v - centre).abs()).collect();
        let limit = centre + LIGHT_SIGMAS * MAD_TO_SIGMA * median(&mut deviations);
        shift.iter().map(|&v| v > limit).collect()
    }

    /// The frame's observed points (the model's, `inverse.observe`): where each is in pad mm, and whether it is
    /// measured (a corner when registered, a square by [`register_squares`]). `relit`: per point, from detection.
    fn observed_points(
        &self,
        lattice: &Lattice,
        registration: &Registration,
        max_displacement_cells: f64,
        relit: Vec<bool>,
    ) -> FramePoints {
        let (mm, valid) = match self.config.inverse.observe {
            ObservedPoints::Corners => (
                lattice.corners.iter().map(|c| c.mm).collect(),
                registration.corners.iter().map(|c| c.valid).collect(),
            ),
            ObservedPoints::Squares => {
                let mapping = &self.rest.mapping;
                let mm: Vec<Option<Point2>> = lattice
                    .squares
                    .iter()
                    .map(|s| s.raw_px.and_then(|p| mapping.raw_to_mm(p)))
                    .collect();
                let valid = register_squares(
                    &self.config.pad,
                    &self.rest.points_found_mm,
                    &mm,
                    registration,
                    max_displacement_cells,
                );
                (mm, valid)
            }
        };
        FramePoints { mm, valid, relit }
    }

    /// Counts frames of persistent motion without contact and re-tares after `retare.frames` of them: the frame
    /// just measured becomes the rest frame. Returns whether it did.
    fn follow_motion(
        &mut self,
        reading: &Reading,
        moved: f64,
        lattice: &Lattice,
        frame: &RgbImage,
    ) -> Result<bool, EstimateError> {
        if reading.is_contact() || moved <= self.config.retare.motion_mm {
            self.moved_frames = 0;
            return Ok(false);
        }
        self.moved_frames += 1;
        if self.moved_frames < self.config.retare.frames {
            return Ok(false);
        }
        // The new rest frame is found as `Estimator::new` finds one: a full search and a tracker built on it. Adopting
        // the tracked frame's positions instead (as before) kept a bias, most likely because they were measured
        // through the old rest frame's windows, carried by the camera's motion, and later frames through windows of
        // the new one, and a centroid's dependence on its window then does not cancel. After a 2 deg roll
        // (hard_cases) the contact test's statistic on the rest frames that followed was 544-684 against a threshold
        // of 457, with corners at the pattern's top-left moved 6-15 µm; an estimator built on the same rest frame
        // reads 309-377 on them, as this one now does. Only if that search fails is the tracked frame adopted.
        let mut squares: Vec<Option<Point2>> = lattice.squares.iter().map(|s| s.raw_px).collect();
        let mut corners: Vec<Option<Point2>> = lattice.corners.iter().map(|c| c.raw_px).collect();
        if let Detector::Fast(tracker) = &mut self.detector {
            match FastTracker::from_reference(frame, self.config.pad, self.config.thresholds) {
                Ok((fresh, detection)) => {
                    *tracker = fresh;
                    squares = detection.squares;
                    corners = detection.corners;
                }
                Err(_) => tracker.adopt_last_frame_as_reference()?,
            }
        }
        (self.rest, self.model) = Rest::new(&self.config, *self.rest.mapping.camera(), squares, &corners)?;
        self.rest.light_sensitive = self.light_sensitive_points(frame);
        self.moved_frames = 0;
        self.retare_count += 1;
        tracing::info!(
            retares = self.retare_count,
            rotation_deg = reading.camera_motion.rotation_deg,
            shift_px = ?reading.camera_motion.shift_px,
            "the pad moved against the camera and stayed without contact: new rest frame"
        );
        Ok(true)
    }
}

/// Which of a frame's observed points (the model's: `inverse.observe`) are measured, and which were relit (see
/// [`FrameLattice::relit`]).
struct FramePoints {
    /// Where the frame's pad map puts each point, pad mm.
    mm: Vec<Option<Point2>>,
    valid: Vec<bool>,
    relit: Vec<bool>,
}

/// Each point's motion from `rest` to `now` (pad mm), 2 per point (zero where not `valid`).
fn moved_mm(now: impl Iterator<Item = Option<Point2>>, rest: &[Point2], valid: &[bool]) -> Vec<f64> {
    now.zip(rest)
        .zip(valid)
        .flat_map(|((at, r), &ok)| at.filter(|_| ok).map_or([0.0, 0.0], |c| [c[0] - r[0], c[1] - r[1]]))
        .collect()
}

/// The displacements with the camera motion removed, and the motion.
struct Compensated {
    /// Displacements after the first pass's motion is removed (stage 1's input), 2 per observed point, mm.
    data: Vec<f64>,
    /// Which of `data`'s points were measured.
    data_valid: Vec<bool>,
    /// The pad's own displacement (second pass's motion removed as well), 2 per corner, mm.
    displacement: Vec<f64>,
    stage: Stage1,
    reported: CameraMotion,
    /// The largest displacement the motion gives a corner, mm.
    largest_mm: f64,
}

/// The compensated shear field in the paper's units, for the gamma-line modes.
/// The paper's gamma of a frame (see [`Estimator::paper_gammas`]).
struct PaperGammas {
    /// Each corner where the rest frame's pad map puts its compensated displacement, paper px.
    compensated_paper_px: Vec<Point2>,
    samples: ShearSamples,
    /// gamma with the camera's motion removed, and as the paper measures it.
    compensated: f64,
    uncompensated: f64,
}

struct PaperField<'a> {
    compensated_paper_px: &'a [Point2],
    samples: &'a ShearSamples,
}

/// Each corner's shear as the reading lists it: where it was and is in the raw frame, and its displacement in pad mm
/// with the camera's motion removed (`displacement`: 2 per corner), none where it is not `valid`.
fn shear_field(registration: &Registration, displacement: &[f64], valid: &[bool]) -> Vec<ShearVector> {
    registration
        .corners
        .iter()
        .enumerate()
        .map(|(i, c)| ShearVector {
            index: c.index,
            reference_px: c.reference_raw,
            current_px: c.current_raw,
            displacement_mm: c
                .displacement_mm
                .map(|_| [displacement[2 * i], displacement[2 * i + 1]])
                .filter(|_| valid[i]),
            valid: c.valid,
        })
        .collect()
}

impl Rest {
    /// The rest frame, and the inverse's model for it (the camera's place, which the model's parallax needs, comes
    /// from the rest frame's map).
    fn new(
        config: &SensorConfig,
        camera: nusense_geometry::FisheyeCamera,
        squares: Vec<Option<Point2>>,
        corners: &[Option<Point2>],
    ) -> Result<(Self, Arc<InverseModel>), EstimateError> {
        let pad = config.pad;
        let undistorted: Vec<Option<Point2>> = corners.iter().map(|c| c.and_then(|p| camera.undistort_px(p))).collect();
        let mapping = PadMapping::fit(camera, &pad, &undistorted, config.pad_map.as_ref())?;
        let shared = InverseModel::shared(config, mapping.camera_view())?;
        let model = &*shared;
        let lattice = build_lattice(config, &mapping, squares, corners);
        let (points_found_mm, nominal_mm): (Vec<Option<Point2>>, Vec<Point2>) = match config.inverse.observe {
            ObservedPoints::Corners => lattice.corners.iter().map(|c| (c.mm, pad.corner_mm(c.index))).unzip(),
            ObservedPoints::Squares => lattice
                .squares
                .iter()
                .map(|s| {
                    (
                        s.raw_px.and_then(|p| mapping.raw_to_mm(p)),
                        pad.square_centre_mm(s.index),
                    )
                })
                .unzip(),
        };
        let points_mm: Vec<Point2> = points_found_mm
            .iter()
            .zip(nominal_mm)
            .map(|(f, n)| f.unwrap_or(n))
            .collect();
        let points_valid: Vec<bool> = points_found_mm.iter().map(Option::is_some).collect();
        let needed = min_valid(config);
        if lattice.corners_found() < needed {
            return Err(EstimateError::TooFewPoints {
                found: lattice.corners_found(),
                needed,
            });
        }
        let corners_mm: Vec<Point2> = lattice
            .corners
            .iter()
            .map(|c| c.mm.unwrap_or_else(|| pad.corner_mm(c.index)))
            .collect();
        let corners_raw = corners_mm.iter().map(|&r| mapping.mm_to_raw(r)).collect();
        let centre_raw = mapping.mm_to_raw([0.0, 0.0]);
        let paper_px: Vec<Point2> = lattice
            .corners
            .iter()
            .map(|c| c.undistorted_px.map(|p| mapping.to_paper(p)).unwrap_or([0.0, 0.0]))
            .collect();
        let valid: Vec<bool> = lattice.corners.iter().map(|c| c.undistorted_px.is_some()).collect();
        let sampler = ShearSampler::new(
            usize::from(pad.corner_rows()),
            usize::from(pad.corner_cols()),
            &config.surface,
            &paper_px,
            &valid,
        )?;
        let gamma_per_n = central_press_gamma(config, model, &mapping, &corners_mm, &sampler, &valid, &points_valid)?;
        let floor_px_mm = mapping
            .mm_per_px_at_centre()
            .map_or(0.0, |scale| config.inverse.noise_floor_px * scale);
        let noise_floor_mm = config.inverse.noise_floor_mm;
        let support_floor_mm = noise_floor_mm.max(floor_px_mm);
        let light_sensitive = vec![false; points_mm.len()];
        Ok((
            Self {
                lattice,
                mapping,
                corners_mm,
                points_found_mm,
                points_mm,
                corners_raw,
                centre_raw,
                paper_px,
                sampler,
                noise_floor_mm,
                support_floor_mm,
                gamma_per_n,
                light_sensitive,
            },
            shared,
        ))
    }
}

/// The rest frame seen under this much more and less light, to find the corners a change of light moves.
const LIGHT_PROBE: [f32; 2] = [0.9, 1.1];
/// A corner moved by the probe more than this many robust standard deviations (over the lattice's corners) beyond
/// the median corner is light-sensitive.
const LIGHT_SIGMAS: f64 = 5.0;

/// The gamma of the pad model's 1 N central press ([`InverseModel::central_press_mm`]) on this rest frame, with the
/// motion stage 1 fits to it removed as [`Estimator::measure`] removes it from a frame. `valid`: the corners the rest
/// frame found; `points_valid`: the model's observed points it found.
fn central_press_gamma(
    config: &SensorConfig,
    model: &InverseModel,
    mapping: &PadMapping,
    corners_mm: &[Point2],
    sampler: &ShearSampler,
    valid: &[bool],
    points_valid: &[bool],
) -> Result<f64, EstimateError> {
    let press = model.central_press_mm();
    let stage = model.stage1(&press, points_valid);
    let corners_press: Vec<f64> = match config.inverse.observe {
        ObservedPoints::Corners => press,
        // The tracker's corner is the midpoint of its two squares, so its motion is their mean motion.
        ObservedPoints::Squares => {
            let squares: Vec<Option<Point2>> = press.chunks_exact(2).map(|d| Some([d[0], d[1]])).collect();
            corners_from_squares(&config.pad, &squares)
                .into_iter()
                .flat_map(|d| d.unwrap_or([0.0, 0.0]))
                .collect()
        }
    };
    let pressed: Vec<Point2> = corners_mm
        .iter()
        .enumerate()
        .map(|(i, &r)| {
            let m = model.motion_field(&stage.motion, r);
            let at = [
                r[0] + corners_press[2 * i] - m[0],
                r[1] + corners_press[2 * i + 1] - m[1],
            ];
            let p = if valid[i] { mapping.mm_to_undistorted(at) } else { None };
            p.map(|p| mapping.to_paper(p)).unwrap_or([0.0, 0.0])
        })
        .collect();
    let samples = sampler.sample(&pressed, valid)?;
    Ok(gamma(&samples, config.calibration.alpha))
}

/// A force vector with its tangential part (fx, fy) calibrated: see `ElasticConfig::tangential_force_scale`.
fn sheared([fx, fy, fz]: [f64; 3], scale: f64) -> [f64; 3] {
    [fx * scale, fy * scale, fz]
}

fn sub(a: Point2, b: Point2) -> Point2 {
    [a[0] - b[0], a[1] - b[1]]
}

fn min_valid(config: &SensorConfig) -> usize {
    ((config.pad.corner_count() as f64 * MIN_VALID_FRACTION).ceil() as usize).max(MIN_VALID_CORNERS)
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
