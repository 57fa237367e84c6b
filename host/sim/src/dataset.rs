//! The layout of a folder written by `nusense sim render|sweep`: `reference.png` (the pad at rest, same sensor,
//! LEDs and seed), one `NAME.png` + `NAME.json` ([`GroundTruth`]) per frame, and `manifest.json` ([`Manifest`]).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::model::SensorModel;
use crate::truth::GroundTruth;

pub const MANIFEST_FILE: &str = "manifest.json";
pub const REFERENCE_IMAGE: &str = "reference.png";

#[derive(Debug, Error)]
pub enum DatasetError {
    #[error("could not read {path}")]
    Read { path: PathBuf, source: std::io::Error },
    #[error("{path} is not a sim manifest")]
    Parse { path: PathBuf, source: serde_json::Error },
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ManifestFrame {
    pub name: String,
    /// File names relative to the folder.
    pub image: String,
    pub truth: String,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub sensor: SensorModel,
    /// Top, Right, Bottom, Left.
    pub led_currents_ma: [f32; 4],
    pub seed: u64,
    pub reference: String,
    pub frames: Vec<ManifestFrame>,
}

impl Manifest {
    pub fn load(dir: &Path) -> Result<Self, DatasetError> {
        let path = dir.join(MANIFEST_FILE);
        let text = std::fs::read_to_string(&path).map_err(|source| DatasetError::Read {
            path: path.clone(),
            source,
        })?;
        serde_json::from_str(&text).map_err(|source| DatasetError::Parse { path, source })
    }

    /// The ground truth of one frame of the folder `dir`.
    pub fn load_truth(dir: &Path, frame: &ManifestFrame) -> Result<GroundTruth, DatasetError> {
        let path = dir.join(&frame.truth);
        let text = std::fs::read_to_string(&path).map_err(|source| DatasetError::Read {
            path: path.clone(),
            source,
        })?;
        serde_json::from_str(&text).map_err(|source| DatasetError::Parse { path, source })
    }
}
