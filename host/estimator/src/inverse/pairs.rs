//! Two presses or one long contact: two round loads against the best straight line load, which splits a contact
//! that is two presses side by side and joins the parts of a long contact the cell map cut apart.

use nusense_geometry::Point2;

use super::lines::{pattern_search, shape_correlation, LineLoad};
use super::moments::ROUND_EXTENT_PITCHES;
use super::regions::group_of;
use super::{InverseModel, Observed, Region, Stage1, Traction, SUPPORT_SIGMAS};

/// [`InverseModel::pair_against_line`]'s pattern search for the two points stops once its halved steps are all
/// below this (mm).
const PAIR_FIT_TOLERANCE_MM: f64 = 0.05;

/// Two round loads against a line load, as [`InverseModel::pair_against_line`] finds them.
pub(super) struct PairAgainstLine {
    /// The two points, mm.
    points: [Point2; 2],
    /// The pair's explained sum of squares less the line's (see [`InverseModel::fit_line_to`]), mm^2.
    gain_mm2: f64,
    /// The two loads' least-squares amplitudes at `points` (model newtons), when both are positive (else the pair is
    /// one load at best).
    amplitudes: Option<[f64; 2]>,
}

/// How round loads at the contacts' own centres must compare with the line that joins three contacts or more (see
/// [`InverseModel::joined_as_line`]).
#[derive(Clone, Copy)]
enum RoundLoads {
    /// The line explains more than they do by the margin (`join_long_groups`, which has no other evidence of a line).
    WorseThanLine,
    /// They do not explain more than the line by the margin (`join_cut_lines`, whose gap test already asks for the
    /// line's pressure between the parts).
    NotBetterThanLine,
}

/// A region's best straight line load, as [`InverseModel::best_line`] fits it: the matched filter's correlations it was
/// fitted to, the line, and the sum of squares it explains (mm^2).
struct BestLine {
    matched: Vec<f64>,
    line: LineLoad,
    score: f64,
}

/// Puts `union` in the place of the first of `members` (ascending indices into `regions`) and removes the others.
fn merge_into_first(regions: &mut Vec<Region>, members: &[usize], union: Region) {
    regions[members[0]] = union;
    for &m in members[1..].iter().rev() {
        regions.remove(m);
    }
}

impl InverseModel {
    /// Two round loads (free positions, amplitudes >= 0, each spread as the best line's points are) against the best
    /// straight line load (a long contact, see [`Self::fit_line_to`]) as the explanation of an elongated region's
    /// displacements (`None` when it is not elongated, see [`Self::elongation`]): the pair's positions and how much
    /// more of the displacements it explains. Points unspread are sharper than the presses the data show, and the
    /// line, longer, makes up for it: on tests/hard_cases.rs' sensor the pair then settled 8.5-9.5 mm apart over
    /// two spheres 10 mm apart and the line explained more on 10 of 15 such pairs; spread alike, the pair explains
    /// 0.04-0.13 mm^2 more on all 15 and a 20 mm edge's line still 0.02-0.11 mm^2 more than a pair (the margin
    /// there is about 0.001 mm^2).
    fn pair_against_line(&self, region: &Region, observed: Observed) -> Option<PairAgainstLine> {
        Some(self.pair_against(&self.best_line(region, observed)?))
    }

    /// The best straight line load of an elongated region (`None` when it is not elongated, see
    /// [`Self::elongation`]), in the displacements less stage 2's other tractions (see [`Self::matched_without`]).
    fn best_line(&self, region: &Region, observed: Observed) -> Option<BestLine> {
        let start = self.elongation(region)?;
        let mut cells: Vec<usize> = region.cells.iter().map(|c| c.0).collect();
        cells.sort_unstable();
        let matched = self.matched_without(observed, &cells);
        let (line, score) = self.fit_line_to(&matched, start);
        Some(BestLine { matched, line, score })
    }

    /// [`Self::pair_against_line`] given the region's best line.
    fn pair_against(&self, best: &BestLine) -> PairAgainstLine {
        let (matched, line, line_score) = (&best.matched, best.line, best.score);
        let pitch = self.pad.pitch_x_mm().max(self.pad.pitch_y_mm());
        let (c, s) = (line.angle_deg.to_radians().cos(), line.angle_deg.to_radians().sin());
        let quarter = 0.25 * line.length_mm;
        // Each point's shape, correlation and energy, kept while it stays where it is: the search moves one
        // coordinate at a time, so one of the two points.
        struct Point {
            at: Option<Point2>,
            shape: Vec<(usize, f64)>,
            correlation: f64,
            energy: f64,
        }
        let mut points = [(); 2].map(|()| Point {
            at: None,
            shape: Vec::new(),
            correlation: 0.0,
            energy: 0.0,
        });
        let mut dense = Vec::new();
        // The explained sum of squares and, when both are positive, the two amplitudes.
        let mut fit = |p: &[f64; 4]| -> (f64, Option<[f64; 2]>) {
            for (point, at) in points.iter_mut().zip([[p[0], p[1]], [p[2], p[3]]]) {
                if point.at != Some(at) {
                    self.line_shape(at, 0.0, 0.0, line.spread_mm, &mut dense, &mut point.shape);
                    point.correlation = shape_correlation(&point.shape, matched);
                    point.energy = self.matched_product(&point.shape, &point.shape);
                    point.at = Some(at);
                }
            }
            let [first, second] = &points;
            let (c1, c2) = (first.correlation, second.correlation);
            let (g11, g22, g12) = (
                first.energy,
                second.energy,
                self.matched_product(&first.shape, &second.shape),
            );
            let det = g11 * g22 - g12 * g12;
            let (a1, a2) = ((g22 * c1 - g12 * c2) / det, (g11 * c2 - g12 * c1) / det);
            if det > 0.0 && a1 > 0.0 && a2 > 0.0 {
                (a1 * c1 + a2 * c2, Some([a1, a2]))
            } else {
                let alone = |c: f64, g: f64| if c > 0.0 && g > 0.0 { c * c / g } else { 0.0 };
                (alone(c1, g11).max(alone(c2, g22)), None)
            }
        };
        let start = [
            line.centre_mm[0] - quarter * c,
            line.centre_mm[1] - quarter * s,
            line.centre_mm[0] + quarter * c,
            line.centre_mm[1] + quarter * s,
        ];
        let (p, pair_score) = pattern_search(
            start,
            [0.25 * pitch; 4],
            |steps| steps.iter().all(|&s| s < PAIR_FIT_TOLERANCE_MM),
            |_| {},
            &mut |p| fit(p).0,
        );
        PairAgainstLine {
            points: [[p[0], p[1]], [p[2], p[3]]],
            gain_mm2: pair_score - line_score,
            amplitudes: fit(&p).1,
        }
    }

    /// Two presses side by side read as one elongated contact when the cover's blur fills the dip between them (on
    /// the validation set, pairs 10 mm apart along oblique directions, which the cell map shows as one peak): a
    /// contact is split in two when [`Self::two_presses`] says so (both loads positive), its two points lie at least
    /// [`ROUND_EXTENT_PITCHES`] apart (closer, the map shows one round contact either way), and each half of its
    /// cells (split at the points' bisector, carrying its load's share of the contact's force) clears the floor where
    /// it is.
    pub(super) fn split_pair(
        &self,
        region: &Region,
        observed: Observed,
        noise_mm: f64,
        min_force_n: f64,
    ) -> Option<[Region; 2]> {
        let pair = self.two_presses(region, observed, noise_mm)?;
        let [a, b] = pair.points;
        let amplitudes = pair.amplitudes?;
        let axis = [b[0] - a[0], b[1] - a[1]];
        let pitch = self.pad.pitch_x_mm().max(self.pad.pitch_y_mm());
        if axis[0].hypot(axis[1]) < ROUND_EXTENT_PITCHES * pitch {
            return None;
        }
        let middle = [0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])];
        let (near_a, near_b): (Vec<Traction>, Vec<Traction>) = region.cells.iter().partition(|(j, _)| {
            let p = self.cells[*j].centre_mm;
            (p[0] - middle[0]) * axis[0] + (p[1] - middle[1]) * axis[1] < 0.0
        });
        if near_a.is_empty() || near_b.is_empty() {
            return None;
        }
        // Each half carries the share of the contact's force its load has in the pair's fit: the cells on one side of
        // the bisector also hold the other press's blurred tail, which the fit gives back to it.
        let total_n = region.force_vector_n[2];
        let own_n = |cells: &[Traction]| cells.iter().map(|c| c.1[2]).sum::<f64>();
        if !(own_n(&near_a) > 0.0 && own_n(&near_b) > 0.0) {
            return None;
        }
        let halves = [(near_a, amplitudes[0]), (near_b, amplitudes[1])].map(|(cells, amplitude)| {
            let factor = total_n * amplitude / (amplitudes[0] + amplitudes[1]) / own_n(&cells);
            self.region(cells.into_iter().map(|(j, f)| (j, f.map(|t| t * factor))).collect())
        });
        halves
            .iter()
            .all(|h| h.force_vector_n[2] >= min_force_n * h.floor_scale)
            .then_some(halves)
    }

    /// The two presses (where they are and their loads), when an elongated region is two of them rather than one long
    /// contact: two round loads explain its displacements better than the best straight line load by more than
    /// [`SUPPORT_SIGMAS`]^2 times the noise at `noise_mm` (the 3 sigma rule of the dips' test; see
    /// [`Self::pair_against_line`]).
    pub(super) fn two_presses(&self, region: &Region, observed: Observed, noise_mm: f64) -> Option<PairAgainstLine> {
        let pair = self.pair_against_line(region, observed)?;
        (pair.gain_mm2 > SUPPORT_SIGMAS * SUPPORT_SIGMAS * noise_mm * noise_mm).then_some(pair)
    }

    /// Whether the loads stage 1 finds at `noise_mm` (its loaded cells and their ring, every group taken as one
    /// region, with stage 1's pressure) are two presses by `Self::two_presses`' rule. The gamma modes read one
    /// contact and take the edge direction from the whole shear field, which two presses side by side make as
    /// elongated as an edge, along the pair; a long contact, which a line explains as well as two points, is not two.
    pub fn stage1_loads_are_two_presses(&self, stage: &Stage1, d: &[f64], valid: &[bool], noise_mm: f64) -> bool {
        let cells: Vec<Traction> = self
            .loaded_groups(stage, noise_mm)
            .into_iter()
            .flatten()
            .map(|j| (j, [0.0, 0.0, stage.tractions[3 * j + 2]]))
            .collect();
        let observed = Observed {
            d,
            valid,
            tractions: &stage.tractions,
        };
        !cells.is_empty() && self.two_presses(&self.region(cells), observed, noise_mm).is_some()
    }

    /// Two regions of one loaded group are one long contact that the cell map cut in two (it cuts the validation
    /// pad's 20 mm edges about 5 mm either side of their centres, where the equivalent layer misreads that pad) when
    /// a straight line load explains their union (with the group's other regions either touches: a contact cut in
    /// three is judged whole) better than two round loads by more than
    /// [`SUPPORT_SIGMAS`]^2 times the noise at `noise_mm` (the other way round from [`Self::two_presses`]), the
    /// weaker would be listed beside the other on its own ([`Self::holds_its_own`]: a load the border or the other's
    /// far field explains is not a part of it), and the pressure between them is more than two round presses can
    /// leave there ([`Self::gap_exceeds_two_presses`]). Three regions or more are not joined when round loads at
    /// their own centres explain their union better than the line by that margin ([`Self::loads_against`]): three 5
    /// mm spheres 12 or 16 mm apart in a row on the validation sensor beat the line by 120-1700 times the margin, while
    /// a line beats two round loads there, and were read as one contact between them. Not the other way round, as
    /// [`Self::join_long_groups`] asks: the lumps of a light 20 mm edge are explained about as well by round loads at
    /// their centres as by the line (that stricter guard here, tried: two of the full validation set's edges at the
    /// floor read as two contacts or at half their force). Regions joined this way are judged again with the others.
    pub(super) fn join_cut_lines(
        &self,
        regions: &mut Vec<Region>,
        groups: &[Vec<usize>],
        halved: &[usize],
        observed: Observed,
        noise_mm: f64,
        min_force_n: f64,
    ) {
        let group_of = |r: &Region| group_of(r, groups);
        let margin = SUPPORT_SIGMAS * SUPPORT_SIGMAS * noise_mm * noise_mm;
        loop {
            let mut joined = None;
            'pairs: for i in 0..regions.len() {
                for k in i + 1..regions.len() {
                    let (a, b) = (&regions[i], &regions[k]);
                    if group_of(a).is_none()
                        || group_of(a) != group_of(b)
                        || !self.touching(a, b)
                        || a.cells.iter().chain(&b.cells).any(|c| halved.contains(&c.0))
                    {
                        continue;
                    }
                    // The cheap test first.
                    if !self.gap_exceeds_two_presses(a, b, observed.tractions) {
                        continue;
                    }
                    let weaker = if a.force_vector_n[2] < b.force_vector_n[2] {
                        a
                    } else {
                        b
                    };
                    let floor_n = min_force_n * weaker.floor_scale;
                    if !self.holds_its_own(observed.d, observed.valid, observed.tractions, weaker, floor_n) {
                        continue;
                    }
                    // With the regions of their group either touches: a long contact cut in three is judged whole
                    // (two of its parts alone, a line explains hardly better than two round loads).
                    let members: Vec<usize> = (0..regions.len())
                        .filter(|&m| {
                            let r = &regions[m];
                            m == i
                                || m == k
                                || (group_of(r) == group_of(a)
                                    && (self.touching(r, a) || self.touching(r, b))
                                    && !r.cells.iter().any(|c| halved.contains(&c.0)))
                        })
                        .collect();
                    if let Some(union) =
                        self.joined_as_line(regions, &members, observed, margin, RoundLoads::NotBetterThanLine)
                    {
                        joined = Some((members, union));
                        break 'pairs;
                    }
                }
            }
            let Some((members, union)) = joined else {
                return;
            };
            merge_into_first(regions, &members, union);
        }
    }

    /// A loaded group the cell map cut into two or more contacts is one long contact when a straight line load
    /// explains the union of its contacts better than two round loads by more than [`SUPPORT_SIGMAS`]^2 times the
    /// noise at `noise_mm`: [`Self::join_cut_lines`]' test, on the whole group at once. Judged two at a time, the
    /// parts can each fail `join_cut_lines`' other tests (the gap between two lumps of a 30 mm edge is at the margin
    /// of [`Self::gap_exceeds_two_presses`]; a weak lump between two strong ones does not hold its own), and a lump
    /// [`Self::split_pair`] halved is never joined there. Moved across the cell rows a sixth of a pitch at a time, a
    /// 30 mm 5 N edge along the rows of the validation sensor was listed as two to four contacts at 4 of 12 places
    /// (with `elastic.normal_from_stack`, 5 of 12, and 5 of 12 along the columns). Taken whole, a line explains such
    /// edges better than a pair by 2500-2800 sigma^2, and two round presses in one group are the other way, by
    /// 21-2650 sigma^2. This runs on stage 2's last pass only: a contact joined earlier carries more than any line
    /// through it, and so would stop the second pass from carrying it further along the line shapes (see
    /// `lines_extending`; a 30 mm 2 N edge then read 15 % light). The cells of halved contacts it joins leave
    /// `halved`.
    pub(super) fn join_long_groups(
        &self,
        regions: &mut Vec<Region>,
        groups: &[Vec<usize>],
        halved: &mut Vec<usize>,
        observed: Observed,
        noise_mm: f64,
    ) {
        let margin = SUPPORT_SIGMAS * SUPPORT_SIGMAS * noise_mm * noise_mm;
        for g in 0..groups.len() {
            let members: Vec<usize> = (0..regions.len())
                .filter(|&m| group_of(&regions[m], groups) == Some(g))
                .collect();
            if members.len() < 2 {
                continue;
            }
            if let Some(union) = self.joined_as_line(regions, &members, observed, margin, RoundLoads::WorseThanLine) {
                halved.retain(|j| !union.cells.iter().any(|c| c.0 == *j));
                merge_into_first(regions, &members, union);
            }
        }
        regions.sort_by(|a, b| b.force_vector_n[2].total_cmp(&a.force_vector_n[2]));
    }

    /// The union of `members` (of `regions`) as one contact, when a straight line load explains it better than two
    /// round loads by more than `margin` (mm^2) and, for three members or more, stands against round loads at the
    /// members' own centres as `round_loads` asks ([`Self::loads_against`]); `None` otherwise.
    fn joined_as_line(
        &self,
        regions: &[Region],
        members: &[usize],
        observed: Observed,
        margin: f64,
        round_loads: RoundLoads,
    ) -> Option<Region> {
        let union = self.union_of(regions, members, observed.tractions);
        let best = self.best_line(&union, observed)?;
        if !(self.pair_against(&best).gain_mm2 < -margin) {
            return None;
        }
        if members.len() >= 3 {
            let centres: Vec<Point2> = members.iter().map(|&m| regions[m].centre_mm).collect();
            let gain = self.loads_against(&best, &centres);
            let stands = match round_loads {
                RoundLoads::WorseThanLine => gain.is_some_and(|gain| gain < -margin),
                RoundLoads::NotBetterThanLine => !gain.is_some_and(|gain| gain > margin),
            };
            if !stands {
                return None;
            }
        }
        Some(union)
    }

    /// How much more of a region's displacements round loads at `centres` explain than its best straight line load
    /// `best` (see [`Self::pair_against_line`]): each load spread as the line's points are, their amplitudes by least
    /// squares. `None` when the loads' fit is singular.
    fn loads_against(&self, best: &BestLine, centres: &[Point2]) -> Option<f64> {
        let BestLine { matched, line, score } = best;
        let mut dense = Vec::new();
        let shapes: Vec<Vec<(usize, f64)>> = centres
            .iter()
            .map(|&at| {
                let mut shape = Vec::new();
                self.line_shape(at, 0.0, 0.0, line.spread_mm, &mut dense, &mut shape);
                shape
            })
            .collect();
        let k = shapes.len();
        let gram = nalgebra::DMatrix::from_fn(k, k, |i, j| self.matched_product(&shapes[i], &shapes[j]));
        let correlations = nalgebra::DVector::from_fn(k, |i, _| shape_correlation(&shapes[i], matched));
        let amplitudes = gram.cholesky()?.solve(&correlations);
        Some(amplitudes.dot(&correlations) - score)
    }

    /// One region of the cells of `members` (indices into `regions`) with stage 2's `tractions` on them: the halves of
    /// a contact [`Self::split_pair`] split carry their loads' shares of its force, and joined again they are the
    /// contact the map shows.
    fn union_of(&self, regions: &[Region], members: &[usize], tractions: &[f64]) -> Region {
        self.region(
            members
                .iter()
                .flat_map(|&m| regions[m].cells.iter())
                .map(|&(j, _)| (j, [tractions[3 * j], tractions[3 * j + 1], tractions[3 * j + 2]]))
                .collect(),
        )
    }

    /// Whether the pressure midway between two regions' peaks is more than two round presses there can leave. A
    /// round press (a pressure falling away from its centre alike in every direction) leaves at the midpoint, half
    /// the peaks' distance from its centre, what it leaves at that distance across the line through the peaks; so
    /// two of them leave at the midpoint at most the sum of what the two peaks show across at that distance, each on
    /// its higher side (the cell map's checkerboard noise makes one side of a peak differ from the other). A strip's
    /// pressure runs on along it, past what its sides show. The pressure at a point is interpolated bilinearly between
    /// the four cell centres around it (cells off the pattern left out; a point with none is left out, and with a peak
    /// that has none across, the regions are not joined). Taken at the nearest cell instead, the midpoint of peaks
    /// three columns and one row apart (a 20 mm edge 15 deg off a row) fell halfway between cells, and the cell it
    /// rounded to was a low one of the checkerboard noise as often as not: such edges were listed as two or three
    /// contacts in 35 of 80 presses of a sweep, against 0-4 of 40 at other angles.
    fn gap_exceeds_two_presses(&self, a: &Region, b: &Region, tractions: &[f64]) -> bool {
        let peak = |r: &Region| {
            r.cells
                .iter()
                .max_by(|x, y| x.1[2].total_cmp(&y.1[2]))
                .map(|c| self.cells[c.0].centre_mm)
        };
        let (Some(pa), Some(pb)) = (peak(a), peak(b)) else {
            return false;
        };
        let (cols, rows) = (usize::from(self.pad.cols), usize::from(self.pad.rows));
        let origin = self.cells[0].centre_mm;
        let (px, py) = (self.pad.pitch_x_mm(), self.pad.pitch_y_mm());
        let cell_pressure = |c: f64, r: f64| -> Option<f64> {
            (c >= 0.0 && r >= 0.0 && (c as usize) < cols && (r as usize) < rows)
                .then(|| tractions[3 * (r as usize * cols + c as usize) + 2])
        };
        let pressure_at = |q: Point2| -> Option<f64> {
            let (u, v) = ((q[0] - origin[0]) / px, (q[1] - origin[1]) / py);
            let (c0, r0) = (u.floor(), v.floor());
            let (fu, fv) = (u - c0, v - r0);
            let corners = [
                (0.0, 0.0, (1.0 - fu) * (1.0 - fv)),
                (1.0, 0.0, fu * (1.0 - fv)),
                (0.0, 1.0, (1.0 - fu) * fv),
                (1.0, 1.0, fu * fv),
            ];
            let (sum, weight) = corners
                .into_iter()
                .filter(|&(_, _, w)| w > 0.0)
                .filter_map(|(dc, dr, w)| cell_pressure(c0 + dc, r0 + dr).map(|p| (w * p, w)))
                .fold((0.0, 0.0), |(s, t), (p, w)| (s + p, t + w));
            (weight > 0.0).then(|| sum / weight)
        };
        let axis = [pb[0] - pa[0], pb[1] - pa[1]];
        let across = [-0.5 * axis[1], 0.5 * axis[0]];
        let Some(gap) = pressure_at([pa[0] + 0.5 * axis[0], pa[1] + 0.5 * axis[1]]) else {
            return false;
        };
        let beside = |p: Point2| {
            [-1.0, 1.0]
                .into_iter()
                .filter_map(|side| pressure_at([p[0] + side * across[0], p[1] + side * across[1]]))
                .reduce(f64::max)
        };
        let (Some(beside_a), Some(beside_b)) = (beside(pa), beside(pb)) else {
            return false;
        };
        gap > beside_a + beside_b
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inverse::test_support::{field, hertz_press, model, node_at, node_press};
    use crate::inverse::MOTION_PARAMETERS;

    /// Two round presses 10 mm apart (issue 12's pair), along the grid and across it, are two contacts with their
    /// forces, and the strongest has no edge direction: the node map's blur bridges the two, but two fingertips
    /// are not an edge along the pair.
    #[test]
    fn two_round_presses_10_mm_apart_are_two_contacts_and_no_edge() {
        let model = model();
        let valid = vec![true; model.observations / 2];
        for (angle, centre) in [(0.0f64, [-2.0, 1.0]), (45.0, [3.0, -2.0]), (120.0, [-4.0, 0.5])] {
            let (c, s) = (angle.to_radians().cos(), angle.to_radians().sin());
            let (a, b) = (
                node_at(&model, [centre[0] - 5.0 * c, centre[1] - 5.0 * s]),
                node_at(&model, [centre[0] + 5.0 * c, centre[1] + 5.0 * s]),
            );
            let mut load = node_press(&model, a.0, a.1, [0.0, 0.0, 3.0]);
            load.extend(node_press(&model, b.0, b.1, [0.0, 0.0, 2.5]));
            let d = field(&model, &load, [0.0; MOTION_PARAMETERS]);
            let stage = model.stage1(&d, &valid);
            let stage2 = model.stage2(&d, &valid, &stage, 0.002, 0.1);
            assert_eq!(stage2.regions.len(), 2, "{angle} deg: {:?}", stage2.regions);
            for (region, truth) in stage2.regions.iter().zip([3.0, 2.5]) {
                assert!(
                    (region.force_vector_n[2] - truth).abs() < 0.2 * truth,
                    "{angle} deg: {:?}",
                    stage2.regions
                );
            }
            // None either when the pair was one region split in two.
            let moments = stage2.edge_region.as_ref().map(|r| model.moments(r, 0.35));
            assert_eq!(moments.and_then(|m| m.angle_deg), None, "{angle} deg: {moments:?}");
        }
    }

    /// Two spheres 10 mm apart along oblique directions (3.4 mm contacts, Hertz's pressure, as the validation set's
    /// pairs): the cell map lists them apart, but the node map's blur bridges the two into one elongated region,
    /// whose second moments would give the pair's direction (45, 60 and 135 deg here) as an edge's. Two round loads
    /// explain the displacements better than any line, so they are two presses: two contacts with their forces and
    /// centres, and no edge direction (two fingertips are not an edge along the pair).
    #[test]
    fn two_spheres_the_node_map_bridges_are_two_contacts_and_no_edge() {
        let model = model();
        let valid = vec![true; model.observations / 2];
        for (angle, centre, forces, radius) in [
            (45.0f64, [-4.0, 0.5], [3.0, 3.0], 3.4),
            (60.0, [-4.0, 0.5], [3.0, 3.0], 3.4),
            (135.0, [0.7, 0.3], [3.0, 2.5], 2.0),
        ] {
            let (c, s) = (angle.to_radians().cos(), angle.to_radians().sin());
            let presses = [
                ([centre[0] - 5.0 * c, centre[1] - 5.0 * s], forces[0]),
                ([centre[0] + 5.0 * c, centre[1] + 5.0 * s], forces[1]),
            ];
            let load: Vec<(usize, [f64; 3])> = presses
                .iter()
                .flat_map(|&(at, force)| hertz_press(&model, at, radius, force))
                .collect();
            let d = field(&model, &load, [0.0; MOTION_PARAMETERS]);
            let stage = model.stage1(&d, &valid);
            let stage2 = model.stage2(&d, &valid, &stage, 0.002, 0.1);
            assert_eq!(stage2.regions.len(), 2, "{angle} deg: {:?}", stage2.regions);
            for (at, force) in presses {
                let distance = |r: &Region| (r.centre_mm[0] - at[0]).hypot(r.centre_mm[1] - at[1]);
                let nearest = stage2
                    .regions
                    .iter()
                    .min_by(|a, b| distance(a).total_cmp(&distance(b)))
                    .expect("two regions");
                assert!(
                    distance(nearest) < 1.0 && (nearest.force_vector_n[2] - force).abs() < 0.1 * force,
                    "{angle} deg, {force} N at {at:?}: {:?}",
                    stage2.regions
                );
            }
            let moments = stage2.edge_region.as_ref().map(|r| model.moments(r, 0.35));
            assert_eq!(moments.and_then(|m| m.angle_deg), None, "{angle} deg: {moments:?}");
        }
    }
}
