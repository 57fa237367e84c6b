//! Fault monitor: decides from each set of measurements which channels must stop, and latches why.
//!
//! - over-current: one sample above [`OVER_CURRENT_TRIP_MA`] switches the channel off on that control step;
//! - open string: full duty and no current for [`OPEN_STRING_CONFIRM_US`];
//! - under-voltage: supply below [`UNDER_VOLTAGE_MV`] for [`UNDER_VOLTAGE_CONFIRM_US`] switches every driven channel
//!   off (an open string is not declared while the supply is low: no current is then expected);
//! - over-temperature: from [`DERATE_START_C`] the setpoints are derated (flag set, channels stay on), at
//!   [`SHUTDOWN_C`] the driven channels are switched off.
//!
//! Flags stay set until [`FaultMonitor::clear`] (the host's `ClearFaults`); a channel switched off by a fault
//! ("tripped") stays off until then. A measurement that is not a number is treated as the unsafe extreme.

use nusense_protocol::{FaultFlags, CHANNEL_COUNT};

use crate::controller::Measurements;
use crate::limits::{
    DERATE_FLOOR, DERATE_START_C, OPEN_STRING_CONFIRM_US, OPEN_STRING_CURRENT_MA, OPEN_STRING_DUTY,
    OVER_CURRENT_TRIP_MA, SHUTDOWN_C, UNDER_VOLTAGE_CONFIRM_US, UNDER_VOLTAGE_MV,
};

/// Over-temperature must hold this long before the shutdown (rides through one noisy sensor reading).
const SHUTDOWN_CONFIRM_US: u64 = 2_000;

#[derive(Clone, Debug, Default)]
pub struct FaultMonitor {
    flags: [FaultFlags; CHANNEL_COUNT],
    tripped: [bool; CHANNEL_COUNT],
    open_since_us: [Option<u64>; CHANNEL_COUNT],
    under_voltage_since_us: Option<u64>,
    too_hot_since_us: Option<u64>,
}

impl FaultMonitor {
    pub const fn new() -> Self {
        Self {
            flags: [FaultFlags {
                open_string: false,
                over_current: false,
                over_temperature: false,
                under_voltage: false,
            }; CHANNEL_COUNT],
            tripped: [false; CHANNEL_COUNT],
            open_since_us: [None; CHANNEL_COUNT],
            under_voltage_since_us: None,
            too_hot_since_us: None,
        }
    }

    /// Checks one set of measurements. `driving[ch]` says whether the channel is meant to carry current,
    /// `duty[ch]` what the regulator applied during the interval that `m` measured.
    pub fn check(&mut self, now_us: u64, m: &Measurements, driving: [bool; CHANNEL_COUNT], duty: [f32; CHANNEL_COUNT]) {
        let supply_low = m.supply_mv < UNDER_VOLTAGE_MV || m.supply_mv.is_nan();
        let under_voltage = confirmed(
            &mut self.under_voltage_since_us,
            supply_low && driving.iter().any(|&d| d),
            now_us,
            UNDER_VOLTAGE_CONFIRM_US,
        );
        let too_hot = m.temperature_c >= SHUTDOWN_C || m.temperature_c.is_nan();
        let shutdown = confirmed(&mut self.too_hot_since_us, too_hot, now_us, SHUTDOWN_CONFIRM_US);
        let derating = m.temperature_c >= DERATE_START_C || m.temperature_c.is_nan();

        for ch in 0..CHANNEL_COUNT {
            let current = m.current_ma[ch];
            if current > OVER_CURRENT_TRIP_MA || current.is_nan() {
                self.trip(ch, |f| f.over_current = true);
            }
            if !driving[ch] || self.tripped[ch] {
                self.open_since_us[ch] = None;
                continue;
            }
            let looks_open = !supply_low && duty[ch] >= OPEN_STRING_DUTY && current < OPEN_STRING_CURRENT_MA;
            if confirmed(&mut self.open_since_us[ch], looks_open, now_us, OPEN_STRING_CONFIRM_US) {
                self.trip(ch, |f| f.open_string = true);
            }
            if under_voltage {
                self.trip(ch, |f| f.under_voltage = true);
            }
            if shutdown {
                self.trip(ch, |f| f.over_temperature = true);
            } else if derating {
                self.flags[ch].over_temperature = true;
            }
        }
    }

    fn trip(&mut self, ch: usize, set: impl FnOnce(&mut FaultFlags)) {
        set(&mut self.flags[ch]);
        self.tripped[ch] = true;
    }

    /// Fraction of the setpoint allowed at this board temperature: 1 below [`DERATE_START_C`], falling linearly to
    /// [`DERATE_FLOOR`] at [`SHUTDOWN_C`], 0 from there (and for a reading that is not a number).
    pub fn derate_factor(temperature_c: f32) -> f32 {
        if temperature_c < DERATE_START_C {
            1.0
        } else if temperature_c < SHUTDOWN_C {
            let x = (temperature_c - DERATE_START_C) / (SHUTDOWN_C - DERATE_START_C);
            1.0 - x * (1.0 - DERATE_FLOOR)
        } else {
            0.0
        }
    }

    pub fn flags(&self) -> [FaultFlags; CHANNEL_COUNT] {
        self.flags
    }

    /// Whether a fault switched this channel off (it stays off until [`Self::clear`]).
    pub fn is_tripped(&self, channel: usize) -> bool {
        self.tripped.get(channel).copied().unwrap_or(false)
    }

    /// The host's `ClearFaults`: flags and trips go; a fault still present is detected again.
    pub fn clear(&mut self) {
        *self = Self::new();
    }
}

/// Tracks how long `condition` has held; true once it has held for `confirm_us`.
fn confirmed(since: &mut Option<u64>, condition: bool, now_us: u64, confirm_us: u64) -> bool {
    if !condition {
        *since = None;
        return false;
    }
    let start = *since.get_or_insert(now_us);
    now_us.saturating_sub(start) >= confirm_us
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn derate_factor_is_continuous_and_bounded() {
        assert_eq!(FaultMonitor::derate_factor(25.0), 1.0);
        assert_eq!(FaultMonitor::derate_factor(DERATE_START_C), 1.0);
        let mid = FaultMonitor::derate_factor((DERATE_START_C + SHUTDOWN_C) / 2.0);
        assert!((mid - (1.0 + DERATE_FLOOR) / 2.0).abs() < 1e-6);
        assert_eq!(FaultMonitor::derate_factor(SHUTDOWN_C), 0.0);
        assert_eq!(FaultMonitor::derate_factor(f32::NAN), 0.0);
    }

    #[test]
    fn nan_current_trips_the_channel() {
        let mut monitor = FaultMonitor::new();
        let m = Measurements {
            current_ma: [f32::NAN, 50.0, 50.0, 50.0],
            supply_mv: 5000.0,
            temperature_c: 30.0,
        };
        monitor.check(0, &m, [true; 4], [0.5; 4]);
        assert!(monitor.is_tripped(0) && monitor.flags()[0].over_current);
        assert!(!monitor.is_tripped(1));
    }
}
