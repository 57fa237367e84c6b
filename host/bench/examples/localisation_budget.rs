//! Diagnostic: where the inverse's localisation error comes from, press by press on the validation set's presses.
//! `cargo run --release -p nusense-bench --example localisation_budget -- [quick|full]`; with
//! `NUSENSE_VALIDATION_CONFIG=SENSOR.toml` the estimator's model is that file's (the pad's own stack, say).
//!
//! Per press: the estimator's reading, and its inverse model's stage 1 and stage 2 (every corner valid in both
//! frames, stage 2 at the noise stage 1 leaves, never below `inverse.noise_floor_px`, and at the contact test's
//! floor) fed the corners' motion twice, both through the rest frame's pad map: as the tracker measured it, and as
//! the simulator's truth puts the corners in the image (a perfect tracker: the material corner, parallax included).
//! The estimator proper also leaves out the corners under the glare and makes further passes, so its column and the
//! tracked one differ a little. Where the tracked column and the perfect one differ, the tracker's measurement makes
//! the error (its corner is the midpoint of two yellow squares' centroids, which a strain gradient moves off the
//! material corner); where the perfect one is off, the model does.

use nusense_bench::validation::base_config_from_env;
use nusense_estimator::inverse::InverseModel;
use nusense_estimator::{Estimator, Mode};
use nusense_geometry::Point2;
use nusense_sim::validation::{CaseKind, Profile, ValidationRenderer, ValidationSet};
use nusense_sim::Indenter;

type Error = Box<dyn std::error::Error>;

/// Squared errors of one kind of tip, per column.
#[derive(Default)]
struct Errors {
    estimator: Vec<f64>,
    tracked: Vec<f64>,
    perfect: Vec<f64>,
}

fn main() -> Result<(), Error> {
    let profile = match std::env::args().nth(1).as_deref() {
        Some("full") => Profile::Full,
        _ => Profile::Quick,
    };
    let set = ValidationSet::new(profile, 7);
    let size = set.sizes()[0];
    let renderer = ValidationRenderer::new(size)?;
    let reference = renderer.reference(7)?;
    let config = base_config_from_env()?;
    let mut estimator = Estimator::new(config.clone(), Mode::Inverse, &reference)?;
    let floor_mm = estimator
        .mapping()
        .mm_per_px_at_centre()
        .map_or(0.0, |mm| config.inverse.noise_floor_px * mm)
        .max(config.inverse.noise_floor_mm);
    let (mut spheres, mut flats) = (Errors::default(), Errors::default());
    println!("press, tip, force N, at mm: error mm of the estimator | tracked corners | perfect tracker");
    for case in set.of_kind(CaseKind::Press) {
        let (frame, truth) = renderer.render(case)?;
        let Some(contact) = truth.frame.contacts.first() else {
            continue;
        };
        let reading = estimator.estimate(&frame)?;
        let mapping = estimator.mapping();
        let mut tracked = Vec::with_capacity(2 * truth.frame.corners.len());
        let mut perfect = Vec::with_capacity(2 * truth.frame.corners.len());
        let mut valid = Vec::with_capacity(truth.frame.corners.len());
        // The shear field lists the corners in the truth's order (`PadGeometry::corner_slot`).
        if reading.shear_field.len() != truth.frame.corners.len() {
            return Err("the reading's shear field does not list every corner".into());
        }
        for (corner, vector) in truth.frame.corners.iter().zip(&reading.shear_field) {
            if vector.index != corner.index {
                return Err("the reading lists the corners in another order than the truth".into());
            }
            let moved = |from: Option<Point2>, to: Option<Point2>| {
                let (a, b) = (mapping.raw_to_mm(from?)?, mapping.raw_to_mm(to?)?);
                Some([b[0] - a[0], b[1] - a[1]])
            };
            let seen = moved(vector.reference_px, vector.current_px).filter(|_| vector.valid);
            valid.push(seen.is_some());
            tracked.extend(seen.unwrap_or([0.0, 0.0]));
            perfect
                .extend(moved(Some(corner.rest_px), Some(corner.displaced_px)).ok_or("a true corner is out of view")?);
        }
        let model = estimator.inverse_model();
        let all = vec![true; valid.len()];
        let off = |found: Option<Point2>| {
            found.map_or(f64::INFINITY, |c| {
                (c[0] - contact.centre_mm[0]).hypot(c[1] - contact.centre_mm[1])
            })
        };
        let errors = [
            off(reading.touch.as_ref().map(|t| t.strongest.centre_mm)),
            off(strongest_centre(model, &tracked, &valid, floor_mm)),
            off(strongest_centre(model, &perfect, &all, floor_mm)),
        ];
        let (name, kind) = match contact.indenter {
            Indenter::Sphere { radius_mm } => (format!("{radius_mm} mm sphere"), &mut spheres),
            Indenter::FlatPunch { radius_mm } => (format!("{radius_mm} mm flat punch"), &mut flats),
            Indenter::Edge { .. } => continue,
        };
        println!(
            "{}, {name}, {:.2}, ({:.1}, {:.1}): {:.3} | {:.3} | {:.3}",
            case.name,
            contact.normal_force_n,
            contact.centre_mm[0],
            contact.centre_mm[1],
            errors[0],
            errors[1],
            errors[2]
        );
        kind.estimator.push(errors[0] * errors[0]);
        kind.tracked.push(errors[1] * errors[1]);
        kind.perfect.push(errors[2] * errors[2]);
    }
    let rms = |squares: &[f64]| (squares.iter().sum::<f64>() / squares.len().max(1) as f64).sqrt();
    println!("\n| presses | n | estimator, RMS mm | tracked corners | perfect tracker |\n|---|---|---|---|---|");
    for (name, errors) in [("spheres", &spheres), ("flat punches", &flats)] {
        println!(
            "| {name} | {} | {:.3} | {:.3} | {:.3} |",
            errors.estimator.len(),
            rms(&errors.estimator),
            rms(&errors.tracked),
            rms(&errors.perfect)
        );
    }
    Ok(())
}

/// The strongest contact's centre from stage 1 and stage 2 on these displacements (2 per corner, pad mm).
fn strongest_centre(model: &InverseModel, displacements: &[f64], valid: &[bool], floor_mm: f64) -> Option<Point2> {
    let stage = model.stage1(displacements, valid);
    let noise_mm = model.frame_noise_mm(&stage, floor_mm).max(floor_mm);
    let floor_n = model.test(&stage, noise_mm).detection_floor_n;
    let described = model.stage2(displacements, valid, &stage, noise_mm, floor_n);
    described.regions.first().map(|r| r.centre_mm)
}
