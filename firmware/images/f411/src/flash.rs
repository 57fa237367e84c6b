//! The two 16 KiB configuration sectors (1 and 2, see memory.x) as `embedded-storage` NOR flash, driven through
//! the flash interface registers (RM0383 section 3): embassy-stm32's sector erase leaves the parallelism (PSIZE)
//! at whatever an earlier write set, the reset value x8 included, which takes twice as long as x32 (DS10314:
//! 16 KiB at x8 400-800 ms, at x32 250-500 ms). This board runs at 3.3 V, where x32 is allowed.

use embassy_stm32::pac::flash::vals::Psize;
use embassy_stm32::pac::FLASH;
use embedded_storage::nor_flash::{ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash};

/// Where the two sectors sit in the address space (memory.x `_config_sectors_start`).
pub const CONFIG_BASE: u32 = 0x0800_4000;
pub const SECTOR_LEN: u32 = 16 * 1024;
/// Sector number of the first configuration sector (RM0383 table 4).
const FIRST_SECTOR: u8 = 1;
const KEY1: u32 = 0x4567_0123;
const KEY2: u32 = 0xCDEF_89AB;

/// Sectors 1 and 2; offsets are from [`CONFIG_BASE`].
pub struct ConfigFlash {
    _flash: embassy_stm32::Peri<'static, embassy_stm32::peripherals::FLASH>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub enum FlashError {
    OutOfBounds,
    NotAligned,
    /// The flash interface reported a programming or protection error (FLASH_SR), value attached.
    Hardware(u32),
}

impl NorFlashError for FlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            FlashError::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            FlashError::NotAligned => NorFlashErrorKind::NotAligned,
            FlashError::Hardware(_) => NorFlashErrorKind::Other,
        }
    }
}

impl ConfigFlash {
    pub fn new(flash: embassy_stm32::Peri<'static, embassy_stm32::peripherals::FLASH>) -> Self {
        Self { _flash: flash }
    }

    fn check(offset: u32, len: usize) -> Result<(), FlashError> {
        match offset.checked_add(len as u32) {
            Some(end) if end <= 2 * SECTOR_LEN => Ok(()),
            _ => Err(FlashError::OutOfBounds),
        }
    }

    /// Unlocks the control register, runs `operation` with no earlier error pending, waits for it to finish,
    /// locks again and reports what the status register says.
    fn with_unlocked(operation: impl FnOnce()) -> Result<(), FlashError> {
        wait_idle();
        if FLASH.cr().read().lock() {
            FLASH.keyr().write_value(KEY1);
            FLASH.keyr().write_value(KEY2);
        }
        // Error flags are cleared by writing 1.
        FLASH.sr().write_value(FLASH.sr().read());
        operation();
        wait_idle();
        let status = FLASH.sr().read();
        FLASH.cr().modify(|w| {
            w.set_ser(false);
            w.set_pg(false);
            w.set_lock(true);
        });
        reset_data_cache();
        let failed = status.pgserr() || status.pgperr() || status.pgaerr() || status.wrperr() || status.operr();
        if failed {
            Err(FlashError::Hardware(status.0))
        } else {
            Ok(())
        }
    }
}

fn wait_idle() {
    while FLASH.sr().read().bsy() {}
}

/// The data cache may still hold what a slot read before it was programmed or erased (RM0383 3.4.2: reset it
/// only while disabled).
fn reset_data_cache() {
    let enabled = FLASH.acr().read().dcen();
    FLASH.acr().modify(|w| w.set_dcen(false));
    FLASH.acr().modify(|w| w.set_dcrst(true));
    FLASH.acr().modify(|w| w.set_dcrst(false));
    FLASH.acr().modify(|w| w.set_dcen(enabled));
}

impl ErrorType for ConfigFlash {
    type Error = FlashError;
}

impl ReadNorFlash for ConfigFlash {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
        Self::check(offset, bytes.len())?;
        for (i, byte) in bytes.iter_mut().enumerate() {
            // SAFETY: inside sectors 1-2, memory-mapped flash that is always readable; nothing else writes it.
            *byte = unsafe { core::ptr::read_volatile((CONFIG_BASE + offset + i as u32) as *const u8) };
        }
        Ok(())
    }

    fn capacity(&self) -> usize {
        2 * SECTOR_LEN as usize
    }
}

impl NorFlash for ConfigFlash {
    const WRITE_SIZE: usize = 4;
    const ERASE_SIZE: usize = SECTOR_LEN as usize;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
        if !from.is_multiple_of(SECTOR_LEN) || !to.is_multiple_of(SECTOR_LEN) || to < from {
            return Err(FlashError::NotAligned);
        }
        Self::check(from, (to - from) as usize)?;
        for start in (from..to).step_by(SECTOR_LEN as usize) {
            let sector = FIRST_SECTOR + (start / SECTOR_LEN) as u8;
            Self::with_unlocked(|| {
                FLASH.cr().modify(|w| {
                    w.set_psize(Psize::PSIZE32);
                    w.set_ser(true);
                    w.set_snb(sector);
                });
                FLASH.cr().modify(|w| w.set_strt(true));
            })?;
        }
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        if !offset.is_multiple_of(4) || !bytes.len().is_multiple_of(4) {
            return Err(FlashError::NotAligned);
        }
        Self::check(offset, bytes.len())?;
        for (i, word) in bytes.chunks_exact(4).enumerate() {
            let address = CONFIG_BASE + offset + 4 * i as u32;
            let value = u32::from_le_bytes([word[0], word[1], word[2], word[3]]);
            Self::with_unlocked(|| {
                FLASH.cr().modify(|w| {
                    w.set_psize(Psize::PSIZE32);
                    w.set_pg(true);
                });
                // SAFETY: a word-aligned address inside sectors 1-2, programmed with PG set as RM0383 3.6.4 asks.
                unsafe { core::ptr::write_volatile(address as *mut u32, value) };
            })?;
        }
        Ok(())
    }
}
