//! The benchmark's outputs: markdown tables (the paper's sweeps per variant, the validation set per mode), the
//! Pareto plot of time against error (plotters), and the machine it ran on.

use std::fmt::Write as _;

use serde::Serialize;

use super::{BenchReport, VariantResult};
use crate::validation::ModeFigures;

/// What the numbers were measured on.
#[derive(Clone, Debug, Serialize)]
pub struct Machine {
    pub cpu_model: String,
    pub logical_cpus: usize,
    pub date_utc: String,
    pub os: String,
    pub profile: &'static str,
}

impl Machine {
    pub fn this() -> Self {
        let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
        let cpu_model = cpuinfo
            .lines()
            .find(|line| line.starts_with("model name"))
            .and_then(|line| line.split_once(':'))
            .map(|(_, model)| model.trim().to_owned())
            .unwrap_or_else(|| "unknown".into());
        let logical_cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
        let os = std::fs::read_to_string("/etc/os-release")
            .unwrap_or_default()
            .lines()
            .find_map(|line| line.strip_prefix("PRETTY_NAME="))
            .map(|name| name.trim_matches('"').to_owned())
            .unwrap_or_else(|| std::env::consts::OS.to_owned());
        Self {
            cpu_model,
            logical_cpus,
            date_utc: utc_now(),
            os,
            profile: if cfg!(debug_assertions) { "debug" } else { "release" },
        }
    }

    /// One line naming the machine, the build and the time of the run.
    pub fn markdown_line(&self) -> String {
        format!(
            "Machine: {} ({} logical CPUs, `nproc`), {}; {} build; run {}.",
            self.cpu_model, self.logical_cpus, self.os, self.profile, self.date_utc
        )
    }
}

/// `YYYY-MM-DD HH:MM UTC` from the system clock (civil-from-days, no time zone database needed).
fn utc_now() -> String {
    let seconds = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs()) as i64;
    let (days, rest) = (seconds.div_euclid(86_400), seconds.rem_euclid(86_400));
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02} {:02}:{:02} UTC",
        rest / 3600,
        rest % 3600 / 60
    )
}

fn opt(value: Option<f64>, digits: usize) -> String {
    value.map_or_else(|| "–".to_owned(), |v| format!("{v:.digits$}"))
}

/// A count that must be all of `frames`, as "n/frames"; a mode that reports nothing to count ("–") misses it.
fn all_of(count: Option<usize>, frames: usize) -> (String, Option<bool>) {
    match count {
        Some(n) => (format!("{n}/{frames}"), Some(n == frames)),
        None => ("–".into(), Some(false)),
    }
}

/// The markdown table with a header describing the run.
pub fn markdown(report: &BenchReport) -> String {
    let mut out = String::new();
    let m = &report.machine;
    let _ = writeln!(out, "# Estimator speed against error (`nusense bench`)\n");
    let _ = writeln!(out, "{}\n", m.markdown_line());
    let _ = writeln!(
        out,
        "Simulated sweeps (nusense-sim, the paper's experiments): {} frames at {}x{} \"full\" resolution; each \
         frame timed {} time(s), single thread. Speed-up: the baseline's (`{}`) median time on the real touch frame \
         over the variant's (every variant, paper mode included, can measure the real pair), both measured in \
         this run. Localisation: RMSE of the contact centre over the position grid (misses counted \
         apart). Force: leave-one-out RMSE after fitting F = a·gamma + b per indenter. Edge: mean absolute \
         angle error over the edge sweep (misses: no direction reported). Real pair: corners found in the \
         reference / touch frame out of 165, and gamma on the touch frame relative to fast mode at full size.\n",
        report.sweep_frames, report.full_size.0, report.full_size.1, report.timing_repeats, report.baseline
    );
    let _ = writeln!(
        out,
        "| variant | frame | K | sim median ms | sim p99 ms | real median ms | real p99 ms | speed-up | loc. RMSE mm (misses) | force LOO RMSE N | edge MAE deg (misses) | real corners ref/touch | real gamma (ratio) |"
    );
    let _ = writeln!(out, "|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for r in &report.results {
        let real = match &r.real {
            Some(real) => (
                format!(
                    "{}/{}",
                    real.reference_corners,
                    real.touch_corners.map_or_else(|| "–".into(), |c| c.to_string())
                ),
                format!("{} ({})", opt(real.gamma, 3), opt(real.gamma_ratio, 3)),
            ),
            None => ("–".into(), "–".into()),
        };
        let real_times = r
            .real
            .as_ref()
            .map_or((None, None), |real| (real.median_ms, real.p99_ms));
        let _ = writeln!(
            out,
            "| {} | {}x{} | {} | {} | {} | {} | {} | {} | {} ({}/{}) | {} | {} ({}/{}) | {} | {} |",
            r.variant.name,
            r.width,
            r.height,
            r.samples_k,
            opt(r.median_ms, 2),
            opt(r.p99_ms, 2),
            opt(real_times.0, 2),
            opt(real_times.1, 2),
            r.speedup.map_or_else(|| "–".into(), |s| format!("{s:.1}x")),
            opt(r.localisation_rmse_mm, 2),
            r.localisation_misses,
            r.localisation_frames,
            opt(r.force_loo_rmse_n, 3),
            opt(r.edge_angle_mae_deg, 1),
            r.edge_misses,
            r.edge_frames,
            real.0,
            real.1,
        );
    }
    let failures: Vec<String> = report
        .results
        .iter()
        .filter_map(|r| {
            let mut notes = Vec::new();
            if let Some(error) = &r.error {
                notes.push(format!("estimator refused the rest frame: {error}"));
            }
            if r.failed_frames > 0 {
                notes.push(format!("{} sweep frames refused with a typed error", r.failed_frames));
            }
            if let Some(error) = r.real.as_ref().and_then(|real| real.error.as_ref()) {
                notes.push(format!("real pair: {error}"));
            }
            (!notes.is_empty()).then(|| format!("- {}: {}", r.variant.name, notes.join("; ")))
        })
        .collect();
    if !failures.is_empty() {
        let _ = writeln!(out, "\nNotes:\n{}", failures.join("\n"));
    }
    let front: Vec<&str> = pareto_front(&report.results)
        .iter()
        .map(|r| r.variant.name.as_str())
        .collect();
    let _ = writeln!(
        out,
        "\nPareto front (median time against localisation RMSE): {}.",
        front.join(", ")
    );
    if let Some(validation) = &report.validation {
        out.push_str(&validation_markdown(validation));
    }
    out
}

/// Variants not beaten on both median time and localisation RMSE by another, fastest first.
pub fn pareto_front(results: &[VariantResult]) -> Vec<&VariantResult> {
    let points: Vec<(&VariantResult, f64, f64)> = results
        .iter()
        .filter_map(|r| Some((r, r.median_ms?, r.localisation_rmse_mm?)))
        .collect();
    let mut front: Vec<(&VariantResult, f64, f64)> = points
        .iter()
        .filter(|(_, t, e)| {
            !points
                .iter()
                .any(|(_, t2, e2)| t2 <= t && e2 <= e && (t2 < t || e2 < e))
        })
        .copied()
        .collect();
    front.sort_by(|a, b| a.1.total_cmp(&b.1));
    front.into_iter().map(|(r, _, _)| r).collect()
}

/// Time (log axis) against localisation RMSE, drawn with plotters: every variant of the sweeps and every mode on
/// the validation set, the sweeps' Pareto front joined by a line.
pub fn pareto_svg(report: &BenchReport) -> String {
    use plotters::prelude::*;

    let sweeps: Vec<(String, f64, f64)> = report
        .results
        .iter()
        .filter_map(|r| Some((r.variant.name.clone(), r.median_ms?, r.localisation_rmse_mm?)))
        .filter(|(_, t, e)| *t > 0.0 && e.is_finite())
        .collect();
    let modes: Vec<(String, f64, f64)> = report
        .validation
        .iter()
        .flat_map(|v| &v.modes)
        .filter_map(|m| {
            Some((
                format!("{} (validation)", m.mode),
                m.median_ms?,
                m.localisation_rmse_mm?,
            ))
        })
        .filter(|(_, t, e)| *t > 0.0 && e.is_finite())
        .collect();
    let all: Vec<&(String, f64, f64)> = sweeps.iter().chain(&modes).collect();
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (800, 500)).into_drawing_area();
        let drawn = (|| -> Result<(), Box<dyn std::error::Error + '_>> {
            root.fill(&WHITE)?;
            let caption = "Median time per frame against localisation RMSE";
            if all.is_empty() {
                root.titled(caption, ("sans-serif", 18))?.draw(&Text::new(
                    "no variant produced both numbers",
                    (250, 200),
                    ("sans-serif", 14),
                ))?;
                return Ok(());
            }
            let t_min = all.iter().map(|p| p.1).fold(f64::MAX, f64::min);
            let t_max = all.iter().map(|p| p.1).fold(f64::MIN, f64::max);
            let e_max = all.iter().map(|p| p.2).fold(0.0, f64::max);
            let mut chart = ChartBuilder::on(&root)
                .caption(caption, ("sans-serif", 18))
                .margin(15)
                .x_label_area_size(40)
                .y_label_area_size(55)
                .build_cartesian_2d((t_min * 0.7..t_max * 1.5).log_scale(), 0.0..(e_max * 1.2).max(1e-3))?;
            chart
                .configure_mesh()
                .x_desc("median time per frame, ms (log scale)")
                .y_desc("localisation RMSE, mm")
                .draw()?;
            let front: Vec<(f64, f64)> = pareto_front(&report.results)
                .iter()
                .filter_map(|r| Some((r.median_ms?, r.localisation_rmse_mm?)))
                .collect();
            if front.len() > 1 {
                chart
                    .draw_series(LineSeries::new(front, RED.stroke_width(2)))?
                    .label("Pareto front (sweeps)")
                    .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED.stroke_width(2)));
            }
            for (points, colour, label) in [
                (&sweeps, BLUE, "paper sweeps, real lens"),
                (&modes, GREEN, "validation set"),
            ] {
                chart
                    .draw_series(points.iter().map(|(name, t, e)| {
                        EmptyElement::at((*t, *e))
                            + Circle::new((0, 0), 5, colour.filled())
                            + Text::new(name.clone(), (8, -12), ("sans-serif", 12))
                    }))?
                    .label(label)
                    .legend(move |(x, y)| Circle::new((x + 10, y), 5, colour.filled()));
            }
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()?;
            root.present()?;
            Ok(())
        })();
        if let Err(error) = drawn {
            drop(root);
            return format!(
                "<svg xmlns=\"http://www.w3.org/2000/svg\"><text x=\"10\" y=\"20\">plot failed: {}</text></svg>",
                escape(&error.to_string())
            );
        }
    }
    svg
}

fn escape(text: &str) -> String {
    text.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

/// One row of issue 12's table: a figure, the target for it, and each mode's value.
struct Row {
    figure: String,
    target: &'static str,
    /// `Some(true)` met, `Some(false)` missed (a mode without the figure misses it), `None`: no target.
    values: Vec<(String, Option<bool>)>,
}

/// Issue 12's table: every estimator mode on the validation set, one row per figure with the target, one
/// column per mode.
pub fn validation_markdown(v: &crate::validation::ValidationReport) -> String {
    let mut out = validation_header(v);
    let mut rows = target_rows(v);
    rows.extend(other_rows(v));
    out += &markdown_table(v, &rows);
    out += &notes_and_rates(v);
    out
}

/// The table's heading and what the set, the calibration and the columns are.
fn validation_header(v: &crate::validation::ValidationReport) -> String {
    let main = main_size(v);
    let mut out = String::new();
    let _ =
        writeln!(
        out,
        "\n## Every mode on the validation set (issue 12)\n\n{} frames ({:?} profile, seed {}) from the validation \
         sensor (`nusense_sim::validation`, docs/validation.md: equisolid decentred lens, tilted pose, layered pad \
         seen through plate and gel, glare, vignetting, shot noise, JPEG 85, LED drift); sizes {}. One force \
         calibration per mode, fitted on the calibration presses, pushes and twists only (N modes: one scale on the \
         normal force; one on the tangential force, the pushes' centre shift and what a push adds to the normal \
         force, all three fitted on the pushes; one on the torque, fitted on the twists; gamma modes: F = a·gamma + b, which \
         their estimators are built with, as `nusense calibrate` leaves a sensor's config), applied everywhere; a \
         missed press reads 0 N. Speed: median/p99 of `estimate` on the {main} frames, one thread, speed-up against `{}` in this run. Floor: smallest force from which every level \
         is detected in >= 90 % of presses. \"–\": the mode does not report what the figure needs; ✗: the issue's \
         target is missed.\n",
        v.frames,
        v.profile,
        v.seed,
        v.sizes.iter().map(|(w, h)| format!("{w}x{h}")).collect::<Vec<_>>().join(", "),
        v.baseline
    );
    out
}

/// The main size's name, e.g. "2048x1536".
fn main_size(v: &crate::validation::ValidationReport) -> String {
    v.sizes.first().map_or_else(String::new, |(w, h)| format!("{w}x{h}"))
}

/// Adds a row to `rows`: `value` gives each mode's text and whether it meets `target`.
fn push_row(
    rows: &mut Vec<Row>,
    v: &crate::validation::ValidationReport,
    figure: String,
    target: &'static str,
    value: &dyn Fn(&ModeFigures) -> (String, Option<bool>),
) {
    rows.push(Row {
        figure,
        target,
        values: v.modes.iter().map(value).collect(),
    });
}

/// The rows of the figures issue 12 sets a target for.
fn target_rows(v: &crate::validation::ValidationReport) -> Vec<Row> {
    let main = main_size(v);
    let within = |value: Option<f64>, limit: f64| Some(value.is_some_and(|x| x <= limit));
    let mut rows: Vec<Row> = Vec::new();
    let mut row = |figure, target, value: &dyn Fn(&ModeFigures) -> (String, Option<bool>)| {
        push_row(&mut rows, v, figure, target, value)
    };
    row(
        format!("median / p99 ms per {main} frame"),
        "<= 2 ms at 2048x1536",
        &|m| {
            let at_full = v.sizes.first() == Some(&(2048, 1536));
            (
                format!("{} / {}", opt(m.median_ms, 2), opt(m.p99_ms, 2)),
                at_full.then_some(m.median_ms.is_some_and(|t| t <= 2.0)),
            )
        },
    );
    row(format!("speed-up against {}", v.baseline), "", &|m| {
        (m.speedup.map_or_else(|| "–".into(), |s| format!("{s:.1}x")), None)
    });
    row("localisation RMSE, mm (misses)".into(), "<= 0.25", &|m| {
        (
            format!(
                "{} ({}/{})",
                opt(m.localisation_rmse_mm, 2),
                m.localisation_misses,
                m.localisation_frames
            ),
            Some(m.localisation_misses == 0 && m.localisation_rmse_mm.is_some_and(|e| e <= 0.25)),
        )
    });
    row(
        "force RMS, N: 1-8 N over the pad, one calibration".into(),
        "<= 0.3",
        &|m| (opt(m.force_rms_n, 2), within(m.force_rms_n, 0.3)),
    );
    row("... camera moved (roll up to 5°) included".into(), "<= 0.3", &|m| {
        (
            opt(m.force_rms_with_motion_n, 2),
            within(m.force_rms_with_motion_n, 0.3),
        )
    });
    row("camera rotation error, RMS / max °".into(), "<= 0.2", &|m| {
        (
            format!(
                "{} / {}",
                opt(m.camera_rotation_rms_deg, 2),
                opt(m.camera_rotation_max_deg, 2)
            ),
            within(m.camera_rotation_max_deg, 0.2),
        )
    });
    row("detection floor, N".into(), "<= 0.5", &|m| {
        (opt(m.detection_floor_n, 2), within(m.detection_floor_n, 0.5))
    });
    row("detection floor, 20 x 1 mm edges, N".into(), "<= 0.5", &|m| {
        (opt(m.edge_detection_floor_n, 2), within(m.edge_detection_floor_n, 0.5))
    });
    row("false contacts on rest frames".into(), "0", &|m| {
        (
            format!("{}/{}", m.false_contacts, m.rest_frames),
            Some(m.false_contacts == 0),
        )
    });
    row("edge direction error, mean / max ° (misses)".into(), "<= 2", &|m| {
        (
            format!(
                "{} / {} ({}/{})",
                opt(m.edge_mae_deg, 1),
                opt(m.edge_max_deg, 1),
                m.edge_misses,
                m.edge_frames
            ),
            Some(m.edge_misses == 0 && m.edge_max_deg.is_some_and(|e| e <= 2.0)),
        )
    });
    row(
        "two contacts 10 mm apart: both listed, each force ±20 %".into(),
        "all",
        &|m| all_of(m.two_contacts_ok, m.two_contact_frames),
    );
    row("20 mm edges listed as one contact".into(), "all", &|m| {
        all_of(m.edges_one_contact, m.edge_frames)
    });
    row("two round presses reported as an edge".into(), "0", &|m| {
        (
            format!("{}/{}", m.round_pairs_with_edge, m.two_contact_frames),
            Some(m.round_pairs_with_edge == 0),
        )
    });
    row("tangential force direction error, mean / max °".into(), "<= 5", &|m| {
        (
            format!(
                "{} / {}",
                opt(m.tangential_direction_mae_deg, 1),
                opt(m.tangential_direction_max_deg, 1)
            ),
            within(m.tangential_direction_max_deg, 5.0),
        )
    });
    rows
}

/// The rows of the figures beside issue 12's targets: pushes, torque, damaged pads, other sizes, refusals and the
/// calibration.
fn other_rows(v: &crate::validation::ValidationReport) -> Vec<Row> {
    let mut rows: Vec<Row> = Vec::new();
    let mut row = |figure, target, value: &dyn Fn(&ModeFigures) -> (String, Option<bool>)| {
        push_row(&mut rows, v, figure, target, value)
    };
    row(
        "tangential force RMS, N (read / true, median): pushes, the tangential scale fitted on the calibration pushes"
            .into(),
        "",
        &|m| {
            (
                format!(
                    "{} ({})",
                    opt(m.tangential_force_rms_n, 2),
                    m.tangential_force_ratio.map_or("–".into(), |r| format!("{r:.2}x"))
                ),
                None,
            )
        },
    );
    row(
        "pushes' localisation RMSE, mm (without the push shift fitted on the calibration pushes)".into(),
        "",
        &|m| {
            (
                format!(
                    "{} ({})",
                    opt(m.push_localisation_rmse_mm, 2),
                    opt(m.push_localisation_unshifted_rmse_mm, 2)
                ),
                None,
            )
        },
    );
    row(
        "pushes' normal force RMS, N (without the push's normal share fitted on the calibration pushes)".into(),
        "",
        &|m| {
            (
                format!(
                    "{} ({})",
                    opt(m.push_force_rms_n, 2),
                    opt(m.push_force_unshared_rms_n, 2)
                ),
                None,
            )
        },
    );
    row(
        "torque RMS, N mm: twists, the torque scale fitted on the calibration twists".into(),
        "",
        &|m| (opt(m.torque_rms_nmm, 2), None),
    );
    row("presses on damaged pads detected".into(), "", &|m| {
        (format!("{}/{}", m.damaged_detected, m.damaged_frames), None)
    });
    row("localisation RMSE at other sizes, mm".into(), "", &|m| {
        (opt(m.resolution_rmse_mm, 2), None)
    });
    row("frames refused".into(), "0", &|m| {
        (format!("{}/{}", m.refused, m.frames), Some(m.refused == 0))
    });
    row("force calibration".into(), "", &|m| {
        (m.calibration.clone().unwrap_or_else(|| "–".into()), None)
    });
    rows
}

/// The rows as a markdown table, one column per mode, a missed target marked ✗.
fn markdown_table(v: &crate::validation::ValidationReport, rows: &[Row]) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "| figure | target | {} |",
        v.modes
            .iter()
            .map(|m| m.mode.to_string())
            .collect::<Vec<_>>()
            .join(" | ")
    );
    let _ = writeln!(out, "|---|---|{}", "---|".repeat(v.modes.len()));
    for r in rows {
        let cells: Vec<String> = r
            .values
            .iter()
            .map(|(text, met)| match met {
                Some(false) => format!("{text} ✗"),
                _ => text.clone(),
            })
            .collect();
        let _ = writeln!(out, "| {} | {} | {} |", r.figure, r.target, cells.join(" | "));
    }
    out
}

/// The modes' errors, if any, and each mode's detection rate per force.
fn notes_and_rates(v: &crate::validation::ValidationReport) -> String {
    let mut out = String::new();
    let notes: Vec<String> = v
        .modes
        .iter()
        .filter_map(|m| m.error.as_ref().map(|e| format!("- {}: {e}", m.mode)))
        .collect();
    if !notes.is_empty() {
        let _ = writeln!(out, "\nNotes:\n{}", notes.join("\n"));
    }
    let rates = |of: &dyn Fn(&ModeFigures) -> &[(f64, f64)]| {
        v.modes
            .iter()
            .map(|m| {
                format!(
                    "{}: {}",
                    m.mode,
                    of(m)
                        .iter()
                        .map(|(f, r)| format!("{f} N {:.0} %", 100.0 * r))
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            })
            .collect::<Vec<_>>()
            .join("; ")
    };
    let _ = writeln!(out, "\nDetection rate by force: {}", rates(&|m| &m.detection_rates));
    let _ = writeln!(
        out,
        "\nDetection rate by force, 20 x 1 mm edges: {}",
        rates(&|m| &m.edge_detection_rates)
    );
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{standard_variants, VariantResult};

    fn result(name: &str, median_ms: f64, rmse: f64) -> VariantResult {
        let mut variant = standard_variants().remove(1);
        variant.name = name.to_owned();
        VariantResult {
            median_ms: Some(median_ms),
            localisation_rmse_mm: Some(rmse),
            ..crate::empty_result(&variant, (64, 48))
        }
    }

    #[test]
    fn the_pareto_front_keeps_only_undominated_variants() {
        let results = vec![
            result("slow exact", 100.0, 0.1),
            result("fast rough", 1.0, 1.0),
            result("dominated", 50.0, 2.0),
            result("middle", 10.0, 0.5),
        ];
        let names: Vec<&str> = pareto_front(&results).iter().map(|r| r.variant.name.as_str()).collect();
        assert_eq!(names, ["fast rough", "middle", "slow exact"]);
    }

    #[test]
    fn the_svg_has_a_point_per_variant_and_the_front_line() {
        let report = BenchReport {
            baseline: "slow exact".into(),
            full_size: (64, 48),
            sweep_frames: 3,
            timing_repeats: 1,
            results: vec![result("slow exact", 100.0, 0.1), result("fast <rough>", 1.0, 1.0)],
            validation: None,
            machine: Machine::this(),
        };
        let svg = pareto_svg(&report);
        // Two blue points and the legend's blue marker (no validation points); the front as a red line.
        let blue = svg
            .lines()
            .filter(|l| l.starts_with("<circle") && l.contains("#0000FF"))
            .count();
        assert_eq!(blue, 3, "{svg}");
        assert!(svg.contains("<polyline") && svg.contains("stroke=\"#FF0000\""), "{svg}");
        assert!(svg.contains("fast &lt;rough&gt;"), "{svg}");
        assert!(markdown(&report).contains("| fast <rough> | 64x48 |"));
    }

    #[test]
    fn the_validation_table_marks_missed_targets_and_only_those() {
        use crate::validation::{score, ValidationReport};
        use nusense_estimator::Mode;
        let mut good = score(Mode::Fast, &[]);
        good.median_ms = Some(1.5);
        good.localisation_rmse_mm = Some(0.2);
        good.localisation_frames = 3;
        good.force_rms_n = Some(0.25);
        good.force_rms_with_motion_n = Some(0.3);
        good.camera_rotation_rms_deg = Some(0.1);
        good.camera_rotation_max_deg = Some(0.15);
        good.detection_floor_n = Some(0.5);
        good.edge_detection_floor_n = Some(0.5);
        good.rest_frames = 4;
        good.edge_mae_deg = Some(1.0);
        good.edge_max_deg = Some(1.9);
        good.edge_frames = 2;
        good.two_contacts_ok = Some(2);
        good.two_contact_frames = 2;
        good.edges_one_contact = Some(2);
        good.tangential_direction_mae_deg = Some(2.0);
        good.tangential_direction_max_deg = Some(4.0);
        // Paper mode as today: no force vector, contacts or camera motion, and one press missed.
        let mut paper = score(Mode::Paper, &[]);
        paper.median_ms = Some(30.0);
        paper.localisation_rmse_mm = Some(0.2);
        paper.localisation_misses = 1;
        paper.localisation_frames = 3;
        paper.detection_floor_n = Some(1.0);
        paper.false_contacts = 1;
        paper.rest_frames = 4;
        paper.two_contact_frames = 2;
        paper.round_pairs_with_edge = 1;
        let report = |size| ValidationReport {
            profile: nusense_sim::validation::Profile::Full,
            seed: 7,
            frames: 10,
            sizes: vec![size],
            baseline: "paper".into(),
            modes: vec![good.clone(), paper.clone()],
            machine: Machine::this(),
        };
        let table = validation_markdown(&report((2048, 1536)));
        let line = |start: &str| {
            table
                .lines()
                .find(|l| l.starts_with(start))
                .unwrap_or_else(|| panic!("no row {start}: {table}"))
                .to_owned()
        };
        assert!(table.contains("| figure | target | fast | paper |"), "{table}");
        assert_eq!(
            line("| median / p99 ms per 2048x1536 frame"),
            "| median / p99 ms per 2048x1536 frame | <= 2 ms at 2048x1536 | 1.50 / – | 30.00 / – ✗ |"
        );
        assert_eq!(
            line("| localisation RMSE"),
            "| localisation RMSE, mm (misses) | <= 0.25 | 0.20 (0/3) | 0.20 (1/3) ✗ |"
        );
        assert_eq!(
            line("| force RMS"),
            "| force RMS, N: 1-8 N over the pad, one calibration | <= 0.3 | 0.25 | – ✗ |"
        );
        assert_eq!(
            line("| detection floor"),
            "| detection floor, N | <= 0.5 | 0.50 | 1.00 ✗ |"
        );
        assert_eq!(
            line("| false contacts"),
            "| false contacts on rest frames | 0 | 0/4 | 1/4 ✗ |"
        );
        assert_eq!(
            line("| two contacts"),
            "| two contacts 10 mm apart: both listed, each force ±20 % | all | 2/2 | – ✗ |"
        );
        assert_eq!(
            line("| two round presses"),
            "| two round presses reported as an edge | 0 | 0/2 | 1/2 ✗ |"
        );
        assert_eq!(
            line("| camera rotation"),
            "| camera rotation error, RMS / max ° | <= 0.2 | 0.10 / 0.15 | – / – ✗ |"
        );
        // Speed is judged against the 2 ms target only on 2048x1536 frames.
        let quick = validation_markdown(&report((1024, 768)));
        assert!(
            quick.contains("| median / p99 ms per 1024x768 frame | <= 2 ms at 2048x1536 | 1.50 / – | 30.00 / – |"),
            "{quick}"
        );
    }
    #[test]
    fn utc_date_is_well_formed() {
        let date = utc_now();
        assert_eq!(date.len(), "2026-01-01 00:00 UTC".len(), "{date}");
        assert!(date.starts_with("20"));
    }
}
