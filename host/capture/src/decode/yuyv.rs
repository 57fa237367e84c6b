//! YUYV 4:2:2 (BT.601, limited range), converted only where it is used: each output pixel of the region is the
//! mean of its `scale x scale` block of the frame, converted to RGB once.

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
        for y in region.y as usize..(region.y + region.height) as usize {
            let line = &bytes[y * stride..][..stride];
            for x in region.x as usize..(region.x + region.width) as usize {
                let pair = &line[(x & !1) * 2..][..4];
                let rgb = to_rgb(i32::from(line[x * 2]), i32::from(pair[1]), i32::from(pair[3]));
                out[(y * out_width as usize + x) * 3..][..3].copy_from_slice(&rgb);
            }
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

/// The whole frame in RGB; `None` for an odd width or too few bytes.
pub fn yuyv_to_rgb(bytes: &[u8], width: u32, height: u32) -> Option<RgbImage> {
    decode(bytes, width, height, &DecodeOptions::FULL).ok().map(|d| d.image)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decode::PixelRect;

    #[test]
    fn grey_and_saturated_red_convert_to_rgb() {
        // Two pixels of mid grey (Y=126, no chroma) then two of saturated red (BT.601: Y=81 U=90 V=240).
        let bytes = [126, 128, 126, 128, 81, 90, 81, 240];
        let img = yuyv_to_rgb(&bytes, 4, 1).expect("whole frame");
        let grey = img.get_pixel(0, 0).0;
        assert!(grey.iter().all(|&c| (c as i32 - 128).abs() <= 2), "{grey:?}");
        let red = img.get_pixel(2, 0).0;
        assert!(red[0] > 240 && red[1] < 15 && red[2] < 15, "{red:?}");
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
