//! Scores every mode on simulated frames (nusense-sim) against the ground truth and prints one table per figure:
//! `cargo run --release -p nusense-estimator --example evaluate -- [WIDTH] [figure...]`.
//! Figures: rest, positions, forces, rotation, two, shear, edges, floor. A development tool: the project's
//! benchmark table is `nusense bench`.

use nusense_estimator::{Estimator, Mode, Reading, SensorConfig};
use nusense_sim::{Contact, Renderer, Scene, SensorModel};

const LEDS: [f32; 4] = [100.0; 4];

struct Bench {
    renderer: Renderer,
    reference: image::RgbImage,
    config: SensorConfig,
}

impl Bench {
    fn new(model: SensorModel, config: SensorConfig) -> Self {
        let renderer = Renderer::new(model).expect("model");
        let (reference, _) = renderer.render(&Scene::rest(), LEDS, 0).expect("rest");
        Self {
            renderer,
            reference,
            config,
        }
    }

    fn estimator(&self, mode: Mode) -> Estimator {
        Estimator::new(self.config.clone(), mode, &self.reference).expect("reference")
    }

    fn read(&self, mode: Mode, scene: &Scene, seed: u64) -> (Option<Reading>, nusense_sim::GroundTruth) {
        let (frame, truth) = self.renderer.render(scene, LEDS, seed).expect("scene");
        let reading = self.estimator(mode).estimate(&frame).map_err(|e| eprintln!("{e}")).ok();
        (reading, truth)
    }
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

/// Both modes, in the order the tables list them.
const MODES: [Mode; 2] = [Mode::Inverse, Mode::Fast];

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let width: u32 = args.first().and_then(|a| a.parse().ok()).unwrap_or(640);
    let figures: Vec<&str> = args.iter().skip(1).map(String::as_str).collect();
    let wants = |f: &str| figures.is_empty() || figures.contains(&f);
    let bench = Bench::new(SensorModel::real(width, width * 3 / 4), config_from_env());
    if wants("rest") {
        rest(&bench);
    }
    if wants("positions") {
        positions(&bench);
    }
    if wants("forces") {
        forces(&bench);
    }
    if wants("rotation") {
        rotation(&bench, width);
    }
    if wants("two") {
        two(&bench);
    }
    if wants("shear") {
        shear(&bench);
    }
    if wants("edges") {
        edges(&bench);
    }
    if wants("floor") {
        floor(&bench);
    }
}

/// The default configuration, with the elastic model overridden by EVAL_ELASTIC = "half:DEPTH" or
/// "layer:COVER:GEL:BORDER(0|1)".
fn config_from_env() -> SensorConfig {
    let mut config = SensorConfig::default();
    if let Ok(spec) = std::env::var("EVAL_ELASTIC") {
        let parts: Vec<&str> = spec.split(':').collect();
        let num = |i: usize| parts[i].parse::<f64>().expect("number");
        match parts[0] {
            "half" => {
                config.elastic.model = nusense_estimator::ElasticModel::HalfSpace;
                config.elastic.cover_mm = num(1);
            }
            _ => {
                config.elastic.cover_mm = num(1);
                config.elastic.gel_mm = num(2);
                config.elastic.bonded_border = parts[3] == "1";
            }
        }
    }
    config
}

/// Ten rest frames per mode: false contacts, the noise and the detection floor.
fn rest(bench: &Bench) {
    for mode in MODES {
        let mut contacts = 0;
        let mut noise = Vec::new();
        let mut floor = Vec::new();
        for seed in 1..=10 {
            let (r, _) = bench.read(mode, &Scene::rest(), seed);
            if let Some(r) = r {
                contacts += usize::from(r.is_contact());
                noise.push(r.test.noise_mm);
                floor.push(r.test.detection_floor_n);
                if seed == 1 {
                    println!(
                        "rest {mode}: stat {:.1} thr {:.1} p {:.3}",
                        r.test.statistic, r.test.threshold, r.test.p_value
                    );
                }
            }
        }
        println!(
            "rest {mode}: {contacts}/10 contacts, noise {:.4} mm, floor {:.3} N",
            noise.iter().sum::<f64>() / noise.len() as f64,
            floor.iter().sum::<f64>() / floor.len() as f64
        );
    }
}

/// The simulator's sweep of press positions: location error and how evenly one press reads across the pad.
fn positions(bench: &Bench) {
    for mode in MODES {
        let (mut loc, mut force) = (Vec::new(), Vec::new());
        for (k, frame) in nusense_sim::sweep::positions().iter().enumerate() {
            let (r, truth) = bench.read(mode, &frame.scene, k as u64 + 1);
            let t = &truth.contacts[0];
            match r.as_ref().and_then(|r| r.contact_mm().map(|c| (c, r.force_n()))) {
                Some((c, f)) => {
                    loc.push((c[0] - t.centre_mm[0]).hypot(c[1] - t.centre_mm[1]));
                    force.push(f);
                }
                None => println!("  {mode}: missed {:?}", t.centre_mm),
            }
        }
        let mean = force.iter().sum::<f64>() / force.len().max(1) as f64;
        let spread: Vec<f64> = force.iter().map(|f| f / mean - 1.0).collect();
        println!(
            "positions {mode}: {} found, loc RMSE {:.3} mm (worst {:.3}), force mean {:.3} N, spread {:.1} % RMS, range {:.2}..{:.2}",
            loc.len(),
            rms(&loc),
            loc.iter().copied().fold(0.0, f64::max),
            mean,
            100.0 * rms(&spread),
            force.iter().copied().fold(f64::MAX, f64::min),
            force.iter().copied().fold(0.0, f64::max),
        );
    }
}

/// Presses of 1 to 8 N by two indenters at three places, scaled by one fitted factor: how linear the force is.
fn forces(bench: &Bench) {
    for mode in MODES {
        for (label, make) in [
            (
                "sphere5",
                Box::new(|f: f64, p: [f64; 2]| Contact::sphere(5.0, p, f)) as Box<dyn Fn(f64, [f64; 2]) -> Contact>,
            ),
            ("punch3", Box::new(|f: f64, p: [f64; 2]| Contact::flat_punch(3.0, p, f))),
        ] {
            forces_of(bench, mode, label, make.as_ref());
        }
    }
}

/// One row of [`forces`]: one mode, one indenter.
fn forces_of(bench: &Bench, mode: Mode, label: &str, make: &dyn Fn(f64, [f64; 2]) -> Contact) {
    let mut pairs = Vec::new();
    for (k, &f) in [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0].iter().enumerate() {
        for p in [[0.0, 0.0], [15.0, 10.0], [-20.0, -12.0]] {
            let (r, _) = bench.read(mode, &Scene::with_contact(make(f, p)), 100 + k as u64);
            pairs.push((f, r.map_or(0.0, |r| r.force_n()), p));
        }
    }
    let scale = pairs.iter().map(|p| p.0 * p.1).sum::<f64>() / pairs.iter().map(|p| p.1 * p.1).sum::<f64>();
    let errors: Vec<f64> = pairs.iter().map(|p| p.1 * scale - p.0).collect();
    println!(
        "forces {mode} {label}: one scale {scale:.3}, RMS error {:.3} N",
        rms(&errors)
    );
    for p in &pairs {
        print!("({:.0}:{:.2}) ", p.0, p.1 * scale);
    }
    println!();
}

/// The camera turned and shifted against the pad after the reference: a rest frame and a press through it.
fn rotation(bench: &Bench, width: u32) {
    for mode in MODES {
        for degrees in [0.0, 1.0, 2.0, 5.0] {
            let mut model = SensorModel::real(width, width * 3 / 4);
            model.pose.rotation_deg[2] += degrees;
            model.pose.shift_mm[0] += 0.3 * degrees;
            let moved = Renderer::new(model).unwrap();
            let mut estimator = bench.estimator(mode);
            let (rest, _) = moved.render(&Scene::rest(), LEDS, 7).unwrap();
            let r = estimator.estimate(&rest).ok();
            let (press, truth) = moved
                .render(&Scene::with_contact(Contact::sphere(5.0, [4.0, -3.0], 4.0)), LEDS, 8)
                .unwrap();
            let p = estimator.estimate(&press).ok();
            println!(
                "rotation {mode} {degrees} deg: rest contact {:?} rot {:?}; press {:?} N at {:?} (truth {:?}), rot {:?}",
                r.as_ref().map(|r| r.is_contact()),
                r.as_ref().map(|r| r.camera_motion.rotation_deg),
                p.as_ref().map(|r| r.force_n()),
                p.as_ref().and_then(|r| r.contact_mm()),
                truth.contacts[0].centre_mm,
                p.as_ref().map(|r| r.camera_motion),
            );
        }
    }
}

/// Two presses side by side (inverse mode): each contact's place and force.
fn two(bench: &Bench) {
    let scene = Scene {
        contacts: vec![
            Contact::sphere(3.0, [-5.0, 2.0], 3.0),
            Contact::sphere(3.0, [5.0, 2.0], 2.0),
        ],
        ..Scene::default()
    };
    let (r, _) = bench.read(Mode::Inverse, &scene, 9);
    if let Some(r) = r {
        for c in r.contacts() {
            println!("two: contact at {:.2?} mm, {:.2} N", c.centre_mm, c.force_n);
        }
    }
}

/// Shear in four directions and a twist (inverse mode): the force vector's direction and the torque.
fn shear(bench: &Bench) {
    for angle in [0.0f64, 60.0, 135.0, 250.0] {
        let mut contact = Contact::sphere(5.0, [2.0, 1.0], 5.0);
        let (s, c) = angle.to_radians().sin_cos();
        contact.tangential_force_n = [1.5 * c, 1.5 * s];
        let (r, _) = bench.read(Mode::Inverse, &Scene::with_contact(contact), 10);
        if let Some(v) = r.as_ref().and_then(|r| r.touch.as_ref()).and_then(|t| t.force_vector_n) {
            println!(
                "shear {angle}: vector {v:.3?}, direction {:.1} deg",
                v[1].atan2(v[0]).to_degrees().rem_euclid(360.0)
            );
        }
    }
    let mut twist = Contact::sphere(5.0, [0.0, 0.0], 5.0);
    twist.torsion_nmm = 5.0;
    let (r, _) = bench.read(Mode::Inverse, &Scene::with_contact(twist), 11);
    println!(
        "twist 5 N mm: torque {:?}",
        r.and_then(|r| r.touch.and_then(|t| t.torque_nmm))
    );
}

/// A straight edge at nine angles: the found angle's error (90 degrees where none was found).
fn edges(bench: &Bench) {
    for mode in MODES {
        let mut errors = Vec::new();
        for angle in [0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.0, 120.0, 165.0] {
            let (r, _) = bench.read(
                mode,
                &Scene::with_contact(Contact::edge(20.0, 1.0, angle, [0.0, 0.0], 8.0)),
                12,
            );
            let found = r.and_then(|r| r.edge_angle_deg());
            let e = found.map(|f| {
                let d = (f - angle).rem_euclid(180.0);
                d.min(180.0 - d)
            });
            errors.push(e.unwrap_or(90.0));
        }
        println!("edges {mode}: errors {errors:.1?}");
    }
}

/// Light presses, four noise seeds each: how many are seen as contacts.
fn floor(bench: &Bench) {
    for mode in MODES {
        let mut line = String::new();
        for f in [0.1, 0.2, 0.3, 0.5, 0.75, 1.0] {
            let mut hits = 0;
            for seed in 0..4 {
                let (r, _) = bench.read(
                    mode,
                    &Scene::with_contact(Contact::sphere(5.0, [3.0, 2.0], f)),
                    200 + seed,
                );
                hits += usize::from(r.is_some_and(|r| r.is_contact()));
            }
            line += &format!("{f} N: {hits}/4  ");
        }
        println!("floor {mode}: {line}");
    }
}
