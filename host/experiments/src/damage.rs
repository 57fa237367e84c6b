//! Damage: the same session on an intact and on a damaged pad, compared: lattice coverage, the lattice points
//! the damage costs, and how much each touch's force reading and location change.

use serde::Serialize;

use crate::plot::{Chart, Series, Style};
use crate::recording::SessionReading;
use crate::repeatability::HOLD_FRACTION;
use crate::report::{plot, table, Report, ReportError};
use crate::segment::{touches, Touch};
use nusense_estimator::stats::quantile;

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PadCoverage {
    pub readings: usize,
    /// Median over the frames without contact (the pattern as the pad is).
    pub points_detected: f64,
    pub points_valid: f64,
    pub points_expected: usize,
    pub coverage_percent: f64,
    pub touches: usize,
}

fn coverage(readings: &[SessionReading]) -> Result<PadCoverage, ReportError> {
    let at_rest: Vec<&SessionReading> = readings.iter().filter(|r| !r.contact).collect();
    let pick =
        |f: fn(&SessionReading) -> usize| quantile(&at_rest.iter().map(|r| f(r) as f64).collect::<Vec<_>>(), 0.5);
    let (Some(points_detected), Some(points_valid)) = (pick(|r| r.points_detected), pick(|r| r.points_valid)) else {
        return Err(ReportError::NotEnoughData {
            what: "damage",
            detail: "no frame without contact".into(),
        });
    };
    let points_expected = readings.iter().map(|r| r.points_expected).max().unwrap_or(0);
    Ok(PadCoverage {
        readings: readings.len(),
        points_detected,
        points_valid,
        points_expected,
        coverage_percent: if points_expected > 0 {
            100.0 * points_detected / points_expected as f64
        } else {
            0.0
        },
        touches: touches(readings).len(),
    })
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TouchChange {
    pub intact_peak_n: f64,
    pub damaged_peak_n: f64,
    /// Damaged minus intact, % of the intact peak.
    pub peak_change_percent: f64,
    /// Distance between the two locations, mm.
    pub location_shift_mm: Option<f64>,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DamageResult {
    pub intact: PadCoverage,
    pub damaged: PadCoverage,
    /// Lattice points the intact pad shows and the damaged one does not (medians at rest).
    pub points_lost: f64,
    pub touches: Vec<TouchChange>,
}

pub fn analyse(intact: &[SessionReading], damaged: &[SessionReading]) -> Result<DamageResult, ReportError> {
    let summarise = |readings: &[SessionReading]| -> Vec<(f64, Option<[f64; 2]>)> {
        touches(readings)
            .iter()
            .map(|t| {
                (
                    readings[t.peak].force_model_n,
                    Touch::position_mm(readings, &t.near_peak(readings, HOLD_FRACTION)),
                )
            })
            .collect()
    };
    let changes = summarise(intact)
        .into_iter()
        .zip(summarise(damaged))
        .map(|((intact_peak_n, a), (damaged_peak_n, b))| TouchChange {
            intact_peak_n,
            damaged_peak_n,
            peak_change_percent: 100.0 * (damaged_peak_n - intact_peak_n) / intact_peak_n.abs(),
            location_shift_mm: a.zip(b).map(|(a, b)| (a[0] - b[0]).hypot(a[1] - b[1])),
        })
        .collect();
    let (intact, damaged) = (coverage(intact)?, coverage(damaged)?);
    Ok(DamageResult {
        points_lost: intact.points_detected - damaged.points_detected,
        intact,
        damaged,
        touches: changes,
    })
}

pub fn report(
    intact: &[SessionReading],
    damaged: &[SessionReading],
    intact_source: &str,
    damaged_source: &str,
) -> Result<Report, ReportError> {
    let result = analyse(intact, damaged)?;
    let series = |readings: &[SessionReading], f: fn(&SessionReading) -> f64| -> Vec<(f64, f64)> {
        let start = readings.first().map_or(0.0, |r| r.time_s);
        readings.iter().map(|r| (r.time_s - start, f(r))).collect()
    };
    let points = Chart::new("Lattice points detected", "time (s)", "points")
        .with(Series::new(
            "intact",
            Style::Line,
            series(intact, |r| r.points_detected as f64),
        ))
        .with(Series::new(
            "damaged",
            Style::Line,
            series(damaged, |r| r.points_detected as f64),
        ));
    let force = Chart::new("Force reading", "time (s)", "force reading (N)")
        .with(Series::new("intact", Style::Line, series(intact, |r| r.force_model_n)))
        .with(Series::new(
            "damaged",
            Style::Line,
            series(damaged, |r| r.force_model_n),
        ));
    let plots = vec![plot("points.svg", &points)?, plot("force.svg", &force)?];
    let pad_row = |name: &str, c: &PadCoverage| {
        vec![
            name.to_string(),
            format!("{:.0} / {}", c.points_detected, c.points_expected),
            format!("{:.0}", c.points_valid),
            format!("{:.1} %", c.coverage_percent),
            format!("{}", c.touches),
        ]
    };
    let rows: Vec<Vec<String>> = result
        .touches
        .iter()
        .enumerate()
        .map(|(k, t)| {
            vec![
                format!("{}", k + 1),
                format!("{:.3}", t.intact_peak_n),
                format!("{:.3}", t.damaged_peak_n),
                format!("{:+.2} %", t.peak_change_percent),
                t.location_shift_mm.map_or("-".into(), |s| format!("{s:.3}")),
            ]
        })
        .collect();
    let markdown = format!(
        "# Damage report\n\nIntact pad: `{intact_source}`; damaged pad: `{damaged_source}`.\n\nThe damage costs \
         **{lost:.0} lattice points** (median at rest: points the intact pad shows that the damaged pad does not).\
         \n\n{pads}\n![points](points.svg)\n\n## Touches, in order\n\n{touches}\n![force](force.svg)\n",
        lost = result.points_lost,
        pads = table(
            &["pad", "points detected", "points valid", "coverage", "touches"],
            &[pad_row("intact", &result.intact), pad_row("damaged", &result.damaged)]
        ),
        touches = table(
            &[
                "touch",
                "intact peak (N)",
                "damaged peak (N)",
                "change",
                "location shift (mm)"
            ],
            &rows
        ),
    );
    let json = serde_json::json!({
        "kind": "damage", "intact_source": intact_source, "damaged_source": damaged_source, "result": result
    });
    Ok(Report {
        kind: "damage",
        markdown,
        plots,
        json,
    })
}
