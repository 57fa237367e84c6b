//! Stage 2's contacts: the watershed regions of its pressure, which of them are contacts, and (on the layered
//! model) their centres from each cell's quarters.

use nalgebra::DMatrix;
use nusense_geometry::Point2;

use super::constrained::{active_set, PressureCovariance};
use super::{neighbourhood, InverseModel, Observed, Region, Traction, MOTION_PARAMETERS, SUPPORT_SIGMAS};
use crate::linalg::{gram, tr_mul_vec, UpdatedCholesky};

/// A local maximum of pressure starts its own contact only if the saddle towards a higher one dips below this
/// fraction of its peak (otherwise it is a bump of the same contact).
const SADDLE_FRACTION: f64 = 0.6;

/// The loaded group (of `groups`, each ascending) a region of stage 2 lies in: the one that holds its first cell.
pub(super) fn group_of(region: &Region, groups: &[Vec<usize>]) -> Option<usize> {
    let first = region.cells.first()?.0;
    groups.iter().position(|g| g.binary_search(&first).is_ok())
}

/// Stage 2's cell pressures' noise, for the watershed's rules that ask whether a dip between two maxima stands out of
/// it (see [`InverseModel::regions`]).
pub(super) struct CellNoise<'a> {
    /// The pressures' covariance per sigma^2.
    pub(super) covariance: &'a PressureCovariance,
    pub(super) sigma_mm: f64,
    /// On the second pass, the contacts the first found; `None` on the first pass, which merges no dip for being
    /// noise. The dip rule joins no two of them, directly or through a third maximum between them: each cleared the
    /// floor on its own, and the rule is for the bumps a light long contact breaks into, not for separate presses.
    /// Several presses at once raise the noise the dips are judged by (their far fields are in it): two presses 14.5
    /// mm apart by the pattern's left border, beside two others, stood apart after the first pass, and the second
    /// joined each of them to a low maximum on the outermost column between them, so into one contact between them
    /// (the unseen-sensors bench, at 3650cf5). Whether such contacts are one long contact is for `join_cut_lines` and
    /// `join_long_groups`, which ask a line to explain them.
    pub(super) found_apart: Option<&'a [Region]>,
}

impl CellNoise<'_> {
    /// The first pass's contact that holds cell `j`, if any.
    fn contact_of(&self, j: usize) -> Option<usize> {
        self.found_apart?.iter().position(|r| r.cells.iter().any(|c| c.0 == j))
    }
}

impl InverseModel {
    /// The layered model's contact centres: each region's pressure solved again on its cells' quarters (pressure >= 0
    /// on each, the region's shear as stage 2's without its twist, the motion free, the same prior per unit area as
    /// stage 2's cells), with the other regions' tractions taken off the displacements; the centre is the quarters'
    /// pressure centroid, and the region's torque is taken about it. The layered kernel is sharper than the cells: on
    /// the quick validation set it reads localisation 0.44 -> 0.40 mm (other sizes 0.39 -> 0.27), and with the
    /// validation pad's own stack 0.40 -> 0.27 mm. Not for the equivalent layer: its kernel is not the pad's, and the
    /// finer unknowns fit its error (0.33 -> 0.36 mm).
    pub(super) fn quarter_centres(&self, d: &[f64], valid: &[bool], tractions: &[f64], regions: &mut [Region]) {
        let Some(quarter_cells) = &self.quarters else { return };
        let rows = self.observations;
        for region in regions.iter_mut() {
            let Some(others) = self.others_and_shape(tractions, region) else {
                continue;
            };
            // The displacements less the other regions' field.
            let data: Vec<f64> = (0..rows)
                .map(|r| if valid[r / 2] { d[r] - others.field[r] } else { 0.0 })
                .collect();
            let quarters: Vec<usize> = region.cells.iter().flat_map(|c| 4 * c.0..4 * c.0 + 4).collect();
            let nq = quarters.len();
            let n = nq + 2 + MOTION_PARAMETERS;
            let mut design = DMatrix::zeros(rows, n);
            let columns = design.as_mut_slice();
            for (k, &q) in quarters.iter().enumerate() {
                columns[k * rows..(k + 1) * rows].copy_from_slice(quarter_cells.pressure_t.row(q));
            }
            // The region's uniform shear, spread as its pressure is (stage 2's shear without its twist).
            for axis in 0..2 {
                columns[(nq + axis) * rows..(nq + axis + 1) * rows].copy_from_slice(&self.share_weighted(
                    region,
                    &others.shares,
                    axis,
                ));
            }
            for p in 0..MOTION_PARAMETERS {
                columns[(nq + 2 + p) * rows..(nq + 3 + p) * rows].copy_from_slice(self.b_t.row(p));
            }
            for r in (0..rows).filter(|&r| !valid[r / 2]) {
                design.row_mut(r).fill(0.0);
            }
            let mut h = gram(&design);
            // Stage 2's prior per unknown: a quarter's force a quarter of a cell's (the same pressure per unit area),
            // the shear's as many cells' as the region has.
            for k in 0..nq {
                h[(k, k)] += 16.0 * self.lambda;
            }
            let cells = region.cells.len() as f64;
            for k in nq..nq + 2 {
                h[(k, k)] += self.lambda / (cells * cells);
            }
            let g = tr_mul_vec(&design, &data);
            let constrained: Vec<bool> = (0..n).map(|i| i < nq).collect();
            let Some(whole) = UpdatedCholesky::new(&h, (0..n).collect()) else {
                continue;
            };
            let Some(x) = active_set(&h, &g, &constrained, &whole) else {
                continue;
            };
            let weight: f64 = (0..nq).map(|k| x[k].max(0.0)).sum();
            if !(weight > 0.0) {
                continue;
            }
            let centre: Point2 = std::array::from_fn(|axis| {
                (0..nq)
                    .map(|k| x[k].max(0.0) * quarter_cells.centres_mm[quarters[k]][axis])
                    .sum::<f64>()
                    / weight
            });
            let (old, force) = (region.centre_mm, region.force_vector_n);
            region.torque_nmm += (old[0] - centre[0]) * force[1] - (old[1] - centre[1]) * force[0];
            region.centre_mm = centre;
        }
    }

    /// The contacts among stage 2's regions (strongest first), each group of loaded cells judged as a whole: a region
    /// that clears the floor where it is (`min_force_n` times its [`Region::floor_scale`]) is a contact, and one that
    /// does not is none, or with `join_fragments` (the line shapes' solve) joins the contact it touches in its group
    /// (a fragment of a long contact). The solve of the per-cell cells leaves such regions out, as it did before the
    /// line shapes: its contacts are whole, and a fragment joined there would move a round contact's centre and
    /// force by its noise. When no region
    /// clears it alone, a group's fragments (the checkerboard noise cuts a light long contact into bumps whose dips
    /// fall below the watershed's saddle) are one region, a contact if it clears the floor as a whole by its unbiased
    /// force ([`Self::matched_fit`]).
    ///
    /// The test has found a contact when stage 2 runs, and stage 2 only describes it: when no region clears the floor
    /// (a press at the floor, whose force the noise puts on either side of it), the contact is the group whose load
    /// is the most significant, unless its unbiased force is significantly below the floor (by more than
    /// [`SUPPORT_SIGMAS`] of its noise at `noise_mm`): then the test's contact is none stage 2 can find, as on a rest
    /// frame where one side's LEDs drift by 20 % (tests/hard_cases.rs: the test's statistic 462 against 457, the
    /// best group 0.16 +- 0.017 N against a floor of 0.36 N there).
    pub(super) fn contacts(
        &self,
        regions: Vec<Region>,
        groups: &[Vec<usize>],
        observed: Observed,
        min_force_n: f64,
        noise_mm: f64,
        join_fragments: bool,
    ) -> Vec<Region> {
        let mut pending: Vec<(&[usize], Vec<Traction>)> = Vec::new();
        let clears = |r: &Region| r.force_vector_n[2] >= min_force_n * r.floor_scale;
        let mut kept: Vec<Region> = Vec::new();
        for (g, group) in groups.iter().enumerate() {
            let members: Vec<&Region> = regions.iter().filter(|r| group_of(r, groups) == Some(g)).collect();
            if members.iter().any(|r| clears(r)) {
                // Each fragment that does not clear the floor joins the contact it touches (repeatedly: through
                // other such fragments); one that touches none is none.
                let (mut strong, mut weak): (Vec<Region>, Vec<Region>) =
                    members.into_iter().cloned().partition(|r| clears(r));
                if join_fragments {
                    loop {
                        let joined = weak.iter().position(|w| strong.iter().any(|c| self.touching(c, w)));
                        let Some(i) = joined else { break };
                        let fragment = weak.remove(i);
                        let target = strong
                            .iter()
                            .position(|c| self.touching(c, &fragment))
                            .expect("found touching above");
                        let mut cells = strong[target].cells.clone();
                        cells.extend(fragment.cells);
                        strong[target] = self.region(cells);
                    }
                }
                kept.extend(strong);
                continue;
            }
            let cells: Vec<(usize, [f64; 3])> = members.iter().flat_map(|r| r.cells.iter().copied()).collect();
            if !cells.is_empty() {
                pending.push((group, cells));
            }
        }
        if !kept.is_empty() {
            kept.sort_by(|a, b| b.force_vector_n[2].total_cmp(&a.force_vector_n[2]));
            return kept;
        }
        // No fragment is a contact: each group is judged whole.
        let mut wholes: Vec<(Region, f64, bool)> = Vec::new();
        for (group, cells) in pending {
            let whole = self.region(cells);
            // Its force in the displacements less those of stage 2's tractions elsewhere (the other groups' loads
            // move its corners too).
            let mut elsewhere = observed.tractions.to_vec();
            for &j in group {
                elsewhere[3 * j..3 * j + 3].fill(0.0);
            }
            let mut moved = vec![0.0; self.observations];
            self.a.mul_vec(&elsewhere, &mut moved);
            let rest: Vec<f64> = observed.d.iter().zip(&moved).map(|(d, m)| d - m).collect();
            let matched = self.matched(&rest, observed.valid);
            let (force, noise) = self.matched_fit(&matched, &whole.cells);
            let floor_n = min_force_n * whole.floor_scale;
            if force >= floor_n {
                kept.push(whole);
            } else {
                let sd = noise * noise_mm;
                wholes.push((whole, force / sd, force + SUPPORT_SIGMAS * sd >= floor_n));
            }
        }
        if kept.is_empty() {
            if let Some((whole, _, near_floor)) = wholes.into_iter().max_by(|a, b| a.1.total_cmp(&b.1)) {
                if near_floor {
                    kept.push(whole);
                }
            }
        }
        kept.sort_by(|a, b| b.force_vector_n[2].total_cmp(&a.force_vector_n[2]));
        kept
    }

    /// Whether a maximum on the pattern's outermost row or column (`lower_peak`) beside a higher one inside the pattern
    /// (`higher_peak`) is the border's rather than a bump of that contact: it stands above the pass between them by at
    /// least [`SUPPORT_SIGMAS`] of that dip's noise (`depth`, in sigmas, asked only of such a pair). The model puts
    /// loads there to stand in for the walls the pad is held by (see `InverseModel::far_field_shadow`), and the
    /// watershed joined them to a press near the border through its flank. Such a maximum joins the one inside only
    /// when the pass is higher than [`SADDLE_FRACTION`] of that one as well (the contact's own flank), not only of its
    /// own. On the full validation set, press_042 (a 3 mm punch of 6.55 N at (-17.4, 10.6) mm) read 5.85 N (the
    /// model's) with such maxima on the outermost column and row and 4.69 N without them; the set's force over the pad
    /// went 0.306 -> 0.244 N RMS and its two contacts 10 mm apart 15 -> 16 of 16, and the quick set reads the same.
    /// Judged by the pass alone, without the noise, a maximum no higher than the noise beside a 3 N press near the
    /// border was cut off on one noise seed and not on another, and the press read 4.5 % lighter on the one
    /// (host/estimator/tests/uneven_light.rs).
    fn border_bump(&self, lower_peak: usize, higher_peak: usize, depth: impl FnOnce() -> Option<f64>) -> bool {
        self.on_outermost_cells(lower_peak)
            && !self.on_outermost_cells(higher_peak)
            && depth().is_some_and(|depth| depth >= SUPPORT_SIGMAS)
    }

    /// Whether cell `j` lies on the pattern's outermost row or column.
    pub(super) fn on_outermost_cells(&self, j: usize) -> bool {
        let (cols, rows) = (usize::from(self.pad.cols), usize::from(self.pad.rows));
        let (row, col) = (j / cols, j % cols);
        row == 0 || col == 0 || row + 1 == rows || col + 1 == cols
    }

    /// Whether two regions have neighbouring cells (8-connected).
    pub(super) fn touching(&self, a: &Region, b: &Region) -> bool {
        let cols = usize::from(self.pad.cols);
        a.cells.iter().any(|&(i, _)| {
            b.cells.iter().any(|&(j, _)| {
                let (ri, ci, rj, cj) = (i / cols, i % cols, j / cols, j % cols);
                ri.abs_diff(rj) <= 1 && ci.abs_diff(cj) <= 1
            })
        })
    }

    /// Watershed of the pressure over the support: each cell climbs to its highest neighbour until a local
    /// maximum; maxima joined by a high saddle are merged.
    /// With `noise` (stage 2's cell map), a maximum on the pattern's outermost cells that stands out of the noise
    /// above its pass towards a higher one inside joins it only when that pass is high for the higher one too (see
    /// [`Self::border_bump`]); on the second pass, maxima whose dip between them is not significant are merged too, the
    /// least significant dip first: the checkerboard noise cuts a light long contact into bumps whose dips are noise.
    pub(super) fn regions(&self, tractions: &[f64], support: &[usize], noise: Option<CellNoise>) -> Vec<Region> {
        let (cols, rows) = (usize::from(self.pad.cols), usize::from(self.pad.rows));
        let pressure = |j: usize| tractions[3 * j + 2];
        let (label, peaks) = self.basins(tractions, support);
        // Merge basins whose shared border is high relative to the lower peak.
        let mut parent: Vec<usize> = (0..peaks.len()).collect();
        fn root(parent: &mut [usize], mut i: usize) -> usize {
            while parent[i] != i {
                parent[i] = parent[parent[i]];
                i = parent[i];
            }
            i
        }
        // The highest pass between two basins: its level and the cell at it.
        let mut saddle = vec![vec![(0.0f64, usize::MAX); peaks.len()]; peaks.len()];
        for &j in support {
            let Some(a) = label[j] else { continue };
            let (r, c) = ((j / cols) as isize, (j % cols) as isize);
            for (nr, nc) in neighbourhood(r, c, rows, cols) {
                let k = nr * cols + nc;
                if let Some(b) = label[k] {
                    if a != b {
                        let low = if pressure(j) <= pressure(k) { j } else { k };
                        if pressure(low) > saddle[a][b].0 {
                            saddle[a][b] = (pressure(low), low);
                        }
                    }
                }
            }
        }
        // A dip's depth below the lower peak in units of its own noise.
        let dip_sigmas = |peak: usize, pass: usize| -> Option<f64> {
            let noise = noise.as_ref()?;
            let dip_noise = noise.covariance.difference_noise(peak, pass)?;
            Some((pressure(peak) - pressure(pass)) / (noise.sigma_mm * dip_noise))
        };
        let second_pass = noise.as_ref().is_some_and(|n| n.found_apart.is_some());
        let mut insignificant_dips: Vec<(f64, usize, usize)> = Vec::new();
        // Each pair once: the highest pass between two basins is the same both ways (the lower of each pair of
        // neighbouring cells across their border), and a pair the first visit joined stays joined.
        for a in 0..peaks.len() {
            for b in a + 1..peaks.len() {
                let (level, pass) = saddle[a][b];
                if pass == usize::MAX {
                    continue;
                }
                let (lower_peak, higher_peak) = if pressure(peaks[a]) <= pressure(peaks[b]) {
                    (peaks[a], peaks[b])
                } else {
                    (peaks[b], peaks[a])
                };
                // The dips' noise is asked only where a rule needs it: its covariance is computed at the first ask.
                let level_to_join = if self.border_bump(lower_peak, higher_peak, || dip_sigmas(lower_peak, pass)) {
                    higher_peak
                } else {
                    lower_peak
                };
                if level > SADDLE_FRACTION * pressure(level_to_join) {
                    let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
                    parent[ra] = rb;
                } else if second_pass {
                    if let Some(depth) = dip_sigmas(lower_peak, pass).filter(|&depth| depth < SUPPORT_SIGMAS) {
                        insignificant_dips.push((depth, a, b));
                    }
                }
            }
        }
        if let Some(noise) = noise.as_ref().filter(|_| second_pass) {
            // Per basin's root, the first pass's contacts among its maxima.
            let mut contacts_in: Vec<Vec<usize>> = vec![Vec::new(); peaks.len()];
            for (a, &peak) in peaks.iter().enumerate() {
                let r = root(&mut parent, a);
                if let Some(contact) = noise.contact_of(peak) {
                    if !contacts_in[r].contains(&contact) {
                        contacts_in[r].push(contact);
                    }
                }
            }
            // The least significant dip first; none joins two of those contacts (each holds one the other does not).
            insignificant_dips.sort_by(|x, y| x.0.total_cmp(&y.0));
            for (_, a, b) in insignificant_dips {
                let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
                if ra == rb {
                    continue;
                }
                let only_in = |x: usize, y: usize| contacts_in[x].iter().any(|c| !contacts_in[y].contains(c));
                if only_in(ra, rb) && only_in(rb, ra) {
                    continue;
                }
                let added: Vec<usize> = contacts_in[ra]
                    .iter()
                    .copied()
                    .filter(|c| !contacts_in[rb].contains(c))
                    .collect();
                contacts_in[rb].extend(added);
                parent[ra] = rb;
            }
        }
        let mut members: Vec<Vec<usize>> = vec![Vec::new(); peaks.len()];
        for &j in support {
            if let Some(a) = label[j] {
                let r = root(&mut parent, a);
                members[r].push(j);
            }
        }
        let mut regions: Vec<Region> = members
            .into_iter()
            .filter(|m| !m.is_empty())
            .map(|m| {
                self.region(
                    m.iter()
                        .map(|&j| (j, [tractions[3 * j], tractions[3 * j + 1], tractions[3 * j + 2]]))
                        .collect(),
                )
            })
            .collect();
        regions.sort_by(|a, b| b.force_vector_n[2].total_cmp(&a.force_vector_n[2]));
        regions
    }

    /// The watershed's basins: each cell of the support with pressure labelled by the local maximum it climbs to
    /// (per cell of the grid, an index into the maxima), and those maxima's cells.
    fn basins(&self, tractions: &[f64], support: &[usize]) -> (Vec<Option<usize>>, Vec<usize>) {
        let (cols, rows) = (usize::from(self.pad.cols), usize::from(self.pad.rows));
        let pressure = |j: usize| tractions[3 * j + 2];
        let in_support = |j: usize| support.binary_search(&j).is_ok();
        let climb = |mut j: usize| loop {
            let (r, c) = ((j / cols) as isize, (j % cols) as isize);
            let best = neighbourhood(r, c, rows, cols)
                .map(|(nr, nc)| nr * cols + nc)
                .filter(|&k| in_support(k))
                .max_by(|&a, &b| pressure(a).total_cmp(&pressure(b)).then(b.cmp(&a)))
                .unwrap_or(j);
            if best == j || pressure(best) <= pressure(j) {
                break j;
            }
            j = best;
        };
        let mut label: Vec<Option<usize>> = vec![None; rows * cols];
        let mut peaks: Vec<usize> = Vec::new();
        for &j in support.iter().filter(|&&j| pressure(j) > 0.0) {
            let peak = climb(j);
            let id = peaks.iter().position(|&p| p == peak).unwrap_or_else(|| {
                peaks.push(peak);
                peaks.len() - 1
            });
            label[j] = Some(id);
        }
        (label, peaks)
    }

    /// A region of cells and their (fx, fy, fz).
    pub(super) fn region(&self, cells: Vec<(usize, [f64; 3])>) -> Region {
        let cell_area = self.pad.pitch_x_mm() * self.pad.pitch_y_mm();
        let force: [f64; 3] = std::array::from_fn(|k| cells.iter().map(|c| c.1[k]).sum());
        let fz = force[2].max(1e-300);
        let centre = [
            cells
                .iter()
                .map(|(j, f)| f[2] * self.cells[*j].centre_mm[0])
                .sum::<f64>()
                / fz,
            cells
                .iter()
                .map(|(j, f)| f[2] * self.cells[*j].centre_mm[1])
                .sum::<f64>()
                / fz,
        ];
        let torque = cells
            .iter()
            .map(|(j, f)| {
                let p = self.cells[*j].centre_mm;
                (p[0] - centre[0]) * f[1] - (p[1] - centre[1]) * f[0]
            })
            .sum();
        let squares: f64 = cells.iter().map(|c| c.1[2] * c.1[2]).sum();
        let area_mm2 = if squares > 0.0 {
            force[2] * force[2] / squares * cell_area
        } else {
            0.0
        };
        Region {
            centre_mm: centre,
            force_vector_n: force,
            torque_nmm: torque,
            area_mm2,
            floor_scale: self.floor_scale(&cells),
            cells,
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::config::{ElasticModel, SensorConfig};
    use crate::elastic::{Border, Cell, PadResponse, PointKernel};
    use crate::inverse::test_support::{cell_at, field as field_of};
    use crate::inverse::{InverseModel, MOTION_PARAMETERS};
    use nusense_geometry::{CornerIndex, Point2, SquareIndex};

    /// The layered model's contact centre from its quarter cells: noise-free, a 2.5 mm square press is found within
    /// the 0.25 mm wherever it falls in a cell (0.22 mm at worst here; the cells' own centroid is 0.31 mm off
    /// at (0.8, -0.8) mm from a cell's centre, and 0.02-0.11 mm off at the others).
    #[test]
    fn the_layered_model_places_a_press_within_a_cell() {
        let mut config = SensorConfig::default();
        config.elastic.model = ElasticModel::Layered;
        config.elastic.shear_modulus_kpa = 11.0;
        let model = InverseModel::new(&config, None).unwrap();
        let pad = config.pad;
        let corners: Vec<Point2> = pad.corners().map(|c| pad.corner_mm(c)).collect();
        let kernel = PointKernel::new(&config.elastic).unwrap();
        let valid = vec![true; model.observations / 2];
        let centre = model.cells[cell_at(&model, [3.0, 2.0])].centre_mm;
        for offset in [[0.0, 0.0], [0.8, 0.0], [1.6, 0.0], [0.8, -0.8], [-1.2, 1.6]] {
            let at = [centre[0] + offset[0], centre[1] + offset[1]];
            let load = Cell {
                centre_mm: at,
                size_mm: [2.5, 2.5],
            };
            let response = PadResponse::new(&kernel, &corners, &[load], Border::None).unwrap();
            let d = crate::elastic::apply(&response, &[0.0, 0.0, 3.0]);
            let stage = model.stage1(&d, &valid);
            let stage2 = model.stage2(&d, &valid, &stage, 0.002, 0.1);
            let found = stage2.regions[0].centre_mm;
            let error = (found[0] - at[0]).hypot(found[1] - at[1]);
            assert!(error < 0.25, "{offset:?}: {found:?} is {error} mm off");
        }
    }

    /// With probes over each square's area, the squares' model sees each square as the mean motion of its area (what a
    /// centroid measures): its field of a load is the mean of the pad's field at n x n points spread over the square.
    #[test]
    fn the_squares_model_averages_over_each_square() {
        let mut config = SensorConfig::default();
        config.elastic.model = ElasticModel::Layered;
        config.elastic.shear_modulus_kpa = 11.0;
        let at_centres = InverseModel::observing_squares(&config, None, 1).unwrap();
        let n = 3;
        let averaged = InverseModel::observing_squares(&config, None, n).unwrap();
        let pad = config.pad;
        let centres: Vec<Point2> = pad.yellow_squares().map(|s| pad.square_centre_mm(s)).collect();
        assert_eq!(averaged.points_mm, centres);
        assert_eq!(averaged.observations, 2 * centres.len());
        let size = [pad.pitch_x_mm(), pad.pitch_y_mm()];
        let step = |k: usize| (k as f64 + 0.5) / n as f64 - 0.5;
        let probes: Vec<Point2> = pad
            .yellow_squares()
            .flat_map(|s| {
                let c = pad.square_centre_mm(s);
                (0..n * n).map(move |k| [c[0] + step(k % n) * size[0], c[1] + step(k / n) * size[1]])
            })
            .collect();
        assert_field_is_the_probes_mean(&config, &averaged, &at_centres, &probes, n * n, 0.05);
    }

    /// With `elastic.tracker_averaging` the model sees each corner where the fast tracker does: at the midpoint of its
    /// two yellow squares' centres (`detection::corners_from_squares`). Its field of a load is, corner by corner, the
    /// mean of the pad's field at those two centres (taken from the kernel here), which differs from the field at the
    /// corners themselves by a fifth of the peak next to a cell's load.
    #[test]
    fn tracker_averaging_sees_each_corner_as_the_midpoint_of_its_squares() {
        let mut config = SensorConfig::default();
        config.elastic.model = ElasticModel::Layered;
        config.elastic.shear_modulus_kpa = 11.0;
        let at_corners = InverseModel::new(&config, None).unwrap();
        config.elastic.tracker_averaging = true;
        let averaged = InverseModel::new(&config, None).unwrap();
        let pad = config.pad;
        let squares: Vec<Point2> = pad
            .corners()
            .flat_map(|CornerIndex { row, col }| {
                let diagonal = if (row + col).is_multiple_of(2) == pad.top_left_yellow {
                    [(row, col), (row + 1, col + 1)]
                } else {
                    [(row, col + 1), (row + 1, col)]
                };
                diagonal.map(|(row, col)| pad.square_centre_mm(SquareIndex { row, col }))
            })
            .collect();
        assert_field_is_the_probes_mean(&config, &averaged, &at_corners, &squares, 2, 0.2);
    }

    /// At three loaded cells: `averaged`'s field of a load is, point by point, the mean of the pad's field (from the
    /// kernel) at `probes` taken `group` at a time (x and y apart), to 1e-12 of its peak; `plain`'s differs from that
    /// mean by more than `differs` times its peak somewhere.
    fn assert_field_is_the_probes_mean(
        config: &SensorConfig,
        averaged: &InverseModel,
        plain: &InverseModel,
        probes: &[Point2],
        group: usize,
        differs: f64,
    ) {
        let kernel = PointKernel::new(&config.elastic).unwrap();
        for p in [[3.0, 2.0], [-20.0, 14.0], [0.0, 0.0]] {
            let cell = cell_at(averaged, p);
            let response = PadResponse::new(&kernel, probes, &[averaged.cells[cell]], Border::None).unwrap();
            let field = crate::elastic::apply(&response, &[0.3, -0.2, 1.0]);
            let seen: Vec<f64> = (0..field.len() / group)
                .map(|r| {
                    (0..group)
                        .map(|k| field[2 * (group * (r / 2) + k) + r % 2])
                        .sum::<f64>()
                        / group as f64
                })
                .collect();
            let load = [(cell, [0.3, -0.2, 1.0])];
            let no_motion = [0.0; MOTION_PARAMETERS];
            let modelled = field_of(averaged, &load, no_motion);
            let unaveraged = field_of(plain, &load, no_motion);
            let largest = |v: &[f64]| v.iter().map(|x| x.abs()).fold(0.0, f64::max);
            let apart = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
            assert!(apart(&modelled, &seen) <= 1e-12 * largest(&seen), "{p:?}");
            assert!(apart(&unaveraged, &seen) > differs * largest(&seen), "{p:?}");
        }
    }
}
