//! The board's persistent configuration and its flash representation.
//!
//! A [`BoardConfig`] becomes a fixed-size, CRC-protected blob ([`BoardConfig::to_blob`]). Flash is kept as an
//! append-only log of such blobs in one erased sector ([`scan_log`]): a save writes the next free slot, the newest
//! valid slot wins at boot, and the sector is erased only when it is full, so a save rarely erases and a power cut
//! mid-write leaves the previous configuration readable.

use nusense_protocol::CHANNEL_COUNT;

use crate::limits::{DEFAULT_RAMP_MS, MAX_CURRENT_MA, MAX_RAMP_MS, NOMINAL_CURRENT_MA};

/// LED setpoints and soft-start, as restored at boot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BoardConfig {
    /// Per channel (protocol `Side` order), already clamped to [`MAX_CURRENT_MA`].
    pub setpoints_ma: [u16; CHANNEL_COUNT],
    pub enabled: [bool; CHANNEL_COUNT],
    /// Soft-start time from 0 to the setpoint.
    pub ramp_ms: u16,
}

impl Default for BoardConfig {
    /// Nominal current on every channel, all off until the host (or a saved configuration) enables them.
    fn default() -> Self {
        Self {
            setpoints_ma: [NOMINAL_CURRENT_MA; CHANNEL_COUNT],
            enabled: [false; CHANNEL_COUNT],
            ramp_ms: DEFAULT_RAMP_MS,
        }
    }
}

/// Why a stored blob was not taken.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ConfigBlobError {
    WrongLength {
        found: usize,
    },
    /// Never written (erased flash).
    Erased,
    BadMagic,
    /// A layout this firmware does not know (written by a newer one).
    UnsupportedLayout(u8),
    BadCrc,
}

impl core::fmt::Display for ConfigBlobError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::WrongLength { found } => write!(
                f,
                "config blob has {found} bytes, expected {}",
                BoardConfig::BLOB_LEN
            ),
            Self::Erased => f.write_str("config slot is erased"),
            Self::BadMagic => f.write_str("config blob does not start with the NUSense magic"),
            Self::UnsupportedLayout(v) => {
                write!(f, "config blob layout {v} is unknown to this firmware")
            }
            Self::BadCrc => f.write_str("config blob CRC does not match"),
        }
    }
}

const MAGIC: [u8; 4] = *b"NUSC";
const LAYOUT: u8 = 1;
const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
const ERASED: u8 = 0xFF;

impl BoardConfig {
    /// Size of one blob and of one slot of the flash log; a multiple of 8 so that every flash programming width
    /// divides it.
    pub const BLOB_LEN: usize = 24;

    /// Layout: magic "NUSC", layout 1, enabled bit mask, ramp_ms (LE u16), 4 setpoints (LE u16), 4 reserved bytes
    /// (0xFF), CRC-32 (ISO-HDLC, LE) of the 20 bytes before it.
    pub fn to_blob(&self) -> [u8; Self::BLOB_LEN] {
        let mut blob = [ERASED; Self::BLOB_LEN];
        blob[0..4].copy_from_slice(&MAGIC);
        blob[4] = LAYOUT;
        blob[5] = self
            .enabled
            .iter()
            .enumerate()
            .fold(0u8, |mask, (i, &on)| mask | (u8::from(on) << i));
        blob[6..8].copy_from_slice(&self.ramp_ms.to_le_bytes());
        for (i, sp) in self.setpoints_ma.iter().enumerate() {
            blob[8 + 2 * i..10 + 2 * i].copy_from_slice(&sp.to_le_bytes());
        }
        let crc = CRC32.checksum(&blob[..20]);
        blob[20..24].copy_from_slice(&crc.to_le_bytes());
        blob
    }

    /// Parses a blob; values out of range (a hand-edited or foreign blob) are clamped, never trusted.
    pub fn from_blob(blob: &[u8]) -> Result<Self, ConfigBlobError> {
        if blob.len() != Self::BLOB_LEN {
            return Err(ConfigBlobError::WrongLength { found: blob.len() });
        }
        if blob.iter().all(|&b| b == ERASED) {
            return Err(ConfigBlobError::Erased);
        }
        if blob[0..4] != MAGIC {
            return Err(ConfigBlobError::BadMagic);
        }
        if blob[4] != LAYOUT {
            return Err(ConfigBlobError::UnsupportedLayout(blob[4]));
        }
        let stored_crc = u32::from_le_bytes([blob[20], blob[21], blob[22], blob[23]]);
        if CRC32.checksum(&blob[..20]) != stored_crc {
            return Err(ConfigBlobError::BadCrc);
        }
        let mut config = Self {
            setpoints_ma: [0; CHANNEL_COUNT],
            enabled: [false; CHANNEL_COUNT],
            ramp_ms: u16::from_le_bytes([blob[6], blob[7]]).min(MAX_RAMP_MS),
        };
        for i in 0..CHANNEL_COUNT {
            config.enabled[i] = blob[5] & (1 << i) != 0;
            config.setpoints_ma[i] =
                u16::from_le_bytes([blob[8 + 2 * i], blob[9 + 2 * i]]).min(MAX_CURRENT_MA);
        }
        Ok(config)
    }
}

/// What [`scan_log`] found in a flash sector used as a configuration log.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LogScan {
    /// The newest valid configuration, if any slot holds one.
    pub latest: Option<BoardConfig>,
    /// Byte offset of the first erased slot, where the next save goes; `None` when the sector is full and must
    /// be erased (then the save goes to offset 0).
    pub next_free: Option<usize>,
}

/// Scans a sector (its bytes as read from flash) slot by slot up to the first erased one. Slots that do not
/// parse (a write cut by a power loss) are skipped, so the newest good one wins.
pub fn scan_log(sector: &[u8]) -> LogScan {
    let mut latest = None;
    for (index, slot) in sector.chunks_exact(BoardConfig::BLOB_LEN).enumerate() {
        match BoardConfig::from_blob(slot) {
            Ok(config) => latest = Some(config),
            Err(ConfigBlobError::Erased) => {
                return LogScan {
                    latest,
                    next_free: Some(index * BoardConfig::BLOB_LEN),
                };
            }
            Err(_) => {}
        }
    }
    LogScan {
        latest,
        next_free: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> BoardConfig {
        BoardConfig {
            setpoints_ma: [100, 90, 120, 0],
            enabled: [true, false, true, true],
            ramp_ms: 250,
        }
    }

    #[test]
    fn blob_round_trips() {
        assert_eq!(BoardConfig::from_blob(&sample().to_blob()), Ok(sample()));
    }

    #[test]
    fn corrupted_blob_is_refused() {
        let mut blob = sample().to_blob();
        blob[9] ^= 0x10;
        assert_eq!(BoardConfig::from_blob(&blob), Err(ConfigBlobError::BadCrc));
        assert_eq!(
            BoardConfig::from_blob(&[0xFF; 24]),
            Err(ConfigBlobError::Erased)
        );
        assert_eq!(
            BoardConfig::from_blob(&[0; 24]),
            Err(ConfigBlobError::BadMagic)
        );
        assert_eq!(
            BoardConfig::from_blob(&[0; 3]),
            Err(ConfigBlobError::WrongLength { found: 3 })
        );
    }

    #[test]
    fn out_of_range_values_are_clamped_on_load() {
        let mut blob = sample().to_blob();
        blob[8..10].copy_from_slice(&5000u16.to_le_bytes());
        let crc = CRC32.checksum(&blob[..20]);
        blob[20..24].copy_from_slice(&crc.to_le_bytes());
        assert_eq!(
            BoardConfig::from_blob(&blob).unwrap().setpoints_ma[0],
            MAX_CURRENT_MA
        );
    }

    #[test]
    fn log_keeps_the_newest_good_slot_and_finds_the_next_free_one() {
        let mut sector = [0xFFu8; 24 * 4];
        assert_eq!(
            scan_log(&sector),
            LogScan {
                latest: None,
                next_free: Some(0)
            }
        );
        let older = BoardConfig::default();
        sector[0..24].copy_from_slice(&older.to_blob());
        sector[24..48].copy_from_slice(&sample().to_blob());
        assert_eq!(
            scan_log(&sector),
            LogScan {
                latest: Some(sample()),
                next_free: Some(48)
            }
        );
        // A write torn by a power cut: the slot is neither erased nor valid, the previous one stays in force.
        sector[48..52].copy_from_slice(b"NUSC");
        assert_eq!(
            scan_log(&sector),
            LogScan {
                latest: Some(sample()),
                next_free: Some(72)
            }
        );
        sector[72..96].copy_from_slice(&older.to_blob());
        assert_eq!(
            scan_log(&sector),
            LogScan {
                latest: Some(older),
                next_free: None
            }
        );
    }
}
