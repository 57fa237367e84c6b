//! Byte transports a [`BoardLink`](super::BoardLink) can speak over: a serial port (USB CDC-ACM, a UART, the
//! pty of QEMU or of the virtual board) or an in-memory pipe for tests and for the in-process virtual board.
//!
//! A transport only moves bytes; framing, sequence numbers and retries live in the link.

use std::collections::VecDeque;
use std::io::{self, Read, Write};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

/// A bidirectional byte stream with timed reads.
pub trait Transport: Send {
    /// Waits up to `timeout` for bytes and copies what is available into `buf`.
    /// `Ok(0)` means nothing arrived in time; an error means the peer is gone.
    fn read_timeout(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize>;
    /// Writes all of `bytes` or fails.
    fn write_all_bytes(&mut self, bytes: &[u8]) -> io::Result<()>;
    /// Drops whatever was received but not read yet (replies to a previous session, old telemetry).
    fn discard_input(&mut self) -> io::Result<()>;
    /// Where the bytes go, for messages.
    fn describe(&self) -> String;
}

/// A serial device opened in raw mode: USB CDC-ACM, a UART, or a pseudo-terminal.
pub struct SerialTransport {
    port: serialport::TTYPort,
    path: String,
}

impl SerialTransport {
    /// Opens `path` raw (no echo, no line editing, 8N1, no flow control), exclusive to this process.
    pub fn open(path: &str, baud: u32) -> Result<Self, serialport::Error> {
        // serialport puts the tty in raw mode (cfmakeraw) and takes TIOCEXCL + flock, which it releases on drop,
        // so a pty can be closed and opened again by the next session.
        let port = serialport::new(path, baud)
            .data_bits(serialport::DataBits::Eight)
            .parity(serialport::Parity::None)
            .stop_bits(serialport::StopBits::One)
            .flow_control(serialport::FlowControl::None)
            // USB CDC-ACM firmware takes DTR as "a host has the port open"; ptys ignore it.
            .dtr_on_open(true)
            .timeout(Duration::from_millis(10))
            .open_native()?;
        Ok(Self {
            port,
            path: path.to_owned(),
        })
    }
}

fn is_timeout(error: &io::Error) -> bool {
    matches!(
        error.kind(),
        io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
    )
}

impl Transport for SerialTransport {
    fn read_timeout(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize> {
        use serialport::SerialPort;
        self.port.set_timeout(timeout).map_err(io::Error::from)?;
        match self.port.read(buf) {
            // poll() said readable and read() found nothing: the other end hung up.
            Ok(0) if !buf.is_empty() => Err(io::Error::new(io::ErrorKind::UnexpectedEof, "serial device hung up")),
            Ok(n) => Ok(n),
            Err(error) if is_timeout(&error) => Ok(0),
            Err(error) => Err(error),
        }
    }

    fn write_all_bytes(&mut self, bytes: &[u8]) -> io::Result<()> {
        use serialport::SerialPort;
        // A whole frame must go out even if the device is slow; one second is far beyond any healthy link.
        self.port.set_timeout(Duration::from_secs(1)).map_err(io::Error::from)?;
        self.port.write_all(bytes)
    }

    fn discard_input(&mut self) -> io::Result<()> {
        use serialport::SerialPort;
        self.port.clear(serialport::ClearBuffer::Input).map_err(io::Error::from)
    }

    fn describe(&self) -> String {
        self.path.clone()
    }
}

/// One direction of an in-memory pipe.
#[derive(Default)]
struct Channel {
    state: Mutex<ChannelState>,
    readable: Condvar,
}

#[derive(Default)]
struct ChannelState {
    bytes: VecDeque<u8>,
    writer_closed: bool,
    reader_closed: bool,
}

impl Channel {
    fn lock(&self) -> MutexGuard<'_, ChannelState> {
        // A panic in another thread while holding the lock leaves plain bytes behind: still usable.
        self.state.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

/// One end of an in-memory, full-duplex byte pipe (see [`memory_pipe`]). Dropping an end is an unplug:
/// the other end reads what is left and then gets `BrokenPipe`.
pub struct PipeEnd {
    incoming: Arc<Channel>,
    outgoing: Arc<Channel>,
    name: String,
}

/// Two connected in-memory transport ends: what one writes, the other reads.
pub fn memory_pipe(name: &str) -> (PipeEnd, PipeEnd) {
    let a_to_b = Arc::new(Channel::default());
    let b_to_a = Arc::new(Channel::default());
    let a = PipeEnd {
        incoming: b_to_a.clone(),
        outgoing: a_to_b.clone(),
        name: format!("{name} (host end)"),
    };
    let b = PipeEnd {
        incoming: a_to_b,
        outgoing: b_to_a,
        name: format!("{name} (board end)"),
    };
    (a, b)
}

fn broken_pipe() -> io::Error {
    io::Error::new(io::ErrorKind::BrokenPipe, "the other end of the pipe was closed")
}

impl Transport for PipeEnd {
    fn read_timeout(&mut self, buf: &mut [u8], timeout: Duration) -> io::Result<usize> {
        let deadline = Instant::now() + timeout;
        let mut state = self.incoming.lock();
        loop {
            if !state.bytes.is_empty() {
                let n = buf.len().min(state.bytes.len());
                for (slot, byte) in buf.iter_mut().zip(state.bytes.drain(..n)) {
                    *slot = byte;
                }
                return Ok(n);
            }
            if state.writer_closed {
                return Err(broken_pipe());
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(0);
            }
            state = self
                .incoming
                .readable
                .wait_timeout(state, deadline - now)
                .unwrap_or_else(|poisoned| poisoned.into_inner())
                .0;
        }
    }

    fn write_all_bytes(&mut self, bytes: &[u8]) -> io::Result<()> {
        let mut state = self.outgoing.lock();
        if state.reader_closed {
            return Err(broken_pipe());
        }
        state.bytes.extend(bytes);
        self.outgoing.readable.notify_all();
        Ok(())
    }

    fn discard_input(&mut self) -> io::Result<()> {
        self.incoming.lock().bytes.clear();
        Ok(())
    }

    fn describe(&self) -> String {
        self.name.clone()
    }
}

impl Drop for PipeEnd {
    fn drop(&mut self) {
        self.outgoing.lock().writer_closed = true;
        self.outgoing.readable.notify_all();
        self.incoming.lock().reader_closed = true;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pipe_carries_bytes_both_ways_and_times_out_when_empty() {
        let (mut host, mut board) = memory_pipe("test");
        host.write_all_bytes(b"ping").unwrap();
        let mut buf = [0u8; 16];
        assert_eq!(board.read_timeout(&mut buf, Duration::from_millis(10)).unwrap(), 4);
        assert_eq!(&buf[..4], b"ping");
        assert_eq!(board.read_timeout(&mut buf, Duration::from_millis(5)).unwrap(), 0);
        board.write_all_bytes(b"pong").unwrap();
        assert_eq!(host.read_timeout(&mut buf, Duration::from_millis(10)).unwrap(), 4);
    }

    #[test]
    fn dropping_one_end_is_seen_as_a_broken_pipe_after_the_remaining_bytes() {
        let (mut host, mut board) = memory_pipe("test");
        board.write_all_bytes(b"last").unwrap();
        drop(board);
        let mut buf = [0u8; 16];
        assert_eq!(host.read_timeout(&mut buf, Duration::from_millis(10)).unwrap(), 4);
        let error = host.read_timeout(&mut buf, Duration::from_millis(10)).unwrap_err();
        assert_eq!(error.kind(), io::ErrorKind::BrokenPipe);
        assert_eq!(
            host.write_all_bytes(b"x").unwrap_err().kind(),
            io::ErrorKind::BrokenPipe
        );
    }

    #[test]
    fn a_blocked_reader_wakes_up_when_bytes_arrive() {
        let (mut host, mut board) = memory_pipe("test");
        let writer = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(20));
            board.write_all_bytes(&[1, 2, 3]).unwrap();
            board
        });
        let mut buf = [0u8; 8];
        let started = Instant::now();
        let n = host.read_timeout(&mut buf, Duration::from_secs(5)).unwrap();
        assert_eq!(n, 3);
        assert!(started.elapsed() < Duration::from_secs(5));
        drop(writer.join().unwrap());
    }
}
