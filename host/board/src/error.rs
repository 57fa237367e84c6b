use nusense_protocol::framing::EncodeError;
use nusense_protocol::DeviceError;

/// Everything that can go wrong talking to a board, in words a user can act on.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    // The cause is part of the message and deliberately not an error `source`: chains would print it twice.
    #[error("cannot open the serial device {path}: {cause}")]
    Open { path: String, cause: serialport::Error },
    #[error("the board did not answer in time, even after retrying")]
    Timeout,
    #[error(
        "the board did not answer the handshake on {path}: is it a NUSense board, powered, with its firmware running?"
    )]
    NoHandshake { path: String },
    #[error(
        "protocol version mismatch: the board speaks protocol version {device}, this host speaks version {host}; \
         update the {} so both speak the same version",
        older_side(*.device, *.host)
    )]
    VersionMismatch { device: u16, host: u16 },
    #[error(
        "protocol schema mismatch: the board and this host both say protocol version {version}, but the board's \
         message types have fingerprint {device:016x} and this host's {host:016x}: one of them was built from \
         changed message types without a version bump; rebuild the firmware and the host from the same source"
    )]
    SchemaMismatch { version: u16, device: u64, host: u64 },
    #[error("the board refused the request: {0}")]
    Device(DeviceError),
    #[error("the board answered {request} with an unexpected reply: {reply}")]
    UnexpectedReply { request: &'static str, reply: String },
    #[error("the board is disconnected")]
    Disconnected,
    #[error("the board is not connected right now (the link is reconnecting)")]
    NotConnected,
    #[error("the board link has been stopped")]
    Stopped,
    #[error("cannot encode the request: {0}")]
    Encode(EncodeError),
    #[error("cannot list serial ports: {0}")]
    Discover(serialport::Error),
    #[error("no NUSense board found (USB {vid:04x}:{pid:04x}{serial}); plug one in, or pass --port PATH or --virtual", serial = serial_hint(.serial_number))]
    NoBoardFound {
        vid: u16,
        pid: u16,
        serial_number: Option<String>,
    },
    #[error("{count} NUSense boards are attached ({ports}); choose one with --port PATH")]
    SeveralBoards { count: usize, ports: String },
}

fn serial_hint(serial_number: &Option<String>) -> String {
    match serial_number {
        Some(serial) => format!(" with serial number {serial}"),
        None => String::new(),
    }
}

fn older_side(device: u16, host: u16) -> &'static str {
    if device < host {
        "board's firmware"
    } else {
        "host software (nusense)"
    }
}

impl LinkError {
    /// True when the link is gone and must be reopened (unplug, closed pty); other errors leave it usable.
    pub fn is_disconnect(&self) -> bool {
        matches!(self, LinkError::Disconnected)
    }
}
