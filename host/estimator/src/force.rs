//! Normal force from gamma through the sensor's linear calibration F = a * gamma + b.
//!
//! Without contact the sensor carries no load, so the reported force is 0 N; the calibration line's own value
//! (b is negative, so it is below zero near gamma = 0) stays visible as `force_model_n`. With contact the line's
//! value is reported as it is, even if negative (outside the calibrated range): nothing is clamped silently.

use crate::config::ForceCalibration;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForceReading {
    /// The reported force, N.
    pub force_n: f64,
    /// a * gamma + b, N, whether or not there is contact.
    pub model_n: f64,
}

pub fn force(calibration: &ForceCalibration, gamma: f64, contact: bool) -> ForceReading {
    let model_n = calibration.a * gamma + calibration.b;
    ForceReading { force_n: if contact { model_n } else { 0.0 }, model_n }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn follows_the_calibration_line_only_in_contact() {
        let c = ForceCalibration::default();
        let f = force(&c, 2.0, true);
        assert!((f.force_n - (3.09 * 2.0 - 1.14)).abs() < 1e-12);
        let none = force(&c, 0.01, false);
        assert_eq!(none.force_n, 0.0);
        assert!(none.model_n < 0.0);
    }
}
