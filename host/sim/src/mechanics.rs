//! Contact mechanics of the gel: a linear elastic half-space loaded on its surface, observed at the colour
//! layer's depth.
//!
//! Each contact's traction is discretised into point forces by quadrature over its contact area (Hertz for the
//! sphere, the flat-punch pressure for the cylinder, a half-elliptic strip for the edge; tangential force and
//! torsion ride on the same weights), and displacements are superposed from the Boussinesq (normal) and Cerruti
//! (tangential) point-force solutions. Points far from a contact see a coarser grouping of its forces, which
//! keeps a frame's mesh cheap without changing the near field.

use crate::model::Material;
use crate::scene::{Contact, Indenter};

/// A surface point force: `force_n` = (x, y tangential, z normal pressing into the gel).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointForce {
    pub at_mm: [f64; 2],
    pub force_n: [f64; 3],
}

/// An isotropic, linear elastic half-space (z into the material).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HalfSpace {
    /// N / mm^2.
    pub shear_modulus: f64,
    pub poisson_ratio: f64,
}

impl HalfSpace {
    pub fn new(material: &Material) -> Self {
        Self {
            shear_modulus: material.shear_modulus_n_per_mm2(),
            poisson_ratio: material.poisson_ratio,
        }
    }

    /// The plane-strain contact modulus E* = E / (1 - nu^2) = 2 G / (1 - nu).
    pub fn contact_modulus(&self) -> f64 {
        2.0 * self.shear_modulus / (1.0 - self.poisson_ratio)
    }

    /// Displacement (mm; x, y in plane, z into the material) at `offset` in plane from a point force and `depth`
    /// below the surface (Johnson, Contact Mechanics, eqs. 3.22 and 3.24: Boussinesq and Cerruti). `depth` must
    /// be > 0 (the solutions are singular under the force).
    pub fn point_force_displacement(&self, force_n: [f64; 3], offset: [f64; 2], depth: f64) -> [f64; 3] {
        let [x, y] = offset;
        let z = depth;
        let rho2 = x * x + y * y + z * z;
        let rho = rho2.sqrt();
        let inv_rho = 1.0 / rho;
        let inv_rho3 = inv_rho / rho2;
        let c = 1.0 - 2.0 * self.poisson_ratio;
        // The compressibility terms vanish for the default nu = 0.5; skipping their division is worth it in a mesh.
        let inv_rz = if c == 0.0 { 0.0 } else { 1.0 / (rho + z) };
        let k = 1.0 / (4.0 * std::f64::consts::PI * self.shear_modulus);
        let [qx, qy, p] = force_n;

        // Boussinesq: normal force p.
        let radial = z * inv_rho3 - c * inv_rho * inv_rz;
        let mut u = [
            p * x * radial,
            p * y * radial,
            p * (z * z * inv_rho3 + 2.0 * (1.0 - self.poisson_ratio) * inv_rho),
        ];

        // Cerruti: tangential force (qx, qy); the y-force solution is the x-force one with x and y swapped.
        let cross = inv_rho3 - c * inv_rho * inv_rz * inv_rz;
        let diagonal = inv_rho + c * inv_rz;
        let dot = qx * x + qy * y;
        u[0] += qx * diagonal + x * dot * cross;
        u[1] += qy * diagonal + y * dot * cross;
        u[2] += dot * (z * inv_rho3 + c * inv_rho * inv_rz);
        u.map(|v| v * k)
    }
}

/// How many quadrature points a contact gets: spacing about half the layer depth, since the kernel at that depth
/// varies on the scale of the depth.
fn points_across(extent_mm: f64, depth_mm: f64, min: usize, max: usize) -> usize {
    let n = (extent_mm / (0.5 * depth_mm)).ceil();
    if n.is_finite() {
        (n as usize).clamp(min, max)
    } else {
        max
    }
}

/// One contact's traction, as point forces.
#[derive(Clone, Debug, PartialEq)]
pub struct ContactLoad {
    pub centre_mm: [f64; 2],
    /// Radius of a circle about the centre that holds every point force.
    pub extent_mm: f64,
    /// Radius of the contact area (sphere: Hertz radius; punch: its radius; edge: half its width).
    pub contact_radius_mm: f64,
    /// The full quadrature.
    pub fine: Vec<PointForce>,
    /// The same forces summed over cells about 1.5 depths wide (force-weighted centroids): exact total force and
    /// first moment, used beyond [`ContactLoad::near_distance_mm`].
    pub coarse: Vec<PointForce>,
    pub near_distance_mm: f64,
    /// Summed over cells as wide as the whole contact, used beyond [`ContactLoad::far_distance_mm`].
    pub far: Vec<PointForce>,
    pub far_distance_mm: f64,
}

/// Hertz contact radius of a rigid sphere of radius `radius_mm` pressed with `force_n`; capped at the sphere's
/// radius, where the small-contact theory has long stopped holding anyway.
pub fn hertz_radius_mm(half_space: &HalfSpace, radius_mm: f64, force_n: f64) -> f64 {
    let a = (3.0 * force_n * radius_mm / (4.0 * half_space.contact_modulus())).cbrt();
    a.min(radius_mm)
}

/// Discretises a (validated) contact. A contact with no load at all yields no forces.
pub fn discretise(contact: &Contact, material: &Material) -> ContactLoad {
    let half_space = HalfSpace::new(material);
    let depth = material.layer_depth_mm;
    let centre = contact.position_mm;
    let loaded = contact.normal_force_n > 0.0
        || contact.tangential_force_n.iter().any(|f| *f != 0.0)
        || contact.torsion_nmm != 0.0;
    // The shape of the traction follows the normal pressure; a contact with (almost) no normal force still needs
    // a footprint to carry its tangential load, so it gets the one of a light touch.
    let shape_force = contact.normal_force_n.max(0.05);

    let (weighted, contact_radius_mm) = match contact.indenter {
        Indenter::Sphere { radius_mm } => {
            let a = hertz_radius_mm(&half_space, radius_mm, shape_force);
            (round_footprint(a, depth, true), a)
        }
        Indenter::FlatPunch { radius_mm } => (round_footprint(radius_mm, depth, false), radius_mm),
        Indenter::Edge {
            length_mm,
            width_mm,
            angle_deg,
        } => (edge_footprint(length_mm, width_mm, angle_deg, depth), width_mm / 2.0),
    };
    let total: f64 = weighted.iter().map(|(_, w)| w).sum();
    let extent_mm = weighted.iter().map(|(p, _)| p[0].hypot(p[1])).fold(0.0, f64::max);
    if !loaded || total <= 0.0 {
        return ContactLoad {
            centre_mm: centre,
            extent_mm,
            contact_radius_mm,
            fine: Vec::new(),
            coarse: Vec::new(),
            near_distance_mm: 0.0,
            far: Vec::new(),
            far_distance_mm: 0.0,
        };
    }
    let polar_moment: f64 = weighted
        .iter()
        .map(|(p, w)| w / total * (p[0] * p[0] + p[1] * p[1]))
        .sum();
    // Torsion as a traction proportional to pressure times lever arm, scaled to the requested moment.
    let twist = if polar_moment > 0.0 {
        contact.torsion_nmm / polar_moment
    } else {
        0.0
    };
    let fine: Vec<PointForce> = weighted
        .iter()
        .map(|&(p, w)| {
            let w = w / total;
            PointForce {
                at_mm: [centre[0] + p[0], centre[1] + p[1]],
                force_n: [
                    w * (contact.tangential_force_n[0] - twist * p[1]),
                    w * (contact.tangential_force_n[1] + twist * p[0]),
                    w * contact.normal_force_n,
                ],
            }
        })
        .collect();
    let coarse = group(&fine, centre, 1.5 * depth);
    let far = group(&fine, centre, 2.0 * extent_mm + 6.0 * depth);
    let near_distance_mm = extent_mm + 4.0 * depth;
    ContactLoad {
        centre_mm: centre,
        extent_mm,
        contact_radius_mm,
        fine,
        coarse,
        near_distance_mm,
        far,
        far_distance_mm: 2.0 * near_distance_mm,
    }
}

/// A disc of radius `a` as points (position relative to its centre, weight): Hertz's pressure on it (`hertz`), else
/// a flat punch's, in rings and angles as fine as the pattern's `depth` resolves.
fn round_footprint(a: f64, depth: f64, hertz: bool) -> Vec<([f64; 2], f64)> {
    // r = a sin(phi) removes the flat punch's rim singularity and the Hertz profile's sqrt from the
    // integrand: Hertz p r dr ~ sin(phi) cos^2(phi) dphi, punch p r dr ~ sin(phi) dphi.
    let n_rings = points_across(a, depth, 3, 16);
    let n_angles = points_across(2.0 * std::f64::consts::PI * a, depth, 8, 64);
    let mut weighted = Vec::with_capacity(n_rings * n_angles);
    for ring in 0..n_rings {
        let phi = (ring as f64 + 0.5) / n_rings as f64 * std::f64::consts::FRAC_PI_2;
        let r = a * phi.sin();
        let radial_weight = if hertz {
            phi.sin() * phi.cos().powi(2)
        } else {
            phi.sin()
        };
        let stagger = if ring % 2 == 0 { 0.0 } else { 0.5 };
        for k in 0..n_angles {
            let theta = (k as f64 + stagger) / n_angles as f64 * std::f64::consts::TAU;
            weighted.push(([r * theta.cos(), r * theta.sin()], radial_weight));
        }
    }
    weighted
}

/// A strip `length_mm` x `width_mm` at `angle_deg` as points (position relative to its centre, weight), with the
/// half-elliptic pressure across it, as fine as the pattern's `depth` resolves.
fn edge_footprint(length_mm: f64, width_mm: f64, angle_deg: f64, depth: f64) -> Vec<([f64; 2], f64)> {
    let (sin, cos) = angle_deg.to_radians().sin_cos();
    let along = [cos, sin];
    let across = [-sin, cos];
    let b = width_mm / 2.0;
    let n_along = points_across(length_mm, depth, 4, 128);
    let n_across = points_across(width_mm, depth, 3, 16);
    let mut weighted = Vec::with_capacity(n_along * n_across);
    for i in 0..n_along {
        let s = ((i as f64 + 0.5) / n_along as f64 - 0.5) * length_mm;
        for j in 0..n_across {
            // x = b sin(phi): the half-elliptic profile sqrt(1 - x^2/b^2) dx becomes cos^2(phi) dphi.
            let phi = ((j as f64 + 0.5) / n_across as f64 - 0.5) * std::f64::consts::PI;
            let t = b * phi.sin();
            weighted.push((
                [s * along[0] + t * across[0], s * along[1] + t * across[1]],
                phi.cos().powi(2),
            ));
        }
    }
    weighted
}

/// Sums forces over square cells of side `cell_mm` about `origin`, each placed at its force-weighted centroid.
fn group(forces: &[PointForce], origin: [f64; 2], cell_mm: f64) -> Vec<PointForce> {
    // Per cell: force-weighted position sum, weight, summed force.
    type Cell = ([f64; 2], f64, [f64; 3]);
    let mut cells: std::collections::BTreeMap<(i64, i64), Cell> = Default::default();
    for f in forces {
        let key = (
            ((f.at_mm[0] - origin[0]) / cell_mm).round() as i64,
            ((f.at_mm[1] - origin[1]) / cell_mm).round() as i64,
        );
        let weight = f.force_n.iter().map(|c| c.abs()).sum::<f64>();
        let entry = cells.entry(key).or_insert(([0.0; 2], 0.0, [0.0; 3]));
        entry.0[0] += weight * f.at_mm[0];
        entry.0[1] += weight * f.at_mm[1];
        entry.1 += weight;
        for k in 0..3 {
            entry.2[k] += f.force_n[k];
        }
    }
    cells
        .into_values()
        .filter(|(_, weight, _)| *weight > 0.0)
        .map(|(moment, weight, force_n)| PointForce {
            at_mm: [moment[0] / weight, moment[1] / weight],
            force_n,
        })
        .collect()
}

/// The gel under a set of contact loads.
#[derive(Clone, Debug)]
pub struct LoadedPad {
    pub half_space: HalfSpace,
    pub depth_mm: f64,
    pub loads: Vec<ContactLoad>,
}

impl LoadedPad {
    pub fn new(contacts: &[Contact], material: &Material) -> Self {
        Self {
            half_space: HalfSpace::new(material),
            depth_mm: material.layer_depth_mm,
            loads: contacts.iter().map(|c| discretise(c, material)).collect(),
        }
    }

    pub fn is_loaded(&self) -> bool {
        self.loads.iter().any(|l| !l.fine.is_empty())
    }

    /// Displacement (mm; x, y, z into the gel) of the colour layer's material point below `at_mm` (pad mm).
    pub fn displacement_mm(&self, at_mm: [f64; 2]) -> [f64; 3] {
        let mut u = [0.0; 3];
        for load in &self.loads {
            let distance2 = (at_mm[0] - load.centre_mm[0]).powi(2) + (at_mm[1] - load.centre_mm[1]).powi(2);
            let forces = if distance2 > load.far_distance_mm.powi(2) {
                &load.far
            } else if distance2 > load.near_distance_mm.powi(2) {
                &load.coarse
            } else {
                &load.fine
            };
            for f in forces {
                let d = self.half_space.point_force_displacement(
                    f.force_n,
                    [at_mm[0] - f.at_mm[0], at_mm[1] - f.at_mm[1]],
                    self.depth_mm,
                );
                for k in 0..3 {
                    u[k] += d[k];
                }
            }
        }
        u
    }

    /// The same using the full quadrature everywhere (the reference the grouping is checked against).
    pub fn displacement_fine_mm(&self, at_mm: [f64; 2]) -> [f64; 3] {
        let mut u = [0.0; 3];
        for f in self.loads.iter().flat_map(|l| &l.fine) {
            let d = self.half_space.point_force_displacement(
                f.force_n,
                [at_mm[0] - f.at_mm[0], at_mm[1] - f.at_mm[1]],
                self.depth_mm,
            );
            for k in 0..3 {
                u[k] += d[k];
            }
        }
        u
    }
}

/// In-plane displacements sampled on a regular mesh in pad mm, for per-pixel interpolation.
#[derive(Clone, Debug)]
pub struct DisplacementMesh {
    pub origin_mm: [f64; 2],
    /// Node spacing along x and y.
    pub step_mm: [f64; 2],
    pub nx: usize,
    pub ny: usize,
    /// Row-major (x fastest), in mm.
    pub values: Vec<[f32; 2]>,
}

impl DisplacementMesh {
    /// A mesh covering `[min, max]` (pad mm) with nodes every `step_mm`, filled by `f`.
    pub fn sample(min: [f64; 2], max: [f64; 2], step_mm: f64, mut f: impl FnMut([f64; 2]) -> [f64; 2]) -> Self {
        let nx = (((max[0] - min[0]) / step_mm).ceil() as usize + 1).max(2);
        let ny = (((max[1] - min[1]) / step_mm).ceil() as usize + 1).max(2);
        let mut values = Vec::with_capacity(nx * ny);
        for j in 0..ny {
            for i in 0..nx {
                let p = [min[0] + i as f64 * step_mm, min[1] + j as f64 * step_mm];
                let u = f(p);
                values.push([u[0] as f32, u[1] as f32]);
            }
        }
        Self {
            origin_mm: min,
            step_mm: [step_mm, step_mm],
            nx,
            ny,
            values,
        }
    }

    /// Bilinear interpolation; zero outside the mesh (the field has decayed there).
    #[inline]
    pub fn at(&self, p: [f32; 2]) -> [f32; 2] {
        let fx = (p[0] - self.origin_mm[0] as f32) / self.step_mm[0] as f32;
        let fy = (p[1] - self.origin_mm[1] as f32) / self.step_mm[1] as f32;
        if !(fx >= 0.0 && fy >= 0.0) {
            return [0.0, 0.0];
        }
        let (i, j) = (fx as usize, fy as usize);
        if i + 1 >= self.nx || j + 1 >= self.ny {
            return [0.0, 0.0];
        }
        let (tx, ty) = (fx - i as f32, fy - j as f32);
        let row = j * self.nx + i;
        let (a, b, c, d) = (
            self.values[row],
            self.values[row + 1],
            self.values[row + self.nx],
            self.values[row + self.nx + 1],
        );
        let lerp = |k: usize| {
            let top = a[k] + (b[k] - a[k]) * tx;
            let bottom = c[k] + (d[k] - c[k]) * tx;
            top + (bottom - top) * ty
        };
        [lerp(0), lerp(1)]
    }

    /// The inverse map on the same nodes: for each node q, the offset v with q + v = p and p + u(p) = q, i.e.
    /// where the material now seen at q came from. Fixed-point iteration, which converges while |grad u| < 1.
    pub fn inverse(&self) -> Self {
        let mut values = Vec::with_capacity(self.values.len());
        for j in 0..self.ny {
            for i in 0..self.nx {
                let q = [
                    (self.origin_mm[0] + i as f64 * self.step_mm[0]) as f32,
                    (self.origin_mm[1] + j as f64 * self.step_mm[1]) as f32,
                ];
                let mut v = self.values[j * self.nx + i].map(|c| -c);
                for _ in 0..4 {
                    let u = self.at([q[0] + v[0], q[1] + v[1]]);
                    v = [-u[0], -u[1]];
                }
                values.push(v);
            }
        }
        Self { values, ..*self }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gel() -> Material {
        Material::real()
    }

    #[test]
    fn point_force_radial_displacement_matches_closed_form() {
        // Boussinesq in cylindrical form: u_r = P / (4 pi G) [r z / rho^3 - (1 - 2 nu) r / (rho (rho + z))].
        for nu in [0.5, 0.3, 0.0] {
            let half = HalfSpace {
                shear_modulus: 0.048,
                poisson_ratio: nu,
            };
            let (p, z) = (2.5, 2.8);
            for (r, angle) in [(0.5, 0.3), (2.0, 1.9), (4.0, -2.5), (12.0, 0.0)] {
                let rho = f64::hypot(r, z);
                let expected = p / (4.0 * std::f64::consts::PI * 0.048)
                    * (r * z / rho.powi(3) - (1.0 - 2.0 * nu) * r / (rho * (rho + z)));
                let offset = [r * f64::cos(angle), r * f64::sin(angle)];
                let u = half.point_force_displacement([0.0, 0.0, p], offset, z);
                let radial = (u[0] * offset[0] + u[1] * offset[1]) / r;
                let tangential = (u[1] * offset[0] - u[0] * offset[1]) / r;
                assert!(
                    (radial - expected).abs() < 1e-12 * expected.abs().max(1.0),
                    "nu {nu} r {r}: {radial} vs {expected}"
                );
                assert!(tangential.abs() < 1e-12);
            }
        }
    }

    #[test]
    fn distributed_loads_approach_the_point_load_far_away() {
        // Saint-Venant: beyond a few contact radii every pressure distribution looks like its resultant.
        let material = gel();
        let half = HalfSpace::new(&material);
        for contact in [
            Contact::sphere(5.0, [0.0, 0.0], 4.0),
            Contact::flat_punch(2.0, [0.0, 0.0], 4.0),
            Contact::edge(3.0, 1.0, 30.0, [0.0, 0.0], 4.0),
        ] {
            let pad = LoadedPad::new(std::slice::from_ref(&contact), &material);
            let at = [25.0, 10.0];
            let point = half.point_force_displacement([0.0, 0.0, 4.0], at, material.layer_depth_mm);
            let u = pad.displacement_fine_mm(at);
            for k in 0..3 {
                assert!(
                    (u[k] - point[k]).abs() < 0.03 * point[k].abs().max(1e-4),
                    "{contact:?} {u:?} vs {point:?}"
                );
            }
        }
    }

    #[test]
    fn total_force_and_moment_are_the_requested_ones() {
        let material = gel();
        let mut contact = Contact::sphere(4.0, [3.0, -2.0], 5.0);
        contact.tangential_force_n = [0.7, -0.2];
        contact.torsion_nmm = 3.0;
        let load = discretise(&contact, &material);
        for forces in [&load.fine, &load.coarse, &load.far] {
            let sum = forces.iter().fold([0.0; 3], |acc, f| {
                [acc[0] + f.force_n[0], acc[1] + f.force_n[1], acc[2] + f.force_n[2]]
            });
            assert!(
                (sum[0] - 0.7).abs() < 1e-9 && (sum[1] + 0.2).abs() < 1e-9 && (sum[2] - 5.0).abs() < 1e-9,
                "{sum:?}"
            );
        }
        let moment: f64 = load
            .fine
            .iter()
            .map(|f| (f.at_mm[0] - 3.0) * f.force_n[1] - (f.at_mm[1] + 2.0) * f.force_n[0])
            .sum();
        assert!((moment - 3.0).abs() < 1e-9, "{moment}");
    }

    #[test]
    fn coarse_far_field_agrees_with_the_full_quadrature() {
        let material = gel();
        let mut contact = Contact::sphere(5.0, [0.0, 0.0], 8.0);
        contact.tangential_force_n = [1.0, 0.5];
        contact.torsion_nmm = 4.0;
        let edge = Contact::edge(20.0, 1.0, 60.0, [-5.0, 3.0], 8.0);
        let pad = LoadedPad::new(&[contact, edge], &material);
        let peak = (0..200)
            .map(|i| {
                let u = pad.displacement_fine_mm([i as f64 * 0.1, 0.0]);
                u[0].hypot(u[1])
            })
            .fold(0.0, f64::max);
        let mut worst: f64 = 0.0;
        for j in -20..=20 {
            for i in -26..=26 {
                let p = [i as f64, j as f64];
                let (a, b) = (pad.displacement_mm(p), pad.displacement_fine_mm(p));
                worst = worst.max((a[0] - b[0]).hypot(a[1] - b[1]));
            }
        }
        println!("grouping error: worst {worst:.5} mm against a peak of {peak:.4} mm");
        assert!(worst < 0.005 * peak, "worst {worst} mm against a peak of {peak} mm");
    }

    #[test]
    fn centred_sphere_gives_a_radially_symmetric_outward_field() {
        let material = gel();
        let pad = LoadedPad::new(&[Contact::sphere(5.0, [0.0, 0.0], 6.0)], &material);
        for r in [1.0, 3.0, 6.0, 10.0] {
            let reference = pad.displacement_mm([r, 0.0]);
            assert!(reference[0] > 0.0, "incompressible gel bulges outward at depth");
            for k in 1..12 {
                let angle = k as f64 * std::f64::consts::FRAC_PI_6 + 0.1;
                let (s, c) = angle.sin_cos();
                let u = pad.displacement_mm([r * c, r * s]);
                let radial = u[0] * c + u[1] * s;
                let tangential = u[1] * c - u[0] * s;
                assert!(
                    (radial - reference[0]).abs() < 0.01 * reference[0],
                    "r {r} angle {angle}: {radial} vs {}",
                    reference[0]
                );
                assert!(tangential.abs() < 0.01 * reference[0]);
            }
        }
    }

    #[test]
    fn displacements_superpose() {
        let material = gel();
        let a = Contact::sphere(5.0, [-8.0, 2.0], 3.0);
        let mut b = Contact::flat_punch(2.0, [6.0, -4.0], 2.0);
        b.tangential_force_n = [0.3, 0.1];
        let both = LoadedPad::new(&[a.clone(), b.clone()], &material);
        let only_a = LoadedPad::new(&[a], &material);
        let only_b = LoadedPad::new(&[b], &material);
        for p in [[0.0, 0.0], [-8.0, 4.0], [6.5, -4.0], [20.0, 15.0]] {
            let (u, ua, ub) = (
                both.displacement_mm(p),
                only_a.displacement_mm(p),
                only_b.displacement_mm(p),
            );
            for k in 0..3 {
                assert!((u[k] - ua[k] - ub[k]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn displacement_grows_linearly_with_force_for_a_punch() {
        // The punch's footprint does not change with force, so its field is exactly linear in the load.
        let material = gel();
        let u1 = LoadedPad::new(&[Contact::flat_punch(3.0, [0.0, 0.0], 1.0)], &material).displacement_mm([4.0, 1.0]);
        let u3 = LoadedPad::new(&[Contact::flat_punch(3.0, [0.0, 0.0], 3.0)], &material).displacement_mm([4.0, 1.0]);
        for k in 0..3 {
            assert!((u3[k] - 3.0 * u1[k]).abs() < 1e-12);
        }
    }

    #[test]
    fn mesh_interpolates_and_inverts() {
        let material = gel();
        let pad = LoadedPad::new(&[Contact::sphere(5.0, [1.0, -1.0], 6.0)], &material);
        let mesh = DisplacementMesh::sample([-30.0, -25.0], [30.0, 25.0], 0.5, |p| {
            let u = pad.displacement_mm(p);
            [u[0], u[1]]
        });
        let inverse = mesh.inverse();
        for p in [[0.3, 0.7], [4.2, -3.1], [-6.0, 2.2]] {
            let exact = pad.displacement_mm(p);
            let u = mesh.at([p[0] as f32, p[1] as f32]);
            assert!((f64::from(u[0]) - exact[0]).abs() < 5e-3 && (f64::from(u[1]) - exact[1]).abs() < 5e-3);
            let q = [p[0] + exact[0], p[1] + exact[1]];
            let v = inverse.at([q[0] as f32, q[1] as f32]);
            assert!((q[0] + f64::from(v[0]) - p[0]).abs() < 5e-3 && (q[1] + f64::from(v[1]) - p[1]).abs() < 5e-3);
        }
    }
}
