//! NUSense LED/controller board firmware (STM32F411CEU6): the hardware-free `Controller` of
//! nusense-firmware-core behind USB CDC-ACM, with TIM4 PWM, ADC1 sensing, the independent watchdog and the
//! configuration log in flash. The board itself is described in `board.rs`.
#![no_std]
#![no_main]

mod board;
mod config_store;
mod dfu;

use core::cell::RefCell;

use defmt_rtt as _;
use embassy_executor::Spawner;
use embassy_futures::join::join;
use embassy_stm32::gpio::Output;
use embassy_stm32::peripherals::{IWDG, USB_OTG_FS};
use embassy_stm32::usb::Driver;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::channel::Channel;
use embassy_time::{Duration, Instant, Ticker, Timer};
use embassy_usb::class::cdc_acm::{CdcAcmClass, Receiver, Sender, State};
use embassy_usb::driver::EndpointError;
use embassy_usb::UsbDevice;
use nusense_firmware_core::{Action, Controller, Identity};
use nusense_protocol::framing::MAX_FRAME_LEN;
use panic_probe as _;
use static_cell::StaticCell;

use crate::board::{Board, LedDrive, Sensors, CONTROL_PERIOD_US};

/// USB identity (pid.codes): the host finds the board by these, see nusense_board::discover.
const USB_VID: u16 = 0x1209;
const USB_PID: u16 = 0x4E55;
const USB_PRODUCT: &str = "NUSense LED board";
const USB_MANUFACTURER: &str = "NUSense";
const USB_PACKET: u16 = 64;

type Frame = heapless::Vec<u8, MAX_FRAME_LEN>;

/// The board's brain, shared by the control loop and the USB link (never held across an await).
static CONTROLLER: Mutex<CriticalSectionRawMutex, RefCell<Option<Controller>>> =
    Mutex::new(RefCell::new(None));
/// Frames on their way to the host. When the host does not read (port closed), new frames are dropped whole.
static TX_FRAMES: Channel<CriticalSectionRawMutex, Frame, 8> = Channel::new();
static WATCHDOG: Mutex<
    CriticalSectionRawMutex,
    RefCell<Option<IndependentWatchdog<'static, IWDG>>>,
> = Mutex::new(RefCell::new(None));

fn with_controller<R>(f: impl FnOnce(&mut Controller) -> R) -> Option<R> {
    CONTROLLER.lock(|c| c.borrow_mut().as_mut().map(f))
}

fn queue_frame(bytes: &[u8]) {
    if let Ok(frame) = Frame::from_slice(bytes) {
        if TX_FRAMES.try_send(frame).is_err() {
            defmt::trace!("tx queue full, frame dropped");
        }
    }
}

fn pet_watchdog() {
    WATCHDOG.lock(|w| {
        if let Some(w) = w.borrow_mut().as_mut() {
            w.pet();
        }
    });
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    dfu::jump_if_requested();
    let p = embassy_stm32::init(board::clock_config());
    let mut board = Board::new(p);
    let uid = embassy_stm32::uid::uid();
    let identity = Identity::new(
        env!("CARGO_PKG_VERSION"),
        env!("NUSENSE_GIT_HASH"),
        "nusense-f411",
        uid,
    );
    let config = config_store::load();
    defmt::info!(
        "NUSense board {} up, config {:?} mA enabled {:?}",
        embassy_stm32::uid::uid_hex(),
        config.setpoints_ma,
        config.enabled
    );
    CONTROLLER.lock(|c| c.replace(Some(Controller::new(identity, config))));
    board.watchdog.unleash();
    WATCHDOG.lock(|w| w.replace(Some(board.watchdog)));

    let mut usb_config = embassy_usb::Config::new(USB_VID, USB_PID);
    usb_config.manufacturer = Some(USB_MANUFACTURER);
    usb_config.product = Some(USB_PRODUCT);
    usb_config.serial_number = Some(embassy_stm32::uid::uid_hex());
    usb_config.max_power = 500;
    usb_config.max_packet_size_0 = 64;

    static CONFIG_DESCRIPTOR: StaticCell<[u8; 256]> = StaticCell::new();
    static BOS_DESCRIPTOR: StaticCell<[u8; 256]> = StaticCell::new();
    static CONTROL_BUF: StaticCell<[u8; 64]> = StaticCell::new();
    static CDC_STATE: StaticCell<State> = StaticCell::new();
    let mut builder = embassy_usb::Builder::new(
        board.usb,
        usb_config,
        CONFIG_DESCRIPTOR.init([0; 256]),
        BOS_DESCRIPTOR.init([0; 256]),
        &mut [],
        CONTROL_BUF.init([0; 64]),
    );
    let class = CdcAcmClass::new(&mut builder, CDC_STATE.init(State::new()), USB_PACKET);
    let usb = builder.build();

    spawner.spawn(usb_task(usb).expect("one usb task"));
    spawner.spawn(
        control_task(board.leds, board.sensors, board.status_led).expect("one control task"),
    );

    let (sender, receiver) = class.split();
    let mut flash = board.flash;
    join(
        serve_host_to_board(receiver, &mut flash),
        serve_board_to_host(sender),
    )
    .await;
}

#[embassy_executor::task]
async fn usb_task(mut usb: UsbDevice<'static, Driver<'static, USB_OTG_FS>>) -> ! {
    usb.run().await
}

/// The regulator: measure, step the controller, drive the gates, at 2 kHz. The only place that pets the
/// watchdog, so a stalled loop resets the board (and a reset leaves the gates off).
#[embassy_executor::task]
async fn control_task(mut leds: LedDrive, mut sensors: Sensors, mut status_led: Output<'static>) {
    let mut ticker = Ticker::every(Duration::from_micros(CONTROL_PERIOD_US));
    let mut step: u32 = 0;
    loop {
        ticker.next().await;
        let measurements = sensors.measure();
        let now_us = Instant::now().as_micros();
        let duty = with_controller(|c| {
            let duty = c.control_step(now_us, &measurements);
            c.poll_telemetry(now_us, &mut queue_frame);
            duty
        });
        match duty {
            Some(duty) => leds.set(duty),
            None => leds.all_off(),
        }
        pet_watchdog();
        // Heartbeat: 1 Hz blink while the loop runs.
        step = step.wrapping_add(1);
        if step % 1_000 == 0 {
            status_led.toggle();
        }
    }
}

/// `loop { wait_connection; serve }`: an unplugged or closed port is a normal event.
async fn serve_host_to_board(
    mut receiver: Receiver<'static, Driver<'static, USB_OTG_FS>>,
    flash: &mut embassy_stm32::flash::Flash<'static, embassy_stm32::flash::Blocking>,
) {
    loop {
        receiver.wait_connection().await;
        defmt::info!("host connected");
        with_controller(|c| c.on_link_reset());
        TX_FRAMES.clear();
        let _: Result<(), EndpointError> = async {
            let mut packet = [0u8; USB_PACKET as usize];
            loop {
                let n = receiver.read_packet(&mut packet).await?;
                let now_us = Instant::now().as_micros();
                let action = with_controller(|c| {
                    c.on_rx(&packet[..n], now_us, &mut queue_frame);
                    c.take_action()
                })
                .flatten();
                match action {
                    Some(Action::SaveConfig(blob)) => {
                        let saved = config_store::save(flash, &blob, pet_watchdog);
                        defmt::info!("configuration saved: {}", saved);
                        with_controller(|c| c.complete_save_config(saved, &mut queue_frame));
                    }
                    Some(Action::Reset) => {
                        // Let the Ack leave first.
                        Timer::after_millis(50).await;
                        cortex_m::peripheral::SCB::sys_reset();
                    }
                    Some(Action::EnterBootloader) => {
                        Timer::after_millis(50).await;
                        dfu::reboot_into_bootloader();
                    }
                    None => {}
                }
            }
        }
        .await;
        defmt::info!("host disconnected");
    }
}

async fn serve_board_to_host(mut sender: Sender<'static, Driver<'static, USB_OTG_FS>>) {
    loop {
        sender.wait_connection().await;
        let _: Result<(), EndpointError> = async {
            loop {
                let frame = TX_FRAMES.receive().await;
                for packet in frame.chunks(USB_PACKET as usize) {
                    sender.write_packet(packet).await?;
                }
                // A transfer that ends on a full packet needs a zero-length packet to end it on the host side.
                if frame.len() % USB_PACKET as usize == 0 {
                    sender.write_packet(&[]).await?;
                }
            }
        }
        .await;
    }
}
