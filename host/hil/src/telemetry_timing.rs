//! The telemetry stream's timing over a window: its rate and jitter on the board's clock (the uptime each frame
//! carries) and on the host's (when each frame arrived), and the control loop's period as the board measured it.
//! Hardware-free, so that the statistics are tested on made-up streams.

use nusense_estimator::stats::{quantile, std_dev};
use nusense_protocol::LoopTiming;
use serde::Serialize;

/// What the host saw of the stream: one entry per telemetry frame, in arrival order.
#[derive(Debug, Default)]
pub(crate) struct TelemetrySamples {
    /// Host milliseconds since the window began.
    pub arrivals_ms: Vec<f64>,
    /// The board's uptime in each frame.
    pub uptimes_us: Vec<u64>,
    pub loop_timings: Vec<LoopTiming>,
}

/// The stream's timing, in the hil report's details under these names.
#[derive(Debug, Serialize, PartialEq)]
pub(crate) struct TelemetryTiming {
    pub period_ms: f64,
    pub requested_hz: f64,
    pub frames: usize,
    pub window_ms: f64,
    pub board_rate_hz: f64,
    pub host_rate_hz: f64,
    pub board_interval_std_ms: f64,
    pub board_interval_p99_deviation_ms: f64,
    pub host_interval_std_ms: f64,
    pub host_interval_p99_deviation_ms: f64,
    pub host_interval_max_ms: f64,
    /// Board-clock intervals over 1.5 periods: a frame the board did not send.
    pub missed_intervals: usize,
    /// Board time over host time while the frames came: 1 for a board on a crystal; an emulator starved of CPU
    /// runs its clock slow, and then sends at the requested rate of its own clock only. None when every frame
    /// arrived at once.
    pub board_clock_ratio: Option<f64>,
    /// None when the board reported no control steps.
    pub control_loop: Option<ControlLoopTiming>,
}

/// The control loop's own period over the window (board clock).
#[derive(Debug, Serialize, PartialEq)]
pub(crate) struct ControlLoopTiming {
    pub steps: u64,
    pub period_mean_us: f64,
    pub period_min_us: Option<u32>,
    pub period_max_us: Option<u32>,
}

impl TelemetryTiming {
    /// The timing of `samples` (at least two frames) streamed at `period_ms`, over a window of `window_ms`.
    pub fn of(samples: &TelemetrySamples, period_ms: f64, window_ms: f64) -> Self {
        let TelemetrySamples {
            arrivals_ms,
            uptimes_us,
            loop_timings,
        } = samples;
        assert!(
            uptimes_us.len() >= 2 && arrivals_ms.len() == uptimes_us.len(),
            "a rate needs two frames"
        );
        let board_span_ms = (uptimes_us[uptimes_us.len() - 1].saturating_sub(uptimes_us[0])) as f64 / 1e3;
        let board_intervals: Vec<f64> = uptimes_us
            .windows(2)
            .map(|w| w[1].saturating_sub(w[0]) as f64 / 1e3)
            .collect();
        let host_intervals: Vec<f64> = arrivals_ms.windows(2).map(|w| w[1] - w[0]).collect();
        let p99_deviation = |intervals: &[f64]| {
            let deviations: Vec<f64> = intervals.iter().map(|i| (i - period_ms).abs()).collect();
            quantile(&deviations, 0.99).unwrap_or(0.0)
        };
        let host_span_ms = arrivals_ms[arrivals_ms.len() - 1] - arrivals_ms[0];
        Self {
            period_ms,
            requested_hz: 1e3 / period_ms,
            frames: uptimes_us.len(),
            window_ms,
            board_rate_hz: (uptimes_us.len() - 1) as f64 / (board_span_ms / 1e3).max(f64::EPSILON),
            host_rate_hz: arrivals_ms.len() as f64 / (window_ms / 1e3),
            board_interval_std_ms: std_dev(&board_intervals).unwrap_or(0.0),
            board_interval_p99_deviation_ms: p99_deviation(&board_intervals),
            host_interval_std_ms: std_dev(&host_intervals).unwrap_or(0.0),
            host_interval_p99_deviation_ms: p99_deviation(&host_intervals),
            host_interval_max_ms: host_intervals.iter().copied().fold(0.0, f64::max),
            missed_intervals: board_intervals.iter().filter(|&&i| i > 1.5 * period_ms).count(),
            board_clock_ratio: (host_span_ms > 0.0).then(|| board_span_ms / host_span_ms),
            control_loop: ControlLoopTiming::of(loop_timings),
        }
    }
}

impl ControlLoopTiming {
    /// Each telemetry frame's summary weighted by the steps it covers.
    fn of(loop_timings: &[LoopTiming]) -> Option<Self> {
        let steps: u64 = loop_timings.iter().map(|t| u64::from(t.steps)).sum();
        if steps == 0 {
            return None;
        }
        let weighted_sum: f64 = loop_timings
            .iter()
            .map(|t| f64::from(t.period_mean_us) * f64::from(t.steps))
            .sum();
        Some(Self {
            steps,
            period_mean_us: weighted_sum / steps as f64,
            period_min_us: loop_timings
                .iter()
                .filter(|t| t.steps > 0)
                .map(|t| t.period_min_us)
                .min(),
            period_max_us: loop_timings.iter().map(|t| t.period_max_us).max(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A stream at 10 ms on the board's clock, arriving on the host at `host_step_ms`.
    fn stream(frames: usize, host_step_ms: f64) -> TelemetrySamples {
        TelemetrySamples {
            arrivals_ms: (0..frames).map(|k| k as f64 * host_step_ms).collect(),
            uptimes_us: (0..frames).map(|k| 5_000_000 + k as u64 * 10_000).collect(),
            loop_timings: vec![LoopTiming::default(); frames],
        }
    }

    #[test]
    fn a_steady_stream_has_the_requested_rate_and_no_jitter() {
        let timing = TelemetryTiming::of(&stream(101, 10.0), 10.0, 1010.0);
        assert_eq!(timing.requested_hz, 100.0);
        assert!((timing.board_rate_hz - 100.0).abs() < 1e-9, "{timing:?}");
        assert!((timing.host_rate_hz - 100.0).abs() < 1e-9, "{timing:?}");
        assert_eq!(timing.board_interval_std_ms, 0.0);
        assert_eq!(timing.board_interval_p99_deviation_ms, 0.0);
        assert_eq!(timing.missed_intervals, 0);
        assert_eq!(timing.board_clock_ratio, Some(1.0));
        assert_eq!(timing.control_loop, None);
    }

    #[test]
    fn a_dropped_frame_is_a_missed_interval_and_a_slow_clock_shows_in_the_ratio() {
        let mut samples = stream(51, 20.0);
        samples.uptimes_us.remove(25);
        samples.arrivals_ms.remove(25);
        let timing = TelemetryTiming::of(&samples, 10.0, 1000.0);
        assert_eq!(timing.missed_intervals, 1);
        assert_eq!(timing.frames, 50);
        // 50 frames over 500 ms of board time, 1000 ms of host time: the board's clock ran at half speed.
        assert_eq!(timing.board_clock_ratio, Some(0.5));
        assert!((timing.board_rate_hz - 49.0 / 0.5).abs() < 1e-9, "{timing:?}");
        // 48 intervals on time and one of 20 ms: the 99th percentile of the deviations lies 0.52 of the way from
        // the 48th (0 ms) to the 49th (10 ms).
        assert!(
            (timing.board_interval_p99_deviation_ms - 5.2).abs() < 1e-9,
            "{timing:?}"
        );
    }

    #[test]
    fn the_control_loop_period_is_weighted_by_steps_and_idle_frames_do_not_set_the_minimum() {
        let timings = [
            LoopTiming {
                steps: 0,
                period_mean_us: 0.0,
                period_min_us: 0,
                period_max_us: 0,
            },
            LoopTiming {
                steps: 30,
                period_mean_us: 500.0,
                period_min_us: 490,
                period_max_us: 520,
            },
            LoopTiming {
                steps: 10,
                period_mean_us: 540.0,
                period_min_us: 495,
                period_max_us: 600,
            },
        ];
        let control = ControlLoopTiming::of(&timings).expect("steps were taken");
        assert_eq!(control.steps, 40);
        assert!((control.period_mean_us - 510.0).abs() < 1e-9);
        assert_eq!(control.period_min_us, Some(490));
        assert_eq!(control.period_max_us, Some(600));
    }
}
