//! Scene -> raw frame.
//!
//! Everything that depends only on the fixed camera is computed once in [`Renderer::new`]: for every pixel, the
//! point of the pad plane under its centre (ray cast through the fisheye model), the pixel's footprint on the pad
//! (for analytic anti-aliasing), and its share of each LED bar's light with vignetting. Per frame only the
//! displacement mesh is solved, inverted, and each pixel looks up which material point it now sees and that
//! point's colour coverage.

use image::RgbImage;
use nusense_geometry::Point2;
use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;
use thiserror::Error;

use crate::layer::{LayerField, LayeredPad, SpectralPad};
use crate::lens::Camera;
use crate::mechanics::{discretise, ContactLoad, DisplacementMesh, LoadedPad};
use crate::model::{Mechanics, ModelError, SensorModel};
use crate::scene::{Damage, Scene, SceneError};
use crate::truth::{ContactTruth, CornerTruth, GroundTruth};

#[derive(Debug, Error)]
pub enum RenderError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error("LED current {side} must be a finite number >= 0 mA, got {value}")]
    BadCurrent { side: &'static str, value: f32 },
    #[error("the pad point {0:?} mm does not project into the camera")]
    NotInView(Point2),
    #[error(
        "the load sinks the pattern at {at_mm:?} mm by {sink_mm:.2} mm towards the camera, past the {gel_mm:.2} mm of gel \
         under it: beyond the pad model's linear reach (a lighter load or a larger tip)"
    )]
    SunkPastGel { at_mm: Point2, sink_mm: f64, gel_mm: f64 },
    #[error("JPEG round trip failed: {0}")]
    Jpeg(#[from] image::ImageError),
}

const SIDES: [&str; 4] = ["top", "right", "bottom", "left"];
/// Pixels whose ray misses the pad plane look at this (far outside everything).
const NOWHERE_MM: f32 = 1.0e4;
/// Margin of the displacement mesh around the rim: the field there is tiny but not zero.
const MESH_MARGIN_MM: f64 = 2.0;

#[derive(Clone, Copy, Debug)]
struct PixelGeometry {
    /// Pad-plane point under the pixel centre, mm.
    q: [f32; 2],
    /// Half-widths of the pixel's footprint along pad x and y, mm, widened by the optical blur.
    half: [f32; 2],
}

#[derive(Clone, Copy, Debug)]
struct PixelLight {
    /// Brightness from each LED bar at its nominal current (Top, Right, Bottom, Left), incl. vignetting and exposure.
    side: [f32; 4],
    ambient: f32,
    /// Reflections fixed in the image at nominal current, 0..1 of full scale.
    glare: f32,
}

/// What the camera looks through on its way to the pattern (layered pads): the rigid plate, then the gel below
/// the pattern. Thicknesses along the pad's normal, mm.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Window {
    plate_mm: f64,
    plate_index: f64,
    gel_mm: f64,
    gel_index: f64,
}

impl Window {
    fn of(pad: &LayeredPad) -> Self {
        Self {
            plate_mm: pad.plate_thickness_mm,
            plate_index: pad.plate_refractive_index,
            gel_mm: pad.thickness_mm() - pad.pattern_depth_mm,
            gel_index: pad.refractive_index,
        }
    }

    /// tan of the ray's angle to the normal inside a medium of index `n`, from the sine of its angle in air.
    fn tan_in(sin_air: f64, n: f64) -> f64 {
        let s = sin_air / n;
        s / (1.0 - s * s).sqrt()
    }

    /// Sideways travel through the plate and a gel of `gel_mm` for a ray whose sine in air is `sin_air`.
    fn travel(&self, sin_air: f64, gel_mm: f64) -> f64 {
        self.plate_mm * Self::tan_in(sin_air, self.plate_index) + gel_mm * Self::tan_in(sin_air, self.gel_index)
    }
}

/// The pad's deformation under one scene's contacts.
enum Deformation {
    HalfSpace(LoadedPad),
    Layered {
        loads: Vec<ContactLoad>,
        field: Option<LayerField>,
    },
}

impl Deformation {
    fn new(model: &SensorModel, spectral: Option<&SpectralPad>, scene: &Scene) -> Self {
        match (&model.mechanics, spectral) {
            (Mechanics::Layered(_), Some(spectral)) => {
                let material = model.contact_material();
                let loads: Vec<ContactLoad> = scene.contacts.iter().map(|c| discretise(c, &material)).collect();
                let forces: Vec<_> = loads.iter().flat_map(|l| l.fine.iter().copied()).collect();
                let field = (!forces.is_empty()).then(|| spectral.solve(&forces));
                Self::Layered { loads, field }
            }
            // A layered pad always has its solver (built with the renderer); the half-space needs none.
            _ => Self::HalfSpace(LoadedPad::new(&scene.contacts, &model.contact_material())),
        }
    }

    fn loads(&self) -> &[ContactLoad] {
        match self {
            Self::HalfSpace(pad) => &pad.loads,
            Self::Layered { loads, .. } => loads,
        }
    }

    /// Displacement of the pattern's material point at `p` (pad mm): in-plane, then into the pad.
    fn displacement_mm(&self, p: Point2) -> [f64; 3] {
        match self {
            Self::HalfSpace(pad) => pad.displacement_mm(p),
            Self::Layered { field, .. } => field.as_ref().map_or([0.0; 3], |f| f.at(p)),
        }
    }
}

/// A smooth random scalar field on a regular grid in pad mm.
#[derive(Clone, Debug)]
struct Texture {
    origin: [f32; 2],
    inv_step: f32,
    nx: usize,
    ny: usize,
    values: Vec<f32>,
}

impl Texture {
    /// Value noise: random levels every `coarse_mm`, bilinear in between, sampled every `step_mm`; two octaves.
    fn new(min: [f64; 2], max: [f64; 2], seed: u64) -> Self {
        let step = 0.5;
        let nx = ((max[0] - min[0]) / step).ceil() as usize + 2;
        let ny = ((max[1] - min[1]) / step).ceil() as usize + 2;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut octave = |coarse: f64| {
            let cx = ((max[0] - min[0]) / coarse).ceil() as usize + 2;
            let cy = ((max[1] - min[1]) / coarse).ceil() as usize + 2;
            let levels: Vec<f64> = (0..cx * cy)
                .map(|_| f64::from(rng.next_u32()) / f64::from(u32::MAX) * 2.0 - 1.0)
                .collect();
            move |x: f64, y: f64| {
                let (fx, fy) = (x / coarse, y / coarse);
                let (i, j) = ((fx as usize).min(cx - 2), (fy as usize).min(cy - 2));
                let (tx, ty) = (fx - i as f64, fy - j as f64);
                let at = |a: usize, b: usize| levels[b * cx + a];
                let top = at(i, j) + (at(i + 1, j) - at(i, j)) * tx;
                let bottom = at(i, j + 1) + (at(i + 1, j + 1) - at(i, j + 1)) * tx;
                top + (bottom - top) * ty
            }
        };
        let large = octave(5.0);
        let small = octave(2.0);
        let mut values = Vec::with_capacity(nx * ny);
        for j in 0..ny {
            for i in 0..nx {
                let (x, y) = (i as f64 * step, j as f64 * step);
                values.push((0.7 * large(x, y) + 0.3 * small(x, y)) as f32);
            }
        }
        Self {
            origin: [min[0] as f32, min[1] as f32],
            inv_step: (1.0 / step) as f32,
            nx,
            ny,
            values,
        }
    }

    #[inline]
    fn at(&self, p: [f32; 2]) -> f32 {
        let fx = (p[0] - self.origin[0]) * self.inv_step;
        let fy = (p[1] - self.origin[1]) * self.inv_step;
        if !(fx >= 0.0 && fy >= 0.0) {
            return 0.0;
        }
        let (i, j) = (fx as usize, fy as usize);
        if i + 1 >= self.nx || j + 1 >= self.ny {
            return 0.0;
        }
        let (tx, ty) = (fx - i as f32, fy - j as f32);
        let row = j * self.nx + i;
        let top = self.values[row] + (self.values[row + 1] - self.values[row]) * tx;
        let bottom = self.values[row + self.nx] + (self.values[row + self.nx + 1] - self.values[row + self.nx]) * tx;
        top + (bottom - top) * ty
    }
}

/// Fraction of the box [x - h, x + h] inside [a, b].
#[inline]
fn box_coverage(x: f32, h: f32, a: f32, b: f32) -> f32 {
    ((x + h).clamp(a, b) - (x - h).clamp(a, b)) / (2.0 * h)
}

/// Fraction of a footprint of half-width `h` at distance `distance` from a disc's centre inside the disc.
#[inline]
fn disc_coverage(distance: f32, radius: f32, h: f32) -> f32 {
    ((radius - distance) / (2.0 * h) + 0.5).clamp(0.0, 1.0)
}

/// The checkerboard's layout in f32 for the per-pixel loop.
#[derive(Clone, Copy, Debug)]
struct PatternLayout {
    half_width: f32,
    half_height: f32,
    rim: f32,
    pitch: [f32; 2],
    inv_pitch: [f32; 2],
    /// Gap between a cell's coloured square and the cell's edge (half the line between cells).
    inset: [f32; 2],
    rows: i32,
    cols: i32,
    top_left_yellow: bool,
}

impl PatternLayout {
    fn new(model: &SensorModel) -> Self {
        let pad = &model.pad;
        let pitch = [pad.pitch_x_mm() as f32, pad.pitch_y_mm() as f32];
        let gap = (1.0 - model.yellow_fill as f32) / 2.0;
        Self {
            half_width: (pad.width_mm / 2.0) as f32,
            half_height: (pad.height_mm / 2.0) as f32,
            rim: model.rim_width_mm as f32,
            pitch,
            inv_pitch: [1.0 / pitch[0], 1.0 / pitch[1]],
            inset: [gap * pitch[0], gap * pitch[1]],
            rows: i32::from(pad.rows),
            cols: i32::from(pad.cols),
            top_left_yellow: pad.top_left_yellow,
        }
    }

    /// Coverage of (rim incl. everything inside it, pattern area, yellow squares, red squares) in a footprint at
    /// material point `p`.
    #[inline]
    fn coverage(&self, p: [f32; 2], half: [f32; 2]) -> (f32, f32, f32, f32) {
        let (hw, hh) = (self.half_width, self.half_height);
        let rim = box_coverage(p[0], half[0], -hw - self.rim, hw + self.rim)
            * box_coverage(p[1], half[1], -hh - self.rim, hh + self.rim);
        if rim <= 0.0 {
            return (0.0, 0.0, 0.0, 0.0);
        }
        let pattern = box_coverage(p[0], half[0], -hw, hw) * box_coverage(p[1], half[1], -hh, hh);
        if pattern <= 0.0 {
            return (rim, 0.0, 0.0, 0.0);
        }
        // Local coordinates from the pattern's top-left corner; a footprint touches at most a few cells.
        let (x, y) = (p[0] + hw, p[1] + hh);
        let col_range = cell_range(x, half[0], self.inv_pitch[0], self.cols);
        let row_range = cell_range(y, half[1], self.inv_pitch[1], self.rows);
        let (mut yellow, mut red) = (0.0, 0.0);
        for row in row_range.0..=row_range.1 {
            let y0 = row as f32 * self.pitch[1] + self.inset[1];
            let cover_y = box_coverage(y, half[1], y0, y0 + self.pitch[1] - 2.0 * self.inset[1]);
            if cover_y <= 0.0 {
                continue;
            }
            for col in col_range.0..=col_range.1 {
                let x0 = col as f32 * self.pitch[0] + self.inset[0];
                let cover = cover_y * box_coverage(x, half[0], x0, x0 + self.pitch[0] - 2.0 * self.inset[0]);
                if ((row + col) % 2 == 0) == self.top_left_yellow {
                    yellow += cover;
                } else {
                    red += cover;
                }
            }
        }
        let yellow = yellow.min(pattern);
        (rim, pattern, yellow, red.min(pattern - yellow))
    }
}

/// `floor` without a libm call (baseline x86-64 has no rounding instruction); exact for |v| < 2^31.
#[inline]
fn floor_to_i32(v: f32) -> i32 {
    let truncated = v as i32;
    truncated - i32::from(v < truncated as f32)
}

#[inline]
fn cell_range(x: f32, h: f32, inv_pitch: f32, count: i32) -> (i32, i32) {
    let first = floor_to_i32((x - h) * inv_pitch);
    let last = floor_to_i32((x + h) * inv_pitch);
    let first = first.clamp(0, count - 1);
    (first, last.clamp(first, (first + 3).min(count - 1)))
}

/// The simulated sensor, ready to render frames.
#[derive(Clone, Debug)]
pub struct Renderer {
    model: SensorModel,
    camera: Camera,
    /// Layered pads: the solver, the window the camera looks through, and each pixel's parallax (how far sideways,
    /// in pad mm, the point it sees moves per mm the pattern comes towards the camera).
    spectral: Option<SpectralPad>,
    window: Option<Window>,
    parallax: Vec<[f32; 2]>,
    geometry: Vec<PixelGeometry>,
    light: Vec<PixelLight>,
    texture: Texture,
    layout: PatternLayout,
    mesh_min: [f64; 2],
    mesh_max: [f64; 2],
}

impl Renderer {
    /// Checks the model and precomputes the per-pixel maps (a few ms at 640 x 480, about a second at 2048 x 1536).
    pub fn new(model: SensorModel) -> Result<Self, ModelError> {
        model.validate()?;
        let camera = model.camera()?;
        let half_extent = [
            model.pad.width_mm / 2.0 + model.rim_width_mm + MESH_MARGIN_MM,
            model.pad.height_mm / 2.0 + model.rim_width_mm + MESH_MARGIN_MM,
        ];
        // Every point the mesh and ground truth use must be in front of the camera.
        for corner in [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]] {
            let p = [corner[0] * half_extent[0], corner[1] * half_extent[1]];
            if model.pose.pad_to_camera(p)[2] <= 0.0 {
                return Err(ModelError::PadBehindCamera(model.pose));
            }
        }
        let (spectral, window) = match &model.mechanics {
            Mechanics::Layered(pad) => (
                Some(SpectralPad::new(
                    pad,
                    [model.pad.width_mm / 2.0, model.pad.height_mm / 2.0],
                    pad.pattern_depth_mm,
                )),
                Some(Window::of(pad)),
            ),
            Mechanics::HalfSpace(_) => (None, None),
        };
        let (geometry, parallax) = pixel_geometry(&model, &camera, window.as_ref());
        let light = pixel_light(&model, &geometry);
        let mesh_min = [-half_extent[0], -half_extent[1]];
        let mesh_max = half_extent;
        let texture = Texture::new(mesh_min, mesh_max, model.texture_seed);
        let layout = PatternLayout::new(&model);
        Ok(Self {
            model,
            camera,
            spectral,
            window,
            parallax,
            geometry,
            light,
            texture,
            layout,
            mesh_min,
            mesh_max,
        })
    }

    pub fn model(&self) -> &SensorModel {
        &self.model
    }

    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// Where a point of the colour layer's plane (pad mm) appears in the raw frame.
    pub fn pad_mm_to_raw_px(&self, p: Point2) -> Option<Point2> {
        self.displaced_to_raw_px(p, 0.0)
    }

    /// Where a point of the pattern at `p` (pad mm), moved `towards_camera_mm` out of its plane towards the camera,
    /// appears in the raw frame (through the plate and gel, for a layered pad).
    pub fn displaced_to_raw_px(&self, p: Point2, towards_camera_mm: f64) -> Option<Point2> {
        let pose = &self.model.pose;
        let Some(window) = &self.window else {
            return self.camera.project(pose.pad_to_camera(p));
        };
        // In pad coordinates the camera sits at c (c_z < 0); find the ray's angle in air whose path through air,
        // plate and gel reaches p sideways.
        let r = pose.rotation();
        let c = pose.camera_in_pad();
        let gel = window.gel_mm - towards_camera_mm;
        let air = -c[2] - window.plate_mm - window.gel_mm;
        if !(air > 0.0 && gel >= 0.0) {
            return None;
        }
        let offset = [p[0] - c[0], p[1] - c[1]];
        let reach = offset[0].hypot(offset[1]);
        let sideways = |sin_air: f64| air * Window::tan_in(sin_air, 1.0) + window.travel(sin_air, gel);
        // Monotonic in the angle: bisection on sin(theta_air).
        let (mut lo, mut hi) = (0.0, 0.999_999);
        if sideways(hi) < reach {
            return None;
        }
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if sideways(mid) < reach {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let sin_air = 0.5 * (lo + hi);
        let cos_air = (1.0 - sin_air * sin_air).sqrt();
        let along = if reach > 0.0 {
            [offset[0] / reach, offset[1] / reach]
        } else {
            [0.0, 0.0]
        };
        let d_pad = [sin_air * along[0], sin_air * along[1], cos_air];
        let d_cam: [f64; 3] = std::array::from_fn(|i| r[i][0] * d_pad[0] + r[i][1] * d_pad[1] + r[i][2] * d_pad[2]);
        self.camera.project(d_cam)
    }

    fn px(&self, p: Point2) -> Result<Point2, RenderError> {
        self.pad_mm_to_raw_px(p).ok_or(RenderError::NotInView(p))
    }

    fn displaced_px(&self, p: Point2, towards_camera_mm: f64) -> Result<Point2, RenderError> {
        // A linear pad model sinks the pattern without bound under a small heavy tip; through a layered pad's gel the
        // ray then has nothing left to cross, which is the load's doing, not the camera's.
        if let Some(window) = self.window.as_ref().filter(|w| towards_camera_mm > w.gel_mm) {
            return Err(RenderError::SunkPastGel {
                at_mm: p,
                sink_mm: towards_camera_mm,
                gel_mm: window.gel_mm,
            });
        }
        self.displaced_to_raw_px(p, towards_camera_mm)
            .ok_or(RenderError::NotInView(p))
    }

    /// This renderer with the camera moved against the pad (`pose` replaced): what a camera that crept on its
    /// mount sees. The pad, its texture and its mechanics stay.
    pub fn with_pose(&self, pose: crate::model::PadPose) -> Result<Self, ModelError> {
        let model = SensorModel {
            pose,
            ..self.model.clone()
        };
        model.validate()?;
        let (geometry, parallax) = pixel_geometry(&model, &self.camera, self.window.as_ref());
        let light = pixel_light(&model, &geometry);
        Ok(Self {
            model,
            geometry,
            parallax,
            light,
            ..self.clone()
        })
    }

    /// Renders one frame. `led_currents_ma`: Top, Right, Bottom, Left (the protocol's side order), 100 mA nominal.
    /// The same scene, currents and seed always give the same frame.
    pub fn render(
        &self,
        scene: &Scene,
        led_currents_ma: [f32; 4],
        seed: u64,
    ) -> Result<(RgbImage, GroundTruth), RenderError> {
        let (image, pad) = self.render_image(scene, led_currents_ma, seed)?;
        let truth = self.truth_of(scene, &pad, led_currents_ma, seed)?;
        Ok((image, truth))
    }

    /// Only the ground truth (no image): cheap.
    pub fn ground_truth(
        &self,
        scene: &Scene,
        led_currents_ma: [f32; 4],
        seed: u64,
    ) -> Result<GroundTruth, RenderError> {
        check_inputs(&self.model, scene, led_currents_ma)?;
        let pad = Deformation::new(&self.model, self.spectral.as_ref(), scene);
        self.truth_of(scene, &pad, led_currents_ma, seed)
    }

    /// The pad's in-plane displacement as meshes in the pattern's plane: the inverse map from where a point is
    /// seen to where it sits in the material and, for the layered pad, the forward in-plane map with the solved field
    /// (whose normal displacement the parallax needs). None where nothing moves.
    #[allow(clippy::type_complexity)]
    fn meshes<'a>(
        &self,
        pad: &'a Deformation,
    ) -> (Option<DisplacementMesh>, Option<(DisplacementMesh, &'a LayerField)>) {
        match pad {
            Deformation::HalfSpace(loaded) => (
                loaded.is_loaded().then(|| {
                    DisplacementMesh::sample(self.mesh_min, self.mesh_max, self.model.mesh_step_mm, |p| {
                        let u = loaded.displacement_mm(p);
                        [u[0], u[1]]
                    })
                    .inverse()
                }),
                None,
            ),
            Deformation::Layered { field, .. } => match field {
                Some(field) => {
                    let in_plane = DisplacementMesh {
                        origin_mm: field.origin_mm,
                        step_mm: field.step_mm,
                        nx: field.nx,
                        ny: field.ny,
                        values: field.values.iter().map(|v| [v[0] as f32, v[1] as f32]).collect(),
                    };
                    let inverse = in_plane.inverse();
                    (Some(inverse), Some((in_plane, field)))
                }
                None => (None, None),
            },
        }
    }

    /// Where in the material the point seen at `q` (pattern plane, mm) by pixel `index` sits, through
    /// [`Self::meshes`]' maps.
    fn material_point(
        &self,
        q: [f32; 2],
        index: usize,
        inverse: Option<&DisplacementMesh>,
        forward: Option<&(DisplacementMesh, &LayerField)>,
    ) -> [f32; 2] {
        match (inverse, forward) {
            (Some(mesh), None) => {
                let v = mesh.at(q);
                [q[0] + v[0], q[1] + v[1]]
            }
            (Some(mesh), Some((in_plane, field))) => {
                // The point seen moved sideways by u and towards the camera by w, which the oblique ray
                // sees as a further sideways shift: solve p + u(p) + w(p) s = q by fixed point from the
                // in-plane inverse (|grad u| and |s| are well below 1).
                let s = self.parallax[index];
                let v = mesh.at(q);
                let mut p = [q[0] + v[0], q[1] + v[1]];
                for _ in 0..3 {
                    let u = in_plane.at(p);
                    let w = field.at([f64::from(p[0]), f64::from(p[1])])[2] as f32;
                    p = [q[0] - u[0] - w * s[0], q[1] - u[1] - w * s[1]];
                }
                p
            }
            _ => q,
        }
    }

    /// Adds the sensor's noise to one pixel's `rgb` from 64 random `bits`: read noise of `noise_scale` (per unit of
    /// a triangular variate), or with shot noise, a level that grows with the signal.
    fn add_noise(&self, rgb: &mut [f32; 3], bits: u64, noise_scale: f32) {
        let shot_noise = self.model.shot_noise;
        for (k, value) in rgb.iter_mut().enumerate() {
            // Two uniform bytes sum to a triangular variate on [-255, 255], variance 255^2 / 6.
            let a = ((bits >> (16 * k)) & 0xff) as f32;
            let b = ((bits >> (16 * k + 8)) & 0xff) as f32;
            let scale = if shot_noise > 0.0 {
                let sigma = (self.model.noise_sigma.powi(2) + shot_noise * value.max(0.0)).sqrt();
                sigma * 6f32.sqrt() / 255.0
            } else {
                noise_scale
            };
            *value += (a + b - 255.0) * scale;
        }
    }

    /// The pad's colour over a pixel's footprint (half-extents `half`, mm) about material point `p`: surround,
    /// rim, lines and squares by their coverage, the squares' ink missing or smeared where `damage` says (missing:
    /// whether the ink is gone, else smeared by the last value; centre and radius in mm).
    fn pad_colour(&self, p: [f32; 2], half: [f32; 2], damage: &[(bool, [f32; 2], f32, f32)]) -> [f32; 3] {
        let colours = &self.model.colours;
        let mut half = half;
        let mut yellow_kept = 1.0;
        for &(missing, centre, radius, smear) in damage {
            let distance = (p[0] - centre[0]).hypot(p[1] - centre[1]);
            let inside = disc_coverage(distance, radius, half[0].max(half[1]));
            if inside > 0.0 {
                if missing {
                    yellow_kept *= 1.0 - inside;
                } else {
                    half = [half[0] + smear * inside, half[1] + smear * inside];
                }
            }
        }
        let (rim, pattern, yellow, red) = self.layout.coverage(p, half);
        // Where the yellow ink is gone, the red base (the lines' colour) shows.
        let yellow = yellow * yellow_kept;
        let shade = if rim > 0.0 {
            1.0 + self.model.texture_amplitude * self.texture.at(p)
        } else {
            1.0
        };
        std::array::from_fn(|k| {
            colours.surround[k] * (1.0 - rim)
                + colours.rim[k] * (rim - pattern)
                + (colours.lines[k] * (pattern - yellow - red) + colours.red[k] * red + colours.yellow[k] * yellow)
                    * shade
        })
    }

    fn render_image(
        &self,
        scene: &Scene,
        led_currents_ma: [f32; 4],
        seed: u64,
    ) -> Result<(RgbImage, Deformation), RenderError> {
        check_inputs(&self.model, scene, led_currents_ma)?;
        let pad = Deformation::new(&self.model, self.spectral.as_ref(), scene);
        let (inverse, forward) = self.meshes(&pad);
        let gains = led_currents_ma.map(|c| c / self.model.lighting.nominal_current_ma);
        let colours = &self.model.colours;
        let damage: Vec<(bool, [f32; 2], f32, f32)> = scene
            .damage
            .iter()
            .map(|d| match *d {
                Damage::Missing { centre_mm, radius_mm } => (true, centre_mm.map(|v| v as f32), radius_mm as f32, 0.0),
                Damage::Smeared {
                    centre_mm,
                    radius_mm,
                    smear_mm,
                } => (false, centre_mm.map(|v| v as f32), radius_mm as f32, smear_mm as f32),
            })
            .collect();
        let occlusions: Vec<([f32; 2], f32, [f32; 3])> = scene
            .occlusions
            .iter()
            .map(|o| {
                (
                    o.centre_mm.map(|v| v as f32),
                    o.radius_mm as f32,
                    o.colour.map(f32::from),
                )
            })
            .collect();
        let noise_scale = self.model.noise_sigma * 6f32.sqrt() / 255.0;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        // The mesh reaches MESH_MARGIN_MM beyond the rim, wider than any pixel footprint.
        let surround_beyond = [self.mesh_max[0] as f32, self.mesh_max[1] as f32];

        let mean_gain = gains.iter().sum::<f32>() / 4.0;
        let shot_noise = self.model.shot_noise;
        let mut image = RgbImage::new(self.model.width, self.model.height);
        for (index, ((out, g), light)) in image
            .as_mut()
            .chunks_exact_mut(3)
            .zip(&self.geometry)
            .zip(&self.light)
            .enumerate()
        {
            let q = g.q;
            let brightness = gains[0] * light.side[0]
                + gains[1] * light.side[1]
                + gains[2] * light.side[2]
                + gains[3] * light.side[3]
                + light.ambient;
            // Beyond the mesh nothing moves and only the surround can be seen: skip the pattern.
            let albedo = if q[0].abs() > surround_beyond[0] || q[1].abs() > surround_beyond[1] {
                colours.surround
            } else {
                let p = self.material_point(q, index, inverse.as_ref(), forward.as_ref());
                self.pad_colour(p, g.half, &damage)
            };
            let glare = light.glare * 255.0 * mean_gain;
            let mut rgb: [f32; 3] = albedo.map(|a| a * brightness + glare);
            for &(centre, radius, colour) in &occlusions {
                let distance = (q[0] - centre[0]).hypot(q[1] - centre[1]);
                let cover = disc_coverage(distance, radius, g.half[0].max(g.half[1]));
                if cover > 0.0 {
                    for k in 0..3 {
                        rgb[k] += (colour[k] * brightness.min(1.0) - rgb[k]) * cover;
                    }
                }
            }
            if noise_scale > 0.0 || shot_noise > 0.0 {
                self.add_noise(&mut rgb, rng.next_u64(), noise_scale);
            }
            for (channel, value) in out.iter_mut().zip(rgb) {
                *channel = (value + 0.5).clamp(0.0, 255.0) as u8;
            }
        }
        if let Some(quality) = self.model.jpeg_quality {
            image = jpeg_round_trip(&image, quality)?;
        }
        Ok((image, pad))
    }

    fn truth_of(
        &self,
        scene: &Scene,
        pad: &Deformation,
        led_currents_ma: [f32; 4],
        seed: u64,
    ) -> Result<GroundTruth, RenderError> {
        let geometry = &self.model.pad;
        let mut corners = Vec::with_capacity(geometry.corner_count());
        // The half-space model's camera does not see the pattern's motion into the pad; the layered one does.
        let parallax = self.window.is_some();
        for index in geometry.corners() {
            let rest_mm = geometry.corner_mm(index);
            let u = pad.displacement_mm(rest_mm);
            let displaced_mm = [rest_mm[0] + u[0], rest_mm[1] + u[1]];
            corners.push(CornerTruth {
                index,
                rest_mm,
                displaced_mm,
                normal_displacement_mm: u[2],
                rest_px: self.px(rest_mm)?,
                displaced_px: self.displaced_px(displaced_mm, if parallax { u[2] } else { 0.0 })?,
            });
        }
        let mut contacts = Vec::with_capacity(scene.contacts.len());
        for (contact, load) in scene.contacts.iter().zip(pad.loads()) {
            let centre_px = self.px(contact.position_mm)?;
            let edge_angle_deg = contact.indenter.edge_angle_deg();
            let edge_angle_px_deg = match edge_angle_deg {
                Some(angle) => {
                    let (s, c) = angle.to_radians().sin_cos();
                    let ahead = self.px([contact.position_mm[0] + 0.5 * c, contact.position_mm[1] + 0.5 * s])?;
                    let behind = self.px([contact.position_mm[0] - 0.5 * c, contact.position_mm[1] - 0.5 * s])?;
                    Some(
                        (ahead[1] - behind[1])
                            .atan2(ahead[0] - behind[0])
                            .to_degrees()
                            .rem_euclid(180.0),
                    )
                }
                None => None,
            };
            contacts.push(ContactTruth {
                indenter: contact.indenter.clone(),
                centre_mm: contact.position_mm,
                centre_px,
                normal_force_n: contact.normal_force_n,
                tangential_force_n: contact.tangential_force_n,
                torsion_nmm: contact.torsion_nmm,
                contact_radius_mm: load.contact_radius_mm,
                area_mm2: loaded_area_mm2(&contact.indenter, load.contact_radius_mm),
                edge_angle_deg,
                edge_angle_px_deg,
            });
        }
        let force_vector_n = scene.contacts.iter().fold([0.0; 3], |acc, c| {
            [
                acc[0] + c.tangential_force_n[0],
                acc[1] + c.tangential_force_n[1],
                acc[2] + c.normal_force_n,
            ]
        });
        let torque_nmm = scene
            .contacts
            .iter()
            .map(|c| {
                c.torsion_nmm + c.position_mm[0] * c.tangential_force_n[1] - c.position_mm[1] * c.tangential_force_n[0]
            })
            .sum();
        Ok(GroundTruth {
            width: self.model.width,
            height: self.model.height,
            seed,
            led_currents_ma,
            contacts,
            total_force_n: scene.total_normal_force_n(),
            force_vector_n,
            torque_nmm,
            corners,
        })
    }
}

/// The area the indenter loads: a disc for round tips, the strip for an edge.
fn loaded_area_mm2(indenter: &crate::scene::Indenter, radius_mm: f64) -> f64 {
    match indenter {
        crate::scene::Indenter::Sphere { .. } | crate::scene::Indenter::FlatPunch { .. } => {
            std::f64::consts::PI * radius_mm * radius_mm
        }
        crate::scene::Indenter::Edge {
            length_mm, width_mm, ..
        } => length_mm * width_mm,
    }
}

fn check_inputs(model: &SensorModel, scene: &Scene, led_currents_ma: [f32; 4]) -> Result<(), RenderError> {
    for (side, value) in SIDES.iter().zip(led_currents_ma) {
        if !(value.is_finite() && value >= 0.0) {
            return Err(RenderError::BadCurrent { side, value });
        }
    }
    scene.validate(&model.pad)?;
    Ok(())
}

fn jpeg_round_trip(image: &RgbImage, quality: u8) -> Result<RgbImage, image::ImageError> {
    let mut bytes = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, quality).encode_image(image)?;
    Ok(image::load_from_memory_with_format(&bytes, image::ImageFormat::Jpeg)?.to_rgb8())
}

/// Ray-casts the pixel-corner lattice onto the pad plane, then takes each pixel's centre and footprint from its
/// four corners.
fn pixel_geometry(
    model: &SensorModel,
    camera: &Camera,
    window: Option<&Window>,
) -> (Vec<PixelGeometry>, Vec<[f32; 2]>) {
    let (w, h) = (model.width as usize, model.height as usize);
    let rays = RayCaster::new(model, camera, window);
    let mut lattice: Vec<Option<[f64; 2]>> = Vec::with_capacity((w + 1) * (h + 1));
    let mut slopes: Vec<[f64; 2]> = Vec::with_capacity(if window.is_some() { (w + 1) * (h + 1) } else { 0 });
    for j in 0..=h {
        for i in 0..=w {
            let hit = rays.cast(i as f64, j as f64);
            lattice.push(hit.map(|(q, _)| q));
            if window.is_some() {
                slopes.push(hit.map_or([0.0, 0.0], |(_, s)| s));
            }
        }
    }
    let parallax = if window.is_some() {
        pixel_parallax(&slopes, w, h)
    } else {
        Vec::new()
    };
    (pixel_footprints(&lattice, w, h, f64::from(model.blur_px)), parallax)
}

/// Where a pixel's ray meets the pattern's plane: straight, or through the window's plate and gel.
struct RayCaster<'a> {
    camera: &'a Camera,
    window: Option<&'a Window>,
    rotation: [[f64; 3]; 3],
    /// The pad's centre in camera coordinates.
    t: [f64; 3],
    /// The pad's normal in camera coordinates.
    normal: [f64; 3],
    normal_dot_t: f64,
    camera_in_pad: [f64; 3],
}

impl<'a> RayCaster<'a> {
    fn new(model: &SensorModel, camera: &'a Camera, window: Option<&'a Window>) -> Self {
        let rotation = model.pose.rotation();
        let t = [model.pose.shift_mm[0], model.pose.shift_mm[1], model.pose.distance_mm];
        let normal = [rotation[0][2], rotation[1][2], rotation[2][2]];
        let normal_dot_t = normal[0] * t[0] + normal[1] * t[1] + normal[2] * t[2];
        Self {
            camera,
            window,
            rotation,
            t,
            normal,
            normal_dot_t,
            camera_in_pad: model.pose.camera_in_pad(),
        }
    }

    /// Rotation is orthonormal: pad coordinates of a camera vector v are R^T v.
    fn to_pad(&self, v: [f64; 3]) -> [f64; 3] {
        let rotation = &self.rotation;
        std::array::from_fn(|k| rotation[0][k] * v[0] + rotation[1][k] * v[1] + rotation[2][k] * v[2])
    }

    /// Where the ray of raw pixel (x, y) meets the pattern's plane (pad mm), and the parallax there.
    fn cast(&self, x: f64, y: f64) -> Option<([f64; 2], [f64; 2])> {
        let n = self.camera.raw_to_normalized([x, y])?;
        let d = [n[0], n[1], 1.0];
        let (normal, t) = (self.normal, self.t);
        match self.window {
            None => {
                let s = self.normal_dot_t / (normal[0] * d[0] + normal[1] * d[1] + normal[2] * d[2]);
                if !(s.is_finite() && s > 0.0) {
                    return None;
                }
                let hit = self.to_pad([s * d[0] - t[0], s * d[1] - t[1], s * d[2] - t[2]]);
                Some(([hit[0], hit[1]], [0.0, 0.0]))
            }
            Some(window) => {
                // Straight through air to the plate, then bent at each flat interface (Snell).
                let d = self.to_pad(d);
                let c = self.camera_in_pad;
                let s = (-(window.plate_mm + window.gel_mm) - c[2]) / d[2];
                if !(s.is_finite() && s > 0.0) {
                    return None;
                }
                let sideways = d[0].hypot(d[1]);
                let sin_air = sideways / (sideways * sideways + d[2] * d[2]).sqrt();
                let along = if sideways > 0.0 {
                    [d[0] / sideways, d[1] / sideways]
                } else {
                    [0.0, 0.0]
                };
                let travel = window.travel(sin_air, window.gel_mm);
                let slope = Window::tan_in(sin_air, window.gel_index);
                Some((
                    [c[0] + s * d[0] + travel * along[0], c[1] + s * d[1] + travel * along[1]],
                    [slope * along[0], slope * along[1]],
                ))
            }
        }
    }
}

/// Each pixel's parallax: the mean of its four corners' ray slopes in the gel.
fn pixel_parallax(slopes: &[[f64; 2]], w: usize, h: usize) -> Vec<[f32; 2]> {
    (0..h)
        .flat_map(|j| (0..w).map(move |i| (i, j)))
        .map(|(i, j)| {
            let corners = [
                j * (w + 1) + i,
                j * (w + 1) + i + 1,
                (j + 1) * (w + 1) + i,
                (j + 1) * (w + 1) + i + 1,
            ];
            let mean = |k: usize| corners.iter().map(|&c| slopes[c][k]).sum::<f64>() / 4.0;
            [mean(0) as f32, mean(1) as f32]
        })
        .collect()
}

/// Each pixel's centre and half-extent on the pad from its four corners, widened by the optical blur (`blur`
/// px); a pixel whose rays miss the pad is nowhere.
fn pixel_footprints(lattice: &[Option<[f64; 2]>], w: usize, h: usize, blur: f64) -> Vec<PixelGeometry> {
    let mut geometry = Vec::with_capacity(w * h);
    for j in 0..h {
        for i in 0..w {
            let corners = [
                lattice[j * (w + 1) + i],
                lattice[j * (w + 1) + i + 1],
                lattice[(j + 1) * (w + 1) + i],
                lattice[(j + 1) * (w + 1) + i + 1],
            ];
            let pixel = match corners {
                [Some(a), Some(b), Some(c), Some(d)] => {
                    let centre = [(a[0] + b[0] + c[0] + d[0]) / 4.0, (a[1] + b[1] + c[1] + d[1]) / 4.0];
                    let along_x = [(b[0] + d[0] - a[0] - c[0]) / 2.0, (b[1] + d[1] - a[1] - c[1]) / 2.0];
                    let along_y = [(c[0] + d[0] - a[0] - b[0]) / 2.0, (c[1] + d[1] - a[1] - b[1]) / 2.0];
                    let half_x = 0.5 * (along_x[0].abs() + along_y[0].abs());
                    let half_y = 0.5 * (along_x[1].abs() + along_y[1].abs());
                    // Gaussian blur of sigma s adds 3 s^2 to the squared half-width of an equivalent box
                    // (variances h^2 / 3 + s^2).
                    let widen = |half: f64| (half * half * (1.0 + 12.0 * blur * blur)).sqrt().max(1e-6);
                    PixelGeometry {
                        q: [centre[0] as f32, centre[1] as f32],
                        half: [widen(half_x) as f32, widen(half_y) as f32],
                    }
                }
                _ => PixelGeometry {
                    q: [NOWHERE_MM, NOWHERE_MM],
                    half: [1.0, 1.0],
                },
            };
            geometry.push(pixel);
        }
    }
    geometry
}

/// Each LED bar lies `bar_offset_mm` outside one edge of the pattern, as long as that edge; its light falls
/// off as 1 / (1 + (d / spread)^2) with the distance d from the bar. Normalised so that all four bars at nominal
/// current give 1 at the pad centre.
fn pixel_light(model: &SensorModel, geometry: &[PixelGeometry]) -> Vec<PixelLight> {
    let lighting = &model.lighting;
    let (hw, hh) = (model.pad.width_mm / 2.0, model.pad.height_mm / 2.0);
    let offset = lighting.bar_offset_mm;
    let falloff = |d: f64| 1.0 / (1.0 + (d / lighting.spread_mm).powi(2));
    let segment_distance = |p: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        let ab = [b[0] - a[0], b[1] - a[1]];
        let t = (((p[0] - a[0]) * ab[0] + (p[1] - a[1]) * ab[1]) / (ab[0] * ab[0] + ab[1] * ab[1])).clamp(0.0, 1.0);
        (p[0] - a[0] - t * ab[0]).hypot(p[1] - a[1] - t * ab[1])
    };
    let bars = [
        ([-hw, -hh - offset], [hw, -hh - offset]),
        ([hw + offset, -hh], [hw + offset, hh]),
        ([-hw, hh + offset], [hw, hh + offset]),
        ([-hw - offset, -hh], [-hw - offset, hh]),
    ];
    let sides_at = |p: [f64; 2]| bars.map(|(a, b)| falloff(segment_distance(p, a, b)));
    let norm: f64 = sides_at([0.0, 0.0]).iter().sum();
    let (w, h) = (model.width as usize, model.height as usize);
    let centre = model.lens.principal_point();
    let corner_radius2 = centre[0].max(f64::from(model.width) - centre[0]).powi(2)
        + centre[1].max(f64::from(model.height) - centre[1]).powi(2);
    let mut light = Vec::with_capacity(w * h);
    for (idx, g) in geometry.iter().enumerate() {
        let (i, j) = (idx % w, idx / w);
        let r2 = (i as f64 + 0.5 - centre[0]).powi(2) + (j as f64 + 0.5 - centre[1]).powi(2);
        let gain = f64::from(model.exposure) * (1.0 - f64::from(model.vignetting) * r2 / corner_radius2);
        // Rays that miss the plane see the housing; light it like the far surround.
        let p = [
            f64::from(g.q[0]).clamp(-3.0 * hw, 3.0 * hw),
            f64::from(g.q[1]).clamp(-3.0 * hh, 3.0 * hh),
        ];
        let sides = sides_at(p).map(|s| (s / norm * gain) as f32);
        let (x, y) = (i as f64 + 0.5, j as f64 + 0.5);
        let glare: f64 = model
            .glare
            .iter()
            .map(|g| {
                let (gx, gy) = (
                    g.centre[0] * f64::from(model.width),
                    g.centre[1] * f64::from(model.height),
                );
                let sigma = g.radius * f64::from(model.width);
                f64::from(g.level) / 255.0 * (-((x - gx).powi(2) + (y - gy).powi(2)) / (2.0 * sigma * sigma)).exp()
            })
            .sum();
        light.push(PixelLight {
            side: sides,
            ambient: (f64::from(lighting.ambient) * gain) as f32,
            glare: glare as f32,
        });
    }
    light
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mechanics::LoadedPad;
    use crate::scene::Contact;

    fn small() -> Renderer {
        Renderer::new(SensorModel::real(320, 240)).unwrap()
    }

    #[test]
    fn same_seed_same_frame_other_seed_other_noise() {
        let r = small();
        let scene = Scene::with_contact(Contact::sphere(5.0, [2.0, 1.0], 4.0));
        let (a, ta) = r.render(&scene, [100.0; 4], 7).unwrap();
        let (b, tb) = r.render(&scene, [100.0; 4], 7).unwrap();
        let (c, _) = r.render(&scene, [100.0; 4], 8).unwrap();
        assert_eq!(a, b);
        assert_eq!(ta, tb);
        assert_ne!(a, c);
    }

    #[test]
    fn led_current_changes_brightness_per_side() {
        let mut model = SensorModel::real(320, 240);
        model.noise_sigma = 0.0;
        let r = Renderer::new(model).unwrap();
        let scene = Scene::rest();
        let mean = |img: &RgbImage, rows: std::ops::Range<u32>| {
            let mut sum = 0.0;
            let mut n = 0.0;
            for y in rows {
                for x in 0..img.width() {
                    let p = img.get_pixel(x, y);
                    sum += f64::from(p[0]) + f64::from(p[1]) + f64::from(p[2]);
                    n += 3.0;
                }
            }
            sum / n
        };
        let (nominal, _) = r.render(&scene, [100.0; 4], 1).unwrap();
        let (dim, _) = r.render(&scene, [50.0; 4], 1).unwrap();
        let (dark, _) = r.render(&scene, [0.0; 4], 1).unwrap();
        let (top_only, _) = r.render(&scene, [100.0, 0.0, 0.0, 0.0], 1).unwrap();
        let all = 0..240;
        assert!(mean(&dark, all.clone()) < 0.5, "no light, no picture");
        let (m_nominal, m_dim) = (mean(&nominal, all.clone()), mean(&dim, all.clone()));
        assert!(
            m_dim < 0.6 * m_nominal && m_dim > 0.4 * m_nominal,
            "{m_dim} vs {m_nominal}"
        );
        // The top bar lights the top of the pad more than the bottom.
        let (top, bottom) = (mean(&top_only, 40..80), mean(&top_only, 160..200));
        assert!(top > 1.3 * bottom, "{top} vs {bottom}");
    }

    #[test]
    fn rest_frame_looks_like_the_real_sensor() {
        let mut model = SensorModel::real(640, 480);
        model.noise_sigma = 0.0;
        let r = Renderer::new(model).unwrap();
        let (img, truth) = r.render(&Scene::rest(), [100.0; 4], 0).unwrap();
        // Centre of a yellow cell (0, 0) and of a red cell (0, 1) at rest.
        let pad = &r.model().pad;
        let yellow = pad.square_centre_mm(nusense_geometry::SquareIndex { row: 5, col: 5 });
        let red = pad.square_centre_mm(nusense_geometry::SquareIndex { row: 5, col: 6 });
        let sample = |p: Point2| {
            let px = r.pad_mm_to_raw_px(p).unwrap();
            *img.get_pixel(px[0] as u32, px[1] as u32)
        };
        let (y, rd) = (sample(yellow), sample(red));
        assert!(y[0] > 180 && y[1] > 170 && y[2] < 200 && y[2] + 40 < y[1], "{y:?}");
        assert!(rd[0] > 130 && rd[1] < 110 && rd[2] > rd[1], "{rd:?}");
        assert!(img.get_pixel(5, 5)[0] < 40, "the surround is dark");
        assert_eq!(truth.corners.len(), 165);
        assert_eq!(truth.max_corner_displacement_mm(), 0.0);
    }

    #[test]
    fn a_press_moves_the_corners_outward_and_the_picture_with_them() {
        let r = small();
        let scene = Scene::with_contact(Contact::sphere(5.0, [0.0, 0.0], 6.0));
        let truth = r.ground_truth(&scene, [100.0; 4], 0).unwrap();
        let moved = truth.max_corner_displacement_mm();
        assert!(moved > 0.2 && moved < 1.5, "{moved}");
        for c in &truth.corners {
            let out =
                (c.displaced_mm[0] - c.rest_mm[0]) * c.rest_mm[0] + (c.displaced_mm[1] - c.rest_mm[1]) * c.rest_mm[1];
            assert!(out >= -1e-9, "{c:?}");
        }
        let (rest, _) = r.render(&Scene::rest(), [100.0; 4], 0).unwrap();
        let (pressed, _) = r.render(&scene, [100.0; 4], 0).unwrap();
        let centre = truth.contacts[0].centre_px;
        let changed_near = count_changed(&rest, &pressed, centre, 30.0);
        let changed_far = count_changed(&rest, &pressed, [20.0, 20.0], 15.0);
        assert!(changed_near > 100, "{changed_near}");
        assert_eq!(changed_far, 0);
    }

    #[test]
    fn yellow_squares_move_as_the_mechanics_says_to_a_fraction_of_a_pixel() {
        // The renderer's inverse warp, anti-aliasing and the forward mechanics must agree: each yellow square's
        // intensity centroid near a press moves like the area centroid of the square pushed through the exact
        // displacement field and the camera.
        // A plain pad: a blotchy one moves its blotches with the material, which weights the centroid unevenly.
        let mut model = SensorModel::real(640, 480);
        model.noise_sigma = 0.0;
        model.texture_amplitude = 0.0;
        let r = Renderer::new(model).unwrap();
        let contact = Contact::sphere(5.0, [1.0, -0.5], 8.0);
        let loaded = LoadedPad::new(std::slice::from_ref(&contact), &r.model().contact_material());
        let (rest, _) = r.render(&Scene::rest(), [100.0; 4], 0).unwrap();
        let (pressed, _) = r.render(&Scene::with_contact(contact), [100.0; 4], 0).unwrap();
        let pad = r.model().pad;
        let half = [
            pad.pitch_x_mm() * r.model().yellow_fill / 2.0,
            pad.pitch_y_mm() * r.model().yellow_fill / 2.0,
        ];
        let mut worst: f64 = 0.0;
        let mut largest_shift: f64 = 0.0;
        for row in 3..9u16 {
            for col in 4..12u16 {
                let cell = nusense_geometry::SquareIndex { row, col };
                if !pad.is_yellow(cell) {
                    continue;
                }
                let centre = pad.square_centre_mm(cell);
                let (before, outline_before) = projected_square(&r, centre, half, |_| [0.0; 3], false);
                let (after, outline_after) = projected_square(&r, centre, half, |p| loaded.displacement_mm(p), false);
                let truth_shift = [after[0] - before[0], after[1] - before[1]];
                let (c0, c1) = (
                    yellow_centroid(&rest, &outline_before),
                    yellow_centroid(&pressed, &outline_after),
                );
                let image_shift = [c1[0] - c0[0], c1[1] - c0[1]];
                worst = worst.max((image_shift[0] - truth_shift[0]).hypot(image_shift[1] - truth_shift[1]));
                largest_shift = largest_shift.max(truth_shift[0].hypot(truth_shift[1]));
            }
        }
        println!("largest square shift {largest_shift:.2} px, worst centroid disagreement {worst:.3} px");
        assert!(largest_shift > 5.0, "{largest_shift}");
        // Measured 0.10 px at 640 x 480 with shifts up to 6.2 px.
        assert!(worst < 0.15, "{worst}");
    }

    #[test]
    fn through_the_plate_squares_move_as_the_layered_mechanics_and_parallax_say() {
        // The validation sensor (layers, refraction, parallax, another lens), its pixels and ground truth must
        // agree: each yellow square's intensity centroid near a press moves like its area pushed through the
        // solved field (in-plane motion plus the motion towards the camera seen obliquely through plate and gel).
        let mut model = SensorModel::validation(640, 480);
        model.noise_sigma = 0.0;
        model.shot_noise = 0.0;
        model.texture_amplitude = 0.0;
        model.jpeg_quality = None;
        model.glare.clear();
        let r = Renderer::new(model).unwrap();
        let scene = Scene::with_contact(Contact::sphere(5.0, [-4.0, 3.0], 8.0));
        let deformation = Deformation::new(r.model(), r.spectral.as_ref(), &scene);
        let (rest, _) = r.render(&Scene::rest(), [100.0; 4], 0).unwrap();
        let (pressed, truth) = r.render(&scene, [100.0; 4], 0).unwrap();
        let pad = r.model().pad;
        let half = [
            pad.pitch_x_mm() * r.model().yellow_fill / 2.0,
            pad.pitch_y_mm() * r.model().yellow_fill / 2.0,
        ];
        let (mut worst, mut largest_shift, mut parallax_effect): (f64, f64, f64) = (0.0, 0.0, 0.0);
        for row in 3..10u16 {
            for col in 3..11u16 {
                let cell = nusense_geometry::SquareIndex { row, col };
                if !pad.is_yellow(cell) {
                    continue;
                }
                let centre = pad.square_centre_mm(cell);
                let (before, outline_before) = projected_square(&r, centre, half, |_| [0.0; 3], true);
                let field = |p| deformation.displacement_mm(p);
                let (after, outline_after) = projected_square(&r, centre, half, field, true);
                let (flat, _) = projected_square(&r, centre, half, field, false);
                let truth_shift = [after[0] - before[0], after[1] - before[1]];
                let (c0, c1) = (
                    yellow_centroid(&rest, &outline_before),
                    yellow_centroid(&pressed, &outline_after),
                );
                worst = worst.max((c1[0] - c0[0] - truth_shift[0]).hypot(c1[1] - c0[1] - truth_shift[1]));
                largest_shift = largest_shift.max(truth_shift[0].hypot(truth_shift[1]));
                parallax_effect = parallax_effect.max((after[0] - flat[0]).hypot(after[1] - flat[1]));
            }
        }
        println!(
            "largest square shift {largest_shift:.2} px, parallax up to {parallax_effect:.2} px, worst centroid \
             disagreement {worst:.3} px"
        );
        // Measured: shifts up to 4.0 px, parallax up to 0.8 px, worst disagreement 0.12 px.
        assert!(largest_shift > 3.0, "{largest_shift}");
        assert!(
            parallax_effect > 0.2,
            "the motion towards the camera shows: {parallax_effect}"
        );
        assert!(worst < 0.15, "{worst}");
        // The truth's totals.
        assert_eq!(truth.force_vector_n, [0.0, 0.0, 8.0]);
        assert_eq!(truth.torque_nmm, 0.0);
        let a = truth.contacts[0].contact_radius_mm;
        assert!((truth.contacts[0].area_mm2 - std::f64::consts::PI * a * a).abs() < 1e-12);
    }

    /// Area centroid (raw px) of the square `centre +- half` (pad mm) after displacing it by `u`, from a fine
    /// grid of small quads; and its four corners pushed 15 % away from that centroid (a window that holds the
    /// blurred square and none of its neighbours).
    fn projected_square(
        r: &Renderer,
        centre: Point2,
        half: [f64; 2],
        u: impl Fn(Point2) -> [f64; 3],
        parallax: bool,
    ) -> (Point2, [Point2; 4]) {
        const N: usize = 16;
        let node = |i: usize, j: usize| {
            let p = [
                centre[0] - half[0] + 2.0 * half[0] * i as f64 / N as f64,
                centre[1] - half[1] + 2.0 * half[1] * j as f64 / N as f64,
            ];
            let d = u(p);
            let towards_camera = if parallax { d[2] } else { 0.0 };
            r.displaced_to_raw_px([p[0] + d[0], p[1] + d[1]], towards_camera)
                .unwrap()
        };
        let nodes: Vec<Vec<Point2>> = (0..=N).map(|j| (0..=N).map(|i| node(i, j)).collect()).collect();
        let (mut area, mut cx, mut cy) = (0.0, 0.0, 0.0);
        for j in 0..N {
            for i in 0..N {
                let quad = [nodes[j][i], nodes[j][i + 1], nodes[j + 1][i + 1], nodes[j + 1][i]];
                // Shoelace area and centroid of the small quad.
                for k in 0..4 {
                    let (a, b) = (quad[k], quad[(k + 1) % 4]);
                    let cross = a[0] * b[1] - b[0] * a[1];
                    area += cross / 2.0;
                    cx += (a[0] + b[0]) * cross / 6.0;
                    cy += (a[1] + b[1]) * cross / 6.0;
                }
            }
        }
        let centroid = [cx / area, cy / area];
        let grow = |p: Point2| {
            [
                centroid[0] + 1.15 * (p[0] - centroid[0]),
                centroid[1] + 1.15 * (p[1] - centroid[1]),
            ]
        };
        (
            centroid,
            [
                grow(nodes[0][0]),
                grow(nodes[0][N]),
                grow(nodes[N][N]),
                grow(nodes[N][0]),
            ],
        )
    }

    /// Centroid of yellowness (green minus blue; zero on the red cells and the lines) inside a convex outline.
    fn yellow_centroid(img: &RgbImage, outline: &[Point2; 4]) -> [f64; 2] {
        let inside = |x: f64, y: f64| {
            let side = |a: Point2, b: Point2| (b[0] - a[0]) * (y - a[1]) - (b[1] - a[1]) * (x - a[0]);
            let signs: Vec<f64> = (0..4).map(|k| side(outline[k], outline[(k + 1) % 4])).collect();
            signs.iter().all(|s| *s >= 0.0) || signs.iter().all(|s| *s <= 0.0)
        };
        let min = [
            outline.iter().map(|p| p[0]).fold(f64::MAX, f64::min),
            outline.iter().map(|p| p[1]).fold(f64::MAX, f64::min),
        ];
        let max = [
            outline.iter().map(|p| p[0]).fold(f64::MIN, f64::max),
            outline.iter().map(|p| p[1]).fold(f64::MIN, f64::max),
        ];
        let (mut sx, mut sy, mut sw) = (0.0, 0.0, 0.0);
        for y in (min[1] as u32)..=(max[1] as u32) {
            for x in (min[0] as u32)..=(max[0] as u32) {
                let (px, py) = (f64::from(x) + 0.5, f64::from(y) + 0.5);
                if !inside(px, py) {
                    continue;
                }
                let p = img.get_pixel(x, y);
                let w = (f64::from(p[1]) - f64::from(p[2])).max(0.0);
                sx += w * px;
                sy += w * py;
                sw += w;
            }
        }
        [sx / sw, sy / sw]
    }

    fn count_changed(a: &RgbImage, b: &RgbImage, centre: [f64; 2], radius: f64) -> usize {
        a.enumerate_pixels()
            .filter(|(x, y, p)| {
                let d = (f64::from(*x) + 0.5 - centre[0]).hypot(f64::from(*y) + 0.5 - centre[1]);
                let q = b.get_pixel(*x, *y);
                d < radius && (0..3).any(|k| (i32::from(p[k]) - i32::from(q[k])).abs() > 12)
            })
            .count()
    }

    #[test]
    fn jpeg_damage_and_occlusion_options_render() {
        let mut model = SensorModel::real(320, 240);
        model.jpeg_quality = Some(70);
        let r = Renderer::new(model).unwrap();
        let mut scene = Scene::rest();
        scene.damage.push(Damage::Missing {
            centre_mm: [0.0, 0.0],
            radius_mm: 6.0,
        });
        scene.occlusions.push(crate::scene::Occlusion {
            centre_mm: [15.0, 10.0],
            radius_mm: 4.0,
            colour: [0, 0, 0],
        });
        let (img, _) = r.render(&scene, [100.0; 4], 3).unwrap();
        let centre = r.pad_mm_to_raw_px([1.6, 1.6]).unwrap();
        let p = img.get_pixel(centre[0] as u32, centre[1] as u32);
        assert!(p[1] < 120, "the yellow square at the centre is gone: {p:?}");
        let occluded = r.pad_mm_to_raw_px([15.0, 10.0]).unwrap();
        let p = img.get_pixel(occluded[0] as u32, occluded[1] as u32);
        assert!(p[0] < 40 && p[1] < 40, "{p:?}");
    }

    #[test]
    fn bad_inputs_are_typed_errors() {
        let r = small();
        assert!(matches!(
            r.render(&Scene::rest(), [100.0, f32::NAN, 0.0, 0.0], 0),
            Err(RenderError::BadCurrent { side: "right", .. })
        ));
        let bad = Scene::with_contact(Contact::sphere(-1.0, [0.0, 0.0], 1.0));
        assert!(matches!(r.render(&bad, [100.0; 4], 0), Err(RenderError::Scene(_))));
        let mut model = SensorModel::real(320, 240);
        model.noise_sigma = f32::INFINITY;
        assert!(Renderer::new(model).is_err());
    }

    /// A 3 mm sphere at 20 N sinks the validation pad's pattern past its 2.7 mm of elastomer in the linear model: that
    /// is said, not reported as a point out of the camera's view.
    #[test]
    fn a_load_that_sinks_the_pattern_past_the_gel_is_named() {
        let r = Renderer::new(SensorModel::validation(320, 240)).unwrap();
        let heavy = Scene::with_contact(Contact::sphere(3.0, [0.0, 0.0], 20.0));
        match r.render(&heavy, [100.0; 4], 0) {
            Err(RenderError::SunkPastGel { sink_mm, gel_mm, .. }) => assert!(sink_mm > gel_mm, "{sink_mm} {gel_mm}"),
            other => panic!("expected SunkPastGel, got {:?}", other.map(|_| ())),
        }
        let light = Scene::with_contact(Contact::sphere(3.0, [0.0, 0.0], 3.0));
        assert!(r.render(&light, [100.0; 4], 0).is_ok());
    }
}
