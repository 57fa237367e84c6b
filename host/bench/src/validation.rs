//! Issue 12's figures, for every estimator mode, on the validation set (`nusense_sim::validation`): frames from a
//! sensor that shares none of the estimator's assumptions.
//!
//! Readings are scored through their JSON form (the `analyze --json` contract), field by field: a mode that does
//! not report a field (today: `force_vector_n`, `contacts`, `camera_motion`, `torque_nmm`) gets "–" for the
//! figures that need it, and the figures light up as soon as the estimator's `Reading` carries the field.

use std::time::Instant;

use image::RgbImage;
use nusense_estimator::calibration::modulus::{
    fit_tangential_scale, fit_torque_scale, ModelForceSample, ModelTorqueSample,
};
use nusense_estimator::calibration::push_centre::{
    fit_push_centre_shift, most_shift_mm, shifted_centre, PushCentreSample,
};
use nusense_estimator::calibration::push_normal::{corrected_normal_n, fit_push_normal_share, PushNormalSample};
use nusense_estimator::calibration::{fit_force_line, CalibrationSample, FitOptions};
use nusense_estimator::{Estimator, Mode, SensorConfig};
use nusense_sim::validation::{CaseKind, CaseTruth, Profile, ValidationRenderer, ValidationSet, FLOOR_FORCES_N};
use nusense_sim::ContactTruth;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::metrics::{distance, edge_angle_error_deg, quantile, rms};
use crate::BenchError;

/// Every mode the estimator offers. The match is exhaustive on purpose: a new `Mode` does not compile here until
/// it is listed, so no mode can miss the table.
pub fn estimator_modes() -> Vec<Mode> {
    let modes = vec![Mode::Fast, Mode::Paper, Mode::Inverse];
    for mode in &modes {
        match mode {
            Mode::Fast | Mode::Paper | Mode::Inverse => {}
        }
    }
    modes
}

/// A detection level counts as reliable at this rate (and so must every heavier level).
pub const RELIABLE_DETECTION: f64 = 0.9;
/// Two contacts are "both listed" when each true centre has its own reported contact this close.
pub const TWO_CONTACT_MATCH_MM: f64 = 3.0;
/// ... and each contact's force is within this fraction of the truth.
pub const TWO_CONTACT_FORCE_TOLERANCE: f64 = 0.2;

#[derive(Clone, Debug, Default, Deserialize)]
struct ObservedContact {
    centre_mm: Option<[f64; 2]>,
    force_n: Option<f64>,
    force_vector_n: Option<[f64; 3]>,
}

#[derive(Clone, Debug, Default, Deserialize)]
struct ObservedMotion {
    rotation_deg: Option<f64>,
}

/// What a reading says, read leniently from its JSON so that fields appear as the estimator gains them.
#[derive(Clone, Debug, Default)]
struct Observed {
    contact: bool,
    contact_mm: Option<[f64; 2]>,
    gamma: Option<f64>,
    force_vector_n: Option<[f64; 3]>,
    torque_nmm: Option<f64>,
    contacts: Option<Vec<ObservedContact>>,
    camera_motion: Option<ObservedMotion>,
    edge_angle_deg: Option<f64>,
}

fn field<T: DeserializeOwned>(value: &serde_json::Value, name: &str) -> Option<T> {
    value.get(name).cloned().and_then(|v| serde_json::from_value(v).ok())
}

impl Observed {
    #[cfg(test)]
    fn of(reading: &impl Serialize) -> Self {
        serde_json::to_value(reading).map_or_else(|_| Self::default(), |value| Self::of_value(&value))
    }

    fn of_value(value: &serde_json::Value) -> Self {
        let contacts: Option<Vec<ObservedContact>> = field(value, "contacts");
        let contact_mm: Option<[f64; 2]> = field(value, "contact_mm");
        // `contact` is a flag today and may become the contact itself: either way, present and not false/null.
        let flagged = match value.get("contact") {
            Some(serde_json::Value::Bool(b)) => *b,
            Some(serde_json::Value::Null) | None => false,
            Some(_) => true,
        };
        Self {
            contact: flagged || contacts.as_ref().is_some_and(|c| !c.is_empty()),
            contact_mm,
            gamma: field(value, "gamma"),
            force_vector_n: field(value, "force_vector_n"),
            torque_nmm: field(value, "torque_nmm"),
            contacts,
            camera_motion: field(value, "camera_motion"),
            edge_angle_deg: field(value, "edge_angle_deg"),
        }
    }
}

/// One mode's figures on the validation set.
#[derive(Clone, Debug, Serialize)]
pub struct ModeFigures {
    pub mode: Mode,
    /// Frames measured and frames refused with a typed error.
    pub frames: usize,
    pub refused: usize,
    pub median_ms: Option<f64>,
    pub p99_ms: Option<f64>,
    /// Baseline median over this mode's, both on the validation frames of this run.
    pub speedup: Option<f64>,
    /// How force is calibrated: "scale" (N from the model, one factor) or "gamma line" (F = a gamma + b).
    pub calibration: Option<String>,
    pub localisation_rmse_mm: Option<f64>,
    pub localisation_misses: usize,
    pub localisation_frames: usize,
    /// RMS force error on 1-8 N presses over the whole pad (missed presses count as 0 N), one calibration.
    pub force_rms_n: Option<f64>,
    /// The same with the camera-motion presses (rotation up to 5 degrees) included.
    pub force_rms_with_motion_n: Option<f64>,
    /// Smallest force from which every lighter-to-heavier level is detected at least RELIABLE_DETECTION of the time.
    pub detection_floor_n: Option<f64>,
    /// Detection rate per floor force (FLOOR_FORCES_N).
    pub detection_rates: Vec<(f64, f64)>,
    /// The same for long contacts: 20 x 1 mm edges at 0, 45, 90 and 135 degrees (the `edge_floor` cases).
    pub edge_detection_floor_n: Option<f64>,
    pub edge_detection_rates: Vec<(f64, f64)>,
    pub false_contacts: usize,
    pub rest_frames: usize,
    pub edge_mae_deg: Option<f64>,
    pub edge_max_deg: Option<f64>,
    pub edge_misses: usize,
    pub edge_frames: usize,
    /// Two presses 10 mm apart: both listed and each force within 20 % (None: the mode lists no contacts).
    pub two_contacts_ok: Option<usize>,
    pub two_contact_frames: usize,
    /// The 20 mm edges (`edge` cases) listed as exactly one contact: a long contact is one contact, not its
    /// fragments (None: the mode lists no contacts). Out of `edge_frames`.
    pub edges_one_contact: Option<usize>,
    /// The two presses 10 mm apart (round tips) reported with an edge direction: two fingertips are not an edge
    /// (issue 12: no direction for round contacts). Out of `two_contact_frames`.
    pub round_pairs_with_edge: usize,
    pub tangential_direction_mae_deg: Option<f64>,
    pub tangential_direction_max_deg: Option<f64>,
    /// The pushes' tangential force (fx, fy) against the truth's, the force calibration's scale applied: RMS of the
    /// vector error (a miss reads 0 N), N, and the median of read / true magnitudes.
    pub tangential_force_rms_n: Option<f64>,
    pub tangential_force_ratio: Option<f64>,
    /// The pushes' strongest contact against the truth, RMS mm, with the push shift fitted on the calibration
    /// pushes and without it (misses left out: the direction figures count them).
    pub push_localisation_rmse_mm: Option<f64>,
    pub push_localisation_unshifted_rmse_mm: Option<f64>,
    /// The pushes' normal force against the truth, RMS N (a miss reads 0 N), with the push's normal share fitted on
    /// the calibration pushes and without it.
    pub push_force_rms_n: Option<f64>,
    pub push_force_unshared_rms_n: Option<f64>,
    pub torque_rms_nmm: Option<f64>,
    pub camera_rotation_rms_deg: Option<f64>,
    pub camera_rotation_max_deg: Option<f64>,
    /// Presses on damaged pads detected, and localisation at other frame sizes.
    pub damaged_detected: usize,
    pub damaged_frames: usize,
    pub resolution_rmse_mm: Option<f64>,
    pub error: Option<String>,
}

#[derive(Clone, Debug, Serialize)]
pub struct ValidationReport {
    pub profile: Profile,
    pub seed: u64,
    pub frames: usize,
    pub sizes: Vec<(u32, u32)>,
    pub baseline: String,
    pub modes: Vec<ModeFigures>,
    pub machine: crate::report::Machine,
}

/// One mode's reading of one case with the case's truth (the corners left out), for looking at the figures case
/// by case: [`run_validation_with`] hands one to its `record` callback per mode and case.
#[derive(Clone, Debug, Serialize)]
pub struct CaseRecord<'a> {
    pub mode: Mode,
    pub case: &'a str,
    pub kind: CaseKind,
    pub size: (u32, u32),
    pub truth_contacts: &'a [ContactTruth],
    pub truth_force_vector_n: [f64; 3],
    pub truth_torque_nmm: f64,
    /// The reading's JSON (the `analyze --json` contract); `None`: refused.
    pub reading: Option<&'a serde_json::Value>,
}

pub(crate) struct Scored {
    kind: CaseKind,
    truth: CaseTruth,
    observed: Option<Observed>,
    elapsed_ms: Option<f64>,
}

/// The sensor config the examples measure from: the TOML file `NUSENSE_VALIDATION_CONFIG` names (an option measured
/// on the set), or the defaults.
pub fn base_config_from_env() -> Result<SensorConfig, Box<dyn std::error::Error>> {
    Ok(match std::env::var_os("NUSENSE_VALIDATION_CONFIG") {
        Some(path) => SensorConfig::from_toml_str(&std::fs::read_to_string(path)?)?,
        None => SensorConfig::default(),
    })
}

/// Renders the set once, size by size, and runs every mode on each frame as it is made.
pub fn run_validation(
    profile: Profile,
    seed: u64,
    modes: &[Mode],
    progress: &mut dyn FnMut(&str),
) -> Result<ValidationReport, BenchError> {
    run_validation_with(profile, seed, modes, &SensorConfig::default(), progress, &mut |_| {})
}

/// [`run_validation`] with every mode's sensor config starting from `base` rather than the defaults (before the
/// calibration fitted on the set), handing every mode's reading of every case to `record` as it is measured.
pub fn run_validation_with(
    profile: Profile,
    seed: u64,
    modes: &[Mode],
    base: &SensorConfig,
    progress: &mut dyn FnMut(&str),
    record: &mut dyn FnMut(&CaseRecord),
) -> Result<ValidationReport, BenchError> {
    let set = ValidationSet::new(profile, seed);
    let sizes = set.sizes();
    let (configs, calibration_frames) = sensor_configs(&set, seed, modes, base, progress)?;
    let mut calibration_frames = calibration_frames.into_iter().peekable();
    let mut scored: Vec<Vec<Scored>> = modes.iter().map(|_| Vec::new()).collect();
    let mut errors: Vec<Option<String>> = vec![None; modes.len()];
    for (size_index, &size) in sizes.iter().enumerate() {
        progress(&format!(
            "validation: rendering the rest frame at {}x{}",
            size.0, size.1
        ));
        let renderer = ValidationRenderer::new(size)?;
        let reference = renderer.reference(seed)?;
        let mut estimators = estimators_for(&configs, modes, &reference, size, &mut errors);
        let cases: Vec<_> = set.cases.iter().filter(|c| c.size == size).collect();
        for (k, case) in cases.iter().enumerate() {
            progress(&format!(
                "validation {}x{}: {} ({}/{})",
                size.0,
                size.1,
                case.name,
                k + 1,
                cases.len()
            ));
            // The calibration presses come first at the main size; they were rendered to fit the lines.
            let (frame, truth) = match calibration_frames.next_if(|(name, _)| *name == case.name) {
                Some((_, rendered)) => rendered,
                None => renderer.render(case)?,
            };
            for (m, estimator) in estimators.iter_mut().enumerate() {
                let (observed, elapsed_ms) = read_timed(estimator.as_mut(), &frame);
                // Speed is the main size's alone.
                let elapsed_ms = elapsed_ms.filter(|_| size_index == 0);
                record(&CaseRecord {
                    mode: modes[m],
                    case: &case.name,
                    kind: case.kind,
                    size,
                    truth_contacts: &truth.frame.contacts,
                    truth_force_vector_n: truth.frame.force_vector_n,
                    truth_torque_nmm: truth.frame.torque_nmm,
                    reading: observed.as_ref(),
                });
                let observed = observed.as_ref().map(Observed::of_value);
                scored[m].push(Scored {
                    kind: case.kind,
                    truth: truth.clone(),
                    observed,
                    elapsed_ms,
                });
            }
        }
    }
    Ok(report_of(profile, seed, set.cases.len(), sizes, modes, &scored, errors))
}

/// One estimator per mode for this size's rest frame; a mode whose estimator cannot be built has none, and its
/// first such error is kept in `errors`.
fn estimators_for(
    configs: &[SensorConfig],
    modes: &[Mode],
    reference: &RgbImage,
    size: (u32, u32),
    errors: &mut [Option<String>],
) -> Vec<Option<Estimator>> {
    modes
        .iter()
        .enumerate()
        .map(|(m, &mode)| match Estimator::new(configs[m].clone(), mode, reference) {
            Ok(e) => Some(e),
            Err(error) => {
                errors[m].get_or_insert_with(|| format!("{}x{} rest frame: {error}", size.0, size.1));
                None
            }
        })
        .collect()
}

/// The estimator's reading of `frame` as JSON and how long it took (ms); none when it has no estimator or no
/// reading.
fn read_timed(estimator: Option<&mut Estimator>, frame: &RgbImage) -> (Option<serde_json::Value>, Option<f64>) {
    let Some(estimator) = estimator else {
        return (None, None);
    };
    let started = Instant::now();
    let reading = estimator.estimate(frame);
    let elapsed = started.elapsed().as_secs_f64() * 1e3;
    match reading.ok().and_then(|r| serde_json::to_value(r).ok()) {
        Some(value) => (Some(value), Some(elapsed)),
        None => (None, None),
    }
}

/// Every mode's figures, with its speed against the baseline's (the paper's mode if run, else the first).
fn report_of(
    profile: Profile,
    seed: u64,
    frames: usize,
    sizes: Vec<(u32, u32)>,
    modes: &[Mode],
    scored: &[Vec<Scored>],
    errors: Vec<Option<String>>,
) -> ValidationReport {
    let mut figures: Vec<ModeFigures> = modes
        .iter()
        .zip(scored)
        .zip(errors)
        .map(|((&mode, scored), error)| ModeFigures {
            error,
            ..score(mode, scored)
        })
        .collect();
    let baseline_index = modes.iter().position(|m| *m == Mode::Paper).unwrap_or(0);
    let baseline = figures.get(baseline_index).and_then(|f| f.median_ms);
    for f in &mut figures {
        f.speedup = match (baseline, f.median_ms) {
            (Some(base), Some(this)) if this > 0.0 => Some(base / this),
            _ => None,
        };
    }
    ValidationReport {
        profile,
        seed,
        frames,
        sizes,
        baseline: modes.get(baseline_index).map(ToString::to_string).unwrap_or_default(),
        modes: figures,
        machine: crate::report::Machine::this(),
    }
}

/// Each mode's sensor config, as `nusense calibrate` would leave it for the validation sensor: the gamma modes'
/// estimators carry the line F = a gamma + b fitted on the calibration presses (the real sensor's default line reads
/// this sensor's light presses below zero, and the gamma modes' detection floor is stated in the line's newtons);
/// the modes that report newtons keep the pad model's defaults and are scaled afterwards (see [`ForceCalibration`]).
/// Also returns the calibration presses' frames (case name, frame, truth), in the set's order, to measure again.
#[allow(clippy::type_complexity)]
fn sensor_configs(
    set: &ValidationSet,
    seed: u64,
    modes: &[Mode],
    base: &SensorConfig,
    progress: &mut dyn FnMut(&str),
) -> Result<(Vec<SensorConfig>, Vec<(String, (RgbImage, CaseTruth))>), BenchError> {
    let cases: Vec<_> = set.cases.iter().filter(|c| c.kind == CaseKind::Calibration).collect();
    let Some(size) = cases.first().map(|c| c.size) else {
        return Ok((vec![base.clone(); modes.len()], Vec::new()));
    };
    progress(&format!(
        "validation: fitting the gamma line on {} calibration presses at {}x{}",
        cases.len(),
        size.0,
        size.1
    ));
    let renderer = ValidationRenderer::new(size)?;
    let reference = renderer.reference(seed)?;
    let frames = cases
        .iter()
        .map(|case| Ok((case.name.clone(), renderer.render(case)?)))
        .collect::<Result<Vec<_>, BenchError>>()?;
    let configs = modes
        .iter()
        .map(|&mode| {
            let mut config = base.clone();
            if mode == Mode::Inverse {
                return config;
            }
            let Ok(mut estimator) = Estimator::new(config.clone(), mode, &reference) else {
                return config;
            };
            // gamma does not depend on the line, so the default one measures it as well as any.
            let samples: Vec<CalibrationSample> = frames
                .iter()
                .filter_map(|(_, (frame, truth))| {
                    Some(CalibrationSample {
                        gamma: estimator.estimate(frame).ok()?.gamma.gamma,
                        force_n: truth.frame.force_vector_n[2],
                    })
                })
                .collect();
            if let Ok(fit) = fit_force_line(&samples, &FitOptions::default()) {
                config.calibration.a = fit.a;
                config.calibration.b = fit.b;
            }
            config
        })
        .collect();
    Ok((configs, frames))
}

/// The strongest true contact's centre.
fn strongest_centre(truth: &CaseTruth) -> Option<[f64; 2]> {
    truth
        .frame
        .contacts
        .iter()
        .max_by(|a, b| a.normal_force_n.total_cmp(&b.normal_force_n))
        .map(|c| c.centre_mm)
}

/// The one force calibration, fitted on the calibration cases only.
enum ForceCalibration {
    /// The mode reports newtons: one scale factor on fz (least squares through the origin, on the calibration
    /// presses), one on fx, fy (`nusense calibrate`'s tangential scale, on the calibration pushes; the normal one when
    /// the set has none), one on the torque (`nusense calibrate`'s torque scale, on the calibration twists; the
    /// tangential one when the set has none), how far a push's centre reads behind it
    /// (`elastic.push_centre_shift_mm`, on the calibration pushes, whose places the set knows) and what a push adds to
    /// its normal force (`elastic.push_normal_share`, on the calibration pushes against the normal scale).
    Scale {
        normal: f64,
        tangential: Option<f64>,
        torque: Option<f64>,
        push_shift_mm: Option<f64>,
        push_normal_share: Option<f64>,
    },
    /// The mode reports gamma: F = a gamma + b, fitted robustly as `nusense calibrate` does.
    GammaLine { a: f64, b: f64 },
}

impl ForceCalibration {
    fn fit(scored: &[Scored]) -> Option<Self> {
        let calibration: Vec<(&Observed, f64)> = scored
            .iter()
            .filter(|s| s.kind == CaseKind::Calibration)
            .filter_map(|s| Some((s.observed.as_ref()?, s.truth.frame.force_vector_n[2])))
            .collect();
        let newtons: Vec<(f64, f64)> = calibration
            .iter()
            .filter_map(|(o, truth)| Some((o.force_vector_n?[2], *truth)))
            .collect();
        if newtons.len() >= 3 {
            let (sxy, sxx) = newtons
                .iter()
                .fold((0.0, 0.0), |(sxy, sxx), (x, y)| (sxy + x * y, sxx + x * x));
            let pushes: Vec<ModelForceSample> = scored
                .iter()
                .filter(|s| s.kind == CaseKind::CalibrationPush)
                .filter_map(|s| {
                    let found = s.observed.as_ref().filter(|o| o.contact)?.force_vector_n?;
                    let truth = s.truth.frame.force_vector_n;
                    Some(ModelForceSample {
                        model_n: found[0].hypot(found[1]),
                        reference_n: truth[0].hypot(truth[1]),
                    })
                })
                .collect();
            let tangential = fit_tangential_scale(&pushes, FitOptions::default().bisquare_c, 0.95)
                .ok()
                .map(|fit| fit.scale);
            let twists: Vec<ModelTorqueSample> = scored
                .iter()
                .filter(|s| s.kind == CaseKind::CalibrationTwist)
                .filter_map(|s| {
                    Some(ModelTorqueSample {
                        model_nmm: s.observed.as_ref().filter(|o| o.contact)?.torque_nmm?,
                        reference_nmm: s.truth.frame.torque_nmm,
                    })
                })
                .collect();
            let torque = fit_torque_scale(&twists, FitOptions::default().bisquare_c, 0.95)
                .ok()
                .map(|fit| fit.scale);
            let centres: Vec<PushCentreSample> = scored
                .iter()
                .filter(|s| s.kind == CaseKind::CalibrationPush)
                .filter_map(|s| {
                    let found = s.observed.as_ref().filter(|o| o.contact)?;
                    Some(PushCentreSample {
                        model_force_vector_n: found.force_vector_n?,
                        read_centre_mm: found.contact_mm?,
                        true_centre_mm: strongest_centre(&s.truth)?,
                    })
                })
                .collect();
            let push_shift_mm = fit_push_centre_shift(&centres).ok();
            if !(sxx > 0.0) {
                return None;
            }
            let normal = sxy / sxx;
            let loads: Vec<PushNormalSample> = scored
                .iter()
                .filter(|s| s.kind == CaseKind::CalibrationPush)
                .filter_map(|s| {
                    Some(PushNormalSample {
                        model_force_vector_n: s.observed.as_ref().filter(|o| o.contact)?.force_vector_n?,
                        reference_normal_n: s.truth.frame.force_vector_n[2],
                    })
                })
                .collect();
            let push_normal_share = fit_push_normal_share(&loads, normal).ok();
            return Some(Self::Scale {
                normal,
                tangential,
                torque,
                push_shift_mm,
                push_normal_share,
            });
        }
        let samples: Vec<CalibrationSample> = calibration
            .iter()
            .filter_map(|(o, truth)| {
                Some(CalibrationSample {
                    gamma: o.gamma?,
                    force_n: *truth,
                })
            })
            .collect();
        let fit = fit_force_line(&samples, &FitOptions::default()).ok()?;
        Some(Self::GammaLine { a: fit.a, b: fit.b })
    }

    fn name(&self) -> String {
        match self {
            Self::Scale {
                normal,
                tangential,
                torque,
                push_shift_mm,
                push_normal_share,
            } => {
                let mut name = format!("scale {normal:.3}");
                if let Some(t) = tangential {
                    name += &format!(", tangential {t:.3}");
                }
                if let Some(t) = torque {
                    name += &format!(", torque {t:.3}");
                }
                if let Some(k) = push_shift_mm {
                    name += &format!(", push shift {k:.2} mm");
                }
                if let Some(c) = push_normal_share {
                    name += &format!(", push normal share {c:.3}");
                }
                name
            }
            Self::GammaLine { a, b } => format!("gamma line {a:.2} g {b:+.2}"),
        }
    }

    /// The calibrated normal force of a reading; no contact reads 0 N, and a force is never negative. With the
    /// push's normal share, what each listed contact's own push adds is taken off its own load, as the estimator does
    /// with `elastic.push_normal_share`.
    fn force_n(&self, o: &Observed) -> Option<f64> {
        self.force_with_share_n(o, self.push_normal_share())
    }

    /// [`Self::force_n`] with the push's normal share `share` (0: the solve's normal force).
    fn force_with_share_n(&self, o: &Observed, share: f64) -> Option<f64> {
        if !o.contact {
            return Some(0.0);
        }
        let f = match self {
            Self::Scale { normal, .. } if share != 0.0 => {
                let per_contact: Option<f64> = o.contacts.as_ref().filter(|c| !c.is_empty()).and_then(|c| {
                    c.iter()
                        .map(|c| Some(corrected_normal_n(c.force_vector_n?, share)))
                        .sum()
                });
                let load = match per_contact {
                    Some(load) => load,
                    None => corrected_normal_n(o.force_vector_n?, share),
                };
                load * normal
            }
            Self::Scale { normal, .. } => o.force_vector_n?[2] * normal,
            Self::GammaLine { a, b } => a * o.gamma? + b,
        };
        Some(f.max(0.0))
    }

    /// The calibrated normal force of one listed contact (what its own push adds taken off when it has a force
    /// vector).
    fn contact_force_n(&self, c: &ObservedContact) -> Option<f64> {
        let share = self.push_normal_share();
        let own = match c.force_vector_n {
            Some(vector) if share != 0.0 => corrected_normal_n(vector, share),
            _ => c.force_n?,
        };
        Some(own * self.scale())
    }

    /// What a push adds to its normal force (see `calibration::push_normal`), 0 where none was fitted.
    fn push_normal_share(&self) -> f64 {
        match self {
            Self::Scale { push_normal_share, .. } => push_normal_share.unwrap_or(0.0),
            Self::GammaLine { .. } => 0.0,
        }
    }

    fn scale(&self) -> f64 {
        match self {
            Self::Scale { normal, .. } => *normal,
            Self::GammaLine { .. } => 1.0,
        }
    }

    /// The factor on the tangential force.
    fn tangential_scale(&self) -> f64 {
        match self {
            Self::Scale { normal, tangential, .. } => tangential.unwrap_or(*normal),
            Self::GammaLine { .. } => 1.0,
        }
    }

    /// The factor on the torque.
    fn torque_scale(&self) -> f64 {
        match self {
            Self::Scale { torque: Some(t), .. } => *t,
            _ => self.tangential_scale(),
        }
    }

    /// mm along a push per unit of push over load (the model's), 0 where none was fitted.
    fn push_shift_mm(&self) -> f64 {
        match self {
            Self::Scale { push_shift_mm, .. } => push_shift_mm.unwrap_or(0.0),
            Self::GammaLine { .. } => 0.0,
        }
    }
}

fn angle_between_deg(a: [f64; 2], b: [f64; 2]) -> f64 {
    let cross = a[0] * b[1] - a[1] * b[0];
    let dot = a[0] * b[0] + a[1] * b[1];
    cross.atan2(dot).abs().to_degrees()
}

/// The detection rate per floor force (FLOOR_FORCES_N) on the cases of `kind`, and the floor: the smallest force
/// from which it and every heavier level is detected at least RELIABLE_DETECTION of the time.
#[allow(clippy::type_complexity)]
fn detection_floor(scored: &[Scored], kind: CaseKind) -> (Vec<(f64, f64)>, Option<f64>) {
    let rates: Vec<(f64, f64)> = FLOOR_FORCES_N
        .iter()
        .map(|&force| {
            let at: Vec<&Scored> = scored
                .iter()
                .filter(|s| s.kind == kind && (s.truth.frame.force_vector_n[2] - force).abs() < 1e-9)
                .collect();
            let found = at
                .iter()
                .filter(|s| s.observed.as_ref().is_some_and(|o| o.contact))
                .count();
            (force, found as f64 / at.len().max(1) as f64)
        })
        .collect();
    let floor = (0..rates.len())
        .find(|&i| rates[i..].iter().all(|(_, rate)| *rate >= RELIABLE_DETECTION))
        .map(|i| rates[i].0);
    (rates, floor)
}

pub(crate) fn score(mode: Mode, scored: &[Scored]) -> ModeFigures {
    let cases = Cases {
        scored,
        calibration: ForceCalibration::fit(scored),
    };
    let times: Vec<f64> = scored.iter().filter_map(|s| s.elapsed_ms).collect();
    let (location_errors, localisation_misses) = cases.localisation_errors();
    let (detection_rates, detection_floor_n) = detection_floor(scored, CaseKind::Floor);
    let (edge_detection_rates, edge_detection_floor_n) = detection_floor(scored, CaseKind::EdgeFloor);
    let (edge_errors, edge_misses) = cases.edge_errors();
    let lists_contacts = scored
        .iter()
        .any(|s| s.observed.as_ref().is_some_and(|o| o.contacts.is_some()));
    let direction_errors = cases.tangential_direction_errors();
    let (tangential_force_errors, tangential_force_ratios) = cases.tangential_force_errors();
    let (push_errors, push_unshifted_errors) = cases.push_localisation_errors();
    let rotation_errors = cases.rotation_errors();
    ModeFigures {
        mode,
        frames: scored.len(),
        refused: scored.iter().filter(|s| s.observed.is_none()).count(),
        median_ms: quantile(&times, 0.5),
        p99_ms: quantile(&times, 0.99),
        speedup: None,
        calibration: cases.calibration.as_ref().map(ForceCalibration::name),
        localisation_rmse_mm: rms(&location_errors),
        localisation_misses,
        localisation_frames: cases.of(CaseKind::Press).count(),
        force_rms_n: cases.force_rms_n(&[CaseKind::Press]),
        force_rms_with_motion_n: cases.force_rms_n(&[CaseKind::Press, CaseKind::CameraMotion]),
        detection_floor_n,
        detection_rates,
        edge_detection_floor_n,
        edge_detection_rates,
        false_contacts: cases.contacts_found(CaseKind::Rest),
        rest_frames: cases.of(CaseKind::Rest).count(),
        edge_mae_deg: nusense_estimator::stats::mean(&edge_errors),
        edge_max_deg: edge_errors.iter().copied().reduce(f64::max),
        edge_misses,
        edge_frames: cases.of(CaseKind::Edge).count(),
        two_contacts_ok: lists_contacts.then(|| {
            cases
                .of(CaseKind::TwoContacts)
                .filter(|s| cases.lists_each_contact(s))
                .count()
        }),
        two_contact_frames: cases.of(CaseKind::TwoContacts).count(),
        edges_one_contact: lists_contacts.then(|| cases.edges_listed_as_one()),
        round_pairs_with_edge: cases
            .of(CaseKind::TwoContacts)
            .filter(|s| s.observed.as_ref().is_some_and(|o| o.edge_angle_deg.is_some()))
            .count(),
        tangential_direction_mae_deg: nusense_estimator::stats::mean(&direction_errors),
        tangential_direction_max_deg: direction_errors.iter().copied().reduce(f64::max),
        tangential_force_rms_n: rms(&tangential_force_errors),
        push_localisation_rmse_mm: rms(&push_errors),
        push_localisation_unshifted_rmse_mm: rms(&push_unshifted_errors),
        push_force_rms_n: cases.push_force_rms_n(None),
        push_force_unshared_rms_n: cases.push_force_rms_n(Some(0.0)),
        tangential_force_ratio: quantile(&tangential_force_ratios, 0.5),
        torque_rms_nmm: rms(&cases.torque_errors()),
        camera_rotation_rms_deg: rms(&rotation_errors),
        camera_rotation_max_deg: rotation_errors.iter().map(|e| e.abs()).reduce(f64::max),
        damaged_detected: cases.contacts_found(CaseKind::Damaged),
        damaged_frames: cases.of(CaseKind::Damaged).count(),
        resolution_rmse_mm: rms(&cases.resolution_errors()),
        error: None,
    }
}

/// One mode's scored cases and the force calibration fitted on them: what each figure of the table is read from.
struct Cases<'a> {
    scored: &'a [Scored],
    calibration: Option<ForceCalibration>,
}

impl<'a> Cases<'a> {
    fn of(&self, kind: CaseKind) -> impl Iterator<Item = &'a Scored> {
        self.scored.iter().filter(move |s| s.kind == kind)
    }

    /// How many of the cases of `kind` the mode reads as a contact.
    fn contacts_found(&self, kind: CaseKind) -> usize {
        self.of(kind)
            .filter(|s| s.observed.as_ref().is_some_and(|o| o.contact))
            .count()
    }

    /// The presses' distances from the strongest true contact (mm), and how many presses had no contact read.
    fn localisation_errors(&self) -> (Vec<f64>, usize) {
        let mut errors = Vec::new();
        let mut misses = 0;
        for s in self.of(CaseKind::Press) {
            match (
                s.observed.as_ref().filter(|o| o.contact).and_then(|o| o.contact_mm),
                strongest_centre(&s.truth),
            ) {
                (Some(found), Some(truth)) => errors.push(distance(found, truth)),
                _ => misses += 1,
            }
        }
        (errors, misses)
    }

    /// RMS of the calibrated normal force's error over the cases of `kinds` (a missed press reads 0 N); `None`
    /// without a calibration.
    fn force_rms_n(&self, kinds: &[CaseKind]) -> Option<f64> {
        let calibration = self.calibration.as_ref()?;
        let errors: Vec<f64> = self
            .scored
            .iter()
            .filter(|s| kinds.contains(&s.kind))
            .map(|s| {
                let found = s.observed.as_ref().and_then(|o| calibration.force_n(o)).unwrap_or(0.0);
                found - s.truth.frame.force_vector_n[2]
            })
            .collect();
        rms(&errors)
    }

    /// The edges' direction errors (deg), and how many edges had no direction read.
    fn edge_errors(&self) -> (Vec<f64>, usize) {
        let mut errors = Vec::new();
        let mut misses = 0;
        for s in self.of(CaseKind::Edge) {
            let truth = s.truth.frame.contacts.first().and_then(|c| c.edge_angle_deg);
            match (s.observed.as_ref().and_then(|o| o.edge_angle_deg), truth) {
                (Some(found), Some(truth)) => errors.push(edge_angle_error_deg(found, truth)),
                _ => misses += 1,
            }
        }
        (errors, misses)
    }

    /// Whether every true contact of a case has a listed contact of its own within TWO_CONTACT_MATCH_MM whose
    /// calibrated force is within TWO_CONTACT_FORCE_TOLERANCE of its own.
    fn lists_each_contact(&self, s: &Scored) -> bool {
        let Some(listed) = s.observed.as_ref().and_then(|o| o.contacts.as_ref()) else {
            return false;
        };
        let mut used = vec![false; listed.len()];
        s.truth.frame.contacts.iter().all(|truth| {
            let best = listed
                .iter()
                .enumerate()
                .filter(|(i, c)| !used[*i] && c.centre_mm.is_some())
                .map(|(i, c)| (i, distance(c.centre_mm.unwrap_or_default(), truth.centre_mm)))
                .min_by(|a, b| a.1.total_cmp(&b.1));
            match best {
                Some((i, d)) if d <= TWO_CONTACT_MATCH_MM => {
                    used[i] = true;
                    let force = match &self.calibration {
                        Some(calibration) => calibration.contact_force_n(&listed[i]),
                        None => listed[i].force_n,
                    };
                    force.is_some_and(|f| {
                        (f - truth.normal_force_n).abs() <= TWO_CONTACT_FORCE_TOLERANCE * truth.normal_force_n
                    })
                }
                _ => false,
            }
        })
    }

    fn edges_listed_as_one(&self) -> usize {
        self.of(CaseKind::Edge)
            .filter(|s| {
                s.observed
                    .as_ref()
                    .and_then(|o| o.contacts.as_ref())
                    .is_some_and(|c| c.len() == 1)
            })
            .count()
    }

    /// The pushes' tangential direction errors (deg); empty when the mode reports no force vector.
    fn tangential_direction_errors(&self) -> Vec<f64> {
        let errors: Vec<f64> = self
            .of(CaseKind::Tangential)
            .filter_map(|s| {
                let found = s.observed.as_ref()?.force_vector_n?;
                let truth = s.truth.frame.force_vector_n;
                Some(angle_between_deg([found[0], found[1]], [truth[0], truth[1]]))
            })
            .collect();
        if errors.is_empty() {
            return errors;
        }
        // Misses count as a full reversal when the mode reports force vectors at all.
        let mut all = errors;
        all.resize(self.of(CaseKind::Tangential).count(), 180.0);
        all
    }

    /// The pushes' tangential force errors (N; a push read as no contact, 0 N) and read / true ratios, with the
    /// tangential scale. It is fitted on the calibration pushes, near the centre: how well one scale holds over the
    /// pad shows here. Empty errors when the mode reports no force vector.
    fn tangential_force_errors(&self) -> (Vec<f64>, Vec<f64>) {
        let scale = self
            .calibration
            .as_ref()
            .map_or(1.0, ForceCalibration::tangential_scale);
        let tangential: Vec<([f64; 2], Option<[f64; 2]>)> = self
            .of(CaseKind::Tangential)
            .map(|s| {
                let truth = s.truth.frame.force_vector_n;
                let found = s
                    .observed
                    .as_ref()
                    .filter(|o| o.contact)
                    .and_then(|o| o.force_vector_n)
                    .map(|f| [f[0] * scale, f[1] * scale]);
                ([truth[0], truth[1]], found)
            })
            .collect();
        let errors = if tangential.iter().any(|(_, found)| found.is_some()) {
            tangential
                .iter()
                .map(|(truth, found)| distance(found.unwrap_or([0.0, 0.0]), *truth))
                .collect()
        } else {
            Vec::new()
        };
        let ratios = tangential
            .iter()
            .filter_map(|(truth, found)| found.map(|f| f[0].hypot(f[1]) / truth[0].hypot(truth[1])))
            .collect();
        (errors, ratios)
    }

    /// The pushes' localisation errors (mm) with the push shift (fitted on the calibration pushes, near the centre,
    /// like the tangential scale) and without it.
    fn push_localisation_errors(&self) -> (Vec<f64>, Vec<f64>) {
        let push_shift_mm = self.calibration.as_ref().map_or(0.0, ForceCalibration::push_shift_mm);
        let most_mm = most_shift_mm(&SensorConfig::default().pad);
        self.of(CaseKind::Tangential)
            .filter_map(|s| {
                let found = s.observed.as_ref().filter(|o| o.contact)?;
                let (read, truth) = (found.contact_mm?, strongest_centre(&s.truth)?);
                let shifted = match found.force_vector_n {
                    Some(f) => shifted_centre(read, f, push_shift_mm, most_mm),
                    None => read,
                };
                Some((distance(shifted, truth), distance(read, truth)))
            })
            .unzip()
    }

    /// RMS of the pushes' calibrated normal force error, with the push's normal share `share` (the calibration's
    /// own when `None`); `None` without a calibration.
    fn push_force_rms_n(&self, share: Option<f64>) -> Option<f64> {
        let calibration = self.calibration.as_ref()?;
        let errors: Vec<f64> = self
            .of(CaseKind::Tangential)
            .map(|s| {
                let found = s.observed.as_ref().and_then(|o| match share {
                    Some(share) => calibration.force_with_share_n(o, share),
                    None => calibration.force_n(o),
                });
                found.unwrap_or(0.0) - s.truth.frame.force_vector_n[2]
            })
            .collect();
        rms(&errors)
    }

    /// The twists' torque errors (N mm), with the torque scale (fitted on the calibration twists, near the centre).
    fn torque_errors(&self) -> Vec<f64> {
        let scale = self.calibration.as_ref().map_or(1.0, ForceCalibration::torque_scale);
        self.of(CaseKind::Twist)
            .filter_map(|s| Some(s.observed.as_ref()?.torque_nmm? * scale - s.truth.frame.torque_nmm))
            .collect()
    }

    /// The camera rotation's errors (deg) on every case with the camera moved.
    fn rotation_errors(&self) -> Vec<f64> {
        self.scored
            .iter()
            .filter_map(|s| {
                let (_, image) = s.truth.camera_motion?;
                let found = s.observed.as_ref()?.camera_motion.as_ref()?.rotation_deg?;
                Some(found - image.rotation_deg)
            })
            .collect()
    }

    /// The other sizes' localisation errors (mm), over the presses read as contacts.
    fn resolution_errors(&self) -> Vec<f64> {
        self.of(CaseKind::Resolution)
            .filter_map(|s| {
                Some(distance(
                    s.observed.as_ref().filter(|o| o.contact)?.contact_mm?,
                    strongest_centre(&s.truth)?,
                ))
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nusense_estimator::calibration::push_normal::uncorrected_normal_n;

    #[test]
    fn new_reading_fields_are_read_when_present_and_absent_ones_stay_empty() {
        let today =
            serde_json::json!({"contact": true, "contact_mm": [1.0, 2.0], "gamma": 0.5, "edge_angle_deg": null});
        let o = Observed::of(&today);
        assert!(o.contact && o.contact_mm == Some([1.0, 2.0]) && o.gamma == Some(0.5));
        assert!(o.force_vector_n.is_none() && o.contacts.is_none() && o.camera_motion.is_none());
        let tomorrow = serde_json::json!({
            "contact": null,
            "contacts": [{"centre_mm": [3.0, 4.0], "centre_px": [1.0, 1.0], "force_n": 2.5, "area_mm2": 9.0}],
            "force_vector_n": [0.1, -0.2, 2.5],
            "torque_nmm": 1.5,
            "camera_motion": {"rotation_deg": 2.0, "shift_px": [1.0, 0.0], "scale": 1.0},
        });
        let o = Observed::of(&tomorrow);
        assert!(o.contact, "a listed contact is a contact");
        assert_eq!(o.force_vector_n, Some([0.1, -0.2, 2.5]));
        assert_eq!(o.contacts.as_ref().map(Vec::len), Some(1));
        assert_eq!(o.camera_motion.and_then(|m| m.rotation_deg), Some(2.0));
        assert_eq!(o.torque_nmm, Some(1.5));
    }

    fn truth(contacts: &[([f64; 2], [f64; 3])], motion_deg: Option<f64>) -> CaseTruth {
        use nusense_sim::validation::{CameraMotion, ImageMotion};
        use nusense_sim::{ContactTruth, GroundTruth, Indenter};
        let contacts: Vec<ContactTruth> = contacts
            .iter()
            .map(|&(centre_mm, f)| ContactTruth {
                indenter: Indenter::Sphere { radius_mm: 5.0 },
                centre_mm,
                centre_px: [0.0, 0.0],
                normal_force_n: f[2],
                tangential_force_n: [f[0], f[1]],
                torsion_nmm: 0.0,
                contact_radius_mm: 2.0,
                area_mm2: 4.0 * std::f64::consts::PI,
                edge_angle_deg: None,
                edge_angle_px_deg: None,
            })
            .collect();
        let force_vector_n = contacts.iter().fold([0.0; 3], |a, c| {
            [
                a[0] + c.tangential_force_n[0],
                a[1] + c.tangential_force_n[1],
                a[2] + c.normal_force_n,
            ]
        });
        CaseTruth {
            frame: GroundTruth {
                width: 64,
                height: 48,
                seed: 0,
                led_currents_ma: [100.0; 4],
                total_force_n: force_vector_n[2],
                force_vector_n,
                torque_nmm: 0.0,
                contacts,
                corners: Vec::new(),
            },
            camera_motion: motion_deg.map(|deg| {
                (
                    CameraMotion {
                        rotation_deg: [0.0, 0.0, deg],
                        shift_mm: [0.0, 0.0],
                    },
                    ImageMotion {
                        rotation_deg: deg,
                        shift_px: [0.0, 0.0],
                        scale: 1.0,
                    },
                )
            }),
        }
    }

    fn case(kind: CaseKind, truth: CaseTruth, reading: Option<serde_json::Value>) -> Scored {
        Scored {
            kind,
            truth,
            observed: reading.as_ref().map(Observed::of),
            elapsed_ms: Some(1.0),
        }
    }

    #[test]
    fn the_figures_are_the_known_answers_of_a_scripted_mode() {
        use serde_json::json;
        // A mode that reports twice the true force in its own units and four times its tangential force, adds a
        // tenth of its push squared over its load to its normal force, misses one press, places another 0.3 mm off,
        // detects from 0.5 N, lists two contacts, turns pushes by 10 degrees and reads the camera's roll 0.1 off.
        let press = |at: [f64; 2], f: f64| truth(&[(at, [0.0, 0.0, f])], None);
        let reading =
            |at: [f64; 2], fz: f64| json!({"contact": true, "contact_mm": at, "force_vector_n": [0.0, 0.0, fz]});
        let mut scored = Vec::new();
        for f in [1.0, 3.0, 5.0, 8.0] {
            scored.push(case(
                CaseKind::Calibration,
                press([0.0, 0.0], f),
                Some(reading([0.0, 0.0], 2.0 * f)),
            ));
        }
        for (t, f) in [(1.0, 3.0), (2.0, 5.0), (0.8, 4.0)] {
            let fz = uncorrected_normal_n(2.0 * f, 4.0 * t, 0.1);
            scored.push(case(
                CaseKind::CalibrationPush,
                truth(&[([0.0, 0.0], [0.0, t, f])], None),
                // Read behind the push by 1.5 mm per unit of the model's push over load.
                Some(json!({"contact": true, "contact_mm": [0.0, -1.5 * 4.0 * t / fz], "force_vector_n": [0.0, 4.0 * t, fz]})),
            ));
        }
        scored.push(case(
            CaseKind::Press,
            press([5.0, 5.0], 4.0),
            Some(reading([5.3, 5.0], 8.0)),
        ));
        scored.push(case(
            CaseKind::Press,
            press([-5.0, 2.0], 2.0),
            Some(json!({"contact": false})),
        ));
        for (f, seen) in [
            (0.2, false),
            (0.3, true),
            (0.5, true),
            (0.75, true),
            (1.0, true),
            (1.5, true),
            (2.0, true),
        ] {
            let r = if seen {
                reading([0.0, 0.0], 2.0 * f)
            } else {
                json!({"contact": false})
            };
            scored.push(case(CaseKind::Floor, press([0.0, 0.0], f), Some(r)));
        }
        // 0.3 N is seen once out of two: the floor is 0.5 N.
        scored.push(case(
            CaseKind::Floor,
            press([0.0, 0.0], 0.3),
            Some(json!({"contact": false})),
        ));
        scored.push(case(
            CaseKind::Rest,
            truth(&[], Some(3.0)),
            Some(json!({"contact": false, "camera_motion": {"rotation_deg": 3.1}})),
        ));
        scored.push(case(CaseKind::Rest, truth(&[], None), Some(json!({"contact": true}))));
        let two = truth(&[([-5.0, 0.0], [0.0, 0.0, 2.0]), ([5.0, 0.0], [0.0, 0.0, 4.0])], None);
        let listed = json!({"contact": true, "contacts": [
            {"centre_mm": [5.5, 0.0], "force_n": 8.4}, {"centre_mm": [-5.0, 0.5], "force_n": 3.8}]});
        scored.push(case(CaseKind::TwoContacts, two.clone(), Some(listed)));
        // Listed apart but told an edge along the pair (a direction across two contacts).
        let wrong_force = json!({"contact": true, "edge_angle_deg": 0.0, "contacts": [
            {"centre_mm": [5.0, 0.0], "force_n": 8.0}, {"centre_mm": [-5.0, 0.0], "force_n": 6.0}]});
        scored.push(case(CaseKind::TwoContacts, two, Some(wrong_force)));
        // An edge listed as one contact, and one listed as two fragments (its direction right in both).
        let edge = press([0.0, 0.0], 2.0);
        let one =
            json!({"contact": true, "edge_angle_deg": 30.0, "contacts": [{"centre_mm": [0.0, 0.0], "force_n": 4.0}]});
        let fragments = json!({"contact": true, "edge_angle_deg": 30.0, "contacts": [
            {"centre_mm": [-4.0, 0.0], "force_n": 2.0}, {"centre_mm": [4.0, 0.0], "force_n": 2.0}]});
        scored.push(case(CaseKind::Edge, edge.clone(), Some(one)));
        scored.push(case(CaseKind::Edge, edge, Some(fragments)));
        let push = truth(&[([0.0, 0.0], [1.0, 0.0, 4.0])], None);
        let turned = [
            4.0 * 10f64.to_radians().cos(),
            4.0 * 10f64.to_radians().sin(),
            uncorrected_normal_n(8.0, 4.0, 0.1),
        ];
        // Read behind the push as the calibration pushes are, and 0.2 mm across it.
        let behind = [-1.5 * turned[0] / turned[2], -1.5 * turned[1] / turned[2] + 0.2];
        scored.push(case(
            CaseKind::Tangential,
            push,
            Some(json!({"contact": true, "contact_mm": behind, "force_vector_n": turned})),
        ));
        // Twists read three times their torque, whatever the tangential scale; one twist 1.5 N mm more.
        let twist = |torque_nmm: f64| {
            let mut t = press([0.0, 0.0], 5.0);
            t.frame.torque_nmm = torque_nmm;
            t
        };
        let twisted =
            |torque_nmm: f64| json!({"contact": true, "force_vector_n": [0.0, 0.0, 10.0], "torque_nmm": torque_nmm});
        for m in [10.0, -6.0, 15.0] {
            scored.push(case(CaseKind::CalibrationTwist, twist(m), Some(twisted(3.0 * m))));
        }
        scored.push(case(CaseKind::Twist, twist(-9.0), Some(twisted(-27.0 + 1.5))));

        let f = score(Mode::Fast, &scored);
        assert_eq!(
            f.calibration.as_deref(),
            Some("scale 0.500, tangential 0.250, torque 0.333, push shift 1.50 mm, push normal share 0.100")
        );
        assert!(
            (f.torque_rms_nmm.unwrap() - 0.5).abs() < 1e-12,
            "{:?}",
            f.torque_rms_nmm
        );
        assert!((f.localisation_rmse_mm.unwrap() - 0.3).abs() < 1e-12);
        assert_eq!((f.localisation_misses, f.localisation_frames), (1, 2));
        // The missed 2 N press reads 0 N; the other is exact.
        assert!(
            (f.force_rms_n.unwrap() - (4.0f64 / 2.0).sqrt()).abs() < 1e-12,
            "{:?}",
            f.force_rms_n
        );
        assert_eq!(f.detection_floor_n, Some(0.5));
        assert_eq!(f.detection_rates[1], (0.3, 0.5));
        assert_eq!((f.false_contacts, f.rest_frames), (1, 2));
        assert_eq!((f.two_contacts_ok, f.two_contact_frames), (Some(1), 2));
        assert_eq!((f.edges_one_contact, f.edge_frames), (Some(1), 2));
        assert_eq!(f.round_pairs_with_edge, 1);
        assert!((f.tangential_direction_mae_deg.unwrap() - 10.0).abs() < 1e-9);
        // The push reads 1 N (4 N at the tangential scale 0.25) turned by 10 degrees: a chord of 2 sin 5 degrees.
        assert!((f.tangential_force_rms_n.unwrap() - 2.0 * 5f64.to_radians().sin()).abs() < 1e-12);
        assert!((f.tangential_force_ratio.unwrap() - 1.0).abs() < 1e-12);
        // The push shift takes the push back to its place but for the 0.2 mm across it.
        assert!((f.push_localisation_rmse_mm.unwrap() - 0.2).abs() < 1e-12);
        assert!((f.push_localisation_unshifted_rmse_mm.unwrap() - behind[0].hypot(behind[1])).abs() < 1e-12);
        // The share takes what the push added back off its normal force.
        assert!(f.push_force_rms_n.unwrap().abs() < 1e-12, "{:?}", f.push_force_rms_n);
        let added = uncorrected_normal_n(8.0, 4.0, 0.1) - 8.0;
        assert!(added > 0.1, "{added}");
        assert!((f.push_force_unshared_rms_n.unwrap() - 0.5 * added).abs() < 1e-12);
        assert!((f.camera_rotation_rms_deg.unwrap() - 0.1).abs() < 1e-9);
        assert_eq!(f.refused, 0);
        assert_eq!(f.median_ms, Some(1.0));
    }

    #[test]
    fn every_mode_is_listed() {
        assert_eq!(estimator_modes(), [Mode::Fast, Mode::Paper, Mode::Inverse]);
    }

    #[test]
    fn direction_errors_are_unsigned_angles() {
        assert!((angle_between_deg([1.0, 0.0], [0.0, 1.0]) - 90.0).abs() < 1e-12);
        assert!((angle_between_deg([1.0, 0.0], [-1.0, -1e-12]) - 180.0).abs() < 1e-6);
        assert!((angle_between_deg([1.0, 1.0], [1.0, 0.9]) - (45.0 - 0.9f64.atan().to_degrees())).abs() < 1e-12);
    }
}
