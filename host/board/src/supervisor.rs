//! A board link that looks after itself: a background thread keeps the board connected, reconnects with
//! backoff after an unplug, forwards telemetry and connection changes to subscribers, and carries out LED
//! commands. This is what the daemon holds; it never needs a restart when the cable is pulled.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender, SyncSender, TrySendError};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use nusense_protocol::{Channel, DeviceInfo, Side, Telemetry, CHANNEL_COUNT};
use serde::Serialize;

use super::discovery::find_board;
use super::error::LinkError;
use super::link::{BoardLink, LinkOptions, LinkStats};

/// Which board to keep connected.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum BoardTarget {
    /// A fixed device path (e.g. /dev/serial/by-id/..., a pty). Reopened at the same path after an unplug.
    Path(String),
    /// The board with this USB serial number, wherever it enumerates.
    UsbSerial(String),
    /// The only attached board.
    AnyBoard,
}

impl std::fmt::Display for BoardTarget {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            BoardTarget::Path(path) => write!(f, "{path}"),
            BoardTarget::UsbSerial(serial) => {
                write!(f, "the board with USB serial number {serial}")
            }
            BoardTarget::AnyBoard => write!(f, "any NUSense board"),
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SupervisorOptions {
    pub link: LinkOptions,
    /// Telemetry period asked of the board after every (re)connect.
    pub telemetry_period_ms: u16,
    /// First wait after a failed connect; doubles up to `backoff_max`.
    pub backoff_min: Duration,
    /// Longest wait between connect attempts; bounds how long a replugged board stays unnoticed.
    pub backoff_max: Duration,
    /// With no telemetry for this long, the board is pinged; no answer means it is gone.
    pub silence_limit: Duration,
}

impl Default for SupervisorOptions {
    fn default() -> Self {
        Self {
            link: LinkOptions::default(),
            telemetry_period_ms: 50,
            backoff_min: Duration::from_millis(50),
            // A replugged board must be back within 2 s: at most 0.5 s of waiting plus the handshake.
            backoff_max: Duration::from_millis(500),
            silence_limit: Duration::from_millis(500),
        }
    }
}

/// What subscribers are told.
#[derive(Clone, Debug, PartialEq)]
pub enum BoardEvent {
    Connected { port: String, info: DeviceInfo },
    Telemetry(Telemetry),
    Disconnected { reason: String },
}

/// The latest known state of the board, for status pages and readings.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct BoardState {
    pub connected: bool,
    /// Device path of the current (or last) connection.
    pub port: Option<String>,
    pub info: Option<DeviceInfo>,
    /// The most recent telemetry (LED currents, duties, faults, temperature, supply).
    pub telemetry: Option<Telemetry>,
    /// Host-side counters of the current connection.
    pub link: LinkStats,
    /// Successful connects since start (1 = never lost).
    pub connects: u64,
    /// Why the last connect attempt or connection failed.
    pub last_error: Option<String>,
    /// LED settings the host asked for (re-applied after every reconnect), per side: Top, Right, Bottom, Left.
    pub requested: [Option<LedRequest>; CHANNEL_COUNT],
}

/// One channel's LED setting as the host last asked for it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct LedRequest {
    pub current_ma: u16,
    pub enabled: bool,
}

enum Command {
    SetLed {
        channel: Channel,
        current_ma: u16,
        enabled: bool,
        reply: Sender<Result<(), LinkError>>,
    },
    Stop,
}

type Connector = Box<dyn FnMut() -> Result<BoardLink, LinkError> + Send>;

struct Shared {
    state: Mutex<BoardState>,
    subscribers: Mutex<Vec<SyncSender<BoardEvent>>>,
    events_dropped: AtomicU64,
    stop: AtomicBool,
}

impl Shared {
    fn state(&self) -> MutexGuard<'_, BoardState> {
        self.state.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    fn publish(&self, event: BoardEvent) {
        let mut subscribers = self.subscribers.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        subscribers.retain(|subscriber| match subscriber.try_send(event.clone()) {
            Ok(()) => true,
            // A slow subscriber loses events rather than stalling the board.
            Err(TrySendError::Full(_)) => {
                self.events_dropped.fetch_add(1, Ordering::Relaxed);
                true
            }
            Err(TrySendError::Disconnected(_)) => false,
        });
    }
}

/// Handle to the background thread; dropping it stops the thread.
pub struct SupervisedLink {
    commands: Sender<Command>,
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
    command_timeout: Duration,
}

/// Events a subscriber may fall behind by before it starts losing them.
const SUBSCRIBER_QUEUE_LEN: usize = 256;
/// How often the thread looks at its command queue while waiting for telemetry.
const COMMAND_POLL: Duration = Duration::from_millis(5);

impl SupervisedLink {
    /// Starts keeping `target` connected.
    pub fn spawn(target: BoardTarget, options: SupervisorOptions) -> Self {
        let description = target.to_string();
        let link_options = options.link;
        let connector: Connector = Box::new(move || match &target {
            BoardTarget::Path(path) => BoardLink::open(path, link_options),
            BoardTarget::UsbSerial(serial) => BoardLink::open(&find_board(Some(serial))?.path, link_options),
            BoardTarget::AnyBoard => BoardLink::open(&find_board(None)?.path, link_options),
        });
        Self::spawn_with(connector, description, options)
    }

    /// Starts keeping a link connected that `connect` opens (e.g. over an in-memory pipe).
    pub fn spawn_with(
        connect: impl FnMut() -> Result<BoardLink, LinkError> + Send + 'static,
        description: String,
        options: SupervisorOptions,
    ) -> Self {
        let (commands, command_rx) = mpsc::channel();
        let shared = Arc::new(Shared {
            state: Mutex::new(BoardState::default()),
            subscribers: Mutex::new(Vec::new()),
            events_dropped: AtomicU64::new(0),
            stop: AtomicBool::new(false),
        });
        let worker = Worker {
            connect: Box::new(connect),
            options,
            commands: command_rx,
            shared: shared.clone(),
        };
        let thread = std::thread::Builder::new()
            .name(format!("board link {description}"))
            .spawn(move || worker.run())
            .ok();
        if thread.is_none() {
            shared.state().last_error = Some("cannot start the board link thread".into());
        }
        let command_timeout = (options.link.timeout * (options.link.retries + 1)) + Duration::from_millis(100);
        Self {
            commands,
            shared,
            thread,
            command_timeout,
        }
    }

    /// A stream of connection changes and telemetry from now on. A subscriber that falls more than 256 events
    /// behind loses the newest ones (counted in [`Self::events_dropped`]); dropping the receiver unsubscribes.
    pub fn subscribe(&self) -> Receiver<BoardEvent> {
        let (sender, receiver) = mpsc::sync_channel(SUBSCRIBER_QUEUE_LEN);
        self.shared
            .subscribers
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
            .push(sender);
        receiver
    }

    /// A copy of the latest board state.
    pub fn state(&self) -> BoardState {
        self.shared.state().clone()
    }

    pub fn is_connected(&self) -> bool {
        self.shared.state().connected
    }

    /// Events not delivered to subscribers that were too slow.
    pub fn events_dropped(&self) -> u64 {
        self.shared.events_dropped.load(Ordering::Relaxed)
    }

    /// Sets LED current on the connected board and waits for its acknowledgement. The setpoint is remembered and
    /// re-applied after reconnects. Fails with [`LinkError::NotConnected`] while the board is away.
    pub fn set_led(&self, channel: Channel, current_ma: u16, enabled: bool) -> Result<(), LinkError> {
        let (reply, answer) = mpsc::channel();
        self.commands
            .send(Command::SetLed {
                channel,
                current_ma,
                enabled,
                reply,
            })
            .map_err(|_| LinkError::Stopped)?;
        match answer.recv_timeout(self.command_timeout) {
            Ok(result) => result,
            Err(RecvTimeoutError::Timeout) => Err(LinkError::Timeout),
            Err(RecvTimeoutError::Disconnected) => Err(LinkError::Stopped),
        }
    }

    /// Waits until the board is connected, up to `timeout`; true if it is.
    pub fn wait_connected(&self, timeout: Duration) -> bool {
        let deadline = Instant::now() + timeout;
        loop {
            if self.is_connected() {
                return true;
            }
            if Instant::now() >= deadline {
                return false;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    }
}

impl Drop for SupervisedLink {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        let _ = self.commands.send(Command::Stop);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

struct Worker {
    connect: Connector,
    options: SupervisorOptions,
    commands: Receiver<Command>,
    shared: Arc<Shared>,
}

/// Why a connection ended.
enum Ended {
    Stopped,
    Lost(LinkError),
}

impl Worker {
    fn run(mut self) {
        let mut backoff = self.options.backoff_min;
        while !self.stopping() {
            match (self.connect)() {
                Ok(link) => {
                    backoff = self.options.backoff_min;
                    match self.serve(link) {
                        Ended::Stopped => return,
                        Ended::Lost(error) => self.mark_lost(&error),
                    }
                }
                Err(error) => {
                    tracing::debug!(target: "nusense_board", %error, "board connect failed");
                    self.shared.state().last_error = Some(error.to_string());
                }
            }
            if self.wait_refusing_commands(backoff) {
                return;
            }
            backoff = (backoff * 2).min(self.options.backoff_max);
        }
    }

    fn stopping(&self) -> bool {
        self.shared.stop.load(Ordering::Relaxed)
    }

    /// Sleeps for `duration` while answering commands with NotConnected; true if asked to stop.
    fn wait_refusing_commands(&self, duration: Duration) -> bool {
        let deadline = Instant::now() + duration;
        loop {
            let now = Instant::now();
            if now >= deadline {
                return self.stopping();
            }
            match self.commands.recv_timeout(deadline - now) {
                Ok(Command::SetLed { reply, .. }) => {
                    let _ = reply.send(Err(LinkError::NotConnected));
                }
                Ok(Command::Stop) | Err(RecvTimeoutError::Disconnected) => return true,
                Err(RecvTimeoutError::Timeout) => return self.stopping(),
            }
        }
    }

    fn mark_lost(&self, error: &LinkError) {
        tracing::warn!(target: "nusense_board", %error, "board link lost; reconnecting");
        {
            let mut state = self.shared.state();
            state.connected = false;
            state.last_error = Some(error.to_string());
        }
        self.shared.publish(BoardEvent::Disconnected {
            reason: error.to_string(),
        });
    }

    /// Brings a fresh connection to the wanted state and serves it until it fails or the handle is dropped.
    fn serve(&mut self, mut link: BoardLink) -> Ended {
        let info = match self.prepare(&mut link) {
            Ok(info) => info,
            Err(error) => return Ended::Lost(error),
        };
        let port = link.describe();
        {
            let mut state = self.shared.state();
            state.connected = true;
            state.port = Some(port.clone());
            state.info = Some(info.clone());
            state.connects += 1;
            state.link = link.stats();
        }
        tracing::info!(target: "nusense_board", %port, "board connected");
        self.shared.publish(BoardEvent::Connected { port, info });

        let mut last_heard = Instant::now();
        loop {
            loop {
                match self.commands.try_recv() {
                    Ok(Command::SetLed {
                        channel,
                        current_ma,
                        enabled,
                        reply,
                    }) => {
                        let result = link.set_led(channel, current_ma, enabled);
                        if result.is_ok() {
                            self.remember_led(channel, current_ma, enabled);
                        }
                        // The caller gets the error; the link is rebuilt if the board is gone or not answering.
                        let lost = match &result {
                            Err(LinkError::Disconnected) => Some(LinkError::Disconnected),
                            Err(LinkError::Timeout) => Some(LinkError::Timeout),
                            _ => None,
                        };
                        let _ = reply.send(result);
                        if let Some(error) = lost {
                            return Ended::Lost(error);
                        }
                    }
                    Ok(Command::Stop) | Err(mpsc::TryRecvError::Disconnected) => return Ended::Stopped,
                    Err(mpsc::TryRecvError::Empty) => break,
                }
            }
            if self.stopping() {
                return Ended::Stopped;
            }
            match link.next_telemetry(COMMAND_POLL) {
                Ok(Some(telemetry)) => {
                    last_heard = Instant::now();
                    {
                        let mut state = self.shared.state();
                        state.telemetry = Some(telemetry);
                        state.link = link.stats();
                    }
                    self.shared.publish(BoardEvent::Telemetry(telemetry));
                }
                Ok(None) if last_heard.elapsed() >= self.options.silence_limit => {
                    // Quiet for too long: a ping tells a hung or vanished board from a slow stream.
                    if let Err(error) = link.ping(0x5EA5_0001) {
                        return Ended::Lost(error);
                    }
                    last_heard = Instant::now();
                    self.shared.state().link = link.stats();
                }
                Ok(None) => {}
                Err(error) => return Ended::Lost(error),
            }
        }
    }

    /// Identity, telemetry stream and the LED setpoints the host asked for before the (re)connect.
    fn prepare(&self, link: &mut BoardLink) -> Result<DeviceInfo, LinkError> {
        let info = link.info()?;
        let requested = self.shared.state().requested;
        for side in Side::ALL {
            if let Some(LedRequest { current_ma, enabled }) = requested[side.index()] {
                link.set_led(Channel::One(side), current_ma, enabled)?;
            }
        }
        link.stream_telemetry(self.options.telemetry_period_ms)?;
        Ok(info)
    }

    fn remember_led(&self, channel: Channel, current_ma: u16, enabled: bool) {
        let request = Some(LedRequest { current_ma, enabled });
        let mut state = self.shared.state();
        match channel {
            Channel::One(side) => state.requested[side.index()] = request,
            Channel::All => state.requested = [request; CHANNEL_COUNT],
        }
    }
}
