//! The sensor config: everything the estimator needs to know about one sensor, as TOML.
//!
//! Every value has a default that fits the real NUSense sensor (the authors' published parameters, which came
//! with the real pair in host/estimator/tests/data/real), so an empty file is a valid config. Unknown keys are
//! errors: a typo must not silently fall back to a default.

use std::path::{Path, PathBuf};

use nusense_geometry::camera::FisheyeIntrinsics;
use nusense_geometry::PadGeometry;
use serde::{Deserialize, Serialize};
use thiserror::Error;

#[derive(Debug, Error)]
pub enum ConfigError {
    #[error("cannot read sensor config {}: {source}", path.display())]
    Io { path: PathBuf, source: std::io::Error },
    #[error("sensor config{}: {message}", file_suffix(path))]
    Parse { path: Option<PathBuf>, message: String },
    #[error("sensor config{}: `{key}` = {value} is not allowed; {allowed}", file_suffix(path))]
    Invalid {
        path: Option<PathBuf>,
        key: &'static str,
        value: String,
        allowed: &'static str,
    },
}

fn file_suffix(path: &Option<PathBuf>) -> String {
    path.as_ref().map(|p| format!(" {}", p.display())).unwrap_or_default()
}

impl ConfigError {
    /// The config key the error is about, when it names one.
    pub fn key(&self) -> Option<&str> {
        match self {
            Self::Invalid { key, .. } => Some(key),
            _ => None,
        }
    }

    fn with_path(self, file: &Path) -> Self {
        match self {
            Self::Parse { message, .. } => Self::Parse {
                path: Some(file.to_owned()),
                message,
            },
            Self::Invalid {
                key, value, allowed, ..
            } => Self::Invalid {
                path: Some(file.to_owned()),
                key,
                value,
                allowed,
            },
            other => other,
        }
    }
}

/// Region of interest in the undistorted frame, in px of the calibration frame size (`camera.width x height`);
/// the paper pipeline crops to it. Scaled with the frame like the camera.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Roi {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
}

impl Default for Roi {
    fn default() -> Self {
        Self {
            x: 390,
            y: 203,
            width: 1335,
            height: 1000,
        }
    }
}

/// Decision thresholds of the fast pipeline. Image thresholds are not here on purpose: they come from each frame
/// (Otsu on yellowness), so that lighting changes do not need a new config.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Thresholds {
    /// Contact when the local (non-affine) displacement of some corner exceeds this, in pad mm.
    pub contact_shear_mm: f64,
    /// A tracked point that moved more than this many cells since the reference is implausible (masked). The tracker
    /// follows a heavy press's motion (a 40 N press with 15 N of shear moves corners 7.8 mm, 2.4 cells), and a point
    /// on the wrong square moves about a cell differently from its neighbours, which registration masks on its own.
    /// The paper mode's detector, which indexes each frame afresh, is held to 1.5 cells at most.
    pub max_displacement_cells: f64,
    /// Tracking is abandoned for a full-frame search when more than this fraction of squares is lost.
    pub recovery_lost_fraction: f64,
    /// Samples sheared by at least this fraction of the peak feed the edge-direction PCA.
    pub edge_sample_fraction: f64,
    /// Below this eigenvalue contrast (1 - minor/major) the contact counts as round: no edge direction.
    pub edge_min_confidence: f64,
}

impl Default for Thresholds {
    fn default() -> Self {
        Self {
            contact_shear_mm: 0.12,
            max_displacement_cells: 2.5,
            recovery_lost_fraction: 0.25,
            edge_sample_fraction: 0.5,
            edge_min_confidence: 0.35,
        }
    }
}

/// F = a * gamma + b, gamma = alpha * sum ||s - s_ref|| (paper units: px of a 2048-px-wide frame).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ForceCalibration {
    pub a: f64,
    pub b: f64,
    pub alpha: f64,
}

impl Default for ForceCalibration {
    fn default() -> Self {
        Self {
            a: 3.09,
            b: -1.14,
            alpha: 1.0 / 18000.0,
        }
    }
}

/// The B-spline surface over the corner lattice: degree along rows (u) and columns (v), sampled on a uv grid.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SurfaceConfig {
    pub degree_u: usize,
    pub degree_v: usize,
    /// Step of the sample grid in u and v (the paper: 0.015, i.e. 67 x 67 samples).
    pub uv_step: f64,
}

impl Default for SurfaceConfig {
    fn default() -> Self {
        Self {
            degree_u: 1,
            degree_v: 1,
            uv_step: 0.015,
        }
    }
}

/// The published pipeline's parameters (mode `paper`), on the undistorted frame of the calibration size.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PaperParams {
    pub bilateral_diameter: u32,
    pub bilateral_sigma_color: f64,
    pub bilateral_sigma_space: f64,
    pub sobel_weight_x: f64,
    pub sobel_weight_y: f64,
    pub binary_threshold: f64,
    pub polygon_epsilon_fraction: f64,
    pub quad_min_area_px2: f64,
    pub quad_max_area_px2: f64,
    pub quad_min_solidity: f64,
    pub pair_distance_px: f64,
}

impl Default for PaperParams {
    fn default() -> Self {
        Self {
            bilateral_diameter: 20,
            bilateral_sigma_color: 65.0,
            bilateral_sigma_space: 75.0,
            sobel_weight_x: 0.86,
            sobel_weight_y: 0.86,
            binary_threshold: 19.0,
            polygon_epsilon_fraction: 0.08,
            quad_min_area_px2: 2000.0,
            quad_max_area_px2: 100000.0,
            quad_min_solidity: 0.2,
            pair_distance_px: 50.0,
        }
    }
}

/// Which elastic solution relates surface tractions to the pattern's displacement (see [`crate::elastic`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ElasticModel {
    /// The pad's layers as built: a stiff skin over soft gel (and optionally a bond layer) on a rigid plate, the
    /// pattern under the skin.
    Layered,
    /// One equivalent layer of gel on a rigid plate, the pattern `cover_mm` deep in it (the model before the skin was
    /// modelled; its far field dies too slowly, see [`ElasticConfig`]).
    BondedLayer,
    /// An elastic half-space (Boussinesq and Cerruti): the fallback when the layer's thickness is unknown.
    HalfSpace,
}

/// The pad's mechanics: what turns displacements in mm into forces in N without any calibration.
///
/// Defaults describe the NUSense pad (the paper's layer stack): 2.2 mm of soft gel on 3 mm of Plexiglass, under an
/// outer Sorta-Clear 18 skin and the dyed pattern layer. The skin is stiffer than the gel and spreads the load;
/// `cover_mm` is its equivalent thickness of gel, and with the gel's modulus it is the project's model of the real
/// pad (the simulator's `Material::real`: the pattern 2.8 mm deep, G = 48 kPa). `nusense calibrate` fits the
/// modulus's scale from a force/torque log.
///
/// `model = "layered"` models the stack as built instead: the skin (`skin_mm`, its modulus `skin_modulus_ratio`
/// times the gel's), the pattern at its bottom, the gel (`gel_mm`, `shear_modulus_kpa`), optionally a bond layer
/// (`bond_mm`, `bond_modulus_ratio`), bonded to the rigid plate. Its values for the NUSense pad: the skin's
/// G = 200 kPa (Sorta-Clear 18's data sheet, E about 0.6 MPa, incompressible); the gel's 2.2 mm (the paper); the skin's
/// thickness and the gel's modulus are published nowhere, so they are the two numbers that turn the equivalent layer
/// fitted to the real pair into a real stack: Odemark's equivalence h_skin (G_skin / G_gel)^(1/3) = 2.8 mm and the
/// same peak in-plane displacement under a 6 N press of 5 mm radius, which give G_gel = 11 kPa
/// (`LAYERED_GEL_KPA`) and h_skin = 1.07 mm (`LAYERED_SKIN_MM`); no bond layer (its thickness is not published
/// either). What it gets right that the equivalent layer does not is shear against pressure: on the quick validation
/// set (at 122e3ba) the pushes' tangential force reads 0.87 times the truth (0.22 N RMS) against 2.40 times (2.39 N),
/// torque 2.1 against 18.7 N mm RMS (both with the normal force's calibration alone; `tangential_force_scale`
/// calibrates the equivalent layer's shear: 0.16 N and 1.3 N mm), the push's direction 1.0 / 2.1 deg mean / max
/// against 1.6 / 6.1. Not the
/// default, because the normal load reads worse: force over the pad 0.41 N RMS against 0.36, localisation 0.44
/// against 0.33 mm (0.40 since its contact centres come from quarter cells, see `InverseModel::quarter_centres`),
/// both of two contacts 10 mm apart listed in 4 of 6 cases against 6, the edges' floor 0.5 against 0.3 N; the
/// inverse's 3.3 mm cells and heuristics were built around the equivalent layer's smoother kernel. To use it, set
/// `model = "layered"` and `shear_modulus_kpa = 11`.
///
/// The pad's edge is free by default: measured on simulated pads without a clamped edge, assuming one where there
/// is none moves contacts near the edge by up to 1 mm and costs 0.35 N RMS of force, while on a pad bonded 3 mm
/// beyond the pattern the rigid plate below already confines the response to a few millimetres.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ElasticConfig {
    pub model: ElasticModel,
    /// Shear modulus of the gel, kPa (`layered`: the soft gel under the pattern; `bonded_layer` and `half_space`:
    /// the one equivalent material). `nusense calibrate` scales it, and with it the whole stack (the skin's and
    /// bond's moduli are given as ratios to it).
    pub shear_modulus_kpa: f64,
    /// 0.5 = incompressible (silicone gels nearly are); every layer's.
    pub poisson_ratio: f64,
    /// Thickness of the skin above the pattern, mm (`layered` only; the pattern lies at its bottom).
    pub skin_mm: f64,
    /// The skin's shear modulus over the gel's (`layered` only).
    pub skin_modulus_ratio: f64,
    /// Thickness of a bond layer between the gel and the plate, mm; 0 for none (`layered` only).
    pub bond_mm: f64,
    /// The bond layer's shear modulus over the gel's (`layered` with `bond_mm` > 0 only).
    pub bond_modulus_ratio: f64,
    /// Depth of the pattern layer below the contact surface, as an equivalent thickness of gel, mm (`bonded_layer`
    /// and `half_space` only).
    pub cover_mm: f64,
    /// Gel between the pattern layer and the rigid plate, mm (bonded layer only).
    pub gel_mm: f64,
    /// The pad is bonded to its frame around the pattern (bonded layer and layered models).
    pub bonded_border: bool,
    /// The pad is held in a frame whose walls, `border_margin_mm` beyond the pattern, it slides along (bonded layer and
    /// layered models, and not with `bonded_border`; see [`crate::elastic::Border::Sliding`]). Off by default: on the
    /// validation sensor, whose pad is held so (4 mm beyond the pattern), it brought the quick set's force over the pad
    /// from 0.34 to 0.22 N RMS at 16c9bf7, but on the simulated real sensor's pad, an unbounded half-space, it moves a
    /// press one cell from the border 1 mm inwards and misreads a rest frame with one LED side 20 % up as a contact at
    /// the pattern's corner (tests/hard_cases.rs); which holds for the real pad has not been measured.
    pub sliding_walls: bool,
    /// Distance from the pattern's edge to where the pad is bonded to its frame, or to the frame's walls, mm.
    pub border_margin_mm: f64,
    /// Refractive index of the gel between the pattern and the plate. A press pushes the pattern towards the camera,
    /// and the camera sees it through the gel along oblique rays: it appears shifted away from the camera's foot by
    /// its normal displacement times the ray's slope in the gel (0.2 at 20 mm from the foot of a camera 72 mm away
    /// with 1.41), as much as a press's own in-plane displacement near the border. The inverse models it from the
    /// rest frame's pose (see [`crate::elastic::parallax_shifts`]); 0 leaves it out. Default: silicone, 1.41.
    pub gel_refractive_index: f64,
    /// The pattern's normal displacement, which the parallax sees (`gel_refractive_index`), from the stack as built
    /// rather than from the equivalent layer (`bonded_layer` only): the stack of `model = "layered"` (`skin_mm`,
    /// `skin_modulus_ratio`, `gel_mm`, `bond_mm`) with its gel at `shear_modulus_kpa` times `LAYERED_GEL_KPA` /
    /// `EQUIVALENT_LAYER_KPA`, the stack that stands for the equivalent layer in-plane (see [`ElasticConfig`]). The
    /// equivalent layer is fitted to the in-plane field, and its normal displacement is not the pad's: a stiff skin
    /// over soft gel bends, and the pattern under it sinks further and wider. On the validation pad, for the true loads
    /// of ten full-set presses of 1-7 N (flat punches of 1.5 and 3 mm, spheres of 3-8 mm; least squares over every
    /// corner, at the force calibration's modulus), the equivalent layer's normal displacement is 0.27-0.57 of the
    /// pad's, the stack's 0.94-1.34; the parallax's geometry (the camera's place, refraction) is within 5 %. The shift
    /// away from the camera's foot that the model lacked read as a tangential force pointing outwards and as extra
    /// pressure, most under flat punches far from the foot (host/estimator/tests/border_force.rs,
    /// docs/benchmarks/validation-full.md). With it, inverse only: the full validation set's force over the pad 0.306
    /// -> 0.229 N (camera moved 0.302 -> 0.236), the quick set's 0.252 -> 0.144 N, localisation, edge direction and
    /// torque better on the full set. Off by default, because three checks and two of the quick set's figures disagree
    /// with it on (measured at d7b6f31, the checks again at d35d57f). On the simulated real sensor, whose camera sees
    /// the pattern directly (a half-space pad, no parallax at all), a press one cell from the border reads 4.71 N for 6
    /// N against 4.80 (host/estimator/tests/hard_cases.rs holds 4.80-7.20; 4.8005 with the option off, at c5114ae).
    /// Making that sensor a stack on its plate would not settle it: rendered so (this stack, seen through 3 mm of
    /// Plexiglass and the gel), the press reads 5.25 N on and 6.91 N off with the frame's walls 10 mm beyond the
    /// pattern, 9.14 and 9.51 N with them 3 mm beyond, and where the real pad is held is not known. On the validation
    /// sensor, which is such a stack: 2 N beside 6 N, 10 mm apart, about (-6, -7) and (-15, -6) mm read as one contact
    /// (2 of the 24 pairs of host/estimator/tests/inverse_shape.rs, none off). Three 8 N presses in a diagonal row read
    /// no contact with it on until 2fe17d7 (the contact test took the misfit, 0.094 mm against 0.048 off, for noise);
    /// since the test judges several compact loads at once, host/estimator/tests/many_contacts.rs passes either way.
    /// The quick set's edge direction reads 2.01 deg mean (1.71 off), its edges' floor 0.5 N (0.3 off; one edge of 0.3
    /// N is missed), its pushes' tangential force 0.146 N RMS (0.114) and torque 1.43 N mm (1.11). A 30 mm edge it
    /// listed as two to four contacts, depending on where it crossed the cell rows, is one contact since
    /// `join_long_groups` (host/estimator/tests/light_edges.rs, with the option off and on).
    pub normal_from_stack: bool,
    /// Each corner modelled as the fast tracker observes it, the midpoint of its two yellow squares' centres, rather
    /// than at the material corner (the response, the walls' images and the parallax alike). The squares fill 0.86
    /// of a pitch, so no junction marks the corner in the image: the tracker finds the squares, and a strain gradient
    /// moves their midpoint off the corner (host/bench/examples/localisation_budget.rs). One probe per square, at its
    /// centre: a model build takes about 2 s more. Off by default: the equivalent layer was fitted to the real pair
    /// as tracked, so it stands for the tracker's averaging already (with it, the quick validation set's localisation
    /// reads 0.73 mm and the force over the pad 0.41 N, against 0.34 and 0.25). It belongs with a model of the pad as
    /// built. Measured inverse only at d543c54 plus the option (`NUSENSE_VALIDATION_CONFIG`, docs/benchmarks), off ->
    /// on: with the validation pad's own stack and frame (`model = "layered"`, its three layers, `sliding_walls` 4 mm
    /// beyond the pattern) the quick set's localisation 0.263 -> 0.24 mm, force over the pad 0.38 -> 0.11 N, edge
    /// direction 1.9 / 3.4 -> 1.4 / 3.5 deg, and the full set reads 0.22 mm and 0.18 N with it, but its edge direction
    /// 2.4 / 11.1 deg (one missed), two contacts 15 of 16 and 20 mm edges as one contact 22 of 24. With the defaults'
    /// stack (`model = "layered"`, `shear_modulus_kpa = 11`) and the walls 4 mm beyond the pattern: quick 0.252 ->
    /// 0.24 mm and 0.30 -> 0.21 N, full 0.49 -> 0.30 mm and 0.51 -> 0.25 N (two contacts 15 -> 13 of 16, two round
    /// presses read as an edge in 2 of 16); 3 mm beyond, quick 0.288 -> 0.26 mm. Not yet sound where a load falls
    /// between cells: fed its own noise-free field of a 2.5 mm square press, stage 2 places it 0.16-1.06 mm off at
    /// 0.8-2.0 mm from a cell's centre with 10 um of noise assumed, up to 2.1 mm with 2 um (the corners' model holds
    /// 0.25 mm at 2 um in the same test, `the_layered_model_places_a_press_within_a_cell`), with phantom loads two
    /// cells apart. The midpoints carry no more than the 96 squares' centroids do (192 numbers for 330), and a motion
    /// of the squares that alternates row by row moves no midpoint (each pairs a square of one row with one of the
    /// next): with the option the cells' pressure response has a null direction (smallest singular value 1e-16,
    /// against 6e-5 without; the 97th 0.09 against 0.58), which stage 2, whose noise model takes the corners as
    /// independent, fills at low noise. Observing the squares themselves (`inverse.observe = "squares"`, or any
    /// number of probes per square with the diagnostic `InverseModel::observing_squares`) keeps their 192 numbers without the null direction, and with the pad's own
    /// stack and frame places the validation presses far better from the tracked squares than from the tracked
    /// corners (docs/benchmarks/validation-quick.md, "Where the localisation error comes from"); but 192 numbers
    /// for the cells' 576 tractions leave it unsound between cells too: fed its own noise-free field of a 2.5 mm
    /// square press (`model = "layered"`, `shear_modulus_kpa = 11`), stage 2 places it exactly at a cell's centre
    /// but 0.46, 1.93, 1.01 and 0.32 mm off at (0.8, 0), (1.6, 0), (0.8, -0.8) and (-1.2, 1.6) mm from it, among
    /// 15-17 regions, with 2 um of noise assumed (0.11-0.52 mm off among 1-4 regions with 10 um); observed as the
    /// mean of 3 x 3 points over each square, 0.25-0.34 mm off among 14-22 regions (0.12-0.35 mm, 2-5 regions).
    pub tracker_averaging: bool,
    /// The reference's tangential force (and torque about the normal, unless `torque_scale` is set) over the
    /// model's, after the modulus: the force vector's fx, fy and the torques are multiplied by it. One equivalent material cannot match a skin over
    /// soft gel in shear and in pressure at once: calibrated on normal presses alone, the equivalent layer reads the
    /// quick validation set's pushes 2.40 times too strong and its twists about as much (docs/benchmarks). It does not
    /// change where or whether a contact is found, nor its normal force. Default 1 (the model's own); `nusense
    /// calibrate` fits it from a force/torque log with pushes in it.
    pub tangential_force_scale: f64,
    /// The reference's torque about the normal over the model's, after the modulus; unset (the default), the
    /// torque takes `tangential_force_scale`. The model's twist and push need not be off by one factor: on the quick
    /// validation set the pushes' scale, 0.51, reads the twists 11 % low (they want 0.57; RMS 1.65 N mm, 1.41 with the
    /// 0.52 its calibration twists fit), though on the full set they want 0.51 and the calibration twists' 0.52 reads
    /// them no better (1.92 against 1.89 N mm): there the twists scatter about any one scale by 15 %.
    /// `nusense calibrate` fits it from a force/torque log with twists in it (a torque about the normal of at least 2
    /// N mm).
    pub torque_scale: Option<f64>,
    /// How far (mm) each contact's centre is moved along its own push, per unit of its push over its load (the
    /// model's (fx, fy) / fz, before `tangential_force_scale`). A pushed contact's pressure centre reads behind the
    /// push, in proportion to the push: on the validation sensor 0.76 mm at a fifth of the load and 1.34 mm at two
    /// fifths, where the model reads the push 2.2-2.4 times the truth's share; the equivalent layer explains part of
    /// the pad's shear response with pressure. It is the pad's and must be fitted on it, where the pushes' places are
    /// known: the validation bench fits it on its calibration pushes, `nusense calibrate` from a force/torque log
    /// that says where the probe touched. Default 0: centres as the pressure puts them. At most one
    /// cell pitch of shift is applied.
    pub push_centre_shift_mm: f64,
    /// What a push adds to each contact's normal force, read as pressure: its normal force fz is reduced by this
    /// times (fx^2 + fy^2) / fz (the model's force vector, fx, fy before `tangential_force_scale`), never below 0. The
    /// pressure that moves a pushed contact's centre behind the push (`push_centre_shift_mm`) also adds to its load,
    /// as the square of the push over the load: on the validation sensor 5, 10, 17 and 27 % of the load at pushes of
    /// 0.2 to 0.5 of it (`calibration::push_normal`). It is the pad's and must be fitted on pushes whose normal force
    /// is known: the validation bench fits it on its calibration pushes, `nusense calibrate` from a force/torque log
    /// with pushes in it. Default 0: the normal force as the pressure puts it.
    pub push_normal_share: f64,
}

impl Default for ElasticConfig {
    fn default() -> Self {
        Self {
            model: ElasticModel::BondedLayer,
            shear_modulus_kpa: EQUIVALENT_LAYER_KPA,
            poisson_ratio: 0.5,
            skin_mm: LAYERED_SKIN_MM,
            skin_modulus_ratio: SKIN_KPA / LAYERED_GEL_KPA,
            bond_mm: 0.0,
            bond_modulus_ratio: 10.0,
            cover_mm: 2.8,
            gel_mm: 2.2,
            bonded_border: false,
            sliding_walls: false,
            border_margin_mm: 3.0,
            gel_refractive_index: 1.41,
            normal_from_stack: false,
            tracker_averaging: false,
            tangential_force_scale: 1.0,
            torque_scale: None,
            push_centre_shift_mm: 0.0,
            push_normal_share: 0.0,
        }
    }
}

impl ElasticConfig {
    /// The factor on the model's torque about the normal: `torque_scale`, or `tangential_force_scale` where it is
    /// unset.
    pub fn torque_factor(&self) -> f64 {
        self.torque_scale.unwrap_or(self.tangential_force_scale)
    }

    /// The defaults' stack (`model = "layered"`, the gel at [`LAYERED_GEL_KPA`]) held in a frame whose sliding walls
    /// stand 4 mm beyond the pattern: the pad as built, as far as the defaults know it, with which
    /// `inverse.observe = "squares"` is measured (the frame's 4 mm is the validation pad's; the real pad's is not
    /// known).
    pub fn layered_in_a_frame() -> Self {
        Self {
            model: ElasticModel::Layered,
            shear_modulus_kpa: LAYERED_GEL_KPA,
            sliding_walls: true,
            border_margin_mm: 4.0,
            ..Self::default()
        }
    }
}

/// The skin's shear modulus, kPa: Sorta-Clear 18 (Shore 18A), E about 0.6 MPa on its data sheet, nearly
/// incompressible, G = E / 3.
const SKIN_KPA: f64 = 200.0;
/// The equivalent layer's shear modulus, kPa (the default `shear_modulus_kpa`, see [`ElasticConfig`]): the real pad
/// as one layer of gel with the pattern 2.8 mm deep.
pub const EQUIVALENT_LAYER_KPA: f64 = 48.0;
/// The gel's shear modulus for `model = "layered"`, kPa (see [`ElasticConfig`]): not on Techsil RTV27905's data
/// sheet (a very soft gel); with [`LAYERED_SKIN_MM`], the stack that the equivalent layer fitted to the real pair
/// stands for.
pub const LAYERED_GEL_KPA: f64 = 11.0;
/// The skin's thickness for `model = "layered"`, mm (see [`ElasticConfig`]; not published).
pub const LAYERED_SKIN_MM: f64 = 1.07;

/// The traction inverse and the contact test (see [`crate::inverse`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct InverseConfig {
    /// Displacement noise of one corner along one axis (1 sigma), mm: the regularisation's noise level. Set in the
    /// config (`nusense calibrate` does not measure it yet); the default is what the fast detector shows on the
    /// simulated real sensor at 640 x 480 (the lowest resolution the daemon captures by default).
    pub noise_mm: f64,
    /// Prior scale (1 sigma) of the force one traction cell carries, N. The regularisation rule is MAP under this
    /// prior: lambda = (noise_mm / traction_prior_n)^2. The default is the load of an 8 N press (the top of the
    /// paper's range) spread over a 5 mm radius, per cell.
    pub traction_prior_n: f64,
    /// The contact test never assumes less noise than this, mm: a guard for identical frames, which would otherwise
    /// have none. The test's noise is measured on each frame (the corners' scatter about the motion-only fit, see
    /// [`crate::inverse`]); the validation sensor's rest frames show 0.8-4 um with a still camera (2048x1536 to
    /// 640x480) and up to 11 um after it moved, well above this.
    pub noise_floor_mm: f64,
    /// Stage 2 of the inverse never assumes less noise than this many px of the frame (converted to mm by the pad
    /// map at the pad's centre), nor than `noise_floor_mm`, when it picks the loaded cells and lists contacts beside
    /// the strongest: lighting changes and JPEG blocks shift neighbouring corners together (a corner rests on the
    /// squares around it), a smooth error its residuals cannot see but the tractions can explain. The published
    /// detector's (`paper` mode's) contact test keeps this floor as well.
    pub noise_floor_px: f64,
    /// Probability that the contact test calls a rest frame a contact.
    pub false_alarm_probability: f64,
    /// A long contact's edge direction from the straight, uniform line load that best explains its displacements (on a
    /// grid of cells a quarter pitch wide, the motion free; see `InverseModel::edge_line`) instead of the second
    /// moments of its pressure map, which read a line with an error that depends on where it crosses between the
    /// corners. Off by default: it reads the direction through the model's far field, and so follows the model's error
    /// of the pad there. Measured inverse only, on c87f237's estimator (`NUSENSE_VALIDATION_CONFIG`, docs/benchmarks):
    /// the full validation set's 24 edges (a layered pad held in a frame, not the model's) 2.66 / 6.41 -> 1.72 / 3.28
    /// deg mean / worst, the quick set's 8 1.71 / 3.36 -> 1.58 / 3.34, 40 other edges of that sensor 1.92 / 7.80 ->
    /// 1.53 / 4.78 (tests/edge_line.rs), the unseen sensors' 38 2.26 / 10.1 -> 2.06 / 6.4 (worse on some: 320x240,
    /// 640x360, the camera 86 mm away); every other figure the same. But on the simulated real sensor, a half-space
    /// pad, the 8 N edges at 30 and 105 deg of tests/hard_cases.rs read 2.3 and 3.5 deg off where the moments read 0.04
    /// and 0.4 (that test asks 2). It costs a model build of 1.8 s instead of 0.55 s (the response of those cells;
    /// release, 1024x768) and 1.41 times the inverse's time on a frame with an edge (1.61 -> 2.26 ms CPU at 1024x768,
    /// `cargo bench -p nusense-estimator -- table`).
    pub edge_from_line: bool,
    /// What the model observes of the pattern: its interior corners (the default), or its yellow squares, each the
    /// mean motion over its cell (what a centroid measures; the fast tracker measures the squares, and its corners
    /// are their midpoints). See [`ObservedPoints`]. Measured on the validation sets (`NUSENSE_VALIDATION_CONFIG`, at
    /// the commit that made it, inverse only) with the defaults' stack held in a frame (`elastic.model = "layered"`,
    /// `shear_modulus_kpa = 11`, `sliding_walls`, `border_margin_mm = 4`), corners -> squares: localisation quick 0.25
    /// -> 0.24 mm, full 0.49 -> 0.23; force over the pad 0.30 -> 0.20 and 0.51 -> 0.22 N; edge direction mean / worst
    /// 1.8 / 3.6 -> 1.7 / 3.7 and 2.2 / 10.7 -> 1.8 / 5.5 deg; two contacts 6 / 6 and 15 / 16 both; detection floor
    /// 0.20 -> 0.30 N (quick; edges 0.30 -> 0.50) and 0.20 (full; edges 0.20 -> 0.30); the pushes' tangential force
    /// 0.11 -> 0.55 N RMS (quick) and 0.14 -> 0.30 (full) after its calibration, while stage 2 left part of a heavy
    /// push's shear on cells beside the pressure that no contact held (since 9f7d4f8 the contacts' force vectors hold
    /// it: the squares read the pushes 0.12 and 0.07 N RMS, their twists' torque 1.61 and 1.06 N mm against 2.89 and
    /// 1.21 before). A scratch test at b16e128 read the edge direction of 40 other edges of the validation sensor
    /// (tests/edge_line.rs's) 1.24 / 4.88 deg mean / worst against the default's 1.92 / 7.80, and of 22 edges of the
    /// simulated real sensor (a half-space) 0.52 / 1.40 against 0.73 / 2.15. With the default model (the equivalent
    /// layer, fitted to the real pair's corners as tracked) the squares read worse: quick 0.34 -> 0.48 mm. Time per
    /// frame on the real pair, against the default's: 0.93-1.19x (512x384 to 2048x1536), the same model observing the
    /// corners 2.6-4.2x (`cargo bench -p nusense-estimator -- table`). Not the default: the frame's 4 mm is the
    /// validation pad's, and the simulated real sensor's pad is a half-space.
    pub observe: ObservedPoints,
}

/// The points of the pattern whose displacements the inverse's model observes (`inverse.observe`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ObservedPoints {
    /// The 165 interior corners, each at its nominal position (or, with `elastic.tracker_averaging`, at its two
    /// squares' centres).
    #[default]
    Corners,
    /// The 96 yellow squares, each as the mean motion of 3 x 3 points over its cell. `inverse.noise_mm` is then a
    /// square's noise (a corner's is the mean of two squares': the default's noise is a corner's).
    Squares,
}

impl Default for InverseConfig {
    fn default() -> Self {
        Self {
            noise_mm: 0.01,
            traction_prior_n: 1.0,
            noise_floor_mm: 0.0002,
            noise_floor_px: 0.08,
            false_alarm_probability: 1e-6,
            edge_from_line: false,
            observe: ObservedPoints::Corners,
        }
    }
}

/// When the pad moves against the camera and stays there without a contact, a new rest frame is taken.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RetareConfig {
    /// Motion that counts: the largest displacement the fitted camera motion gives a corner, mm.
    pub motion_mm: f64,
    /// Consecutive frames without contact and with that motion before the re-tare.
    pub frames: u32,
}

impl Default for RetareConfig {
    fn default() -> Self {
        Self {
            motion_mm: 0.1,
            frames: 30,
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SensorConfig {
    /// The lens, for frames of `camera.width x camera.height`; other frame sizes scale it.
    pub camera: FisheyeIntrinsics,
    pub pad: PadGeometry,
    pub roi: Roi,
    pub thresholds: Thresholds,
    pub calibration: ForceCalibration,
    pub surface: SurfaceConfig,
    pub paper: PaperParams,
    pub elastic: ElasticConfig,
    pub inverse: InverseConfig,
    pub retare: RetareConfig,
    /// The raw px -> pad mm map fitted on this sensor's rest frame by `nusense calibrate`; without it, each rest
    /// frame fits its own.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pad_map: Option<crate::pad_map::StoredPadMap>,
}

impl Default for SensorConfig {
    fn default() -> Self {
        Self {
            camera: FisheyeIntrinsics::paper(2048, 1536),
            pad: PadGeometry::default(),
            roi: Roi::default(),
            thresholds: Thresholds::default(),
            calibration: ForceCalibration::default(),
            surface: SurfaceConfig::default(),
            paper: PaperParams::default(),
            elastic: ElasticConfig::default(),
            inverse: InverseConfig::default(),
            retare: RetareConfig::default(),
            pad_map: None,
        }
    }
}

fn invalid(key: &'static str, value: impl std::fmt::Display, allowed: &'static str) -> ConfigError {
    ConfigError::Invalid {
        path: None,
        key,
        value: value.to_string(),
        allowed,
    }
}

fn finite_positive(key: &'static str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(invalid(key, v, "must be a finite number > 0"))
    }
}

fn finite(key: &'static str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(invalid(key, v, "must be a finite number"))
    }
}

fn fraction(key: &'static str, v: f64) -> Result<(), ConfigError> {
    in_range(key, v, 0.0..=1.0, "must be between 0 and 1")
}

/// `v` within `range` (a NaN never is); `allowed` says so in the error.
fn in_range(
    key: &'static str,
    v: f64,
    range: std::ops::RangeInclusive<f64>,
    allowed: &'static str,
) -> Result<(), ConfigError> {
    if range.contains(&v) {
        Ok(())
    } else {
        Err(invalid(key, v, allowed))
    }
}

impl SensorConfig {
    pub fn from_toml_str(text: &str) -> Result<Self, ConfigError> {
        let config: Self = toml::from_str(text).map_err(|e| ConfigError::Parse {
            path: None,
            message: e.to_string(),
        })?;
        config.validate()?;
        Ok(config)
    }

    pub fn load(path: impl AsRef<Path>) -> Result<Self, ConfigError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
            path: path.to_owned(),
            source,
        })?;
        Self::from_toml_str(&text).map_err(|e| e.with_path(path))
    }

    pub fn to_toml_string(&self) -> String {
        // Serialising plain structs of numbers cannot fail; keep the fallback explicit rather than panic.
        toml::to_string_pretty(self).unwrap_or_else(|e| format!("# cannot serialise config: {e}\n"))
    }

    /// Checks every value against what the estimator can use; the error names the key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.validate_frame()?;
        self.validate_gamma()?;
        self.validate_paper()?;
        self.validate_elastic()?;
        self.validate_inverse()?;
        if let Some(map) = &self.pad_map {
            map.validate()
                .map_err(|reason| invalid("pad_map", reason, "a map written by `nusense calibrate`"))?;
        }
        Ok(())
    }

    /// The camera, the pad's grid and the ROI.
    fn validate_frame(&self) -> Result<(), ConfigError> {
        let cam = &self.camera;
        if cam.width < 16 || cam.height < 16 {
            return Err(invalid(
                "camera.width",
                format!("{} x {}", cam.width, cam.height),
                "frame sides >= 16 px",
            ));
        }
        finite_positive("camera.fx", cam.fx)?;
        finite_positive("camera.fy", cam.fy)?;
        finite("camera.cx", cam.cx)?;
        finite("camera.cy", cam.cy)?;
        if cam.distortion.iter().any(|k| !k.is_finite()) {
            return Err(invalid(
                "camera.distortion",
                format!("{:?}", cam.distortion),
                "four finite numbers",
            ));
        }
        nusense_geometry::FisheyeCamera::new(*cam)
            .map_err(|e| invalid("camera.distortion", format!("{:?}", cam.distortion), leak_reason(e)))?;
        let pad = &self.pad;
        if pad.rows < 3 || pad.cols < 3 {
            return Err(invalid(
                "pad.rows",
                format!("{} x {}", pad.rows, pad.cols),
                "at least 3 x 3 cells",
            ));
        }
        finite_positive("pad.width_mm", pad.width_mm)?;
        finite_positive("pad.height_mm", pad.height_mm)?;
        if self.roi.width == 0 || self.roi.height == 0 {
            return Err(invalid(
                "roi.width",
                format!("{} x {}", self.roi.width, self.roi.height),
                "a non-empty ROI",
            ));
        }
        if self.roi.x.saturating_add(self.roi.width) > cam.width
            || self.roi.y.saturating_add(self.roi.height) > cam.height
        {
            return Err(invalid(
                "roi.x",
                format!("{:?}", self.roi),
                "the ROI must lie inside the camera.width x camera.height frame",
            ));
        }
        Ok(())
    }

    /// What the gamma modes read: the shear thresholds, the paper's force line and the B-spline surface.
    fn validate_gamma(&self) -> Result<(), ConfigError> {
        let t = &self.thresholds;
        finite_positive("thresholds.contact_shear_mm", t.contact_shear_mm)?;
        finite_positive("thresholds.max_displacement_cells", t.max_displacement_cells)?;
        fraction("thresholds.recovery_lost_fraction", t.recovery_lost_fraction)?;
        fraction("thresholds.edge_sample_fraction", t.edge_sample_fraction)?;
        fraction("thresholds.edge_min_confidence", t.edge_min_confidence)?;
        finite("calibration.a", self.calibration.a)?;
        finite("calibration.b", self.calibration.b)?;
        finite_positive("calibration.alpha", self.calibration.alpha)?;
        let s = &self.surface;
        let (net_rows, net_cols) = (usize::from(self.pad.corner_rows()), usize::from(self.pad.corner_cols()));
        if s.degree_u < 1 || s.degree_u >= net_rows {
            return Err(invalid(
                "surface.degree_u",
                s.degree_u,
                "1 ..= corner rows - 1 (10 on the real pad)",
            ));
        }
        if s.degree_v < 1 || s.degree_v >= net_cols {
            return Err(invalid(
                "surface.degree_v",
                s.degree_v,
                "1 ..= corner columns - 1 (14 on the real pad)",
            ));
        }
        in_range("surface.uv_step", s.uv_step, 0.001..=1.0, "0.001 ..= 1")
    }

    /// The published method's image filters and quadrilateral search.
    fn validate_paper(&self) -> Result<(), ConfigError> {
        let p = &self.paper;
        if p.bilateral_diameter == 0 {
            return Err(invalid("paper.bilateral_diameter", p.bilateral_diameter, "> 0"));
        }
        finite_positive("paper.bilateral_sigma_color", p.bilateral_sigma_color)?;
        finite_positive("paper.bilateral_sigma_space", p.bilateral_sigma_space)?;
        finite("paper.sobel_weight_x", p.sobel_weight_x)?;
        finite("paper.sobel_weight_y", p.sobel_weight_y)?;
        finite("paper.binary_threshold", p.binary_threshold)?;
        fraction("paper.polygon_epsilon_fraction", p.polygon_epsilon_fraction)?;
        finite_positive("paper.quad_min_area_px2", p.quad_min_area_px2)?;
        if !(p.quad_max_area_px2.is_finite() && p.quad_max_area_px2 > p.quad_min_area_px2) {
            return Err(invalid(
                "paper.quad_max_area_px2",
                p.quad_max_area_px2,
                "finite and > paper.quad_min_area_px2",
            ));
        }
        fraction("paper.quad_min_solidity", p.quad_min_solidity)?;
        finite_positive("paper.pair_distance_px", p.pair_distance_px)
    }

    /// The pad's elastic model and the force calibration the inverse applies to it.
    fn validate_elastic(&self) -> Result<(), ConfigError> {
        let e = &self.elastic;
        finite_positive("elastic.shear_modulus_kpa", e.shear_modulus_kpa)?;
        in_range("elastic.poisson_ratio", e.poisson_ratio, 0.0..=0.5, "between 0 and 0.5")?;
        in_range("elastic.cover_mm", e.cover_mm, 0.1..=20.0, "0.1 ..= 20 mm")?;
        in_range("elastic.gel_mm", e.gel_mm, 0.1..=50.0, "0.1 ..= 50 mm")?;
        in_range("elastic.skin_mm", e.skin_mm, 0.05..=20.0, "0.05 ..= 20 mm")?;
        in_range(
            "elastic.skin_modulus_ratio",
            e.skin_modulus_ratio,
            0.01..=1000.0,
            "0.01 ..= 1000 (the skin's shear modulus over the gel's)",
        )?;
        in_range("elastic.bond_mm", e.bond_mm, 0.0..=20.0, "0 (no bond layer) ..= 20 mm")?;
        in_range(
            "elastic.bond_modulus_ratio",
            e.bond_modulus_ratio,
            0.01..=1000.0,
            "0.01 ..= 1000 (the bond layer's shear modulus over the gel's)",
        )?;
        in_range(
            "elastic.border_margin_mm",
            e.border_margin_mm,
            0.0..=50.0,
            "0 ..= 50 mm",
        )?;
        if e.gel_refractive_index != 0.0 {
            in_range(
                "elastic.gel_refractive_index",
                e.gel_refractive_index,
                1.0..=3.0,
                "0 (no parallax) or 1 ..= 3",
            )?;
        }
        in_range(
            "elastic.tangential_force_scale",
            e.tangential_force_scale,
            0.01..=100.0,
            "0.01 ..= 100 (the reference's tangential force over the model's)",
        )?;
        if let Some(scale) = e.torque_scale {
            in_range(
                "elastic.torque_scale",
                scale,
                0.01..=100.0,
                "0.01 ..= 100 (the reference's torque over the model's), or unset",
            )?;
        }
        in_range(
            "elastic.push_centre_shift_mm",
            e.push_centre_shift_mm,
            -10.0..=10.0,
            "-10 ..= 10 (mm along the push per unit of push over load)",
        )?;
        in_range(
            "elastic.push_normal_share",
            e.push_normal_share,
            -1.0..=1.0,
            "-1 ..= 1 (the normal force read too much per unit of push squared over load)",
        )
    }

    /// The inverse's noise, prior and contact test, and the re-tare.
    fn validate_inverse(&self) -> Result<(), ConfigError> {
        let i = &self.inverse;
        finite_positive("inverse.noise_mm", i.noise_mm)?;
        finite_positive("inverse.traction_prior_n", i.traction_prior_n)?;
        finite_positive("inverse.noise_floor_mm", i.noise_floor_mm)?;
        finite_positive("inverse.noise_floor_px", i.noise_floor_px)?;
        if !(i.false_alarm_probability > 0.0 && i.false_alarm_probability < 0.5) {
            return Err(invalid(
                "inverse.false_alarm_probability",
                i.false_alarm_probability,
                "strictly between 0 and 0.5",
            ));
        }
        finite_positive("retare.motion_mm", self.retare.motion_mm)?;
        if self.retare.frames == 0 {
            return Err(invalid("retare.frames", 0, ">= 1"));
        }
        Ok(())
    }
}

fn leak_reason(e: nusense_geometry::CameraError) -> &'static str {
    match e {
        nusense_geometry::CameraError::NonMonotonicDistortion(_) => {
            "coefficients that keep theta_d increasing over the frame (the lens must not fold the image)"
        }
        _ => "a usable fisheye model",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_file_is_the_real_sensor() {
        assert_eq!(SensorConfig::from_toml_str("").unwrap(), SensorConfig::default());
    }

    /// Configs written before the layered model load as they did (the equivalent layer), and a layered one names its
    /// stack; a bad layer value is a typed error naming its key.
    #[test]
    fn the_elastic_stack_loads_and_checks_its_values() {
        let old = "[elastic]\nmodel = \"bonded_layer\"\nshear_modulus_kpa = 48.0\ncover_mm = 2.8\ngel_mm = 2.2\n";
        assert_eq!(SensorConfig::from_toml_str(old).unwrap(), SensorConfig::default());
        let layered = "[elastic]\nmodel = \"layered\"\nshear_modulus_kpa = 11.0\nskin_mm = 0.8\nskin_modulus_ratio = 18.0\nbond_mm = 0.5\n";
        let config = SensorConfig::from_toml_str(layered).unwrap();
        assert_eq!(config.elastic.model, ElasticModel::Layered);
        assert_eq!((config.elastic.skin_mm, config.elastic.bond_mm), (0.8, 0.5));
        for (key, text) in [
            ("elastic.skin_mm", "[elastic]\nskin_mm = 0.0\n"),
            ("elastic.skin_modulus_ratio", "[elastic]\nskin_modulus_ratio = -2.0\n"),
            ("elastic.bond_mm", "[elastic]\nbond_mm = -0.5\n"),
            ("elastic.bond_modulus_ratio", "[elastic]\nbond_modulus_ratio = inf\n"),
            (
                "elastic.tangential_force_scale",
                "[elastic]\ntangential_force_scale = 0.0\n",
            ),
            (
                "elastic.tangential_force_scale",
                "[elastic]\ntangential_force_scale = nan\n",
            ),
            ("elastic.torque_scale", "[elastic]\ntorque_scale = 0.0\n"),
            ("elastic.torque_scale", "[elastic]\ntorque_scale = -0.5\n"),
            (
                "elastic.push_centre_shift_mm",
                "[elastic]\npush_centre_shift_mm = 12.0\n",
            ),
            ("elastic.push_normal_share", "[elastic]\npush_normal_share = 1.5\n"),
        ] {
            assert_eq!(
                SensorConfig::from_toml_str(text).unwrap_err().key(),
                Some(key),
                "{text}"
            );
        }
        assert!(matches!(
            SensorConfig::from_toml_str("[elastic]\nskin_thickness_mm = 1.0\n"),
            Err(ConfigError::Parse { .. })
        ));
    }

    /// Every checked value, set wrong (out of range, or NaN where a range is checked), is refused by the error naming
    /// its key, and the default config passes.
    #[test]
    fn every_checked_value_names_its_key_when_wrong() {
        type Spoil = fn(&mut SensorConfig);
        let cases: [(&str, Spoil); 34] = [
            ("camera.width", |c| c.camera.width = 8),
            ("camera.fx", |c| c.camera.fx = 0.0),
            ("camera.cy", |c| c.camera.cy = f64::NAN),
            ("camera.distortion", |c| c.camera.distortion[2] = f64::INFINITY),
            ("pad.rows", |c| c.pad.cols = 2),
            ("pad.height_mm", |c| c.pad.height_mm = -40.0),
            ("roi.width", |c| c.roi.height = 0),
            ("roi.x", |c| c.roi.x = c.camera.width),
            ("thresholds.contact_shear_mm", |c| c.thresholds.contact_shear_mm = 0.0),
            ("thresholds.edge_min_confidence", |c| {
                c.thresholds.edge_min_confidence = 1.5
            }),
            ("calibration.b", |c| c.calibration.b = f64::NAN),
            ("calibration.alpha", |c| c.calibration.alpha = 0.0),
            ("surface.degree_u", |c| c.surface.degree_u = 0),
            ("surface.degree_v", |c| c.surface.degree_v = 15),
            ("surface.uv_step", |c| c.surface.uv_step = f64::NAN),
            ("paper.bilateral_diameter", |c| c.paper.bilateral_diameter = 0),
            ("paper.binary_threshold", |c| c.paper.binary_threshold = f64::INFINITY),
            ("paper.quad_max_area_px2", |c| {
                c.paper.quad_max_area_px2 = c.paper.quad_min_area_px2
            }),
            ("paper.pair_distance_px", |c| c.paper.pair_distance_px = -1.0),
            ("elastic.shear_modulus_kpa", |c| c.elastic.shear_modulus_kpa = 0.0),
            ("elastic.poisson_ratio", |c| c.elastic.poisson_ratio = 0.6),
            ("elastic.poisson_ratio", |c| c.elastic.poisson_ratio = f64::NAN),
            ("elastic.cover_mm", |c| c.elastic.cover_mm = 25.0),
            ("elastic.gel_mm", |c| c.elastic.gel_mm = 0.0),
            ("elastic.border_margin_mm", |c| c.elastic.border_margin_mm = -1.0),
            ("elastic.gel_refractive_index", |c| c.elastic.gel_refractive_index = 0.5),
            ("elastic.gel_refractive_index", |c| {
                c.elastic.gel_refractive_index = f64::NAN
            }),
            ("inverse.noise_mm", |c| c.inverse.noise_mm = 0.0),
            ("inverse.noise_floor_px", |c| c.inverse.noise_floor_px = f64::INFINITY),
            ("inverse.false_alarm_probability", |c| {
                c.inverse.false_alarm_probability = 0.5
            }),
            ("inverse.false_alarm_probability", |c| {
                c.inverse.false_alarm_probability = f64::NAN
            }),
            ("retare.motion_mm", |c| c.retare.motion_mm = -1.0),
            ("retare.frames", |c| c.retare.frames = 0),
            ("elastic.push_centre_shift_mm", |c| {
                c.elastic.push_centre_shift_mm = f64::NAN
            }),
        ];
        assert_eq!(SensorConfig::default().validate().map_err(|e| e.to_string()), Ok(()));
        for (key, spoil) in cases {
            let mut config = SensorConfig::default();
            spoil(&mut config);
            assert_eq!(config.validate().unwrap_err().key(), Some(key));
        }
        let mut no_parallax = SensorConfig::default();
        no_parallax.elastic.gel_refractive_index = 0.0;
        assert!(no_parallax.validate().is_ok());
    }

    #[test]
    fn round_trips_through_toml() {
        let mut config = SensorConfig::default();
        config.calibration.a = 2.5;
        config.surface.degree_u = 3;
        let text = config.to_toml_string();
        assert_eq!(SensorConfig::from_toml_str(&text).unwrap(), config);
    }
}
