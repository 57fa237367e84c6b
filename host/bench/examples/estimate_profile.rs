//! The estimator's per-frame work alone, for profilers (`valgrind --tool=callgrind`, `perf`) and for checking
//! that a speed change leaves the readings as they were:
//!
//! - `cargo run --release -p nusense-bench --example estimate_profile -- run MODE WxH REPEATS [DECODE_SCALE]`
//!   renders the validation sensor's rest frame and a 5 N press at that size (JPEG q85, decoded once), builds
//!   the estimator in MODE (fast, inverse, paper) and runs `estimate` REPEATS times on the press; with
//!   DECODE_SCALE (1, 2, 4, 8) each repeat decodes the press's JPEG bytes first (the pattern's region at that
//!   scale, as the daemon does), i.e. camera bytes to reading. Prints CPU ms per frame. The two frames are
//!   rendered once and kept in `$NUSENSE_PROFILE_CACHE` (else the temporary folder).
//! - `... -- dump OUT CACHE_DIR [full]` writes every reading (elapsed time zeroed) of the quick validation set (the
//!   full one with `full`) in fast and inverse modes to OUT, to diff before and after a change, and prints CPU ms
//!   per frame for each mode and size (the frames are rendered once into CACHE_DIR as raw RGB: about 3.8 GB for
//!   the full set).
//! - `... -- time MODE CACHE_DIR PASSES [quick|full]` times MODE alone on the set's main-size frames (those of `dump`'s
//!   cache, rendered there if missing), PASSES times over the set, the frames read in batches of 32 (not in the cache,
//!   as in `dump`), and prints the per-frame CPU ms's median, p90, p99 and mean per pass: two builds run one after the
//!   other this way give a speed ratio on a busy machine. With `cold` it writes 64 MB between two frames, so that each
//!   estimate starts with none of its own data cached, as after a frame's decoding in the daemon, or after the other
//!   modes and the renderer in the validation bench. With `after-fast` it writes the 64 MB and then runs fast mode on
//!   the frame before timing MODE on it, untimed, as the validation bench does when it runs fast and inverse: the
//!   frame's pattern is then in the caches and the model's matrices are not.
//! - `... -- rest WxH FRAMES PASSES` times inverse mode on frames with no contact: the validation sensor at that size
//!   at rest under uneven light (each LED's current off nominal by up to 8 %, its own seed per frame; JPEG q85, decoded
//!   once), each frame estimated once per pass, and prints how long the estimator (its model with it) took to build,
//!   the per-frame CPU ms's median, p90, p99 and mean per pass and how many frames read a contact (none should). Such
//!   frames run every rescue of the contact test, the costliest path a frame with no contact takes; two builds run one
//!   after the other this way give its speed ratio. The frames are rendered once and kept in `$NUSENSE_PROFILE_CACHE`
//!   (else the temporary folder).

use std::sync::Arc;
use std::time::Instant;

use image::RgbImage;
use nusense_capture::{DecodeOptions, Decoder, FramePixels, PixelRect, Scale};
use nusense_estimator::{Estimator, Mode, SensorConfig};
use nusense_sim::validation::{Case, CaseKind, Profile, ValidationRenderer, ValidationSet};
use nusense_sim::{Contact, Scene, NOMINAL_LED_CURRENT_MA};

type Error = Box<dyn std::error::Error>;

fn encode(image: &RgbImage) -> Vec<u8> {
    let mut bytes = Vec::new();
    let _ = image.write_with_encoder(image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, 85));
    bytes
}

fn thread_cpu_s() -> f64 {
    let mut now = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime writes the timespec it is given.
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut now) };
    now.tv_sec as f64 + now.tv_nsec as f64 * 1e-9
}

/// The rest frame and the 5 N press at `size` as JPEG (q85), rendered once and kept in `cache`.
fn press_pair(size: (u32, u32), cache: &std::path::Path) -> Result<(Vec<u8>, Vec<u8>), Error> {
    let path = |name: &str| cache.join(format!("{}x{}-{name}.jpg", size.0, size.1));
    if let (Ok(reference), Ok(touch)) = (std::fs::read(path("rest")), std::fs::read(path("press"))) {
        return Ok((reference, touch));
    }
    let renderer = ValidationRenderer::new(size)?;
    let reference = encode(&renderer.reference(7)?);
    let case = Case::still(
        "press",
        CaseKind::Press,
        size,
        Scene::with_contact(Contact::sphere(5.0, [3.0, -2.0], 5.0)),
        11,
    );
    let touch = encode(&renderer.render(&case)?.0);
    std::fs::create_dir_all(cache)?;
    std::fs::write(path("rest"), &reference)?;
    std::fs::write(path("press"), &touch)?;
    Ok((reference, touch))
}

fn run(mode: Mode, size: (u32, u32), repeats: usize, decode_scale: Option<Scale>) -> Result<(), Error> {
    let cache = std::env::var_os("NUSENSE_PROFILE_CACHE").map_or_else(std::env::temp_dir, Into::into);
    let (reference_jpeg, touch_jpeg) = press_pair(size, &cache)?;
    let scale = decode_scale.unwrap_or(Scale::Full);
    let mut decoder = Decoder::new();
    let reference = decoder
        .decode(
            &FramePixels::Jpeg(Arc::new(reference_jpeg)),
            &DecodeOptions::scaled(scale),
        )?
        .image;
    let mut estimator = Estimator::new(SensorConfig::default(), mode, &reference)?;
    let region = estimator
        .pattern_region_px()
        .and_then(|(min, max)| PixelRect::from_scaled_bounds(min, max, scale, size));
    let options = DecodeOptions { scale, region };
    let touch_bytes = FramePixels::Jpeg(Arc::new(touch_jpeg));
    let touch = decoder.decode(&touch_bytes, &options)?.image;
    let first = estimator.estimate(&touch)?;
    let started = (thread_cpu_s(), Instant::now());
    for _ in 0..repeats {
        let reading = match decode_scale {
            Some(_) => estimator.estimate(&decoder.decode(&touch_bytes, &options)?.image)?,
            None => estimator.estimate(&touch)?,
        };
        std::hint::black_box(reading);
    }
    let cpu_ms = (thread_cpu_s() - started.0) * 1e3 / repeats.max(1) as f64;
    let wall_ms = started.1.elapsed().as_secs_f64() * 1e3 / repeats.max(1) as f64;
    println!(
        "{mode} {}x{} decode {:?}: {cpu_ms:.3} ms CPU, {wall_ms:.3} ms wall per frame ({repeats} frames); contact {:?} force {:.3} N",
        size.0,
        size.1,
        decode_scale.map(Scale::divisor),
        first.contact_mm(),
        first.force_n(),
    );
    Ok(())
}

/// One pass's CPU times per frame (ms; sorted here) as the commands print them.
fn cpu_summary(cpu_ms: &mut [f64]) -> String {
    cpu_ms.sort_by(f64::total_cmp);
    let at = |percent: usize| cpu_ms[cpu_ms.len() * percent / 100];
    format!(
        "{} frames, CPU ms per frame median {:.3}, p90 {:.3}, p99 {:.3}, mean {:.3}",
        cpu_ms.len(),
        at(50),
        at(90),
        at(99),
        cpu_ms.iter().sum::<f64>() / cpu_ms.len() as f64
    )
}

/// LED currents off nominal by up to 8 % (the validation set's rest frames' drift), one set per frame `k`: uneven
/// light, which moves the corners the way no camera motion does.
fn uneven_leds(k: u64) -> [f32; 4] {
    let offsets = [
        [-0.08, 0.05, 0.02, -0.03],
        [0.06, -0.04, -0.07, 0.08],
        [0.0, 0.08, -0.05, 0.03],
    ];
    let o = offsets[(k % 3) as usize];
    std::array::from_fn(|i| NOMINAL_LED_CURRENT_MA * (1.0 + o[i]))
}

/// The validation sensor's rest frame and `frames` frames at rest under uneven light (see [`uneven_leds`]), at `size`,
/// as JPEG (q85), rendered once and kept in `cache`.
fn rest_frames(size: (u32, u32), frames: usize, cache: &std::path::Path) -> Result<(Vec<u8>, Vec<Vec<u8>>), Error> {
    let path = |name: String| cache.join(format!("{}x{}-{name}.jpg", size.0, size.1));
    let renderer = ValidationRenderer::new(size)?;
    let reference = match std::fs::read(path("rest".into())) {
        Ok(bytes) => bytes,
        Err(_) => encode(&renderer.reference(7)?),
    };
    std::fs::create_dir_all(cache)?;
    std::fs::write(path("rest".into()), &reference)?;
    let mut uneven = Vec::with_capacity(frames);
    for k in 0..frames as u64 {
        let name = format!("rest-uneven-{k}");
        let bytes = match std::fs::read(path(name.clone())) {
            Ok(bytes) => bytes,
            Err(_) => {
                let case = Case {
                    led_currents_ma: uneven_leds(k),
                    ..Case::still(name.clone(), CaseKind::Rest, size, Scene::rest(), 1000 + k)
                };
                let bytes = encode(&renderer.render(&case)?.0);
                std::fs::write(path(name), &bytes)?;
                bytes
            }
        };
        uneven.push(bytes);
    }
    Ok((reference, uneven))
}

fn rest(size: (u32, u32), frames: usize, passes: usize) -> Result<(), Error> {
    let cache = std::env::var_os("NUSENSE_PROFILE_CACHE").map_or_else(std::env::temp_dir, Into::into);
    let (reference, uneven) = rest_frames(size, frames, &cache)?;
    let reference = image::load_from_memory(&reference)?.to_rgb8();
    let frames = uneven
        .iter()
        .map(|bytes| Ok(image::load_from_memory(bytes)?.to_rgb8()))
        .collect::<Result<Vec<_>, Error>>()?;
    let started = (thread_cpu_s(), Instant::now());
    let mut estimator = Estimator::new(SensorConfig::default(), Mode::Inverse, &reference)?;
    println!(
        "inverse rest {}x{}: estimator built (the model with it) in {:.1} ms CPU, {:.1} ms wall",
        size.0,
        size.1,
        (thread_cpu_s() - started.0) * 1e3,
        started.1.elapsed().as_secs_f64() * 1e3
    );
    for pass in 0..passes {
        let mut cpu_ms = Vec::with_capacity(frames.len());
        let mut contacts = 0;
        for frame in &frames {
            let started = thread_cpu_s();
            let reading = estimator.estimate(frame);
            cpu_ms.push((thread_cpu_s() - started) * 1e3);
            contacts += usize::from(reading.as_ref().is_ok_and(|r| r.is_contact()));
            std::hint::black_box(reading.ok());
        }
        println!(
            "inverse rest {}x{} pass {pass}: {}; {contacts} read a contact",
            size.0,
            size.1,
            cpu_summary(&mut cpu_ms)
        );
    }
    Ok(())
}

/// The validation frames, rendered once and kept as raw RGB in `cache` (rendering dominates a run otherwise).
fn validation_frame(renderer: &ValidationRenderer, case: &Case, cache: &std::path::Path) -> Result<RgbImage, Error> {
    let path = cache.join(format!(
        "{}x{}-{}.rgb",
        case.size.0,
        case.size.1,
        case.name.replace('/', "_")
    ));
    if let Ok(raw) = std::fs::read(&path) {
        if let Some(image) = RgbImage::from_raw(case.size.0, case.size.1, raw) {
            return Ok(image);
        }
    }
    let (frame, _) = renderer.render(case)?;
    std::fs::create_dir_all(cache)?;
    std::fs::write(&path, frame.as_raw())?;
    Ok(frame)
}

fn dump(out: &str, cache: &std::path::Path, profile: Profile) -> Result<(), Error> {
    let set = ValidationSet::new(profile, 7);
    let mut text = String::new();
    for size in set.sizes() {
        let renderer = ValidationRenderer::new(size)?;
        let reference = renderer.reference(7)?;
        let frames = set
            .cases
            .iter()
            .filter(|c| c.size == size)
            .map(|case| Ok((case, validation_frame(&renderer, case, cache)?)))
            .collect::<Result<Vec<_>, Error>>()?;
        for mode in [Mode::Fast, Mode::Inverse] {
            let mut estimator = Estimator::new(SensorConfig::default(), mode, &reference)?;
            let mut cpu_ms = Vec::new();
            for (case, frame) in &frames {
                let started = thread_cpu_s();
                let reading = estimator.estimate(frame);
                cpu_ms.push((thread_cpu_s() - started) * 1e3);
                let line = match reading {
                    Ok(mut reading) => {
                        reading.elapsed_ms = 0.0;
                        format!("{reading:?}")
                    }
                    Err(error) => format!("error: {error}"),
                };
                text.push_str(&format!("{mode} {}x{} {}: {line}\n", size.0, size.1, case.name));
            }
            cpu_ms.sort_by(f64::total_cmp);
            eprintln!(
                "{mode} {}x{}: {} frames, CPU ms per frame median {:.3}, p90 {:.3}, max {:.3}, total {:.1}",
                size.0,
                size.1,
                cpu_ms.len(),
                cpu_ms[cpu_ms.len() / 2],
                cpu_ms[cpu_ms.len() * 9 / 10],
                cpu_ms[cpu_ms.len() - 1],
                cpu_ms.iter().sum::<f64>()
            );
        }
    }
    std::fs::write(out, text)?;
    Ok(())
}

/// What `time` does between two frames (see the module's notes).
#[derive(Clone, Copy, PartialEq)]
enum Between {
    Nothing,
    Evict,
    EvictThenFast,
}

fn time(mode: Mode, cache: &std::path::Path, passes: usize, profile: Profile, between: Between) -> Result<(), Error> {
    let mut evictor = if between == Between::Nothing {
        Vec::new()
    } else {
        vec![0u8; EVICTION_BYTES]
    };
    let set = ValidationSet::new(profile, 7);
    let size = set.sizes()[0];
    let renderer = ValidationRenderer::new(size)?;
    let reference = renderer.reference(7)?;
    let cases: Vec<&Case> = set.cases.iter().filter(|c| c.size == size).collect();
    for case in &cases {
        validation_frame(&renderer, case, cache)?;
    }
    for pass in 0..passes {
        let mut estimator = Estimator::new(SensorConfig::default(), mode, &reference)?;
        let mut fast = match between {
            Between::EvictThenFast => Some(Estimator::new(SensorConfig::default(), Mode::Fast, &reference)?),
            _ => None,
        };
        let mut cpu_ms = Vec::with_capacity(cases.len());
        for batch in cases.chunks(32) {
            let frames = batch
                .iter()
                .map(|case| validation_frame(&renderer, case, cache))
                .collect::<Result<Vec<_>, Error>>()?;
            for frame in &frames {
                evict_caches(&mut evictor);
                if let Some(fast) = fast.as_mut() {
                    std::hint::black_box(fast.estimate(frame).ok());
                }
                let started = thread_cpu_s();
                let reading = estimator.estimate(frame);
                cpu_ms.push((thread_cpu_s() - started) * 1e3);
                std::hint::black_box(reading.ok());
            }
        }
        println!("{mode} {}x{} pass {pass}: {}", size.0, size.1, cpu_summary(&mut cpu_ms));
    }
    Ok(())
}

/// Twice the last-level cache of the machine these figures come from (32 MB): writing it all leaves none of the
/// estimator's own data cached.
const EVICTION_BYTES: usize = 64 << 20;

/// Writes every cache line of `buffer` (empty: nothing), as a frame's decoding and the daemon's other work do
/// between two frames: each estimate then starts with its model's matrices out of the caches.
fn evict_caches(buffer: &mut [u8]) {
    for line in buffer.chunks_mut(64) {
        line[0] = line[0].wrapping_add(1);
    }
    std::hint::black_box(&buffer);
}

fn profile_arg(arg: Option<&String>) -> Result<Profile, Error> {
    match arg.map(String::as_str) {
        None | Some("quick") => Ok(Profile::Quick),
        Some("full") => Ok(Profile::Full),
        Some(other) => Err(format!("unknown profile {other} (quick or full)").into()),
    }
}

fn main() -> Result<(), Error> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("run") if args.len() >= 4 => {
            let mode: Mode = args[1].parse()?;
            let (w, h) = args[2].split_once('x').ok_or("size is WxH")?;
            let repeats: usize = args[3].parse()?;
            let scale = args.get(4).map(|s| s.parse::<Scale>()).transpose()?;
            run(mode, (w.parse()?, h.parse()?), repeats, scale)
        }
        Some("rest") if args.len() == 4 => {
            let (w, h) = args[1].split_once('x').ok_or("size is WxH")?;
            rest((w.parse()?, h.parse()?), args[2].parse()?, args[3].parse()?)
        }
        Some("dump") if args.len() == 3 || args.len() == 4 => {
            dump(&args[1], std::path::Path::new(&args[2]), profile_arg(args.get(3))?)
        }
        Some("time") if (4..=6).contains(&args.len()) => time(
            args[1].parse()?,
            std::path::Path::new(&args[2]),
            args[3].parse()?,
            profile_arg(args.get(4))?,
            match args.get(5).map(String::as_str) {
                None => Between::Nothing,
                Some("cold") => Between::Evict,
                Some("after-fast") => Between::EvictThenFast,
                Some(other) => return Err(format!("unknown option {other} (cold, after-fast)").into()),
            },
        ),
        _ => Err(
            "usage: estimate_profile run MODE WxH REPEATS [DECODE_SCALE] | rest WxH FRAMES PASSES \
             | dump OUT CACHE_DIR [quick|full] \
             | time MODE CACHE_DIR PASSES [quick|full] [cold|after-fast]"
                .into(),
        ),
    }
}
