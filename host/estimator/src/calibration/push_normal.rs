//! How much of a contact's push its normal force reads as pressure (`elastic.push_normal_share`), fitted on pushes
//! whose normal force is known: fz - reference / scale = share (fx^2 + fy^2) / fz, with (fx, fy, fz) the model's force
//! vector and `scale` the normal force's calibration (reference N per model N), by least squares through the origin.
//!
//! The equivalent layer explains part of a skin-over-gel pad's shear response with pressure: that pressure moves the
//! contact's centre behind its push (`push_centre`) and adds to its normal force. What it adds grows with the push
//! over the load and with the push: on the validation sensor (5 mm spheres of 4 and 7 N at six places, pushed by 0.2
//! to 0.5 of their load in six directions, 640x480, each against the same press unpushed) 5, 10, 17 and 27 % of the
//! load at pushes of 0.2, 0.3, 0.4 and 0.5 of it: the square of the push over the load, where a share of the push
//! itself leaves 3-5 % too much at both ends.

use super::push_centre::{MIN_PUSHES, MIN_PUSH_RATIO};
use super::CalibrationError;

/// A contact's normal force less what its push adds: fz - share (fx^2 + fy^2) / fz for the model's force vector (fx,
/// fy before `tangential_force_scale`), never below 0; as it is without a normal force.
pub fn corrected_normal_n([fx, fy, fz]: [f64; 3], share: f64) -> f64 {
    if share == 0.0 || !(fz > 0.0) {
        return fz;
    }
    (fz - share * (fx * fx + fy * fy) / fz).max(0.0)
}

/// The normal force [`corrected_normal_n`] was given, from the one it returned with the same push and share (a
/// reading made with that share): the positive root of fz^2 - read fz - share push^2 = 0. Exact unless the correction
/// was cut at 0 (a push that large says nothing of its load).
pub fn uncorrected_normal_n(read_n: f64, push_n: f64, share: f64) -> f64 {
    if share == 0.0 || !(read_n > 0.0) {
        return read_n;
    }
    0.5 * (read_n + (read_n * read_n + 4.0 * share * push_n * push_n).sqrt())
}

/// One push: the model's force vector (before `tangential_force_scale` and `push_normal_share`) and the reference's
/// normal force.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PushNormalSample {
    pub model_force_vector_n: [f64; 3],
    pub reference_normal_n: f64,
}

/// Whether [`fit_push_normal_share`] uses a sample: pushed by [`MIN_PUSH_RATIO`] of its load or more, everything
/// finite.
pub fn is_push(sample: &PushNormalSample) -> bool {
    let [fx, fy, fz] = sample.model_force_vector_n;
    sample.model_force_vector_n.iter().all(|v| v.is_finite())
        && sample.reference_normal_n.is_finite()
        && fz > 0.0
        && fx.hypot(fy) >= MIN_PUSH_RATIO * fz
}

/// The share (see [`corrected_normal_n`]) for a normal force calibration of `normal_scale` reference N per model N.
/// Errors with fewer than [`MIN_PUSHES`] usable pushes (pushed by at least [`MIN_PUSH_RATIO`] of their model load,
/// everything finite) or a scale that is not finite and positive.
pub fn fit_push_normal_share(samples: &[PushNormalSample], normal_scale: f64) -> Result<f64, CalibrationError> {
    if !(normal_scale.is_finite() && normal_scale > 0.0) {
        return Err(CalibrationError::BadScale(normal_scale));
    }
    let used: Vec<(f64, f64)> = samples
        .iter()
        .filter(|s| is_push(s))
        .map(|s| {
            let [fx, fy, fz] = s.model_force_vector_n;
            let push = fx.hypot(fy);
            (push * push / fz, fz - s.reference_normal_n / normal_scale)
        })
        .collect();
    if used.len() < MIN_PUSHES {
        return Err(CalibrationError::TooFewPushes {
            found: used.len(),
            needed: MIN_PUSHES,
        });
    }
    let (along, squares) = used.iter().fold((0.0, 0.0), |(a, q), (shape, excess)| {
        (a + shape * excess, q + shape * shape)
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
    fn the_share_is_the_excess_normal_force_per_square_of_the_push_over_the_load() {
        // Scale 2: a reference 8 N is 4 model N. Pushes of 2 and 1 model N read as 4.15 and 3.05 model N: 0.15 and
        // 0.05 too much.
        let samples = [
            push([2.0, 0.0, 4.15], 8.0),
            push([0.0, -1.0, 3.05], 6.0),
            // A plain press (no push) and a non-finite reading take no part.
            push([0.05, 0.0, 5.0], 8.0),
            push([1.0, 0.0, f64::NAN], 4.0),
        ];
        let share = fit_push_normal_share(&samples, 2.0).unwrap();
        // Least squares through the origin of the excesses against push^2 / fz.
        let shapes = [4.0 / 4.15, 1.0 / 3.05];
        let expected = (shapes[0] * 0.15 + shapes[1] * 0.05) / (shapes[0] * shapes[0] + shapes[1] * shapes[1]);
        assert!((share - expected).abs() < 1e-12, "{share} against {expected}");
    }

    #[test]
    fn the_correction_takes_the_share_off_never_goes_below_zero_and_is_undone_exactly() {
        // A push of 5 on a load of 5: 0.1 * 25 / 5 = 0.5 off.
        assert!((corrected_normal_n([3.0, -4.0, 5.0], 0.1) - 4.5).abs() < 1e-12);
        assert_eq!(corrected_normal_n([3.0, -4.0, 6.0], 0.0), 6.0);
        assert_eq!(corrected_normal_n([30.0, -40.0, 6.0], 0.5), 0.0);
        assert_eq!(corrected_normal_n([3.0, -4.0, 0.0], 0.1), 0.0);
        for (force, share) in [
            ([3.0, -4.0, 5.0], 0.1),
            ([0.5, 0.2, 2.0], 0.19),
            ([1.0, 1.0, 3.0], -0.2),
        ] {
            let read = corrected_normal_n(force, share);
            let back = uncorrected_normal_n(read, force[0].hypot(force[1]), share);
            assert!((back - force[2]).abs() < 1e-12, "{force:?}, {share}: {back}");
        }
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
