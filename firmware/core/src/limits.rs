//! The board's electrical limits and the thresholds of the fault monitor. Every number the regulator and the fault
//! monitor compare against lives here, so the README, the tests and the code cannot disagree.

/// Current each LED string is designed for.
pub const NOMINAL_CURRENT_MA: u16 = 100;
/// Hard limit per string: setpoints above it are clamped, whatever the host sends.
pub const MAX_CURRENT_MA: u16 = 120;
/// A single sample above this switches the channel off (over-current). Ten percent above the hard limit, so the
/// sensing noise of a string regulated at the limit never trips it, while a shorted string (several hundred mA)
/// trips on the first control step after the short.
pub const OVER_CURRENT_TRIP_MA: f32 = MAX_CURRENT_MA as f32 * 1.1;

/// Duty at or above which a string that still carries no current is declared open.
pub const OPEN_STRING_DUTY: f32 = 0.95;
/// "No current": below this a string at [`OPEN_STRING_DUTY`] is open.
pub const OPEN_STRING_CURRENT_MA: f32 = 5.0;
/// How long the open-string condition must hold; rides through the first steps of a soft start.
pub const OPEN_STRING_CONFIRM_US: u64 = 20_000;

/// Below this supply the strings cannot reach their setpoint (the LED forward voltage plus the sense and ballast
/// drop at 100 mA is about 4.1 V).
pub const UNDER_VOLTAGE_MV: f32 = 4_200.0;
/// Supply dips shorter than this are ridden through.
pub const UNDER_VOLTAGE_CONFIRM_US: u64 = 5_000;

/// Board temperature at which the setpoints start to be derated.
pub const DERATE_START_C: f32 = 70.0;
/// Board temperature at which the channels are switched off (latched).
pub const SHUTDOWN_C: f32 = 85.0;
/// Fraction of the setpoint left just below [`SHUTDOWN_C`]; the derating is linear from 1 at [`DERATE_START_C`].
pub const DERATE_FLOOR: f32 = 0.5;

/// Default soft-start: time from 0 to the setpoint.
pub const DEFAULT_RAMP_MS: u16 = 50;
/// Longest soft-start the host may ask for.
pub const MAX_RAMP_MS: u16 = 10_000;
/// Shortest telemetry period the host may ask for (a frame is about 130 bytes: ~11 ms at 115200 baud, far less
/// over USB, so faster requests would only fill the link).
pub const MIN_TELEMETRY_PERIOD_MS: u16 = 5;

/// What a USB 2.0 port grants a configured high-power device, and what the board declares as bMaxPower.
pub const USB_CONFIGURED_MA: u16 = 500;
/// What the board itself draws from VBUS besides the LED strings: the STM32F411 at 96 MHz with USB, ADC and
/// timers running (about 25 mA typical, 40 mA worst case over temperature), the 3.3 V regulator's own
/// consumption and the status LED, rounded up.
pub const MCU_RESERVE_MA: u16 = 60;
/// The most the four strings may draw together: the port's grant less the board's own draw. Also the default
/// budget; the host may lower it (`SetCurrentBudget`), never raise it.
pub const MAX_TOTAL_CURRENT_MA: u16 = USB_CONFIGURED_MA - MCU_RESERVE_MA;

// The default budget must keep the board within what the port grants, and must matter at the hard limit.
const _: () = assert!(MAX_TOTAL_CURRENT_MA + MCU_RESERVE_MA <= USB_CONFIGURED_MA);
const _: () = assert!(4 * MAX_CURRENT_MA > MAX_TOTAL_CURRENT_MA);
