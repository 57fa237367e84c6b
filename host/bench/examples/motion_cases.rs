//! Diagnostic: the inverse's force on the quick set's camera-motion presses, each rendered again with no motion and
//! with each part of its motion alone (roll, tilt, shift), to see which part of the motion moves the force.
//! `cargo run --release -p nusense-bench --example motion_cases -- [quick|full]`; with `TRUTH=1` also, per motion, on
//! the rest scene: the rest frame's pad map applied to the simulator's true corners before and after the motion
//! (what is left after the best homography of pad mm), and the tracker's error and its change with the motion.

use nusense_estimator::homography::Homography;
use nusense_estimator::{Estimator, Mode, SensorConfig};
use nusense_sim::validation::{CameraMotion, Case, CaseKind, Profile, ValidationRenderer, ValidationSet};
use nusense_sim::Scene;

type Error = Box<dyn std::error::Error>;
/// A part of a case's camera motion (or none of it).
type Variant = fn(CameraMotion) -> Option<CameraMotion>;

fn main() -> Result<(), Error> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let profile = if args.first().map(String::as_str) == Some("full") {
        Profile::Full
    } else {
        Profile::Quick
    };
    let set = ValidationSet::new(profile, 7);
    let size = set.sizes()[0];
    let renderer = ValidationRenderer::new(size)?;
    let reference = renderer.reference(7)?;
    let mut estimator = Estimator::new(SensorConfig::default(), Mode::Inverse, &reference)?;
    let variants: [(&str, Variant); 5] = [
        ("none", |_| None),
        ("full", Some),
        ("roll", |m| {
            Some(CameraMotion {
                rotation_deg: [0.0, 0.0, m.rotation_deg[2]],
                shift_mm: [0.0, 0.0],
            })
        }),
        ("tilt", |m| {
            Some(CameraMotion {
                rotation_deg: [m.rotation_deg[0], m.rotation_deg[1], 0.0],
                shift_mm: [0.0, 0.0],
            })
        }),
        ("shift", |m| {
            Some(CameraMotion {
                rotation_deg: [0.0, 0.0, 0.0],
                shift_mm: m.shift_mm,
            })
        }),
    ];
    for case in set.of_kind(CaseKind::CameraMotion) {
        let motion = case.camera_motion.expect("camera-motion cases move the camera");
        let contact = &case.scene.contacts[0];
        println!(
            "{} at [{:.1}, {:.1}] {:.2} N; motion rot [{:.2}, {:.2}, {:.2}] shift [{:.2}, {:.2}]",
            case.name,
            contact.position_mm[0],
            contact.position_mm[1],
            contact.normal_force_n,
            motion.rotation_deg[0],
            motion.rotation_deg[1],
            motion.rotation_deg[2],
            motion.shift_mm[0],
            motion.shift_mm[1]
        );
        for (name, variant) in &variants {
            if let (Some(m), true) = (variant(motion), std::env::var_os("TRUTH").is_some()) {
                truth_check(&renderer, &mut estimator, case, m, name)?;
            }
            let moved = Case {
                camera_motion: variant(motion),
                ..case.clone()
            };
            let (frame, _) = renderer.render(&moved)?;
            match estimator.estimate(&frame) {
                Ok(r) => {
                    let f = r.touch.as_ref().and_then(|t| t.force_vector_n).unwrap_or([0.0; 3]);
                    let at = r.touch.as_ref().map(|t| t.strongest.centre_mm);
                    let n = r.touch.as_ref().map_or(0, |t| 1 + t.others.len());
                    println!(
                        "  {name:5} fz {:6.3} fxy [{:6.3}, {:6.3}] contacts {n} at {:?} rot {:6.3} scale {:.5} noise {:.2} um stat {:.1}/{:.1} floor {:.2}",
                        f[2],
                        f[0],
                        f[1],
                        at.map(|p| [(p[0] * 10.0).round() / 10.0, (p[1] * 10.0).round() / 10.0]),
                        r.camera_motion.rotation_deg,
                        r.camera_motion.scale,
                        r.test.noise_mm * 1e3,
                        r.test.statistic,
                        r.test.threshold,
                        r.test.detection_floor_n,
                    );
                    if let Some(t) = &r.touch {
                        let list: Vec<String> = t
                            .contacts()
                            .map(|c| format!("{:.2} N at [{:.1}, {:.1}]", c.force_n, c.centre_mm[0], c.centre_mm[1]))
                            .collect();
                        println!("        contacts: {}", list.join("; "));
                    }
                }
                Err(e) => println!("  {name:5} error {e}"),
            }
        }
    }
    Ok(())
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

/// On the rest scene: the rest frame's map applied to the TRUE raw corners before and after the motion (what is
/// left after the best homography of pad mm: the map's share), and the detector's error before and after.
fn truth_check(
    renderer: &ValidationRenderer,
    estimator: &mut Estimator,
    case: &Case,
    motion: CameraMotion,
    name: &str,
) -> Result<(), Error> {
    let r = renderer.renderer();
    let moved = r.with_pose(motion.applied_to(r.model().pose))?;
    let rest = Scene::rest();
    let before = r.ground_truth(&rest, case.led_currents_ma, case.seed)?;
    let after = moved.ground_truth(&rest, case.led_currents_ma, case.seed)?;
    let map = estimator.mapping().clone();
    let (mut from, mut to, mut zs) = (Vec::new(), Vec::new(), Vec::new());
    let mut rest_err = Vec::new();
    for (a, b) in before.corners.iter().zip(&after.corners) {
        if let (Some(pa), Some(pb)) = (map.raw_to_mm(a.rest_px), map.raw_to_mm(b.rest_px)) {
            rest_err.push(pa[0] - a.rest_mm[0]);
            rest_err.push(pa[1] - a.rest_mm[1]);
            from.push(pa);
            to.push(pb);
            zs.push(a.rest_mm);
        }
    }
    let h = Homography::fit(&from, &to).ok_or("fit")?;
    let mut miss = Vec::new();
    for (p, q) in from.iter().zip(&to) {
        let m = h.apply(*p).ok_or("apply")?;
        miss.push(m[0] - q[0]);
        miss.push(m[1] - q[1]);
    }
    // Detector: detected raw px minus true raw px, at rest and moved; then the change of that error, in px.
    let (frame_rest, _) = r.render(&rest, case.led_currents_ma, case.seed)?;
    let (frame_moved, _) = moved.render(&rest, case.led_currents_ma, case.seed)?;
    let la = estimator.detect(&frame_rest)?;
    let lb = estimator.detect(&frame_moved)?;
    let mut change = Vec::new();
    let mut err_rest = Vec::new();
    for (a, b) in before.corners.iter().zip(&after.corners) {
        let (Some(ca), Some(cb)) = (la.corner(a.index), lb.corner(b.index)) else {
            continue;
        };
        let (Some(pa), Some(pb)) = (ca.raw_px, cb.raw_px) else {
            continue;
        };
        let ea = [pa[0] - a.rest_px[0], pa[1] - a.rest_px[1]];
        let eb = [pb[0] - b.rest_px[0], pb[1] - b.rest_px[1]];
        err_rest.push(ea[0]);
        err_rest.push(ea[1]);
        change.push(eb[0] - ea[0]);
        change.push(eb[1] - ea[1]);
    }
    let mean = |v: &[f64], k: usize| v.iter().skip(k).step_by(2).sum::<f64>() / (v.len() / 2).max(1) as f64;
    println!(
        "  truth {name:5}: map at rest rms {:.1} um; motion not a pad homography through the map rms {:.1} um; detector error rms {:.3} px (mean [{:.3}, {:.3}]), its change with the motion rms {:.3} px over {} corners",
        rms(&rest_err) * 1e3,
        rms(&miss) * 1e3,
        rms(&err_rest),
        mean(&err_rest, 0),
        mean(&err_rest, 1),
        rms(&change),
        change.len() / 2
    );
    Ok(())
}
