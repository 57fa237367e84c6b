//! Stage 2 (see the module notes of [`super`]): the tractions again on the cells where stage 1 finds pressure, with
//! pressure >= 0, in one or two passes, and the strongest contact's shape for its edge direction.

use super::constrained::PressureBasis;
use super::regions::CellNoise;
use super::{neighbourhood, InverseModel, Observed, Region, Stage1, Traction, MOTION_PARAMETERS, SUPPORT_SIGMAS};

/// The node map's blur can cut a light long contact that the cell map keeps whole into parts, each its own watershed
/// region: a 20 mm edge of 2-3.5 N at 63 deg across the validation sensor's cells holds two node peaks 10 mm apart.
/// The part without the contact's peak cell belongs to its shape when it lies mostly on the contact's cells and
/// stands about as high as the part with it (there 0.93 of its peak); read from one part alone, that edge was 10 mm
/// long, too short for a direction. The node map's other regions on a contact's cells are mostly its noise and the
/// pad's border, lower: 0.12-0.32 of the contact's peak on the full set's edge_152, edge_159, edge_170 and press_042,
/// and with them all the full set's edges read 2.68 -> 2.94 deg.
const CUT_PART_PEAK_FRACTION: f64 = 0.6;

/// One pass of stage 2: its groups of cells, their union (ascending), the motion, the contacts (strongest first)
/// and the tractions (3 per cell, N).
struct Solved {
    groups: Vec<Vec<usize>>,
    support: Vec<usize>,
    motion: [f64; MOTION_PARAMETERS],
    regions: Vec<Region>,
    tractions: Vec<f64>,
}

/// Stage 2's result.
#[derive(Clone, Debug, PartialEq)]
pub struct Stage2 {
    /// (fx, fy, fz) per cell of the whole grid, N (zero off the support).
    pub tractions: Vec<f64>,
    pub motion: [f64; MOTION_PARAMETERS],
    /// Strongest (largest normal force) first.
    pub regions: Vec<Region>,
    /// The strongest contact as the node solve sees it (see `PressureBasis`), for its edge direction.
    pub edge_region: Option<Region>,
    /// The direction (degrees from +x towards +y, in [0, 180)) of the straight line load that best explains the
    /// strongest contact, when its shape is elongated and the config asks for it (`inverse.edge_from_line`; see
    /// [`InverseModel::edge_line`]).
    pub edge_line_deg: Option<f64>,
}

impl InverseModel {
    /// Stage 2 (see the module notes), seeded by a stage 1 result at noise `noise_mm`; regions carrying less normal
    /// force than `min_force_n` (the detection floor) are not contacts.
    pub fn stage2(&self, d: &[f64], valid: &[bool], seed: &Stage1, noise_mm: f64, min_force_n: f64) -> Stage2 {
        let cells = self.cells.len();
        let empty = Stage2 {
            tractions: vec![0.0; 3 * cells],
            motion: seed.motion,
            regions: Vec::new(),
            edge_region: None,
            edge_line_deg: None,
        };
        // The loaded cells are those of stage 1's per-cell test; only when they hold no contact (a light long one,
        // whose load no single cell carries above its noise) also those of the line shapes. Picked everywhere, the
        // line shapes also find lines in the smooth errors a moved camera leaves (tried: force over the pad with the
        // camera moved 0.57 -> 1.22 N RMS on the quick set). When no cell clears the per-cell test at all, its
        // strongest cell joins the line shapes' (see `strongest_cell`). When they hold contacts, only the line
        // shapes that carry the strongest further are added (see `lines_extending`).
        let mut solved: Option<Solved> = None;
        // The cells of contacts split in two (see `split_pair`).
        let mut halved: Vec<usize> = Vec::new();
        for pass in 0..2 {
            let extending = solved.as_ref().is_some_and(|found| !found.regions.is_empty());
            let lines = if pass == 0 {
                Vec::new()
            } else {
                self.second_pass_lines(d, valid, seed, solved.as_ref(), noise_mm)
            };
            if solved.is_some() && !lines.iter().any(|&l| l) {
                break;
            }
            let groups = self.loaded_groups_and(seed, noise_mm, &lines);
            if groups.is_empty() {
                continue;
            }
            let Some((tractions, motion, covariance)) =
                self.constrained_solve(d, valid, seed, &groups, PressureBasis::Cells)
            else {
                continue;
            };
            let mut support: Vec<usize> = groups.iter().flatten().copied().collect();
            support.sort_unstable();
            let noise = CellNoise {
                covariance: &covariance,
                sigma_mm: noise_mm,
                found_apart: (pass == 1).then(|| solved.as_ref().map_or(&[][..], |found| &found.regions[..])),
            };
            let regions = self.contacts(
                self.regions(&tractions, &support, Some(noise)),
                &groups,
                Observed {
                    d,
                    valid,
                    tractions: &tractions,
                },
                min_force_n,
                noise_mm,
                pass == 1,
            );
            let observed = Observed {
                d,
                valid,
                tractions: &tractions,
            };
            let mut halves_of: Vec<usize> = Vec::new();
            let mut regions: Vec<Region> = regions
                .into_iter()
                .flat_map(|r| match self.split_pair(&r, observed, noise_mm, min_force_n) {
                    Some(halves) => {
                        halves_of.extend(r.cells.iter().map(|c| c.0));
                        halves.to_vec()
                    }
                    None => vec![r],
                })
                .collect();
            self.join_cut_lines(&mut regions, &groups, &halves_of, observed, noise_mm, min_force_n);
            regions.sort_by(|a, b| b.force_vector_n[2].total_cmp(&a.force_vector_n[2]));
            if extending && regions.is_empty() {
                break;
            }
            halved = halves_of;
            solved = Some(Solved {
                groups,
                support,
                motion,
                regions,
                tractions,
            });
        }
        let Some(mut solved) = solved else {
            return empty;
        };
        self.join_long_groups(
            &mut solved.regions,
            &solved.groups,
            &mut halved,
            Observed {
                d,
                valid,
                tractions: &solved.tractions,
            },
            noise_mm,
        );
        self.stage2_of(d, valid, seed, solved, &halved, noise_mm)
    }

    /// Stage 2's result from its last pass, `solved` (`halved`: the cells of the contacts split in two): the
    /// strongest contact's shape for its edge direction, the contacts' tractions alone, and their centres.
    fn stage2_of(
        &self,
        d: &[f64],
        valid: &[bool],
        seed: &Stage1,
        solved: Solved,
        halved: &[usize],
        noise_mm: f64,
    ) -> Stage2 {
        let cells = self.cells.len();
        let observed = Observed {
            d,
            valid,
            tractions: &solved.tractions,
        };
        let edge_region = self.edge_region(observed, seed, &solved, halved, noise_mm);
        let edge_line_deg = edge_region.as_ref().filter(|_| self.fine.is_some()).and_then(|shape| {
            let start = self.elongation(shape)?;
            let mut loaded: Vec<usize> = shape.cells.iter().map(|c| c.0).collect();
            loaded.extend(
                solved
                    .regions
                    .first()
                    .into_iter()
                    .flat_map(|r| r.cells.iter().map(|c| c.0)),
            );
            loaded.sort_unstable();
            loaded.dedup();
            Some(self.edge_line(observed, &loaded, start)?.angle_deg)
        });
        let Solved {
            motion,
            mut regions,
            tractions,
            groups,
            ..
        } = solved;
        // Tractions outside the contacts are not reported (they are below the floor), but for the shear a contact's
        // force vector takes from the cells beside it (see `give_shear_beside`).
        let mut kept = vec![0.0; 3 * cells];
        for (j, f) in regions.iter().flat_map(|r| &r.cells) {
            kept[3 * j..3 * j + 3].copy_from_slice(f);
        }
        self.quarter_centres(d, valid, &kept, &mut regions);
        self.give_shear_beside(&tractions, &groups, &mut regions, &mut kept);
        Stage2 {
            tractions: kept,
            motion,
            regions,
            edge_region,
            edge_line_deg,
        }
    }

    /// Gives each contact's force vector the shear its group's cells without pressure carry. Stage 2's shear unknowns
    /// are a group's: its total push and twist, spread over its cells in proportion to stage 1's pressure (and along
    /// the push; see `push_shear_unknowns`). A contact's region holds only cells with pressure, so where stage 2 leaves
    /// a cell of the group none, the share of the push on it was lost from every contact's force vector: most on
    /// pushes, whose shear stage 1 spreads ahead of the pressure. Each such cell's shear goes to the group's contact
    /// cell nearest it (and stays in `kept`, stage 2's tractions); a group without a contact (below the floor) keeps
    /// none. The contact's torque stays its own cells': on those cells beside it, at the longest lever arms, the
    /// twist is mostly the solve's noise. With them the validation sets' twists scattered about their own best scale
    /// by a coefficient of variation of 0.10 and 0.29 (quick, full) instead of 0.06 and 0.16, and read 1.19 and 4.83 N
    /// mm RMS with the pushes' tangential scale (1.65 and 1.89 without them; 1.11 and 3.51 before this change, when
    /// the pushes too lost that shear). Centres, areas, normal forces and torques stay as they were.
    fn give_shear_beside(&self, tractions: &[f64], groups: &[Vec<usize>], regions: &mut [Region], kept: &mut [f64]) {
        let mut owner: Vec<Option<usize>> = vec![None; self.cells.len()];
        for (k, region) in regions.iter().enumerate() {
            for &(j, _) in &region.cells {
                owner[j] = Some(k);
            }
        }
        for group in groups {
            let held: Vec<(usize, usize)> = group.iter().filter_map(|&j| Some((owner[j]?, j))).collect();
            for &j in group {
                let shear = [tractions[3 * j], tractions[3 * j + 1]];
                if owner[j].is_some() || tractions[3 * j + 2] > 0.0 || shear == [0.0, 0.0] {
                    continue;
                }
                let p = self.cells[j].centre_mm;
                let distance = |c: usize| {
                    let q = self.cells[c].centre_mm;
                    (p[0] - q[0]).hypot(p[1] - q[1])
                };
                let Some(&(k, _)) = held.iter().min_by(|a, b| distance(a.1).total_cmp(&distance(b.1))) else {
                    continue;
                };
                let force = &mut regions[k].force_vector_n;
                force[0] += shear[0];
                force[1] += shear[1];
                kept[3 * j] = shear[0];
                kept[3 * j + 1] = shear[1];
            }
        }
    }

    /// The cells of the line shapes stage 2's second pass adds (see [`Self::stage2`]): after a first pass that found
    /// contacts, those of the lines that carry the strongest further; else those of every significant line, and the
    /// strongest cell of stage 1 when the first pass found nothing to solve.
    fn second_pass_lines(
        &self,
        d: &[f64],
        valid: &[bool],
        seed: &Stage1,
        first: Option<&Solved>,
        noise_mm: f64,
    ) -> Vec<bool> {
        match first {
            Some(found) if !found.regions.is_empty() => self.lines_extending(
                &found.regions,
                Observed {
                    d,
                    valid,
                    tractions: &found.tractions,
                },
                &found.support,
                noise_mm,
            ),
            _ => {
                let mut lines = self.line_loads(&self.matched(d, valid), noise_mm);
                if first.is_none() {
                    if let Some(strongest) = self.strongest_cell(seed) {
                        lines[strongest] = true;
                    }
                }
                lines
            }
        }
    }

    /// The strongest contact's shape, from the node solve: its region there that holds the contact's peak cell, with
    /// the other parts of the contact the node map cut off (see [`CUT_PART_PEAK_FRACTION`]).
    /// Half of a contact split in two is a point load's (see `split_pair`): it has no direction, and the node
    /// solve's region holds both halves, bridged by the blur. The blur bridges contacts the cell map lists apart
    /// too: when the listed contacts it bridges are two presses by `split_pair`'s rule ([`Self::two_presses`],
    /// their cells taken as one), the others' cells are not the strongest's shape (two fingertips are not an
    /// edge along the pair); when a line explains them as well, they are a long contact's parts (the cell map cuts
    /// some 20 mm edges into two or three; `join_cut_lines` and `join_long_groups` join those within one loaded
    /// group) and the direction is theirs. `observed`: the frame and stage 2's tractions; `solved`: stage 2's last
    /// pass; `halved`: the cells of the contacts split in two.
    fn edge_region(
        &self,
        observed: Observed,
        seed: &Stage1,
        solved: &Solved,
        halved: &[usize],
        noise_mm: f64,
    ) -> Option<Region> {
        let first = solved.regions.first()?;
        if first.cells.iter().any(|c| halved.contains(&c.0)) {
            return None;
        }
        let peak = first.cells.iter().max_by(|a, b| a.1[2].total_cmp(&b.1[2]))?.0;
        let (smooth, _, _) =
            self.constrained_solve(observed.d, observed.valid, seed, &solved.groups, PressureBasis::Nodes)?;
        let node_regions = self.regions(&smooth, &solved.support, None);
        let peak_pressure = |r: &Region| r.cells.iter().map(|c| c.1[2]).fold(0.0, f64::max);
        let main = node_regions.iter().find(|r| r.cells.iter().any(|c| c.0 == peak))?;
        let main_peak = peak_pressure(main);
        let mostly_on_first = |r: &Region| r.mostly_on(|j| first.cells.iter().any(|f| f.0 == j));
        let shape = self.region(
            node_regions
                .iter()
                .filter(|r| {
                    std::ptr::eq(*r, main)
                        || (mostly_on_first(r) && peak_pressure(r) >= CUT_PART_PEAK_FRACTION * main_peak)
                })
                .flat_map(|r| r.cells.iter().copied())
                .collect(),
        );
        let bridged: Vec<&Region> = solved.regions[1..]
            .iter()
            .filter(|other| other.cells.iter().any(|c| shape.cells.iter().any(|s| s.0 == c.0)))
            .collect();
        if bridged.is_empty() {
            return Some(shape);
        }
        let listed = self.region(
            first
                .cells
                .iter()
                .chain(bridged.iter().flat_map(|other| &other.cells))
                .copied()
                .collect(),
        );
        if self.two_presses(&listed, observed, noise_mm).is_none() {
            return Some(shape);
        }
        let apart: Vec<usize> = bridged
            .iter()
            .flat_map(|other| other.cells.iter().map(|c| c.0))
            .collect();
        let own: Vec<Traction> = shape.cells.into_iter().filter(|c| !apart.contains(&c.0)).collect();
        (!own.is_empty()).then(|| self.region(own))
    }

    /// The cell whose stage 1 pressure is the most above its noise (the per-cell test's best), if that pressure is
    /// positive. The contact test has found a load when stage 2 runs; when no cell clears [`SUPPORT_SIGMAS`] and no
    /// line is a long contact, that load is still somewhere, most likely there. Without it the line shapes alone may
    /// pick only cells far from the load: on the validation sensor at 640x480, a 3 N press 1 mm inside a hole of 8 mm
    /// in the ink near the border (its own corners missing since the rest frame, the best cell at 2.7 sigmas; the
    /// line shapes lay along the left and bottom borders) was read on every noise seed tried as one contact 35 mm
    /// away, along the opposite border, of 0.46-0.90 N (model) where the same press on an intact pad reads 2.40 N; now
    /// 2.7 mm off, 1.53 N (the press's own corners are gone: tests/damaged_pad.rs).
    fn strongest_cell(&self, seed: &Stage1) -> Option<usize> {
        (0..self.cells.len())
            .map(|j| (j, seed.tractions[3 * j + 2] / self.pressure_noise[j]))
            .filter(|&(_, z)| z > 0.0)
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(j, _)| j)
    }

    /// Cells where stage 1 finds pressure above its noise, with a ring around them, as connected groups.
    pub(super) fn loaded_groups(&self, seed: &Stage1, noise_mm: f64) -> Vec<Vec<usize>> {
        self.loaded_groups_and(seed, noise_mm, &[])
    }

    /// [`Self::loaded_groups`] with the cells `also` (per cell; empty: none) loaded as well.
    pub(super) fn loaded_groups_and(&self, seed: &Stage1, noise_mm: f64, also: &[bool]) -> Vec<Vec<usize>> {
        let cells = self.cells.len();
        let (cols, rows) = (usize::from(self.pad.cols), usize::from(self.pad.rows));
        let loaded: Vec<bool> = (0..cells)
            .map(|j| {
                seed.tractions[3 * j + 2] > SUPPORT_SIGMAS * noise_mm * self.pressure_noise[j]
                    || also.get(j).copied().unwrap_or(false)
            })
            .collect();
        let support: Vec<bool> = (0..cells)
            .map(|j| {
                let (r, c) = ((j / cols) as isize, (j % cols) as isize);
                neighbourhood(r, c, rows, cols).any(|(nr, nc)| loaded[nr * cols + nc])
            })
            .collect();
        let mut seen = vec![false; cells];
        let mut groups = Vec::new();
        for start in 0..cells {
            if !support[start] || seen[start] {
                continue;
            }
            let (mut group, mut stack) = (Vec::new(), vec![start]);
            seen[start] = true;
            while let Some(j) = stack.pop() {
                group.push(j);
                let (r, c) = ((j / cols) as isize, (j % cols) as isize);
                for (nr, nc) in neighbourhood(r, c, rows, cols) {
                    let k = nr * cols + nc;
                    if support[k] && !seen[k] {
                        seen[k] = true;
                        stack.push(k);
                    }
                }
            }
            group.sort_unstable();
            groups.push(group);
        }
        groups
    }
}

#[cfg(test)]
mod tests {
    use super::PressureBasis;
    use crate::inverse::test_support::{cell_at, field, model};
    use crate::inverse::MOTION_PARAMETERS;

    #[test]
    fn recovers_a_press_with_shear_under_camera_motion_exactly_without_noise() {
        let model = model();
        let centre = cell_at(&model, [5.0, -3.0]);
        let cols = usize::from(model.pad.cols);
        let press = [
            (centre, [0.4, -0.2, 2.0]),
            (centre + 1, [0.2, -0.1, 1.0]),
            (centre + cols, [0.2, -0.1, 1.0]),
            (centre + cols + 1, [0.1, 0.0, 0.5]),
        ];
        let motion = [0.3, -0.2, 0.01, 0.05, -0.05, 0.01, 0.002, -0.001];
        let d = field(&model, &press, motion);
        let valid = vec![true; model.observations / 2];
        let stage = model.stage1(&d, &valid);
        let outcome = model.test(&stage, 0.002);
        assert!(outcome.contact, "{outcome:?}");
        let stage2 = model.stage2(&d, &valid, &stage, 0.002, 0.1);
        assert_eq!(stage2.regions.len(), 1, "{:?}", stage2.regions);
        let total: [f64; 3] = std::array::from_fn(|k| press.iter().map(|p| p.1[k]).sum());
        let found = stage2.regions[0].force_vector_n;
        for k in 0..3 {
            assert!((found[k] - total[k]).abs() < 0.02 * total[2], "{found:?} vs {total:?}");
        }
        for k in 0..MOTION_PARAMETERS {
            assert!(
                (stage2.motion[k] - motion[k]).abs() < 1e-3,
                "{:?} vs {motion:?}",
                stage2.motion
            );
        }
        // A missing corner under the press changes little.
        let mut holes = valid.clone();
        holes[80] = false;
        holes[81] = false;
        let stage = model.stage1(&d, &holes);
        assert_eq!(stage.residuals[80], None);
        let stage2 = model.stage2(&d, &holes, &stage, 0.002, 0.1);
        assert!(
            (stage2.regions[0].force_vector_n[2] - total[2]).abs() < 0.05 * total[2],
            "{:?}",
            stage2.regions
        );
    }

    /// A press whose push reaches the cells around it, as the pad spreads a contact's shear beyond its pressure:
    /// stage 2 leaves some of the cells it solves shear on without pressure, and the contact's force vector holds the
    /// shear of all of them, the whole push the solve found (before `give_shear_beside` the contact lost the shear of
    /// its group's cells without pressure, here a tenth of the push); its torque stays that of its own cells.
    #[test]
    fn a_contact_holds_all_the_shear_its_group_carries() {
        let model = model();
        let centre = cell_at(&model, [-4.0, 2.0]);
        let cols = usize::from(model.pad.cols);
        let ring = [
            centre - cols - 1,
            centre - cols,
            centre - cols + 1,
            centre - 1,
            centre + 1,
            centre + cols - 1,
            centre + cols,
            centre + cols + 1,
        ];
        let mut press = vec![(centre, [0.2, -0.1, 4.0])];
        press.extend(ring.map(|j| (j, [0.15, -0.1, 0.0])));
        let d = field(&model, &press, [0.0; MOTION_PARAMETERS]);
        let valid = vec![true; model.observations / 2];
        let stage = model.stage1(&d, &valid);
        let stage2 = model.stage2(&d, &valid, &stage, 0.002, 0.1);
        assert_eq!(stage2.regions.len(), 1, "{:?}", stage2.regions);
        let region = &stage2.regions[0];
        // The solve stage 2 made: one pass on stage 1's loaded groups (no line carries this press further).
        let groups = model.loaded_groups(&stage, 0.002);
        let (solved, _, _) = model
            .constrained_solve(&d, &valid, &stage, &groups, PressureBasis::Cells)
            .expect("the press's cells can be solved");
        let group = groups.iter().find(|g| g.contains(&centre)).expect("the press's group");
        let without_pressure = group
            .iter()
            .filter(|&&j| solved[3 * j + 2] <= 0.0 && (solved[3 * j] != 0.0 || solved[3 * j + 1] != 0.0))
            .count();
        assert!(
            without_pressure > 0,
            "every cell of the group kept pressure: nothing to test"
        );
        let shear: [f64; 2] = std::array::from_fn(|k| group.iter().map(|&j| solved[3 * j + k]).sum());
        let torque: f64 = group
            .iter()
            .filter(|&&j| solved[3 * j + 2] > 0.0)
            .map(|&j| {
                let p = model.cells[j].centre_mm;
                (p[0] - region.centre_mm[0]) * solved[3 * j + 1] - (p[1] - region.centre_mm[1]) * solved[3 * j]
            })
            .sum();
        for k in 0..2 {
            assert!(
                (region.force_vector_n[k] - shear[k]).abs() < 1e-9,
                "{:?} against the group's {shear:?}",
                region.force_vector_n
            );
        }
        assert!(
            (region.torque_nmm - torque).abs() < 1e-9,
            "{} against {torque}",
            region.torque_nmm
        );
        let reported: [f64; 2] =
            std::array::from_fn(|k| (0..model.cells.len()).map(|j| stage2.tractions[3 * j + k]).sum());
        assert!(
            (reported[0] - shear[0]).abs() < 1e-9 && (reported[1] - shear[1]).abs() < 1e-9,
            "{reported:?}"
        );
    }

    #[test]
    fn two_presses_apart_are_two_regions_and_an_edge_has_a_direction() {
        let model = model();
        let (a, b) = (cell_at(&model, [-8.0, 0.0]), cell_at(&model, [8.0, 0.0]));
        let d = field(
            &model,
            &[(a, [0.0, 0.0, 3.0]), (b, [0.0, 0.0, 2.0])],
            [0.0; MOTION_PARAMETERS],
        );
        let valid = vec![true; model.observations / 2];
        let stage = model.stage1(&d, &valid);
        let stage2 = model.stage2(&d, &valid, &stage, 0.002, 0.1);
        assert_eq!(stage2.regions.len(), 2, "{:?}", stage2.regions);
        assert!(
            (stage2.regions[0].force_vector_n[2] - 3.0).abs() < 0.1
                && (stage2.regions[1].force_vector_n[2] - 2.0).abs() < 0.1
        );
        // A line of cells along a diagonal.
        let cols = usize::from(model.pad.cols);
        let line: Vec<(usize, [f64; 3])> = (0..7).map(|k| ((2 + k) * cols + 4 + k, [0.0, 0.0, 1.0])).collect();
        let d = field(&model, &line, [0.0; MOTION_PARAMETERS]);
        let stage = model.stage1(&d, &valid);
        let stage2 = model.stage2(&d, &valid, &stage, 0.002, 0.1);
        assert_eq!(stage2.regions.len(), 1, "{:?}", stage2.regions);
        let moments = model.moments(stage2.edge_region.as_ref().expect("a contact"), 0.35);
        let angle = moments.angle_deg.expect("a line has a direction");
        let truth = (3.333f64).atan2(3.3125).to_degrees();
        assert!(
            (angle - truth).abs() < 1.5,
            "{angle} vs {truth}: {moments:?} {:?}",
            stage2.regions[0].cells
        );
    }

    #[test]
    fn degenerate_inputs_give_finite_outputs() {
        let model = model();
        let valid = vec![false; model.observations / 2];
        let d = vec![0.0; model.observations];
        let stage = model.stage1(&d, &valid);
        assert!(stage.tractions.iter().all(|v| v.is_finite()));
        let outcome = model.test(&stage, 0.0);
        assert!(!outcome.contact);
        for v in [
            outcome.statistic,
            outcome.threshold,
            outcome.p_value,
            outcome.detection_floor_n,
        ] {
            assert!(v.is_finite(), "{outcome:?}");
        }
        let stage2 = model.stage2(&d, &valid, &stage, 0.0, 0.1);
        assert!(stage2.regions.is_empty());
    }
}
