//! The key layout of `serve --zenoh`: every key of a sensor is under `nusense/<serial>/`
//! (docs/integrations/zenoh.md is the layout for clients).

/// First chunk of every key.
pub const ROOT: &str = "nusense";
/// Every sensor's liveliness token: a client subscribes to liveliness on this to see sensors come and go.
pub const ALL_ALIVE: &str = "nusense/*/alive";

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum KeyError {
    #[error("a sensor's serial number names its Zenoh keys and cannot be empty")]
    EmptySerial,
    /// Zenoh gives `/`, `*`, `$`, `?`, `#` and others meanings in keys; serials are hex and never need them.
    #[error("serial number {serial:?} cannot name Zenoh keys: only ASCII letters, digits, '-', '_' and '.' may")]
    BadSerial { serial: String },
}

/// The keys of one sensor.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SensorKeys {
    serial: String,
}

impl SensorKeys {
    pub fn new(serial: &str) -> Result<Self, KeyError> {
        if serial.is_empty() {
            return Err(KeyError::EmptySerial);
        }
        let allowed = |c: char| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.');
        // "." and ".." alone read like path steps to people and tools: a serial has a letter or digit.
        if !serial.chars().all(allowed) || !serial.chars().any(|c| c.is_ascii_alphanumeric()) {
            return Err(KeyError::BadSerial {
                serial: serial.to_owned(),
            });
        }
        Ok(Self {
            serial: serial.to_owned(),
        })
    }

    pub fn serial(&self) -> &str {
        &self.serial
    }

    fn key(&self, leaf: &str) -> String {
        format!("{ROOT}/{}/{leaf}", self.serial)
    }

    /// Liveliness token, declared while the sensor is served.
    pub fn alive(&self) -> String {
        self.key("alive")
    }

    /// Every processed frame's reading (the WebSocket stream's message).
    pub fn reading(&self) -> String {
        self.key("reading")
    }

    /// Every processed frame's contacts.
    pub fn contacts(&self) -> String {
        self.key("contacts")
    }

    /// The board part of the status, whenever the board reports telemetry.
    pub fn telemetry(&self) -> String {
        self.key("telemetry")
    }

    /// The camera's JPEG: published while someone subscribes, and a queryable for the latest one.
    pub fn frame(&self) -> String {
        self.key("frame")
    }

    pub fn status(&self) -> String {
        self.key("status")
    }

    pub fn led(&self) -> String {
        self.key("led")
    }

    pub fn tare(&self) -> String {
        self.key("tare")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_key_is_under_the_sensors_serial() {
        let keys = SensorKeys::new("5642000012340000000000A1").unwrap();
        let all = [
            keys.alive(),
            keys.reading(),
            keys.contacts(),
            keys.telemetry(),
            keys.frame(),
            keys.status(),
            keys.led(),
            keys.tare(),
        ];
        assert_eq!(
            all,
            [
                "nusense/5642000012340000000000A1/alive",
                "nusense/5642000012340000000000A1/reading",
                "nusense/5642000012340000000000A1/contacts",
                "nusense/5642000012340000000000A1/telemetry",
                "nusense/5642000012340000000000A1/frame",
                "nusense/5642000012340000000000A1/status",
                "nusense/5642000012340000000000A1/led",
                "nusense/5642000012340000000000A1/tare",
            ]
        );
        for key in &all {
            zenoh::key_expr::KeyExpr::try_from(key.as_str()).expect("a valid key expression");
            assert!(
                zenoh::key_expr::KeyExpr::try_from(ALL_ALIVE)
                    .unwrap()
                    .intersects(&zenoh::key_expr::KeyExpr::try_from(keys.alive()).unwrap()),
                "the liveliness wildcard covers the sensor's token"
            );
        }
    }

    #[test]
    fn serials_that_would_change_the_keys_meaning_are_refused() {
        assert_eq!(SensorKeys::new(""), Err(KeyError::EmptySerial));
        for bad in ["a/b", "*", "**", "ab$*", "a?b", "a#b", "..", "a b", "é"] {
            assert_eq!(
                SensorKeys::new(bad),
                Err(KeyError::BadSerial { serial: bad.into() }),
                "{bad:?}"
            );
        }
        assert_eq!(SensorKeys::new("board-2_v1.0").unwrap().serial(), "board-2_v1.0");
    }
}
