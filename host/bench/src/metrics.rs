//! Error measures of the benchmark, each from pairs of truth and estimate. Empty input gives `None`.

use nusense_estimator::calibration::{fit_force_line, CalibrationSample, FitOptions};

/// Root mean square of the values.
pub fn rms(values: &[f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let value = (values.iter().map(|v| v * v).sum::<f64>() / values.len() as f64).sqrt();
    value.is_finite().then_some(value)
}

/// The `q`-quantile (0..=1) by linear interpolation; `None` for no finite samples.
pub fn quantile(samples: &[f64], q: f64) -> Option<f64> {
    nusense_estimator::stats::quantile(samples, q)
}

/// Distance between two points in the plane.
pub fn distance(a: [f64; 2], b: [f64; 2]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
}

/// Smallest difference between two undirected edge angles, degrees in [0, 90].
pub fn edge_angle_error_deg(found: f64, truth: f64) -> f64 {
    let difference = (found - truth).rem_euclid(180.0);
    difference.min(180.0 - difference)
}

/// Leave-one-out force error: for each sample, F = a * gamma + b is fitted (robustly, as `nusense calibrate`
/// does) to all the others and evaluated at the left-out gamma. Returns the prediction errors in N; samples
/// whose fit fails (fewer than three distinct others) are skipped.
pub fn leave_one_out_force_errors(samples: &[CalibrationSample]) -> Vec<f64> {
    let options = FitOptions::default();
    (0..samples.len())
        .filter_map(|left_out| {
            let others: Vec<CalibrationSample> = samples
                .iter()
                .enumerate()
                .filter(|(i, _)| *i != left_out)
                .map(|(_, s)| *s)
                .collect();
            let fit = fit_force_line(&others, &options).ok()?;
            let sample = samples[left_out];
            let predicted = fit.a * sample.gamma + fit.b;
            predicted.is_finite().then_some(predicted - sample.force_n)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn edge_angles_wrap_at_180_degrees() {
        assert_eq!(edge_angle_error_deg(179.0, 1.0), 2.0);
        assert_eq!(edge_angle_error_deg(10.0, 100.0), 90.0);
        assert_eq!(edge_angle_error_deg(45.0, 40.0), 5.0);
    }

    #[test]
    fn leave_one_out_on_a_perfect_line_is_exact_and_sees_an_outlier() {
        let mut samples: Vec<CalibrationSample> = (1..=8)
            .map(|k| CalibrationSample {
                gamma: f64::from(k),
                force_n: 3.0 * f64::from(k) - 1.0,
            })
            .collect();
        let errors = leave_one_out_force_errors(&samples);
        assert_eq!(errors.len(), 8);
        assert!(errors.iter().all(|e| e.abs() < 1e-6), "{errors:?}");
        samples[3].force_n += 5.0;
        let errors = leave_one_out_force_errors(&samples);
        assert!(
            (errors[3].abs() - 5.0).abs() < 1e-6,
            "the left-out outlier is predicted from the line: {errors:?}"
        );
        assert_eq!(rms(&[3.0, 4.0]), Some((12.5f64).sqrt()));
        assert_eq!(rms(&[]), None);
    }
}
