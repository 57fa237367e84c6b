//! The reports' line fit and interpolation; mean, spread, median and correlation are `nusense_estimator::stats`.

use nusense_estimator::stats::mean;

/// Ordinary least-squares line y = slope * x + intercept.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Line {
    pub slope: f64,
    pub intercept: f64,
}

/// `None` below two points or when x does not vary.
pub fn least_squares(x: &[f64], y: &[f64]) -> Option<Line> {
    if x.len() != y.len() || x.len() < 2 {
        return None;
    }
    let (mx, my) = (mean(x)?, mean(y)?);
    let sxx: f64 = x.iter().map(|a| (a - mx).powi(2)).sum();
    if sxx <= 0.0 {
        return None;
    }
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let slope = sxy / sxx;
    Some(Line {
        slope,
        intercept: my - slope * mx,
    })
}

/// Linear interpolation in a series sorted by x; `None` outside it.
pub fn interpolate(series: &[(f64, f64)], x: f64) -> Option<f64> {
    let after = series.partition_point(|p| p.0 < x);
    if after == 0 {
        return series.first().filter(|p| p.0 == x).map(|p| p.1);
    }
    let (x0, y0) = series[after - 1];
    let &(x1, y1) = series.get(after)?;
    Some(if x1 > x0 {
        y0 + (y1 - y0) * (x - x0) / (x1 - x0)
    } else {
        0.5 * (y0 + y1)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_line_through_known_points_and_interpolation_inside_a_series() {
        let line = least_squares(&[0.0, 1.0, 2.0], &[1.0, 3.0, 5.0]).unwrap();
        assert!((line.slope - 2.0).abs() < 1e-12 && (line.intercept - 1.0).abs() < 1e-12);
        let series = [(0.0, 0.0), (1.0, 10.0), (3.0, 30.0)];
        assert_eq!(interpolate(&series, 2.0), Some(20.0));
        assert_eq!(interpolate(&series, 0.0), Some(0.0));
        assert_eq!(interpolate(&series, 3.5), None);
    }
}
