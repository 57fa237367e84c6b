//! What the estimator reports for one frame.
//!
//! In Rust a contact is an `Option<Touch>`, so a reading cannot say "no contact" and carry a force, a location or
//! an edge, nor "contact" without them. On the wire (JSON) a reading is the flat object every consumer of
//! `analyze --json` and the daemon has read since the first release: `contact`, `contact_px`, `force_n`, ... stay
//! where they were, the new fields sit beside them (null where a mode has none), and deserialising checks that the
//! flat fields agree with each other.

use nusense_geometry::{CornerIndex, Point2};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::estimator::Mode;

/// One lattice corner's motion.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct ShearVector {
    pub index: CornerIndex,
    pub reference_px: Option<Point2>,
    pub current_px: Option<Point2>,
    /// The pad's own motion at this corner since the reference, camera motion removed, pad mm; `None` when either
    /// frame missed the corner.
    pub displacement_mm: Option<Point2>,
    /// Seen in both frames with a plausible motion (only valid corners are measured).
    pub valid: bool,
}

/// How the camera (or the whole pad) moved between the rest frame and this frame: the similarity closest to the
/// fitted motion of the pad plane.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CameraMotion {
    /// Rotation of the pattern in the image, degrees from +x towards +y.
    pub rotation_deg: f64,
    /// Motion of the pad centre's image, raw px [dx, dy].
    pub shift_px: Point2,
    /// Apparent size now / at rest.
    pub scale: f64,
}

impl CameraMotion {
    pub const NONE: Self = Self {
        rotation_deg: 0.0,
        shift_px: [0.0, 0.0],
        scale: 1.0,
    };
}

/// One contact region.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ContactRegion {
    /// The pattern's point under the contact's centre, raw px of this frame.
    pub centre_px: Point2,
    pub centre_undistorted_px: Point2,
    pub centre_mm: Point2,
    /// Normal force, N (> 0).
    pub force_n: f64,
    /// [fx, fy, fz], N, pad frame (x right, y down as seen in the raw image, z into the pad); modes without the
    /// traction inverse have none.
    pub force_vector_n: Option<[f64; 3]>,
    /// Moment about the pad normal through `centre_mm`, N mm, from +x towards +y.
    pub torque_nmm: Option<f64>,
    /// Area that carries the load, mm^2 (the pressure's participation area); traction inverse only.
    pub area_mm2: Option<f64>,
}

/// Direction of an elongated contact.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct EdgeReading {
    /// Degrees from +x towards +y on the pad, in [0, 180); `None` for a round contact.
    pub angle_deg: Option<f64>,
    /// 0 for a round contact, towards 1 for a long edge.
    pub confidence: f64,
}

/// Everything that exists only while something touches the pad.
#[derive(Clone, Debug, PartialEq)]
pub struct Touch {
    /// The strongest contact (largest normal force).
    pub strongest: ContactRegion,
    /// The others, strongest first.
    pub others: Vec<ContactRegion>,
    /// Total normal force, N (>= the detection floor).
    pub force_n: f64,
    /// Total [fx, fy, fz], N (traction inverse only).
    pub force_vector_n: Option<[f64; 3]>,
    /// Total moment about the pad normal through the centre of pressure, N mm (traction inverse only).
    pub torque_nmm: Option<f64>,
    pub edge: EdgeReading,
}

impl Touch {
    pub fn contacts(&self) -> impl Iterator<Item = &ContactRegion> {
        std::iter::once(&self.strongest).chain(&self.others)
    }
}

/// The contact decision and what it rests on.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ContactTest {
    /// Improvement of the traction fit over the motion-only fit, in units of the noise variance.
    pub statistic: f64,
    /// The statistic's 1 - alpha quantile without contact (alpha: `inverse.false_alarm_probability`).
    pub threshold: f64,
    /// Probability of a statistic this large without contact.
    pub p_value: f64,
    /// This frame's corner noise, mm (1 sigma per axis): the corners' scatter about the motion-only fit, never below
    /// `inverse.noise_floor_mm` (paper mode: the residual noise of the traction fit, never below the floors of
    /// `inverse.noise_floor_mm` and `inverse.noise_floor_px`).
    pub noise_mm: f64,
    /// Smallest normal force at the pad's centre the test detects at this noise, N.
    pub detection_floor_n: f64,
}

/// The pressure over the pad: a grid in pad mm (the pattern's cells).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PressureMap {
    /// Centre of the first cell (top-left as the camera sees it), pad mm.
    pub origin_mm: Point2,
    /// Cell pitch along x and y, mm.
    pub step_mm: Point2,
    pub cols: usize,
    pub rows: usize,
    /// Row-major, kPa.
    pub kpa: Vec<f64>,
}

/// Lattice bookkeeping: what was found and used.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct LatticeCounts {
    /// Corners found in this frame.
    pub points_detected: usize,
    pub points_expected: usize,
    pub squares_detected: usize,
    pub squares_expected: usize,
    /// Corners seen in both frames with a plausible motion.
    pub points_valid: usize,
    /// Corners seen in both frames but masked as implausible.
    pub points_implausible: usize,
}

/// The paper's shear measure.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct GammaReading {
    /// alpha * sum ||s - s_ref|| with the camera motion removed, paper px.
    pub gamma: f64,
    /// The same without removing camera motion: the paper's value.
    pub gamma_uncompensated: f64,
    pub samples_used: usize,
    pub samples_total: usize,
}

/// One frame's measurement.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(into = "ReadingJson", try_from = "ReadingJson")]
pub struct Reading {
    pub mode: Mode,
    /// `None`: nothing touches the pad (above the detection floor).
    pub touch: Option<Touch>,
    pub test: ContactTest,
    pub camera_motion: CameraMotion,
    pub gamma: GammaReading,
    /// a * gamma + b, N, whether or not there is contact (the paper's calibration line as it is).
    pub force_model_n: f64,
    /// Third-largest local (non-affine) corner shear, mm: how far the pad departs from rigid motion.
    pub contact_score_mm: f64,
    /// The traction inverse's pressure map (modes with the inverse; zero without contact).
    pub pressure_map: Option<PressureMap>,
    pub counts: LatticeCounts,
    /// The fast tracker had to search the whole frame again.
    pub recovered: bool,
    /// This frame became the new rest frame (persistent motion without contact).
    pub retared: bool,
    /// Re-tares since the estimator was built.
    pub retare_count: u64,
    pub shear_field: Vec<ShearVector>,
    pub elapsed_ms: f64,
}

impl Reading {
    /// Moves every image-space point by `factor`: a reading measured in a frame decoded at 1/2 scale, scaled by
    /// 2, is in the full frame's raw px (the camera model scales with the frame, so undistorted px scale too).
    /// Everything in mm, N or paper px is unchanged.
    pub fn scale_px(&mut self, factor: f64) {
        let scale = |p: &mut Point2| *p = [p[0] * factor, p[1] * factor];
        if let Some(touch) = &mut self.touch {
            for contact in std::iter::once(&mut touch.strongest).chain(&mut touch.others) {
                scale(&mut contact.centre_px);
                scale(&mut contact.centre_undistorted_px);
            }
        }
        scale(&mut self.camera_motion.shift_px);
        for vector in &mut self.shear_field {
            for p in [&mut vector.reference_px, &mut vector.current_px].into_iter().flatten() {
                scale(p);
            }
        }
    }

    pub fn is_contact(&self) -> bool {
        self.touch.is_some()
    }

    /// Total normal force, N: 0 without contact.
    pub fn force_n(&self) -> f64 {
        self.touch.as_ref().map_or(0.0, |t| t.force_n)
    }

    pub fn strongest(&self) -> Option<&ContactRegion> {
        self.touch.as_ref().map(|t| &t.strongest)
    }

    pub fn contact_px(&self) -> Option<Point2> {
        self.strongest().map(|c| c.centre_px)
    }

    pub fn contact_mm(&self) -> Option<Point2> {
        self.strongest().map(|c| c.centre_mm)
    }

    pub fn contacts(&self) -> Vec<ContactRegion> {
        self.touch
            .as_ref()
            .map(|t| t.contacts().copied().collect())
            .unwrap_or_default()
    }

    pub fn edge_angle_deg(&self) -> Option<f64> {
        self.touch.as_ref().and_then(|t| t.edge.angle_deg)
    }

    pub fn edge_confidence(&self) -> f64 {
        self.touch.as_ref().map_or(0.0, |t| t.edge.confidence)
    }

    /// Every number in the reading, for finiteness checks.
    pub fn numbers(&self) -> Vec<f64> {
        let json = ReadingJson::from(self.clone());
        let mut v = vec![
            json.gamma,
            json.gamma_uncompensated,
            json.force_n,
            json.force_model_n,
            json.edge_confidence,
            json.contact_score_mm,
            json.elapsed_ms,
            json.camera_motion.rotation_deg,
            json.camera_motion.scale,
            json.contact_test.statistic,
            json.contact_test.threshold,
            json.contact_test.p_value,
            json.contact_test.noise_mm,
            json.contact_test.detection_floor_n,
        ];
        v.extend(json.camera_motion.shift_px);
        v.extend(json.contact_px.into_iter().flatten());
        v.extend(json.contact_undistorted_px.into_iter().flatten());
        v.extend(json.contact_mm.into_iter().flatten());
        v.extend(json.edge_angle_deg);
        v.extend(json.force_vector_n.into_iter().flatten());
        v.extend(json.torque_nmm);
        for c in &json.contacts {
            v.extend(c.centre_px.iter().chain(&c.centre_undistorted_px).chain(&c.centre_mm));
            v.push(c.force_n);
            v.extend(c.force_vector_n.into_iter().flatten());
            v.extend(c.torque_nmm);
            v.extend(c.area_mm2);
        }
        if let Some(map) = &json.pressure_map {
            v.extend(map.origin_mm.iter().chain(&map.step_mm).chain(&map.kpa));
        }
        for s in &json.shear_field {
            v.extend(s.reference_px.into_iter().flatten());
            v.extend(s.current_px.into_iter().flatten());
            v.extend(s.displacement_mm.into_iter().flatten());
        }
        v
    }
}

/// The flat JSON form of a [`Reading`] (field names are an interface other tools rely on).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(title = "Reading")]
pub struct ReadingJson {
    pub mode: Mode,
    pub contact: bool,
    /// The strongest contact's centre, raw px.
    pub contact_px: Option<Point2>,
    pub contact_undistorted_px: Option<Point2>,
    pub contact_mm: Option<Point2>,
    /// alpha * sum ||s - s_ref||, camera motion removed, paper px.
    pub gamma: f64,
    /// The paper's gamma, camera motion not removed.
    pub gamma_uncompensated: f64,
    /// Total normal force, N: 0 without contact, never negative.
    pub force_n: f64,
    /// a * gamma + b whether or not there is contact.
    pub force_model_n: f64,
    /// Total [fx, fy, fz], N, pad frame (x right, y down in the raw image, z into the pad); null without the
    /// traction inverse or without contact.
    pub force_vector_n: Option<[f64; 3]>,
    /// Moment about the pad normal, N mm; null without the traction inverse or without contact.
    pub torque_nmm: Option<f64>,
    /// Every contact, strongest first; empty without contact.
    pub contacts: Vec<ContactRegion>,
    pub edge_angle_deg: Option<f64>,
    pub edge_confidence: f64,
    pub camera_motion: CameraMotion,
    pub contact_test: ContactTest,
    pub pressure_map: Option<PressureMap>,
    pub points_detected: usize,
    pub points_expected: usize,
    pub squares_detected: usize,
    pub squares_expected: usize,
    pub points_valid: usize,
    pub points_implausible: usize,
    pub samples_used: usize,
    pub samples_total: usize,
    /// Third-largest local (non-affine) corner shear, mm.
    pub contact_score_mm: f64,
    pub recovered: bool,
    pub retared: bool,
    pub retare_count: u64,
    pub shear_field: Vec<ShearVector>,
    pub elapsed_ms: f64,
}

impl From<Reading> for ReadingJson {
    fn from(r: Reading) -> Self {
        let strongest = r.strongest().copied();
        Self {
            mode: r.mode,
            contact: r.touch.is_some(),
            contact_px: strongest.map(|c| c.centre_px),
            contact_undistorted_px: strongest.map(|c| c.centre_undistorted_px),
            contact_mm: strongest.map(|c| c.centre_mm),
            gamma: r.gamma.gamma,
            gamma_uncompensated: r.gamma.gamma_uncompensated,
            force_n: r.force_n(),
            force_model_n: r.force_model_n,
            force_vector_n: r.touch.as_ref().and_then(|t| t.force_vector_n),
            torque_nmm: r.touch.as_ref().and_then(|t| t.torque_nmm),
            contacts: r.contacts(),
            edge_angle_deg: r.edge_angle_deg(),
            edge_confidence: r.edge_confidence(),
            camera_motion: r.camera_motion,
            contact_test: r.test,
            pressure_map: r.pressure_map,
            points_detected: r.counts.points_detected,
            points_expected: r.counts.points_expected,
            squares_detected: r.counts.squares_detected,
            squares_expected: r.counts.squares_expected,
            points_valid: r.counts.points_valid,
            points_implausible: r.counts.points_implausible,
            samples_used: r.gamma.samples_used,
            samples_total: r.gamma.samples_total,
            contact_score_mm: r.contact_score_mm,
            recovered: r.recovered,
            retared: r.retared,
            retare_count: r.retare_count,
            shear_field: r.shear_field,
            elapsed_ms: r.elapsed_ms,
        }
    }
}

impl TryFrom<ReadingJson> for Reading {
    type Error = String;

    fn try_from(j: ReadingJson) -> Result<Self, Self::Error> {
        let touch = if j.contact {
            let mut contacts = j.contacts.into_iter();
            let strongest = contacts.next().ok_or("`contact` is true but `contacts` is empty")?;
            if j.contact_px != Some(strongest.centre_px) || j.contact_mm != Some(strongest.centre_mm) {
                return Err("`contact_px` / `contact_mm` are not the first contact's centre".into());
            }
            if !(j.force_n >= 0.0) {
                return Err(format!("`force_n` = {} is negative", j.force_n));
            }
            Some(Touch {
                strongest,
                others: contacts.collect(),
                force_n: j.force_n,
                force_vector_n: j.force_vector_n,
                torque_nmm: j.torque_nmm,
                edge: EdgeReading {
                    angle_deg: j.edge_angle_deg,
                    confidence: j.edge_confidence,
                },
            })
        } else {
            let stray = j.contact_px.is_some()
                || j.contact_undistorted_px.is_some()
                || j.contact_mm.is_some()
                || !j.contacts.is_empty()
                || j.force_n != 0.0
                || j.force_vector_n.is_some()
                || j.torque_nmm.is_some()
                || j.edge_angle_deg.is_some();
            if stray {
                return Err("`contact` is false but a location, force or edge is given".into());
            }
            None
        };
        Ok(Self {
            mode: j.mode,
            touch,
            test: j.contact_test,
            camera_motion: j.camera_motion,
            gamma: GammaReading {
                gamma: j.gamma,
                gamma_uncompensated: j.gamma_uncompensated,
                samples_used: j.samples_used,
                samples_total: j.samples_total,
            },
            force_model_n: j.force_model_n,
            contact_score_mm: j.contact_score_mm,
            pressure_map: j.pressure_map,
            counts: LatticeCounts {
                points_detected: j.points_detected,
                points_expected: j.points_expected,
                squares_detected: j.squares_detected,
                squares_expected: j.squares_expected,
                points_valid: j.points_valid,
                points_implausible: j.points_implausible,
            },
            recovered: j.recovered,
            retared: j.retared,
            retare_count: j.retare_count,
            shear_field: j.shear_field,
            elapsed_ms: j.elapsed_ms,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(contact: bool) -> Reading {
        let region = ContactRegion {
            centre_px: [1000.0, 760.0],
            centre_undistorted_px: [995.0, 758.0],
            centre_mm: [-1.0, 2.0],
            force_n: 4.0,
            force_vector_n: Some([0.1, -0.2, 4.0]),
            torque_nmm: Some(0.5),
            area_mm2: Some(30.0),
        };
        Reading {
            mode: Mode::Inverse,
            touch: contact.then(|| Touch {
                strongest: region,
                others: vec![ContactRegion { force_n: 1.0, ..region }],
                force_n: 5.0,
                force_vector_n: Some([0.1, -0.2, 5.0]),
                torque_nmm: Some(0.4),
                edge: EdgeReading {
                    angle_deg: None,
                    confidence: 0.1,
                },
            }),
            test: ContactTest {
                statistic: 900.0,
                threshold: 60.0,
                p_value: 0.0,
                noise_mm: 0.01,
                detection_floor_n: 0.1,
            },
            camera_motion: CameraMotion {
                rotation_deg: 1.5,
                shift_px: [3.0, -2.0],
                scale: 1.001,
            },
            gamma: GammaReading {
                gamma: 1.0,
                gamma_uncompensated: 1.2,
                samples_used: 10,
                samples_total: 10,
            },
            force_model_n: 1.95,
            contact_score_mm: 0.3,
            pressure_map: Some(PressureMap {
                origin_mm: [-1.0, -1.0],
                step_mm: [2.0, 2.0],
                cols: 2,
                rows: 1,
                kpa: vec![0.0, 3.0],
            }),
            counts: LatticeCounts {
                points_detected: 165,
                points_expected: 165,
                squares_detected: 96,
                squares_expected: 96,
                points_valid: 165,
                points_implausible: 0,
            },
            recovered: false,
            retared: false,
            retare_count: 2,
            shear_field: vec![],
            elapsed_ms: 1.2,
        }
    }

    #[test]
    fn json_keeps_the_flat_keys_and_round_trips() {
        for contact in [true, false] {
            let reading = sample(contact);
            let json = serde_json::to_value(&reading).unwrap();
            for key in [
                "contact",
                "contact_px",
                "contact_undistorted_px",
                "contact_mm",
                "gamma",
                "force_n",
                "force_model_n",
                "edge_angle_deg",
                "edge_confidence",
                "points_detected",
                "points_expected",
                "squares_detected",
                "squares_expected",
                "points_valid",
                "points_implausible",
                "samples_used",
                "samples_total",
                "contact_score_mm",
                "recovered",
                "shear_field",
                "elapsed_ms",
                "camera_motion",
                "force_vector_n",
                "torque_nmm",
                "contacts",
                "pressure_map",
                "gamma_uncompensated",
            ] {
                assert!(json.get(key).is_some(), "{key} missing from {json}");
            }
            assert_eq!(json["contact"], contact);
            let back: Reading = serde_json::from_value(json).unwrap();
            assert_eq!(back, reading);
        }
    }

    #[test]
    fn impossible_json_is_refused() {
        let mut json = serde_json::to_value(sample(false)).unwrap();
        json["force_n"] = serde_json::json!(1.0);
        assert!(serde_json::from_value::<Reading>(json).is_err());
        let mut json = serde_json::to_value(sample(true)).unwrap();
        json["contacts"] = serde_json::json!([]);
        assert!(serde_json::from_value::<Reading>(json).is_err());
    }

    #[test]
    fn the_schema_describes_the_flat_object() {
        let schema = serde_json::to_value(schemars::schema_for!(Reading)).unwrap();
        let properties = &schema["properties"];
        assert!(
            properties.get("contact_px").is_some() && properties.get("camera_motion").is_some(),
            "{schema}"
        );
        assert!(properties.get("touch").is_none(), "{schema}");
    }
}
