//! The [`Controller`]: everything the board decides, driven by the board glue with bytes, measurements and time.
//!
//! The glue (USB or USART task, ADC/PWM loop, flash, reset) calls:
//! - [`Controller::on_rx`] with every chunk received from the host; replies go out through `tx` as whole frames;
//! - [`Controller::control_step`] at >= 1 kHz with fresh measurements; it returns the PWM duty per channel;
//! - [`Controller::poll_telemetry`] often (e.g. after each control step); it sends a frame when one is due;
//! - [`Controller::take_action`] after `on_rx`, to carry out what only the glue can do (flash, reset, DFU);
//! - [`Controller::set_power_state`] when USB is configured, suspended or reset: the LEDs light only while the
//!   port grants the current they draw;
//! - [`Controller::set_host_present`] when the host opens or closes the port (DTR on USB CDC-ACM): telemetry
//!   flows only to a host that listens.
//!
//! Replies (written by `on_rx` and `complete_save_config`) and telemetry (written by `poll_telemetry`) leave
//! through separate `tx` callbacks, so the glue can give replies a path of their own that telemetry cannot fill.

use nusense_protocol::framing::{encode, FrameDecoder, MAX_FRAME_LEN};
use nusense_protocol::{
    Argument, BoardMessage, Channel, ChannelState, DeviceError, DeviceInfo, LinkCounters, LoopTiming, PowerState,
    Reply, Request, RequestBody, Response, Seq, Side, Status, Telemetry, CHANNEL_COUNT, PROTOCOL_VERSION,
    SCHEMA_FINGERPRINT,
};

use crate::config::BoardConfig;
use crate::faults::FaultMonitor;
use crate::identity::Identity;
use crate::limits::{MAX_CURRENT_MA, MAX_RAMP_MS, MAX_TOTAL_CURRENT_MA, MIN_TELEMETRY_PERIOD_MS};
use crate::regulator::ChannelRegulator;

/// One set of readings from the board's ADC, already in physical units.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Measurements {
    /// Per channel, in the protocol's `Side` order.
    pub current_ma: [f32; CHANNEL_COUNT],
    pub supply_mv: f32,
    pub temperature_c: f32,
}

/// Something only the board glue can carry out, requested by the host.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Action {
    /// Store this configuration as written by `request_id` ([`crate::store::ConfigStore::save`]), then report
    /// the outcome with [`Controller::complete_save_config`]: the host's reply waits for it.
    SaveConfig { config: BoardConfig, request_id: u32 },
    /// The Ack has been written to `tx`: reset once it has left the link.
    Reset,
    /// The Ack has been written to `tx`: start the MCU's built-in DFU bootloader once it has left the link.
    EnterBootloader,
}

/// The board's brain: command dispatch, regulator, fault monitor, telemetry. No hardware, no allocation.
pub struct Controller {
    decoder: FrameDecoder,
    board: BoardState,
}

struct BoardState {
    identity: Identity,
    config: BoardConfig,
    regulators: [ChannelRegulator; CHANNEL_COUNT],
    monitor: FaultMonitor,
    duty: [f32; CHANNEL_COUNT],
    last: Measurements,
    last_step_us: Option<u64>,
    loop_stats: LoopStats,
    handshaken: bool,
    host_present: bool,
    power: PowerState,
    /// The glue holds the outputs off (a flash erase is about to stall the CPU).
    outputs_held_off: bool,
    telemetry_period_ms: u16,
    next_telemetry_us: u64,
    pending_action: Option<Action>,
    pending_save: Option<PendingSave>,
    /// The request id of the last save that reached flash (from the stored record at boot).
    last_saved_request_id: Option<u32>,
    /// Frames that passed the CRC but hold a request this firmware does not know (answered `UnknownRequest`).
    unknown_requests: u32,
}

/// A `SaveConfig` handed to the glue and not completed yet.
#[derive(Clone, Copy, Debug)]
struct PendingSave {
    /// The sequence number to answer: the latest attempt's, when the host retried meanwhile.
    seq: Seq,
    request_id: u32,
}

/// The control loop's period over a window of steps (see [`LoopTiming`]).
#[derive(Clone, Copy, Debug, Default)]
struct LoopStats {
    steps: u32,
    sum_us: u64,
    min_us: u32,
    max_us: u32,
}

impl LoopStats {
    fn record(&mut self, period_us: u32) {
        if self.steps == 0 {
            self.min_us = period_us;
            self.max_us = period_us;
        } else {
            self.min_us = self.min_us.min(period_us);
            self.max_us = self.max_us.max(period_us);
        }
        self.steps = self.steps.saturating_add(1);
        self.sum_us = self.sum_us.saturating_add(u64::from(period_us));
    }

    fn timing(&self) -> LoopTiming {
        LoopTiming {
            steps: self.steps,
            period_mean_us: if self.steps == 0 {
                0.0
            } else {
                self.sum_us as f32 / self.steps as f32
            },
            period_min_us: self.min_us,
            period_max_us: self.max_us,
        }
    }
}

impl Controller {
    /// A board that has booted with `config` (clamped to the limits). The LEDs stay off until the glue reports
    /// [`PowerState::Configured`].
    pub fn new(identity: Identity, config: BoardConfig) -> Self {
        let config = config.clamped();
        Self {
            decoder: FrameDecoder::new(),
            board: BoardState {
                identity,
                config,
                regulators: [ChannelRegulator::new(); CHANNEL_COUNT],
                monitor: FaultMonitor::new(),
                duty: [0.0; CHANNEL_COUNT],
                last: Measurements::default(),
                last_step_us: None,
                loop_stats: LoopStats::default(),
                handshaken: false,
                host_present: true,
                power: PowerState::Unconfigured,
                outputs_held_off: false,
                telemetry_period_ms: 0,
                next_telemetry_us: 0,
                pending_action: None,
                pending_save: None,
                last_saved_request_id: None,
                unknown_requests: 0,
            },
        }
    }

    /// The request id of the record the configuration was restored from, so that a host retrying the save that
    /// wrote it (the board reset before the reply left) is answered without a second write.
    pub fn with_saved_request_id(mut self, request_id: Option<u32>) -> Self {
        self.board.last_saved_request_id = request_id;
        self
    }

    /// What USB allows now. Anything but `Configured` switches every string off at the next control step (and
    /// the soft start begins again once it is back).
    pub fn set_power_state(&mut self, power: PowerState) {
        self.board.power = power;
    }

    pub fn power_state(&self) -> PowerState {
        self.board.power
    }

    /// Every string off from the next control step until released, then a soft start: what the glue asks for
    /// around a flash erase, during which the CPU cannot run the loop.
    pub fn hold_outputs_off(&mut self, held: bool) {
        self.board.outputs_held_off = held;
    }

    /// Whether a host has the port open (DTR). Opening or closing it is a new session: a half-received frame is
    /// dropped, the stream stops and a new handshake is expected. While nobody listens, no telemetry is made.
    pub fn set_host_present(&mut self, present: bool) {
        if present != self.board.host_present {
            self.on_link_reset();
        }
        self.board.host_present = present;
    }

    /// Bytes from the host link (USB CDC or USART), any chunking; writes encoded reply frames through `tx`.
    pub fn on_rx(&mut self, bytes: &[u8], now_us: u64, tx: &mut impl FnMut(&[u8])) {
        let Self { decoder, board } = self;
        // The status a request in this chunk reports counts the frames of earlier chunks.
        let counters = board.counters(decoder.counters());
        decoder.feed::<Inbound>(bytes, |frame| match frame {
            Ok(Inbound::Request(request)) => {
                if let Some(response) = board.handle(request, now_us, counters) {
                    send(&BoardMessage::Response(response), tx);
                }
            }
            Ok(Inbound::Unknown { seq }) => {
                board.unknown_requests = board.unknown_requests.wrapping_add(1);
                send(
                    &BoardMessage::Response(Response {
                        seq,
                        result: Err(DeviceError::UnknownRequest),
                    }),
                    tx,
                );
            }
            // Damaged frames carry no sequence number to answer; they are counted and show in Status/Telemetry.
            Err(_) => {}
        });
    }

    /// The link went away (USB unplugged, port closed): drop any half-received frame, stop streaming, and expect
    /// a new handshake. The LEDs keep their state.
    pub fn on_link_reset(&mut self) {
        self.decoder.clear();
        self.board.handshaken = false;
        self.board.telemetry_period_ms = 0;
    }

    /// One regulator + fault-monitor step (call at >= 1 kHz); returns the PWM duty per channel (0..=1).
    pub fn control_step(&mut self, now_us: u64, m: &Measurements) -> [f32; CHANNEL_COUNT] {
        self.board.control_step(now_us, m)
    }

    /// Sends a Telemetry frame through `tx` when one is due (and a host listens).
    pub fn poll_telemetry(&mut self, now_us: u64, tx: &mut impl FnMut(&[u8])) {
        let board = &mut self.board;
        if !board.host_present || board.telemetry_period_ms == 0 || now_us < board.next_telemetry_us {
            return;
        }
        let period_us = u64::from(board.telemetry_period_ms) * 1_000;
        board.next_telemetry_us += period_us;
        if board.next_telemetry_us <= now_us {
            // Fell behind (a stalled link): resume the cadence from now instead of bursting.
            board.next_telemetry_us = now_us + period_us;
        }
        let counters = board.counters(self.decoder.counters());
        let telemetry = Telemetry {
            uptime_us: now_us,
            channels: board.channel_states(),
            temperature_c: finite_or_zero(board.last.temperature_c),
            supply_mv: supply_mv_u16(board.last.supply_mv),
            counters,
            loop_timing: board.loop_stats.timing(),
        };
        // Each frame reports the steps since the previous one.
        board.loop_stats = LoopStats::default();
        send(&BoardMessage::Telemetry(telemetry), tx);
    }

    /// SaveConfig / Reset / EnterBootloader for the board glue to carry out.
    pub fn take_action(&mut self) -> Option<Action> {
        self.board.pending_action.take()
    }

    /// Outcome of an [`Action::SaveConfig`]; sends the reply the host is waiting for.
    pub fn complete_save_config(&mut self, saved: bool, tx: &mut impl FnMut(&[u8])) {
        if let Some(PendingSave { seq, request_id }) = self.board.pending_save.take() {
            let result = if saved {
                self.board.last_saved_request_id = Some(request_id);
                Ok(Reply::Ack)
            } else {
                Err(DeviceError::Storage)
            };
            send(&BoardMessage::Response(Response { seq, result }), tx);
        }
    }

    /// The loop timing since the last telemetry frame (what the next one will report).
    pub fn loop_timing(&self) -> LoopTiming {
        self.board.loop_stats.timing()
    }

    /// What `GetStatus` would answer now.
    pub fn status(&self, now_us: u64) -> Status {
        self.board.status(now_us, self.board.counters(self.decoder.counters()))
    }

    /// The live configuration (what `SaveConfig` would store).
    pub fn config(&self) -> BoardConfig {
        self.board.config
    }

    /// Duty applied by the last control step.
    pub fn duty(&self) -> [f32; CHANNEL_COUNT] {
        self.board.duty
    }

    pub fn identity(&self) -> &Identity {
        &self.board.identity
    }
}

impl BoardState {
    fn counters(&self, link: LinkCounters) -> LinkCounters {
        LinkCounters {
            unknown_tag: link.unknown_tag.wrapping_add(self.unknown_requests),
            ..link
        }
    }

    /// `None` when the answer is deferred (SaveConfig waits for the flash).
    fn handle(&mut self, request: Request, now_us: u64, counters: LinkCounters) -> Option<Response> {
        let seq = request.seq;
        let allowed_before_handshake = matches!(
            request.body,
            RequestBody::Hello { .. } | RequestBody::GetInfo | RequestBody::Ping { .. }
        );
        let result = if !self.handshaken && !allowed_before_handshake {
            Err(DeviceError::NotHandshaken)
        } else {
            match request.body {
                RequestBody::Hello { protocol_version } => self.hello(protocol_version),
                RequestBody::GetInfo => Ok(Reply::Info(self.info())),
                RequestBody::GetStatus => Ok(Reply::Status(self.status(now_us, counters))),
                RequestBody::SetLed {
                    channel,
                    current_ma,
                    enabled,
                } => self.set_led(channel, current_ma, enabled),
                RequestBody::SetRamp { ms } => {
                    if ms > MAX_RAMP_MS {
                        Err(DeviceError::BadArgument(Argument::RampMs))
                    } else {
                        self.config.ramp_ms = ms;
                        Ok(Reply::Ack)
                    }
                }
                RequestBody::StreamTelemetry { period_ms } => self.stream(period_ms, now_us),
                RequestBody::ClearFaults => {
                    self.monitor.clear();
                    // Restart every channel with its soft start rather than jumping back to the old duty.
                    self.regulators = [ChannelRegulator::new(); CHANNEL_COUNT];
                    Ok(Reply::Ack)
                }
                RequestBody::SaveConfig { request_id } => return self.save_config(seq, request_id),
                RequestBody::Reset => self.request_action(Action::Reset),
                RequestBody::EnterBootloader => self.request_action(Action::EnterBootloader),
                RequestBody::Ping { nonce } => Ok(Reply::Pong { nonce }),
                RequestBody::SetCurrentBudget { total_ma } => {
                    self.config.current_budget_ma = total_ma.min(MAX_TOTAL_CURRENT_MA);
                    Ok(Reply::Ack)
                }
            }
        };
        Some(Response { seq, result })
    }

    /// A retry of the save that already reached flash is acknowledged without writing; a retry of the one under
    /// way gets the answer when it completes; any other save waits its turn (`Busy`).
    fn save_config(&mut self, seq: Seq, request_id: u32) -> Option<Response> {
        let result = if self.last_saved_request_id == Some(request_id) {
            Ok(Reply::Ack)
        } else if let Some(pending) = &mut self.pending_save {
            if pending.request_id != request_id {
                Err(DeviceError::Busy)
            } else {
                pending.seq = seq;
                return None;
            }
        } else if self.pending_action.is_some() {
            Err(DeviceError::Busy)
        } else {
            self.pending_action = Some(Action::SaveConfig {
                config: self.config,
                request_id,
            });
            self.pending_save = Some(PendingSave { seq, request_id });
            return None;
        };
        Some(Response { seq, result })
    }

    fn hello(&mut self, host: u16) -> Result<Reply, DeviceError> {
        if host == PROTOCOL_VERSION {
            self.handshaken = true;
            Ok(Reply::Hello {
                protocol_version: PROTOCOL_VERSION,
                schema: SCHEMA_FINGERPRINT,
            })
        } else {
            Err(DeviceError::VersionMismatch {
                device: PROTOCOL_VERSION,
                host,
            })
        }
    }

    fn info(&self) -> DeviceInfo {
        DeviceInfo {
            protocol_version: PROTOCOL_VERSION,
            firmware_version: self.identity.firmware_version.clone(),
            git_hash: self.identity.git_hash.clone(),
            board_id: self.identity.board_id.clone(),
            mcu_uid: self.identity.mcu_uid,
            channel_count: CHANNEL_COUNT as u8,
            max_current_ma: MAX_CURRENT_MA,
            max_total_current_ma: MAX_TOTAL_CURRENT_MA,
        }
    }

    fn set_led(&mut self, channel: Channel, current_ma: u16, enabled: bool) -> Result<Reply, DeviceError> {
        let sides: &[Side] = match &channel {
            Channel::One(side) => core::slice::from_ref(side),
            Channel::All => &Side::ALL,
        };
        if enabled {
            if let Some(&side) = sides.iter().find(|s| self.monitor.is_tripped(s.index())) {
                return Err(DeviceError::FaultActive { channel: side });
            }
        }
        for side in sides {
            let ch = side.index();
            self.config.setpoints_ma[ch] = current_ma.min(MAX_CURRENT_MA);
            self.config.enabled[ch] = enabled;
            if !enabled {
                self.regulators[ch].reset();
            }
        }
        Ok(Reply::Ack)
    }

    fn stream(&mut self, period_ms: u16, now_us: u64) -> Result<Reply, DeviceError> {
        if period_ms != 0 && period_ms < MIN_TELEMETRY_PERIOD_MS {
            return Err(DeviceError::BadArgument(Argument::PeriodMs));
        }
        self.telemetry_period_ms = period_ms;
        self.next_telemetry_us = now_us;
        Ok(Reply::Ack)
    }

    fn request_action(&mut self, action: Action) -> Result<Reply, DeviceError> {
        if self.pending_action.is_some() || self.pending_save.is_some() {
            return Err(DeviceError::Busy);
        }
        self.pending_action = Some(action);
        Ok(Reply::Ack)
    }

    fn control_step(&mut self, now_us: u64, m: &Measurements) -> [f32; CHANNEL_COUNT] {
        let dt_us = match self.last_step_us {
            Some(last) => u32::try_from(now_us.saturating_sub(last)).unwrap_or(u32::MAX),
            None => 0,
        };
        if self.last_step_us.is_some() {
            self.loop_stats.record(dt_us);
        }
        self.last_step_us = Some(now_us);
        self.last = *m;

        let powered = self.power == PowerState::Configured && !self.outputs_held_off;
        let driving = core::array::from_fn(|ch| powered && self.config.enabled[ch] && self.config.setpoints_ma[ch] > 0);
        self.monitor.check(now_us, m, driving, self.duty);
        let targets = self.targets_ma(driving, FaultMonitor::derate_factor(m.temperature_c));
        self.duty = core::array::from_fn(|ch| match targets[ch] {
            Some(target_ma) => self.regulators[ch].step(target_ma, self.config.ramp_ms, m.current_ma[ch], dt_us),
            None => {
                self.regulators[ch].reset();
                0.0
            }
        });
        self.duty
    }

    /// The current each lit channel regulates to: its setpoint, derated when the board is hot, and scaled down
    /// with the others so that together they stay within the current budget. `None`: the channel is off.
    fn targets_ma(&self, driving: [bool; CHANNEL_COUNT], derate: f32) -> [Option<f32>; CHANNEL_COUNT] {
        let mut targets: [Option<f32>; CHANNEL_COUNT] = core::array::from_fn(|ch| {
            (driving[ch] && !self.monitor.is_tripped(ch))
                .then(|| f32::from(self.config.setpoints_ma[ch].min(MAX_CURRENT_MA)) * derate)
        });
        let total: f32 = targets.iter().flatten().sum();
        let budget = f32::from(self.config.current_budget_ma.min(MAX_TOTAL_CURRENT_MA));
        if total > budget {
            let scale = budget / total;
            for target in targets.iter_mut().flatten() {
                *target *= scale;
            }
        }
        targets
    }

    fn channel_states(&self) -> [ChannelState; CHANNEL_COUNT] {
        let flags = self.monitor.flags();
        core::array::from_fn(|ch| ChannelState {
            setpoint_ma: self.config.setpoints_ma[ch],
            measured_ma: finite_or_zero(self.last.current_ma[ch]),
            duty: self.duty[ch],
            enabled: self.config.enabled[ch],
            faults: flags[ch],
        })
    }

    fn status(&self, now_us: u64, counters: LinkCounters) -> Status {
        Status {
            uptime_us: now_us,
            channels: self.channel_states(),
            temperature_c: finite_or_zero(self.last.temperature_c),
            supply_mv: supply_mv_u16(self.last.supply_mv),
            ramp_ms: self.config.ramp_ms,
            telemetry_period_ms: self.telemetry_period_ms,
            counters,
            power: self.power,
            current_budget_ma: self.config.current_budget_ma,
            loop_timing: self.loop_stats.timing(),
        }
    }
}

fn send(message: &BoardMessage, tx: &mut impl FnMut(&[u8])) {
    let mut buf = [0u8; MAX_FRAME_LEN];
    // Every BoardMessage fits MAX_FRAME_LEN by construction of the protocol crate, so this cannot fail.
    if let Ok(frame) = encode(message, &mut buf) {
        tx(frame);
    }
}

fn finite_or_zero(x: f32) -> f32 {
    if x.is_finite() {
        x
    } else {
        0.0
    }
}

fn supply_mv_u16(mv: f32) -> u16 {
    // `as` saturates and maps NaN to 0.
    mv as u16
}

/// A received request, or just its sequence number when the body is not one this firmware knows, so that even
/// an unknown request gets an answer the host can match.
enum Inbound {
    Request(Request),
    Unknown { seq: Seq },
}

impl<'de> serde::Deserialize<'de> for Inbound {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        // postcard encodes a struct as its fields in order, read through a sequence: ask for "as many elements
        // as there are" so that after the sequence number the rest can be inspected byte by byte.
        deserializer.deserialize_tuple(usize::MAX, InboundVisitor)
    }
}

struct InboundVisitor;

impl<'de> serde::de::Visitor<'de> for InboundVisitor {
    type Value = Inbound;

    fn expecting(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("a request: sequence number then body")
    }

    fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<Inbound, A::Error> {
        let Some(number) = seq.next_element::<Seq>()? else {
            return Err(serde::de::Error::invalid_length(0, &self));
        };
        let body = seq.next_element::<RequestBody>().ok().flatten();
        // Consume whatever is left: trailing bytes after a known body also make the request unknown.
        let mut trailing = false;
        while let Ok(Some(_)) = seq.next_element::<u8>() {
            trailing = true;
        }
        Ok(match body {
            Some(body) if !trailing => Inbound::Request(Request { seq: number, body }),
            _ => Inbound::Unknown { seq: number },
        })
    }
}
