//! Synthetic NUSense sensor: contact mechanics, camera, LEDs, ground truth.
//!
//! A [`Scene`] (indenters and loads) is turned into a raw camera frame by a [`Renderer`] built for one
//! [`SensorModel`] (pad, gel, camera pose, colours, LEDs, image formation), together with the [`GroundTruth`]
//! the estimator is scored against. Given the same scene, LED currents and seed, a frame is bit-identical.
//!
//! ```
//! use nusense_sim::{Contact, Renderer, Scene, SensorModel};
//! let renderer = Renderer::new(SensorModel::real(160, 120)).unwrap();
//! let scene = Scene::with_contact(Contact::sphere(5.0, [0.0, 0.0], 6.0));
//! let (frame, truth) = renderer.render(&scene, [100.0; 4], 42).unwrap();
//! assert_eq!(frame.dimensions(), (160, 120));
//! assert_eq!(truth.corners.len(), 165);
//! ```

pub mod dataset;
pub mod layer;
pub mod lens;
pub mod mechanics;
pub mod model;
pub mod render;
pub mod scene;
pub mod script;
pub mod sweep;
pub mod truth;
pub mod validation;

/// The estimator's sensor configuration (TOML) for the simulated sensor: the force line and the gel's modulus as
/// a calibration on the simulator's presses gives them (the real sensor's defaults read its forces 5x low). The
/// simulator does not depend on the estimator, so it ships the text; `SensorConfig::from_toml_str` reads it.
pub const SENSOR_CONFIG_TOML: &str = include_str!("../simulated-sensor.toml");

pub use model::{Glare, Mechanics, ModelError, PadPose, SensorModel, NOMINAL_LED_CURRENT_MA};
pub use render::{RenderError, Renderer};
pub use scene::{Contact, Damage, Indenter, Occlusion, Scene, SceneError, SceneFile, SensorOverrides};
pub use truth::{ContactTruth, CornerTruth, GroundTruth};
