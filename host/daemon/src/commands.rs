//! What a client may ask of a sensor, whichever way it asks (HTTP `PUT /api/v1/led` and `POST /api/v1/tare`, the
//! Zenoh queryables `nusense/<serial>/led` and `.../tare`): bodies are parsed and checked here, once, so both
//! give the same answer and the same error text for the same request.

use std::sync::Arc;

use serde::{Deserialize, Serialize};

use crate::pipeline::{error_chain, Board, BoardError, BoardStatus, LedCommand, PipelineHandle};

/// Why an LED request was not carried out. The message is the same over every interface; each maps the kind to
/// its own status (HTTP: [`LedRequestError::http_status`]).
#[derive(Debug, thiserror::Error)]
pub enum LedRequestError {
    #[error("the LED request is not JSON: {0}")]
    NotJson(#[source] serde_json::Error),
    /// Valid JSON that is not an LED request (an unknown key, a current that is not a whole number of mA).
    #[error("the LED request does not fit {{top, right, bottom, left, all, enabled}}: {0}")]
    Shape(#[source] serde_json::Error),
    #[error("give either `all` or per-side currents, not both")]
    AllAndSides,
    #[error("nothing to set: give currents in mA as `top`, `right`, `bottom`, `left` or `all`, and/or `enabled`")]
    NothingToSet,
    /// Refused by the board's rules (a current above the limit), no board, or the link failed.
    #[error("{}", error_chain(.0))]
    Board(#[from] BoardError),
}

impl LedRequestError {
    /// The HTTP status that says whose fault it was.
    pub fn http_status(&self) -> u16 {
        match self {
            LedRequestError::NotJson(_) => 400,
            LedRequestError::Shape(_)
            | LedRequestError::AllAndSides
            | LedRequestError::NothingToSet
            | LedRequestError::Board(BoardError::AboveLimit { .. }) => 422,
            LedRequestError::Board(BoardError::NoBoard) => 503,
            LedRequestError::Board(BoardError::Link(_)) => 502,
        }
    }
}

/// The LED request body: currents in mA per side, or `all`; `enabled` switches the addressed channels.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct LedBody {
    top: Option<u16>,
    right: Option<u16>,
    bottom: Option<u16>,
    left: Option<u16>,
    all: Option<u16>,
    enabled: Option<bool>,
}

/// Parses and checks an LED request body (JSON bytes) into the command the board is given.
pub fn parse_led_request(body: &[u8]) -> Result<LedCommand, LedRequestError> {
    let value: serde_json::Value = serde_json::from_slice(body).map_err(LedRequestError::NotJson)?;
    let body: LedBody = serde_json::from_value(value).map_err(LedRequestError::Shape)?;
    let per_side = [body.top, body.right, body.bottom, body.left];
    let current_ma = match body.all {
        Some(_) if per_side.iter().any(Option::is_some) => return Err(LedRequestError::AllAndSides),
        Some(all) => [Some(all); nusense_protocol::CHANNEL_COUNT],
        None => per_side,
    };
    if current_ma.iter().all(Option::is_none) && body.enabled.is_none() {
        return Err(LedRequestError::NothingToSet);
    }
    let command = LedCommand {
        current_ma,
        enabled: body.enabled,
    };
    command.validate()?;
    Ok(command)
}

/// What an accepted LED request answers: the board as it is after the command.
#[derive(Serialize)]
pub struct LedReply {
    pub board: BoardStatus,
}

/// Parses, checks and carries out an LED request. Blocks until the board has answered: call it off the async
/// runtime's workers.
pub fn apply_led_request(board: &Arc<dyn Board>, body: &[u8]) -> Result<LedReply, LedRequestError> {
    let command = parse_led_request(body)?;
    board.set_leds(&command)?;
    Ok(LedReply { board: board.status() })
}

/// What a tare answers: it happens on the next frame, not now.
#[derive(Serialize)]
pub struct TareReply {
    pub tare: &'static str,
}

/// Asks for a tare: the next frame becomes the rest frame.
pub fn tare(pipeline: &PipelineHandle) -> TareReply {
    pipeline.request_tare();
    TareReply {
        tare: "the next frame becomes the rest frame",
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::LED_LIMIT_MA;
    use nusense_protocol::Side;

    #[test]
    fn per_side_currents_become_one_command_leaving_the_others_alone() {
        let command = parse_led_request(br#"{"top": 60, "left": 90, "enabled": true}"#).unwrap();
        assert_eq!(
            command,
            LedCommand {
                current_ma: [Some(60), None, None, Some(90)],
                enabled: Some(true),
            }
        );
    }

    #[test]
    fn all_sets_every_side() {
        let command = parse_led_request(br#"{"all": 80}"#).unwrap();
        assert_eq!(command.current_ma, [Some(80); 4]);
        assert_eq!(command.enabled, None);
        let switch_only = parse_led_request(br#"{"enabled": false}"#).unwrap();
        assert_eq!(switch_only.current_ma, [None; 4]);
        assert_eq!(switch_only.enabled, Some(false));
    }

    #[test]
    fn bad_requests_are_refused_with_their_reason_and_status() {
        let cases: [(&[u8], u16, &str); 6] = [
            (
                b"{not json",
                400,
                "the LED request is not JSON: key must be a string at line 1 column 2",
            ),
            (
                br#"{"middle": 10}"#,
                422,
                "does not fit {top, right, bottom, left, all, enabled}: unknown field `middle`",
            ),
            (br#"{"top": -1}"#, 422, "invalid value: integer `-1`, expected u16"),
            (
                br#"{"all": 10, "top": 10}"#,
                422,
                "give either `all` or per-side currents, not both",
            ),
            (br#"{}"#, 422, "nothing to set"),
            (
                br#"{"right": 121}"#,
                422,
                "Right LED current 121 mA is above the 120 mA limit",
            ),
        ];
        assert_eq!(LED_LIMIT_MA, 120, "the cases below name the limit");
        for (body, status, message) in cases {
            let error = parse_led_request(body).unwrap_err();
            assert_eq!(error.http_status(), status, "{error}");
            assert!(
                error.to_string().contains(message),
                "{:?}: {error}",
                String::from_utf8_lossy(body)
            );
        }
        let above = parse_led_request(br#"{"right": 121}"#).unwrap_err();
        assert!(matches!(
            above,
            LedRequestError::Board(BoardError::AboveLimit {
                side: Side::Right,
                requested_ma: 121,
                ..
            })
        ));
    }
}
