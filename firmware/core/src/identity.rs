//! Who the board is, as reported by `GetInfo`.

use heapless::String;
use nusense_protocol::{BOARD_ID_LEN, GIT_HASH_LEN, VERSION_TEXT_LEN};

#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Identity {
    pub firmware_version: String<VERSION_TEXT_LEN>,
    pub git_hash: String<GIT_HASH_LEN>,
    pub board_id: String<BOARD_ID_LEN>,
    /// The MCU's 96-bit factory unique id (also the USB serial number, in hex).
    pub mcu_uid: [u8; 12],
}

impl Identity {
    /// Texts longer than their protocol field are cut at a character boundary rather than refused: an identity
    /// must never stop a board from booting.
    pub fn new(firmware_version: &str, git_hash: &str, board_id: &str, mcu_uid: [u8; 12]) -> Self {
        Self {
            firmware_version: truncated(firmware_version),
            git_hash: truncated(git_hash),
            board_id: truncated(board_id),
            mcu_uid,
        }
    }

    /// The USB serial number: the unique id as 24 upper-case hex digits.
    pub fn serial_number(&self) -> String<24> {
        let mut s = String::new();
        for byte in self.mcu_uid {
            for nibble in [byte >> 4, byte & 0x0F] {
                let digit = char::from_digit(u32::from(nibble), 16)
                    .unwrap_or('0')
                    .to_ascii_uppercase();
                let _ = s.push(digit);
            }
        }
        s
    }
}

fn truncated<const N: usize>(text: &str) -> String<N> {
    let mut out = String::new();
    for c in text.chars() {
        if out.push(c).is_err() {
            break;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn long_texts_are_cut_and_serial_is_hex() {
        let id = Identity::new(
            "0.1.0",
            "0123456789abcdef",
            "nusense-led-board-v1",
            [0xAB, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 0x0F],
        );
        assert_eq!(id.git_hash.as_str(), "0123456789ab");
        assert_eq!(id.board_id.len(), BOARD_ID_LEN);
        assert_eq!(id.serial_number().as_str(), "AB0102030405060708090A0F");
    }
}
