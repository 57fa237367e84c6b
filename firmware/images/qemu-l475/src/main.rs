//! The NUSense board firmware on QEMU's b-l475e-iot01a machine: the same [`Controller`] as the real board,
//! talking over USART1 instead of USB, with the simulated LED plant in place of PWM and ADC.
//!
//!     qemu-system-arm -M b-l475e-iot01a -nographic -monitor none -serial pty -kernel nusense-qemu-l475
#![no_std]
#![no_main]

mod saved_config;
mod time_driver;
mod usart;

use defmt_rtt as _;
use embassy_executor::Spawner;
use embassy_futures::select::{select, Either};
use embassy_time::{Duration, Instant, Ticker};
use nusense_firmware_core::plant::{LedPlant, PlantParams};
use nusense_firmware_core::{Action, Controller, Identity};
use panic_halt as _;

/// MSI at reset: QEMU's RCC model starts the L475 there, and nothing here needs more.
const CORE_CLOCK_HZ: u32 = 4_000_000;
const BAUD: u32 = 115_200;
/// The regulator's rate, as on the real board.
const CONTROL_PERIOD: Duration = Duration::from_micros(1_000);

/// There is no factory unique id to read under QEMU (the system memory is not modelled): a fixed one, "QEMU-L475-VG".
const QEMU_UID: [u8; 12] = *b"QEMU-L475-VG";

#[embassy_executor::main]
async fn main(_spawner: Spawner) {
    let core = cortex_m::Peripherals::take().unwrap();
    time_driver::start(core.SYST, CORE_CLOCK_HZ);
    usart::init(CORE_CLOCK_HZ, BAUD);

    let identity = Identity::new(
        env!("CARGO_PKG_VERSION"),
        env!("NUSENSE_GIT_HASH"),
        "qemu-l475",
        QEMU_UID,
    );
    let mut controller = Controller::new(identity, saved_config::restore());
    let mut plant = LedPlant::new(PlantParams::default(), 0x5EED);

    let mut ticker = Ticker::every(CONTROL_PERIOD);
    let mut last_step = Instant::now();
    let mut rx = [0u8; 64];
    let tx = &mut |frame: &[u8]| usart::write(frame);
    loop {
        match select(ticker.next(), usart::read(&mut rx)).await {
            Either::First(()) => {
                let now = Instant::now();
                let dt_us = (now - last_step).as_micros() as u32;
                last_step = now;
                let measurements = plant.step(controller.duty(), dt_us);
                controller.control_step(now.as_micros(), &measurements);
                controller.poll_telemetry(now.as_micros(), tx);
            }
            Either::Second(n) => {
                controller.on_rx(&rx[..n], Instant::now().as_micros(), tx);
                match controller.take_action() {
                    Some(Action::SaveConfig(blob)) => {
                        saved_config::store(&blob);
                        controller.complete_save_config(true, tx);
                    }
                    Some(Action::Reset) => cortex_m::peripheral::SCB::sys_reset(),
                    // No ROM bootloader under emulation: the request is acknowledged and the board carries on.
                    Some(Action::EnterBootloader) | None => {}
                }
            }
        }
    }
}
