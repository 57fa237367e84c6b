//! Everything on the host that talks to the LED board, usable without the daemon.
//!
//! - [`transport`]: byte streams (serial devices and ptys, in-memory pipes).
//! - [`BoardLink`]: handshake with version check, requests with sequence numbers, timeouts and retries,
//!   telemetry queued between replies, framing counters. Blocking, one caller.
//! - [`discover`]: boards by USB VID:PID and serial number.
//! - [`SupervisedLink`]: a thread that keeps a board connected across unplugs, for the daemon.
//! - [`virtual_board`]: the firmware's own logic on a host thread, behind a pty or an in-memory pipe, for
//!   running and testing everything without hardware.

mod discovery;
mod error;
mod link;
mod supervisor;
pub mod transport;
pub mod virtual_board;

pub use discovery::{discover, find_board, BoardPort, USB_PID, USB_VID};
pub use error::LinkError;
pub use link::{BoardLink, LinkOptions, LinkStats};
pub use supervisor::{BoardEvent, BoardState, BoardTarget, LedRequest, SupervisedLink, SupervisorOptions};
pub use transport::{memory_pipe, PipeEnd, SerialTransport, Transport};

/// The most current the firmware accepts on one LED string, mA: the firmware's own limit, so that host and board
/// can never disagree.
pub const LED_LIMIT_MA: u16 = nusense_firmware_core::limits::MAX_CURRENT_MA;

#[cfg(test)]
mod link_tests;
