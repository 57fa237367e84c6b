//! The colour cue: the pad is yellow squares (red and green high, blue low) on red/magenta (green low, blue
//! mid) inside a dark frame. `min(R, G) - B` is high only on yellow, whatever the overall brightness, and the
//! split between "yellow" and "not yellow" is taken from each image by Otsu's method, never hard-coded.

/// Number of yellowness values (-255..=255), the length of a histogram and of a membership table.
pub const YELLOWNESS_BINS: usize = 511;

/// Membership of the yellow class for every yellowness value (bin = value + 255).
pub type MembershipTable = [f32; YELLOWNESS_BINS];

/// Yellowness of one RGB pixel, in -255..=255.
#[inline(always)]
pub fn yellowness(r: u8, g: u8, b: u8) -> i32 {
    i32::from(r.min(g)) - i32::from(b)
}

/// Histogram of yellowness values (bin = value + 255).
#[derive(Clone)]
pub struct Histogram {
    pub bins: [u32; YELLOWNESS_BINS],
}

impl Default for Histogram {
    fn default() -> Self {
        Self {
            bins: [0; YELLOWNESS_BINS],
        }
    }
}

impl Histogram {
    #[inline(always)]
    pub fn add(&mut self, value: i32) {
        self.bins[(value + 255) as usize] += 1;
    }

    pub fn total(&self) -> u64 {
        self.bins.iter().map(|&c| u64::from(c)).sum()
    }
}

/// Otsu's split of a histogram: the threshold (values > threshold are the upper class) and both class means.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OtsuSplit {
    pub threshold: f64,
    pub lower_mean: f64,
    pub upper_mean: f64,
}

impl OtsuSplit {
    /// The contrast between the classes, in yellowness units.
    pub fn contrast(&self) -> f64 {
        self.upper_mean - self.lower_mean
    }

    /// Soft membership of the upper class: 0 below the ramp, 1 above, linear in between. The ramp spans a
    /// fraction of the class contrast around the threshold, so edge pixels weigh by how yellow they are, which
    /// makes centroids sub-pixel.
    pub fn ramp(&self) -> Ramp {
        let half_width = (0.25 * self.contrast()).max(1.0);
        Ramp {
            start: self.threshold - half_width,
            inv_width: 1.0 / (2.0 * half_width),
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ramp {
    pub start: f64,
    pub inv_width: f64,
}

impl Ramp {
    /// Lookup table of the membership for every yellowness value (bin = value + 255).
    pub fn table(&self) -> MembershipTable {
        std::array::from_fn(|bin| self.membership(bin as f64 - 255.0) as f32)
    }

    /// The membership of a yellowness value, in f64 (the table holds it rounded to f32).
    #[inline(always)]
    pub fn membership(&self, yellowness: f64) -> f64 {
        ((yellowness - self.start) * self.inv_width).clamp(0.0, 1.0)
    }
}

/// A ramp's membership table with the ramp it comes from, so that a vector loop may compute an entry (in f64, then
/// rounded to f32, as the table's were) rather than look it up.
#[derive(Clone, Debug)]
pub struct Membership {
    pub table: MembershipTable,
    pub ramp: Ramp,
}

impl From<Ramp> for Membership {
    fn from(ramp: Ramp) -> Self {
        Self {
            table: ramp.table(),
            ramp,
        }
    }
}

/// `None` when the histogram is empty or has a single value (no split exists).
pub fn otsu(h: &Histogram) -> Option<OtsuSplit> {
    let total = h.total() as f64;
    if total == 0.0 {
        return None;
    }
    let sum_all: f64 = h.bins.iter().enumerate().map(|(i, &c)| i as f64 * f64::from(c)).sum();
    let (mut weight_lo, mut sum_lo) = (0.0, 0.0);
    let mut best: Option<(f64, usize)> = None;
    for (i, &c) in h.bins.iter().enumerate() {
        weight_lo += f64::from(c);
        sum_lo += i as f64 * f64::from(c);
        let weight_hi = total - weight_lo;
        if weight_lo == 0.0 || weight_hi == 0.0 {
            continue;
        }
        let mean_lo = sum_lo / weight_lo;
        let mean_hi = (sum_all - sum_lo) / weight_hi;
        let between = weight_lo * weight_hi * (mean_lo - mean_hi).powi(2);
        if best.is_none_or(|(b, _)| between > b) {
            best = Some((between, i));
        }
    }
    let (_, split) = best?;
    let (mut w_lo, mut s_lo, mut w_hi, mut s_hi) = (0.0, 0.0, 0.0, 0.0);
    for (i, &c) in h.bins.iter().enumerate() {
        if i <= split {
            w_lo += f64::from(c);
            s_lo += i as f64 * f64::from(c);
        } else {
            w_hi += f64::from(c);
            s_hi += i as f64 * f64::from(c);
        }
    }
    Some(OtsuSplit {
        threshold: split as f64 - 255.0 + 0.5,
        lower_mean: s_lo / w_lo - 255.0,
        upper_mean: s_hi / w_hi - 255.0,
    })
}

/// A small yellowness image: each pixel the mean yellowness of a `factor x factor` block of the frame.
pub struct YellownessMap {
    pub width: usize,
    pub height: usize,
    pub factor: usize,
    pub values: Vec<i16>,
}

impl YellownessMap {
    pub fn new(frame: &image::RgbImage, factor: usize) -> Self {
        let factor = factor.max(1);
        let (fw, fh) = (frame.width() as usize, frame.height() as usize);
        let (width, height) = (fw / factor, fh / factor);
        let raw = frame.as_raw();
        let mut values = vec![0i16; width * height];
        // Each block's sum in two steps: the block's rows added column by column (a plain pass over the pixels, which
        // the compiler vectorises where it may use AVX2), then each block's columns. Integer sums, so the same values
        // as summing each block in any order.
        let mut column_sums = vec![0i32; width * factor];
        let area = (factor * factor) as i32;
        #[cfg(target_arch = "x86_64")]
        let avx2 = std::arch::is_x86_feature_detected!("avx2");
        for y in 0..height {
            column_sums.fill(0);
            for dy in 0..factor {
                let line = &raw[(y * factor + dy) * fw * 3..][..width * factor * 3];
                #[cfg(target_arch = "x86_64")]
                if avx2 {
                    // SAFETY: the processor has AVX2 (checked above).
                    unsafe { add_line_avx2(&mut column_sums, line) };
                    continue;
                }
                add_line(&mut column_sums, line);
            }
            for (v, block) in values[y * width..][..width]
                .iter_mut()
                .zip(column_sums.chunks_exact(factor))
            {
                *v = (block.iter().sum::<i32>() / area) as i16;
            }
        }
        Self {
            width,
            height,
            factor,
            values,
        }
    }

    pub fn histogram(&self) -> Histogram {
        let mut h = Histogram::default();
        for &v in &self.values {
            h.add(i32::from(v));
        }
        h
    }
}

/// Adds each RGB pixel's yellowness in `line` to its column's sum.
#[inline(always)]
fn add_line(column_sums: &mut [i32], line: &[u8]) {
    for (sum, px) in column_sums.iter_mut().zip(line.chunks_exact(3)) {
        *sum += yellowness(px[0], px[1], px[2]);
    }
}

/// [`add_line`] compiled for AVX2, which the compiler vectorises (the plain x86-64 build does not: its cost of
/// taking the three colours apart is too high there).
///
/// # Safety
/// The processor has AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn add_line_avx2(column_sums: &mut [i32], line: &[u8]) {
    add_line(column_sums, line);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn map_values_are_the_blocks_mean_yellowness_truncated() {
        // Odd sizes leave a margin outside the blocks; the pixels' yellowness covers both signs.
        let (w, h) = (23u32, 17u32);
        let frame = image::RgbImage::from_fn(w, h, |x, y| {
            let v = |k: u32| ((x * 37 + y * 91 + k * 53).wrapping_mul(2_654_435_761) >> 24) as u8;
            image::Rgb([v(1), v(2), v(3)])
        });
        for factor in 1..=5usize {
            let map = YellownessMap::new(&frame, factor);
            assert_eq!((map.width, map.height), (w as usize / factor, h as usize / factor));
            for (i, &value) in map.values.iter().enumerate() {
                let (bx, by) = (i % map.width, i / map.width);
                let mut sum = 0;
                for y in by * factor..(by + 1) * factor {
                    for x in bx * factor..(bx + 1) * factor {
                        let p = frame.get_pixel(x as u32, y as u32).0;
                        sum += yellowness(p[0], p[1], p[2]);
                    }
                }
                assert_eq!(
                    i32::from(value),
                    sum / (factor * factor) as i32,
                    "factor {factor} block ({bx}, {by})"
                );
            }
        }
    }

    #[test]
    fn otsu_splits_two_clusters() {
        let mut h = Histogram::default();
        for _ in 0..100 {
            h.add(-40);
            h.add(80);
        }
        let s = otsu(&h).unwrap();
        assert!(s.threshold > -40.0 && s.threshold < 80.0, "{s:?}");
        assert!((s.lower_mean + 40.0).abs() < 1e-9 && (s.upper_mean - 80.0).abs() < 1e-9);
        assert!(otsu(&Histogram::default()).is_none());
    }
}
