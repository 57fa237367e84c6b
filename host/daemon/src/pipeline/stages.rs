//! The two stages that cost time, decoding and estimating, and the rule that ties them: a frame is decoded the way
//! the current rest frame asks (its decode scale, its pattern's region), and the rest frame itself is always a
//! frame decoded whole.
//!
//! With [`Stages::Overlapped`] (the default) each stage has its own thread and a bounded drop-oldest queue lies
//! between them, so that frame n+1 is decoded while frame n is estimated: on two cores the daemon keeps the
//! camera's frame rate as long as neither stage alone takes longer than a frame interval. [`Stages::OneThread`]
//! runs both on one thread, one after the other (the daemon before issue 13), so that the pipeline benchmark can
//! measure against it.
//!
//! Overlapped, the decode stage runs ahead of the estimate stage: it decodes with the [`DecodePlan`] of the last
//! frame estimated, not of the frame before it. What keeps that correct:
//! - The plan is written only by the estimate stage, whole (scale, region and the tares it has acted on) under one
//!   lock, after each frame.
//! - Tares are counted (`Shared::tares_requested`). A decoded frame carries the count the decode stage saw. While
//!   the count differs from the plan's, frames are decoded whole at the scale for their size, as a rest frame must
//!   be; the estimate stage takes the first frame whose count is above the tares it has acted on as the new rest
//!   frame. Such a frame was decoded after the tare was asked for and before the plan could have caught up with
//!   it: whole. Frames decoded before the tare was asked for may carry the old rest frame's region; they come
//!   first out of the queue, and are measured against the old rest frame, the one they were decoded for.
//! - Until there is a rest frame (the first frames, or after a rest frame that could not be measured) the plan
//!   has none, and frames are decoded whole.

use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use nusense_capture::{unix_time_us, CaptureError, DecodeOptions, DecodedFrame, Decoder, PixelRect, Scale};
use nusense_estimator::{Estimator, Mode, SensorConfig};
use serde::Serialize;

use super::{lock, publish, DecodeScale, QueuedFrame, Shared, POLL_INTERVAL};
use crate::reading::{ReadingMessage, SCHEMA_VERSION};

/// How decoding and estimation share the machine.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Stages {
    /// A decode thread and an estimator thread with a drop-oldest queue between them: the two overlap.
    #[default]
    Overlapped,
    /// One thread decodes a frame, then estimates it, then takes the next: the baseline of the pipeline benchmark.
    OneThread,
}

/// What the estimate stage tells the decode stage: how to decode frames for the current rest frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(super) struct DecodePlan {
    /// Tare requests the estimate stage has acted on (compared with `Shared::tares_requested`).
    tares_done: u64,
    /// The rest frame's decode scale and pattern region; `None` until there is a rest frame.
    rest: Option<RestDecode>,
    /// The last frame estimated was measured. After one that was not, frames are decoded whole: the pattern may
    /// have left the region.
    last_measured: bool,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct RestDecode {
    /// Every frame is decoded at the rest frame's scale, so that the estimator compares frames of one size.
    scale: Scale,
    /// The pattern's part of the frame, full-size raw px; `None`: whole frames (`--decode-whole`, paper mode).
    region: Option<PixelRect>,
}

impl DecodePlan {
    /// How to decode a frame when `tares_requested` tares have been asked for: the rest frame's way, or `whole`
    /// (the frame as a rest frame must be decoded) when there is no rest frame or a tare waits.
    fn options(&self, tares_requested: u64, whole: DecodeOptions) -> DecodeOptions {
        match self.rest {
            Some(rest) if tares_requested == self.tares_done => DecodeOptions {
                scale: rest.scale,
                region: rest.region.filter(|_| self.last_measured),
            },
            _ => whole,
        }
    }
}

/// A frame decoded for the estimator.
pub(super) struct DecodedItem {
    pub(super) frame: QueuedFrame,
    decoded: DecodedFrame,
    /// How it was decoded.
    options: DecodeOptions,
    /// Tares asked for when it was decoded.
    tares_requested: u64,
    decode_started_at: Instant,
    decoded_at: Instant,
}

/// Turns the camera's bytes into the pixels the estimator reads.
pub(super) struct DecodeStage {
    decoder: Decoder,
    mode: Mode,
    decode_scale: DecodeScale,
}

impl DecodeStage {
    pub(super) fn new(mode: Mode, decode_scale: DecodeScale) -> Self {
        Self {
            decoder: Decoder::new(),
            mode,
            decode_scale,
        }
    }

    /// The decode thread of [`Stages::Overlapped`]: captured frames in, decoded frames out.
    pub(super) fn run(mut self, shared: &Shared) {
        while !shared.stop.load(Ordering::Relaxed) {
            if let Some(frame) = shared.queue.pop_timeout(POLL_INTERVAL) {
                if let Some(item) = self.decode(frame, shared) {
                    shared.decoded.push(item);
                }
            }
        }
    }

    /// Decodes a frame as the plan says; `None` for a frame that did not decode (a truncated or corrupt JPEG, a
    /// short YUYV buffer): it is counted, its error kept for the status, and the next frame may be fine.
    pub(super) fn decode(&mut self, frame: QueuedFrame, shared: &Shared) -> Option<DecodedItem> {
        let decode_started_at = Instant::now();
        let tares_requested = shared.tares_requested.load(Ordering::Acquire);
        let plan = *lock(&shared.plan);
        let width = frame.pixels.dimensions().map_or(0, |(width, _)| width);
        let whole = DecodeOptions::scaled(self.decode_scale.for_frame(self.mode, width));
        let options = plan.options(tares_requested, whole);
        match self.decoder.decode(&frame.pixels, &options) {
            Ok(decoded) => {
                let mut status = lock(&shared.decode);
                status.scale = Some(decoded.scale);
                status.region = options.region;
                drop(status);
                Some(DecodedItem {
                    frame,
                    decoded,
                    options,
                    tares_requested,
                    decode_started_at,
                    decoded_at: Instant::now(),
                })
            }
            Err(source) => {
                let error = CaptureError::Decode {
                    origin: format!("frame {} of {}", frame.frame_id, lock(&shared.source_info).name),
                    source,
                };
                tracing::warn!("decode: {error}");
                // The error first, then the counts: a status that counts the frame also says why.
                lock(&shared.decode).last_error = Some(error.to_string());
                shared.counters.decode_errors.fetch_add(1, Ordering::Relaxed);
                shared.counters.frames_processed.fetch_add(1, Ordering::Relaxed);
                None
            }
        }
    }
}

/// The estimator and the rest frame it measures against.
struct Measuring {
    estimator: Estimator,
    rest: RestDecode,
    reference_frame_id: u64,
}

fn region_of(estimator: &Estimator, scale: Scale, frame: (u32, u32)) -> Option<PixelRect> {
    let (min, max) = estimator.pattern_region_px()?;
    PixelRect::from_scaled_bounds(min, max, scale, frame)
}

/// Turns decoded frames into readings and publishes them; owns the rest frame and the decode plan.
pub(super) struct EstimateStage {
    config: SensorConfig,
    mode: Mode,
    decode_region: bool,
    measuring: Option<Measuring>,
    /// Tare requests acted on: the count carried by the last frame taken as a rest frame because of one.
    tares_done: u64,
}

impl EstimateStage {
    pub(super) fn new(config: SensorConfig, mode: Mode, decode_region: bool) -> Self {
        Self {
            config,
            mode,
            decode_region,
            measuring: None,
            tares_done: 0,
        }
    }

    /// The estimator thread of [`Stages::Overlapped`].
    pub(super) fn run(mut self, shared: &Shared) {
        while !shared.stop.load(Ordering::Relaxed) {
            if let Some(item) = shared.decoded.pop_timeout(POLL_INTERVAL) {
                self.estimate(item, shared);
            }
        }
    }

    /// Measures a decoded frame (or takes it as the rest frame), publishes its reading and tells the decode stage
    /// how to decode the next frames.
    pub(super) fn estimate(&mut self, item: DecodedItem, shared: &Shared) {
        let estimate_started_at = Instant::now();
        let frame_size = (item.decoded.frame_width, item.decoded.frame_height);
        let mut error = None;
        if self.measuring.is_none() || item.tares_requested > self.tares_done {
            // See the module's comment: such a frame was decoded whole.
            debug_assert_eq!(item.options.region, None, "a rest frame decoded in a region");
            self.tares_done = self.tares_done.max(item.tares_requested);
            self.measuring = None;
            match Estimator::new(self.config.clone(), self.mode, &item.decoded.image) {
                Ok(estimator) => {
                    let scale = item.decoded.scale;
                    let region = self
                        .decode_region
                        .then(|| region_of(&estimator, scale, frame_size))
                        .flatten();
                    self.measuring = Some(Measuring {
                        estimator,
                        rest: RestDecode { scale, region },
                        reference_frame_id: item.frame.frame_id,
                    });
                    shared.counters.tares.fetch_add(1, Ordering::Relaxed);
                }
                Err(e) => error = Some(format!("no rest frame yet: {e}")),
            }
        }
        let estimate = match self.measuring.as_mut() {
            None => None,
            Some(m) => match m.estimator.estimate(&item.decoded.image) {
                Ok(mut reading) => {
                    if reading.retared && self.decode_region {
                        // A new rest lattice: the region follows it.
                        m.rest.region = region_of(&m.estimator, m.rest.scale, frame_size);
                    }
                    reading.scale_px(f64::from(item.decoded.scale.divisor()));
                    Some(reading)
                }
                Err(e) => {
                    error = Some(e.to_string());
                    None
                }
            },
        };
        *lock(&shared.plan) = DecodePlan {
            tares_done: self.tares_done,
            rest: self.measuring.as_ref().map(|m| m.rest),
            last_measured: estimate.is_some(),
        };
        if error.is_some() {
            shared.counters.estimate_errors.fetch_add(1, Ordering::Relaxed);
        }
        shared.counters.frames_processed.fetch_add(1, Ordering::Relaxed);
        let estimated_at = Instant::now();
        let frame = item.frame;
        let since_capture = |t: Instant| ms(t.saturating_duration_since(frame.captured_at));
        let waited = item.decode_started_at.saturating_duration_since(frame.captured_at)
            + estimate_started_at.saturating_duration_since(item.decoded_at);
        let message = ReadingMessage {
            schema_version: SCHEMA_VERSION,
            frame_id: frame.frame_id,
            file: None,
            capture_time_us: frame.capture_time_us,
            processed_time_us: unix_time_us(),
            latency_ms: since_capture(estimated_at),
            queue_ms: ms(waited),
            reference_frame_id: self.measuring.as_ref().map(|m| m.reference_frame_id),
            estimate,
            error,
            led: shared.board.led_state(),
        };
        lock(&shared.latency).push(message.latency_ms);
        let capture_to_decode = since_capture(item.decoded_at);
        publish(shared, frame, message);
        let published_at = Instant::now();
        let mut stages = lock(&shared.stage_latency);
        stages.capture_to_decode.push(capture_to_decode);
        stages
            .decode_to_estimate
            .push(ms(estimated_at.saturating_duration_since(item.decoded_at)));
        stages
            .estimate_to_publish
            .push(ms(published_at.saturating_duration_since(estimated_at)));
    }
}

fn ms(duration: Duration) -> f64 {
    duration.as_secs_f64() * 1e3
}

/// [`Stages::OneThread`]: each frame decoded and then estimated on this thread before the next is taken.
pub(super) fn run_one_thread(mut decode: DecodeStage, mut estimate: EstimateStage, shared: &Shared) {
    while !shared.stop.load(Ordering::Relaxed) {
        if let Some(frame) = shared.queue.pop_timeout(POLL_INTERVAL) {
            if let Some(item) = decode.decode(frame, shared) {
                estimate.estimate(item, shared);
            }
        }
    }
}

#[cfg(test)]
impl DecodePlan {
    /// The region later frames are decoded in, if any.
    pub(super) fn region(&self) -> Option<PixelRect> {
        self.rest.and_then(|rest| rest.region)
    }
}

#[cfg(test)]
impl DecodedItem {
    pub(super) fn options(&self) -> DecodeOptions {
        self.options
    }
}

#[cfg(test)]
#[path = "stages_tests.rs"]
mod tests;
