//! How the pad deforms: the in-plane displacement of the pattern layer per unit force on the pad's surface.
//!
//! Three models, chosen in the sensor config (`[elastic]`):
//!
//! - **Bonded layer** (the default): one isotropic elastic layer of thickness h = `cover_mm + gel_mm`, loaded on its
//!   top surface, bonded to a rigid base at its bottom, observed at depth d = `cover_mm` (the pattern layer, under
//!   the skin's equivalent thickness of gel). Its normal displacement, which the camera sees as parallax, is not the
//!   pad's (it is fitted in-plane): with `elastic.normal_from_stack` the parallax takes it from the stack as built
//!   instead ([`normal_stack`]).
//! - **Layered**: the stack as built, a stiff skin with the pattern at its bottom over soft gel (and optionally a
//!   bond layer), bonded to the rigid plate; see [`stack_spectra`].
//!
//! Both are solved per wave number k in the Fourier domain: the response to a surface traction splits into a
//! transverse part and a coupled longitudinal/normal part, each layer's field written in a basis of exponentials
//! that decay from its top and from its bottom (well conditioned for every k h), the layers joined by continuity of
//! displacement and traction. Real space needs Hankel transforms, and those converge slowly for the half-space part
//! of the response (its 1 / r far field), so the half-space of the top layer's material at the pattern's depth is
//! taken in closed form (Boussinesq and Cerruti, below) and only what the layers below and the rigid base change is
//! integrated numerically once and tabulated in r. (For one layer that difference decays like exp(-k (2h - d)); with
//! the pattern on an interface, like exp(-k d).)
//! - **Half-space**: Boussinesq (normal force) and Cerruti (tangential force) at the pattern's depth (Johnson,
//!   Contact Mechanics, section 3.2); the fallback when the layer's thickness is not known.
//!
//! A point force f = (fx, fy, fz) at the origin (z pressing into the pad) moves the pattern at in-plane offset r by
//! u = (a(r) I + b(r) r̂ r̂ᵀ) (fx, fy) + c(r) r̂ fz: three radial functions describe each model completely.
//! [`PadResponse`] builds the matrix of cell tractions to pattern displacements used by the inverse, including the
//! pad bonded at its border.

use nalgebra::{DMatrix, DVector};
use nusense_geometry::Point2;
use thiserror::Error;

use crate::config::{ElasticConfig, ElasticModel, EQUIVALENT_LAYER_KPA, LAYERED_GEL_KPA};

#[derive(Debug, Error, Clone, PartialEq)]
pub enum ElasticError {
    #[error("the elastic model cannot be built: {0}")]
    Degenerate(&'static str),
}

/// Largest in-plane distance the tabulated layer correction covers (the pad's diagonal with its rim is about
/// 73 mm); beyond it the layer's response has decayed by many orders of magnitude and is taken as zero.
const TABLE_REACH_MM: f64 = 90.0;
/// Radial step of the tabulated correction; it varies on the scale of the layer's thickness (mm), so a tenth of a
/// millimetre with cubic interpolation is exact to well below the noise.
const TABLE_STEP_MM: f64 = 0.1;
/// The correction's spectrum decays like exp(-k (2h - d)); stop where it is below exp(-30) of its start.
const SPECTRUM_DECAY: f64 = 30.0;
/// Quadrature points per oscillation of the Bessel functions at the largest radius.
const POINTS_PER_PERIOD: f64 = 24.0;

/// The radial functions a, b, c (mm per N) at one distance.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Radial {
    pub a: f64,
    pub b: f64,
    pub c: f64,
}

impl std::ops::Add for Radial {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        Self {
            a: self.a + o.a,
            b: self.b + o.b,
            c: self.c + o.c,
        }
    }
}

/// The response of the pattern to a point force on the surface.
#[derive(Clone, Debug)]
pub struct PointKernel {
    shear_modulus_n_per_mm2: f64,
    poisson_ratio: f64,
    depth_mm: f64,
    /// Bonded layer minus half-space, tabulated every `TABLE_STEP_MM` from 0 (layer model only).
    correction: Option<Vec<Radial>>,
    /// The same for the pattern's normal displacement ([`Vertical`]).
    vertical_correction: Option<Vec<Vertical>>,
}

/// The pattern's displacement along the normal (positive into the pad, towards the plate and the camera) at
/// in-plane distance r from a point force: w = z(r) fz + t(r) r̂ · (fx, fy), mm per N.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Vertical {
    pub z: f64,
    pub t: f64,
}

impl PointKernel {
    pub fn new(config: &ElasticConfig) -> Result<Self, ElasticError> {
        let layers = stack_layers(config);
        let nu = config.poisson_ratio;
        let depth = match config.model {
            ElasticModel::Layered => config.skin_mm,
            _ => config.cover_mm,
        };
        // The near field is the half-space of the top layer (the one the pattern lies under).
        let mu = layers
            .first()
            .map_or(config.shear_modulus_kpa * 1e-3, |layer| layer.shear_modulus);
        if !(mu > 0.0 && (0.0..=0.5).contains(&nu) && depth > 0.0) {
            return Err(ElasticError::Degenerate(
                "needs a positive modulus and depth and 0 <= nu <= 0.5",
            ));
        }
        if layers
            .iter()
            .any(|layer| !(layer.thickness_mm > 0.0 && layer.shear_modulus > 0.0 && layer.shear_modulus.is_finite()))
        {
            return Err(ElasticError::Degenerate(
                "every layer needs a positive thickness and modulus (a bonded layer needs gel below the pattern)",
            ));
        }
        let (correction, vertical_correction) = if layers.is_empty() {
            (None, None)
        } else {
            let (radial, vertical) = tabulate_stack_correction(&layers, depth);
            (Some(radial), Some(vertical))
        };
        Ok(Self {
            shear_modulus_n_per_mm2: mu,
            poisson_ratio: nu,
            depth_mm: depth,
            correction,
            vertical_correction,
        })
    }

    /// The normal displacement's radial functions at in-plane distance `r` (mm).
    pub fn vertical_radial(&self, r: f64) -> Vertical {
        let half = half_space_vertical(self.shear_modulus_n_per_mm2, self.poisson_ratio, self.depth_mm, r);
        match &self.vertical_correction {
            None => half,
            // Beyond the table the layer's response has decayed: the correction cancels the half-space.
            Some(table) => {
                catmull_rom(table, r / TABLE_STEP_MM).map_or_else(Vertical::default, |correction| Vertical {
                    z: half.z + correction.z,
                    t: half.t + correction.t,
                })
            }
        }
    }

    /// Normal displacement (mm, into the pad) per N of (fx, fy, fz) at `offset` (mm) from the force.
    pub fn vertical(&self, offset: Point2) -> [f64; 3] {
        let r = offset[0].hypot(offset[1]);
        let Vertical { z, t } = self.vertical_radial(r);
        if r > 1e-12 {
            [t * offset[0] / r, t * offset[1] / r, z]
        } else {
            [0.0, 0.0, z]
        }
    }

    /// a, b, c at in-plane distance `r` (mm).
    pub fn radial(&self, r: f64) -> Radial {
        let half = half_space_radial(self.shear_modulus_n_per_mm2, self.poisson_ratio, self.depth_mm, r);
        match &self.correction {
            None => half,
            // Beyond the table the layer's response has decayed: the correction cancels the half-space.
            Some(table) => {
                catmull_rom(table, r / TABLE_STEP_MM).map_or_else(Radial::default, |correction| half + correction)
            }
        }
    }

    /// In-plane displacement (mm) per N of (fx, fy, fz) at `offset` (mm) from the force: rows x and y.
    pub fn response(&self, offset: Point2) -> [[f64; 3]; 2] {
        let r = offset[0].hypot(offset[1]);
        let Radial { a, b, c } = self.radial(r);
        let (ux, uy) = if r > 1e-12 {
            (offset[0] / r, offset[1] / r)
        } else {
            (0.0, 0.0)
        };
        [
            [a + b * ux * ux, b * ux * uy, c * ux],
            [b * ux * uy, a + b * uy * uy, c * uy],
        ]
    }
}

/// Boussinesq and Cerruti at depth z below the surface (Johnson eqs. 3.22, 3.24), as a, b, c.
pub fn half_space_radial(mu: f64, nu: f64, z: f64, r: f64) -> Radial {
    let k = 1.0 / (4.0 * std::f64::consts::PI * mu);
    let compressibility = 1.0 - 2.0 * nu;
    let rho = r.hypot(z);
    let rho3 = rho * rho * rho;
    let rz = rho + z;
    Radial {
        a: k * (1.0 / rho + compressibility / rz),
        b: k * r * r * (1.0 / rho3 - compressibility / (rho * rz * rz)),
        c: k * r * (z / rho3 - compressibility / (rho * rz)),
    }
}

/// Boussinesq's and Cerruti's normal displacement at depth z (Johnson eqs. 3.22, 3.86), as [`Vertical`].
pub fn half_space_vertical(mu: f64, nu: f64, z: f64, r: f64) -> Vertical {
    let k = 1.0 / (4.0 * std::f64::consts::PI * mu);
    let rho = r.hypot(z);
    let rho3 = rho * rho * rho;
    Vertical {
        z: k * (2.0 * (1.0 - nu) / rho + z * z / rho3),
        t: k * (r * z / rho3 + (1.0 - 2.0 * nu) * r / (rho * (rho + z))),
    }
}

/// The normal displacement's spectra at depth `d` for unit shear modulus: [from longitudinal traction, from normal
/// pressure], of the half-space (the family decaying from the surface, as in [`half_space_spectra`]).
pub fn half_space_vertical_spectra(k: f64, nu: f64, d: f64) -> [f64; 2] {
    let e = (-k * d).exp();
    [
        (0.5 * (1.0 - 2.0 * nu) + 0.5 * k * d) * e,
        ((1.0 - nu) + 0.5 * k * d) * e,
    ]
}

/// The same for the bonded layer (thickness `h`), from the solution of [`layer_spectra`]'s system. Test only: the
/// closed form [`stack_spectra`] is held to.
#[cfg(test)]
pub fn layer_vertical_spectra(k: f64, nu: f64, d: f64, h: f64) -> [f64; 2] {
    let kappa = 3.0 - 4.0 * nu;
    let matrix = layer_matrix(k, nu, h);
    let w_at_d = |x: [f64; 4]| {
        let (s, kd) = (h - d, k * d);
        (-x[0] - kappa * x[1] - x[1] * kd) * (-kd).exp() + (x[2] + kappa * x[3] + x[3] * k * s) * (-k * s).exp()
    };
    [
        crate::linalg::solve_small(matrix, [1.0, 0.0, 0.0, 0.0]).map_or(f64::NAN, w_at_d),
        crate::linalg::solve_small(matrix, [0.0, 1.0, 0.0, 0.0]).map_or(f64::NAN, w_at_d),
    ]
}

/// k times the transfer functions (longitudinal from longitudinal traction, longitudinal from normal pressure,
/// transverse from transverse traction) at depth `d`, for unit shear modulus.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spectra {
    pub ll: f64,
    pub ln: f64,
    pub tt: f64,
}

/// The half-space's spectra: the top boundary conditions on the family decaying from the surface,
/// U = (a + b k z) e^(-kz), W = (-a - kappa b - b k z) e^(-kz), solved by hand.
pub fn half_space_spectra(k: f64, nu: f64, d: f64) -> Spectra {
    let e = (-k * d).exp();
    Spectra {
        ll: ((1.0 - nu) - 0.5 * k * d) * e,
        ln: (0.5 * (1.0 - 2.0 * nu) - 0.5 * k * d) * e,
        tt: e,
    }
}

/// The bonded layer's spectra (thickness `h`, observed at depth `d`): top loaded, bottom clamped. Test only: the
/// closed form [`stack_spectra`] is held to.
#[cfg(test)]
pub fn layer_spectra(k: f64, nu: f64, d: f64, h: f64) -> Spectra {
    let kh = k * h;
    let matrix = layer_matrix(k, nu, h);
    let u_at_d = |x: [f64; 4]| {
        let (s, kd) = (h - d, k * d);
        (x[0] + x[1] * kd) * (-kd).exp() + (x[2] + x[3] * k * s) * (-k * s).exp()
    };
    let ll = crate::linalg::solve_small(matrix, [1.0, 0.0, 0.0, 0.0]).map_or(f64::NAN, u_at_d);
    let ln = crate::linalg::solve_small(matrix, [0.0, 1.0, 0.0, 0.0]).map_or(f64::NAN, u_at_d);
    // Transverse: u = sinh(k(h - z)) / (k cosh(kh)) per unit traction, written with decaying exponentials.
    let tt = ((-k * d).exp() - (-k * (2.0 * h - d)).exp()) / (1.0 + (-2.0 * kh).exp());
    Spectra { ll, ln, tt }
}

/// The bonded layer's boundary conditions. Unknowns (a, b) of the family decaying from the top,
/// U = (a + b k z) e^(-kz), W = (-a - kappa b - b k z) e^(-kz), and (a2, b2) of the family decaying from the bottom,
/// U2 = (a2 + b2 k s) e^(-ks), W2 = (a2 + kappa b2 + b2 k s) e^(-ks) with s = h - z, all multiplied by k.
/// Rows: shear traction and normal traction at the top, U and W at the bottom.
#[cfg(test)]
fn layer_matrix(k: f64, nu: f64, h: f64) -> [[f64; 4]; 4] {
    let kappa = 3.0 - 4.0 * nu;
    let e = (-k * h).exp();
    let kh = k * h;
    [
        [2.0, kappa - 1.0, -2.0 * e, -(kappa - 1.0 + 2.0 * kh) * e],
        [-2.0, -4.0 * (1.0 - nu), -2.0 * e, -(4.0 * (1.0 - nu) + 2.0 * kh) * e],
        [e, kh * e, 1.0, 0.0],
        [-e, (-kappa - kh) * e, 1.0, kappa],
    ]
}

/// Hankel transforms of k T(k) to a, b, c:
/// a = 1/(4 pi) ∫ [kT_ll (J0 + J2) + kT_tt (J0 - J2)] dk, b = 1/(2 pi) ∫ (kT_tt - kT_ll) J2 dk,
/// c = -1/(2 pi) ∫ kT_ln J1 dk (Simpson's rule on `spectra` sampled every `dk` from k = 0). Test only: the plain
/// transform the tables' accumulation (with its asymptotic Bessel functions) is held to.
#[cfg(test)]
pub fn hankel(spectra: &[Spectra], dk: f64, r: f64) -> Radial {
    let n = spectra.len();
    let (mut a, mut b, mut c) = (0.0, 0.0, 0.0);
    for (i, s) in spectra.iter().enumerate() {
        let weight = simpson_weight(i, n);
        let x = i as f64 * dk * r;
        let (j0, j1) = (libm::j0(x), libm::j1(x));
        // J2 by the recurrence, with the series where 2 J1 / x - J0 cancels.
        let j2 = if x < 1e-3 { x * x / 8.0 } else { 2.0 * j1 / x - j0 };
        a += weight * (s.ll * (j0 + j2) + s.tt * (j0 - j2));
        b += weight * (s.tt - s.ll) * j2;
        c += weight * s.ln * j1;
    }
    let h = dk / 3.0;
    let tau = std::f64::consts::TAU;
    Radial {
        a: a * h / (2.0 * tau),
        b: b * h / tau,
        c: -c * h / tau,
    }
}

/// Simpson's weight of sample `i` of `n` (n odd): 1 at the ends, then 4 and 2 by turns.
fn simpson_weight(i: usize, n: usize) -> f64 {
    if i == 0 || i == n - 1 {
        1.0
    } else if i % 2 == 1 {
        4.0
    } else {
        2.0
    }
}

/// Samples `f` every `dk` over [0, k_max] with an odd number of points (Simpson).
pub fn sample_spectra<T>(k_max: f64, dk: f64, f: impl Fn(f64) -> T) -> Vec<T> {
    let mut n = (k_max / dk).ceil() as usize + 1;
    if n.is_multiple_of(2) {
        n += 1;
    }
    (0..n).map(|i| f(i as f64 * dk)).collect()
}

/// Where the stack's response stops differing from the half-space's at depth `d` below its top (mm): the
/// difference decays like exp(-k L) with L the distance down to the first interface (or the plate) below the pattern
/// and back up to it, or the pattern's depth itself if an interface lies above it (its transmitted field differs from
/// the half-space's at every k).
fn correction_decay_length(layers: &[Layer], d: f64) -> f64 {
    let mut z = 0.0;
    let mut length = f64::INFINITY;
    for layer in layers {
        z += layer.thickness_mm;
        if z < d - 1e-12 {
            length = length.min(d);
        } else {
            length = length.min(2.0 * z - d);
        }
    }
    length.max(1e-3)
}

/// The stack's response less the half-space's of its top layer at the pattern's depth `d`, tabulated every
/// `TABLE_STEP_MM` from 0: the in-plane radial functions (the transforms of `hankel`, a test's reference) and the
/// normal displacement's, z = 1/(2 pi) ∫ kW_nn J0 dk, t = 1/(2 pi) ∫ kW_nl J1 dk (which give Boussinesq's and
/// Cerruti's w for the half-space's spectra). The spectrum is sampled every `dk` (24 points per period of the Bessel
/// functions at the table's reach) up to where the difference has decayed by exp(-`SPECTRUM_DECAY`).
fn tabulate_stack_correction(layers: &[Layer], d: f64) -> (Vec<Radial>, Vec<Vertical>) {
    let (mu, nu) = (layers[0].shear_modulus, layers[0].poisson_ratio);
    let k_max = SPECTRUM_DECAY / correction_decay_length(layers, d);
    let dk = std::f64::consts::TAU / TABLE_REACH_MM / POINTS_PER_PERIOD;
    let spectra = sample_spectra(k_max, dk, |k| {
        let (layer, vertical) = stack_spectra(k, layers, d, mu);
        let (half, half_vertical) = (half_space_spectra(k, nu, d), half_space_vertical_spectra(k, nu, d));
        (
            Spectra {
                ll: layer.ll - half.ll,
                ln: layer.ln - half.ln,
                tt: layer.tt - half.tt,
            },
            [vertical[0] - half_vertical[0], vertical[1] - half_vertical[1]],
        )
    });
    let n = spectra.len();
    let steps = (TABLE_REACH_MM / TABLE_STEP_MM).ceil() as usize + 3;
    let tau = std::f64::consts::TAU;
    let scale = dk / 3.0 / tau / mu;
    // 1 / i and 1 / sqrt(i), shared by every radius's asymptotic Bessel functions.
    let inverse: Vec<f64> = (0..n).map(|i| 1.0 / (i.max(1) as f64)).collect();
    let inverse_sqrt: Vec<f64> = inverse.iter().map(|v| v.sqrt()).collect();
    (0..steps)
        .map(|step| {
            let r = step as f64 * TABLE_STEP_MM;
            let theta = dk * r;
            let (mut a, mut b, mut c, mut z, mut t) = (0.0, 0.0, 0.0, 0.0, 0.0);
            let mut add = |i: usize, j0: f64, j1: f64, j2: f64| {
                let (s, v) = &spectra[i];
                let weight = simpson_weight(i, n);
                a += weight * (s.ll * (j0 + j2) + s.tt * (j0 - j2));
                b += weight * (s.tt - s.ll) * j2;
                c += weight * s.ln * j1;
                z += weight * v[1] * j0;
                t += weight * v[0] * j1;
            };
            // Below x = ASYMPTOTIC_FROM, the library's Bessel functions; beyond, their asymptotic expansions with
            // the phase advanced by one rotation per sample (most of the table's samples, at a few times less cost).
            let first_asymptotic = if theta > 0.0 {
                ((ASYMPTOTIC_FROM / theta).ceil() as usize).min(n)
            } else {
                n
            };
            for i in 0..first_asymptotic {
                let x = i as f64 * theta;
                let (j0, j1) = (libm::j0(x), libm::j1(x));
                // J2 by the recurrence, with the series where 2 J1 / x - J0 cancels.
                let j2 = if x < 1e-3 { x * x / 8.0 } else { 2.0 * j1 / x - j0 };
                add(i, j0, j1, j2);
            }
            if first_asymptotic < n {
                let amplitude = (2.0 / (std::f64::consts::PI * theta)).sqrt();
                let (step_sin, step_cos) = theta.sin_cos();
                // cos and sin of x - pi/4 (J0's phase; J1's is a quarter turn behind).
                let (mut sin, mut cos) = (first_asymptotic as f64 * theta - std::f64::consts::FRAC_PI_4).sin_cos();
                for i in first_asymptotic..n {
                    let inv_x = inverse[i] / theta;
                    let [j0, j1] = asymptotic_j0_j1(inv_x, amplitude * inverse_sqrt[i], cos, sin);
                    add(i, j0, j1, 2.0 * j1 * inv_x - j0);
                    (sin, cos) = (sin * step_cos + cos * step_sin, cos * step_cos - sin * step_sin);
                }
            }
            (
                Radial {
                    a: 0.5 * a * scale,
                    b: b * scale,
                    c: -c * scale,
                },
                Vertical {
                    z: z * scale,
                    t: t * scale,
                },
            )
        })
        .unzip()
}

/// Where [`tabulate_stack_correction`] switches to the Bessel functions' asymptotic expansions: at x = 25 their
/// first omitted terms are below 1e-9 (a unit test holds them to the library's within 1e-9).
const ASYMPTOTIC_FROM: f64 = 25.0;

/// J0(x) and J1(x) from their Hankel asymptotic expansions (Abramowitz and Stegun 9.2.5, 9.2.9, 9.2.10, three
/// terms each), given 1 / x, sqrt(2 / (pi x)), and cos and sin of x - pi / 4.
fn asymptotic_j0_j1(inv_x: f64, amplitude: f64, cos: f64, sin: f64) -> [f64; 2] {
    let y = 0.125 * inv_x;
    let y2 = y * y;
    // mu = 4 nu^2: 0 for J0, 4 for J1.
    let p0 = 1.0 - y2 * (9.0 / 2.0) * (1.0 - y2 * (25.0 * 49.0 / 12.0) * (1.0 - y2 * (81.0 * 121.0 / 30.0)));
    let q0 = -y * (1.0 - y2 * (9.0 * 25.0 / 6.0) * (1.0 - y2 * (49.0 * 81.0 / 20.0)));
    let p1 = 1.0 + y2 * (3.0 * 5.0 / 2.0) * (1.0 - y2 * (21.0 * 45.0 / 12.0) * (1.0 - y2 * (77.0 * 117.0 / 30.0)));
    let q1 = 3.0 * y * (1.0 - y2 * (5.0 * 21.0 / 6.0) * (1.0 - y2 * (45.0 * 77.0 / 20.0)));
    // J1's phase x - 3 pi / 4: cos -> sin, sin -> -cos.
    [amplitude * (p0 * cos - q0 * sin), amplitude * (p1 * sin + q1 * cos)]
}

/// One homogeneous layer of the pad's stack, for [`stack_spectra`]: thickness (mm), shear modulus (N/mm²) and
/// Poisson's ratio.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Layer {
    pub thickness_mm: f64,
    pub shear_modulus: f64,
    pub poisson_ratio: f64,
}

/// The pad's layers from the contact surface down, bonded to each other and, the last one, to a rigid plate.
pub fn stack_layers(config: &ElasticConfig) -> Vec<Layer> {
    let mu = config.shear_modulus_kpa * 1e-3;
    let nu = config.poisson_ratio;
    let layer = |thickness_mm: f64, shear_modulus: f64| Layer {
        thickness_mm,
        shear_modulus,
        poisson_ratio: nu,
    };
    match config.model {
        ElasticModel::HalfSpace => Vec::new(),
        ElasticModel::BondedLayer => vec![layer(config.cover_mm + config.gel_mm, mu)],
        ElasticModel::Layered => {
            let mut layers = vec![
                layer(config.skin_mm, mu * config.skin_modulus_ratio),
                layer(config.gel_mm, mu),
            ];
            if config.bond_mm > 0.0 {
                layers.push(layer(config.bond_mm, mu * config.bond_modulus_ratio));
            }
            layers
        }
    }
}

/// The spectra of a stack of bonded layers on a rigid plate, observed at depth `d` (mm below the surface), for a
/// reference shear modulus `mu_ref` (the [`Spectra`] and the normal displacement's spectra of
/// `layer_vertical_spectra` (the tests' closed form) times mu_ref / mu, so that one layer of modulus mu_ref gives
/// exactly those).
///
/// Each layer's plane-strain field under a surface load of wave number k is a sum of two families, one decaying
/// from its top (local depth z) and one from its bottom (s = h - z), with u_x = U(z) sin kx and u_z = W(z) cos kx:
///
/// U = (a + b kz) e^(-kz) + (A + B ks) e^(-ks), W = (a + kappa b + b kz) e^(-kz) - (A + kappa B + B ks) e^(-ks),
///
/// with the stresses (over mu k) sigma_xz = -2 (a + b kz + (1 - 2 nu) b) e^(-kz) + 2 (A + B ks + (1 - 2 nu) B) e^(-ks),
/// sigma_zz = -2 (a + b kz + 2 (1 - nu) b) e^(-kz) - 2 (A + B ks + 2 (1 - nu) B) e^(-ks) (each family solves
/// Navier's equations; checked symbolically, and in the tests against the one-layer closed form). Every
/// exponential is at most 1 inside its layer, so the global system (surface tractions, continuity of U, W and both
/// stresses at each interface, U = W = 0 on the plate: 4 equations per layer) stays well conditioned at every kh.
/// The transverse part is V = p e^(-kz) + q e^(-ks) with sigma_yz = mu V', 2 equations per layer. Unknowns are
/// scaled by mu_ref k, so the values returned are k times the transfer functions times mu_ref, and vanish at k = 0
/// (a layer on a plate moves by a finite amount under a uniform traction).
pub fn stack_spectra(k: f64, layers: &[Layer], d: f64, mu_ref: f64) -> (Spectra, [f64; 2]) {
    if !(k > 0.0) || layers.is_empty() {
        return (
            Spectra {
                ll: 0.0,
                ln: 0.0,
                tt: 0.0,
            },
            [0.0, 0.0],
        );
    }
    let at = pattern_layer(layers, d);
    let nan = (
        Spectra {
            ll: f64::NAN,
            ln: f64::NAN,
            tt: f64::NAN,
        },
        [f64::NAN; 2],
    );
    let Some(([ll, ln], vertical)) = plane_strain_response(k, layers, at, mu_ref) else {
        return nan;
    };
    let Some(tt) = transverse_response(k, layers, at, mu_ref) else {
        return nan;
    };
    (Spectra { ll, ln, tt }, vertical)
}

/// Which layer the pattern at depth `d` lies in, and its depth in it (on an interface both layers agree).
fn pattern_layer(layers: &[Layer], d: f64) -> (usize, f64) {
    let n = layers.len();
    let mut top = 0.0;
    let mut at = (n - 1, layers[n - 1].thickness_mm);
    for (j, layer) in layers.iter().enumerate() {
        if d <= top + layer.thickness_mm {
            at = (j, (d - top).max(0.0));
            break;
        }
        top += layer.thickness_mm;
    }
    at
}

/// In-plane and normal displacement, shear and normal stress rows of a layer's four plane-strain unknowns at local
/// depth z (see [`stack_spectra`]).
fn plane_strain_rows(layer: &Layer, k: f64, z: f64, mu_ref: f64) -> [[f64; 4]; 4] {
    let kappa = 3.0 - 4.0 * layer.poisson_ratio;
    let s = layer.thickness_mm - z;
    let (et, eb) = ((-k * z).exp(), (-k * s).exp());
    let (kz, ks) = (k * z, k * s);
    let u = [et, kz * et, eb, ks * eb];
    let w = [et, (kappa + kz) * et, -eb, -(kappa + ks) * eb];
    let c = 1.0 - 2.0 * layer.poisson_ratio;
    let q = 2.0 * (1.0 - layer.poisson_ratio);
    let ratio = layer.shear_modulus / mu_ref;
    let sxz = [
        -2.0 * ratio * et,
        -2.0 * ratio * (kz + c) * et,
        2.0 * ratio * eb,
        2.0 * ratio * (ks + c) * eb,
    ];
    let szz = [
        -2.0 * ratio * et,
        -2.0 * ratio * (kz + q) * et,
        -2.0 * ratio * eb,
        -2.0 * ratio * (ks + q) * eb,
    ];
    [u, w, sxz, szz]
}

/// The plane-strain (sagittal) part at the pattern (layer `at.0`, depth `at.1`): [ll, ln] and the normal
/// displacement's [from t_x, from p]; none if the system is singular.
fn plane_strain_response(k: f64, layers: &[Layer], at: (usize, f64), mu_ref: f64) -> Option<([f64; 2], [f64; 2])> {
    let n = layers.len();
    let rows = |layer: &Layer, z: f64| plane_strain_rows(layer, k, z, mu_ref);
    let size = 4 * n;
    let mut m = DMatrix::zeros(size, size);
    let mut rhs = DMatrix::zeros(size, 2);
    // The surface: sigma_xz = -t_x, sigma_zz = -p (z points into the pad).
    let surface = rows(&layers[0], 0.0);
    for c in 0..4 {
        m[(0, c)] = surface[2][c];
        m[(1, c)] = surface[3][c];
    }
    rhs[(0, 0)] = -1.0;
    rhs[(1, 1)] = -1.0;
    for j in 0..n - 1 {
        let (above, below) = (rows(&layers[j], layers[j].thickness_mm), rows(&layers[j + 1], 0.0));
        for (i, (a, b)) in above.iter().zip(&below).enumerate() {
            for c in 0..4 {
                m[(2 + 4 * j + i, 4 * j + c)] = a[c];
                m[(2 + 4 * j + i, 4 * (j + 1) + c)] = -b[c];
            }
        }
    }
    let plate = rows(&layers[n - 1], layers[n - 1].thickness_mm);
    for c in 0..4 {
        m[(size - 2, 4 * (n - 1) + c)] = plate[0][c];
        m[(size - 1, 4 * (n - 1) + c)] = plate[1][c];
    }
    let x = m.lu().solve(&rhs)?;
    let observed = rows(&layers[at.0], at.1);
    let value = |row: &[f64; 4], col: usize| (0..4).map(|c| row[c] * x[(4 * at.0 + c, col)]).sum::<f64>();
    // This basis's sin/cos phases make the cross terms the opposite sign of [`Spectra`]'s.
    let (ll, ln) = (value(&observed[0], 0), -value(&observed[0], 1));
    let vertical = [-value(&observed[1], 0), value(&observed[1], 1)];
    Some(([ll, ln], vertical))
}

/// Displacement and shear stress rows of a layer's two transverse (antiplane) unknowns p, q at local depth z.
fn transverse_rows(layer: &Layer, k: f64, z: f64, mu_ref: f64) -> [[f64; 2]; 2] {
    let s = layer.thickness_mm - z;
    let (et, eb) = ((-k * z).exp(), (-k * s).exp());
    let ratio = layer.shear_modulus / mu_ref;
    [[et, eb], [-ratio * et, ratio * eb]]
}

/// The transverse part at the pattern: tt; none if the system is singular.
fn transverse_response(k: f64, layers: &[Layer], at: (usize, f64), mu_ref: f64) -> Option<f64> {
    let n = layers.len();
    let sh = |layer: &Layer, z: f64| transverse_rows(layer, k, z, mu_ref);
    let size = 2 * n;
    let mut m = DMatrix::zeros(size, size);
    let mut rhs = DVector::zeros(size);
    let surface = sh(&layers[0], 0.0);
    m[(0, 0)] = surface[1][0];
    m[(0, 1)] = surface[1][1];
    rhs[0] = -1.0;
    for j in 0..n - 1 {
        let (above, below) = (sh(&layers[j], layers[j].thickness_mm), sh(&layers[j + 1], 0.0));
        for i in 0..2 {
            for c in 0..2 {
                m[(1 + 2 * j + i, 2 * j + c)] = above[i][c];
                m[(1 + 2 * j + i, 2 * (j + 1) + c)] = -below[i][c];
            }
        }
    }
    let plate = sh(&layers[n - 1], layers[n - 1].thickness_mm);
    m[(size - 1, 2 * (n - 1))] = plate[0][0];
    m[(size - 1, 2 * (n - 1) + 1)] = plate[0][1];
    let x = m.lu().solve(&rhs)?;
    let observed = sh(&layers[at.0], at.1);
    Some(observed[0][0] * x[2 * at.0] + observed[0][1] * x[2 * at.0 + 1])
}

/// One Catmull-Rom segment at `t` in [0, 1) between p1 and p2.
fn catmull_rom_1(t: f64, p0: f64, p1: f64, p2: f64, p3: f64) -> f64 {
    p1 + 0.5 * t * (p2 - p0 + t * (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3 + t * (3.0 * (p1 - p2) + p3 - p0)))
}

/// A table of radial functions that [`catmull_rom`] interpolates: each field on its own, mirrored at r = 0.
trait RadialTable: Copy {
    /// The value at -r from the value at r (each field even or odd in r).
    fn mirrored(self) -> Self;
    /// [`catmull_rom_1`] on every field.
    fn segment(t: f64, p: [Self; 4]) -> Self;
}

impl RadialTable for Radial {
    /// a is even in r, b and c vanish there with even / odd symmetry.
    fn mirrored(self) -> Self {
        Radial { c: -self.c, ..self }
    }

    fn segment(t: f64, [p0, p1, p2, p3]: [Self; 4]) -> Self {
        Radial {
            a: catmull_rom_1(t, p0.a, p1.a, p2.a, p3.a),
            b: catmull_rom_1(t, p0.b, p1.b, p2.b, p3.b),
            c: catmull_rom_1(t, p0.c, p1.c, p2.c, p3.c),
        }
    }
}

impl RadialTable for Vertical {
    /// z is even in r, t odd.
    fn mirrored(self) -> Self {
        Vertical { t: -self.t, ..self }
    }

    fn segment(t: f64, [p0, p1, p2, p3]: [Self; 4]) -> Self {
        Vertical {
            z: catmull_rom_1(t, p0.z, p1.z, p2.z, p3.z),
            t: catmull_rom_1(t, p0.t, p1.t, p2.t, p3.t),
        }
    }
}

/// Cubic (Catmull-Rom) interpolation of a table at fractional index `at`; `None` past the table's reach
/// (at >= len - 2), where it has no neighbours to interpolate with.
fn catmull_rom<T: RadialTable>(table: &[T], at: f64) -> Option<T> {
    if !(at < (table.len() - 2) as f64) {
        return None;
    }
    let i = at.floor() as usize;
    let p0 = if i == 0 { table[1].mirrored() } else { table[i - 1] };
    Some(T::segment(at - i as f64, [p0, table[i], table[i + 1], table[i + 2]]))
}

/// A rectangular cell of uniform traction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cell {
    pub centre_mm: Point2,
    pub size_mm: Point2,
}

impl Cell {
    /// Gauss points and weights (summing to 1) of the cell's uniform unit load.
    fn samples(&self) -> impl Iterator<Item = (Point2, f64)> + '_ {
        GAUSS.iter().flat_map(move |&(gx, wx)| {
            GAUSS.iter().map(move |&(gy, wy)| {
                (
                    [
                        self.centre_mm[0] + gx * self.size_mm[0],
                        self.centre_mm[1] + gy * self.size_mm[1],
                    ],
                    wx * wy,
                )
            })
        })
    }
}

/// Gauss-Legendre points and weights on [-1/2, 1/2] (5 points: exact for polynomials of degree 9; the kernel at
/// the pattern's depth varies on the scale of that depth, about a cell).
const GAUSS: [(f64, f64); 5] = [
    (-0.453_089_922_969_332_3, 0.118_463_442_528_094_54),
    (-0.269_234_655_052_841_5, 0.239_314_335_249_683_23),
    (0.0, 0.284_444_444_444_444_45),
    (0.269_234_655_052_841_5, 0.239_314_335_249_683_23),
    (0.453_089_922_969_332_3, 0.118_463_442_528_094_54),
];

/// Where the pad ends (bonded layer only).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Border {
    /// An unbounded layer.
    None,
    /// Bonded to its frame along a rectangle of these half-extents (mm): held still there.
    Clamped(Point2),
    /// Held in a frame whose walls, at these half-extents (mm), stop the gel moving through them and let it slide
    /// along them (no shear on them): each wall is a plane of symmetry of the field, which mirror images of the load
    /// across it give exactly (its tangential traction normal to the wall flipped). Only the images across each wall
    /// and across both walls at each corner are kept; images of images lie more than twice the pad's size away, where
    /// the layer's response has decayed.
    Sliding(Point2),
}

/// A load at `q` and its images across the sliding walls `walls` (half-extents, mm), if any: each image's place
/// and the sign of its tangential traction (x, y).
fn with_images(q: Point2, walls: Option<Point2>) -> impl Iterator<Item = (Point2, [f64; 2])> {
    let reflections: &[(i8, i8)] = if walls.is_some() {
        &[
            (0, 0),
            (1, 0),
            (-1, 0),
            (0, 1),
            (0, -1),
            (1, 1),
            (1, -1),
            (-1, 1),
            (-1, -1),
        ]
    } else {
        &[(0, 0)]
    };
    let [half_x, half_y] = walls.unwrap_or([0.0, 0.0]);
    reflections.iter().map(move |&(ix, iy)| {
        let x = if ix == 0 {
            q[0]
        } else {
            2.0 * f64::from(ix) * half_x - q[0]
        };
        let y = if iy == 0 {
            q[1]
        } else {
            2.0 * f64::from(iy) * half_y - q[1]
        };
        let flip = |i: i8| if i == 0 { 1.0 } else { -1.0 };
        ([x, y], [flip(ix), flip(iy)])
    })
}

/// The stack whose normal displacement the parallax sees when it is not `config`'s own model's (see
/// [`ElasticConfig::normal_from_stack`]): the equivalent layer's stack as built, its moduli in proportion to
/// `config.shear_modulus_kpa`.
pub fn normal_stack(config: &ElasticConfig) -> Option<ElasticConfig> {
    (config.model == ElasticModel::BondedLayer && config.normal_from_stack).then(|| ElasticConfig {
        model: ElasticModel::Layered,
        shear_modulus_kpa: config.shear_modulus_kpa * LAYERED_GEL_KPA / EQUIVALENT_LAYER_KPA,
        ..*config
    })
}

/// The matrix of cell forces (N; fx, fy, fz per cell) to in-plane displacements (mm; x, y per observation point),
/// with the pad clamped along a rectangle or held between sliding walls when asked.
#[derive(Clone, Debug)]
pub struct PadResponse {
    /// (2 * observations) x (3 * cells).
    pub matrix: DMatrix<f64>,
    /// The sliding walls' half-extents, if any (the parallax's images too).
    walls: Option<Point2>,
}

impl PadResponse {
    /// `border`: where and how the pad is held at its edge.
    pub fn new(
        kernel: &PointKernel,
        observations: &[Point2],
        cells: &[Cell],
        border: Border,
    ) -> Result<Self, ElasticError> {
        let walls = match border {
            Border::Sliding(half) => Some(half),
            _ => None,
        };
        let mut matrix = cell_matrix(kernel, observations, cells, walls);
        if let Border::Clamped(half) = border {
            // The frame holds the pattern still along the border: reaction forces there cancel the displacement
            // that the cell tractions would cause at the border. A displacement field u = A t becomes
            // u - G_ob G_bb^-1 G_bt t, with G the point responses between observation, border and cell points.
            let points = border_points(half, kernel.depth_mm);
            let g_bb = point_matrix(kernel, &points, &points);
            let g_ob = point_matrix(kernel, observations, &points);
            let g_bt = cell_matrix(kernel, &points, cells, None);
            // The reactions' own response is positive definite; a tiny ridge keeps the factorisation stable.
            let ridge = 1e-9 * g_bb.diagonal().iter().map(|v| v.abs()).fold(0.0, f64::max);
            let mut regularised = g_bb;
            for i in 0..regularised.nrows() {
                regularised[(i, i)] += ridge;
            }
            let lu = regularised.lu();
            let reactions = lu
                .solve(&g_bt)
                .ok_or(ElasticError::Degenerate("border reactions are singular"))?;
            matrix -= g_ob * reactions;
        }
        if matrix.iter().any(|v| !v.is_finite()) {
            return Err(ElasticError::Degenerate("the response matrix is not finite"));
        }
        Ok(Self { matrix, walls })
    }

    /// Adds what the camera sees of the pattern's normal displacement: a point that moves by w towards the camera
    /// appears shifted in the pattern's plane by w times `shifts[i]` (its ray's in-plane slope where it moves, see
    /// [`parallax_shifts`]). w is `kernel`'s normal displacement, which need not be the in-plane response's kernel
    /// (see [`normal_stack`]). Cell-averaged like the in-plane response; the border's reactions (if any) are not
    /// applied to it.
    pub fn add_parallax(&mut self, kernel: &PointKernel, observations: &[Point2], cells: &[Cell], shifts: &[Point2]) {
        for (j, cell) in cells.iter().enumerate() {
            for (i, p) in observations.iter().enumerate() {
                let s = shifts[i];
                if s == [0.0, 0.0] {
                    continue;
                }
                let mut w = [0.0; 3];
                for (q, weight) in cell.samples() {
                    for (q, flip) in with_images(q, self.walls) {
                        let v = kernel.vertical([p[0] - q[0], p[1] - q[1]]);
                        let flip = [flip[0], flip[1], 1.0];
                        for ((sum, v), f) in w.iter_mut().zip(v).zip(flip) {
                            *sum += weight * v * f;
                        }
                    }
                }
                for (row, s) in s.iter().enumerate() {
                    for (col, w) in w.iter().enumerate() {
                        self.matrix[(2 * i + row, 3 * j + col)] += s * w;
                    }
                }
            }
        }
    }
}

/// Where the camera is, seen from the pattern: the foot of its centre on the pattern's plane (pad mm) and its
/// height above that plane (mm, as the rest frame's homography sees it through the plate and the gel).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraView {
    pub foot_mm: Point2,
    pub height_mm: f64,
}

/// Per observation point, the in-plane shift (mm per mm) with which a point of the pattern that moves towards the
/// camera appears to move along its ray: away from the camera's foot, by the tangent of the ray's angle in the gel
/// it moves through (Snell: sin = sin in air / `refractive_index`).
pub fn parallax_shifts(view: &CameraView, refractive_index: f64, observations: &[Point2]) -> Vec<Point2> {
    observations
        .iter()
        .map(|p| {
            let offset = [p[0] - view.foot_mm[0], p[1] - view.foot_mm[1]];
            let r = offset[0].hypot(offset[1]);
            if !(r > 1e-12 && view.height_mm > 0.0) {
                return [0.0, 0.0];
            }
            let sin_air = r / r.hypot(view.height_mm);
            let sin_gel = sin_air / refractive_index;
            let tan_gel = sin_gel / (1.0 - sin_gel * sin_gel).sqrt();
            [tan_gel * offset[0] / r, tan_gel * offset[1] / r]
        })
        .collect()
}

/// Points along the clamped rectangle, spaced about one pattern depth apart (closer adds nothing the kernel can
/// resolve at that depth, and only worsens the reactions' conditioning).
fn border_points(half: Point2, depth: f64) -> Vec<Point2> {
    let spacing = depth.clamp(0.5, 3.0);
    let mut points = Vec::new();
    let nx = ((2.0 * half[0]) / spacing).ceil() as usize;
    let ny = ((2.0 * half[1]) / spacing).ceil() as usize;
    for i in 0..nx {
        let x = -half[0] + 2.0 * half[0] * i as f64 / nx as f64;
        points.push([x, -half[1]]);
        points.push([-x, half[1]]);
    }
    for j in 0..ny {
        let y = -half[1] + 2.0 * half[1] * j as f64 / ny as f64;
        points.push([half[0], y]);
        points.push([-half[0], -y]);
    }
    points
}

/// In-plane point responses: (2 * to) x (2 * from), tangential forces only.
fn point_matrix(kernel: &PointKernel, to: &[Point2], from: &[Point2]) -> DMatrix<f64> {
    let mut m = DMatrix::zeros(2 * to.len(), 2 * from.len());
    for (i, p) in to.iter().enumerate() {
        for (j, q) in from.iter().enumerate() {
            let r = kernel.response([p[0] - q[0], p[1] - q[1]]);
            for row in 0..2 {
                for col in 0..2 {
                    m[(2 * i + row, 2 * j + col)] = r[row][col];
                }
            }
        }
    }
    m
}

/// What sliding walls at half-extents `walls` (mm) add to the in-plane response of `cells` at `observations`: the
/// cell-averaged responses of the loads' images alone, (2 * observations) x (3 * cells). How much a load's far field
/// depends on how the pad is held at its edge (see `InverseModel::border_doubt`).
pub fn image_matrix(kernel: &PointKernel, observations: &[Point2], cells: &[Cell], walls: Point2) -> DMatrix<f64> {
    cell_matrix(kernel, observations, cells, Some(walls)) - cell_matrix(kernel, observations, cells, None)
}

/// Cell-averaged responses: (2 * to) x (3 * cells), with the loads' images across sliding `walls` if any.
fn cell_matrix(kernel: &PointKernel, to: &[Point2], cells: &[Cell], walls: Option<Point2>) -> DMatrix<f64> {
    let mut m = DMatrix::zeros(2 * to.len(), 3 * cells.len());
    for (j, cell) in cells.iter().enumerate() {
        for (i, p) in to.iter().enumerate() {
            let mut sum = [[0.0; 3]; 2];
            for (q, weight) in cell.samples() {
                for (q, flip) in with_images(q, walls) {
                    let r = kernel.response([p[0] - q[0], p[1] - q[1]]);
                    let flip = [flip[0], flip[1], 1.0];
                    for row in 0..2 {
                        for col in 0..3 {
                            sum[row][col] += weight * r[row][col] * flip[col];
                        }
                    }
                }
            }
            for row in 0..2 {
                for col in 0..3 {
                    m[(2 * i + row, 3 * j + col)] = sum[row][col];
                }
            }
        }
    }
    m
}

/// Displacements (mm) at `observations` from forces `forces` (N, 3 per cell), for tests and the simulator checks.
pub fn apply(response: &PadResponse, forces: &[f64]) -> Vec<f64> {
    (&response.matrix * DVector::from_column_slice(forces))
        .as_slice()
        .to_vec()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64, tolerance: f64) -> bool {
        (a - b).abs() <= tolerance
    }

    #[test]
    fn hankel_of_the_half_space_spectra_gives_boussinesq_and_cerruti() {
        // The spectra and the closed forms come from separate derivations; agreement checks both, and every sign
        // convention between them.
        for nu in [0.5, 0.3] {
            let d = 2.0;
            let dk = 0.002;
            let spectra = sample_spectra(40.0 / d, dk, |k| half_space_spectra(k, nu, d));
            for r in [0.0, 0.7, 2.0, 5.0, 11.0] {
                let numeric = hankel(&spectra, dk, r);
                let exact = half_space_radial(1.0, nu, d, r);
                let scale = exact.a.abs();
                assert!(
                    close(numeric.a, exact.a, 1e-4 * scale),
                    "nu {nu} r {r}: a {numeric:?} vs {exact:?}"
                );
                assert!(
                    close(numeric.b, exact.b, 1e-4 * scale),
                    "nu {nu} r {r}: b {numeric:?} vs {exact:?}"
                );
                assert!(
                    close(numeric.c, exact.c, 1e-4 * scale),
                    "nu {nu} r {r}: c {numeric:?} vs {exact:?}"
                );
            }
        }
    }

    fn layer(thickness_mm: f64, shear_modulus: f64, poisson_ratio: f64) -> Layer {
        Layer {
            thickness_mm,
            shear_modulus,
            poisson_ratio,
        }
    }

    #[test]
    fn the_asymptotic_bessel_functions_are_the_librarys() {
        let mut worst: f64 = 0.0;
        for i in 0..20_000 {
            let x = ASYMPTOTIC_FROM + 0.0137 * i as f64;
            let amplitude = (2.0 / (std::f64::consts::PI * x)).sqrt();
            let (sin, cos) = (x - std::f64::consts::FRAC_PI_4).sin_cos();
            let [j0, j1] = asymptotic_j0_j1(1.0 / x, amplitude, cos, sin);
            worst = worst.max((j0 - libm::j0(x)).abs()).max((j1 - libm::j1(x)).abs());
        }
        assert!(worst < 1e-9, "{worst}");
    }

    /// A stack of layers of one material is one layer: its spectra are the closed form's of [`layer_spectra`] (a
    /// separate derivation), wherever the pattern lies and however the thickness is cut into layers.
    #[test]
    fn a_stack_of_one_material_is_the_single_layer() {
        for nu in [0.5, 0.3, 0.0] {
            for (d, h) in [(2.8, 5.0), (0.8, 3.5), (1.0, 1.5)] {
                let cuts = [
                    vec![layer(h, 0.048, nu)],
                    vec![layer(d, 0.048, nu), layer(h - d, 0.048, nu)],
                    vec![layer(0.3, 0.048, nu), layer(h - 0.8, 0.048, nu), layer(0.5, 0.048, nu)],
                ];
                for layers in &cuts {
                    for k in [1e-3, 0.05, 0.3, 1.0, 4.0, 20.0] {
                        let (stack, vertical) = stack_spectra(k, layers, d, 0.048);
                        let (single, single_vertical) =
                            (layer_spectra(k, nu, d, h), layer_vertical_spectra(k, nu, d, h));
                        let scale = 1e-9 * (1.0 + (-k * d).exp());
                        for (what, a, b) in [
                            ("ll", stack.ll, single.ll),
                            ("ln", stack.ln, single.ln),
                            ("tt", stack.tt, single.tt),
                            ("wl", vertical[0], single_vertical[0]),
                            ("wn", vertical[1], single_vertical[1]),
                        ] {
                            assert!(
                                close(a, b, scale.max(1e-9 * b.abs())),
                                "nu {nu} d {d} h {h} k {k} {} layers: {what} {a} vs {b}",
                                layers.len()
                            );
                        }
                    }
                }
            }
        }
    }

    fn layered(skin_mm: f64, skin_modulus_ratio: f64, gel_mm: f64) -> ElasticConfig {
        ElasticConfig {
            model: ElasticModel::Layered,
            shear_modulus_kpa: 20.0,
            skin_mm,
            skin_modulus_ratio,
            gel_mm,
            ..ElasticConfig::default()
        }
    }

    /// A skin of the gel's own modulus over 100 mm of gel is, within a few millimetres of the load, Boussinesq's and
    /// Cerruti's half-space at the skin's depth (the plate 100 mm down takes away the half-space's 1 / r field beyond
    /// about its own depth: of order the pattern's depth over the thickness, 1 % here; held to 2 %).
    #[test]
    fn a_thick_stack_is_the_half_space() {
        let kernel = PointKernel::new(&layered(1.0, 1.0, 100.0)).unwrap();
        let near = half_space_radial(0.02, 0.5, 1.0, 0.0).a;
        for r in [0.0, 0.5, 1.0, 2.0, 4.0, 8.0] {
            let (stack, half) = (kernel.radial(r), half_space_radial(0.02, 0.5, 1.0, r));
            for (what, a, b) in [("a", stack.a, half.a), ("b", stack.b, half.b), ("c", stack.c, half.c)] {
                assert!(close(a, b, 0.02 * near), "r {r}: {what} {a} vs {b}");
            }
            let (stack, half) = (kernel.vertical_radial(r), half_space_vertical(0.02, 0.5, 1.0, r));
            assert!(close(stack.z, half.z, 0.02 * near), "r {r}: z {stack:?} vs {half:?}");
            assert!(close(stack.t, half.t, 0.02 * near), "r {r}: t {stack:?} vs {half:?}");
        }
    }

    /// A stiff skin carries a point load outwards before the soft gel takes it: the pattern under it moves less
    /// right under the load, and a normal load pushes it outward over a wider radius (Odemark: a skin of modulus
    /// ratio m acts like gel m^(1/3) times as thick, so the peak of the outward push moves out with the ratio).
    #[test]
    fn a_stiff_skin_spreads_the_load() {
        let peak = |kernel: &PointKernel| {
            (0..300)
                .map(|i| 0.02 * i as f64)
                .max_by(|a, b| kernel.radial(*a).c.total_cmp(&kernel.radial(*b).c))
                .unwrap()
        };
        let plain = PointKernel::new(&layered(1.0, 1.0, 3.0)).unwrap();
        let stiff = PointKernel::new(&layered(1.0, 10.0, 3.0)).unwrap();
        let stiffer = PointKernel::new(&layered(1.0, 100.0, 3.0)).unwrap();
        let (a0, a1, a2) = (plain.radial(0.0).a, stiff.radial(0.0).a, stiffer.radial(0.0).a);
        assert!(a1 < 0.5 * a0 && a2 < 0.5 * a1, "{a0} {a1} {a2}");
        let (p0, p1, p2) = (peak(&plain), peak(&stiff), peak(&stiffer));
        assert!(
            p1 > 1.2 * p0 && p2 > 1.4 * p1,
            "peaks of the outward push at {p0} {p1} {p2} mm"
        );
        // With the plain layer the plate makes the response die within ten thicknesses.
        let far = plain.radial(40.0);
        assert!(far.a.abs().max(far.b.abs()).max(far.c.abs()) < 1e-3 * a0, "{far:?}");
    }

    #[test]
    fn a_thick_layer_is_a_half_space_and_a_thin_one_is_stiffer() {
        for nu in [0.5, 0.25] {
            for k in [0.3, 1.0, 4.0] {
                let thick = layer_spectra(k, nu, 1.5, 200.0);
                let half = half_space_spectra(k, nu, 1.5);
                assert!(
                    close(thick.ll, half.ll, 1e-9) && close(thick.ln, half.ln, 1e-9),
                    "k {k}: {thick:?} {half:?}"
                );
                assert!(close(thick.tt, half.tt, 1e-9));
            }
        }
        // Long waves: a clamped layer under a uniform shear traction shears uniformly, u = q (h - d) / mu, so
        // k T_ll -> 0 with T_ll -> h - d; incompressible, it cannot move sideways under uniform pressure.
        let (d, h) = (1.0, 3.2);
        let k = 1e-4;
        let s = layer_spectra(k, 0.5, d, h);
        assert!(close(s.ll / k, h - d, 1e-3), "{}", s.ll / k);
        assert!(close(s.tt / k, h - d, 1e-3), "{}", s.tt / k);
        assert!((s.ln / k).abs() < 1e-2, "{}", s.ln / k);
        assert!(layer_spectra(0.0, 0.5, d, h).ll.is_finite());
    }

    #[test]
    fn the_layer_kernel_is_the_half_space_near_the_load_and_vanishes_far_away() {
        let config = ElasticConfig::default();
        let layer = PointKernel::new(&config).unwrap();
        let half = PointKernel::new(&ElasticConfig {
            model: ElasticModel::HalfSpace,
            ..config
        })
        .unwrap();
        let h = config.cover_mm + config.gel_mm;
        // Right above the load the rigid base stiffens the response, but only somewhat.
        let (near_l, near_h) = (layer.radial(0.0), half.radial(0.0));
        assert!(
            near_l.a > 0.3 * near_h.a && near_l.a < near_h.a,
            "{near_l:?} {near_h:?}"
        );
        // The normal load pushes the pattern outward at depth, in both models.
        assert!(layer.radial(config.cover_mm).c > 0.0 && half.radial(config.cover_mm).c > 0.0);
        // Ten thicknesses away the layer has forgotten the load; the half-space has not (1 / r).
        let far = layer.radial(10.0 * h);
        assert!(
            far.a.abs() < 1e-3 * near_l.a && far.c.abs() < 1e-3 * near_l.a,
            "{far:?}"
        );
        assert!(half.radial(10.0 * h).a > 0.02 * near_h.a);
        // The table is smooth: interpolation between nodes agrees with a direct transform.
        let k_max = SPECTRUM_DECAY / (2.0 * h - config.cover_mm);
        let dk = std::f64::consts::TAU / TABLE_REACH_MM / POINTS_PER_PERIOD;
        let spectra = sample_spectra(k_max, dk, |k| {
            let (l, s) = (
                layer_spectra(k, 0.5, config.cover_mm, h),
                half_space_spectra(k, 0.5, config.cover_mm),
            );
            Spectra {
                ll: l.ll - s.ll,
                ln: l.ln - s.ln,
                tt: l.tt - s.tt,
            }
        });
        let mu = config.shear_modulus_kpa * 1e-3;
        for r in [0.05, 1.234, 3.377, 7.91] {
            let direct = hankel(&spectra, dk, r);
            let direct = half_space_radial(mu, 0.5, config.cover_mm, r)
                + Radial {
                    a: direct.a / mu,
                    b: direct.b / mu,
                    c: direct.c / mu,
                };
            let table = layer.radial(r);
            let scale = near_l.a;
            assert!(
                close(direct.a, table.a, 1e-5 * scale) && close(direct.b, table.b, 1e-5 * scale),
                "{r}"
            );
            assert!(close(direct.c, table.c, 1e-5 * scale), "{r}");
        }
    }

    /// The normal displacement's spectra and transforms: the half-space's spectra transform to Boussinesq's and
    /// Cerruti's closed forms (so the table's transform is the right one), the layer's spectra are the
    /// half-space's for short waves, and an incompressible layer on its plate does not sink under a uniform load.
    #[test]
    fn the_normal_displacement_is_boussinesq_and_cerruti_and_the_layer_tends_to_them() {
        for nu in [0.5, 0.3] {
            let d = 2.8;
            let dk = 1e-3;
            let n = 40_001;
            for r in [0.5, 2.0, 5.0, 10.0] {
                let (mut z, mut t) = (0.0, 0.0);
                for i in 0..n {
                    let k = i as f64 * dk;
                    let w = if i == 0 || i == n - 1 {
                        1.0
                    } else if i % 2 == 1 {
                        4.0
                    } else {
                        2.0
                    };
                    let s = half_space_vertical_spectra(k, nu, d);
                    z += w * s[1] * libm::j0(k * r);
                    t += w * s[0] * libm::j1(k * r);
                }
                let scale = dk / 3.0 / std::f64::consts::TAU;
                let exact = half_space_vertical(1.0, nu, d, r);
                assert!(
                    close(z * scale, exact.z, 1e-6 * exact.z),
                    "nu {nu} r {r}: {} {}",
                    z * scale,
                    exact.z
                );
                assert!(
                    close(t * scale, exact.t, 1e-6 * exact.t),
                    "nu {nu} r {r}: {} {}",
                    t * scale,
                    exact.t
                );
            }
            let (layer, half) = (
                layer_vertical_spectra(30.0, nu, 0.5, 5.0),
                half_space_vertical_spectra(30.0, nu, 0.5),
            );
            assert!(
                close(layer[0], half[0], 1e-9) && close(layer[1], half[1], 1e-9),
                "{layer:?} {half:?}"
            );
        }
        let uniform = layer_vertical_spectra(1e-9, 0.5, 2.8, 5.0);
        assert!(uniform[1].abs() < 1e-6, "{uniform:?}");
    }

    #[test]
    fn sliding_walls_stop_the_pattern_moving_through_them() {
        let kernel = PointKernel::new(&ElasticConfig::default()).unwrap();
        let walls = [29.5, 23.0];
        let cells = [Cell {
            centre_mm: [22.0, 15.0],
            size_mm: [3.3, 3.3],
        }];
        // Points on the right wall and on the bottom one, near the load.
        let on_right: Vec<Point2> = (0..7).map(|i| [walls[0], 6.0 + 3.0 * i as f64]).collect();
        let on_bottom: Vec<Point2> = (0..7).map(|i| [12.0 + 3.0 * i as f64, walls[1]]).collect();
        for (points, across) in [(on_right, 0), (on_bottom, 1)] {
            let free = PadResponse::new(&kernel, &points, &cells, Border::None).unwrap();
            let held = PadResponse::new(&kernel, &points, &cells, Border::Sliding(walls)).unwrap();
            for col in 0..3 {
                let largest = (0..points.len())
                    .map(|i| free.matrix[(2 * i + across, col)].abs())
                    .fold(0.0, f64::max);
                for (i, point) in points.iter().enumerate() {
                    let through = held.matrix[(2 * i + across, col)];
                    assert!(
                        through.abs() < 1e-5 * largest,
                        "force {col} moves {point:?} through the wall by {through} ({largest} free)"
                    );
                }
                // Along the wall the pattern still moves (it slides), more than without the wall for a normal load.
                if col == 2 {
                    let along =
                        |m: &DMatrix<f64>| (0..points.len()).map(|i| m[(2 * i + 1 - across, 2)].abs()).sum::<f64>();
                    assert!(
                        along(&held.matrix) > along(&free.matrix),
                        "the wall does not let it slide"
                    );
                }
            }
        }
        // Far from the walls they change little.
        let centre = [Cell {
            centre_mm: [0.0, 0.0],
            size_mm: [3.3, 3.3],
        }];
        let inside = [[0.0, 3.0], [4.0, 0.0]];
        let free = PadResponse::new(&kernel, &inside, &centre, Border::None).unwrap();
        let held = PadResponse::new(&kernel, &inside, &centre, Border::Sliding(walls)).unwrap();
        let change = (&free.matrix - &held.matrix).abs().max();
        assert!(change < 1e-3 * free.matrix.abs().max(), "{change}");
    }

    #[test]
    #[ignore = "known failure: 13 mm from the clamp the response changes by 1.3 %, above the 1 % this test asks"]
    fn a_clamped_border_holds_the_border_still() {
        let config = ElasticConfig {
            model: ElasticModel::BondedLayer,
            bonded_border: true,
            ..ElasticConfig::default()
        };
        let kernel = PointKernel::new(&config).unwrap();
        let half = [20.0, 15.0];
        let on_border: Vec<Point2> = (0..9).map(|i| [-16.0 + 4.0 * i as f64, 15.0]).collect();
        let cells = [Cell {
            centre_mm: [0.0, 12.0],
            size_mm: [3.0, 3.0],
        }];
        let free = PadResponse::new(&kernel, &on_border, &cells, Border::None).unwrap();
        let clamped = PadResponse::new(&kernel, &on_border, &cells, Border::Clamped(half)).unwrap();
        let largest = |m: &DMatrix<f64>| m.iter().map(|v| v.abs()).fold(0.0, f64::max);
        assert!(
            largest(&clamped.matrix) < 0.1 * largest(&free.matrix),
            "{} vs {}",
            largest(&clamped.matrix),
            largest(&free.matrix)
        );
        // Far from the border the clamp changes little.
        let inside = [[0.0, 2.0]];
        let centre = [Cell {
            centre_mm: [0.0, 0.0],
            size_mm: [3.0, 3.0],
        }];
        let free = PadResponse::new(&kernel, &inside, &centre, Border::None).unwrap();
        let clamped = PadResponse::new(&kernel, &inside, &centre, Border::Clamped(half)).unwrap();
        let change = (&free.matrix - &clamped.matrix).abs().max();
        assert!(
            change < 0.01 * largest(&free.matrix),
            "{change} of {}",
            largest(&free.matrix)
        );
    }
}
