//! How much of a contact's push its normal force reads as pressure (`elastic.push_normal_share`), fitted on pushes
//! whose normal force is known: fz - reference / scale = share |(fx, fy)|, with (fx, fy, fz) the model's force vector
//! and `scale` the normal force's calibration (reference N per model N), by least squares through the origin.
//!
//! The equivalent layer explains part of a skin-over-gel pad's shear response with pressure: that pressure moves the
//! contact's centre behind its push (`push_centre`) and adds to its normal force in proportion to the push.

use super::push_centre::{MIN_PUSHES, MIN_PUSH_RATIO};
use super::CalibrationError;

/// A contact's normal force with `share` of its push taken off: fz - share |(fx, fy)| for the model's force vector
/// (fx, fy before `tangential_force_scale`), never below 0.
pub fn corrected_normal_n([fx, fy, fz]: [f64; 3], share: f64) -> f64 {
    if share == 0.0 {
        return fz;
    }
    (fz - share * fx.hypot(fy)).max(0.0)
}

/// One push: the model's force vector (before `tangential_force_scale` and `push_normal_share`) and the reference's
/// normal force.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PushNormalSample {
    pub model_force_vector_n: [f64; 3],
    pub reference_normal_n: f64,
}

/// The share of a push read as normal force, for a normal force calibration of `normal_scale` reference N per model
/// N. Errors with fewer than [`MIN_PUSHES`] usable pushes (pushed by at least [`MIN_PUSH_RATIO`] of their model load,
/// everything finite) or a scale that is not finite and positive.
pub fn fit_push_normal_share(samples: &[PushNormalSample], normal_scale: f64) -> Result<f64, CalibrationError> {
    if !(normal_scale.is_finite() && normal_scale > 0.0) {
        return Err(CalibrationError::BadScale(normal_scale));
    }
    let used: Vec<(f64, f64)> = samples
        .iter()
        .filter(|s| s.model_force_vector_n.iter().all(|v| v.is_finite()) && s.reference_normal_n.is_finite())
        .filter_map(|s| {
            let [fx, fy, fz] = s.model_force_vector_n;
            let push = fx.hypot(fy);
            (fz > 0.0 && push >= MIN_PUSH_RATIO * fz).then(|| (push, fz - s.reference_normal_n / normal_scale))
        })
        .collect();
    if used.len() < MIN_PUSHES {
        return Err(CalibrationError::TooFewPushes {
            found: used.len(),
            needed: MIN_PUSHES,
        });
    }
    let (along, squares) = used.iter().fold((0.0, 0.0), |(a, q), (push, excess)| {
        (a + push * excess, q + push * push)
    });
    Ok(along / squares)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn push(force: [f64; 3], reference_normal_n: f64) -> PushNormalSample {
        PushNormalSample {
            model_force_vector_n: force,
            reference_normal_n,
        }
    }

    #[test]
    fn the_share_is_the_excess_normal_force_per_newton_of_push() {
        // Scale 2: a reference 8 N is 4 model N. Pushes of 2 and 1 model N read 0.24 and 0.12 N too much: 0.12 each.
        let samples = [
            push([2.0, 0.0, 4.24], 8.0),
            push([0.0, -1.0, 3.12], 6.0),
            // A plain press (no push) and a non-finite reading take no part.
            push([0.05, 0.0, 5.0], 8.0),
            push([1.0, 0.0, f64::NAN], 4.0),
        ];
        let share = fit_push_normal_share(&samples, 2.0).unwrap();
        assert!((share - 0.12).abs() < 1e-12, "{share}");
    }

    #[test]
    fn the_correction_takes_the_share_of_the_push_off_and_never_goes_below_zero() {
        assert!((corrected_normal_n([3.0, -4.0, 6.0], 0.1) - 5.5).abs() < 1e-12);
        assert_eq!(corrected_normal_n([3.0, -4.0, 6.0], 0.0), 6.0);
        assert_eq!(corrected_normal_n([30.0, -40.0, 6.0], 0.5), 0.0);
    }

    #[test]
    fn presses_without_a_push_or_a_bad_scale_fit_nothing() {
        let samples = [push([0.1, 0.0, 4.0], 8.0), push([2.0, 0.0, 4.0], 8.0)];
        assert_eq!(
            fit_push_normal_share(&samples, 2.0),
            Err(CalibrationError::TooFewPushes { found: 1, needed: 2 })
        );
        assert!(fit_push_normal_share(&samples, 0.0).is_err());
        assert!(fit_push_normal_share(&samples, f64::NAN).is_err());
    }
}
