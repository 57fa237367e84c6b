//! Camera lenses the simulator can image the pad through.
//!
//! [`Lens::KannalaBrandt`] is the paper's model (OpenCV's `fisheye`), the one the estimator assumes by default.
//! [`Lens::Equisolid`] is another fisheye design, r = 2 f sin(theta / 2), with a radial polynomial and Brown-Conrady
//! decentring terms and an off-centre principal point: no Kannala-Brandt coefficients reproduce it exactly, so
//! frames through it test an estimator's lens-independence.

use nusense_geometry::camera::FisheyeIntrinsics;
use nusense_geometry::{CameraError, FisheyeCamera, Point2};
use serde::{Deserialize, Serialize};

/// An equisolid-angle fisheye with radial and decentring distortion.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EquisolidLens {
    pub width: u32,
    pub height: u32,
    /// Focal length along x, px.
    pub f_px: f64,
    /// fy / fx.
    pub aspect: f64,
    pub cx: f64,
    pub cy: f64,
    /// k1, k2 of (1 + k1 r^2 + k2 r^4) on the equisolid radius r (in focal lengths).
    pub radial: [f64; 2],
    /// Brown-Conrady p1, p2 (a lens element off the axis).
    pub decentring: [f64; 2],
}

impl EquisolidLens {
    /// A lens of about the paper's field of view on a `width x height` frame, decentred and off-centre: radial
    /// -0.04, decentring (1.5e-3, -1e-3), principal point 1.5 % right and 1 % down of the centre, aspect 1.004.
    pub fn decentred(width: u32, height: u32) -> Self {
        let (w, h) = (f64::from(width), f64::from(height));
        Self {
            width,
            height,
            f_px: 0.98 * w,
            aspect: 1.004,
            cx: 0.515 * w,
            cy: 0.51 * h,
            radial: [-0.04, 0.0],
            decentring: [1.5e-3, -1.0e-3],
        }
    }

    /// Equisolid radius (focal lengths) to distorted normalised image coordinates.
    fn distort(&self, e: Point2) -> Point2 {
        let [x, y] = e;
        let r2 = x * x + y * y;
        let [k1, k2] = self.radial;
        let [p1, p2] = self.decentring;
        let s = 1.0 + r2 * (k1 + r2 * k2);
        [
            x * s + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
            y * s + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
        ]
    }

    fn project(&self, p: [f64; 3]) -> Option<Point2> {
        let rho = p[0].hypot(p[1]);
        let theta = rho.atan2(p[2]);
        if !(theta.is_finite() && theta < std::f64::consts::FRAC_PI_2) {
            return None;
        }
        let r = 2.0 * (theta / 2.0).sin();
        let e = if rho > 0.0 {
            [r * p[0] / rho, r * p[1] / rho]
        } else {
            [0.0, 0.0]
        };
        let d = self.distort(e);
        Some([self.f_px * d[0] + self.cx, self.f_px * self.aspect * d[1] + self.cy])
    }

    /// Normalised pinhole coordinates (x / z, y / z) of the ray through `px`.
    fn unproject(&self, px: Point2) -> Option<Point2> {
        let target = [
            (px[0] - self.cx) / self.f_px,
            (px[1] - self.cy) / (self.f_px * self.aspect),
        ];
        // Newton on the distortion (a small perturbation of the identity), Jacobian by central differences.
        let mut e = target;
        for _ in 0..20 {
            let d = self.distort(e);
            let residual = [d[0] - target[0], d[1] - target[1]];
            if residual[0].hypot(residual[1]) < 1e-14 {
                break;
            }
            let h = 1e-7;
            let dx = self.distort([e[0] + h, e[1]]);
            let dxm = self.distort([e[0] - h, e[1]]);
            let dy = self.distort([e[0], e[1] + h]);
            let dym = self.distort([e[0], e[1] - h]);
            let j = [
                [(dx[0] - dxm[0]) / (2.0 * h), (dy[0] - dym[0]) / (2.0 * h)],
                [(dx[1] - dxm[1]) / (2.0 * h), (dy[1] - dym[1]) / (2.0 * h)],
            ];
            let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
            // A NaN determinant is as singular as a zero one.
            if !det.is_finite() || det.abs() <= 1e-12 {
                return None;
            }
            e[0] -= (j[1][1] * residual[0] - j[0][1] * residual[1]) / det;
            e[1] -= (-j[1][0] * residual[0] + j[0][0] * residual[1]) / det;
        }
        let r = e[0].hypot(e[1]);
        if !(r.is_finite() && r < std::f64::consts::SQRT_2) {
            return None;
        }
        let theta = 2.0 * (r / 2.0).asin();
        if r < 1e-15 {
            return Some([0.0, 0.0]);
        }
        let scale = theta.tan() / r;
        Some([e[0] * scale, e[1] * scale])
    }
}

/// The lens of a simulated camera, as a sensor model stores it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Lens {
    /// OpenCV's fisheye model (equidistant, Kannala-Brandt), as the paper calibrated it.
    KannalaBrandt(FisheyeIntrinsics),
    Equisolid(EquisolidLens),
}

impl Lens {
    pub fn size(&self) -> (u32, u32) {
        match self {
            Lens::KannalaBrandt(k) => (k.width, k.height),
            Lens::Equisolid(e) => (e.width, e.height),
        }
    }

    /// The principal point, px (vignetting is centred there).
    pub fn principal_point(&self) -> Point2 {
        match self {
            Lens::KannalaBrandt(k) => [k.cx, k.cy],
            Lens::Equisolid(e) => [e.cx, e.cy],
        }
    }
}

/// A lens ready to project.
#[derive(Clone, Debug)]
pub enum Camera {
    KannalaBrandt(FisheyeCamera),
    Equisolid(EquisolidLens),
}

impl Camera {
    pub fn new(lens: &Lens) -> Result<Self, CameraError> {
        match lens {
            Lens::KannalaBrandt(k) => Ok(Self::KannalaBrandt(FisheyeCamera::new(*k)?)),
            Lens::Equisolid(e) => {
                if e.width == 0 || e.height == 0 {
                    return Err(CameraError::EmptyFrame {
                        width: e.width,
                        height: e.height,
                    });
                }
                let finite = [e.f_px, e.aspect, e.cx, e.cy].iter().all(|v| v.is_finite());
                if !(finite && e.f_px > 0.0 && e.aspect > 0.0) {
                    return Err(CameraError::BadFocalLength {
                        fx: e.f_px,
                        fy: e.f_px * e.aspect,
                    });
                }
                let d = [e.radial[0], e.radial[1], e.decentring[0], e.decentring[1]];
                if d.iter().any(|v| !v.is_finite()) {
                    return Err(CameraError::BadDistortion(d));
                }
                Ok(Self::Equisolid(*e))
            }
        }
    }

    /// A point in camera coordinates (z along the optical axis) to raw px.
    pub fn project(&self, p: [f64; 3]) -> Option<Point2> {
        match self {
            Camera::KannalaBrandt(c) => c.project(p),
            Camera::Equisolid(e) => e.project(p),
        }
    }

    /// Raw px to normalised pinhole coordinates of its ray.
    pub fn raw_to_normalized(&self, px: Point2) -> Option<Point2> {
        match self {
            Camera::KannalaBrandt(c) => c.raw_to_normalized(px),
            Camera::Equisolid(e) => e.unproject(px),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equisolid_projection_round_trips_and_is_not_the_paper_lens() {
        let lens = EquisolidLens::decentred(2048, 1536);
        let camera = Camera::new(&Lens::Equisolid(lens)).unwrap();
        for n in [[0.0, 0.0], [0.3, -0.2], [-0.45, 0.35], [0.05, 0.4]] {
            let px = camera.project([n[0] * 50.0, n[1] * 50.0, 50.0]).unwrap();
            let back = camera.raw_to_normalized(px).unwrap();
            assert!(
                (back[0] - n[0]).abs() < 1e-9 && (back[1] - n[1]).abs() < 1e-9,
                "{n:?} -> {px:?} -> {back:?}"
            );
        }
        // On the axis: the principal point; a ray at 30 degrees along +x lands at r = 2 f sin(15 deg) (1 - 0.04 r^2)
        // plus the decentring p2 (r^2 + 2 r^2) = 3 p2 r^2 along x and p1 r^2 along y.
        let centre = camera.project([0.0, 0.0, 1.0]).unwrap();
        assert_eq!(centre, [lens.cx, lens.cy]);
        let r = 2.0 * 15f64.to_radians().sin();
        let px = camera.project([30f64.to_radians().tan(), 0.0, 1.0]).unwrap();
        let x = r * (1.0 - 0.04 * r * r) + 3.0 * -1.0e-3 * r * r;
        let y = 1.5e-3 * r * r;
        assert!((px[0] - (lens.cx + lens.f_px * x)).abs() < 1e-9, "{px:?}");
        assert!((px[1] - (lens.cy + lens.f_px * lens.aspect * y)).abs() < 1e-9, "{px:?}");
    }
}
