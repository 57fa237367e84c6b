//! The paper's experiments as scene lists: a grid of contact positions, force ramps for a sphere and a flat
//! tip, and edge angles.

use crate::scene::{Contact, Indenter, Scene};

/// Tip used for the position grid and the sphere force ramp (the real frames' indenter, about 5 mm radius).
pub const SPHERE_RADIUS_MM: f64 = 5.0;
/// Flat tip of the force ramp.
pub const FLAT_PUNCH_RADIUS_MM: f64 = 3.0;
pub const POSITION_FORCE_N: f64 = 6.0;
/// The paper's position grid: 6 x 4 points, 6.4 mm apart in x and 7 mm in y, centred on the pad.
pub const POSITION_STEP_MM: [f64; 2] = [6.4, 7.0];
pub const POSITION_GRID: [usize; 2] = [6, 4];
pub const FORCE_STEP_N: f64 = 0.5;
pub const FORCE_MAX_N: f64 = 8.0;
pub const EDGE_FORCE_N: f64 = 8.0;
pub const EDGE_STEP_DEG: f64 = 15.0;
pub const EDGE_LENGTH_MM: f64 = 20.0;
pub const EDGE_WIDTH_MM: f64 = 1.0;

/// One frame of a sweep; `name` is unique within the sweep and safe as a file name.
#[derive(Clone, Debug, PartialEq)]
pub struct SweepFrame {
    pub name: String,
    pub scene: Scene,
}

/// 24 sphere presses at 6 N on the paper's grid.
pub fn positions() -> Vec<SweepFrame> {
    let [nx, ny] = POSITION_GRID;
    let mut frames = Vec::with_capacity(nx * ny);
    for j in 0..ny {
        for i in 0..nx {
            let x = (i as f64 - (nx as f64 - 1.0) / 2.0) * POSITION_STEP_MM[0];
            let y = (j as f64 - (ny as f64 - 1.0) / 2.0) * POSITION_STEP_MM[1];
            frames.push(SweepFrame {
                name: format!("pos_r{j}_c{i}"),
                scene: Scene::with_contact(Contact::sphere(SPHERE_RADIUS_MM, [x, y], POSITION_FORCE_N)),
            });
        }
    }
    frames
}

/// 0.5, 1.0, ... 8 N at the pad centre with `indenter`; names start with `label`.
pub fn forces_with(indenter: &Indenter, label: &str) -> Vec<SweepFrame> {
    let steps = (FORCE_MAX_N / FORCE_STEP_N).round() as usize;
    (1..=steps)
        .map(|k| {
            let force = k as f64 * FORCE_STEP_N;
            let contact = Contact {
                indenter: indenter.clone(),
                position_mm: [0.0, 0.0],
                normal_force_n: force,
                tangential_force_n: [0.0, 0.0],
                torsion_nmm: 0.0,
            };
            SweepFrame {
                name: format!("{label}_{force:.1}N"),
                scene: Scene::with_contact(contact),
            }
        })
        .collect()
}

/// The force ramps for the sphere and the flat tip.
pub fn forces() -> Vec<SweepFrame> {
    let mut frames = forces_with(
        &Indenter::Sphere {
            radius_mm: SPHERE_RADIUS_MM,
        },
        "sphere",
    );
    frames.extend(forces_with(
        &Indenter::FlatPunch {
            radius_mm: FLAT_PUNCH_RADIUS_MM,
        },
        "flat",
    ));
    frames
}

/// An edge at 0, 15, ... 165 degrees through the pad centre at 8 N.
pub fn edges() -> Vec<SweepFrame> {
    let steps = (180.0 / EDGE_STEP_DEG).round() as usize;
    (0..steps)
        .map(|k| {
            let angle = k as f64 * EDGE_STEP_DEG;
            SweepFrame {
                name: format!("edge_{angle:03.0}deg"),
                scene: Scene::with_contact(Contact::edge(
                    EDGE_LENGTH_MM,
                    EDGE_WIDTH_MM,
                    angle,
                    [0.0, 0.0],
                    EDGE_FORCE_N,
                )),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nusense_geometry::PadGeometry;

    #[test]
    fn sweeps_match_the_paper_and_are_valid() {
        let pad = PadGeometry::default();
        let p = positions();
        assert_eq!(p.len(), 24);
        let xs: Vec<f64> = p.iter().map(|f| f.scene.contacts[0].position_mm[0]).collect();
        assert!((xs[1] - xs[0] - 6.4).abs() < 1e-12 && (xs[0] + xs[5]).abs() < 1e-12);
        assert!((p[6].scene.contacts[0].position_mm[1] - p[0].scene.contacts[0].position_mm[1] - 7.0).abs() < 1e-12);
        let f = forces();
        assert_eq!(f.len(), 32);
        assert_eq!(f[0].scene.total_normal_force_n(), 0.5);
        assert_eq!(f[15].scene.total_normal_force_n(), 8.0);
        let e = edges();
        assert_eq!(e.len(), 12);
        assert_eq!(e[11].scene.contacts[0].indenter.edge_angle_deg(), Some(165.0));
        for frame in p.iter().chain(&f).chain(&e) {
            frame.scene.validate(&pad).unwrap();
        }
        let mut names: Vec<&str> = p.iter().chain(&f).chain(&e).map(|f| f.name.as_str()).collect();
        names.sort();
        names.dedup();
        assert_eq!(names.len(), 24 + 32 + 12);
    }
}
