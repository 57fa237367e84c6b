//! Why a frame could not be measured. Every way a frame can be bad has its own variant; none panics.

use thiserror::Error;

use crate::config::ConfigError;
use crate::surface::SurfaceError;
use crate::Mode;

#[derive(Debug, Error)]
pub enum EstimateError {
    #[error(
        "the frame is {found_width} x {found_height} px but the reference is {expected_width} x {expected_height} px"
    )]
    FrameSizeMismatch {
        expected_width: u32,
        expected_height: u32,
        found_width: u32,
        found_height: u32,
    },
    #[error("the frame is {width} x {height} px, too small to hold the pad's pattern (need at least {min} px a side)")]
    FrameTooSmall { width: u32, height: u32, min: u32 },
    #[error("no pattern in view: {reason}")]
    NoPattern { reason: String },
    #[error("too few lattice points: found {found}, need at least {needed}")]
    TooFewPoints { found: usize, needed: usize },
    #[error("camera model: {0}")]
    Camera(#[from] nusense_geometry::CameraError),
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error("B-spline surface: {0}")]
    Surface(#[from] SurfaceError),
    #[error("elastic model: {0}")]
    Model(#[from] crate::elastic::ElasticError),
    #[error("mode {mode:?} is not available: {reason}")]
    ModeUnavailable { mode: Mode, reason: String },
}
