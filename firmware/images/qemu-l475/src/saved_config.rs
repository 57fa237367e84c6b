//! QEMU does not model flash writes: the configuration blob is kept in RAM that the runtime does not initialise,
//! so it survives a `Reset` request (as it would in flash) for the life of the emulator process.

use core::mem::MaybeUninit;

use nusense_firmware_core::BoardConfig;

#[unsafe(link_section = ".uninit.nusense_config")]
static mut BLOB: MaybeUninit<[u8; BoardConfig::BLOB_LEN]> = MaybeUninit::uninit();

/// The saved configuration, or the default when nothing valid is there (first boot: RAM holds noise, which the
/// blob's magic and CRC reject).
pub fn restore() -> BoardConfig {
    // SAFETY: single-threaded boot code; any bit pattern is a valid [u8; N].
    let blob = unsafe { (*core::ptr::addr_of!(BLOB)).assume_init() };
    BoardConfig::from_blob(&blob).unwrap_or_default()
}

pub fn store(blob: &[u8; BoardConfig::BLOB_LEN]) {
    // SAFETY: only the main task writes, and nothing holds a reference into BLOB.
    unsafe { core::ptr::addr_of_mut!(BLOB).write(MaybeUninit::new(*blob)) };
}
