//! Small statistics over measured samples (hil checks, benchmarks, the experiments' reports): percentiles, mean and
//! spread, correlation.
//! Empty or degenerate input gives `None`, never NaN.

/// The `q`-quantile (0..=1) by linear interpolation between order statistics; `None` for no samples.
pub fn quantile(samples: &[f64], q: f64) -> Option<f64> {
    let mut sorted: Vec<f64> = samples.iter().copied().filter(|v| v.is_finite()).collect();
    if sorted.is_empty() || !q.is_finite() {
        return None;
    }
    sorted.sort_by(f64::total_cmp);
    let position = q.clamp(0.0, 1.0) * (sorted.len() - 1) as f64;
    let below = position.floor() as usize;
    let above = position.ceil() as usize;
    let fraction = position - below as f64;
    Some(sorted[below] + (sorted[above] - sorted[below]) * fraction)
}

pub fn mean(samples: &[f64]) -> Option<f64> {
    if samples.is_empty() {
        return None;
    }
    let value = samples.iter().sum::<f64>() / samples.len() as f64;
    value.is_finite().then_some(value)
}

/// Population standard deviation.
pub fn std_dev(samples: &[f64]) -> Option<f64> {
    let centre = mean(samples)?;
    let variance = samples.iter().map(|v| (v - centre).powi(2)).sum::<f64>() / samples.len() as f64;
    let value = variance.sqrt();
    value.is_finite().then_some(value)
}

/// Sample standard deviation (n - 1: the spread of the population the samples come from); `None` below two.
pub fn sample_std_dev(samples: &[f64]) -> Option<f64> {
    if samples.len() < 2 {
        return None;
    }
    let centre = mean(samples)?;
    let variance = samples.iter().map(|v| (v - centre).powi(2)).sum::<f64>() / (samples.len() - 1) as f64;
    let value = variance.sqrt();
    value.is_finite().then_some(value)
}

/// Pearson correlation of paired samples; `None` when either side has no spread.
pub fn pearson(x: &[f64], y: &[f64]) -> Option<f64> {
    if x.len() != y.len() || x.len() < 2 {
        return None;
    }
    let (mx, my) = (mean(x)?, mean(y)?);
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (a, b) in x.iter().zip(y) {
        sxy += (a - mx) * (b - my);
        sxx += (a - mx).powi(2);
        syy += (b - my).powi(2);
    }
    let denominator = (sxx * syy).sqrt();
    if denominator <= f64::EPSILON {
        return None;
    }
    let value = sxy / denominator;
    value.is_finite().then_some(value)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_interpolate_between_order_statistics() {
        let samples = [4.0, 1.0, 3.0, 2.0, 5.0];
        assert_eq!(quantile(&samples, 0.5), Some(3.0));
        assert_eq!(quantile(&samples, 0.0), Some(1.0));
        assert_eq!(quantile(&samples, 1.0), Some(5.0));
        assert_eq!(quantile(&samples, 0.25), Some(2.0));
        assert_eq!(quantile(&[1.0, 2.0], 0.5), Some(1.5));
        assert_eq!(quantile(&[], 0.5), None);
    }

    #[test]
    fn spread_and_correlation() {
        assert_eq!(std_dev(&[2.0, 4.0, 4.0, 4.0, 5.0, 5.0, 7.0, 9.0]), Some(2.0));
        let sample = sample_std_dev(&[2.0, 4.0, 4.0, 4.0, 5.0, 5.0, 7.0, 9.0]).unwrap();
        assert!((sample - (32.0f64 / 7.0).sqrt()).abs() < 1e-12);
        assert_eq!(sample_std_dev(&[3.0]), None);
        let x = [1.0, 2.0, 3.0, 4.0];
        let y = [2.0, 4.1, 5.9, 8.0];
        assert!(pearson(&x, &y).unwrap() > 0.99);
        let falling = [8.0, 6.0, 4.0, 2.0];
        assert!(pearson(&x, &falling).unwrap() < -0.99);
        assert_eq!(pearson(&x, &[1.0, 1.0, 1.0, 1.0]), None);
        assert_eq!(pearson(&x, &[1.0]), None);
    }
}
