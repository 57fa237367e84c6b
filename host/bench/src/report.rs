//! The benchmark's outputs: a markdown table, the Pareto front of time against error as SVG (written by hand:
//! a handful of points and lines needs no plotting library), and the machine it ran on.

use std::fmt::Write as _;

use serde::Serialize;

use super::{BenchReport, VariantResult};

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

/// The markdown table with a header describing the run.
pub fn markdown(report: &BenchReport) -> String {
    let mut out = String::new();
    let m = &report.machine;
    let _ = writeln!(out, "# Estimator speed against error (`nusense bench`)\n");
    let _ = writeln!(
        out,
        "Machine: {} ({} logical CPUs, `nproc`), {}; {} build; run {}.\n",
        m.cpu_model, m.logical_cpus, m.os, m.profile, m.date_utc
    );
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

/// Time (log axis) against localisation RMSE; the Pareto front joined by a line.
pub fn pareto_svg(report: &BenchReport) -> String {
    const W: f64 = 760.0;
    const H: f64 = 480.0;
    const LEFT: f64 = 70.0;
    const RIGHT: f64 = 180.0;
    const TOP: f64 = 40.0;
    const BOTTOM: f64 = 60.0;
    let points: Vec<(&VariantResult, f64, f64)> = report
        .results
        .iter()
        .filter_map(|r| Some((r, r.median_ms?, r.localisation_rmse_mm?)))
        .filter(|(_, t, e)| *t > 0.0 && e.is_finite())
        .collect();
    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" viewBox="0 0 {W} {H}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(svg, r#"<rect width="{W}" height="{H}" fill="white"/>"#);
    let _ = writeln!(
        svg,
        r#"<text x="{}" y="22" font-size="15" text-anchor="middle">Estimator variants: median time per frame against localisation RMSE</text>"#,
        W / 2.0
    );
    if points.is_empty() {
        let _ = writeln!(
            svg,
            r#"<text x="{}" y="{}" text-anchor="middle">no variant produced both numbers</text></svg>"#,
            W / 2.0,
            H / 2.0
        );
        return svg;
    }
    let (t_min, t_max) = points
        .iter()
        .fold((f64::MAX, f64::MIN), |(lo, hi), p| (lo.min(p.1), hi.max(p.1)));
    let e_max = points.iter().map(|p| p.2).fold(0.0, f64::max);
    let log_lo = (t_min.log10() - 0.15).floor();
    let log_hi = (t_max.log10() + 0.15).ceil().max(log_lo + 1.0);
    let e_hi = if e_max > 0.0 { e_max * 1.15 } else { 1.0 };
    let plot_w = W - LEFT - RIGHT;
    let plot_h = H - TOP - BOTTOM;
    let x_of = |t: f64| LEFT + (t.log10() - log_lo) / (log_hi - log_lo) * plot_w;
    let y_of = |e: f64| TOP + plot_h - e / e_hi * plot_h;

    let _ = writeln!(
        svg,
        r##"<rect x="{LEFT}" y="{TOP}" width="{plot_w}" height="{plot_h}" fill="none" stroke="#444"/>"##
    );
    let mut decade = log_lo;
    while decade <= log_hi + 1e-9 {
        let x = LEFT + (decade - log_lo) / (log_hi - log_lo) * plot_w;
        let label = 10f64.powf(decade);
        let _ = writeln!(
            svg,
            r##"<line x1="{x:.1}" y1="{TOP}" x2="{x:.1}" y2="{:.1}" stroke="#ddd"/>"##,
            TOP + plot_h
        );
        let _ = writeln!(
            svg,
            r#"<text x="{x:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
            TOP + plot_h + 18.0,
            if label < 1.0 {
                format!("{label}")
            } else {
                format!("{label:.0}")
            }
        );
        decade += 1.0;
    }
    for k in 0..=4 {
        let e = e_hi * f64::from(k) / 4.0;
        let y = y_of(e);
        let _ = writeln!(
            svg,
            r##"<line x1="{LEFT}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#eee"/>"##,
            LEFT + plot_w
        );
        let _ = writeln!(
            svg,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="end">{e:.2}</text>"#,
            LEFT - 6.0,
            y + 4.0
        );
    }
    let _ = writeln!(
        svg,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">median time per frame, ms (log scale)</text>"#,
        LEFT + plot_w / 2.0,
        H - 18.0
    );
    let _ = writeln!(
        svg,
        r#"<text x="18" y="{:.1}" text-anchor="middle" transform="rotate(-90 18 {:.1})">localisation RMSE, mm</text>"#,
        TOP + plot_h / 2.0,
        TOP + plot_h / 2.0
    );
    let front = pareto_front(&report.results);
    let line: Vec<String> = front
        .iter()
        .filter_map(|r| {
            Some(format!(
                "{:.1},{:.1}",
                x_of(r.median_ms?),
                y_of(r.localisation_rmse_mm?)
            ))
        })
        .collect();
    if line.len() > 1 {
        let _ = writeln!(
            svg,
            r##"<polyline points="{}" fill="none" stroke="#c0392b" stroke-width="2"/>"##,
            line.join(" ")
        );
    }
    for (r, t, e) in &points {
        let on_front = front.iter().any(|f| std::ptr::eq(*f, *r));
        let (x, y) = (x_of(*t), y_of(*e));
        let colour = if on_front { "#c0392b" } else { "#2c3e50" };
        let _ = writeln!(
            svg,
            r#"<circle cx="{x:.1}" cy="{y:.1}" r="5" fill="{colour}"><title>{}: {t:.2} ms, {e:.3} mm</title></circle>"#,
            escape(&r.variant.name)
        );
        let _ = writeln!(
            svg,
            r#"<text x="{:.1}" y="{:.1}" fill="{colour}">{}</text>"#,
            x + 8.0,
            y - 6.0,
            escape(&r.variant.name)
        );
    }
    let _ = writeln!(
        svg,
        r##"<text x="{:.1}" y="{:.1}" fill="#c0392b">— Pareto front</text>"##,
        W - RIGHT + 12.0,
        TOP + 14.0
    );
    let _ = writeln!(
        svg,
        r##"<text x="{:.1}" y="{:.1}" fill="#555">{}</text>"##,
        W - RIGHT + 12.0,
        TOP + 32.0,
        escape(&report.machine.date_utc)
    );
    svg.push_str("</svg>\n");
    svg
}

fn escape(text: &str) -> String {
    text.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
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
            machine: Machine::this(),
        };
        let svg = pareto_svg(&report);
        assert_eq!(svg.matches("<circle").count(), 2);
        assert!(svg.contains("<polyline") && svg.contains("fast &lt;rough&gt;"));
        assert!(markdown(&report).contains("| fast <rough> | 64x48 |"));
    }

    #[test]
    fn utc_date_is_well_formed() {
        let date = utc_now();
        assert_eq!(date.len(), "2026-01-01 00:00 UTC".len(), "{date}");
        assert!(date.starts_with("20"));
    }
}
