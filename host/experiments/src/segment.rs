//! Touches found in a run of readings: the estimator's own contact decision (made against the sensor's
//! measured noise), with single-frame dropouts bridged and single-frame blips ignored.

use serde::Serialize;

use crate::recording::SessionReading;

/// A gap of up to this many frames without contact inside a touch does not end it.
const MAX_GAP_FRAMES: usize = 1;
/// A touch lasts at least this many frames with contact.
const MIN_FRAMES: usize = 2;

/// One touch: indices into the readings.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Touch {
    pub first: usize,
    pub last: usize,
    /// The reading with the largest force model value.
    pub peak: usize,
}

impl Touch {
    /// The frames of the touch within `fraction` of its peak force: the hold, for positions.
    pub fn near_peak(&self, readings: &[SessionReading], fraction: f64) -> Vec<usize> {
        let peak = readings[self.peak].force_model_n;
        let base = (self.first..=self.last)
            .map(|i| readings[i].force_model_n)
            .fold(f64::INFINITY, f64::min);
        let threshold = base + fraction * (peak - base);
        (self.first..=self.last)
            .filter(|&i| readings[i].force_model_n >= threshold)
            .collect()
    }

    /// The mean contact position over `frames` that have one.
    pub fn position_mm(readings: &[SessionReading], frames: &[usize]) -> Option<[f64; 2]> {
        let positions: Vec<[f64; 2]> = frames.iter().filter_map(|&i| readings[i].contact_mm).collect();
        (!positions.is_empty()).then(|| {
            let n = positions.len() as f64;
            [
                positions.iter().map(|p| p[0]).sum::<f64>() / n,
                positions.iter().map(|p| p[1]).sum::<f64>() / n,
            ]
        })
    }
}

pub fn touches(readings: &[SessionReading]) -> Vec<Touch> {
    let mut runs: Vec<(usize, usize)> = Vec::new();
    for (i, reading) in readings.iter().enumerate() {
        if !reading.contact {
            continue;
        }
        match runs.last_mut() {
            Some(run) if i - run.1 <= MAX_GAP_FRAMES + 1 => run.1 = i,
            _ => runs.push((i, i)),
        }
    }
    runs.into_iter()
        .filter(|&(first, last)| (first..=last).filter(|&i| readings[i].contact).count() >= MIN_FRAMES)
        .map(|(first, last)| {
            let peak = (first..=last)
                .max_by(|&a, &b| readings[a].force_model_n.total_cmp(&readings[b].force_model_n))
                .expect("a run is not empty");
            Touch { first, last, peak }
        })
        .collect()
}

#[cfg(test)]
pub(crate) fn reading(time_s: f64, contact: bool, force: f64) -> SessionReading {
    SessionReading {
        frame_id: (time_s * 10.0) as u64,
        time_s,
        contact,
        gamma: force,
        force_model_n: force,
        contact_mm: contact.then_some([1.0, 2.0]),
        points_detected: 165,
        points_expected: 165,
        points_valid: 165,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn touches_bridge_one_frame_gaps_and_ignore_one_frame_blips() {
        let pattern = [0, 1, 1, 0, 1, 1, 0, 0, 1, 0, 0, 1, 1, 1, 0];
        let force = [
            0.0, 2.0, 5.0, 1.0, 6.0, 3.0, 0.0, 0.0, 9.0, 0.0, 0.0, 1.0, 4.0, 2.0, 0.0,
        ];
        let readings: Vec<_> = pattern
            .iter()
            .zip(force)
            .enumerate()
            .map(|(i, (&c, f))| reading(i as f64 * 0.1, c == 1, f))
            .collect();
        let found = touches(&readings);
        assert_eq!(
            found,
            vec![
                Touch {
                    first: 1,
                    last: 5,
                    peak: 4
                },
                Touch {
                    first: 11,
                    last: 13,
                    peak: 12
                }
            ]
        );
        assert_eq!(found[0].near_peak(&readings, 0.8), vec![2, 4]);
    }
}
