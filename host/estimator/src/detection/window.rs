//! The per-frame search: each square is measured only inside its own cell, a parallelogram spanned by the local
//! column and row steps around where the square is predicted. Neighbouring yellow squares sit in the diagonal
//! cells, so they never enter the window; the yellowness-weighted centroid is therefore sub-pixel and cheap.

use nusense_geometry::Point2;

use super::yellowness::{Histogram, Membership, MembershipTable};

/// The local cell of a square in raw px: one column step and one row step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CellFrame {
    pub col_step: Point2,
    pub row_step: Point2,
    inverse: [[f64; 2]; 2],
    /// [`Self::min_step`], computed once: the tracker divides by it for every square in every frame.
    min_step: f64,
}

impl CellFrame {
    /// `None` when the steps are degenerate (parallel or not finite).
    pub fn new(col_step: Point2, row_step: Point2) -> Option<Self> {
        let det = col_step[0] * row_step[1] - col_step[1] * row_step[0];
        if !det.is_finite() || det.abs() < 1e-6 {
            return None;
        }
        let inverse = [
            [row_step[1] / det, -row_step[0] / det],
            [-col_step[1] / det, col_step[0] / det],
        ];
        Some(Self {
            col_step,
            row_step,
            inverse,
            min_step: col_step[0].hypot(col_step[1]).min(row_step[0].hypot(row_step[1])),
        })
    }

    /// Cell coordinates (column steps, row steps) of an offset in raw px.
    pub fn to_cell(&self, d: Point2) -> Point2 {
        [
            self.inverse[0][0] * d[0] + self.inverse[0][1] * d[1],
            self.inverse[1][0] * d[0] + self.inverse[1][1] * d[1],
        ]
    }

    /// Length of the shorter step, px.
    pub fn min_step(&self) -> f64 {
        self.min_step
    }

    /// The x-range (in pixel-centre offsets from the centre) of row offset `dy` inside |s|, |t| <= half.
    fn row_span(&self, dy: f64, half: f64) -> Option<(f64, f64)> {
        let mut lo = f64::NEG_INFINITY;
        let mut hi = f64::INFINITY;
        for k in 0..2 {
            let (a, b) = (self.inverse[k][0], self.inverse[k][1] * dy);
            if a.abs() < 1e-12 {
                if b.abs() > half {
                    return None;
                }
                continue;
            }
            let (p, q) = ((-half - b) / a, (half - b) / a);
            // -half - b <= half - b, and rounding keeps that order, so p <= q where a > 0 and q <= p otherwise.
            // Comparisons rather than f64::min and max, whose NaN handling cost several instructions each on every
            // row of every window: a NaN bound (from a dy that is not finite) leaves lo and hi as they were either way.
            let (near, far) = if a > 0.0 { (p, q) } else { (q, p) };
            if near > lo {
                lo = near;
            }
            if far < hi {
                hi = far;
            }
        }
        (lo <= hi).then_some((lo, hi))
    }
}

/// A frame's pixels, borrowed.
pub struct Pixels<'a> {
    pub raw: &'a [u8],
    pub width: usize,
    pub height: usize,
}

/// Below this magnitude an f64 converts to i64 and back exactly once truncated (the fraction goes, nothing else).
const EXACT_INTEGERS: f64 = 4.5e15;

/// `x.floor()` as a comparison sees it (a -0.0 may come out as 0.0). The build targets any x86-64, whose baseline
/// has no rounding instruction, so `f64::floor` is a call into the C library; a window's every row takes one floor
/// and one ceil.
#[inline(always)]
fn floor(x: f64) -> f64 {
    if x.abs() < EXACT_INTEGERS {
        let t = x as i64 as f64;
        if t > x {
            t - 1.0
        } else {
            t
        }
    } else {
        x.floor()
    }
}

/// `x.ceil()` as a comparison sees it (a -0.0 may come out as 0.0): see [`floor`].
#[inline(always)]
fn ceil(x: f64) -> f64 {
    if x.abs() < EXACT_INTEGERS {
        let t = x as i64 as f64;
        if t < x {
            t + 1.0
        } else {
            t
        }
    } else {
        x.ceil()
    }
}

/// The first multiple of `stride` from `x` on: an integer division (a row's first pixel), but for the common stride 1.
#[inline(always)]
fn on_grid(x: usize, stride: usize) -> usize {
    if stride == 1 {
        x
    } else {
        x.div_ceil(stride) * stride
    }
}

/// Visits the pixels of the window (every `stride`-th row and column of the frame's global grid).
#[inline(always)]
fn for_each_row<'a>(
    px: &Pixels<'a>,
    centre: Point2,
    cell: &CellFrame,
    half: f64,
    stride: usize,
    row: impl FnMut(usize, &'a [u8], usize, usize),
) {
    for_each_row_spanned(
        px,
        centre,
        cell,
        half,
        stride,
        |y| computed_row(cell, half, centre, y as i64),
        row,
    );
}

/// Row `y`'s first and last pixel ([`row_pixels`]) in the window of `cell` and `half` about `centre`: the rule every
/// row follows, which a [`Window`]'s table only holds ready for a centre on a whole pixel.
#[inline(always)]
fn computed_row(cell: &CellFrame, half: f64, centre: Point2, y: i64) -> Option<(i64, i64)> {
    cell.row_span(y as f64 + 0.5 - centre[1], half)
        .map(|span| row_pixels(centre[0], span))
}

/// The first and last pixel (not yet clamped to the frame) of a row whose x-range about `centre_x` is `(lo, hi)`
/// ([`CellFrame::row_span`]): -inf and +inf, from a row without bounds, saturate to i64's ends.
#[inline(always)]
fn row_pixels(centre_x: f64, (lo, hi): (f64, f64)) -> (i64, i64) {
    (ceil(centre_x + lo - 0.5) as i64, floor(centre_x + hi - 0.5) as i64)
}

/// [`for_each_row`], with row `y`'s first and last pixel (as [`row_pixels`] gives them for that row) from
/// `pixels_of`.
#[inline(always)]
fn for_each_row_spanned<'a>(
    px: &Pixels<'a>,
    centre: Point2,
    cell: &CellFrame,
    half: f64,
    stride: usize,
    pixels_of: impl Fn(usize) -> Option<(i64, i64)>,
    mut row: impl FnMut(usize, &'a [u8], usize, usize),
) {
    let reach = half * (cell.col_step[1].abs() + cell.row_step[1].abs());
    let y_lo = ceil(centre[1] - reach - 0.5).max(0.0) as usize;
    let y_hi = floor(centre[1] + reach - 0.5).min(px.height as f64 - 1.0);
    if !(y_hi >= 0.0) || !centre[0].is_finite() {
        return;
    }
    // The bounds are whole numbers from here on, x's in 0..width and y's in 0..height once checked, so they convert
    // exactly either way; through i64 rather than usize, whose conversions to and from f64 are several instructions
    // each on x86-64 (a window's every row takes three).
    let y_last = y_hi as i64 as usize;
    let y_start = on_grid(y_lo, stride);
    let mut y = y_start;
    while y <= y_last {
        if let Some((x_lo, x_hi)) = pixels_of(y) {
            // Clamped to the frame as whole numbers: a row's range is finite or unbounded, never NaN (`row_span`
            // with a finite offset; the centre is finite), so this is the clamp in f64 it replaces.
            let x_lo = x_lo.max(0);
            let x_hi = x_hi.min(px.width as i64 - 1);
            if x_hi >= x_lo {
                let x0 = on_grid(x_lo as usize, stride);
                let x1 = x_hi as usize;
                if x0 <= x1 {
                    let line = &px.raw[y * px.width * 3..(y + 1) * px.width * 3];
                    row(y, line, x0, x1);
                }
            }
        }
        y += stride;
    }
}

/// Calls `f` on the pixels `x0, x0 + stride, ...` up to `x1` of one row (`x0 <= x1 < width`), as RGB triples.
/// One slice check per row rather than one per pixel: this loop is most of a frame's time.
#[inline(always)]
fn for_each_pixel(line: &[u8], x0: usize, x1: usize, stride: usize, mut f: impl FnMut([u8; 3])) {
    let row = &line[x0 * 3..x1 * 3 + 3];
    if stride == 1 {
        // Every pixel (frames up to about 1024 px wide): the loop the compiler makes tightest.
        for p in row.chunks_exact(3) {
            if let &[r, g, b] = p {
                f([r, g, b]);
            }
        }
    } else {
        for p in row.chunks(3 * stride) {
            if let Some(&[r, g, b]) = p.first_chunk::<3>() {
                f([r, g, b]);
            }
        }
    }
}

/// Membership of one pixel: the table's entry for its yellowness (in -255..=255, so the index is in bounds), but
/// for a pixel whose red and green both clip ([`CLIPPED_LEVEL`]), which is yellow ink: see [`yellow_bin`].
#[inline(always)]
fn member(table: &MembershipTable, [r, g, b]: [u8; 3]) -> f32 {
    table[yellow_bin(r.min(g), b)]
}

/// The membership table's index of a pixel of `min(R, G) = low` and blue `b`: its yellowness (bin = value + 255),
/// except that a pixel whose red and green both clip takes the last bin, the yellowest there is.
///
/// Such a pixel is yellow ink: the red squares and the lines between cells have little green (see
/// [`super::yellowness`]), so their green clips only under light that has long clipped their red and blue and the
/// yellow's every channel, where nothing is measured. Its yellowness, though, says nothing: with red and green held
/// at the clip, it is `255 - B` and falls as the light rises, while the blue grows. The yellow sits near the clip at
/// nominal light, so when one LED side is brighter than in the rest frame (or glare adds to it) the squares on that
/// side clip, their yellowness falls with the light across each square, and with it their membership: the centroid
/// moves away from the light by up to several px (validation sensor at 1024x768, a rest frame with the right side at
/// 150 %: 0.64 px RMS over the squares, 4.7 px at most), read as a contact of about a newton. Counted as the yellow
/// they are, clipped pixels weigh as in any light, and only the pixels across a square's edge that clip under the
/// brighter light but not in the rest frame still weigh differently.
#[inline(always)]
fn yellow_bin(low: u8, b: u8) -> usize {
    if low >= CLIPPED_LEVEL {
        super::yellowness::YELLOWNESS_BINS - 1
    } else {
        usize::from(low) + 255 - usize::from(b)
    }
}

/// Adds the window's yellowness values to a histogram; returns how many pixels it visited and how many of them
/// were clipped.
pub fn add_to_histogram(
    px: &Pixels,
    centre: Point2,
    cell: &CellFrame,
    half: f64,
    stride: usize,
    h: &mut Histogram,
) -> (usize, usize) {
    let (mut visited, mut clipped) = (0usize, 0usize);
    for_each_row(px, centre, cell, half, stride, |_, line, x0, x1| {
        for_each_pixel(line, x0, x1, stride, |p| {
            h.add(super::yellowness::yellowness(p[0], p[1], p[2]));
            visited += 1;
            clipped += usize::from(p[0].min(p[1]).min(p[2]) >= CLIPPED_LEVEL);
        });
    });
    (visited, clipped)
}

/// A pixel with no channel below this is clipped: it no longer tells yellow from red.
pub const CLIPPED_LEVEL: u8 = 250;

/// What the window around one square holds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WindowCentroid {
    /// Yellowness-weighted centroid, raw px.
    pub at: Point2,
    /// Weighted yellow area, raw px^2.
    pub area: f64,
    /// Fraction of the window's pixels clipped in every channel.
    pub clipped_fraction: f64,
}

/// A square's search window: its cell and half-size (cell units), with every row it can hold tabulated for a centre
/// on a whole pixel, the only centre [`centroid`] is given by the tracker. A row's range is `CellFrame::row_span`
/// of the row's offset from the centre, and with the centre on a whole pixel that offset is the same half-integer for
/// the same row of the window wherever the window is, so the table holds the very values the row would compute (their
/// divisions and comparisons took about 70 of the some 150 instructions a window's row cost, and a frame at 2048x1536
/// has some 11,000 such rows), and for most rows the first and last pixel as offsets from the centre, which save the
/// row its rounding (see `TabulatedRow::Offsets`).
#[derive(Clone, Debug, PartialEq)]
pub struct Window {
    cell: CellFrame,
    half: f64,
    /// The row offset (row minus the centre's row) of `rows[0]`.
    first_offset: i64,
    rows: Vec<TabulatedRow>,
}

/// One row of a [`Window`]'s table.
#[derive(Clone, Copy, Debug, PartialEq)]
enum TabulatedRow {
    /// No pixel of the row is in the window.
    Empty,
    /// The row's first and last pixel from a whole-pixel centre: [`row_pixels`] gives the centre plus these for any
    /// such centre within [`WHOLE_CENTRE`] of 0 (see [`Window::new`]), so they need no rounding in the row.
    Offsets(i64, i64),
    /// The row's range (its ends lie too near a pixel's edge for `Offsets`).
    Span(f64, f64),
}

/// Most rows a [`Window`] tabulates (a window this tall is no square's: its rows are computed as they come).
const MAX_TABULATED_ROWS: f64 = 4096.0;
/// A whole-pixel centre's x at most this far from 0 takes a [`TabulatedRow::Offsets`] (frames are far narrower).
const WHOLE_CENTRE: f64 = 1_048_576.0;
/// A row end this close to a pixel's edge (after the half pixel) is rounded in the row.
const EDGE_MARGIN: f64 = 1e-6;

impl Window {
    pub fn new(cell: CellFrame, half: f64) -> Self {
        let reach = half * (cell.col_step[1].abs() + cell.row_step[1].abs());
        // Offsets are exact: for a whole x with |x| <= 2^20 and |lo - 0.5| < 2^20, the row computes x + lo - 0.5 in
        // two roundings of at most 2^-32 each (half an ulp below 2^22), and lo - 0.5 is computed here in one of at
        // most 2^-33, all far inside EDGE_MARGIN of the nearest whole number (x is whole, so the sum's distance to one
        // is lo - 0.5's), so rounding the computed sum up gives x plus the rounded-up lo - 0.5 (and the same for hi,
        // rounded down).
        let row = |j: i64| match cell.row_span(j as f64 + 0.5, half) {
            None => TabulatedRow::Empty,
            Some((lo, hi)) => {
                let (u, v) = (lo - 0.5, hi - 0.5);
                let clear = |e: f64| e.abs() < WHOLE_CENTRE && (e - e.round()).abs() > EDGE_MARGIN;
                if clear(u) && clear(v) {
                    TabulatedRow::Offsets(u.ceil() as i64, v.floor() as i64)
                } else {
                    TabulatedRow::Span(lo, hi)
                }
            }
        };
        // Every row a window visits lies within `reach` + 1 of its centre (`for_each_row`); one more on each side.
        let (first_offset, rows) = if reach.is_finite() && reach < MAX_TABULATED_ROWS / 2.0 - 2.0 {
            let (first, last) = (-(ceil(reach) as i64) - 2, ceil(reach) as i64 + 2);
            (first, (first..=last).map(row).collect())
        } else {
            (0, Vec::new())
        };
        Self {
            cell,
            half,
            first_offset,
            rows,
        }
    }

    pub fn cell(&self) -> &CellFrame {
        &self.cell
    }

    /// The first and last pixel ([`row_pixels`]) of the row `offset` rows below a centre on a whole row, at
    /// `centre_x`; `whole_x`: that `centre_x` is a whole pixel within [`WHOLE_CENTRE`] of 0.
    #[inline(always)]
    fn pixels(&self, offset: i64, centre_x: f64, whole_x: bool) -> Option<(i64, i64)> {
        let tabulated = offset
            .checked_sub(self.first_offset)
            .and_then(|i| usize::try_from(i).ok())
            .and_then(|i| self.rows.get(i));
        match tabulated {
            Some(TabulatedRow::Empty) => None,
            Some(&TabulatedRow::Offsets(lo, hi)) if whole_x => {
                let x = centre_x as i64;
                Some((x + lo, x + hi))
            }
            Some(&TabulatedRow::Offsets(..)) => self.computed(offset, centre_x),
            Some(&TabulatedRow::Span(lo, hi)) => Some(row_pixels(centre_x, (lo, hi))),
            None => self.computed(offset, centre_x),
        }
    }

    /// [`computed_row`] for the row `offset` rows below a centre on a whole row, as that row of a centre on row 0: the
    /// cell sees only the row's offset from the centre, the same half-integer either way (`offset + 0.5 - 0.0` is
    /// `offset + 0.5` to the bit).
    fn computed(&self, offset: i64, centre_x: f64) -> Option<(i64, i64)> {
        computed_row(&self.cell, self.half, [centre_x, 0.0], offset)
    }
}

/// Weighted centroid and area of the yellow inside the window, and how much of the window is clipped; `None`
/// when the window holds no yellow.
///
/// The sums are those of the plain loop: each row's membership and membership times x in f32 from the left, pixel
/// by pixel, and the rows' totals in f64 from the top. A row's f32 sums are two chains of dependent additions,
/// which would bound this loop's speed, so `ROWS_AT_ONCE` rows are summed together, as the lanes of one vector:
/// their memberships are first looked up into a buffer (pixel-major, a row per lane, zeros past a row's end, which
/// add nothing), then added lane by lane. Each row's own order is kept, and with it every bit of the result. On a
/// processor with AVX2 (checked at run time: the build targets any x86-64) the lookups are vector gathers, one
/// pixel of every lane at a time, summed as they come (see `gathered`): the same additions in the same order. With
/// AVX-512 VBMI as well, each row's pixels are loaded eight at a time and taken apart with a byte permutation rather
/// than gathered (see `permuted`): again the same additions in the same order.
pub fn centroid(
    px: &Pixels,
    centre: Point2,
    window: &Window,
    stride: usize,
    membership: &Membership,
) -> Option<WindowCentroid> {
    centroid_with(px, centre, window, stride, membership, Lookup::detect())
}

/// How [`centroid`] looks its memberships up.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Lookup {
    /// One pixel at a time, on any processor.
    Scalar,
    /// Vector gathers (x86-64 with AVX2 only: see [`Lookup::detect`]).
    #[cfg(target_arch = "x86_64")]
    Gathered,
    /// Each row's pixels loaded eight at a time and taken apart by a byte permutation, then transposed into the
    /// lanes (x86-64 with AVX-512 VBMI only: see [`Lookup::detect`]); `Gathered` for strides above
    /// [`PERMUTED_MAX_STRIDE`].
    #[cfg(target_arch = "x86_64")]
    Permuted,
}

/// The largest stride whose eight pixels' words (the byte before each pixel and its R, G, B) fit in the 64 bytes
/// one AVX-512 load reads: 7 * 3 * stride + 4 bytes.
#[cfg(target_arch = "x86_64")]
const PERMUTED_MAX_STRIDE: usize = 2;

/// Per stride up to [`PERMUTED_MAX_STRIDE`], the byte permutation that turns 64 bytes, from the byte before the
/// first of eight pixels on, into the pixels' words: word j is bytes `j * 3 * stride ..= j * 3 * stride + 3`.
#[cfg(target_arch = "x86_64")]
const WORD_BYTES: [[u8; 64]; PERMUTED_MAX_STRIDE] = [word_bytes(3), word_bytes(6)];

#[cfg(target_arch = "x86_64")]
const fn word_bytes(pixel_bytes: usize) -> [u8; 64] {
    let mut permutation = [0u8; 64];
    let mut i = 0;
    while i < 32 {
        permutation[i] = ((i / 4) * pixel_bytes + i % 4) as u8;
        i += 1;
    }
    permutation
}

impl Lookup {
    /// The fastest this processor runs.
    #[inline]
    fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::is_x86_feature_detected as has;
            if has!("avx2") && has!("avx512f") && has!("avx512bw") && has!("avx512vl") && has!("avx512vbmi") {
                return Self::Permuted;
            }
            if has!("avx2") {
                return Self::Gathered;
            }
        }
        Self::Scalar
    }
}

#[inline(always)]
fn centroid_with(
    px: &Pixels,
    centre: Point2,
    window: &Window,
    stride: usize,
    membership: &Membership,
    lookup: Lookup,
) -> Option<WindowCentroid> {
    // The gathers address the frame with 32-bit offsets.
    #[cfg(target_arch = "x86_64")]
    let lookup = if px.raw.len() <= i32::MAX as usize {
        lookup
    } else {
        Lookup::Scalar
    };
    let mut totals = WindowTotals::default();
    let mut pending: [RowSpan; ROWS_AT_ONCE] = [RowSpan::EMPTY; ROWS_AT_ONCE];
    let mut held = 0;
    let (cell, half) = (&window.cell, window.half);
    // With the centre on a whole row, row y's offset y + 0.5 - centre is exactly (y - centre) + 0.5 (whole numbers
    // and halves this small are exact in f64), so the table's row is the one the row would compute.
    let centre_row = (centre[1].abs() < EXACT_INTEGERS && floor(centre[1]) == centre[1]).then_some(centre[1] as i64);
    let whole_x = centre[0].abs() <= WHOLE_CENTRE && floor(centre[0]) == centre[0];
    let pixels_of = |y: usize| match centre_row {
        Some(centre_row) => window.pixels(y as i64 - centre_row, centre[0], whole_x),
        None => computed_row(cell, half, centre, y as i64),
    };
    for_each_row_spanned(px, centre, cell, half, stride, pixels_of, |y, line, x0, x1| {
        pending[held] = RowSpan::new(y, line, x0, x1, stride);
        held += 1;
        if held == ROWS_AT_ONCE {
            totals.add_rows(&pending, px.raw, stride, membership, lookup);
            held = 0;
        }
    });
    if held > 0 {
        totals.add_rows(&pending[..held], px.raw, stride, membership, lookup);
    }
    let WindowTotals {
        sum_w,
        sum_x,
        sum_y,
        visited,
        clipped,
    } = totals;
    if sum_w <= 0.0 {
        return None;
    }
    Some(WindowCentroid {
        at: [sum_x / sum_w + 0.5, sum_y / sum_w + 0.5],
        area: sum_w * (stride * stride) as f64,
        clipped_fraction: clipped as f64 / visited.max(1) as f64,
    })
}

/// Rows [`centroid`] sums together (the lanes of its sums).
const ROWS_AT_ONCE: usize = 8;
/// Pixels per row [`centroid`] looks up before summing them (a longer row is summed in several such pieces).
const PIXELS_AT_ONCE: usize = 64;

/// Bytes per cache line (x86-64 and most ARM cores).
const CACHE_LINE: usize = 64;

/// One row of a window: its pixels `x0, x0 + stride, ...` (`count` of them), from `pixels`, which starts at `x0`
/// and ends with the last one.
#[derive(Clone, Copy)]
struct RowSpan<'a> {
    y: usize,
    x0: usize,
    count: usize,
    pixels: &'a [u8],
}

impl<'a> RowSpan<'a> {
    const EMPTY: Self = Self {
        y: 0,
        x0: 0,
        count: 0,
        pixels: &[],
    };

    #[inline(always)]
    fn new(y: usize, line: &'a [u8], x0: usize, x1: usize, stride: usize) -> Self {
        let count = (x1 - x0) / stride + 1;
        Self {
            y,
            x0,
            count,
            pixels: &line[x0 * 3..(x0 + (count - 1) * stride) * 3 + 3],
        }
    }
}

/// The window's sums, rows added from the top.
#[derive(Default)]
struct WindowTotals {
    sum_w: f64,
    sum_x: f64,
    sum_y: f64,
    visited: usize,
    clipped: usize,
}

impl WindowTotals {
    /// Sums up to [`ROWS_AT_ONCE`] rows together and adds them in order. `raw`: the frame the spans are rows of.
    #[inline(always)]
    fn add_rows(&mut self, spans: &[RowSpan], raw: &[u8], stride: usize, membership: &Membership, lookup: Lookup) {
        #[cfg(target_arch = "x86_64")]
        let ramp_is_finite = membership.ramp.start.is_finite() && membership.ramp.inv_width.is_finite();
        #[cfg(target_arch = "x86_64")]
        if lookup == Lookup::Permuted && stride <= PERMUTED_MAX_STRIDE && ramp_is_finite {
            // SAFETY: `Permuted` is chosen only where the processor has AVX2 and AVX-512 F, BW, VL and VBMI
            // (`Lookup::detect`); the spans are rows of `raw` (`for_each_row`); the stride and the ramp are checked
            // above.
            if unsafe { self.add_rows_permuted(spans, raw, stride, membership) } {
                return;
            }
        } else if matches!(lookup, Lookup::Gathered | Lookup::Permuted) {
            // SAFETY: `Gathered` and `Permuted` are chosen only where the processor has AVX2 (`Lookup::detect`), and
            // only for a frame of at most i32::MAX bytes (`centroid_with`); the spans are rows of `raw`
            // (`for_each_row`).
            if unsafe { self.add_rows_gathered(spans, raw, stride, &membership.table) } {
                return;
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = (raw, lookup);
        // The common strides get their own copies of the loops, with the stride a constant.
        match stride {
            1 => self.add_rows_at(spans, 1, &membership.table),
            2 => self.add_rows_at(spans, 2, &membership.table),
            _ => self.add_rows_at(spans, stride, &membership.table),
        }
    }

    #[inline(always)]
    fn add_rows_at(&mut self, spans: &[RowSpan], stride: usize, membership: &MembershipTable) {
        let longest = spans.iter().map(|s| s.count).max().unwrap_or(0);
        let mut w = [0f32; ROWS_AT_ONCE];
        let mut wx = [0f32; ROWS_AT_ONCE];
        // x of the lanes' current pixels: exact integers in f32 (frames are far narrower than 2^24 px), so adding
        // the stride keeps them exact.
        let mut x = [0f32; ROWS_AT_ONCE];
        for (xk, span) in x.iter_mut().zip(spans) {
            *xk = span.x0 as f32;
        }
        let step = stride as f32;
        touch_rows(spans);
        let mut looked_up = [[0f32; ROWS_AT_ONCE]; PIXELS_AT_ONCE];
        let mut start = 0;
        while start < longest {
            let piece = (longest - start).min(PIXELS_AT_ONCE);
            for (k, span) in spans.iter().enumerate() {
                let from = (start * stride * 3).min(span.pixels.len());
                // Whole steps of the stride, then the row's last pixel, which ends the span without a step's tail
                // after it (exact chunks let the loop go without a length check per pixel).
                let whole = span.pixels[from..].chunks_exact(stride * 3);
                let last = whole.remainder();
                let mut filled = 0;
                for (slot, p) in looked_up[..piece].iter_mut().zip(whole) {
                    let (r, g, b) = (p[0], p[1], p[2]);
                    slot[k] = member(membership, [r, g, b]);
                    self.clipped += usize::from(r.min(g).min(b) >= CLIPPED_LEVEL);
                    filled += 1;
                }
                if filled < piece {
                    if let Some(&[r, g, b]) = last.first_chunk::<3>() {
                        looked_up[filled][k] = member(membership, [r, g, b]);
                        self.clipped += usize::from(r.min(g).min(b) >= CLIPPED_LEVEL);
                        filled += 1;
                    }
                }
                for slot in &mut looked_up[filled..piece] {
                    slot[k] = 0.0;
                }
            }
            for m in &looked_up[..piece] {
                for k in 0..ROWS_AT_ONCE {
                    w[k] += m[k];
                    wx[k] += m[k] * x[k];
                    x[k] += step;
                }
            }
            start += piece;
        }
        self.add_lanes(spans, &w, &wx);
    }

    /// Each row's sums (lane k is `spans[k]`) into the window's.
    fn add_lanes(&mut self, spans: &[RowSpan], w: &[f32; ROWS_AT_ONCE], wx: &[f32; ROWS_AT_ONCE]) {
        for (k, span) in spans.iter().enumerate() {
            self.sum_w += f64::from(w[k]);
            self.sum_x += f64::from(wx[k]);
            self.sum_y += f64::from(w[k]) * span.y as f64;
            self.visited += span.count;
        }
    }
}

/// The rows lie a frame's width apart, and at large sizes most of them are not in the cache: reading one byte per
/// cache line of every row first lets the memory fetch them all at once (the independent loads overlap) rather than
/// one line at a time as a window's lookups reach them.
fn touch_rows(spans: &[RowSpan]) {
    let mut touched = 0u8;
    for span in spans {
        for byte in span.pixels.iter().step_by(CACHE_LINE) {
            touched ^= byte;
        }
        touched ^= span.pixels.last().copied().unwrap_or(0);
    }
    std::hint::black_box(touched);
}

#[cfg(target_arch = "x86_64")]
impl WindowTotals {
    /// [`Self::add_rows_at`] with AVX2: each lane (a row) reads its next pixel's four bytes from one byte before it
    /// (a gather of 32-bit words: the byte before, R, G, B, so that no read passes the row's last pixel) and its
    /// membership (a gather from the table), and adds them to its sums as the plain loop does, in f32, the same
    /// operations in the same order (no fused multiply-add), so every bit is the same. Lanes past their row's end
    /// read the row's last pixel again and add zeros, as the plain loop's zero-filled slots do. Returns false, having
    /// added nothing, when some row starts at the frame's first byte (there is no byte before it).
    ///
    /// # Safety
    /// The processor has AVX2; `raw` is at most `i32::MAX` bytes long and every span's pixels lie in it.
    #[target_feature(enable = "avx2")]
    unsafe fn add_rows_gathered(
        &mut self,
        spans: &[RowSpan],
        raw: &[u8],
        stride: usize,
        membership: &MembershipTable,
    ) -> bool {
        use std::arch::x86_64::*;
        let Some(first_span) = spans.first() else {
            return true;
        };
        let base = raw.as_ptr();
        let offset_of = |span: &RowSpan| span.pixels.as_ptr() as usize - base as usize;
        if spans.iter().any(|span| offset_of(span) == 0 || span.count == 0) {
            return false;
        }
        let pixel_bytes = 3 * stride;
        // Per lane: the offset of the word before its first pixel, of the one before its last, its pixel count, and
        // its first x. Lanes without a row read the first row's first pixel and add nothing (count 0).
        let mut first = [(offset_of(first_span) - 1) as i32; ROWS_AT_ONCE];
        let mut last = first;
        let mut count = [0i32; ROWS_AT_ONCE];
        let mut x0 = [0f32; ROWS_AT_ONCE];
        for (k, span) in spans.iter().enumerate() {
            first[k] = (offset_of(span) - 1) as i32;
            last[k] = first[k] + ((span.count - 1) * pixel_bytes) as i32;
            count[k] = span.count as i32;
            x0[k] = span.x0 as f32;
        }
        touch_rows(spans);
        let longest = spans.iter().map(|s| s.count).max().unwrap_or(0);
        // SAFETY (the loads and gathers below): the arrays are ROWS_AT_ONCE = 8 lanes of 32 bits, a vector's width;
        // every word gathered from `raw` starts at `min(first + i * pixel_bytes, last)` for a lane (no clamp is
        // needed while i < `shortest`, every lane's count: there the first term is at most `last`), between the byte
        // before its row's first pixel (which exists: no row starts at 0) and the byte before its last pixel, so its
        // four bytes lie in the row's span; every table index is min(R, G) + 255 - B or 510 (`yellow_bin`), in
        // 0..=510, the table's range.
        let (mut offset, last, count) = unsafe {
            (
                _mm256_loadu_si256(first.as_ptr().cast()),
                _mm256_loadu_si256(last.as_ptr().cast()),
                _mm256_loadu_si256(count.as_ptr().cast()),
            )
        };
        let mut x = unsafe { _mm256_loadu_ps(x0.as_ptr()) };
        let step_bytes = _mm256_set1_epi32(pixel_bytes as i32);
        let step = _mm256_set1_ps(stride as f32);
        let (mut w, mut wx) = (_mm256_setzero_ps(), _mm256_setzero_ps());
        let mut clipped = _mm256_setzero_si256();
        let table = membership.as_ptr();
        // One pixel of every lane: its membership and whether it is clipped white (all ones where it is).
        let look_up = |at: __m256i| {
            let words = unsafe { _mm256_i32gather_epi32::<1>(base.cast(), at) };
            let (bin, white) = unsafe { bins_of_words(words) };
            let m = unsafe { _mm256_i32gather_ps::<4>(table, bin) };
            (m, white)
        };
        // While every lane still has pixels (most of a batch: its rows differ in length by a few pixels at most,
        // near a window's top and bottom), the offsets need no clamp and the sums no mask: the same additions of the
        // same values as the loop after it, in about 0.8 times its instructions.
        let shortest = if spans.len() == ROWS_AT_ONCE {
            spans.iter().map(|s| s.count).min().unwrap_or(0)
        } else {
            0
        };
        for _ in 0..shortest {
            let (m, white) = look_up(offset);
            clipped = _mm256_sub_epi32(clipped, white);
            w = _mm256_add_ps(w, m);
            wx = _mm256_add_ps(wx, _mm256_mul_ps(m, x));
            x = _mm256_add_ps(x, step);
            offset = _mm256_add_epi32(offset, step_bytes);
        }
        for i in shortest..longest {
            let (m, white) = look_up(_mm256_min_epi32(offset, last));
            let live = _mm256_cmpgt_epi32(count, _mm256_set1_epi32(i as i32));
            let m = _mm256_and_ps(m, _mm256_castsi256_ps(live));
            clipped = _mm256_sub_epi32(clipped, _mm256_and_si256(white, live));
            w = _mm256_add_ps(w, m);
            wx = _mm256_add_ps(wx, _mm256_mul_ps(m, x));
            x = _mm256_add_ps(x, step);
            offset = _mm256_add_epi32(offset, step_bytes);
        }
        unsafe { self.add_lane_vectors(spans, w, wx, clipped, spans.len()) };
        true
    }

    /// [`Self::add_rows_gathered`] without the gathers from the frame, which were half its time on the 2048x1536
    /// validation frames: each row's next eight pixels are one 64-byte load and one byte permutation into the same
    /// words the gathers read (the byte before each pixel, R, G, B), the eight pixels' memberships are looked up along
    /// the row, and eight rows' memberships are transposed so that each row is again one lane. The lanes then add them
    /// pixel by pixel as the gathered loop does, the same operations in the same order, so every bit is the same.
    /// Pixels past a row's end weigh zero and count as not clipped, as there. The memberships are computed from the
    /// ramp rather than looked up (`ramp_memberships`: the table's very entries; a gather from the table was then
    /// the loop's slowest step). Returns false, having added nothing, when some row starts at the frame's first byte
    /// (there is no byte before it).
    ///
    /// # Safety
    /// The processor has AVX2 and AVX-512 F, BW, VL and VBMI; every span's pixels lie in `raw`; `stride` is at most
    /// [`PERMUTED_MAX_STRIDE`]; the ramp's start and slope are finite.
    #[target_feature(enable = "avx2,avx512f,avx512bw,avx512vl,avx512vbmi")]
    unsafe fn add_rows_permuted(
        &mut self,
        spans: &[RowSpan],
        raw: &[u8],
        stride: usize,
        membership: &Membership,
    ) -> bool {
        use std::arch::x86_64::*;
        let Some(first_span) = spans.first() else {
            return true;
        };
        if spans
            .iter()
            .any(|span| span.pixels.as_ptr() == raw.as_ptr() || span.count == 0)
        {
            return false;
        }
        let pixel_bytes = 3 * stride;
        let words_of = unsafe { _mm512_loadu_si512(WORD_BYTES[stride - 1].as_ptr().cast()) };
        // Per lane: the byte before its row's first pixel (the first row's for lanes without a row, which read
        // nothing: count 0), its pixel count and its first x.
        let mut before_first = [first_span.pixels.as_ptr().wrapping_sub(1); ROWS_AT_ONCE];
        let mut count = [0usize; ROWS_AT_ONCE];
        let mut x0 = [0f32; ROWS_AT_ONCE];
        for (k, span) in spans.iter().enumerate() {
            before_first[k] = span.pixels.as_ptr().wrapping_sub(1);
            count[k] = span.count;
            x0[k] = span.x0 as f32;
        }
        touch_rows(spans);
        let longest = spans.iter().map(|s| s.count).max().unwrap_or(0);
        let mut x = unsafe { _mm256_loadu_ps(x0.as_ptr()) };
        let step = _mm256_set1_ps(stride as f32);
        let (mut w, mut wx) = (_mm256_setzero_ps(), _mm256_setzero_ps());
        let mut clipped = _mm256_setzero_si256();
        let (start, inv_width) = (
            _mm512_set1_pd(membership.ramp.start),
            _mm512_set1_pd(membership.ramp.inv_width),
        );
        // Where every row has eight more pixels and a full 64-byte load from each stays inside the frame (all but a
        // window's last block of rows near the frame's bottom-right corner), the loads need no mask and the lanes none
        // either: the bytes past the eight pixels' words are other pixels of the frame, which the permutation drops.
        let shortest = if spans.len() == ROWS_AT_ONCE {
            spans.iter().map(|s| s.count).min().unwrap_or(0)
        } else {
            0
        };
        let frame_end = raw.as_ptr_range().end as usize;
        let last_load_end = before_first.iter().map(|&p| p as usize).max().unwrap_or(0) + shortest * pixel_bytes + 64;
        let unmasked_blocks = if last_load_end <= frame_end {
            shortest / ROWS_AT_ONCE
        } else {
            0
        };
        let mut done = 0;
        for _ in 0..unmasked_blocks {
            // SAFETY: each load's 64 bytes lie in `raw` (checked above: `done` + 8 pixels is at most `shortest`).
            let along_rows: [__m256; ROWS_AT_ONCE] = std::array::from_fn(|k| unsafe {
                let bytes = _mm512_loadu_si512(before_first[k].add(done * pixel_bytes).cast());
                let words = _mm512_castsi512_si256(_mm512_permutexvar_epi8(words_of, bytes));
                let (bin, white) = bins_of_words(words);
                clipped = _mm256_sub_epi32(clipped, white);
                ramp_memberships(bin, start, inv_width)
            });
            for m in transposed(along_rows) {
                w = _mm256_add_ps(w, m);
                wx = _mm256_add_ps(wx, _mm256_mul_ps(m, x));
                x = _mm256_add_ps(x, step);
            }
            done += ROWS_AT_ONCE;
        }
        // The rest: each row's remaining pixels, up to eight, and zeros past its end.
        while done < longest {
            let along_rows: [__m256; ROWS_AT_ONCE] = std::array::from_fn(|k| {
                let live = count[k].saturating_sub(done).min(ROWS_AT_ONCE);
                if live == 0 {
                    return _mm256_setzero_ps();
                }
                let at = before_first[k].wrapping_add(done * pixel_bytes);
                // A load with a byte mask costs more than a plain one, so it reads only where 64 bytes would pass the
                // frame's end, and then just the live pixels' words: the byte before the first up to the last one's
                // blue (at most 7 * 6 + 4 bytes).
                let live_bytes = (live - 1) * pixel_bytes + 4;
                // SAFETY: the plain load's 64 bytes lie in `raw`; the masked one reads only the bytes of its mask, which
                // lie in this row's span or are the byte before its first pixel (which exists: no row starts at 0).
                let (m, white) = unsafe {
                    let bytes = if at as usize + 64 <= frame_end {
                        _mm512_loadu_si512(at.cast())
                    } else {
                        _mm512_maskz_loadu_epi8((1u64 << live_bytes) - 1, at.cast())
                    };
                    let words = _mm512_castsi512_si256(_mm512_permutexvar_epi8(words_of, bytes));
                    let (bin, white) = bins_of_words(words);
                    (ramp_memberships(bin, start, inv_width), white)
                };
                let live_mask = ((1u32 << live) - 1) as __mmask8;
                clipped = _mm256_sub_epi32(clipped, _mm256_maskz_mov_epi32(live_mask, white));
                _mm256_maskz_mov_ps(live_mask, m)
            });
            let pixels = (longest - done).min(ROWS_AT_ONCE);
            for m in &transposed(along_rows)[..pixels] {
                w = _mm256_add_ps(w, *m);
                wx = _mm256_add_ps(wx, _mm256_mul_ps(*m, x));
                x = _mm256_add_ps(x, step);
            }
            done += pixels;
        }
        // Here a lane of `clipped` counts one pixel of the eight along every row, not one row: all eight count.
        unsafe { self.add_lane_vectors(spans, w, wx, clipped, ROWS_AT_ONCE) };
        true
    }

    /// The vector loops' sums into the window's: `w` and `wx` one row per lane (see [`Self::add_lanes`]), and the
    /// first `clipped_lanes` lanes of `clipped`, counts of clipped pixels.
    ///
    /// # Safety
    /// The processor has AVX.
    #[target_feature(enable = "avx")]
    unsafe fn add_lane_vectors(
        &mut self,
        spans: &[RowSpan],
        w: std::arch::x86_64::__m256,
        wx: std::arch::x86_64::__m256,
        clipped: std::arch::x86_64::__m256i,
        clipped_lanes: usize,
    ) {
        use std::arch::x86_64::*;
        let (mut w_lanes, mut wx_lanes, mut clipped_counts) =
            ([0f32; ROWS_AT_ONCE], [0f32; ROWS_AT_ONCE], [0i32; ROWS_AT_ONCE]);
        unsafe {
            _mm256_storeu_ps(w_lanes.as_mut_ptr(), w);
            _mm256_storeu_ps(wx_lanes.as_mut_ptr(), wx);
            _mm256_storeu_si256(clipped_counts.as_mut_ptr().cast(), clipped);
        }
        self.add_lanes(spans, &w_lanes, &wx_lanes);
        self.clipped += clipped_counts[..clipped_lanes]
            .iter()
            .map(|&c| c as usize)
            .sum::<usize>();
    }
}

/// Eight pixels' membership table indices ([`yellow_bin`]) and whether each is clipped white (all ones where it is),
/// from their 32-bit words: the byte before the pixel, then its R, G, B.
///
/// # Safety
/// The processor has AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn bins_of_words(words: std::arch::x86_64::__m256i) -> (std::arch::x86_64::__m256i, std::arch::x86_64::__m256i) {
    use std::arch::x86_64::*;
    let byte = _mm256_set1_epi32(0xff);
    let below_clipped = _mm256_set1_epi32(i32::from(CLIPPED_LEVEL) - 1);
    let r = _mm256_and_si256(_mm256_srli_epi32::<8>(words), byte);
    let g = _mm256_and_si256(_mm256_srli_epi32::<16>(words), byte);
    let b = _mm256_srli_epi32::<24>(words);
    let low = _mm256_min_epi32(r, g);
    // `yellow_bin`: a pixel whose red and green clip takes the last bin.
    let low_clipped = _mm256_cmpgt_epi32(low, below_clipped);
    let bin = _mm256_sub_epi32(_mm256_add_epi32(low, _mm256_set1_epi32(255)), b);
    let last_bin = _mm256_set1_epi32(super::yellowness::YELLOWNESS_BINS as i32 - 1);
    let bin = _mm256_max_epi32(bin, _mm256_and_si256(low_clipped, last_bin));
    (bin, _mm256_cmpgt_epi32(_mm256_min_epi32(low, b), below_clipped))
}

/// [`Ramp::membership`](super::yellowness::Ramp::membership) of eight pixels' table indices (`bin` = yellowness +
/// 255), rounded to f32: the membership table's entries, by the same operations (the index's yellowness is exact in
/// f64; clamping a number that is not NaN to 0..=1 is a max and a min; the rounding to f32 is to nearest).
///
/// # Safety
/// The processor has AVX2 and AVX-512 F; `start` and `inv_width` are finite (so nothing is NaN).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,avx512f")]
#[inline]
unsafe fn ramp_memberships(
    bin: std::arch::x86_64::__m256i,
    start: std::arch::x86_64::__m512d,
    inv_width: std::arch::x86_64::__m512d,
) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::*;
    let yellowness = _mm512_cvtepi32_pd(_mm256_sub_epi32(bin, _mm256_set1_epi32(255)));
    let m = _mm512_mul_pd(_mm512_sub_pd(yellowness, start), inv_width);
    _mm512_cvtpd_ps(_mm512_min_pd(
        _mm512_max_pd(m, _mm512_setzero_pd()),
        _mm512_set1_pd(1.0),
    ))
}

/// The 8 x 8 transpose of `rows`: lane k of the result's vector i is lane i of `rows[k]`.
///
/// # Safety
/// The processor has AVX.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
#[inline]
unsafe fn transposed(rows: [std::arch::x86_64::__m256; 8]) -> [std::arch::x86_64::__m256; 8] {
    use std::arch::x86_64::*;
    let pairs = |a, b| (_mm256_unpacklo_ps(a, b), _mm256_unpackhi_ps(a, b));
    let (t0, t1) = pairs(rows[0], rows[1]);
    let (t2, t3) = pairs(rows[2], rows[3]);
    let (t4, t5) = pairs(rows[4], rows[5]);
    let (t6, t7) = pairs(rows[6], rows[7]);
    // Each half of s_i holds pixel i (low half) and pixel i + 4 (high half) of four rows.
    let (s0, s1) = (_mm256_shuffle_ps::<0x44>(t0, t2), _mm256_shuffle_ps::<0xEE>(t0, t2));
    let (s2, s3) = (_mm256_shuffle_ps::<0x44>(t1, t3), _mm256_shuffle_ps::<0xEE>(t1, t3));
    let (s4, s5) = (_mm256_shuffle_ps::<0x44>(t4, t6), _mm256_shuffle_ps::<0xEE>(t4, t6));
    let (s6, s7) = (_mm256_shuffle_ps::<0x44>(t5, t7), _mm256_shuffle_ps::<0xEE>(t5, t7));
    [
        _mm256_permute2f128_ps::<0x20>(s0, s4),
        _mm256_permute2f128_ps::<0x20>(s1, s5),
        _mm256_permute2f128_ps::<0x20>(s2, s6),
        _mm256_permute2f128_ps::<0x20>(s3, s7),
        _mm256_permute2f128_ps::<0x31>(s0, s4),
        _mm256_permute2f128_ps::<0x31>(s1, s5),
        _mm256_permute2f128_ps::<0x31>(s2, s6),
        _mm256_permute2f128_ps::<0x31>(s3, s7),
    ]
}

/// Mean membership over the window of half-size `half` (cell units) around `centre`; 0 for an empty window. A
/// centroid that is truly a square's has yellow all around it; one taken over parts of two squares lies on the
/// lines and red between them.
pub fn mean_membership(
    px: &Pixels,
    centre: Point2,
    cell: &CellFrame,
    half: f64,
    stride: usize,
    membership: &MembershipTable,
) -> f32 {
    let (sum, visited) = window_sum(px, centre, cell, half, stride, |p| member(membership, p));
    if visited == 0 {
        0.0
    } else {
        sum / visited as f32
    }
}

/// Mean of R + G + B over the window of half-size `half` (cell units) around `centre`; 0 for an empty window. Over
/// a patch in a square's middle (all yellow ink, whatever the pad's deformation) it changes with the light alone.
pub fn mean_brightness(px: &Pixels, centre: Point2, cell: &CellFrame, half: f64, stride: usize) -> f64 {
    let (sum, visited) = window_sum(px, centre, cell, half, stride, |p| {
        u64::from(p[0]) + u64::from(p[1]) + u64::from(p[2])
    });
    if visited == 0 {
        0.0
    } else {
        sum as f64 / visited as f64
    }
}

/// The sum of `value` over the window's pixels (in row order) and how many it visited.
fn window_sum<T: Default + std::ops::AddAssign>(
    px: &Pixels,
    centre: Point2,
    cell: &CellFrame,
    half: f64,
    stride: usize,
    mut value: impl FnMut([u8; 3]) -> T,
) -> (T, usize) {
    let (mut sum, mut visited) = (T::default(), 0usize);
    for_each_row(px, centre, cell, half, stride, |_, line, x0, x1| {
        for_each_pixel(line, x0, x1, stride, |p| {
            sum += value(p);
            visited += 1;
        });
    });
    (sum, visited)
}

#[cfg(test)]
mod tests {
    use super::super::yellowness::{Ramp, YELLOWNESS_BINS};
    use super::*;

    /// The gathered lookups (AVX2), and the permuted loads (AVX-512 VBMI) where this processor has them, give every bit
    /// the plain loop gives: windows of every stride the tracker uses and more, clipped by every border of the frame
    /// (the top-left corner's first byte included, where they fall back to the plain loop; the bottom-right one, where
    /// the permuted loads' masks keep them inside the frame), over a frame of noise with clipped pixels, and a ramp of
    /// memberships.
    #[test]
    #[cfg(target_arch = "x86_64")]
    fn gathered_lookups_are_the_plain_loops_bit_for_bit() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            eprintln!("no AVX2 here: the plain loop is the only one this processor runs");
            return;
        }
        let permutes = Lookup::detect() == Lookup::Permuted;
        if !permutes {
            eprintln!("no AVX-512 VBMI here: the permuted loads are not compared");
        }
        let (w, h) = (97usize, 61usize);
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let raw: Vec<u8> = (0..w * h * 3)
            .map(|_| match next() % 8 {
                0 => 255,
                1 => 250,
                _ => (next() % 256) as u8,
            })
            .collect();
        let px = Pixels {
            raw: &raw,
            width: w,
            height: h,
        };
        let membership = Membership::from(Ramp {
            start: 13.7,
            inv_width: 1.0 / 97.3,
        });
        let cells = [
            CellFrame::new([21.0, 0.0], [0.0, 19.0]).unwrap(),
            CellFrame::new([17.3, 4.1], [-3.7, 16.2]).unwrap(),
            CellFrame::new([40.0, -9.0], [8.0, 33.0]).unwrap(),
        ];
        let mut compared = 0;
        for stride in [1, 2, 3, 5] {
            for cell in &cells {
                for centre in [
                    [0.0, 0.0],
                    [3.0, 2.0],
                    [48.0, 30.0],
                    [96.0, 60.0],
                    [90.0, 4.0],
                    [7.4, 55.6],
                ] {
                    for half in [0.15, 0.55] {
                        let window = Window::new(*cell, half);
                        let plain = centroid_with(&px, centre, &window, stride, &membership, Lookup::Scalar);
                        let gathered = centroid_with(&px, centre, &window, stride, &membership, Lookup::Gathered);
                        let permuted = permutes
                            .then(|| centroid_with(&px, centre, &window, stride, &membership, Lookup::Permuted));
                        let bits = |c: Option<WindowCentroid>| {
                            c.map(|c| {
                                [
                                    c.at[0].to_bits(),
                                    c.at[1].to_bits(),
                                    c.area.to_bits(),
                                    c.clipped_fraction.to_bits(),
                                ]
                            })
                        };
                        assert_eq!(
                            bits(plain),
                            bits(gathered),
                            "stride {stride} centre {centre:?} half {half}"
                        );
                        if let Some(permuted) = permuted {
                            assert_eq!(
                                bits(plain),
                                bits(permuted),
                                "permuted: stride {stride} centre {centre:?} half {half}"
                            );
                        }
                        compared += usize::from(plain.is_some());
                    }
                }
            }
        }
        assert!(compared > 100, "{compared} windows held yellow");
    }

    /// The memberships the permuted loop computes are the table's entries, bit for bit, over every index and ramps of
    /// every kind the frames give (a threshold on either side of zero, contrasts from the smallest Otsu accepts on).
    #[test]
    #[cfg(target_arch = "x86_64")]
    fn computed_memberships_are_the_tables() {
        use std::arch::x86_64::*;
        if Lookup::detect() != Lookup::Permuted {
            eprintln!("no AVX-512 VBMI here: the computed memberships are not used");
            return;
        }
        for (threshold, contrast) in [(0.5, 8.0), (37.5, 91.3), (-12.5, 240.0), (101.5, 17.77), (254.5, 510.0)] {
            let half_width = f64::max(0.25 * contrast, 1.0);
            let ramp = Ramp {
                start: threshold - half_width,
                inv_width: 1.0 / (2.0 * half_width),
            };
            let table = ramp.table();
            for first in (0..YELLOWNESS_BINS as i32).step_by(8) {
                let bins: [i32; 8] = std::array::from_fn(|k| (first + k as i32).min(YELLOWNESS_BINS as i32 - 1));
                let mut computed = [0f32; 8];
                // SAFETY: the processor has AVX-512 (checked above); the ramp is finite.
                unsafe {
                    let m = ramp_memberships(
                        _mm256_loadu_si256(bins.as_ptr().cast()),
                        _mm512_set1_pd(ramp.start),
                        _mm512_set1_pd(ramp.inv_width),
                    );
                    _mm256_storeu_ps(computed.as_mut_ptr(), m);
                }
                for (bin, m) in bins.iter().zip(computed) {
                    assert_eq!(m.to_bits(), table[*bin as usize].to_bits(), "bin {bin} ramp {ramp:?}");
                }
            }
        }
    }

    /// A window's tabulated rows give the pixels its rows compute around a whole-pixel centre, past the table's ends
    /// too (where they are computed as they come), and rows whose ends lie near a pixel's edge.
    #[test]
    fn tabulated_rows_are_the_computed_ones() {
        let cells = [
            CellFrame::new([21.0, 0.0], [0.0, 19.0]).unwrap(),
            CellFrame::new([17.3, 4.1], [-3.7, 16.2]).unwrap(),
            CellFrame::new([40.0, -9.0], [8.0, 33.0]).unwrap(),
            CellFrame::new([91.7, 2.3], [-1.9, 88.4]).unwrap(),
            // Row ends on pixel edges: a square cell of 30 px, its half-width 4.5 px at 0.15 and 16.5 px at 0.55.
            CellFrame::new([30.0, 0.0], [0.0, 30.0]).unwrap(),
        ];
        let mut spans = 0;
        for cell in cells {
            for half in [0.15, 0.55] {
                let window = Window::new(cell, half);
                assert!(!window.rows.is_empty());
                spans += window
                    .rows
                    .iter()
                    .filter(|r| matches!(r, TabulatedRow::Span(..)))
                    .count();
                for centre in [[0.0f64, 0.0], [5.0, 7.0], [2047.0, 1535.0], [-3.0, 9.0], [4e6, 12.0]] {
                    let centre_row = centre[1] as i64;
                    let whole_x = centre[0].abs() <= WHOLE_CENTRE;
                    for y in (centre_row - 200).max(0)..centre_row + 200 {
                        let computed = computed_row(&cell, half, centre, y);
                        let tabulated = window.pixels(y - centre_row, centre[0], whole_x);
                        assert_eq!(tabulated, computed, "{cell:?} {half} {centre:?} {y}");
                    }
                }
            }
        }
        assert!(spans > 0, "no row end near a pixel's edge");
    }

    #[test]
    fn floor_and_ceil_are_the_libraries() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut values = vec![
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            2.5,
            -2.5,
            1e15 + 0.5,
            -1e15 - 0.5,
            4.5e15,
            1e300,
            -1e300,
            f64::MAX,
            f64::MIN_POSITIVE,
            -f64::MIN_POSITIVE,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ];
        for _ in 0..10_000 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            values.push((state >> 11) as f64 / (1u64 << 53) as f64 * 8000.0 - 4000.0);
            values.push(((state >> 20) % 4000) as f64 - 2000.0);
        }
        for x in values {
            let same = |a: f64, b: f64| a == b || (a.is_nan() && b.is_nan());
            assert!(same(floor(x), x.floor()), "floor {x}");
            assert!(same(ceil(x), x.ceil()), "ceil {x}");
        }
    }

    #[test]
    fn centroid_of_a_square_is_sub_pixel() {
        // A 20 x 20 yellow square from (40.5, 30.5) to (60.5, 50.5) with soft edges: centre (50.5, 40.5).
        let (w, h) = (100usize, 80usize);
        let mut raw = vec![0u8; w * h * 3];
        for y in 0..h {
            for x in 0..w {
                let cover = |c: f64, a: f64, b: f64| ((c + 0.5).min(b) - (c - 0.5).max(a)).clamp(0.0, 1.0);
                let k = cover(x as f64 + 0.5, 40.5, 60.5) * cover(y as f64 + 0.5, 30.5, 50.5);
                let i = (y * w + x) * 3;
                raw[i] = 200;
                raw[i + 1] = (40.0 + 160.0 * k) as u8;
                raw[i + 2] = 60;
            }
        }
        let px = Pixels {
            raw: &raw,
            width: w,
            height: h,
        };
        let cell = CellFrame::new([30.0, 0.0], [0.0, 30.0]).unwrap();
        let membership = Membership::from(Ramp {
            start: -20.0,
            inv_width: 1.0 / 140.0,
        });
        let found = centroid(&px, [48.0, 43.0], &Window::new(cell, 0.55), 1, &membership).unwrap();
        let (c, area) = (found.at, found.area);
        assert!((c[0] - 50.5).abs() < 0.05 && (c[1] - 40.5).abs() < 0.05, "{c:?}");
        assert!(area > 300.0 && area < 500.0, "{area}");
        assert_eq!(found.clipped_fraction, 0.0);
        assert!(mean_membership(&px, c, &cell, 0.15, 1, &membership.table) > 0.9);
        // Beside the square (here: on the red) is not on yellow.
        assert!(mean_membership(&px, [75.0, 40.0], &cell, 0.15, 1, &membership.table) < 0.1);
    }
}
