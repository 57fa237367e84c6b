//! Stage 2's constrained solve: least squares on the loaded cells with pressure >= 0, by an active set over a
//! Cholesky factor updated as pressures join and leave the free set.

use std::cell::OnceCell;

use nalgebra::{DMatrix, DVector};

use super::{InverseModel, Stage1, MOTION_PARAMETERS};
use crate::linalg::{dot, gram, tr_mul_vec, UpdatedCholesky};

/// Stage 2 gives a contact's shear a second shape, stage 1's own shear along the push (see
/// `InverseModel::shear_along_push`), only when stage 1's net shear on its cells is at least this share of their net
/// pressure. On the quick validation set stage 1 reads the plain presses' net shear at 0.01-0.58 of their pressure
/// (median 0.1) and pushes of 0.2-0.5 of their load at 0.7-2.1. Given to every contact, the second shape fits the
/// model's error on plain presses too: a press halfway to the pattern's corner in a 16:9 frame scaled from the sensor
/// read 7 % lighter than in the 4:3 frame (tests/frame_shapes.rs asks 5 %). The switch is a step: a 4 N press at (-12,
/// 6) mm pushed from 0 to 0.25 of its load in steps of 0.0125 (a scratch ramp at 640x480) crosses it at 0.15 of its
/// load, from where it reads 3 % less normal force and 5-7 % more push than without the shape; the support's own
/// changes make steps as large (5.5 % of the normal force at 0.075, with or without the shape). The same ramp at (2, 1)
/// mm shows no step.
const PUSH_SHAPE_MIN_RATIO: f64 = 0.5;
/// Most active-set iterations of stage 2 (it converges in a few).
const MAX_ACTIVE_SET_ITERATIONS: usize = 50;

/// Stage 2's cell pressures' covariance per sigma^2, from the unconstrained problem's H^-1 (the bound p >= 0 only
/// narrows it). Its block is computed the first time a dip is judged: most frames judge none.
pub(super) struct PressureCovariance {
    /// Per cell: its unknown in `inverse`, if on the support.
    unknown_of: Vec<Option<usize>>,
    /// H's factor and how many of its first unknowns are the cells' pressures (none for the node basis).
    factor: Option<(UpdatedCholesky, usize)>,
    inverse: OnceCell<DMatrix<f64>>,
}

impl PressureCovariance {
    /// The noise (per sigma) of the difference of two cells' pressures.
    pub(super) fn difference_noise(&self, i: usize, j: usize) -> Option<f64> {
        let (factor, pressures) = self.factor.as_ref()?;
        let (a, b) = (self.unknown_of.get(i).copied()??, self.unknown_of.get(j).copied()??);
        let inverse = self.inverse.get_or_init(|| factor.inverse_block(*pressures));
        Some(
            (inverse[(a, a)] + inverse[(b, b)] - 2.0 * inverse[(a, b)])
                .max(0.0)
                .sqrt(),
        )
    }
}

/// The unknowns of stage 2's pressure.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum PressureBasis {
    /// One per cell: the sharpest map, which keeps contacts 10 mm apart apart (and gives the contacts, their forces
    /// and centres). But a pressure that alternates cell by cell (a checkerboard) moves no corner to first order, as
    /// each corner lies between two high and two low cells, so the solve fills it with noise: it splits a long
    /// contact into bumps and turns its second moments.
    Cells,
    /// One per grid node (the pattern's corners and its outline), shared equally by the group's cells that meet
    /// there, each >= 0: no checkerboard, a map one pitch blurrier, for the edge direction.
    Nodes,
}

/// min ½ xᵀ H x - gᵀ x with x_i >= 0 where `constrained[i]`, given `whole`, H's factor over all of its indices in
/// order. The free set's Cholesky factor is factorised once and then updated as pressures join and leave it
/// ([`UpdatedCholesky`]), not refactorised at every step.
pub(super) fn active_set(
    h: &DMatrix<f64>,
    g: &DVector<f64>,
    constrained: &[bool],
    whole: &UpdatedCholesky,
) -> Option<DVector<f64>> {
    let n = g.len();
    let solve = |factor: &UpdatedCholesky| -> DVector<f64> {
        let mut xf: Vec<f64> = factor.index().iter().map(|&i| g[i]).collect();
        factor.solve_mut(&mut xf);
        let mut x = DVector::zeros(n);
        for (&i, &v) in factor.index().iter().zip(&xf) {
            x[i] = v;
        }
        x
    };
    let unconstrained = solve(whole);
    if (0..n).all(|i| !constrained[i] || unconstrained[i] >= 0.0) {
        return Some(unconstrained);
    }
    // Start from the clamped solution: feasible, and usually close.
    let mut free: Vec<bool> = (0..n).map(|i| !constrained[i] || unconstrained[i] > 0.0).collect();
    let mut x = unconstrained.map(|v| v.max(0.0));
    for i in 0..n {
        if !constrained[i] {
            x[i] = unconstrained[i];
        }
    }
    let free_set = |free: &[bool]| (0..n).filter(|&i| free[i]).collect::<Vec<usize>>();
    let mut factor = UpdatedCholesky::new(h, free_set(&free))?;
    let growing = 1e-12 * g.amax().max(1e-300);
    for _ in 0..MAX_ACTIVE_SET_ITERATIONS {
        let z = solve(&factor);
        let infeasible: Vec<usize> = (0..n).filter(|&i| constrained[i] && free[i] && z[i] < 0.0).collect();
        if infeasible.is_empty() {
            x = z;
            // Optimal unless some held pressure would lower the objective by growing.
            let gradient = g - h * &x;
            let best = (0..n)
                .filter(|&i| constrained[i] && !free[i] && gradient[i] > growing)
                .max_by(|&a, &b| gradient[a].total_cmp(&gradient[b]));
            match best {
                Some(i) => {
                    free[i] = true;
                    // Where the update finds the enlarged set not positive definite, a factorisation from scratch
                    // decides (and fails as the solve always did).
                    if !factor.push(h, i) {
                        factor = UpdatedCholesky::new(h, free_set(&free))?;
                    }
                }
                None => return Some(x),
            }
        } else {
            let step = infeasible
                .iter()
                .map(|&i| x[i] / (x[i] - z[i]))
                .fold(1.0, f64::min)
                .clamp(0.0, 1.0);
            x = &x + (&z - &x) * step;
            for i in 0..n {
                if constrained[i] && free[i] && x[i] <= 1e-12 {
                    x[i] = 0.0;
                    free[i] = false;
                    let position = factor.index().iter().position(|&j| j == i)?;
                    factor.remove(position);
                }
            }
        }
    }
    Some(x)
}

/// [`InverseModel::constrained_solve`]'s unknowns but the motion, each a combination of traction components
/// (component index, weight), and the scale of each one's prior (its sigma in units of stage 1's per component).
#[derive(Default)]
struct Unknowns {
    combinations: Vec<Vec<(usize, f64)>>,
    prior_scale: Vec<f64>,
}

impl Unknowns {
    fn push(&mut self, combination: Vec<(usize, f64)>, prior_scale: f64) {
        self.combinations.push(combination);
        self.prior_scale.push(prior_scale);
    }
}

impl InverseModel {
    /// Least squares on the groups with pressure >= 0. Unknowns: each cell's pressure; per group the total
    /// tangential force (x, y) and the twisting moment, carried by the cells in proportion to stage 1's pressure
    /// (friction follows pressure; left free per cell, a ring of inward shear plus extra pressure would mimic a
    /// plain press); and the motion. An active-set solve started from the clamped unconstrained solution.
    #[allow(clippy::type_complexity)]
    pub(super) fn constrained_solve(
        &self,
        d: &[f64],
        valid: &[bool],
        seed: &Stage1,
        groups: &[Vec<usize>],
        basis: PressureBasis,
    ) -> Option<(Vec<f64>, [f64; MOTION_PARAMETERS], PressureCovariance)> {
        let cells = self.cells.len();
        let mut unknowns = self.pressure_unknowns(groups, basis);
        let pressures = unknowns.combinations.len();
        let stage1_dual = Self::stage1_dual(seed, self.lambda);
        for group in groups {
            self.push_shear_unknowns(seed, &stage1_dual, group, &mut unknowns);
        }
        let nt = unknowns.combinations.len();
        let n = nt + MOTION_PARAMETERS;
        let (h, g) = self.normal_equations(d, valid, &unknowns);
        let constrained: Vec<bool> = (0..n).map(|i| i < pressures).collect();
        let whole = UpdatedCholesky::new(&h, (0..n).collect())?;
        let x = active_set(&h, &g, &constrained, &whole)?;
        let mut tractions = vec![0.0; 3 * cells];
        for (k, combination) in unknowns.combinations.iter().enumerate() {
            for &(component, weight) in combination {
                tractions[component] += weight * x[k];
            }
        }
        let motion = std::array::from_fn(|p| x[nt + p]);
        // The cell basis's unknowns are one per cell.
        let covariance = if basis == PressureBasis::Cells {
            let mut unknown_of = vec![None; cells];
            for (k, combination) in unknowns.combinations.iter().take(pressures).enumerate() {
                unknown_of[combination[0].0 / 3] = Some(k);
            }
            PressureCovariance {
                unknown_of,
                factor: Some((whole, pressures)),
                inverse: OnceCell::new(),
            }
        } else {
            PressureCovariance {
                unknown_of: Vec::new(),
                factor: None,
                inverse: OnceCell::new(),
            }
        };
        Some((tractions, motion, covariance))
    }

    /// [`Self::constrained_solve`]'s pressure unknowns in `basis`: one per cell of the groups, or one per node of
    /// each group shared equally by the group's cells that meet there.
    fn pressure_unknowns(&self, groups: &[Vec<usize>], basis: PressureBasis) -> Unknowns {
        let mut unknowns = Unknowns::default();
        for group in groups.iter().filter(|_| basis == PressureBasis::Cells) {
            for &j in group {
                unknowns.push(vec![(3 * j + 2, 1.0)], 1.0);
            }
        }
        for group in groups.iter().filter(|_| basis == PressureBasis::Nodes) {
            for node in self.group_nodes(group) {
                let around: Vec<usize> = self
                    .node_cells(node)
                    .into_iter()
                    .filter(|j| group.binary_search(j).is_ok())
                    .collect();
                let share = 1.0 / around.len() as f64;
                unknowns.push(around.into_iter().map(|j| (3 * j + 2, share)).collect(), 1.0);
            }
        }
        unknowns
    }

    /// [`Self::constrained_solve`]'s shear unknowns of one group: its total tangential force (x, y) spread like stage
    /// 1's pressure, again spread like stage 1's shear along a push when there is one, and its twisting moment.
    /// `stage1_dual`: [`Self::stage1_dual`] of `seed`.
    fn push_shear_unknowns(&self, seed: &Stage1, stage1_dual: &[f64], group: &[usize], unknowns: &mut Unknowns) {
        let raw: Vec<f64> = group.iter().map(|&j| seed.tractions[3 * j + 2].max(0.0)).collect();
        let total: f64 = raw.iter().sum();
        let weights: Vec<f64> = if total > 0.0 {
            raw.iter().map(|w| w / total).collect()
        } else {
            vec![1.0 / group.len() as f64; group.len()]
        };
        let centre = [
            group
                .iter()
                .zip(&weights)
                .map(|(&j, w)| w * self.cells[j].centre_mm[0])
                .sum::<f64>(),
            group
                .iter()
                .zip(&weights)
                .map(|(&j, w)| w * self.cells[j].centre_mm[1])
                .sum::<f64>(),
        ];
        let arm = |j: usize| {
            [
                self.cells[j].centre_mm[0] - centre[0],
                self.cells[j].centre_mm[1] - centre[1],
            ]
        };
        let inertia: f64 = group
            .iter()
            .zip(&weights)
            .map(|(&j, w)| w * (arm(j)[0].powi(2) + arm(j)[1].powi(2)))
            .sum();
        // The shear has the pressure's shape and, on a pushed contact, a second one, stage 1's own shear along the
        // push (see `shear_along_push`), each with its own (fx, fy). A push's shear is not where its pressure is:
        // on the validation pad the pressure centre reads behind the push, and with the pressure's shape alone
        // part of the push was explained by pressure (quick set, against that shape alone: force over the pad
        // 0.36 -> 0.25 N, the pushes' normal force 0.56 -> 0.26 N RMS before `push_normal_share`, tangential
        // direction worst 6.1 -> 3.1 deg).
        let n = group.len() as f64;
        let along = self.shear_along_push(seed, stage1_dual, group);
        for shape in std::iter::once(&weights).chain(along.as_ref()) {
            unknowns.push(group.iter().zip(shape).map(|(&j, &w)| (3 * j, w)).collect(), n);
            unknowns.push(group.iter().zip(shape).map(|(&j, &w)| (3 * j + 1, w)).collect(), n);
        }
        if inertia > 1e-9 {
            let twist = group
                .iter()
                .zip(&weights)
                .flat_map(|(&j, &w)| [(3 * j, -w * arm(j)[1] / inertia), (3 * j + 1, w * arm(j)[0] / inertia)])
                .collect();
            unknowns.push(twist, n * inertia.sqrt());
        }
    }

    /// The normal equations (H, g) of [`Self::constrained_solve`]'s least squares in `unknowns` and the motion over
    /// the corners `valid`, with each unknown's prior on H's diagonal.
    fn normal_equations(&self, d: &[f64], valid: &[bool], unknowns: &Unknowns) -> (DMatrix<f64>, DVector<f64>) {
        let prior = (self.lambda).sqrt().recip();
        let n = unknowns.combinations.len() + MOTION_PARAMETERS;
        // Columns of the reduced design matrix, masked rows zeroed.
        let rows = self.observations;
        // Column by column over contiguous slices (the design is column-major): each column the sum of its
        // combination's rows of A^T, from zero, in the combination's order. The first term is written as it is added
        // to zero (0.0 + w a, the same bits, a -0.0 product included) instead of zeroing the matrix first: that fill
        // took about a tenth of this solve's instructions.
        let mut columns: Vec<f64> = Vec::with_capacity(rows * n);
        for combination in &unknowns.combinations {
            let start = columns.len();
            let Some((&(component, weight), rest)) = combination.split_first() else {
                columns.resize(start + rows, 0.0);
                continue;
            };
            columns.extend(self.a_t.row(component).iter().map(|&a| 0.0 + weight * a));
            let out = &mut columns[start..];
            for &(component, weight) in rest {
                for (o, &a) in out.iter_mut().zip(self.a_t.row(component)) {
                    *o += weight * a;
                }
            }
        }
        for p in 0..MOTION_PARAMETERS {
            columns.extend_from_slice(self.b_t.row(p));
        }
        let mut design = DMatrix::from_vec(rows, n, columns);
        let mut data = DVector::from_column_slice(d);
        for r in (0..rows).filter(|&r| !valid[r / 2]) {
            design.row_mut(r).fill(0.0);
            data[r] = 0.0;
        }
        let mut h = gram(&design);
        for (k, scale) in unknowns.prior_scale.iter().enumerate() {
            h[(k, k)] += (1.0 / (prior * scale)).powi(2) * 1.0;
        }
        let g = tr_mul_vec(&design, data.as_slice());
        (h, g)
    }

    /// Stage 1's kriging solution y (its tractions are Aᵀ y), from its residuals: lambda y on the corners it used, 0
    /// on the others.
    fn stage1_dual(seed: &Stage1, lambda: f64) -> Vec<f64> {
        seed.residuals
            .iter()
            .flat_map(|r| r.map_or([0.0, 0.0], |[x, y]| [x / lambda, y / lambda]))
            .collect()
    }

    /// Stage 1's shear on a group's cells along the group's net shear (the push), cut at 0, as shares that sum to 1;
    /// none unless stage 1 finds a push there: a net shear of at least [`PUSH_SHAPE_MIN_RATIO`] of the group's net
    /// pressure. Stage 1 computes only pressure; its shear Aᵀ y is read here, for the group's cells alone, from its
    /// kriging solution `y` ([`Self::stage1_dual`]).
    fn shear_along_push(&self, seed: &Stage1, y: &[f64], group: &[usize]) -> Option<Vec<f64>> {
        let shear: Vec<[f64; 2]> = group
            .iter()
            .map(|&j| [dot(self.a_t.row(3 * j), y), dot(self.a_t.row(3 * j + 1), y)])
            .collect();
        let pressure: f64 = group.iter().map(|&j| seed.tractions[3 * j + 2]).sum();
        let net = shear.iter().fold([0.0, 0.0], |a, t| [a[0] + t[0], a[1] + t[1]]);
        let length = net[0].hypot(net[1]);
        if !(pressure > 0.0 && length >= PUSH_SHAPE_MIN_RATIO * pressure) {
            return None;
        }
        let along: Vec<f64> = shear
            .iter()
            .map(|t| ((t[0] * net[0] + t[1] * net[1]) / length).max(0.0))
            .collect();
        let total: f64 = along.iter().sum();
        (total > 0.0).then(|| along.iter().map(|a| a / total).collect())
    }

    /// The grid's nodes ((rows + 1) x (cols + 1), row-major: the pattern's corners and its outline) at the corners
    /// of a group's cells.
    fn group_nodes(&self, group: &[usize]) -> Vec<usize> {
        let cols = usize::from(self.pad.cols);
        let mut nodes: Vec<usize> = group
            .iter()
            .flat_map(|&j| {
                let (r, c) = (j / cols, j % cols);
                [(r, c), (r, c + 1), (r + 1, c), (r + 1, c + 1)]
            })
            .map(|(r, c)| r * (cols + 1) + c)
            .collect();
        nodes.sort_unstable();
        nodes.dedup();
        nodes
    }

    /// The cells (up to four) that meet at a node.
    pub(super) fn node_cells(&self, node: usize) -> Vec<usize> {
        let (cols, rows) = (usize::from(self.pad.cols), usize::from(self.pad.rows));
        let (r, c) = (node / (cols + 1), node % (cols + 1));
        [
            (r.wrapping_sub(1), c.wrapping_sub(1)),
            (r.wrapping_sub(1), c),
            (r, c.wrapping_sub(1)),
            (r, c),
        ]
        .into_iter()
        .filter(|&(r, c)| r < rows && c < cols)
        .map(|(r, c)| r * cols + c)
        .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inverse::test_support::pseudo_gauss;

    /// The active-set solve as it was before the free set's factor was updated in place: a factorisation from
    /// scratch at every step.
    fn active_set_from_scratch(h: &DMatrix<f64>, g: &DVector<f64>, constrained: &[bool]) -> Option<DVector<f64>> {
        let n = g.len();
        let solve_free = |free: &[bool]| -> Option<DVector<f64>> {
            let index: Vec<usize> = (0..n).filter(|&i| free[i]).collect();
            let hf = DMatrix::from_fn(index.len(), index.len(), |i, j| h[(index[i], index[j])]);
            let gf = DVector::from_fn(index.len(), |i, _| g[index[i]]);
            let xf = hf.cholesky()?.solve(&gf);
            let mut x = DVector::zeros(n);
            for (k, &i) in index.iter().enumerate() {
                x[i] = xf[k];
            }
            Some(x)
        };
        let unconstrained = solve_free(&vec![true; n])?;
        if (0..n).all(|i| !constrained[i] || unconstrained[i] >= 0.0) {
            return Some(unconstrained);
        }
        let mut free: Vec<bool> = (0..n).map(|i| !constrained[i] || unconstrained[i] > 0.0).collect();
        let mut x = unconstrained.map(|v| v.max(0.0));
        for i in 0..n {
            if !constrained[i] {
                x[i] = unconstrained[i];
            }
        }
        for _ in 0..MAX_ACTIVE_SET_ITERATIONS {
            let z = solve_free(&free)?;
            let infeasible: Vec<usize> = (0..n).filter(|&i| constrained[i] && free[i] && z[i] < 0.0).collect();
            if infeasible.is_empty() {
                x = z;
                let gradient = g - h * &x;
                let best = (0..n)
                    .filter(|&i| constrained[i] && !free[i] && gradient[i] > 1e-12 * g.amax().max(1e-300))
                    .max_by(|&a, &b| gradient[a].total_cmp(&gradient[b]));
                match best {
                    Some(i) => free[i] = true,
                    None => return Some(x),
                }
            } else {
                let step = infeasible
                    .iter()
                    .map(|&i| x[i] / (x[i] - z[i]))
                    .fold(1.0, f64::min)
                    .clamp(0.0, 1.0);
                x = &x + (&z - &x) * step;
                for i in 0..n {
                    if constrained[i] && free[i] && x[i] <= 1e-12 {
                        x[i] = 0.0;
                        free[i] = false;
                    }
                }
            }
        }
        Some(x)
    }

    /// Random non-negative least squares problems (some unknowns free of the bound, as the tangential forces and the
    /// motion are; some designs with near-collinear columns): the solve with the updated factor meets the KKT
    /// conditions (x >= 0 where bound; zero gradient where x is free or positive; a gradient that would not lower
    /// the objective by growing a held x) and gives the solve from scratch's answer, to what the condition number
    /// allows (the solution of a strictly convex problem is unique).
    #[test]
    fn the_active_set_solve_with_an_updated_factor_meets_kkt_and_matches_the_solve_from_scratch() {
        let mut draw = pseudo_gauss(2024);
        let mut iterated = 0;
        for problem in 0..300 {
            let n = 6 + problem % 40;
            let rows = n + 4 + problem % 17;
            let mut a = DMatrix::from_fn(rows, n, |_, _| draw());
            if problem % 3 == 0 {
                // Near-collinear columns: neighbouring cells' responses.
                let spread = [1e-2, 1e-3, 1e-4][problem / 3 % 3];
                for j in (1..n).step_by(4) {
                    for r in 0..rows {
                        a[(r, j)] = a[(r, j - 1)] + spread * draw();
                    }
                }
            }
            // A press-like truth: some positive, some held at zero, the rest free; data with noise.
            let constrained: Vec<bool> = (0..n).map(|i| i < n * 3 / 4).collect();
            let truth = DVector::from_fn(n, |i, _| if constrained[i] { draw().max(0.0) } else { draw() });
            let b = &a * &truth + DVector::from_fn(rows, |_, _| 0.5 * draw());
            let mut h = a.tr_mul(&a);
            for i in 0..n {
                h[(i, i)] += 1e-6;
            }
            let g = a.tr_mul(&b);
            let whole = UpdatedCholesky::new(&h, (0..n).collect()).unwrap();
            let x = active_set(&h, &g, &constrained, &whole).unwrap();
            let reference = active_set_from_scratch(&h, &g, &constrained).unwrap();
            let unconstrained = h.clone().cholesky().unwrap().solve(&g);
            if (0..n).any(|i| constrained[i] && unconstrained[i] < 0.0) {
                iterated += 1;
            }
            let eigen = h.clone().symmetric_eigen().eigenvalues;
            let kappa = eigen.max() / eigen.min();
            let gradient = &g - &h * &x;
            // The solves are backward stable (the updates too), so the free unknowns' gradient is rounding whatever
            // the conditioning: a few units of n ε (|g| + |H| |x|).
            let scale = g.amax() + h.abs().column_sum().amax() * x.amax();
            let tolerance = 4.0 * n as f64 * f64::EPSILON * scale;
            for i in 0..n {
                if constrained[i] {
                    assert!(x[i] >= 0.0, "problem {problem}: x[{i}] = {}", x[i]);
                }
                if !constrained[i] || x[i] > 0.0 {
                    assert!(
                        gradient[i].abs() <= tolerance,
                        "problem {problem}: gradient[{i}] = {:e}",
                        gradient[i]
                    );
                } else {
                    assert!(
                        gradient[i] <= tolerance,
                        "problem {problem}: held x[{i}] would grow: {:e}",
                        gradient[i]
                    );
                }
            }
            // Both backward stable: apart by at most the condition number times that rounding.
            let difference = (&x - &reference).norm();
            assert!(
                difference <= n as f64 * f64::EPSILON * kappa * reference.norm().max(1e-300),
                "problem {problem}: κ {kappa:e}, |x - x_scratch| = {difference:e}, |x| = {:e}",
                reference.norm()
            );
        }
        // Most problems needed the active set, not just the unconstrained solution.
        assert!(iterated > 200, "only {iterated} problems had a bound to hold");
    }
}
