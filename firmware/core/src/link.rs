//! Whether a host has the port open, on links that cannot say so. USB CDC-ACM has DTR; a plain UART (the QEMU
//! image's USART1) has no modem lines, so there the host's link sends a lone 0x00 (an empty frame, ignored by
//! the decoder) at least every [`HOST_KEEPALIVE_MS`] while it has the port open, and the board takes a longer
//! silence as a closed port.

/// How often a host keeps a UART link alive when it has nothing else to send.
pub const HOST_KEEPALIVE_MS: u64 = 1_000;

/// "DTR" for a UART: present while the host was heard from within the limit.
#[derive(Clone, Copy, Debug)]
pub struct HostLease {
    silence_limit_us: u64,
    last_heard_us: Option<u64>,
}

impl HostLease {
    /// `silence_limit_us` should be a few keepalive periods, so one late keepalive does not end a session.
    pub const fn new(silence_limit_us: u64) -> Self {
        Self {
            silence_limit_us,
            last_heard_us: None,
        }
    }

    /// Bytes arrived from the host at `now_us`.
    pub fn heard_from(&mut self, now_us: u64) {
        self.last_heard_us = Some(now_us);
    }

    pub fn is_present(&self, now_us: u64) -> bool {
        self.last_heard_us
            .is_some_and(|heard| now_us.saturating_sub(heard) <= self.silence_limit_us)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_lease_runs_out_after_the_silence_limit() {
        let mut lease = HostLease::new(3 * HOST_KEEPALIVE_MS * 1_000);
        assert!(!lease.is_present(0), "nobody has spoken yet");
        lease.heard_from(1_000_000);
        assert!(lease.is_present(1_000_000) && lease.is_present(4_000_000));
        assert!(!lease.is_present(4_000_001));
        lease.heard_from(4_500_000);
        assert!(lease.is_present(7_000_000));
    }
}
