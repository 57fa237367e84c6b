//! Frames that arrive as RGB (the simulator, PNG files): the region copied, or box-averaged at a smaller scale.

use image::RgbImage;

use super::{output_region, DecodeError, DecodeOptions, DecodedFrame, Scale};

pub(super) fn decode(frame: &RgbImage, options: &DecodeOptions) -> Result<DecodedFrame, DecodeError> {
    let (width, height) = frame.dimensions();
    let (region, decoded) = output_region(options, width, height)?;
    let done = |image| DecodedFrame {
        image,
        scale: options.scale,
        decoded,
        frame_width: width,
        frame_height: height,
    };
    if options.scale == Scale::Full && options.region.is_none() {
        return Ok(done(frame.clone()));
    }
    let (out_width, out_height) = options.scale.apply(width, height);
    let mut image = RgbImage::new(out_width, out_height);
    let d = options.scale.divisor() as usize;
    let (src, out) = (frame.as_raw(), image.as_mut());
    if options.scale == Scale::Full {
        // The region's rows copied as they are: nothing to average.
        let row = width as usize * 3;
        let (x0, x1) = (region.x as usize * 3, (region.x + region.width) as usize * 3);
        for y in region.y as usize..(region.y + region.height) as usize {
            out[y * row + x0..y * row + x1].copy_from_slice(&src[y * row + x0..y * row + x1]);
        }
        return Ok(done(image));
    }
    for oy in region.y as usize..(region.y + region.height) as usize {
        let rows = oy * d..((oy + 1) * d).min(height as usize);
        for ox in region.x as usize..(region.x + region.width) as usize {
            let columns = ox * d..((ox + 1) * d).min(width as usize);
            let mut sum = [0u32; 3];
            for y in rows.clone() {
                for px in src[(y * width as usize + columns.start) * 3..(y * width as usize + columns.end) * 3]
                    .chunks_exact(3)
                {
                    sum.iter_mut().zip(px).for_each(|(s, &c)| *s += u32::from(c));
                }
            }
            let n = (rows.len() * columns.len()) as u32;
            let at = (oy * out_width as usize + ox) * 3;
            for (o, s) in out[at..at + 3].iter_mut().zip(sum) {
                *o = ((s + n / 2) / n) as u8;
            }
        }
    }
    Ok(done(image))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decode::PixelRect;

    #[test]
    fn half_scale_is_the_mean_of_each_two_by_two_block() {
        let frame = RgbImage::from_fn(4, 4, |x, y| image::Rgb([(x * 10) as u8, (y * 20) as u8, 7]));
        let decoded = decode(&frame, &DecodeOptions::scaled(Scale::Half)).unwrap();
        assert_eq!(decoded.image.dimensions(), (2, 2));
        assert_eq!(decoded.image.get_pixel(1, 1).0, [25, 50, 7]);
        let region = DecodeOptions {
            scale: Scale::Full,
            region: Some(PixelRect {
                x: 1,
                y: 1,
                width: 1,
                height: 2,
            }),
        };
        let cropped = decode(&frame, &region).unwrap();
        for (x, y, pixel) in cropped.image.enumerate_pixels() {
            let inside = x == 1 && (1..3).contains(&y);
            let expected = if inside { frame.get_pixel(x, y).0 } else { [0, 0, 0] };
            assert_eq!(pixel.0, expected, "({x}, {y})");
        }
    }
}
