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
/// Nominal ADC reference (VDDA, the board's 3.3 V rail), at which the factory calibration values were taken;
/// the real VDDA is measured through VREFINT ([`vdda_mv`]).
pub const ADC_VREF_MV: f32 = 3_300.0;
/// Full scale of the 12-bit converter.
pub const ADC_FULL_SCALE: u16 = 4095;
/// PWM frequency of the gate drive.
pub const PWM_HZ: u32 = 25_000;

/// A VDDA this far from nominal means the VREFINT reading (or its calibration word) is wrong, not the rail:
/// the regulator would not run the MCU outside 1.7-3.6 V anyway.
const VDDA_PLAUSIBLE_MV: core::ops::RangeInclusive<f32> = 2_400.0..=3_600.0;

/// VDDA from a reading of the internal reference: the factory measured VREFINT as `vrefint_cal` counts at
/// VDDA = 3.3 V (RM0383 / DS10314: VREFINT_CAL), so VDDA = 3.3 V x cal / reading. `None` when the result is
/// implausible (no reading, a blank calibration word): then the nominal 3.3 V is the better guess.
pub fn vdda_mv(vrefint_counts: u16, vrefint_cal: u16) -> Option<f32> {
    if vrefint_counts == 0 || vrefint_cal == 0 || vrefint_cal >= ADC_FULL_SCALE {
        return None;
    }
    let vdda = ADC_VREF_MV * f32::from(vrefint_cal) / f32::from(vrefint_counts);
    VDDA_PLAUSIBLE_MV.contains(&vdda).then_some(vdda)
}

/// ADC counts -> millivolts at the pin, for a converter referenced to `vdda_mv`.
pub fn counts_to_mv(counts: u16, vdda_mv: f32) -> f32 {
    f32::from(counts.min(ADC_FULL_SCALE)) * vdda_mv / f32::from(ADC_FULL_SCALE)
}

/// ADC counts of a sense resistor pin -> string current.
pub fn sense_counts_to_ma(counts: u16, vdda_mv: f32) -> f32 {
    counts_to_mv(counts, vdda_mv) / SENSE_OHM
}

/// ADC counts of the divider pin -> supply voltage.
pub fn divider_counts_to_supply_mv(counts: u16, vdda_mv: f32) -> f32 {
    counts_to_mv(counts, vdda_mv) * SUPPLY_DIVIDER_RATIO
}

/// The internal temperature sensor's factory calibration (RM0383 / DS10314: TS_CAL1 at 30 degC and TS_CAL2 at
/// 110 degC, both read at VDDA = 3.3 V).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TemperatureCalibration {
    pub ts_cal1: u16,
    pub ts_cal2: u16,
}

impl TemperatureCalibration {
    pub const CAL1_C: f32 = 30.0;
    pub const CAL2_C: f32 = 110.0;

    /// The calibration words when they look like a real sensor's (the datasheet's typical sensor gives about 960
    /// and 1210 counts; each may be off by the typical sensor's spread), `None` for blank or foreign values.
    pub fn checked(ts_cal1: u16, ts_cal2: u16) -> Option<Self> {
        let plausible = (700..=1_300).contains(&ts_cal1) && ts_cal2 > ts_cal1 + 100 && ts_cal2 < ts_cal1 + 500;
        plausible.then_some(Self { ts_cal1, ts_cal2 })
    }

    /// Sensor counts at `vdda_mv` -> degrees C, on the line through the two calibration points.
    pub fn celsius(&self, counts: u16, vdda_mv: f32) -> f32 {
        // The calibration counts are for 3.3 V: bring the reading to the same scale first.
        let at_cal_vdda = f32::from(counts) * vdda_mv / ADC_VREF_MV;
        Self::CAL1_C
            + (at_cal_vdda - f32::from(self.ts_cal1)) * (Self::CAL2_C - Self::CAL1_C)
                / f32::from(self.ts_cal2 - self.ts_cal1)
    }
}

/// The datasheet's typical sensor (DS10314: V25 = 0.76 V, 2.5 mV/degC), for parts without calibration words and
/// as the cross-check of a calibrated reading: two answers far apart mean the wrong channel is read.
pub fn typical_sensor_celsius(counts: u16, vdda_mv: f32) -> f32 {
    const V25_MV: f32 = 760.0;
    const SLOPE_MV_PER_C: f32 = 2.5;
    (counts_to_mv(counts, vdda_mv) - V25_MV) / SLOPE_MV_PER_C + 25.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vdda_follows_the_reference_reading() {
        // A typical part: VREFINT 1.21 V reads 1502 counts at 3.3 V.
        assert_eq!(vdda_mv(1502, 1502), Some(3_300.0));
        let low = vdda_mv(1652, 1502).unwrap();
        assert!((low - 3_000.0).abs() < 1.0, "{low}");
        assert_eq!(vdda_mv(0, 1502), None);
        assert_eq!(vdda_mv(1502, 0xFFFF), None);
        assert_eq!(vdda_mv(500, 1502), None, "9.9 V is not a rail this MCU runs on");
        // The same pin voltage reads fewer counts at a higher VDDA, and converts back to the same current.
        let ma_at_3v0 = sense_counts_to_ma(1365, 3_000.0);
        let ma_at_3v3 = sense_counts_to_ma(1241, 3_300.0);
        assert!((ma_at_3v0 - 100.0).abs() < 0.1 && (ma_at_3v3 - 100.0).abs() < 0.1);
    }

    #[test]
    fn calibrated_temperature_goes_through_both_points_and_agrees_with_the_typical_sensor() {
        let cal = TemperatureCalibration::checked(958, 1206).unwrap();
        assert_eq!(cal.celsius(958, 3_300.0), 30.0);
        assert_eq!(cal.celsius(1206, 3_300.0), 110.0);
        // The same 30 degC sensor voltage read at VDDA 3.0 V gives more counts.
        assert!((cal.celsius(1054, 3_000.0) - 30.0).abs() < 0.3);
        assert!((typical_sensor_celsius(958, 3_300.0) - 30.0).abs() < 2.0);
        assert_eq!(TemperatureCalibration::checked(0xFFFF, 0xFFFF), None);
        assert_eq!(TemperatureCalibration::checked(958, 958), None);
    }
}
