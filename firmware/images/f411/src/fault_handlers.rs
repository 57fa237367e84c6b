//! What happens when the firmware goes wrong (in the binary only: the on-target tests bring embedded-test's own
//! panic handler): every path drives the LED gates low first, then reports, then
//! resets (or, with a debugger attached, stops where it is so the probe can show why).
//!
//! - a panic ([`panic`]), including defmt's `unwrap!`/`panic!` (they end in `core::panic!`);
//! - a HardFault, which is also where a stack overflow ends (memory.x puts the stack at the bottom of RAM, so
//!   it overflows into unmapped memory and faults instead of corrupting static data);
//! - a stalled control loop: the independent watchdog resets the board, and a reset leaves the gates to their
//!   100 kOhm pull-downs.

use cortex_m::peripheral::{DCB, SCB};

use nusense_f411::board::force_gates_low;

/// True when a debugger has enabled halting debug (DHCSR.C_DEBUGEN).
fn debugger_attached() -> bool {
    // SAFETY: a read of a core debug register, no side effects.
    unsafe { (*DCB::PTR).dhcsr.read() & 1 != 0 }
}

/// Stop here for the debugger, or reset the board without one.
fn halt_or_reset() -> ! {
    if debugger_attached() {
        loop {
            cortex_m::asm::bkpt();
        }
    }
    SCB::sys_reset()
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    force_gates_low();
    defmt::error!("panic: {}", defmt::Display2Format(info));
    halt_or_reset()
}

#[cortex_m_rt::exception]
unsafe fn HardFault(frame: &cortex_m_rt::ExceptionFrame) -> ! {
    force_gates_low();
    defmt::error!("hard fault at pc {=u32:#x}", frame.pc());
    halt_or_reset()
}
