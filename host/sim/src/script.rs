//! A looping, deterministic time -> scene animation for the live demo (the daemon's simulated camera):
//! a sphere presses, holds, slides while dragging, releases; then an edge presses at four angles.

use crate::scene::{Contact, Scene};

/// Length of one loop of [`scene_at`], seconds.
pub const PERIOD_S: f64 = 20.0;

const SPHERE_RADIUS_MM: f64 = 5.0;
const PRESS_FORCE_N: f64 = 5.0;
const SLIDE_FROM_MM: [f64; 2] = [-8.0, -4.0];
const SLIDE_TO_MM: [f64; 2] = [8.0, 4.0];
/// Friction while sliding, as a fraction of the normal force.
const SLIDE_FRICTION: f64 = 0.1;
const EDGE_FORCE_N: f64 = 6.0;
const EDGE_LENGTH_MM: f64 = 20.0;
const EDGE_WIDTH_MM: f64 = 1.0;
const EDGE_ANGLES_DEG: [f64; 4] = [0.0, 45.0, 90.0, 135.0];

/// What the demo is doing at a moment, for labels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    Rest,
    PressRamp,
    Hold,
    Slide,
    Release,
    Edge,
}

fn smoothstep(t: f64) -> f64 {
    let t = t.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

fn wrap(t_s: f64) -> f64 {
    if t_s.is_finite() {
        t_s.rem_euclid(PERIOD_S)
    } else {
        0.0
    }
}

/// The demo's phase at time `t_s` (any time; the animation repeats every [`PERIOD_S`]).
pub fn phase_at(t_s: f64) -> Phase {
    match wrap(t_s) {
        t if t < 1.0 => Phase::Rest,
        t if t < 3.0 => Phase::PressRamp,
        t if t < 5.0 => Phase::Hold,
        t if t < 9.0 => Phase::Slide,
        t if t < 10.0 => Phase::Release,
        t if t < 11.0 => Phase::Rest,
        t if t < 19.0 => Phase::Edge,
        _ => Phase::Rest,
    }
}

/// The scene at time `t_s`; always valid for the default pad.
pub fn scene_at(t_s: f64) -> Scene {
    let t = wrap(t_s);
    let sphere = |position: [f64; 2], force: f64, tangential: [f64; 2]| {
        let mut contact = Contact::sphere(SPHERE_RADIUS_MM, position, force);
        contact.tangential_force_n = tangential;
        Scene::with_contact(contact)
    };
    match phase_at(t) {
        Phase::Rest => Scene::rest(),
        Phase::PressRamp => sphere(SLIDE_FROM_MM, PRESS_FORCE_N * smoothstep((t - 1.0) / 2.0), [0.0, 0.0]),
        Phase::Hold => sphere(SLIDE_FROM_MM, PRESS_FORCE_N, [0.0, 0.0]),
        Phase::Slide => {
            let s = smoothstep((t - 5.0) / 4.0);
            let position = std::array::from_fn(|k| SLIDE_FROM_MM[k] + s * (SLIDE_TO_MM[k] - SLIDE_FROM_MM[k]));
            let direction = [SLIDE_TO_MM[0] - SLIDE_FROM_MM[0], SLIDE_TO_MM[1] - SLIDE_FROM_MM[1]];
            let norm = direction[0].hypot(direction[1]);
            let drag = SLIDE_FRICTION * PRESS_FORCE_N;
            sphere(
                position,
                PRESS_FORCE_N,
                [drag * direction[0] / norm, drag * direction[1] / norm],
            )
        }
        Phase::Release => sphere(SLIDE_TO_MM, PRESS_FORCE_N * (1.0 - smoothstep(t - 9.0)), [0.0, 0.0]),
        Phase::Edge => {
            let local = t - 11.0;
            let slot = ((local / 2.0) as usize).min(EDGE_ANGLES_DEG.len() - 1);
            let within = local - 2.0 * slot as f64;
            let level = smoothstep(within / 0.5) * (1.0 - smoothstep((within - 1.5) / 0.5));
            Scene::with_contact(Contact::edge(
                EDGE_LENGTH_MM,
                EDGE_WIDTH_MM,
                EDGE_ANGLES_DEG[slot],
                [0.0, 0.0],
                EDGE_FORCE_N * level,
            ))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nusense_geometry::PadGeometry;

    #[test]
    fn every_moment_is_a_valid_scene_and_the_loop_repeats() {
        let pad = PadGeometry::default();
        // Dyadic times, so that adding the period is exact.
        for i in 0..320 {
            let t = f64::from(i) / 16.0;
            let scene = scene_at(t);
            scene.validate(&pad).unwrap();
            assert_eq!(scene, scene_at(t + PERIOD_S));
        }
        assert_eq!(scene_at(f64::NAN), scene_at(0.0));
    }

    #[test]
    fn the_story_is_told_in_order() {
        assert!(scene_at(0.5).contacts.is_empty());
        let ramp = scene_at(2.0).total_normal_force_n();
        assert!(ramp > 0.5 && ramp < PRESS_FORCE_N);
        assert_eq!(scene_at(4.0).total_normal_force_n(), PRESS_FORCE_N);
        let slide = scene_at(7.0);
        assert!(slide.contacts[0].position_mm[0] > SLIDE_FROM_MM[0] && slide.contacts[0].tangential_force_n[0] > 0.0);
        assert!(scene_at(10.5).contacts.is_empty());
        let angles: Vec<f64> = [12.0, 14.0, 16.0, 18.0]
            .iter()
            .map(|&t| scene_at(t).contacts[0].indenter.edge_angle_deg().unwrap())
            .collect();
        assert_eq!(angles, EDGE_ANGLES_DEG.to_vec());
        assert_eq!(scene_at(12.0).total_normal_force_n(), EDGE_FORCE_N);
        assert_eq!(phase_at(19.5), Phase::Rest);
    }
}
