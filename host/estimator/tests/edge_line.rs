//! `inverse.edge_from_line` on frames of the validation sensor (`nusense_sim::validation`: a layered pad held in a
//! frame, another lens and pose than the estimator assumes): the edge direction from the straight line load that
//! best explains the displacements, against the second moments of the pressure map (the default).
//!
//! The moments read a 20 mm edge with an error that depends on where it crosses between the corners
//! (docs/benchmarks/validation-full.md, "Edge direction"). Neither reads this pad's edges within 2 deg: the model's
//! error of the pad sets both. Measured on these 40 edges (random angles, places and forces of their own, not the
//! validation set's): moments 1.92 / 7.80 deg mean / worst, line load 1.53 / 4.78.

use nusense_estimator::{Estimator, Mode, SensorConfig};
use nusense_sim::validation::{Case, CaseKind, ValidationRenderer};
use nusense_sim::{Contact, Scene};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const SIZE: (u32, u32) = (1024, 768);
const EDGES: usize = 40;

/// Unsigned angle between two directions, degrees.
fn off_deg(found: f64, truth: f64) -> f64 {
    let off = (found - truth).rem_euclid(180.0);
    off.min(180.0 - off)
}

#[test]
fn the_line_load_reads_a_layered_pads_edges_better_than_the_moments() {
    let renderer = ValidationRenderer::new(SIZE).unwrap();
    let reference = renderer.reference(7).unwrap();
    let mut moments = Estimator::new(SensorConfig::default(), Mode::Inverse, &reference).unwrap();
    let mut config = SensorConfig::default();
    config.inverse.edge_from_line = true;
    let mut line = Estimator::new(config, Mode::Inverse, &reference).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let (mut moments_off, mut line_off) = (Vec::new(), Vec::new());
    for k in 0..EDGES {
        let angle = rng.gen_range(0.0..180.0);
        let centre = [rng.gen_range(-10.0..=10.0), rng.gen_range(-7.0..=7.0)];
        let force = rng.gen_range(3.0..=8.0);
        let case = Case::still(
            format!("{force:.1} N edge at {angle:.1} deg about {centre:.1?} mm"),
            CaseKind::Edge,
            SIZE,
            Scene::with_contact(Contact::edge(20.0, 1.0, angle, centre, force)),
            60 + k as u64,
        );
        let (frame, _) = renderer.render(&case).unwrap();
        for (estimator, errors) in [(&mut moments, &mut moments_off), (&mut line, &mut line_off)] {
            let reading = estimator.estimate(&frame).unwrap();
            let found = reading
                .edge_angle_deg()
                .unwrap_or_else(|| panic!("{}: no direction ({})", case.name, reading.edge_confidence()));
            errors.push(off_deg(found, angle));
        }
    }
    let mean = |e: &[f64]| e.iter().sum::<f64>() / e.len() as f64;
    let worst = |e: &[f64]| e.iter().copied().fold(0.0, f64::max);
    let (moments_mean, line_mean) = (mean(&moments_off), mean(&line_off));
    assert!(
        line_mean < moments_mean && worst(&line_off) < worst(&moments_off),
        "line load {line_mean:.2} / {:.2} deg mean / worst against the moments' {moments_mean:.2} / {:.2}",
        worst(&line_off),
        worst(&moments_off)
    );
}
