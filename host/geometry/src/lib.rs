//! Geometry shared by the estimator and the simulator, so that both speak one convention:
//!
//! - raw px: the frame as captured, x right, y down, origin at the top-left pixel *corner*;
//! - undistorted px: after the fisheye model, in the rectified camera of
//!   [`FisheyeCamera::rectified`] (OpenCV's `estimateNewCameraMatrixForUndistortRectify`, balance 1);
//! - pad mm: origin at the pad centre, x right and y down as the camera sees it.
//!
//! Pixel *centres* sit at half-integer raw px; image loops that index pixel (i, j) must add 0.5.

pub mod camera;
pub mod lattice;
pub mod similarity;

pub use camera::{CameraError, FisheyeCamera, PinholeCamera};
pub use lattice::{CornerIndex, PadGeometry, SquareIndex};
pub use similarity::Similarity;

/// A 2-D point or vector in whichever frame the context names.
pub type Point2 = [f64; 2];
