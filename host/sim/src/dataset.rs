//! The layout of a folder written by `nusense sim render|sweep`: `reference.png` (the pad at rest, same sensor,
//! LEDs and seed), one `NAME.png` + `NAME.json` ([`GroundTruth`]) per frame, and `manifest.json` ([`Manifest`]).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::model::SensorModel;
use crate::render::{RenderError, Renderer};
use crate::scene::Scene;
use crate::sweep::SweepFrame;
use crate::truth::GroundTruth;

pub const MANIFEST_FILE: &str = "manifest.json";
pub const REFERENCE_IMAGE: &str = "reference.png";

#[derive(Debug, Error)]
pub enum DatasetError {
    #[error("could not read {path}")]
    Read { path: PathBuf, source: std::io::Error },
    #[error("{path} is not a sim manifest")]
    Parse { path: PathBuf, source: serde_json::Error },
    #[error("could not write {path}")]
    Write { path: PathBuf, source: std::io::Error },
    #[error("could not encode {path}")]
    Encode { path: PathBuf, source: image::ImageError },
    #[error("rendering {frame}")]
    Render { frame: String, source: RenderError },
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

/// Renders the rest frame and every frame of `frames` with `renderer` and writes them, their ground truth and the
/// manifest into `out` (created if missing). `progress` hears the name of each frame as it starts ("reference"
/// first). Frame k is rendered with seed `seed + k + 1`, the reference with `seed`.
pub fn write_dataset(
    renderer: &Renderer,
    led_currents_ma: [f32; 4],
    seed: u64,
    frames: &[SweepFrame],
    out: &Path,
    progress: &mut dyn FnMut(&str),
) -> Result<Manifest, DatasetError> {
    std::fs::create_dir_all(out).map_err(|source| DatasetError::Write {
        path: out.to_path_buf(),
        source,
    })?;
    progress("reference");
    let (reference, _) = renderer
        .render(&Scene::rest(), led_currents_ma, seed)
        .map_err(|source| DatasetError::Render {
            frame: "reference".into(),
            source,
        })?;
    save_image(&reference, &out.join(REFERENCE_IMAGE))?;

    let mut manifest_frames = Vec::with_capacity(frames.len());
    for (k, frame) in frames.iter().enumerate() {
        progress(&frame.name);
        let (image, truth) = renderer
            .render(&frame.scene, led_currents_ma, seed.wrapping_add(k as u64 + 1))
            .map_err(|source| DatasetError::Render {
                frame: frame.name.clone(),
                source,
            })?;
        let image_name = format!("{}.png", frame.name);
        let truth_name = format!("{}.json", frame.name);
        save_image(&image, &out.join(&image_name))?;
        write_json(&out.join(&truth_name), &truth)?;
        manifest_frames.push(ManifestFrame {
            name: frame.name.clone(),
            image: image_name,
            truth: truth_name,
        });
    }
    let manifest = Manifest {
        sensor: renderer.model().clone(),
        led_currents_ma,
        seed,
        reference: REFERENCE_IMAGE.to_owned(),
        frames: manifest_frames,
    };
    write_json(&out.join(MANIFEST_FILE), &manifest)?;
    Ok(manifest)
}

fn save_image(image: &image::RgbImage, path: &Path) -> Result<(), DatasetError> {
    image.save(path).map_err(|source| DatasetError::Encode {
        path: path.to_path_buf(),
        source,
    })
}

fn write_json(path: &Path, value: &impl Serialize) -> Result<(), DatasetError> {
    let text = serde_json::to_string_pretty(value).map_err(|source| DatasetError::Parse {
        path: path.to_path_buf(),
        source,
    })?;
    std::fs::write(path, text).map_err(|source| DatasetError::Write {
        path: path.to_path_buf(),
        source,
    })
}
