//! Scripted sessions on the simulator, recorded as the daemon records a real sensor, with their ground truth:
//! frames and readings in MCAP (through the daemon's own recorder), the applied force as the CSV a force/torque
//! sensor logs on its own clock (a fixed offset from the camera's, noise, a higher rate), and `truth.json`.
//!
//! The pad is elastic except where a session asks for a viscoelastic term (a standard linear solid under force
//! control): the pattern deforms as if loaded by `(1 - w) F + w c`, where the creep part `c` follows the applied
//! force `F` with time constant `tau` (`dc/dt = (F - c) / tau`). Loading and unloading then trace a loop.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use nusense_daemon::pipeline::PublishedReading;
use nusense_daemon::reading::SCHEMA_VERSION;
use nusense_daemon::record::{encode_jpeg, FramePixels, RecordError, RecordItem, Recorder, RecorderOptions};
use nusense_daemon::ReadingMessage;
use nusense_estimator::{ConfigError, EstimateError, Estimator, Mode, SensorConfig};
use nusense_geometry::SquareIndex;
use nusense_sim::{Contact, Damage, ModelError, RenderError, Renderer, Scene, SensorModel};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};
use thiserror::Error;

/// The camera clock's start: a fixed moment, so that sessions are reproducible byte for byte.
const START_US: u64 = 1_700_000_000_000_000;
const SPHERE_RADIUS_MM: f64 = 5.0;
/// Below this the scene is the pad at rest (the sphere has lifted off).
const LIFT_OFF_N: f64 = 0.02;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SessionKind {
    /// Presses of different depths and speeds at the centre, for the force calibration.
    Calibration,
    /// Triangular loading/unloading cycles on a viscoelastic pad.
    Hysteresis,
    /// Repeated touches with drift and spread in force and position.
    Repeatability,
    /// Touches at a grid of known targets (`targets.csv`).
    Localisation,
    /// The same touches on an intact and on a damaged pad (`intact.mcap`, `damaged.mcap`).
    Damage,
}

#[derive(Clone, Debug, Serialize)]
pub struct SessionOptions {
    pub width: u32,
    pub height: u32,
    pub frame_rate_hz: f64,
    pub ft_rate_hz: f64,
    /// F/T clock minus camera clock, seconds.
    pub ft_offset_s: f64,
    /// Standard deviation of the F/T sensor's noise on each axis, N.
    pub ft_noise_n: f64,
    pub seed: u64,
    /// The recorded frames' JPEG quality (the readings are estimated from the decoded JPEG, as in the daemon).
    pub jpeg_quality: u8,
    /// Touches (repeatability, damage) or cycles (hysteresis, calibration presses).
    pub repetitions: usize,
    /// Localisation: targets per row and per column.
    pub grid: [usize; 2],
    /// The hysteresis session's viscoelastic term.
    pub viscoelastic: Viscoelastic,
}

impl SessionOptions {
    /// Small frames and few repetitions: seconds of rendering, for tests.
    pub fn short() -> Self {
        Self {
            width: 160,
            height: 120,
            frame_rate_hz: 10.0,
            ft_rate_hz: 200.0,
            ft_offset_s: 0.43,
            ft_noise_n: 0.03,
            seed: 17,
            jpeg_quality: 90,
            repetitions: 4,
            grid: [2, 2],
            viscoelastic: Viscoelastic {
                weight: 0.3,
                tau_s: 0.4,
            },
        }
    }

    /// The documentation's example sessions: larger frames, more repetitions.
    pub fn example() -> Self {
        Self {
            width: 320,
            height: 240,
            frame_rate_hz: 15.0,
            repetitions: 10,
            grid: [4, 3],
            ..Self::short()
        }
    }
}

/// A standard linear solid's creep under force control, see the module documentation.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Viscoelastic {
    /// Share of the deformation that creeps, 0 (elastic) to 1.
    pub weight: f64,
    pub tau_s: f64,
}

#[derive(Debug, Error)]
pub enum SessionError {
    #[error("the simulated sensor: {0}")]
    Model(#[from] ModelError),
    #[error("rendering frame {frame}: {source}")]
    Render { frame: usize, source: RenderError },
    #[error("the rest frame: {0}")]
    Reference(EstimateError),
    #[error("the simulated sensor's built-in configuration: {0}")]
    Config(#[from] ConfigError),
    #[error(transparent)]
    Record(#[from] RecordError),
    #[error("cannot write {path}: {source}")]
    Write { path: String, source: std::io::Error },
    #[error("a session needs a frame rate, F/T rate and size above zero and at least one repetition")]
    BadOptions,
}

/// One touch of a session's script.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TouchTruth {
    /// Camera-clock seconds since the Unix epoch.
    pub start_s: f64,
    pub end_s: f64,
    pub peak_n: f64,
    pub position_mm: [f64; 2],
}

/// What happened at one recorded frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameTruth {
    pub frame_id: u64,
    /// Camera-clock seconds since the Unix epoch.
    pub time_s: f64,
    /// The force pressing on the pad (what the F/T sensor measures, before its noise), N.
    pub applied_n: f64,
    /// The force the pad's deformation corresponds to (equal to `applied_n` on an elastic pad), N.
    pub deformation_n: f64,
    /// Where the pad is deformed (the sphere's place), while it is.
    pub position_mm: Option<[f64; 2]>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DamageTruth {
    pub centre_mm: [f64; 2],
    pub radius_mm: f64,
    /// Interior corners the damage costs (see [`corners_lost`]).
    pub corners_lost: usize,
    /// Interior corners inside the disc: fewer, as the disc cuts squares whose far corners lie outside it.
    pub corners_in_disc: usize,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SessionTruth {
    pub kind: SessionKind,
    pub frame_interval_s: f64,
    pub ft_offset_s: f64,
    pub viscoelastic: Option<Viscoelastic>,
    pub touches: Vec<TouchTruth>,
    pub frames: Vec<FrameTruth>,
    pub damage: Option<DamageTruth>,
}

/// The files a session wrote.
#[derive(Clone, Debug)]
pub struct SessionFiles {
    /// The session (for damage: the damaged pad).
    pub recording: PathBuf,
    /// Damage: the intact pad.
    pub intact: Option<PathBuf>,
    pub ft_log: PathBuf,
    pub targets: Option<PathBuf>,
    pub truth: PathBuf,
    pub truth_data: SessionTruth,
}

/// A script: where the sphere is and how hard it is pressed at any time, and what is scripted to happen.
struct Script {
    duration_s: f64,
    touches: Vec<TouchTruth>,
    /// Applied force and position at a time since the start.
    at: Box<dyn Fn(f64) -> (f64, [f64; 2])>,
}

fn smoothstep(t: f64) -> f64 {
    let t = t.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Touches one after the other: `lead_s` at rest, then for each a ramp, a hold, a release and a gap.
fn touch_script(lead_s: f64, touches: Vec<([f64; 2], f64)>) -> Script {
    const RAMP_S: f64 = 0.3;
    const HOLD_S: f64 = 0.5;
    const GAP_S: f64 = 0.5;
    let period = 2.0 * RAMP_S + HOLD_S + GAP_S;
    let start = START_US as f64 * 1e-6;
    let truths = touches
        .iter()
        .enumerate()
        .map(|(k, &(position_mm, peak_n))| {
            let begin = lead_s + k as f64 * period;
            TouchTruth {
                start_s: start + begin,
                end_s: start + begin + 2.0 * RAMP_S + HOLD_S,
                peak_n,
                position_mm,
            }
        })
        .collect();
    let duration_s = lead_s + touches.len() as f64 * period;
    Script {
        duration_s,
        touches: truths,
        at: Box::new(move |t| {
            let k = ((t - lead_s) / period).floor();
            if k < 0.0 || k as usize >= touches.len() {
                return (0.0, touches.first().map_or([0.0; 2], |t| t.0));
            }
            let (position, peak) = touches[k as usize];
            let local = t - lead_s - k * period;
            let envelope = if local < RAMP_S {
                smoothstep(local / RAMP_S)
            } else if local < RAMP_S + HOLD_S {
                1.0
            } else {
                1.0 - smoothstep((local - RAMP_S - HOLD_S) / RAMP_S)
            };
            (peak * envelope, position)
        }),
    }
}

/// Presses of different peaks and speeds (so that the cross-correlation has a single best lag).
fn calibration_script(presses: usize) -> Script {
    const PEAKS_N: [f64; 6] = [4.0, 8.0, 5.5, 7.0, 3.0, 6.5];
    const RISE_S: [f64; 6] = [0.6, 1.0, 0.7, 0.9, 0.5, 0.8];
    let lead_s = 0.5;
    let segments: Vec<(f64, f64, f64)> = (0..presses.max(1))
        .scan(lead_s, |begin, k| {
            let (peak, rise) = (PEAKS_N[k % 6], RISE_S[k % 6]);
            let segment = (*begin, rise, peak);
            *begin += 2.0 * rise + 0.4;
            Some(segment)
        })
        .collect();
    let duration_s = segments.last().map_or(lead_s, |&(b, r, _)| b + 2.0 * r + 0.4);
    Script {
        duration_s,
        touches: Vec::new(),
        at: Box::new(move |t| {
            let force = segments
                .iter()
                .find(|&&(b, r, _)| t >= b && t < b + 2.0 * r)
                .map_or(0.0, |&(b, r, peak)| peak * (1.0 - ((t - b - r) / r).abs()));
            (force, [0.0, 0.0])
        }),
    }
}

/// Triangular cycles 0 -> 8 N -> 0.
fn hysteresis_script(cycles: usize) -> Script {
    const PEAK_N: f64 = 8.0;
    const HALF_S: f64 = 1.5;
    let lead_s = 0.5;
    let cycles = cycles.max(1);
    Script {
        duration_s: 2.0 * lead_s + cycles as f64 * 2.0 * HALF_S,
        touches: Vec::new(),
        at: Box::new(move |t| {
            let local = t - lead_s;
            if local < 0.0 || local >= cycles as f64 * 2.0 * HALF_S {
                return (0.0, [0.0, 0.0]);
            }
            let phase = local.rem_euclid(2.0 * HALF_S) / HALF_S;
            (PEAK_N * (1.0 - (phase - 1.0).abs()), [0.0, 0.0])
        }),
    }
}

/// The targets of a localisation session: a grid over the middle of the pad, visited row by row.
pub fn target_grid(grid: [usize; 2]) -> Vec<[f64; 2]> {
    let axis = |n: usize, half: f64| -> Vec<f64> {
        if n <= 1 {
            vec![0.0]
        } else {
            (0..n).map(|i| -half + 2.0 * half * i as f64 / (n - 1) as f64).collect()
        }
    };
    let (xs, ys) = (axis(grid[0], 14.0), axis(grid[1], 9.0));
    ys.iter().flat_map(|&y| xs.iter().map(move |&x| [x, y])).collect()
}

/// The damaged pad's damage: the ink gone in a disc away from the touches. It takes two yellow squares whole and
/// leaves every other square it reaches most of its ink, so the lattice points it costs do not hinge on how little
/// ink the detector still takes for a square (see [`corners_lost`] and its test).
pub const DAMAGE_CENTRE_MM: [f64; 2] = [-13.0, 6.5];
pub const DAMAGE_RADIUS_MM: f64 = 4.5;

/// A yellow square is found while more than this share of its ink is left: the detector keeps a yellow blob
/// larger than 35 % of the pattern's typical square (the estimator's `detection/blobs.rs`).
pub const MIN_INK_FOUND: f64 = 0.35;

/// The share of a yellow square's ink outside the disc, on the pad at rest (sampled on a 48 x 48 grid).
pub fn ink_kept(model: &SensorModel, square: SquareIndex, centre_mm: [f64; 2], radius_mm: f64) -> f64 {
    const SAMPLES: usize = 48;
    let pad = &model.pad;
    let centre = pad.square_centre_mm(square);
    let side = [
        model.yellow_fill * pad.pitch_x_mm(),
        model.yellow_fill * pad.pitch_y_mm(),
    ];
    let offset = |k: usize, axis: usize| ((k as f64 + 0.5) / SAMPLES as f64 - 0.5) * side[axis];
    let kept = (0..SAMPLES * SAMPLES)
        .filter(|k| {
            let p = [centre[0] + offset(k % SAMPLES, 0), centre[1] + offset(k / SAMPLES, 1)];
            (p[0] - centre_mm[0]).hypot(p[1] - centre_mm[1]) >= radius_mm
        })
        .count();
    kept as f64 / (SAMPLES * SAMPLES) as f64
}

/// Interior corners the damage costs on the pad at rest. The estimator measures corner (r, c) as the midpoint of
/// the two yellow squares of its 2 x 2 block, so a corner is lost with either of them, even outside the disc,
/// and kept inside it while both squares keep enough ink; a square is lost when less than [`MIN_INK_FOUND`] of
/// its ink is left.
pub fn corners_lost(model: &SensorModel, centre_mm: [f64; 2], radius_mm: f64) -> usize {
    let pad = &model.pad;
    let lost = |row: u16, col: u16| {
        let square = SquareIndex { row, col };
        pad.is_yellow(square) && ink_kept(model, square, centre_mm, radius_mm) < MIN_INK_FOUND
    };
    pad.corners()
        .filter(|c| {
            [
                (c.row, c.col),
                (c.row, c.col + 1),
                (c.row + 1, c.col),
                (c.row + 1, c.col + 1),
            ]
            .into_iter()
            .any(|(row, col)| lost(row, col))
        })
        .count()
}

/// Renders and records a session of `kind` into `dir`; `progress(done, total)` after each frame.
pub fn write_session(
    kind: SessionKind,
    options: &SessionOptions,
    dir: &Path,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<SessionFiles, SessionError> {
    if !(options.frame_rate_hz > 0.0 && options.ft_rate_hz > 0.0 && options.width > 0 && options.repetitions > 0) {
        return Err(SessionError::BadOptions);
    }
    std::fs::create_dir_all(dir).map_err(|source| SessionError::Write {
        path: dir.display().to_string(),
        source,
    })?;
    // One generator for the whole session, drawn in a fixed order (script, then F/T noise), so that a seed gives
    // the same session byte for byte.
    let mut rng = ChaCha8Rng::seed_from_u64(options.seed);
    let script = session_script(kind, options, &mut rng);
    let viscoelastic = (kind == SessionKind::Hysteresis).then_some(options.viscoelastic);
    let (ft_csv, frames) = play_script(&script, options, viscoelastic, &mut rng);
    let ft_log = dir.join("ft.csv");
    write(&ft_log, &ft_csv)?;

    let model = SensorModel::real(options.width, options.height);
    let damage = (kind == SessionKind::Damage).then(|| damage_truth(&model));
    let renderer = Renderer::new(model)?;
    let mut files = SessionFiles {
        recording: dir.join(if kind == SessionKind::Damage {
            "damaged.mcap"
        } else {
            "session.mcap"
        }),
        intact: None,
        ft_log,
        targets: None,
        truth: dir.join("truth.json"),
        truth_data: SessionTruth {
            kind,
            frame_interval_s: 1.0 / options.frame_rate_hz,
            ft_offset_s: options.ft_offset_s,
            viscoelastic,
            touches: script.touches,
            frames,
            damage,
        },
    };
    record_session(&renderer, options, dir, &mut files, progress)?;
    if kind == SessionKind::Localisation {
        files.targets = Some(write_targets(dir, options.grid)?);
    }
    let json = serde_json::to_string_pretty(&files.truth_data).expect("truth is plain data");
    write(&files.truth, &json)?;
    Ok(files)
}

/// What the session scripts: the force and the sphere's place over time.
fn session_script(kind: SessionKind, options: &SessionOptions, rng: &mut ChaCha8Rng) -> Script {
    let n = options.repetitions;
    match kind {
        SessionKind::Calibration => calibration_script(n),
        SessionKind::Hysteresis => hysteresis_script(n.div_ceil(2)),
        SessionKind::Repeatability => {
            let spread = Normal::new(0.0, 0.25).expect("a positive deviation");
            let force_spread = Normal::new(0.0, 0.1).expect("a positive deviation");
            let touches = (0..n)
                .map(|k| {
                    let drift = k as f64;
                    let position = [4.0 + 0.12 * drift + spread.sample(rng), -3.0 + spread.sample(rng)];
                    (position, 6.0 - 0.08 * drift + force_spread.sample(rng))
                })
                .collect();
            touch_script(0.5, touches)
        }
        SessionKind::Localisation => {
            touch_script(0.5, target_grid(options.grid).into_iter().map(|p| (p, 6.0)).collect())
        }
        SessionKind::Damage => touch_script(0.5, vec![([6.0, -4.0], 6.0), ([10.0, 6.0], 5.0)]),
    }
}

/// Plays the script: the F/T sensor's log (CSV, its clock and noise) and what happens at each camera frame.
fn play_script(
    script: &Script,
    options: &SessionOptions,
    viscoelastic: Option<Viscoelastic>,
    rng: &mut ChaCha8Rng,
) -> (String, Vec<FrameTruth>) {
    let ft_step = 1.0 / options.ft_rate_hz;
    let frame_step = 1.0 / options.frame_rate_hz;
    let start_s = START_US as f64 * 1e-6;

    // Integrate the creep at the F/T rate; sample frames as they fall due.
    let mut ft_csv = String::from("time_s,fx,fy,fz,tx,ty,tz\n");
    let noise = Normal::new(0.0, options.ft_noise_n.max(0.0)).expect("a finite deviation");
    let mut creep = 0.0;
    let mut frames = Vec::new();
    let ft_steps = (script.duration_s / ft_step).ceil() as usize;
    for i in 0..=ft_steps {
        let t = i as f64 * ft_step;
        let (applied, position) = (script.at)(t);
        let deformation = match viscoelastic {
            Some(v) => {
                creep += (applied - creep) * (1.0 - (-ft_step / v.tau_s).exp());
                (1.0 - v.weight) * applied + v.weight * creep
            }
            None => applied,
        };
        let mut sample = || noise.sample(rng);
        // Compression reads negative on the F/T sensor's z axis, as it does on most.
        ft_csv.push_str(&format!(
            "{:.6},{:.4},{:.4},{:.4},{:.5},{:.5},{:.5}\n",
            start_s + t + options.ft_offset_s,
            sample(),
            sample(),
            -applied + sample(),
            0.01 * sample(),
            0.01 * sample(),
            0.01 * sample()
        ));
        while (frames.len() as f64) * frame_step <= t + 1e-9 && (frames.len() as f64) * frame_step <= script.duration_s
        {
            let frame_t = frames.len() as f64 * frame_step;
            frames.push(FrameTruth {
                frame_id: frames.len() as u64,
                time_s: start_s + frame_t,
                applied_n: applied,
                deformation_n: deformation,
                // A viscoelastic pad is still deformed for a while after the sphere lifts off: render that too.
                position_mm: (applied.max(deformation) > LIFT_OFF_N).then_some(position),
            });
        }
    }
    (ft_csv, frames)
}

/// The damage session's disc of missing ink, and the corners it costs.
fn damage_truth(model: &SensorModel) -> DamageTruth {
    DamageTruth {
        centre_mm: DAMAGE_CENTRE_MM,
        radius_mm: DAMAGE_RADIUS_MM,
        corners_lost: corners_lost(model, DAMAGE_CENTRE_MM, DAMAGE_RADIUS_MM),
        corners_in_disc: model
            .pad
            .corners()
            .filter(|&c| {
                let p = model.pad.corner_mm(c);
                (p[0] - DAMAGE_CENTRE_MM[0]).hypot(p[1] - DAMAGE_CENTRE_MM[1]) < DAMAGE_RADIUS_MM
            })
            .count(),
    }
}

/// Records the session's frames into `files.recording`; a damage session first records them on the intact pad
/// (`intact.mcap`), then on the damaged one.
fn record_session(
    renderer: &Renderer,
    options: &SessionOptions,
    dir: &Path,
    files: &mut SessionFiles,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(), SessionError> {
    let frames = &files.truth_data.frames;
    let damage = files.truth_data.damage.as_ref();
    let total = frames.len() * if damage.is_some() { 2 } else { 1 };
    let mut done = 0;
    let mut step = |_| {
        done += 1;
        progress(done, total);
    };
    let Some(damage) = damage else {
        return record(renderer, options, frames, &[], &files.recording, &mut step);
    };
    let intact = dir.join("intact.mcap");
    record(renderer, options, frames, &[], &intact, &mut step)?;
    let ink = Damage::Missing {
        centre_mm: damage.centre_mm,
        radius_mm: damage.radius_mm,
    };
    record(renderer, options, frames, &[ink], &files.recording, &mut step)?;
    files.intact = Some(intact);
    Ok(())
}

/// The localisation session's targets, as `targets.csv`.
fn write_targets(dir: &Path, grid: [usize; 2]) -> Result<PathBuf, SessionError> {
    let targets = dir.join("targets.csv");
    let mut csv = String::from("x_mm,y_mm\n");
    for t in target_grid(grid) {
        csv.push_str(&format!("{},{}\n", t[0], t[1]));
    }
    write(&targets, &csv)?;
    Ok(targets)
}

fn write(path: &Path, text: &str) -> Result<(), SessionError> {
    std::fs::write(path, text).map_err(|source| SessionError::Write {
        path: path.display().to_string(),
        source,
    })
}

/// Renders the frames, estimates each from its decoded JPEG against frame 0 (the rest frame, as the daemon
/// does), and records frame and reading.
fn record(
    renderer: &Renderer,
    options: &SessionOptions,
    frames: &[FrameTruth],
    damage: &[Damage],
    path: &Path,
    on_frame: &mut dyn FnMut(usize),
) -> Result<(), SessionError> {
    let recorder = Recorder::create(path, RecorderOptions::default())?;
    // The simulated sensor's own calibration, as `serve --sim` measures it: the real sensor's default line read a
    // 6 N touch as 1.4 N and put light presses below the detection floor.
    let config = SensorConfig::from_toml_str(nusense_sim::SENSOR_CONFIG_TOML)?;
    let mut estimator: Option<Estimator> = None;
    for (index, frame) in frames.iter().enumerate() {
        let mut scene = match frame.position_mm {
            Some(position) if frame.deformation_n > LIFT_OFF_N => {
                Scene::with_contact(Contact::sphere(SPHERE_RADIUS_MM, position, frame.deformation_n))
            }
            _ => Scene::rest(),
        };
        scene.damage = damage.to_vec();
        let (image, _) = renderer
            .render(
                &scene,
                [nusense_sim::NOMINAL_LED_CURRENT_MA; 4],
                options.seed + index as u64 + 1,
            )
            .map_err(|source| SessionError::Render { frame: index, source })?;
        let jpeg = encode_jpeg(&image, options.jpeg_quality);
        let decoded = image::load_from_memory(&jpeg)
            .map(|i| i.to_rgb8())
            .unwrap_or_else(|_| image.clone());
        let capture_time_us = START_US + (frame.time_s * 1e6 - START_US as f64).round() as u64;
        let started = Instant::now();
        let (estimate, error) = match estimator.as_mut() {
            None => {
                estimator =
                    Some(Estimator::new(config.clone(), Mode::Fast, &decoded).map_err(SessionError::Reference)?);
                (None, Some("the rest frame".to_string()))
            }
            Some(estimator) => match estimator.estimate(&decoded) {
                Ok(reading) => (Some(reading), None),
                Err(error) => (None, Some(error.to_string())),
            },
        };
        let elapsed_us = started.elapsed().as_micros() as u64;
        let message = ReadingMessage {
            schema_version: SCHEMA_VERSION,
            frame_id: frame.frame_id,
            file: None,
            capture_time_us,
            processed_time_us: capture_time_us + elapsed_us,
            latency_ms: elapsed_us as f64 * 1e-3,
            queue_ms: 0.0,
            reference_frame_id: Some(0),
            estimate,
            error,
            led: None,
        };
        recorder.record(RecordItem::Frame {
            frame_id: frame.frame_id,
            capture_time_us,
            pixels: FramePixels::Jpeg(Arc::new(jpeg)),
        });
        let json = serde_json::to_string(&message).expect("a reading serialises");
        recorder.record(RecordItem::Reading(Arc::new(PublishedReading { message, json })));
        on_frame(index);
    }
    recorder.finish()?;
    Ok(())
}
