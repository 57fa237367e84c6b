//! Hysteresis: loading/unloading cycles found in the force log, the loop of the sensor's force reading
//! against the reference force, and the hysteresis error as a percentage of the reading's full scale.
//!
//! A cycle is a stretch where the reference force stays above 5 % of its largest value; its peak splits it into
//! a loading and an unloading branch. Both branches are averaged in eight equal bins of reference force over
//! the range they share; the hysteresis error is the largest gap between the branches' bin means, over the
//! reading's full scale (its span over all cycles). Binning keeps sensor noise from posing as hysteresis.
//!
//! The F/T log's clock offset must come from outside the hysteresis recording (`Clock::Given`: hardware sync, or
//! the calibration report on the same rig). Cross-correlating the reading of a viscoelastic pad with its force
//! finds the clocks' offset plus the pad's lag: aligning by it slides the unloading branch onto the loading one
//! and hides most of the loop (on the short simulated session, 76 ms of lag turn the pad's 17.6 % loop into
//! 7.0 %).

use nusense_estimator::calibration::ForceSample;
use serde::Serialize;

use crate::calibration::{find_clock_offset, ClockOffset};
use crate::plot::{Chart, Series, Style};
use crate::recording::SessionReading;
use crate::report::{plot, table, Report, ReportError};
use nusense_estimator::stats::mean;

use crate::stats::interpolate;

const CYCLE_THRESHOLD: f64 = 0.05;
const BINS: usize = 8;

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Cycle {
    /// Indices into the (reference, reading) pairs.
    pub first: usize,
    pub peak: usize,
    pub last: usize,
    pub peak_reference_n: f64,
    /// Largest gap between the branches, % of full scale.
    pub hysteresis_percent: f64,
    /// The reference force where the gap is largest, N.
    pub at_reference_n: f64,
}

/// Cycles and their hysteresis in time-ordered (reference, reading) pairs.
pub fn cycles(pairs: &[(f64, f64)]) -> Vec<Cycle> {
    let peak_reference = pairs.iter().map(|p| p.0).fold(0.0, f64::max);
    let threshold = CYCLE_THRESHOLD * peak_reference;
    let mut stretches: Vec<(usize, usize)> = Vec::new();
    for (i, &(reference, _)) in pairs.iter().enumerate() {
        if reference <= threshold {
            continue;
        }
        match stretches.last_mut() {
            Some(stretch) if stretch.1 + 1 == i => stretch.1 = i,
            _ => stretches.push((i, i)),
        }
    }
    let in_cycles: Vec<f64> = stretches
        .iter()
        .flat_map(|&(a, b)| pairs[a..=b].iter().map(|p| p.1))
        .collect();
    let full_scale = in_cycles.iter().copied().fold(f64::NEG_INFINITY, f64::max)
        - in_cycles.iter().copied().fold(f64::INFINITY, f64::min);
    stretches
        .into_iter()
        .filter(|&(first, last)| last >= first + 3)
        .filter_map(|(first, last)| {
            let peak = (first..=last).max_by(|&a, &b| pairs[a].0.total_cmp(&pairs[b].0))?;
            let (gap, at) = largest_gap(&pairs[first..=peak], &pairs[peak..=last])?;
            Some(Cycle {
                first,
                peak,
                last,
                peak_reference_n: pairs[peak].0,
                hysteresis_percent: 100.0 * gap / full_scale,
                at_reference_n: at,
            })
        })
        .collect()
}

/// The largest |unloading - loading| between bin means, and the bin's centre.
fn largest_gap(loading: &[(f64, f64)], unloading: &[(f64, f64)]) -> Option<(f64, f64)> {
    let span = |branch: &[(f64, f64)]| {
        branch.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.0), hi.max(p.0))
        })
    };
    let ((lo_l, hi_l), (lo_u, hi_u)) = (span(loading), span(unloading));
    let (lo, hi) = (lo_l.max(lo_u), hi_l.min(hi_u));
    // Branches that share no range of force (or NaN spans) have no gap to measure.
    if hi.is_nan() || lo.is_nan() || hi <= lo {
        return None;
    }
    let width = (hi - lo) / BINS as f64;
    let bin_mean = |branch: &[(f64, f64)], k: usize| {
        let (a, b) = (lo + k as f64 * width, lo + (k + 1) as f64 * width);
        mean(
            &branch
                .iter()
                .filter(|p| p.0 >= a && (p.0 < b || k + 1 == BINS && p.0 <= b))
                .map(|p| p.1)
                .collect::<Vec<_>>(),
        )
    };
    (0..BINS)
        .filter_map(|k| {
            Some((
                (bin_mean(unloading, k)? - bin_mean(loading, k)?).abs(),
                lo + (k as f64 + 0.5) * width,
            ))
        })
        .max_by(|a, b| a.0.total_cmp(&b.0))
}

/// Where the F/T clock's offset comes from (F/T time = camera time + offset).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Clock {
    /// Known from outside this recording, s.
    Given(f64),
    /// Cross-correlation within this many seconds: includes the pad's lag, so the loop is a lower bound.
    CrossCorrelation { max_lag_s: f64 },
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct HysteresisResult {
    pub clock_offset_s: f64,
    /// Whether the offset was given; `false`: cross-correlated, and the loop is a lower bound.
    pub clock_given: bool,
    /// The cross-correlation, when the offset was found by it.
    pub clock: Option<ClockOffset>,
    pub cycles: Vec<Cycle>,
    pub max_percent: f64,
    pub mean_percent: f64,
    /// The reading's span over the cycles, N.
    pub full_scale_n: f64,
    #[serde(skip)]
    pub pairs: Vec<(f64, f64)>,
}

pub fn analyse(
    readings: &[SessionReading],
    forces: &[ForceSample],
    clock: Clock,
) -> Result<HysteresisResult, ReportError> {
    let (clock_offset_s, clock) = match clock {
        Clock::Given(offset_s) => (offset_s, None),
        Clock::CrossCorrelation { max_lag_s } => {
            let found = find_clock_offset(readings, forces, max_lag_s)?;
            (found.offset_s, Some(found))
        }
    };
    let series: Vec<(f64, f64)> = forces.iter().map(|f| (f.time_s, f.force_n)).collect();
    let pairs: Vec<(f64, f64)> = readings
        .iter()
        .filter_map(|r| interpolate(&series, r.time_s + clock_offset_s).map(|f| (f, r.force_model_n)))
        .collect();
    let cycles = cycles(&pairs);
    if cycles.is_empty() {
        return Err(ReportError::NotEnoughData {
            what: "hysteresis",
            detail: "no loading/unloading cycle in the force log over the readings".into(),
        });
    }
    let percents: Vec<f64> = cycles.iter().map(|c| c.hysteresis_percent).collect();
    let in_cycles: Vec<f64> = cycles
        .iter()
        .flat_map(|c| pairs[c.first..=c.last].iter().map(|p| p.1))
        .collect();
    Ok(HysteresisResult {
        clock_offset_s,
        clock_given: clock.is_none(),
        clock,
        max_percent: percents.iter().copied().fold(0.0, f64::max),
        mean_percent: mean(&percents).unwrap_or(f64::NAN),
        full_scale_n: in_cycles.iter().copied().fold(f64::NEG_INFINITY, f64::max)
            - in_cycles.iter().copied().fold(f64::INFINITY, f64::min),
        cycles,
        pairs,
    })
}

pub fn report(
    readings: &[SessionReading],
    forces: &[ForceSample],
    clock: Clock,
    source: &str,
) -> Result<Report, ReportError> {
    let result = analyse(readings, forces, clock)?;
    let branch = |loading: bool| -> Vec<(f64, f64)> {
        result
            .cycles
            .iter()
            .flat_map(|c| {
                if loading {
                    &result.pairs[c.first..=c.peak]
                } else {
                    &result.pairs[c.peak..=c.last]
                }
            })
            .copied()
            .collect()
    };
    let chart = Chart::new(
        "Force reading against reference force",
        "reference force (N)",
        "force reading (N)",
    )
    .with(Series::new("loading", Style::Points, branch(true)))
    .with(Series::new("unloading", Style::Points, branch(false)));
    let plots = vec![plot("hysteresis.svg", &chart)?];
    let rows: Vec<Vec<String>> = result
        .cycles
        .iter()
        .enumerate()
        .map(|(k, c)| {
            vec![
                format!("{}", k + 1),
                format!("{:.2}", c.peak_reference_n),
                format!("{:.2}", c.hysteresis_percent),
                format!("{:.2}", c.at_reference_n),
            ]
        })
        .collect();
    let clock_line = match &result.clock {
        None => format!("F/T clock = camera clock {:+.4} s (given).", result.clock_offset_s),
        Some(found) => format!(
            "F/T clock = camera clock {:+.4} s, found by cross-correlation ({:.4}). **That offset includes the \
             pad's lag, so the loop below is a lower bound**: give the rig's offset with `--clock-offset`.",
            found.offset_s, found.correlation
        ),
    };
    let markdown =
        format!(
        "# Hysteresis report\n\nRecording: `{source}`; {readings} readings. {clock_line}\n\nHysteresis error: **{max:.2} %** of full scale at worst, {mean:.2} % on \
         average over {n} cycles (full scale: the reading's span, {fs:.3} N). Each branch is averaged in {BINS} \
         bins of reference force; the error is the largest gap between the branches.\n\n{table}\n\
         ![hysteresis](hysteresis.svg)\n",
        readings = readings.len(),
        max = result.max_percent,
        mean = result.mean_percent,
        n = result.cycles.len(),
        fs = result.full_scale_n,
        table = table(&["cycle", "peak reference (N)", "hysteresis (% FS)", "largest gap at (N)"], &rows),
    );
    let json = serde_json::json!({ "kind": "hysteresis", "source": source, "result": result });
    Ok(Report {
        kind: "hysteresis",
        markdown,
        plots,
        json,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_loop_with_a_known_gap_gives_that_gap_over_full_scale() {
        // Load 0 -> 10 N, unload 10 -> 0 N; the reading equals the force loading and 0.5 N above it unloading
        // (except at the very top, where the branches meet).
        let mut pairs: Vec<(f64, f64)> = (0..=100).map(|i| (0.1 * i as f64, 0.1 * i as f64)).collect();
        pairs.extend((0..100).rev().map(|i| (0.1 * i as f64, 0.1 * i as f64 + 0.5)));
        let found = cycles(&pairs);
        assert_eq!(found.len(), 1);
        // Full scale: the reading's span where the reference is above 5 % of its peak.
        let span = {
            let above: Vec<f64> = pairs.iter().filter(|p| p.0 > 0.5).map(|p| p.1).collect();
            above.iter().copied().fold(f64::MIN, f64::max) - above.iter().copied().fold(f64::MAX, f64::min)
        };
        assert!(
            (found[0].hysteresis_percent - 100.0 * 0.5 / span).abs() < 1e-9,
            "{:?}",
            found[0]
        );
        assert!((span - 9.8).abs() < 1e-9);
        assert_eq!(found[0].peak_reference_n, 10.0);
    }
}
