//! The board's main loop on the host: the firmware core's [`Controller`] driving a simulated [`LedPlant`] at
//! 1 kHz of real time, fed with bytes from whichever host side it is plugged into.

use std::io;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::mpsc::Receiver;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use nusense_firmware_core::plant::{LedPlant, PlantParams, StringFault};
use nusense_firmware_core::{Action, BoardConfig, Controller, Identity, Measurements, CHANNEL_COUNT};

use super::pty::{MasterRead, PtyMaster};
use crate::{PipeEnd, Transport};

/// Control period: the regulator runs at 1 kHz, as on the real board.
pub(crate) const STEP_US: u64 = 1_000;
/// After a stall (a descheduled thread) at most this many steps are caught up; the rest of the gap is skipped.
const MAX_CATCH_UP_STEPS: u32 = 50;
/// Replies and telemetry waiting for a host that does not read are dropped beyond this.
const MAX_PENDING_TX: usize = 64 * 1024;

/// State the board thread shares with the [`super::VirtualBoard`] handle.
pub(crate) struct Shared {
    pub(crate) stop: AtomicBool,
    /// The PWM-averaged current per string (f32 bits), what the simulated camera sees.
    pub(crate) currents_ma: [AtomicU32; CHANNEL_COUNT],
    /// The configuration "flash": the blob of the last SaveConfig, restored at every (re)boot.
    pub(crate) flash: Mutex<Option<[u8; BoardConfig::BLOB_LEN]>>,
    pub(crate) steps: AtomicU64,
    pub(crate) tx_dropped_bytes: AtomicU64,
    pub(crate) host_sessions: AtomicU64,
    /// String faults to inject into the plant at the next step.
    pub(crate) pending_faults: Mutex<Vec<(usize, StringFault)>>,
}

impl Shared {
    pub(crate) fn new(flash: Option<[u8; BoardConfig::BLOB_LEN]>) -> Self {
        Self {
            stop: AtomicBool::new(false),
            currents_ma: Default::default(),
            flash: Mutex::new(flash),
            steps: AtomicU64::new(0),
            tx_dropped_bytes: AtomicU64::new(0),
            host_sessions: AtomicU64::new(0),
            pending_faults: Mutex::new(Vec::new()),
        }
    }

    pub(crate) fn currents(&self) -> [f32; CHANNEL_COUNT] {
        std::array::from_fn(|ch| f32::from_bits(self.currents_ma[ch].load(Ordering::Relaxed)))
    }

    fn flash(&self) -> std::sync::MutexGuard<'_, Option<[u8; BoardConfig::BLOB_LEN]>> {
        self.flash.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

/// Where the host is: a pty master, or in-memory pipes handed over by [`super::VirtualBoard::connect`].
pub(crate) enum HostSide {
    Pty(PtyMaster),
    Pipe {
        current: Option<PipeEnd>,
        incoming: Receiver<PipeEnd>,
    },
}

impl HostSide {
    fn read(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<MasterRead> {
        match self {
            HostSide::Pty(master) => master.read(buf, timeout),
            HostSide::Pipe { current, incoming } => {
                // A newer connection replaces the current one, like a host closing and reopening the port: report
                // the hang-up once so the board resets its link state before the new session talks.
                if let Some(newest) = incoming.try_iter().last() {
                    let replaced = current.replace(newest).is_some();
                    if replaced {
                        return Ok(MasterRead::HostAbsent);
                    }
                }
                let Some(pipe) = current else {
                    std::thread::sleep(timeout.min(Duration::from_millis(1)));
                    return Ok(MasterRead::HostAbsent);
                };
                match pipe.read_timeout(buf, timeout) {
                    Ok(0) => Ok(MasterRead::Nothing),
                    Ok(n) => Ok(MasterRead::Data(n)),
                    Err(_) => {
                        *current = None;
                        Ok(MasterRead::HostAbsent)
                    }
                }
            }
        }
    }

    /// Bytes taken now; the rest stays queued (or is dropped by the caller when too much piles up).
    fn write(&mut self, bytes: &[u8]) -> io::Result<usize> {
        match self {
            HostSide::Pty(master) => master.write(bytes),
            HostSide::Pipe {
                current: Some(pipe), ..
            } => match pipe.write_all_bytes(bytes) {
                Ok(()) => Ok(bytes.len()),
                Err(_) => Ok(0),
            },
            HostSide::Pipe { current: None, .. } => Ok(0),
        }
    }
}

pub(crate) struct BootParams {
    pub(crate) identity: Identity,
    pub(crate) default_config: BoardConfig,
    pub(crate) plant: PlantParams,
    pub(crate) noise_seed: u64,
}

/// Runs the board until `shared.stop` is set. A cold boot: the configuration comes from the flash blob.
pub(crate) fn run(mut host: HostSide, boot: BootParams, shared: &Shared) {
    let config = shared
        .flash()
        .and_then(|blob| BoardConfig::from_blob(&blob).ok())
        .unwrap_or(boot.default_config);
    let mut controller = Controller::new(boot.identity.clone(), config);
    let mut plant = LedPlant::new(boot.plant, boot.noise_seed);
    let mut measurements: Measurements = plant.step([0.0; CHANNEL_COUNT], 1);
    let started = Instant::now();
    let now_us = || started.elapsed().as_micros() as u64;
    let mut last_step_us = 0u64;
    let mut host_present = false;
    let mut pending_tx: Vec<u8> = Vec::new();
    let mut buf = [0u8; 1024];

    while !shared.stop.load(Ordering::Relaxed) {
        let wait = Duration::from_micros((last_step_us + STEP_US).saturating_sub(now_us()));
        match host.read(&mut buf, wait) {
            Ok(MasterRead::Data(n)) => {
                if !host_present {
                    host_present = true;
                    shared.host_sessions.fetch_add(1, Ordering::Relaxed);
                }
                controller.on_rx(&buf[..n], now_us(), &mut |frame| pending_tx.extend_from_slice(frame));
            }
            Ok(MasterRead::Nothing) => {}
            Ok(MasterRead::HostAbsent) => {
                if host_present {
                    // The port was closed: like a USB disconnect, the next session starts with a handshake.
                    host_present = false;
                    controller.on_link_reset();
                    pending_tx.clear();
                }
                // A pty without a reader reports HUP at once; do not spin.
                std::thread::sleep(wait.min(Duration::from_micros(500)));
            }
            Err(error) => {
                tracing::warn!(target: "nusense_board::virtual_board", %error, "host side failed; board stops");
                return;
            }
        }

        let now = now_us();
        let mut steps = 0;
        while last_step_us + STEP_US <= now && steps < MAX_CATCH_UP_STEPS {
            last_step_us += STEP_US;
            for (channel, fault) in shared
                .pending_faults
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .drain(..)
            {
                plant.set_fault(channel, fault);
            }
            let duty = controller.control_step(last_step_us, &measurements);
            measurements = plant.step(duty, STEP_US as u32);
            controller.poll_telemetry(last_step_us, &mut |frame| pending_tx.extend_from_slice(frame));
            steps += 1;
        }
        if steps == MAX_CATCH_UP_STEPS {
            last_step_us = now;
        }
        if steps > 0 {
            shared.steps.fetch_add(u64::from(steps), Ordering::Relaxed);
            for (slot, current) in shared.currents_ma.iter().zip(plant.true_current_ma()) {
                slot.store(current.to_bits(), Ordering::Relaxed);
            }
        }

        while let Some(action) = controller.take_action() {
            match action {
                Action::SaveConfig(blob) => {
                    *shared.flash() = Some(blob);
                    controller.complete_save_config(true, &mut |frame| pending_tx.extend_from_slice(frame));
                }
                // The Ack is queued; send it, then "reboot" from flash. A virtual board has no bootloader, so
                // EnterBootloader reboots into the same firmware.
                Action::Reset | Action::EnterBootloader => {
                    flush(&mut host, &mut pending_tx, shared);
                    let config = shared
                        .flash()
                        .and_then(|blob| BoardConfig::from_blob(&blob).ok())
                        .unwrap_or(boot.default_config);
                    controller = Controller::new(boot.identity.clone(), config);
                }
            }
        }
        if host_present {
            flush(&mut host, &mut pending_tx, shared);
        }
    }
    for slot in &shared.currents_ma {
        slot.store(0f32.to_bits(), Ordering::Relaxed);
    }
}

fn flush(host: &mut HostSide, pending_tx: &mut Vec<u8>, shared: &Shared) {
    if pending_tx.is_empty() {
        return;
    }
    let written = host.write(pending_tx).unwrap_or(0);
    pending_tx.drain(..written);
    if pending_tx.len() > MAX_PENDING_TX {
        shared
            .tx_dropped_bytes
            .fetch_add(pending_tx.len() as u64, Ordering::Relaxed);
        pending_tx.clear();
    }
}
