//! The pipeline decodes only what the estimator reads, and a frame that does not decode costs only that frame.

use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

use nusense_capture::{CaptureError, Frame, FramePixels, FrameSource, Scale, SourceInfo};
use nusense_estimator::{Estimator, Mode, SensorConfig};

use super::{DecodeScale, NoBoard, Pipeline, PipelineOptions, PublishedReading, StageDrops, Stages};

fn real(name: &str) -> Vec<u8> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../estimator/tests/data/real")
        .join(name);
    std::fs::read(path).expect("the real pair ships with the project")
}

fn full_decode(bytes: &[u8]) -> image::RgbImage {
    image::load_from_memory(bytes).expect("a whole JPEG").to_rgb8()
}

#[test]
fn auto_scale_keeps_the_decoded_frame_at_least_1024_px_wide() {
    let auto = DecodeScale::Auto;
    assert_eq!(auto.for_frame(Mode::Fast, 2048), Scale::Half);
    assert_eq!(auto.for_frame(Mode::Inverse, 4096), Scale::Quarter);
    assert_eq!(auto.for_frame(Mode::Fast, 1280), Scale::Full);
    assert_eq!(auto.for_frame(Mode::Fast, 640), Scale::Full);
    assert_eq!(auto.for_frame(Mode::Paper, 2048), Scale::Full);
    assert_eq!(
        DecodeScale::Fixed(Scale::Eighth).for_frame(Mode::Fast, 640),
        Scale::Eighth
    );
}

/// The real pair through the pipeline with a truncated frame between them: that frame is a typed decode error,
/// counted in the status, and the frames after it are measured. The touch frame, decoded at 1/2 scale inside
/// the pattern's region, gives the corners and contact a plain full decode gives, in the full frame's raw px.
/// Decoding and estimation overlapped (two threads) and one after the other (one thread) give the same.
#[test]
fn a_truncated_frame_is_a_decode_error_and_the_pipeline_goes_on() {
    truncated_frame_among_good_ones(Stages::Overlapped);
}

#[test]
fn a_truncated_frame_is_a_decode_error_and_the_pipeline_goes_on_in_one_thread() {
    truncated_frame_among_good_ones(Stages::OneThread);
}

/// Frames the test hands over one at a time: the real pipeline, in an order no slow build can change.
struct HandedFrames(std::sync::mpsc::Receiver<Vec<u8>>);

impl FrameSource for HandedFrames {
    fn info(&self) -> SourceInfo {
        SourceInfo {
            kind: "replay",
            name: "the test's frames".into(),
            width: 2048,
            height: 1536,
            fps: 5.0,
        }
    }

    fn next_frame(&mut self) -> Result<Frame, CaptureError> {
        let bytes = self.0.recv().map_err(|_| CaptureError::EndOfStream)?;
        Ok(Frame::now(FramePixels::Jpeg(Arc::new(bytes))))
    }
}

fn truncated_frame_among_good_ones(stages: Stages) {
    let (reference, touch) = (real("reference_fisheye.jpg"), real("touch_fisheye.jpg"));
    let (frames, handed) = std::sync::mpsc::channel();
    let mut options = PipelineOptions::new(SensorConfig::default(), Mode::Fast);
    // Nothing dropped however slow this build is: every frame must reach the estimator.
    options.queue_len = 8;
    options.stages = stages;
    let pipeline = Pipeline::start(Box::new(HandedFrames(handed)), Arc::new(NoBoard), options).unwrap();
    let handle = pipeline.handle();
    let mut readings = handle.subscribe();
    let deadline = Instant::now() + Duration::from_secs(300);
    let mut published: Vec<Arc<PublishedReading>> = Vec::new();
    // Each frame is handed over once the one before has been dealt with, so that (overlapped too) the touch
    // frames are decoded after the rest frame has set the pattern's region.
    for (frame_id, bytes) in [
        reference.clone(),
        touch[..touch.len() / 2].to_vec(),
        touch.clone(),
        touch.clone(),
    ]
    .into_iter()
    .enumerate()
    {
        let truncated = frame_id == 1;
        frames.send(bytes).unwrap();
        while Instant::now() < deadline {
            match readings.try_recv() {
                Ok(reading) => published.push(reading),
                Err(_) => std::thread::sleep(Duration::from_millis(20)),
            }
            let done = match truncated {
                true => handle.status().decode.errors > 0,
                false => published.iter().any(|p| p.message.frame_id == frame_id as u64),
            };
            if done {
                break;
            }
        }
    }
    drop(frames);
    // The stage latencies of the last frame are kept just after its reading is published.
    while handle.status().stage_latency_ms.estimate_to_publish.samples < 3 && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(20));
    }
    let frame_ids: Vec<u64> = published.iter().map(|p| p.message.frame_id).collect();
    assert_eq!(
        frame_ids,
        [0, 2, 3],
        "the truncated frame has no reading, the others do"
    );
    let status = handle.status();
    assert_eq!(status.decode.errors, 1);
    let decode_error = status.decode.last_error.clone().unwrap_or_default();
    assert!(
        decode_error.contains("frame 1") && decode_error.contains("truncated"),
        "{decode_error}"
    );
    assert_eq!(
        (status.frames_captured, status.frames_processed, status.frames_dropped),
        (4, 4, 0)
    );
    assert_eq!(status.frames_dropped_by_stage, StageDrops::default());
    assert_eq!(status.stages, stages);
    assert_eq!(status.estimate_errors, 0);
    assert_eq!(status.decode.scale, Some(Scale::Half));
    let region = status
        .decode
        .region
        .expect("later frames decode only the pattern's region");
    assert!(
        region.width * region.height < 2048 * 1536 * 3 / 4,
        "{region:?} is the pattern's part of the frame"
    );
    assert_eq!(status.stage_latency_ms.capture_to_decode.samples, 3);
    assert_eq!(status.stage_latency_ms.decode_to_estimate.samples, 3);
    assert_eq!(status.stage_latency_ms.estimate_to_publish.samples, 3);

    let last = &published[2].message;
    assert_eq!(last.reference_frame_id, Some(0));
    let reading = last.estimate.as_ref().expect("the touch frame is measured");
    let mut estimator = Estimator::new(SensorConfig::default(), Mode::Fast, &full_decode(&reference)).unwrap();
    let expected = estimator.estimate(&full_decode(&touch)).unwrap();
    let distances: Vec<f64> = expected
        .shear_field
        .iter()
        .zip(&reading.shear_field)
        .filter_map(|(a, b)| {
            let (a, b) = (a.current_px?, b.current_px?);
            Some((a[0] - b[0]).hypot(a[1] - b[1]))
        })
        .collect();
    assert!(distances.len() > 150, "{} corners in both", distances.len());
    let rms = (distances.iter().map(|d| d * d).sum::<f64>() / distances.len() as f64).sqrt();
    assert!(rms <= 0.1, "corners {rms:.3} px RMS from the full decode's");
    // The real touch is a press near the pad's centre: both decodes find it, at the same place.
    let (found, full) = (
        reading.contact_mm().expect("contact found"),
        expected.contact_mm().expect("contact found in the full decode"),
    );
    let shift = (found[0] - full[0]).hypot(found[1] - full[1]);
    assert!(shift <= 0.05, "contact {shift:.3} mm from the full decode's");
    let (found, full) = (reading.contact_px().unwrap(), expected.contact_px().unwrap());
    let shift_px = (found[0] - full[0]).hypot(found[1] - full[1]);
    assert!(
        shift_px <= 2.0,
        "contact {shift_px:.2} raw px from the full decode's: px not scaled back?"
    );
}
