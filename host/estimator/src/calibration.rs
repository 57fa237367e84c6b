//! Force calibration: fit F = a * gamma + b to (gamma, force) pairs, robustly and with confidence intervals, and
//! write a and b into a sensor config without disturbing the rest of it.
//!
//! The fit is an MM-type regression: the Theil-Sen line (median of pairwise slopes, breakdown point 29 %) gives
//! the start and the residual scale (1.4826 x MAD), then iteratively reweighted least squares with Tukey's
//! bisquare at that fixed scale gives an efficient final line. A convex loss such as Huber's is not enough: its
//! minimum follows a single far-out gamma (a bad leverage point, e.g. a frame caught mid-press), the bisquare
//! gives such points weight zero. Intervals use the M-estimator's asymptotic (sandwich) covariance with Huber's
//! small-sample correction and Student's t with n - 2 degrees of freedom.
//!
//! Pairs come either straight from a CSV of (gamma, force), or from a recorded session: readings with
//! timestamps aligned with a force/torque log by time ([`align_by_time`]).

use nusense_geometry::Point2;
use thiserror::Error;

pub mod modulus;
pub mod push_centre;
pub mod push_normal;

/// One calibration point: the sensor's gamma and the reference force in newtons.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CalibrationSample {
    pub gamma: f64,
    pub force_n: f64,
}

#[derive(Debug, Error, Clone, PartialEq)]
pub enum CalibrationError {
    #[error("a line needs at least {needed} distinct (gamma, force) points, got {found}")]
    TooFewPoints { found: usize, needed: usize },
    #[error("point {index} is not a finite number (gamma {gamma}, force {force_n})")]
    NotFinite { index: usize, gamma: f64, force_n: f64 },
    #[error("gamma does not vary (all points at gamma = {gamma}): the force cannot be fitted as a function of it")]
    GammaConstant { gamma: f64 },
    #[error("the confidence level {0} must lie strictly between 0 and 1")]
    BadConfidence(f64),
    #[error("line {line}: {message}")]
    Parse { line: usize, message: String },
    #[error("no column named {wanted} in the header (columns: {found})")]
    MissingColumn { wanted: String, found: String },
    #[error("no reading lies within {max_skew_s} s of a force sample ({readings} readings, {forces} force samples)")]
    NoOverlap {
        readings: usize,
        forces: usize,
        max_skew_s: f64,
    },
    #[error(
        "the push centre shift and the push's normal share need at least {needed} pushes of a tenth of their load or \
         more, got {found}"
    )]
    TooFewPushes { found: usize, needed: usize },
    #[error("the normal force scale {0} must be finite and positive")]
    BadScale(f64),
    #[error("the sensor config: {0}")]
    Config(String),
    #[error(
        "the force/torque log's torque column `{column}` does not say its unit: name it {column}_nm (N m) or \
         {column}_nmm (N mm)"
    )]
    TorqueUnit { column: String },
}

/// Options of [`fit_force_line`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FitOptions {
    /// Tukey bisquare's tuning constant in units of the residual scale (4.685: 95 % efficiency on Gaussian
    /// noise); residuals beyond it get weight zero.
    pub bisquare_c: f64,
    /// Two-sided confidence level of the intervals.
    pub confidence: f64,
    pub max_iterations: usize,
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            bisquare_c: 4.685,
            confidence: 0.95,
            max_iterations: 200,
        }
    }
}

/// The fitted line with its uncertainty.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForceFit {
    pub a: f64,
    pub b: f64,
    /// Confidence interval of `a` at `confidence`.
    pub a_interval: [f64; 2],
    pub b_interval: [f64; 2],
    pub a_std_error: f64,
    pub b_std_error: f64,
    pub confidence: f64,
    /// Robust standard deviation of the residuals (1.4826 x MAD), N.
    pub residual_scale_n: f64,
    pub points: usize,
    /// Points with weight zero in the final line (beyond `bisquare_c` residual scales).
    pub outliers: usize,
    pub iterations: usize,
}

const MAD_TO_SIGMA: f64 = 1.482_602_218_505_602;

/// Fits F = a * gamma + b robustly; see the module notes.
pub fn fit_force_line(samples: &[CalibrationSample], options: &FitOptions) -> Result<ForceFit, CalibrationError> {
    if !(options.confidence > 0.0 && options.confidence < 1.0) {
        return Err(CalibrationError::BadConfidence(options.confidence));
    }
    if let Some((index, s)) = samples
        .iter()
        .enumerate()
        .find(|(_, s)| !(s.gamma.is_finite() && s.force_n.is_finite()))
    {
        return Err(CalibrationError::NotFinite {
            index,
            gamma: s.gamma,
            force_n: s.force_n,
        });
    }
    let distinct = distinct_count(samples);
    const NEEDED: usize = 3;
    if distinct < NEEDED {
        return Err(CalibrationError::TooFewPoints {
            found: distinct,
            needed: NEEDED,
        });
    }
    let x: Vec<f64> = samples.iter().map(|s| s.gamma).collect();
    let y: Vec<f64> = samples.iter().map(|s| s.force_n).collect();
    let (x_min, x_max) = x
        .iter()
        .fold((f64::MAX, f64::MIN), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    if x_max - x_min <= 1e-12 * x_max.abs().max(x_min.abs()).max(1e-300) {
        return Err(CalibrationError::GammaConstant { gamma: x_min });
    }
    let n = x.len();
    let c = if options.bisquare_c > 0.0 && options.bisquare_c.is_finite() {
        options.bisquare_c
    } else {
        4.685
    };

    let (mut a, mut b) = theil_sen(&x, &y).ok_or(CalibrationError::GammaConstant { gamma: x_min })?;
    // The residual scale stays at that of the Theil-Sen start (the MM-estimation recipe): re-estimating it each
    // round lets a far-out gamma inflate the scale, gain weight and tilt the line towards itself.
    let start_residuals: Vec<f64> = x.iter().zip(&y).map(|(&xi, &yi)| yi - (a * xi + b)).collect();
    let scale = robust_scale(&start_residuals);
    let mut iterations = 0;
    let mut weights = vec![1.0; n];
    for iteration in 1..=options.max_iterations.max(1) {
        iterations = iteration;
        let residuals: Vec<f64> = x.iter().zip(&y).map(|(&xi, &yi)| yi - (a * xi + b)).collect();
        if scale <= 0.0 {
            // More than half the points lie exactly on the start line: that line is the fit.
            break;
        }
        for (w, r) in weights.iter_mut().zip(&residuals) {
            *w = bisquare_weight(r / scale, c);
        }
        let Some((na, nb)) = weighted_line(&x, &y, &weights) else {
            break;
        };
        let converged = (na - a).abs() <= 1e-12 * (1.0 + a.abs()) && (nb - b).abs() <= 1e-12 * (1.0 + b.abs());
        a = na;
        b = nb;
        if converged {
            break;
        }
    }

    let residuals: Vec<f64> = x.iter().zip(&y).map(|(&xi, &yi)| yi - (a * xi + b)).collect();
    let (a_std_error, b_std_error) = m_estimator_standard_errors(&x, &residuals, scale, c);
    let t = student_t_quantile(0.5 + options.confidence / 2.0, (n - 2) as f64);
    let outliers = if scale > 0.0 {
        residuals.iter().filter(|r| r.abs() >= c * scale).count()
    } else {
        residuals.iter().filter(|r| **r != 0.0).count()
    };
    Ok(ForceFit {
        a,
        b,
        a_interval: [a - t * a_std_error, a + t * a_std_error],
        b_interval: [b - t * b_std_error, b + t * b_std_error],
        a_std_error,
        b_std_error,
        confidence: options.confidence,
        residual_scale_n: scale,
        points: n,
        outliers,
        iterations,
    })
}

fn distinct_count(samples: &[CalibrationSample]) -> usize {
    let mut keys: Vec<(u64, u64)> = samples
        .iter()
        .map(|s| (s.gamma.to_bits(), s.force_n.to_bits()))
        .collect();
    keys.sort_unstable();
    keys.dedup();
    keys.len()
}

fn median(values: &mut [f64]) -> f64 {
    let n = values.len();
    if n == 0 {
        return 0.0;
    }
    values.sort_unstable_by(f64::total_cmp);
    if n % 2 == 1 {
        values[n / 2]
    } else {
        0.5 * (values[n / 2 - 1] + values[n / 2])
    }
}

/// 1.4826 x the median absolute deviation from the median: the standard deviation for Gaussian residuals.
fn robust_scale(residuals: &[f64]) -> f64 {
    let mut r = residuals.to_vec();
    let centre = median(&mut r);
    let mut deviations: Vec<f64> = residuals.iter().map(|v| (v - centre).abs()).collect();
    MAD_TO_SIGMA * median(&mut deviations)
}

/// Most slope pairs Theil-Sen looks at; beyond that a fixed, evenly spread subset of pairs.
const MAX_SLOPE_PAIRS: usize = 2_000_000;

/// Median of pairwise slopes, intercept the median of y - a x. `None` if no two points differ in x.
fn theil_sen(x: &[f64], y: &[f64]) -> Option<(f64, f64)> {
    let n = x.len();
    let total = n * (n - 1) / 2;
    let stride = total.div_ceil(MAX_SLOPE_PAIRS).max(1);
    let mut slopes = Vec::with_capacity(total.min(MAX_SLOPE_PAIRS) + 1);
    let mut pair = 0usize;
    for i in 0..n {
        for j in i + 1..n {
            pair += 1;
            if !pair.is_multiple_of(stride) {
                continue;
            }
            let dx = x[j] - x[i];
            if dx != 0.0 {
                slopes.push((y[j] - y[i]) / dx);
            }
        }
    }
    if slopes.is_empty() {
        return None;
    }
    let a = median(&mut slopes);
    let mut intercepts: Vec<f64> = x.iter().zip(y).map(|(&xi, &yi)| yi - a * xi).collect();
    Some((a, median(&mut intercepts)))
}

fn weighted_line(x: &[f64], y: &[f64], w: &[f64]) -> Option<(f64, f64)> {
    let sw: f64 = w.iter().sum();
    if !(sw > 0.0) {
        return None;
    }
    let mx = x.iter().zip(w).map(|(a, b)| a * b).sum::<f64>() / sw;
    let my = y.iter().zip(w).map(|(a, b)| a * b).sum::<f64>() / sw;
    let sxx: f64 = x.iter().zip(w).map(|(&xi, &wi)| wi * (xi - mx) * (xi - mx)).sum();
    let sxy: f64 = x
        .iter()
        .zip(y)
        .zip(w)
        .map(|((&xi, &yi), &wi)| wi * (xi - mx) * (yi - my))
        .sum();
    if !(sxx > 0.0) {
        return None;
    }
    let a = sxy / sxx;
    let b = my - a * mx;
    (a.is_finite() && b.is_finite()).then_some((a, b))
}

fn bisquare_weight(u: f64, c: f64) -> f64 {
    let t = u / c;
    if t.abs() < 1.0 {
        (1.0 - t * t).powi(2)
    } else {
        0.0
    }
}

fn bisquare_psi_prime(u: f64, c: f64) -> f64 {
    let t2 = (u / c).powi(2);
    if t2 < 1.0 {
        (1.0 - t2) * (1.0 - 5.0 * t2)
    } else {
        0.0
    }
}

/// Standard errors of (a, b) from the M-estimator's asymptotic covariance
/// K^2 [sum psi^2 / (n - p)] / mean(psi')^2 s^2 (X^T X)^-1 with Huber's correction K = 1 + p/n var(psi')/mean(psi')^2
/// (Huber 1981, "Robust Statistics", 7.6). Zero when the residual scale is zero (an exact line).
fn m_estimator_standard_errors(x: &[f64], residuals: &[f64], scale: f64, c: f64) -> (f64, f64) {
    let n = x.len() as f64;
    let p = 2.0;
    if !(scale > 0.0) || n <= p {
        return (0.0, 0.0);
    }
    let u: Vec<f64> = residuals.iter().map(|r| r / scale).collect();
    let psi_sq_sum: f64 = u.iter().map(|&v| (v * bisquare_weight(v, c)).powi(2)).sum();
    let psi_prime: Vec<f64> = u.iter().map(|&v| bisquare_psi_prime(v, c)).collect();
    let m = psi_prime.iter().sum::<f64>() / n;
    let sx: f64 = x.iter().sum();
    let sxx: f64 = x.iter().map(|v| v * v).sum();
    let det = n * sxx - sx * sx;
    if !(det > 0.0) {
        return (0.0, 0.0);
    }
    let factor = if m > 0.0 {
        let var_psi_prime = psi_prime.iter().map(|v| (v - m).powi(2)).sum::<f64>() / n;
        let correction = 1.0 + p / n * var_psi_prime / (m * m);
        correction * correction * (psi_sq_sum / (n - p)) / (m * m) * scale * scale
    } else {
        // Most residuals sit where the bisquare turns over: fall back to the plain least-squares variance.
        residuals.iter().map(|r| r * r).sum::<f64>() / (n - p)
    };
    ((factor * n / det).max(0.0).sqrt(), (factor * sxx / det).max(0.0).sqrt())
}

/// Regularised incomplete beta function I_x(a, b) by its continued fraction (Numerical Recipes, 6.4).
fn incomplete_beta(x: f64, a: f64, b: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 1.0 {
        return 1.0;
    }
    let ln_front = ln_gamma(a + b) - ln_gamma(a) - ln_gamma(b) + a * x.ln() + b * (1.0 - x).ln();
    let front = ln_front.exp();
    if x < (a + 1.0) / (a + b + 2.0) {
        front * beta_continued_fraction(x, a, b) / a
    } else {
        1.0 - front * beta_continued_fraction(1.0 - x, b, a) / b
    }
}

fn beta_continued_fraction(x: f64, a: f64, b: f64) -> f64 {
    const TINY: f64 = 1e-300;
    let (qab, qap, qam) = (a + b, a + 1.0, a - 1.0);
    let mut c = 1.0;
    let mut d = 1.0 - qab * x / qap;
    if d.abs() < TINY {
        d = TINY;
    }
    d = 1.0 / d;
    let mut h = d;
    for m in 1..300 {
        let m = f64::from(m);
        let m2 = 2.0 * m;
        let aa = m * (b - m) * x / ((qam + m2) * (a + m2));
        d = 1.0 + aa * d;
        d = if d.abs() < TINY { TINY } else { d };
        c = 1.0 + aa / c;
        c = if c.abs() < TINY { TINY } else { c };
        d = 1.0 / d;
        h *= d * c;
        let aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2));
        d = 1.0 + aa * d;
        d = if d.abs() < TINY { TINY } else { d };
        c = 1.0 + aa / c;
        c = if c.abs() < TINY { TINY } else { c };
        d = 1.0 / d;
        let delta = d * c;
        h *= delta;
        if (delta - 1.0).abs() < 1e-15 {
            break;
        }
    }
    h
}

/// ln Gamma(x) for x > 0 (Lanczos, g = 7, n = 9).
fn ln_gamma(x: f64) -> f64 {
    const COEFFICIENTS: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        // Reflection.
        let pi = std::f64::consts::PI;
        return (pi / (pi * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let t = x + 7.5;
    let mut sum = COEFFICIENTS[0];
    for (i, c) in COEFFICIENTS.iter().enumerate().skip(1) {
        sum += c / (x + i as f64);
    }
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + sum.ln()
}

fn student_t_cdf(t: f64, dof: f64) -> f64 {
    let x = dof / (dof + t * t);
    let tail = 0.5 * incomplete_beta(x, dof / 2.0, 0.5);
    if t >= 0.0 {
        1.0 - tail
    } else {
        tail
    }
}

/// The `p` quantile of Student's t with `dof` degrees of freedom (p in (0.5, 1)), by bisection on the CDF.
/// With no degrees of freedom left the interval is unbounded: infinity.
pub fn student_t_quantile(p: f64, dof: f64) -> f64 {
    if !(dof >= 1.0) {
        return f64::INFINITY;
    }
    let (mut lo, mut hi) = (0.0, 1.0);
    while student_t_cdf(hi, dof) < p && hi < 1e12 {
        hi *= 2.0;
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if student_t_cdf(mid, dof) < p {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Splits a CSV line (plain numeric logs: commas, optional spaces, no quoting).
fn split_csv(line: &str) -> Vec<&str> {
    line.split(',').map(str::trim).collect()
}

/// The finite number in column `col` of a CSV line's `fields`; `what` names the column in the error.
fn number_at(fields: &[&str], col: usize, line: usize, what: &str) -> Result<f64, CalibrationError> {
    let field = fields.get(col).ok_or_else(|| CalibrationError::Parse {
        line,
        message: format!("no {what} column"),
    })?;
    field
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .ok_or_else(|| CalibrationError::Parse {
            line,
            message: format!("{what} `{field}` is not a finite number"),
        })
}

/// A force/torque log's header (its first data line, split) and the data lines after it.
fn log_header(text: &str) -> Result<(Vec<&str>, impl Iterator<Item = (usize, &str)>), CalibrationError> {
    let mut lines = data_lines(text);
    let (_, header_line) = lines.next().ok_or(CalibrationError::MissingColumn {
        wanted: "a header".into(),
        found: String::new(),
    })?;
    Ok((split_csv(header_line), lines))
}

fn data_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'))
}

fn find_column(header: &[&str], names: &[&str]) -> Option<usize> {
    header
        .iter()
        .position(|h| names.iter().any(|n| h.eq_ignore_ascii_case(n)))
}

/// (gamma, force) pairs from CSV: a header naming `gamma` and `force` (or `force_n`), or no header and the
/// first two columns in that order.
pub fn parse_pairs_csv(text: &str) -> Result<Vec<CalibrationSample>, CalibrationError> {
    let mut lines = data_lines(text).peekable();
    let (gamma_col, force_col) = match lines.peek() {
        // A header is a first line whose first field is not a number.
        Some(&(_, first)) if split_csv(first)[0].parse::<f64>().is_err() => {
            let header = split_csv(first);
            let found = header.join(", ");
            let gamma = find_column(&header, &["gamma"]).ok_or_else(|| CalibrationError::MissingColumn {
                wanted: "gamma".into(),
                found: found.clone(),
            })?;
            let force =
                find_column(&header, &["force", "force_n", "f", "f_n"]).ok_or(CalibrationError::MissingColumn {
                    wanted: "force (or force_n)".into(),
                    found,
                })?;
            lines.next();
            (gamma, force)
        }
        _ => (0, 1),
    };
    lines
        .map(|(line, text)| {
            let fields = split_csv(text);
            let get = |col: usize, what: &str| number_at(&fields, col, line, what);
            Ok(CalibrationSample {
                gamma: get(gamma_col, "gamma")?,
                force_n: get(force_col, "force")?,
            })
        })
        .collect()
}

/// Which force of a force/torque log is the reference for the normal force.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ForceComponent {
    /// |fz|: the sensor's z axis along the pad normal (sign conventions differ between F/T sensors).
    AbsFz,
    Fx,
    Fy,
    Fz,
    /// sqrt(fx^2 + fy^2 + fz^2).
    Norm,
    /// sqrt(fx^2 + fy^2): the push's size, whatever the F/T sensor's axes in the pad's plane (the reference for
    /// [`modulus::fit_tangential_scale`]).
    Tangential,
}

/// A force/torque log sample: time in seconds and the chosen force in newtons.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForceSample {
    pub time_s: f64,
    pub force_n: f64,
}

/// A gamma with its time in seconds (the same clock as the force log, after any offset).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TimedGamma {
    pub time_s: f64,
    pub gamma: f64,
}

/// A force/torque log: a header with a time column (`timestamp`, `time`, `t`, with an optional `_s`, `_ms` or
/// `_us` suffix giving the unit; seconds otherwise) and `fx`, `fy`, `fz`; other columns are ignored.
pub fn parse_force_log_csv(text: &str, component: ForceComponent) -> Result<Vec<ForceSample>, CalibrationError> {
    let (header, lines) = log_header(text)?;
    let found = header.join(", ");
    let (time_col, time_unit) = time_column(&header)?;
    let column = |name: &str| {
        find_column(&header, &[name]).ok_or_else(|| CalibrationError::MissingColumn {
            wanted: name.into(),
            found: found.clone(),
        })
    };
    let needed: Vec<(usize, &str)> = match component {
        ForceComponent::Fx => vec![(column("fx")?, "fx")],
        ForceComponent::Fy => vec![(column("fy")?, "fy")],
        ForceComponent::Fz | ForceComponent::AbsFz => vec![(column("fz")?, "fz")],
        ForceComponent::Norm => vec![(column("fx")?, "fx"), (column("fy")?, "fy"), (column("fz")?, "fz")],
        ForceComponent::Tangential => vec![(column("fx")?, "fx"), (column("fy")?, "fy")],
    };
    lines
        .map(|(line, text)| {
            let fields = split_csv(text);
            let get = |col: usize, what: &str| number_at(&fields, col, line, what);
            let time_s = get(time_col, "timestamp")? * time_unit;
            let values: Vec<f64> = needed.iter().map(|&(c, name)| get(c, name)).collect::<Result<_, _>>()?;
            let force_n = match component {
                ForceComponent::AbsFz => values[0].abs(),
                ForceComponent::Fx | ForceComponent::Fy | ForceComponent::Fz => values[0],
                ForceComponent::Norm | ForceComponent::Tangential => values.iter().map(|v| v * v).sum::<f64>().sqrt(),
            };
            Ok(ForceSample { time_s, force_n })
        })
        .collect()
}

/// A force/torque log's time column and its unit in seconds: `timestamp`, `time` or `t`, with an optional `_s`,
/// `_ms` or `_us` suffix (seconds without one).
fn time_column(header: &[&str]) -> Result<(usize, f64), CalibrationError> {
    let time_columns: [(&str, f64); 12] = [
        ("timestamp", 1.0),
        ("time", 1.0),
        ("t", 1.0),
        ("timestamp_s", 1.0),
        ("time_s", 1.0),
        ("t_s", 1.0),
        ("timestamp_ms", 1e-3),
        ("time_ms", 1e-3),
        ("t_ms", 1e-3),
        ("timestamp_us", 1e-6),
        ("time_us", 1e-6),
        ("t_us", 1e-6),
    ];
    time_columns
        .iter()
        .find_map(|&(name, unit)| find_column(header, &[name]).map(|c| (c, unit)))
        .ok_or_else(|| CalibrationError::MissingColumn {
            wanted: "timestamp".into(),
            found: header.join(", "),
        })
}

/// Where the probe touched the pad at a time of a force/torque log: mm from the pattern's centre in the pad's frame
/// (x right, y down as seen in the raw image; the frame of a reading's `contact_mm`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PositionSample {
    pub time_s: f64,
    pub position_mm: Point2,
}

/// The probe's contact point from a force/torque log's optional `x_mm` and `y_mm` columns (the time column as
/// [`parse_force_log_csv`] reads it). `Ok(None)` when the header has neither; a header with only one of them is a
/// [`CalibrationError::MissingColumn`], and a row whose `x_mm` or `y_mm` is not a finite number a
/// [`CalibrationError::Parse`] (every row must carry both).
pub fn parse_position_log_csv(text: &str) -> Result<Option<Vec<PositionSample>>, CalibrationError> {
    let (header, lines) = log_header(text)?;
    let (x_col, y_col) = match (find_column(&header, &["x_mm"]), find_column(&header, &["y_mm"])) {
        (None, None) => return Ok(None),
        (Some(x), Some(y)) => (x, y),
        (x, _) => {
            return Err(CalibrationError::MissingColumn {
                wanted: if x.is_some() { "y_mm" } else { "x_mm" }.into(),
                found: header.join(", "),
            })
        }
    };
    let (time_col, time_unit) = time_column(&header)?;
    lines
        .map(|(line, text)| {
            let fields = split_csv(text);
            let get = |col: usize, what: &str| number_at(&fields, col, line, what);
            Ok(PositionSample {
                time_s: get(time_col, "timestamp")? * time_unit,
                position_mm: [get(x_col, "x_mm")?, get(y_col, "y_mm")?],
            })
        })
        .collect::<Result<Vec<_>, _>>()
        .map(Some)
}

/// The torque about the normal (N mm, its size) from a force/torque log's optional `mz` or `tz` column, whose name
/// must say its unit: `mz_nmm` / `tz_nmm` (N mm) or `mz_nm` / `tz_nm` (N m). `Ok(None)` when the header has none
/// of them; a bare `mz` or `tz` (F/T sensors log N m or N mm) is a [`CalibrationError::TorqueUnit`], and a row
/// whose torque is not a finite number a [`CalibrationError::Parse`]. The time column as [`parse_force_log_csv`]
/// reads it.
pub fn parse_torque_log_csv(text: &str) -> Result<Option<Vec<ForceSample>>, CalibrationError> {
    let (header, lines) = log_header(text)?;
    let with_unit = [("mz_nmm", 1.0), ("tz_nmm", 1.0), ("mz_nm", 1e3), ("tz_nm", 1e3)];
    let Some((column, unit, name)) = with_unit
        .iter()
        .find_map(|&(name, unit)| find_column(&header, &[name]).map(|c| (c, unit, name)))
    else {
        return match ["mz", "tz"]
            .into_iter()
            .find(|name| find_column(&header, &[name]).is_some())
        {
            Some(bare) => Err(CalibrationError::TorqueUnit { column: bare.into() }),
            None => Ok(None),
        };
    };
    let (time_col, time_unit) = time_column(&header)?;
    lines
        .map(|(line, text)| {
            let fields = split_csv(text);
            let get = |col: usize, what: &str| number_at(&fields, col, line, what);
            Ok(ForceSample {
                time_s: get(time_col, "timestamp")? * time_unit,
                force_n: (get(column, name)? * unit).abs(),
            })
        })
        .collect::<Result<Vec<_>, _>>()
        .map(Some)
}

/// The log's position at each of `times` (seconds, the log's clock), interpolated by [`align_by_time`]'s rule as
/// the forces are; `None` where no sample lies within `max_skew_s`.
pub fn positions_at_times(times: &[f64], positions: &[PositionSample], max_skew_s: f64) -> Vec<Option<Point2>> {
    let axis = |k: usize| {
        let samples: Vec<ForceSample> = positions
            .iter()
            .map(|p| ForceSample {
                time_s: p.time_s,
                force_n: p.position_mm[k],
            })
            .collect();
        forces_at_times(times, &samples, max_skew_s)
    };
    axis(0).into_iter().zip(axis(1)).map(|(x, y)| Some([x?, y?])).collect()
}

/// The outcome of [`align_by_time`].
#[derive(Clone, Debug, PartialEq)]
pub struct Alignment {
    pub samples: Vec<CalibrationSample>,
    /// Readings with no force sample within the allowed skew.
    pub dropped: usize,
}

/// Pairs each reading with the force at its time: linear interpolation between the two force samples around it
/// when the nearer of them is within `max_skew_s`, otherwise the reading is dropped (counted, not guessed).
pub fn align_by_time(
    readings: &[TimedGamma],
    forces: &[ForceSample],
    max_skew_s: f64,
) -> Result<Alignment, CalibrationError> {
    let times: Vec<f64> = readings
        .iter()
        .map(|r| if r.gamma.is_finite() { r.time_s } else { f64::NAN })
        .collect();
    let mut samples = Vec::new();
    let mut dropped = 0;
    for (r, force) in readings.iter().zip(forces_at_times(&times, forces, max_skew_s)) {
        match force {
            Some(force_n) => samples.push(CalibrationSample {
                gamma: r.gamma,
                force_n,
            }),
            None => dropped += 1,
        }
    }
    if samples.is_empty() {
        return Err(CalibrationError::NoOverlap {
            readings: readings.len(),
            forces: forces.len(),
            max_skew_s,
        });
    }
    Ok(Alignment { samples, dropped })
}

/// The log's force at each of `times` (seconds, the log's clock), by [`align_by_time`]'s rule; `None` where no
/// force sample lies within `max_skew_s` or the time is not finite.
pub fn forces_at_times(times: &[f64], forces: &[ForceSample], max_skew_s: f64) -> Vec<Option<f64>> {
    let mut forces: Vec<ForceSample> = forces
        .iter()
        .copied()
        .filter(|f| f.time_s.is_finite() && f.force_n.is_finite())
        .collect();
    forces.sort_by(|a, b| a.time_s.total_cmp(&b.time_s));
    times
        .iter()
        .map(|&time_s| {
            if !time_s.is_finite() {
                return None;
            }
            let after = forces.partition_point(|f| f.time_s < time_s);
            let before = after.checked_sub(1).map(|i| forces[i]);
            let next = forces.get(after).copied();
            match (before, next) {
                (Some(b), Some(n)) => {
                    let nearest = (time_s - b.time_s).min(n.time_s - time_s);
                    (nearest <= max_skew_s).then(|| {
                        let span = n.time_s - b.time_s;
                        if span > 0.0 {
                            b.force_n + (n.force_n - b.force_n) * (time_s - b.time_s) / span
                        } else {
                            0.5 * (b.force_n + n.force_n)
                        }
                    })
                }
                (Some(only), None) | (None, Some(only)) => {
                    ((time_s - only.time_s).abs() <= max_skew_s).then_some(only.force_n)
                }
                (None, None) => None,
            }
        })
        .collect()
}

/// Sets `calibration.a` and `calibration.b` in a sensor config's TOML text, keeping every other key, comment
/// and the layout; the result must still be a valid config.
pub fn update_config_toml(text: &str, a: f64, b: f64) -> Result<String, CalibrationError> {
    if !(a.is_finite() && b.is_finite()) {
        return Err(CalibrationError::Config(format!(
            "refusing to write a non-finite calibration (a = {a}, b = {b})"
        )));
    }
    edit_config(text, |document| {
        let table = table_mut(document, "calibration")?;
        table.insert("a", toml_edit::value(a));
        table.insert("b", toml_edit::value(b));
        Ok(())
    })
}

/// Sets `elastic.shear_modulus_kpa` (what [`modulus::fit_modulus_scale`] calibrates), keeping everything else.
pub fn set_config_shear_modulus(text: &str, kpa: f64) -> Result<String, CalibrationError> {
    if !(kpa.is_finite() && kpa > 0.0) {
        return Err(CalibrationError::Config(format!(
            "refusing to write a shear modulus of {kpa} kPa"
        )));
    }
    set_elastic_value(text, "shear_modulus_kpa", kpa)
}

/// Sets `elastic.tangential_force_scale` (what [`modulus::fit_tangential_scale`] calibrates), keeping everything
/// else.
pub fn set_config_tangential_force_scale(text: &str, scale: f64) -> Result<String, CalibrationError> {
    if !(scale.is_finite() && scale > 0.0) {
        return Err(CalibrationError::Config(format!(
            "refusing to write a tangential force scale of {scale}"
        )));
    }
    set_elastic_value(text, "tangential_force_scale", scale)
}

/// Sets `elastic.torque_scale` (what [`modulus::fit_torque_scale`] calibrates), keeping everything else.
pub fn set_config_torque_scale(text: &str, scale: f64) -> Result<String, CalibrationError> {
    if !(scale.is_finite() && scale > 0.0) {
        return Err(CalibrationError::Config(format!(
            "refusing to write a torque scale of {scale}"
        )));
    }
    set_elastic_value(text, "torque_scale", scale)
}

/// Sets `elastic.push_centre_shift_mm` (what [`push_centre::fit_push_centre_shift`] calibrates), keeping everything
/// else; a shift the config refuses (beyond +-10 mm) is refused.
pub fn set_config_push_centre_shift(text: &str, shift_mm: f64) -> Result<String, CalibrationError> {
    if !shift_mm.is_finite() {
        return Err(CalibrationError::Config(format!(
            "refusing to write a push centre shift of {shift_mm} mm"
        )));
    }
    set_elastic_value(text, "push_centre_shift_mm", shift_mm)
}

/// Sets `elastic.push_normal_share` (what [`push_normal::fit_push_normal_share`] calibrates), keeping everything
/// else; a share the config refuses (beyond +-1) is refused.
pub fn set_config_push_normal_share(text: &str, share: f64) -> Result<String, CalibrationError> {
    if !share.is_finite() {
        return Err(CalibrationError::Config(format!(
            "refusing to write a push normal share of {share}"
        )));
    }
    set_elastic_value(text, "push_normal_share", share)
}

/// Sets `[elastic]`'s `key` to `value`, keeping everything else (each caller checks its own value first).
fn set_elastic_value(text: &str, key: &str, value: f64) -> Result<String, CalibrationError> {
    edit_config(text, |document| {
        table_mut(document, "elastic")?.insert(key, toml_edit::value(value));
        Ok(())
    })
}

/// Replaces the config's `[pad_map]` with `map` (the rest frame's fitted raw px -> pad mm map), keeping everything
/// else.
pub fn set_config_pad_map(text: &str, map: &crate::StoredPadMap) -> Result<String, CalibrationError> {
    map.validate()
        .map_err(|reason| CalibrationError::Config(format!("refusing to write the pad map: {reason}")))?;
    let serialised = toml::to_string(map).map_err(|e| CalibrationError::Config(e.to_string()))?;
    let parsed: toml_edit::DocumentMut = serialised
        .parse()
        .map_err(|e: toml_edit::TomlError| CalibrationError::Config(e.to_string()))?;
    edit_config(text, |document| {
        let mut table = parsed.as_table().clone();
        table.set_implicit(false);
        document.insert("pad_map", toml_edit::Item::Table(table));
        Ok(())
    })
}

/// Parses a config's TOML, applies `edit`, and checks that the result is still a valid config.
fn edit_config(
    text: &str,
    edit: impl FnOnce(&mut toml_edit::DocumentMut) -> Result<(), CalibrationError>,
) -> Result<String, CalibrationError> {
    let mut document: toml_edit::DocumentMut = text
        .parse()
        .map_err(|e: toml_edit::TomlError| CalibrationError::Config(e.to_string()))?;
    edit(&mut document)?;
    let updated = document.to_string();
    crate::SensorConfig::from_toml_str(&updated).map_err(|e| CalibrationError::Config(e.to_string()))?;
    Ok(updated)
}

fn table_mut<'a>(
    document: &'a mut toml_edit::DocumentMut,
    name: &str,
) -> Result<&'a mut dyn toml_edit::TableLike, CalibrationError> {
    document
        .entry(name)
        .or_insert_with(|| toml_edit::Item::Table(toml_edit::Table::new()))
        .as_table_like_mut()
        .ok_or_else(|| CalibrationError::Config(format!("`{name}` is not a table")))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic small noise in [-amplitude, amplitude] (no RNG dependency, no tuning to a seed).
    fn noise(i: usize, amplitude: f64) -> f64 {
        let phase = (i as f64 * 0.618_033_988_749_895).fract();
        (2.0 * phase - 1.0) * amplitude
    }

    fn line(a: f64, b: f64, gammas: impl Iterator<Item = f64>, amplitude: f64) -> Vec<CalibrationSample> {
        gammas
            .enumerate()
            .map(|(i, g)| CalibrationSample {
                gamma: g,
                force_n: a * g + b + noise(i, amplitude),
            })
            .collect()
    }

    #[test]
    fn recovers_an_exact_line() {
        let samples = line(3.09, -1.14, (0..20).map(|i| 0.5 + 0.1 * f64::from(i)), 0.0);
        let fit = fit_force_line(&samples, &FitOptions::default()).unwrap();
        assert!((fit.a - 3.09).abs() < 1e-9 && (fit.b + 1.14).abs() < 1e-9, "{fit:?}");
        assert_eq!(fit.residual_scale_n, 0.0);
        assert!(fit.a_interval[0] <= fit.a && fit.a <= fit.a_interval[1]);
    }

    #[test]
    fn shrugs_off_outliers_that_pull_least_squares_away() {
        let mut samples = line(3.09, -1.14, (0..40).map(|i| 0.4 + 0.07 * f64::from(i)), 0.05);
        // Five wild points (20 % would be too many for a fair test of least squares; 12 % is plenty).
        for (i, s) in samples.iter_mut().enumerate().filter(|(i, _)| i % 8 == 3) {
            s.force_n += if i % 16 == 3 { 4.0 } else { -3.0 };
        }
        let fit = fit_force_line(&samples, &FitOptions::default()).unwrap();
        assert!((fit.a - 3.09).abs() < 0.05, "a = {}", fit.a);
        assert!((fit.b + 1.14).abs() < 0.08, "b = {}", fit.b);
        assert_eq!(fit.outliers, 5, "{fit:?}");
        assert!(fit.a_interval[0] < 3.09 && 3.09 < fit.a_interval[1], "{fit:?}");
        assert!(fit.b_interval[0] < -1.14 && -1.14 < fit.b_interval[1], "{fit:?}");
        // Ordinary least squares on the same points misses by far more.
        let w = vec![1.0; samples.len()];
        let x: Vec<f64> = samples.iter().map(|s| s.gamma).collect();
        let y: Vec<f64> = samples.iter().map(|s| s.force_n).collect();
        let (ols_a, ols_b) = weighted_line(&x, &y, &w).unwrap();
        assert!((ols_a - 3.09).abs() + (ols_b + 1.14).abs() > 3.0 * ((fit.a - 3.09).abs() + (fit.b + 1.14).abs()));
    }

    #[test]
    fn a_high_leverage_outlier_does_not_tilt_the_line() {
        let mut samples = line(2.0, 0.5, (0..15).map(|i| 1.0 + 0.2 * f64::from(i)), 0.02);
        samples.push(CalibrationSample {
            gamma: 20.0,
            force_n: 0.0,
        });
        let fit = fit_force_line(&samples, &FitOptions::default()).unwrap();
        assert!((fit.a - 2.0).abs() < 0.05 && (fit.b - 0.5).abs() < 0.1, "{fit:?}");
    }

    #[test]
    fn intervals_cover_the_truth_at_about_the_stated_rate() {
        // 200 independent noisy lines; a 95 % interval should miss the true slope in roughly 5 % of them.
        let mut misses = 0;
        let trials = 200;
        for trial in 0..trials {
            let samples: Vec<CalibrationSample> = (0..25)
                .map(|i| {
                    let g = 0.5 + 0.1 * f64::from(i);
                    // Sum of uniforms: roughly Gaussian noise, different in every trial.
                    let e: f64 = (0..4)
                        .map(|k| noise(trial * 1000 + i as usize * 7 + k * 131 + 1, 0.1))
                        .sum();
                    CalibrationSample {
                        gamma: g,
                        force_n: 3.0 * g - 1.0 + e,
                    }
                })
                .collect();
            let fit = fit_force_line(&samples, &FitOptions::default()).unwrap();
            if !(fit.a_interval[0] <= 3.0 && 3.0 <= fit.a_interval[1]) {
                misses += 1;
            }
        }
        assert!(misses <= 25, "{misses} of {trials} intervals missed");
        assert!(
            misses >= 1,
            "intervals so wide they never miss are useless: {misses} of {trials}"
        );
    }

    #[test]
    fn degenerate_data_gives_typed_errors() {
        let p = |g: f64, f: f64| CalibrationSample { gamma: g, force_n: f };
        let options = FitOptions::default();
        assert_eq!(
            fit_force_line(&[], &options),
            Err(CalibrationError::TooFewPoints { found: 0, needed: 3 })
        );
        assert!(matches!(
            fit_force_line(&[p(1.0, 1.0), p(2.0, 2.0)], &options),
            Err(CalibrationError::TooFewPoints { found: 2, .. })
        ));
        // Duplicates do not count as new information.
        assert!(matches!(
            fit_force_line(&[p(1.0, 1.0), p(1.0, 1.0), p(2.0, 2.0), p(2.0, 2.0)], &options),
            Err(CalibrationError::TooFewPoints { found: 2, .. })
        ));
        assert!(matches!(
            fit_force_line(&[p(1.0, 1.0), p(1.0, 2.0), p(1.0, 3.0)], &options),
            Err(CalibrationError::GammaConstant { .. })
        ));
        assert!(matches!(
            fit_force_line(&[p(1.0, 1.0), p(f64::NAN, 2.0), p(2.0, 3.0)], &options),
            Err(CalibrationError::NotFinite { index: 1, .. })
        ));
        assert!(matches!(
            fit_force_line(
                &[p(1.0, 1.0), p(2.0, 2.0), p(3.0, 3.5)],
                &FitOptions {
                    confidence: 1.0,
                    ..options
                }
            ),
            Err(CalibrationError::BadConfidence(_))
        ));
    }

    #[test]
    fn three_points_fit_with_finite_numbers() {
        let fit = fit_force_line(
            &[
                CalibrationSample {
                    gamma: 1.0,
                    force_n: 2.0,
                },
                CalibrationSample {
                    gamma: 2.0,
                    force_n: 4.1,
                },
                CalibrationSample {
                    gamma: 3.0,
                    force_n: 5.9,
                },
            ],
            &FitOptions::default(),
        )
        .unwrap();
        for v in [
            fit.a,
            fit.b,
            fit.a_interval[0],
            fit.a_interval[1],
            fit.b_interval[0],
            fit.b_interval[1],
        ] {
            assert!(v.is_finite(), "{fit:?}");
        }
    }

    #[test]
    fn t_quantiles_match_tables() {
        for (dof, expected) in [
            (1.0, 12.706),
            (2.0, 4.303),
            (5.0, 2.571),
            (30.0, 2.042),
            (1000.0, 1.962),
        ] {
            let t = student_t_quantile(0.975, dof);
            assert!((t - expected).abs() < 2e-3, "dof {dof}: {t}");
        }
        assert_eq!(student_t_quantile(0.975, 0.0), f64::INFINITY);
    }

    #[test]
    fn parses_pair_csv_with_and_without_header() {
        let with = parse_pairs_csv("# a comment\nforce_n, gamma\n1.5, 0.8\n3.0,1.3e0\n").unwrap();
        assert_eq!(
            with,
            vec![
                CalibrationSample {
                    gamma: 0.8,
                    force_n: 1.5
                },
                CalibrationSample {
                    gamma: 1.3,
                    force_n: 3.0
                }
            ]
        );
        let without = parse_pairs_csv("0.8,1.5\n1.3,3\n").unwrap();
        assert_eq!(without, with);
        assert!(matches!(
            parse_pairs_csv("gamma,force\n0.8,abc\n"),
            Err(CalibrationError::Parse { line: 2, .. })
        ));
        assert!(matches!(
            parse_pairs_csv("g,force\n"),
            Err(CalibrationError::MissingColumn { .. })
        ));
        assert!(matches!(
            parse_pairs_csv("0.8,inf\n"),
            Err(CalibrationError::Parse { .. })
        ));
    }

    #[test]
    fn parses_force_logs_with_units_and_components() {
        let log = "timestamp_ms,fx,fy,fz,tx\n1000,0.3,0.4,-1.2,0\n1010,0,0,-2,0\n";
        let abs = parse_force_log_csv(log, ForceComponent::AbsFz).unwrap();
        assert_eq!(
            abs,
            vec![
                ForceSample {
                    time_s: 1.0,
                    force_n: 1.2
                },
                ForceSample {
                    time_s: 1.01,
                    force_n: 2.0
                }
            ]
        );
        let norm = parse_force_log_csv(log, ForceComponent::Norm).unwrap();
        assert!((norm[0].force_n - (0.09f64 + 0.16 + 1.44).sqrt()).abs() < 1e-12);
        assert!(matches!(
            parse_force_log_csv("time,fx\n0,1\n", ForceComponent::AbsFz),
            Err(CalibrationError::MissingColumn { .. })
        ));
        assert!(matches!(
            parse_force_log_csv("fz\n1\n", ForceComponent::AbsFz),
            Err(CalibrationError::MissingColumn { .. })
        ));
    }

    #[test]
    fn the_probe_position_columns_are_optional_and_checked() {
        let log = "t_ms,fx,fy,fz,x_mm,y_mm\n1000,0.3,0.4,-1.2,2.5,-4\n1010,0,0,-2,3.5,-4.5\n";
        assert_eq!(
            parse_position_log_csv(log).unwrap(),
            Some(vec![
                PositionSample {
                    time_s: 1.0,
                    position_mm: [2.5, -4.0]
                },
                PositionSample {
                    time_s: 1.01,
                    position_mm: [3.5, -4.5]
                }
            ])
        );
        // Interpolated at the readings' times as the forces are; none far from every sample.
        let positions = parse_position_log_csv(log).unwrap().unwrap();
        let at = positions_at_times(&[1.005, 1.5], &positions, 0.006);
        assert!((at[0].unwrap()[0] - 3.0).abs() < 1e-9 && (at[0].unwrap()[1] + 4.25).abs() < 1e-9);
        assert_eq!(at[1], None);
        // No position columns: nothing to fit, no error.
        assert_eq!(parse_position_log_csv("timestamp,fx,fy,fz\n0,0,0,1\n").unwrap(), None);
        // One of the two, a malformed value, a missing field, a missing time column: typed errors.
        assert!(matches!(
            parse_position_log_csv("timestamp,fz,x_mm\n0,1,2\n"),
            Err(CalibrationError::MissingColumn { ref wanted, .. }) if wanted == "y_mm"
        ));
        assert!(matches!(
            parse_position_log_csv("timestamp,fz,y_mm\n0,1,2\n"),
            Err(CalibrationError::MissingColumn { ref wanted, .. }) if wanted == "x_mm"
        ));
        assert!(matches!(
            parse_position_log_csv("timestamp,fz,x_mm,y_mm\n0,1,2,3\n0.01,1,abc,3\n"),
            Err(CalibrationError::Parse { line: 3, .. })
        ));
        assert!(matches!(
            parse_position_log_csv("timestamp,fz,x_mm,y_mm\n0,1,2\n"),
            Err(CalibrationError::Parse { line: 2, .. })
        ));
        assert!(matches!(
            parse_position_log_csv("timestamp,fz,x_mm,y_mm\n0,1,nan,3\n"),
            Err(CalibrationError::Parse { line: 2, .. })
        ));
        assert!(matches!(
            parse_position_log_csv("fz,x_mm,y_mm\n1,2,3\n"),
            Err(CalibrationError::MissingColumn { .. })
        ));
    }

    /// The torque column's name says its unit; N m are read as N mm, the sign dropped (an F/T sensor's z axis may
    /// point either way); a bare `tz` or `mz` is refused by name, a log without any is no torque and no error.
    #[test]
    fn the_torque_log_reads_its_unit_from_the_column_name() {
        let read = |text: &str| -> Vec<f64> {
            parse_torque_log_csv(text)
                .unwrap()
                .unwrap()
                .iter()
                .map(|s| s.force_n)
                .collect()
        };
        assert_eq!(read("t_ms,fz,tz_nmm\n0,1,-12.5\n10,1,3\n"), vec![12.5, 3.0]);
        assert_eq!(read("timestamp,Mz_Nm,fz\n0,-0.0125,1\n"), vec![12.5]);
        let times: Vec<f64> = parse_torque_log_csv("t_ms,fz,tz_nmm\n0,1,-12.5\n10,1,3\n")
            .unwrap()
            .unwrap()
            .iter()
            .map(|s| s.time_s)
            .collect();
        assert_eq!(times, vec![0.0, 0.01]);
        assert_eq!(parse_torque_log_csv("timestamp,fx,fy,fz\n0,0,0,1\n").unwrap(), None);
        for (text, bare) in [("timestamp,fz,tz\n0,1,2\n", "tz"), ("timestamp,MZ,fz\n0,1,2\n", "mz")] {
            let error = parse_torque_log_csv(text).unwrap_err();
            assert_eq!(error, CalibrationError::TorqueUnit { column: bare.into() });
            assert!(error.to_string().contains(&format!("{bare}_nmm")), "{error}");
        }
        assert!(matches!(
            parse_torque_log_csv("timestamp,fz,tz_nmm\n0,1,2\n0.01,1,inf\n"),
            Err(CalibrationError::Parse { line: 3, .. })
        ));
        assert!(matches!(
            parse_torque_log_csv("fz,tz_nmm\n1,2\n"),
            Err(CalibrationError::MissingColumn { .. })
        ));
    }

    #[test]
    fn aligns_by_interpolation_within_the_skew() {
        let forces: Vec<ForceSample> = (0..11)
            .map(|i| ForceSample {
                time_s: 0.01 * f64::from(i),
                force_n: f64::from(i),
            })
            .collect();
        let readings = [
            TimedGamma {
                time_s: 0.025,
                gamma: 1.0,
            }, // halfway between 2 and 3
            TimedGamma {
                time_s: 0.1004,
                gamma: 2.0,
            }, // just after the log, within skew
            TimedGamma {
                time_s: 0.5,
                gamma: 3.0,
            }, // far outside
        ];
        let aligned = align_by_time(&readings, &forces, 0.006).unwrap();
        assert_eq!(aligned.dropped, 1);
        assert_eq!(aligned.samples.len(), 2);
        assert!((aligned.samples[0].force_n - 2.5).abs() < 1e-9);
        assert_eq!(aligned.samples[1].force_n, 10.0);
        // A gap in the log wider than twice the skew drops readings in its middle.
        let gappy = [forces[0], forces[10]];
        assert!(matches!(
            align_by_time(
                &[TimedGamma {
                    time_s: 0.05,
                    gamma: 1.0
                }],
                &gappy,
                0.002
            ),
            Err(CalibrationError::NoOverlap { .. })
        ));
    }

    #[test]
    fn config_update_keeps_other_keys_and_comments() {
        let text = "# my sensor\n[surface]\ndegree_u = 3 # smoother\n\n[calibration]\nalpha = 0.0001\na = 1.0\n";
        let updated = update_config_toml(text, 2.5, -0.75).unwrap();
        assert!(
            updated.contains("# my sensor") && updated.contains("degree_u = 3 # smoother"),
            "{updated}"
        );
        let config = crate::SensorConfig::from_toml_str(&updated).unwrap();
        assert_eq!(
            (config.calibration.a, config.calibration.b, config.calibration.alpha),
            (2.5, -0.75, 0.0001)
        );
        assert_eq!(config.surface.degree_u, 3);
        // An empty config gains a calibration table.
        let fresh = crate::SensorConfig::from_toml_str(&update_config_toml("", 1.0, 2.0).unwrap()).unwrap();
        assert_eq!((fresh.calibration.a, fresh.calibration.b), (1.0, 2.0));
        assert!(update_config_toml("calibration = 3\n", 1.0, 2.0).is_err());
        assert!(update_config_toml("", f64::NAN, 2.0).is_err());
        assert!(
            update_config_toml("[surface]\ndegree_u = 99\n", 1.0, 2.0).is_err(),
            "an invalid config stays invalid"
        );
    }

    #[test]
    fn the_modulus_and_the_pad_map_are_written_beside_other_keys_and_read_back_exactly() {
        let text = "# bench sensor\n[elastic]\ngel_mm = 2.0\n";
        let updated = set_config_shear_modulus(text, 31.25).unwrap();
        let config = crate::SensorConfig::from_toml_str(&updated).unwrap();
        assert_eq!((config.elastic.shear_modulus_kpa, config.elastic.gel_mm), (31.25, 2.0));
        assert!(updated.contains("# bench sensor"), "{updated}");
        assert!(set_config_shear_modulus(text, 0.0).is_err());
        assert!(set_config_shear_modulus(text, f64::INFINITY).is_err());

        let map = crate::StoredPadMap {
            width: 1024,
            height: 768,
            correction: crate::pad_map::LensCorrection {
                centre_px: [511.5, 383.25],
                scale_px: 402.0,
                x: [1e-3, -2e-4, 3e-5, 0.0, 1.5e-6, -7e-7, 2e-8],
                y: [-1e-3, 2e-4, -3e-5, 4e-6, 0.0, 7e-7, -2e-8],
            },
            homography: [0.05, 1e-4, -25.0, -2e-4, 0.051, -19.0, 1e-6, -2e-6, 1.0],
            residual: crate::MapResidual {
                rms_mm: 0.011,
                max_mm: 0.04,
                points: 163,
                outliers: 2,
            },
        };
        let with_map = set_config_pad_map(&updated, &map).unwrap();
        let config = crate::SensorConfig::from_toml_str(&with_map).unwrap();
        assert_eq!(config.pad_map, Some(map), "{with_map}");
        assert_eq!(config.elastic.shear_modulus_kpa, 31.25);
        // Writing it again replaces the table rather than adding a second one.
        let moved = crate::StoredPadMap {
            homography: [0.06, 0.0, -20.0, 0.0, 0.06, -15.0, 0.0, 0.0, 1.0],
            ..map
        };
        let again = set_config_pad_map(&with_map, &moved).unwrap();
        assert_eq!(
            crate::SensorConfig::from_toml_str(&again).unwrap().pad_map,
            Some(moved),
            "{again}"
        );
        let shifted = set_config_push_centre_shift(&with_map, -0.76).unwrap();
        let config = crate::SensorConfig::from_toml_str(&shifted).unwrap();
        assert_eq!(config.elastic.push_centre_shift_mm, -0.76);
        assert_eq!((config.elastic.shear_modulus_kpa, config.elastic.gel_mm), (31.25, 2.0));
        assert!(shifted.contains("# bench sensor"), "{shifted}");
        assert!(set_config_push_centre_shift(text, f64::NAN).is_err());
        assert!(set_config_push_centre_shift(text, 12.0).is_err(), "the config's bound");
        let shared = set_config_push_normal_share(&shifted, 0.115).unwrap();
        let config = crate::SensorConfig::from_toml_str(&shared).unwrap();
        assert_eq!(config.elastic.push_normal_share, 0.115);
        assert_eq!(config.elastic.push_centre_shift_mm, -0.76, "the other keys are kept");
        assert!(shared.contains("# bench sensor"), "{shared}");
        assert!(set_config_push_normal_share(text, f64::INFINITY).is_err());
        assert!(set_config_push_normal_share(text, -1.5).is_err(), "the config's bound");
        let broken = crate::StoredPadMap { width: 0, ..map };
        assert!(set_config_pad_map(text, &broken).is_err());
    }
}
