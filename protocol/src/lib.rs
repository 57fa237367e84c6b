//! The NUSense wire protocol, shared by the firmware and the host (no_std, no alloc).
//!
//! - [`message`]: what is said: host requests, board responses and telemetry.
//! - [`framing`]: how it travels on a byte stream (postcard + CRC + COBS, 0x00-delimited).
#![cfg_attr(not(test), no_std)]

pub mod framing;
pub mod message;

pub use message::*;
