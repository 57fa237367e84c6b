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
//! | VREFINT (measures VDDA)| -   | ADC1_IN17 (internal)  |
//! | USB D- / D+           | PA11 / PA12 | OTG_FS         |
//! | Status LED (low = on) | PC13 | GPIO                  |
//! | HSE crystal 25 MHz    | PH0 / PH1 | RCC              |

use core::sync::atomic::{AtomicU32, Ordering};

use embassy_stm32::gpio::{Level, Output, OutputType, Speed};
use embassy_stm32::pac;
use embassy_stm32::peripherals::{ADC1, IWDG, TIM4, USB_OTG_FS};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::low_level::{CountingMode, OutputCompareMode};
use embassy_stm32::timer::simple_pwm::{PwmPin, SimplePwm};
use embassy_stm32::usb::Driver;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{bind_interrupts, usb, Peri, Peripherals};
use nusense_firmware_core::analog::{
    divider_counts_to_supply_mv, sense_counts_to_ma, typical_sensor_celsius, vdda_mv, TemperatureCalibration,
    ADC_VREF_MV, PWM_HZ,
};
use nusense_firmware_core::{Measurements, CHANNEL_COUNT};
use static_cell::StaticCell;

use crate::flash::ConfigFlash;

bind_interrupts!(pub struct Irqs {
    OTG_FS => usb::InterruptHandler<USB_OTG_FS>;
});

/// Control loop period: 2 kHz, twice the required rate, so an over-current is acted on within 0.5 ms.
pub const CONTROL_PERIOD_US: u64 = 500;
/// Heartbeat: the status LED toggles once a second while the control loop runs.
pub const HEARTBEAT_STEPS: u32 = (1_000_000 / CONTROL_PERIOD_US) as u32;
/// Watchdog timeout, nominal. The IWDG runs on the LSI (17-47 kHz on the F411, DS10314; embassy assumes 32 kHz),
/// so the real timeout is 1.0-2.8 s: always above the worst configuration-sector erase (500 ms, sector 1 or 2 at
/// x32), during which the CPU stalls and the control loop that feeds the watchdog cannot run; the watchdog is also
/// fed right before the erase.
pub const WATCHDOG_TIMEOUT_US: u32 = 1_500_000;
/// Samples averaged per sense channel and control step (on top of the RC filter) against PWM ripple.
const SENSE_OVERSAMPLING: u32 = 2;
/// The internal channels (VREFINT, temperature) change slowly and need long sampling: read every this many steps.
const INTERNAL_CHANNEL_EVERY: u32 = 10;

/// ADC channel numbers (RM0383 11.3.3; the F411 puts its temperature sensor on IN18, shared with VBAT, unlike
/// the F405/F407 (IN16). embassy-stm32 0.6 picks 16 for every `stm32f41x`, the F411 included, so this board
/// reads the internal channels itself.)
const SENSE_CHANNELS: [u8; CHANNEL_COUNT] = [1, 2, 3, 4];
const SUPPLY_CHANNEL: u8 = 5;
pub const VREFINT_CHANNEL: u8 = 17;
pub const TEMPERATURE_CHANNEL: u8 = 18;
/// Factory calibration words in system memory (DS10314 tables "Temperature sensor calibration values" and
/// "Internal reference voltage calibration values"), all taken at VDDA = 3.3 V.
const VREFINT_CAL_ADDRESS: usize = 0x1FFF_7A2A;
const TS_CAL1_ADDRESS: usize = 0x1FFF_7A2C;
const TS_CAL2_ADDRESS: usize = 0x1FFF_7A2E;

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

/// While the core is halted by a debugger: stop the watchdog (else it resets the board under the debugger) and
/// the time base TIM2 (board time stops with the core). TIM4 is deliberately left running: a general-purpose
/// timer frozen mid-period holds its outputs where they are, which for a string that was on means full
/// on-current (about 190 mA) as DC, above the 120 mA limit; running, it keeps the last regulated duty.
pub fn freeze_watchdog_when_halted() {
    pac::DBGMCU.apb1fzr().modify(|w| {
        w.set_iwdg(true);
        w.set_tim2(true);
    });
}

/// Drives the four MOSFET gates low through their GPIO output registers, whatever the timer is doing: the first
/// thing the panic and fault handlers do, and what holds the LEDs off around a flash erase. Touches only
/// registers, so it is safe from any context, including a fault with a broken stack discipline.
pub fn force_gates_low() {
    use pac::gpio::vals::Moder;
    pac::GPIOB.bsrr().write(|w| {
        for pin in GATE_PINS {
            w.set_br(pin, true);
        }
    });
    pac::GPIOB.moder().modify(|w| {
        for pin in GATE_PINS {
            w.set_moder(pin, Moder::OUTPUT);
        }
    });
}

/// Hands the gates back to TIM4 after [`force_gates_low`].
pub fn release_gates() {
    use pac::gpio::vals::Moder;
    pac::GPIOB.moder().modify(|w| {
        for pin in GATE_PINS {
            w.set_moder(pin, Moder::ALTERNATE);
        }
    });
}

/// PB6..PB9: TIM4 channels 1..4.
const GATE_PINS: [usize; CHANNEL_COUNT] = [6, 7, 8, 9];

/// Everything the firmware drives, taken from the chip's peripherals.
pub struct Board {
    pub leds: LedDrive,
    pub sensors: Sensors,
    pub usb: Driver<'static, USB_OTG_FS>,
    pub flash: ConfigFlash,
    pub watchdog: IndependentWatchdog<'static, IWDG>,
    pub status_led: Output<'static>,
}

impl Board {
    pub fn new(p: Peripherals) -> Self {
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
            leds: LedDrive::new(p.TIM4, p.PB6, p.PB7, p.PB8, p.PB9),
            sensors: Sensors::new(p.ADC1),
            usb,
            flash: ConfigFlash::new(p.FLASH),
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

/// Which strings switch half a period after the others: the timer counts up and down (centre-aligned), Top and
/// Bottom (PWM mode 1) conduct around the bottom of the count, Right and Left (PWM mode 2) around its top. So
/// the two pairs' edges never coincide and, up to 50 % duty (100 mA is about 53 %), at most two strings conduct
/// at once; within a pair the edges coincide only when their duties are equal.
const LATE_PHASE: [bool; CHANNEL_COUNT] = [false, true, false, true];

/// The four MOSFET gates on TIM4, in the protocol's Side order.
pub struct LedDrive {
    pwm: SimplePwm<'static, TIM4>,
}

impl LedDrive {
    pub fn new(
        tim: Peri<'static, TIM4>,
        top: Peri<'static, embassy_stm32::peripherals::PB6>,
        right: Peri<'static, embassy_stm32::peripherals::PB7>,
        bottom: Peri<'static, embassy_stm32::peripherals::PB8>,
        left: Peri<'static, embassy_stm32::peripherals::PB9>,
    ) -> Self {
        let pwm = SimplePwm::new(
            tim,
            Some(PwmPin::new(top, OutputType::PushPull)),
            Some(PwmPin::new(right, OutputType::PushPull)),
            Some(PwmPin::new(bottom, OutputType::PushPull)),
            Some(PwmPin::new(left, OutputType::PushPull)),
            Hertz(PWM_HZ),
            CountingMode::CenterAlignedBothInterrupts,
        );
        let mut drive = Self { pwm };
        for (ch, late) in CHANNELS.into_iter().zip(LATE_PHASE) {
            let mode = if late {
                OutputCompareMode::PwmMode2
            } else {
                OutputCompareMode::PwmMode1
            };
            drive.pwm.channel(ch).set_output_compare_mode(mode);
        }
        drive.all_off();
        for ch in CHANNELS {
            drive.pwm.channel(ch).enable();
        }
        drive
    }

    pub fn set(&mut self, duty: [f32; CHANNEL_COUNT]) {
        let max = self.pwm.max_duty_cycle();
        for ((ch, late), d) in CHANNELS.into_iter().zip(LATE_PHASE).zip(duty) {
            // The core guarantees 0..=1; clamp anyway so a bug there cannot overflow the compare register.
            let d = if d.is_nan() { 0.0 } else { d.clamp(0.0, 1.0) };
            let on = (d * max as f32) as u32;
            // Mode 2 is active from the compare value up: the compare value is the off time.
            self.pwm.channel(ch).set_duty_cycle(if late { max - on } else { on });
        }
    }

    pub fn all_off(&mut self) {
        self.set([0.0; CHANNEL_COUNT]);
    }
}

/// ADC1 through its registers: the four sense resistors, the supply divider, VREFINT (for the real VDDA) and the
/// internal temperature sensor, single conversions started by software.
pub struct Sensors {
    _adc: Peri<'static, ADC1>,
    vrefint_cal: u16,
    temperature_cal: Option<TemperatureCalibration>,
    vdda_mv: f32,
    temperature_c: f32,
    step: u32,
}

/// The latest VDDA (mV, f32 bits), for on-target tests and logs.
pub static LAST_VDDA_MV: AtomicU32 = AtomicU32::new(0);

impl Sensors {
    pub fn new(adc: Peri<'static, ADC1>) -> Self {
        use pac::adc::vals::SampleTime;
        use pac::adccommon::vals::Adcpre;
        pac::RCC.apb2enr().modify(|w| w.set_adc1en(true));
        // APB2 96 MHz / 4 = 24 MHz, within the 36 MHz maximum.
        pac::ADC1_COMMON.ccr().modify(|w| {
            w.set_adcpre(Adcpre::DIV4);
            w.set_tsvrefe(true);
            // VBAT shares IN18 with the sensor and wins when both are enabled (RM0383 11.10).
            w.set_vbate(false);
        });
        pac::ADC1.sqr1().modify(|w| w.set_l(0));
        // Sense and supply pins sit behind 2 kOhm: 56 cycles (2.3 us) settle them to 12 bits. The internal
        // channels need >= 10 us (DS10314 TS_temp, TS_vrefint): 480 cycles = 20 us.
        for ch in SENSE_CHANNELS.into_iter().chain([SUPPLY_CHANNEL]) {
            pac::ADC1
                .smpr2()
                .modify(|w| w.set_smp(usize::from(ch), SampleTime::CYCLES56));
        }
        for ch in [VREFINT_CHANNEL, TEMPERATURE_CHANNEL] {
            pac::ADC1
                .smpr1()
                .modify(|w| w.set_smp(usize::from(ch - 10), SampleTime::CYCLES480));
        }
        pac::ADC1.cr2().modify(|w| w.set_adon(true));
        // tSTAB (3 us) for the converter, 10 us start-up for the sensor and reference: wait generously.
        cortex_m::asm::delay(96 * 20);
        let (vrefint_cal, ts_cal1, ts_cal2) = factory_calibration();
        let mut sensors = Self {
            _adc: adc,
            vrefint_cal,
            temperature_cal: TemperatureCalibration::checked(ts_cal1, ts_cal2),
            vdda_mv: ADC_VREF_MV,
            temperature_c: 25.0,
            step: 0,
        };
        sensors.read_internal_channels();
        sensors
    }

    /// One conversion of `channel`.
    pub fn convert(&mut self, channel: u8) -> u16 {
        pac::ADC1.sqr3().write(|w| w.set_sq(0, channel));
        pac::ADC1.cr2().modify(|w| w.set_swstart(true));
        while !pac::ADC1.sr().read().eoc() {}
        // Reading DR clears EOC.
        pac::ADC1.dr().read().data()
    }

    fn read_internal_channels(&mut self) {
        if let Some(vdda) = vdda_mv(self.convert(VREFINT_CHANNEL), self.vrefint_cal) {
            self.vdda_mv = vdda;
            LAST_VDDA_MV.store(vdda.to_bits(), Ordering::Relaxed);
        }
        let counts = self.convert(TEMPERATURE_CHANNEL);
        self.temperature_c = match self.temperature_cal {
            Some(cal) => cal.celsius(counts, self.vdda_mv),
            None => typical_sensor_celsius(counts, self.vdda_mv),
        };
    }

    /// The temperature from the factory calibration and from the datasheet's typical sensor, for the same
    /// reading: far apart means the wrong channel (or a broken calibration); on-target tests check it.
    pub fn temperature_cross_check(&mut self) -> (Option<f32>, f32) {
        let counts = self.convert(TEMPERATURE_CHANNEL);
        (
            self.temperature_cal.map(|cal| cal.celsius(counts, self.vdda_mv)),
            typical_sensor_celsius(counts, self.vdda_mv),
        )
    }

    pub fn vdda_mv(&self) -> f32 {
        self.vdda_mv
    }

    pub fn measure(&mut self) -> Measurements {
        if self.step % INTERNAL_CHANNEL_EVERY == 0 {
            self.read_internal_channels();
        }
        self.step = self.step.wrapping_add(1);
        let mut sums = [0u32; CHANNEL_COUNT];
        for _ in 0..SENSE_OVERSAMPLING {
            for (sum, ch) in sums.iter_mut().zip(SENSE_CHANNELS) {
                *sum += u32::from(self.convert(ch));
            }
        }
        let vdda = self.vdda_mv;
        Measurements {
            current_ma: sums.map(|s| sense_counts_to_ma((s / SENSE_OVERSAMPLING) as u16, vdda)),
            supply_mv: divider_counts_to_supply_mv(self.convert(SUPPLY_CHANNEL), vdda),
            temperature_c: self.temperature_c,
        }
    }
}

/// VREFINT_CAL, TS_CAL1, TS_CAL2 from system memory.
pub fn factory_calibration() -> (u16, u16, u16) {
    // SAFETY: system memory, always mapped and readable on the STM32F411.
    unsafe {
        (
            core::ptr::read_volatile(VREFINT_CAL_ADDRESS as *const u16),
            core::ptr::read_volatile(TS_CAL1_ADDRESS as *const u16),
            core::ptr::read_volatile(TS_CAL2_ADDRESS as *const u16),
        )
    }
}
