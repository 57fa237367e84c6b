//! The fisheye camera: OpenCV's `fisheye` (equidistant, Kannala-Brandt) model, as the sensor's authors used it.
//!
//! The paper's intrinsics for a w x h frame are K = [[w, 0, w/2], [0, w, h/2], [0, 0, 1]] and
//! D = [-0.28, 0.07, 0, 0]. We place that principal point at the exact centre of the frame in our raw-px
//! convention (origin at the top-left pixel corner); OpenCV's origin is the top-left pixel centre, half a pixel
//! away, which is far below anything the estimator resolves.

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::Point2;

#[derive(Debug, Error, PartialEq)]
pub enum CameraError {
    #[error("camera frame size must be positive, got {width} x {height}")]
    EmptyFrame { width: u32, height: u32 },
    #[error("focal lengths must be finite and positive, got fx = {fx}, fy = {fy}")]
    BadFocalLength { fx: f64, fy: f64 },
    #[error("distortion coefficients must be finite, got {0:?}")]
    BadDistortion([f64; 4]),
    #[error("the distortion {0:?} folds the image over (theta_d is not increasing up to the frame's corners)")]
    NonMonotonicDistortion([f64; 4]),
}

/// Intrinsics as they appear in a sensor config: the calibration's frame size, focal lengths and principal point
/// in px, and the four fisheye coefficients k1..k4.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FisheyeIntrinsics {
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub distortion: [f64; 4],
}

impl FisheyeIntrinsics {
    /// The paper's model for a `width x height` frame.
    pub fn paper(width: u32, height: u32) -> Self {
        let w = f64::from(width);
        let h = f64::from(height);
        Self {
            width,
            height,
            fx: w,
            fy: w,
            cx: w / 2.0,
            cy: h / 2.0,
            distortion: [-0.28, 0.07, 0.0, 0.0],
        }
    }

    /// The same lens on a frame of another size (a webcam's lower modes scale the full sensor).
    pub fn scaled_to(&self, width: u32, height: u32) -> Self {
        let sx = f64::from(width) / f64::from(self.width);
        let sy = f64::from(height) / f64::from(self.height);
        Self {
            width,
            height,
            fx: self.fx * sx,
            fy: self.fy * sy,
            cx: self.cx * sx,
            cy: self.cy * sy,
            ..*self
        }
    }
}

/// An ideal pinhole camera: the rectified ("undistorted px") view.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PinholeCamera {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

impl PinholeCamera {
    pub fn normalized_to_px(&self, n: Point2) -> Point2 {
        [self.fx * n[0] + self.cx, self.fy * n[1] + self.cy]
    }

    pub fn px_to_normalized(&self, p: Point2) -> Point2 {
        [(p[0] - self.cx) / self.fx, (p[1] - self.cy) / self.fy]
    }
}

/// A calibrated fisheye camera together with its rectified pinhole view.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FisheyeCamera {
    intrinsics: FisheyeIntrinsics,
    rectified: PinholeCamera,
}

const NEWTON_ITERATIONS: usize = 20;
const NEWTON_TOLERANCE: f64 = 1e-12;

impl FisheyeCamera {
    pub fn new(intrinsics: FisheyeIntrinsics) -> Result<Self, CameraError> {
        let FisheyeIntrinsics {
            width,
            height,
            fx,
            fy,
            distortion,
            ..
        } = intrinsics;
        if width == 0 || height == 0 {
            return Err(CameraError::EmptyFrame { width, height });
        }
        let focal_ok = fx.is_finite() && fy.is_finite() && fx > 0.0 && fy > 0.0;
        let centre_ok = intrinsics.cx.is_finite() && intrinsics.cy.is_finite();
        if !(focal_ok && centre_ok) {
            return Err(CameraError::BadFocalLength { fx, fy });
        }
        if distortion.iter().any(|k| !k.is_finite()) {
            return Err(CameraError::BadDistortion(distortion));
        }
        let mut camera = Self {
            intrinsics,
            rectified: PinholeCamera {
                fx,
                fy,
                cx: intrinsics.cx,
                cy: intrinsics.cy,
            },
        };
        // Undistortion inverts theta_d(theta) by Newton's method, which is only meaningful where theta_d rises.
        let corner = camera.pixel_to_distorted_normalized([0.0, 0.0]);
        let theta_d_max = (corner[0].hypot(corner[1])).max({
            let c = camera.pixel_to_distorted_normalized([f64::from(width), f64::from(height)]);
            c[0].hypot(c[1])
        });
        if !camera.theta_d_increasing_up_to(theta_d_max) {
            return Err(CameraError::NonMonotonicDistortion(distortion));
        }
        camera.rectified = camera.new_camera_matrix(1.0);
        Ok(camera)
    }

    /// The paper's camera for a `width x height` frame.
    pub fn paper(width: u32, height: u32) -> Result<Self, CameraError> {
        Self::new(FisheyeIntrinsics::paper(width, height))
    }

    pub fn intrinsics(&self) -> &FisheyeIntrinsics {
        &self.intrinsics
    }

    pub fn width(&self) -> u32 {
        self.intrinsics.width
    }

    pub fn height(&self) -> u32 {
        self.intrinsics.height
    }

    /// The pinhole camera of the undistorted frame (balance 1: every raw pixel stays in view).
    pub fn rectified(&self) -> &PinholeCamera {
        &self.rectified
    }

    fn theta_d(&self, theta: f64) -> f64 {
        let [k1, k2, k3, k4] = self.intrinsics.distortion;
        let t2 = theta * theta;
        theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
    }

    fn theta_d_slope(&self, theta: f64) -> f64 {
        let [k1, k2, k3, k4] = self.intrinsics.distortion;
        let t2 = theta * theta;
        1.0 + t2 * (3.0 * k1 + t2 * (5.0 * k2 + t2 * (7.0 * k3 + t2 * 9.0 * k4)))
    }

    fn theta_d_increasing_up_to(&self, theta_d_max: f64) -> bool {
        // Walk theta until theta_d passes the frame's corner; the slope must stay positive on the way.
        let mut theta = 0.0;
        while theta < std::f64::consts::FRAC_PI_2 {
            if self.theta_d_slope(theta) <= 0.0 {
                return false;
            }
            if self.theta_d(theta) > theta_d_max {
                return true;
            }
            theta += 1e-3;
        }
        // The whole frame lies within 90 degrees of the axis and theta_d never reached its corner: usable.
        true
    }

    fn pixel_to_distorted_normalized(&self, p: Point2) -> Point2 {
        let k = &self.intrinsics;
        [(p[0] - k.cx) / k.fx, (p[1] - k.cy) / k.fy]
    }

    /// Applies the fisheye distortion to a normalised pinhole point (x/z, y/z).
    pub fn distort_normalized(&self, n: Point2) -> Point2 {
        let r = n[0].hypot(n[1]);
        if r < 1e-12 {
            return n;
        }
        let scale = self.theta_d(r.atan()) / r;
        [n[0] * scale, n[1] * scale]
    }

    /// Inverts [`Self::distort_normalized`]; `None` where the model has no inverse (beyond 90 degrees).
    pub fn undistort_normalized(&self, d: Point2) -> Option<Point2> {
        let theta_d = d[0].hypot(d[1]);
        if !theta_d.is_finite() {
            return None;
        }
        if theta_d < 1e-12 {
            return Some(d);
        }
        let mut theta = theta_d;
        let mut converged = false;
        for _ in 0..NEWTON_ITERATIONS {
            let step = (self.theta_d(theta) - theta_d) / self.theta_d_slope(theta);
            theta -= step;
            if step.abs() < NEWTON_TOLERANCE {
                converged = true;
                break;
            }
        }
        if !converged || !(0.0..std::f64::consts::FRAC_PI_2).contains(&theta) {
            return None;
        }
        let scale = theta.tan() / theta_d;
        Some([d[0] * scale, d[1] * scale])
    }

    /// A point in camera coordinates (z along the optical axis, towards the pad) to raw px.
    pub fn project(&self, p: [f64; 3]) -> Option<Point2> {
        if !(p[2] > 0.0) {
            return None;
        }
        Some(self.normalized_to_raw([p[0] / p[2], p[1] / p[2]]))
    }

    pub fn normalized_to_raw(&self, n: Point2) -> Point2 {
        let d = self.distort_normalized(n);
        let k = &self.intrinsics;
        [k.fx * d[0] + k.cx, k.fy * d[1] + k.cy]
    }

    pub fn raw_to_normalized(&self, p: Point2) -> Option<Point2> {
        self.undistort_normalized(self.pixel_to_distorted_normalized(p))
    }

    /// Raw px to undistorted px.
    pub fn undistort_px(&self, p: Point2) -> Option<Point2> {
        self.raw_to_normalized(p).map(|n| self.rectified.normalized_to_px(n))
    }

    /// Undistorted px to raw px.
    pub fn distort_px(&self, p: Point2) -> Point2 {
        self.normalized_to_raw(self.rectified.px_to_normalized(p))
    }

    /// OpenCV's `fisheye::estimateNewCameraMatrixForUndistortRectify` with R = I, the same output size and
    /// fov_scale 1: a pinhole camera whose view keeps the four edge midpoints of the raw frame in view
    /// (balance 1) or crops to them (balance 0).
    pub fn new_camera_matrix(&self, balance: f64) -> PinholeCamera {
        let balance = balance.clamp(0.0, 1.0);
        let w = f64::from(self.intrinsics.width);
        let h = f64::from(self.intrinsics.height);
        let edge_midpoints = [[w / 2.0, 0.0], [w, h / 2.0], [w / 2.0, h], [0.0, h / 2.0]];
        let aspect = self.intrinsics.fx / self.intrinsics.fy;
        let undistorted: Vec<Point2> = edge_midpoints
            .iter()
            .map(|&p| {
                let n = self
                    .raw_to_normalized(p)
                    .unwrap_or(self.pixel_to_distorted_normalized(p));
                [n[0], n[1] * aspect]
            })
            .collect();
        let centre = [
            undistorted.iter().map(|p| p[0]).sum::<f64>() / 4.0,
            undistorted.iter().map(|p| p[1]).sum::<f64>() / 4.0,
        ];
        let (mut min_x, mut max_x, mut min_y, mut max_y) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for p in &undistorted {
            min_x = min_x.min(p[0]);
            max_x = max_x.max(p[0]);
            min_y = min_y.min(p[1]);
            max_y = max_y.max(p[1]);
        }
        let candidates = [
            w * 0.5 / (centre[0] - min_x),
            w * 0.5 / (max_x - centre[0]),
            h * 0.5 / (centre[1] - min_y),
            h * 0.5 / (max_y - centre[1]),
        ];
        let f_min = candidates.iter().copied().fold(f64::MAX, f64::min);
        let f_max = candidates.iter().copied().fold(f64::MIN, f64::max);
        let f = balance * f_min + (1.0 - balance) * f_max;
        PinholeCamera {
            fx: f,
            fy: f / aspect,
            cx: -centre[0] * f + w * 0.5,
            cy: (-centre[1] * f + h * 0.5) / aspect,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn paper() -> FisheyeCamera {
        FisheyeCamera::paper(2048, 1536).unwrap()
    }

    #[test]
    fn principal_point_is_fixed() {
        let cam = paper();
        let c = cam.undistort_px([1024.0, 768.0]).unwrap();
        assert!((c[0] - 1024.0).abs() < 1e-9 && (c[1] - 768.0).abs() < 1e-9, "{c:?}");
    }

    #[test]
    fn balance_one_keeps_edge_midpoints_in_frame() {
        // With balance 1 the tightest of the four edge midpoints lands exactly on its frame edge, the others inside.
        let cam = paper();
        let edges = [[1024.0, 0.0], [2048.0, 768.0], [1024.0, 1536.0], [0.0, 768.0]];
        let mapped: Vec<Point2> = edges.iter().map(|&p| cam.undistort_px(p).unwrap()).collect();
        for p in &mapped {
            assert!(
                p[0] >= -1e-6 && p[0] <= 2048.0 + 1e-6 && p[1] >= -1e-6 && p[1] <= 1536.0 + 1e-6,
                "{p:?}"
            );
        }
        let on_edge = mapped
            .iter()
            .filter(|p| p[0].abs() < 1e-6 || (p[0] - 2048.0).abs() < 1e-6)
            .count()
            + mapped
                .iter()
                .filter(|p| p[1].abs() < 1e-6 || (p[1] - 1536.0).abs() < 1e-6)
                .count();
        assert!(on_edge >= 2, "{mapped:?}");
        // Barrel distortion: undistortion pushes points outward, so the rectified focal length is below fx.
        assert!(cam.rectified().fx < 2048.0);
    }

    #[test]
    fn known_forward_value() {
        // theta = atan(0.5); theta_d = theta (1 - 0.28 theta^2 + 0.07 theta^4), computed by hand.
        let cam = paper();
        let theta: f64 = 0.5f64.atan();
        let theta_d = theta * (1.0 - 0.28 * theta.powi(2) + 0.07 * theta.powi(4));
        let d = cam.distort_normalized([0.5, 0.0]);
        assert!((d[0] - theta_d).abs() < 1e-15);
    }

    #[test]
    fn rejects_folding_distortion() {
        let mut k = FisheyeIntrinsics::paper(640, 480);
        k.distortion = [-2.0, 0.0, 0.0, 0.0];
        assert!(matches!(
            FisheyeCamera::new(k),
            Err(CameraError::NonMonotonicDistortion(_))
        ));
        k.distortion = [f64::NAN, 0.0, 0.0, 0.0];
        assert!(matches!(FisheyeCamera::new(k), Err(CameraError::BadDistortion(_))));
        assert!(FisheyeCamera::new(FisheyeIntrinsics {
            width: 0,
            ..FisheyeIntrinsics::paper(640, 480)
        })
        .is_err());
    }

    #[test]
    fn scaled_lens_agrees_with_paper_model() {
        let full = FisheyeIntrinsics::paper(2048, 1536);
        assert_eq!(full.scaled_to(1024, 768), FisheyeIntrinsics::paper(1024, 768));
    }

    proptest! {
        #[test]
        fn raw_undistorted_round_trip(x in 0.0f64..2048.0, y in 0.0f64..1536.0) {
            let cam = paper();
            let u = cam.undistort_px([x, y]).unwrap();
            let back = cam.distort_px(u);
            prop_assert!((back[0] - x).abs() < 1e-7 && (back[1] - y).abs() < 1e-7, "{:?} -> {:?} -> {:?}", [x, y], u, back);
        }

        #[test]
        fn project_then_unproject(x in -0.6f64..0.6, y in -0.45f64..0.45) {
            let cam = paper();
            let raw = cam.project([x * 10.0, y * 10.0, 10.0]).unwrap();
            let n = cam.raw_to_normalized(raw).unwrap();
            prop_assert!((n[0] - x).abs() < 1e-9 && (n[1] - y).abs() < 1e-9);
        }
    }
}
