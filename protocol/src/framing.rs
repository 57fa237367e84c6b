//! How messages travel on a byte stream (USB CDC-ACM, a UART, a pty).
//!
//! A frame is `COBS(postcard(message) ++ crc32(postcard(message)).to_le_bytes()) ++ [0x00]`:
//! - postcard gives a compact, schema-less payload (the schema is [`crate::message`] and its version);
//! - CRC-32 (ISO-HDLC, the zlib/Ethernet one) catches bytes damaged on the way;
//! - COBS removes every 0x00 from the frame body, so 0x00 only ever marks a frame's end and a receiver that
//!   starts mid-stream, or loses bytes, is back in step at the next 0x00.
//!
//! [`FrameDecoder`] never fails: a bad frame is dropped, reported to the caller and counted in
//! [`LinkCounters`], and decoding carries on with the next frame.

use core::fmt;

use postcard::experimental::max_size::MaxSize;
use serde::{de::DeserializeOwned, Serialize};

use crate::message::{BoardMessage, LinkCounters, Request};

/// Bytes of the CRC-32 that follows the payload.
pub const CRC_LEN: usize = 4;

/// The frame delimiter; COBS guarantees it appears nowhere else.
pub const DELIMITER: u8 = 0x00;

// Same CRC either way; only the lookup table differs. Slice-by-16 (16 KiB) makes the host's decoder several
// times faster; the MCU keeps the byte-wise 1 KiB table to save flash and RAM.
#[cfg(target_os = "none")]
type CrcTable = crc::Table<1>;
#[cfg(not(target_os = "none"))]
type CrcTable = crc::Table<16>;
const CRC: crc::Crc<u32, CrcTable> = crc::Crc::<u32, CrcTable>::new(&crc::CRC_32_ISO_HDLC);

const fn max(a: usize, b: usize) -> usize {
    if a > b {
        a
    } else {
        b
    }
}

/// Largest postcard payload of any message in either direction, from the types themselves (postcard's `MaxSize`).
pub const MAX_PAYLOAD_LEN: usize = max(Request::POSTCARD_MAX_SIZE, BoardMessage::POSTCARD_MAX_SIZE);

/// Largest encoded frame for a payload of `payload_len` bytes, including CRC, COBS overhead and the delimiter.
///
/// COBS adds one code byte per started run of 254 bytes (`n / 254 + 1` is an upper bound for every `n`).
pub const fn max_frame_len(payload_len: usize) -> usize {
    let body = payload_len + CRC_LEN;
    body + body / 254 + 1 + 1
}

/// Largest encoded frame on the wire, including CRC, COBS overhead and the 0x00 delimiter.
pub const MAX_FRAME_LEN: usize = max_frame_len(MAX_PAYLOAD_LEN);

// An explicit budget: the decoder buffer lives in MCU RAM and encode() keeps the payload on the stack, so a
// message growing past this is a decision to take consciously (and a protocol version bump anyway).
const _: () = assert!(MAX_FRAME_LEN <= 256);

/// Why a received frame was dropped. Each kind has its own counter in [`LinkCounters`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum WireError {
    /// The bytes between two delimiters are not valid COBS.
    BadCobs,
    /// The CRC does not match, or the frame is too short to hold one.
    BadCrc,
    /// More bytes than the decoder's buffer before a delimiter; discarded up to the next 0x00.
    Oversize,
    /// The CRC is right but postcard could not decode the payload as the expected message
    /// (unknown enum tag, value out of range, too few bytes, or bytes left over).
    UnknownTag,
}

impl fmt::Display for WireError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            WireError::BadCobs => "frame dropped: not valid COBS",
            WireError::BadCrc => "frame dropped: CRC mismatch",
            WireError::Oversize => "frame dropped: longer than the receive buffer",
            WireError::UnknownTag => "frame dropped: not a message of this protocol version",
        })
    }
}

impl core::error::Error for WireError {}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum EncodeError {
    /// `buf` cannot hold the encoded frame; [`MAX_FRAME_LEN`] bytes always suffice for this crate's messages.
    BufferTooSmall,
    /// postcard refused the value (only possible for types outside this crate's message set).
    Serialize,
    /// The payload is longer than [`MAX_PAYLOAD_LEN`]: no peer's decoder would accept the frame.
    PayloadTooLarge,
}

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            EncodeError::BufferTooSmall => "output buffer too small for the frame",
            EncodeError::Serialize => "message could not be serialised",
            EncodeError::PayloadTooLarge => "message larger than the protocol's maximum payload",
        })
    }
}

impl core::error::Error for EncodeError {}

/// postcard payload + CRC (little-endian) -> COBS -> trailing 0x00; returns the written slice of `buf`.
///
/// `buf` of [`MAX_FRAME_LEN`] bytes fits any message of this crate.
pub fn encode<'b, T: Serialize>(msg: &T, buf: &'b mut [u8]) -> Result<&'b [u8], EncodeError> {
    // COBS needs distinct source and destination; the raw payload is small enough for the stack (also on the MCU).
    let mut raw = [0u8; MAX_PAYLOAD_LEN + CRC_LEN];
    let payload_len = match postcard::to_slice(msg, &mut raw[..MAX_PAYLOAD_LEN]) {
        Ok(payload) => payload.len(),
        Err(postcard::Error::SerializeBufferFull) => return Err(EncodeError::PayloadTooLarge),
        Err(_) => return Err(EncodeError::Serialize),
    };
    let crc = CRC.checksum(&raw[..payload_len]).to_le_bytes();
    raw[payload_len..payload_len + CRC_LEN].copy_from_slice(&crc);
    let body = &raw[..payload_len + CRC_LEN];

    let encoded_len = cobs::try_encode(body, buf).map_err(|_| EncodeError::BufferTooSmall)?;
    let frame_len = encoded_len + 1;
    let delimiter = buf.get_mut(encoded_len).ok_or(EncodeError::BufferTooSmall)?;
    *delimiter = DELIMITER;
    Ok(&buf[..frame_len])
}

/// Decodes one frame body: the COBS bytes between two delimiters (without the 0x00). Decodes in place, so
/// `encoded` is overwritten.
pub fn decode_frame<T: DeserializeOwned>(encoded: &mut [u8]) -> Result<T, WireError> {
    // The COBS decoder would silently stop at a 0x00 and ignore the rest; a body never contains one.
    if encoded.contains(&DELIMITER) {
        return Err(WireError::BadCobs);
    }
    let decoded_len = cobs::decode_in_place(encoded).map_err(|_| WireError::BadCobs)?;
    let decoded = encoded.get(..decoded_len).ok_or(WireError::BadCobs)?;
    if decoded.len() < CRC_LEN {
        return Err(WireError::BadCrc);
    }
    let (payload, crc) = decoded.split_at(decoded.len() - CRC_LEN);
    let expected = CRC.checksum(payload).to_le_bytes();
    if crc != expected {
        return Err(WireError::BadCrc);
    }
    match postcard::take_from_bytes::<T>(payload) {
        Ok((message, [])) => Ok(message),
        // Leftover bytes mean sender and receiver disagree about the message; never guess.
        Ok(_) | Err(_) => Err(WireError::UnknownTag),
    }
}

/// Byte-stream decoder: accepts arbitrary chunks, yields whole messages, resyncs at the next 0x00, counts errors.
///
/// `N` is the receive buffer: the longest frame (without its delimiter) that is decoded; longer ones are
/// dropped as [`WireError::Oversize`]. The default fits every message of this crate. In an expression, name the
/// type so the default applies: `let mut decoder: FrameDecoder = FrameDecoder::new();`.
///
/// Empty frames (0x00 right after 0x00) are skipped silently: a sender may send a lone 0x00 to flush a
/// half-received frame at the peer, e.g. after opening the port.
#[derive(Clone, Debug)]
pub struct FrameDecoder<const N: usize = MAX_FRAME_LEN> {
    buf: [u8; N],
    len: usize,
    /// The current frame outgrew `buf`: drop everything up to the next delimiter.
    overflowed: bool,
    counters: LinkCounters,
}

impl<const N: usize> Default for FrameDecoder<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> FrameDecoder<N> {
    pub const fn new() -> Self {
        Self {
            buf: [0; N],
            len: 0,
            overflowed: false,
            counters: LinkCounters {
                bad_cobs: 0,
                bad_crc: 0,
                oversize: 0,
                unknown_tag: 0,
                frames_ok: 0,
            },
        }
    }

    /// Feed bytes; calls `on_message` for each complete frame: Ok(T) or the WireError it was dropped for.
    pub fn feed<T: DeserializeOwned>(&mut self, bytes: &[u8], mut on_message: impl FnMut(Result<T, WireError>)) {
        let mut rest = bytes;
        while !rest.is_empty() {
            match rest.iter().position(|&b| b == DELIMITER) {
                Some(end) => {
                    self.push(&rest[..end]);
                    if let Some(result) = self.finish_frame() {
                        on_message(result);
                    }
                    rest = &rest[end + 1..];
                }
                None => {
                    self.push(rest);
                    rest = &[];
                }
            }
        }
    }

    /// What has been decoded and dropped so far, by kind.
    pub fn counters(&self) -> LinkCounters {
        self.counters
    }

    /// Drops a half-received frame (e.g. after the port was reopened); the counters stay.
    pub fn clear(&mut self) {
        self.len = 0;
        self.overflowed = false;
    }

    fn push(&mut self, body: &[u8]) {
        if self.overflowed {
            return;
        }
        match self.buf.get_mut(self.len..self.len + body.len()) {
            Some(room) => {
                room.copy_from_slice(body);
                self.len += body.len();
            }
            None => {
                self.overflowed = true;
                self.len = 0;
            }
        }
    }

    fn finish_frame<T: DeserializeOwned>(&mut self) -> Option<Result<T, WireError>> {
        let overflowed = core::mem::replace(&mut self.overflowed, false);
        let len = core::mem::replace(&mut self.len, 0);
        let result = if overflowed {
            Err(WireError::Oversize)
        } else if len == 0 {
            return None;
        } else {
            decode_frame(&mut self.buf[..len])
        };
        let counter = match result {
            Ok(_) => &mut self.counters.frames_ok,
            Err(WireError::BadCobs) => &mut self.counters.bad_cobs,
            Err(WireError::BadCrc) => &mut self.counters.bad_crc,
            Err(WireError::Oversize) => &mut self.counters.oversize,
            Err(WireError::UnknownTag) => &mut self.counters.unknown_tag,
        };
        // Wrapping, not saturating: a peer that polls the counters takes differences.
        *counter = counter.wrapping_add(1);
        Some(result)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::message::*;

    /// The hand-written `MaxSize` of `DeviceInfo` (and postcard's derive) must bound what postcard really writes.
    #[test]
    fn largest_possible_messages_fit_the_bound() {
        let text = |n: usize| {
            let mut s = heapless::String::<32>::new();
            for _ in 0..n {
                s.push('~').unwrap();
            }
            s
        };
        let info = DeviceInfo {
            protocol_version: u16::MAX,
            firmware_version: text(VERSION_TEXT_LEN).as_str().try_into().unwrap(),
            git_hash: text(GIT_HASH_LEN).as_str().try_into().unwrap(),
            board_id: text(BOARD_ID_LEN).as_str().try_into().unwrap(),
            mcu_uid: [0xFF; 12],
            channel_count: u8::MAX,
            max_current_ma: u16::MAX,
            max_total_current_ma: u16::MAX,
        };
        let counters = LinkCounters {
            bad_cobs: u32::MAX,
            bad_crc: u32::MAX,
            oversize: u32::MAX,
            unknown_tag: u32::MAX,
            frames_ok: u32::MAX,
        };
        let loop_timing = LoopTiming {
            steps: u32::MAX,
            period_mean_us: f32::MAX,
            period_min_us: u32::MAX,
            period_max_us: u32::MAX,
        };
        let flags = FaultFlags {
            open_string: true,
            over_current: true,
            over_temperature: true,
            under_voltage: true,
        };
        let channel = ChannelState {
            setpoint_ma: u16::MAX,
            measured_ma: f32::MAX,
            duty: 1.0,
            enabled: true,
            faults: flags,
        };
        let status = Status {
            uptime_us: u64::MAX,
            channels: [channel; CHANNEL_COUNT],
            temperature_c: f32::MIN,
            supply_mv: u16::MAX,
            ramp_ms: u16::MAX,
            telemetry_period_ms: u16::MAX,
            counters,
            power: PowerState::Suspended,
            current_budget_ma: u16::MAX,
            loop_timing,
        };
        let telemetry = Telemetry {
            uptime_us: u64::MAX,
            channels: [channel; CHANNEL_COUNT],
            temperature_c: f32::MAX,
            supply_mv: u16::MAX,
            counters,
            loop_timing,
        };
        let mut payload = [0u8; 1024];
        let mut frame = [0u8; MAX_FRAME_LEN];
        let board_messages = [
            BoardMessage::Response(Response {
                seq: u16::MAX,
                result: Ok(Reply::Info(info.clone())),
            }),
            BoardMessage::Response(Response {
                seq: u16::MAX,
                result: Ok(Reply::Status(status)),
            }),
            BoardMessage::Telemetry(telemetry),
        ];
        let info_len = postcard::to_slice(&info, &mut payload).unwrap().len();
        assert!(
            info_len <= DeviceInfo::POSTCARD_MAX_SIZE,
            "{info_len} > {}",
            DeviceInfo::POSTCARD_MAX_SIZE
        );
        for message in &board_messages {
            let len = postcard::to_slice(message, &mut payload).unwrap().len();
            assert!(len <= MAX_PAYLOAD_LEN, "{message:?}: {len} > {MAX_PAYLOAD_LEN}");
            let framed = encode(message, &mut frame).unwrap().len();
            assert!(framed <= MAX_FRAME_LEN);
        }
        let request = Request {
            seq: u16::MAX,
            body: RequestBody::SetLed {
                channel: Channel::One(Side::Left),
                current_ma: u16::MAX,
                enabled: true,
            },
        };
        assert!(postcard::to_slice(&request, &mut payload).unwrap().len() <= MAX_PAYLOAD_LEN);
    }

    #[test]
    fn request_round_trips_through_a_frame() {
        let request = Request {
            seq: 7,
            body: RequestBody::Ping { nonce: 0xDEAD_BEEF },
        };
        let mut buf = [0u8; MAX_FRAME_LEN];
        let frame = encode(&request, &mut buf).unwrap();
        assert_eq!(frame.last(), Some(&0));
        assert!(!frame[..frame.len() - 1].contains(&0));
        let mut decoder: FrameDecoder = FrameDecoder::new();
        let mut got = None;
        decoder.feed::<Request>(frame, |m| got = Some(m));
        assert_eq!(got, Some(Ok(request)));
        assert_eq!(decoder.counters().frames_ok, 1);
    }

    #[test]
    fn a_body_with_a_delimiter_inside_is_bad_cobs() {
        let request = Request {
            seq: 3,
            body: RequestBody::Reset,
        };
        let mut buf = [0u8; MAX_FRAME_LEN];
        let frame = encode(&request, &mut buf).unwrap();
        let mut body = [0u8; MAX_FRAME_LEN + 2];
        let n = frame.len();
        body[..n].copy_from_slice(frame);
        body[n] = 0x42; // bytes after the delimiter must not be ignored
        let mut whole = body;
        assert_eq!(decode_frame::<Request>(&mut whole[..n + 1]), Err(WireError::BadCobs));
        assert_eq!(decode_frame::<Request>(&mut body[..n - 1]), Ok(request));
    }

    #[test]
    fn small_buffer_is_reported_not_panicked() {
        let request = Request {
            seq: 1,
            body: RequestBody::GetInfo,
        };
        let mut buf = [0u8; 4];
        assert_eq!(encode(&request, &mut buf), Err(EncodeError::BufferTooSmall));
    }

    #[test]
    fn oversize_frame_is_dropped_until_next_delimiter() {
        let mut decoder = FrameDecoder::<8>::new();
        let mut results = heapless::Vec::<Result<Request, WireError>, 4>::new();
        decoder.feed::<Request>(&[1; 20], |r| results.push(r).unwrap());
        decoder.feed::<Request>(&[1, 2, 0], |r| results.push(r).unwrap());
        let mut buf = [0u8; MAX_FRAME_LEN];
        let request = Request {
            seq: 2,
            body: RequestBody::GetStatus,
        };
        let frame = encode(&request, &mut buf).unwrap();
        decoder.feed::<Request>(frame, |r| results.push(r).unwrap());
        assert_eq!(results.as_slice(), &[Err(WireError::Oversize), Ok(request)]);
        assert_eq!(decoder.counters().oversize, 1);
    }
}
