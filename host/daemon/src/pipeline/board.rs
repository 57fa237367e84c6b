//! What the pipeline needs from the LED board: its LED state for each reading, LED commands from the API,
//! a status for `/api/status` and telemetry for recordings. The board link (nusense-board) provides it;
//! sources without a board (replay, a bare camera) use [`NoBoard`].

use std::sync::mpsc::Receiver;

use nusense_protocol::{Side, CHANNEL_COUNT};
use serde::Serialize;

/// Highest LED current the daemon will ask for, per channel: the board's own hard limit, so a request the
/// board would clamp is refused with a message instead.
pub use nusense_board::LED_LIMIT_MA;

/// LED state attached to each reading; per channel in Side order: Top, Right, Bottom, Left.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct LedState {
    pub setpoint_ma: [u16; CHANNEL_COUNT],
    pub measured_ma: [f32; CHANNEL_COUNT],
    pub enabled: [bool; CHANNEL_COUNT],
    pub any_fault: bool,
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
    #[error("the LED board did not accept the command: {0}")]
    Link(String),
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
    fn status(&self) -> serde_json::Value;
    /// Telemetry as it arrives (JSON), for recordings. None when the board has none.
    fn telemetry(&self) -> Option<Receiver<String>>;
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
    fn status(&self) -> serde_json::Value {
        serde_json::json!({ "connected": false, "kind": "none" })
    }
    fn telemetry(&self) -> Option<Receiver<String>> {
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
        let telemetry = self.link.state().telemetry?;
        let mut led = LedState::default();
        for (i, channel) in telemetry.channels.iter().enumerate() {
            led.setpoint_ma[i] = channel.setpoint_ma;
            led.measured_ma[i] = if channel.measured_ma.is_finite() {
                channel.measured_ma
            } else {
                0.0
            };
            led.enabled[i] = channel.enabled;
            led.any_fault |= channel.faults.any();
        }
        Some(led)
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
        let link_error = |e: nusense_board::LinkError| BoardError::Link(e.to_string());
        let first = command.current_ma[0];
        if first.is_some() && command.current_ma.iter().all(|c| *c == first) {
            // One command for all four: they change in the same regulator step.
            return self
                .link
                .set_led(Channel::All, first.unwrap_or(0), command.enabled.unwrap_or(true))
                .map_err(link_error);
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
                .set_led(Channel::One(side), current_ma, command.enabled.unwrap_or(true))
                .map_err(link_error)?;
        }
        Ok(())
    }

    fn status(&self) -> serde_json::Value {
        let kind = if self.virtual_board.is_some() {
            "virtual"
        } else {
            "serial"
        };
        let mut status = serde_json::to_value(self.link.state()).unwrap_or_default();
        if let Some(object) = status.as_object_mut() {
            object.insert("kind".into(), kind.into());
            object.insert("led_limit_ma".into(), LED_LIMIT_MA.into());
        }
        status
    }

    fn telemetry(&self) -> Option<Receiver<String>> {
        let events = self.link.subscribe();
        let (sender, receiver) = std::sync::mpsc::sync_channel(256);
        std::thread::Builder::new()
            .name("telemetry json".into())
            .spawn(move || {
                for event in events {
                    if let nusense_board::BoardEvent::Telemetry(telemetry) = event {
                        let json =
                            serde_json::json!({ "time_us": nusense_capture::unix_time_us(), "telemetry": telemetry });
                        if sender.send(json.to_string()).is_err() {
                            return;
                        }
                    }
                }
            })
            .ok()?;
        Some(receiver)
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
}
