//! The board's analog front end: the component values that both the real board's ADC scaling (firmware/images/f411)
//! and the simulated plant ([`crate::plant`]) use, so the simulation describes the board that is built.
//!
//! Each LED string: supply -> LED -> low-side N-MOSFET (gate = PWM) -> sense resistor -> ground. The ADC reads the
//! sense voltage through an RC low-pass that averages the PWM current; the supply through a resistive divider.

/// Sense resistor per string. 100 mA gives 1.0 V, a third of the ADC range, with room above the 120 mA limit.
pub const SENSE_OHM: f32 = 10.0;
/// RC low-pass between the sense resistor and the ADC pin (2.0 kOhm, 100 nF): averages 25 kHz PWM, still fast
/// enough for the over-current trip to see a short within a control period.
pub const SENSE_FILTER_TAU_US: f32 = 200.0;
/// Supply divider (top 20 kOhm, bottom 10 kOhm): 5 V reads as 1.67 V.
pub const SUPPLY_DIVIDER_RATIO: f32 = 3.0;
/// Nominal LED supply: USB VBUS.
pub const SUPPLY_NOMINAL_MV: f32 = 5_000.0;
/// ADC reference (VDDA) and full scale of the 12-bit converter.
pub const ADC_VREF_MV: f32 = 3_300.0;
pub const ADC_FULL_SCALE: u16 = 4095;
/// PWM frequency of the gate drive.
pub const PWM_HZ: u32 = 25_000;

/// ADC counts of a sense resistor pin -> string current.
pub fn sense_counts_to_ma(counts: u16) -> f32 {
    counts_to_mv(counts) / SENSE_OHM
}

/// ADC counts of the divider pin -> supply voltage.
pub fn divider_counts_to_supply_mv(counts: u16) -> f32 {
    counts_to_mv(counts) * SUPPLY_DIVIDER_RATIO
}

fn counts_to_mv(counts: u16) -> f32 {
    f32::from(counts.min(ADC_FULL_SCALE)) * ADC_VREF_MV / f32::from(ADC_FULL_SCALE)
}
