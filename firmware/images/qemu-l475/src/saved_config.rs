//! QEMU does not model flash writes: the configuration store runs on RAM that the runtime does not initialise
//! ([`RamFlash`], NOR semantics), so a saved configuration survives a `Reset` request, as it would in flash, for
//! the life of the emulator process. At power-on the RAM holds whatever QEMU left there: the store's magic and
//! CRC reject it and the first save erases a sector first, exactly as on a board with foreign data in flash.

use core::mem::MaybeUninit;

use nusense_firmware_core::{ConfigStore, RamFlash};

/// Two small sectors: the store's logic does not depend on their size, and boot scans stay short.
const SECTOR_LEN: usize = 4 * 1024;

pub type Store = ConfigStore<RamFlash<'static, SECTOR_LEN>>;

#[unsafe(link_section = ".uninit.nusense_config")]
static mut FLASH: MaybeUninit<[u8; 2 * SECTOR_LEN]> = MaybeUninit::uninit();

/// The store; call once.
pub fn take() -> Store {
    // SAFETY: called once at boot, so this is the only reference to FLASH; any bit pattern is a valid [u8; N].
    let bytes: &'static mut [u8; 2 * SECTOR_LEN] = unsafe { (*core::ptr::addr_of_mut!(FLASH)).assume_init_mut() };
    ConfigStore::new(RamFlash::new(bytes), [0, SECTOR_LEN as u32]).expect("two whole sectors")
}
