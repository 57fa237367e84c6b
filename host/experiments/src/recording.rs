//! Readings from a recording, read through the recorded JSON and tolerant of the fields it gains over time:
//! the reports need only time, gamma, the force, the contact and the lattice counts.

use std::path::Path;

use nusense_daemon::record::{read_recording, READING_TOPIC};
use serde::Deserialize;

use crate::report::ReportError;

/// One estimated frame of a recording.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SessionReading {
    pub frame_id: u64,
    /// Capture time, seconds since the Unix epoch (the camera's clock).
    pub time_s: f64,
    pub contact: bool,
    pub gamma: f64,
    /// The force model's value whether or not there is contact (a * gamma + b), N.
    pub force_model_n: f64,
    pub contact_mm: Option<[f64; 2]>,
    pub points_detected: usize,
    pub points_expected: usize,
    pub points_valid: usize,
}

#[derive(Deserialize)]
struct Recorded {
    frame_id: u64,
    capture_time_us: u64,
    #[serde(default)]
    estimate: Option<Estimate>,
}

#[derive(Deserialize)]
struct Estimate {
    #[serde(default)]
    contact: bool,
    gamma: f64,
    #[serde(default)]
    force_model_n: Option<f64>,
    #[serde(default)]
    force_n: Option<f64>,
    #[serde(default)]
    contact_mm: Option<[f64; 2]>,
    #[serde(default)]
    points_detected: usize,
    #[serde(default)]
    points_expected: usize,
    #[serde(default)]
    points_valid: usize,
}

/// The paper's line, for recordings whose readings carry gamma only.
const PAPER_SLOPE: f64 = 3.09;
const PAPER_INTERCEPT: f64 = -1.14;

/// The readings with an estimate, in capture order, and how many frames had none (no lattice, a failed frame).
pub fn load_readings(path: &Path) -> Result<(Vec<SessionReading>, usize), ReportError> {
    let recording = read_recording(path)?;
    let mut readings = Vec::new();
    let mut without_estimate = 0;
    for message in recording.on_topic(READING_TOPIC) {
        let recorded: Recorded = serde_json::from_slice(&message.data).map_err(|source| ReportError::Reading {
            path: path.display().to_string(),
            sequence: message.sequence,
            source,
        })?;
        let Some(estimate) = recorded.estimate.filter(|e| e.gamma.is_finite()) else {
            without_estimate += 1;
            continue;
        };
        let force_model_n = estimate
            .force_model_n
            .or(estimate.force_n.filter(|_| estimate.contact))
            .unwrap_or(PAPER_SLOPE * estimate.gamma + PAPER_INTERCEPT);
        readings.push(SessionReading {
            frame_id: recorded.frame_id,
            time_s: recorded.capture_time_us as f64 * 1e-6,
            contact: estimate.contact,
            gamma: estimate.gamma,
            force_model_n,
            contact_mm: estimate.contact_mm.filter(|p| p.iter().all(|v| v.is_finite())),
            points_detected: estimate.points_detected,
            points_expected: estimate.points_expected,
            points_valid: estimate.points_valid,
        });
    }
    readings.sort_by(|a, b| a.time_s.total_cmp(&b.time_s));
    if readings.is_empty() {
        return Err(ReportError::NoReadings {
            path: path.display().to_string(),
            without_estimate,
        });
    }
    Ok((readings, without_estimate))
}
