//! YUYV 4:2:2 (BT.601, limited range), converted only where it is used: each output pixel of the region is the
//! mean of its `scale x scale` block of the frame, converted to RGB once.
//!
//! A pair's chroma is sited between its two pixels (V4L2's sample location for YUYV). At full size each pixel takes
//! the chroma at its own position, interpolated between the two nearest pairs (3/4 of its own pair's, 1/4 of the
//! neighbour's on its side), as libjpeg's "fancy" upsampling does: copying the pair's chroma to both pixels instead
//! moves every chroma edge by half a pixel towards the even pixels, and the estimator, which reads every other pixel
//! of a frame 2048 px wide, then finds the yellow-on-red lattice (its contrast lives in the chroma) 0.48 px left of
//! where it is. The scaled paths average whole pairs over blocks of an even width, centred where the block is.

use image::RgbImage;

use super::{output_region, DecodeError, DecodeOptions, DecodedFrame, Scale};

/// Luma and chroma of one output pixel (means over its block), to RGB in 8.8 fixed point.
#[inline(always)]
fn to_rgb(y: i32, u: i32, v: i32) -> [u8; 3] {
    let c = 298 * (y - 16) + 128;
    let (d, e) = (u - 128, v - 128);
    let clamp = |x: i32| (x >> 8).clamp(0, 255) as u8;
    [clamp(c + 409 * e), clamp(c - 100 * d - 208 * e), clamp(c + 516 * d)]
}

/// Scratch space for converting one row at full size, kept across rows: luma and interpolated chroma per pixel, so
/// that each step is a plain loop over slices (no branch or bounds check per pixel) that the compiler vectorises.
#[derive(Default)]
struct FullSizeRow {
    /// U and V of the pairs the pixels fall in, with one more pair each side (the row's end pair repeated).
    pair_u: Vec<i32>,
    pair_v: Vec<i32>,
    y: Vec<i32>,
    u: Vec<i32>,
    v: Vec<i32>,
}

impl FullSizeRow {
    /// Pixels `x0..x1` of `line` (one whole row of YUYV) to RGB in `out`, each pixel with its chroma interpolated
    /// at its own position (module docs): 3/4 of its pair's, 1/4 of the neighbouring pair's on its side.
    fn convert(&mut self, line: &[u8], x0: usize, x1: usize, out: &mut [u8]) {
        let last_pair = line.len() / 4 - 1;
        let (p0, p1) = (x0 / 2, x1.div_ceil(2));
        let pairs = &line[p0 * 4..p1 * 4];
        for (plane, offset) in [(&mut self.pair_u, 1), (&mut self.pair_v, 3)] {
            plane.clear();
            plane.push(i32::from(line[p0.saturating_sub(1) * 4 + offset]));
            plane.extend(pairs.chunks_exact(4).map(|pair| i32::from(pair[offset])));
            plane.push(i32::from(line[p1.min(last_pair) * 4 + offset]));
        }
        let pixels = (p1 - p0) * 2;
        self.y.resize(pixels, 0);
        for (y, pair) in self.y.chunks_exact_mut(2).zip(pairs.chunks_exact(4)) {
            y[0] = i32::from(pair[0]);
            y[1] = i32::from(pair[2]);
        }
        for (plane, pair_plane) in [(&mut self.u, &self.pair_u), (&mut self.v, &self.pair_v)] {
            plane.resize(pixels, 0);
            for (c, w) in plane.chunks_exact_mut(2).zip(pair_plane.windows(3)) {
                let own = 3 * w[1] + 2;
                c[0] = (own + w[0]) >> 2;
                c[1] = (own + w[2]) >> 2;
            }
        }
        let skip = x0 - p0 * 2;
        let take = skip..skip + (x1 - x0);
        let (y, u, v) = (&self.y[take.clone()], &self.u[take.clone()], &self.v[take]);
        for (((rgb, &y), &u), &v) in out.chunks_exact_mut(3).zip(y).zip(u).zip(v) {
            rgb.copy_from_slice(&to_rgb(y, u, v));
        }
    }
}

pub(super) fn decode(
    bytes: &[u8],
    width: u32,
    height: u32,
    options: &DecodeOptions,
) -> Result<DecodedFrame, DecodeError> {
    if !width.is_multiple_of(2) {
        return Err(DecodeError::OddYuyvWidth { width, height });
    }
    let needed = width as usize * height as usize * 2;
    if bytes.len() < needed {
        return Err(DecodeError::Short {
            format: "YUYV",
            width,
            height,
            found: bytes.len(),
            needed,
        });
    }
    let (region, decoded) = output_region(options, width, height)?;
    let (out_width, out_height) = options.scale.apply(width, height);
    let mut image = RgbImage::new(out_width, out_height);
    let stride = width as usize * 2;
    let out = image.as_mut();
    if options.scale == Scale::Full {
        let mut row = FullSizeRow::default();
        let (x0, x1) = (region.x as usize, (region.x + region.width) as usize);
        for y in region.y as usize..(region.y + region.height) as usize {
            let line = &bytes[y * stride..][..stride];
            let start = y * out_width as usize;
            row.convert(line, x0, x1, &mut out[(start + x0) * 3..(start + x1) * 3]);
        }
    } else {
        // Blocks are an even number of pixels wide, so each holds whole Y0 U Y1 V pairs.
        let d = options.scale.divisor() as usize;
        for oy in region.y as usize..(region.y + region.height) as usize {
            let rows = oy * d..((oy + 1) * d).min(height as usize);
            for ox in region.x as usize..(region.x + region.width) as usize {
                let columns = ox * d..((ox + 1) * d).min(width as usize);
                let (mut luma, mut u, mut v) = (0u32, 0u32, 0u32);
                for y in rows.clone() {
                    let block = &bytes[y * stride + columns.start * 2..y * stride + columns.end * 2];
                    for quad in block.chunks_exact(4) {
                        luma += u32::from(quad[0]) + u32::from(quad[2]);
                        u += u32::from(quad[1]);
                        v += u32::from(quad[3]);
                    }
                }
                let pixels = (rows.len() * columns.len()) as u32;
                let pairs = pixels / 2;
                let mean = |sum: u32, n: u32| ((sum + n / 2) / n) as i32;
                let rgb = to_rgb(mean(luma, pixels), mean(u, pairs), mean(v, pairs));
                out[(oy * out_width as usize + ox) * 3..][..3].copy_from_slice(&rgb);
            }
        }
    }
    Ok(DecodedFrame {
        image,
        scale: options.scale,
        decoded,
        frame_width: width,
        frame_height: height,
    })
}

/// An RGB image as a YUYV camera would deliver it (BT.601, limited range, each pair of pixels sharing the mean of
/// their chroma): the inverse of [`yuyv_to_rgb`] up to the chroma subsampling and rounding. Benchmarks and tests
/// make YUYV frames of rendered or real images with it; `None` for an odd width.
pub fn rgb_to_yuyv(image: &RgbImage) -> Option<Vec<u8>> {
    if !image.width().is_multiple_of(2) {
        return None;
    }
    let luma = |[r, g, b]: [i32; 3]| ((66 * r + 129 * g + 25 * b + 128) >> 8) + 16;
    let mut bytes = Vec::with_capacity(image.as_raw().len() / 3 * 2);
    for pair in image.as_raw().chunks_exact(6) {
        let left = [i32::from(pair[0]), i32::from(pair[1]), i32::from(pair[2])];
        let right = [i32::from(pair[3]), i32::from(pair[4]), i32::from(pair[5])];
        let [r, g, b] = [0, 1, 2].map(|c| left[c] + right[c]);
        // Sums of two pixels: the shift by 9 takes their mean.
        let u = ((-38 * r - 74 * g + 112 * b + 256) >> 9) + 128;
        let v = ((112 * r - 94 * g - 18 * b + 256) >> 9) + 128;
        let byte = |x: i32| x.clamp(0, 255) as u8;
        bytes.extend_from_slice(&[byte(luma(left)), byte(u), byte(luma(right)), byte(v)]);
    }
    Some(bytes)
}

/// The whole frame in RGB; `None` for an odd width or too few bytes.
pub fn yuyv_to_rgb(bytes: &[u8], width: u32, height: u32) -> Option<RgbImage> {
    decode(bytes, width, height, &DecodeOptions::FULL).ok().map(|d| d.image)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decode::PixelRect;

    /// The full-size conversion as first written (ddd3c9f): one pixel at a time, its chroma read from its own pair
    /// and the neighbouring one on its side.
    fn reference_pixel(line: &[u8], x: usize) -> [u8; 3] {
        let last_pair = line.len() / 4 - 1;
        let chroma = |pair: usize| (i32::from(line[pair * 4 + 1]), i32::from(line[pair * 4 + 3]));
        let own = x / 2;
        let neighbour = if x.is_multiple_of(2) {
            own.saturating_sub(1)
        } else {
            (own + 1).min(last_pair)
        };
        let ((u0, v0), (u1, v1)) = (chroma(own), chroma(neighbour));
        to_rgb(i32::from(line[x * 2]), (3 * u0 + u1 + 2) >> 2, (3 * v0 + v1 + 2) >> 2)
    }

    #[test]
    fn the_row_conversion_gives_the_per_pixel_conversion_exactly_in_any_region() {
        // Noise, so that every pixel's chroma differs from its neighbours'; regions starting and ending on even and
        // odd pixels, at the frame's edges and inside, down to one pixel.
        let (w, h) = (38u32, 5u32);
        let mut state = 0x2545_f491_u32;
        let bytes: Vec<u8> = (0..w * h * 2)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 17;
                state ^= state << 5;
                state as u8
            })
            .collect();
        for (x, width) in [
            (0, 38),
            (0, 1),
            (1, 1),
            (37, 1),
            (1, 36),
            (2, 35),
            (3, 4),
            (36, 2),
            (5, 30),
        ] {
            let region = PixelRect {
                x,
                y: 1,
                width,
                height: 3,
            };
            let options = DecodeOptions {
                scale: Scale::Full,
                region: Some(region),
            };
            let decoded = decode(&bytes, w, h, &options).unwrap();
            for py in 0..h {
                let line = &bytes[(py * w * 2) as usize..][..(w * 2) as usize];
                for px in 0..w {
                    let inside = (x..x + width).contains(&px) && (1..4).contains(&py);
                    let expected = if inside {
                        reference_pixel(line, px as usize)
                    } else {
                        [0; 3]
                    };
                    assert_eq!(
                        decoded.image.get_pixel(px, py).0,
                        expected,
                        "({px}, {py}) in {region:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn grey_and_saturated_red_convert_to_rgb() {
        // Four pixels of mid grey (Y=126, no chroma) then four of saturated red (BT.601: Y=81 U=90 V=240).
        let bytes = [126, 128, 126, 128, 126, 128, 126, 128, 81, 90, 81, 240, 81, 90, 81, 240];
        let img = yuyv_to_rgb(&bytes, 8, 1).expect("whole frame");
        for x in 0..3 {
            let grey = img.get_pixel(x, 0).0;
            assert!(grey.iter().all(|&c| (c as i32 - 128).abs() <= 2), "{x}: {grey:?}");
        }
        for x in 5..8 {
            let red = img.get_pixel(x, 0).0;
            assert!(red[0] > 240 && red[1] < 15 && red[2] < 15, "{x}: {red:?}");
        }
    }

    #[test]
    fn a_chroma_edge_stays_where_it_is() {
        // Red turning yellow along a ramp from x = 3 to x = 11, half-way at x = 7 (inside the pair (6, 7)), as a
        // blurred edge of the pattern does. Where the green channel crosses half-way between the two colours,
        // interpolated between the pixels one reads, is x = 7 to a tenth of a pixel, whichever pixels one reads.
        let (red, yellow) = ([200.0, 30.0, 30.0], [230.0, 200.0, 40.0]);
        let width = 16u32;
        let fraction = |x: f64| ((x - 3.0) / 8.0).clamp(0.0, 1.0);
        let mut image = RgbImage::new(width, 1);
        for x in 0..width {
            let f = fraction(f64::from(x));
            let rgb = [0, 1, 2].map(|c| (red[c] + f * (yellow[c] - red[c])).round() as u8);
            image.put_pixel(x, 0, image::Rgb(rgb));
        }
        let back = yuyv_to_rgb(&rgb_to_yuyv(&image).unwrap(), width, 1).unwrap();
        let half_way = (red[1] + yellow[1]) / 2.0;
        let crossing = |xs: Vec<u32>| {
            xs.windows(2).find_map(|w| {
                let (g0, g1) = (
                    f64::from(back.get_pixel(w[0], 0)[1]),
                    f64::from(back.get_pixel(w[1], 0)[1]),
                );
                (g0 < half_way && g1 >= half_way)
                    .then(|| f64::from(w[0]) + f64::from(w[1] - w[0]) * (half_way - g0) / (g1 - g0))
            })
        };
        for (name, xs) in [
            ("every pixel", (0..width).collect::<Vec<_>>()),
            ("even pixels", (0..width).step_by(2).collect()),
            ("odd pixels", (1..width).step_by(2).collect()),
        ] {
            let found = crossing(xs).expect("the edge is in the frame");
            assert!((found - 7.0).abs() <= 0.1, "{name}: edge at {found:.2}, truly at 7.00");
        }
    }

    #[test]
    fn rgb_through_yuyv_and_back_keeps_the_colours() {
        // Runs of four equal pixels lose nothing to the chroma subsampling in their middle two pixels (the outer
        // two take a quarter of the neighbouring run's chroma): only BT.601's 8-bit rounding remains.
        let colours = [
            [255, 0, 0],
            [240, 200, 30],
            [200, 40, 30],
            [0, 0, 0],
            [255, 255, 255],
            [20, 90, 180],
        ];
        let image = RgbImage::from_fn(colours.len() as u32 * 4, 1, |x, _| image::Rgb(colours[x as usize / 4]));
        let bytes = rgb_to_yuyv(&image).expect("even width");
        assert_eq!(bytes.len(), colours.len() * 8);
        let back = yuyv_to_rgb(&bytes, image.width(), 1).unwrap();
        let middles = image
            .pixels()
            .zip(back.pixels())
            .enumerate()
            .filter(|(x, _)| x % 4 == 1 || x % 4 == 2);
        for (x, (a, b)) in middles {
            for c in 0..3 {
                assert!(
                    (i32::from(a[c]) - i32::from(b[c])).abs() <= 3,
                    "pixel {x}: {:?} came back as {:?}",
                    a.0,
                    b.0
                );
            }
        }
        assert_eq!(rgb_to_yuyv(&RgbImage::new(3, 1)), None, "odd width");
    }

    #[test]
    fn short_or_odd_frames_are_typed_errors() {
        assert!(matches!(
            decode(&[0; 6], 4, 1, &DecodeOptions::FULL),
            Err(DecodeError::Short { needed: 8, .. })
        ));
        assert!(matches!(
            decode(&[0; 6], 3, 1, &DecodeOptions::FULL),
            Err(DecodeError::OddYuyvWidth { .. })
        ));
    }

    #[test]
    fn scaled_region_is_the_block_mean_and_black_elsewhere() {
        // 8x4 frame: left half luma 60, right half luma 200, no chroma.
        let (w, h) = (8u32, 4u32);
        let mut bytes = Vec::new();
        for _ in 0..h {
            for x in (0..w).step_by(2) {
                let y = if x < 4 { 60 } else { 200 };
                bytes.extend_from_slice(&[y, 128, y, 128]);
            }
        }
        let options = DecodeOptions {
            scale: Scale::Half,
            region: Some(PixelRect {
                x: 4,
                y: 0,
                width: 4,
                height: 2,
            }),
        };
        let decoded = decode(&bytes, w, h, &options).unwrap();
        assert_eq!(decoded.image.dimensions(), (4, 2));
        let full = yuyv_to_rgb(&bytes, w, h).unwrap();
        assert_eq!(decoded.image.get_pixel(2, 0), full.get_pixel(5, 1));
        assert_eq!(
            decoded.image.get_pixel(1, 0).0,
            [0, 0, 0],
            "outside the region stays black"
        );
        assert_eq!(decoded.image.get_pixel(2, 1).0, [0, 0, 0]);
        assert_eq!(
            decoded.decoded,
            PixelRect {
                x: 4,
                y: 0,
                width: 4,
                height: 2
            }
        );
    }
}
