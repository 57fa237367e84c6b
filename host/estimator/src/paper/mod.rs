//! Mode `paper`: the sensor authors' published pipeline with their parameters (the config's defaults), as
//! faithfully as we can make it, so that speed and error can be compared with the fast mode on the same frames.
//!
//! Stages, in order: fisheye undistortion with a bilinear remap ([`undistort`]), crop to the region of interest,
//! grey, bilateral filter, |Sobel x| and |Sobel y| weighted and thresholded, 3x3 dilation then erosion
//! ([`filters`]), external contours approximated by polygons, quadrilaterals by area and solidity ([`quads`]),
//! nearest-vertex pairing of neighbouring quads with midpoints as control points ([`lattice`]).
//!
//! One deliberate departure: the published code matched control points to the rest frame by sorting them into
//! rows, which fails on the real pair; here every control point gets its lattice index instead (see
//! [`lattice`]), and missing points stay missing.
//!
//! Frames of another size than the calibration's (`config.camera`) get the lens, the ROI and every length
//! (filter diameter, spatial sigma, area window, pairing distance) scaled to them by s = new / calibration size.
//! The gradient threshold is divided by s: the same physical edge spans s times fewer pixels, so its Sobel
//! response per pixel grows by 1 / s (without this, at half size the edge rings merge and no quad is left).
//! The fixed 3x3 Sobel and morphology cannot shrink with the pattern: at a quarter size (squares of ~20 px) the
//! published method finds no quadrilaterals at all, and paper mode reports that as `NoPattern`.

pub mod filters;
pub mod lattice;
pub mod quads;
pub mod undistort;

use image::{GrayImage, RgbImage};
use nusense_geometry::{CornerIndex, FisheyeCamera, PadGeometry, Point2, SquareIndex};

use crate::config::SensorConfig;
use crate::EstimateError;
use filters::Bilateral;
use lattice::{CellColour, IndexingFailure};
use quads::{Quad, QuadFilter};
use undistort::RemapTable;

/// A rectangle of the undistorted frame in whole pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RoiPx {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
}

/// A control point found by the published method, with the lattice index we give it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PaperPoint {
    pub index: CornerIndex,
    pub raw_px: Point2,
    pub undistorted_px: Point2,
}

/// A quadrilateral the published method accepted, with its lattice index when one could be given.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PaperSquare {
    pub index: Option<SquareIndex>,
    /// Mean of the four polygon vertices.
    pub centre_raw_px: Point2,
    pub centre_undistorted_px: Point2,
}

#[derive(Clone, Debug, PartialEq)]
pub struct PaperDetection {
    /// One per lattice corner found, ordered by index (row-major).
    pub points: Vec<PaperPoint>,
    pub squares: Vec<PaperSquare>,
    /// Quadrilaterals accepted by the published test: the published count of squares.
    pub squares_found: usize,
    /// Distinct midpoints of the published pairing: the published count of corners.
    pub corners_found: usize,
    /// Pairs that joined quads which are not diagonal neighbours of the lattice (their midpoints are dropped).
    pub implausible_pairs: usize,
}

impl PaperDetection {
    pub fn squares_indexed(&self) -> usize {
        self.squares.iter().filter(|s| s.index.is_some()).count()
    }
}

/// The published parameters resolved for one frame size, plus the remap table for it.
#[derive(Clone, Debug)]
pub struct PaperDetector {
    camera: FisheyeCamera,
    pad: PadGeometry,
    remap: RemapTable,
    bilateral: Bilateral,
    sobel_weights: (f32, f32),
    binary_threshold: u8,
    quad_filter: QuadFilter,
    pair_distance_px: f64,
}

/// Below this the published filters (a 20 px bilateral window at full size) have nothing left to work on.
const MIN_FRAME_SIDE: u32 = 64;

impl PaperDetector {
    /// Resolves the config for `width x height` frames and builds the remap table (the costly part of setup).
    pub fn new(config: &SensorConfig, width: u32, height: u32) -> Result<Self, EstimateError> {
        if width < MIN_FRAME_SIDE || height < MIN_FRAME_SIDE {
            return Err(EstimateError::FrameTooSmall {
                width,
                height,
                min: MIN_FRAME_SIDE,
            });
        }
        let intrinsics = config.camera.scaled_to(width, height);
        let camera = FisheyeCamera::new(intrinsics)?;
        let sx = f64::from(width) / f64::from(config.camera.width);
        let sy = f64::from(height) / f64::from(config.camera.height);
        let s = (sx * sy).sqrt();
        let roi = scaled_roi(config, sx, sy, width, height).ok_or_else(|| EstimateError::NoPattern {
            reason: "the region of interest lies outside the frame".into(),
        })?;
        let p = &config.paper;
        let scale_len = |v: f64| (v * s).max(1.0);
        Ok(Self {
            camera,
            pad: config.pad,
            remap: RemapTable::new(&camera, roi),
            bilateral: Bilateral {
                diameter: (f64::from(p.bilateral_diameter) * s).round().max(1.0) as u32,
                sigma_color: p.bilateral_sigma_color,
                sigma_space: scale_len(p.bilateral_sigma_space),
            },
            sobel_weights: (p.sobel_weight_x as f32, p.sobel_weight_y as f32),
            binary_threshold: (p.binary_threshold / s).round().clamp(0.0, 255.0) as u8,
            quad_filter: QuadFilter {
                epsilon_fraction: p.polygon_epsilon_fraction,
                min_area: p.quad_min_area_px2 * s * s,
                max_area: p.quad_max_area_px2 * s * s,
                min_solidity: p.quad_min_solidity,
            },
            pair_distance_px: scale_len(p.pair_distance_px),
        })
    }

    pub fn camera(&self) -> &FisheyeCamera {
        &self.camera
    }

    pub fn roi(&self) -> RoiPx {
        self.remap.roi()
    }

    /// Stage 1: the ROI of the undistorted frame, grey.
    pub fn undistorted_roi_gray(&self, frame: &RgbImage) -> Result<GrayImage, EstimateError> {
        self.check_size(frame)?;
        Ok(self.remap.undistorted_gray(frame))
    }

    /// Stage 2: bilateral filter, Sobel, threshold, closing: the binary edge map of the ROI.
    pub fn edge_map(&self, gray: &GrayImage) -> GrayImage {
        let smoothed = self.bilateral.apply(gray);
        let binary = filters::sobel_threshold(
            &smoothed,
            self.sobel_weights.0,
            self.sobel_weights.1,
            self.binary_threshold,
        );
        filters::close_3x3(&binary)
    }

    /// Stage 3: the quadrilaterals of the edge map (ROI pixel indices).
    pub fn quads(&self, edges: &GrayImage) -> Vec<Quad> {
        quads::find_quads(&quads::external_contours(edges), &self.quad_filter)
    }

    /// The whole published pipeline on one frame, with lattice indices on the control points.
    pub fn detect(&self, frame: &RgbImage) -> Result<PaperDetection, EstimateError> {
        let gray = self.undistorted_roi_gray(frame)?;
        let edges = self.edge_map(&gray);
        let quads = self.quads(&edges);
        self.index(frame, &quads)
    }

    /// Stage 4: pairing, lattice indices, and the way back to raw px.
    pub fn index(&self, frame: &RgbImage, quads: &[Quad]) -> Result<PaperDetection, EstimateError> {
        self.check_size(frame)?;
        let roi = self.remap.roi();
        let pairs = lattice::pair_vertices(quads, self.pair_distance_px);
        let corners_found = lattice::distinct_midpoints(&pairs);
        if quads.is_empty() {
            return Err(EstimateError::NoPattern {
                reason: "the published method found no quadrilateral".into(),
            });
        }
        let roi_centre = [f64::from(roi.width) / 2.0, f64::from(roi.height) / 2.0];
        let colour = FrameColour {
            frame,
            camera: &self.camera,
            roi,
        };
        let assignment =
            lattice::assign_lattice(quads, &pairs, &self.pad, roi_centre, &colour).map_err(|e| match e {
                IndexingFailure::NoPairs => EstimateError::NoPattern {
                    reason: format!("{} quadrilaterals but no two of them share a corner", quads.len()),
                },
                IndexingFailure::TooFewConnected { found, needed } => EstimateError::TooFewPoints { found, needed },
                IndexingFailure::LargerThanPad => EstimateError::NoPattern {
                    reason: "the quadrilaterals span more rows or columns than the pad has".into(),
                },
            })?;
        // ROI pixel indices -> undistorted frame indices -> raw px (our convention) -> undistorted px (ours).
        let locate = |p: [f64; 2]| -> Option<(Point2, Point2)> {
            let raw = undistort::index_to_raw_px(&self.camera, [p[0] + f64::from(roi.x), p[1] + f64::from(roi.y)]);
            let undistorted = self.camera.undistort_px(raw)?;
            raw.iter()
                .chain(&undistorted)
                .all(|v| v.is_finite())
                .then_some((raw, undistorted))
        };
        let points = assignment
            .corners
            .iter()
            .filter_map(|(&index, &p)| {
                locate(p).map(|(raw_px, undistorted_px)| PaperPoint {
                    index,
                    raw_px,
                    undistorted_px,
                })
            })
            .collect();
        let squares = quads
            .iter()
            .zip(&assignment.squares)
            .filter_map(|(quad, &index)| {
                locate(quad.centre()).map(|(centre_raw_px, centre_undistorted_px)| PaperSquare {
                    index,
                    centre_raw_px,
                    centre_undistorted_px,
                })
            })
            .collect();
        Ok(PaperDetection {
            points,
            squares,
            squares_found: quads.len(),
            corners_found,
            implausible_pairs: assignment.implausible_pairs,
        })
    }

    fn check_size(&self, frame: &RgbImage) -> Result<(), EstimateError> {
        let (w, h) = frame.dimensions();
        if (w, h) != (self.camera.width(), self.camera.height()) {
            return Err(EstimateError::FrameSizeMismatch {
                expected_width: self.camera.width(),
                expected_height: self.camera.height(),
                found_width: w,
                found_height: h,
            });
        }
        Ok(())
    }
}

/// One-shot detection (builds the remap table each call; keep a [`PaperDetector`] for a stream of frames).
pub fn detect(frame: &RgbImage, config: &SensorConfig) -> Result<PaperDetection, EstimateError> {
    PaperDetector::new(config, frame.width(), frame.height())?.detect(frame)
}

fn scaled_roi(config: &SensorConfig, sx: f64, sy: f64, width: u32, height: u32) -> Option<RoiPx> {
    let r = &config.roi;
    let x = (f64::from(r.x) * sx).round() as u32;
    let y = (f64::from(r.y) * sy).round() as u32;
    let w = ((f64::from(r.width) * sx).round() as u32).min(width.saturating_sub(x));
    let h = ((f64::from(r.height) * sy).round() as u32).min(height.saturating_sub(y));
    (w > 0 && h > 0).then_some(RoiPx {
        x,
        y,
        width: w,
        height: h,
    })
}

/// Yellowness of the undistorted frame, sampled through the camera model at ROI pixel positions.
struct FrameColour<'a> {
    frame: &'a RgbImage,
    camera: &'a FisheyeCamera,
    roi: RoiPx,
}

impl CellColour for FrameColour<'_> {
    fn yellowness(&self, at: [f64; 2]) -> f64 {
        let p = [at[0] + f64::from(self.roi.x), at[1] + f64::from(self.roi.y)];
        let [_, g, b] = undistort::sample_undistorted_rgb(self.frame, self.camera, p);
        // Yellow carries green, the red-magenta background hardly any; blue is low in yellow only.
        f64::from(g) - f64::from(b)
    }
}
