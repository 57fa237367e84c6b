//! Normal force from gamma through the sensor's linear calibration F = a * gamma + b (the paper's line; modes `fast`
//! and `paper`).
//!
//! The line's value is always reported as `force_model_n`. As a force it only counts with contact and above the
//! detection floor: b is negative, so for light presses the line goes below zero, and a force is never negative
//! (see `Estimator::line_touch`).

use crate::config::ForceCalibration;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForceReading {
    /// a * gamma + b, N.
    pub model_n: f64,
}

pub fn force(calibration: &ForceCalibration, gamma: f64) -> ForceReading {
    ForceReading {
        model_n: calibration.a * gamma + calibration.b,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn follows_the_calibration_line() {
        let c = ForceCalibration::default();
        assert!((force(&c, 2.0).model_n - (3.09 * 2.0 - 1.14)).abs() < 1e-12);
        assert!(force(&c, 0.01).model_n < 0.0);
    }
}
