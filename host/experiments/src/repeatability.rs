//! Repeatability: repeated touches segmented, each touch's peak force reading and its location, their spread,
//! and their drift over the session (a straight line through them against touch number).

use serde::Serialize;

use crate::plot::{Chart, Series, Style};
use crate::recording::SessionReading;
use crate::report::{plot, table, Report, ReportError};
use crate::segment::{touches, Touch};
use nusense_estimator::stats::{mean, sample_std_dev};

use crate::stats::least_squares;

/// Positions are averaged over the frames within this fraction of the touch's peak force (the hold).
pub const HOLD_FRACTION: f64 = 0.8;

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TouchSummary {
    pub touch: Touch,
    /// Seconds since the first reading.
    pub time_s: f64,
    pub peak_force_n: f64,
    pub position_mm: Option<[f64; 2]>,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Spread {
    pub mean: f64,
    pub std_dev: f64,
    /// Change per touch of a straight line through the values.
    pub drift_per_touch: f64,
}

fn spread(values: &[f64]) -> Option<Spread> {
    let index: Vec<f64> = (0..values.len()).map(|i| i as f64).collect();
    Some(Spread {
        mean: mean(values)?,
        std_dev: sample_std_dev(values)?,
        drift_per_touch: least_squares(&index, values)?.slope,
    })
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RepeatabilityResult {
    pub touches: Vec<TouchSummary>,
    pub peak_force_n: Spread,
    /// Standard deviation over mean of the peak force, %.
    pub peak_force_cv_percent: f64,
    pub position_x_mm: Option<Spread>,
    pub position_y_mm: Option<Spread>,
    /// RMS distance of the touches' positions from their mean, mm.
    pub position_spread_mm: Option<f64>,
}

pub fn analyse(readings: &[SessionReading]) -> Result<RepeatabilityResult, ReportError> {
    let start = readings.first().map_or(0.0, |r| r.time_s);
    let found = touches(readings);
    let summaries: Vec<TouchSummary> = found
        .iter()
        .map(|t| TouchSummary {
            touch: *t,
            time_s: readings[t.peak].time_s - start,
            peak_force_n: readings[t.peak].force_model_n,
            position_mm: Touch::position_mm(readings, &t.near_peak(readings, HOLD_FRACTION)),
        })
        .collect();
    let peaks: Vec<f64> = summaries.iter().map(|s| s.peak_force_n).collect();
    let peak_force_n = spread(&peaks).ok_or(ReportError::NotEnoughData {
        what: "repeatability",
        detail: format!("{} touches found; at least two are needed", summaries.len()),
    })?;
    let positions: Vec<[f64; 2]> = summaries.iter().filter_map(|s| s.position_mm).collect();
    let xs: Vec<f64> = positions.iter().map(|p| p[0]).collect();
    let ys: Vec<f64> = positions.iter().map(|p| p[1]).collect();
    let position_spread_mm = mean(&xs)
        .zip(mean(&ys))
        .filter(|_| positions.len() >= 2)
        .map(|(mx, my)| {
            (positions
                .iter()
                .map(|p| (p[0] - mx).powi(2) + (p[1] - my).powi(2))
                .sum::<f64>()
                / positions.len() as f64)
                .sqrt()
        });
    Ok(RepeatabilityResult {
        peak_force_cv_percent: 100.0 * peak_force_n.std_dev / peak_force_n.mean.abs(),
        peak_force_n,
        position_x_mm: spread(&xs),
        position_y_mm: spread(&ys),
        position_spread_mm,
        touches: summaries,
    })
}

pub fn report(readings: &[SessionReading], source: &str) -> Result<Report, ReportError> {
    let result = analyse(readings)?;
    let start = readings.first().map_or(0.0, |r| r.time_s);
    let peaks: Vec<(f64, f64)> = result
        .touches
        .iter()
        .enumerate()
        .map(|(k, t)| ((k + 1) as f64, t.peak_force_n))
        .collect();
    let drift = &result.peak_force_n;
    let n = peaks.len() as f64;
    let intercept = drift.mean - drift.drift_per_touch * (n - 1.0) / 2.0;
    let peak_chart = Chart::new("Peak force reading per touch", "touch", "peak force reading (N)")
        .with(Series::new("touches", Style::Points, peaks))
        .with(Series::new(
            format!("drift {:+.4} N per touch", drift.drift_per_touch),
            Style::Line,
            vec![(1.0, intercept), (n, intercept + drift.drift_per_touch * (n - 1.0))],
        ));
    let mut positions_chart = Chart::new("Touch locations", "x (mm)", "y (mm)").with(Series::new(
        "touches",
        Style::Points,
        result
            .touches
            .iter()
            .filter_map(|t| t.position_mm)
            .map(|p| (p[0], p[1]))
            .collect(),
    ));
    positions_chart.equal_axes = true;
    let timeline = Chart::new("Session", "time (s)", "force reading (N)")
        .with(Series::new(
            "readings",
            Style::Line,
            readings.iter().map(|r| (r.time_s - start, r.force_model_n)).collect(),
        ))
        .with(Series::new(
            "touch peaks",
            Style::Points,
            result.touches.iter().map(|t| (t.time_s, t.peak_force_n)).collect(),
        ));
    let plots = vec![
        plot("peaks.svg", &peak_chart)?,
        plot("locations.svg", &positions_chart)?,
        plot("timeline.svg", &timeline)?,
    ];
    let fmt_spread = |name: &str, s: &Option<Spread>, unit: &str| match s {
        Some(s) => vec![
            name.to_string(),
            format!("{:.3} {unit}", s.mean),
            format!("{:.3} {unit}", s.std_dev),
            format!("{:+.4} {unit}", s.drift_per_touch),
        ],
        None => vec![name.to_string(), "-".into(), "-".into(), "-".into()],
    };
    let rows: Vec<Vec<String>> = result
        .touches
        .iter()
        .enumerate()
        .map(|(k, t)| {
            vec![
                format!("{}", k + 1),
                format!("{:.2}", t.time_s),
                format!("{:.3}", t.peak_force_n),
                t.position_mm
                    .map_or("-".into(), |p| format!("({:.2}, {:.2})", p[0], p[1])),
            ]
        })
        .collect();
    let markdown = format!(
        "# Repeatability report\n\nRecording: `{source}`; {readings} readings, **{n} touches** (the estimator's \
         contact decision, one-frame gaps bridged). Peak force reading: coefficient of variation **{cv:.2} %**; \
         locations: RMS spread **{spread}** around their mean (each touch's location averaged over the frames \
         within {hold:.0} % of its peak).\n\n{summary}\n![peaks](peaks.svg)\n\n![locations](locations.svg)\n\n\
         ![timeline](timeline.svg)\n\n## Touches\n\n{touches}",
        readings = readings.len(),
        n = result.touches.len(),
        cv = result.peak_force_cv_percent,
        spread = result.position_spread_mm.map_or("-".into(), |s| format!("{s:.3} mm")),
        hold = HOLD_FRACTION * 100.0,
        summary = table(
            &["", "mean", "standard deviation", "drift per touch"],
            &[
                fmt_spread("peak force reading", &Some(result.peak_force_n.clone()), "N"),
                fmt_spread("x", &result.position_x_mm, "mm"),
                fmt_spread("y", &result.position_y_mm, "mm"),
            ]
        ),
        touches = table(&["touch", "time (s)", "peak force reading (N)", "location (mm)"], &rows),
    );
    let json = serde_json::json!({ "kind": "repeatability", "source": source, "result": result });
    Ok(Report {
        kind: "repeatability",
        markdown,
        plots,
        json,
    })
}
