//! Camera bytes to reading: the time from the bytes a camera delivers (MJPEG or YUYV) to the estimator's reading,
//! per decode scale and mode, with what each costs in accuracy against a plain full decode, and the floors
//! measured in the same run (a memcpy of the frame; for JPEG, entropy-decoding the whole frame, which no JPEG path
//! avoids, a plain full decode with `image` and libjpeg-turbo's full decode; for YUYV, converting the whole frame).
//!
//! Times are the thread's CPU time (`CLOCK_THREAD_CPUTIME_ID`): one core's work, which a shared machine's other
//! load inflates far less than wall time. Wall medians are reported beside them.

use std::fmt::Write as _;
use std::sync::Arc;
use std::time::Instant;

use image::RgbImage;
use nusense_capture::{rgb_to_yuyv, yuyv_to_rgb, DecodeOptions, Decoder, FramePixels, PixelRect, Scale};
use nusense_estimator::{Estimator, Lattice, Mode, SensorConfig, PATTERN_REGION_MARGIN_CELLS};
use nusense_sim::{sweep, GroundTruth, Renderer, Scene, SensorModel};
use serde::Serialize;

use crate::metrics::{distance, quantile, rms};
use crate::report::Machine;

#[derive(Clone, Debug)]
pub struct DecodeBenchOptions {
    /// Timed repetitions per row.
    pub repeats: usize,
    /// Keep every n-th frame of the simulated position sweep.
    pub sweep_stride: usize,
    /// JPEG quality of the frames encoded here (a webcam's MJPEG is typically 80-90).
    pub camera_quality: u8,
    /// The real pair's folder; `None` leaves out its frame sets.
    pub real_dir: Option<std::path::PathBuf>,
}

impl DecodeBenchOptions {
    pub fn full() -> Self {
        Self {
            repeats: 30,
            sweep_stride: 1,
            camera_quality: 85,
            real_dir: None,
        }
    }

    pub fn quick() -> Self {
        Self {
            repeats: 10,
            sweep_stride: 4,
            ..Self::full()
        }
    }
}

/// One way of turning bytes into a reading.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Pathway {
    pub mode: Mode,
    pub scale: Scale,
    /// Only the pattern's region decoded (after the rest frame, which is always decoded whole).
    pub region: bool,
}

impl Pathway {
    pub fn name(&self) -> String {
        format!(
            "{} {}{}",
            self.mode,
            self.scale,
            if self.region { " region" } else { "" }
        )
    }
}

/// Every pathway measured: fast mode at each scale with the region, fast 1/2 of the whole frame (what the region
/// saves), and the paper's pipeline on a full decode.
pub fn pathways() -> Vec<Pathway> {
    let fast = |scale, region| Pathway {
        mode: Mode::Fast,
        scale,
        region,
    };
    vec![
        fast(Scale::Full, true),
        fast(Scale::Half, false),
        fast(Scale::Half, true),
        fast(Scale::Quarter, true),
        fast(Scale::Eighth, true),
        Pathway {
            mode: Mode::Paper,
            scale: Scale::Full,
            region: false,
        },
    ]
}

/// A time's median and p99, ms.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct Timing {
    pub cpu_median_ms: Option<f64>,
    pub cpu_p99_ms: Option<f64>,
    pub wall_median_ms: Option<f64>,
}

impl Timing {
    fn of(cpu_ms: &[f64], wall_ms: &[f64]) -> Self {
        Self {
            cpu_median_ms: quantile(cpu_ms, 0.5),
            cpu_p99_ms: quantile(cpu_ms, 0.99),
            wall_median_ms: quantile(wall_ms, 0.5),
        }
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct FloorResult {
    pub name: &'static str,
    pub timing: Timing,
}

#[derive(Clone, Debug, Serialize)]
pub struct PathwayResult {
    pub pathway: Pathway,
    pub name: String,
    /// Decoding alone, and decoding plus estimating: bytes to reading.
    pub decode: Timing,
    pub bytes_to_reading: Timing,
    /// Full-frame px decoded, as a fraction of the frame.
    pub decoded_fraction: Option<f64>,
    /// Real pair: the touch frame's corners against the plain full decode's (full-size px), and gamma's ratio.
    pub corner_rms_px: Option<f64>,
    pub corner_max_px: Option<f64>,
    pub gamma_ratio: Option<f64>,
    /// Simulated presses: contact centre against the truth, and against fast mode on a plain full decode.
    pub localisation_rmse_mm: Option<f64>,
    pub location_shift_rms_mm: Option<f64>,
    pub location_shift_max_mm: Option<f64>,
    pub error: Option<String>,
}

#[derive(Clone, Debug, Serialize)]
pub struct FrameSetResult {
    pub name: String,
    pub width: u32,
    pub height: u32,
    /// Bytes of the timed (touch) frame.
    pub frame_bytes: usize,
    pub floors: Vec<FloorResult>,
    pub pathways: Vec<PathwayResult>,
}

#[derive(Clone, Debug, Serialize)]
pub struct DecodeReport {
    pub repeats: usize,
    pub camera_quality: u8,
    pub sets: Vec<FrameSetResult>,
}

/// Camera frames (JPEG or YUYV bytes) with (for simulated sets) the truth of each press.
struct FrameSet {
    name: String,
    size: (u32, u32),
    reference: FramePixels,
    /// The frame timed (a press).
    touch: FramePixels,
    presses: Vec<(FramePixels, GroundTruth)>,
}

/// How a camera delivers its frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum CameraFormat {
    Mjpeg { quality: u8 },
    Yuyv,
}

impl CameraFormat {
    fn deliver(self, image: &RgbImage) -> FramePixels {
        match self {
            CameraFormat::Mjpeg { quality } => FramePixels::Jpeg(Arc::new(encode(image, quality))),
            CameraFormat::Yuyv => FramePixels::Yuyv {
                // Every frame here is an even number of pixels wide.
                bytes: Arc::new(rgb_to_yuyv(image).unwrap_or_default()),
                width: image.width(),
                height: image.height(),
            },
        }
    }

    fn label(self) -> String {
        match self {
            CameraFormat::Mjpeg { quality } => format!("JPEG q{quality}"),
            CameraFormat::Yuyv => "YUYV".into(),
        }
    }
}

/// The frame in RGB as a plain decoder gives it: the accuracy baseline.
fn plain_rgb(pixels: &FramePixels) -> Option<RgbImage> {
    match pixels {
        FramePixels::Jpeg(bytes) => image::load_from_memory(bytes).ok().map(|i| i.to_rgb8()),
        FramePixels::Yuyv { bytes, width, height } => yuyv_to_rgb(bytes, *width, *height),
        FramePixels::Rgb(image) => Some(image.as_ref().clone()),
    }
}

fn encode(image: &RgbImage, quality: u8) -> Vec<u8> {
    let mut bytes = Vec::new();
    // Writing an RGB8 image of valid size into a Vec cannot fail.
    let _ = image.write_with_encoder(image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, quality));
    bytes
}

fn simulated_set(
    size: (u32, u32),
    format: CameraFormat,
    options: &DecodeBenchOptions,
) -> Result<FrameSet, crate::BenchError> {
    let renderer = Renderer::new(SensorModel::real(size.0, size.1))?;
    let leds = [nusense_sim::NOMINAL_LED_CURRENT_MA; 4];
    let (reference, _) = renderer.render(&Scene::rest(), leds, 1)?;
    let mut presses = Vec::new();
    for (k, frame) in sweep::positions()
        .into_iter()
        .step_by(options.sweep_stride.max(1))
        .enumerate()
    {
        let (image, truth) = renderer.render(&frame.scene, leds, 100 + k as u64)?;
        presses.push((format.deliver(&image), truth));
    }
    let reference = format.deliver(&reference);
    let touch = presses
        .get(presses.len() / 2)
        .map_or_else(|| reference.clone(), |(pixels, _)| pixels.clone());
    Ok(FrameSet {
        name: format!("simulated, {}", format.label()),
        size,
        reference,
        touch,
        presses,
    })
}

fn real_sets(dir: &std::path::Path, quality: u8) -> Vec<FrameSet> {
    let (Ok(reference), Ok(touch)) = (
        std::fs::read(dir.join("reference_fisheye.jpg")),
        std::fs::read(dir.join("touch_fisheye.jpg")),
    ) else {
        return Vec::new();
    };
    let Ok(size) = nusense_capture::jpeg_dimensions(&reference) else {
        return Vec::new();
    };
    let (reference, touch) = (
        FramePixels::Jpeg(Arc::new(reference)),
        FramePixels::Jpeg(Arc::new(touch)),
    );
    let (Some(reference_rgb), Some(touch_rgb)) = (plain_rgb(&reference), plain_rgb(&touch)) else {
        return Vec::new();
    };
    let camera = CameraFormat::Mjpeg { quality };
    let small = (640, 480);
    let resize =
        |image: &RgbImage| image::imageops::resize(image, small.0, small.1, image::imageops::FilterType::Triangle);
    vec![
        FrameSet {
            name: "real pair, as shipped (q100)".into(),
            size,
            reference,
            touch,
            presses: Vec::new(),
        },
        FrameSet {
            name: format!("real pair, {}", camera.label()),
            size,
            reference: camera.deliver(&reference_rgb),
            touch: camera.deliver(&touch_rgb),
            presses: Vec::new(),
        },
        FrameSet {
            name: format!("real pair, {}", camera.label()),
            size: small,
            reference: camera.deliver(&resize(&reference_rgb)),
            touch: camera.deliver(&resize(&touch_rgb)),
            presses: Vec::new(),
        },
        FrameSet {
            name: "real pair, YUYV".into(),
            size: small,
            reference: CameraFormat::Yuyv.deliver(&resize(&reference_rgb)),
            touch: CameraFormat::Yuyv.deliver(&resize(&touch_rgb)),
            presses: Vec::new(),
        },
    ]
}

/// CPU time of this thread, s.
fn thread_cpu_s() -> f64 {
    let mut now = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime writes the timespec it is given.
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut now) };
    now.tv_sec as f64 + now.tv_nsec as f64 * 1e-9
}

/// Times `work` on `state` `repeats` times after one untimed run (`prepare` runs untimed before each).
fn time<S>(repeats: usize, state: &mut S, mut prepare: impl FnMut(&mut S), mut work: impl FnMut(&mut S)) -> Timing {
    prepare(state);
    work(state);
    let (mut cpu, mut wall) = (Vec::new(), Vec::new());
    for _ in 0..repeats.max(1) {
        prepare(state);
        let (cpu_start, wall_start) = (thread_cpu_s(), Instant::now());
        work(state);
        cpu.push((thread_cpu_s() - cpu_start) * 1e3);
        wall.push(wall_start.elapsed().as_secs_f64() * 1e3);
    }
    Timing::of(&cpu, &wall)
}

fn floors(set: &FrameSet, repeats: usize) -> Vec<FloorResult> {
    let touch = &set.touch;
    let mut copy = Vec::new();
    // Decoding the touch frame with `options`, through the decoder the pipelines use.
    let decoding = |name, options: &DecodeOptions| FloorResult {
        name,
        timing: time(
            repeats,
            &mut Decoder::new(),
            |_| {},
            |decoder| {
                let _ = std::hint::black_box(decoder.decode(touch, options));
            },
        ),
    };
    let bytes: &[u8] = match touch {
        FramePixels::Jpeg(bytes) | FramePixels::Yuyv { bytes, .. } => bytes,
        FramePixels::Rgb(image) => image.as_raw(),
    };
    let memcpy = FloorResult {
        name: "memcpy of the frame's bytes",
        timing: time(
            repeats,
            &mut copy,
            |_| {},
            |copy| {
                copy.clear();
                copy.extend_from_slice(bytes);
                std::hint::black_box(&copy);
            },
        ),
    };
    let FramePixels::Jpeg(jpeg_bytes) = touch else {
        return vec![memcpy, decoding("whole frame to RGB", &DecodeOptions::FULL)];
    };
    // Entropy-decoding the whole frame is what decoding its last rows costs: everything above them is
    // Huffman-decoded and skipped without IDCT.
    let last_rows = DecodeOptions {
        scale: Scale::Eighth,
        region: Some(PixelRect {
            x: 0,
            y: set.size.1.saturating_sub(8),
            width: set.size.0,
            height: 8,
        }),
    };
    vec![
        memcpy,
        decoding("entropy decoding alone (libjpeg-turbo, whole frame)", &last_rows),
        FloorResult {
            name: "plain full decode to RGB (`image`, zune-jpeg)",
            timing: time(
                repeats,
                &mut (),
                |_| {},
                |_| {
                    let _ = std::hint::black_box(image::load_from_memory(jpeg_bytes));
                },
            ),
        },
        decoding("full decode to RGB (libjpeg-turbo)", &DecodeOptions::FULL),
    ]
}

/// The estimator on the plain full decode: the accuracy baseline.
struct Baseline {
    touch: Option<(Lattice, f64)>,
    locations: Vec<Option<[f64; 2]>>,
}

fn baseline(set: &FrameSet) -> Baseline {
    let Some(mut estimator) =
        plain_rgb(&set.reference).and_then(|r| Estimator::new(SensorConfig::default(), Mode::Fast, &r).ok())
    else {
        return Baseline {
            touch: None,
            locations: vec![None; set.presses.len()],
        };
    };
    let touch = plain_rgb(&set.touch).and_then(|t| {
        let lattice = estimator.detect(&t).ok()?;
        Some((lattice, estimator.estimate(&t).ok()?.gamma.gamma))
    });
    let locations = set
        .presses
        .iter()
        .map(|(pixels, _)| {
            let reading = estimator.estimate(&plain_rgb(pixels)?).ok()?;
            reading.contact_mm()
        })
        .collect();
    Baseline { touch, locations }
}

/// One pathway's estimator and decoder, set up on the set's reference frame.
struct Pipeline {
    decoder: Decoder,
    estimator: Estimator,
    options: DecodeOptions,
}

impl Pipeline {
    fn new(set: &FrameSet, pathway: Pathway) -> Result<Self, String> {
        let mut decoder = Decoder::new();
        let reference = decoder
            .decode(&set.reference, &DecodeOptions::scaled(pathway.scale))
            .map_err(|e| e.to_string())?;
        let estimator =
            Estimator::new(SensorConfig::default(), pathway.mode, &reference.image).map_err(|e| e.to_string())?;
        let region = if pathway.region {
            let (min, max) = estimator.pattern_region_px().ok_or("no pattern region")?;
            Some(PixelRect::from_scaled_bounds(min, max, pathway.scale, set.size).ok_or("no pattern region")?)
        } else {
            None
        };
        Ok(Self {
            decoder,
            estimator,
            options: DecodeOptions {
                scale: pathway.scale,
                region,
            },
        })
    }

    fn decode(&mut self, frame: &FramePixels) -> Option<RgbImage> {
        self.decoder.decode(frame, &self.options).ok().map(|d| d.image)
    }
}

fn measure_pathway(set: &FrameSet, pathway: Pathway, base: &Baseline, repeats: usize) -> PathwayResult {
    let mut result = PathwayResult {
        pathway,
        name: pathway.name(),
        decode: Timing::default(),
        bytes_to_reading: Timing::default(),
        decoded_fraction: None,
        corner_rms_px: None,
        corner_max_px: None,
        gamma_ratio: None,
        localisation_rmse_mm: None,
        location_shift_rms_mm: None,
        location_shift_max_mm: None,
        error: None,
    };
    let mut pipeline = match Pipeline::new(set, pathway) {
        Ok(p) => p,
        Err(error) => {
            result.error = Some(error);
            return result;
        }
    };
    let (reference, touch) = (&set.reference, &set.touch);
    if let Ok(decoded) = pipeline.decoder.decode(touch, &pipeline.options) {
        let area = f64::from(decoded.decoded.width) * f64::from(decoded.decoded.height);
        result.decoded_fraction = Some(area / (f64::from(set.size.0) * f64::from(set.size.1)));
    }
    result.decode = time(
        repeats,
        &mut pipeline,
        |_| {},
        |pipeline| {
            let _ = std::hint::black_box(pipeline.decode(touch));
        },
    );
    // Rest and touch alternate so that the tracker predicts as in live use; only the touch frame is timed.
    let mut failed = None;
    result.bytes_to_reading = time(
        repeats,
        &mut pipeline,
        |pipeline| {
            if let Some(image) = pipeline.decode(reference) {
                let _ = pipeline.estimator.estimate(&image);
            }
        },
        |pipeline| match pipeline.decode(touch).map(|image| pipeline.estimator.estimate(&image)) {
            Some(Ok(reading)) => {
                std::hint::black_box(reading);
            }
            Some(Err(error)) => failed = Some(error.to_string()),
            None => failed = Some("the touch frame did not decode".into()),
        },
    );
    result.error = failed;

    if let (Some((full_lattice, full_gamma)), Some(image)) = (&base.touch, pipeline.decode(touch)) {
        if let Ok(lattice) = pipeline.estimator.detect(&image) {
            let d = f64::from(pathway.scale.divisor());
            let distances: Vec<f64> = full_lattice
                .corners
                .iter()
                .zip(&lattice.corners)
                .filter_map(|(a, b)| Some(distance(a.raw_px?, b.raw_px.map(|p| [p[0] * d, p[1] * d])?)))
                .collect();
            result.corner_rms_px = rms(&distances);
            result.corner_max_px = distances.iter().copied().reduce(f64::max);
        }
        if let Ok(reading) = pipeline.estimator.estimate(&image) {
            result.gamma_ratio = (full_gamma.abs() > f64::EPSILON).then(|| reading.gamma.gamma / full_gamma);
        }
    }

    let (mut to_truth, mut shifts) = (Vec::new(), Vec::new());
    for ((pixels, truth), full) in set.presses.iter().zip(&base.locations) {
        let found = pipeline
            .decode(pixels)
            .and_then(|image| pipeline.estimator.estimate(&image).ok())
            .and_then(|r| r.contact_mm());
        if let (Some(at), Some(contact)) = (found, truth.contacts.first()) {
            to_truth.push(distance(at, contact.centre_mm));
        }
        if let (Some(at), Some(full)) = (found, full) {
            shifts.push(distance(at, *full));
        }
    }
    result.localisation_rmse_mm = rms(&to_truth);
    result.location_shift_rms_mm = rms(&shifts);
    result.location_shift_max_mm = shifts.iter().copied().reduce(f64::max);
    result
}

/// Runs every frame set (simulated at 2048x1536 and 640x480 as MJPEG, and at 640x480 as YUYV; the real pair as
/// shipped, re-encoded, and at 640x480 as MJPEG and YUYV) through every pathway.
pub fn run_decode_bench(
    options: &DecodeBenchOptions,
    progress: &mut dyn FnMut(&str),
) -> Result<DecodeReport, crate::BenchError> {
    let mut sets = Vec::new();
    if let Some(dir) = &options.real_dir {
        sets.extend(real_sets(dir, options.camera_quality));
    }
    let mjpeg = CameraFormat::Mjpeg {
        quality: options.camera_quality,
    };
    // A YUYV camera is a 640x480 one: USB 2's bandwidth carries 2048x1536 YUYV at about 5 fps.
    for (size, format) in [
        (crate::FULL_SIZE, mjpeg),
        ((640, 480), mjpeg),
        ((640, 480), CameraFormat::Yuyv),
    ] {
        progress(&format!(
            "rendering the position sweep at {}x{} as {}",
            size.0,
            size.1,
            format.label()
        ));
        sets.push(simulated_set(size, format, options)?);
    }
    let mut results = Vec::new();
    for set in &sets {
        progress(&format!("decode floors: {} {}x{}", set.name, set.size.0, set.size.1));
        let floors = floors(set, options.repeats);
        let base = baseline(set);
        let pathways = pathways()
            .into_iter()
            .map(|pathway| {
                progress(&format!(
                    "{}: {} {}x{}",
                    pathway.name(),
                    set.name,
                    set.size.0,
                    set.size.1
                ));
                measure_pathway(set, pathway, &base, options.repeats)
            })
            .collect();
        results.push(FrameSetResult {
            name: set.name.clone(),
            width: set.size.0,
            height: set.size.1,
            frame_bytes: set.touch.byte_len(),
            floors,
            pathways,
        });
    }
    Ok(DecodeReport {
        repeats: options.repeats,
        camera_quality: options.camera_quality,
        sets: results,
    })
}

/// The bytes-to-reading tables: per frame set, the floors, then every pathway's time and accuracy.
pub fn markdown(report: &DecodeReport, machine: &Machine) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "# Camera bytes to reading (`nusense bench`)\n");
    let _ = writeln!(
        out,
        "Machine: {} ({} logical CPUs, `nproc`), {}; {} build; run {}.\n",
        machine.cpu_model, machine.logical_cpus, machine.os, machine.profile, machine.date_utc
    );
    let _ = writeln!(
        out,
        "From the camera's bytes (JPEG or YUYV) to the estimator's reading, one thread. Times are the thread's CPU time (median and \
         p99 of {} runs; wall median beside it). Region: only the rest frame's pattern plus {} cells decoded. \
         Accuracy against fast mode on a plain full decode (`image` for JPEG, the whole frame converted for YUYV): real pair, the touch frame's corners (RMS \
         and worst, full-size px) and gamma's ratio; simulated presses, the contact centre's RMSE against the truth \
         and its shift from the full decode's (RMS and worst, mm). Frames encoded here use quality {}.\n",
        report.repeats, PATTERN_REGION_MARGIN_CELLS, report.camera_quality
    );
    for set in &report.sets {
        let _ = writeln!(
            out,
            "## {} {}x{} ({} KiB per frame)\n",
            set.name,
            set.width,
            set.height,
            set.frame_bytes / 1024
        );
        let _ = writeln!(
            out,
            "| floor | CPU median ms | CPU p99 ms | wall median ms |\n|---|---|---|---|"
        );
        for floor in &set.floors {
            let t = &floor.timing;
            let _ = writeln!(
                out,
                "| {} | {} | {} | {} |",
                floor.name,
                opt(t.cpu_median_ms, 2),
                opt(t.cpu_p99_ms, 2),
                opt(t.wall_median_ms, 2)
            );
        }
        let _ = writeln!(
            out,
            "\n| mode, decode scale | decoded | decode ms | bytes→reading ms (p99) | wall ms | corners RMS / max px | gamma ratio | loc. RMSE mm | shift from full decode RMS / max mm |\n|---|---|---|---|---|---|---|---|---|"
        );
        for p in &set.pathways {
            let _ = writeln!(
                out,
                "| {} | {} | {} | {} ({}) | {} | {} / {} | {} | {} | {} / {} |",
                p.name,
                p.decoded_fraction
                    .map_or_else(|| "–".into(), |f| format!("{:.0} %", f * 100.0)),
                opt(p.decode.cpu_median_ms, 2),
                opt(p.bytes_to_reading.cpu_median_ms, 2),
                opt(p.bytes_to_reading.cpu_p99_ms, 2),
                opt(p.bytes_to_reading.wall_median_ms, 2),
                opt(p.corner_rms_px, 3),
                opt(p.corner_max_px, 2),
                opt(p.gamma_ratio, 3),
                opt(p.localisation_rmse_mm, 3),
                opt(p.location_shift_rms_mm, 3),
                opt(p.location_shift_max_mm, 3),
            );
        }
        let errors: Vec<String> = set
            .pathways
            .iter()
            .filter_map(|p| Some(format!("- {}: {}", p.name, p.error.as_ref()?)))
            .collect();
        if !errors.is_empty() {
            let _ = writeln!(out, "\nNotes:\n{}", errors.join("\n"));
        }
        let _ = writeln!(out);
    }
    out
}

fn opt(value: Option<f64>, digits: usize) -> String {
    value.map_or_else(|| "–".to_owned(), |v| format!("{v:.digits$}"))
}
