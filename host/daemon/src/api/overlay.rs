//! Draws the lattice found in a frame, its shear field and its contacts onto the frame, for
//! `/api/v1/frame.jpg?overlay=1`, in the dashboard's colours.

use std::collections::HashMap;

use image::{Rgb, RgbImage};
use nusense_estimator::Reading;

const LATTICE: Rgb<u8> = Rgb([40, 255, 90]);
const SHEAR: Rgb<u8> = Rgb([0, 200, 255]);
/// Magenta: a colour the pad (yellow on red, black around it) never shows.
const CONTACT: Rgb<u8> = Rgb([255, 0, 255]);
/// Contact crosses are this many pixels thick, so that they survive JPEG's colour subsampling.
const CONTACT_THICKNESS: i32 = 3;
/// Shear arrows are drawn this many times longer than the displacement, so sub-pixel shear is visible.
const ARROW_GAIN: f64 = 4.0;

pub fn draw_overlay(image: &mut RgbImage, reading: &Reading) {
    let corners: HashMap<(u16, u16), [f64; 2]> = reading
        .shear_field
        .iter()
        .filter(|v| v.valid)
        .filter_map(|v| Some(((v.index.row, v.index.col), v.current_px?)))
        .collect();
    for (&(row, col), &p) in &corners {
        for neighbour in [(row + 1, col), (row, col + 1)] {
            if let Some(&q) = corners.get(&neighbour) {
                draw_line(image, p, q, LATTICE);
            }
        }
    }
    for v in reading.shear_field.iter().filter(|v| v.valid) {
        let (Some(r), Some(c)) = (v.reference_px, v.current_px) else {
            continue;
        };
        let tip = [r[0] + ARROW_GAIN * (c[0] - r[0]), r[1] + ARROW_GAIN * (c[1] - r[1])];
        draw_line(image, r, tip, SHEAR);
    }
    if let Some(c) = reading.contact_px() {
        let arm = (image.width().min(image.height()) as f64 / 30.0).max(4.0);
        for offset in 0..CONTACT_THICKNESS {
            let d = f64::from(offset - CONTACT_THICKNESS / 2);
            draw_line(image, [c[0] - arm, c[1] + d], [c[0] + arm, c[1] + d], CONTACT);
            draw_line(image, [c[0] + d, c[1] - arm], [c[0] + d, c[1] + arm], CONTACT);
        }
    }
}

/// A straight line, clipped to the image; non-finite ends draw nothing.
fn draw_line(image: &mut RgbImage, a: [f64; 2], b: [f64; 2], colour: Rgb<u8>) {
    if !(a.iter().chain(b.iter()).all(|v| v.is_finite())) {
        return;
    }
    let steps = (b[0] - a[0]).abs().max((b[1] - a[1]).abs()).ceil().clamp(1.0, 10_000.0) as usize;
    for i in 0..=steps {
        let t = i as f64 / steps as f64;
        let x = (a[0] + t * (b[0] - a[0])).floor();
        let y = (a[1] + t * (b[1] - a[1])).floor();
        if x >= 0.0 && y >= 0.0 && (x as u32) < image.width() && (y as u32) < image.height() {
            image.put_pixel(x as u32, y as u32, colour);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_are_clipped_and_nan_draws_nothing() {
        let mut image = RgbImage::new(10, 10);
        draw_line(&mut image, [-5.0, 5.5], [20.0, 5.5], LATTICE);
        assert!((0..10).all(|x| *image.get_pixel(x, 5) == LATTICE));
        let before = image.clone();
        draw_line(&mut image, [f64::NAN, 0.0], [5.0, 5.0], SHEAR);
        assert_eq!(image, before);
    }
}
