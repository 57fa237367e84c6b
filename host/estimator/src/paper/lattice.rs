//! From quadrilaterals to indexed control points.
//!
//! The published step pairs every quad vertex with the nearest vertex of another quad within a distance and
//! takes the midpoints as control points; it then matched them to the rest frame by sorting them into rows,
//! which breaks as soon as a row has a gap. Here the pairing stays as published, but correspondence is by
//! lattice index: each quad is a square of one colour of the checkerboard, and a pair joins two diagonal
//! neighbours, so walking the pairs gives every quad its (row, col) relative to a seed; a fitted affine lattice
//! places pieces that no pair connects; the colour of the quads fixes the checkerboard parity, and the pad's size
//! together with the region of interest (which the published method centres on the pad) fixes the offset.

use std::collections::{BTreeMap, HashSet, VecDeque};

use nusense_geometry::{CornerIndex, PadGeometry, SquareIndex};

use super::quads::{PixelPoint, Quad};

/// One published pairing: vertex `from_vertex` of quad `from` and its nearest vertex of another quad.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VertexPair {
    pub from: usize,
    pub from_vertex: usize,
    pub to: usize,
    pub to_vertex: usize,
    pub distance: f64,
    /// Integer midpoint, floor-divided as the published code does.
    pub midpoint: PixelPoint,
}

/// For every vertex of every quad, the nearest vertex of any other quad strictly closer than `max_distance`.
pub fn pair_vertices(quads: &[Quad], max_distance: f64) -> Vec<VertexPair> {
    let mut pairs = Vec::new();
    for (i, quad) in quads.iter().enumerate() {
        for (k, &a) in quad.vertices.iter().enumerate() {
            let mut best: Option<VertexPair> = None;
            let mut best_distance = f64::INFINITY;
            for (j, other) in quads.iter().enumerate() {
                if i == j {
                    continue;
                }
                for (l, &b) in other.vertices.iter().enumerate() {
                    let d = f64::from(a[0] - b[0]).hypot(f64::from(a[1] - b[1]));
                    if d < best_distance && d < max_distance {
                        best_distance = d;
                        best = Some(VertexPair {
                            from: i,
                            from_vertex: k,
                            to: j,
                            to_vertex: l,
                            distance: d,
                            midpoint: [(a[0] + b[0]).div_euclid(2), (a[1] + b[1]).div_euclid(2)],
                        });
                    }
                }
            }
            pairs.extend(best);
        }
    }
    pairs
}

/// Distinct midpoints: the published count of control points.
pub fn distinct_midpoints(pairs: &[VertexPair]) -> usize {
    pairs.iter().map(|p| p.midpoint).collect::<HashSet<_>>().len()
}

/// Why no lattice could be placed on the quads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum IndexingFailure {
    /// No two quads are paired, so the lattice's directions are unknown.
    NoPairs,
    /// The largest connected piece is too small (or degenerate) to fit a lattice to.
    TooFewConnected { found: usize, needed: usize },
    /// The quads span more rows or columns than the pad has.
    LargerThanPad,
}

/// The lattice placed on the quads.
#[derive(Clone, Debug, PartialEq)]
pub struct LatticeAssignment {
    /// Per quad, its cell on the pad (None: not placed).
    pub squares: Vec<Option<SquareIndex>>,
    /// Per interior corner found: the midpoint of the closest pair joining its two diagonal squares.
    pub corners: BTreeMap<CornerIndex, [f64; 2]>,
    /// Pairs that join quads which are not diagonal neighbours after indexing (dropped).
    pub implausible_pairs: usize,
}

/// Which colour the detected quads are: the colour decides the checkerboard parity of their indices.
pub trait CellColour {
    /// A score that is higher for yellow than for the red background, at a position in ROI pixel indices.
    fn yellowness(&self, at: [f64; 2]) -> f64;
}

/// A quad's (row, col) relative to the seed of its walk.
type RelativeCell = (i32, i32);

struct Link {
    a: usize,
    b: usize,
    step: (i32, i32),
}

/// An affine map from (row, col) to ROI px, fitted by least squares.
#[derive(Clone, Copy, Debug)]
struct AffineLattice {
    // x = m[0] * col + m[1] * row + m[2]; y = m[3] * col + m[4] * row + m[5]
    m: [f64; 6],
}

impl AffineLattice {
    fn fit(samples: &[((i32, i32), [f64; 2])]) -> Option<Self> {
        if samples.len() < 3 {
            return None;
        }
        // Normal equations of [col, row, 1].
        let mut ata = [[0.0f64; 3]; 3];
        let mut atx = [0.0f64; 3];
        let mut aty = [0.0f64; 3];
        for &((row, col), p) in samples {
            let a = [f64::from(col), f64::from(row), 1.0];
            for i in 0..3 {
                for j in 0..3 {
                    ata[i][j] += a[i] * a[j];
                }
                atx[i] += a[i] * p[0];
                aty[i] += a[i] * p[1];
            }
        }
        let sx = solve3(ata, atx)?;
        let sy = solve3(ata, aty)?;
        let lattice = Self {
            m: [sx[0], sx[1], sx[2], sy[0], sy[1], sy[2]],
        };
        (lattice.determinant().abs() > 1e-6).then_some(lattice)
    }

    fn determinant(&self) -> f64 {
        self.m[0] * self.m[4] - self.m[1] * self.m[3]
    }

    fn position(&self, row: f64, col: f64) -> [f64; 2] {
        let m = &self.m;
        [m[0] * col + m[1] * row + m[2], m[3] * col + m[4] * row + m[5]]
    }

    /// Continuous (row, col) of a position.
    fn index_of(&self, p: [f64; 2]) -> (f64, f64) {
        let m = &self.m;
        let (x, y) = (p[0] - m[2], p[1] - m[5]);
        let det = self.determinant();
        let col = (m[4] * x - m[1] * y) / det;
        let row = (-m[3] * x + m[0] * y) / det;
        (row, col)
    }
}

fn solve3(mut a: [[f64; 3]; 3], mut b: [f64; 3]) -> Option<[f64; 3]> {
    for col in 0..3 {
        let pivot = (col..3).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[pivot][col].abs() < 1e-12 {
            return None;
        }
        a.swap(col, pivot);
        b.swap(col, pivot);
        let pivot_row = a[col];
        for row in col + 1..3 {
            let f = a[row][col] / pivot_row[col];
            for (x, p) in a[row][col..].iter_mut().zip(&pivot_row[col..]) {
                *x -= f * p;
            }
            b[row] -= f * b[col];
        }
    }
    let mut x = [0.0; 3];
    for row in (0..3).rev() {
        let s: f64 = (row + 1..3).map(|k| a[row][k] * x[k]).sum();
        x[row] = (b[row] - s) / a[row][row];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        return f64::NAN;
    }
    v[v.len() / 2]
}

/// Quads in the largest connected piece needed to fit the lattice.
pub const MIN_CONNECTED_QUADS: usize = 4;
/// A piece joins the lattice only if each of its quads lies this close (in cells) to its predicted cell.
const MAX_PLACEMENT_ERROR_CELLS: f64 = 0.35;

pub fn assign_lattice(
    quads: &[Quad],
    pairs: &[VertexPair],
    pad: &PadGeometry,
    roi_centre: [f64; 2],
    colour: &impl CellColour,
) -> Result<LatticeAssignment, IndexingFailure> {
    let centres: Vec<[f64; 2]> = quads.iter().map(Quad::centre).collect();
    let links = diagonal_links(&centres, pairs)?;
    let (relative, pieces) = connected_pieces(quads.len(), &links);
    let lattice = fit_main_piece(&pieces[0], &relative, &centres)?;
    let placed = place_pieces(&pieces, &relative, &centres, &lattice);
    let parity = quad_parity(&placed, &centres, &lattice, colour, pad);
    let offset = absolute_offset(&placed, &lattice, pad, roi_centre, parity)?;
    let squares: Vec<Option<SquareIndex>> = placed
        .iter()
        .map(|cell| {
            cell.map(|(r, c)| SquareIndex {
                row: (r + offset.0) as u16,
                col: (c + offset.1) as u16,
            })
        })
        .collect();
    let (corners, implausible_pairs) = closest_pair_per_corner(pairs, &squares);
    Ok(LatticeAssignment {
        squares,
        corners,
        implausible_pairs,
    })
}

/// Relative indices by breadth-first walks over the links, one walk per connected piece; the pieces come
/// largest first, each walk's indices relative to its own seed.
fn connected_pieces(quad_count: usize, links: &[Link]) -> (Vec<Option<RelativeCell>>, Vec<Vec<usize>>) {
    let mut adjacency: Vec<Vec<(usize, (i32, i32))>> = vec![Vec::new(); quad_count];
    for link in links {
        adjacency[link.a].push((link.b, link.step));
        adjacency[link.b].push((link.a, (-link.step.0, -link.step.1)));
    }
    let mut relative: Vec<Option<RelativeCell>> = vec![None; quad_count];
    let mut pieces: Vec<Vec<usize>> = Vec::new();
    for seed in 0..quad_count {
        if relative[seed].is_some() {
            continue;
        }
        relative[seed] = Some((0, 0));
        let mut piece = vec![seed];
        let mut queue = VecDeque::from([seed]);
        while let Some(q) = queue.pop_front() {
            let (r, c) = relative[q].expect("queued quads are placed");
            for &(n, (dr, dc)) in &adjacency[q] {
                if relative[n].is_none() {
                    relative[n] = Some((r + dr, c + dc));
                    piece.push(n);
                    queue.push_back(n);
                }
            }
        }
        pieces.push(piece);
    }
    pieces.sort_by_key(|p| std::cmp::Reverse(p.len()));
    (relative, pieces)
}

/// The affine lattice through the largest piece's quads, if the piece is big enough to fit one.
fn fit_main_piece(
    main: &[usize],
    relative: &[Option<RelativeCell>],
    centres: &[[f64; 2]],
) -> Result<AffineLattice, IndexingFailure> {
    let samples: Vec<((i32, i32), [f64; 2])> = main
        .iter()
        .map(|&q| (relative[q].expect("walked"), centres[q]))
        .collect();
    (main.len() >= MIN_CONNECTED_QUADS)
        .then(|| AffineLattice::fit(&samples))
        .flatten()
        .ok_or(IndexingFailure::TooFewConnected {
            found: main.len(),
            needed: MIN_CONNECTED_QUADS,
        })
}

/// Per quad, its cell relative to the largest piece's seed: the largest piece as walked, the other pieces
/// (often single quads whose corners found no partner) placed through the fitted lattice, largest first, each
/// only if none of its cells is taken already.
fn place_pieces(
    pieces: &[Vec<usize>],
    relative: &[Option<RelativeCell>],
    centres: &[[f64; 2]],
    lattice: &AffineLattice,
) -> Vec<Option<RelativeCell>> {
    let mut placed: Vec<Option<RelativeCell>> = vec![None; relative.len()];
    let mut taken: HashSet<(i32, i32)> = HashSet::new();
    for &q in &pieces[0] {
        placed[q] = relative[q];
        taken.insert(relative[q].expect("walked"));
    }
    for piece in &pieces[1..] {
        if let Some(offset) = piece_offset(piece, relative, centres, lattice) {
            let cells: Vec<(i32, i32)> = piece
                .iter()
                .map(|&q| {
                    let (r, c) = relative[q].expect("walked");
                    (r + offset.0, c + offset.1)
                })
                .collect();
            if cells.iter().all(|cell| !taken.contains(cell)) {
                for (&q, &cell) in piece.iter().zip(&cells) {
                    placed[q] = Some(cell);
                    taken.insert(cell);
                }
            }
        }
    }
    placed
}

/// Per interior corner, the midpoint of the closest pair joining its two diagonal squares; and the count of
/// pairs whose quads are unplaced or not diagonal neighbours.
fn closest_pair_per_corner(
    pairs: &[VertexPair],
    squares: &[Option<SquareIndex>],
) -> (BTreeMap<CornerIndex, [f64; 2]>, usize) {
    let mut corners: BTreeMap<CornerIndex, ([f64; 2], f64)> = BTreeMap::new();
    let mut implausible_pairs = 0;
    for pair in pairs {
        let (Some(a), Some(b)) = (squares[pair.from], squares[pair.to]) else {
            implausible_pairs += 1;
            continue;
        };
        if a.row.abs_diff(b.row) != 1 || a.col.abs_diff(b.col) != 1 {
            implausible_pairs += 1;
            continue;
        }
        let corner = CornerIndex {
            row: a.row.min(b.row),
            col: a.col.min(b.col),
        };
        let midpoint = [f64::from(pair.midpoint[0]), f64::from(pair.midpoint[1])];
        let keep = corners.get(&corner).is_none_or(|&(_, d)| pair.distance < d);
        if keep {
            corners.insert(corner, (midpoint, pair.distance));
        }
    }
    let corners = corners.into_iter().map(|(k, (p, _))| (k, p)).collect();
    (corners, implausible_pairs)
}

/// Pairs that join two different quads, each as a unit diagonal step in the lattice's own axes.
fn diagonal_links(centres: &[[f64; 2]], pairs: &[VertexPair]) -> Result<Vec<Link>, IndexingFailure> {
    let vectors: Vec<(usize, usize, [f64; 2])> = pairs
        .iter()
        .filter(|p| p.from < p.to)
        .map(|p| {
            (
                p.from,
                p.to,
                [
                    centres[p.to][0] - centres[p.from][0],
                    centres[p.to][1] - centres[p.from][1],
                ],
            )
        })
        .chain(
            // A pair seen only from the higher-numbered quad still joins the two.
            pairs
                .iter()
                .filter(|p| p.from > p.to && !pairs.iter().any(|q| q.from == p.to && q.to == p.from))
                .map(|p| {
                    (
                        p.to,
                        p.from,
                        [
                            centres[p.from][0] - centres[p.to][0],
                            centres[p.from][1] - centres[p.to][1],
                        ],
                    )
                }),
        )
        .collect();
    if vectors.is_empty() {
        return Err(IndexingFailure::NoPairs);
    }
    // Diagonal steps point at 45 + k 90 degrees in the lattice's axes: the mean of 4 (angle - 45 deg) on the
    // circle gives the lattice's rotation without knowing k.
    let (mut s, mut c) = (0.0, 0.0);
    for (_, _, v) in &vectors {
        let a = 4.0 * (v[1].atan2(v[0]) - std::f64::consts::FRAC_PI_4);
        s += a.sin();
        c += a.cos();
    }
    let rotation = s.atan2(c) / 4.0;
    let (sin, cos) = rotation.sin_cos();
    let in_axes: Vec<(usize, usize, [f64; 2])> = vectors
        .iter()
        .map(|&(a, b, v)| (a, b, [cos * v[0] + sin * v[1], -sin * v[0] + cos * v[1]]))
        .collect();
    let pitch_x = median(in_axes.iter().map(|(_, _, u)| u[0].abs()).collect());
    let pitch_y = median(in_axes.iter().map(|(_, _, u)| u[1].abs()).collect());
    let plausible = |d: f64, pitch: f64| d > 0.5 * pitch && d < 1.5 * pitch;
    Ok(in_axes
        .into_iter()
        .filter(|(_, _, u)| plausible(u[0].abs(), pitch_x) && plausible(u[1].abs(), pitch_y))
        .map(|(a, b, u)| Link {
            a,
            b,
            step: (u[1].signum() as i32, u[0].signum() as i32),
        })
        .collect())
}

/// The index shift that puts a piece where the fitted lattice predicts it, keeping the colour parity.
fn piece_offset(
    piece: &[usize],
    relative: &[Option<RelativeCell>],
    centres: &[[f64; 2]],
    lattice: &AffineLattice,
) -> Option<(i32, i32)> {
    let residuals: Vec<(f64, f64)> = piece
        .iter()
        .map(|&q| {
            let (r, c) = relative[q].expect("walked");
            let (pr, pc) = lattice.index_of(centres[q]);
            (pr - f64::from(r), pc - f64::from(c))
        })
        .collect();
    let n = residuals.len() as f64;
    let mean = (
        residuals.iter().map(|r| r.0).sum::<f64>() / n,
        residuals.iter().map(|r| r.1).sum::<f64>() / n,
    );
    let base = (mean.0.round() as i32, mean.1.round() as i32);
    let candidates = [
        base,
        (base.0 + 1, base.1),
        (base.0 - 1, base.1),
        (base.0, base.1 + 1),
        (base.0, base.1 - 1),
    ];
    candidates
        .into_iter()
        // Quads are all of one colour: a shift must keep row + col parity.
        .filter(|&(dr, dc)| (dr + dc).rem_euclid(2) == 0)
        .map(|(dr, dc)| {
            let worst = residuals
                .iter()
                .map(|&(rr, rc)| (rr - f64::from(dr)).abs().max((rc - f64::from(dc)).abs()))
                .fold(0.0, f64::max);
            ((dr, dc), worst)
        })
        .filter(|&(_, worst)| worst < MAX_PLACEMENT_ERROR_CELLS)
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(offset, _)| offset)
}

/// Parity (row + col) mod 2 of the detected quads' relative indices that makes them the colour they are.
/// Returns the parity that relative (0, 0) must have in absolute indices.
fn quad_parity(
    placed: &[Option<(i32, i32)>],
    centres: &[[f64; 2]],
    lattice: &AffineLattice,
    colour: &impl CellColour,
    pad: &PadGeometry,
) -> i32 {
    // Compare the quads' own colour with the cells beside them (the other colour).
    let (mut own, mut beside) = (0.0, 0.0);
    for (q, cell) in placed.iter().enumerate() {
        if let Some((r, c)) = cell {
            own += colour.yellowness(centres[q]);
            beside += colour.yellowness(lattice.position(f64::from(*r), f64::from(*c) + 1.0));
        }
    }
    let quads_are_yellow = own >= beside;
    let yellow_parity = if pad.top_left_yellow { 0 } else { 1 };
    if quads_are_yellow {
        yellow_parity
    } else {
        1 - yellow_parity
    }
}

/// Shift from relative to absolute indices: every placed quad must land on the pad with the right colour
/// parity; among the shifts that allow that, the one that puts the pad's centre nearest the ROI's centre.
fn absolute_offset(
    placed: &[Option<(i32, i32)>],
    lattice: &AffineLattice,
    pad: &PadGeometry,
    roi_centre: [f64; 2],
    parity: i32,
) -> Result<(i32, i32), IndexingFailure> {
    let cells: Vec<(i32, i32)> = placed.iter().flatten().copied().collect();
    let (min_r, max_r) = (
        cells.iter().map(|c| c.0).min().unwrap_or(0),
        cells.iter().map(|c| c.0).max().unwrap_or(0),
    );
    let (min_c, max_c) = (
        cells.iter().map(|c| c.1).min().unwrap_or(0),
        cells.iter().map(|c| c.1).max().unwrap_or(0),
    );
    let (rows, cols) = (i32::from(pad.rows), i32::from(pad.cols));
    let centre_cell = (f64::from(rows - 1) / 2.0, f64::from(cols - 1) / 2.0);
    let mut best: Option<((i32, i32), f64)> = None;
    for dr in -min_r..=(rows - 1 - max_r) {
        for dc in -min_c..=(cols - 1 - max_c) {
            // Relative (0, 0) is a detected quad's cell: its absolute parity is dr + dc.
            if (dr + dc).rem_euclid(2) != parity {
                continue;
            }
            let p = lattice.position(centre_cell.0 - f64::from(dr), centre_cell.1 - f64::from(dc));
            let d = (p[0] - roi_centre[0]).hypot(p[1] - roi_centre[1]);
            if best.is_none_or(|(_, bd)| d < bd) {
                best = Some(((dr, dc), d));
            }
        }
    }
    best.map(|(offset, _)| offset).ok_or(IndexingFailure::LargerThanPad)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A synthetic lattice of yellow squares as the quad stage would report them: squares of side `s` centred
    /// on cell centres with small gaps at the corners.
    fn synthetic_quads(
        pad: &PadGeometry,
        pitch: f64,
        origin: [f64; 2],
        skip: &[SquareIndex],
    ) -> (Vec<Quad>, Vec<SquareIndex>) {
        let half = 0.5 * pitch - 3.0;
        let mut quads = Vec::new();
        let mut truth = Vec::new();
        for cell in pad.yellow_squares() {
            if skip.contains(&cell) {
                continue;
            }
            let cx = origin[0] + (f64::from(cell.col) + 0.5) * pitch;
            let cy = origin[1] + (f64::from(cell.row) + 0.5) * pitch;
            let v = |dx: f64, dy: f64| [(cx + dx).round() as i32, (cy + dy).round() as i32];
            quads.push(Quad {
                vertices: [v(-half, -half), v(half, -half), v(half, half), v(-half, half)],
                area: (2.0 * half).powi(2),
                solidity: 1.0,
            });
            truth.push(cell);
        }
        (quads, truth)
    }

    struct Checkerboard {
        pitch: f64,
        origin: [f64; 2],
    }

    impl CellColour for Checkerboard {
        fn yellowness(&self, at: [f64; 2]) -> f64 {
            let c = ((at[0] - self.origin[0]) / self.pitch).floor() as i64;
            let r = ((at[1] - self.origin[1]) / self.pitch).floor() as i64;
            if (r + c).rem_euclid(2) == 0 {
                100.0
            } else {
                -50.0
            }
        }
    }

    #[test]
    fn indexes_a_full_lattice_exactly() {
        let pad = PadGeometry::default();
        let (pitch, origin) = (80.0, [30.0, 20.0]);
        let (quads, truth) = synthetic_quads(&pad, pitch, origin, &[]);
        let pairs = pair_vertices(&quads, 50.0);
        let roi_centre = [origin[0] + 8.0 * pitch, origin[1] + 6.0 * pitch];
        let got = assign_lattice(&quads, &pairs, &pad, roi_centre, &Checkerboard { pitch, origin }).unwrap();
        let expected: Vec<Option<SquareIndex>> = truth.iter().copied().map(Some).collect();
        assert_eq!(got.squares, expected);
        assert_eq!(got.corners.len(), pad.corner_count());
        assert_eq!(got.implausible_pairs, 0);
        let c = got.corners[&CornerIndex { row: 4, col: 6 }];
        assert!((c[0] - (origin[0] + 7.0 * pitch)).abs() <= 1.0 && (c[1] - (origin[1] + 5.0 * pitch)).abs() <= 1.0);
        assert_eq!(distinct_midpoints(&pairs), pad.corner_count());
    }

    #[test]
    fn isolated_quads_are_placed_through_the_lattice_and_gaps_stay_masked() {
        let pad = PadGeometry::default();
        let (pitch, origin) = (80.0, [30.0, 20.0]);
        // Remove the four diagonal neighbours of (6, 8): it becomes an isolated piece.
        let skip = [
            SquareIndex { row: 5, col: 7 },
            SquareIndex { row: 5, col: 9 },
            SquareIndex { row: 7, col: 7 },
            SquareIndex { row: 7, col: 9 },
        ];
        let (quads, truth) = synthetic_quads(&pad, pitch, origin, &skip);
        let pairs = pair_vertices(&quads, 50.0);
        let roi_centre = [origin[0] + 8.0 * pitch, origin[1] + 6.0 * pitch];
        let got = assign_lattice(&quads, &pairs, &pad, roi_centre, &Checkerboard { pitch, origin }).unwrap();
        let expected: Vec<Option<SquareIndex>> = truth.iter().copied().map(Some).collect();
        assert_eq!(got.squares, expected);
        // Each removed square takes its 4 corners (corners on the border of the pad have fewer) with it.
        assert!(!got.corners.contains_key(&CornerIndex { row: 5, col: 7 }));
        assert!(got.corners.len() < pad.corner_count());
    }

    #[test]
    fn parity_follows_colour_when_the_first_row_is_missing() {
        // Without row 0 the detected quads span rows 1..11: the colour and the ROI centre must still place them.
        let pad = PadGeometry::default();
        let (pitch, origin) = (80.0, [30.0, 20.0]);
        let skip: Vec<SquareIndex> = pad.yellow_squares().filter(|s| s.row == 0).collect();
        let (quads, truth) = synthetic_quads(&pad, pitch, origin, &skip);
        let pairs = pair_vertices(&quads, 50.0);
        let roi_centre = [origin[0] + 8.0 * pitch, origin[1] + 6.0 * pitch];
        let got = assign_lattice(&quads, &pairs, &pad, roi_centre, &Checkerboard { pitch, origin }).unwrap();
        let expected: Vec<Option<SquareIndex>> = truth.iter().copied().map(Some).collect();
        assert_eq!(got.squares, expected);
    }

    #[test]
    fn no_pairs_is_a_typed_failure() {
        let pad = PadGeometry::default();
        let (quads, _) = synthetic_quads(&pad, 80.0, [0.0, 0.0], &[]);
        let lonely = vec![quads[0].clone()];
        let pairs = pair_vertices(&lonely, 50.0);
        let colour = Checkerboard {
            pitch: 80.0,
            origin: [0.0, 0.0],
        };
        assert_eq!(
            assign_lattice(&lonely, &pairs, &pad, [0.0, 0.0], &colour),
            Err(IndexingFailure::NoPairs)
        );
        let two = vec![quads[0].clone(), quads[8].clone()];
        let pairs = pair_vertices(&two, 50.0);
        assert!(matches!(
            assign_lattice(&two, &pairs, &pad, [0.0, 0.0], &colour),
            Err(IndexingFailure::TooFewConnected { .. })
        ));
    }
}
