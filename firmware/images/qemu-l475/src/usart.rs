//! USART1 (PB6 TX, PB7 RX, AF7: the ST-LINK virtual COM port of the B-L475E-IOT01A) through the PAC, because
//! `embassy_stm32::init` waits for the backup-domain unlock that QEMU does not model. Reception is interrupt driven
//! into a ring buffer (QEMU holds further input until RDR is read, so polling would pace the link at the poll
//! rate); transmission polls TXE, which QEMU makes immediate.

use core::cell::RefCell;

use critical_section::Mutex;
use embassy_sync::waitqueue::AtomicWaker;
use heapless::Deque;
use stm32_metapac::gpio::vals::Moder;
use stm32_metapac::{interrupt, GPIOB, RCC, USART1};

const RX_CAPACITY: usize = 512;

static RX: Mutex<RefCell<Deque<u8, RX_CAPACITY>>> = Mutex::new(RefCell::new(Deque::new()));
static RX_WAKER: AtomicWaker = AtomicWaker::new();

pub fn init(kernel_clock_hz: u32, baud: u32) {
    RCC.ahb2enr().modify(|w| w.set_gpioben(true));
    RCC.apb2enr().modify(|w| w.set_usart1en(true));
    for pin in [6usize, 7] {
        GPIOB.moder().modify(|w| w.set_moder(pin, Moder::ALTERNATE));
        GPIOB.afr(0).modify(|w| w.set_afr(pin, 7));
    }
    USART1.brr().write(|w| w.set_brr((kernel_clock_hz / baud) as u16));
    USART1.cr1().write(|w| {
        w.set_te(true);
        w.set_re(true);
        w.set_rxneie(true);
        w.set_ue(true);
    });
    // SAFETY: the handler below only touches the RX ring through its critical section.
    unsafe { cortex_m::peripheral::NVIC::unmask(stm32_metapac::Interrupt::USART1) };
}

pub fn write(bytes: &[u8]) {
    for &b in bytes {
        while !USART1.isr().read().txe() {}
        USART1.tdr().write(|w| w.set_dr(u16::from(b)));
    }
}

/// Waits until bytes have arrived, then moves up to `buf.len()` of them into `buf`.
pub async fn read(buf: &mut [u8]) -> usize {
    core::future::poll_fn(|cx| {
        RX_WAKER.register(cx.waker());
        let n = critical_section::with(|cs| {
            let mut rx = RX.borrow(cs).borrow_mut();
            let mut n = 0;
            while n < buf.len() {
                match rx.pop_front() {
                    Some(b) => {
                        buf[n] = b;
                        n += 1;
                    }
                    None => break,
                }
            }
            n
        });
        if n > 0 {
            core::task::Poll::Ready(n)
        } else {
            core::task::Poll::Pending
        }
    })
    .await
}

#[interrupt]
fn USART1() {
    let isr = USART1.isr().read();
    if isr.ore() {
        USART1.icr().write(|w| w.set_ore(true));
    }
    if isr.rxne() {
        let byte = USART1.rdr().read().dr() as u8;
        critical_section::with(|cs| {
            // A full ring drops the byte; the protocol's CRC and resync turn that into one counted bad frame.
            let _ = RX.borrow(cs).borrow_mut().push_back(byte);
        });
        RX_WAKER.wake();
    }
}

/// USART2 (QEMU's second `-serial`), transmit only: the simulated strings' true currents, the light a camera
/// would see. The firmware's Controller never reads it; the host's hardware-in-the-loop check compares it with
/// what the board reports, so an image whose measurements or telemetry went wrong cannot pass on its own word.
pub mod light {
    use stm32_metapac::{RCC, USART2};

    pub fn init(kernel_clock_hz: u32, baud: u32) {
        RCC.apb1enr1().modify(|w| w.set_usart2en(true));
        USART2.brr().write(|w| w.set_brr((kernel_clock_hz / baud) as u16));
        USART2.cr1().write(|w| {
            w.set_te(true);
            w.set_ue(true);
        });
    }

    /// One line: `L`, the board time in microseconds (the clock telemetry's `uptime_us` is on), and the four
    /// currents in microamps, Top Right Bottom Left.
    pub fn report(uptime_us: u64, currents_ma: [f32; 4]) {
        let mut line: heapless::String<80> = heapless::String::new();
        let _ = core::fmt::Write::write_fmt(&mut line, format_args!("L {uptime_us}"));
        for current in currents_ma {
            let _ = core::fmt::Write::write_fmt(&mut line, format_args!(" {}", (current.max(0.0) * 1000.0) as u32));
        }
        let _ = line.push('\n');
        for &b in line.as_bytes() {
            while !USART2.isr().read().txe() {}
            USART2.tdr().write(|w| w.set_dr(u16::from(b)));
        }
    }
}
