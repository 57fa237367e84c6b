//! The board's persistent configuration and its flash record.
//!
//! A [`BoardConfig`] is saved as a fixed-size, CRC-protected [`ConfigRecord`] that also carries a sequence
//! number (the newest valid record wins at boot) and the id of the `SaveConfig` request that wrote it (so a
//! retried request is recognised and not written twice). Where the records live is [`crate::store`].

use nusense_protocol::CHANNEL_COUNT;

use crate::limits::{DEFAULT_RAMP_MS, MAX_CURRENT_MA, MAX_RAMP_MS, MAX_TOTAL_CURRENT_MA, NOMINAL_CURRENT_MA};

/// LED setpoints, soft-start and power budget, as restored at boot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BoardConfig {
    /// Per channel (protocol `Side` order), already clamped to [`MAX_CURRENT_MA`].
    pub setpoints_ma: [u16; CHANNEL_COUNT],
    pub enabled: [bool; CHANNEL_COUNT],
    /// Soft-start time from 0 to the setpoint.
    pub ramp_ms: u16,
    /// Cap on the sum of the string currents, at most [`MAX_TOTAL_CURRENT_MA`].
    pub current_budget_ma: u16,
}

impl Default for BoardConfig {
    /// Nominal current on every channel, all off until the host (or a saved configuration) enables them.
    fn default() -> Self {
        Self {
            setpoints_ma: [NOMINAL_CURRENT_MA; CHANNEL_COUNT],
            enabled: [false; CHANNEL_COUNT],
            ramp_ms: DEFAULT_RAMP_MS,
            current_budget_ma: MAX_TOTAL_CURRENT_MA,
        }
    }
}

impl BoardConfig {
    /// The same configuration with every value in its allowed range: what a hand-edited, foreign or corrupted
    /// source gets turned into, never trusted as it is.
    pub fn clamped(mut self) -> Self {
        for setpoint in &mut self.setpoints_ma {
            *setpoint = (*setpoint).min(MAX_CURRENT_MA);
        }
        self.ramp_ms = self.ramp_ms.min(MAX_RAMP_MS);
        self.current_budget_ma = self.current_budget_ma.min(MAX_TOTAL_CURRENT_MA);
        self
    }
}

/// Why a stored record was not taken.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RecordError {
    WrongLength {
        found: usize,
    },
    /// Never written (erased flash).
    Erased,
    BadMagic,
    /// A layout this firmware does not know (written by a newer one).
    UnsupportedLayout(u8),
    /// Damaged, or a write cut short by a power loss.
    BadCrc,
}

impl core::fmt::Display for RecordError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::WrongLength { found } => {
                write!(f, "config record has {found} bytes, expected {}", ConfigRecord::LEN)
            }
            Self::Erased => f.write_str("config slot is erased"),
            Self::BadMagic => f.write_str("config record does not start with the NUSense magic"),
            Self::UnsupportedLayout(v) => {
                write!(f, "config record layout {v} is unknown to this firmware")
            }
            Self::BadCrc => f.write_str("config record CRC does not match"),
        }
    }
}

const MAGIC: [u8; 4] = *b"NUSC";
/// Layout 1 was the 24-byte blob of the single-sector log; 2 adds the budget, sequence number and request id.
const LAYOUT: u8 = 2;
const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
/// What erased NOR flash reads as.
pub const ERASED: u8 = 0xFF;

/// One saved configuration, as it sits in a flash slot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ConfigRecord {
    pub config: BoardConfig,
    /// Incremented by every save; the valid record with the highest number is the current one.
    pub sequence: u32,
    /// The `SaveConfig` request that wrote this record.
    pub request_id: u32,
}

impl ConfigRecord {
    /// Size of a record and of a flash slot; a multiple of 8 so that every flash programming width divides it.
    pub const LEN: usize = 32;
    const CRC_AT: usize = Self::LEN - 4;

    /// Layout 2: magic "NUSC", layout, enabled bit mask, ramp_ms, 4 setpoints, budget (all LE u16), sequence
    /// (LE u32), request id (LE u32), 2 reserved bytes (0xFF), CRC-32 (ISO-HDLC, LE) of the 28 bytes before it.
    pub fn to_bytes(&self) -> [u8; Self::LEN] {
        let config = &self.config;
        let mut bytes = [ERASED; Self::LEN];
        bytes[0..4].copy_from_slice(&MAGIC);
        bytes[4] = LAYOUT;
        bytes[5] = config
            .enabled
            .iter()
            .enumerate()
            .fold(0u8, |mask, (i, &on)| mask | (u8::from(on) << i));
        bytes[6..8].copy_from_slice(&config.ramp_ms.to_le_bytes());
        for (i, setpoint) in config.setpoints_ma.iter().enumerate() {
            bytes[8 + 2 * i..10 + 2 * i].copy_from_slice(&setpoint.to_le_bytes());
        }
        bytes[16..18].copy_from_slice(&config.current_budget_ma.to_le_bytes());
        bytes[18..22].copy_from_slice(&self.sequence.to_le_bytes());
        bytes[22..26].copy_from_slice(&self.request_id.to_le_bytes());
        let crc = CRC32.checksum(&bytes[..Self::CRC_AT]);
        bytes[Self::CRC_AT..].copy_from_slice(&crc.to_le_bytes());
        bytes
    }

    /// Parses a record; values out of range are clamped ([`BoardConfig::clamped`]).
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, RecordError> {
        if bytes.len() != Self::LEN {
            return Err(RecordError::WrongLength { found: bytes.len() });
        }
        if bytes.iter().all(|&b| b == ERASED) {
            return Err(RecordError::Erased);
        }
        if bytes[0..4] != MAGIC {
            return Err(RecordError::BadMagic);
        }
        if bytes[4] != LAYOUT {
            return Err(RecordError::UnsupportedLayout(bytes[4]));
        }
        let stored_crc = u32::from_le_bytes([bytes[28], bytes[29], bytes[30], bytes[31]]);
        if CRC32.checksum(&bytes[..Self::CRC_AT]) != stored_crc {
            return Err(RecordError::BadCrc);
        }
        let u16_at = |i: usize| u16::from_le_bytes([bytes[i], bytes[i + 1]]);
        let u32_at = |i: usize| u32::from_le_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
        let config = BoardConfig {
            setpoints_ma: core::array::from_fn(|i| u16_at(8 + 2 * i)),
            enabled: core::array::from_fn(|i| bytes[5] & (1 << i) != 0),
            ramp_ms: u16_at(6),
            current_budget_ma: u16_at(16),
        };
        Ok(Self {
            config: config.clamped(),
            sequence: u32_at(18),
            request_id: u32_at(22),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> ConfigRecord {
        ConfigRecord {
            config: BoardConfig {
                setpoints_ma: [100, 90, 120, 0],
                enabled: [true, false, true, true],
                ramp_ms: 250,
                current_budget_ma: 300,
            },
            sequence: 0x0102_0304,
            request_id: 0xA0B0_C0D0,
        }
    }

    #[test]
    fn record_round_trips() {
        assert_eq!(ConfigRecord::from_bytes(&sample().to_bytes()), Ok(sample()));
    }

    #[test]
    fn corrupted_records_are_refused() {
        let mut bytes = sample().to_bytes();
        bytes[9] ^= 0x10;
        assert_eq!(ConfigRecord::from_bytes(&bytes), Err(RecordError::BadCrc));
        assert_eq!(ConfigRecord::from_bytes(&[0xFF; 32]), Err(RecordError::Erased));
        assert_eq!(ConfigRecord::from_bytes(&[0; 32]), Err(RecordError::BadMagic));
        assert_eq!(
            ConfigRecord::from_bytes(&[0; 3]),
            Err(RecordError::WrongLength { found: 3 })
        );
        let mut layout_1 = sample().to_bytes();
        layout_1[4] = 1;
        assert_eq!(
            ConfigRecord::from_bytes(&layout_1),
            Err(RecordError::UnsupportedLayout(1))
        );
    }

    #[test]
    fn out_of_range_values_are_clamped_on_load() {
        let mut bytes = sample().to_bytes();
        bytes[8..10].copy_from_slice(&5000u16.to_le_bytes());
        bytes[16..18].copy_from_slice(&u16::MAX.to_le_bytes());
        let crc = CRC32.checksum(&bytes[..28]);
        bytes[28..32].copy_from_slice(&crc.to_le_bytes());
        let record = ConfigRecord::from_bytes(&bytes).unwrap();
        assert_eq!(record.config.setpoints_ma[0], MAX_CURRENT_MA);
        assert_eq!(record.config.current_budget_ma, MAX_TOTAL_CURRENT_MA);
    }
}
