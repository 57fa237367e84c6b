//! Microseconds since boot from the core's cycle counter (DWT CYCCNT at 96 MHz): the control loop's period and
//! jitter are measured on it to a cycle, where embassy-time's tick (10 kHz in this workspace) would hide anything
//! below 100 us. The 32-bit counter wraps every 44.7 s; it is extended to 64 bits on every read, and the control
//! loop reads it every 500 us.

use core::cell::Cell;

use critical_section::Mutex;

const CYCLES_PER_US: u64 = 96;

/// (last counter value seen, wraps so far).
static EXTENDED: Mutex<Cell<(u32, u64)>> = Mutex::new(Cell::new((0, 0)));

/// Starts the cycle counter; call once at boot.
pub fn start(dcb: &mut cortex_m::peripheral::DCB, dwt: &mut cortex_m::peripheral::DWT) {
    dcb.enable_trace();
    dwt.enable_cycle_counter();
}

pub fn now_us() -> u64 {
    critical_section::with(|cs| {
        let cell = EXTENDED.borrow(cs);
        let (last, mut wraps) = cell.get();
        let now = cortex_m::peripheral::DWT::cycle_count();
        if now < last {
            wraps += 1;
        }
        cell.set((now, wraps));
        ((wraps << 32) | u64::from(now)) / CYCLES_PER_US
    })
}
