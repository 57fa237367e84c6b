//! `inverse.observe = "squares"` on frames of the validation sensor (`nusense_sim::validation`: a layered pad held in
//! a frame, another lens and pose than the estimator assumes): the model observes the yellow squares the fast
//! tracker measures, each as the mean motion over its cell, instead of the corners (their midpoints).
//!
//! With a model of the pad as built (the defaults' layered stack, sliding walls 4 mm beyond the pattern), the squares
//! locate a press better than the corners: the localisation budget's stage runs (docs/benchmarks/validation-quick.md,
//! "Where the localisation error comes from") halved the full set's error. These presses are drawn here (tips,
//! forces and places of their own, not the validation set's).

use nusense_estimator::{ElasticConfig, Estimator, Mode, ObservedPoints, SensorConfig};
use nusense_sim::validation::{Case, CaseKind, ValidationRenderer};
use nusense_sim::{Contact, Scene};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const SIZE: (u32, u32) = (1024, 768);
const PRESSES: usize = 24;

/// The defaults' layered stack on its plate, held in a frame with sliding walls 4 mm beyond the pattern.
fn pad_as_built(observe: ObservedPoints) -> SensorConfig {
    let mut config = SensorConfig {
        elastic: ElasticConfig::layered_in_a_frame(),
        ..SensorConfig::default()
    };
    config.inverse.observe = observe;
    config
}

#[test]
fn observing_the_squares_locates_presses_within_a_quarter_millimetre() {
    let renderer = ValidationRenderer::new(SIZE).unwrap();
    let reference = renderer.reference(7).unwrap();
    let mut corners = Estimator::new(pad_as_built(ObservedPoints::Corners), Mode::Inverse, &reference).unwrap();
    let mut squares = Estimator::new(pad_as_built(ObservedPoints::Squares), Mode::Inverse, &reference).unwrap();
    assert_eq!(squares.inverse_model().observed_points_mm().len(), 96);
    let mut rng = ChaCha8Rng::seed_from_u64(21);
    let (mut corners_off, mut squares_off) = (Vec::new(), Vec::new());
    for k in 0..PRESSES {
        let at = [rng.gen_range(-20.0..=20.0), rng.gen_range(-14.0..=14.0)];
        let contact = match k % 3 {
            0 => Contact::sphere(5.0, at, rng.gen_range(2.0..=8.0)),
            1 => Contact::sphere(8.0, at, rng.gen_range(2.0..=8.0)),
            _ => Contact::flat_punch(3.0, at, rng.gen_range(2.0..=8.0)),
        };
        let case = Case::still(
            format!("{:?} at {at:.1?} mm", contact.indenter),
            CaseKind::Press,
            SIZE,
            Scene::with_contact(contact),
            80 + k as u64,
        );
        let (frame, truth) = renderer.render(&case).unwrap();
        let truth = truth.frame.contacts[0].centre_mm;
        for (estimator, errors) in [(&mut corners, &mut corners_off), (&mut squares, &mut squares_off)] {
            let reading = estimator.estimate(&frame).unwrap();
            let found = reading
                .touch
                .as_ref()
                .unwrap_or_else(|| panic!("{}: no contact", case.name))
                .strongest
                .centre_mm;
            errors.push((found[0] - truth[0]).hypot(found[1] - truth[1]));
        }
    }
    let rms = |e: &[f64]| (e.iter().map(|v| v * v).sum::<f64>() / e.len() as f64).sqrt();
    let (corners_rms, squares_rms) = (rms(&corners_off), rms(&squares_off));
    assert!(
        squares_rms <= 0.25 && squares_rms < corners_rms,
        "squares {squares_rms:.3} mm RMS against the corners' {corners_rms:.3} (target 0.25)"
    );
}
