//! Hardware-in-the-loop checks: a board (real, emulated under QEMU, or virtual) is put through the things the
//! host relies on — handshake and versions, the LED current regulation, camera brightness following the LED
//! current, each string's current as the camera sees it (not as the board reports it), telemetry rate and jitter
//! (on the board's own clock under emulation), command round-trip latency, clamping of over-limit requests, and
//! recovery after the port is closed and reopened. Each check reports PASS, FAIL or SKIP with its numbers.
//!
//! [`target`] starts what is under test (nothing for a real port, a [`nusense_board::virtual_board::VirtualBoard`],
//! or [`crate::emulator::QemuBoard`]); [`run_suite`] runs the checks against its serial path.

pub mod camera;
mod checks;
pub mod emulator;
pub mod light;
pub mod target;
mod telemetry_timing;

use std::time::Duration;

use serde::Serialize;

pub use camera::{BrightnessProbe, CameraProbeError, SimulatedCameraProbe, V4l2CameraProbe};
pub use checks::run_suite;
pub use target::{BoardClock, HilTarget, RunningTarget, TargetError};

use nusense_board::LinkOptions;

/// Checks whose verdict rests on wall-clock timing (rate, jitter, latency). On a loaded machine, or with an
/// emulator starved of CPU, they can fail without anything being wrong with the firmware; automated tests
/// therefore assert their measurements, and leave the verdict to people and to `nusense hil` runs on real boards.
pub const TIMING_CHECKS: [&str; 2] = ["telemetry_rate", "latency"];

/// What the checks ask of the board and what they accept.
#[derive(Clone, Debug)]
pub struct HilOptions {
    pub link: LinkOptions,
    /// How long the first connection keeps retrying (a board still booting, a port QEMU has not polled yet).
    pub connect_timeout: Duration,
    /// LED currents the ramp and brightness checks step through, in mA.
    pub setpoints_ma: Vec<u16>,
    /// Allowed deviation of the settled measured current from its setpoint (0.05 = +/-5 %).
    pub current_tolerance: f64,
    /// Longest wait for the current to settle after a change, on top of the board's soft-start time.
    pub settle_timeout: Duration,
    /// Telemetry frames averaged once the current has settled.
    pub settled_frames: usize,
    /// Telemetry period requested for the rate and jitter check, in ms.
    pub telemetry_period_ms: u16,
    /// How long telemetry is collected for the rate and jitter check.
    pub telemetry_window: Duration,
    /// Allowed deviation of the measured telemetry rate from the requested one (0.1 = +/-10 %).
    pub rate_tolerance: f64,
    /// Allowed p99 deviation of the board-side telemetry interval from the period, as a fraction of the period.
    pub max_jitter_fraction: f64,
    /// Pings sent for the latency percentiles.
    pub pings: usize,
    /// p99 round-trip latency above which the latency check fails, in ms.
    pub max_p99_latency_ms: f64,
    /// The over-limit request of the clamp check, in mA.
    pub over_limit_request_ma: u16,
    /// The hard limit per string the board must clamp to, in mA (issue 3: 120 mA).
    pub hard_limit_ma: u16,
    /// How long the recovery check keeps trying to reopen the port.
    pub recovery_timeout: Duration,
}

impl Default for HilOptions {
    fn default() -> Self {
        Self {
            link: LinkOptions::default(),
            connect_timeout: Duration::from_secs(5),
            setpoints_ma: vec![25, 50, 75, 100],
            current_tolerance: 0.05,
            settle_timeout: Duration::from_secs(3),
            settled_frames: 10,
            telemetry_period_ms: 10,
            telemetry_window: Duration::from_secs(2),
            rate_tolerance: 0.10,
            max_jitter_fraction: 0.5,
            pings: 200,
            max_p99_latency_ms: 50.0,
            over_limit_request_ma: 500,
            hard_limit_ma: nusense_firmware_core::limits::MAX_CURRENT_MA,
            recovery_timeout: Duration::from_secs(5),
        }
    }
}

impl HilOptions {
    /// Fewer samples, for CI and quick looks: the same checks and limits, shorter windows.
    pub fn quick() -> Self {
        Self {
            telemetry_window: Duration::from_secs(1),
            pings: 50,
            settled_frames: 5,
            ..Self::default()
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Verdict {
    Pass,
    Fail,
    /// Not applicable to this target (no camera attached).
    Skip,
}

impl Verdict {
    pub fn label(self) -> &'static str {
        match self {
            Verdict::Pass => "PASS",
            Verdict::Fail => "FAIL",
            Verdict::Skip => "SKIP",
        }
    }
}

/// The outcome of one check: a verdict, one line for people, and the measured numbers for machines.
#[derive(Clone, Debug, Serialize)]
pub struct CheckResult {
    pub name: &'static str,
    pub verdict: Verdict,
    pub summary: String,
    pub details: serde_json::Value,
    pub elapsed_ms: f64,
}

/// Every check's result for one target.
#[derive(Clone, Debug, Serialize)]
pub struct HilReport {
    /// What was tested (port path and kind).
    pub target: String,
    pub camera: Option<String>,
    pub checks: Vec<CheckResult>,
    pub passed: usize,
    pub failed: usize,
    pub skipped: usize,
    /// [`Self::summary_line`], for machine readers too.
    pub summary: String,
}

impl HilReport {
    pub fn new(target: String, camera: Option<String>, checks: Vec<CheckResult>) -> Self {
        let count = |verdict| checks.iter().filter(|c| c.verdict == verdict).count();
        let (passed, failed, skipped) = (count(Verdict::Pass), count(Verdict::Fail), count(Verdict::Skip));
        let summary = format!("hil: {passed} passed, {failed} failed");
        Self {
            target,
            camera,
            checks,
            passed,
            failed,
            skipped,
            summary,
        }
    }

    /// `hil: N passed, M failed` — the line scripts look for.
    pub fn summary_line(&self) -> String {
        self.summary.clone()
    }

    pub fn all_passed(&self) -> bool {
        self.failed == 0 && self.passed > 0
    }

    pub fn check(&self, name: &str) -> Option<&CheckResult> {
        self.checks.iter().find(|c| c.name == name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_virtual_board_passes_every_check() {
        let mut target = HilTarget::Virtual.start().unwrap();
        let report = run_suite(&mut target, &HilOptions::quick(), &mut |_| {});
        for check in &report.checks {
            assert_eq!(check.verdict, Verdict::Pass, "{}: {}", check.name, check.summary);
        }
        assert_eq!(report.checks.len(), 8);
        assert_eq!(report.summary_line(), "hil: 8 passed, 0 failed");
        let latency = report.check("latency").unwrap();
        assert!(latency.details["p50_ms"].as_f64().unwrap() > 0.0);
        let camera = report.check("camera_current").unwrap();
        assert_eq!(camera.details["calibrated_in_ma"], true);
        for side in camera.details["sides"].as_array().unwrap() {
            let (reported, seen) = (
                side["reported_ma"].as_f64().unwrap(),
                side["camera_ma"].as_f64().unwrap(),
            );
            assert!((reported - 100.0).abs() < 5.0 && (seen - 100.0).abs() < 5.0, "{side}");
        }
    }

    /// A board whose right string's sense path reads 20 % low regulates that string to 125 mA while reporting
    /// 100 mA: every check that trusts the board passes, the camera does not.
    #[test]
    fn a_board_that_misreports_its_current_fails_the_camera_check() {
        let mut options = nusense_board::virtual_board::VirtualBoardOptions::default();
        options.plant.sense_gain[nusense_protocol::Side::Right.index()] = 0.8;
        let mut target = HilTarget::VirtualWith(Box::new(options)).start().unwrap();
        let report = run_suite(&mut target, &HilOptions::quick(), &mut |_| {});
        let camera = report.check("camera_current").unwrap();
        assert_eq!(camera.verdict, Verdict::Fail, "{}", camera.summary);
        assert!(
            camera.summary.starts_with("right: the board reports"),
            "{}",
            camera.summary
        );
        assert_eq!(
            report.check("led_ramp").unwrap().verdict,
            Verdict::Pass,
            "the board's own word is fine"
        );
        let right = &camera.details["sides"][1];
        assert!((right["camera_ma"].as_f64().unwrap() - 125.0).abs() < 6.0, "{right}");
    }

    #[test]
    fn a_missing_port_fails_every_board_check_and_skips_the_camera() {
        let mut target = HilTarget::Port {
            path: "/dev/nusense-no-such-port".into(),
            camera: None,
        }
        .start()
        .unwrap();
        let report = run_suite(&mut target, &HilOptions::quick(), &mut |_| {});
        assert_eq!(report.failed, 6, "{report:#?}");
        assert_eq!(report.skipped, 2);
        assert!(!report.all_passed());
        assert_eq!(report.summary_line(), "hil: 0 passed, 6 failed");
        assert!(report
            .check("handshake")
            .unwrap()
            .summary
            .contains("/dev/nusense-no-such-port"));
    }
}
