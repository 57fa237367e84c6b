//! Shear, force, contact and edge estimation from NUSense frames.
//!
//! One module per stage, in the order a frame flows through them:
//! [`detection`] (fast mode) or [`paper`] (the published pipeline) find the lattice in raw px;
//! [`pad_map`] undistorts the points and maps them to pad mm; [`registration`] pairs them with the rest frame by
//! lattice index; [`surface`] and [`shear`] give gamma; [`force`], [`contact`] and [`edge`] the readings.
//! [`Estimator`] runs them; [`SensorConfig`] holds every parameter, with defaults for the real sensor.

pub mod calibration;
pub mod config;
pub mod contact;
pub mod detection;
pub mod edge;
pub mod error;
pub mod estimator;
pub mod force;
pub mod homography;
pub mod lattice;
pub mod pad_map;
pub mod paper;
pub mod registration;
pub mod shear;
pub mod stats;
pub mod surface;

pub use config::{ConfigError, ForceCalibration, PaperParams, Roi, SensorConfig, SurfaceConfig, Thresholds};
pub use error::EstimateError;
pub use estimator::{Estimator, Mode, Reading, ShearVector};
pub use lattice::{CornerObservation, Lattice, SquareObservation};
