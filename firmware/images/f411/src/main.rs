//! NUSense LED/controller board firmware (STM32F411CEU6): the hardware-free `Controller` of
//! nusense-firmware-core behind USB CDC-ACM, with TIM4 PWM, ADC1 sensing, the independent watchdog and the
//! configuration store in flash sectors 1 and 2. The board itself is described in `board.rs`.
//!
//! Two executors: the control loop runs alone in an interrupt executor (USART6's vector, unused otherwise) at a
//! priority above USB, so nothing in thread mode (USB, logging, flash) delays it; the USB link runs in the
//! thread-mode executor.
#![no_std]
#![no_main]

mod fault_handlers;

use core::cell::RefCell;

use defmt_rtt as _;
use embassy_executor::{InterruptExecutor, Spawner};
use embassy_futures::join::join3;
use embassy_futures::select::{select, Either};
use embassy_stm32::gpio::Output;
use embassy_stm32::interrupt::{self, InterruptExt, Priority};
use embassy_stm32::peripherals::{IWDG, USB_OTG_FS};
use embassy_stm32::usb::Driver;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::channel::Channel;
use embassy_time::{Duration, Ticker, Timer};
use embassy_usb::class::cdc_acm::{CdcAcmClass, ControlChanged, Receiver, Sender, State};
use embassy_usb::driver::EndpointError;
use embassy_usb::{Handler, UsbDevice};
use nusense_f411::board::{self, Board, LedDrive, Sensors, CONTROL_PERIOD_US, HEARTBEAT_STEPS};
use nusense_f411::flash::{ConfigFlash, SECTOR_LEN};
use nusense_f411::{clock, dfu};
use nusense_firmware_core::limits::USB_CONFIGURED_MA;
use nusense_firmware_core::{Action, ConfigStore, Controller, Identity, PowerState};
use nusense_protocol::framing::MAX_FRAME_LEN;
use static_cell::StaticCell;

/// USB identity (pid.codes): the host finds the board by these, see nusense_board::discover.
const USB_VID: u16 = 0x1209;
const USB_PID: u16 = 0x4E55;
const USB_PRODUCT: &str = "NUSense LED board";
const USB_MANUFACTURER: &str = "NUSense";
const USB_PACKET: u16 = 64;
/// The smallest frame (a one-byte sequence number, a one-byte request tag, CRC, COBS code, delimiter): a packet
/// holds at most this many requests, so at most this many replies come out of one.
const MIN_FRAME_LEN: usize = 8;
const MAX_REPLIES_PER_PACKET: usize = USB_PACKET as usize / MIN_FRAME_LEN;

type Frame = heapless::Vec<u8, MAX_FRAME_LEN>;

/// The board's brain, shared by the control loop and the USB link (never held across an await).
static CONTROLLER: Mutex<CriticalSectionRawMutex, RefCell<Option<Controller>>> = Mutex::new(RefCell::new(None));
/// Replies on their own path: the receiving side waits for room here (and the host's next request waits in USB
/// flow control), so a reply is never dropped, and telemetry cannot take its place.
static REPLIES: Channel<CriticalSectionRawMutex, Frame, 4> = Channel::new();
/// Telemetry: when the host reads too slowly, new frames are dropped whole.
static TELEMETRY: Channel<CriticalSectionRawMutex, Frame, 2> = Channel::new();
static WATCHDOG: Mutex<CriticalSectionRawMutex, RefCell<Option<IndependentWatchdog<'static, IWDG>>>> =
    Mutex::new(RefCell::new(None));
static CONTROL_EXECUTOR: InterruptExecutor = InterruptExecutor::new();

fn with_controller<R>(f: impl FnOnce(&mut Controller) -> R) -> Option<R> {
    CONTROLLER.lock(|c| c.borrow_mut().as_mut().map(f))
}

fn queue_telemetry(bytes: &[u8]) {
    if let Ok(frame) = Frame::from_slice(bytes) {
        if TELEMETRY.try_send(frame).is_err() {
            defmt::trace!("telemetry queue full, frame dropped");
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

#[embassy_stm32::interrupt]
unsafe fn USART6() {
    // SAFETY: the executor was started on this interrupt, and this is its only handler.
    unsafe { CONTROL_EXECUTOR.on_interrupt() }
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    dfu::jump_if_requested();
    let p = embassy_stm32::init(board::clock_config());
    board::freeze_watchdog_when_halted();
    let mut core = cortex_m::Peripherals::take().expect("core peripherals, taken once");
    clock::start(&mut core.DCB, &mut core.DWT);
    let mut board = Board::new(p);
    let identity = Identity::new(
        env!("CARGO_PKG_VERSION"),
        env!("NUSENSE_GIT_HASH"),
        "nusense-f411",
        embassy_stm32::uid::uid(),
    );
    let mut store = ConfigStore::new(board.flash, [0, SECTOR_LEN]).expect("sectors 1 and 2 fit the flash");
    let saved = store.load().ok().flatten();
    let config = saved.map(|record| record.config).unwrap_or_default();
    defmt::info!(
        "NUSense board {} up, config {:?} mA enabled {:?}, VDDA {} mV",
        embassy_stm32::uid::uid_hex(),
        config.setpoints_ma,
        config.enabled,
        board.sensors.vdda_mv()
    );
    let mut controller = Controller::new(identity, config).with_saved_request_id(saved.map(|r| r.request_id));
    // No host until DTR says so.
    controller.set_host_present(false);
    CONTROLLER.lock(|c| c.replace(Some(controller)));
    board.watchdog.unleash();
    WATCHDOG.lock(|w| w.replace(Some(board.watchdog)));

    let mut usb_config = embassy_usb::Config::new(USB_VID, USB_PID);
    usb_config.manufacturer = Some(USB_MANUFACTURER);
    usb_config.product = Some(USB_PRODUCT);
    usb_config.serial_number = Some(embassy_stm32::uid::uid_hex());
    // The LEDs light only once configured and stay within the budget, so the board draws at most this.
    usb_config.max_power = USB_CONFIGURED_MA;
    usb_config.self_powered = false;
    usb_config.max_packet_size_0 = 64;

    static CONFIG_DESCRIPTOR: StaticCell<[u8; 256]> = StaticCell::new();
    static BOS_DESCRIPTOR: StaticCell<[u8; 256]> = StaticCell::new();
    static CONTROL_BUF: StaticCell<[u8; 64]> = StaticCell::new();
    static CDC_STATE: StaticCell<State> = StaticCell::new();
    static POWER_HANDLER: StaticCell<PowerHandler> = StaticCell::new();
    let mut builder = embassy_usb::Builder::new(
        board.usb,
        usb_config,
        CONFIG_DESCRIPTOR.init([0; 256]),
        BOS_DESCRIPTOR.init([0; 256]),
        &mut [],
        CONTROL_BUF.init([0; 64]),
    );
    builder.handler(POWER_HANDLER.init(PowerHandler { configured: false }));
    let class = CdcAcmClass::new(&mut builder, CDC_STATE.init(State::new()), USB_PACKET);
    let usb = builder.build();

    // The control loop above USB; the time driver (TIM2) stays above both, since it wakes the loop.
    interrupt::OTG_FS.set_priority(Priority::P3);
    interrupt::USART6.set_priority(Priority::P2);
    let control = CONTROL_EXECUTOR.start(interrupt::USART6);
    control.spawn(control_task(board.leds, board.sensors, board.status_led).expect("one control task"));
    spawner.spawn(usb_task(usb).expect("one usb task"));

    let (sender, receiver, control_lines) = class.split_with_control();
    join3(
        serve_host_to_board(receiver, &mut store),
        serve_board_to_host(sender),
        follow_dtr(control_lines),
    )
    .await;
}

#[embassy_executor::task]
async fn usb_task(mut usb: UsbDevice<'static, Driver<'static, USB_OTG_FS>>) -> ! {
    usb.run().await
}

/// What USB grants, passed on to the controller: the LEDs light only while configured and not suspended.
struct PowerHandler {
    configured: bool,
}

impl PowerHandler {
    fn report(&self, power: PowerState) {
        defmt::info!("USB power state {}", defmt::Debug2Format(&power));
        with_controller(|c| c.set_power_state(power));
    }
}

impl Handler for PowerHandler {
    fn enabled(&mut self, enabled: bool) {
        if !enabled {
            self.configured = false;
            self.report(PowerState::Unconfigured);
        }
    }

    fn reset(&mut self) {
        self.configured = false;
        self.report(PowerState::Unconfigured);
    }

    fn configured(&mut self, configured: bool) {
        self.configured = configured;
        self.report(if configured {
            PowerState::Configured
        } else {
            PowerState::Unconfigured
        });
    }

    fn suspended(&mut self, suspended: bool) {
        self.report(match (suspended, self.configured) {
            (true, _) => PowerState::Suspended,
            (false, true) => PowerState::Configured,
            (false, false) => PowerState::Unconfigured,
        });
    }
}

/// The regulator: measure, step the controller, drive the gates, at 2 kHz. The only place that feeds the
/// watchdog, so a stalled loop resets the board (and a reset leaves the gates off).
#[embassy_executor::task]
async fn control_task(mut leds: LedDrive, mut sensors: Sensors, mut status_led: Output<'static>) {
    let mut ticker = Ticker::every(Duration::from_micros(CONTROL_PERIOD_US));
    let mut step: u32 = 0;
    loop {
        ticker.next().await;
        let now_us = clock::now_us();
        let measurements = sensors.measure();
        let duty = with_controller(|c| {
            let duty = c.control_step(now_us, &measurements);
            c.poll_telemetry(now_us, &mut queue_telemetry);
            duty
        });
        match duty {
            Some(duty) => leds.set(duty),
            None => leds.all_off(),
        }
        pet_watchdog();
        step = step.wrapping_add(1);
        if step.is_multiple_of(HEARTBEAT_STEPS) {
            status_led.toggle();
        }
    }
}

/// Opening or closing the port (DTR) starts or ends a host session.
async fn follow_dtr(control: ControlChanged<'static>) {
    loop {
        control.control_changed().await;
        let present = control.dtr();
        defmt::info!("DTR {}", present);
        with_controller(|c| c.set_host_present(present));
        if !present {
            TELEMETRY.clear();
        }
    }
}

/// `loop { wait_connection; serve }`: an unplugged or closed port is a normal event.
async fn serve_host_to_board(
    mut receiver: Receiver<'static, Driver<'static, USB_OTG_FS>>,
    store: &mut ConfigStore<ConfigFlash>,
) {
    loop {
        receiver.wait_connection().await;
        defmt::info!("USB link up");
        // DTR as it stands now; later changes come through `follow_dtr`.
        let present = receiver.dtr();
        with_controller(|c| c.set_host_present(present));
        let _: Result<(), EndpointError> = async {
            let mut packet = [0u8; USB_PACKET as usize];
            loop {
                let n = receiver.read_packet(&mut packet).await?;
                let now_us = clock::now_us();
                let mut replies: heapless::Vec<Frame, MAX_REPLIES_PER_PACKET> = heapless::Vec::new();
                let action = with_controller(|c| {
                    c.on_rx(&packet[..n], now_us, &mut |bytes: &[u8]| {
                        if let Ok(frame) = Frame::from_slice(bytes) {
                            let _ = replies.push(frame);
                        }
                    });
                    c.take_action()
                })
                .flatten();
                for reply in replies {
                    REPLIES.send(reply).await;
                }
                match action {
                    Some(Action::SaveConfig { config, request_id }) => {
                        let saved = save_config(store, &config, request_id);
                        let mut reply = None;
                        with_controller(|c| {
                            c.complete_save_config(saved, &mut |bytes: &[u8]| reply = Frame::from_slice(bytes).ok())
                        });
                        if let Some(reply) = reply {
                            REPLIES.send(reply).await;
                        }
                    }
                    Some(Action::Reset) => {
                        // Let the Ack leave first.
                        Timer::after_millis(50).await;
                        board::force_gates_low();
                        cortex_m::peripheral::SCB::sys_reset();
                    }
                    Some(Action::EnterBootloader) => {
                        Timer::after_millis(50).await;
                        board::force_gates_low();
                        dfu::reboot_into_bootloader();
                    }
                    None => {}
                }
            }
        }
        .await;
        defmt::info!("USB link down");
        // Unplugged or reset: no host until the next configuration and DTR.
        with_controller(|c| c.set_host_present(false));
    }
}

/// Writes the record; around a sector erase (the CPU stalls on every flash fetch for up to 500 ms, so the control
/// loop cannot run) the gates are held low and the watchdog is fed right before and after.
fn save_config(store: &mut ConfigStore<ConfigFlash>, config: &nusense_firmware_core::BoardConfig, id: u32) -> bool {
    let mut erased = false;
    let result = store.save(config, id, || {
        erased = true;
        with_controller(|c| c.hold_outputs_off(true));
        board::force_gates_low();
        pet_watchdog();
    });
    if erased {
        pet_watchdog();
        board::release_gates();
        with_controller(|c| c.hold_outputs_off(false));
    }
    match result {
        Ok(record) => {
            defmt::info!("configuration saved as record {}", record.sequence);
            true
        }
        Err(error) => {
            defmt::warn!("configuration not saved: {}", defmt::Debug2Format(&error));
            false
        }
    }
}

async fn serve_board_to_host(mut sender: Sender<'static, Driver<'static, USB_OTG_FS>>) {
    loop {
        sender.wait_connection().await;
        let _: Result<(), EndpointError> = async {
            loop {
                // Replies first: `select` polls its first future first.
                let frame = match select(REPLIES.receive(), TELEMETRY.receive()).await {
                    Either::First(reply) => reply,
                    Either::Second(telemetry) => telemetry,
                };
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
