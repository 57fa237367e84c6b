//! What the pipeline needs from the LED board: its LED state for each reading, LED commands from the API,
//! a status for `/api/v1/status` and telemetry for recordings. The board link (nusense-board) provides it;
//! sources without a board (replay, a bare camera) use [`NoBoard`].

use std::sync::mpsc::Receiver;

use nusense_board::{BoardEvent, BoardState};
use nusense_protocol::{FaultFlags, Side, Telemetry, CHANNEL_COUNT};
use schemars::JsonSchema;
use serde::Serialize;

/// Highest LED current the daemon will ask for, per channel: the board's own hard limit, so a request the
/// board would clamp is refused with a message instead.
pub use nusense_board::LED_LIMIT_MA;

/// LED state attached to each reading; per channel in Side order: Top, Right, Bottom, Left.
#[derive(Clone, Debug, Default, PartialEq, Serialize, JsonSchema)]
pub struct LedState {
    /// Current asked of each string, mA.
    pub setpoint_ma: [u16; CHANNEL_COUNT],
    /// Current measured through each string, mA.
    pub measured_ma: [f32; CHANNEL_COUNT],
    pub enabled: [bool; CHANNEL_COUNT],
    /// What the board reports wrong with each string, by name (`open_string`, `over_current`,
    /// `over_temperature`, `under_voltage`); empty when it is healthy.
    pub faults: [Vec<String>; CHANNEL_COUNT],
    pub any_fault: bool,
    /// Board temperature, degrees C.
    pub temperature_c: f32,
    /// Supply voltage at the board, mV.
    pub supply_mv: u16,
}

impl LedState {
    pub fn from_telemetry(telemetry: &Telemetry) -> Self {
        let mut led = LedState {
            temperature_c: finite_or_zero(telemetry.temperature_c),
            supply_mv: telemetry.supply_mv,
            ..Default::default()
        };
        for (i, channel) in telemetry.channels.iter().enumerate() {
            led.setpoint_ma[i] = channel.setpoint_ma;
            led.measured_ma[i] = finite_or_zero(channel.measured_ma);
            led.enabled[i] = channel.enabled;
            led.faults[i] = fault_names(&channel.faults);
            led.any_fault |= channel.faults.any();
        }
        led
    }
}

/// JSON has no NaN: a sensor reading that is not a number is shown as 0 (the fault flags say why).
fn finite_or_zero(value: f32) -> f32 {
    if value.is_finite() {
        value
    } else {
        0.0
    }
}

/// The names of the flags that are set, as the protocol's own serialisation spells them (one place for the
/// names: the flag struct's field names).
fn fault_names(flags: &FaultFlags) -> Vec<String> {
    match serde_json::to_value(flags) {
        Ok(serde_json::Value::Object(map)) => map
            .into_iter()
            .filter(|(_, set)| *set == serde_json::Value::Bool(true))
            .map(|(name, _)| name)
            .collect(),
        _ => Vec::new(),
    }
}

/// What kind of board the daemon drives.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum BoardKind {
    /// No board: the LEDs are not the daemon's to control.
    None,
    /// The virtual board (the firmware's logic with simulated LEDs) behind a pty.
    Virtual,
    /// A board on a serial port.
    Serial,
}

/// The board part of `/api/v1/status`.
#[derive(Clone, Debug, Serialize)]
pub struct BoardStatus {
    pub kind: BoardKind,
    pub connected: bool,
    /// Highest current the daemon accepts per string, mA.
    pub led_limit_ma: u16,
    /// The link's view: port, identity, latest telemetry, counters, reconnects, last error; none without a board.
    pub link: Option<BoardState>,
}

#[derive(Debug, thiserror::Error)]
pub enum BoardError {
    #[error("no LED board is connected")]
    NoBoard,
    #[error("{side:?} LED current {requested_ma} mA is above the {limit_ma} mA limit")]
    AboveLimit {
        side: Side,
        requested_ma: u16,
        limit_ma: u16,
    },
    #[error("the LED board did not accept the command")]
    Link(#[from] nusense_board::LinkError),
}

/// One LED command: a current per side (None leaves that side as it is).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LedCommand {
    pub current_ma: [Option<u16>; CHANNEL_COUNT],
    pub enabled: Option<bool>,
}

impl LedCommand {
    /// Rejects currents above [`LED_LIMIT_MA`] before anything reaches the board.
    pub fn validate(&self) -> Result<(), BoardError> {
        for side in Side::ALL {
            if let Some(requested_ma) = self.current_ma[side.index()] {
                if requested_ma > LED_LIMIT_MA {
                    return Err(BoardError::AboveLimit {
                        side,
                        requested_ma,
                        limit_ma: LED_LIMIT_MA,
                    });
                }
            }
        }
        Ok(())
    }
}

pub trait Board: Send + Sync {
    /// The latest LED state, when a board is connected and has reported it.
    fn led_state(&self) -> Option<LedState>;
    /// Currents through the LEDs now (what lights the pad); the simulated camera renders with them.
    fn led_currents_ma(&self) -> [f32; CHANNEL_COUNT];
    fn set_leds(&self, command: &LedCommand) -> Result<(), BoardError>;
    fn status(&self) -> BoardStatus;
    /// The board's events (telemetry, connects, disconnects) as they happen, for recordings. None without a board.
    fn events(&self) -> Option<Receiver<BoardEvent>>;
    /// The board's USB serial number (its MCU's unique id in hex), once known: at once for the virtual board, from
    /// the first connection for a real one. None without a board. It names the sensor on Zenoh.
    fn serial_number(&self) -> Option<String>;
}

/// The USB serial number a board reports: its MCU's unique id, upper-case hex (as the firmware's USB stack
/// writes it).
pub fn serial_number_of(info: &nusense_protocol::DeviceInfo) -> String {
    info.mcu_uid.iter().map(|byte| format!("{byte:02X}")).collect()
}

/// No board attached: LEDs are not the daemon's to control (replay, a camera with its own lighting).
pub struct NoBoard;

impl Board for NoBoard {
    fn led_state(&self) -> Option<LedState> {
        None
    }
    fn led_currents_ma(&self) -> [f32; CHANNEL_COUNT] {
        [0.0; CHANNEL_COUNT]
    }
    fn set_leds(&self, command: &LedCommand) -> Result<(), BoardError> {
        command.validate()?;
        Err(BoardError::NoBoard)
    }
    fn status(&self) -> BoardStatus {
        BoardStatus {
            kind: BoardKind::None,
            connected: false,
            led_limit_ma: LED_LIMIT_MA,
            link: None,
        }
    }
    fn events(&self) -> Option<Receiver<BoardEvent>> {
        None
    }

    fn serial_number(&self) -> Option<String> {
        None
    }
}

/// A board kept connected by the board link (nusense-board), optionally the virtual board behind a pty.
pub struct LinkedBoard {
    link: nusense_board::SupervisedLink,
    /// Kept alive as long as the link talks to it.
    virtual_board: Option<nusense_board::virtual_board::VirtualBoard>,
}

impl LinkedBoard {
    pub fn new(
        link: nusense_board::SupervisedLink,
        virtual_board: Option<nusense_board::virtual_board::VirtualBoard>,
    ) -> Self {
        Self { link, virtual_board }
    }

    pub fn link(&self) -> &nusense_board::SupervisedLink {
        &self.link
    }
}

impl Board for LinkedBoard {
    fn led_state(&self) -> Option<LedState> {
        let state = self.link.state();
        if !state.connected {
            // Telemetry from before an unplug is history, not the LEDs' state now.
            return None;
        }
        Some(LedState::from_telemetry(state.telemetry.as_ref()?))
    }

    fn led_currents_ma(&self) -> [f32; CHANNEL_COUNT] {
        if let Some(board) = &self.virtual_board {
            return board.led_currents_ma();
        }
        self.led_state()
            .map(|led| led.measured_ma)
            .unwrap_or([0.0; CHANNEL_COUNT])
    }

    fn set_leds(&self, command: &LedCommand) -> Result<(), BoardError> {
        use nusense_protocol::Channel;
        command.validate()?;
        let state = self.link.state();
        if !state.connected {
            return Err(BoardError::NoBoard);
        }
        let first = command.current_ma[0];
        if first.is_some() && command.current_ma.iter().all(|c| *c == first) {
            // One command for all four: they change in the same regulator step.
            return self
                .link
                .set_led(Channel::All, first.unwrap_or(0), command.enabled.unwrap_or(true))
                .map_err(BoardError::from);
        }
        for side in Side::ALL {
            let i = side.index();
            let current = command.current_ma[i];
            if current.is_none() && command.enabled.is_none() {
                continue;
            }
            // Switching a channel on or off keeps its current: the one asked for before, else the board's setpoint.
            let current_ma = current
                .or(state.requested[i].map(|r| r.current_ma))
                .or(state.telemetry.map(|t| t.channels[i].setpoint_ma))
                .unwrap_or(0);
            self.link
                .set_led(Channel::One(side), current_ma, command.enabled.unwrap_or(true))?;
        }
        Ok(())
    }

    fn status(&self) -> BoardStatus {
        let state = self.link.state();
        BoardStatus {
            kind: if self.virtual_board.is_some() {
                BoardKind::Virtual
            } else {
                BoardKind::Serial
            },
            connected: state.connected,
            led_limit_ma: LED_LIMIT_MA,
            link: Some(state),
        }
    }

    fn events(&self) -> Option<Receiver<BoardEvent>> {
        Some(self.link.subscribe())
    }

    fn serial_number(&self) -> Option<String> {
        match &self.virtual_board {
            Some(board) => Some(board.serial_number()),
            None => self.link.state().info.as_ref().map(serial_number_of),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn currents_above_the_limit_are_refused_naming_the_side() {
        let command = LedCommand {
            current_ma: [Some(100), None, Some(LED_LIMIT_MA + 1), None],
            enabled: None,
        };
        let error = command.validate().unwrap_err();
        assert!(
            matches!(error, BoardError::AboveLimit { side: Side::Bottom, .. }),
            "{error}"
        );
        assert!(error.to_string().contains("121 mA"), "{error}");
        let at_limit = LedCommand {
            current_ma: [Some(LED_LIMIT_MA); 4],
            enabled: Some(true),
        };
        assert!(at_limit.validate().is_ok());
    }

    #[test]
    fn telemetry_becomes_led_state_with_faults_named() {
        let mut telemetry = Telemetry::default();
        telemetry.channels[1].faults.open_string = true;
        telemetry.channels[3].faults.over_current = true;
        telemetry.channels[3].faults.under_voltage = true;
        telemetry.channels[0].measured_ma = f32::NAN;
        telemetry.channels[2].measured_ma = 99.5;
        telemetry.supply_mv = 5010;
        let led = LedState::from_telemetry(&telemetry);
        assert!(led.any_fault);
        assert_eq!(led.faults[0], Vec::<String>::new());
        assert_eq!(led.faults[1], vec!["open_string"]);
        assert_eq!(led.faults[3], vec!["over_current", "under_voltage"]);
        assert_eq!(led.measured_ma, [0.0, 0.0, 99.5, 0.0]);
        assert_eq!(led.supply_mv, 5010);
        assert!(!LedState::from_telemetry(&Telemetry::default()).any_fault);
    }
}
