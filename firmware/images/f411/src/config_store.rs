//! The board configuration in flash: an append-only log of blobs (`nusense_firmware_core::config`) in the last
//! 128 KiB sector (sector 7, 0x0806_0000), far above the code (budget 96 KiB from 0x0800_0000). A save writes
//! the next free 24-byte slot; the sector is erased only when all 5461 slots are used.

use embassy_stm32::flash::{Blocking, Flash, FLASH_BASE};
use nusense_firmware_core::config::scan_log;
use nusense_firmware_core::BoardConfig;

const SECTOR_OFFSET: u32 = 0x6_0000;
const SECTOR_LEN: u32 = 0x2_0000;

fn sector() -> &'static [u8] {
    // SAFETY: the sector is memory-mapped flash, readable at any time; it is only written through `Flash`, and
    // never while this slice is being read (single executor, blocking flash calls).
    unsafe {
        core::slice::from_raw_parts(
            (FLASH_BASE as u32 + SECTOR_OFFSET) as *const u8,
            SECTOR_LEN as usize,
        )
    }
}

/// The newest saved configuration, or the default (all LEDs off) on a fresh board.
pub fn load() -> BoardConfig {
    scan_log(sector()).latest.unwrap_or_default()
}

/// Appends `blob`; `before_erase` runs before a (rare, up to 2 s) sector erase, to pet the watchdog.
pub fn save(
    flash: &mut Flash<'static, Blocking>,
    blob: &[u8; BoardConfig::BLOB_LEN],
    before_erase: impl FnOnce(),
) -> bool {
    let offset = match scan_log(sector()).next_free {
        Some(offset) => offset as u32,
        None => {
            before_erase();
            if flash
                .blocking_erase(SECTOR_OFFSET, SECTOR_OFFSET + SECTOR_LEN)
                .is_err()
            {
                return false;
            }
            0
        }
    };
    let written_ok = flash.blocking_write(SECTOR_OFFSET + offset, blob).is_ok();
    flush_flash_data_cache();
    if !written_ok {
        return false;
    }
    let written = &sector()[offset as usize..offset as usize + BoardConfig::BLOB_LEN];
    written == blob
}

/// The flash data cache may still hold the erased (0xFF) slot that `scan_log` just read; on single-bank F4 parts
/// embassy does not reset it after programming, so reset it here before anything reads the log again.
fn flush_flash_data_cache() {
    use embassy_stm32::pac::FLASH;
    let enabled = FLASH.acr().read().dcen();
    FLASH.acr().modify(|w| w.set_dcen(false));
    FLASH.acr().modify(|w| w.set_dcrst(true));
    FLASH.acr().modify(|w| w.set_dcrst(false));
    FLASH.acr().modify(|w| w.set_dcen(enabled));
}
