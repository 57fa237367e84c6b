//! The published first stage: the whole frame undistorted through the fisheye model with a bilinear remap, then
//! converted to grey the way OpenCV's `cvtColor(BGR2GRAY)` does.
//!
//! The remap reproduces OpenCV's `fisheye::initUndistortRectifyMap`, which reads K (cx = w/2, cy = h/2) and the
//! new camera matrix in pixel-*index* coordinates (origin at the top-left pixel's centre). Our raw-px convention
//! puts the origin at the pixel's corner, half a pixel away; evaluating the same formulas on pixel indices keeps
//! the image identical to the published one (checked against OpenCV: the remaining differences are its 1/32-px
//! fixed-point interpolation). [`index_to_raw_px`] converts the results back to our convention.
//!
//! Only the pixels inside the region of interest are ever read by the later stages, so the table covers exactly
//! those: the output is the same as remapping the whole frame and cropping, without computing pixels that are
//! thrown away. The table is built once per camera and frame size (the model inversion is the costly part).

use image::{GrayImage, RgbImage};
use nusense_geometry::{FisheyeCamera, Point2};

use super::RoiPx;

/// Where each ROI pixel of the undistorted frame samples the raw frame: the top-left neighbour and the
/// bilinear weights.
#[derive(Clone, Debug)]
pub struct RemapTable {
    roi: RoiPx,
    raw_width: u32,
    raw_height: u32,
    taps: Vec<RemapTap>,
}

#[derive(Clone, Copy, Debug)]
struct RemapTap {
    x0: i32,
    y0: i32,
    fx: f32,
    fy: f32,
}

impl RemapTable {
    pub fn new(camera: &FisheyeCamera, roi: RoiPx) -> Self {
        let mut taps = Vec::with_capacity(roi.width as usize * roi.height as usize);
        for row in 0..roi.height {
            for col in 0..roi.width {
                let source = camera.distort_px([f64::from(roi.x + col), f64::from(roi.y + row)]);
                taps.push(tap_for(source));
            }
        }
        Self {
            roi,
            raw_width: camera.width(),
            raw_height: camera.height(),
            taps,
        }
    }

    pub fn roi(&self) -> RoiPx {
        self.roi
    }

    /// The ROI of the undistorted frame in grey (OpenCV's BGR2GRAY weights and rounding).
    pub fn undistorted_gray(&self, frame: &RgbImage) -> GrayImage {
        debug_assert_eq!(frame.dimensions(), (self.raw_width, self.raw_height));
        let pixels: Vec<u8> = self.taps.iter().map(|tap| gray_of(bilinear_rgb(frame, tap))).collect();
        GrayImage::from_raw(self.roi.width, self.roi.height, pixels).expect("the table has one tap per ROI pixel")
    }
}

/// The bilinear tap at a source position in pixel-index coordinates.
fn tap_for(source: Point2) -> RemapTap {
    let [sx, sy] = source;
    if !(sx.is_finite() && sy.is_finite()) || sx.abs() > 1e6 || sy.abs() > 1e6 {
        // Outside the model: reads the constant (black) border like OpenCV's BORDER_CONSTANT.
        return RemapTap {
            x0: i32::MIN / 2,
            y0: i32::MIN / 2,
            fx: 0.0,
            fy: 0.0,
        };
    }
    let x0 = sx.floor();
    let y0 = sy.floor();
    RemapTap {
        x0: x0 as i32,
        y0: y0 as i32,
        fx: (sx - x0) as f32,
        fy: (sy - y0) as f32,
    }
}

/// Bilinear interpolation with a black constant border, rounded to 8 bits per channel like `cv::remap`.
fn bilinear_rgb(frame: &RgbImage, tap: &RemapTap) -> [u8; 3] {
    let (w, h) = (frame.width() as i32, frame.height() as i32);
    let (x0, y0) = (tap.x0, tap.y0);
    if x0 >= 0 && y0 >= 0 && x0 + 1 < w && y0 + 1 < h {
        // All four neighbours inside: read the buffer directly (the common case, and the hot loop).
        let raw = frame.as_raw();
        let stride = 3 * w as usize;
        let i = y0 as usize * stride + 3 * x0 as usize;
        let (fx, fy) = (tap.fx, tap.fy);
        let mut out = [0u8; 3];
        for ch in 0..3 {
            let a = f32::from(raw[i + ch]);
            let b = f32::from(raw[i + 3 + ch]);
            let c = f32::from(raw[i + stride + ch]);
            let d = f32::from(raw[i + stride + 3 + ch]);
            let top = a + (b - a) * fx;
            let bottom = c + (d - c) * fx;
            out[ch] = (top + (bottom - top) * fy).round().clamp(0.0, 255.0) as u8;
        }
        return out;
    }
    let fetch = |x: i32, y: i32| -> [f32; 3] {
        if x < 0 || y < 0 || x >= w || y >= h {
            [0.0; 3]
        } else {
            let p = frame.get_pixel(x as u32, y as u32).0;
            [f32::from(p[0]), f32::from(p[1]), f32::from(p[2])]
        }
    };
    let (a, b, c, d) = (
        fetch(x0, y0),
        fetch(x0 + 1, y0),
        fetch(x0, y0 + 1),
        fetch(x0 + 1, y0 + 1),
    );
    let (fx, fy) = (tap.fx, tap.fy);
    let mut out = [0u8; 3];
    for ch in 0..3 {
        let top = a[ch] + (b[ch] - a[ch]) * fx;
        let bottom = c[ch] + (d[ch] - c[ch]) * fx;
        out[ch] = (top + (bottom - top) * fy).round().clamp(0.0, 255.0) as u8;
    }
    out
}

/// OpenCV's fixed-point BGR2GRAY: 0.299 R + 0.587 G + 0.114 B in 14-bit fixed point with rounding.
pub fn gray_of(rgb: [u8; 3]) -> u8 {
    const R2Y: u32 = 4899;
    const G2Y: u32 = 9617;
    const B2Y: u32 = 1868;
    let [r, g, b] = rgb.map(u32::from);
    ((r * R2Y + g * G2Y + b * B2Y + (1 << 13)) >> 14) as u8
}

/// The colour of the undistorted frame at a position in its pixel-index coordinates (for the few samples the
/// lattice indexing needs; the bulk of the frame goes through [`RemapTable`]).
pub fn sample_undistorted_rgb(frame: &RgbImage, camera: &FisheyeCamera, undistorted_index: Point2) -> [u8; 3] {
    bilinear_rgb(frame, &tap_for(camera.distort_px(undistorted_index)))
}

/// A position of the undistorted frame in pixel-index coordinates (as the published pipeline sees it) to raw px
/// in our convention: through the same model as the remap, then half a pixel to the pixel-corner origin.
pub fn index_to_raw_px(camera: &FisheyeCamera, undistorted_index: Point2) -> Point2 {
    let raw_index = camera.distort_px(undistorted_index);
    [raw_index[0] + 0.5, raw_index[1] + 0.5]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gray_matches_opencv_fixed_point() {
        assert_eq!(gray_of([255, 255, 255]), 255);
        assert_eq!(gray_of([0, 0, 0]), 0);
        // 0.299 * 200 + 0.587 * 100 + 0.114 * 50 = 124.2
        assert_eq!(gray_of([200, 100, 50]), 124);
        assert_eq!(gray_of([255, 0, 0]), 76);
    }

    #[test]
    fn remap_of_a_flat_frame_is_flat_where_it_sees_the_frame_and_black_beyond() {
        let camera = FisheyeCamera::paper(64, 48).unwrap();
        let frame = RgbImage::from_pixel(64, 48, image::Rgb([90, 90, 90]));
        let roi = RoiPx {
            x: 0,
            y: 0,
            width: 64,
            height: 48,
        };
        let gray = RemapTable::new(&camera, roi).undistorted_gray(&frame);
        // Balance 1 keeps the farthest edge midpoints on the frame's edge; the others land inside, so parts of the
        // undistorted frame look past the raw frame: OpenCV fills them from its black constant border.
        let (mut inside, mut beyond) = (0, 0);
        for (x, y, p) in gray.enumerate_pixels() {
            let s = camera.distort_px([f64::from(x), f64::from(y)]);
            if s[0] >= 0.0 && s[1] >= 0.0 && s[0] <= 63.0 && s[1] <= 47.0 {
                assert_eq!(p.0[0], 90, "({x}, {y}) samples {s:?}");
                inside += 1;
            } else if s[0] <= -1.0 || s[1] <= -1.0 || s[0] >= 64.0 || s[1] >= 48.0 {
                assert_eq!(p.0[0], 0, "({x}, {y}) samples {s:?}");
                beyond += 1;
            }
        }
        assert!(inside > 2500 && beyond > 0, "{inside} inside, {beyond} beyond");
        assert_eq!(sample_undistorted_rgb(&frame, &camera, [-40.0, 24.0]), [0, 0, 0]);
        assert_eq!(sample_undistorted_rgb(&frame, &camera, [32.0, 24.0]), [90, 90, 90]);
    }
}
