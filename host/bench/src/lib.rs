//! Speed against error for every estimator variant, measured in one run on the same frames.
//!
//! Variants: paper mode; fast mode at full, 1/2 and 1/4 resolution; several surface sample counts K; B-spline
//! degree p = q = 1 against p = q = 3. Each is scored on the simulated sweeps of the paper's experiments
//! (nusense-sim: a grid of press positions, force ramps for a sphere and a flat tip, edge angles) for
//! localisation RMSE, leave-one-out force error after calibration and edge-angle error, and on the real pair
//! ([`find_real_pair`]) for points found and gamma agreement. Speed is the median and p99 time of `estimate`
//! per frame, and a ratio against a baseline variant timed in the same run.

pub mod decode;
pub mod metrics;
pub mod report;
pub mod validation;

use std::path::{Path, PathBuf};
use std::time::Instant;

use image::RgbImage;
use nusense_estimator::calibration::CalibrationSample;
use nusense_estimator::{Estimator, Mode, SensorConfig, SurfaceConfig};
use nusense_sim::sweep::{self, SweepFrame};
use nusense_sim::{GroundTruth, Renderer, Scene, SensorModel};
use serde::Serialize;

use metrics::{distance, edge_angle_error_deg, leave_one_out_force_errors, quantile, rms};

/// The real sensor's frame size; "full resolution" of the benchmark.
pub const FULL_SIZE: (u32, u32) = (2048, 1536);

#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    #[error("the simulated sensor: {0}")]
    Model(#[from] nusense_sim::ModelError),
    #[error("rendering a sweep frame: {0}")]
    Render(#[from] nusense_sim::RenderError),
    #[error(transparent)]
    Validation(#[from] nusense_sim::validation::ValidationError),
    #[error("variant {variant}: the estimator cannot use the simulated rest frame: {source}")]
    Reference {
        variant: String,
        #[source]
        source: nusense_estimator::EstimateError,
    },
}

/// One estimator configuration under test.
#[derive(Clone, Debug, Serialize)]
pub struct Variant {
    pub name: String,
    pub mode: Mode,
    /// Frame size divisor against [`BenchOptions::full_size`] (1, 2 or 4).
    pub scale_divisor: u32,
    pub surface: SurfaceConfig,
}

impl Variant {
    fn new(name: &str, mode: Mode, scale_divisor: u32, surface: SurfaceConfig) -> Self {
        Self {
            name: name.to_owned(),
            mode,
            scale_divisor,
            surface,
        }
    }

    /// Surface samples per frame (K = samples per axis squared).
    pub fn samples_k(&self) -> usize {
        nusense_estimator::surface::uv_values(self.surface.uv_step).map_or(0, |v| v.len() * v.len())
    }

    fn config(&self) -> SensorConfig {
        SensorConfig {
            surface: self.surface,
            ..SensorConfig::default()
        }
    }
}

/// The variants of issue 7, the first one being the speed baseline.
pub fn standard_variants() -> Vec<Variant> {
    let default = SurfaceConfig::default();
    let with_step = |uv_step| SurfaceConfig { uv_step, ..default };
    let cubic = SurfaceConfig {
        degree_u: 3,
        degree_v: 3,
        ..default
    };
    vec![
        Variant::new("paper", Mode::Paper, 1, default),
        Variant::new("fast full", Mode::Fast, 1, default),
        Variant::new("fast 1/2", Mode::Fast, 2, default),
        Variant::new("fast 1/4", Mode::Fast, 4, default),
        Variant::new("fast K=10x10", Mode::Fast, 1, with_step(0.1)),
        Variant::new("fast K=34x34", Mode::Fast, 1, with_step(0.03)),
        Variant::new("fast K=100x100", Mode::Fast, 1, with_step(0.01)),
        Variant::new("fast p=q=3", Mode::Fast, 1, cubic),
    ]
}

#[derive(Clone, Debug)]
pub struct BenchOptions {
    pub full_size: (u32, u32),
    /// Keep every n-th frame of each sweep (1 = all).
    pub sweep_stride: usize,
    /// Times each frame is estimated for the timing statistics.
    pub timing_repeats: usize,
    /// Times the real touch frame is estimated for its timing statistics.
    pub real_repeats: usize,
    /// The real pair (reference_fisheye.jpg, touch_fisheye.jpg); `None` skips those columns.
    pub real_dir: Option<PathBuf>,
    pub variants: Vec<Variant>,
    pub seed: u64,
    /// Issue 12's figures for every estimator mode on the validation set of this profile; `None` skips them.
    pub validation: Option<nusense_sim::validation::Profile>,
}

impl BenchOptions {
    pub fn full() -> Self {
        Self {
            full_size: FULL_SIZE,
            sweep_stride: 1,
            timing_repeats: 3,
            real_repeats: 20,
            real_dir: None,
            variants: standard_variants(),
            seed: 7,
            validation: Some(nusense_sim::validation::Profile::Full),
        }
    }

    /// CI-sized: half-size "full" frames and a quarter of each sweep.
    pub fn quick() -> Self {
        Self {
            full_size: (FULL_SIZE.0 / 2, FULL_SIZE.1 / 2),
            sweep_stride: 4,
            timing_repeats: 1,
            validation: Some(nusense_sim::validation::Profile::Quick),
            ..Self::full()
        }
    }
}

/// Speed and errors of one variant.
#[derive(Clone, Debug, Serialize)]
pub struct VariantResult {
    pub variant: Variant,
    pub width: u32,
    pub height: u32,
    pub samples_k: usize,
    pub median_ms: Option<f64>,
    pub p99_ms: Option<f64>,
    /// Baseline median / this median on the real touch frame: how many times faster than the baseline. The
    /// real pair is the one input every variant (paper mode included) can measure.
    pub speedup: Option<f64>,
    pub localisation_rmse_mm: Option<f64>,
    /// Position-grid presses with no contact or no location (not in the RMSE).
    pub localisation_misses: usize,
    pub localisation_frames: usize,
    pub force_loo_rmse_n: Option<f64>,
    pub force_frames: usize,
    pub edge_angle_mae_deg: Option<f64>,
    /// Edge presses with no direction reported.
    pub edge_misses: usize,
    pub edge_frames: usize,
    /// Frames of the sweeps the estimator refused (typed errors).
    pub failed_frames: usize,
    pub real: Option<RealPairResult>,
    pub error: Option<String>,
}

/// The real pair at this variant's resolution.
#[derive(Clone, Debug, Serialize)]
pub struct RealPairResult {
    pub reference_corners: usize,
    pub touch_corners: Option<usize>,
    pub corners_expected: usize,
    pub gamma: Option<f64>,
    /// This variant's gamma over the baseline-resolution fast variant's gamma.
    pub gamma_ratio: Option<f64>,
    /// Median and p99 time of `estimate` on the touch frame, ms.
    pub median_ms: Option<f64>,
    pub p99_ms: Option<f64>,
    pub error: Option<String>,
}

#[derive(Clone, Debug, Serialize)]
pub struct BenchReport {
    pub baseline: String,
    pub full_size: (u32, u32),
    pub sweep_frames: usize,
    pub timing_repeats: usize,
    pub results: Vec<VariantResult>,
    pub validation: Option<validation::ValidationReport>,
    pub machine: report::Machine,
}

/// The rendered sweeps at one resolution.
struct Dataset {
    size: (u32, u32),
    reference: RgbImage,
    positions: Vec<(RgbImage, GroundTruth)>,
    forces: Vec<(RgbImage, GroundTruth)>,
    edges: Vec<(RgbImage, GroundTruth)>,
}

impl Dataset {
    fn frames(&self) -> impl Iterator<Item = &RgbImage> {
        self.positions
            .iter()
            .chain(&self.forces)
            .chain(&self.edges)
            .map(|(frame, _)| frame)
    }

    fn len(&self) -> usize {
        self.positions.len() + self.forces.len() + self.edges.len()
    }
}

fn strided(frames: Vec<SweepFrame>, stride: usize) -> Vec<Scene> {
    frames.into_iter().step_by(stride.max(1)).map(|f| f.scene).collect()
}

fn render_dataset(
    size: (u32, u32),
    options: &BenchOptions,
    progress: &mut dyn FnMut(&str),
) -> Result<Dataset, BenchError> {
    let renderer = Renderer::new(SensorModel::real(size.0, size.1))?;
    progress(&format!("rendering sweeps at {}x{}", size.0, size.1));
    let leds = [nusense_sim::NOMINAL_LED_CURRENT_MA; 4];
    let mut seed = options.seed;
    let mut render_all = |scenes: Vec<Scene>| -> Result<Vec<(RgbImage, GroundTruth)>, BenchError> {
        scenes
            .iter()
            .map(|scene| {
                seed += 1;
                Ok(renderer.render(scene, leds, seed)?)
            })
            .collect()
    };
    let reference = render_all(vec![Scene::rest()])?.remove(0).0;
    let positions = render_all(strided(sweep::positions(), options.sweep_stride))?;
    let forces = render_all(strided(sweep::forces(), options.sweep_stride))?;
    let edges = render_all(strided(sweep::edges(), options.sweep_stride))?;
    Ok(Dataset {
        size,
        reference,
        positions,
        forces,
        edges,
    })
}

fn scaled(size: (u32, u32), divisor: u32) -> (u32, u32) {
    (size.0 / divisor.max(1), size.1 / divisor.max(1))
}

/// The real pair, resized to `size` when it differs from the frames' own.
struct RealPair {
    reference: RgbImage,
    touch: RgbImage,
}

fn load_real_pair(dir: &Path) -> Option<RealPair> {
    let load = |name: &str| image::open(dir.join(name)).ok().map(|image| image.to_rgb8());
    Some(RealPair {
        reference: load("reference_fisheye.jpg")?,
        touch: load("touch_fisheye.jpg")?,
    })
}

fn resized(frame: &RgbImage, size: (u32, u32)) -> RgbImage {
    if frame.dimensions() == size {
        frame.clone()
    } else {
        image::imageops::resize(frame, size.0, size.1, image::imageops::FilterType::Triangle)
    }
}

/// Runs every variant; `progress` hears what is being done.
pub fn run_bench(options: &BenchOptions, progress: &mut dyn FnMut(&str)) -> Result<BenchReport, BenchError> {
    let mut datasets: Vec<Dataset> = Vec::new();
    let real = options.real_dir.as_deref().and_then(load_real_pair);
    let mut results = Vec::new();
    for variant in &options.variants {
        let size = scaled(options.full_size, variant.scale_divisor);
        if !datasets.iter().any(|d| d.size == size) {
            datasets.push(render_dataset(size, options, progress)?);
        }
        let dataset = datasets.iter().find(|d| d.size == size).expect("rendered above");
        progress(&format!("measuring {} at {}x{}", variant.name, size.0, size.1));
        let mut result = measure_variant(variant, dataset, options.timing_repeats);
        if let Some(real) = &real {
            let real_size = scaled(real.reference.dimensions(), variant.scale_divisor);
            result.real = Some(measure_real(variant, real, real_size, options.real_repeats));
        }
        results.push(result);
    }
    // Ratios against the baseline (the first variant) on the real pair, and gamma agreement against fast mode at
    // full size with the default surface, the shipped configuration.
    let real_median = |r: &VariantResult| r.real.as_ref().and_then(|real| real.median_ms);
    let baseline_median = results.first().and_then(real_median);
    for result in &mut results {
        result.speedup = match (baseline_median, real_median(result)) {
            (Some(base), Some(this)) if this > 0.0 => Some(base / this),
            _ => None,
        };
    }
    let shipped_gamma = results
        .iter()
        .find(|r| {
            r.variant.mode == Mode::Fast
                && r.variant.scale_divisor == 1
                && r.variant.surface == SurfaceConfig::default()
        })
        .and_then(|r| r.real.as_ref()?.gamma);
    for result in &mut results {
        if let Some(real) = &mut result.real {
            real.gamma_ratio = match (real.gamma, shipped_gamma) {
                (Some(gamma), Some(shipped)) if shipped.abs() > f64::EPSILON => Some(gamma / shipped),
                _ => None,
            };
        }
    }
    let validation = match options.validation {
        Some(profile) => Some(validation::run_validation(
            profile,
            options.seed,
            &validation::estimator_modes(),
            progress,
        )?),
        None => None,
    };
    Ok(BenchReport {
        validation,
        baseline: options.variants.first().map(|v| v.name.clone()).unwrap_or_default(),
        full_size: options.full_size,
        sweep_frames: datasets.first().map_or(0, Dataset::len),
        timing_repeats: options.timing_repeats,
        results,
        machine: report::Machine::this(),
    })
}

pub(crate) fn empty_result(variant: &Variant, size: (u32, u32)) -> VariantResult {
    VariantResult {
        variant: variant.clone(),
        width: size.0,
        height: size.1,
        samples_k: variant.samples_k(),
        median_ms: None,
        p99_ms: None,
        speedup: None,
        localisation_rmse_mm: None,
        localisation_misses: 0,
        localisation_frames: 0,
        force_loo_rmse_n: None,
        force_frames: 0,
        edge_angle_mae_deg: None,
        edge_misses: 0,
        edge_frames: 0,
        failed_frames: 0,
        real: None,
        error: None,
    }
}

fn measure_variant(variant: &Variant, data: &Dataset, repeats: usize) -> VariantResult {
    let mut result = empty_result(variant, data.size);
    let mut estimator = match Estimator::new(variant.config(), variant.mode, &data.reference) {
        Ok(estimator) => estimator,
        Err(error) => {
            result.error = Some(error.to_string());
            return result;
        }
    };

    // Timing: every sweep frame, `repeats` times, in sweep order (the fast tracker's prediction from the last
    // frame is part of what is timed, as in live use).
    let mut times_ms = Vec::new();
    for _ in 0..repeats.max(1) {
        for frame in data.frames() {
            let started = Instant::now();
            let outcome = estimator.estimate(frame);
            let elapsed = started.elapsed().as_secs_f64() * 1e3;
            if outcome.is_ok() {
                times_ms.push(elapsed);
            }
        }
    }
    result.median_ms = quantile(&times_ms, 0.5);
    result.p99_ms = quantile(&times_ms, 0.99);

    let mut failed = 0usize;
    let mut location_errors = Vec::new();
    for (frame, truth) in &data.positions {
        let reading = estimator.estimate(frame);
        let found = reading.as_ref().ok().and_then(|r| r.contact_mm());
        match (found, truth.contacts.first()) {
            (Some(at), Some(contact)) => location_errors.push(distance(at, contact.centre_mm)),
            _ => result.localisation_misses += 1,
        }
        failed += usize::from(reading.is_err());
    }
    result.localisation_frames = data.positions.len();
    result.localisation_rmse_mm = rms(&location_errors);

    // Force: gamma against the true force, per indenter, calibrated leave-one-out.
    let mut force_errors = Vec::new();
    let mut by_indenter: Vec<(&str, Vec<CalibrationSample>)> = Vec::new();
    for (frame, truth) in &data.forces {
        let reading = estimator.estimate(frame);
        failed += usize::from(reading.is_err());
        let (Ok(reading), Some(contact)) = (reading, truth.contacts.first()) else {
            continue;
        };
        let kind = match contact.indenter {
            nusense_sim::Indenter::Sphere { .. } => "sphere",
            nusense_sim::Indenter::FlatPunch { .. } => "flat punch",
            nusense_sim::Indenter::Edge { .. } => "edge",
        };
        let sample = CalibrationSample {
            gamma: reading.gamma.gamma,
            force_n: truth.total_force_n,
        };
        match by_indenter.iter_mut().find(|(k, _)| *k == kind) {
            Some((_, samples)) => samples.push(sample),
            None => by_indenter.push((kind, vec![sample])),
        }
    }
    for (_, samples) in &by_indenter {
        force_errors.extend(leave_one_out_force_errors(samples));
    }
    result.force_frames = data.forces.len();
    result.force_loo_rmse_n = rms(&force_errors);

    let mut angle_errors = Vec::new();
    for (frame, truth) in &data.edges {
        let reading = estimator.estimate(frame);
        failed += usize::from(reading.is_err());
        let found = reading.as_ref().ok().and_then(|r| r.edge_angle_deg());
        match (found, truth.contacts.first().and_then(|c| c.edge_angle_deg)) {
            (Some(found), Some(angle)) => angle_errors.push(edge_angle_error_deg(found, angle)),
            _ => result.edge_misses += 1,
        }
    }
    result.edge_frames = data.edges.len();
    result.edge_angle_mae_deg = metrics_mean(&angle_errors);
    result.failed_frames = failed;
    result
}

fn metrics_mean(values: &[f64]) -> Option<f64> {
    nusense_estimator::stats::mean(values)
}

fn measure_real(variant: &Variant, real: &RealPair, size: (u32, u32), repeats: usize) -> RealPairResult {
    let reference = resized(&real.reference, size);
    let touch = resized(&real.touch, size);
    let mut result = RealPairResult {
        reference_corners: 0,
        touch_corners: None,
        corners_expected: SensorConfig::default().pad.corner_count(),
        gamma: None,
        gamma_ratio: None,
        median_ms: None,
        p99_ms: None,
        error: None,
    };
    match Estimator::new(variant.config(), variant.mode, &reference) {
        Ok(mut estimator) => {
            result.reference_corners = estimator.reference_lattice().corners_found();
            match estimator.estimate(&touch) {
                Ok(reading) => {
                    result.touch_corners = Some(reading.counts.points_detected);
                    result.gamma = Some(reading.gamma.gamma);
                    // Alternate rest and touch, so the tracker's prediction is exercised as in live use.
                    let mut times_ms = Vec::new();
                    for _ in 0..repeats.max(1) {
                        let _ = estimator.estimate(&reference);
                        let started = Instant::now();
                        if estimator.estimate(&touch).is_ok() {
                            times_ms.push(started.elapsed().as_secs_f64() * 1e3);
                        }
                    }
                    result.median_ms = quantile(&times_ms, 0.5);
                    result.p99_ms = quantile(&times_ms, 0.99);
                }
                Err(error) => result.error = Some(error.to_string()),
            }
        }
        Err(error) => result.error = Some(error.to_string()),
    }
    result
}

/// The real pair's folder: the copy the project ships (`host/estimator/tests/data/real`), or `shared/data/real`
/// next to or above the repository, searched upwards from `start`.
pub fn find_real_pair(start: &Path) -> Option<PathBuf> {
    let compiled_in = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    start.ancestors().chain(compiled_in.ancestors()).find_map(|dir| {
        [
            "host/estimator/tests/data/real",
            "shared/data/real",
            "../shared/data/real",
        ]
        .iter()
        .map(|relative| dir.join(relative))
        .find(|candidate| candidate.join("reference_fisheye.jpg").is_file())
    })
}
