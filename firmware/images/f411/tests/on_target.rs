//! On-target tests of the STM32F411 glue, run on a real board with a debug probe:
//!
//!     cd firmware/images && PATH=/usr/bin:$PATH RUSTC_BOOTSTRAP=1 cargo test --release -p nusense-f411
//!
//! (probe-rs flashes the test ELF and runs each test after a reset; embedded-test reports like libtest.) CI
//! builds them (firmware/build-images) but has no board to run them on.
//!
//! They erase and rewrite the configuration sectors: a board comes out of them with its saved configuration
//! gone (the defaults: every string off). The PWM tests switch the gates at 25-50 % duty open loop for a few
//! milliseconds, which on the NUSense board is below the strings' regulated current.
#![no_std]
#![no_main]

use defmt_rtt as _;

#[embedded_test::tests(default_timeout = 10)]
mod tests {
    use embassy_stm32::pac;
    use embassy_stm32::Peripherals;
    use embedded_storage::nor_flash::NorFlash;
    use nusense_f411::board::{self, LedDrive, Sensors};
    use nusense_f411::clock;
    use nusense_f411::flash::{ConfigFlash, SECTOR_LEN};
    use nusense_firmware_core::{BoardConfig, ConfigStore};

    #[init]
    fn init() -> Peripherals {
        let p = embassy_stm32::init(board::clock_config());
        let mut core = cortex_m::Peripherals::take().unwrap();
        clock::start(&mut core.DCB, &mut core.DWT);
        p
    }

    /// IN18 is the sensor on the F411 (RM0383 11.10): the factory calibration and the datasheet's typical sensor
    /// agree on it within the typical sensor's spread, and it reads a temperature a board on a desk can have.
    /// (On IN16, which embassy-stm32 0.6 would read, nothing is connected on this part.)
    #[test]
    fn the_temperature_channel_is_the_sensor_and_agrees_with_its_calibration(p: Peripherals) {
        let mut sensors = Sensors::new(p.ADC1);
        let (calibrated, typical) = sensors.temperature_cross_check();
        let calibrated = calibrated.expect("the part has plausible TS_CAL1/TS_CAL2 words");
        defmt::info!(
            "temperature: calibrated {} degC, typical sensor {} degC",
            calibrated,
            typical
        );
        assert!((5.0..=60.0).contains(&calibrated));
        assert!((calibrated - typical).abs() <= 15.0);
    }

    #[test]
    fn vdda_is_measured_through_vrefint(p: Peripherals) {
        let sensors = Sensors::new(p.ADC1);
        let vdda = sensors.vdda_mv();
        defmt::info!("VDDA {} mV", vdda);
        assert!((3_000.0..=3_600.0).contains(&vdda));
    }

    /// A sector erase runs at x32 and within the 500 ms the watchdog and the host's save timeout are sized for.
    #[test]
    fn a_config_sector_erases_at_x32_within_500_ms(p: Peripherals) {
        let mut flash = ConfigFlash::new(p.FLASH);
        let started = clock::now_us();
        flash.erase(0, SECTOR_LEN).unwrap();
        let took_us = clock::now_us() - started;
        defmt::info!("16 KiB sector erase: {} us", took_us);
        assert_eq!(pac::FLASH.cr().read().psize(), pac::flash::vals::Psize::PSIZE32);
        assert!(took_us <= 500_000);
    }

    /// The store on the real sectors, through a sector switch (512 records fill one).
    #[test]
    #[timeout(30)]
    fn the_store_saves_and_loads_on_the_real_sectors(p: Peripherals) {
        let mut store = ConfigStore::new(ConfigFlash::new(p.FLASH), [0, SECTOR_LEN]).unwrap();
        let mut erases = 0;
        let slots = ConfigStore::<ConfigFlash>::slots_per_sector();
        for n in 0..slots + 2 {
            let config = BoardConfig {
                ramp_ms: n as u16,
                ..BoardConfig::default()
            };
            store.save(&config, n, || erases += 1).unwrap();
        }
        let newest = store.load().unwrap().unwrap();
        assert_eq!(
            (newest.request_id, newest.config.ramp_ms),
            (slots + 1, (slots + 1) as u16)
        );
        assert!((1..=2).contains(&erases));
    }

    fn gate_levels() -> [bool; 4] {
        let idr = pac::GPIOB.idr().read();
        [6, 7, 8, 9].map(|pin| idr.idr(pin) == pac::gpio::vals::Idr::HIGH)
    }

    /// Top/Bottom and Right/Left conduct half a period apart: at 25 % duty the two pairs never overlap, and each
    /// gate is high about a quarter of the time.
    #[test]
    fn the_two_string_pairs_switch_half_a_period_apart(p: Peripherals) {
        let mut leds = LedDrive::new(p.TIM4, p.PB6, p.PB7, p.PB8, p.PB9);
        leds.set([0.25; 4]);
        let mut high = [0u32; 4];
        let mut overlaps = 0;
        const SAMPLES: u32 = 20_000;
        for _ in 0..SAMPLES {
            let levels = gate_levels();
            for (count, level) in high.iter_mut().zip(levels) {
                *count += u32::from(level);
            }
            if (levels[0] || levels[2]) && (levels[1] || levels[3]) {
                overlaps += 1;
            }
        }
        leds.all_off();
        defmt::info!("high samples {:?} of {}, overlaps {}", high, SAMPLES, overlaps);
        assert_eq!(overlaps, 0);
        for count in high {
            assert!((SAMPLES * 20 / 100..=SAMPLES * 30 / 100).contains(&count));
        }
    }

    /// What the panic and fault handlers and the flash erase rely on: the gates go low whatever the timer does,
    /// and come back to it afterwards.
    #[test]
    fn forcing_the_gates_low_overrides_the_timer(p: Peripherals) {
        let mut leds = LedDrive::new(p.TIM4, p.PB6, p.PB7, p.PB8, p.PB9);
        leds.set([0.5; 4]);
        board::force_gates_low();
        for _ in 0..10_000 {
            assert_eq!(gate_levels(), [false; 4]);
        }
        board::release_gates();
        let mut seen_high = false;
        for _ in 0..10_000 {
            seen_high |= gate_levels().iter().any(|&g| g);
        }
        leds.all_off();
        assert!(seen_high);
    }

    #[test]
    fn a_halted_core_freezes_the_watchdog_and_the_time_base() {
        board::freeze_watchdog_when_halted();
        let frozen = pac::DBGMCU.apb1fzr().read();
        assert!(frozen.iwdg() && frozen.tim2());
        assert!(!frozen.tim4(), "the PWM timer keeps running (see board.rs)");
    }

    /// memory.x: the stack sits below the static data, so an overflow faults instead of corrupting it.
    #[test]
    fn the_stack_sits_below_the_static_data() {
        unsafe extern "C" {
            static __sdata: u32;
        }
        let sp = cortex_m::register::msp::read();
        let static_data = core::ptr::addr_of!(__sdata) as u32;
        assert!(sp < static_data && sp >= 0x2000_0000);
    }
}
