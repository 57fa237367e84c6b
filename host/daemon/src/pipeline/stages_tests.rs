//! The decode and estimate stages driven by hand, in the orders the two threads can take, on the real frames.

use std::path::Path;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Instant;

use image::codecs::jpeg::JpegEncoder;
use nusense_capture::{unix_time_us, FramePixels, PixelRect, Scale, SourceInfo};
use nusense_estimator::{Mode, SensorConfig};

use super::{DecodeStage, DecodedItem, EstimateStage};
use crate::pipeline::{
    lock, NoBoard, PipelineHandle, PipelineOptions, PublishedReading, QueuedFrame, Shared, StageDrops,
};

fn real(name: &str) -> Vec<u8> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../estimator/tests/data/real")
        .join(name);
    std::fs::read(path).expect("the real pair ships with the project")
}

fn frame(frame_id: u64, jpeg: &Arc<Vec<u8>>) -> QueuedFrame {
    QueuedFrame {
        frame_id,
        captured_at: Instant::now(),
        capture_time_us: unix_time_us(),
        pixels: FramePixels::Jpeg(jpeg.clone()),
    }
}

fn shared(queue_len: usize) -> Arc<Shared> {
    let mut options = PipelineOptions::new(SensorConfig::default(), Mode::Fast);
    options.queue_len = queue_len;
    let info = SourceInfo {
        kind: "replay",
        name: "the real pair".into(),
        width: 2048,
        height: 1536,
        fps: 30.0,
    };
    Arc::new(Shared::new(info, Arc::new(NoBoard), &options))
}

/// The frame moved `dx` px sideways (as if the camera had been knocked), black where nothing moved in, as a JPEG.
fn shifted(jpeg: &[u8], dx: i64) -> Vec<u8> {
    let image = image::load_from_memory(jpeg).unwrap().to_rgb8();
    let mut moved = image::RgbImage::new(image.width(), image.height());
    for (x, y, pixel) in moved.enumerate_pixels_mut() {
        let from = i64::from(x) - dx;
        if (0..i64::from(image.width())).contains(&from) {
            *pixel = *image.get_pixel(from as u32, y);
        }
    }
    let mut bytes = Vec::new();
    JpegEncoder::new_with_quality(&mut bytes, 92)
        .encode_image(&moved)
        .unwrap();
    bytes
}

/// Estimates `item` and returns its reading as published.
fn estimate(stage: &mut EstimateStage, item: DecodedItem, shared: &Shared) -> Arc<PublishedReading> {
    let mut readings = shared.readings.subscribe();
    stage.estimate(item, shared);
    readings
        .try_recv()
        .expect("a reading is published for every frame estimated")
}

/// The largest distance between a corner's rest and current position, full-size px.
fn worst_corner_shift_px(reading: &nusense_estimator::Reading) -> f64 {
    reading
        .shear_field
        .iter()
        .filter_map(|v| {
            let (a, b) = (v.reference_px?, v.current_px?);
            Some((a[0] - b[0]).hypot(a[1] - b[1]))
        })
        .fold(0.0, f64::max)
}

fn contains(outer: PixelRect, inner: PixelRect) -> bool {
    outer.x <= inner.x
        && outer.y <= inner.y
        && inner.x + inner.width <= outer.x + outer.width
        && inner.y + inner.height <= outer.y + outer.height
}

/// The decode stage runs ahead of the estimate stage. Here a frame is decoded with the old rest frame's region,
/// then a tare is asked for, then the frame that becomes the new rest frame is decoded before the estimate stage
/// has caught up, and the camera has moved in between (so the old region cuts the pattern). The frame decoded
/// before the tare is measured against the old rest frame; the new rest frame is decoded whole, so its lattice is
/// complete; the frames after it are decoded in its own region and measured against it.
#[test]
fn a_tare_takes_a_frame_decoded_whole_and_the_region_follows_the_new_rest_frame() {
    let shared = shared(2);
    let handle = PipelineHandle { shared: shared.clone() };
    let mut decode = DecodeStage::new(Mode::Fast, super::DecodeScale::Auto);
    let mut stage = EstimateStage::new(SensorConfig::default(), Mode::Fast, true);
    let (reference, touch) = (
        Arc::new(real("reference_fisheye.jpg")),
        Arc::new(real("touch_fisheye.jpg")),
    );

    let first = decode.decode(frame(0, &reference), &shared).unwrap();
    assert_eq!(first.options().region, None, "no rest frame yet: decoded whole");
    assert_eq!(first.options().scale, Scale::Half);
    let rest = estimate(&mut stage, first, &shared);
    assert_eq!(rest.message.reference_frame_id, Some(0));
    let rest_counts = rest.message.estimate.as_ref().expect("the rest frame measures").counts;
    // The estimator's tracked corners on the rest frame itself sit a little off its rest lattice's: the bound below.
    let rest_self_px = worst_corner_shift_px(rest.message.estimate.as_ref().unwrap());
    let old_region = lock(&shared.plan).region().expect("the pattern's region");
    assert!(
        old_region.width < 2048 * 9 / 10,
        "{old_region:?} is a part of the frame"
    );

    // The camera is knocked sideways by more than the region's margin, the pattern still in view.
    let room_right = 2048 - i64::from(old_region.x + old_region.width);
    let dx = if room_right > i64::from(old_region.x) {
        300
    } else {
        -300
    };
    let moved = Arc::new(shifted(&reference, dx));

    let before_tare = decode.decode(frame(1, &touch), &shared).unwrap();
    assert_eq!(before_tare.options().region, Some(old_region));
    handle.request_tare();
    let new_rest = decode.decode(frame(2, &moved), &shared).unwrap();
    assert_eq!(
        new_rest.options().region,
        None,
        "decoded after the tare was asked for: whole"
    );

    let touched = estimate(&mut stage, before_tare, &shared);
    assert_eq!(
        touched.message.reference_frame_id,
        Some(0),
        "decoded for the old rest frame, measured against it"
    );
    let touch_reading = touched.message.estimate.as_ref().expect("the touch frame measures");
    assert!(touch_reading.contact_mm().is_some(), "the real press is found");
    let decoded_meanwhile = decode.decode(frame(3, &moved), &shared).unwrap();
    assert_eq!(
        decoded_meanwhile.options().region,
        None,
        "the estimate stage has not acted on the tare yet: whole"
    );

    let taken = estimate(&mut stage, new_rest, &shared);
    assert_eq!(taken.message.reference_frame_id, Some(2));
    let new_region = lock(&shared.plan).region().expect("the moved pattern's region");
    assert!(
        !contains(old_region, new_region),
        "the moved pattern {new_region:?} reaches outside the old region {old_region:?}: a rest frame decoded in \
         the old region would have lost part of it"
    );
    let mut corners = Vec::new();
    for item in [decoded_meanwhile, decode.decode(frame(4, &moved), &shared).unwrap()] {
        let frame_id = item.frame.frame_id;
        let expected_region = if frame_id == 4 { Some(new_region) } else { None };
        assert_eq!(item.options().region, expected_region, "frame {frame_id}");
        let published = estimate(&mut stage, item, &shared);
        assert_eq!(published.message.reference_frame_id, Some(2), "frame {frame_id}");
        let reading = published.message.estimate.clone().expect("the moved frame measures");
        assert_eq!(
            reading.counts.points_detected, rest_counts.points_detected,
            "frame {frame_id}: the whole moved pattern, as in the first rest frame"
        );
        assert_eq!(
            reading.counts.points_valid, rest_counts.points_valid,
            "frame {frame_id}"
        );
        assert!(
            reading.contact_mm().is_none(),
            "frame {frame_id}: the rest frame again, no touch"
        );
        let shift_px = worst_corner_shift_px(&reading);
        assert!(
            shift_px <= rest_self_px + 0.05,
            "frame {frame_id}: a corner {shift_px:.3} px from the new rest lattice (the first rest frame: \
             {rest_self_px:.3} px from its own)"
        );
        corners.push(reading.shear_field.iter().map(|v| v.current_px).collect::<Vec<_>>());
    }
    // Decoded whole (frame 3) or in the new rest frame's region (frame 4), the same frame gives the same corners.
    assert_eq!(corners[0].len(), corners[1].len());
    for (whole, region) in corners[0].iter().zip(&corners[1]) {
        let (whole, region) = (whole.expect("every corner found"), region.expect("every corner found"));
        let apart = (whole[0] - region[0]).hypot(whole[1] - region[1]);
        assert!(apart <= 0.01, "{whole:?} decoded whole, {region:?} in the region");
    }
    assert_eq!(shared.counters.tares.load(Ordering::Relaxed), 2);
    assert_eq!(handle.status().tares, 2);
}

/// Two tares asked for before the estimate stage acts on the first: each takes its own, later, frame.
#[test]
fn a_second_tare_asked_for_meanwhile_takes_a_later_frame_again() {
    let shared = shared(2);
    let handle = PipelineHandle { shared: shared.clone() };
    let mut decode = DecodeStage::new(Mode::Fast, super::DecodeScale::Auto);
    let mut stage = EstimateStage::new(SensorConfig::default(), Mode::Fast, true);
    let (reference, touch) = (
        Arc::new(real("reference_fisheye.jpg")),
        Arc::new(real("touch_fisheye.jpg")),
    );
    let first = decode.decode(frame(0, &reference), &shared).unwrap();
    estimate(&mut stage, first, &shared);
    handle.request_tare();
    let a = decode.decode(frame(1, &touch), &shared).unwrap();
    handle.request_tare();
    let b = decode.decode(frame(2, &reference), &shared).unwrap();
    let c = decode.decode(frame(3, &reference), &shared).unwrap();
    for item in [&a, &b, &c] {
        assert_eq!(item.options().region, None, "frame {}", item.frame.frame_id);
    }
    let references: Vec<Option<u64>> = [a, b, c]
        .into_iter()
        .map(|item| estimate(&mut stage, item, &shared).message.reference_frame_id)
        .collect();
    assert_eq!(references, [Some(1), Some(2), Some(2)]);
    assert_eq!(handle.status().tares, 3);
    let next = decode.decode(frame(4, &touch), &shared).unwrap();
    assert!(next.options().region.is_some(), "both tares acted on: the region again");
}

/// Frames dropped in front of each stage are counted apart, and `frames_dropped` is their sum.
#[test]
fn drops_are_counted_per_stage() {
    let shared = shared(1);
    let handle = PipelineHandle { shared: shared.clone() };
    let mut decode = DecodeStage::new(Mode::Fast, super::DecodeScale::Fixed(Scale::Eighth));
    let reference = Arc::new(real("reference_fisheye.jpg"));
    for id in 0..3 {
        shared.queue.push(frame(id, &reference));
    }
    for id in 0..2 {
        let item = decode.decode(frame(id, &reference), &shared).unwrap();
        shared.decoded.push(item);
    }
    let status = handle.status();
    assert_eq!(status.frames_dropped_by_stage, StageDrops { decode: 2, estimate: 1 });
    assert_eq!(status.frames_dropped, 3);
    assert_eq!(handle.frames_dropped(), 3);
}
