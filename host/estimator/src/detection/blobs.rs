//! Full-frame search (reference frame and recovery only): yellow blobs in the small yellowness map, kept when
//! they look like the pattern's squares (the dominant size, compact).

use nusense_geometry::Point2;

use super::yellowness::{otsu, OtsuSplit, YellownessMap};

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Blob {
    /// Centroid in raw px.
    pub centre: Point2,
    /// Area in raw px^2.
    pub area: f64,
}

/// Yellow blobs of square-like size and shape, and the Otsu split that defined "yellow".
pub fn find_square_blobs(map: &YellownessMap, expected_squares: usize) -> Option<(Vec<Blob>, OtsuSplit)> {
    let split = otsu(&map.histogram())?;
    if split.contrast() < 8.0 {
        return None;
    }
    let (w, h) = (map.width, map.height);
    let yellow: Vec<bool> = map.values.iter().map(|&v| f64::from(v) > split.threshold).collect();
    let mut label = vec![u32::MAX; w * h];
    let mut stack = Vec::new();
    struct Raw {
        count: usize,
        sx: f64,
        sy: f64,
        min: [usize; 2],
        max: [usize; 2],
    }
    let mut raws = Vec::new();
    for start in 0..w * h {
        if !yellow[start] || label[start] != u32::MAX {
            continue;
        }
        let id = raws.len() as u32;
        let mut r = Raw {
            count: 0,
            sx: 0.0,
            sy: 0.0,
            min: [usize::MAX; 2],
            max: [0; 2],
        };
        label[start] = id;
        stack.push(start);
        while let Some(i) = stack.pop() {
            let (x, y) = (i % w, i / w);
            r.count += 1;
            r.sx += x as f64;
            r.sy += y as f64;
            r.min = [r.min[0].min(x), r.min[1].min(y)];
            r.max = [r.max[0].max(x), r.max[1].max(y)];
            let mut visit = |j: usize| {
                if yellow[j] && label[j] == u32::MAX {
                    label[j] = id;
                    stack.push(j);
                }
            };
            if x > 0 {
                visit(i - 1);
            }
            if x + 1 < w {
                visit(i + 1);
            }
            if y > 0 {
                visit(i - w);
            }
            if y + 1 < h {
                visit(i + w);
            }
        }
        raws.push(r);
    }
    // The squares are the most numerous blobs of one size: take the median area of the largest
    // `expected_squares` blobs as that size (noise specks are smaller, merged blobs rarer).
    let mut areas: Vec<usize> = raws.iter().map(|r| r.count).collect();
    areas.sort_unstable_by(|a, b| b.cmp(a));
    let top = &areas[..areas.len().min(expected_squares.max(1))];
    let typical = *top.get(top.len() / 2)? as f64;
    if typical < 4.0 {
        return None;
    }
    let f = map.factor as f64;
    let blobs = raws
        .iter()
        .filter(|r| {
            let area = r.count as f64;
            let bbox = ((r.max[0] - r.min[0] + 1) * (r.max[1] - r.min[1] + 1)) as f64;
            // Not touching the map's border (a cut square has a biased centre); square-ish at any rotation.
            let inside = r.min[0] > 0 && r.min[1] > 0 && r.max[0] + 1 < w && r.max[1] + 1 < h;
            inside && area > 0.35 * typical && area < 2.5 * typical && area / bbox > 0.4
        })
        .map(|r| Blob {
            centre: [(r.sx / r.count as f64 + 0.5) * f, (r.sy / r.count as f64 + 0.5) * f],
            area: r.count as f64 * f * f,
        })
        .collect();
    Some((blobs, split))
}
