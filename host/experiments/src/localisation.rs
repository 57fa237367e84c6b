//! Localisation: touches at known targets (a CSV visited in order) against the contacts the sensor reported:
//! per-target error, bias, RMSE and a map.

use std::path::Path;

use serde::Serialize;

use crate::plot::{Chart, Series, Style};
use crate::recording::SessionReading;
use crate::repeatability::HOLD_FRACTION;
use crate::report::{plot, read_text, table, Report, ReportError};
use crate::segment::{touches, Touch};

/// Targets in pad mm from a CSV with a header naming `x_mm` and `y_mm` (other columns are ignored), in the
/// order they were touched.
pub fn load_targets(path: &Path) -> Result<Vec<[f64; 2]>, ReportError> {
    let name = path.display().to_string();
    let text = read_text(path)?;
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
    let csv_error = |line: usize, message: String| ReportError::Csv {
        path: name.clone(),
        line: line + 1,
        message,
    };
    let (header_line, header) = lines
        .next()
        .ok_or_else(|| csv_error(0, "empty: a header x_mm,y_mm is needed".into()))?;
    let columns: Vec<String> = header.split(',').map(|c| c.trim().to_ascii_lowercase()).collect();
    let column = |wanted: &str| {
        columns.iter().position(|c| c == wanted).ok_or_else(|| {
            csv_error(
                header_line,
                format!("no column {wanted} (columns: {})", columns.join(", ")),
            )
        })
    };
    let (x, y) = (column("x_mm")?, column("y_mm")?);
    lines
        .map(|(line, text)| {
            let fields: Vec<&str> = text.split(',').map(str::trim).collect();
            let number = |col: usize, what: &str| -> Result<f64, ReportError> {
                fields
                    .get(col)
                    .and_then(|f| f.parse::<f64>().ok())
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| csv_error(line, format!("{what} is not a number: {text:?}")))
            };
            Ok([number(x, "x_mm")?, number(y, "y_mm")?])
        })
        .collect()
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TargetResult {
    pub target_mm: [f64; 2],
    pub measured_mm: Option<[f64; 2]>,
    pub error_mm: Option<f64>,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LocalisationResult {
    pub targets: Vec<TargetResult>,
    pub rmse_mm: f64,
    pub max_error_mm: f64,
    /// Mean of measured - target, mm.
    pub bias_mm: [f64; 2],
    /// Touches without a reported location.
    pub unlocated: usize,
}

pub fn analyse(readings: &[SessionReading], targets: &[[f64; 2]]) -> Result<LocalisationResult, ReportError> {
    let found = touches(readings);
    if found.len() != targets.len() {
        return Err(ReportError::NotEnoughData {
            what: "localisation",
            detail: format!(
                "{} touches found for {} targets: each target must be touched once, in order",
                found.len(),
                targets.len()
            ),
        });
    }
    let results: Vec<TargetResult> = found
        .iter()
        .zip(targets)
        .map(|(touch, &target_mm)| {
            let measured_mm = Touch::position_mm(readings, &touch.near_peak(readings, HOLD_FRACTION));
            TargetResult {
                target_mm,
                measured_mm,
                error_mm: measured_mm.map(|m| (m[0] - target_mm[0]).hypot(m[1] - target_mm[1])),
            }
        })
        .collect();
    let located: Vec<&TargetResult> = results.iter().filter(|r| r.measured_mm.is_some()).collect();
    if located.is_empty() {
        return Err(ReportError::NotEnoughData {
            what: "localisation",
            detail: "no touch has a location".into(),
        });
    }
    let n = located.len() as f64;
    let errors: Vec<f64> = located.iter().filter_map(|r| r.error_mm).collect();
    let bias = |axis: usize| {
        located
            .iter()
            .map(|r| r.measured_mm.unwrap()[axis] - r.target_mm[axis])
            .sum::<f64>()
            / n
    };
    Ok(LocalisationResult {
        rmse_mm: (errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt(),
        max_error_mm: errors.iter().copied().fold(0.0, f64::max),
        bias_mm: [bias(0), bias(1)],
        unlocated: results.len() - located.len(),
        targets: results,
    })
}

pub fn report(readings: &[SessionReading], targets: &[[f64; 2]], source: &str) -> Result<Report, ReportError> {
    let result = analyse(readings, targets)?;
    let measured: Vec<(f64, f64)> = result
        .targets
        .iter()
        .filter_map(|t| t.measured_mm)
        .map(|p| (p[0], p[1]))
        .collect();
    let vectors: Vec<(f64, f64)> = result
        .targets
        .iter()
        .filter_map(|t| t.measured_mm.map(|m| [(t.target_mm[0], t.target_mm[1]), (m[0], m[1])]))
        .flatten()
        .collect();
    let mut map = Chart::new("Targets and reported contacts", "x (mm)", "y (mm, down)")
        .with(Series::new(
            "targets",
            Style::Points,
            targets.iter().map(|t| (t[0], t[1])).collect(),
        ))
        .with(Series::new("reported", Style::Points, measured))
        .with(Series::new("error", Style::Segments, vectors));
    map.equal_axes = true;
    let plots = vec![plot("map.svg", &map)?];
    let rows: Vec<Vec<String>> = result
        .targets
        .iter()
        .enumerate()
        .map(|(k, t)| {
            vec![
                format!("{}", k + 1),
                format!("({:.2}, {:.2})", t.target_mm[0], t.target_mm[1]),
                t.measured_mm
                    .map_or("-".into(), |m| format!("({:.2}, {:.2})", m[0], m[1])),
                t.error_mm.map_or("-".into(), |e| format!("{e:.3}")),
            ]
        })
        .collect();
    let markdown = format!(
        "# Localisation report\n\nRecording: `{source}`; {readings} readings, {n} targets touched in order. \
         RMSE **{rmse:.3} mm**, largest error {max:.3} mm, bias ({bx:+.3}, {by:+.3}) mm; {unlocated} touches \
         without a location. Each touch's location is the mean over the frames within {hold:.0} % of its peak \
         force.\n\n![map](map.svg)\n\n{table}",
        readings = readings.len(),
        n = targets.len(),
        rmse = result.rmse_mm,
        max = result.max_error_mm,
        bx = result.bias_mm[0],
        by = result.bias_mm[1],
        unlocated = result.unlocated,
        hold = HOLD_FRACTION * 100.0,
        table = table(&["touch", "target (mm)", "reported (mm)", "error (mm)"], &rows),
    );
    let json = serde_json::json!({ "kind": "localisation", "source": source, "result": result });
    Ok(Report {
        kind: "localisation",
        markdown,
        plots,
        json,
    })
}
