//! The published edge stage: bilateral filter, Sobel magnitude, binary threshold, dilation then erosion.
//!
//! The bilateral filter is our own code rather than `imageproc::filter::bilateral_filter`, because the latter
//! differs from OpenCV's `bilateralFilter` in ways that change which pixels pass the threshold downstream: it
//! uses a square window (OpenCV: a disc of radius d/2), clamps at the border (OpenCV: reflect-101), approximates
//! exp(), and truncates instead of rounding. The same border rule is why the 3x3 Sobel is written here too.
//! Morphology uses imageproc, which matches OpenCV's 3x3 rectangle including its border behaviour.

use image::GrayImage;
use imageproc::distance_transform::Norm;

/// Parameters of OpenCV's `bilateralFilter(src, d, sigmaColor, sigmaSpace)` for 8-bit grey images.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bilateral {
    pub diameter: u32,
    pub sigma_color: f64,
    pub sigma_space: f64,
}

/// OpenCV's BORDER_REFLECT_101 (gfedcb|abcdefgh|gfedcba) for an index `i` in a line of `n` samples.
fn reflect_101(i: i64, n: i64) -> usize {
    if n == 1 {
        return 0;
    }
    let period = 2 * (n - 1);
    let mut j = i.rem_euclid(period);
    if j >= n {
        j = period - j;
    }
    j as usize
}

impl Bilateral {
    pub fn apply(&self, src: &GrayImage) -> GrayImage {
        let (w, h) = (src.width() as usize, src.height() as usize);
        if w == 0 || h == 0 {
            return src.clone();
        }
        let sigma_color = if self.sigma_color <= 0.0 { 1.0 } else { self.sigma_color };
        let sigma_space = if self.sigma_space <= 0.0 { 1.0 } else { self.sigma_space };
        let radius = (self.diameter / 2).max(1) as i64;
        let color_coeff = -0.5 / (sigma_color * sigma_color);
        let space_coeff = -0.5 / (sigma_space * sigma_space);
        let color_weight: Vec<f32> = (0..256).map(|d| ((d * d) as f64 * color_coeff).exp() as f32).collect();

        // Padded copy so the inner loop never branches on the border.
        let pad = radius as usize;
        let pw = w + 2 * pad;
        let ph = h + 2 * pad;
        let raw = src.as_raw();
        let mut padded = vec![0u8; pw * ph];
        for py in 0..ph {
            let sy = reflect_101(py as i64 - radius, h as i64);
            for px in 0..pw {
                let sx = reflect_101(px as i64 - radius, w as i64);
                padded[py * pw + px] = raw[sy * w + sx];
            }
        }

        // The disc of OpenCV's kernel: offsets with distance <= radius.
        let mut taps: Vec<(usize, f32)> = Vec::new();
        for dy in -radius..=radius {
            for dx in -radius..=radius {
                let r = ((dx * dx + dy * dy) as f64).sqrt();
                if r > radius as f64 {
                    continue;
                }
                let offset = ((dy + radius) as usize) * pw + (dx + radius) as usize;
                taps.push((offset, (r * r * space_coeff).exp() as f32));
            }
        }

        // Row at a time, tap by tap: the per-pixel sums see the taps in the same order as a per-pixel loop would
        // (so the result is identical), but the row walk keeps memory access sequential.
        let mut out = vec![0u8; w * h];
        let mut sum = vec![0f32; w];
        let mut weight_sum = vec![0f32; w];
        for y in 0..h {
            sum.fill(0.0);
            weight_sum.fill(0.0);
            let centre = &padded[(y + pad) * pw + pad..][..w];
            for &(offset, ws) in &taps {
                let window = &padded[y * pw + offset..][..w];
                for x in 0..w {
                    let value = window[x];
                    let weight = ws * color_weight[usize::from(value.abs_diff(centre[x]))];
                    sum[x] += weight * f32::from(value);
                    weight_sum[x] += weight;
                }
            }
            for x in 0..w {
                out[y * w + x] = (sum[x] / weight_sum[x]).round_ties_even().clamp(0.0, 255.0) as u8;
            }
        }
        GrayImage::from_raw(w as u32, h as u32, out).expect("sized from the source")
    }
}

/// `addWeighted(|Sobel_x|, wx, |Sobel_y|, wy, 0)` followed by `threshold(.., t, 255, THRESH_BINARY)`, with
/// OpenCV's 3x3 Sobel (reflect-101 border) and 8-bit saturation and rounding at each step.
pub fn sobel_threshold(src: &GrayImage, weight_x: f32, weight_y: f32, threshold: u8) -> GrayImage {
    let (w, h) = (src.width() as usize, src.height() as usize);
    let raw = src.as_raw();
    let at = |x: i64, y: i64| i32::from(raw[reflect_101(y, h as i64) * w + reflect_101(x, w as i64)]);
    let mut out = vec![0u8; w * h];
    for y in 0..h as i64 {
        for x in 0..w as i64 {
            let gx = (at(x + 1, y - 1) - at(x - 1, y - 1))
                + 2 * (at(x + 1, y) - at(x - 1, y))
                + (at(x + 1, y + 1) - at(x - 1, y + 1));
            let gy = (at(x - 1, y + 1) - at(x - 1, y - 1))
                + 2 * (at(x, y + 1) - at(x, y - 1))
                + (at(x + 1, y + 1) - at(x + 1, y - 1));
            let ax = gx.unsigned_abs().min(255) as f32;
            let ay = gy.unsigned_abs().min(255) as f32;
            let combined = (ax * weight_x + ay * weight_y).round_ties_even().clamp(0.0, 255.0) as u8;
            out[y as usize * w + x as usize] = if combined > threshold { 255 } else { 0 };
        }
    }
    GrayImage::from_raw(w as u32, h as u32, out).expect("sized from the source")
}

/// 3x3 dilation then 3x3 erosion (a closing with a square element), as the paper does it.
pub fn close_3x3(binary: &GrayImage) -> GrayImage {
    let dilated = imageproc::morphology::dilate(binary, Norm::LInf, 1);
    imageproc::morphology::erode(&dilated, Norm::LInf, 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reflect_101_mirrors_without_repeating_the_edge() {
        let n = 5;
        let got: Vec<usize> = (-3..8).map(|i| reflect_101(i, n)).collect();
        assert_eq!(got, vec![3, 2, 1, 0, 1, 2, 3, 4, 3, 2, 1]);
        assert_eq!(reflect_101(-4, 1), 0);
    }

    #[test]
    fn bilateral_keeps_a_step_and_flattens_noise() {
        // A step of 200 grey levels is far beyond sigma_color: it must survive; +-4 ripple must be smoothed.
        let img = GrayImage::from_fn(40, 20, |x, y| {
            let base = if x < 20 { 20u8 } else { 220u8 };
            image::Luma([if (x + y) % 2 == 0 { base + 4 } else { base - 4 }])
        });
        let filtered = Bilateral {
            diameter: 6,
            sigma_color: 20.0,
            sigma_space: 5.0,
        }
        .apply(&img);
        assert!((i32::from(filtered.get_pixel(5, 10).0[0]) - 20).abs() <= 1);
        assert!((i32::from(filtered.get_pixel(35, 10).0[0]) - 220).abs() <= 1);
        assert!(filtered.get_pixel(19, 10).0[0] < 40 && filtered.get_pixel(20, 10).0[0] > 200);
    }

    #[test]
    fn bilateral_of_constant_image_is_identity() {
        let img = GrayImage::from_pixel(13, 7, image::Luma([77]));
        let filtered = Bilateral {
            diameter: 20,
            sigma_color: 65.0,
            sigma_space: 75.0,
        }
        .apply(&img);
        assert_eq!(filtered, img);
    }

    #[test]
    fn sobel_threshold_marks_edges_only() {
        let img = GrayImage::from_fn(10, 10, |x, _| image::Luma([if x < 5 { 0 } else { 100 }]));
        let edges = sobel_threshold(&img, 0.86, 0.86, 19);
        assert_eq!(edges.get_pixel(4, 5).0[0], 255);
        assert_eq!(edges.get_pixel(5, 5).0[0], 255);
        assert_eq!(edges.get_pixel(1, 5).0[0], 0);
        assert_eq!(edges.get_pixel(8, 5).0[0], 0);
        // Reflect-101 at the border: a flat image edge is no gradient.
        assert_eq!(edges.get_pixel(0, 0).0[0], 0);
    }

    #[test]
    fn threshold_follows_rounding_of_weighted_sum() {
        // |gx| = 4 * 6 = 24 -> 0.86 * 24 = 20.6 -> 21 > 19; a step of 5 gives |gx| = 20 -> 17 -> not an edge.
        let step = |s: u8| GrayImage::from_fn(6, 6, move |x, _| image::Luma([if x < 3 { 50 } else { 50 + s }]));
        assert_eq!(sobel_threshold(&step(6), 0.86, 0.86, 19).get_pixel(2, 3).0[0], 255);
        assert_eq!(sobel_threshold(&step(5), 0.86, 0.86, 19).get_pixel(2, 3).0[0], 0);
    }

    #[test]
    fn closing_fills_a_one_pixel_gap_and_keeps_the_border() {
        let mut img = GrayImage::from_fn(9, 5, |_, y| image::Luma([if y == 2 { 255 } else { 0 }]));
        img.put_pixel(4, 2, image::Luma([0]));
        let closed = close_3x3(&img);
        assert_eq!(closed.get_pixel(4, 2).0[0], 255);
        assert_eq!(
            closed.get_pixel(0, 2).0[0],
            255,
            "erosion must not eat the line where it meets the border"
        );
        assert_eq!(closed.get_pixel(4, 0).0[0], 0);
    }
}
