//! The simulated sensor: pad, gel, camera pose, colours, LEDs and image formation settings.
//!
//! [`SensorModel::real`] reproduces the real sensor of host/estimator/tests/data/real. Where a number was measured
//! on those two frames (2048 x 1536 raw JPEGs), the comment next to it says how; nothing here is fitted per pixel,
//! only a handful of physical constants.

use nusense_geometry::camera::FisheyeIntrinsics;
use nusense_geometry::{CameraError, PadGeometry};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::layer::LayeredPad;
use crate::lens::{Camera, Lens};

/// LED current at which the pad looks like the real frames (each of the four sides).
pub const NOMINAL_LED_CURRENT_MA: f32 = 100.0;

// The pad's colours were measured on reference_fisheye.jpg at the cells' centres and edges, located with the pose of
// [`PadPose::real`]: the mean of a 16 x 16 px patch at the centre of each of the 140 inner cells, and of a
// 3 x 20 px strip on each vertical cell edge (the bright lines between cells); the median over cells is the
// constant, the 10th..90th percentiles are given for the spread the texture imitates.

/// Yellow cells: median (251, 255, 186), 10..90 %: (216, 231, 136)..(255, 255, 227). Green clips at 255 in the
/// middle of the pad, so the albedo sits just below clipping at nominal light and clips where the light is higher.
pub const REAL_YELLOW_RGB: [f32; 3] = [248.0, 250.0, 180.0];
/// Red cells (darker than the lines between cells): median (191, 85, 129), 10..90 %: (158, 56, 100)..(227, 97, 145).
pub const REAL_RED_RGB: [f32; 3] = [191.0, 85.0, 129.0];
/// The bright red lines between cells: median (224, 100, 131), 10..90 %: (201, 85, 112)..(246, 128, 148).
pub const REAL_LINE_RGB: [f32; 3] = [224.0, 100.0, 131.0];
/// The dark bluish rim around the pattern (the edge of the pad and its window): samples along row 768 between
/// x = 280 and 340 and along column 1024 between y = 100 and 136 of reference_fisheye.jpg, about (30..50, 37..53,
/// 46..83); we take the middle.
pub const REAL_RIM_RGB: [f32; 3] = [36.0, 44.0, 68.0];
/// The housing around the window: 40 x 40 px means at the frame's corners and edge midpoints of
/// reference_fisheye.jpg range (9, 7, 6)..(29, 19, 17).
pub const REAL_SURROUND_RGB: [f32; 3] = [18.0, 13.0, 13.0];
/// Side of a cell's coloured square / cell pitch (the rest is the line between cells). Near the frame centre the
/// yellow runs along rows and columns of reference_fisheye.jpg are 80..83 px long and repeat every 188..190 px
/// (two cells), so 82 / 95 = 0.86.
pub const REAL_YELLOW_FILL: f64 = 0.86;

#[derive(Debug, Error, PartialEq)]
pub enum ModelError {
    #[error("sensor model: {field} must be {expected}, got {value}")]
    BadValue {
        field: &'static str,
        expected: &'static str,
        value: f64,
    },
    #[error("sensor model camera: {0}")]
    Camera(#[from] CameraError),
    #[error("sensor model: the pad plane is not in front of the camera (pose {0:?})")]
    PadBehindCamera(PadPose),
}

/// Where the pad's colour layer sits relative to the camera: the camera looks along +z; the pad plane's origin
/// (pad centre) is at (shift_mm.x, shift_mm.y, distance_mm), its axes rotated by `rotation_deg` about the
/// camera's x, then y, then z axis.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PadPose {
    pub distance_mm: f64,
    pub shift_mm: [f64; 2],
    pub rotation_deg: [f64; 3],
}

impl PadPose {
    /// Fitted to the 96 yellow-square centroids of reference_fisheye.jpg with the paper's fisheye model
    /// (least squares over distance, shift and the three angles; residual 4.6 px RMS, 8 px max on a 2048 x 1536
    /// frame, the rest being the real lens differing from the paper's K and D). The pattern then spans about
    /// x 363..1770, y 142..1239 px of the raw frame.
    pub fn real() -> Self {
        Self {
            distance_mm: 71.18,
            shift_mm: [1.741, -2.840],
            rotation_deg: [2.667, 0.832, 0.065],
        }
    }

    /// The validation sensor's pose: tilted about all three axes and off-centre the other way from the real one.
    pub fn validation() -> Self {
        Self {
            distance_mm: 74.0,
            shift_mm: [-1.4, 0.4],
            rotation_deg: [-3.2, 2.4, -1.5],
        }
    }

    /// Rotation matrix (row-major) taking pad axes to camera axes.
    pub fn rotation(&self) -> [[f64; 3]; 3] {
        let [ax, ay, az] = self.rotation_deg.map(f64::to_radians);
        let (sx, cx) = ax.sin_cos();
        let (sy, cy) = ay.sin_cos();
        let (sz, cz) = az.sin_cos();
        let rx = [[1.0, 0.0, 0.0], [0.0, cx, -sx], [0.0, sx, cx]];
        let ry = [[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]];
        let rz = [[cz, -sz, 0.0], [sz, cz, 0.0], [0.0, 0.0, 1.0]];
        mat_mul(&rz, &mat_mul(&ry, &rx))
    }

    /// The camera's centre in pad coordinates (mm; negative z: the camera is below the pad). The rotation is
    /// orthonormal, so a camera vector v is R^T v in pad coordinates, and the camera sits at -R^T t.
    pub fn camera_in_pad(&self) -> [f64; 3] {
        let r = self.rotation();
        let t = [self.shift_mm[0], self.shift_mm[1], self.distance_mm];
        std::array::from_fn(|k| -(r[0][k] * t[0] + r[1][k] * t[1] + r[2][k] * t[2]))
    }

    /// A point of the pad plane (pad mm) in camera coordinates.
    pub fn pad_to_camera(&self, p: [f64; 2]) -> [f64; 3] {
        let r = self.rotation();
        let t = [self.shift_mm[0], self.shift_mm[1], self.distance_mm];
        std::array::from_fn(|i| r[i][0] * p[0] + r[i][1] * p[1] + t[i])
    }
}

fn mat_mul(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

/// The gel as an elastic half-space, and where the camera-visible colour layer sits in it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Material {
    /// Depth of the colour layer below the contact surface.
    pub layer_depth_mm: f64,
    pub shear_modulus_kpa: f64,
    /// 0.5 = incompressible (silicone gels are nearly so).
    pub poisson_ratio: f64,
}

impl Material {
    /// Fitted to the real pair: the displacements of the 96 yellow-square centroids between reference_fisheye.jpg
    /// and touch_fisheye.jpg (peak about 17 px) against this crate's model of a 5 mm sphere at 6 N (the
    /// authors' label), with the centre, depth and modulus free and nu = 0.5: 1.1 px RMS residual at depth
    /// 2.8 mm, G = 48 kPa.
    pub fn real() -> Self {
        Self {
            layer_depth_mm: 2.8,
            shear_modulus_kpa: 48.0,
            poisson_ratio: 0.5,
        }
    }

    /// In N / mm^2 (MPa), the unit the mechanics works in.
    pub fn shear_modulus_n_per_mm2(&self) -> f64 {
        self.shear_modulus_kpa * 1e-3
    }
}

/// How the pad deforms under a load.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Mechanics {
    /// An elastic half-space observed at the pattern's depth (Boussinesq and Cerruti), fitted to the real pair;
    /// the camera sees the pattern directly (no refraction, no parallax).
    HalfSpace(Material),
    /// Layers bonded to a rigid plate in a frame ([`crate::layer`]); the camera looks through the plate and the
    /// gel below the pattern, so it sees refraction and the parallax of the pattern's motion into the pad.
    Layered(LayeredPad),
}

/// A bright reflection fixed in the image (an LED seen in the glass), added to what the pad shows.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Glare {
    /// Centre as a fraction of the frame's width and height.
    pub centre: [f64; 2],
    /// Gaussian radius (1 sigma) as a fraction of the frame's width.
    pub radius: f64,
    /// Peak in 8-bit levels at nominal LED current (scales with the mean LED current).
    pub level: f32,
}

/// The pad's look at nominal illumination (the real frames' LED currents), RGB in 0..255.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PadColours {
    pub yellow: [f32; 3],
    pub red: [f32; 3],
    /// The lines between cells.
    pub lines: [f32; 3],
    /// The rim around the pattern.
    pub rim: [f32; 3],
    /// Everything outside the window.
    pub surround: [f32; 3],
}

impl PadColours {
    pub fn real() -> Self {
        Self {
            yellow: REAL_YELLOW_RGB,
            red: REAL_RED_RGB,
            lines: REAL_LINE_RGB,
            rim: REAL_RIM_RGB,
            surround: REAL_SURROUND_RGB,
        }
    }
}

/// Four LED bars, one along each side of the pad just outside the rim; each lights its own side more.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Lighting {
    /// Current at which a side gives its nominal brightness; brightness is linear in current.
    pub nominal_current_ma: f32,
    /// Distance of each LED bar outside the pattern's edge, mm.
    pub bar_offset_mm: f64,
    /// A bar's light falls as 1 / (1 + (d / spread)^2) with distance d from it.
    pub spread_mm: f64,
    /// Light that does not come from the LEDs, as a fraction of the nominal total (0: dark with LEDs off).
    pub ambient: f32,
}

impl Lighting {
    pub fn real() -> Self {
        Self {
            nominal_current_ma: NOMINAL_LED_CURRENT_MA,
            bar_offset_mm: 5.0,
            spread_mm: 25.0,
            ambient: 0.0,
        }
    }
}

/// Everything fixed about one simulated sensor.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorModel {
    pub pad: PadGeometry,
    pub width: u32,
    pub height: u32,
    pub lens: Lens,
    pub pose: PadPose,
    pub mechanics: Mechanics,
    pub colours: PadColours,
    /// Side of each cell's coloured square as a fraction of the cell pitch (the rest is the line between cells).
    pub yellow_fill: f64,
    /// Width of the dark rim around the pattern, mm.
    pub rim_width_mm: f64,
    /// Blotchiness of the pad's colours (relative amplitude of a smooth random texture fixed to the material).
    pub texture_amplitude: f32,
    /// Seed of that texture: it belongs to the pad, not to the frame.
    pub texture_seed: u64,
    pub lighting: Lighting,
    /// Gain on everything (1 = the real frames' exposure).
    pub exposure: f32,
    /// Brightness lost at the frame's corners relative to its centre (quadratic in radius).
    pub vignetting: f32,
    /// Standard deviation of per-pixel noise, in 8-bit levels.
    pub noise_sigma: f32,
    /// Shot noise: variance added per level of signal (photon counting), in 8-bit levels.
    #[serde(default)]
    pub shot_noise: f32,
    /// Reflections fixed in the image.
    #[serde(default)]
    pub glare: Vec<Glare>,
    /// Optical blur (Gaussian sigma) in px of this frame size.
    pub blur_px: f32,
    /// Encode and decode every frame as JPEG at this quality, as a webcam's MJPEG stream would.
    pub jpeg_quality: Option<u8>,
    /// Spacing of the mesh on which displacements are computed and then interpolated per pixel.
    pub mesh_step_mm: f64,
}

impl SensorModel {
    /// The real sensor at `width x height` (the paper's lens scaled to that frame size).
    pub fn real(width: u32, height: u32) -> Self {
        let scale = f64::from(width.max(1)) / 2048.0;
        Self {
            pad: PadGeometry::default(),
            width,
            height,
            lens: Lens::KannalaBrandt(FisheyeIntrinsics::paper(2048, 1536).scaled_to(width.max(1), height.max(1))),
            pose: PadPose::real(),
            mechanics: Mechanics::HalfSpace(Material::real()),
            colours: PadColours::real(),
            yellow_fill: REAL_YELLOW_FILL,
            rim_width_mm: 3.0,
            texture_amplitude: 0.1,
            texture_seed: 0x006e_7573_656e_7365,
            lighting: Lighting::real(),
            exposure: 1.0,
            vignetting: 0.25,
            // About what the real frames show in flat yellow areas at 2048 px; JPEG adds its own.
            noise_sigma: 2.0,
            shot_noise: 0.0,
            glare: Vec::new(),
            // About 2 px of defocus at 2048 px wide, scaled to this frame.
            blur_px: (2.0 * scale).max(0.3) as f32,
            jpeg_quality: None,
            mesh_step_mm: 0.5,
        }
    }

    /// The validation sensor: the same pad seen by another camera, built to share none of the estimator's
    /// assumptions: an equisolid, decentred lens with an off-centre principal point; the pad tilted and shifted
    /// differently; the pad as layers bonded to a plate in a frame (refraction through the plate and gel, and the
    /// parallax of the pattern's motion towards the camera); two glare spots; stronger vignetting; shot noise; JPEG
    /// at quality 85 as a webcam's MJPEG stream.
    pub fn validation(width: u32, height: u32) -> Self {
        let real = Self::real(width, height);
        Self {
            lens: Lens::Equisolid(crate::lens::EquisolidLens::decentred(width.max(1), height.max(1))),
            pose: PadPose::validation(),
            mechanics: Mechanics::Layered(LayeredPad::nusense()),
            vignetting: 0.4,
            noise_sigma: 1.5,
            shot_noise: 0.05,
            glare: vec![
                Glare {
                    centre: [0.3, 0.22],
                    radius: 0.03,
                    level: 60.0,
                },
                Glare {
                    centre: [0.74, 0.8],
                    radius: 0.02,
                    level: 90.0,
                },
            ],
            jpeg_quality: Some(85),
            texture_seed: 0x7661_6c69_6461_7465,
            ..real
        }
    }

    pub fn camera(&self) -> Result<Camera, ModelError> {
        let (width, height) = self.lens.size();
        if (width, height) != (self.width, self.height) {
            return Err(ModelError::BadValue {
                field: "lens.width/height",
                expected: "equal to the model's width and height",
                value: f64::from(width),
            });
        }
        Ok(Camera::new(&self.lens)?)
    }

    /// The material whose modulus sets an indenter's contact radius (Hertz): the half-space, or the stack's softest
    /// layer.
    pub fn contact_material(&self) -> Material {
        match &self.mechanics {
            Mechanics::HalfSpace(material) => *material,
            Mechanics::Layered(pad) => {
                let soft = pad.softest().copied().unwrap_or(crate::layer::ElasticLayer {
                    thickness_mm: 1.0,
                    shear_modulus_kpa: 1.0,
                    poisson_ratio: 0.5,
                });
                Material {
                    // Quadrature fine enough for the pattern's depth and the solver's grid.
                    layer_depth_mm: pad.pattern_depth_mm.min(2.0 * pad.grid_step_mm),
                    shear_modulus_kpa: soft.shear_modulus_kpa,
                    poisson_ratio: soft.poisson_ratio,
                }
            }
        }
    }

    /// Refuses a model that cannot be rendered, naming the first field that is wrong.
    pub fn validate(&self) -> Result<(), ModelError> {
        self.validate_frame_and_pose()?;
        self.validate_mechanics()?;
        self.validate_imaging()?;
        self.validate_mesh()?;
        let normal = self.pose.rotation().map(|row| row[2]);
        let centre = self.pose.pad_to_camera([0.0, 0.0]);
        let facing = normal[0] * centre[0] + normal[1] * centre[1] + normal[2] * centre[2];
        if !(centre[2] > 0.0 && facing.abs() > 1e-6) {
            return Err(ModelError::PadBehindCamera(self.pose));
        }
        self.camera()?;
        Ok(())
    }

    fn validate_frame_and_pose(&self) -> Result<(), ModelError> {
        positive("width", f64::from(self.width))?;
        positive("height", f64::from(self.height))?;
        let fewest_cells = self.pad.rows.min(self.pad.cols);
        check(
            fewest_cells >= 2,
            "pad.rows/cols",
            "at least 2 cells each way",
            f64::from(fewest_cells),
        )?;
        positive("pad.width_mm", self.pad.width_mm)?;
        positive("pad.height_mm", self.pad.height_mm)?;
        positive("pose.distance_mm", self.pose.distance_mm)?;
        for &v in self.pose.shift_mm.iter().chain(&self.pose.rotation_deg) {
            check(v.is_finite(), "pose", "finite numbers", v)?;
        }
        Ok(())
    }

    fn validate_mechanics(&self) -> Result<(), ModelError> {
        match &self.mechanics {
            Mechanics::HalfSpace(material) => {
                positive("material.layer_depth_mm", material.layer_depth_mm)?;
                positive("material.shear_modulus_kpa", material.shear_modulus_kpa)?;
                within(
                    "material.poisson_ratio",
                    material.poisson_ratio,
                    0.0..=0.5,
                    "between 0 and 0.5",
                )
            }
            Mechanics::Layered(pad) => match pad.problem() {
                Some((field, value)) => check(false, field, "see the field's name", value),
                None => Ok(()),
            },
        }
    }

    fn validate_imaging(&self) -> Result<(), ModelError> {
        non_negative("shot_noise", f64::from(self.shot_noise))?;
        for glare in &self.glare {
            let ok = glare.centre.iter().all(|v| v.is_finite())
                && glare.radius.is_finite()
                && glare.radius > 0.0
                && glare.level.is_finite()
                && glare.level >= 0.0;
            check(ok, "glare", "finite centres, radius > 0, level >= 0", glare.radius)?;
        }
        check(
            self.yellow_fill.is_finite() && self.yellow_fill > 0.0 && self.yellow_fill <= 1.0,
            "yellow_fill",
            "in (0, 1]",
            self.yellow_fill,
        )?;
        non_negative("rim_width_mm", self.rim_width_mm)?;
        non_negative("texture_amplitude", f64::from(self.texture_amplitude))?;
        positive(
            "lighting.nominal_current_ma",
            f64::from(self.lighting.nominal_current_ma),
        )?;
        non_negative("lighting.bar_offset_mm", self.lighting.bar_offset_mm)?;
        positive("lighting.spread_mm", self.lighting.spread_mm)?;
        non_negative("lighting.ambient", f64::from(self.lighting.ambient))?;
        non_negative("exposure", f64::from(self.exposure))?;
        within("vignetting", f64::from(self.vignetting), 0.0..=1.0, "between 0 and 1")?;
        non_negative("noise_sigma", f64::from(self.noise_sigma))?;
        non_negative("blur_px", f64::from(self.blur_px))?;
        if let Some(q) = self.jpeg_quality {
            check((1..=100).contains(&q), "jpeg_quality", "1..=100", f64::from(q))?;
        }
        Ok(())
    }

    fn validate_mesh(&self) -> Result<(), ModelError> {
        positive("mesh_step_mm", self.mesh_step_mm)?;
        check(
            self.mesh_step_mm <= 5.0,
            "mesh_step_mm",
            "at most 5 mm",
            self.mesh_step_mm,
        )
    }
}

/// `field` is wrong unless `ok`; `value` is what it holds.
fn check(ok: bool, field: &'static str, expected: &'static str, value: f64) -> Result<(), ModelError> {
    if ok {
        Ok(())
    } else {
        Err(ModelError::BadValue { field, expected, value })
    }
}

fn positive(field: &'static str, value: f64) -> Result<(), ModelError> {
    check(value.is_finite() && value > 0.0, field, "a finite number > 0", value)
}

fn non_negative(field: &'static str, value: f64) -> Result<(), ModelError> {
    check(value.is_finite() && value >= 0.0, field, "a finite number >= 0", value)
}

fn within(
    field: &'static str,
    value: f64,
    range: std::ops::RangeInclusive<f64>,
    expected: &'static str,
) -> Result<(), ModelError> {
    check(value.is_finite() && range.contains(&value), field, expected, value)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_validation_sensor_frames_the_whole_pattern_like_the_real_one() {
        for (w, h) in [(640, 480), (2048, 1536)] {
            let m = SensorModel::validation(w, h);
            m.validate().unwrap();
            let r = crate::Renderer::new(SensorModel {
                width: w,
                height: h,
                ..m
            })
            .unwrap();
            let px = |p: [f64; 2]| r.pad_mm_to_raw_px(p).unwrap();
            let (sx, sy) = (f64::from(w) / 2048.0, f64::from(h) / 1536.0);
            let (left, right, top, bottom) = (px([-26.5, 0.0]), px([26.5, 0.0]), px([0.0, -20.0]), px([0.0, 20.0]));
            println!("{w}x{h}: left {left:?} right {right:?} top {top:?} bottom {bottom:?}");
            // Inside the frame with a margin, and about as large as in the real frames (1390 x 1060 px at 2048).
            assert!(left[0] > 150.0 * sx && right[0] < 1900.0 * sx, "{left:?} {right:?}");
            assert!(top[1] > 100.0 * sy && bottom[1] < 1430.0 * sy, "{top:?} {bottom:?}");
            assert!(((right[0] - left[0]) / sx - 1390.0).abs() < 200.0);
        }
    }

    #[test]
    fn real_model_is_valid_at_common_sizes() {
        for (w, h) in [(2048, 1536), (640, 480), (320, 240), (1280, 720)] {
            SensorModel::real(w, h).validate().unwrap();
        }
    }

    #[test]
    fn invalid_models_are_typed_errors() {
        let mut m = SensorModel::real(640, 480);
        m.mechanics = Mechanics::HalfSpace(Material {
            poisson_ratio: 0.7,
            ..Material::real()
        });
        assert!(matches!(
            m.validate(),
            Err(ModelError::BadValue {
                field: "material.poisson_ratio",
                ..
            })
        ));
        let mut m = SensorModel::real(640, 480);
        m.pose.distance_mm = -5.0;
        assert!(m.validate().is_err());
        let mut m = SensorModel::real(640, 480);
        m.width = 320;
        assert!(m.validate().is_err());
        let mut m = SensorModel::real(640, 480);
        m.jpeg_quality = Some(0);
        assert!(m.validate().is_err());
    }

    #[test]
    fn every_checked_value_names_its_field_when_wrong() {
        type Spoil = fn(&mut SensorModel);
        let spoils: [(&str, Spoil); 24] = [
            ("width", |m| m.width = 0),
            ("pad.rows/cols", |m| m.pad.cols = 1),
            ("pad.width_mm", |m| m.pad.width_mm = f64::NAN),
            ("pad.height_mm", |m| m.pad.height_mm = 0.0),
            ("pose.distance_mm", |m| m.pose.distance_mm = -5.0),
            ("pose", |m| m.pose.shift_mm[1] = f64::INFINITY),
            ("pose", |m| m.pose.rotation_deg[2] = f64::NAN),
            ("material.layer_depth_mm", |m| {
                m.mechanics = Mechanics::HalfSpace(Material {
                    layer_depth_mm: 0.0,
                    ..Material::real()
                })
            }),
            ("material.poisson_ratio", |m| {
                m.mechanics = Mechanics::HalfSpace(Material {
                    poisson_ratio: f64::NAN,
                    ..Material::real()
                })
            }),
            ("shot_noise", |m| m.shot_noise = -1.0),
            ("glare", |m| {
                m.glare = vec![Glare {
                    centre: [0.5, 0.5],
                    radius: 0.1,
                    level: -1.0,
                }]
            }),
            ("yellow_fill", |m| m.yellow_fill = 1.5),
            ("rim_width_mm", |m| m.rim_width_mm = f64::NAN),
            ("texture_amplitude", |m| m.texture_amplitude = -0.1),
            ("lighting.nominal_current_ma", |m| m.lighting.nominal_current_ma = 0.0),
            ("lighting.bar_offset_mm", |m| m.lighting.bar_offset_mm = -1.0),
            ("lighting.spread_mm", |m| m.lighting.spread_mm = f64::INFINITY),
            ("lighting.ambient", |m| m.lighting.ambient = f32::NAN),
            ("exposure", |m| m.exposure = -1.0),
            ("vignetting", |m| m.vignetting = 1.5),
            ("noise_sigma", |m| m.noise_sigma = f32::NAN),
            ("blur_px", |m| m.blur_px = -0.5),
            ("jpeg_quality", |m| m.jpeg_quality = Some(101)),
            ("mesh_step_mm", |m| m.mesh_step_mm = 6.0),
        ];
        for (expected_field, spoil) in spoils {
            let mut m = SensorModel::real(640, 480);
            spoil(&mut m);
            match m.validate() {
                Err(ModelError::BadValue { field, .. }) => assert_eq!(field, expected_field),
                other => panic!("{expected_field}: {other:?}"),
            }
        }
        let mut behind = SensorModel::real(640, 480);
        // Edge-on: the pad's plane passes through the camera.
        behind.pose.rotation_deg = [90.0, 0.0, 0.0];
        behind.pose.shift_mm = [0.0, 0.0];
        assert!(matches!(behind.validate(), Err(ModelError::PadBehindCamera(_))));
    }

    #[test]
    fn real_pose_places_the_pattern_like_the_real_frames() {
        // The brief's rough extent of the pattern in the real 2048 x 1536 frame: x 370..1760, y 160..1220.
        let m = SensorModel::real(2048, 1536);
        let cam = m.camera().unwrap();
        let px = |p: [f64; 2]| cam.project(m.pose.pad_to_camera(p)).unwrap();
        let left = px([-26.5, 0.0]);
        let right = px([26.5, 0.0]);
        let top = px([0.0, -20.0]);
        let bottom = px([0.0, 20.0]);
        assert!(
            (left[0] - 370.0).abs() < 30.0 && (right[0] - 1760.0).abs() < 30.0,
            "{left:?} {right:?}"
        );
        assert!(
            (top[1] - 160.0).abs() < 30.0 && (bottom[1] - 1220.0).abs() < 30.0,
            "{top:?} {bottom:?}"
        );
    }
}
