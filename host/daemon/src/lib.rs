//! The nusense daemon: frames from a source (camera, recording or simulator) through the estimator, with the
//! LED board kept in step, published over HTTP/WebSocket with a dashboard, Foxglove and Zenoh, and recorded to
//! MCAP.
//!
//! [`pipeline`] runs capture, estimation and publication; [`api`] serves them (and the dashboard); [`zenoh_out`]
//! publishes every sensor on Zenoh; [`commands`] checks what clients ask of a sensor, for both; [`record`] writes
//! and reads recordings; [`reading`] is the one reading message all of them (and `nusense analyze`) speak.

pub mod api;
pub mod commands;
mod dashboard;
pub mod foxglove_live;
pub mod pipeline;
pub mod reading;
pub mod record;
pub mod zenoh_out;

pub use reading::{ReadingMessage, SCHEMA_VERSION};
