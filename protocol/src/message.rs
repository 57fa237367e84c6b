//! Messages. The wire format is frozen by golden vectors in the tests: add variants only at the end of an enum,
//! and bump [`PROTOCOL_VERSION`] for any change a peer could notice. [`SCHEMA_FINGERPRINT`] is a hash of the
//! message types themselves, so two builds that say the same version but disagree about a type still find out.

use core::fmt;

use heapless::String;
use postcard::experimental::max_size::MaxSize;
use postcard_schema::Schema;
use serde::{Deserialize, Serialize};

/// Version of this message set. The host and the board refuse to talk across versions.
///
/// v2: schema fingerprint in the Hello reply, `SaveConfig` with a request id, LED power state, total current
/// budget and control-loop timing in `Status`/`Telemetry`, `SetCurrentBudget`.
pub const PROTOCOL_VERSION: u16 = 2;

/// FNV-1a 64 of the postcard schemas (type names, field names, layout) of both directions, computed at compile
/// time by postcard-schema. The board sends its own in `Reply::Hello`; the host refuses a board whose fingerprint
/// differs from its own even when the version numbers agree (someone changed a type without bumping the version).
pub const SCHEMA_FINGERPRINT: u64 = {
    let host_to_board = postcard_schema::key::hash::fnv1a64::hash_ty_path::<Request>("nusense/host-to-board");
    let board_to_host = postcard_schema::key::hash::fnv1a64::hash_ty_path::<BoardMessage>("nusense/board-to-host");
    u64::from_le_bytes(host_to_board) ^ u64::from_le_bytes(board_to_host).rotate_left(1)
};

/// Longest the board may take to answer `SaveConfig`: the contract between host and firmware. The F411 board's
/// worst case is one 16 KiB flash sector erase at x32 parallelism (500 ms max, STM32F411 datasheet) plus one
/// 32-byte record; the host waits this long for the reply before it retries (with the same request id, so a
/// retry never writes twice).
pub const SAVE_CONFIG_REPLY_WITHIN_MS: u32 = 2_000;

/// LED strings on the board: one per side of the light guide.
pub const CHANNEL_COUNT: usize = 4;

/// Length bound of the textual fields of [`DeviceInfo`].
pub const VERSION_TEXT_LEN: usize = 16;
pub const GIT_HASH_LEN: usize = 12;
pub const BOARD_ID_LEN: usize = 16;

/// Sequence number chosen by the host; the board echoes it in the matching [`Response`].
pub type Seq = u16;

/// A side of the light guide, as the camera sees the pad.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, MaxSize, Schema)]
pub enum Side {
    Top,
    Right,
    Bottom,
    Left,
}

impl Side {
    pub const ALL: [Side; CHANNEL_COUNT] = [Side::Top, Side::Right, Side::Bottom, Side::Left];

    /// Index of this side's channel in per-channel arrays.
    pub const fn index(self) -> usize {
        self as usize
    }
}

/// Which LED channels a command addresses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, MaxSize, Schema)]
pub enum Channel {
    One(Side),
    All,
}

/// Host -> board.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize, MaxSize, Schema)]
pub struct Request {
    pub seq: Seq,
    pub body: RequestBody,
}

#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize, MaxSize, Schema)]
pub enum RequestBody {
    Hello {
        protocol_version: u16,
    },
    GetInfo,
    GetStatus,
    SetLed {
        channel: Channel,
        current_ma: u16,
        enabled: bool,
    },
    /// Soft-start: time for a channel to ramp from 0 to its setpoint.
    SetRamp {
        ms: u16,
    },
    /// Period of unsolicited [`Telemetry`]; 0 stops the stream.
    StreamTelemetry {
        period_ms: u16,
    },
    ClearFaults,
    /// Stores the live configuration in flash. `request_id` makes it idempotent: a retry with the id of a save
    /// that already happened (or is under way) is answered without writing again. Pick a new id per save.
    SaveConfig {
        request_id: u32,
    },
    Reset,
    EnterBootloader,
    Ping {
        nonce: u32,
    },
    /// Cap on the sum of all LED string currents (the board's USB power budget); clamped to
    /// `DeviceInfo::max_total_current_ma`. Setpoints above their share are scaled down together.
    SetCurrentBudget {
        total_ma: u16,
    },
}

/// Board -> host.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, MaxSize, Schema)]
pub enum BoardMessage {
    Response(Response),
    Telemetry(Telemetry),
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, MaxSize, Schema)]
pub struct Response {
    /// The [`Request::seq`] this answers.
    pub seq: Seq,
    pub result: Result<Reply, DeviceError>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, MaxSize, Schema)]
pub enum Reply {
    /// The request was carried out and has nothing to report.
    Ack,
    Info(DeviceInfo),
    Status(Status),
    Pong {
        nonce: u32,
    },
    /// Answer to `Hello` (only sent when the versions are equal; otherwise the board answers
    /// `DeviceError::VersionMismatch`, whose bytes never move): the board's protocol version and
    /// [`SCHEMA_FINGERPRINT`].
    Hello {
        protocol_version: u16,
        schema: u64,
    },
}

#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize, Schema)]
pub struct DeviceInfo {
    pub protocol_version: u16,
    pub firmware_version: String<VERSION_TEXT_LEN>,
    pub git_hash: String<GIT_HASH_LEN>,
    pub board_id: String<BOARD_ID_LEN>,
    /// The MCU's 96-bit factory unique id.
    pub mcu_uid: [u8; 12],
    pub channel_count: u8,
    /// Hard limit per channel; setpoints above it are clamped.
    pub max_current_ma: u16,
    /// Largest total LED current the board allows (its USB power budget less its own draw).
    pub max_total_current_ma: u16,
}

/// Serialised size bound of a `heapless::String<N>` (a varint length, then the bytes). postcard's own `MaxSize`
/// covers only its heapless 0.7 types, so the impl for [`DeviceInfo`] is written by hand; the framing tests
/// serialise the longest possible `DeviceInfo` and check it against this bound.
const fn string_max_size(capacity: usize) -> usize {
    let mut varint_len = 1;
    let mut rest = capacity >> 7;
    while rest > 0 {
        varint_len += 1;
        rest >>= 7;
    }
    varint_len + capacity
}

impl MaxSize for DeviceInfo {
    const POSTCARD_MAX_SIZE: usize = u16::POSTCARD_MAX_SIZE
        + string_max_size(VERSION_TEXT_LEN)
        + string_max_size(GIT_HASH_LEN)
        + string_max_size(BOARD_ID_LEN)
        + <[u8; 12]>::POSTCARD_MAX_SIZE
        + u8::POSTCARD_MAX_SIZE
        + u16::POSTCARD_MAX_SIZE
        + u16::POSTCARD_MAX_SIZE;
}

/// Why the board refused or could not carry out a request.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, MaxSize, Schema)]
pub enum DeviceError {
    /// The frame decoded but its request tag is not one this firmware knows.
    UnknownRequest,
    /// An argument is out of range; names which one.
    BadArgument(Argument),
    /// The board is in a state that cannot take this request now (e.g. flash write in progress).
    Busy,
    /// The request would drive a channel that has a latched fault; clear faults first.
    FaultActive { channel: Side },
    /// `Hello` with another protocol version.
    VersionMismatch { device: u16, host: u16 },
    /// Saving the configuration to flash failed.
    Storage,
    /// A request other than `Hello`, `GetInfo` or `Ping` arrived before the version handshake.
    NotHandshaken,
}

/// The argument a [`DeviceError::BadArgument`] is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, MaxSize, Schema)]
pub enum Argument {
    CurrentMa,
    RampMs,
    PeriodMs,
    Channel,
}

/// Fault flags of one channel, latched until `ClearFaults`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, MaxSize, Schema)]
pub struct FaultFlags {
    /// Full duty and still no current: the string is open (broken wire, dead LED).
    pub open_string: bool,
    /// Current above the hard limit: the channel was switched off.
    pub over_current: bool,
    /// Board too hot: the channel is derated, then switched off.
    pub over_temperature: bool,
    /// Supply too low to regulate.
    pub under_voltage: bool,
}

impl FaultFlags {
    pub const fn any(&self) -> bool {
        self.open_string || self.over_current || self.over_temperature || self.under_voltage
    }
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize, MaxSize, Schema)]
pub struct ChannelState {
    pub setpoint_ma: u16,
    /// Measured over the sense resistor, in mA.
    pub measured_ma: f32,
    /// PWM duty, 0.0 ..= 1.0.
    pub duty: f32,
    pub enabled: bool,
    pub faults: FaultFlags,
}

/// Snapshot of the board, answered to `GetStatus`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize, MaxSize, Schema)]
pub struct Status {
    pub uptime_us: u64,
    pub channels: [ChannelState; CHANNEL_COUNT],
    pub temperature_c: f32,
    pub supply_mv: u16,
    pub ramp_ms: u16,
    pub telemetry_period_ms: u16,
    pub counters: LinkCounters,
    /// Whether the LEDs may be lit at all (USB configured and not suspended).
    pub power: PowerState,
    /// Cap on the sum of the string currents now in force.
    pub current_budget_ma: u16,
    pub loop_timing: LoopTiming,
}

/// What USB allows the board to draw, and so whether the LEDs may be lit.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, MaxSize, Schema)]
pub enum PowerState {
    /// Not (yet) configured by the host: 100 mA allowed, LEDs off.
    #[default]
    Unconfigured,
    /// Configured: the declared bMaxPower is allowed, LEDs as set.
    Configured,
    /// The bus is suspended: 2.5 mA allowed, LEDs off.
    Suspended,
}

/// The control loop's measured period since the previous telemetry frame (or boot), from the board's own clock.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize, MaxSize, Schema)]
pub struct LoopTiming {
    /// Control steps in the window.
    pub steps: u32,
    pub period_mean_us: f32,
    pub period_min_us: u32,
    /// `period_max_us - period_min_us` is the loop's peak-to-peak jitter.
    pub period_max_us: u32,
}

/// Streamed every `period_ms` once `StreamTelemetry` asked for it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize, MaxSize, Schema)]
pub struct Telemetry {
    pub uptime_us: u64,
    pub channels: [ChannelState; CHANNEL_COUNT],
    pub temperature_c: f32,
    pub supply_mv: u16,
    pub counters: LinkCounters,
    pub loop_timing: LoopTiming,
}

/// What the board's stream decoder threw away, by kind (see the framing module).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, MaxSize, Schema)]
pub struct LinkCounters {
    pub bad_cobs: u32,
    pub bad_crc: u32,
    pub oversize: u32,
    pub unknown_tag: u32,
    pub frames_ok: u32,
}

impl fmt::Display for Side {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Side::Top => "top",
            Side::Right => "right",
            Side::Bottom => "bottom",
            Side::Left => "left",
        })
    }
}

impl fmt::Display for Argument {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Argument::CurrentMa => "LED current (mA)",
            Argument::RampMs => "ramp time (ms)",
            Argument::PeriodMs => "telemetry period (ms)",
            Argument::Channel => "channel",
        })
    }
}

/// Plain words for a person at the host; no allocation, so the firmware can use it with defmt or a UART too.
impl fmt::Display for DeviceError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            DeviceError::UnknownRequest => {
                f.write_str("the board does not know this request (is the firmware older than the host?)")
            }
            DeviceError::BadArgument(argument) => write!(f, "the board rejected the {argument}: out of range"),
            DeviceError::Busy => f.write_str("the board is busy (e.g. writing its configuration); try again"),
            DeviceError::FaultActive { channel } => write!(
                f,
                "the {channel} LED channel has a latched fault; clear faults first (and check the LED string)"
            ),
            DeviceError::VersionMismatch { device, host } => {
                let update = if device < host {
                    "update the firmware"
                } else {
                    "update the host"
                };
                write!(
                    f,
                    "board speaks protocol v{device} but this host speaks v{host}: {update} so that both speak the same version"
                )
            }
            DeviceError::Storage => f.write_str("the board could not save its configuration to flash"),
            DeviceError::NotHandshaken => {
                f.write_str("the board has not been greeted yet: send Hello with the protocol version first")
            }
        }
    }
}

impl core::error::Error for DeviceError {}
