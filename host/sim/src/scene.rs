//! What presses on the pad in one frame: contacts (indenter, position, loads), pad damage and occlusions.
//! Scenes come from TOML (`SceneFile`) or are built in code (sweeps, the demo script); either way they pass
//! [`Scene::validate`] before anything is rendered, so a bad value is a typed error that names its key.

use std::path::{Path, PathBuf};

use nusense_geometry::PadGeometry;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::model::SensorModel;

#[derive(Debug, Error)]
pub enum SceneError {
    #[error("could not read scene file {path}")]
    Read { path: PathBuf, source: std::io::Error },
    #[error("scene file {path} is not a valid scene")]
    Parse {
        path: PathBuf,
        source: Box<toml::de::Error>,
    },
    #[error("{key} must be {expected}, got {value}")]
    BadValue {
        key: String,
        expected: &'static str,
        value: f64,
    },
    #[error("{key} = [{:.2}, {:.2}] mm lies outside the pad (|x| <= {half_width_mm} mm, |y| <= {half_height_mm} mm)", position_mm[0], position_mm[1])]
    OutsidePad {
        key: String,
        position_mm: [f64; 2],
        half_width_mm: f64,
        half_height_mm: f64,
    },
    #[error("a scene file gives either top-level [[contacts]]/[[damage]]/[[occlusions]] or [[frames]], not both")]
    FramesAndTopLevelScene,
}

/// The shape that presses on the pad.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Indenter {
    /// A rigid sphere: Hertzian pressure over a circle whose radius grows with the force.
    Sphere { radius_mm: f64 },
    /// A rigid flat-ended cylinder: the flat-punch pressure (singular at the rim) over its face.
    FlatPunch { radius_mm: f64 },
    /// A long rigid edge (a blade's rounded edge) lying along `angle_deg` (from +x towards +y, pad mm):
    /// a strip load `length_mm` long with a half-elliptic profile `width_mm` wide.
    Edge {
        length_mm: f64,
        width_mm: f64,
        angle_deg: f64,
    },
}

impl Indenter {
    /// The edge's direction folded into [0, 180), if this is an edge.
    pub fn edge_angle_deg(&self) -> Option<f64> {
        match self {
            Indenter::Edge { angle_deg, .. } => Some(angle_deg.rem_euclid(180.0)),
            _ => None,
        }
    }
}

/// One indenter pressing on the pad.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Contact {
    pub indenter: Indenter,
    /// Centre of the contact in pad mm.
    pub position_mm: [f64; 2],
    /// Pressing force (into the pad), N.
    pub normal_force_n: f64,
    /// Force along the pad surface (x, y in pad axes), N.
    #[serde(default)]
    pub tangential_force_n: [f64; 2],
    /// Twisting moment about the pad normal, N mm, positive from +x towards +y.
    #[serde(default)]
    pub torsion_nmm: f64,
}

impl Contact {
    pub fn sphere(radius_mm: f64, position_mm: [f64; 2], normal_force_n: f64) -> Self {
        Self::pressing(Indenter::Sphere { radius_mm }, position_mm, normal_force_n)
    }

    pub fn flat_punch(radius_mm: f64, position_mm: [f64; 2], normal_force_n: f64) -> Self {
        Self::pressing(Indenter::FlatPunch { radius_mm }, position_mm, normal_force_n)
    }

    pub fn edge(length_mm: f64, width_mm: f64, angle_deg: f64, position_mm: [f64; 2], normal_force_n: f64) -> Self {
        Self::pressing(
            Indenter::Edge {
                length_mm,
                width_mm,
                angle_deg,
            },
            position_mm,
            normal_force_n,
        )
    }

    fn pressing(indenter: Indenter, position_mm: [f64; 2], normal_force_n: f64) -> Self {
        Self {
            indenter,
            position_mm,
            normal_force_n,
            tangential_force_n: [0.0, 0.0],
            torsion_nmm: 0.0,
        }
    }
}

/// Damage printed into the pad's colour layer; it moves with the material.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Damage {
    /// The yellow ink is gone inside the disc (only the red base shows).
    Missing { centre_mm: [f64; 2], radius_mm: f64 },
    /// The ink is smeared inside the disc: edges spread over `smear_mm`.
    Smeared {
        centre_mm: [f64; 2],
        radius_mm: f64,
        smear_mm: f64,
    },
}

/// Something between the camera and the pad (dirt on the glass, a finger's shadow); fixed to the camera, so it
/// does not move with the pad. Given in pad mm at the pad's plane.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Occlusion {
    pub centre_mm: [f64; 2],
    pub radius_mm: f64,
    #[serde(default = "Occlusion::default_colour")]
    pub colour: [u8; 3],
}

impl Occlusion {
    fn default_colour() -> [u8; 3] {
        [12, 10, 10]
    }
}

/// Everything that differs between two frames of the same sensor.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    #[serde(default)]
    pub contacts: Vec<Contact>,
    #[serde(default)]
    pub damage: Vec<Damage>,
    #[serde(default)]
    pub occlusions: Vec<Occlusion>,
}

impl Scene {
    /// The pad at rest.
    pub fn rest() -> Self {
        Self::default()
    }

    pub fn with_contact(contact: Contact) -> Self {
        Self {
            contacts: vec![contact],
            ..Self::default()
        }
    }

    pub fn total_normal_force_n(&self) -> f64 {
        self.contacts.iter().map(|c| c.normal_force_n).sum()
    }

    /// Checks every value against what the mechanics and renderer can honour.
    pub fn validate(&self, pad: &PadGeometry) -> Result<(), SceneError> {
        for (i, contact) in self.contacts.iter().enumerate() {
            let key = |field: &str| format!("contacts[{i}].{field}");
            finite_in_pad(&key("position_mm"), contact.position_mm, pad)?;
            at_least(
                &key("normal_force_n"),
                contact.normal_force_n,
                0.0,
                "a finite force >= 0 N",
            )?;
            for (axis, value) in ["x", "y"].iter().zip(contact.tangential_force_n) {
                finite(&key(&format!("tangential_force_n.{axis}")), value)?;
            }
            finite(&key("torsion_nmm"), contact.torsion_nmm)?;
            match contact.indenter {
                Indenter::Sphere { radius_mm } | Indenter::FlatPunch { radius_mm } => {
                    positive(&key("indenter.radius_mm"), radius_mm)?;
                }
                Indenter::Edge {
                    length_mm,
                    width_mm,
                    angle_deg,
                } => {
                    positive(&key("indenter.length_mm"), length_mm)?;
                    positive(&key("indenter.width_mm"), width_mm)?;
                    finite(&key("indenter.angle_deg"), angle_deg)?;
                }
            }
        }
        for (i, damage) in self.damage.iter().enumerate() {
            let key = |field: &str| format!("damage[{i}].{field}");
            let (centre_mm, radius_mm) = match *damage {
                Damage::Missing { centre_mm, radius_mm } => (centre_mm, radius_mm),
                Damage::Smeared {
                    centre_mm,
                    radius_mm,
                    smear_mm,
                } => {
                    positive(&key("smear_mm"), smear_mm)?;
                    (centre_mm, radius_mm)
                }
            };
            for (axis, value) in ["x", "y"].iter().zip(centre_mm) {
                finite(&key(&format!("centre_mm.{axis}")), value)?;
            }
            positive(&key("radius_mm"), radius_mm)?;
        }
        for (i, occlusion) in self.occlusions.iter().enumerate() {
            for (axis, value) in ["x", "y"].iter().zip(occlusion.centre_mm) {
                finite(&format!("occlusions[{i}].centre_mm.{axis}"), value)?;
            }
            positive(&format!("occlusions[{i}].radius_mm"), occlusion.radius_mm)?;
        }
        Ok(())
    }
}

fn finite(key: &str, value: f64) -> Result<(), SceneError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(SceneError::BadValue {
            key: key.to_owned(),
            expected: "a finite number",
            value,
        })
    }
}

fn positive(key: &str, value: f64) -> Result<(), SceneError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(SceneError::BadValue {
            key: key.to_owned(),
            expected: "a finite number > 0",
            value,
        })
    }
}

fn at_least(key: &str, value: f64, min: f64, expected: &'static str) -> Result<(), SceneError> {
    if value.is_finite() && value >= min {
        Ok(())
    } else {
        Err(SceneError::BadValue {
            key: key.to_owned(),
            expected,
            value,
        })
    }
}

fn finite_in_pad(key: &str, position_mm: [f64; 2], pad: &PadGeometry) -> Result<(), SceneError> {
    for (axis, value) in ["x", "y"].iter().zip(position_mm) {
        finite(&format!("{key}.{axis}"), value)?;
    }
    if pad.contains_mm(position_mm) {
        Ok(())
    } else {
        Err(SceneError::OutsidePad {
            key: key.to_owned(),
            position_mm,
            half_width_mm: pad.width_mm / 2.0,
            half_height_mm: pad.height_mm / 2.0,
        })
    }
}

/// Camera and pad settings a scene file may change from [`SensorModel::real`].
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorOverrides {
    pub width: Option<u32>,
    pub height: Option<u32>,
    pub jpeg_quality: Option<u8>,
    pub noise_sigma: Option<f32>,
    pub blur_px: Option<f32>,
    pub exposure: Option<f32>,
    pub vignetting: Option<f32>,
    /// Moves the pad in its own plane as the camera sees it (a camera mounted off-centre), mm.
    pub camera_shift_mm: Option<[f64; 2]>,
    /// Extra tilt of the pad about the camera's x, y and z axes, degrees.
    pub camera_rotation_deg: Option<[f64; 3]>,
    pub layer_depth_mm: Option<f64>,
    pub shear_modulus_kpa: Option<f64>,
    pub poisson_ratio: Option<f64>,
}

impl SensorOverrides {
    pub fn sensor_model(&self) -> SensorModel {
        let width = self.width.unwrap_or(640);
        let height = self.height.unwrap_or(width * 3 / 4);
        let mut model = SensorModel::real(width, height);
        if let Some(q) = self.jpeg_quality {
            model.jpeg_quality = Some(q);
        }
        if let Some(v) = self.noise_sigma {
            model.noise_sigma = v;
        }
        if let Some(v) = self.blur_px {
            model.blur_px = v;
        }
        if let Some(v) = self.exposure {
            model.exposure = v;
        }
        if let Some(v) = self.vignetting {
            model.vignetting = v;
        }
        if let Some(shift) = self.camera_shift_mm {
            model.pose.shift_mm = [model.pose.shift_mm[0] + shift[0], model.pose.shift_mm[1] + shift[1]];
        }
        if let Some(rotation) = self.camera_rotation_deg {
            for (axis, extra) in model.pose.rotation_deg.iter_mut().zip(rotation) {
                *axis += extra;
            }
        }
        if let crate::model::Mechanics::HalfSpace(material) = &mut model.mechanics {
            if let Some(v) = self.layer_depth_mm {
                material.layer_depth_mm = v;
            }
            if let Some(v) = self.shear_modulus_kpa {
                material.shear_modulus_kpa = v;
            }
            if let Some(v) = self.poisson_ratio {
                material.poisson_ratio = v;
            }
        }
        model
    }
}

fn nominal_currents() -> [f32; 4] {
    [crate::model::NOMINAL_LED_CURRENT_MA; 4]
}

/// A scene file for `nusense sim render`: sensor settings, LED currents, seed, and either one scene given at the
/// top level or a list of `[[frames]]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    #[serde(default)]
    pub sensor: SensorOverrides,
    /// Top, Right, Bottom, Left (the protocol's side order), mA.
    #[serde(default = "nominal_currents")]
    pub led_currents_ma: [f32; 4],
    #[serde(default)]
    pub seed: u64,
    #[serde(default)]
    pub contacts: Vec<Contact>,
    #[serde(default)]
    pub damage: Vec<Damage>,
    #[serde(default)]
    pub occlusions: Vec<Occlusion>,
    #[serde(default)]
    pub frames: Vec<Scene>,
}

impl SceneFile {
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Self, SceneError> {
        let file: SceneFile = toml::from_str(text).map_err(|source| SceneError::Parse {
            path: path.to_owned(),
            source: Box::new(source),
        })?;
        let top_level = !(file.contacts.is_empty() && file.damage.is_empty() && file.occlusions.is_empty());
        if top_level && !file.frames.is_empty() {
            return Err(SceneError::FramesAndTopLevelScene);
        }
        for (i, current) in file.led_currents_ma.iter().enumerate() {
            if !(current.is_finite() && *current >= 0.0) {
                return Err(SceneError::BadValue {
                    key: format!("led_currents_ma[{i}]"),
                    expected: "a finite current >= 0 mA",
                    value: f64::from(*current),
                });
            }
        }
        let pad = file.sensor.sensor_model().pad;
        for scene in file.scenes() {
            scene.validate(&pad)?;
        }
        Ok(file)
    }

    pub fn load(path: &Path) -> Result<Self, SceneError> {
        let text = std::fs::read_to_string(path).map_err(|source| SceneError::Read {
            path: path.to_owned(),
            source,
        })?;
        Self::from_toml_str(&text, path)
    }

    /// The frames this file describes, in order.
    pub fn scenes(&self) -> Vec<Scene> {
        if self.frames.is_empty() {
            vec![Scene {
                contacts: self.contacts.clone(),
                damage: self.damage.clone(),
                occlusions: self.occlusions.clone(),
            }]
        } else {
            self.frames.clone()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<SceneFile, SceneError> {
        SceneFile::from_toml_str(text, Path::new("test.toml"))
    }

    #[test]
    fn parses_a_single_scene_and_frames() {
        let file = parse(
            r#"
            seed = 3
            led_currents_ma = [100, 100, 50, 100]
            [sensor]
            width = 320
            jpeg_quality = 85
            [[contacts]]
            indenter = { kind = "sphere", radius_mm = 5.0 }
            position_mm = [1.0, -2.0]
            normal_force_n = 6.0
            tangential_force_n = [0.5, 0.0]
            [[contacts]]
            indenter = { kind = "edge", length_mm = 20.0, width_mm = 1.0, angle_deg = 30.0 }
            position_mm = [-10.0, 5.0]
            normal_force_n = 2.0
            [[damage]]
            kind = "smeared"
            centre_mm = [5.0, 5.0]
            radius_mm = 3.0
            smear_mm = 1.0
            "#,
        )
        .unwrap();
        let scenes = file.scenes();
        assert_eq!(scenes.len(), 1);
        assert_eq!(scenes[0].contacts.len(), 2);
        assert_eq!(scenes[0].contacts[1].indenter.edge_angle_deg(), Some(30.0));
        assert_eq!(file.sensor.sensor_model().height, 240);
        assert_eq!(file.sensor.sensor_model().jpeg_quality, Some(85));

        let frames = parse(
            r#"
            [[frames]]
            [[frames]]
            [[frames.contacts]]
            indenter = { kind = "flat_punch", radius_mm = 3.0 }
            position_mm = [0.0, 0.0]
            normal_force_n = 1.0
            "#,
        )
        .unwrap();
        assert_eq!(frames.scenes().len(), 2);
        assert!(frames.scenes()[0].contacts.is_empty());
    }

    #[test]
    fn the_example_scene_file_is_valid() {
        let path = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/example.toml"));
        let file = SceneFile::load(path).unwrap();
        let scenes = file.scenes();
        assert_eq!(scenes.len(), 3);
        assert_eq!(scenes[1].contacts.len(), 2);
        assert_eq!(scenes[2].damage.len(), 2);
    }

    #[test]
    fn bad_scenes_give_typed_errors_naming_the_key() {
        let negative = parse(
            "[[contacts]]\nindenter = { kind = \"sphere\", radius_mm = 5.0 }\nposition_mm = [0.0, 0.0]\nnormal_force_n = -1.0\n",
        );
        match negative {
            Err(SceneError::BadValue { key, .. }) => assert_eq!(key, "contacts[0].normal_force_n"),
            other => panic!("{other:?}"),
        }
        let zero_radius = parse(
            "[[contacts]]\nindenter = { kind = \"flat_punch\", radius_mm = 0.0 }\nposition_mm = [0.0, 0.0]\nnormal_force_n = 1.0\n",
        );
        assert!(
            matches!(zero_radius, Err(SceneError::BadValue { ref key, .. }) if key == "contacts[0].indenter.radius_mm")
        );
        let outside = parse(
            "[[contacts]]\nindenter = { kind = \"sphere\", radius_mm = 5.0 }\nposition_mm = [40.0, 0.0]\nnormal_force_n = 1.0\n",
        );
        assert!(matches!(outside, Err(SceneError::OutsidePad { .. })));
        let unknown_key = parse(
            "[[contacts]]\nindenter = { kind = \"sphere\", radius_mm = 5.0 }\nposition = [0.0, 0.0]\nnormal_force_n = 1.0\n",
        );
        match unknown_key {
            Err(SceneError::Parse { source, .. }) => assert!(source.to_string().contains("position"), "{source}"),
            other => panic!("{other:?}"),
        }
        let unknown_indenter =
            parse("[[contacts]]\nindenter = { kind = \"cone\" }\nposition_mm = [0.0, 0.0]\nnormal_force_n = 1.0\n");
        assert!(matches!(unknown_indenter, Err(SceneError::Parse { .. })));
        let both = parse(
            "[[contacts]]\nindenter = { kind = \"sphere\", radius_mm = 5.0 }\nposition_mm = [0.0, 0.0]\nnormal_force_n = 1.0\n[[frames]]\n",
        );
        assert!(matches!(both, Err(SceneError::FramesAndTopLevelScene)));
        assert!(matches!(
            parse("led_currents_ma = [100, -1, 0, 0]\n"),
            Err(SceneError::BadValue { .. })
        ));
    }
}
