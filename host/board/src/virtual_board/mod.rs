//! A board without hardware: the firmware's own logic (nusense-firmware-core's `Controller`) driving a simulated
//! LED plant, on a host thread at 1 kHz. The host reaches it exactly like a real board:
//!
//! - behind a pseudo-terminal ([`VirtualBoard::spawn_pty`]): [`crate::BoardLink::open`] gets the slave
//!   path, so the whole serial stack is exercised; the host may close and reopen the port at will;
//! - or in process ([`VirtualBoard::spawn_in_process`] + [`VirtualBoard::connect`]): an in-memory pipe for
//!   [`crate::BoardLink::over`], when no pty is wanted.
//!
//! [`VirtualBoard::led_currents_ma`] is the current the strings actually carry, for the simulated camera.

mod engine;
mod pty;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::mpsc::{self, Sender};
use std::sync::Arc;
use std::thread::JoinHandle;

pub use nusense_firmware_core::plant::{PlantParams, StringFault};
use nusense_firmware_core::{BoardConfig, Identity, CHANNEL_COUNT};
use nusense_protocol::Side;

use crate::{memory_pipe, PipeEnd};
use engine::{BootParams, HostSide, Shared};

#[derive(Debug, thiserror::Error)]
pub enum VirtualBoardError {
    #[error("cannot create a pseudo-terminal for the virtual board: {0}")]
    Pty(#[source] std::io::Error),
    #[error("cannot link {link} to the virtual board's pty: {source}")]
    Link {
        link: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot start the virtual board thread: {0}")]
    Thread(#[source] std::io::Error),
    #[error("this virtual board sits behind a pty; open its path instead of connecting in process")]
    NotInProcess,
    #[error("the virtual board is unplugged")]
    Unplugged,
}

/// How a virtual board is built.
#[derive(Clone, Debug)]
pub struct VirtualBoardOptions {
    /// Keep a symlink here pointing at the current pty (like udev's /dev/serial/by-id links), so the path stays
    /// the same across [`VirtualBoard::unplug`] and [`VirtualBoard::replug`].
    pub link_path: Option<PathBuf>,
    pub identity: Identity,
    /// Configuration at first boot, until a SaveConfig writes the virtual flash. By default every string is on
    /// at its nominal current, as on a sensor that was set up once and saved, so the simulated camera sees a
    /// lit pad from the start.
    pub config: BoardConfig,
    pub plant: PlantParams,
    pub noise_seed: u64,
}

impl Default for VirtualBoardOptions {
    fn default() -> Self {
        Self {
            link_path: None,
            identity: virtual_identity(),
            config: BoardConfig {
                enabled: [true; CHANNEL_COUNT],
                ..BoardConfig::default()
            },
            plant: PlantParams::default(),
            noise_seed: 0x5EED,
        }
    }
}

/// A distinct unique id per virtual board in this machine's lifetime: "VB", the process id, a counter.
fn virtual_identity() -> Identity {
    static NEXT: AtomicU32 = AtomicU32::new(1);
    let mut uid = [0u8; 12];
    uid[..2].copy_from_slice(b"VB");
    uid[2..6].copy_from_slice(&std::process::id().to_be_bytes());
    uid[6..10].copy_from_slice(&NEXT.fetch_add(1, Ordering::Relaxed).to_be_bytes());
    Identity::new(env!("CARGO_PKG_VERSION"), "virtual", "virtual-board", uid)
}

enum Mode {
    Pty { slave_path: String },
    InProcess { connections: Sender<PipeEnd> },
}

/// A running virtual board. Dropping it powers the board off (the host sees a disconnect).
pub struct VirtualBoard {
    options: VirtualBoardOptions,
    in_process: bool,
    shared: Arc<Shared>,
    mode: Option<Mode>,
    thread: Option<JoinHandle<()>>,
    path: String,
}

impl VirtualBoard {
    /// A board behind a new pseudo-terminal; give [`Self::path`] to `BoardLink::open`.
    pub fn spawn_pty() -> Result<Self, VirtualBoardError> {
        Self::spawn(VirtualBoardOptions::default(), false)
    }

    /// A board reached through [`Self::connect`] instead of a pty.
    pub fn spawn_in_process() -> Result<Self, VirtualBoardError> {
        Self::spawn(VirtualBoardOptions::default(), true)
    }

    pub fn spawn_pty_with(options: VirtualBoardOptions) -> Result<Self, VirtualBoardError> {
        Self::spawn(options, false)
    }

    pub fn spawn_in_process_with(options: VirtualBoardOptions) -> Result<Self, VirtualBoardError> {
        Self::spawn(options, true)
    }

    fn spawn(options: VirtualBoardOptions, in_process: bool) -> Result<Self, VirtualBoardError> {
        let shared = Arc::new(Shared::new());
        let mut board = Self {
            options,
            in_process,
            shared,
            mode: None,
            thread: None,
            path: String::new(),
        };
        board.power_on()?;
        Ok(board)
    }

    fn power_on(&mut self) -> Result<(), VirtualBoardError> {
        self.shared.stop.store(false, Ordering::Relaxed);
        let (host, mode, path) = if self.in_process {
            let (connections, incoming) = mpsc::channel();
            let path = format!("in-process virtual board {}", self.serial_number());
            (
                HostSide::Pipe {
                    current: None,
                    incoming,
                },
                Mode::InProcess { connections },
                path,
            )
        } else {
            let master = pty::PtyMaster::open().map_err(VirtualBoardError::Pty)?;
            let slave_path = master.slave_path().to_owned();
            let path = match &self.options.link_path {
                Some(link) => {
                    replace_symlink(&slave_path, link).map_err(|source| VirtualBoardError::Link {
                        link: link.clone(),
                        source,
                    })?;
                    link.to_string_lossy().into_owned()
                }
                None => slave_path.clone(),
            };
            (HostSide::Pty(master), Mode::Pty { slave_path }, path)
        };
        let boot = BootParams {
            identity: self.options.identity.clone(),
            default_config: self.options.config,
            plant: self.options.plant,
            noise_seed: self.options.noise_seed,
        };
        let shared = self.shared.clone();
        let thread = std::thread::Builder::new()
            .name("virtual board".into())
            .spawn(move || engine::run(host, boot, &shared))
            .map_err(VirtualBoardError::Thread)?;
        self.thread = Some(thread);
        self.mode = Some(mode);
        self.path = path;
        Ok(())
    }

    /// The serial device path to open (the pty slave, or the stable link), or a description in process.
    pub fn path(&self) -> &str {
        &self.path
    }

    /// The pty slave itself (differs from [`Self::path`] when a stable link is kept); `None` in process.
    pub fn pty_path(&self) -> Option<&str> {
        match &self.mode {
            Some(Mode::Pty { slave_path }) => Some(slave_path),
            _ => None,
        }
    }

    /// A new in-process connection (the host end of a pipe); it replaces any previous one, like a reopened port.
    pub fn connect(&self) -> Result<PipeEnd, VirtualBoardError> {
        match &self.mode {
            Some(Mode::InProcess { connections }) => {
                let (host, board) = memory_pipe(&self.path);
                connections.send(board).map_err(|_| VirtualBoardError::Unplugged)?;
                Ok(host)
            }
            Some(Mode::Pty { .. }) => Err(VirtualBoardError::NotInProcess),
            None => Err(VirtualBoardError::Unplugged),
        }
    }

    /// Current each string carries now (PWM-averaged, no sensing noise), in mA: Top, Right, Bottom, Left.
    pub fn led_currents_ma(&self) -> [f32; CHANNEL_COUNT] {
        self.shared.currents()
    }

    /// A cheap handle for another thread (the simulated camera) to read the LED currents.
    pub fn led_currents(&self) -> LedCurrents {
        LedCurrents {
            shared: self.shared.clone(),
        }
    }

    /// The USB serial number a real board with this identity would report.
    pub fn serial_number(&self) -> String {
        self.options.identity.serial_number().as_str().to_owned()
    }

    /// Control steps run so far (1 per millisecond while running).
    pub fn control_steps(&self) -> u64 {
        self.shared.steps.load(Ordering::Relaxed)
    }

    /// Times a host started talking after the port was (re)opened.
    pub fn host_sessions(&self) -> u64 {
        self.shared.host_sessions.load(Ordering::Relaxed)
    }

    /// Telemetry frames dropped because the host did not read them (replies are never dropped).
    pub fn telemetry_dropped(&self) -> u64 {
        self.shared.telemetry_dropped.load(Ordering::Relaxed)
    }

    /// Times a SaveConfig wrote the virtual flash (a retried save writes once).
    pub fn flash_writes(&self) -> u64 {
        self.shared.flash_writes.load(Ordering::Relaxed)
    }

    /// Breaks (or repairs) an LED string, for fault-handling demos and tests.
    pub fn set_string_fault(&self, side: Side, fault: StringFault) {
        self.shared
            .pending_faults
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .push((side.index(), fault));
    }

    /// Pulls the cable: the board powers off and its port disappears (the host sees a disconnect).
    pub fn unplug(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
        // Dropping the mode closes the pty master or the connection channel.
        self.mode = None;
    }

    /// Plugs the cable back in: a cold boot from the virtual flash, on a new pty (same [`Self::path`] when a
    /// stable link path was given).
    pub fn replug(&mut self) -> Result<(), VirtualBoardError> {
        if self.thread.is_some() {
            return Ok(());
        }
        self.power_on()
    }

    pub fn is_plugged(&self) -> bool {
        self.thread.is_some()
    }
}

impl Drop for VirtualBoard {
    fn drop(&mut self) {
        self.unplug();
        if let Some(link) = &self.options.link_path {
            let _ = std::fs::remove_file(link);
        }
    }
}

/// Reads a virtual board's LED currents from any thread.
#[derive(Clone)]
pub struct LedCurrents {
    shared: Arc<Shared>,
}

impl LedCurrents {
    /// mA per string: Top, Right, Bottom, Left (0 while the board is unplugged).
    pub fn get(&self) -> [f32; CHANNEL_COUNT] {
        self.shared.currents()
    }
}

fn replace_symlink(target: &str, link: &Path) -> std::io::Result<()> {
    match std::fs::remove_file(link) {
        Ok(()) => {}
        Err(error) if error.kind() == std::io::ErrorKind::NotFound => {}
        Err(error) => return Err(error),
    }
    std::os::unix::fs::symlink(target, link)
}

#[cfg(test)]
mod tests;
