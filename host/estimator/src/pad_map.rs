//! From raw px to the two other frames: undistorted px (the fisheye model, points only) and pad mm (a
//! homography from the reference lattice's undistorted corners to their nominal positions on the pad).
//!
//! Gamma is a sum of pixel distances, so its value depends on the frame's resolution. The paper's alpha was
//! chosen for 2048-px-wide frames; we therefore measure surfaces in "paper px": undistorted px multiplied by
//! 2048 / frame width. At full resolution paper px and undistorted px coincide, and at 1/2 or 1/4 resolution
//! the same touch gives the same gamma and force.

use nusense_geometry::{FisheyeCamera, PadGeometry, Point2};

use crate::config::SensorConfig;
use crate::error::EstimateError;
use crate::homography::Homography;

/// Frame width the paper's alpha (and so gamma's unit) refers to.
pub const PAPER_FRAME_WIDTH: f64 = 2048.0;

#[derive(Clone, Debug)]
pub struct PadMapping {
    camera: FisheyeCamera,
    to_mm: Homography,
    to_undistorted: Homography,
    paper_scale: f64,
}

/// The config's lens scaled to a frame of `width x height`.
pub fn camera_for(config: &SensorConfig, width: u32, height: u32) -> Result<FisheyeCamera, EstimateError> {
    Ok(FisheyeCamera::new(config.camera.scaled_to(width, height))?)
}

impl PadMapping {
    /// `reference_undistorted` holds each corner's undistorted px in `corner_slot` order.
    pub fn new(
        camera: FisheyeCamera,
        pad: &PadGeometry,
        reference_undistorted: &[Option<Point2>],
    ) -> Result<Self, EstimateError> {
        let (mut from, mut to) = (Vec::new(), Vec::new());
        for (index, p) in pad.corners().zip(reference_undistorted) {
            if let Some(p) = p {
                from.push(*p);
                to.push(pad.corner_mm(index));
            }
        }
        let needed = 8;
        if from.len() < needed {
            return Err(EstimateError::TooFewPoints { found: from.len(), needed });
        }
        let degenerate = || EstimateError::NoPattern { reason: "the reference corners are degenerate (collinear)".into() };
        let to_mm = Homography::fit(&from, &to).ok_or_else(degenerate)?;
        let to_undistorted = Homography::fit(&to, &from).ok_or_else(degenerate)?;
        let paper_scale = PAPER_FRAME_WIDTH / f64::from(camera.width());
        Ok(Self { camera, to_mm, to_undistorted, paper_scale })
    }

    pub fn camera(&self) -> &FisheyeCamera {
        &self.camera
    }

    pub fn undistort(&self, raw: Point2) -> Option<Point2> {
        self.camera.undistort_px(raw).filter(|p| p[0].is_finite() && p[1].is_finite())
    }

    pub fn distort(&self, undistorted: Point2) -> Option<Point2> {
        let p = self.camera.distort_px(undistorted);
        (p[0].is_finite() && p[1].is_finite()).then_some(p)
    }

    pub fn undistorted_to_mm(&self, p: Point2) -> Option<Point2> {
        self.to_mm.apply(p)
    }

    pub fn mm_to_undistorted(&self, p: Point2) -> Option<Point2> {
        self.to_undistorted.apply(p)
    }

    /// Undistorted px to paper px (see the module notes).
    pub fn to_paper(&self, p: Point2) -> Point2 {
        [p[0] * self.paper_scale, p[1] * self.paper_scale]
    }

    pub fn from_paper(&self, p: Point2) -> Point2 {
        [p[0] / self.paper_scale, p[1] / self.paper_scale]
    }

    pub fn paper_scale(&self) -> f64 {
        self.paper_scale
    }
}
