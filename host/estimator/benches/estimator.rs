//! Speed per stage and per frame, fast, inverse and paper mode, on the real frames at full, 1/2 and 1/4 size and at
//! 640x480. `cargo bench -p nusense-estimator` (add `-- --quick` for a short run). After criterion's own report it
//! prints a table of ms per frame of every mode measured in the same run (thread CPU time, and wall time), with the
//! ratios between them. `-- table` (a filter no criterion benchmark matches) prints the table alone. A second table
//! times the inverse on a 20 mm edge press of the validation sensor with the edge direction from the moments (the
//! default) and from the line load (`inverse.edge_from_line`), in the same run; a third the inverse on the real pair
//! with the defaults' stack held in a frame, observing the corners and the squares (`inverse.observe`), against the
//! default.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use criterion::{black_box, Criterion};
use image::{imageops, RgbImage};
use nusense_estimator::contact::{divergence_centre, fit_affine_motion, FieldPoint};
use nusense_estimator::registration::register;
use nusense_estimator::shear::{gamma, ShearSampler};
use nusense_estimator::{ElasticConfig, Estimator, Mode, ObservedPoints, SensorConfig};
use nusense_sim::validation::{Case, CaseKind, ValidationRenderer};
use nusense_sim::{Contact, Scene};

fn load(name: &str) -> RgbImage {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/real");
    image::open(dir.join(name))
        .expect("the real frames are part of the shared data")
        .to_rgb8()
}

fn sizes() -> Vec<(&'static str, RgbImage, RgbImage)> {
    let (reference, touch) = (load("reference_fisheye.jpg"), load("touch_fisheye.jpg"));
    let scaled = |image: &RgbImage, d: u32| {
        imageops::resize(
            image,
            image.width() / d,
            image.height() / d,
            imageops::FilterType::Triangle,
        )
    };
    vec![
        ("2048x1536", reference.clone(), touch.clone()),
        ("1024x768", scaled(&reference, 2), scaled(&touch, 2)),
        ("512x384", scaled(&reference, 4), scaled(&touch, 4)),
        (
            "640x480",
            imageops::resize(&reference, 640, 480, imageops::FilterType::Triangle),
            imageops::resize(&touch, 640, 480, imageops::FilterType::Triangle),
        ),
    ]
}

fn fast_stages(c: &mut Criterion, label: &str, reference: &RgbImage, touch: &RgbImage) {
    let config = SensorConfig::default();
    let mut estimator = Estimator::new(config.clone(), Mode::Fast, reference).expect("reference");
    let lattice = estimator.detect(touch).expect("touch");
    let registration = register(
        estimator.reference_lattice(),
        &lattice,
        config.thresholds.max_displacement_cells,
    );
    let mapping = estimator.mapping().clone();
    let paper = |c: Option<[f64; 2]>| c.map(|p| mapping.to_paper(p)).unwrap_or([0.0, 0.0]);
    let valid: Vec<bool> = registration.corners.iter().map(|c| c.valid).collect();
    let reference_px: Vec<[f64; 2]> = estimator
        .reference_lattice()
        .corners
        .iter()
        .map(|c| paper(c.undistorted_px))
        .collect();
    let current_px: Vec<[f64; 2]> = lattice.corners.iter().map(|c| paper(c.undistorted_px)).collect();
    let reference_valid: Vec<bool> = estimator
        .reference_lattice()
        .corners
        .iter()
        .map(|c| c.undistorted_px.is_some())
        .collect();
    let sampler = ShearSampler::new(11, 15, &config.surface, &reference_px, &reference_valid).expect("surface");
    let field: Vec<FieldPoint> = reference_px
        .iter()
        .zip(&current_px)
        .map(|(r, c)| FieldPoint {
            position: *r,
            displacement: [c[0] - r[0], c[1] - r[1]],
        })
        .collect();

    let mut group = c.benchmark_group(format!("fast/{label}"));
    group.bench_function("1 detect (track lattice)", |b| {
        b.iter(|| estimator.detect(black_box(touch)).unwrap())
    });
    group.bench_function("2 register", |b| {
        b.iter(|| {
            register(
                estimator.reference_lattice(),
                black_box(&lattice),
                config.thresholds.max_displacement_cells,
            )
        })
    });
    group.bench_function("3 surface + gamma", |b| {
        b.iter(|| gamma(&sampler.sample(black_box(&current_px), &valid).unwrap(), 1.0 / 18000.0))
    });
    group.bench_function("4 contact (affine + centre)", |b| {
        b.iter(|| {
            let motion = fit_affine_motion(black_box(&field)).unwrap();
            let residuals: Vec<[f64; 2]> = field.iter().map(|p| motion.residual(p)).collect();
            divergence_centre(&field, &residuals)
        })
    });
    group.bench_function("frame (estimate)", |b| {
        b.iter(|| estimator.estimate(black_box(touch)).unwrap())
    });
    group.finish();
}

fn inverse_frame(c: &mut Criterion, label: &str, reference: &RgbImage, touch: &RgbImage) {
    let mut estimator = Estimator::new(SensorConfig::default(), Mode::Inverse, reference).expect("reference");
    let mut group = c.benchmark_group(format!("inverse/{label}"));
    group.bench_function("frame (estimate)", |b| {
        b.iter(|| estimator.estimate(black_box(touch)).unwrap())
    });
    group.finish();
}

fn paper_frame(c: &mut Criterion, label: &str, reference: &RgbImage, touch: &RgbImage) {
    let Ok(mut estimator) = Estimator::new(SensorConfig::default(), Mode::Paper, reference) else {
        eprintln!("paper mode unavailable at {label}");
        return;
    };
    let mut group = c.benchmark_group(format!("paper/{label}"));
    group.sample_size(10);
    group.bench_function("frame (estimate)", |b| b.iter(|| estimator.estimate(black_box(touch))));
    group.finish();
}

/// The published pipeline's stages (paper mode), each on its own input from the stage before.
fn paper_stages(c: &mut Criterion, label: &str, touch: &RgbImage) {
    use nusense_estimator::paper::PaperDetector;
    let Ok(detector) = PaperDetector::new(&SensorConfig::default(), touch.width(), touch.height()) else {
        return;
    };
    let Ok(gray) = detector.undistorted_roi_gray(touch) else {
        return;
    };
    let edges = detector.edge_map(&gray);
    let quads = detector.quads(&edges);
    let mut group = c.benchmark_group(format!("paper/{label}"));
    group.sample_size(10);
    group.bench_function("1 remap + grey", |b| {
        b.iter(|| detector.undistorted_roi_gray(black_box(touch)))
    });
    group.bench_function("2 bilateral + Sobel + closing", |b| {
        b.iter(|| detector.edge_map(black_box(&gray)))
    });
    group.bench_function("3 contours + quads", |b| b.iter(|| detector.quads(black_box(&edges))));
    group.bench_function("4 pairing + lattice indices", |b| {
        b.iter(|| detector.index(touch, black_box(&quads)))
    });
    group.finish();
}

/// CPU time of this thread, s: on a machine shared with other builds, the work itself, not the waits for a core.
fn thread_cpu_s() -> f64 {
    let mut now = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime writes the timespec it is given.
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut now) };
    now.tv_sec as f64 + now.tv_nsec as f64 * 1e-9
}

/// Mean ms per `estimate` over `repeats` frames (after one warm-up frame), (thread CPU, wall); `None` if the mode
/// fails.
fn ms_per_frame(mode: Mode, reference: &RgbImage, touch: &RgbImage, repeats: usize) -> Option<(f64, f64)> {
    ms_per_frame_with(SensorConfig::default(), mode, reference, touch, repeats)
}

/// [`ms_per_frame`] with the sensor config `config`.
fn ms_per_frame_with(
    config: SensorConfig,
    mode: Mode,
    reference: &RgbImage,
    touch: &RgbImage,
    repeats: usize,
) -> Option<(f64, f64)> {
    let mut estimator = Estimator::new(config, mode, reference).ok()?;
    estimator.estimate(touch).ok()?;
    let (cpu, wall) = (thread_cpu_s(), Instant::now());
    for _ in 0..repeats {
        black_box(estimator.estimate(touch).ok()?);
    }
    let per_frame = |s: f64| s * 1e3 / repeats as f64;
    Some((per_frame(thread_cpu_s() - cpu), per_frame(wall.elapsed().as_secs_f64())))
}

fn main() {
    let mut c = Criterion::default()
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(2))
        .configure_from_args();
    let frames = sizes();
    for (label, reference, touch) in &frames {
        fast_stages(&mut c, label, reference, touch);
        inverse_frame(&mut c, label, reference, touch);
        paper_frame(&mut c, label, reference, touch);
        paper_stages(&mut c, label, touch);
    }
    c.final_summary();

    println!(
        "\nms per frame (estimate only, no decoding; thread CPU time, wall time in brackets), every mode in this run:"
    );
    println!(
        "{:>10} {:>18} {:>18} {:>20} {:>13} {:>11}",
        "size", "fast", "inverse", "paper", "inverse/fast", "paper/fast"
    );
    for (label, reference, touch) in &frames {
        let fast = ms_per_frame(Mode::Fast, reference, touch, 200);
        let inverse = ms_per_frame(Mode::Inverse, reference, touch, 200);
        let paper = ms_per_frame(Mode::Paper, reference, touch, 3);
        println!(
            "{label:>10} {:>18} {:>18} {:>20} {:>13} {:>11}",
            show(fast),
            show(inverse),
            show(paper),
            ratio(inverse, fast, 2),
            ratio(paper, fast, 0)
        );
    }
    observed_points_table(&frames);
    edge_direction_table();
}

/// The inverse's ms per frame on the real pair with the defaults' stack held in a frame (`elastic.model = "layered"`,
/// sliding walls 4 mm beyond the pattern), observing the corners and the squares (`inverse.observe`), against the
/// default (the equivalent layer, the corners).
fn observed_points_table(frames: &[(&'static str, RgbImage, RgbImage)]) {
    let in_a_frame = |observe: ObservedPoints| {
        let mut config = SensorConfig {
            elastic: ElasticConfig::layered_in_a_frame(),
            ..SensorConfig::default()
        };
        config.inverse.observe = observe;
        config
    };
    println!(
        "\ninverse ms per frame, the defaults' stack held in a frame, observing corners or squares (thread CPU, wall):"
    );
    println!(
        "{:>10} {:>18} {:>18} {:>18} {:>16} {:>16}",
        "size", "default", "frame, corners", "frame, squares", "corners/default", "squares/default"
    );
    for (label, reference, touch) in frames {
        let default = ms_per_frame(Mode::Inverse, reference, touch, 200);
        let corners = ms_per_frame_with(
            in_a_frame(ObservedPoints::Corners),
            Mode::Inverse,
            reference,
            touch,
            200,
        );
        let squares = ms_per_frame_with(
            in_a_frame(ObservedPoints::Squares),
            Mode::Inverse,
            reference,
            touch,
            200,
        );
        println!(
            "{label:>10} {:>18} {:>18} {:>18} {:>16} {:>16}",
            show(default),
            show(corners),
            show(squares),
            ratio(corners, default, 2),
            ratio(squares, default, 2)
        );
    }
}

/// The inverse's ms per frame on an edge press of the validation sensor, the edge direction from the moments and
/// from the line load, and their ratio.
fn edge_direction_table() {
    const SIZE: (u32, u32) = (1024, 768);
    let renderer = ValidationRenderer::new(SIZE).expect("the validation sensor renders");
    let reference = renderer.reference(7).expect("its rest frame");
    let case = Case::still(
        "edge",
        CaseKind::Edge,
        SIZE,
        Scene::with_contact(Contact::edge(20.0, 1.0, 85.0, [3.0, 3.0], 5.0)),
        3,
    );
    let (edge, _) = renderer.render(&case).expect("the edge press renders");
    let mut line = SensorConfig::default();
    line.inverse.edge_from_line = true;
    let moments = ms_per_frame(Mode::Inverse, &reference, &edge, 100);
    let line = ms_per_frame_with(line, Mode::Inverse, &reference, &edge, 100);
    println!(
        "\ninverse ms per frame on a 5 N, 20 mm edge press of the validation sensor at 1024x768 (thread CPU, wall):"
    );
    println!("{:>18} {:>18} {:>15}", "moments", "line load", "line/moments");
    println!(
        "{:>18} {:>18} {:>15}",
        show(moments),
        show(line),
        ratio(line, moments, 2)
    );
}

/// A [`ms_per_frame`] as "cpu (wall)", or "n/a".
fn show(v: Option<(f64, f64)>) -> String {
    v.map(|(cpu, wall)| format!("{cpu:.3} ({wall:.3})"))
        .unwrap_or_else(|| "n/a".into())
}

/// The ratio of two [`ms_per_frame`]s' CPU times with `digits` decimals, or "n/a".
fn ratio(a: Option<(f64, f64)>, b: Option<(f64, f64)>, digits: usize) -> String {
    match (a, b) {
        (Some((a, _)), Some((b, _))) if b > 0.0 => format!("{:.digits$}x", a / b),
        _ => "n/a".into(),
    }
}
