//! The host side of the board protocol.
//!
//! - [`transport`]: byte streams (serial devices and ptys, in-memory pipes).
//! - [`BoardLink`]: handshake with version check, requests with sequence numbers, timeouts and retries,
//!   telemetry queued between replies, framing counters. Blocking, one caller.
//! - [`discover`]: boards by USB VID:PID and serial number.
//! - [`SupervisedLink`]: a thread that keeps a board connected across unplugs, for the daemon.

mod discovery;
mod error;
mod link;
mod supervisor;
pub mod transport;

pub use discovery::{discover, find_board, BoardPort, USB_PID, USB_VID};
pub use error::LinkError;
pub use link::{BoardLink, LinkOptions, LinkStats};
pub use supervisor::{
    BoardEvent, BoardState, BoardTarget, LedRequest, SupervisedLink, SupervisorOptions,
};
pub use transport::{memory_pipe, PipeEnd, SerialTransport, Transport};

#[cfg(test)]
mod link_tests;
