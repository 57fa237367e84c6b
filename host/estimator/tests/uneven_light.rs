//! The traction inverse under light that changed unevenly since the rest frame: one LED side at 150 %, the others
//! nominal (a failing or ageing LED string, or a user raising one side), on frames of the validation sensor
//! (`nusense_sim::validation`: another lens, pose and pad model than the estimator assumes, with glare and
//! vignetting) at 1024x768.
//!
//! The pad's yellow sits near the clip at nominal light, so the brighter side's squares clip in red and green while
//! their blue still grows. Before the tracker counted a pixel whose red and green both clip as yellow ink, their
//! yellowness (255 - B) fell with the light across each square and pulled its centroid away from the light (0.64 px
//! RMS over a rest frame's squares, 4.7 px at most): a 1 N press read as a phantom of 0.7-1.4 N at the glare or at
//! a pad corner, stronger than the press itself (19 of 96 presses of a sweep more than 1 mm off).

use nusense_estimator::{Estimator, Mode, Reading, SensorConfig};
use nusense_sim::validation::ValidationRenderer;
use nusense_sim::{Contact, Scene, NOMINAL_LED_CURRENT_MA};

const SIZE: (u32, u32) = (1024, 768);
const NOMINAL: [f32; 4] = [NOMINAL_LED_CURRENT_MA; 4];
/// Right (the second side) and left (the fourth) at 150 %: on main at 9320666 each put the strongest contact of a
/// 1 N press at the glare or a pad corner.
const ONE_SIDE_BRIGHT: [[f32; 4]; 2] = [[100.0, 150.0, 100.0, 100.0], [100.0, 100.0, 100.0, 150.0]];

fn read(renderer: &ValidationRenderer, estimator: &mut Estimator, scene: &Scene, leds: [f32; 4], seed: u64) -> Reading {
    let (frame, _) = renderer.renderer().render(scene, leds, seed).unwrap();
    estimator.estimate(&frame).unwrap()
}

/// The force of `scene` under the nominal light, which the press must be read as a contact under.
fn nominal_force_n(renderer: &ValidationRenderer, estimator: &mut Estimator, scene: &Scene, seed: u64) -> f64 {
    read(renderer, estimator, scene, NOMINAL, seed)
        .touch
        .as_ref()
        .expect("the press under nominal light is a contact")
        .force_n
}

#[test]
fn one_led_side_at_150_percent_is_no_contact_and_moves_no_light_press() {
    let renderer = ValidationRenderer::new(SIZE).unwrap();
    let reference = renderer.reference(7).unwrap();
    let mut estimator = Estimator::new(SensorConfig::default(), Mode::Inverse, &reference).unwrap();
    for leds in ONE_SIDE_BRIGHT {
        let rest = read(&renderer, &mut estimator, &Scene::rest(), leds, 201);
        assert!(
            !rest.is_contact(),
            "LEDs {leds:?}, rest: contact of {:.2} N at {:?}",
            rest.force_n(),
            rest.contact_mm()
        );
    }
    // Measured at the fix (N, model's): 0.656-0.660 under the nominal light, within 3.5 % of that under one side at
    // 150 %, the strongest 0.17-0.29 mm from the truth and no other contact. Before: the strongest contact at
    // (21.3, 18.2) or (-17.9, -17.2), 27-32 mm away, with one to three others.
    for (k, at) in [[0.0, 0.0], [6.0, -4.0]].into_iter().enumerate() {
        let scene = Scene::with_contact(Contact::sphere(5.0, at, 1.0));
        let seed = 210 + k as u64;
        let nominal_n = nominal_force_n(&renderer, &mut estimator, &scene, seed);
        for leds in ONE_SIDE_BRIGHT {
            let case = format!("LEDs {leds:?}, 1 N at {at:?}");
            let reading = read(&renderer, &mut estimator, &scene, leds, seed);
            let touch = reading.touch.as_ref().unwrap_or_else(|| panic!("{case}: no contact"));
            let c = touch.strongest.centre_mm;
            let off = (c[0] - at[0]).hypot(c[1] - at[1]);
            assert!(off <= 1.0, "{case}: the strongest contact at {c:.2?}, {off:.2} mm off");
            let others: Vec<_> = touch.others.iter().map(|o| (o.centre_mm, o.force_n)).collect();
            let force_n = touch.force_n;
            eprintln!("{case}: {force_n:.3} N at {c:.2?} ({off:.2} mm off), {nominal_n:.3} N under the nominal light");
            assert!(others.is_empty(), "{case}: other contacts {others:.2?}");
            assert!(
                (touch.force_n / nominal_n - 1.0).abs() <= 0.15,
                "{case}: {:.2} N, {nominal_n:.2} N under the nominal light",
                touch.force_n
            );
        }
    }
}

/// Every LED alike at another current than in the rest frame (the user set them so, or they drifted together): a
/// press beside the glare reads as under the nominal light. The glare clips, so the squares in it keep their light
/// while every other square's changes; the tracker used to call a square's light changed when it departed from the
/// rest frame's, which under such light is every square, and a press's squares (whose area a press changes beyond what
/// their spacing explains) were then flagged as relit and left out of the contact test. A 3 N press 4-5 mm from the
/// glare was read as two contacts, the strongest 1.6-2.2 mm off, on 19 of 20 noise seeds at 90 % and 17 of 20 at
/// 110 % (none under the nominal light). The light is now judged against the frame's typical change. Measured at the
/// fix (model's N): 2.22-2.23 nominal, 2.23-2.27 under these lights, 0.17-0.30 mm from the truth, one contact each.
#[test]
fn every_led_alike_at_another_current_leaves_a_press_beside_the_glare_as_it_is() {
    let renderer = ValidationRenderer::new(SIZE).unwrap();
    let reference = renderer.reference(7).unwrap();
    let mut estimator = Estimator::new(SensorConfig::default(), Mode::Inverse, &reference).unwrap();
    let at = [-11.0, -13.0];
    let scene = Scene::with_contact(Contact::sphere(5.0, at, 3.0));
    for seed in [1018, 1019] {
        let nominal_n = nominal_force_n(&renderer, &mut estimator, &scene, seed);
        for level in [50.0, 90.0, 110.0] {
            let case = format!("every LED at {level} %, 3 N at {at:?}, seed {seed}");
            let reading = read(&renderer, &mut estimator, &scene, [level; 4], seed);
            let contacts = reading.contacts();
            assert_eq!(contacts.len(), 1, "{case}: contacts {contacts:?}");
            let c = contacts[0].centre_mm;
            let off = (c[0] - at[0]).hypot(c[1] - at[1]);
            assert!(off <= 0.5, "{case}: read at {c:.2?}, {off:.2} mm off");
            let ratio = reading.force_n() / nominal_n;
            assert!(
                (ratio - 1.0).abs() <= 0.05,
                "{case}: {:.2} N against {nominal_n:.2} N under the nominal light",
                reading.force_n()
            );
        }
    }
}
