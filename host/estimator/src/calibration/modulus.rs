//! The pad model's stiffness from a force/torque log: F_reference = s * F_model, and the gel's shear modulus
//! becomes s * G.
//!
//! The traction inverse turns displacements into tractions through the layer's compliance, which is inversely
//! proportional to the shear modulus; with the regularisation weak against the data (a press well above the
//! detection floor) the model's force is proportional to G, so one scale through the origin is the whole
//! calibration. The fit is the same MM recipe as the force line's ([`super::fit_force_line`]): a median-of-ratios
//! start, its residual scale, then Tukey-bisquare reweighting; the interval is the M-estimator's sandwich with
//! Student's t on n - 1 degrees of freedom.

use super::{bisquare_psi_prime, bisquare_weight, median, robust_scale, student_t_quantile, CalibrationError};

/// One pair: the model's normal force (the traction inverse's fz, N) and the reference force at the same time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelForceSample {
    pub model_n: f64,
    pub reference_n: f64,
}

/// The fitted scale with its uncertainty.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModulusFit {
    /// Reference force / model force: the factor the config's shear modulus is multiplied by.
    pub scale: f64,
    pub scale_interval: [f64; 2],
    pub scale_std_error: f64,
    pub confidence: f64,
    /// Robust standard deviation of the residuals F_reference - s F_model, N.
    pub residual_scale_n: f64,
    pub points: usize,
    /// Points with weight zero in the final fit.
    pub outliers: usize,
}

/// Model forces below this are not used: without contact the model reads 0 N, and a ratio against 0 says nothing
/// about the stiffness.
pub const MIN_MODEL_FORCE_N: f64 = 0.05;

/// Fits F_reference = s * F_model robustly (see the module notes).
pub fn fit_modulus_scale(
    samples: &[ModelForceSample],
    bisquare_c: f64,
    confidence: f64,
) -> Result<ModulusFit, CalibrationError> {
    if !(confidence > 0.0 && confidence < 1.0) {
        return Err(CalibrationError::BadConfidence(confidence));
    }
    if let Some((index, s)) = samples
        .iter()
        .enumerate()
        .find(|(_, s)| !(s.model_n.is_finite() && s.reference_n.is_finite()))
    {
        return Err(CalibrationError::NotFinite {
            index,
            gamma: s.model_n,
            force_n: s.reference_n,
        });
    }
    let used: Vec<ModelForceSample> = samples
        .iter()
        .copied()
        .filter(|s| s.model_n >= MIN_MODEL_FORCE_N)
        .collect();
    const NEEDED: usize = 2;
    if used.len() < NEEDED {
        return Err(CalibrationError::TooFewPoints {
            found: used.len(),
            needed: NEEDED,
        });
    }
    let x: Vec<f64> = used.iter().map(|s| s.model_n).collect();
    let y: Vec<f64> = used.iter().map(|s| s.reference_n).collect();
    let mut ratios: Vec<f64> = x.iter().zip(&y).map(|(xi, yi)| yi / xi).collect();
    let mut scale_fit = median(&mut ratios);
    let residuals = |s: f64| -> Vec<f64> { x.iter().zip(&y).map(|(&xi, &yi)| yi - s * xi).collect() };
    let sigma = robust_scale(&residuals(scale_fit));
    let c = if bisquare_c > 0.0 && bisquare_c.is_finite() {
        bisquare_c
    } else {
        4.685
    };
    if sigma > 0.0 {
        for _ in 0..200 {
            let weights: Vec<f64> = residuals(scale_fit)
                .iter()
                .map(|r| bisquare_weight(r / sigma, c))
                .collect();
            let sxx: f64 = x.iter().zip(&weights).map(|(xi, w)| w * xi * xi).sum();
            if !(sxx > 0.0) {
                break;
            }
            let next = x
                .iter()
                .zip(&y)
                .zip(&weights)
                .map(|((xi, yi), w)| w * xi * yi)
                .sum::<f64>()
                / sxx;
            let converged = (next - scale_fit).abs() <= 1e-12 * (1.0 + scale_fit.abs());
            scale_fit = next;
            if converged {
                break;
            }
        }
    }
    if !(scale_fit.is_finite() && scale_fit > 0.0) {
        return Err(CalibrationError::Config(format!(
            "the reference forces do not grow with the model's (scale {scale_fit}): check the force log's axis and sign"
        )));
    }
    let final_residuals = residuals(scale_fit);
    let std_error = sandwich_std_error(&x, &final_residuals, sigma, c);
    let n = x.len();
    let t = student_t_quantile(0.5 + confidence / 2.0, (n - 1) as f64);
    let outliers = if sigma > 0.0 {
        final_residuals.iter().filter(|r| r.abs() >= c * sigma).count()
    } else {
        final_residuals.iter().filter(|r| **r != 0.0).count()
    };
    Ok(ModulusFit {
        scale: scale_fit,
        scale_interval: [scale_fit - t * std_error, scale_fit + t * std_error],
        scale_std_error: std_error,
        confidence,
        residual_scale_n: sigma,
        points: n,
        outliers,
    })
}

/// Pushes lighter than this (reference tangential force, N) are not used for the tangential scale: a normal press
/// alone reads up to about 0.3 N of tangential force in the model (5 % of its load, the quick validation set's
/// presses), which against a reference near 0 says nothing about the shear stiffness.
pub const MIN_REFERENCE_TANGENTIAL_N: f64 = 0.5;

/// Fits F_reference,t = s * F_model,t on the tangential force's size (sqrt(fx^2 + fy^2): the F/T sensor's axes in
/// the pad's plane need not be the pad's), on the readings whose reference push is at least
/// [`MIN_REFERENCE_TANGENTIAL_N`]; the same robust fit through the origin as [`fit_modulus_scale`]'s. The model's
/// tangential force is proportional to the shear stiffness it assumes, as its normal force is to the modulus, so
/// one scale is the whole calibration (`elastic.tangential_force_scale`).
pub fn fit_tangential_scale(
    samples: &[ModelForceSample],
    bisquare_c: f64,
    confidence: f64,
) -> Result<ModulusFit, CalibrationError> {
    let pushes: Vec<ModelForceSample> = samples
        .iter()
        .copied()
        .filter(|s| !(s.reference_n < MIN_REFERENCE_TANGENTIAL_N))
        .collect();
    fit_modulus_scale(&pushes, bisquare_c, confidence)
}

/// Twists lighter than this (reference torque about the normal, N mm) are not used for the torque scale: presses and
/// pushes read up to about 1.1 N mm of torque in the model (the quick validation set's, before any scale), which
/// against a reference near 0 says nothing about the pad's torsional stiffness.
pub const MIN_REFERENCE_TORQUE_NMM: f64 = 2.0;

/// One twist: the size of the model's torque about the normal and of the reference's at the same time, N mm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelTorqueSample {
    pub model_nmm: f64,
    pub reference_nmm: f64,
}

/// Fits |M_reference| = s |M_model| on the torque about the normal (sizes: an F/T sensor's z axis may point either
/// way), on the readings whose reference torque is at least [`MIN_REFERENCE_TORQUE_NMM`]; the same robust fit through
/// the origin as [`fit_modulus_scale`]'s, its residual scale in N mm. The model's twist and push are not off by one
/// factor, so the torque has a scale of its own (`elastic.torque_scale`).
pub fn fit_torque_scale(
    samples: &[ModelTorqueSample],
    bisquare_c: f64,
    confidence: f64,
) -> Result<ModulusFit, CalibrationError> {
    let twists: Vec<ModelForceSample> = samples
        .iter()
        .filter(|s| !(s.reference_nmm.abs() < MIN_REFERENCE_TORQUE_NMM))
        .map(|s| ModelForceSample {
            model_n: s.model_nmm.abs(),
            reference_n: s.reference_nmm.abs(),
        })
        .collect();
    fit_modulus_scale(&twists, bisquare_c, confidence)
}

/// Standard error of a one-parameter M-estimator through the origin: K^2 [sum psi^2 / (n - 1)] / mean(psi')^2
/// sigma^2 / sum x^2, Huber's correction K as in the force line's.
fn sandwich_std_error(x: &[f64], residuals: &[f64], sigma: f64, c: f64) -> f64 {
    let n = x.len() as f64;
    let sxx: f64 = x.iter().map(|v| v * v).sum();
    if !(sigma > 0.0) || n <= 1.0 || !(sxx > 0.0) {
        return 0.0;
    }
    let u: Vec<f64> = residuals.iter().map(|r| r / sigma).collect();
    let psi_sq_sum: f64 = u.iter().map(|&v| (v * bisquare_weight(v, c)).powi(2)).sum();
    let psi_prime: Vec<f64> = u.iter().map(|&v| bisquare_psi_prime(v, c)).collect();
    let m = psi_prime.iter().sum::<f64>() / n;
    let variance = if m > 0.0 {
        let var_psi_prime = psi_prime.iter().map(|v| (v - m).powi(2)).sum::<f64>() / n;
        let correction = 1.0 + var_psi_prime / (n * m * m);
        correction * correction * (psi_sq_sum / (n - 1.0)) / (m * m) * sigma * sigma / sxx
    } else {
        residuals.iter().map(|r| r * r).sum::<f64>() / (n - 1.0) / sxx
    };
    variance.max(0.0).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn samples(scale: f64, wiggle: f64) -> Vec<ModelForceSample> {
        (0..40)
            .map(|i| {
                let model_n = 0.5 + 0.2 * f64::from(i);
                let noise = wiggle * (f64::from(i) * 2.399).sin();
                ModelForceSample {
                    model_n,
                    reference_n: scale * model_n + noise,
                }
            })
            .collect()
    }

    #[test]
    fn recovers_the_scale_and_brackets_it() {
        let fit = fit_modulus_scale(&samples(0.62, 0.05), 4.685, 0.95).unwrap();
        assert!((fit.scale - 0.62).abs() < 0.005, "{fit:?}");
        assert!(fit.scale_interval[0] < 0.62 && 0.62 < fit.scale_interval[1], "{fit:?}");
        assert_eq!(fit.points, 40);
        assert_eq!(fit.outliers, 0);
    }

    /// A session of normal presses with a few pushes: the presses' own small model shear (no reference push) must
    /// not pull the scale towards 0.
    #[test]
    fn the_tangential_scale_is_fitted_on_the_pushes_alone() {
        let pushes: Vec<ModelForceSample> = (0..6)
            .map(|i| {
                let model_n = 1.5 + 0.4 * f64::from(i);
                ModelForceSample {
                    model_n,
                    reference_n: 0.58 * model_n,
                }
            })
            .collect();
        let mut session: Vec<ModelForceSample> = (0..30)
            .map(|i| ModelForceSample {
                model_n: 0.1 + 0.01 * f64::from(i),
                reference_n: 0.02,
            })
            .collect();
        session.extend(&pushes);
        let fit = fit_tangential_scale(&session, 4.685, 0.95).unwrap();
        assert_eq!(fit.points, 6, "{fit:?}");
        assert!((fit.scale - 0.58).abs() < 1e-9, "{fit:?}");
        assert_eq!(
            fit_tangential_scale(&session[..30], 4.685, 0.95).unwrap_err(),
            CalibrationError::TooFewPoints { found: 0, needed: 2 }
        );
    }

    /// Twists whose F/T sensor reads the torque with the opposite sign, among presses and pushes whose model torque is
    /// small: the scale is fitted on the twists' sizes alone.
    #[test]
    fn the_torque_scale_is_fitted_on_the_twists_alone_whatever_their_sign() {
        let twists = (0..6).map(|i| {
            let model_nmm = if i % 2 == 0 { 1.0 } else { -1.0 } * (8.0 + 5.0 * f64::from(i));
            ModelTorqueSample {
                model_nmm,
                reference_nmm: -0.57 * model_nmm,
            }
        });
        let mut session: Vec<ModelTorqueSample> = (0..30)
            .map(|i| ModelTorqueSample {
                model_nmm: 0.05 * f64::from(i),
                reference_nmm: 0.1,
            })
            .collect();
        session.extend(twists);
        let fit = fit_torque_scale(&session, 4.685, 0.95).unwrap();
        assert_eq!(fit.points, 6, "{fit:?}");
        assert!((fit.scale - 0.57).abs() < 1e-9, "{fit:?}");
        assert_eq!(
            fit_torque_scale(&session[..30], 4.685, 0.95).unwrap_err(),
            CalibrationError::TooFewPoints { found: 0, needed: 2 }
        );
    }

    #[test]
    fn a_slipped_reading_gets_no_weight() {
        let mut data = samples(1.7, 0.03);
        data[25].reference_n = 0.1; // the probe slipped off during this frame
        let fit = fit_modulus_scale(&data, 4.685, 0.95).unwrap();
        assert!((fit.scale - 1.7).abs() < 0.005, "{fit:?}");
        assert_eq!(fit.outliers, 1);
    }

    #[test]
    fn readings_without_contact_are_left_out_and_too_few_is_an_error() {
        let mut data = samples(0.9, 0.0);
        data.extend((0..100).map(|_| ModelForceSample {
            model_n: 0.0,
            reference_n: 0.02,
        }));
        let fit = fit_modulus_scale(&data, 4.685, 0.95).unwrap();
        assert_eq!(fit.points, 40);
        assert!((fit.scale - 0.9).abs() < 1e-9, "{fit:?}");
        let few = [
            ModelForceSample {
                model_n: 1.0,
                reference_n: 1.0,
            },
            ModelForceSample {
                model_n: 0.0,
                reference_n: 0.0,
            },
        ];
        assert_eq!(
            fit_modulus_scale(&few, 4.685, 0.95).unwrap_err(),
            CalibrationError::TooFewPoints { found: 1, needed: 2 }
        );
    }

    #[test]
    fn a_reversed_axis_is_refused_with_a_reason() {
        let data: Vec<ModelForceSample> = samples(1.0, 0.0)
            .into_iter()
            .map(|s| ModelForceSample {
                reference_n: -s.reference_n,
                ..s
            })
            .collect();
        let err = fit_modulus_scale(&data, 4.685, 0.95).unwrap_err();
        assert!(err.to_string().contains("axis and sign"), "{err}");
    }

    #[test]
    fn non_finite_input_is_named() {
        let data = [ModelForceSample {
            model_n: f64::NAN,
            reference_n: 1.0,
        }];
        assert!(matches!(
            fit_modulus_scale(&data, 4.685, 0.95),
            Err(CalibrationError::NotFinite { index: 0, .. })
        ));
    }
}
