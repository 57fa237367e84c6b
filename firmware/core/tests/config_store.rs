//! The configuration store against a simulated NOR flash that loses power at a chosen step: after a cut at any
//! word write and at any point of any erase, a fresh boot reads back the old configuration or the new one, never
//! anything else, and the next save works.

use embedded_storage::nor_flash::{ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash};
use nusense_firmware_core::{BoardConfig, ConfigRecord, ConfigStore, RamFlash};

/// Two 16 KiB sectors, as on the STM32F411 (sectors 1 and 2).
const SECTOR: usize = 16 * 1024;
const SECTORS: [u32; 2] = [0, SECTOR as u32];
/// Steps an erase is cut into: a cut lands between two of them and leaves the rest of the sector as it was,
/// with the piece being erased when the power went half erased.
const ERASE_PIECES: usize = 8;

#[derive(Debug, PartialEq, Eq)]
struct PowerLost;

impl NorFlashError for PowerLost {
    fn kind(&self) -> NorFlashErrorKind {
        NorFlashErrorKind::Other
    }
}

/// NOR flash (programming clears bits, erase sets 0xFF) that counts its steps and dies at step `cut_at`: the word
/// being programmed then holds only some of its new zero bits, the erase piece under way some of its ones.
struct CuttableFlash {
    bytes: Vec<u8>,
    steps: usize,
    cut_at: Option<usize>,
    dead: bool,
    noise: u64,
}

impl CuttableFlash {
    fn new(bytes: Vec<u8>, cut_at: Option<usize>) -> Self {
        Self {
            bytes,
            steps: 0,
            cut_at,
            dead: false,
            noise: 0x9E37_79B9_7F4A_7C15 ^ cut_at.unwrap_or(0) as u64,
        }
    }

    fn random_byte(&mut self) -> u8 {
        self.noise ^= self.noise << 13;
        self.noise ^= self.noise >> 7;
        self.noise ^= self.noise << 17;
        self.noise as u8
    }

    /// One step; `Err` when the power goes now (and for every later call).
    fn step(&mut self) -> Result<(), PowerLost> {
        if self.dead {
            return Err(PowerLost);
        }
        if Some(self.steps) == self.cut_at {
            self.dead = true;
            return Err(PowerLost);
        }
        self.steps += 1;
        Ok(())
    }
}

impl ErrorType for CuttableFlash {
    type Error = PowerLost;
}

impl ReadNorFlash for CuttableFlash {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), PowerLost> {
        if self.dead {
            return Err(PowerLost);
        }
        let start = offset as usize;
        bytes.copy_from_slice(&self.bytes[start..start + bytes.len()]);
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.bytes.len()
    }
}

impl NorFlash for CuttableFlash {
    const WRITE_SIZE: usize = 4;
    const ERASE_SIZE: usize = SECTOR;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), PowerLost> {
        let piece = SECTOR / ERASE_PIECES;
        for start in (from as usize..to as usize).step_by(piece) {
            if self.step().is_err() {
                for i in start..start + piece {
                    let ones = self.random_byte();
                    self.bytes[i] |= ones;
                }
                return Err(PowerLost);
            }
            self.bytes[start..start + piece].fill(0xFF);
        }
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), PowerLost> {
        assert_eq!(offset % 4, 0, "word aligned");
        for (word, chunk) in bytes.chunks(4).enumerate() {
            let at = offset as usize + 4 * word;
            if self.step().is_err() {
                for (i, &byte) in chunk.iter().enumerate() {
                    let some_zeros = byte | self.random_byte();
                    self.bytes[at + i] &= some_zeros;
                }
                return Err(PowerLost);
            }
            for (i, &byte) in chunk.iter().enumerate() {
                assert_eq!(
                    self.bytes[at + i] & byte,
                    byte,
                    "programming over a non-erased byte at {}",
                    at + i
                );
                self.bytes[at + i] &= byte;
            }
        }
        Ok(())
    }
}

fn config(n: u16) -> BoardConfig {
    BoardConfig {
        setpoints_ma: [n % 121, 100, 50, 120],
        enabled: [n.is_multiple_of(2), true, false, true],
        ramp_ms: n,
        current_budget_ma: 400,
    }
}

fn load(bytes: &[u8]) -> Option<ConfigRecord> {
    let mut store = ConfigStore::new(CuttableFlash::new(bytes.to_vec(), None), SECTORS).unwrap();
    store.load().unwrap()
}

/// Saves `count` configurations into `bytes` with no cut, returning the last.
fn fill(bytes: &mut Vec<u8>, first: u16, count: u16) -> Option<ConfigRecord> {
    let mut store = ConfigStore::new(CuttableFlash::new(std::mem::take(bytes), None), SECTORS).unwrap();
    let mut last = None;
    for n in first..first + count {
        last = Some(store.save(&config(n), u32::from(n), || {}).unwrap());
    }
    *bytes = store.into_flash().bytes;
    last
}

/// From `start`, a save of `config(new)` cut at every step it takes: a boot afterwards finds `old` or the new
/// record, and a save after that boot lands. Returns the number of steps of an uncut save.
fn cut_everywhere(start: &[u8], old: Option<ConfigRecord>, new: u16) -> usize {
    let steps_of_uncut = {
        let mut store = ConfigStore::new(CuttableFlash::new(start.to_vec(), None), SECTORS).unwrap();
        store.save(&config(new), u32::from(new), || {}).unwrap();
        store.into_flash().steps
    };
    for cut_at in 0..=steps_of_uncut {
        let mut store = ConfigStore::new(CuttableFlash::new(start.to_vec(), Some(cut_at)), SECTORS).unwrap();
        let outcome = store.save(&config(new), u32::from(new), || {});
        let after_cut = store.into_flash().bytes;
        let found = load(&after_cut);
        let is_new = found.is_some_and(|r| r.config == config(new) && r.request_id == u32::from(new));
        assert!(
            found == old || is_new,
            "cut at step {cut_at} of {steps_of_uncut}: found {found:?}, old {old:?}"
        );
        if cut_at == steps_of_uncut {
            assert!(outcome.is_ok() && is_new);
        } else {
            assert!(outcome.is_err(), "a cut save reports its failure");
        }
        // Whatever the cut left behind, the next boot can save again and that save wins.
        let mut again = after_cut;
        let saved = fill(&mut again, 900, 1).unwrap();
        assert_eq!(load(&again), Some(saved), "save after a cut at step {cut_at}");
        assert!(saved.sequence > old.map_or(0, |r| r.sequence));
    }
    steps_of_uncut
}

#[test]
fn a_power_cut_during_the_first_save_leaves_nothing_or_the_new_config() {
    let erased = vec![0xFF; 2 * SECTOR];
    assert_eq!(load(&erased), None);
    let steps = cut_everywhere(&erased, None, 1);
    assert_eq!(
        steps, 8,
        "one 32-byte record is 8 words, and a blank sector needs no erase"
    );
}

#[test]
fn a_power_cut_during_an_append_leaves_the_old_or_the_new_config() {
    let mut bytes = vec![0xFF; 2 * SECTOR];
    let old = fill(&mut bytes, 1, 5);
    assert_eq!(load(&bytes), old);
    cut_everywhere(&bytes, old, 6);
}

#[test]
fn a_power_cut_while_switching_sectors_leaves_the_old_or_the_new_config() {
    let slots = ConfigStore::<CuttableFlash>::slots_per_sector() as u16;
    assert_eq!(slots, 512);
    // Sector 0 full, sector 1 holding stale records from the previous round: the next save erases sector 1.
    let mut bytes = vec![0xFF; 2 * SECTOR];
    let old = fill(&mut bytes, 1, 2 * slots);
    assert_eq!(old.unwrap().sequence, u32::from(2 * slots));
    let steps = cut_everywhere(&bytes, old, 5000);
    assert_eq!(steps, ERASE_PIECES + 8, "an erase of the stale sector, then the record");
}

/// Noise where the store expects flash (the QEMU image's RAM at power-on, a sector some other firmware wrote):
/// nothing valid is found, the first save erases a sector before writing, and cuts there are safe too.
#[test]
fn garbage_in_both_sectors_reads_as_no_config_and_is_erased_before_use() {
    let mut noise = CuttableFlash::new(vec![0; 2 * SECTOR], None);
    let garbage: Vec<u8> = (0..2 * SECTOR).map(|_| noise.random_byte()).collect();
    assert_eq!(load(&garbage), None);
    let steps = cut_everywhere(&garbage, None, 7);
    assert_eq!(steps, ERASE_PIECES + 8);
}

#[test]
fn before_erase_runs_only_when_a_sector_is_erased() {
    let slots = ConfigStore::<CuttableFlash>::slots_per_sector();
    let mut store = ConfigStore::new(CuttableFlash::new(vec![0xFF; 2 * SECTOR], None), SECTORS).unwrap();
    let mut erases = 0;
    for n in 0..3 * slots {
        store.save(&config(n as u16), n, || erases += 1).unwrap();
    }
    // Sector 0 was blank; sector 1 is erased when 0 fills, sector 0 again when 1 fills.
    assert_eq!(erases, 2);
    assert_eq!(store.load().unwrap().unwrap().request_id, 3 * slots - 1);
}

#[test]
fn a_layout_that_does_not_fit_the_flash_is_refused() {
    let flash = || CuttableFlash::new(vec![0xFF; 2 * SECTOR], None);
    assert!(ConfigStore::new(flash(), [0, 0]).is_err());
    assert!(ConfigStore::new(flash(), [0, 100]).is_err());
    assert!(ConfigStore::new(flash(), [0, 2 * SECTOR as u32]).is_err());
}

/// The RAM flash of the QEMU image and the virtual board keeps NOR semantics, so the store behaves there as on
/// the chip.
#[test]
fn the_store_works_the_same_on_ram_flash() {
    let mut ram = vec![0xA5u8; 2 * 1024];
    let mut store = ConfigStore::new(RamFlash::<1024>::new(&mut ram), [0, 1024]).unwrap();
    assert_eq!(store.load().unwrap(), None);
    for n in 0..100u16 {
        store.save(&config(n), u32::from(n), || {}).unwrap();
    }
    let newest = store.load().unwrap().unwrap();
    assert_eq!(
        (newest.config, newest.request_id, newest.sequence),
        (config(99), 99, 100)
    );
}
