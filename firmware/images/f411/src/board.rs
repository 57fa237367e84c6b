//! The NUSense LED/controller board, in one place: clocks, which pin does what, timer channels, ADC channels and
//! sample times. The analog component values (sense resistor, filter, divider) are in
//! `nusense_firmware_core::analog`, shared with the simulated plant. firmware/README.md has the pin table.
//!
//! | Function              | Pin  | Peripheral            |
//! |-----------------------|------|-----------------------|
//! | LED string Top gate   | PB6  | TIM4_CH1 (PWM)        |
//! | LED string Right gate | PB7  | TIM4_CH2 (PWM)        |
//! | LED string Bottom gate| PB8  | TIM4_CH3 (PWM)        |
//! | LED string Left gate  | PB9  | TIM4_CH4 (PWM)        |
//! | Top sense             | PA1  | ADC1_IN1              |
//! | Right sense           | PA2  | ADC1_IN2              |
//! | Bottom sense          | PA3  | ADC1_IN3              |
//! | Left sense            | PA4  | ADC1_IN4              |
//! | Supply divider        | PA5  | ADC1_IN5              |
//! | MCU temperature       | -    | ADC1_IN18 (internal)  |
//! | USB D- / D+           | PA11 / PA12 | OTG_FS         |
//! | Status LED (low = on) | PC13 | GPIO                  |
//! | HSE crystal 25 MHz    | PH0 / PH1 | RCC              |

use embassy_stm32::adc::{Adc, AdcChannel, AnyAdcChannel, SampleTime, Temperature};
use embassy_stm32::flash::{Blocking, Flash};
use embassy_stm32::gpio::{Level, Output, OutputType, Speed};
use embassy_stm32::peripherals::{ADC1, IWDG, TIM4, USB_OTG_FS};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::timer::simple_pwm::{PwmPin, SimplePwm};
use embassy_stm32::usb::Driver;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{bind_interrupts, usb, Peripherals};
use nusense_firmware_core::analog::{divider_counts_to_supply_mv, sense_counts_to_ma, PWM_HZ};
use nusense_firmware_core::{Measurements, CHANNEL_COUNT};
use static_cell::StaticCell;

bind_interrupts!(pub struct Irqs {
    OTG_FS => usb::InterruptHandler<USB_OTG_FS>;
});

/// Control loop period: 2 kHz, twice the required rate, so an over-current is acted on within 0.5 ms.
pub const CONTROL_PERIOD_US: u64 = 500;
/// Watchdog timeout: longer than the worst-case erase of the 128 KiB configuration sector (2 s), which stalls
/// the CPU and so the control loop that pets it.
pub const WATCHDOG_TIMEOUT_US: u32 = 3_000_000;
/// Samples averaged per sense channel and control step (on top of the RC filter) against PWM ripple.
const SENSE_OVERSAMPLING: u32 = 2;
/// The sense pins sit behind 2 kOhm: 56 cycles at the 24 MHz ADC clock (2.3 us) settle them to 12 bits.
const SENSE_SAMPLE_TIME: SampleTime = SampleTime::CYCLES56;
/// The temperature sensor needs >= 10 us of sampling: 480 cycles = 20 us.
const TEMPERATURE_SAMPLE_TIME: SampleTime = SampleTime::CYCLES480;

/// HSE 25 MHz -> PLL: 96 MHz system clock, 48 MHz for USB; APB1 48 MHz (timers 96 MHz), APB2 96 MHz (ADC /4).
pub fn clock_config() -> embassy_stm32::Config {
    use embassy_stm32::rcc::*;
    let mut config = embassy_stm32::Config::default();
    config.rcc.hse = Some(Hse {
        freq: Hertz(25_000_000),
        mode: HseMode::Oscillator,
    });
    config.rcc.pll_src = PllSource::HSE;
    config.rcc.pll = Some(Pll {
        prediv: PllPreDiv::DIV25,
        mul: PllMul::MUL192,
        divp: Some(PllPDiv::DIV2),
        divq: Some(PllQDiv::DIV4),
        divr: None,
    });
    config.rcc.sys = Sysclk::PLL1_P;
    config.rcc.ahb_pre = AHBPrescaler::DIV1;
    config.rcc.apb1_pre = APBPrescaler::DIV2;
    config.rcc.apb2_pre = APBPrescaler::DIV1;
    config
}

/// Everything the firmware drives, taken from the chip's peripherals.
pub struct Board {
    pub leds: LedDrive,
    pub sensors: Sensors,
    pub usb: Driver<'static, USB_OTG_FS>,
    pub flash: Flash<'static, Blocking>,
    pub watchdog: IndependentWatchdog<'static, IWDG>,
    pub status_led: Output<'static>,
}

impl Board {
    pub fn new(p: Peripherals) -> Self {
        let mut pwm = SimplePwm::new(
            p.TIM4,
            Some(PwmPin::new(p.PB6, OutputType::PushPull)),
            Some(PwmPin::new(p.PB7, OutputType::PushPull)),
            Some(PwmPin::new(p.PB8, OutputType::PushPull)),
            Some(PwmPin::new(p.PB9, OutputType::PushPull)),
            Hertz(PWM_HZ),
            CountingMode::EdgeAlignedUp,
        );
        for ch in CHANNELS {
            pwm.channel(ch).set_duty_cycle_fully_off();
            pwm.channel(ch).enable();
        }

        let adc = Adc::new(p.ADC1);
        let temperature = adc.enable_temperature();
        let sensors = Sensors {
            sense: [
                p.PA1.degrade_adc(),
                p.PA2.degrade_adc(),
                p.PA3.degrade_adc(),
                p.PA4.degrade_adc(),
            ],
            supply: p.PA5.degrade_adc(),
            temperature,
            adc,
        };

        static EP_OUT_BUFFER: StaticCell<[u8; 256]> = StaticCell::new();
        let mut usb_config = embassy_stm32::usb::Config::default();
        // The board is bus powered: VBUS is always there while USB is, and PA9 is free for other uses.
        usb_config.vbus_detection = false;
        let usb = Driver::new_fs(
            p.USB_OTG_FS,
            Irqs,
            p.PA12,
            p.PA11,
            EP_OUT_BUFFER.init([0; 256]),
            usb_config,
        );

        Self {
            leds: LedDrive { pwm },
            sensors,
            usb,
            flash: Flash::new_blocking(p.FLASH),
            watchdog: IndependentWatchdog::new(p.IWDG, WATCHDOG_TIMEOUT_US),
            status_led: Output::new(p.PC13, Level::High, Speed::Low),
        }
    }
}

const CHANNELS: [embassy_stm32::timer::Channel; CHANNEL_COUNT] = [
    embassy_stm32::timer::Channel::Ch1,
    embassy_stm32::timer::Channel::Ch2,
    embassy_stm32::timer::Channel::Ch3,
    embassy_stm32::timer::Channel::Ch4,
];

/// The four MOSFET gates on TIM4, in the protocol's Side order.
pub struct LedDrive {
    pwm: SimplePwm<'static, TIM4>,
}

impl LedDrive {
    pub fn set(&mut self, duty: [f32; CHANNEL_COUNT]) {
        let max = self.pwm.max_duty_cycle();
        for (ch, d) in CHANNELS.into_iter().zip(duty) {
            // The core guarantees 0..=1; clamp anyway so a bug there cannot overflow the compare register.
            let d = if d.is_nan() { 0.0 } else { d.clamp(0.0, 1.0) };
            self.pwm.channel(ch).set_duty_cycle((d * max as f32) as u32);
        }
    }

    pub fn all_off(&mut self) {
        for ch in CHANNELS {
            self.pwm.channel(ch).set_duty_cycle_fully_off();
        }
    }
}

/// ADC1: the four sense resistors, the supply divider and the internal temperature sensor.
pub struct Sensors {
    adc: Adc<'static, ADC1>,
    sense: [AnyAdcChannel<'static, ADC1>; CHANNEL_COUNT],
    supply: AnyAdcChannel<'static, ADC1>,
    temperature: Temperature,
}

impl Sensors {
    pub fn measure(&mut self) -> Measurements {
        let mut sums = [0u32; CHANNEL_COUNT];
        for _ in 0..SENSE_OVERSAMPLING {
            for (sum, pin) in sums.iter_mut().zip(self.sense.iter_mut()) {
                *sum += u32::from(self.adc.blocking_read(pin, SENSE_SAMPLE_TIME));
            }
        }
        let current_ma = sums.map(|s| sense_counts_to_ma((s / SENSE_OVERSAMPLING) as u16));
        let supply_mv = divider_counts_to_supply_mv(
            self.adc.blocking_read(&mut self.supply, SENSE_SAMPLE_TIME),
        );
        let raw_temperature = self
            .adc
            .blocking_read(&mut self.temperature, TEMPERATURE_SAMPLE_TIME);
        Measurements {
            current_ma,
            supply_mv,
            temperature_c: temperature_c(raw_temperature),
        }
    }
}

/// Internal sensor counts -> degrees C, with the factory calibration points (30 and 110 degC at 3.3 V) when they
/// look sane, the datasheet's typical V25 = 0.76 V and 2.5 mV/K otherwise.
fn temperature_c(counts: u16) -> f32 {
    // SAFETY: system memory, always mapped and readable on the STM32F411.
    let (cal30, cal110) = unsafe {
        (
            core::ptr::read_volatile(0x1FFF_7A2C as *const u16),
            core::ptr::read_volatile(0x1FFF_7A2E as *const u16),
        )
    };
    if cal30 > 500 && cal110 > cal30 && cal110 < 4095 {
        30.0 + (f32::from(counts) - f32::from(cal30)) * 80.0 / f32::from(cal110 - cal30)
    } else {
        let mv = f32::from(counts) * 3300.0 / 4095.0;
        (mv - 760.0) / 2.5 + 25.0
    }
}
