//! From raw px to the two other frames: undistorted px (the configured fisheye model, points only) and pad mm.
//!
//! Pad mm come from a per-sensor map fitted on a rest frame's lattice, whose corners sit on a known grid (the
//! pattern's pitch, 3.3125 mm): undistorted px -> a smooth lens correction (a cubic polynomial warp, for where the
//! real lens differs from the configured fisheye model) -> a homography (the pad plane's pose). The fit's residual
//! against the grid says how well the map holds. `nusense calibrate` stores the lens correction in the sensor
//! config ([`StoredPadMap`]); a rest frame then only re-fits the pose, so the correction comes from a frame known
//! to be at rest and the pose follows the camera whenever the sensor is tared again.
//!
//! Gamma is a sum of pixel distances, so its value depends on the frame's resolution. The paper's alpha was chosen
//! for 2048-px-wide frames; we therefore measure surfaces in "paper px": undistorted px multiplied by
//! 2048 / frame width. At full resolution paper px and undistorted px coincide, and at 1/2 or 1/4 resolution the
//! same touch gives the same gamma and force.

use nalgebra::{DMatrix, DVector, Vector3};
use nusense_geometry::{FisheyeCamera, PadGeometry, Point2};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::config::SensorConfig;
use crate::elastic::CameraView;
use crate::error::EstimateError;
use crate::homography::Homography;

/// Frame width the paper's alpha (and so gamma's unit) refers to.
pub const PAPER_FRAME_WIDTH: f64 = 2048.0;

/// Terms of the lens correction per axis: every monomial of degree 2 and 3 in the normalised undistorted
/// coordinates (degrees 0 and 1 belong to the homography).
const CORRECTION_TERMS: usize = 7;
/// A map needs this many corners: the homography's 8 and the correction's 14 unknowns with room to judge them.
pub const MIN_MAP_POINTS: usize = 30;
/// Gauss-Newton steps of the joint fit (it converges in three or four from the homography alone).
const FIT_ITERATIONS: usize = 8;
/// Newton steps and tolerance (in units of the normalisation scale) of the correction's inverse.
const INVERT_ITERATIONS: usize = 20;
const INVERT_TOLERANCE: f64 = 1e-12;
/// Halvings of a Gauss-Newton step tried before the fit stops where it is.
const STEP_HALVINGS: usize = 30;
/// Corners further than this many robust sigmas from the fit are left out of it (a corner mis-found at tare)...
const OUTLIER_SIGMAS: f64 = 5.0;
/// ...and never closer than this, mm (a printed pattern is not more exact than this).
const OUTLIER_FLOOR_MM: f64 = 0.05;

fn monomials(p: Point2) -> [f64; CORRECTION_TERMS] {
    let [x, y] = p;
    [x * x, x * y, y * y, x * x * x, x * x * y, x * y * y, y * y * y]
}

/// A smooth warp of undistorted px, in coordinates normalised by a centre and a scale.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LensCorrection {
    /// Centre of the normalisation, undistorted px.
    pub centre_px: Point2,
    /// Scale of the normalisation, undistorted px.
    pub scale_px: f64,
    /// Coefficients of x^2, xy, y^2, x^3, x^2 y, x y^2, y^3 for the x and the y shift (normalised units).
    pub x: [f64; CORRECTION_TERMS],
    pub y: [f64; CORRECTION_TERMS],
}

impl LensCorrection {
    fn none(centre_px: Point2, scale_px: f64) -> Self {
        Self {
            centre_px,
            scale_px,
            x: [0.0; CORRECTION_TERMS],
            y: [0.0; CORRECTION_TERMS],
        }
    }

    fn normalise(&self, p: Point2) -> Point2 {
        [
            (p[0] - self.centre_px[0]) / self.scale_px,
            (p[1] - self.centre_px[1]) / self.scale_px,
        ]
    }

    /// Undistorted px to corrected px.
    pub fn apply(&self, p: Point2) -> Point2 {
        let m = monomials(self.normalise(p));
        let dx: f64 = m.iter().zip(&self.x).map(|(a, b)| a * b).sum();
        let dy: f64 = m.iter().zip(&self.y).map(|(a, b)| a * b).sum();
        [p[0] + dx * self.scale_px, p[1] + dy * self.scale_px]
    }

    /// Corrected px back to undistorted px, by Newton's method from `q` itself (the warp is a small, smooth
    /// shift); `None` where it does not converge (far outside the region the warp was fitted on).
    pub fn invert(&self, q: Point2) -> Option<Point2> {
        let mut p = q;
        for _ in 0..INVERT_ITERATIONS {
            let a = self.apply(p);
            let (ex, ey) = (a[0] - q[0], a[1] - q[1]);
            if ex.hypot(ey) <= INVERT_TOLERANCE * self.scale_px {
                return Some(p);
            }
            let [x, y] = self.normalise(p);
            let d_dx = [2.0 * x, y, 0.0, 3.0 * x * x, 2.0 * x * y, y * y, 0.0];
            let d_dy = [0.0, x, 2.0 * y, 0.0, x * x, 2.0 * x * y, 3.0 * y * y];
            let along = |coefficients: &[f64; CORRECTION_TERMS], d: &[f64; CORRECTION_TERMS]| -> f64 {
                coefficients.iter().zip(d).map(|(c, d)| c * d).sum()
            };
            let (j00, j01) = (1.0 + along(&self.x, &d_dx), along(&self.x, &d_dy));
            let (j10, j11) = (along(&self.y, &d_dx), 1.0 + along(&self.y, &d_dy));
            let det = j00 * j11 - j01 * j10;
            if !(det.abs() > 1e-12) {
                return None;
            }
            p = [p[0] - (j11 * ex - j01 * ey) / det, p[1] - (j00 * ey - j10 * ex) / det];
            if !(p[0].is_finite() && p[1].is_finite()) {
                return None;
            }
        }
        let a = self.apply(p);
        ((a[0] - q[0]).hypot(a[1] - q[1]) <= INVERT_TOLERANCE * self.scale_px).then_some(p)
    }

    /// The same warp for a frame `factor` times as wide (the lens scaled with the frame).
    fn scaled(&self, factor: f64) -> Self {
        Self {
            centre_px: [self.centre_px[0] * factor, self.centre_px[1] * factor],
            scale_px: self.scale_px * factor,
            ..*self
        }
    }
}

/// How well a map puts a rest frame's corners on the known grid.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MapResidual {
    pub rms_mm: f64,
    pub max_mm: f64,
    /// Corners the fit rests on.
    pub points: usize,
    /// Corners left out as outliers.
    pub outliers: usize,
}

/// What `nusense calibrate` writes into the sensor config's `[pad_map]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct StoredPadMap {
    /// Frame size the map was fitted on; other sizes scale it like the lens.
    pub width: u32,
    pub height: u32,
    pub correction: LensCorrection,
    /// Corrected undistorted px -> pad mm at calibration (row-major 3 x 3); each rest frame re-fits it.
    pub homography: [f64; 9],
    pub residual: MapResidual,
}

impl StoredPadMap {
    pub fn validate(&self) -> Result<(), String> {
        let finite = self
            .homography
            .iter()
            .chain(&self.correction.x)
            .chain(&self.correction.y)
            .all(|v| v.is_finite())
            && self.correction.centre_px.iter().all(|v| v.is_finite())
            && self.correction.scale_px.is_finite()
            && self.correction.scale_px > 0.0;
        if !finite {
            return Err("non-finite or non-positive numbers".into());
        }
        if self.width == 0 || self.height == 0 {
            return Err(format!("frame size {} x {}", self.width, self.height));
        }
        Ok(())
    }
}

#[derive(Clone, Debug)]
pub struct PadMapping {
    camera: FisheyeCamera,
    correction: LensCorrection,
    to_mm: Homography,
    to_corrected: Homography,
    paper_scale: f64,
    residual: MapResidual,
}

/// The config's lens scaled to a frame of `width x height`.
pub fn camera_for(config: &SensorConfig, width: u32, height: u32) -> Result<FisheyeCamera, EstimateError> {
    Ok(FisheyeCamera::new(config.camera.scaled_to(width, height))?)
}

impl PadMapping {
    /// Fits the map to a rest frame's corners (`reference_undistorted` in `corner_slot` order). With `stored`, its
    /// lens correction is kept and only the pose is fitted.
    pub fn fit(
        camera: FisheyeCamera,
        pad: &PadGeometry,
        reference_undistorted: &[Option<Point2>],
        stored: Option<&StoredPadMap>,
    ) -> Result<Self, EstimateError> {
        let (mut from, mut to) = (Vec::new(), Vec::new());
        for (index, p) in pad.corners().zip(reference_undistorted) {
            if let Some(p) = p {
                from.push(*p);
                to.push(pad.corner_mm(index));
            }
        }
        let needed = if stored.is_some() { 8 } else { MIN_MAP_POINTS };
        if from.len() < needed {
            return Err(EstimateError::TooFewPoints {
                found: from.len(),
                needed,
            });
        }
        let degenerate = || EstimateError::NoPattern {
            reason: "the reference corners are degenerate (collinear)".into(),
        };
        let frame_scale = |stored: &StoredPadMap| f64::from(camera.width()) / f64::from(stored.width);
        let (correction, to_mm, used) = match stored {
            Some(s) => {
                let correction = s.correction.scaled(frame_scale(s));
                let corrected: Vec<Point2> = from.iter().map(|&p| correction.apply(p)).collect();
                let used = robust_subset(&corrected, &to, |c, t| {
                    Homography::fit(c, t).map(|h| Box::new(move |p| h.apply(p)) as Mapper)
                })
                .ok_or_else(degenerate)?;
                let (c, t) = select(&corrected, &to, &used);
                (correction, Homography::fit(&c, &t).ok_or_else(degenerate)?, used)
            }
            None => {
                let used = robust_subset(&from, &to, |f, t| {
                    fit_joint(f, t).map(|(c, h)| Box::new(move |p| h.apply(c.apply(p))) as Mapper)
                })
                .ok_or_else(degenerate)?;
                let (f, t) = select(&from, &to, &used);
                let (correction, to_mm) = fit_joint(&f, &t).ok_or_else(degenerate)?;
                (correction, to_mm, used)
            }
        };
        let to_corrected = to_mm.inverse().ok_or_else(degenerate)?;
        let paper_scale = PAPER_FRAME_WIDTH / f64::from(camera.width());
        let mut mapping = Self {
            camera,
            correction,
            to_mm,
            to_corrected,
            paper_scale,
            residual: MapResidual {
                rms_mm: 0.0,
                max_mm: 0.0,
                points: 0,
                outliers: 0,
            },
        };
        let errors: Vec<f64> = from
            .iter()
            .zip(&to)
            .zip(&used)
            .filter(|(_, &u)| u)
            .filter_map(|((&p, &t), _)| mapping.undistorted_to_mm(p).map(|m| (m[0] - t[0]).hypot(m[1] - t[1])))
            .collect();
        mapping.residual = MapResidual {
            rms_mm: (errors.iter().map(|e| e * e).sum::<f64>() / errors.len().max(1) as f64).sqrt(),
            max_mm: errors.iter().copied().fold(0.0, f64::max),
            points: errors.len(),
            outliers: used.iter().filter(|&&u| !u).count(),
        };
        Ok(mapping)
    }

    /// The map as `nusense calibrate` stores it.
    pub fn stored(&self) -> StoredPadMap {
        StoredPadMap {
            width: self.camera.width(),
            height: self.camera.height(),
            correction: self.correction,
            homography: self.to_mm.matrix(),
            residual: self.residual,
        }
    }

    pub fn residual(&self) -> MapResidual {
        self.residual
    }

    pub fn camera(&self) -> &FisheyeCamera {
        &self.camera
    }

    pub fn undistort(&self, raw: Point2) -> Option<Point2> {
        self.camera
            .undistort_px(raw)
            .filter(|p| p[0].is_finite() && p[1].is_finite())
    }

    pub fn distort(&self, undistorted: Point2) -> Option<Point2> {
        let p = self.camera.distort_px(undistorted);
        (p[0].is_finite() && p[1].is_finite()).then_some(p)
    }

    pub fn undistorted_to_mm(&self, p: Point2) -> Option<Point2> {
        self.to_mm.apply(self.correction.apply(p))
    }

    pub fn mm_to_undistorted(&self, p: Point2) -> Option<Point2> {
        let q = self.correction.invert(self.to_corrected.apply(p)?)?;
        (q[0].is_finite() && q[1].is_finite()).then_some(q)
    }

    /// Where the camera is against the pattern's plane, from the pose part of the map (the homography of pad mm to
    /// the corrected undistorted px) and the configured lens's pinhole: H = K [r1 r2 t] up to scale, and the
    /// camera's centre is -Rᵀt. Through the plate and the gel the height is the apparent one (a few % short of the
    /// true distance), and a lens whose focal length differs from the configured one scales it.
    pub fn camera_view(&self) -> Option<CameraView> {
        let h = self.to_corrected.matrix();
        let k = self.camera.rectified();
        // K^-1 applied to each column of H.
        let column = |c: usize| {
            let (x, y, w) = (h[c], h[3 + c], h[6 + c]);
            Vector3::new((x - k.cx * w) / k.fx, (y - k.cy * w) / k.fy, w)
        };
        let (m1, m2, m3) = (column(0), column(1), column(2));
        let mut scale = 2.0 / (m1.norm() + m2.norm());
        // The pattern lies in front of the camera.
        if m3.z * scale < 0.0 {
            scale = -scale;
        }
        let (r1, r2, t) = (m1 * scale, m2 * scale, m3 * scale);
        let view = CameraView {
            foot_mm: [-r1.dot(&t), -r2.dot(&t)],
            height_mm: r1.cross(&r2).dot(&t).abs(),
        };
        (view.foot_mm.iter().all(|v| v.is_finite()) && view.height_mm.is_finite() && view.height_mm > 0.0)
            .then_some(view)
    }

    /// Pad mm per raw px at the pad's centre (the mean of the two axes).
    pub fn mm_per_px_at_centre(&self) -> Option<f64> {
        let centre = self.mm_to_raw([0.0, 0.0])?;
        let at = |dx: f64, dy: f64| self.raw_to_mm([centre[0] + dx, centre[1] + dy]);
        let (o, x, y) = (at(0.0, 0.0)?, at(1.0, 0.0)?, at(0.0, 1.0)?);
        let scale = 0.5 * ((x[0] - o[0]).hypot(x[1] - o[1]) + (y[0] - o[0]).hypot(y[1] - o[1]));
        (scale.is_finite() && scale > 0.0).then_some(scale)
    }

    pub fn raw_to_mm(&self, raw: Point2) -> Option<Point2> {
        self.undistorted_to_mm(self.undistort(raw)?)
    }

    pub fn mm_to_raw(&self, mm: Point2) -> Option<Point2> {
        self.distort(self.mm_to_undistorted(mm)?)
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

/// A fitted map, asked for its error at each point by the outlier pass.
type Mapper = Box<dyn Fn(Point2) -> Option<Point2>>;

/// Which points to keep: fit, drop those beyond `OUTLIER_SIGMAS` robust sigmas, fit the rest again and judge every
/// point against that fit, until the set stops changing (an outlier pulls a flexible fit towards itself, so its
/// neighbours look wrong only until it is left out).
fn robust_subset(
    from: &[Point2],
    to: &[Point2],
    fit: impl Fn(&[Point2], &[Point2]) -> Option<Mapper>,
) -> Option<Vec<bool>> {
    let mut used = vec![true; from.len()];
    for _ in 0..4 {
        let (f, t) = select(from, to, &used);
        let map = fit(&f, &t)?;
        let errors: Vec<f64> = from
            .iter()
            .zip(to)
            .map(|(&p, t)| map(p).map_or(f64::INFINITY, |m| (m[0] - t[0]).hypot(m[1] - t[1])))
            .collect();
        let mut sorted: Vec<f64> = errors
            .iter()
            .zip(&used)
            .filter(|(e, &u)| u && e.is_finite())
            .map(|(e, _)| *e)
            .collect();
        if sorted.is_empty() {
            return None;
        }
        sorted.sort_unstable_by(f64::total_cmp);
        // Median of a 2-D Gaussian error's length is 1.18 sigma.
        let sigma = sorted[sorted.len() / 2] / 1.177_4;
        let limit = (OUTLIER_SIGMAS * sigma).max(OUTLIER_FLOOR_MM);
        let next: Vec<bool> = errors.iter().map(|&e| e <= limit).collect();
        if next == used {
            break;
        }
        used = next;
    }
    Some(used)
}

fn select(from: &[Point2], to: &[Point2], used: &[bool]) -> (Vec<Point2>, Vec<Point2>) {
    from.iter()
        .zip(to)
        .zip(used)
        .filter(|(_, &u)| u)
        .map(|((f, t), _)| (*f, *t))
        .unzip()
}

/// Lens correction and homography together, by Gauss-Newton from the homography alone.
fn fit_joint(from: &[Point2], to: &[Point2]) -> Option<(LensCorrection, Homography)> {
    if from.len() < MIN_MAP_POINTS {
        return None;
    }
    let n = from.len() as f64;
    let centre = [
        from.iter().map(|p| p[0]).sum::<f64>() / n,
        from.iter().map(|p| p[1]).sum::<f64>() / n,
    ];
    let scale = (from
        .iter()
        .map(|p| (p[0] - centre[0]).powi(2) + (p[1] - centre[1]).powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    if !(scale > 0.0) {
        return None;
    }
    let mut correction = LensCorrection::none(centre, scale);
    let mut h = Homography::fit(from, to)?;
    let unknowns = 8 + 2 * CORRECTION_TERMS;
    for _ in 0..FIT_ITERATIONS {
        let residual = |c: &LensCorrection, h: &Homography| -> Option<DVector<f64>> {
            let mut r = DVector::zeros(2 * from.len());
            for (i, (&p, t)) in from.iter().zip(to).enumerate() {
                let m = h.apply(c.apply(p))?;
                r[2 * i] = m[0] - t[0];
                r[2 * i + 1] = m[1] - t[1];
            }
            Some(r)
        };
        let r0 = residual(&correction, &h)?;
        // Forward differences on the parameters: 8 of the homography (h22 fixed at 1), 14 of the correction.
        let mut jacobian = DMatrix::zeros(2 * from.len(), unknowns);
        for k in 0..unknowns {
            let (mut c, mut hh) = (correction, h.matrix());
            let step = if k < 8 { 1e-7 * hh[k].abs().max(1e-3) } else { 1e-7 };
            if k < 8 {
                hh[k] += step;
            } else if k < 8 + CORRECTION_TERMS {
                c.x[k - 8] += step;
            } else {
                c.y[k - 8 - CORRECTION_TERMS] += step;
            }
            let r = residual(&c, &Homography::from_matrix(hh)?)?;
            jacobian.set_column(k, &((r - &r0) / step));
        }
        // The quadratic terms and the homography's perspective row overlap (both bend lines): a relative cut-off
        // on the singular values takes the minimum-norm step along that direction instead of a huge one.
        let svd = jacobian.svd(true, true);
        let largest = svd.singular_values.max();
        let step = svd.solve(&(-&r0), 1e-10 * largest).ok()?;
        // Gauss-Newton overshoots when the start is far off (a coarse frame, a few poorly placed corners): take the
        // longest halving of the step that lowers the residual, so the fit never ends worse than the homography
        // it starts from.
        let cost = r0.norm_squared();
        let mut accepted = None;
        let mut length = 1.0;
        for _ in 0..STEP_HALVINGS {
            let mut hh = h.matrix();
            for k in 0..8 {
                hh[k] += length * step[k];
            }
            let mut c = correction;
            for k in 0..CORRECTION_TERMS {
                c.x[k] += length * step[8 + k];
                c.y[k] += length * step[8 + CORRECTION_TERMS + k];
            }
            if let Some(candidate) = Homography::from_matrix(hh) {
                if residual(&c, &candidate).is_some_and(|r| r.norm_squared() < cost) {
                    accepted = Some((c, candidate));
                    break;
                }
            }
            length *= 0.5;
        }
        let Some((c, candidate)) = accepted else { break };
        correction = c;
        h = candidate;
        if length * step.norm() < 1e-12 {
            break;
        }
    }
    Some((correction, h))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(pad: &PadGeometry) -> Vec<Point2> {
        pad.corners().map(|c| pad.corner_mm(c)).collect()
    }

    #[test]
    fn a_lens_the_fisheye_model_does_not_know_is_absorbed_by_the_correction() {
        let pad = PadGeometry::default();
        let camera = FisheyeCamera::paper(1024, 768).unwrap();
        // The "true" undistorted corners: a perspective view of the grid, then an extra barrel term the configured
        // model lacks (the real lens is not the paper's).
        let truth: Vec<Point2> = grid(&pad)
            .iter()
            .map(|p| {
                let (x, y) = (
                    512.0 + 12.0 * p[0] + 0.01 * p[0] * p[1],
                    384.0 + 12.2 * p[1] - 0.02 * p[0],
                );
                let w = 1.0 + 0.0008 * p[0] - 0.0005 * p[1];
                let (x, y) = (x / w, y / w);
                let r2 = ((x - 512.0).powi(2) + (y - 384.0).powi(2)) / 400.0f64.powi(2);
                [
                    512.0 + (x - 512.0) * (1.0 - 0.03 * r2),
                    384.0 + (y - 384.0) * (1.0 - 0.03 * r2),
                ]
            })
            .collect();
        let observed: Vec<Option<Point2>> = truth.iter().map(|&p| Some(p)).collect();
        let map = PadMapping::fit(camera, &pad, &observed, None).unwrap();
        let residual = map.residual();
        assert!(residual.rms_mm < 0.01 && residual.max_mm < 0.03, "{residual:?}");
        assert_eq!(residual.points, 165);
        // Round trip mm -> undistorted -> mm anywhere on the pad.
        for p in [[0.0, 0.0], [26.0, -19.0], [-25.0, 18.0], [3.3, 7.7]] {
            let back = map.undistorted_to_mm(map.mm_to_undistorted(p).unwrap()).unwrap();
            assert!(
                (back[0] - p[0]).abs() < 1e-6 && (back[1] - p[1]).abs() < 1e-6,
                "{p:?} -> {back:?}"
            );
        }
        // The homography alone leaves the barrel term in place.
        let h = Homography::fit(&truth, &grid(&pad)).unwrap();
        let worst = truth
            .iter()
            .zip(grid(&pad))
            .map(|(&p, t)| {
                let m = h.apply(p).unwrap();
                (m[0] - t[0]).hypot(m[1] - t[1])
            })
            .fold(0.0, f64::max);
        assert!(worst > 10.0 * residual.max_mm, "{worst}");
        // A stored map keeps the correction and re-fits the pose: the same frame gives the same residual.
        let stored = map.stored();
        let again = PadMapping::fit(camera, &pad, &observed, Some(&stored)).unwrap();
        assert!(
            (again.residual().rms_mm - residual.rms_mm).abs() < 1e-3,
            "{:?}",
            again.residual()
        );
    }

    /// The camera's place from the map's pose: the grid seen through the configured lens's pinhole from a camera
    /// 72 mm below the pattern, tilted 3 and -2 deg, whose centre is over (4, -3) mm of the pad.
    #[test]
    fn the_camera_view_is_where_the_camera_is() {
        let pad = PadGeometry::default();
        let camera = FisheyeCamera::paper(1024, 768).unwrap();
        let k = *camera.rectified();
        let (a, b) = (3f64.to_radians(), (-2f64).to_radians());
        // Rotation about x by a, then about y by b (camera frame from pad frame), and the camera's centre.
        let rx = [[1.0, 0.0, 0.0], [0.0, a.cos(), -a.sin()], [0.0, a.sin(), a.cos()]];
        let ry = [[b.cos(), 0.0, b.sin()], [0.0, 1.0, 0.0], [-b.sin(), 0.0, b.cos()]];
        let r: Vec<[f64; 3]> = (0..3)
            .map(|i| std::array::from_fn(|j| (0..3).map(|m| ry[i][m] * rx[m][j]).sum()))
            .collect();
        let centre = [4.0, -3.0, -72.0];
        let observed: Vec<Option<Point2>> = grid(&pad)
            .iter()
            .map(|p| {
                let v = [p[0] - centre[0], p[1] - centre[1], -centre[2]];
                let c: Vec<f64> = (0..3).map(|i| (0..3).map(|j| r[i][j] * v[j]).sum()).collect();
                Some([k.fx * c[0] / c[2] + k.cx, k.fy * c[1] / c[2] + k.cy])
            })
            .collect();
        let map = PadMapping::fit(camera, &pad, &observed, None).unwrap();
        let view = map.camera_view().unwrap();
        assert!(
            (view.foot_mm[0] - 4.0).abs() < 0.05 && (view.foot_mm[1] + 3.0).abs() < 0.05,
            "{view:?}"
        );
        assert!((view.height_mm - 72.0).abs() < 0.05, "{view:?}");
    }

    #[test]
    fn a_mis_found_corner_is_left_out_and_counted() {
        let pad = PadGeometry::default();
        let camera = FisheyeCamera::paper(1024, 768).unwrap();
        let mut observed: Vec<Option<Point2>> = grid(&pad)
            .iter()
            .map(|p| Some([512.0 + 12.0 * p[0], 384.0 + 12.0 * p[1]]))
            .collect();
        observed[40] = observed[40].map(|p| [p[0] + 9.0, p[1] - 4.0]);
        let map = PadMapping::fit(camera, &pad, &observed, None).unwrap();
        assert_eq!(map.residual().outliers, 1);
        assert!(map.residual().max_mm < 1e-6, "{:?}", map.residual());
    }

    #[test]
    fn too_few_or_collinear_corners_are_typed_errors() {
        let pad = PadGeometry::default();
        let camera = FisheyeCamera::paper(1024, 768).unwrap();
        let few: Vec<Option<Point2>> = (0..165)
            .map(|i| (i < 10).then_some([i as f64 * 10.0, i as f64 * 3.0]))
            .collect();
        assert!(matches!(
            PadMapping::fit(camera, &pad, &few, None),
            Err(EstimateError::TooFewPoints { .. })
        ));
        let line: Vec<Option<Point2>> = (0..165).map(|i| Some([i as f64 * 3.0, 100.0])).collect();
        assert!(PadMapping::fit(camera, &pad, &line, None).is_err());
    }
}
