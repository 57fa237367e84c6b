//! Calibration: readings aligned with a force/torque log (the clocks' offset found by cross-correlation), the
//! force line F = a * gamma + b fitted robustly with confidence intervals (the estimator's own fit), residuals
//! against force, and the paper's line beside it.

use std::path::Path;

use nusense_estimator::calibration::{
    align_by_time, fit_force_line, parse_force_log_csv, FitOptions, ForceComponent, ForceSample, TimedGamma,
};
use serde::Serialize;

use crate::plot::{Chart, Series, Style};
use crate::recording::SessionReading;
use crate::report::{plot, read_text, table, Report, ReportError};
use nusense_estimator::stats::{pearson, quantile};

use crate::stats::interpolate;

/// The paper's calibration of the original sensor (F = 3.09 gamma - 1.14 N, fitted over 1-8 N).
pub const PAPER_LINE: (f64, f64) = (3.09, -1.14);
/// Clocks whose first samples lie further apart than this are different clocks (one not since the epoch).
const SAME_CLOCK_S: f64 = 3600.0;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CalibrationOptions {
    /// The offset is searched within this far of the clocks' nominal alignment, s.
    pub max_lag_s: f64,
    /// Pairs below this reference force are left out of the fit (the paper fits 1-8 N), N.
    pub min_force_n: f64,
    pub confidence: f64,
}

impl Default for CalibrationOptions {
    fn default() -> Self {
        Self {
            max_lag_s: 2.0,
            min_force_n: 1.0,
            confidence: 0.95,
        }
    }
}

/// The force/torque log's normal force (|fz|).
pub fn load_force_log(path: &Path) -> Result<Vec<ForceSample>, ReportError> {
    let text = read_text(path)?;
    let mut forces = parse_force_log_csv(&text, ForceComponent::AbsFz).map_err(|source| ReportError::ForceLog {
        path: path.display().to_string(),
        source,
    })?;
    forces.retain(|f| f.time_s.is_finite() && f.force_n.is_finite());
    forces.sort_by(|a, b| a.time_s.total_cmp(&b.time_s));
    if forces.len() < 2 {
        return Err(ReportError::NotEnoughData {
            what: "the force log",
            detail: format!("{} samples", forces.len()),
        });
    }
    Ok(forces)
}

/// The offset between the camera's clock and the force log's: F/T time = camera time + `offset_s`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ClockOffset {
    pub offset_s: f64,
    /// Correlation of gamma with the force at the best lag.
    pub correlation: f64,
    /// Spacing of the lags searched, s (the estimate is refined between them).
    pub lag_step_s: f64,
    /// (lag, correlation) for every lag searched.
    #[serde(skip)]
    pub curve: Vec<(f64, f64)>,
}

/// Finds the lag that best correlates gamma with the logged force, within `max_lag_s` of the clocks' nominal
/// alignment (the same clock when their first samples are within an hour, else their first samples).
pub fn find_clock_offset(
    readings: &[SessionReading],
    forces: &[ForceSample],
    max_lag_s: f64,
) -> Result<ClockOffset, ReportError> {
    let series: Vec<(f64, f64)> = forces.iter().map(|f| (f.time_s, f.force_n)).collect();
    let (Some(first_reading), Some(first_force)) = (readings.first(), forces.first()) else {
        return Err(ReportError::NotEnoughData {
            what: "clock offset",
            detail: "no readings or forces".into(),
        });
    };
    let nominal = first_force.time_s - first_reading.time_s;
    let centre = if nominal.abs() > SAME_CLOCK_S { nominal } else { 0.0 };
    let force_step = quantile(
        &forces.windows(2).map(|w| w[1].time_s - w[0].time_s).collect::<Vec<_>>(),
        0.5,
    )
    .unwrap_or(0.01);
    let frame_step = quantile(
        &readings
            .windows(2)
            .map(|w| w[1].time_s - w[0].time_s)
            .collect::<Vec<_>>(),
        0.5,
    )
    .unwrap_or(0.1);
    let lag_step_s = force_step.min(frame_step / 4.0).max(1e-4);
    let steps = (max_lag_s / lag_step_s).ceil() as i64;
    let correlate = |lag: f64| -> Option<f64> {
        let (mut gamma, mut force) = (Vec::new(), Vec::new());
        for r in readings {
            if let Some(f) = interpolate(&series, r.time_s + lag) {
                gamma.push(r.gamma);
                force.push(f);
            }
        }
        // Half the readings at least, so that a lag cannot win on a sliver of overlap.
        (gamma.len() * 2 >= readings.len())
            .then(|| pearson(&gamma, &force))
            .flatten()
    };
    let curve: Vec<(f64, f64)> = (-steps..=steps)
        .filter_map(|k| {
            let lag = centre + k as f64 * lag_step_s;
            correlate(lag).map(|c| (lag, c))
        })
        .collect();
    let best = (0..curve.len())
        .max_by(|&a, &b| curve[a].1.total_cmp(&curve[b].1))
        .ok_or(ReportError::NotEnoughData {
            what: "clock offset",
            detail: format!("the readings and the force log do not overlap within ±{max_lag_s} s"),
        })?;
    let mut offset_s = curve[best].0;
    // A parabola through the best lag and its neighbours places the peak between the lags searched.
    if best > 0 && best + 1 < curve.len() {
        let (l, c, r) = (curve[best - 1].1, curve[best].1, curve[best + 1].1);
        let denominator = l - 2.0 * c + r;
        if denominator < 0.0 {
            offset_s += 0.5 * (l - r) / denominator * lag_step_s;
        }
    }
    Ok(ClockOffset {
        offset_s,
        correlation: curve[best].1,
        lag_step_s,
        curve,
    })
}

/// The fitted line as JSON shows it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FittedLine {
    pub a: f64,
    pub b: f64,
    pub a_interval: [f64; 2],
    pub b_interval: [f64; 2],
    pub confidence: f64,
    pub residual_scale_n: f64,
    pub points: usize,
    pub outliers: usize,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CalibrationResult {
    pub readings: usize,
    pub force_samples: usize,
    pub clock: ClockOffset,
    /// Readings paired with a force (within two force-log intervals of one).
    pub pairs: usize,
    /// Pairs at or above the minimum force, the ones fitted.
    pub pairs_fitted: usize,
    pub min_force_n: f64,
    pub fit: FittedLine,
    pub rmse_n: f64,
    pub max_abs_residual_n: f64,
    pub r_squared: f64,
    /// The paper's line on the same pairs.
    pub paper_rmse_n: f64,
    /// (gamma, reference force) of every fitted pair.
    #[serde(skip)]
    pub samples: Vec<(f64, f64)>,
}

pub fn analyse(
    readings: &[SessionReading],
    forces: &[ForceSample],
    options: &CalibrationOptions,
) -> Result<CalibrationResult, ReportError> {
    let clock = find_clock_offset(readings, forces, options.max_lag_s)?;
    let force_step = quantile(
        &forces.windows(2).map(|w| w[1].time_s - w[0].time_s).collect::<Vec<_>>(),
        0.5,
    )
    .unwrap_or(0.01);
    let timed: Vec<TimedGamma> = readings
        .iter()
        .map(|r| TimedGamma {
            time_s: r.time_s + clock.offset_s,
            gamma: r.gamma,
        })
        .collect();
    let alignment = align_by_time(&timed, forces, 2.0 * force_step)?;
    let samples: Vec<_> = alignment
        .samples
        .iter()
        .copied()
        .filter(|s| s.force_n >= options.min_force_n)
        .collect();
    let fit = fit_force_line(
        &samples,
        &FitOptions {
            confidence: options.confidence,
            ..FitOptions::default()
        },
    )?;
    let residuals: Vec<f64> = samples.iter().map(|s| s.force_n - (fit.a * s.gamma + fit.b)).collect();
    let n = residuals.len() as f64;
    let rmse_n = (residuals.iter().map(|r| r * r).sum::<f64>() / n).sqrt();
    let mean_force = samples.iter().map(|s| s.force_n).sum::<f64>() / n;
    let total: f64 = samples.iter().map(|s| (s.force_n - mean_force).powi(2)).sum();
    let paper_rmse_n = (samples
        .iter()
        .map(|s| (s.force_n - (PAPER_LINE.0 * s.gamma + PAPER_LINE.1)).powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    Ok(CalibrationResult {
        readings: readings.len(),
        force_samples: forces.len(),
        clock,
        pairs: alignment.samples.len(),
        pairs_fitted: samples.len(),
        min_force_n: options.min_force_n,
        fit: FittedLine {
            a: fit.a,
            b: fit.b,
            a_interval: fit.a_interval,
            b_interval: fit.b_interval,
            confidence: fit.confidence,
            residual_scale_n: fit.residual_scale_n,
            points: fit.points,
            outliers: fit.outliers,
        },
        rmse_n,
        max_abs_residual_n: residuals.iter().fold(0.0, |m, r| m.max(r.abs())),
        r_squared: if total > 0.0 {
            1.0 - n * rmse_n * rmse_n / total
        } else {
            f64::NAN
        },
        paper_rmse_n,
        samples: samples.iter().map(|s| (s.gamma, s.force_n)).collect(),
    })
}

pub fn report(
    readings: &[SessionReading],
    forces: &[ForceSample],
    options: &CalibrationOptions,
    source: &str,
) -> Result<Report, ReportError> {
    let result = analyse(readings, forces, options)?;
    let plots = calibration_plots(&result, readings, forces)?;
    let markdown = calibration_markdown(&result, options, source);
    let json = serde_json::json!({ "kind": "calibration", "source": source, "result": result });
    Ok(Report {
        kind: "calibration",
        markdown,
        plots,
        json,
    })
}

/// The report's charts: the force line, its residuals, the clock offset's correlation and the aligned session.
fn calibration_plots(
    result: &CalibrationResult,
    readings: &[SessionReading],
    forces: &[ForceSample],
) -> Result<Vec<(String, String)>, ReportError> {
    let fit = &result.fit;
    let gamma_max = result.samples.iter().map(|s| s.0).fold(0.0, f64::max);
    let line = |a: f64, b: f64| vec![(0.0, b), (gamma_max, a * gamma_max + b)];
    let calibration = Chart::new("Reference force against gamma", "gamma", "reference force (N)")
        .with(Series::new("readings", Style::Points, result.samples.clone()))
        .with(Series::new(
            format!("fit: F = {:.3} gamma {:+.3} N", fit.a, fit.b),
            Style::Line,
            line(fit.a, fit.b),
        ))
        .with(Series::new(
            "paper: F = 3.09 gamma - 1.14 N",
            Style::Line,
            line(PAPER_LINE.0, PAPER_LINE.1),
        ));
    let residuals = Chart::new("Residuals against force", "reference force (N)", "residual (N)").with(Series::new(
        "F - (a gamma + b)",
        Style::Points,
        result
            .samples
            .iter()
            .map(|&(g, f)| (f, f - (fit.a * g + fit.b)))
            .collect(),
    ));
    let offset = Chart::new(
        "Clock offset by cross-correlation",
        "F/T clock - camera clock (s)",
        "correlation",
    )
    .with(Series::new(
        "gamma against force",
        Style::Line,
        result.clock.curve.clone(),
    ))
    .with(Series::new(
        format!("best: {:.3} s", result.clock.offset_s),
        Style::Points,
        vec![(result.clock.offset_s, result.clock.correlation)],
    ));
    let start = readings.first().map_or(0.0, |r| r.time_s);
    let timeline = Chart::new("Aligned session", "time (s)", "force (N)")
        .with(Series::new(
            "F/T log",
            Style::Line,
            forces
                .iter()
                .map(|f| (f.time_s - result.clock.offset_s - start, f.force_n))
                .collect(),
        ))
        .with(Series::new(
            "a gamma + b",
            Style::Points,
            readings
                .iter()
                .map(|r| (r.time_s - start, fit.a * r.gamma + fit.b))
                .collect(),
        ));
    Ok(vec![
        plot("calibration.svg", &calibration)?,
        plot("residuals.svg", &residuals)?,
        plot("offset.svg", &offset)?,
        plot("timeline.svg", &timeline)?,
    ])
}

fn calibration_markdown(result: &CalibrationResult, options: &CalibrationOptions, source: &str) -> String {
    let fit = &result.fit;
    let pct = |v: f64| format!("{:.0} %", v * 100.0);
    format!(
        "# Calibration report\n\nRecording: `{source}`; {readings} readings, {forces} force samples.\n\n\
         ## Clocks\n\nF/T clock = camera clock {offset:+.4} s (correlation {corr:.4} at the best lag; lags searched \
         every {step:.4} s within ±{max_lag} s, the peak refined between them).\n\n![offset](offset.svg)\n\n\
         ![timeline](timeline.svg)\n\n## Force line\n\n{pairs} readings paired with a force; {fitted} at or above \
         {min_force} N fitted (robust MM fit, {outliers} outliers given weight zero).\n\n{table}\n\
         Residuals: RMSE {rmse:.3} N, largest {max_res:.3} N, R² {r2:.4}. The paper's line on the same pairs: RMSE \
         {paper:.3} N (a sensor of another build needs its own line).\n\n![calibration](calibration.svg)\n\n\
         ![residuals](residuals.svg)\n",
        readings = result.readings,
        forces = result.force_samples,
        offset = result.clock.offset_s,
        corr = result.clock.correlation,
        step = result.clock.lag_step_s,
        max_lag = options.max_lag_s,
        pairs = result.pairs,
        fitted = result.pairs_fitted,
        min_force = options.min_force_n,
        outliers = fit.outliers,
        table = table(
            &["", "value", &format!("{} interval", pct(fit.confidence)), "paper"],
            &[
                vec![
                    "a (N per gamma)".into(),
                    format!("{:.4}", fit.a),
                    format!("[{:.4}, {:.4}]", fit.a_interval[0], fit.a_interval[1]),
                    format!("{}", PAPER_LINE.0),
                ],
                vec![
                    "b (N)".into(),
                    format!("{:.4}", fit.b),
                    format!("[{:.4}, {:.4}]", fit.b_interval[0], fit.b_interval[1]),
                    format!("{}", PAPER_LINE.1),
                ],
            ],
        ),
        rmse = result.rmse_n,
        max_res = result.max_abs_residual_n,
        r2 = result.r_squared,
        paper = result.paper_rmse_n,
    )
}
