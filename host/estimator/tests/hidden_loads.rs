//! Loads no corner sees: the solve may spend the far field of a heavy load on cells that nothing constrains (the
//! corner cells under the glare, whose corners the rest frame's light probe leaves out of the solve once the camera
//! has moved), and a region there is no contact. Validation sensor (`nusense_sim::SensorModel::validation`), the
//! camera moved after the rest frame, the LEDs drifting.
//!
//! Both cases are known failures (the README's "Everything at once"). A rule that drops a region with more than 75 %
//! of its pressure on such cells, unless no region is seen, passes both and leaves the quick validation set as it is,
//! but drops a real edge's strongest part under the glare in another scene (20 mm at 46 deg at (-15.6, -15.7) mm,
//! 4.6 N, 640x480, camera moved 0.6 deg: force 0.90 -> 0.34 of the truth): the solve cannot tell a load under the
//! glare from one it spends there.

use image::RgbImage;
use nusense_estimator::{Estimator, Mode, Reading, SensorConfig};
use nusense_sim::validation::CameraMotion;
use nusense_sim::{Contact, Damage, Renderer, Scene, SensorModel};

/// A scene seen with the camera moved after the rest frame: the model, the pad's damage (in both frames), the
/// camera's motion, the LED currents (%) of the frame, the contact, and the noise seeds of both frames.
struct Moved {
    model: SensorModel,
    damage: Vec<Damage>,
    motion: CameraMotion,
    leds: [f32; 4],
    contact: Contact,
    seeds: (u64, u64),
}

fn read(scene: Moved) -> Reading {
    let renderer = Renderer::new(scene.model).expect("the validation sensor is valid");
    let rest = Scene {
        damage: scene.damage.clone(),
        ..Scene::rest()
    };
    let reference: RgbImage = renderer
        .render(&rest, [100.0; 4], scene.seeds.0)
        .expect("a rest frame")
        .0;
    let moved = renderer
        .with_pose(scene.motion.applied_to(renderer.model().pose))
        .expect("a small camera move is valid");
    let pressed = Scene {
        damage: scene.damage,
        ..Scene::with_contact(scene.contact)
    };
    let frame = moved
        .render(&pressed, scene.leds, scene.seeds.1)
        .expect("the scene is valid")
        .0;
    Estimator::new(SensorConfig::default(), Mode::Inverse, &reference)
        .expect("the rest frame is measurable")
        .estimate(&frame)
        .expect("the frame is measurable")
}

fn distance(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// A 5.8 N flat punch on the pattern's corner cell, the camera rolled 1.9 deg: one contact, at the punch (within the
/// 2 mm the outermost cells' centres read inwards: README). A second of 3.0 N (calibrated) is listed 5 mm beyond the
/// punch's edge, on cells whose corners were all left out of the solve.
#[test]
#[ignore = "known failure: a second contact of 1.9 N (model) 5 mm beyond the punch's edge, on cells whose corners \
            were all left out of the solve"]
fn a_corner_press_after_a_camera_move_lists_no_load_beside_it_that_no_corner_sees() {
    let at = [23.4, 17.6];
    let reading = read(Moved {
        model: SensorModel::validation(1024, 768),
        damage: Vec::new(),
        motion: CameraMotion {
            rotation_deg: [0.0, 0.0, 1.9],
            shift_mm: [0.6, 0.05],
        },
        leds: [104.0, 108.0, 103.0, 106.0],
        contact: Contact::flat_punch(3.1, at, 5.8),
        seeds: (1, 2),
    });
    let contacts = reading.contacts();
    assert_eq!(contacts.len(), 1, "{contacts:?}");
    let off = distance(contacts[0].centre_mm, at);
    assert!(off < 2.0, "read at {:?}, {off:.2} mm off", contacts[0].centre_mm);
}

/// A 27 mm edge of 6.8 N pushed sideways, near the y axis, the camera rolled 2.2 deg, JPEG at quality 50, a 4.6 mm
/// hole in the ink 20 mm away: every contact is on the edge. The strongest, 2.9 N (calibrated), is listed on the
/// pattern's corner cell 15 mm away (a random scene of a scratch sweep over 700 such scenes; the only one of them read
/// that far off).
#[test]
#[ignore = "known failure: the strongest contact, 2.9 N calibrated, on the pattern's corner cell at (-23.4, -18.0) \
            mm, 15 mm from the edge"]
fn a_pushed_edge_after_a_camera_move_is_read_on_the_edge_not_on_a_corner_cell() {
    let (at, angle_deg, length_mm) = ([-10.003, -0.746], 95.057f64, 27.348);
    let mut edge = Contact::edge(length_mm, 1.0, angle_deg, at, 6.788);
    edge.tangential_force_n = [-0.120, -1.058];
    let mut model = SensorModel::validation(800, 600);
    model.jpeg_quality = Some(50);
    let reading = read(Moved {
        model,
        damage: vec![Damage::Missing {
            centre_mm: [5.800, -17.452],
            radius_mm: 2.285,
        }],
        motion: CameraMotion {
            rotation_deg: [0.0, 0.0, 2.226],
            shift_mm: [0.050, 0.091],
        },
        leds: [112.389, 111.996, 100.384, 104.889],
        contact: edge,
        seeds: (315, 415),
    });
    let (u, v) = (angle_deg.to_radians().cos(), angle_deg.to_radians().sin());
    let from_edge = |p: [f64; 2]| {
        let (dx, dy) = (p[0] - at[0], p[1] - at[1]);
        let t = (dx * u + dy * v).clamp(-length_mm / 2.0, length_mm / 2.0);
        (dx - t * u).hypot(dy - t * v)
    };
    let contacts = reading.contacts();
    assert!(!contacts.is_empty(), "the edge is found");
    for contact in &contacts {
        assert!(
            from_edge(contact.centre_mm) < 3.0,
            "a contact {:?} off the edge: {contacts:?}",
            contact.centre_mm
        );
    }
}
