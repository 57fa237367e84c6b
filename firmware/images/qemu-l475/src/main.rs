//! The NUSense board firmware on QEMU's b-l475e-iot01a machine: the same [`Controller`] as the real board,
//! talking over USART1 instead of USB, with the simulated LED plant in place of PWM and ADC.
//!
//!     qemu-system-arm -M b-l475e-iot01a -nographic -monitor none -serial pty -kernel nusense-qemu-l475
//!
//! What differs from the real board, and why:
//! - no USB: the port counts as configured from boot (a UART has no configuration to wait for);
//! - no DTR on a UART: the host counts as present while it has sent something within [`HOST_SILENCE_LIMIT_US`]
//!   (the host's link sends a lone 0x00 at least every second while it has the port open), so telemetry stops
//!   when the host goes away, as it does on USB when DTR drops. Silence only pauses telemetry: it does not end the
//!   session (handshake, stream period), because a UART cannot tell a closed port from a host that was starved of
//!   CPU for a few seconds, and a USB board keeps the session of a stalled host whose port stays open. A new host
//!   starts its session with a Hello, as every host does;
//! - replies and telemetry both leave through blocking writes to USART1 (which QEMU makes immediate): a reply is
//!   written as soon as its request is handled, never queued behind telemetry, so telemetry cannot crowd it out;
//! - the regulator runs at 1 kHz (the real board: 2 kHz) on the simulated plant, from SysTick time;
//! - the plant's true string currents go out on USART2 every 20 ms: what a camera looking at the pad would see,
//!   independent of what the firmware measures and reports (the host's hil check compares the two). Each line
//!   carries the board time it describes, the clock telemetry is stamped with, so the host can look at the light
//!   of the moment a telemetry frame describes rather than at whatever line its reader took last.
#![no_std]
#![no_main]

mod saved_config;
mod time_driver;
mod usart;

use defmt_rtt as _;
use embassy_executor::Spawner;
use embassy_futures::select::{select, Either};
use embassy_time::{Duration, Instant, Ticker};
use nusense_firmware_core::link::HostLease;
use nusense_firmware_core::plant::{LedPlant, PlantParams};
use nusense_firmware_core::{Action, Controller, Identity, PowerState};
use panic_halt as _;

/// MSI at reset: QEMU's RCC model starts the L475 there, and nothing here needs more.
const CORE_CLOCK_HZ: u32 = 4_000_000;
const BAUD: u32 = 115_200;
/// The regulator's rate under emulation: half the real board's 2 kHz, ample for the simulated plant.
const CONTROL_PERIOD: Duration = Duration::from_micros(1_000);
/// Host silence after which telemetry pauses until the host is heard again (its keepalive comes every second).
const HOST_SILENCE_LIMIT_US: u64 = 3_000_000;
/// How often the true string currents go out on USART2 (the "camera's view", see `usart::light`).
const LIGHT_REPORT_EVERY_STEPS: u32 = 20;

/// There is no factory unique id to read under QEMU (the system memory is not modelled): a fixed one, "QEMU-L475-VG".
const QEMU_UID: [u8; 12] = *b"QEMU-L475-VG";

#[embassy_executor::main]
async fn main(_spawner: Spawner) {
    let core = cortex_m::Peripherals::take().unwrap();
    time_driver::start(core.SYST, CORE_CLOCK_HZ);
    usart::init(CORE_CLOCK_HZ, BAUD);
    usart::light::init(CORE_CLOCK_HZ, BAUD);

    let identity = Identity::new(
        env!("CARGO_PKG_VERSION"),
        env!("NUSENSE_GIT_HASH"),
        "qemu-l475",
        QEMU_UID,
    );
    let mut store = saved_config::take();
    let saved = store.load().ok().flatten();
    let mut controller = Controller::new(identity, saved.map(|r| r.config).unwrap_or_default())
        .with_saved_request_id(saved.map(|r| r.request_id));
    controller.set_power_state(PowerState::Configured);
    let mut lease = HostLease::new(HOST_SILENCE_LIMIT_US);
    controller.set_host_present(false);
    let mut plant = LedPlant::new(PlantParams::default(), 0x5EED);

    let mut ticker = Ticker::every(CONTROL_PERIOD);
    let mut last_step = Instant::now();
    let mut rx = [0u8; 64];
    let mut step: u32 = 0;
    let tx = &mut |frame: &[u8]| usart::write(frame);
    loop {
        match select(ticker.next(), usart::read(&mut rx)).await {
            Either::First(()) => {
                let now = Instant::now();
                let now_us = now.as_micros();
                let dt_us = (now - last_step).as_micros() as u32;
                last_step = now;
                let measurements = plant.step(controller.duty(), dt_us);
                controller.control_step(now_us, &measurements);
                if lease.is_present(now_us) {
                    controller.poll_telemetry(now_us, tx);
                }
                step = step.wrapping_add(1);
                if step.is_multiple_of(LIGHT_REPORT_EVERY_STEPS) {
                    usart::light::report(now_us, plant.true_current_ma());
                }
            }
            Either::Second(n) => {
                let now_us = Instant::now().as_micros();
                lease.heard_from(now_us);
                // The first bytes after boot open the session; later ones change nothing here.
                controller.set_host_present(true);
                controller.on_rx(&rx[..n], now_us, tx);
                match controller.take_action() {
                    Some(Action::SaveConfig { config, request_id }) => {
                        let saved = store.save(&config, request_id, || {}).is_ok();
                        controller.complete_save_config(saved, tx);
                    }
                    Some(Action::Reset) => cortex_m::peripheral::SCB::sys_reset(),
                    // No ROM bootloader under emulation: the request is acknowledged and the board carries on.
                    Some(Action::EnterBootloader) | None => {}
                }
            }
        }
    }
}
