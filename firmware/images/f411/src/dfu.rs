//! `EnterBootloader`: reboot into the STM32F411's ROM DFU bootloader (then `dfu-util` flashes over USB).
//!
//! The request is a magic word in RAM that the runtime does not initialise; the next boot sees it before any
//! clock or peripheral is touched and jumps to system memory, as the ROM bootloader expects a reset state.

use core::mem::MaybeUninit;

const REQUEST_MAGIC: u32 = 0xDF00_B007;
const SYSTEM_MEMORY: u32 = 0x1FFF_0000;

#[unsafe(link_section = ".uninit.nusense_dfu")]
static mut REQUEST: MaybeUninit<u32> = MaybeUninit::uninit();

/// Reset now and come up in the ROM bootloader.
pub fn reboot_into_bootloader() -> ! {
    // SAFETY: plain store to our own static; nothing else holds a reference to it.
    unsafe { core::ptr::addr_of_mut!(REQUEST).write(MaybeUninit::new(REQUEST_MAGIC)) };
    cortex_m::peripheral::SCB::sys_reset()
}

/// Call first thing at boot: jumps to the ROM bootloader if the previous run asked for it.
pub fn jump_if_requested() {
    // SAFETY: any bit pattern is a valid u32; this runs before anything else uses the static.
    let requested = unsafe { (*core::ptr::addr_of!(REQUEST)).assume_init() } == REQUEST_MAGIC;
    if !requested {
        return;
    }
    // SAFETY: as above.
    unsafe { core::ptr::addr_of_mut!(REQUEST).write(MaybeUninit::new(0)) };
    // Map system memory at 0x0000_0000, as a BOOT0 boot would, so the bootloader finds its vectors.
    embassy_stm32::pac::RCC.apb2enr().modify(|w| w.set_syscfgen(true));
    embassy_stm32::pac::SYSCFG.memrm().modify(|w| w.set_mem_mode(1));
    // SAFETY: the system memory holds a valid vector table; nothing has been set up that it would trip over.
    unsafe { cortex_m::asm::bootload(SYSTEM_MEMORY as *const u32) }
}
