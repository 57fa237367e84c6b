//! `nusense calibrate`: fit a sensor's calibration and write it into its config:
//! - the paper's force line F = a * gamma + b (`[calibration]`), from (gamma, force) pairs or a session;
//! - the pad model's stiffness (`elastic.shear_modulus_kpa`), from a session's inverse-mode readings: the reference
//!   force against the model's, one scale through the origin (see `nusense_estimator::calibration::modulus`);
//! - the pad model's shear stiffness against its normal stiffness (`elastic.tangential_force_scale`), from the same
//!   session's pushes: the reference's tangential force against the model's, one scale through the origin, on the
//!   readings whose reference push is at least 0.5 N (see `nusense_estimator::calibration::modulus`); the log needs
//!   `fx` and `fy` for it, and a session without pushes leaves the scale as it was;
//! - the pad model's torque about the normal against its normal stiffness (`elastic.torque_scale`), from the same
//!   session's twists: the reference's torque against the model's (their sizes), one scale through the origin, on
//!   the readings whose reference torque is at least 2 N mm (see `nusense_estimator::calibration::modulus`); the log
//!   needs a torque column that says its unit for it (`mz_nmm` or `tz_nmm` in N mm, `mz_nm` or `tz_nm` in N m: the
//!   torque about the normal through the probe's contact point, as an F/T sensor on the probe whose z axis runs
//!   through its tip logs it), and a session without twists leaves the scale as it was (unset, the torque takes the
//!   tangential scale), and the output says why;
//! - how far a push's contact centre reads behind (or ahead of) the push (`elastic.push_centre_shift_mm`), from the
//!   same session when the log also says where the probe touched (`x_mm`, `y_mm`, see below): the offset from each
//!   reading's strongest contact to the probe, against the model's push over load, one factor through the origin on
//!   the readings pushed by a tenth of their load or more (see `nusense_estimator::calibration::push_centre`). A log
//!   without those columns, or a session with fewer than two such pushes, leaves the key as it was, and the output
//!   says why;
//! - what a push adds to its normal force (`elastic.push_normal_share`), from the same session's pushes: the model's
//!   normal force less the reference's over the modulus fit's scale, against the model's push squared over its normal
//!   force, one share through the origin on the readings pushed by a tenth of their load or more (see
//!   `nusense_estimator::calibration::push_normal`). A session without a modulus fit, or with fewer than two such
//!   pushes, leaves the key as it was, and the output says why;
//! - with `--rest FRAME`, the raw px -> pad mm map of this sensor's lens and pose (`[pad_map]`), fitted on a frame
//!   with nothing touching the pad, and its residual.
//!
//! Force input, one of (optional with `--rest`):
//! - `--pairs FILE.csv`: (gamma, force) pairs; a header naming `gamma` and `force` (or `force_n`), or no header
//!   and those two columns in that order.
//! - `--readings FILE.jsonl --ft-log FILE.csv`: a recorded session. Readings are JSON lines (as `nusense analyze
//!   --json`, `nusense replay --json`, the daemon's stream and recordings write them: `estimate.gamma` at
//!   `capture_time_us`; lines without an estimate are skipped). Flat lines with `gamma` and a time field
//!   (`timestamp_s`, `time_s`, `t`, `timestamp_ms` or `timestamp_us`) are read too; those with `ok: false` are
//!   skipped. The force/torque log is CSV with a time column (`timestamp`, `time`,
//!   `t`, optional `_s`/`_ms`/`_us` suffix) and `fx, fy, fz`, and optionally `x_mm, y_mm`: the probe's contact
//!   point in the pad's frame (mm from the pattern's centre, x right and y down as seen in the raw image: the frame
//!   of the readings' `contact_mm`), both or neither, a finite number on every row. Each reading takes the force
//!   (and the position) interpolated at its time when a log sample lies within `--max-skew-ms`; others are dropped
//!   and counted.
//!
//! Readings in inverse mode with contact also give the model's force (`force_n`); with at least two of them the
//! modulus scale is fitted as well, and with at least two pushes the tangential scale. With `x_mm, y_mm` in the log,
//! their strongest contact (`contact_mm`, and that contact's `force_vector_n`, or the reading's when it lists no
//! contacts) gives the push centre shift. Their force vector and normal force, against the reference the modulus is
//! fitted on, give the push normal share.
//!
//! Readings carry no record of the config they were made with: they are taken to have been made with the
//! `--config` file's current values (the defaults without one). So the fitted scales are relative to its modulus
//! and tangential scale, and for the push centre shift the readings' fx, fy are divided by its
//! `tangential_force_scale` (the shift is in the model's push over load) and their centres moved back by its
//! `push_centre_shift_mm` before the fit; that moving back is exact (the move depends only on the contact's force
//! and the config, also where it was cut short at one cell pitch) when the readings were indeed made with it. For the
//! push normal share the readings' normal force gets back what their `push_normal_share` took off for their push
//! (fx, fy over the tangential scale; `calibration::push_normal::uncorrected_normal_n`); that is exact for one contact
//! at a time (a session of one probe), and readings whose normal force reads 0 (where the share may have cut it off)
//! are left out.
//!
//! With `--config FILE`, what was fitted is written into that TOML (created if missing; other keys and comments are
//! kept) unless `--dry-run`; the modulus is the config's own times the fitted scale, the tangential scale the
//! config's own times its fitted ratio over the modulus's (the new modulus scales the model's shear as well), and the
//! push centre shift and the push normal share the fitted ones (neither scale changes the model's push over load, or
//! the model's normal force against its push).
//! `--json` prints the fits as one JSON object. A line that does not rise with gamma is refused and nothing is written (`--dry-run` still shows
//! it). Exit code: 0 on a fit, 1 when the data cannot be fitted, the line does not rise or the config cannot be
//! written.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{bail, Context};
use nusense_capture::read_image_rgb;
use nusense_estimator::calibration::modulus::{
    fit_modulus_scale, fit_tangential_scale, fit_torque_scale, ModelForceSample, ModelTorqueSample, ModulusFit,
};
use nusense_estimator::calibration::push_centre::{
    fit_push_centre_shift, most_shift_mm, unshifted_centre, PushCentreSample,
};
use nusense_estimator::calibration::push_normal::{
    fit_push_normal_share, is_push, uncorrected_normal_n, PushNormalSample,
};
use nusense_estimator::calibration::{
    align_by_time, fit_force_line, forces_at_times, parse_force_log_csv, parse_pairs_csv, parse_position_log_csv,
    parse_torque_log_csv, positions_at_times, set_config_pad_map, set_config_push_centre_shift,
    set_config_push_normal_share, set_config_shear_modulus, set_config_tangential_force_scale, set_config_torque_scale,
    update_config_toml, CalibrationError, CalibrationSample, FitOptions, ForceComponent, ForceFit, ForceSample,
    TimedGamma,
};
use nusense_estimator::{Estimator, MapResidual, Mode, SensorConfig, StoredPadMap};
use serde::Serialize;

#[derive(clap::Args)]
pub struct Args {
    /// CSV of (gamma, force) pairs.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["readings", "ft_log"])]
    pairs: Option<PathBuf>,
    /// Readings with timestamps, one JSON object per line.
    #[arg(long, value_name = "FILE", requires = "ft_log")]
    readings: Option<PathBuf>,
    /// Force/torque log (CSV with a time column and fx, fy, fz).
    #[arg(long = "ft-log", value_name = "FILE", requires = "readings")]
    ft_log: Option<PathBuf>,
    /// Which force of the log is the reference.
    #[arg(long, value_enum, default_value_t = CliForce::AbsFz)]
    force: CliForce,
    /// Largest time gap between a reading and the nearest force sample, in milliseconds.
    #[arg(long, value_name = "MS", default_value_t = 20.0)]
    max_skew_ms: f64,
    /// Added to every force-log time (seconds) to bring it onto the readings' clock.
    #[arg(long, value_name = "S", default_value_t = 0.0, allow_negative_numbers = true)]
    time_offset_s: f64,
    /// Two-sided confidence level of the intervals.
    #[arg(long, default_value_t = 0.95)]
    confidence: f64,
    /// A frame with nothing touching the pad: fit this sensor's raw px -> pad mm map on it.
    #[arg(long, value_name = "FRAME")]
    rest: Option<PathBuf>,
    /// Sensor config (TOML) to write what was fitted into; created if missing.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Fit and print, but leave the config file as it is.
    #[arg(long)]
    dry_run: bool,
    /// Print the fit as one JSON object.
    #[arg(long)]
    json: bool,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum CliForce {
    /// |fz|
    AbsFz,
    Fx,
    Fy,
    Fz,
    /// sqrt(fx^2 + fy^2 + fz^2)
    Norm,
}

impl From<CliForce> for ForceComponent {
    fn from(force: CliForce) -> Self {
        match force {
            CliForce::AbsFz => ForceComponent::AbsFz,
            CliForce::Fx => ForceComponent::Fx,
            CliForce::Fy => ForceComponent::Fy,
            CliForce::Fz => ForceComponent::Fz,
            CliForce::Norm => ForceComponent::Norm,
        }
    }
}

#[derive(Serialize)]
struct Report {
    /// The force line; null when only `--rest` was given.
    a: Option<f64>,
    b: Option<f64>,
    a_interval: Option<[f64; 2]>,
    b_interval: Option<[f64; 2]>,
    a_std_error: Option<f64>,
    b_std_error: Option<f64>,
    confidence: f64,
    residual_scale_n: Option<f64>,
    points: usize,
    outliers: usize,
    /// Readings skipped (ok: false) or without a force sample within the skew.
    readings_dropped: usize,
    /// The pad model's stiffness; null without inverse-mode readings in contact.
    modulus: Option<ModulusReport>,
    /// The pad model's shear against its normal stiffness; null without at least two pushes in the session.
    tangential: Option<TangentialReport>,
    /// The pad model's torque against its normal stiffness; null unless the log has a torque column with its unit and
    /// the session at least two twists (`torque_left_alone` says which).
    torque: Option<TorqueReport>,
    /// Why `elastic.torque_scale` was not fitted (and so left as it was) in a session; null otherwise.
    torque_left_alone: Option<String>,
    /// How far a push's centre reads behind it; null unless the log has `x_mm`, `y_mm` and the session at least two
    /// pushes of a tenth of their load (`push_centre_left_alone` says which).
    push_centre: Option<PushCentreReport>,
    /// Why `elastic.push_centre_shift_mm` was not fitted (and so left as it was) in a session; null otherwise.
    push_centre_left_alone: Option<String>,
    /// How much of a push its normal force reads as pressure; null unless the session has a modulus fit and at least
    /// two pushes of a tenth of their load (`push_normal_left_alone` says which).
    push_normal: Option<PushNormalReport>,
    /// Why `elastic.push_normal_share` was not fitted (and so left as it was) in a session; null otherwise.
    push_normal_left_alone: Option<String>,
    /// The rest frame's pad map; null without `--rest`.
    pad_map: Option<PadMapReport>,
    config_written: Option<String>,
}

#[derive(Serialize)]
struct ModulusReport {
    scale: f64,
    scale_interval: [f64; 2],
    /// The config's shear modulus before and after, kPa.
    shear_modulus_kpa_before: f64,
    shear_modulus_kpa: f64,
    residual_scale_n: f64,
    points: usize,
    outliers: usize,
}

#[derive(Serialize)]
struct TangentialReport {
    /// Reference tangential force / the model's, as the session's readings reported it.
    scale: f64,
    scale_interval: [f64; 2],
    /// The config's tangential force scale before and after (after the new modulus's share is taken out).
    tangential_force_scale_before: f64,
    tangential_force_scale: f64,
    residual_scale_n: f64,
    points: usize,
    outliers: usize,
}

#[derive(Serialize)]
struct TorqueReport {
    /// Reference torque / the model's, as the session's readings reported it.
    scale: f64,
    scale_interval: [f64; 2],
    /// The config's torque scale before (its `tangential_force_scale` when `torque_scale` was unset) and after (after
    /// the new modulus's share is taken out).
    torque_scale_before: f64,
    torque_scale: f64,
    residual_scale_nmm: f64,
    points: usize,
    outliers: usize,
}

#[derive(Serialize)]
struct PushCentreReport {
    /// The config's `elastic.push_centre_shift_mm` before and after: mm along the push per unit of the model's push
    /// over load.
    push_centre_shift_mm_before: f64,
    push_centre_shift_mm: f64,
    /// Inverse-mode readings in contact with a force vector and a logged probe position (pushes and presses alike;
    /// the fit uses those pushed by a tenth of their load or more).
    readings: usize,
}

#[derive(Serialize)]
struct PushNormalReport {
    /// The config's `elastic.push_normal_share` before and after: the model's normal force less the reference's (over
    /// the normal scale) per unit of its push squared over its normal force.
    push_normal_share_before: f64,
    push_normal_share: f64,
    /// Inverse-mode readings pushed by a tenth of their load or more: those the share was fitted on.
    pushes: usize,
}

#[derive(Serialize)]
struct PadMapReport {
    width: u32,
    height: u32,
    residual: MapResidual,
}

/// What one run fitted.
struct Fits {
    line: Option<ForceFit>,
    modulus: Option<(ModulusFit, f64)>,
    /// The fit and the config's new `elastic.tangential_force_scale`.
    tangential: Option<(ModulusFit, f64)>,
    /// The fit and the config's new `elastic.torque_scale`, or why it is left as it was (sessions only).
    torque: Option<Result<(ModulusFit, f64), String>>,
    /// The config's new `elastic.push_centre_shift_mm`, or why it is left as it was (sessions only).
    push_centre: Option<Result<PushCentreFit, String>>,
    /// The config's new `elastic.push_normal_share`, or why it is left as it was (sessions only).
    push_normal: Option<Result<PushNormalFit, String>>,
    pad_map: Option<StoredPadMap>,
    readings_dropped: usize,
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    if !(args.max_skew_ms.is_finite() && args.max_skew_ms >= 0.0) {
        bail!("--max-skew-ms must be a finite number >= 0, got {}", args.max_skew_ms);
    }
    if !args.time_offset_s.is_finite() {
        bail!("--time-offset-s must be finite, got {}", args.time_offset_s);
    }
    if args.pairs.is_none() && args.readings.is_none() && args.rest.is_none() {
        bail!("give --pairs FILE, or --readings FILE together with --ft-log FILE, and/or --rest FRAME");
    }
    let existing = match &args.config {
        Some(path) => match std::fs::read_to_string(path) {
            Ok(text) => Some(text),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
            Err(e) => return Err(e).with_context(|| format!("cannot read {}", path.display())),
        },
        None => None,
    };
    // The text just read is the config the fits start from (its modulus) and the one they are written into.
    let config = match (&existing, &args.config) {
        (Some(text), Some(path)) => SensorConfig::from_toml_str(text)
            .with_context(|| format!("loading the sensor configuration {}", path.display()))?,
        _ => SensorConfig::default(),
    };
    let fits = fit_all(&args, &config)?;
    if let (Some(line), Some(path), false) = (&fits.line, &args.config, args.dry_run) {
        // A force that falls (or stays) as the pad deforms more is no sensor's line: it comes from a log that does not
        // belong to these readings (another column, another clock). Written, it would put every reading below the
        // detection floor, and the sensor would report no contact ever after.
        if !(line.a > 0.0) {
            bail!(
                "the fitted line F = {:.4} gamma {:+.4} N does not rise with gamma; {} was not changed (check the force \
                 column and the clock offset, or see the fit with --dry-run)",
                line.a,
                line.b,
                path.display()
            );
        }
    }

    let config_written = match (&args.config, args.dry_run) {
        (Some(path), false) => {
            let mut text = existing.unwrap_or_default();
            let context = || format!("cannot update the sensor config {}", path.display());
            if let Some(line) = &fits.line {
                text = update_config_toml(&text, line.a, line.b).with_context(context)?;
            }
            if let Some((_, kpa)) = fits.modulus {
                text = set_config_shear_modulus(&text, kpa).with_context(context)?;
            }
            if let Some((_, scale)) = fits.tangential {
                text = set_config_tangential_force_scale(&text, scale).with_context(context)?;
            }
            if let Some(Ok((_, scale))) = fits.torque {
                text = set_config_torque_scale(&text, scale).with_context(context)?;
            }
            if let Some(Ok(fit)) = fits.push_centre {
                text = set_config_push_centre_shift(&text, fit.shift_mm).with_context(context)?;
            }
            if let Some(Ok(fit)) = fits.push_normal {
                text = set_config_push_normal_share(&text, fit.share).with_context(context)?;
            }
            if let Some(map) = &fits.pad_map {
                text = set_config_pad_map(&text, map).with_context(context)?;
            }
            std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))?;
            Some(path.display().to_string())
        }
        _ => None,
    };

    if args.json {
        println!(
            "{}",
            serde_json::to_string(&report(&fits, &config, args.confidence, config_written))?
        );
    } else {
        print_human(
            &fits,
            &config,
            config_written.as_deref(),
            args.dry_run && args.config.is_some(),
        );
    }
    Ok(ExitCode::SUCCESS)
}

fn fit_all(args: &Args, config: &SensorConfig) -> anyhow::Result<Fits> {
    let options = FitOptions {
        confidence: args.confidence,
        ..FitOptions::default()
    };
    let mut fits = Fits {
        line: None,
        modulus: None,
        tangential: None,
        torque: None,
        push_centre: None,
        push_normal: None,
        pad_map: None,
        readings_dropped: 0,
    };
    if let Some(path) = &args.pairs {
        let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
        let samples = parse_pairs_csv(&text).with_context(|| format!("in {}", path.display()))?;
        fits.line = Some(fit_force_line(&samples, &options).context("cannot fit the force calibration")?);
    }
    if let (Some(readings_path), Some(log_path)) = (&args.readings, &args.ft_log) {
        let session = load_session(args, config, readings_path, log_path)?;
        fits.line = Some(fit_force_line(&session.samples, &options).context("cannot fit the force calibration")?);
        fits.readings_dropped = session.dropped;
        if session.model.len() >= 2 {
            let fit = fit_modulus_scale(&session.model, options.bisquare_c, args.confidence)
                .context("cannot fit the pad model's modulus")?;
            fits.modulus = Some((fit, config.elastic.shear_modulus_kpa * fit.scale));
        }
        // The readings' shear came from the config's modulus; the new one scales the model's shear by its own
        // factor, which the tangential scale must not count twice.
        let modulus_scale = fits.modulus.as_ref().map_or(1.0, |(fit, _)| fit.scale);
        match fit_tangential_scale(&session.tangential, options.bisquare_c, args.confidence) {
            Ok(fit) => {
                let scale = config.elastic.tangential_force_scale * fit.scale / modulus_scale;
                fits.tangential = Some((fit, scale));
            }
            // A session of normal presses: nothing to say about shear.
            Err(CalibrationError::TooFewPoints { .. }) => {}
            Err(e) => return Err(e).context("cannot fit the pad model's tangential force scale"),
        }
        // As the tangential scale: relative to the torque the readings were made with, less the new modulus's share.
        fits.torque = Some(match &session.torques {
            Err(why) => Err(why.clone()),
            Ok(samples) => match fit_torque_scale(samples, options.bisquare_c, args.confidence) {
                Ok(fit) => Ok((fit, config.elastic.torque_factor() * fit.scale / modulus_scale)),
                Err(CalibrationError::TooFewPoints { found, needed }) => {
                    Err(format!("{found} readings twisted by 2 N mm or more, {needed} needed"))
                }
                Err(e) => return Err(e).context("cannot fit the pad model's torque scale"),
            },
        });
        // The shift is in the model's push over load, which neither the modulus nor the tangential scale changes.
        fits.push_centre = Some(match &session.push_centres {
            None => Err("the force/torque log has no x_mm, y_mm columns".to_string()),
            Some(samples) => match fit_push_centre_shift(samples) {
                Ok(shift_mm) => Ok(PushCentreFit {
                    shift_mm,
                    readings: samples.len(),
                }),
                Err(CalibrationError::TooFewPushes { found, needed }) => Err(format!(
                    "{found} readings with a logged position pushed by a tenth of their load or more, {needed} needed"
                )),
                Err(e) => return Err(e).context("cannot fit the push centre shift"),
            },
        });
        // The pushes' excess normal force is measured against the normal scale as the session's readings reported it
        // (the modulus fit's): the share is a ratio of model forces, which neither the modulus nor the tangential
        // scale changes.
        fits.push_normal = Some(match &fits.modulus {
            None => Err("no pad model fit (fewer than two inverse-mode readings in contact)".to_string()),
            Some((modulus, _)) => match fit_push_normal_share(&session.push_normals, modulus.scale) {
                Ok(share) => Ok(PushNormalFit {
                    share,
                    pushes: session.push_normals.iter().filter(|s| is_push(s)).count(),
                }),
                Err(CalibrationError::TooFewPushes { found, needed }) => Err(format!(
                    "{found} inverse-mode readings pushed by a tenth of their load or more, {needed} needed"
                )),
                Err(e) => return Err(e).context("cannot fit the push normal share"),
            },
        });
    }
    if let Some(path) = &args.rest {
        let frame = read_image_rgb(path).with_context(|| format!("rest frame {}", path.display()))?;
        // The map is fitted afresh: a stored one would only have its pose re-fitted.
        let config = SensorConfig {
            pad_map: None,
            ..config.clone()
        };
        let estimator = Estimator::new(config, Mode::Fast, &frame)
            .with_context(|| format!("cannot find the pattern in the rest frame {}", path.display()))?;
        fits.pad_map = Some(estimator.mapping().stored());
    }
    Ok(fits)
}

/// The push centre shift and the readings it was fitted on.
#[derive(Clone, Copy)]
struct PushCentreFit {
    shift_mm: f64,
    readings: usize,
}

/// The push normal share and the pushes it was fitted on.
#[derive(Clone, Copy)]
struct PushNormalFit {
    share: f64,
    pushes: usize,
}

/// A session's readings paired with the force log.
struct Session {
    samples: Vec<CalibrationSample>,
    /// Inverse-mode readings in contact: the model's force against the reference.
    model: Vec<ModelForceSample>,
    /// The same readings' tangential force (its size) against the reference's; empty when the log has no fx, fy.
    tangential: Vec<ModelForceSample>,
    /// The same readings' torque about the normal against the reference's, or why the log gives none.
    torques: Result<Vec<ModelTorqueSample>, String>,
    /// The same readings' strongest contact, un-shifted, against the log's probe position; `None` when the log has
    /// no x_mm, y_mm.
    push_centres: Option<Vec<PushCentreSample>>,
    /// The same readings' model force vector, their push's share put back, against the reference normal force the
    /// modulus is fitted on.
    push_normals: Vec<PushNormalSample>,
    dropped: usize,
}

fn load_session(
    args: &Args,
    config: &SensorConfig,
    readings_path: &PathBuf,
    log_path: &PathBuf,
) -> anyhow::Result<Session> {
    let text =
        std::fs::read_to_string(readings_path).with_context(|| format!("cannot read {}", readings_path.display()))?;
    let parsed = parse_readings(&text).with_context(|| format!("in {}", readings_path.display()))?;
    let log = std::fs::read_to_string(log_path).with_context(|| format!("cannot read {}", log_path.display()))?;
    // The log's chosen force on the readings' clock.
    let read_log = |component: ForceComponent| {
        parse_force_log_csv(&log, component).map(|mut forces| {
            for f in &mut forces {
                f.time_s += args.time_offset_s;
            }
            forces
        })
    };
    let forces = read_log(args.force.into()).with_context(|| format!("in {}", log_path.display()))?;
    let max_skew_s = args.max_skew_ms / 1e3;
    let alignment = align_by_time(&parsed.readings, &forces, max_skew_s)
        .context("cannot align the readings with the force log (check the clocks, --time-offset-s, --max-skew-ms)")?;
    let model = with_reference(parsed.model.iter().map(|m| (m.time_s, m.force_n)), &forces, max_skew_s);
    let push_normals = push_normal_samples(&parsed.model, &forces, config, max_skew_s);
    let tangential = match read_log(ForceComponent::Tangential) {
        Ok(pushes) => with_reference(
            parsed.model.iter().filter_map(|m| Some((m.time_s, m.tangential_n?))),
            &pushes,
            max_skew_s,
        ),
        // A log of the normal force alone (no fx, fy columns): the normal calibrations still stand.
        Err(CalibrationError::MissingColumn { .. }) => Vec::new(),
        Err(e) => return Err(e).with_context(|| format!("in {}", log_path.display())),
    };
    let torques = match parse_torque_log_csv(&log) {
        Ok(Some(mut log_torques)) => {
            for t in &mut log_torques {
                t.time_s += args.time_offset_s;
            }
            let twisted: Vec<(f64, f64)> = parsed
                .model
                .iter()
                .filter_map(|m| Some((m.time_s, m.torque_nmm?)))
                .collect();
            Ok(with_reference(twisted.into_iter(), &log_torques, max_skew_s)
                .into_iter()
                .map(|s| ModelTorqueSample {
                    model_nmm: s.model_n,
                    reference_nmm: s.reference_n,
                })
                .collect())
        }
        Ok(None) => Err("the force/torque log has no torque column (mz_nmm, tz_nmm, mz_nm or tz_nm)".to_string()),
        // A torque whose unit is unknown is left out; the forces still calibrate.
        Err(e @ CalibrationError::TorqueUnit { .. }) => Err(e.to_string()),
        Err(e) => return Err(e).with_context(|| format!("in {}", log_path.display())),
    };
    let push_centres = match parse_position_log_csv(&log).with_context(|| format!("in {}", log_path.display()))? {
        None => None,
        Some(mut positions) => {
            for p in &mut positions {
                p.time_s += args.time_offset_s;
            }
            Some(push_centre_samples(&parsed.model, &positions, config, max_skew_s))
        }
    };
    Ok(Session {
        samples: alignment.samples,
        model,
        tangential,
        torques,
        push_centres,
        push_normals,
        dropped: parsed.skipped + alignment.dropped,
    })
}

/// Each reading's strongest contact against the log's probe position at its time (those with no position sample
/// within `max_skew_s`, or without a force vector, are left out). The readings are taken to have been made with
/// `config`: their fx, fy are divided by its `tangential_force_scale` to give the model's, and their centre is moved
/// back by its `push_centre_shift_mm` (exactly: the move depends only on the contact's force and the config).
fn push_centre_samples(
    readings: &[TimedModelForce],
    positions: &[nusense_estimator::calibration::PositionSample],
    config: &SensorConfig,
    max_skew_s: f64,
) -> Vec<PushCentreSample> {
    let times: Vec<f64> = readings.iter().map(|r| r.time_s).collect();
    let scale = config.elastic.tangential_force_scale;
    let most_mm = most_shift_mm(&config.pad);
    readings
        .iter()
        .zip(positions_at_times(&times, positions, max_skew_s))
        .filter_map(|(reading, truth)| {
            let (centre, [fx, fy, fz]) = reading.strongest?;
            let model = [fx / scale, fy / scale, fz];
            Some(PushCentreSample {
                model_force_vector_n: model,
                read_centre_mm: unshifted_centre(centre, model, config.elastic.push_centre_shift_mm, most_mm),
                true_centre_mm: truth?,
            })
        })
        .collect()
}

/// Each reading with a force vector against the log's reference force at its time (the one the modulus is fitted on;
/// those with no log sample within `max_skew_s` are left out). The readings are taken to have been made with
/// `config`: the model's push is their tangential force over its `tangential_force_scale`, and their normal force gets
/// back what its `push_normal_share` had taken off for that push. That is exact for one contact at a time (a session of
/// one probe: the reading's total is then the contact's own; with several, the total push is not the sum of theirs)
/// unless the share cut the normal force off at 0, so readings that read 0 N are left out. The push's direction is not
/// kept: the share needs only its size.
fn push_normal_samples(
    readings: &[TimedModelForce],
    log: &[ForceSample],
    config: &SensorConfig,
    max_skew_s: f64,
) -> Vec<PushNormalSample> {
    let pushed: Vec<(f64, f64, f64)> = readings
        .iter()
        .filter(|r| r.force_n > 0.0)
        .filter_map(|r| Some((r.time_s, r.force_n, r.tangential_n?)))
        .collect();
    let times: Vec<f64> = pushed.iter().map(|p| p.0).collect();
    let scale = config.elastic.tangential_force_scale;
    let share = config.elastic.push_normal_share;
    pushed
        .iter()
        .zip(forces_at_times(&times, log, max_skew_s))
        .filter_map(|(&(_, force_n, tangential_n), reference)| {
            let push = tangential_n / scale;
            Some(PushNormalSample {
                model_force_vector_n: [push, 0.0, uncorrected_normal_n(force_n, push, share)],
                reference_normal_n: reference?,
            })
        })
        .collect()
}

/// Each (time, model force) paired with the log's force at that time; those with no log sample within `max_skew_s`
/// are left out.
fn with_reference(
    readings: impl Iterator<Item = (f64, f64)>,
    log: &[ForceSample],
    max_skew_s: f64,
) -> Vec<ModelForceSample> {
    let readings: Vec<(f64, f64)> = readings.collect();
    let times: Vec<f64> = readings.iter().map(|r| r.0).collect();
    readings
        .iter()
        .zip(forces_at_times(&times, log, max_skew_s))
        .filter_map(|(&(_, model_n), reference)| reference.map(|reference_n| ModelForceSample { model_n, reference_n }))
        .collect()
}

/// Time fields a reading may carry, with their unit in seconds.
const TIME_FIELDS: [(&str, f64); 6] = [
    ("timestamp_s", 1.0),
    ("time_s", 1.0),
    ("t", 1.0),
    ("timestamp", 1.0),
    ("timestamp_ms", 1e-3),
    ("timestamp_us", 1e-6),
];

/// An inverse-mode reading in contact: the model's normal force at a time, the size of its tangential force when
/// the reading has a force vector, and its strongest contact's centre (`contact_mm`) and force vector (the
/// contact's own, or the reading's when it lists no contacts) when it has both.
#[derive(Clone, Copy, Debug, PartialEq)]
struct TimedModelForce {
    time_s: f64,
    force_n: f64,
    tangential_n: Option<f64>,
    /// The torque about the normal, N mm.
    torque_nmm: Option<f64>,
    strongest: Option<([f64; 2], [f64; 3])>,
}

/// A JSON array of N finite numbers.
fn numbers<const N: usize>(value: Option<&serde_json::Value>) -> Option<[f64; N]> {
    let array = value?.as_array()?;
    if array.len() != N {
        return None;
    }
    let mut out = [0.0; N];
    for (o, v) in out.iter_mut().zip(array) {
        *o = v.as_f64().filter(|v| v.is_finite())?;
    }
    Some(out)
}

/// What a readings file holds for calibration.
#[derive(Debug, PartialEq)]
struct ParsedReadings {
    readings: Vec<TimedGamma>,
    model: Vec<TimedModelForce>,
    /// Lines without a measurement (`ok: false`, or a message without an estimate).
    skipped: usize,
}

/// Readings with a time and a gamma, and the model's force of those in inverse mode with contact.
fn parse_readings(text: &str) -> anyhow::Result<ParsedReadings> {
    let mut parsed = ParsedReadings {
        readings: Vec::new(),
        model: Vec::new(),
        skipped: 0,
    };
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let n = i + 1;
        let value: serde_json::Value =
            serde_json::from_str(line).with_context(|| format!("line {n} is not a JSON object"))?;
        if value.get("schema_version").is_some() {
            // A reading message: the estimate (if any) and the capture time.
            let Some(estimate) = value.get("estimate").filter(|e| e.is_object()) else {
                parsed.skipped += 1;
                continue;
            };
            let gamma = estimate
                .get("gamma")
                .and_then(serde_json::Value::as_f64)
                .with_context(|| format!("line {n}: the estimate has no numeric `gamma`"))?;
            let time_s = value
                .get("capture_time_us")
                .and_then(serde_json::Value::as_f64)
                .with_context(|| format!("line {n} has no `capture_time_us`"))?
                * 1e-6;
            parsed.readings.push(TimedGamma { time_s, gamma });
            let inverse = estimate.get("mode").and_then(serde_json::Value::as_str) == Some("inverse");
            let contact = estimate.get("contact").and_then(serde_json::Value::as_bool) == Some(true);
            if inverse && contact {
                let force_n = estimate
                    .get("force_n")
                    .and_then(serde_json::Value::as_f64)
                    .with_context(|| {
                        format!("line {n}: an inverse-mode estimate in contact has no numeric `force_n`")
                    })?;
                let tangential_n = estimate
                    .get("force_vector_n")
                    .and_then(serde_json::Value::as_array)
                    .and_then(|v| Some(v.first()?.as_f64()?.hypot(v.get(1)?.as_f64()?)));
                let strongest_vector = estimate
                    .get("contacts")
                    .and_then(serde_json::Value::as_array)
                    .and_then(|c| c.first())
                    .map_or(estimate.get("force_vector_n"), |c| c.get("force_vector_n"));
                let strongest = numbers::<2>(estimate.get("contact_mm")).zip(numbers::<3>(strongest_vector));
                let torque_nmm = estimate
                    .get("torque_nmm")
                    .and_then(serde_json::Value::as_f64)
                    .filter(|t| t.is_finite());
                parsed.model.push(TimedModelForce {
                    time_s,
                    force_n,
                    tangential_n,
                    torque_nmm,
                    strongest,
                });
            }
            continue;
        }
        if value.get("ok").and_then(serde_json::Value::as_bool) == Some(false) {
            parsed.skipped += 1;
            continue;
        }
        let gamma = value
            .get("gamma")
            .and_then(serde_json::Value::as_f64)
            .with_context(|| format!("line {n} has no numeric `gamma`"))?;
        let time_s = TIME_FIELDS
            .iter()
            .find_map(|&(field, unit)| value.get(field).and_then(serde_json::Value::as_f64).map(|t| t * unit))
            .with_context(|| {
                let names: Vec<&str> = TIME_FIELDS.iter().map(|f| f.0).collect();
                format!("line {n} has no time field (one of {})", names.join(", "))
            })?;
        parsed.readings.push(TimedGamma { time_s, gamma });
    }
    Ok(parsed)
}

fn report(fits: &Fits, config: &SensorConfig, confidence: f64, config_written: Option<String>) -> Report {
    let line = fits.line.as_ref();
    Report {
        a: line.map(|f| f.a),
        b: line.map(|f| f.b),
        a_interval: line.map(|f| f.a_interval),
        b_interval: line.map(|f| f.b_interval),
        a_std_error: line.map(|f| f.a_std_error),
        b_std_error: line.map(|f| f.b_std_error),
        confidence,
        residual_scale_n: line.map(|f| f.residual_scale_n),
        points: line.map_or(0, |f| f.points),
        outliers: line.map_or(0, |f| f.outliers),
        readings_dropped: fits.readings_dropped,
        modulus: fits.modulus.map(|(fit, kpa)| ModulusReport {
            scale: fit.scale,
            scale_interval: fit.scale_interval,
            shear_modulus_kpa_before: config.elastic.shear_modulus_kpa,
            shear_modulus_kpa: kpa,
            residual_scale_n: fit.residual_scale_n,
            points: fit.points,
            outliers: fit.outliers,
        }),
        tangential: fits.tangential.map(|(fit, scale)| TangentialReport {
            scale: fit.scale,
            scale_interval: fit.scale_interval,
            tangential_force_scale_before: config.elastic.tangential_force_scale,
            tangential_force_scale: scale,
            residual_scale_n: fit.residual_scale_n,
            points: fit.points,
            outliers: fit.outliers,
        }),
        torque: fits
            .torque
            .as_ref()
            .and_then(|r| r.as_ref().ok())
            .map(|(fit, scale)| TorqueReport {
                scale: fit.scale,
                scale_interval: fit.scale_interval,
                torque_scale_before: config.elastic.torque_factor(),
                torque_scale: *scale,
                residual_scale_nmm: fit.residual_scale_n,
                points: fit.points,
                outliers: fit.outliers,
            }),
        torque_left_alone: fits.torque.as_ref().and_then(|r| r.as_ref().err().cloned()),
        push_centre: fits
            .push_centre
            .as_ref()
            .and_then(|r| r.as_ref().ok())
            .map(|fit| PushCentreReport {
                push_centre_shift_mm_before: config.elastic.push_centre_shift_mm,
                push_centre_shift_mm: fit.shift_mm,
                readings: fit.readings,
            }),
        push_centre_left_alone: fits.push_centre.as_ref().and_then(|r| r.as_ref().err().cloned()),
        push_normal: fits
            .push_normal
            .as_ref()
            .and_then(|r| r.as_ref().ok())
            .map(|fit| PushNormalReport {
                push_normal_share_before: config.elastic.push_normal_share,
                push_normal_share: fit.share,
                pushes: fit.pushes,
            }),
        push_normal_left_alone: fits.push_normal.as_ref().and_then(|r| r.as_ref().err().cloned()),
        pad_map: fits.pad_map.map(|m| PadMapReport {
            width: m.width,
            height: m.height,
            residual: m.residual,
        }),
        config_written,
    }
}

fn print_human(fits: &Fits, config: &SensorConfig, config_written: Option<&str>, dry_run: bool) {
    if let Some(fit) = &fits.line {
        let level = fit.confidence * 100.0;
        println!(
            "F = a * gamma + b from {} points ({} outliers given no weight)",
            fit.points, fit.outliers
        );
        println!(
            "  a = {:.4}   {level:.0} % interval [{:.4}, {:.4}]",
            fit.a, fit.a_interval[0], fit.a_interval[1]
        );
        println!(
            "  b = {:.4} N {level:.0} % interval [{:.4}, {:.4}]",
            fit.b, fit.b_interval[0], fit.b_interval[1]
        );
        println!("  robust residual scale {:.4} N", fit.residual_scale_n);
    }
    if fits.readings_dropped > 0 {
        println!(
            "  {} readings dropped (not ok, or no force sample close enough in time)",
            fits.readings_dropped
        );
    }
    if let Some((fit, kpa)) = &fits.modulus {
        let level = fit.confidence * 100.0;
        println!(
            "pad model: reference force = {:.4} x model force from {} inverse-mode readings ({} outliers), \
             {level:.0} % interval [{:.4}, {:.4}], residual scale {:.4} N",
            fit.scale, fit.points, fit.outliers, fit.scale_interval[0], fit.scale_interval[1], fit.residual_scale_n
        );
        println!(
            "  shear modulus {:.2} kPa -> {kpa:.2} kPa",
            config.elastic.shear_modulus_kpa
        );
    }
    if let Some((fit, scale)) = &fits.tangential {
        let level = fit.confidence * 100.0;
        println!(
            "pad model's shear: reference tangential force = {:.4} x model's from {} pushes ({} outliers), \
             {level:.0} % interval [{:.4}, {:.4}], residual scale {:.4} N",
            fit.scale, fit.points, fit.outliers, fit.scale_interval[0], fit.scale_interval[1], fit.residual_scale_n
        );
        println!(
            "  tangential force scale {:.4} -> {scale:.4}",
            config.elastic.tangential_force_scale
        );
    }
    match &fits.torque {
        Some(Ok((fit, scale))) => {
            let level = fit.confidence * 100.0;
            println!(
                "pad model's torque: reference torque = {:.4} x model's from {} twists ({} outliers), {level:.0} % \
                 interval [{:.4}, {:.4}], residual scale {:.4} N mm",
                fit.scale, fit.points, fit.outliers, fit.scale_interval[0], fit.scale_interval[1], fit.residual_scale_n
            );
            println!("  torque scale {:.4} -> {scale:.4}", config.elastic.torque_factor());
        }
        Some(Err(why)) => match config.elastic.torque_scale {
            Some(scale) => println!("pad model's torque: {why}; elastic.torque_scale left at {scale:.4}"),
            None => println!("pad model's torque: {why}; elastic.torque_scale left unset (the tangential scale)"),
        },
        None => {}
    }
    match &fits.push_centre {
        Some(Ok(fit)) => println!(
            "push centre: fitted on the pushes among {} readings with a logged probe position, shift {:.3} -> {:.3} mm \
             along the push per unit of push over load",
            fit.readings, config.elastic.push_centre_shift_mm, fit.shift_mm
        ),
        Some(Err(why)) => println!(
            "push centre: {why}; elastic.push_centre_shift_mm left at {:.3} mm",
            config.elastic.push_centre_shift_mm
        ),
        None => {}
    }
    match &fits.push_normal {
        Some(Ok(fit)) => println!(
            "push normal share: fitted on {} pushes, share {:.4} -> {:.4} (the model's normal force reads this times its \
             push squared over itself too much)",
            fit.pushes, config.elastic.push_normal_share, fit.share
        ),
        Some(Err(why)) => println!(
            "push normal share: {why}; elastic.push_normal_share left at {:.4}",
            config.elastic.push_normal_share
        ),
        None => {}
    }
    if let Some(map) = &fits.pad_map {
        let r = map.residual;
        println!(
            "pad map on {}x{}: residual {:.4} mm RMS, {:.4} mm max, {} corners ({} left out)",
            map.width, map.height, r.rms_mm, r.max_mm, r.points, r.outliers
        );
    }
    match (config_written, dry_run) {
        (Some(path), _) => println!("wrote the fitted values to {path}"),
        (None, true) => println!("dry run: config left unchanged"),
        (None, false) => println!("no --config given: nothing written"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn readings_take_any_documented_time_field_and_skip_failed_frames() {
        let text = r#"{"frame":"a.jpg","ok":true,"gamma":0.5,"timestamp_us":1500000}
{"frame":"b.jpg","ok":false,"error":"no pattern","gamma":null}

{"frame":"c.jpg","ok":true,"gamma":0.75,"t":2.0}
"#;
        let parsed = parse_readings(text).unwrap();
        assert_eq!(parsed.skipped, 1);
        assert_eq!(
            parsed.readings,
            vec![
                TimedGamma {
                    time_s: 1.5,
                    gamma: 0.5
                },
                TimedGamma {
                    time_s: 2.0,
                    gamma: 0.75
                }
            ]
        );
        assert!(parsed.model.is_empty());
        let messages = r#"{"schema_version":1,"frame_id":0,"capture_time_us":2500000,"estimate":{"mode":"fast","contact":true,"gamma":0.25,"force_n":0.3}}
{"schema_version":1,"frame_id":1,"capture_time_us":2600000,"estimate":null,"error":"no pattern"}
{"schema_version":1,"frame_id":2,"capture_time_us":2700000,"estimate":{"mode":"inverse","contact":true,"gamma":0.5,"force_n":4.5}}
{"schema_version":1,"frame_id":3,"capture_time_us":2800000,"estimate":{"mode":"inverse","contact":false,"gamma":0.01,"force_n":0.0}}
"#;
        let parsed = parse_readings(messages).unwrap();
        assert_eq!(parsed.skipped, 1);
        assert_eq!(parsed.readings.len(), 3);
        assert_eq!(
            parsed.readings[0],
            TimedGamma {
                time_s: 2.5,
                gamma: 0.25
            }
        );
        // Only the inverse's force in contact is the pad model's: the fast mode's is the paper's line.
        assert_eq!(parsed.model.len(), 1);
        assert!(
            (parsed.model[0].time_s - 2.7).abs() < 1e-12 && parsed.model[0].force_n == 4.5,
            "{:?}",
            parsed.model
        );
        let err = parse_readings(r#"{"ok":true,"gamma":1.0}"#).unwrap_err();
        assert!(format!("{err:#}").contains("line 1 has no time field"), "{err:#}");
        assert!(parse_readings("not json").is_err());
    }

    #[test]
    fn a_readings_strongest_contact_is_taken_back_to_the_models_push_and_unshifted_centre() {
        // The contact's own vector, not the reading's total (which a second contact would change).
        let messages = r#"{"schema_version":1,"frame_id":0,"capture_time_us":1000000,"estimate":{"mode":"inverse","contact":true,"gamma":0.5,"force_n":5.0,"contact_mm":[1.375,-2.0],"force_vector_n":[3.0,0.0,5.0],"contacts":[{"force_vector_n":[2.0,0.0,4.0]},{"force_vector_n":[1.0,0.0,1.0]}]}}
{"schema_version":1,"frame_id":1,"capture_time_us":2000000,"estimate":{"mode":"inverse","contact":true,"gamma":0.5,"force_n":4.0,"contact_mm":[0.0,0.0],"force_vector_n":null,"contacts":[]}}
"#;
        let parsed = parse_readings(messages).unwrap();
        assert_eq!(parsed.model[0].strongest, Some(([1.375, -2.0], [2.0, 0.0, 4.0])));
        assert_eq!(parsed.model[1].strongest, None, "no force vector: no push");
        // Read with a tangential scale of 2 and a shift of 1.5 mm: the model's push is [1, 0, 4], a quarter of the
        // load, so the centre was moved 0.375 mm along x.
        let mut config = SensorConfig::default();
        config.elastic.tangential_force_scale = 2.0;
        config.elastic.push_centre_shift_mm = 1.5;
        let positions = [
            nusense_estimator::calibration::PositionSample {
                time_s: 0.99,
                position_mm: [1.0, -2.0],
            },
            nusense_estimator::calibration::PositionSample {
                time_s: 1.01,
                position_mm: [2.0, -2.0],
            },
        ];
        let samples = push_centre_samples(&parsed.model, &positions, &config, 0.02);
        assert_eq!(samples.len(), 1, "{samples:?}");
        assert_eq!(samples[0].model_force_vector_n, [1.0, 0.0, 4.0]);
        assert!((samples[0].read_centre_mm[0] - 1.0).abs() < 1e-12 && samples[0].read_centre_mm[1] == -2.0);
        assert!((samples[0].true_centre_mm[0] - 1.5).abs() < 1e-9 && samples[0].true_centre_mm[1] == -2.0);
    }

    #[test]
    fn a_readings_normal_force_gets_back_what_the_configs_share_took_off_for_its_push() {
        // Read with a tangential scale of 2 and a share of 0.1: a model push of 1.5 N read as 3 N, and the model's
        // 4 N normal force read as 4 - 0.1 * 1.5^2 / 4 N.
        let mut config = SensorConfig::default();
        config.elastic.tangential_force_scale = 2.0;
        config.elastic.push_normal_share = 0.1;
        let reading = |time_s: f64, force_n: f64, tangential_n: Option<f64>| TimedModelForce {
            time_s,
            force_n,
            tangential_n,
            torque_nmm: None,
            strongest: None,
        };
        let readings = [
            reading(1.0, 4.0 - 0.1 * 1.5 * 1.5 / 4.0, Some(3.0)),
            // Cut off at 0 by the share: its model normal force is not known.
            reading(2.0, 0.0, Some(3.0)),
            // No force vector: no push.
            reading(3.0, 5.0, None),
            // No log sample within the skew.
            reading(9.0, 5.0, Some(1.0)),
            reading(4.0, 6.0, Some(0.0)),
        ];
        let log: Vec<ForceSample> = [1.0, 2.0, 3.0, 4.0]
            .iter()
            .map(|&time_s| ForceSample {
                time_s,
                force_n: 2.0 * time_s,
            })
            .collect();
        let samples = push_normal_samples(&readings, &log, &config, 0.02);
        assert_eq!(samples.len(), 2, "{samples:?}");
        assert_eq!(samples[0].reference_normal_n, 2.0);
        let [fx, fy, fz] = samples[0].model_force_vector_n;
        assert!(
            (fx - 1.5).abs() < 1e-12 && fy == 0.0 && (fz - 4.0).abs() < 1e-12,
            "{samples:?}"
        );
        assert_eq!(samples[1].model_force_vector_n, [0.0, 0.0, 6.0]);
        assert_eq!(samples[1].reference_normal_n, 8.0);
        assert!(is_push(&samples[0]) && !is_push(&samples[1]));
    }
}
