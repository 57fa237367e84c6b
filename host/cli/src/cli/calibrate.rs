//! `nusense calibrate`: fit the force calibration F = a * gamma + b and write it into the sensor config.
//!
//! Input, one of:
//! - `--pairs FILE.csv`: (gamma, force) pairs; a header naming `gamma` and `force` (or `force_n`), or no header
//!   and those two columns in that order.
//! - `--readings FILE.jsonl --ft-log FILE.csv`: a recorded session. Readings are JSON lines (as `nusense analyze
//!   --json`, `nusense replay --json`, the daemon's stream and recordings write them: `estimate.gamma` at
//!   `capture_time_us`; lines without an estimate are skipped). Flat lines with `gamma` and a time field
//!   (`timestamp_s`, `time_s`, `t`, `timestamp_ms` or `timestamp_us`) are read too; those with `ok: false` are
//!   skipped. The force/torque log is CSV with a time column (`timestamp`, `time`,
//!   `t`, optional `_s`/`_ms`/`_us` suffix) and `fx, fy, fz`. Each reading takes the force interpolated at its
//!   time when a force sample lies within `--max-skew-ms`; others are dropped and counted.
//!
//! With `--config FILE`, a and b are written into that TOML (created if missing; other keys and comments are
//! kept) unless `--dry-run`. `--json` prints the fit as one JSON object.
//! Exit code: 0 on a fit, 1 when the data cannot be fitted or the config cannot be written.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{bail, Context};
use nusense_estimator::calibration::{
    align_by_time, fit_force_line, parse_force_log_csv, parse_pairs_csv, update_config_toml, CalibrationSample,
    FitOptions, ForceComponent, ForceFit, TimedGamma,
};
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
    /// Sensor config (TOML) to write a and b into; created if missing.
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
    a: f64,
    b: f64,
    a_interval: [f64; 2],
    b_interval: [f64; 2],
    a_std_error: f64,
    b_std_error: f64,
    confidence: f64,
    residual_scale_n: f64,
    points: usize,
    outliers: usize,
    /// Readings skipped (ok: false) or without a force sample within the skew.
    readings_dropped: usize,
    config_written: Option<String>,
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    if !(args.max_skew_ms.is_finite() && args.max_skew_ms >= 0.0) {
        bail!("--max-skew-ms must be a finite number >= 0, got {}", args.max_skew_ms);
    }
    if !args.time_offset_s.is_finite() {
        bail!("--time-offset-s must be finite, got {}", args.time_offset_s);
    }
    let (samples, readings_dropped) = load_samples(&args)?;
    let options = FitOptions {
        confidence: args.confidence,
        ..FitOptions::default()
    };
    let fit = fit_force_line(&samples, &options).context("cannot fit the force calibration")?;

    let config_written = match (&args.config, args.dry_run) {
        (Some(path), false) => {
            let text = match std::fs::read_to_string(path) {
                Ok(text) => text,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => String::new(),
                Err(e) => return Err(e).with_context(|| format!("cannot read {}", path.display())),
            };
            let updated = update_config_toml(&text, fit.a, fit.b)
                .with_context(|| format!("cannot update the sensor config {}", path.display()))?;
            std::fs::write(path, updated).with_context(|| format!("cannot write {}", path.display()))?;
            Some(path.display().to_string())
        }
        _ => None,
    };

    if args.json {
        println!(
            "{}",
            serde_json::to_string(&report(&fit, readings_dropped, config_written))?
        );
    } else {
        print_human(
            &fit,
            readings_dropped,
            config_written.as_deref(),
            args.dry_run && args.config.is_some(),
        );
    }
    Ok(ExitCode::SUCCESS)
}

fn load_samples(args: &Args) -> anyhow::Result<(Vec<CalibrationSample>, usize)> {
    if let Some(path) = &args.pairs {
        let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
        let samples = parse_pairs_csv(&text).with_context(|| format!("in {}", path.display()))?;
        return Ok((samples, 0));
    }
    let (Some(readings_path), Some(log_path)) = (&args.readings, &args.ft_log) else {
        bail!("give either --pairs FILE, or --readings FILE together with --ft-log FILE");
    };
    let text =
        std::fs::read_to_string(readings_path).with_context(|| format!("cannot read {}", readings_path.display()))?;
    let (readings, skipped) = parse_readings(&text).with_context(|| format!("in {}", readings_path.display()))?;
    let log = std::fs::read_to_string(log_path).with_context(|| format!("cannot read {}", log_path.display()))?;
    let mut forces =
        parse_force_log_csv(&log, args.force.into()).with_context(|| format!("in {}", log_path.display()))?;
    for f in &mut forces {
        f.time_s += args.time_offset_s;
    }
    let alignment = align_by_time(&readings, &forces, args.max_skew_ms / 1e3)
        .context("cannot align the readings with the force log (check the clocks, --time-offset-s, --max-skew-ms)")?;
    Ok((alignment.samples, skipped + alignment.dropped))
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

/// Readings with a time and a gamma; returns them and the number of lines skipped (`ok: false`).
fn parse_readings(text: &str) -> anyhow::Result<(Vec<TimedGamma>, usize)> {
    let mut readings = Vec::new();
    let mut skipped = 0;
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
                skipped += 1;
                continue;
            };
            let gamma = estimate
                .get("gamma")
                .and_then(serde_json::Value::as_f64)
                .with_context(|| format!("line {n}: the estimate has no numeric `gamma`"))?;
            let time_us = value
                .get("capture_time_us")
                .and_then(serde_json::Value::as_f64)
                .with_context(|| format!("line {n} has no `capture_time_us`"))?;
            readings.push(TimedGamma {
                time_s: time_us * 1e-6,
                gamma,
            });
            continue;
        }
        if value.get("ok").and_then(serde_json::Value::as_bool) == Some(false) {
            skipped += 1;
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
        readings.push(TimedGamma { time_s, gamma });
    }
    Ok((readings, skipped))
}

fn report(fit: &ForceFit, readings_dropped: usize, config_written: Option<String>) -> Report {
    Report {
        a: fit.a,
        b: fit.b,
        a_interval: fit.a_interval,
        b_interval: fit.b_interval,
        a_std_error: fit.a_std_error,
        b_std_error: fit.b_std_error,
        confidence: fit.confidence,
        residual_scale_n: fit.residual_scale_n,
        points: fit.points,
        outliers: fit.outliers,
        readings_dropped,
        config_written,
    }
}

fn print_human(fit: &ForceFit, readings_dropped: usize, config_written: Option<&str>, dry_run: bool) {
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
    if readings_dropped > 0 {
        println!("  {readings_dropped} readings dropped (not ok, or no force sample close enough in time)");
    }
    match (config_written, dry_run) {
        (Some(path), _) => println!("wrote calibration.a and calibration.b to {path}"),
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
        let (readings, skipped) = parse_readings(text).unwrap();
        assert_eq!(skipped, 1);
        assert_eq!(
            readings,
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
        let messages = r#"{"schema_version":1,"frame_id":0,"capture_time_us":2500000,"estimate":{"gamma":0.25}}
{"schema_version":1,"frame_id":1,"capture_time_us":2600000,"estimate":null,"error":"no pattern"}
"#;
        let (readings, skipped) = parse_readings(messages).unwrap();
        assert_eq!(skipped, 1);
        assert_eq!(
            readings,
            vec![TimedGamma {
                time_s: 2.5,
                gamma: 0.25
            }]
        );
        let err = parse_readings(r#"{"ok":true,"gamma":1.0}"#).unwrap_err();
        assert!(format!("{err:#}").contains("line 1 has no time field"), "{err:#}");
        assert!(parse_readings("not json").is_err());
    }
}
