//! External contours of the closed edge map, approximated by polygons; quadrilaterals of plausible size and
//! solidity are the pattern's squares.
//!
//! Contours come from `imageproc::contours` (Suzuki-Abe, like OpenCV). The polygon approximation is our own:
//! `imageproc::geometry::approximate_polygon_dp` runs plain Douglas-Peucker from the contour's first point,
//! whereas OpenCV's `approxPolyDP` on a closed curve first looks for two far-apart points, splits there, and
//! then removes vertices on nearly straight runs. With epsilon = 8 % of the perimeter those differences decide
//! whether a square comes out with 4 vertices, so we follow OpenCV.

use image::GrayImage;
use imageproc::contours::BorderType;
use imageproc::point::Point;

/// A contour point or polygon vertex, in pixel indices of the ROI image.
pub type PixelPoint = [i32; 2];

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QuadFilter {
    pub epsilon_fraction: f64,
    pub min_area: f64,
    pub max_area: f64,
    pub min_solidity: f64,
}

/// A quadrilateral the published method accepts: its four vertices (as `approxPolyDP` returns them) and the
/// area of the contour it came from.
#[derive(Clone, Debug, PartialEq)]
pub struct Quad {
    pub vertices: [PixelPoint; 4],
    pub area: f64,
    pub solidity: f64,
}

impl Quad {
    pub fn centre(&self) -> [f64; 2] {
        let sx: i32 = self.vertices.iter().map(|v| v[0]).sum();
        let sy: i32 = self.vertices.iter().map(|v| v[1]).sum();
        [f64::from(sx) / 4.0, f64::from(sy) / 4.0]
    }
}

/// Outer borders of the outermost regions (OpenCV's RETR_EXTERNAL), compressed like CHAIN_APPROX_SIMPLE.
pub fn external_contours(binary: &GrayImage) -> Vec<Vec<PixelPoint>> {
    imageproc::contours::find_contours::<i32>(binary)
        .into_iter()
        .filter(|c| c.border_type == BorderType::Outer && c.parent.is_none())
        .map(|c| compress_chain(&c.points))
        .collect()
}

/// Keeps only the points where the chain changes direction (CHAIN_APPROX_SIMPLE); the polygon they describe is
/// the same, so perimeter and area are unchanged.
fn compress_chain(points: &[Point<i32>]) -> Vec<PixelPoint> {
    let n = points.len();
    if n < 3 {
        return points.iter().map(|p| [p.x, p.y]).collect();
    }
    let mut out = Vec::new();
    for i in 0..n {
        let prev = points[(i + n - 1) % n];
        let here = points[i];
        let next = points[(i + 1) % n];
        let incoming = (here.x - prev.x, here.y - prev.y);
        let outgoing = (next.x - here.x, next.y - here.y);
        if i == 0 || incoming != outgoing {
            out.push([here.x, here.y]);
        }
    }
    out
}

pub fn arc_length_closed(points: &[PixelPoint]) -> f64 {
    if points.len() < 2 {
        return 0.0;
    }
    let n = points.len();
    (0..n)
        .map(|i| {
            let a = points[i];
            let b = points[(i + 1) % n];
            f64::from(b[0] - a[0]).hypot(f64::from(b[1] - a[1]))
        })
        .sum()
}

/// Shoelace area, non-negative.
pub fn polygon_area(points: &[PixelPoint]) -> f64 {
    if points.len() < 3 {
        return 0.0;
    }
    let n = points.len();
    let twice: i64 = (0..n)
        .map(|i| {
            let a = points[i];
            let b = points[(i + 1) % n];
            i64::from(a[0]) * i64::from(b[1]) - i64::from(b[0]) * i64::from(a[1])
        })
        .sum();
    (twice as f64 / 2.0).abs()
}

fn convex_hull_area(points: &[PixelPoint]) -> f64 {
    let hull: Vec<PixelPoint> =
        imageproc::geometry::convex_hull(points.iter().map(|p| Point::new(p[0], p[1])).collect::<Vec<_>>())
            .into_iter()
            .map(|p| [p.x, p.y])
            .collect();
    polygon_area(&hull)
}

/// OpenCV's `approxPolyDP(curve, epsilon, closed = true)`.
pub fn approx_poly_dp_closed(curve: &[PixelPoint], epsilon: f64) -> Vec<PixelPoint> {
    let count = curve.len();
    if count == 0 {
        return Vec::new();
    }
    let eps2 = epsilon * epsilon;
    let at = |i: usize| curve[i % count];
    let dist2 = |a: PixelPoint, b: PixelPoint| {
        let dx = f64::from(b[0] - a[0]);
        let dy = f64::from(b[1] - a[1]);
        dx * dx + dy * dy
    };

    // 1. Approximately two farthest points: three rounds of "farthest from the current start".
    let mut start = 0usize;
    let mut far_offset = 0usize;
    let mut within_eps = false;
    for _ in 0..3 {
        start = (start + far_offset) % count;
        let start_pt = at(start);
        let mut max_dist = 0.0;
        far_offset = 0;
        for j in 1..count {
            let d = dist2(start_pt, at(start + j));
            if d > max_dist {
                max_dist = d;
                far_offset = j;
            }
        }
        within_eps = max_dist <= eps2;
    }

    let mut result: Vec<PixelPoint> = Vec::new();
    if within_eps {
        result.push(at(start));
    } else {
        // 2. Split at the two far points; 3. recursive subdivision, left slice first.
        let far = (start + far_offset) % count;
        let mut stack: Vec<(usize, usize)> = vec![(far, start), (start, far)];
        while let Some((slice_start, slice_end)) = stack.pop() {
            let start_pt = curve[slice_start];
            let end_pt = curve[slice_end];
            let mut pos = (slice_start + 1) % count;
            let mut split = slice_start;
            let le_eps = if pos != slice_end {
                let dx = f64::from(end_pt[0] - start_pt[0]);
                let dy = f64::from(end_pt[1] - start_pt[1]);
                let mut max_dist = 0.0;
                while pos != slice_end {
                    let pt = curve[pos];
                    let d = (f64::from(pt[1] - start_pt[1]) * dx - f64::from(pt[0] - start_pt[0]) * dy).abs();
                    if d > max_dist {
                        max_dist = d;
                        split = pos;
                    }
                    pos = (pos + 1) % count;
                }
                max_dist * max_dist <= eps2 * (dx * dx + dy * dy)
            } else {
                true
            };
            if le_eps {
                result.push(start_pt);
            } else {
                stack.push((split, slice_end));
                stack.push((slice_start, split));
            }
        }
    }

    remove_nearly_collinear(result, eps2)
}

/// OpenCV's final clean-up pass of approxPolyDP on a closed polygon: drops vertices that lie within
/// epsilon / sqrt(2) of the line through their neighbours (and between them).
fn remove_nearly_collinear(mut dst: Vec<PixelPoint>, eps2: f64) -> Vec<PixelPoint> {
    let count = dst.len();
    if count < 3 {
        return dst;
    }
    let mut new_count = count;
    let mut pos = count - 1;
    let read = |dst: &Vec<PixelPoint>, pos: &mut usize| {
        let p = dst[*pos];
        *pos += 1;
        if *pos >= count {
            *pos = 0;
        }
        p
    };
    let mut start_pt = read(&dst, &mut pos);
    let mut wpos = pos;
    let mut pt = read(&dst, &mut pos);
    let mut i = 0;
    while i < count && new_count > 2 {
        let end_pt = read(&dst, &mut pos);
        let dx = f64::from(end_pt[0] - start_pt[0]);
        let dy = f64::from(end_pt[1] - start_pt[1]);
        let dist = (f64::from(pt[0] - start_pt[0]) * dy - f64::from(pt[1] - start_pt[1]) * dx).abs();
        let successive_inner_product = f64::from(pt[0] - start_pt[0]) * f64::from(end_pt[0] - pt[0])
            + f64::from(pt[1] - start_pt[1]) * f64::from(end_pt[1] - pt[1]);
        if dist * dist <= 0.5 * eps2 * (dx * dx + dy * dy) && dx != 0.0 && dy != 0.0 && successive_inner_product >= 0.0
        {
            new_count -= 1;
            start_pt = end_pt;
            dst[wpos] = start_pt;
            wpos = (wpos + 1) % count;
            pt = read(&dst, &mut pos);
            i += 2;
            continue;
        }
        start_pt = pt;
        dst[wpos] = start_pt;
        wpos = (wpos + 1) % count;
        pt = end_pt;
        i += 1;
    }
    // Survivors are written from index 0 onwards, as in OpenCV, which returns the first `new_count` entries.
    dst.truncate(new_count);
    dst
}

/// The published quadrilateral test on each external contour.
pub fn find_quads(contours: &[Vec<PixelPoint>], filter: &QuadFilter) -> Vec<Quad> {
    contours
        .iter()
        .filter_map(|contour| {
            let perimeter = arc_length_closed(contour);
            if !(perimeter > 0.0) {
                return None;
            }
            let approx = approx_poly_dp_closed(contour, filter.epsilon_fraction * perimeter);
            if approx.len() != 4 {
                return None;
            }
            let area = polygon_area(contour);
            let hull_area = convex_hull_area(contour);
            let solidity = if hull_area > 0.0 { area / hull_area } else { 0.0 };
            let accepted = filter.min_area < area && area < filter.max_area && solidity > filter.min_solidity;
            accepted.then(|| Quad {
                vertices: [approx[0], approx[1], approx[2], approx[3]],
                area,
                solidity,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn filled_square(size: u32, x0: u32, y0: u32, side: u32) -> GrayImage {
        GrayImage::from_fn(size, size, |x, y| {
            image::Luma([if x >= x0 && x < x0 + side && y >= y0 && y < y0 + side {
                255
            } else {
                0
            }])
        })
    }

    #[test]
    fn square_contour_compresses_to_its_corners() {
        let contours = external_contours(&filled_square(20, 5, 6, 8));
        assert_eq!(contours.len(), 1);
        let mut c = contours[0].clone();
        c.sort();
        assert_eq!(c, vec![[5, 6], [5, 13], [12, 6], [12, 13]]);
        assert_eq!(polygon_area(&contours[0]), 49.0);
        assert_eq!(arc_length_closed(&contours[0]), 28.0);
    }

    #[test]
    fn holes_and_nested_regions_are_not_external() {
        // A ring with a blob inside its hole: only the ring's outer border is external.
        let img = GrayImage::from_fn(30, 30, |x, y| {
            let ring = (3..27).contains(&x) && (3..27).contains(&y) && !((6..24).contains(&x) && (6..24).contains(&y));
            let blob = (12..16).contains(&x) && (12..16).contains(&y);
            image::Luma([if ring || blob { 255 } else { 0 }])
        });
        assert_eq!(external_contours(&img).len(), 1);
    }

    #[test]
    fn approximates_a_rotated_square_by_four_vertices() {
        // A diamond (square rotated 45 degrees) with pixel staircase edges.
        let img = GrayImage::from_fn(80, 80, |x, y| {
            let d = (x as i32 - 40).abs() + (y as i32 - 40).abs();
            image::Luma([if d <= 30 { 255 } else { 0 }])
        });
        let contours = external_contours(&img);
        assert_eq!(contours.len(), 1);
        let approx = approx_poly_dp_closed(&contours[0], 0.08 * arc_length_closed(&contours[0]));
        assert_eq!(approx.len(), 4, "{approx:?}");
        let mut sorted = approx.clone();
        sorted.sort();
        assert_eq!(sorted, vec![[10, 40], [40, 10], [40, 70], [70, 40]]);
    }

    #[test]
    fn a_circle_is_not_a_quad_but_a_square_is() {
        let filter = QuadFilter {
            epsilon_fraction: 0.08,
            min_area: 100.0,
            max_area: 1e5,
            min_solidity: 0.2,
        };
        let square = external_contours(&filled_square(60, 10, 10, 30));
        let quads = find_quads(&square, &filter);
        assert_eq!(quads.len(), 1);
        assert!((quads[0].solidity - 1.0).abs() < 1e-12);
        assert_eq!(quads[0].centre(), [24.5, 24.5]);
        // Too small for the area window.
        let small = external_contours(&filled_square(60, 10, 10, 5));
        assert!(find_quads(&small, &filter).is_empty());
        // A triangle approximates to three vertices.
        let triangle = GrayImage::from_fn(60, 60, |x, y| {
            image::Luma([if x >= 5 && y >= 5 && x + y < 55 { 255 } else { 0 }])
        });
        assert!(find_quads(&external_contours(&triangle), &filter).is_empty());
    }

    #[test]
    fn degenerate_contours_do_not_panic() {
        assert!(approx_poly_dp_closed(&[], 1.0).is_empty());
        assert_eq!(approx_poly_dp_closed(&[[3, 3]], 1.0), vec![[3, 3]]);
        let line = vec![[0, 0], [5, 0]];
        assert!(approx_poly_dp_closed(&line, 0.5).len() <= 2);
        let filter = QuadFilter {
            epsilon_fraction: 0.08,
            min_area: 0.0,
            max_area: 1e5,
            min_solidity: 0.0,
        };
        assert!(find_quads(&[vec![], vec![[1, 1]], line], &filter).is_empty());
    }
}
