//! Three presses at once on the validation sensor (`nusense_sim::SensorModel::validation`, 1024x768): three contacts,
//! each where its press is.

use image::RgbImage;
use nusense_estimator::{Estimator, Mode, SensorConfig};
use nusense_sim::{Contact, Renderer, Scene, SensorModel};

const NOMINAL: [f32; 4] = [100.0; 4];

fn render(renderer: &Renderer, scene: &Scene, seed: u64) -> RgbImage {
    renderer
        .render(scene, NOMINAL, seed)
        .expect("the presses fit on the pad")
        .0
}

/// Three 5 mm spheres of `force` each at `presses` (mm), read by the inverse estimator on the validation sensor: `None`
/// when they are listed as three contacts each within 1 mm of its press, else what was listed.
fn three_presses_misread(
    renderer: &Renderer,
    estimator: &mut Estimator,
    presses: [[f64; 2]; 3],
    force: f64,
) -> Option<Vec<[f64; 2]>> {
    let scene = Scene {
        contacts: presses.iter().map(|&at| Contact::sphere(5.0, at, force)).collect(),
        ..Scene::default()
    };
    let reading = estimator
        .estimate(&render(renderer, &scene, 950))
        .expect("the frame is measurable");
    let listed: Vec<[f64; 2]> = reading.contacts().iter().map(|c| c.centre_mm).collect();
    let each_found = presses
        .iter()
        .all(|p| listed.iter().any(|c| (c[0] - p[0]).hypot(c[1] - p[1]) < 1.0));
    (listed.len() != 3 || !each_found).then_some(listed)
}

fn validation_sensor() -> (Renderer, Estimator) {
    let renderer = Renderer::new(SensorModel::validation(1024, 768)).expect("the validation sensor model is valid");
    let reference = render(&renderer, &Scene::rest(), 1);
    let estimator =
        Estimator::new(SensorConfig::default(), Mode::Inverse, &reference).expect("the rest frame shows the pattern");
    (renderer, estimator)
}

/// Three presses in a row, 14 mm apart along a diagonal, that the contact test finds: `join_long_groups` joined the
/// contacts of one loaded group into one when a line explained their union better than two round loads, and three
/// presses in a row are not two, so they were read as one contact between them (at 2 and 8 N). The line must now also
/// explain them better than round loads at the contacts' own centres, one each.
#[test]
fn three_presses_in_a_row_are_not_joined_into_a_line() {
    let (renderer, mut estimator) = validation_sensor();
    for force in [2.0, 8.0] {
        let misread = three_presses_misread(
            &renderer,
            &mut estimator,
            [[-12.0, -8.0], [0.0, 0.0], [12.0, 8.0]],
            force,
        );
        assert!(misread.is_none(), "{force} N each: listed {misread:.1?}");
    }
}

/// Three 5 mm spheres of 2, 4 or 8 N each, 12-24 mm apart, in a row, along a diagonal and in a triangle: each listed
/// as a contact within 1 mm of its press. Three presses move most of the corners, so their scatter about the motion,
/// which the contact test takes for the noise, grows with the load (24-113 um, a rest frame's about 1.5 um): 8 of these
/// 12 scenes read no contact at all (a triangle of three 8 N presses among them), one row reads as one contact, its
/// line, and three scenes as their three presses (seed 950).
#[test]
#[ignore = "known failure: 8 of 12 scenes of three presses read no contact (the test's noise is their own far \
            field), one row one contact"]
fn three_presses_at_once_are_three_contacts() {
    let (renderer, mut estimator) = validation_sensor();
    let mut failures = Vec::new();
    for force in [2.0, 4.0, 8.0] {
        for (arrangement, presses) in [
            ("a diagonal row", [[-12.0, -8.0], [0.0, 0.0], [12.0, 8.0]]),
            ("a row 12 mm apart", [[-12.0, 2.0], [0.0, 2.0], [12.0, 2.0]]),
            ("a row 16 mm apart", [[-16.0, 2.0], [0.0, 2.0], [16.0, 2.0]]),
            ("a triangle", [[-12.0, -8.0], [12.0, -8.0], [0.0, 9.0]]),
        ] {
            if let Some(listed) = three_presses_misread(&renderer, &mut estimator, presses, force) {
                failures.push(format!("{force} N each in {arrangement}: listed {listed:.1?}"));
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
