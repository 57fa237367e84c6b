//! Latency over a sliding window of recent frames.

use std::collections::VecDeque;

use serde::Serialize;

pub struct LatencyWindow {
    samples_ms: VecDeque<f64>,
    capacity: usize,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct LatencySummary {
    pub samples: usize,
    pub p50: f64,
    pub p99: f64,
    pub max: f64,
}

impl LatencyWindow {
    pub fn new(capacity: usize) -> Self {
        Self {
            samples_ms: VecDeque::with_capacity(capacity),
            capacity: capacity.max(1),
        }
    }

    pub fn push(&mut self, latency_ms: f64) {
        if !latency_ms.is_finite() {
            return;
        }
        if self.samples_ms.len() == self.capacity {
            self.samples_ms.pop_front();
        }
        self.samples_ms.push_back(latency_ms);
    }

    pub fn summary(&self) -> LatencySummary {
        summarise(self.samples_ms.iter().copied().collect())
    }
}

/// Nearest-rank percentiles of a sample set (zeros when empty).
pub fn summarise(mut samples: Vec<f64>) -> LatencySummary {
    samples.retain(|s| s.is_finite());
    if samples.is_empty() {
        return LatencySummary::default();
    }
    samples.sort_by(f64::total_cmp);
    let rank = |p: f64| samples[((p * samples.len() as f64).ceil() as usize).clamp(1, samples.len()) - 1];
    LatencySummary {
        samples: samples.len(),
        p50: rank(0.50),
        p99: rank(0.99),
        max: samples[samples.len() - 1],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_use_nearest_rank() {
        let summary = summarise((1..=100).map(f64::from).collect());
        assert_eq!(summary.samples, 100);
        assert_eq!(summary.p50, 50.0);
        assert_eq!(summary.p99, 99.0);
        assert_eq!(summary.max, 100.0);
        assert_eq!(summarise(vec![]), LatencySummary::default());
    }

    #[test]
    fn window_forgets_old_samples_and_ignores_nan() {
        let mut window = LatencyWindow::new(3);
        for v in [100.0, f64::NAN, 1.0, 2.0, 3.0] {
            window.push(v);
        }
        let summary = window.summary();
        assert_eq!(summary.samples, 3);
        assert_eq!(summary.max, 3.0);
    }
}
