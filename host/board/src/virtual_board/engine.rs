//! The board's main loop on the host: the firmware core's [`Controller`] driving a simulated [`LedPlant`] at
//! 1 kHz of real time, fed with bytes from whichever host side it is plugged into.
//!
//! Modelled as on the real board: the configuration lives in the firmware core's two-sector store (on RAM that
//! behaves like NOR flash); the port counts as USB-configured from power-on; an open pty (or pipe) is DTR, so
//! telemetry stops when the host closes it; replies and telemetry leave through separate queues, replies first
//! and never dropped, telemetry dropped oldest-first when the host does not read.

use std::collections::VecDeque;
use std::io;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::mpsc::Receiver;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use nusense_firmware_core::plant::{LedPlant, PlantParams, StringFault};
use nusense_firmware_core::{
    Action, BoardConfig, ConfigStore, Controller, Identity, Measurements, PowerState, RamFlash, CHANNEL_COUNT,
};

use super::pty::{MasterRead, PtyMaster};
use crate::{PipeEnd, Transport};

/// Control period: the regulator runs at 1 kHz (the slowest rate the firmware core allows; the real board runs
/// at 2 kHz), which a host thread keeps up with.
pub(crate) const STEP_US: u64 = 1_000;
/// After a stall (a descheduled thread) at most this many steps are caught up; the rest of the gap is skipped.
const MAX_CATCH_UP_STEPS: u32 = 50;
/// Telemetry frames waiting for a host that does not read; older ones are dropped beyond this (the real board
/// keeps two).
const MAX_QUEUED_TELEMETRY: usize = 8;
/// The configuration flash: two sectors as on the F411 (sectors 1 and 2).
const FLASH_SECTOR_LEN: usize = 16 * 1024;

/// State the board thread shares with the [`super::VirtualBoard`] handle.
pub(crate) struct Shared {
    pub(crate) stop: AtomicBool,
    /// The PWM-averaged current per string (f32 bits), what the simulated camera sees.
    pub(crate) currents_ma: [AtomicU32; CHANNEL_COUNT],
    /// The configuration flash (two sectors of the firmware core's store), kept across (re)boots.
    pub(crate) flash: Mutex<Vec<u8>>,
    pub(crate) steps: AtomicU64,
    /// Telemetry frames dropped because the host did not read them.
    pub(crate) telemetry_dropped: AtomicU64,
    /// Times a SaveConfig wrote the flash.
    pub(crate) flash_writes: AtomicU64,
    pub(crate) host_sessions: AtomicU64,
    /// String faults to inject into the plant at the next step.
    pub(crate) pending_faults: Mutex<Vec<(usize, StringFault)>>,
}

impl Shared {
    /// A board whose configuration flash is erased.
    pub(crate) fn new() -> Self {
        Self {
            stop: AtomicBool::new(false),
            currents_ma: Default::default(),
            flash: Mutex::new(vec![0xFF; 2 * FLASH_SECTOR_LEN]),
            steps: AtomicU64::new(0),
            telemetry_dropped: AtomicU64::new(0),
            flash_writes: AtomicU64::new(0),
            host_sessions: AtomicU64::new(0),
            pending_faults: Mutex::new(Vec::new()),
        }
    }

    pub(crate) fn currents(&self) -> [f32; CHANNEL_COUNT] {
        std::array::from_fn(|ch| f32::from_bits(self.currents_ma[ch].load(Ordering::Relaxed)))
    }

    fn flash(&self) -> std::sync::MutexGuard<'_, Vec<u8>> {
        self.flash.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// A cold boot: the controller restored from the flash (or `default` on a blank one), port configured.
    fn boot(&self, boot: &BootParams) -> Controller {
        let saved = with_store(&mut self.flash(), |store| store.load().ok().flatten());
        let mut controller = Controller::new(boot.identity.clone(), saved.map_or(boot.default_config, |r| r.config))
            .with_saved_request_id(saved.map(|r| r.request_id));
        controller.set_power_state(PowerState::Configured);
        controller.set_host_present(false);
        controller
    }

    fn save(&self, config: &BoardConfig, request_id: u32) -> bool {
        let saved = with_store(&mut self.flash(), |store| store.save(config, request_id, || {}).is_ok());
        if saved {
            self.flash_writes.fetch_add(1, Ordering::Relaxed);
        }
        saved
    }
}

fn with_store<R>(flash: &mut [u8], f: impl FnOnce(&mut ConfigStore<RamFlash<'_, FLASH_SECTOR_LEN>>) -> R) -> R {
    let mut store =
        ConfigStore::new(RamFlash::new(flash), [0, FLASH_SECTOR_LEN as u32]).expect("two whole sectors of RAM flash");
    f(&mut store)
}

/// What the board sends: replies on a path of their own, ahead of telemetry and never dropped; telemetry
/// bounded. A frame that was partly written finishes before anything else goes.
#[derive(Default)]
struct Outbox {
    in_flight: Vec<u8>,
    replies: VecDeque<Vec<u8>>,
    telemetry: VecDeque<Vec<u8>>,
}

impl Outbox {
    fn reply(&mut self, frame: &[u8]) {
        self.replies.push_back(frame.to_vec());
    }

    fn telemetry(&mut self, frame: &[u8], shared: &Shared) {
        if self.telemetry.len() == MAX_QUEUED_TELEMETRY {
            self.telemetry.pop_front();
            shared.telemetry_dropped.fetch_add(1, Ordering::Relaxed);
        }
        self.telemetry.push_back(frame.to_vec());
    }

    /// The host went away: nothing queued is for the next session.
    fn clear(&mut self) {
        *self = Self::default();
    }

    /// Writes what the host side takes now.
    fn flush(&mut self, host: &mut HostSide) {
        loop {
            if self.in_flight.is_empty() {
                match self.replies.pop_front().or_else(|| self.telemetry.pop_front()) {
                    Some(frame) => self.in_flight = frame,
                    None => return,
                }
            }
            let written = host.write(&self.in_flight).unwrap_or(0);
            self.in_flight.drain(..written);
            if !self.in_flight.is_empty() {
                return;
            }
        }
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

/// Runs the board until `shared.stop` is set. A cold boot: the configuration comes from the flash.
pub(crate) fn run(mut host: HostSide, boot: BootParams, shared: &Shared) {
    let mut controller = shared.boot(&boot);
    let mut plant = LedPlant::new(boot.plant, boot.noise_seed);
    let mut measurements: Measurements = plant.step([0.0; CHANNEL_COUNT], 1);
    let started = Instant::now();
    let now_us = || started.elapsed().as_micros() as u64;
    let mut last_step_us = 0u64;
    let mut host_present = false;
    let mut outbox = Outbox::default();
    let mut buf = [0u8; 1024];

    while !shared.stop.load(Ordering::Relaxed) {
        let wait = Duration::from_micros((last_step_us + STEP_US).saturating_sub(now_us()));
        match host.read(&mut buf, wait) {
            Ok(MasterRead::Data(n)) => {
                if !host_present {
                    // The port was opened (DTR up): a new session.
                    host_present = true;
                    controller.set_host_present(true);
                    shared.host_sessions.fetch_add(1, Ordering::Relaxed);
                }
                controller.on_rx(&buf[..n], now_us(), &mut |frame| outbox.reply(frame));
            }
            Ok(MasterRead::Nothing) => {}
            Ok(MasterRead::HostAbsent) => {
                if host_present {
                    // The port was closed (DTR down): the stream stops and the next session shakes hands again.
                    host_present = false;
                    controller.set_host_present(false);
                    outbox.clear();
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
            controller.poll_telemetry(last_step_us, &mut |frame| outbox.telemetry(frame, shared));
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
                Action::SaveConfig { config, request_id } => {
                    let saved = shared.save(&config, request_id);
                    controller.complete_save_config(saved, &mut |frame| outbox.reply(frame));
                }
                // The Ack is queued; send it, then "reboot" from flash. A virtual board has no bootloader, so
                // EnterBootloader reboots into the same firmware.
                Action::Reset | Action::EnterBootloader => {
                    outbox.flush(&mut host);
                    controller = shared.boot(&boot);
                    host_present = false;
                }
            }
        }
        if host_present {
            outbox.flush(&mut host);
        }
    }
    for slot in &shared.currents_ma {
        slot.store(0f32.to_bits(), Ordering::Relaxed);
    }
}
