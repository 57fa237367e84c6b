//! Diagnostic: where the inverse's localisation error comes from, press by press on the validation set's presses.
//! `cargo run --release -p nusense-bench --example localisation_budget -- [quick|full]`; with
//! `NUSENSE_VALIDATION_CONFIG=SENSOR.toml` the estimator's model is that file's (the pad's own stack, say).
//!
//! Per press: the estimator's reading, and its inverse model's stage 1 and stage 2 (every corner valid in both
//! frames, stage 2 at the noise stage 1 leaves, never below `inverse.noise_floor_px`, and at the contact test's
//! floor) fed the corners' motion twice, both through the rest frame's pad map: as the tracker measured it, and as
//! the simulator's truth puts the corners in the image (a perfect tracker: the material corner, parallax included).
//! The estimator proper also leaves out the corners under the glare and makes further passes, so its column and the
//! tracked one differ a little (with `inverse.observe = "squares"` the estimator observes the squares, and the
//! corners' columns are a model of the same config observing the corners). Where the tracked column and the perfect one differ, the tracker's measurement makes
//! the error (its corner is the midpoint of two yellow squares' centroids, which a strain gradient moves off the
//! material corner); where the perfect one is off, the model does. The last two columns feed the same stages, of
//! models of the same config that observe the yellow squares instead (`InverseModel::observing_squares`), the
//! squares' motion as the tracker measured it (every square found in both frames): modelled at the squares'
//! centres, and as the mean motion of 3 x 3 points over each square's cell. For the set's edges, each column's edge
//! direction: the estimator's, and the second moments' major axis of the strongest region of the others
//! (`InverseModel::moments`, at `thresholds.edge_min_confidence`; "none" where it is round or missing).

use nusense_bench::validation::base_config_from_env;
use nusense_estimator::inverse::{InverseModel, Region};
use nusense_estimator::{Estimator, InverseConfig, Mode, ObservedPoints, SensorConfig};
use nusense_geometry::Point2;
use nusense_sim::validation::{CaseKind, Profile, ValidationRenderer, ValidationSet};
use nusense_sim::Indenter;

type Error = Box<dyn std::error::Error>;

/// The columns: what places the contact.
const COLUMNS: [&str; 5] = [
    "estimator",
    "tracked corners",
    "perfect tracker",
    "tracked squares, at centres",
    "tracked squares, 3 x 3 over each",
];

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
    let view = estimator.mapping().camera_view();
    // The corners' columns need a model of the corners, whatever `inverse.observe` gives the estimator.
    let corners_model = InverseModel::shared(
        &SensorConfig {
            inverse: InverseConfig {
                observe: ObservedPoints::Corners,
                ..config.inverse
            },
            ..config.clone()
        },
        view,
    )?;
    let square_models = [
        InverseModel::observing_squares(&config, view, 1)?,
        InverseModel::observing_squares(&config, view, 3)?,
    ];
    let rest_squares: Vec<Option<Point2>> = estimator
        .reference_lattice()
        .squares
        .iter()
        .map(|s| s.raw_px.and_then(|p| estimator.mapping().raw_to_mm(p)))
        .collect();
    // Squared errors per column, of spheres and of flat punches.
    let (mut spheres, mut flats) = (vec![Vec::new(); COLUMNS.len()], vec![Vec::new(); COLUMNS.len()]);
    println!("press, tip, force N, at mm: error mm of the {}", COLUMNS.join(" | "));
    // Per column, edges: the direction's error, deg (infinite where it has none).
    let mut edges = vec![Vec::new(); COLUMNS.len()];
    for case in set.of_kind(CaseKind::Press).chain(set.of_kind(CaseKind::Edge)) {
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
        let now = estimator.detect(&frame)?;
        let mut squares_moved = Vec::with_capacity(2 * now.squares.len());
        let mut squares_valid = Vec::with_capacity(now.squares.len());
        for (rest, seen) in rest_squares.iter().zip(&now.squares) {
            let moved = match (rest, seen.raw_px.and_then(|p| estimator.mapping().raw_to_mm(p))) {
                (Some(a), Some(b)) => Some([b[0] - a[0], b[1] - a[1]]),
                _ => None,
            };
            squares_valid.push(moved.is_some());
            squares_moved.extend(moved.unwrap_or([0.0, 0.0]));
        }
        let model = &*corners_model;
        let all = vec![true; valid.len()];
        let off = |found: Option<Point2>| {
            found.map_or(f64::INFINITY, |c| {
                (c[0] - contact.centre_mm[0]).hypot(c[1] - contact.centre_mm[1])
            })
        };
        let regions = [
            (model, strongest_region(model, &tracked, &valid, floor_mm)),
            (model, strongest_region(model, &perfect, &all, floor_mm)),
            (
                &square_models[0],
                strongest_region(&square_models[0], &squares_moved, &squares_valid, floor_mm),
            ),
            (
                &square_models[1],
                strongest_region(&square_models[1], &squares_moved, &squares_valid, floor_mm),
            ),
        ];
        if let Some(truth_deg) = contact.indenter.edge_angle_deg() {
            let min_confidence = config.thresholds.edge_min_confidence;
            let angles = std::iter::once(reading.edge_angle_deg()).chain(
                regions
                    .iter()
                    .map(|(m, r)| r.as_ref().and_then(|r| m.moments(r, min_confidence).angle_deg)),
            );
            let mut shown = Vec::new();
            for (column, angle) in edges.iter_mut().zip(angles) {
                let error = angle.map_or(f64::INFINITY, |a| {
                    let d = (a - truth_deg).rem_euclid(180.0);
                    d.min(180.0 - d)
                });
                shown.push(format!("{error:.2}"));
                column.push(error);
            }
            println!(
                "{}, edge at {truth_deg:.0} deg: error deg {}",
                case.name,
                shown.join(" | ")
            );
            continue;
        }
        let errors: Vec<f64> = std::iter::once(off(reading.touch.as_ref().map(|t| t.strongest.centre_mm)))
            .chain(regions.iter().map(|(_, r)| off(r.as_ref().map(|r| r.centre_mm))))
            .collect();
        let (name, kind) = match contact.indenter {
            Indenter::Sphere { radius_mm } => (format!("{radius_mm} mm sphere"), &mut spheres),
            Indenter::FlatPunch { radius_mm } => (format!("{radius_mm} mm flat punch"), &mut flats),
            Indenter::Edge { .. } => continue,
        };
        let shown: Vec<String> = errors.iter().map(|e| format!("{e:.3}")).collect();
        println!(
            "{}, {name}, {:.2}, ({:.1}, {:.1}): {}",
            case.name,
            contact.normal_force_n,
            contact.centre_mm[0],
            contact.centre_mm[1],
            shown.join(" | ")
        );
        for (column, error) in kind.iter_mut().zip(errors) {
            column.push(error * error);
        }
    }
    let rms = |squares: &[f64]| (squares.iter().sum::<f64>() / squares.len().max(1) as f64).sqrt();
    println!(
        "\n| presses | n | {}, RMS mm |\n|---|---|{}",
        COLUMNS.join(" | "),
        "---|".repeat(COLUMNS.len())
    );
    for (name, errors) in [("spheres", &spheres), ("flat punches", &flats)] {
        let shown: Vec<String> = errors.iter().map(|e| format!("{:.3}", rms(e))).collect();
        println!("| {name} | {} | {} |", errors[0].len(), shown.join(" | "));
    }
    let shown: Vec<String> = edges
        .iter()
        .map(|e| {
            let found: Vec<f64> = e.iter().copied().filter(|x| x.is_finite()).collect();
            let mean = found.iter().sum::<f64>() / found.len().max(1) as f64;
            let max = found.iter().copied().fold(0.0, f64::max);
            format!("{mean:.2} / {max:.2} ({} none)", e.len() - found.len())
        })
        .collect();
    println!("| edges, mean / max deg | {} | {} |", edges[0].len(), shown.join(" | "));
    Ok(())
}

/// The strongest contact from stage 1 and stage 2 on these displacements (2 per observed point, pad mm).
fn strongest_region(model: &InverseModel, displacements: &[f64], valid: &[bool], floor_mm: f64) -> Option<Region> {
    let stage = model.stage1(displacements, valid);
    let noise_mm = model.frame_noise_mm(&stage, floor_mm).max(floor_mm);
    let floor_n = model.test(&stage, noise_mm).detection_floor_n;
    let described = model.stage2(displacements, valid, &stage, noise_mm, floor_n);
    described.regions.into_iter().next()
}
