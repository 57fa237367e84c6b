//! Shear, force, contact and edge estimation from NUSense frames.
//!
//! One module per stage, in the order a frame flows through them:
//! [`detection`] (fast and inverse modes) or [`paper`] (the published pipeline) find the lattice in raw px;
//! [`pad_map`] undistorts the points and maps them to pad mm with a per-sensor map; [`registration`] pairs them
//! with the rest frame by lattice index; [`inverse`] fits the camera motion ([`motion`]) jointly with the surface
//! tractions of the pad's elastic model ([`elastic`]), removes it and decides contact against the frame's noise;
//! [`surface`] and [`shear`] give the paper's gamma, `force`, [`contact`] and `edge` the paper-line readings.
//! [`Estimator`] runs them and returns a [`Reading`]; [`SensorConfig`] holds every parameter, with defaults for the
//! real sensor; [`calibration`] fits what the model cannot know from a force/torque log.

pub mod calibration;
pub(crate) mod config;
pub mod contact;
pub mod detection;
pub(crate) mod edge;
pub mod elastic;
pub(crate) mod error;
pub(crate) mod estimator;
pub(crate) mod force;
pub mod homography;
pub mod inverse;
pub(crate) mod lattice;
pub(crate) mod linalg;
pub mod motion;
pub mod pad_map;
pub mod paper;
pub(crate) mod reading;
pub mod registration;
pub mod shear;
pub mod stats;
pub mod surface;

pub use config::{
    ConfigError, ElasticConfig, ElasticModel, ForceCalibration, InverseConfig, ObservedPoints, PaperParams,
    RetareConfig, Roi, SensorConfig, SurfaceConfig, Thresholds,
};
pub use error::EstimateError;
pub use estimator::{Estimator, Mode, PATTERN_REGION_MARGIN_CELLS};
pub use lattice::{CornerObservation, Lattice, SquareObservation};
pub use pad_map::{MapResidual, StoredPadMap};
pub use reading::{
    CameraMotion, ContactRegion, ContactTest, EdgeReading, GammaReading, LatticeCounts, PressureMap, Reading,
    ReadingJson, ShearVector, Touch,
};
