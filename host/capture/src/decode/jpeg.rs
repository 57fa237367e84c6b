//! JPEG through libjpeg-turbo (built from source by mozjpeg-sys, with its SIMD when nasm is installed): the
//! IDCT scaled to 1/2, 1/4 or 1/8, the columns outside the region cropped (`jpeg_crop_scanline`), the rows
//! above it skipped without IDCT (`jpeg_skip_scanlines`) and nothing read below it.
//!
//! libjpeg reports errors by calling `error_exit`, which must not return; here it unwinds (mozjpeg-sys builds
//! the C code with unwind tables for this) back to `decode`, which turns it into a [`DecodeError`]. Warnings
//! (corrupt entropy data, a premature end of file) unwind the same way: a frame with grey-filled rows would
//! give a wrong lattice, not a noisy one.

use std::ffi::{c_int, c_ulong};
use std::panic::{catch_unwind, resume_unwind, AssertUnwindSafe};

use image::RgbImage;
use mozjpeg_sys as ffi;

use super::{output_region, DecodeError, DecodeOptions, DecodedFrame};

/// What libjpeg complained about; the unwinding payload.
struct Failure {
    code: c_int,
    message: String,
}

impl From<Failure> for DecodeError {
    fn from(failure: Failure) -> Self {
        match failure.code as ffi::J_MESSAGE_CODE {
            ffi::JWRN_JPEG_EOF | ffi::JERR_INPUT_EMPTY | ffi::JERR_INPUT_EOF => DecodeError::Truncated,
            ffi::JERR_CONVERSION_NOTIMPL | ffi::JERR_NOT_COMPILED | ffi::JERR_ARITH_NOTIMPL => {
                DecodeError::Unsupported(failure.message)
            }
            _ => DecodeError::Corrupt(failure.message),
        }
    }
}

unsafe fn failure(cinfo: &mut ffi::jpeg_common_struct) -> Failure {
    let err = &*cinfo.err;
    let code = err.msg_code;
    let mut buffer = [0u8; 80];
    let at = buffer.as_mut_ptr();
    if let Some(format) = err.format_message {
        format(cinfo, &*(at as *const [u8; 80]));
    }
    let written = std::slice::from_raw_parts(at, 80);
    let end = written.iter().position(|&b| b == 0).unwrap_or(written.len());
    Failure {
        code,
        message: String::from_utf8_lossy(&written[..end]).into_owned(),
    }
}

unsafe extern "C-unwind" fn error_exit(cinfo: &mut ffi::jpeg_common_struct) {
    // resume_unwind, not panic!: no panic hook, no backtrace in the log for a bad frame.
    resume_unwind(Box::new(failure(cinfo)))
}

unsafe extern "C-unwind" fn emit_message(cinfo: &mut ffi::jpeg_common_struct, level: c_int) {
    if level < 0 {
        resume_unwind(Box::new(failure(cinfo)))
    }
}

pub(crate) struct JpegDecoder {
    // Boxed: libjpeg keeps pointers to both.
    cinfo: Box<ffi::jpeg_decompress_struct>,
    _err: Box<ffi::jpeg_error_mgr>,
    /// Row pointers for one `jpeg_read_scanlines` call.
    rows: Vec<*mut u8>,
}

// The codec state is owned here alone and used from one thread at a time.
unsafe impl Send for JpegDecoder {}

/// Most rows libjpeg hands out per call (its `rec_outbuf_height` is at most 4).
const ROWS_PER_CALL: usize = 16;

impl JpegDecoder {
    pub(crate) fn new() -> Self {
        // SAFETY: both structs are plain C data that libjpeg initialises; zeroed is how C callers start them.
        unsafe {
            let mut err: Box<ffi::jpeg_error_mgr> = Box::new(std::mem::zeroed());
            let mut cinfo: Box<ffi::jpeg_decompress_struct> = Box::new(std::mem::zeroed());
            cinfo.common.err = ffi::jpeg_std_error(&mut err);
            err.error_exit = Some(error_exit);
            err.emit_message = Some(emit_message);
            ffi::jpeg_create_decompress(&mut *cinfo);
            Self {
                cinfo,
                _err: err,
                rows: vec![std::ptr::null_mut(); ROWS_PER_CALL],
            }
        }
    }

    pub(crate) fn decode(&mut self, bytes: &[u8], options: &DecodeOptions) -> Result<DecodedFrame, DecodeError> {
        if !bytes.starts_with(&[0xFF, 0xD8]) {
            return Err(DecodeError::NotJpeg);
        }
        let outcome = catch_unwind(AssertUnwindSafe(|| unsafe { self.run(bytes, options) }));
        // SAFETY: aborting is valid in every state of the decompressor, and stops it reading `bytes`.
        unsafe { ffi::jpeg_abort_decompress(&mut self.cinfo) };
        match outcome {
            Ok(result) => result,
            Err(payload) => match payload.downcast::<Failure>() {
                Ok(failure) => Err((*failure).into()),
                Err(other) => resume_unwind(other),
            },
        }
    }

    /// # Safety
    /// `bytes` outlives the call (libjpeg reads it in place until `jpeg_abort_decompress`).
    unsafe fn run(&mut self, bytes: &[u8], options: &DecodeOptions) -> Result<DecodedFrame, DecodeError> {
        let cinfo = &mut *self.cinfo;
        ffi::jpeg_mem_src(cinfo, bytes.as_ptr(), bytes.len() as c_ulong);
        // jpeglib.h: JPEG_HEADER_OK is 1 (2 would be a tables-only stream).
        if ffi::jpeg_read_header(cinfo, 1) != 1 {
            return Err(DecodeError::Corrupt("no image in the JPEG stream (tables only)".into()));
        }
        let (frame_width, frame_height) = (cinfo.image_width, cinfo.image_height);
        let (region, decoded) = output_region(options, frame_width, frame_height)?;
        cinfo.scale_num = 1;
        cinfo.scale_denom = options.scale.divisor();
        cinfo.out_color_space = ffi::J_COLOR_SPACE::JCS_RGB;
        // At full size a 4:2:0 or 4:2:2 frame's chroma is interpolated between its samples (libjpeg's default):
        // replicating it instead shifts it half a pixel wherever the estimator samples every other pixel, which
        // moves every corner by 0.7 px. At 1/2 scale and below the scaled IDCT yields chroma at the output's own
        // resolution and nothing is upsampled.
        cinfo.do_fancy_upsampling = 1;
        ffi::jpeg_start_decompress(cinfo);
        let (width, height) = (cinfo.output_width, cinfo.output_height);
        let mut image = RgbImage::new(width, height);
        let (mut x0, mut columns) = (region.x, region.width);
        if columns < width {
            // Grows the range outwards to whole iMCU columns; output rows are then `columns` wide.
            ffi::jpeg_crop_scanline(cinfo, &mut x0, &mut columns);
        }
        let y_end = (region.y + region.height).min(height);
        if region.y > 0 {
            ffi::jpeg_skip_scanlines(cinfo, region.y);
        }
        let base = image.as_mut_ptr();
        while cinfo.output_scanline < y_end {
            let y = cinfo.output_scanline as usize;
            let wanted = (y_end as usize - y).min(ROWS_PER_CALL);
            for (k, row) in self.rows.iter_mut().take(wanted).enumerate() {
                // SAFETY: row y + k < height, and x0 + columns <= width, so the row's bytes lie in `image`.
                *row = base.add(((y + k) * width as usize + x0 as usize) * 3);
            }
            if ffi::jpeg_read_scanlines(cinfo, self.rows.as_mut_ptr(), wanted as u32) == 0 {
                return Err(DecodeError::Truncated);
            }
        }
        let decoded_x = x0 * options.scale.divisor();
        let decoded = super::PixelRect {
            x: decoded_x,
            width: ((x0 + columns) * options.scale.divisor()).min(frame_width) - decoded_x,
            ..decoded
        };
        Ok(DecodedFrame {
            image,
            scale: options.scale,
            decoded,
            frame_width,
            frame_height,
        })
    }
}

impl Drop for JpegDecoder {
    fn drop(&mut self) {
        // SAFETY: created in `new`, destroyed once.
        unsafe { ffi::jpeg_destroy_decompress(&mut self.cinfo) };
    }
}

/// Width and height from the start-of-frame marker, walking the marker segments before it.
pub(crate) fn dimensions(bytes: &[u8]) -> Result<(u32, u32), DecodeError> {
    if !bytes.starts_with(&[0xFF, 0xD8]) {
        return Err(DecodeError::NotJpeg);
    }
    let mut at = 2;
    loop {
        // Markers may be preceded by any number of 0xFF fill bytes.
        while bytes.get(at) == Some(&0xFF) && bytes.get(at + 1) == Some(&0xFF) {
            at += 1;
        }
        let (Some(&0xFF), Some(&marker)) = (bytes.get(at), bytes.get(at + 1)) else {
            return Err(if at >= bytes.len() {
                DecodeError::Truncated
            } else {
                DecodeError::Corrupt("no marker where one must be".into())
            });
        };
        at += 2;
        if (0xD0..=0xD7).contains(&marker) || marker == 0x01 {
            continue;
        }
        let length = match bytes.get(at..at + 2) {
            Some(l) => usize::from(u16::from_be_bytes([l[0], l[1]])),
            None => return Err(DecodeError::Truncated),
        };
        let is_frame_header = (0xC0..=0xCF).contains(&marker) && !matches!(marker, 0xC4 | 0xC8 | 0xCC);
        if is_frame_header {
            let header = bytes.get(at + 2..at + 7).ok_or(DecodeError::Truncated)?;
            let height = u32::from(u16::from_be_bytes([header[1], header[2]]));
            let width = u32::from(u16::from_be_bytes([header[3], header[4]]));
            if width == 0 || height == 0 {
                return Err(DecodeError::Unsupported(format!("frame header says {width}x{height}")));
            }
            return Ok((width, height));
        }
        if marker == 0xDA || marker == 0xD9 {
            return Err(DecodeError::Corrupt("image data before any frame header".into()));
        }
        at += length;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decode::{PixelRect, Scale};

    fn real_frame() -> Vec<u8> {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../estimator/tests/data/real/reference_fisheye.jpg"
        );
        std::fs::read(path).expect("the real pair ships with the project")
    }

    fn mean_abs_difference(a: &RgbImage, b: &RgbImage) -> f64 {
        assert_eq!(a.dimensions(), b.dimensions());
        let sum: u64 = a
            .as_raw()
            .iter()
            .zip(b.as_raw())
            .map(|(&x, &y)| u64::from(x.abs_diff(y)))
            .sum();
        sum as f64 / a.as_raw().len() as f64
    }

    #[test]
    fn full_decode_matches_the_image_crate_and_scaled_decodes_match_its_block_means() {
        let bytes = real_frame();
        assert_eq!(dimensions(&bytes), Ok((2048, 1536)));
        let reference = image::load_from_memory(&bytes).unwrap().to_rgb8();
        let mut decoder = JpegDecoder::new();
        let full = decoder.decode(&bytes, &DecodeOptions::FULL).unwrap();
        assert_eq!(full.decoded, PixelRect::whole(2048, 1536));
        // Two decoders differ by rounding and chroma upsampling only.
        assert!(mean_abs_difference(&full.image, &reference) < 1.0);
        for scale in [Scale::Half, Scale::Quarter, Scale::Eighth] {
            let scaled = decoder.decode(&bytes, &DecodeOptions::scaled(scale)).unwrap();
            let block_means = crate::decode::rgb::decode(&reference, &DecodeOptions::scaled(scale))
                .unwrap()
                .image;
            let difference = mean_abs_difference(&scaled.image, &block_means);
            assert!(difference < 2.0, "{scale}: mean |difference| {difference}");
        }
    }

    #[test]
    fn a_region_decodes_exactly_what_the_whole_frame_has_there_and_nothing_else() {
        let bytes = real_frame();
        let mut decoder = JpegDecoder::new();
        let region = PixelRect {
            x: 333,
            y: 141,
            width: 1400,
            height: 1100,
        };
        // Interpolated chroma reads one row or column beyond the decoded ones, which a region decode lacks.
        let edge = 1;
        for scale in [Scale::Full, Scale::Half, Scale::Quarter] {
            let whole = decoder.decode(&bytes, &DecodeOptions::scaled(scale)).unwrap().image;
            let part = decoder
                .decode(
                    &bytes,
                    &DecodeOptions {
                        scale,
                        region: Some(region),
                    },
                )
                .unwrap();
            let d = scale.divisor();
            let got = part.decoded;
            assert!(got.x <= region.x && got.y <= region.y, "{scale}: {got:?}");
            assert!(got.x + got.width >= region.x + region.width && got.y + got.height >= region.y + region.height);
            assert!(
                got.width < 2048 && got.height < 1536,
                "{scale}: decoded no more than the block grid needs"
            );
            for (x, y, px) in part.image.enumerate_pixels() {
                let (fx, fy) = (x * d, y * d);
                let inside = fx >= got.x && fx < got.x + got.width && fy >= got.y && fy < got.y + got.height;
                let near_edge = fx < got.x + edge
                    || fy < got.y + edge
                    || fx + d + edge > got.x + got.width
                    || fy + d + edge > got.y + got.height;
                if inside {
                    if !near_edge {
                        assert_eq!(px, whole.get_pixel(x, y), "{scale}: ({x}, {y})");
                    }
                } else {
                    assert_eq!(px.0, [0, 0, 0], "{scale}: ({x}, {y}) outside the region");
                }
            }
        }
    }

    #[test]
    fn truncated_and_corrupt_frames_are_typed_errors_and_the_decoder_goes_on() {
        let bytes = real_frame();
        let mut decoder = JpegDecoder::new();
        let truncated = &bytes[..bytes.len() / 2];
        assert_eq!(
            decoder.decode(truncated, &DecodeOptions::FULL).unwrap_err(),
            DecodeError::Truncated
        );
        // A region that ends above the cut needs none of the missing data.
        let top = PixelRect {
            x: 0,
            y: 0,
            width: 2048,
            height: 256,
        };
        assert!(decoder
            .decode(
                truncated,
                &DecodeOptions {
                    scale: Scale::Half,
                    region: Some(top)
                }
            )
            .is_ok());
        assert_eq!(
            decoder.decode(&bytes[..400], &DecodeOptions::FULL).unwrap_err(),
            DecodeError::Truncated
        );

        // A marker in the middle of the entropy-coded data.
        let mut marked = bytes.clone();
        let middle = marked.len() / 2;
        marked[middle..middle + 2].copy_from_slice(&[0xFF, 0xD3]);
        assert!(matches!(
            decoder.decode(&marked, &DecodeOptions::FULL),
            Err(DecodeError::Corrupt(_))
        ));
        // A frame header that lies about its size.
        let mut bad_header = bytes.clone();
        let sof = bad_header.windows(2).position(|w| w == [0xFF, 0xC0]).unwrap();
        bad_header[sof + 5..sof + 9].copy_from_slice(&[0, 0, 0, 0]);
        assert!(matches!(
            decoder.decode(&bad_header, &DecodeOptions::FULL),
            Err(DecodeError::Corrupt(_))
        ));
        assert_eq!(
            decoder.decode(b"GIF89a", &DecodeOptions::FULL).unwrap_err(),
            DecodeError::NotJpeg
        );

        let after = decoder.decode(&bytes, &DecodeOptions::scaled(Scale::Eighth)).unwrap();
        assert_eq!(after.image.dimensions(), (256, 192));
    }

    #[test]
    fn dimensions_are_read_from_the_frame_header_alone() {
        let mut encoded = Vec::new();
        let image = RgbImage::from_pixel(40, 24, image::Rgb([200, 30, 60]));
        image::codecs::jpeg::JpegEncoder::new(&mut encoded)
            .encode_image(&image)
            .unwrap();
        assert_eq!(dimensions(&encoded), Ok((40, 24)));
        assert_eq!(dimensions(&encoded[..4]), Err(DecodeError::Truncated));
        assert_eq!(dimensions(b"\x89PNG"), Err(DecodeError::NotJpeg));
    }
}
