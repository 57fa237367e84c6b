//! The pad as it is built: elastomer layers bonded to a rigid plate, held in a frame, solved in the Fourier domain.
//!
//! This is the validation set's mechanics, written to share nothing with the estimator's kernels but the physics:
//!
//! - **Through the thickness**, each wavevector's response comes from the layers' state equations (displacement
//!   and traction on horizontal planes, d s / dz = k A s), propagated by a numerical matrix exponential over thin
//!   sub-layers and combined bottom-up by the compliance recursion (C = 0 on the rigid plate; each sub-layer maps
//!   the compliance below it to the one above). No closed-form layer solution, no half-space split, no Hankel
//!   transform: any number of layers, each with its own modulus and Poisson ratio (nu = 0.5 included).
//! - **In the plane**, the surface tractions are laid on a grid and transformed with a 2-D FFT. The pad ends at
//!   rigid frame walls `border_margin_mm` beyond the pattern; mirror images of the load across the walls (tangential
//!   traction normal to a wall flips sign) make the walls exact planes of symmetry: no displacement through them
//!   and no shear on them. The FFT's period is then twice the pad's size, and the field inside is that of the
//!   finite pad, not of an infinite one.
//!
//! Limits the tests hold it to: a thick layer is the half-space (Boussinesq, Cerruti); a thin incompressible layer
//! is the lubrication solution; uniform shear and pressure give simple shear and confined compression; the surface
//! compliance is reciprocal (Hermitian); the laid-down load carries exactly the requested force and moment.

use std::f64::consts::PI;
use std::sync::Arc;

use rustfft::num_complex::Complex64;
use rustfft::{Fft, FftPlanner};
use serde::{Deserialize, Serialize};

use crate::mechanics::PointForce;

/// One elastomer layer of the pad.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ElasticLayer {
    pub thickness_mm: f64,
    pub shear_modulus_kpa: f64,
    /// 0.5 = incompressible.
    pub poisson_ratio: f64,
}

impl ElasticLayer {
    fn mu(&self) -> f64 {
        self.shear_modulus_kpa * 1e-3
    }

    /// 1 / (lambda + 2 mu), mm^2 / N: the layer's compliance under confined compression (0 when incompressible).
    fn confined_compliance(&self) -> f64 {
        let nu = self.poisson_ratio;
        (1.0 - 2.0 * nu) / (2.0 * self.mu() * (1.0 - nu))
    }
}

/// The stack from the contact surface down to the rigid plate, where the pattern lies in it, and the frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LayeredPad {
    /// From the contact surface down; the last one is bonded to the rigid plate.
    pub layers: Vec<ElasticLayer>,
    /// Depth of the pattern below the contact surface.
    pub pattern_depth_mm: f64,
    /// Distance from the pattern's edge to the frame walls, mm (each side).
    pub border_margin_mm: f64,
    /// Largest spacing of the in-plane grid, mm.
    pub grid_step_mm: f64,
    /// Refractive index of the elastomer between the pattern and the plate (parallax and refraction).
    pub refractive_index: f64,
    /// The rigid plate the camera looks through.
    pub plate_thickness_mm: f64,
    pub plate_refractive_index: f64,
}

impl LayeredPad {
    /// The NUSense stack as the paper describes it, with moduli from the materials' data sheets: an outer
    /// Sorta-Clear 18 skin (Shore 18A, E about 0.6 MPa) over the pattern, 2.2 mm of very soft gel (Techsil RTV27905),
    /// and a transparent PDMS bonding layer on the Plexiglass plate. The skin's and bond's thicknesses are not
    /// published; 0.8 and 0.5 mm are what such pads are cast with. The gel's modulus is the one free number: chosen
    /// so that a 6 N press of a 5 mm sphere moves the pattern as far as the half-space model of [`crate::model::Material::real`]
    /// does (about 0.6 mm at the peak), which itself was fitted to the real pair.
    pub fn nusense() -> Self {
        Self {
            layers: vec![
                ElasticLayer {
                    thickness_mm: 0.8,
                    shear_modulus_kpa: 200.0,
                    poisson_ratio: 0.49,
                },
                ElasticLayer {
                    thickness_mm: 2.2,
                    shear_modulus_kpa: 24.0,
                    poisson_ratio: 0.499,
                },
                ElasticLayer {
                    thickness_mm: 0.5,
                    shear_modulus_kpa: 400.0,
                    poisson_ratio: 0.49,
                },
            ],
            pattern_depth_mm: 0.8,
            border_margin_mm: 4.0,
            grid_step_mm: 0.25,
            refractive_index: 1.41,
            // Plexiglass (PMMA).
            plate_thickness_mm: 3.0,
            plate_refractive_index: 1.49,
        }
    }

    pub fn thickness_mm(&self) -> f64 {
        self.layers.iter().map(|l| l.thickness_mm).sum()
    }

    /// The layer that carries the contact's shape (the softest: it sets how far a tip sinks in).
    pub fn softest(&self) -> Option<&ElasticLayer> {
        self.layers
            .iter()
            .min_by(|a, b| a.shear_modulus_kpa.total_cmp(&b.shear_modulus_kpa))
    }

    /// A description of what is wrong, if anything.
    pub fn problem(&self) -> Option<(&'static str, f64)> {
        if self.layers.is_empty() {
            return Some(("layers (at least one)", 0.0));
        }
        for layer in &self.layers {
            let checks = [
                (
                    "layers.thickness_mm (> 0)",
                    layer.thickness_mm,
                    layer.thickness_mm > 0.0,
                ),
                (
                    "layers.shear_modulus_kpa (> 0)",
                    layer.shear_modulus_kpa,
                    layer.shear_modulus_kpa > 0.0,
                ),
                (
                    "layers.poisson_ratio (0 ..= 0.5)",
                    layer.poisson_ratio,
                    (0.0..=0.5).contains(&layer.poisson_ratio),
                ),
            ];
            if let Some((what, value, _)) = checks.iter().find(|(_, v, ok)| !(v.is_finite() && *ok)) {
                return Some((what, *value));
            }
        }
        let h = self.thickness_mm();
        let checks = [
            (
                "pattern_depth_mm (inside the stack, > 0)",
                self.pattern_depth_mm,
                self.pattern_depth_mm > 0.0 && self.pattern_depth_mm < h,
            ),
            (
                "border_margin_mm (>= 0)",
                self.border_margin_mm,
                self.border_margin_mm >= 0.0,
            ),
            (
                "grid_step_mm (0.05 ..= 2)",
                self.grid_step_mm,
                (0.05..=2.0).contains(&self.grid_step_mm),
            ),
            (
                "refractive_index (>= 1)",
                self.refractive_index,
                self.refractive_index >= 1.0,
            ),
            (
                "plate_thickness_mm (>= 0)",
                self.plate_thickness_mm,
                self.plate_thickness_mm >= 0.0,
            ),
            (
                "plate_refractive_index (>= 1)",
                self.plate_refractive_index,
                self.plate_refractive_index >= 1.0,
            ),
        ];
        checks
            .iter()
            .find(|(_, v, ok)| !(v.is_finite() && *ok))
            .map(|(what, value, _)| (*what, *value))
    }
}

/// How the layer stack answers a surface traction of one wavevector k (magnitude `k`, direction k̂), at one depth.
/// With û the in-plane displacement split along k̂ (L) and across it (T), ŵ the displacement into the pad, q̂ the
/// tangential traction split the same way and p̂ the pressure into the pad (transforms with e^{-i k.x}):
///
/// û_L = uq q̂_L + i up p̂,   ŵ = -i wq q̂_L + wp p̂,   û_T = t q̂_T.   Units: mm per (N / mm^2).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Response {
    pub uq: f64,
    pub up: f64,
    pub wq: f64,
    pub wp: f64,
    pub t: f64,
}

/// Sub-layers are at most this many 1/k thick, so each one's propagator is well conditioned.
const MAX_K_DZ: f64 = 0.5;
/// Material more than this many 1/k below the depth of interest does not reach it (e^-40); the recursion starts
/// there as if on the rigid plate.
const DECAY_CUT: f64 = 20.0;
/// Below this k the state equations degenerate (k = 0 is solved apart, exactly).
const K_ZERO: f64 = 1e-9;

type M2 = [[f64; 2]; 2];
type M4 = [[f64; 4]; 4];

fn mul2(a: &M2, b: &M2) -> M2 {
    std::array::from_fn(|i| std::array::from_fn(|j| a[i][0] * b[0][j] + a[i][1] * b[1][j]))
}

fn add2(a: &M2, b: &M2) -> M2 {
    std::array::from_fn(|i| std::array::from_fn(|j| a[i][j] + b[i][j]))
}

fn inv2(a: &M2) -> M2 {
    let det = a[0][0] * a[1][1] - a[0][1] * a[1][0];
    [[a[1][1] / det, -a[0][1] / det], [-a[1][0] / det, a[0][0] / det]]
}

/// exp(m) by scaling and squaring of a Taylor series (the matrices here are small and their exponent's norm is at
/// most a few units, where this is accurate to rounding).
fn expm<const N: usize>(m: &[[f64; N]; N]) -> [[f64; N]; N] {
    let norm = (0..N)
        .map(|i| (0..N).map(|j| m[i][j].abs()).sum::<f64>())
        .fold(0.0, f64::max);
    let mut squarings = 0;
    let mut scale = 1.0;
    while norm * scale > 0.25 {
        scale *= 0.5;
        squarings += 1;
    }
    let a: [[f64; N]; N] = std::array::from_fn(|i| std::array::from_fn(|j| m[i][j] * scale));
    let identity: [[f64; N]; N] = std::array::from_fn(|i| std::array::from_fn(|j| f64::from(u8::from(i == j))));
    let mul = |x: &[[f64; N]; N], y: &[[f64; N]; N]| -> [[f64; N]; N] {
        std::array::from_fn(|i| std::array::from_fn(|j| (0..N).map(|k| x[i][k] * y[k][j]).sum()))
    };
    // 0.25^18 / 18! is far below rounding.
    let mut result = identity;
    let mut term = identity;
    for n in 1..=18 {
        term = mul(&term, &a);
        let inv = 1.0 / f64::from(n);
        for row in term.iter_mut() {
            for v in row.iter_mut() {
                *v *= inv;
            }
        }
        for i in 0..N {
            for j in 0..N {
                result[i][j] += term[i][j];
            }
        }
    }
    for _ in 0..squarings {
        result = mul(&result, &result);
    }
    result
}

/// One slice of the stack the recursion steps over: its thickness and material.
#[derive(Clone, Copy, Debug)]
struct Slice {
    thickness: f64,
    layer: usize,
    /// The depth of interest lies at this slice's top.
    observed_at_top: bool,
}

/// The state matrices k·A of one layer in balanced variables: displacements (U, w) and tractions divided by
/// mu_ref k (T̂, σ̂), where u_L = i U and σ_Lz = i T; and the transverse pair (u_T, τ̂_T).
fn state_matrices(layer: &ElasticLayer, mu_ref: f64) -> (M4, M2) {
    let nu = layer.poisson_ratio;
    let r = mu_ref / layer.mu();
    let beta = nu / (1.0 - nu);
    let g = r * (1.0 - 2.0 * nu) / (2.0 * (1.0 - nu));
    let c = 2.0 / ((1.0 - nu) * r);
    (
        [
            [0.0, -1.0, r, 0.0],
            [beta, 0.0, 0.0, g],
            [c, 0.0, 0.0, -beta],
            [0.0, 0.0, 1.0, 0.0],
        ],
        [[0.0, r], [1.0 / r, 0.0]],
    )
}

/// The response at `depth_mm` below the surface of the stack `layers` (bonded to a rigid plate) to a surface
/// traction of wavenumber `k` (1/mm).
pub fn response(layers: &[ElasticLayer], depth_mm: f64, k: f64) -> Response {
    let h: f64 = layers.iter().map(|l| l.thickness_mm).sum();
    let depth = depth_mm.clamp(0.0, h);
    if k < K_ZERO {
        return response_at_rest(layers, depth);
    }
    if k * depth > 2.0 * DECAY_CUT {
        return Response::default();
    }
    let mu_ref = layers[0].mu();
    let start = h.min(depth + DECAY_CUT / k);

    // Slices from `start` up to the surface, bottom first, split at the depth of interest.
    let mut slices = Vec::new();
    let mut bottom = h;
    for (index, layer) in layers.iter().enumerate().rev() {
        let top = bottom - layer.thickness_mm;
        let (lo, hi) = (top.max(0.0), bottom.min(start));
        bottom = top;
        if hi <= lo {
            continue;
        }
        let mut pieces: Vec<(f64, f64)> = Vec::new();
        if depth > lo && depth < hi {
            pieces.push((depth, hi));
            pieces.push((lo, depth));
        } else {
            pieces.push((lo, hi));
        }
        for (piece_top, piece_bottom) in pieces {
            let n = ((piece_bottom - piece_top) * k / MAX_K_DZ).ceil().max(1.0) as usize;
            let thickness = (piece_bottom - piece_top) / n as f64;
            for i in 0..n {
                slices.push(Slice {
                    thickness,
                    layer: index,
                    observed_at_top: i == n - 1 && (piece_top - depth).abs() < 1e-12,
                });
            }
        }
    }

    let mut cache: Vec<(usize, f64, M4, M2)> = Vec::new();
    let mut propagators = |slice: &Slice| -> (M4, M2) {
        if let Some((_, _, p, s)) = cache
            .iter()
            .find(|(l, t, _, _)| *l == slice.layer && *t == slice.thickness)
        {
            return (*p, *s);
        }
        let (a, a_sh) = state_matrices(&layers[slice.layer], mu_ref);
        // Upward across the slice: s(z - dz) = exp(-k dz A) s(z).
        let f = -k * slice.thickness;
        let p = expm(&a.map(|row| row.map(|v| v * f)));
        let s = expm(&a_sh.map(|row| row.map(|v| v * f)));
        cache.push((slice.layer, slice.thickness, p, s));
        (p, s)
    };

    // Bottom up: displacement = C traction at each level, C = 0 where the material is held still.
    let mut c: M2 = [[0.0; 2]; 2];
    let mut c_sh = 0.0;
    let mut steps: Vec<(M2, f64)> = Vec::with_capacity(slices.len());
    let mut observed: Option<(usize, M2, f64)> = (depth >= start).then_some((0, c, c_sh));
    for slice in &slices {
        let (p, s) = propagators(slice);
        let block = |r: usize, col: usize| -> M2 { [[p[r][col], p[r][col + 1]], [p[r + 1][col], p[r + 1][col + 1]]] };
        let (p11, p12, p21, p22) = (block(0, 0), block(0, 2), block(2, 0), block(2, 2));
        let m = inv2(&add2(&mul2(&p21, &c), &p22));
        c = mul2(&add2(&mul2(&p11, &c), &p12), &m);
        let m_sh = 1.0 / (s[1][0] * c_sh + s[1][1]);
        c_sh = (s[0][0] * c_sh + s[0][1]) * m_sh;
        steps.push((m, m_sh));
        if slice.observed_at_top {
            observed = Some((steps.len(), c, c_sh));
        }
    }
    let (level, c_obs, c_sh_obs) = observed.unwrap_or((steps.len(), c, c_sh));
    // Top down to the depth of interest: the surface traction's share at each level.
    let mut traction: M2 = [[1.0, 0.0], [0.0, 1.0]];
    let mut traction_sh = 1.0;
    for (m, m_sh) in steps[level..].iter().rev() {
        traction = mul2(m, &traction);
        traction_sh *= m_sh;
    }
    let g = mul2(&c_obs, &traction);
    let g_sh = c_sh_obs * traction_sh;
    // Surface tractions in balanced variables: T̂ = i q_L / (mu_ref k), σ̂ = -p / (mu_ref k), τ̂ = -q_T / (mu_ref k).
    let unit = -1.0 / (mu_ref * k);
    Response {
        uq: g[0][0] * unit,
        up: g[0][1] * unit,
        wq: g[1][0] * unit,
        wp: g[1][1] * unit,
        t: g_sh * unit,
    }
}

/// k = 0: uniform traction. Shear is carried down to the plate (simple shear), pressure compresses the layers
/// confined (nothing moves sideways in a uniform state).
fn response_at_rest(layers: &[ElasticLayer], depth: f64) -> Response {
    let (mut shear, mut confined) = (0.0, 0.0);
    let mut top = 0.0;
    for layer in layers {
        let bottom = top + layer.thickness_mm;
        let below = (bottom - top.max(depth)).max(0.0);
        shear += below / layer.mu();
        confined += below * layer.confined_compliance();
        top = bottom;
    }
    Response {
        uq: shear,
        up: 0.0,
        wq: 0.0,
        wp: confined,
        t: shear,
    }
}

/// The response tabulated in k, for the FFT grid (the functions are smooth in k; cubic interpolation).
#[derive(Clone, Debug)]
struct ResponseTable {
    dk: f64,
    values: Vec<Response>,
}

impl ResponseTable {
    fn new(layers: &[ElasticLayer], depth: f64, k_max: f64, dk: f64) -> Self {
        let n = (k_max / dk).ceil() as usize + 3;
        let values = (0..n).map(|i| response(layers, depth, i as f64 * dk)).collect();
        Self { dk, values }
    }

    fn at(&self, k: f64) -> Response {
        let x = k / self.dk;
        let i = (x.floor() as usize).min(self.values.len() - 3);
        let t = x - i as f64;
        let at = |j: usize| self.values[j];
        let (p1, p2, p3) = (at(i), at(i + 1), at(i + 2));
        // Before the first node: uq, wp and t are even in k, up and wq odd (they change sign with the direction k̂).
        let p0 = if i == 0 {
            Response {
                uq: p2.uq,
                up: -p2.up,
                wq: -p2.wq,
                wp: p2.wp,
                t: p2.t,
            }
        } else {
            at(i - 1)
        };
        // Cubic Lagrange through the four nodes around k.
        let w = [
            -t * (t - 1.0) * (t - 2.0) / 6.0,
            (t + 1.0) * (t - 1.0) * (t - 2.0) / 2.0,
            -(t + 1.0) * t * (t - 2.0) / 2.0,
            (t + 1.0) * t * (t - 1.0) / 6.0,
        ];
        let mix = |f: fn(&Response) -> f64| w[0] * f(&p0) + w[1] * f(&p1) + w[2] * f(&p2) + w[3] * f(&p3);
        Response {
            uq: mix(|r| r.uq),
            up: mix(|r| r.up),
            wq: mix(|r| r.wq),
            wp: mix(|r| r.wp),
            t: mix(|r| r.t),
        }
    }
}

/// Displacements of one level of the pad on a regular grid over the pad inside its frame, mm.
#[derive(Clone, Debug)]
pub struct LayerField {
    /// Position of node (0, 0): the frame's corner (-A, -B).
    pub origin_mm: [f64; 2],
    pub step_mm: [f64; 2],
    pub nx: usize,
    pub ny: usize,
    /// Row-major, x fastest: (u_x, u_y, w into the pad).
    pub values: Vec<[f64; 3]>,
}

impl LayerField {
    /// Bilinear interpolation; zero outside the frame.
    pub fn at(&self, p: [f64; 2]) -> [f64; 3] {
        let fx = (p[0] - self.origin_mm[0]) / self.step_mm[0];
        let fy = (p[1] - self.origin_mm[1]) / self.step_mm[1];
        if !(fx >= 0.0 && fy >= 0.0) {
            return [0.0; 3];
        }
        let (i, j) = (fx as usize, fy as usize);
        if i + 1 >= self.nx || j + 1 >= self.ny {
            return [0.0; 3];
        }
        let (tx, ty) = (fx - i as f64, fy - j as f64);
        let row = j * self.nx + i;
        let (a, b, c, d) = (
            self.values[row],
            self.values[row + 1],
            self.values[row + self.nx],
            self.values[row + self.nx + 1],
        );
        std::array::from_fn(|k| {
            let top = a[k] + (b[k] - a[k]) * tx;
            let bottom = c[k] + (d[k] - c[k]) * tx;
            top + (bottom - top) * ty
        })
    }

    /// The node nearest to `p` and its value.
    pub fn node(&self, i: usize, j: usize) -> ([f64; 2], [f64; 3]) {
        (
            [
                self.origin_mm[0] + i as f64 * self.step_mm[0],
                self.origin_mm[1] + j as f64 * self.step_mm[1],
            ],
            self.values[j * self.nx + i],
        )
    }
}

/// The FFT solution of one pad: grid, plans and the stack's response, built once per sensor.
#[derive(Clone)]
pub struct SpectralPad {
    /// Half-sizes of the pad inside its frame (pattern half-size plus the border margin).
    half_mm: [f64; 2],
    /// Grid of the mirror-extended period (4 A x 4 B).
    n: [usize; 2],
    step: [f64; 2],
    table: ResponseTable,
    forward: [Arc<dyn Fft<f64>>; 2],
    inverse: [Arc<dyn Fft<f64>>; 2],
}

impl std::fmt::Debug for SpectralPad {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SpectralPad")
            .field("half_mm", &self.half_mm)
            .field("n", &self.n)
            .field("step", &self.step)
            .finish_non_exhaustive()
    }
}

/// Grid size >= `n` with only the factors 2, 3 and 5 (fast FFTs), a multiple of 4 so that the pad's centre and its
/// walls fall on nodes.
fn fft_size(n: usize) -> usize {
    let mut m = n.max(2);
    loop {
        let mut r = m;
        for p in [2, 3, 5] {
            while r.is_multiple_of(p) {
                r /= p;
            }
        }
        if r == 1 && m.is_multiple_of(4) {
            return m;
        }
        m += 1;
    }
}

impl SpectralPad {
    /// `pattern_half_mm`: half the pattern's width and height; the frame lies `pad.border_margin_mm` beyond.
    pub fn new(pad: &LayeredPad, pattern_half_mm: [f64; 2], depth_mm: f64) -> Self {
        let half_mm = pattern_half_mm.map(|h| h + pad.border_margin_mm);
        let n = half_mm.map(|a| fft_size((4.0 * a / pad.grid_step_mm).ceil() as usize));
        let step = [4.0 * half_mm[0] / n[0] as f64, 4.0 * half_mm[1] / n[1] as f64];
        let k_max = PI * (1.0 / (step[0] * step[0]) + 1.0 / (step[1] * step[1])).sqrt();
        // An eighth of the grid's wavenumber step: a stiff skin spreads loads over several mm, and the response then
        // turns over at small k.
        let dk = 2.0 * PI / (4.0 * half_mm[0].max(half_mm[1])) / 8.0;
        let table = ResponseTable::new(&pad.layers, depth_mm, k_max, dk);
        let mut planner = FftPlanner::new();
        let forward = [planner.plan_fft_forward(n[0]), planner.plan_fft_forward(n[1])];
        let inverse = [planner.plan_fft_inverse(n[0]), planner.plan_fft_inverse(n[1])];
        Self {
            half_mm,
            n,
            step,
            table,
            forward,
            inverse,
        }
    }

    pub fn half_mm(&self) -> [f64; 2] {
        self.half_mm
    }

    pub fn step_mm(&self) -> [f64; 2] {
        self.step
    }

    /// Lays point forces on the grid (bilinear shares, so force and first moment are kept exactly) with their mirror
    /// images across the frame walls; returns the three traction components (x, y, into the pad) in N / mm^2.
    pub fn tractions(&self, forces: &[PointForce]) -> [Vec<f64>; 3] {
        let [nx, ny] = self.n;
        let mut grid = [vec![0.0; nx * ny], vec![0.0; nx * ny], vec![0.0; nx * ny]];
        let [a, b] = self.half_mm;
        let cell = self.step[0] * self.step[1];
        for f in forces {
            let images = [
                ([f.at_mm[0], f.at_mm[1]], [1.0, 1.0]),
                ([2.0 * a - f.at_mm[0], f.at_mm[1]], [-1.0, 1.0]),
                ([f.at_mm[0], 2.0 * b - f.at_mm[1]], [1.0, -1.0]),
                ([2.0 * a - f.at_mm[0], 2.0 * b - f.at_mm[1]], [-1.0, -1.0]),
            ];
            for (at, sign) in images {
                let fx = (at[0] + a) / self.step[0];
                let fy = (at[1] + b) / self.step[1];
                let (i0, j0) = (fx.floor(), fy.floor());
                let (tx, ty) = (fx - i0, fy - j0);
                for (di, wx) in [(0, 1.0 - tx), (1, tx)] {
                    for (dj, wy) in [(0, 1.0 - ty), (1, ty)] {
                        let i = (i0 as i64 + di).rem_euclid(nx as i64) as usize;
                        let j = (j0 as i64 + dj).rem_euclid(ny as i64) as usize;
                        let w = wx * wy / cell;
                        let idx = j * nx + i;
                        grid[0][idx] += w * sign[0] * f.force_n[0];
                        grid[1][idx] += w * sign[1] * f.force_n[1];
                        grid[2][idx] += w * f.force_n[2];
                    }
                }
            }
        }
        grid
    }

    fn fft2(&self, data: &mut [Complex64], inverse: bool) {
        let [nx, ny] = self.n;
        let (row_plan, col_plan) = if inverse {
            (&self.inverse[0], &self.inverse[1])
        } else {
            (&self.forward[0], &self.forward[1])
        };
        row_plan.process(data);
        let mut column = vec![Complex64::default(); ny];
        for i in 0..nx {
            for j in 0..ny {
                column[j] = data[j * nx + i];
            }
            col_plan.process(&mut column);
            for j in 0..ny {
                data[j * nx + i] = column[j];
            }
        }
    }

    /// Displacements at the solved depth under the point forces, on the grid over the pad inside its frame.
    pub fn solve(&self, forces: &[PointForce]) -> LayerField {
        let [nx, ny] = self.n;
        let tractions = self.tractions(forces);
        let mut spectra: Vec<Vec<Complex64>> = tractions
            .iter()
            .map(|t| {
                let mut c: Vec<Complex64> = t.iter().map(|&v| Complex64::new(v, 0.0)).collect();
                self.fft2(&mut c, false);
                c
            })
            .collect();
        let period = [nx as f64 * self.step[0], ny as f64 * self.step[1]];
        let i = Complex64::new(0.0, 1.0);
        for j in 0..ny {
            let nj = if j <= ny / 2 { j as f64 } else { j as f64 - ny as f64 };
            let ky = 2.0 * PI * nj / period[1];
            for m in 0..nx {
                let nm = if m <= nx / 2 { m as f64 } else { m as f64 - nx as f64 };
                let kx = 2.0 * PI * nm / period[0];
                let k = kx.hypot(ky);
                let idx = j * nx + m;
                let (qx, qy, p) = (spectra[0][idx], spectra[1][idx], spectra[2][idx]);
                let r = self.table.at(k);
                // On a Nyquist line the transform of a real field has no sign for k: the odd couplings drop there.
                let nyquist = (nx % 2 == 0 && m == nx / 2) || (ny % 2 == 0 && j == ny / 2);
                let (ux, uy, w) = if k < K_ZERO {
                    (qx * r.uq, qy * r.uq, p * r.wp)
                } else {
                    let (cx, cy) = (kx / k, ky / k);
                    let q_l = qx * cx + qy * cy;
                    let q_t = -qx * cy + qy * cx;
                    let odd = if nyquist { 0.0 } else { 1.0 };
                    let u_l = q_l * r.uq + i * p * (r.up * odd);
                    let u_t = q_t * r.t;
                    let w = -i * q_l * (r.wq * odd) + p * r.wp;
                    (u_l * cx - u_t * cy, u_l * cy + u_t * cx, w)
                };
                spectra[0][idx] = ux;
                spectra[1][idx] = uy;
                spectra[2][idx] = w;
            }
        }
        for s in &mut spectra {
            self.fft2(s, true);
        }
        let norm = 1.0 / (nx * ny) as f64;
        // The pad inside its frame is the first quarter of the period, nodes 0 ..= n/2.
        let (mx, my) = (nx / 2 + 1, ny / 2 + 1);
        let mut values = Vec::with_capacity(mx * my);
        for j in 0..my {
            for m in 0..mx {
                let idx = j * nx + m;
                values.push([
                    spectra[0][idx].re * norm,
                    spectra[1][idx].re * norm,
                    spectra[2][idx].re * norm,
                ]);
            }
        }
        LayerField {
            origin_mm: [-self.half_mm[0], -self.half_mm[1]],
            step_mm: self.step,
            nx: mx,
            ny: my,
            values,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mechanics::HalfSpace;

    fn layer(thickness_mm: f64, shear_modulus_kpa: f64, poisson_ratio: f64) -> ElasticLayer {
        ElasticLayer {
            thickness_mm,
            shear_modulus_kpa,
            poisson_ratio,
        }
    }

    fn close(found: f64, expected: f64, scale: f64, tolerance: f64, what: &str) {
        assert!(
            (found - expected).abs() <= tolerance * scale,
            "{what}: {found:e} vs {expected:e} (scale {scale:e})"
        );
    }

    #[test]
    fn a_thick_layer_is_the_half_space() {
        // Fourier transforms of Boussinesq's and Cerruti's solutions at depth z (Johnson, Contact Mechanics, 3.2),
        // with e = exp(-k z) / (2 mu k): uq = (2 (1 - nu) - k z) e, up = (1 - 2 nu - k z) e, wq = (1 - 2 nu + k z) e,
        // wp = (2 (1 - nu) + k z) e, t = 2 e.
        for nu in [0.5, 0.3, 0.0] {
            let mu = 0.048;
            let stack = [layer(2000.0, mu * 1e3, nu)];
            for z in [0.0, 0.8, 2.8] {
                for k in [0.05, 0.4, 1.5, 6.0] {
                    let r = response(&stack, z, k);
                    let e = (-k * z).exp() / (2.0 * mu * k);
                    let what = |name: &str| format!("nu {nu} z {z} k {k}: {name}");
                    close(r.uq, (2.0 * (1.0 - nu) - k * z) * e, e, 1e-9, &what("uq"));
                    close(r.up, (1.0 - 2.0 * nu - k * z) * e, e, 1e-9, &what("up"));
                    close(r.wq, (1.0 - 2.0 * nu + k * z) * e, e, 1e-9, &what("wq"));
                    close(r.wp, (2.0 * (1.0 - nu) + k * z) * e, e, 1e-9, &what("wp"));
                    close(r.t, 2.0 * e, e, 1e-9, &what("t"));
                }
            }
        }
    }

    #[test]
    fn a_thin_incompressible_layer_is_the_lubrication_solution() {
        // Thin-film flow of an incompressible layer (free top, bonded base), height zeta above the base:
        // u = grad(p) (zeta^2 / 2 - h zeta) / mu and w = k^2 p (h zeta^2 - zeta^3 / 3) / (2 mu); in shear,
        // u = q zeta / mu. Corrections are O((k h)^2) = 1e-6 here.
        let (h, mu, k) = (1.0, 0.03, 1e-3);
        let stack = [layer(h, mu * 1e3, 0.5)];
        for depth in [0.0, 0.3, 0.7] {
            let zeta: f64 = h - depth;
            let r = response(&stack, depth, k);
            let up = k * (zeta * zeta / 2.0 - h * zeta) / mu;
            let wp = k * k * (h * zeta * zeta - zeta.powi(3) / 3.0) / (2.0 * mu);
            close(r.up, up, up.abs(), 1e-5, &format!("depth {depth}: up"));
            close(r.wp, wp, wp.abs(), 1e-5, &format!("depth {depth}: wp"));
            close(r.uq, zeta / mu, zeta / mu, 1e-5, &format!("depth {depth}: uq"));
            close(r.t, zeta / mu, zeta / mu, 1e-5, &format!("depth {depth}: t"));
        }
    }

    fn three_layers() -> Vec<ElasticLayer> {
        LayeredPad::nusense().layers
    }

    #[test]
    fn uniform_traction_is_simple_shear_and_confined_compression() {
        let stack = [layer(0.8, 200.0, 0.49), layer(2.2, 24.0, 0.3), layer(0.5, 400.0, 0.0)];
        // Below 0.8 mm: the gel and the bond. Simple shear: sum of t / mu; confined: sum of t / (lambda + 2 mu).
        let shear = 2.2 / 0.024 + 0.5 / 0.4;
        let confined = 2.2 * 0.4 / (2.0 * 0.024 * 0.7) + 0.5 * 1.0 / (2.0 * 0.4);
        let r = response(&stack, 0.8, 0.0);
        assert_eq!((r.up, r.wq), (0.0, 0.0));
        close(r.uq, shear, shear, 1e-14, "uq");
        close(r.t, shear, shear, 1e-14, "t");
        close(r.wp, confined, confined, 1e-14, "wp");
        // And the k > 0 solution tends to it.
        let near = response(&stack, 0.8, 1e-6);
        close(near.uq, shear, shear, 1e-6, "uq as k -> 0");
        close(near.t, shear, shear, 1e-6, "t as k -> 0");
        close(near.wp, confined, confined, 1e-6, "wp as k -> 0");
    }

    #[test]
    fn the_surface_compliance_is_reciprocal_and_positive() {
        // Betti: the surface's compliance matrix [[uq, i up], [-i wq, wp]] is Hermitian, and it stores energy.
        let stack = three_layers();
        for k in [1e-3, 0.01, 0.1, 0.5, 1.0, 3.0, 10.0] {
            let r = response(&stack, 0.0, k);
            let scale = r.uq.abs().max(r.wp.abs());
            close(r.up, r.wq, scale, 1e-10, &format!("k {k}: up = wq"));
            assert!(r.uq > 0.0 && r.wp > 0.0 && r.t > 0.0, "k {k}: {r:?}");
            assert!(r.uq * r.wp > r.up * r.wq, "k {k}: {r:?}");
        }
    }

    #[test]
    fn the_table_interpolates_the_response() {
        let stack = three_layers();
        let table = ResponseTable::new(&stack, 0.8, 15.0, 2.0 * PI / 122.0 / 8.0);
        let peak = response(&stack, 0.8, 0.0).uq;
        for k in [0.0, 0.004, 0.05, 0.33, 1.7, 6.1, 12.9] {
            let (a, b) = (table.at(k), response(&stack, 0.8, k));
            for (x, y) in [(a.uq, b.uq), (a.up, b.up), (a.wq, b.wq), (a.wp, b.wp), (a.t, b.t)] {
                close(x, y, peak, 1e-5, &format!("k {k}"));
            }
        }
    }

    fn pad(margin: f64, step: f64, layers: Vec<ElasticLayer>, depth: f64) -> (LayeredPad, SpectralPad) {
        let pad = LayeredPad {
            layers,
            pattern_depth_mm: depth,
            border_margin_mm: margin,
            grid_step_mm: step,
            ..LayeredPad::nusense()
        };
        let spectral = SpectralPad::new(&pad, [26.5, 20.0], depth);
        (pad, spectral)
    }

    #[test]
    fn the_laid_down_load_carries_the_requested_force_and_moment() {
        let (_, spectral) = pad(4.0, 0.25, three_layers(), 0.8);
        let mut contact = crate::Contact::sphere(5.0, [3.3, -2.1], 4.0);
        contact.tangential_force_n = [0.7, -0.4];
        contact.torsion_nmm = 6.0;
        let load = crate::mechanics::discretise(&contact, &crate::model::Material::real());
        let grid = spectral.tractions(&load.fine);
        let [a, b] = spectral.half_mm();
        let [dx, dy] = spectral.step_mm();
        let (mut force, mut torque) = ([0.0; 3], 0.0);
        for j in 0..spectral.n[1] {
            for i in 0..spectral.n[0] {
                let (x, y) = (-a + i as f64 * dx, -b + j as f64 * dy);
                // The pad itself (the images lie beyond its walls).
                if x > a || y > b {
                    continue;
                }
                let idx = j * spectral.n[0] + i;
                let f = [grid[0][idx] * dx * dy, grid[1][idx] * dx * dy, grid[2][idx] * dx * dy];
                for k in 0..3 {
                    force[k] += f[k];
                }
                torque += (x - 3.3) * f[1] - (y + 2.1) * f[0];
            }
        }
        close(force[0], 0.7, 1.0, 1e-12, "fx");
        close(force[1], -0.4, 1.0, 1e-12, "fy");
        close(force[2], 4.0, 1.0, 1e-12, "fz");
        close(torque, 6.0, 1.0, 1e-11, "torque about the contact centre");
    }

    fn symmetric_forces(force: impl Fn([f64; 2]) -> [f64; 3]) -> Vec<PointForce> {
        let mut forces = Vec::new();
        for r in [0.5, 1.2, 2.0] {
            for k in 0..8 {
                let angle = f64::from(k) * PI / 4.0 + 0.3 * f64::from(k % 2);
                for at in [[r * angle.cos(), r * angle.sin()], [-r * angle.cos(), r * angle.sin()]] {
                    for at in [at, [at[0], -at[1]]] {
                        forces.push(PointForce {
                            at_mm: at,
                            force_n: force(at),
                        });
                    }
                }
            }
        }
        forces
    }

    #[test]
    fn a_centred_press_is_mirror_symmetric_and_a_twist_turns_without_pressing() {
        let (_, spectral) = pad(4.0, 0.5, three_layers(), 0.8);
        let press = spectral.solve(&symmetric_forces(|_| [0.0, 0.0, 0.05]));
        let twist = spectral.solve(&symmetric_forces(|p| [-0.05 * p[1], 0.05 * p[0], 0.0]));
        let peak = |f: &LayerField| f.values.iter().map(|v| v[0].hypot(v[1])).fold(0.0, f64::max);
        let (press_peak, twist_peak) = (peak(&press), peak(&twist));
        assert!(press_peak > 1e-3 && twist_peak > 1e-3, "{press_peak} {twist_peak}");
        let (nx, ny) = (press.nx, press.ny);
        for j in 0..ny {
            for i in 0..nx {
                let (at, u) = press.node(i, j);
                let (_, mirrored_x) = press.node(nx - 1 - i, j);
                let (_, mirrored_y) = press.node(i, ny - 1 - j);
                let tol = 1e-12 * press_peak;
                assert!(
                    (u[0] + mirrored_x[0]).abs() < tol && (u[1] - mirrored_x[1]).abs() < tol,
                    "{at:?}"
                );
                assert!(
                    (u[0] - mirrored_y[0]).abs() < tol && (u[1] + mirrored_y[1]).abs() < tol,
                    "{at:?}"
                );
                assert!(
                    (u[2] - mirrored_x[2]).abs() < tol && (u[2] - mirrored_y[2]).abs() < tol,
                    "{at:?}"
                );
                // Outward everywhere on the axes.
                if j == ny / 2 && i > nx / 2 {
                    assert!(u[0] > 0.0 && u[1].abs() < tol, "{at:?} {u:?}");
                }
                let (_, v) = twist.node(i, j);
                let tol = 1e-12 * twist_peak;
                // A twist moves the axes' points across them only, and not into the pad (mirroring the pad about an
                // axis reverses the twist).
                if j == ny / 2 {
                    assert!(v[0].abs() < tol, "{at:?} {v:?}");
                }
                if i == nx / 2 {
                    assert!(v[1].abs() < tol, "{at:?} {v:?}");
                }
                if i == nx / 2 || j == ny / 2 {
                    assert!(v[2].abs() < tol, "{at:?} {v:?}");
                }
            }
        }
        // At the frame walls nothing moves through them.
        for j in 0..ny {
            assert!(press.node(0, j).1[0].abs() < 1e-12 * press_peak);
            assert!(press.node(nx - 1, j).1[0].abs() < 1e-12 * press_peak);
        }
    }

    #[test]
    fn a_thick_layer_in_a_wide_frame_moves_like_the_half_space_near_the_load() {
        // Real space: 300 mm of incompressible gel in a frame 60 mm beyond the pattern, the pattern 2.8 mm deep,
        // against Johnson's point-force solutions summed over the same forces. Compared where the half-space field
        // decays like 1 / r^2 (in-plane under pressure, vertical under shear), so that the distant base and walls
        // change it by much less than the tolerance (measured: 0.8 % at 3 mm from the load, where the 0.5 mm grid
        // shows, 0.2 % beyond; with only 60 mm of gel the base still pulls 2 % at 6 mm).
        let mu_kpa = 48.0;
        let (_, spectral) = pad(60.0, 0.5, vec![layer(300.0, mu_kpa, 0.5)], 2.8);
        let forces: Vec<PointForce> = symmetric_forces(|_| [0.01, 0.0, 0.05]);
        let half = HalfSpace {
            shear_modulus: mu_kpa * 1e-3,
            poisson_ratio: 0.5,
        };
        let normal_only: Vec<PointForce> = forces
            .iter()
            .map(|f| PointForce {
                at_mm: f.at_mm,
                force_n: [0.0, 0.0, f.force_n[2]],
            })
            .collect();
        let shear_only: Vec<PointForce> = forces
            .iter()
            .map(|f| PointForce {
                at_mm: f.at_mm,
                force_n: [f.force_n[0], 0.0, 0.0],
            })
            .collect();
        let (pressed, sheared) = (spectral.solve(&normal_only), spectral.solve(&shear_only));
        for (r, angle) in [(3.0, 0.2), (4.5, 1.3), (6.0, 2.6), (8.0, -0.9)] {
            let p = [r * f64::cos(angle), r * f64::sin(angle)];
            let sum = |fs: &[PointForce]| {
                fs.iter().fold([0.0; 3], |acc, f| {
                    let u = half.point_force_displacement(f.force_n, [p[0] - f.at_mm[0], p[1] - f.at_mm[1]], 2.8);
                    [acc[0] + u[0], acc[1] + u[1], acc[2] + u[2]]
                })
            };
            let (a, b) = (pressed.at(p), sum(&normal_only));
            let scale = b[0].hypot(b[1]);
            assert!(
                (a[0] - b[0]).hypot(a[1] - b[1]) < 0.015 * scale,
                "press at {p:?}: {a:?} vs {b:?}"
            );
            let (a, b) = (sheared.at(p), sum(&shear_only));
            println!("r {r} mm: shear w {:.5} vs {:.5} (half-space)", a[2], b[2]);
            assert!(
                (a[2] - b[2]).abs() < 0.015 * b[2].abs(),
                "shear at {p:?}: {a:?} vs {b:?}"
            );
        }
    }
}
