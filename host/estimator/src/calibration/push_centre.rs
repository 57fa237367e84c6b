//! How far a pushed contact's pressure centre reads behind its push (`elastic.push_centre_shift_mm`), fitted on
//! pushes whose true place is known: true - read = k (fx, fy) / fz, with (fx, fy, fz) the model's force vector, by
//! least squares through the origin.

use nusense_geometry::{PadGeometry, Point2};

use super::CalibrationError;

/// Pushes whose model tangential force is less than this share of their normal force say nothing about the shift
/// (a normal press reads up to about 5 % of its load as shear in the model).
pub const MIN_PUSH_RATIO: f64 = 0.1;
/// Fewest pushes the shift is fitted on.
pub const MIN_PUSHES: usize = 2;

/// The most a contact's centre is moved (`elastic.push_centre_shift_mm`): one cell pitch (the smaller) of `pad`.
pub fn most_shift_mm(pad: &PadGeometry) -> f64 {
    pad.pitch_x_mm().min(pad.pitch_y_mm())
}

/// A contact's centre moved along its push by `shift_mm` per unit of push over load (the model's (fx, fy) / fz: see
/// `ElasticConfig::push_centre_shift_mm`), by at most `most_mm`; as it was without a normal force.
pub fn shifted_centre(centre_mm: Point2, [fx, fy, fz]: [f64; 3], shift_mm: f64, most_mm: f64) -> Point2 {
    if shift_mm == 0.0 || !(fz > 0.0) {
        return centre_mm;
    }
    let moved = [shift_mm * fx / fz, shift_mm * fy / fz];
    let length = moved[0].hypot(moved[1]);
    let keep = if length > most_mm { most_mm / length } else { 1.0 };
    [centre_mm[0] + keep * moved[0], centre_mm[1] + keep * moved[1]]
}

/// The centre [`shifted_centre`] was given, from the centre it returned with the same force, shift and bound: the
/// move depends on those alone, so this is exact (to rounding) whether or not the bound cut the move short.
pub fn unshifted_centre(shifted_mm: Point2, force_vector_n: [f64; 3], shift_mm: f64, most_mm: f64) -> Point2 {
    let moved = shifted_centre([0.0, 0.0], force_vector_n, shift_mm, most_mm);
    [shifted_mm[0] - moved[0], shifted_mm[1] - moved[1]]
}

/// One push: the model's force vector (before `tangential_force_scale`), where its contact was read and where it was.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PushCentreSample {
    pub model_force_vector_n: [f64; 3],
    pub read_centre_mm: Point2,
    pub true_centre_mm: Point2,
}

/// The shift in mm per unit of push over load. Errors with fewer than [`MIN_PUSHES`] usable pushes (at least
/// [`MIN_PUSH_RATIO`], everything finite).
pub fn fit_push_centre_shift(samples: &[PushCentreSample]) -> Result<f64, CalibrationError> {
    let used: Vec<([f64; 2], [f64; 2])> = samples
        .iter()
        .filter(|s| {
            s.model_force_vector_n
                .iter()
                .chain(&s.read_centre_mm)
                .chain(&s.true_centre_mm)
                .all(|v| v.is_finite())
        })
        .filter_map(|s| {
            let [fx, fy, fz] = s.model_force_vector_n;
            let ratio = [fx / fz, fy / fz];
            (fz > 0.0 && ratio[0].hypot(ratio[1]) >= MIN_PUSH_RATIO).then(|| {
                let offset = [
                    s.true_centre_mm[0] - s.read_centre_mm[0],
                    s.true_centre_mm[1] - s.read_centre_mm[1],
                ];
                (ratio, offset)
            })
        })
        .collect();
    if used.len() < MIN_PUSHES {
        return Err(CalibrationError::TooFewPushes {
            found: used.len(),
            needed: MIN_PUSHES,
        });
    }
    let (along, squares) = used.iter().fold((0.0, 0.0), |(a, q), (r, o)| {
        (a + r[0] * o[0] + r[1] * o[1], q + r[0] * r[0] + r[1] * r[1])
    });
    Ok(along / squares)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn push(force: [f64; 3], read: Point2, truth: Point2) -> PushCentreSample {
        PushCentreSample {
            model_force_vector_n: force,
            read_centre_mm: read,
            true_centre_mm: truth,
        }
    }

    #[test]
    fn the_shift_is_the_offset_along_the_push_per_unit_of_push_over_load() {
        // Read 1.5 mm behind a push of half the load, and 0.6 mm behind one of a fifth: 3 mm per unit either way.
        let samples = [
            push([2.0, 0.0, 4.0], [8.5, 1.0], [10.0, 1.0]),
            push([0.0, -1.0, 5.0], [-3.0, 2.6], [-3.0, 2.0]),
            // A plain press (no push) and a non-finite reading take no part.
            push([0.05, 0.0, 6.0], [0.0, 0.0], [3.0, 0.0]),
            push([1.0, 0.0, f64::NAN], [0.0, 0.0], [3.0, 0.0]),
        ];
        let shift = fit_push_centre_shift(&samples).unwrap();
        assert!((shift - 3.0).abs() < 1e-12, "{shift}");
    }

    #[test]
    fn the_centre_moves_along_the_push_by_at_most_the_bound() {
        assert_eq!(shifted_centre([1.0, 2.0], [1.0, -2.0, 4.0], 2.0, 3.0), [1.5, 1.0]);
        // 4 mm asked, 2 allowed: the same direction, 2 mm.
        assert_eq!(shifted_centre([0.0, 0.0], [4.0, 0.0, 2.0], 2.0, 2.0), [2.0, 0.0]);
        assert_eq!(shifted_centre([1.0, 2.0], [1.0, 0.0, 0.0], 2.0, 3.0), [1.0, 2.0]);
    }

    #[test]
    fn unshifting_takes_the_centre_back_whether_or_not_the_bound_applied() {
        for (centre, force, shift, most) in [
            ([1.0, 2.0], [1.0, -2.0, 4.0], 2.0, 3.0),
            // Cut short by the bound: 4 mm asked, 2 allowed.
            ([-3.0, 0.5], [4.0, 0.0, 2.0], 2.0, 2.0),
            ([0.5, -7.0], [-1.5, 0.8, 3.0], -0.76, 3.0),
            ([1.0, 2.0], [1.0, 0.0, 0.0], 2.0, 3.0),
        ] {
            let back = unshifted_centre(shifted_centre(centre, force, shift, most), force, shift, most);
            assert!(
                (back[0] - centre[0]).abs() < 1e-12 && (back[1] - centre[1]).abs() < 1e-12,
                "{centre:?} -> {back:?}"
            );
        }
        assert_eq!(unshifted_centre([1.5, 1.0], [1.0, -2.0, 4.0], 2.0, 3.0), [1.0, 2.0]);
    }

    #[test]
    fn presses_without_a_push_fit_nothing() {
        let samples = [
            push([0.1, 0.0, 4.0], [0.5, 0.0], [0.0, 0.0]),
            push([2.0, 0.0, 4.0], [8.5, 1.0], [10.0, 1.0]),
        ];
        assert_eq!(
            fit_push_centre_shift(&samples),
            Err(CalibrationError::TooFewPushes { found: 1, needed: 2 })
        );
    }
}
