//! Decoding only what the estimator needs: a frame at a power-of-two scale (the JPEG's own scaled IDCT, or a box
//! average for YUYV and RGB frames) and only inside a region of interest, everything outside it left black.
//!
//! The estimator's fast mode samples a cell at about 36 points across (detection's `SAMPLES_PER_CELL`), so a
//! 2048x1536 frame whose cells are 90 px wide carries more pixels than it reads; the lattice spans about half
//! the frame. A JPEG must still be entropy-decoded in full up to the region's last row (no restart markers in a
//! webcam's MJPEG), which is the floor of any JPEG path: `nusense bench` measures it beside the decode modes.

mod jpeg;
mod rgb;
mod yuyv;

use image::RgbImage;
use serde::{Deserialize, Serialize};

pub use yuyv::{rgb_to_yuyv, yuyv_to_rgb};

use crate::FramePixels;

/// The output size as a fraction of the frame's: 1/1, 1/2, 1/4 or 1/8 (the factors a JPEG's IDCT scales by
/// for free).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(try_from = "u32", into = "u32")]
pub enum Scale {
    #[default]
    Full,
    Half,
    Quarter,
    Eighth,
}

impl Scale {
    pub const ALL: [Scale; 4] = [Scale::Full, Scale::Half, Scale::Quarter, Scale::Eighth];

    /// Frame pixels per output pixel along each axis.
    pub fn divisor(self) -> u32 {
        match self {
            Scale::Full => 1,
            Scale::Half => 2,
            Scale::Quarter => 4,
            Scale::Eighth => 8,
        }
    }

    pub fn from_divisor(divisor: u32) -> Option<Self> {
        Scale::ALL.into_iter().find(|s| s.divisor() == divisor)
    }

    /// The output size of a `width` x `height` frame (rounded up, as a JPEG decoder rounds).
    pub fn apply(self, width: u32, height: u32) -> (u32, u32) {
        let d = self.divisor();
        (width.div_ceil(d), height.div_ceil(d))
    }
}

impl From<Scale> for u32 {
    fn from(scale: Scale) -> u32 {
        scale.divisor()
    }
}

impl TryFrom<u32> for Scale {
    type Error = String;

    fn try_from(divisor: u32) -> Result<Self, Self::Error> {
        Scale::from_divisor(divisor).ok_or_else(|| format!("decode scale 1/{divisor} is not one of 1/1, 1/2, 1/4, 1/8"))
    }
}

impl std::str::FromStr for Scale {
    type Err = String;

    /// `1`, `2`, `4`, `8`, or the same as `1/2`-style fractions.
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let divisor = text.trim().strip_prefix("1/").unwrap_or(text.trim());
        let divisor: u32 = divisor
            .parse()
            .map_err(|_| format!("`{text}` is not a decode scale; allowed: 1, 2, 4, 8 (or 1/2, 1/4, 1/8)"))?;
        Scale::try_from(divisor)
    }
}

impl std::fmt::Display for Scale {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "1/{}", self.divisor())
    }
}

/// A rectangle of the frame in full-size raw px: `x..x + width`, `y..y + height`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct PixelRect {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
}

impl PixelRect {
    pub fn whole(width: u32, height: u32) -> Self {
        Self {
            x: 0,
            y: 0,
            width,
            height,
        }
    }

    /// The smallest rectangle holding `[x0, y0]..[x1, y1]` (raw px, any order), clipped to the frame; `None` when
    /// nothing of it is inside the frame or a bound is not finite.
    pub fn from_bounds(min: [f64; 2], max: [f64; 2], frame: (u32, u32)) -> Option<Self> {
        if !(min.iter().chain(&max).all(|v| v.is_finite())) {
            return None;
        }
        let clamp = |v: f64, limit: u32| v.clamp(0.0, f64::from(limit));
        let (x0, x1) = (
            clamp(min[0].min(max[0]).floor(), frame.0),
            clamp(min[0].max(max[0]).ceil(), frame.0),
        );
        let (y0, y1) = (
            clamp(min[1].min(max[1]).floor(), frame.1),
            clamp(min[1].max(max[1]).ceil(), frame.1),
        );
        (x1 > x0 && y1 > y0).then_some(Self {
            x: x0 as u32,
            y: y0 as u32,
            width: (x1 - x0) as u32,
            height: (y1 - y0) as u32,
        })
    }

    /// [`PixelRect::from_bounds`] for bounds in px of the frame decoded at `scale` (an estimator's region found
    /// in a scaled frame), back in the full frame's raw px.
    pub fn from_scaled_bounds(min: [f64; 2], max: [f64; 2], scale: Scale, frame: (u32, u32)) -> Option<Self> {
        let d = f64::from(scale.divisor());
        Self::from_bounds([min[0] * d, min[1] * d], [max[0] * d, max[1] * d], frame)
    }

    fn right(&self) -> u32 {
        self.x + self.width
    }

    fn bottom(&self) -> u32 {
        self.y + self.height
    }

    /// This rectangle clipped to a `width` x `height` frame.
    pub fn clipped(&self, width: u32, height: u32) -> Option<Self> {
        let (x0, y0) = (self.x.min(width), self.y.min(height));
        let (x1, y1) = (self.right().min(width), self.bottom().min(height));
        (x1 > x0 && y1 > y0).then(|| Self {
            x: x0,
            y: y0,
            width: x1 - x0,
            height: y1 - y0,
        })
    }

    /// The rectangle of output pixels at `scale` that hold any of it (grown outwards to whole output pixels).
    fn scaled(&self, scale: Scale) -> Self {
        let d = scale.divisor();
        let (x0, y0) = (self.x / d, self.y / d);
        let (x1, y1) = (self.right().div_ceil(d), self.bottom().div_ceil(d));
        Self {
            x: x0,
            y: y0,
            width: x1 - x0,
            height: y1 - y0,
        }
    }

    /// An output-pixel rectangle at `scale` back in frame px (clipped to the frame).
    fn unscaled(&self, scale: Scale, frame: (u32, u32)) -> Self {
        let d = scale.divisor();
        let x1 = (self.right() * d).min(frame.0);
        let y1 = (self.bottom() * d).min(frame.1);
        Self {
            x: self.x * d,
            y: self.y * d,
            width: x1 - self.x * d,
            height: y1 - self.y * d,
        }
    }
}

/// How much of a frame to decode.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DecodeOptions {
    pub scale: Scale,
    /// Full-size raw px; `None` decodes the whole frame.
    pub region: Option<PixelRect>,
}

impl DecodeOptions {
    /// The whole frame at full size (the dashboard's picture, a recording's first frame).
    pub const FULL: DecodeOptions = DecodeOptions {
        scale: Scale::Full,
        region: None,
    };

    pub fn scaled(scale: Scale) -> Self {
        Self { scale, region: None }
    }
}

/// A decoded frame.
#[derive(Clone, Debug)]
pub struct DecodedFrame {
    /// The whole frame at `scale` (size [`Scale::apply`] of the frame's); black outside `decoded`. A point at
    /// `(x, y)` here is at `(x, y) * scale.divisor()` in the full frame (raw px, origin at the top-left corner).
    pub image: RgbImage,
    pub scale: Scale,
    /// Full-size raw px actually decoded: the region asked for, grown to the codec's block grid and clipped.
    pub decoded: PixelRect,
    /// The frame's own (full) size.
    pub frame_width: u32,
    pub frame_height: u32,
}

/// Why a frame could not be decoded.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DecodeError {
    #[error("the JPEG ends before its image data does (truncated frame)")]
    Truncated,
    #[error("corrupt JPEG: {0}")]
    Corrupt(String),
    #[error("unsupported JPEG: {0}")]
    Unsupported(String),
    #[error("not a JPEG (no start-of-image marker)")]
    NotJpeg,
    #[error("short {format} frame: {found} bytes for {width}x{height} (needs {needed})")]
    Short {
        format: &'static str,
        width: u32,
        height: u32,
        found: usize,
        needed: usize,
    },
    #[error("a {width}x{height} YUYV frame needs an even width")]
    OddYuyvWidth { width: u32, height: u32 },
    #[error("the region asked for ({region:?}) lies outside the {width}x{height} frame")]
    RegionOutside { region: PixelRect, width: u32, height: u32 },
}

/// Decodes frames; holds the JPEG codec's state between frames so that each frame allocates little. One per
/// thread (it is `Send`, not `Sync`).
#[derive(Default)]
pub struct Decoder {
    jpeg: Option<jpeg::JpegDecoder>,
}

impl Decoder {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn decode(&mut self, pixels: &FramePixels, options: &DecodeOptions) -> Result<DecodedFrame, DecodeError> {
        match pixels {
            FramePixels::Jpeg(bytes) => self
                .jpeg
                .get_or_insert_with(jpeg::JpegDecoder::new)
                .decode(bytes, options),
            FramePixels::Yuyv { bytes, width, height } => yuyv::decode(bytes, *width, *height, options),
            FramePixels::Rgb(image) => rgb::decode(image, options),
        }
    }
}

/// The region to decode at `scale` in output px, and the same in frame px; errors when it misses the frame.
fn output_region(options: &DecodeOptions, width: u32, height: u32) -> Result<(PixelRect, PixelRect), DecodeError> {
    let region = match options.region {
        None => PixelRect::whole(width, height),
        Some(region) => region
            .clipped(width, height)
            .ok_or(DecodeError::RegionOutside { region, width, height })?,
    };
    let scaled = region.scaled(options.scale);
    Ok((scaled, scaled.unscaled(options.scale, (width, height))))
}

/// The width and height in a JPEG's start-of-frame header, without decoding anything.
pub fn jpeg_dimensions(bytes: &[u8]) -> Result<(u32, u32), DecodeError> {
    jpeg::dimensions(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scales_parse_and_round_up_like_a_jpeg_decoder() {
        assert_eq!("1/4".parse::<Scale>(), Ok(Scale::Quarter));
        assert_eq!("2".parse::<Scale>(), Ok(Scale::Half));
        assert!("3".parse::<Scale>().is_err());
        assert!("half".parse::<Scale>().is_err());
        assert_eq!(Scale::Eighth.apply(2048, 1536), (256, 192));
        assert_eq!(Scale::Quarter.apply(642, 481), (161, 121));
    }

    #[test]
    fn regions_grow_to_whole_output_pixels_and_clip_to_the_frame() {
        let region = PixelRect {
            x: 5,
            y: 9,
            width: 10,
            height: 100,
        };
        let (scaled, frame_px) = output_region(
            &DecodeOptions {
                scale: Scale::Quarter,
                region: Some(region),
            },
            64,
            48,
        )
        .expect("inside");
        assert_eq!(
            scaled,
            PixelRect {
                x: 1,
                y: 2,
                width: 3,
                height: 10
            }
        );
        assert_eq!(
            frame_px,
            PixelRect {
                x: 4,
                y: 8,
                width: 12,
                height: 40
            }
        );
        let outside = PixelRect {
            x: 70,
            y: 0,
            width: 4,
            height: 4,
        };
        assert!(matches!(
            output_region(
                &DecodeOptions {
                    scale: Scale::Full,
                    region: Some(outside)
                },
                64,
                48
            ),
            Err(DecodeError::RegionOutside { .. })
        ));
        assert_eq!(
            PixelRect::from_bounds([10.4, 20.6], [-3.0, 60.2], (50, 50)),
            Some(PixelRect {
                x: 0,
                y: 20,
                width: 11,
                height: 30
            })
        );
        assert_eq!(PixelRect::from_bounds([f64::NAN, 0.0], [1.0, 1.0], (50, 50)), None);
    }
}
