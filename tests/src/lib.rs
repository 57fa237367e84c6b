//! Helpers shared by the integration tests.

pub mod firmware_image;
