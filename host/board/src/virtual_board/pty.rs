//! The board's end of a pseudo-terminal: the master side, which the virtual board reads and writes while the
//! host opens the slave path like any serial device.

use std::io;
use std::os::fd::AsRawFd;
use std::time::Duration;

use serialport::{SerialPort, TTYPort};

/// What a read on the master found.
#[derive(Debug, PartialEq, Eq)]
pub(crate) enum MasterRead {
    Data(usize),
    /// Nothing within the timeout; the host has the slave open.
    Nothing,
    /// No process has the slave open: the host closed the port (or never opened it).
    HostAbsent,
}

pub(crate) struct PtyMaster {
    master: TTYPort,
    slave_path: String,
}

impl PtyMaster {
    /// A new pseudo-terminal. Its slave is raw (no echo, no line editing) and closed again, so that the host's
    /// open and close of the slave path are what the board sees as connect and disconnect.
    pub(crate) fn open() -> io::Result<Self> {
        let (master, slave) = TTYPort::pair().map_err(io::Error::from)?;
        let slave_path = slave
            .name()
            .ok_or_else(|| io::Error::new(io::ErrorKind::NotFound, "the new pty has no slave path"))?;
        drop(slave);
        // Non-blocking writes: a host that stops reading must not stall the control loop; what does not fit is
        // dropped, like a USB CDC endpoint nobody polls.
        let fd = master.as_raw_fd();
        // SAFETY: fcntl on a descriptor this struct owns, with integer arguments only.
        let flags = unsafe { libc::fcntl(fd, libc::F_GETFL) };
        if flags < 0 || unsafe { libc::fcntl(fd, libc::F_SETFL, flags | libc::O_NONBLOCK) } < 0 {
            return Err(io::Error::last_os_error());
        }
        Ok(Self { master, slave_path })
    }

    pub(crate) fn slave_path(&self) -> &str {
        &self.slave_path
    }

    pub(crate) fn read(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<MasterRead> {
        let mut poll = libc::pollfd {
            fd: self.master.as_raw_fd(),
            events: libc::POLLIN,
            revents: 0,
        };
        let timeout_ms = timeout.as_micros().div_ceil(1000).min(i32::MAX as u128) as i32;
        // SAFETY: one valid pollfd for the duration of the call.
        let ready = unsafe { libc::poll(&mut poll, 1, timeout_ms) };
        if ready < 0 {
            let error = io::Error::last_os_error();
            return if error.kind() == io::ErrorKind::Interrupted {
                Ok(MasterRead::Nothing)
            } else {
                Err(error)
            };
        }
        if ready == 0 {
            return Ok(MasterRead::Nothing);
        }
        if poll.revents & libc::POLLIN != 0 {
            // SAFETY: buf is valid for buf.len() bytes.
            let n = unsafe { libc::read(poll.fd, buf.as_mut_ptr().cast(), buf.len()) };
            if n > 0 {
                return Ok(MasterRead::Data(n as usize));
            }
            let error = io::Error::last_os_error();
            return match error.raw_os_error() {
                Some(libc::EAGAIN) | Some(libc::EINTR) => Ok(MasterRead::Nothing),
                // Linux reports a pty whose slave is closed with EIO.
                Some(libc::EIO) => Ok(MasterRead::HostAbsent),
                _ if n == 0 => Ok(MasterRead::HostAbsent),
                _ => Err(error),
            };
        }
        if poll.revents & (libc::POLLHUP | libc::POLLERR) != 0 {
            return Ok(MasterRead::HostAbsent);
        }
        Ok(MasterRead::Nothing)
    }

    /// Writes what fits into the pty now; returns how many bytes were taken (the rest is the caller's to drop).
    pub(crate) fn write(&mut self, bytes: &[u8]) -> io::Result<usize> {
        // SAFETY: bytes is valid for bytes.len() bytes.
        let n = unsafe { libc::write(self.master.as_raw_fd(), bytes.as_ptr().cast(), bytes.len()) };
        if n >= 0 {
            return Ok(n as usize);
        }
        let error = io::Error::last_os_error();
        match error.raw_os_error() {
            Some(libc::EAGAIN) | Some(libc::EINTR) | Some(libc::EIO) => Ok(0),
            _ => Err(error),
        }
    }
}
