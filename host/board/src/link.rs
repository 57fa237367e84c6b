//! Request/response with a board over any [`Transport`]: handshake, sequence numbers, timeouts, retries, and a
//! queue for the telemetry that arrives between replies.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use nusense_firmware_core::link::HOST_KEEPALIVE_MS;
use nusense_protocol::framing::{self, FrameDecoder, MAX_FRAME_LEN};
use nusense_protocol::{
    BoardMessage, Channel, DeviceError, DeviceInfo, LinkCounters, Reply, Request, RequestBody, Seq, Status, Telemetry,
    PROTOCOL_VERSION, SAVE_CONFIG_REPLY_WITHIN_MS, SCHEMA_FINGERPRINT,
};

use super::error::LinkError;
use super::transport::{SerialTransport, Transport};

/// How patient the link is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LinkOptions {
    /// How long to wait for each attempt's reply.
    pub timeout: Duration,
    /// Further attempts after the first one times out.
    pub retries: u32,
    /// Line speed for real UARTs; USB CDC-ACM and ptys ignore it.
    pub baud: u32,
}

impl Default for LinkOptions {
    fn default() -> Self {
        Self {
            timeout: Duration::from_millis(250),
            retries: 2,
            baud: 115_200,
        }
    }
}

/// Everything that went wrong on the host's side of the link, by kind, and what arrived.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct LinkStats {
    /// Frames the host's decoder dropped, by reason (bad COBS, bad CRC, oversize, undecodable), and frames it
    /// accepted.
    pub wire: LinkCounters,
    /// Replies whose sequence number matched no outstanding request (late answers to a retried request).
    pub stale_replies: u64,
    /// Replies to the right request but of the wrong kind (a `Pong` to `GetStatus`, a `Pong` with another nonce).
    pub unexpected_replies: u64,
    /// Attempts that got no reply in time.
    pub timeouts: u64,
    /// Requests sent again after a timeout.
    pub retries: u64,
    /// Telemetry frames received.
    pub telemetry_received: u64,
    /// Telemetry frames thrown away because nobody read the queue.
    pub telemetry_dropped: u64,
}

/// Telemetry kept while the caller waits for replies; at the fastest stream (1 ms) this is a second's worth.
const TELEMETRY_QUEUE_LEN: usize = 1024;
/// How long a `SaveConfig` attempt waits: the board's promise plus the same margin an ordinary request gets.
/// Retries carry the same request id, so a slow save that did complete is not written again.
fn save_timeout(options: &LinkOptions) -> Duration {
    Duration::from_millis(u64::from(SAVE_CONFIG_REPLY_WITHIN_MS)) + options.timeout
}

/// A handshaken connection to one board. Blocking; one caller at a time (the daemon wraps it in a thread,
/// see [`super::SupervisedLink`]).
pub struct BoardLink {
    transport: Box<dyn Transport>,
    options: LinkOptions,
    decoder: FrameDecoder<MAX_FRAME_LEN>,
    inbox: VecDeque<BoardMessage>,
    telemetry: VecDeque<Telemetry>,
    next_seq: Seq,
    stats: LinkStats,
    device_protocol_version: u16,
    /// When the host last wrote anything (for the keepalive).
    last_sent: Instant,
}

impl BoardLink {
    /// Opens a serial device (USB CDC-ACM, or a pty from QEMU / the virtual board) and does the Hello handshake.
    pub fn open(path: &str, options: LinkOptions) -> Result<Self, LinkError> {
        let transport = SerialTransport::open(path, options.baud).map_err(|cause| LinkError::Open {
            path: path.to_owned(),
            cause,
        })?;
        Self::over(Box::new(transport), options)
    }

    /// Does the handshake over an already open transport (an in-memory pipe, or a port opened elsewhere).
    pub fn over(mut transport: Box<dyn Transport>, options: LinkOptions) -> Result<Self, LinkError> {
        // Whatever is waiting is left over from a previous session: telemetry, replies to old sequence numbers.
        transport
            .discard_input()
            .map_err(|error| disconnected(&*transport, &error))?;
        let mut link = BoardLink {
            transport,
            options,
            decoder: FrameDecoder::new(),
            inbox: VecDeque::new(),
            telemetry: VecDeque::new(),
            // Start where a previous session is unlikely to have left off, so its late replies look stale.
            next_seq: start_seq(),
            stats: LinkStats::default(),
            device_protocol_version: 0,
            last_sent: Instant::now(),
        };
        link.handshake()?;
        Ok(link)
    }

    fn handshake(&mut self) -> Result<(), LinkError> {
        let hello = RequestBody::Hello {
            protocol_version: PROTOCOL_VERSION,
        };
        match self.request(hello) {
            Ok(Reply::Hello {
                protocol_version,
                schema,
            }) if protocol_version == PROTOCOL_VERSION => {
                if schema != SCHEMA_FINGERPRINT {
                    return Err(LinkError::SchemaMismatch {
                        version: protocol_version,
                        device: schema,
                        host: SCHEMA_FINGERPRINT,
                    });
                }
                self.device_protocol_version = protocol_version;
                Ok(())
            }
            Ok(Reply::Hello { protocol_version, .. }) => Err(LinkError::VersionMismatch {
                device: protocol_version,
                host: PROTOCOL_VERSION,
            }),
            Ok(other) => Err(self.unexpected("Hello", &other)),
            Err(LinkError::Device(DeviceError::VersionMismatch { device, host })) => {
                Err(LinkError::VersionMismatch { device, host })
            }
            Err(LinkError::Timeout) => Err(LinkError::NoHandshake {
                path: self.transport.describe(),
            }),
            Err(other) => Err(other),
        }
    }

    /// The board's protocol version (equal to the host's once open succeeded).
    pub fn device_protocol_version(&self) -> u16 {
        self.device_protocol_version
    }

    /// Where this link goes (device path or pipe name).
    pub fn describe(&self) -> String {
        self.transport.describe()
    }

    pub fn options(&self) -> LinkOptions {
        self.options
    }

    pub fn info(&mut self) -> Result<DeviceInfo, LinkError> {
        match self.request(RequestBody::GetInfo)? {
            Reply::Info(info) => Ok(info),
            other => Err(self.unexpected("GetInfo", &other)),
        }
    }

    pub fn status(&mut self) -> Result<Status, LinkError> {
        match self.request(RequestBody::GetStatus)? {
            Reply::Status(status) => Ok(status),
            other => Err(self.unexpected("GetStatus", &other)),
        }
    }

    /// Sets a channel's (or every channel's) current; the board clamps it to its hard limit.
    pub fn set_led(&mut self, channel: Channel, current_ma: u16, enabled: bool) -> Result<(), LinkError> {
        self.expect_ack(
            "SetLed",
            RequestBody::SetLed {
                channel,
                current_ma,
                enabled,
            },
        )
    }

    /// Soft-start time from 0 to the setpoint.
    pub fn set_ramp(&mut self, ms: u16) -> Result<(), LinkError> {
        self.expect_ack("SetRamp", RequestBody::SetRamp { ms })
    }

    /// Asks for telemetry every `period_ms` (0 stops it); read it with [`Self::next_telemetry`].
    pub fn stream_telemetry(&mut self, period_ms: u16) -> Result<(), LinkError> {
        self.expect_ack("StreamTelemetry", RequestBody::StreamTelemetry { period_ms })
    }

    pub fn clear_faults(&mut self) -> Result<(), LinkError> {
        self.expect_ack("ClearFaults", RequestBody::ClearFaults)
    }

    /// Stores the board's live configuration in its flash. Each attempt waits as long as the board may take
    /// (a sector erase); a retry repeats the same request id, which the board answers without writing twice.
    pub fn save_config(&mut self) -> Result<(), LinkError> {
        let body = RequestBody::SaveConfig {
            request_id: new_request_id(),
        };
        let timeout = save_timeout(&self.options);
        match self.request_waiting(body, timeout)? {
            Reply::Ack => Ok(()),
            other => Err(self.unexpected("SaveConfig", &other)),
        }
    }

    /// Caps the sum of the string currents (the board clamps it to its USB budget).
    pub fn set_current_budget(&mut self, total_ma: u16) -> Result<(), LinkError> {
        self.expect_ack("SetCurrentBudget", RequestBody::SetCurrentBudget { total_ma })
    }

    /// Restarts the board; the link is gone afterwards (USB re-enumerates) and must be reopened.
    pub fn reset(&mut self) -> Result<(), LinkError> {
        self.expect_ack("Reset", RequestBody::Reset)
    }

    /// Round trip of a Ping, measured from just before sending to the matching Pong.
    pub fn ping(&mut self, nonce: u32) -> Result<Duration, LinkError> {
        let started = Instant::now();
        match self.request(RequestBody::Ping { nonce })? {
            Reply::Pong { nonce: echoed } if echoed == nonce => Ok(started.elapsed()),
            other => Err(self.unexpected("Ping", &other)),
        }
    }

    /// The oldest queued telemetry, or the next one to arrive within `timeout`; `None` if none came.
    pub fn next_telemetry(&mut self, timeout: Duration) -> Result<Option<Telemetry>, LinkError> {
        self.keep_alive()?;
        if let Some(telemetry) = self.telemetry.pop_front() {
            return Ok(Some(telemetry));
        }
        let deadline = Instant::now() + timeout;
        while let Some(message) = self.receive(deadline)? {
            match message {
                BoardMessage::Telemetry(telemetry) => {
                    self.stats.telemetry_received += 1;
                    return Ok(Some(telemetry));
                }
                // Nothing is outstanding: any reply here answers a request that already timed out.
                BoardMessage::Response(_) => self.stats.stale_replies += 1,
            }
        }
        Ok(None)
    }

    /// Telemetry received so far and not yet taken, oldest first.
    pub fn drain_telemetry(&mut self) -> impl Iterator<Item = Telemetry> + '_ {
        self.telemetry.drain(..)
    }

    /// The host decoder's framing counters (bad COBS, bad CRC, oversize, undecodable, good frames).
    pub fn counters(&self) -> LinkCounters {
        self.decoder.counters()
    }

    /// Framing counters plus stale replies, timeouts, retries and telemetry bookkeeping.
    pub fn stats(&self) -> LinkStats {
        LinkStats {
            wire: self.decoder.counters(),
            ..self.stats
        }
    }

    fn expect_ack(&mut self, name: &'static str, body: RequestBody) -> Result<(), LinkError> {
        match self.request(body)? {
            Reply::Ack => Ok(()),
            other => Err(self.unexpected(name, &other)),
        }
    }

    /// Sends `body` with a fresh sequence number and waits for its reply, retrying on timeout. Each attempt gets
    /// its own number, so a late reply to an earlier attempt is recognised as stale and dropped.
    pub fn request(&mut self, body: RequestBody) -> Result<Reply, LinkError> {
        self.request_waiting(body, self.options.timeout)
    }

    /// Tells a board on a link without DTR (a plain UART: the QEMU image) that the host is still there, when
    /// nothing else was sent for a while: a lone 0x00, an empty frame the board's decoder skips. Harmless on USB.
    fn keep_alive(&mut self) -> Result<(), LinkError> {
        if self.last_sent.elapsed() >= Duration::from_millis(HOST_KEEPALIVE_MS) {
            self.write(&[framing::DELIMITER])?;
        }
        Ok(())
    }

    fn request_waiting(&mut self, body: RequestBody, timeout: Duration) -> Result<Reply, LinkError> {
        for attempt in 0..=self.options.retries {
            if attempt > 0 {
                self.stats.retries += 1;
            }
            let seq = self.allocate_seq();
            self.send(&Request {
                seq,
                body: body.clone(),
            })?;
            let deadline = Instant::now() + timeout;
            while let Some(message) = self.receive(deadline)? {
                match message {
                    BoardMessage::Response(response) if response.seq == seq => {
                        return response.result.map_err(LinkError::Device);
                    }
                    BoardMessage::Response(_) => self.stats.stale_replies += 1,
                    BoardMessage::Telemetry(telemetry) => self.queue_telemetry(telemetry),
                }
            }
            self.stats.timeouts += 1;
            tracing::debug!(target: "nusense_board", link = %self.transport.describe(), seq, attempt, "no reply in time");
        }
        Err(LinkError::Timeout)
    }

    fn allocate_seq(&mut self) -> Seq {
        let seq = self.next_seq;
        self.next_seq = self.next_seq.wrapping_add(1);
        seq
    }

    fn send(&mut self, request: &Request) -> Result<(), LinkError> {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let frame = framing::encode(request, &mut buf).map_err(LinkError::Encode)?;
        self.write(frame)
    }

    fn write(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        self.last_sent = Instant::now();
        self.transport
            .write_all_bytes(bytes)
            .map_err(|error| disconnected(&*self.transport, &error))
    }

    fn unexpected(&mut self, request: &'static str, reply: &Reply) -> LinkError {
        self.stats.unexpected_replies += 1;
        LinkError::UnexpectedReply {
            request,
            reply: format!("{reply:?}"),
        }
    }

    fn queue_telemetry(&mut self, telemetry: Telemetry) {
        self.stats.telemetry_received += 1;
        if self.telemetry.len() == TELEMETRY_QUEUE_LEN {
            self.telemetry.pop_front();
            self.stats.telemetry_dropped += 1;
        }
        self.telemetry.push_back(telemetry);
    }

    /// The next decoded message, reading the transport until `deadline`; `None` when the deadline passed.
    /// Frames that fail to decode are counted by the decoder and skipped.
    fn receive(&mut self, deadline: Instant) -> Result<Option<BoardMessage>, LinkError> {
        let mut buf = [0u8; 512];
        loop {
            if let Some(message) = self.inbox.pop_front() {
                return Ok(Some(message));
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(None);
            }
            let n = self
                .transport
                .read_timeout(&mut buf, deadline - now)
                .map_err(|error| disconnected(&*self.transport, &error))?;
            let inbox = &mut self.inbox;
            let link = &self.transport;
            self.decoder.feed::<BoardMessage>(&buf[..n], |decoded| match decoded {
                Ok(message) => inbox.push_back(message),
                Err(error) => {
                    tracing::debug!(target: "nusense_board", link = %link.describe(), ?error, "dropped a bad frame")
                }
            });
        }
    }
}

fn disconnected(transport: &dyn Transport, error: &std::io::Error) -> LinkError {
    tracing::info!(target: "nusense_board", link = %transport.describe(), %error, "board link lost");
    LinkError::Disconnected
}

/// A save's request id: new for every save of every session (clock and a counter), repeated by its retries.
fn new_request_id() -> u32 {
    static COUNTER: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|elapsed| elapsed.as_nanos() as u32)
        .unwrap_or(0);
    nanos
        ^ COUNTER
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed)
            .rotate_left(16)
}

/// A sequence number that differs between sessions (low bits of the clock), so a reply meant for a previous
/// process on the same port is not mistaken for ours.
fn start_seq() -> Seq {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|elapsed| elapsed.subsec_nanos())
        .unwrap_or(0);
    (nanos >> 10) as Seq
}
