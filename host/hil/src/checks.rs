//! The checks, in the order they run. Each takes the session (the open link, reopened after a disconnect) and
//! returns its verdict with the numbers it measured; a link error fails that check and the suite goes on.

use std::time::{Duration, Instant};

use nusense_protocol::{Channel, DeviceError, LinkCounters, Side, Status, Telemetry, CHANNEL_COUNT, PROTOCOL_VERSION};
use serde::Serialize;
use serde_json::Value;

use super::camera::BrightnessProbe;
use super::telemetry_timing::{ControlLoopTiming, TelemetrySamples, TelemetryTiming};
use super::{BoardClock, CheckResult, HilOptions, HilReport, RunningTarget, Verdict};
use nusense_board::{BoardLink, LinkError};
use nusense_estimator::stats::{mean, pearson, quantile};

/// Consecutive telemetry frames within tolerance that count as "settled".
const SETTLED_RUN: usize = 5;
/// How long a single telemetry read waits before the settle loop looks at its deadline again.
const TELEMETRY_POLL: Duration = Duration::from_millis(100);
/// The nominal LED current, restored after the clamp check when the board's own state is unknown.
const NOMINAL_MA: u16 = nusense_firmware_core::limits::NOMINAL_CURRENT_MA;
/// Under emulation, how many times a wait's length in board time the wall clock may run before the wait ends
/// anyway: only a board whose telemetry has stopped gets there (a starved emulator runs at a fraction of wall
/// time, well above this).
const EMULATED_WALL_GUARD: u32 = 20;

/// How long a wait on the board lasts: on the wall clock for a board on a crystal (its clock and the host's agree),
/// on the board's own clock under emulation, measured by the telemetry it sends, because a starved emulator runs
/// slower than wall time and would otherwise be given less time to do the same work than a real board.
struct Deadline {
    clock: BoardClock,
    length: Duration,
    started: Instant,
    first_uptime_us: Option<u64>,
    last_uptime_us: u64,
}

impl Deadline {
    fn new(clock: BoardClock, length: Duration) -> Self {
        Self {
            clock,
            length,
            started: Instant::now(),
            first_uptime_us: None,
            last_uptime_us: 0,
        }
    }

    /// A telemetry frame arrived: board time has moved on. The first frame's time is the start: frames still in
    /// flight from before the request make it earlier, never later, than the request.
    fn saw(&mut self, telemetry: &Telemetry) {
        self.first_uptime_us.get_or_insert(telemetry.uptime_us);
        self.last_uptime_us = telemetry.uptime_us;
    }

    fn passed(&self) -> bool {
        match self.clock {
            BoardClock::WallClock => self.started.elapsed() >= self.length,
            BoardClock::Emulated => {
                let board = self
                    .first_uptime_us
                    .map(|first| Duration::from_micros(self.last_uptime_us.saturating_sub(first)));
                board.is_some_and(|board| board >= self.length)
                    || self.started.elapsed() >= self.length * EMULATED_WALL_GUARD
            }
        }
    }
}

type Outcome = Result<(Verdict, String, Value), CheckError>;

/// A check's details as the report's JSON: each check has its own typed struct.
fn as_json(details: impl Serialize) -> Value {
    serde_json::to_value(details).expect("check details are plain numbers and text")
}

/// A check that ended in an error (or, for the reopen, could not reopen).
#[derive(Serialize)]
struct ErrorDetails {
    error: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    reopen_ms: Option<f64>,
}

#[derive(Debug, thiserror::Error)]
enum CheckError {
    #[error("{0}")]
    Link(#[from] LinkError),
    #[error("no telemetry arrived within {0:?} although streaming was requested")]
    NoTelemetry(Duration),
    #[error("{0}")]
    Camera(#[from] super::CameraProbeError),
}

struct Session<'a> {
    port: &'a str,
    options: &'a HilOptions,
    link: Option<BoardLink>,
    /// The board's state before the suite touched it, restored at the end.
    initial: Option<Status>,
    max_current_ma: Option<u16>,
    /// The board's total current budget (`DeviceInfo::max_total_current_ma`).
    max_total_current_ma: Option<u16>,
    /// Attempts the last (re)open of the link took.
    open_attempts: u32,
    clock: BoardClock,
    /// Board time over wall time, measured by the telemetry check (1 for a board on a crystal).
    board_clock_ratio: Option<f64>,
}

/// Opens `port` with the handshake, retrying until `options.connect_timeout`; returns the link and the number
/// of attempts, or the last attempt's error.
fn open_with_retries(port: &str, options: &HilOptions) -> Result<(BoardLink, u32), LinkError> {
    let started = Instant::now();
    let mut attempts = 0;
    loop {
        attempts += 1;
        match BoardLink::open(port, options.link) {
            Ok(link) => return Ok((link, attempts)),
            Err(error) if started.elapsed() >= options.connect_timeout => return Err(error),
            Err(_) => std::thread::sleep(Duration::from_millis(100)),
        }
    }
}

impl Session<'_> {
    /// The open link, opening it when needed. A board that has just booted (QEMU starting, USB enumerating) or
    /// a port that was just closed may not answer at once: opening is retried for `connect_timeout`.
    fn link(&mut self) -> Result<&mut BoardLink, LinkError> {
        if self.link.is_none() {
            let (link, attempts) = open_with_retries(self.port, self.options)?;
            self.open_attempts = attempts;
            self.link = Some(link);
        }
        Ok(self.link.as_mut().expect("opened above"))
    }

    fn ramp_ms(&self) -> u64 {
        self.initial.map_or(0, |status| u64::from(status.ramp_ms))
    }
}

/// Runs every check against `target` and returns the report; `on_result` sees each result as it is decided
/// (for live output).
pub fn run_suite(
    target: &mut RunningTarget,
    options: &HilOptions,
    on_result: &mut dyn FnMut(&CheckResult),
) -> HilReport {
    let mut session = Session {
        port: &target.port,
        options,
        link: None,
        initial: None,
        max_current_ma: None,
        max_total_current_ma: None,
        open_attempts: 0,
        clock: target.clock,
        board_clock_ratio: None,
    };
    let camera_name = target.camera.as_ref().map(|c| c.describe());
    let camera = target.camera.as_deref_mut();
    let mut results = Vec::new();
    let mut record = |name: &'static str, started: Instant, outcome: Outcome, session: &mut Session| {
        let (verdict, summary, details) = match outcome {
            Ok(result) => result,
            Err(error) => {
                if matches!(error, CheckError::Link(ref e) if e.is_disconnect()) {
                    session.link = None;
                }
                let error_details = as_json(ErrorDetails {
                    error: error.to_string(),
                    reopen_ms: None,
                });
                (Verdict::Fail, error.to_string(), error_details)
            }
        };
        let result = CheckResult {
            name,
            verdict,
            summary,
            details,
            elapsed_ms: started.elapsed().as_secs_f64() * 1e3,
        };
        on_result(&result);
        results.push(result);
    };

    let started = Instant::now();
    let outcome = handshake_and_versions(&mut session);
    record("handshake", started, outcome, &mut session);

    let started = Instant::now();
    let outcome = led_ramp(&mut session);
    record("led_ramp", started, outcome, &mut session);

    let mut camera = camera;
    let no_camera = || {
        Ok((
            Verdict::Skip,
            "no camera attached (pass --camera DEV)".into(),
            Value::Null,
        ))
    };
    let started = Instant::now();
    let outcome = match camera.as_deref_mut() {
        Some(camera) => brightness_follows_current(&mut session, camera),
        None => no_camera(),
    };
    record("camera_brightness", started, outcome, &mut session);

    let started = Instant::now();
    let outcome = match camera {
        Some(camera) => camera_confirms_each_current(&mut session, camera),
        None => no_camera(),
    };
    record("camera_current", started, outcome, &mut session);

    let started = Instant::now();
    let outcome = telemetry_rate_and_jitter(&mut session);
    record("telemetry_rate", started, outcome, &mut session);

    let started = Instant::now();
    let outcome = round_trip_latency(&mut session);
    record("latency", started, outcome, &mut session);

    let started = Instant::now();
    let outcome = over_limit_is_clamped(&mut session);
    record("over_limit_clamp", started, outcome, &mut session);

    let started = Instant::now();
    let outcome = recovery_after_reopen(&mut session);
    record("reopen_recovery", started, outcome, &mut session);

    restore(&mut session);
    HilReport::new(
        format!("{} ({})", target.description, target.port),
        camera_name,
        results,
    )
}

fn handshake_and_versions(session: &mut Session) -> Outcome {
    let started = Instant::now();
    session.link()?;
    let handshake_ms = started.elapsed().as_secs_f64() * 1e3;
    let attempts = session.open_attempts;
    let link = session.link()?;
    let info = link.info()?;
    let status = link.status()?;
    let serial: String = info.mcu_uid.iter().map(|b| format!("{b:02X}")).collect();
    let mut problems = Vec::new();
    if info.protocol_version != PROTOCOL_VERSION {
        problems.push(format!(
            "protocol v{} (host v{PROTOCOL_VERSION})",
            info.protocol_version
        ));
    }
    if usize::from(info.channel_count) != CHANNEL_COUNT {
        problems.push(format!(
            "{} LED channels (expected {CHANNEL_COUNT})",
            info.channel_count
        ));
    }
    if info.firmware_version.is_empty() {
        problems.push("empty firmware version".into());
    }
    if info.max_current_ma > session.options.hard_limit_ma {
        problems.push(format!(
            "declares a limit of {} mA, above the hard limit {} mA",
            info.max_current_ma, session.options.hard_limit_ma
        ));
    }
    let faults: Vec<String> = Side::ALL
        .iter()
        .filter(|side| status.channels[side.index()].faults.any())
        .map(|side| format!("{side}: {:?}", status.channels[side.index()].faults))
        .collect();
    session.initial = Some(status);
    session.max_current_ma = Some(info.max_current_ma);
    session.max_total_current_ma = Some(info.max_total_current_ma);
    let details = as_json(HandshakeDetails {
        handshake_ms,
        open_attempts: attempts,
        protocol_version: info.protocol_version,
        host_protocol_version: PROTOCOL_VERSION,
        firmware_version: info.firmware_version.as_str(),
        git_hash: info.git_hash.as_str(),
        board_id: info.board_id.as_str(),
        serial_number: &serial,
        channel_count: info.channel_count,
        max_current_ma: info.max_current_ma,
        host_version: env!("CARGO_PKG_VERSION"),
        latched_faults_at_start: faults,
    });
    if problems.is_empty() {
        let summary = format!(
            "protocol v{}, firmware {} ({}), board {}, serial {serial}, handshake {handshake_ms:.1} ms \
             ({attempts} attempt{})",
            info.protocol_version,
            info.firmware_version.as_str(),
            info.git_hash.as_str(),
            info.board_id.as_str(),
            if attempts == 1 { "" } else { "s" }
        );
        Ok((Verdict::Pass, summary, details))
    } else {
        Ok((Verdict::Fail, problems.join("; "), details))
    }
}

#[derive(Serialize)]
struct HandshakeDetails<'a> {
    handshake_ms: f64,
    open_attempts: u32,
    protocol_version: u16,
    host_protocol_version: u16,
    firmware_version: &'a str,
    git_hash: &'a str,
    board_id: &'a str,
    serial_number: &'a str,
    channel_count: u8,
    max_current_ma: u16,
    host_version: &'static str,
    latched_faults_at_start: Vec<String>,
}

/// The current after a change, once it has settled (or the wait ran out); in the report under these names (see
/// [`SettledDetails`]).
#[derive(Serialize)]
struct Settled {
    target_ma: u16,
    /// Time from the request to the first of [`SETTLED_RUN`] frames within tolerance; `None` if it never settled.
    settled_after_ms: Option<f64>,
    #[serde(rename = "measured_ma")]
    mean_ma: [f64; CHANNEL_COUNT],
    reported_setpoint_ma: [u16; CHANNEL_COUNT],
    #[serde(rename = "over_current_fault")]
    over_current: bool,
    /// Board time of the last frame averaged: the camera looks at the light of this moment or later.
    #[serde(skip)]
    uptime_us: u64,
}

impl Settled {
    fn worst_error(&self) -> f64 {
        self.mean_ma
            .iter()
            .map(|m| (m - f64::from(self.target_ma)).abs() / f64::from(self.target_ma.max(1)))
            .fold(0.0, f64::max)
    }

    fn into_details(self) -> SettledDetails {
        SettledDetails {
            worst_error_percent: self.worst_error() * 100.0,
            settled: self,
        }
    }
}

/// A settled current with its worst error, as the report shows it.
#[derive(Serialize)]
struct SettledDetails {
    #[serde(flatten)]
    settled: Settled,
    worst_error_percent: f64,
}

/// Sets every string to `request_ma`, waits until the telemetry says all of them carry the current the board
/// should regulate to (`target_ma`, the request clamped), then averages the next frames.
fn set_and_settle(session: &mut Session, request_ma: u16, target_ma: u16) -> Result<Settled, CheckError> {
    let options = session.options;
    let clock = session.clock;
    let deadline_after = Duration::from_millis(session.ramp_ms()) + options.settle_timeout;
    let link = session.link()?;
    link.stream_telemetry(options.telemetry_period_ms)?;
    link.set_led(Channel::All, request_ma, true)?;
    let requested_at = Instant::now();
    // Frames queued before the request describe the old setpoint.
    link.drain_telemetry().for_each(drop);
    let within = |t: &Telemetry| {
        t.channels.iter().all(|c| {
            (f64::from(c.measured_ma) - f64::from(target_ma)).abs() <= options.current_tolerance * f64::from(target_ma)
        })
    };
    let mut run = 0usize;
    let mut settled_after_ms = None;
    let mut recent: Vec<Telemetry> = Vec::new();
    let mut any = false;
    let mut deadline = Deadline::new(clock, deadline_after);
    while !deadline.passed() {
        let Some(telemetry) = link.next_telemetry(TELEMETRY_POLL)? else {
            continue;
        };
        deadline.saw(&telemetry);
        any = true;
        run = if within(&telemetry) { run + 1 } else { 0 };
        recent.push(telemetry);
        if run == SETTLED_RUN {
            settled_after_ms = Some(requested_at.elapsed().as_secs_f64() * 1e3);
            break;
        }
    }
    if !any {
        return Err(CheckError::NoTelemetry(deadline_after));
    }
    if settled_after_ms.is_some() {
        recent.clear();
        let mut averaging = Deadline::new(
            clock,
            Duration::from_millis(u64::from(options.telemetry_period_ms) * options.settled_frames as u64 * 3)
                + TELEMETRY_POLL,
        );
        while recent.len() < options.settled_frames && !averaging.passed() {
            if let Some(telemetry) = link.next_telemetry(TELEMETRY_POLL)? {
                averaging.saw(&telemetry);
                recent.push(telemetry);
            }
        }
    }
    let window = &recent[recent.len().saturating_sub(options.settled_frames)..];
    let last = window.last().ok_or(CheckError::NoTelemetry(deadline_after))?;
    let mean_ma = std::array::from_fn(|ch| {
        let values: Vec<f64> = window.iter().map(|t| f64::from(t.channels[ch].measured_ma)).collect();
        mean(&values).unwrap_or(0.0)
    });
    Ok(Settled {
        target_ma,
        settled_after_ms,
        mean_ma,
        reported_setpoint_ma: last.channels.map(|c| c.setpoint_ma),
        over_current: window.iter().any(|t| t.channels.iter().any(|c| c.faults.over_current)),
        uptime_us: last.uptime_us,
    })
}

fn led_ramp(session: &mut Session) -> Outcome {
    let tolerance = session.options.current_tolerance;
    let mut steps = Vec::new();
    let mut failures = Vec::new();
    let mut worst = 0.0f64;
    for &setpoint in &session.options.setpoints_ma.clone() {
        let settled = set_and_settle(session, setpoint, setpoint)?;
        worst = worst.max(settled.worst_error());
        if settled.worst_error() > tolerance {
            failures.push(format!(
                "{setpoint} mA: measured {:.1?} mA{}",
                settled.mean_ma,
                if settled.settled_after_ms.is_none() {
                    " (never settled)"
                } else {
                    ""
                }
            ));
        }
        if settled.reported_setpoint_ma.iter().any(|&s| s != setpoint) {
            failures.push(format!(
                "{setpoint} mA: board reports setpoints {:?}",
                settled.reported_setpoint_ma
            ));
        }
        steps.push(settled.into_details());
    }
    let details = as_json(RampDetails {
        tolerance_percent: tolerance * 100.0,
        steps,
    });
    if failures.is_empty() {
        let summary = format!(
            "{} setpoints {:?} mA, all strings within {:.2} % (limit {:.0} %)",
            session.options.setpoints_ma.len(),
            session.options.setpoints_ma,
            worst * 100.0,
            tolerance * 100.0
        );
        Ok((Verdict::Pass, summary, details))
    } else {
        Ok((Verdict::Fail, failures.join("; "), details))
    }
}

#[derive(Serialize)]
struct RampDetails {
    tolerance_percent: f64,
    steps: Vec<SettledDetails>,
}

/// Least correlation between LED current and mean image brightness accepted as "follows".
const MIN_BRIGHTNESS_CORRELATION: f64 = 0.95;

#[derive(Serialize)]
struct BrightnessStep {
    setpoint_ma: u16,
    measured_ma: f64,
    mean_luma: f64,
}

#[derive(Serialize)]
struct BrightnessDetails {
    camera: String,
    steps: Vec<BrightnessStep>,
    correlation: Option<f64>,
    strictly_increasing: bool,
    min_correlation: f64,
}

fn brightness_follows_current(session: &mut Session, camera: &mut dyn BrightnessProbe) -> Outcome {
    let mut currents = Vec::new();
    let mut brightness = Vec::new();
    let mut steps = Vec::new();
    for &setpoint in &session.options.setpoints_ma.clone() {
        let settled = set_and_settle(session, setpoint, setpoint)?;
        let level = camera.brightness_since(settled.uptime_us)?;
        let mean_current = settled.mean_ma.iter().sum::<f64>() / CHANNEL_COUNT as f64;
        currents.push(mean_current);
        brightness.push(level);
        steps.push(BrightnessStep {
            setpoint_ma: setpoint,
            measured_ma: mean_current,
            mean_luma: level,
        });
    }
    let increasing = brightness.windows(2).all(|pair| pair[1] > pair[0]);
    let correlation = pearson(&currents, &brightness);
    let details = as_json(BrightnessDetails {
        camera: camera.describe(),
        steps,
        correlation,
        strictly_increasing: increasing,
        min_correlation: MIN_BRIGHTNESS_CORRELATION,
    });
    let levels: Vec<String> = brightness.iter().map(|b| format!("{b:.1}")).collect();
    let summary = format!(
        "mean luma {} at {:?} mA, correlation {}",
        levels.join(" < "),
        session.options.setpoints_ma,
        correlation.map_or("undefined".into(), |r| format!("{r:.3}"))
    );
    let passed = increasing && correlation.is_some_and(|r| r >= MIN_BRIGHTNESS_CORRELATION);
    Ok((if passed { Verdict::Pass } else { Verdict::Fail }, summary, details))
}

/// How far the camera's reading of one string may be from what the board reports (a calibrated camera), or one
/// side's brightness per reported mA from the others' (an uncalibrated one).
const CAMERA_CURRENT_TOLERANCE: f64 = 0.10;

/// Lights one string alone at `ma` and returns the current the board reports for it once settled, and the board
/// time of the last frame averaged.
fn light_one_side(session: &mut Session, side: Side, ma: u16) -> Result<(f64, u64), CheckError> {
    let options = session.options;
    let clock = session.clock;
    let deadline_after = Duration::from_millis(session.ramp_ms()) + options.settle_timeout;
    let link = session.link()?;
    for other in Side::ALL {
        link.set_led(Channel::One(other), ma, other == side)?;
    }
    link.stream_telemetry(options.telemetry_period_ms)?;
    link.drain_telemetry().for_each(drop);
    let mut settled: Vec<f64> = Vec::new();
    let mut run = 0;
    let mut uptime_us = 0;
    let mut deadline = Deadline::new(clock, deadline_after);
    while !deadline.passed() && settled.len() < options.settled_frames {
        let Some(telemetry) = link.next_telemetry(TELEMETRY_POLL)? else {
            continue;
        };
        deadline.saw(&telemetry);
        uptime_us = telemetry.uptime_us;
        let reported = f64::from(telemetry.channels[side.index()].measured_ma);
        let others_dark = Side::ALL
            .iter()
            .filter(|&&s| s != side)
            .all(|s| telemetry.channels[s.index()].measured_ma < 1.0);
        if run >= SETTLED_RUN {
            settled.push(reported);
        } else if others_dark && (reported - f64::from(ma)).abs() <= options.current_tolerance * f64::from(ma) {
            run += 1;
        } else {
            run = 0;
        }
    }
    let reported = mean(&settled).ok_or(CheckError::NoTelemetry(deadline_after))?;
    Ok((reported, uptime_us))
}

/// Each string alone, measured from outside the board: the camera's brightness turned into milliamps by its
/// calibration (or, for an uncalibrated camera, compared across the sides) must agree with the current the board
/// reports. A board whose sense path or telemetry is wrong regulates the wrong current and says it is right;
/// here it fails.
fn camera_confirms_each_current(session: &mut Session, camera: &mut dyn BrightnessProbe) -> Outcome {
    let setpoint = NOMINAL_MA;
    let dark_after = Duration::from_millis(session.ramp_ms().max(50));
    let link = session.link()?;
    link.set_led(Channel::All, setpoint, false)?;
    // The board turned the strings off before this status: the light of `dark_after` later in its time is dark.
    let off_at_us = link.status()?.uptime_us;
    std::thread::sleep(dark_after);
    let dark = camera.brightness_since(off_at_us + dark_after.as_micros() as u64)?;
    let mut steps = Vec::new();
    let mut problems = Vec::new();
    let mut per_ma = Vec::new();
    for side in Side::ALL {
        let (reported, uptime_us) = light_one_side(session, side, setpoint)?;
        let luma = camera.brightness_since(uptime_us)?;
        let seen = camera.current_ma(side, luma)?;
        if let Some(seen) = seen {
            if (seen - reported).abs() > CAMERA_CURRENT_TOLERANCE * reported.max(1.0) {
                problems.push(format!(
                    "{side}: the board reports {reported:.1} mA, the camera sees {seen:.1} mA"
                ));
            }
        }
        per_ma.push((luma - dark) / reported.max(1.0));
        steps.push(SideLight {
            side: side.to_string(),
            reported_ma: reported,
            mean_luma: luma,
            camera_ma: seen,
        });
    }
    // A camera calibrated in mA gives every side's current (a NaN, which JSON cannot hold, is no current).
    let calibrated = steps.iter().all(|s| s.camera_ma.is_some_and(f64::is_finite));
    if !calibrated {
        // Without a calibration in mA, each side's light per reported mA must match the others'.
        let mut sorted = per_ma.clone();
        sorted.sort_by(f64::total_cmp);
        let median = (sorted[1] + sorted[2]) / 2.0;
        for (side, k) in Side::ALL.iter().zip(&per_ma) {
            if median <= 0.0 || (k - median).abs() > CAMERA_CURRENT_TOLERANCE * median {
                problems.push(format!(
                    "{side}: {k:.3} luma per reported mA, the sides' median {median:.3}"
                ));
            }
        }
    }
    let (verdict, summary) = if !problems.is_empty() {
        (Verdict::Fail, problems.join("; "))
    } else if calibrated {
        let readings: Vec<String> = steps
            .iter()
            .map(|s| format!("{} {:.1}/{:.1}", s.side, s.reported_ma, s.camera_ma.unwrap_or(0.0)))
            .collect();
        let summary = format!(
            "each string alone, reported/camera mA: {} (within {:.0} %)",
            readings.join(", "),
            CAMERA_CURRENT_TOLERANCE * 100.0
        );
        (Verdict::Pass, summary)
    } else {
        let summary = "each string alone gives the same light per reported mA as the others (uncalibrated camera)";
        (Verdict::Pass, summary.to_string())
    };
    let details = as_json(CameraCurrentDetails {
        camera: camera.describe(),
        setpoint_ma: setpoint,
        dark_luma: dark,
        calibrated_in_ma: calibrated,
        tolerance_percent: CAMERA_CURRENT_TOLERANCE * 100.0,
        sides: steps,
    });
    Ok((verdict, summary, details))
}

/// One string alone: the current the board reports, the light the camera sees, and (a calibrated camera) the
/// current that light means.
#[derive(Serialize)]
struct SideLight {
    side: String,
    reported_ma: f64,
    mean_luma: f64,
    camera_ma: Option<f64>,
}

#[derive(Serialize)]
struct CameraCurrentDetails {
    camera: String,
    setpoint_ma: u16,
    dark_luma: f64,
    calibrated_in_ma: bool,
    tolerance_percent: f64,
    sides: Vec<SideLight>,
}

fn telemetry_rate_and_jitter(session: &mut Session) -> Outcome {
    let options = session.options;
    let period_ms = f64::from(options.telemetry_period_ms);
    let link = session.link()?;
    link.stream_telemetry(options.telemetry_period_ms)?;
    // Let the stream start, then forget what is queued: arrival times must be measured, not read from a queue.
    std::thread::sleep(Duration::from_millis(u64::from(options.telemetry_period_ms) * 3));
    while link.next_telemetry(Duration::ZERO)?.is_some() {}
    let started = Instant::now();
    let mut samples = TelemetrySamples::default();
    while started.elapsed() < options.telemetry_window {
        if let Some(telemetry) = link.next_telemetry(TELEMETRY_POLL)? {
            samples.arrivals_ms.push(started.elapsed().as_secs_f64() * 1e3);
            samples.uptimes_us.push(telemetry.uptime_us);
            samples.loop_timings.push(telemetry.loop_timing);
        }
    }
    let window_ms = started.elapsed().as_secs_f64() * 1e3;
    if samples.uptimes_us.len() < 3 {
        return Err(CheckError::NoTelemetry(options.telemetry_window));
    }
    let timing = TelemetryTiming::of(&samples, period_ms, window_ms);
    session.board_clock_ratio = timing.board_clock_ratio;
    let problems = telemetry_problems(&timing, session.clock, options);
    let summary = telemetry_summary(&timing, session.clock);
    let details = TelemetryDetails {
        timing,
        judged_on: match session.clock {
            BoardClock::WallClock => "wall clock",
            BoardClock::Emulated => "board clock (emulated)",
        },
        rate_tolerance_percent: options.rate_tolerance * 100.0,
        max_jitter_ms: options.max_jitter_fraction * period_ms,
    };
    let details = as_json(details);
    if problems.is_empty() {
        Ok((Verdict::Pass, summary, details))
    } else {
        Ok((Verdict::Fail, format!("{}; {summary}", problems.join("; ")), details))
    }
}

/// The telemetry check's details: the timing and what it was judged against.
#[derive(Serialize)]
struct TelemetryDetails {
    #[serde(flatten)]
    timing: TelemetryTiming,
    judged_on: &'static str,
    rate_tolerance_percent: f64,
    max_jitter_ms: f64,
}

/// Where the stream misses the requested rate or jitter.
fn telemetry_problems(timing: &TelemetryTiming, clock: BoardClock, options: &HilOptions) -> Vec<String> {
    let rate_ok = |rate: f64| (rate - timing.requested_hz).abs() <= options.rate_tolerance * timing.requested_hz;
    let mut problems = Vec::new();
    if !rate_ok(timing.board_rate_hz) {
        problems.push(format!("board sends at {:.1} Hz", timing.board_rate_hz));
    }
    // An emulator's clock runs as fast as the host lets it: its rate is judged on its own clock (above) and the
    // slowdown reported; a real board must also deliver in wall time.
    if clock == BoardClock::WallClock && !rate_ok(timing.host_rate_hz) {
        let slow_clock = match timing.board_clock_ratio {
            Some(ratio) if (ratio - 1.0).abs() > options.rate_tolerance => {
                format!(" (the board's clock ran at {ratio:.2}x wall time)")
            }
            _ => String::new(),
        };
        problems.push(format!("host receives {:.1} Hz{slow_clock}", timing.host_rate_hz));
    }
    if timing.board_interval_p99_deviation_ms > options.max_jitter_fraction * timing.period_ms {
        problems.push(format!(
            "board-side p99 interval deviation {:.2} ms",
            timing.board_interval_p99_deviation_ms
        ));
    }
    problems
}

fn telemetry_summary(timing: &TelemetryTiming, clock: BoardClock) -> String {
    let clock = match (clock, timing.board_clock_ratio) {
        (BoardClock::Emulated, Some(ratio)) => {
            format!(" (judged on the board's clock, which ran at {ratio:.2}x wall time)")
        }
        _ => String::new(),
    };
    let loop_text = match &timing.control_loop {
        Some(ControlLoopTiming {
            period_mean_us: mean,
            period_min_us: Some(min),
            period_max_us: Some(max),
            ..
        }) => format!("; control loop {mean:.1} us ({min}-{max} us)"),
        _ => String::new(),
    };
    format!(
        "{:.0} Hz requested: board {:.1} Hz, host {:.1} Hz{clock}; jitter board std {:.3} ms p99 {:.3} ms, host std \
         {:.2} ms p99 {:.2} ms{loop_text}",
        timing.requested_hz,
        timing.board_rate_hz,
        timing.host_rate_hz,
        timing.board_interval_std_ms,
        timing.board_interval_p99_deviation_ms,
        timing.host_interval_std_ms,
        timing.host_interval_p99_deviation_ms,
    )
}

#[derive(Serialize)]
struct LatencyDetails {
    pings: usize,
    answered: usize,
    failed: usize,
    p50_ms: Option<f64>,
    p90_ms: Option<f64>,
    p99_ms: Option<f64>,
    max_ms: Option<f64>,
    max_p99_ms: f64,
    link_retries: u64,
    link_timeouts: u64,
    board_clock_ratio: Option<f64>,
}

fn round_trip_latency(session: &mut Session) -> Outcome {
    let options = session.options;
    let link = session.link()?;
    // Without telemetry in the way, the round trip is the command path alone.
    link.stream_telemetry(0)?;
    std::thread::sleep(Duration::from_millis(20));
    link.drain_telemetry().for_each(drop);
    let mut latencies_ms = Vec::with_capacity(options.pings);
    let mut errors = 0usize;
    for nonce in 0..options.pings {
        match link.ping(0xA5A5_0000 ^ nonce as u32) {
            Ok(rtt) => latencies_ms.push(rtt.as_secs_f64() * 1e3),
            Err(error) if error.is_disconnect() => return Err(error.into()),
            Err(_) => errors += 1,
        }
    }
    let p50 = quantile(&latencies_ms, 0.5);
    let p90 = quantile(&latencies_ms, 0.9);
    let p99 = quantile(&latencies_ms, 0.99);
    let max = latencies_ms
        .iter()
        .copied()
        .fold(None, |m: Option<f64>, v| Some(m.map_or(v, |m| m.max(v))));
    let stats = link.stats();
    let details = as_json(LatencyDetails {
        pings: options.pings,
        answered: latencies_ms.len(),
        failed: errors,
        p50_ms: p50,
        p90_ms: p90,
        p99_ms: p99,
        max_ms: max,
        max_p99_ms: options.max_p99_latency_ms,
        link_retries: stats.retries,
        link_timeouts: stats.timeouts,
        board_clock_ratio: session.board_clock_ratio,
    });
    let fmt = |v: Option<f64>| v.map_or("-".into(), |v| format!("{v:.3}"));
    // Under emulation the round trip is judged in the board's time: wall time scaled by how fast its clock ran
    // (measured by the telemetry check), so a starved emulator is not mistaken for a slow firmware.
    let scale = match (session.clock, session.board_clock_ratio) {
        (BoardClock::Emulated, Some(ratio)) if ratio > 0.0 => ratio.min(1.0),
        _ => 1.0,
    };
    let judged_p99 = p99.map(|p| p * scale);
    let clock = if scale < 1.0 {
        format!(
            " (p99 {} ms in board time, clock at {scale:.2}x wall time)",
            fmt(judged_p99)
        )
    } else {
        String::new()
    };
    let summary = format!(
        "{} pings: p50 {} ms, p90 {} ms, p99 {} ms, max {} ms, {errors} unanswered{clock}",
        options.pings,
        fmt(p50),
        fmt(p90),
        fmt(p99),
        fmt(max)
    );
    let passed = errors == 0 && judged_p99.is_some_and(|p| p <= options.max_p99_latency_ms);
    Ok((if passed { Verdict::Pass } else { Verdict::Fail }, summary, details))
}

fn over_limit_is_clamped(session: &mut Session) -> Outcome {
    let options = session.options;
    let per_string_limit = options
        .hard_limit_ma
        .min(session.max_current_ma.unwrap_or(options.hard_limit_ma));
    // Four strings at their limit would exceed the board's USB budget, which scales them down together.
    let budget_share = session
        .max_total_current_ma
        .map_or(u16::MAX, |total| total / CHANNEL_COUNT as u16);
    let limit = per_string_limit;
    let settles_at = per_string_limit.min(budget_share);
    let request = options.over_limit_request_ma;
    let link = session.link()?;
    match link.set_led(Channel::All, request, true) {
        Ok(()) => {}
        Err(LinkError::Device(DeviceError::BadArgument(argument))) => {
            let summary = format!("the board rejected {request} mA ({argument}) instead of clamping it");
            let details = as_json(RejectedDetails {
                request_ma: request,
                rejected: true,
            });
            return Ok((Verdict::Fail, summary, details));
        }
        Err(error) => return Err(error.into()),
    }
    let status = link.status()?;
    let reported: Vec<u16> = status.channels.iter().map(|c| c.setpoint_ma).collect();
    let settled = set_and_settle(session, request, settles_at)?;
    let peak = settled.mean_ma.iter().copied().fold(0.0, f64::max);
    let mut problems = Vec::new();
    if reported.iter().any(|&s| s > limit) {
        problems.push(format!("reported setpoints {reported:?} mA exceed {limit} mA"));
    }
    if peak > f64::from(limit) * (1.0 + options.current_tolerance) {
        problems.push(format!("strings carry up to {peak:.1} mA"));
    }
    if settled.over_current {
        problems.push("the over-current fault tripped".into());
    }
    let details = as_json(ClampDetails {
        request_ma: request,
        limit_ma: limit,
        budget_share_ma: budget_share,
        reported_setpoint_ma: &reported,
        settled: settled.into_details(),
    });
    // Back to nominal so the remaining checks do not run the strings at their limit.
    session.link()?.set_led(Channel::All, NOMINAL_MA, true)?;
    if problems.is_empty() {
        let summary = format!(
            "{request} mA requested: setpoints {reported:?} mA, strings settle at {peak:.1} mA (limit {limit} mA, \
             {settles_at} mA each within the board's total budget)"
        );
        Ok((Verdict::Pass, summary, details))
    } else {
        Ok((Verdict::Fail, problems.join("; "), details))
    }
}

/// The board refused an over-limit request instead of clamping it.
#[derive(Serialize)]
struct RejectedDetails {
    request_ma: u16,
    rejected: bool,
}

#[derive(Serialize)]
struct ClampDetails<'a> {
    request_ma: u16,
    limit_ma: u16,
    budget_share_ma: u16,
    reported_setpoint_ma: &'a [u16],
    settled: SettledDetails,
}

fn recovery_after_reopen(session: &mut Session) -> Outcome {
    let options = session.options;
    // Close with the stream running: the hardest case, bytes in flight when the port goes.
    session.link()?.stream_telemetry(options.telemetry_period_ms)?;
    std::thread::sleep(Duration::from_millis(50));
    session.link = None;
    std::thread::sleep(Duration::from_millis(100));
    let started = Instant::now();
    let reopen_options = HilOptions {
        connect_timeout: options.recovery_timeout,
        ..options.clone()
    };
    let (link, attempts) = match open_with_retries(session.port, &reopen_options) {
        Ok(opened) => opened,
        Err(error) => {
            let summary = format!("could not reopen within {:?}: {error}", options.recovery_timeout);
            let details = as_json(ErrorDetails {
                error: error.to_string(),
                reopen_ms: Some(started.elapsed().as_secs_f64() * 1e3),
            });
            return Ok((Verdict::Fail, summary, details));
        }
    };
    let reopen_ms = started.elapsed().as_secs_f64() * 1e3;
    let link = session.link.insert(link);
    let ping_ms = link.ping(0x5EC0_4E55)?.as_secs_f64() * 1e3;
    link.status()?;
    link.stream_telemetry(options.telemetry_period_ms)?;
    let telemetry = link.next_telemetry(Duration::from_secs(1))?;
    link.stream_telemetry(0)?;
    let details = as_json(ReopenDetails {
        attempts,
        reopen_ms,
        ping_after_reopen_ms: ping_ms,
        telemetry_after_reopen: telemetry.is_some(),
        wire_errors_after_reopen: link.counters(),
    });
    if telemetry.is_none() {
        return Ok((
            Verdict::Fail,
            "reopened and handshaken, but no telemetry after reopening".into(),
            details,
        ));
    }
    let summary = format!(
        "reopened after {reopen_ms:.0} ms ({attempts} attempt{}), ping {ping_ms:.2} ms, telemetry flowing",
        if attempts == 1 { "" } else { "s" }
    );
    Ok((Verdict::Pass, summary, details))
}

#[derive(Serialize)]
struct ReopenDetails {
    attempts: u32,
    reopen_ms: f64,
    ping_after_reopen_ms: f64,
    telemetry_after_reopen: bool,
    wire_errors_after_reopen: LinkCounters,
}

/// Puts the board back as the suite found it: stream off, each string's setpoint and enable.
fn restore(session: &mut Session) {
    let initial = session.initial;
    let Ok(link) = session.link() else { return };
    let _ = link.stream_telemetry(0);
    if let Some(status) = initial {
        for side in Side::ALL {
            let channel = status.channels[side.index()];
            if let Err(error) = link.set_led(Channel::One(side), channel.setpoint_ma, channel.enabled) {
                tracing::warn!(target: "nusense_hil", %error, %side, "cannot restore the LED channel");
            }
        }
    }
}
