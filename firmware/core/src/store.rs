//! Where [`ConfigRecord`]s live: two flash sectors used in turn, generic over `embedded-storage`'s
//! [`NorFlash`] so that the same code runs on the STM32F411 (two 16 KiB sectors), under QEMU and in the host's
//! virtual board (RAM that behaves like NOR flash), and is tested on the host with a power cut injected at
//! every step.
//!
//! Each sector is a log of fixed-size slots. A save appends the next record (sequence number + 1) to the
//! sector that holds the newest valid record; when that sector is full, the *other* sector is erased and the
//! record goes to its first slot. So an erase only ever destroys records that are already superseded, and a
//! write cut short leaves a slot that fails its CRC: at boot the valid record with the highest sequence number
//! wins, which is always the old configuration or the new one. A slot is written only when it and every slot
//! after it read erased, so the debris of an interrupted write or erase is never programmed over.

use embedded_storage::nor_flash::{ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash};

use crate::config::{BoardConfig, ConfigRecord, ERASED};

/// Why a save failed. The configuration in force before it is still the one restored at boot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StoreError<E> {
    Flash(E),
    /// The record read back differs from what was written.
    Verify,
}

impl<E> From<E> for StoreError<E> {
    fn from(error: E) -> Self {
        StoreError::Flash(error)
    }
}

/// The layout does not fit the flash: the sectors must be `F::ERASE_SIZE` long, aligned, distinct and inside it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LayoutError;

/// The two sectors and what was found in them.
pub struct ConfigStore<F> {
    flash: F,
    sectors: [u32; 2],
}

/// What one sector holds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct SectorScan {
    newest: Option<ConfigRecord>,
    /// The first slot after the last one that is not erased; `None` when that is past the end (sector full).
    free_slot: Option<u32>,
}

const SLOT_LEN: u32 = ConfigRecord::LEN as u32;

impl<F: NorFlash> ConfigStore<F> {
    /// A store in the two sectors that start at these offsets of `flash`.
    pub fn new(flash: F, sectors: [u32; 2]) -> Result<Self, LayoutError> {
        let erase = F::ERASE_SIZE as u32;
        let fits = |start: u32| {
            erase >= SLOT_LEN
                && start.is_multiple_of(erase)
                && erase.is_multiple_of(SLOT_LEN)
                && (SLOT_LEN as usize).is_multiple_of(F::WRITE_SIZE)
                && (SLOT_LEN as usize).is_multiple_of(F::READ_SIZE)
                && (start as usize)
                    .checked_add(erase as usize)
                    .is_some_and(|end| end <= flash.capacity())
        };
        if sectors[0] == sectors[1] || !fits(sectors[0]) || !fits(sectors[1]) {
            return Err(LayoutError);
        }
        Ok(Self { flash, sectors })
    }

    /// Slots per sector.
    pub fn slots_per_sector() -> u32 {
        F::ERASE_SIZE as u32 / SLOT_LEN
    }

    /// The current configuration record (the valid one with the highest sequence number), if any was saved.
    pub fn load(&mut self) -> Result<Option<ConfigRecord>, F::Error> {
        let [a, b] = [self.scan(0)?, self.scan(1)?];
        Ok(newer(a.newest, b.newest))
    }

    /// Saves `config` as written by request `request_id`. `before_erase` runs right before a sector erase (one
    /// in [`Self::slots_per_sector`] saves), which on a real chip stalls every fetch from flash for up to the
    /// worst-case erase time: the board glue switches the LEDs off and feeds the watchdog there.
    pub fn save(
        &mut self,
        config: &BoardConfig,
        request_id: u32,
        before_erase: impl FnOnce(),
    ) -> Result<ConfigRecord, StoreError<F::Error>> {
        let scans = [self.scan(0)?, self.scan(1)?];
        let newest = newer(scans[0].newest, scans[1].newest);
        // The sector holding the newest record; either one while nothing valid exists.
        let active = match (scans[0].newest, scans[1].newest) {
            (_, Some(b)) if newest == Some(b) => 1,
            _ => 0,
        };
        let (sector, slot) = match scans[active].free_slot {
            Some(slot) => (active, slot),
            None => {
                let other = 1 - active;
                before_erase();
                let start = self.sectors[other];
                self.flash.erase(start, start + F::ERASE_SIZE as u32)?;
                (other, 0)
            }
        };
        let record = ConfigRecord {
            config: *config,
            sequence: newest.map_or(1, |record| record.sequence.wrapping_add(1)),
            request_id,
        };
        let offset = self.sectors[sector] + slot * SLOT_LEN;
        let bytes = record.to_bytes();
        self.flash.write(offset, &bytes)?;
        let mut read_back = [0u8; ConfigRecord::LEN];
        self.flash.read(offset, &mut read_back)?;
        if read_back != bytes {
            return Err(StoreError::Verify);
        }
        Ok(record)
    }

    pub fn flash(&mut self) -> &mut F {
        &mut self.flash
    }

    pub fn into_flash(self) -> F {
        self.flash
    }

    fn scan(&mut self, sector: usize) -> Result<SectorScan, F::Error> {
        let start = self.sectors[sector];
        let mut scan = SectorScan::default();
        let mut last_used = None;
        let mut slot = [0u8; ConfigRecord::LEN];
        for index in 0..Self::slots_per_sector() {
            self.flash.read(start + index * SLOT_LEN, &mut slot)?;
            if slot.iter().all(|&b| b == ERASED) {
                continue;
            }
            last_used = Some(index);
            if let Ok(record) = ConfigRecord::from_bytes(&slot) {
                scan.newest = newer(scan.newest, Some(record));
            }
        }
        let next = last_used.map_or(0, |used| used + 1);
        scan.free_slot = (next < Self::slots_per_sector()).then_some(next);
        Ok(scan)
    }
}

fn newer(a: Option<ConfigRecord>, b: Option<ConfigRecord>) -> Option<ConfigRecord> {
    match (a, b) {
        (Some(a), Some(b)) => Some(if b.sequence > a.sequence { b } else { a }),
        (a, None) => a,
        (None, b) => b,
    }
}

/// RAM that behaves like NOR flash (programming only clears bits, erasing sets a whole sector to 0xFF): the
/// configuration "flash" of the QEMU image (RAM that survives a reset) and of the host's virtual board.
pub struct RamFlash<'a, const ERASE_SIZE: usize> {
    bytes: &'a mut [u8],
}

impl<'a, const ERASE_SIZE: usize> RamFlash<'a, ERASE_SIZE> {
    pub fn new(bytes: &'a mut [u8]) -> Self {
        Self { bytes }
    }
}

/// An access outside the RAM flash or not aligned to its sizes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RamFlashError {
    OutOfBounds,
    NotAligned,
}

impl NorFlashError for RamFlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            RamFlashError::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            RamFlashError::NotAligned => NorFlashErrorKind::NotAligned,
        }
    }
}

impl<const ERASE_SIZE: usize> ErrorType for RamFlash<'_, ERASE_SIZE> {
    type Error = RamFlashError;
}

impl<const ERASE_SIZE: usize> RamFlash<'_, ERASE_SIZE> {
    fn range(&self, offset: u32, len: usize) -> Result<core::ops::Range<usize>, RamFlashError> {
        let start = offset as usize;
        let end = start.checked_add(len).ok_or(RamFlashError::OutOfBounds)?;
        if end > self.bytes.len() {
            return Err(RamFlashError::OutOfBounds);
        }
        Ok(start..end)
    }
}

impl<const ERASE_SIZE: usize> ReadNorFlash for RamFlash<'_, ERASE_SIZE> {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        let range = self.range(offset, bytes.len())?;
        bytes.copy_from_slice(&self.bytes[range]);
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.bytes.len()
    }
}

impl<const ERASE_SIZE: usize> NorFlash for RamFlash<'_, ERASE_SIZE> {
    const WRITE_SIZE: usize = 4;
    const ERASE_SIZE: usize = ERASE_SIZE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        if !from.is_multiple_of(ERASE_SIZE as u32) || !to.is_multiple_of(ERASE_SIZE as u32) || to < from {
            return Err(RamFlashError::NotAligned);
        }
        let range = self.range(from, (to - from) as usize)?;
        self.bytes[range].fill(ERASED);
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        if !(offset as usize).is_multiple_of(Self::WRITE_SIZE) || !bytes.len().is_multiple_of(Self::WRITE_SIZE) {
            return Err(RamFlashError::NotAligned);
        }
        let range = self.range(offset, bytes.len())?;
        for (cell, &byte) in self.bytes[range].iter_mut().zip(bytes) {
            *cell &= byte;
        }
        Ok(())
    }
}
