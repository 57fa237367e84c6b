//! How well the contact test knows the noise, and the distributions it is judged by: the corners' censored scatter
//! with its degrees of freedom ([`NoiseEstimate`]), and the normal and F quantiles and tails.

/// The contact test's noise, the corners' scatter, counts this share of the corners, those with the largest
/// residuals, only as being at least as large as the rest (see `NoiseEstimate::censored_of`): a contact's corners,
/// a minority, barely count, and the rest measure the noise as precisely as 1.5 squares per corner. The median
/// corner's scatter alone was as precise as 0.96: with it the threshold on rest frames of the daemon's simulated
/// sensor was 640-713 and the real pair's detection floor 0.46 N; with the censored scatter, when it came in, 575-620
/// and 0.415 N (the floor 0.414 N at c5114ae).
const NOISE_CENSORED_SHARE: f64 = 0.25;

/// Standard normal quantile (Acklam's rational approximation, relative error below 1.2e-9).
pub fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969_683_028_665_376e1,
        2.209_460_984_245_205e2,
        -2.759_285_104_469_687e2,
        1.383_577_518_672_69e2,
        -3.066_479_806_614_716e1,
        2.506_628_277_459_239,
    ];
    const B: [f64; 5] = [
        -5.447_609_879_822_406e1,
        1.615_858_368_580_409e2,
        -1.556_989_798_598_866e2,
        6.680_131_188_771_972e1,
        -1.328_068_155_288_572e1,
    ];
    const C: [f64; 6] = [
        -7.784_894_002_430_293e-3,
        -3.223_964_580_411_365e-1,
        -2.400_758_277_161_838,
        -2.549_732_539_343_734,
        4.374_664_141_464_968,
        2.938_163_982_698_783,
    ];
    const D: [f64; 4] = [
        7.784_695_709_041_462e-3,
        3.224_671_290_700_398e-1,
        2.445_134_137_142_996,
        3.754_408_661_907_416,
    ];
    let p = p.clamp(1e-300, 1.0 - 1e-16);
    let low = 0.024_25;
    if p < low {
        let q = (-2.0 * p.ln()).sqrt();
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    } else if p <= 1.0 - low {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    } else {
        -normal_quantile(1.0 - p)
    }
}

/// A noise level (mm per axis) and how well it is known: the degrees of freedom of the chi-square that a sum of
/// squares as precise would have (infinite for a noise that is given, not measured); and the median corner's
/// scatter, the scale that loads are looked for at.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct NoiseEstimate {
    pub(super) mm: f64,
    pub(super) dof: f64,
    /// The median corner's scatter, mm per axis: it ignores half of the corners where `mm` ignores
    /// [`NOISE_CENSORED_SHARE`], and a load heavy enough to move most of them (whose cells are looked for at this
    /// scale, to leave their corners out of `mm`) inflates it less. Looked for at `mm`, the 6 N press of the real pair
    /// left 9 more corners near it in the test's noise, which it raised 6.2 -> 8.3 um (the detection floor 0.41 ->
    /// 0.54 N). The test divides by it too when it is the larger (see
    /// [`InverseModel::verdict`](super::InverseModel::verdict)).
    pub(super) median_mm: f64,
}

impl NoiseEstimate {
    pub(super) fn known(mm: f64) -> Self {
        Self {
            mm,
            dof: f64::INFINITY,
            median_mm: mm,
        }
    }

    /// From corners' squared residuals |r|^2, each sigma^2 chi-square(2), that is 2 sigma^2 times an exponential.
    /// The largest [`NOISE_CENSORED_SHARE`] of them, where a contact's corners would be, count only as being at least
    /// the largest of the others (type II censoring). With k squares kept, T = (sum of the k smallest) + (n - k)
    /// (the k-th smallest) is the sum of the first k spacings between the ordered squares, each times the number of
    /// squares from it up; those are independent exponentials of mean 2 sigma^2 (Renyi), so T / sigma^2 is exactly
    /// chi-square(2 k) (Epstein and Sobel): sigma^2 = T / 2 k, with 2 k degrees of freedom, 1.5 per corner where the
    /// median's were 2 ln^2 2 = 0.96. `squares` must not be empty.
    pub(super) fn censored_of(squares: &mut [f64]) -> Self {
        let n = squares.len();
        let kept = n - (NOISE_CENSORED_SHARE * n as f64) as usize;
        let (smaller, largest_kept, _) = squares.select_nth_unstable_by(kept - 1, f64::total_cmp);
        let largest_kept = *largest_kept;
        let total = smaller.iter().sum::<f64>() + (n - kept + 1) as f64 * largest_kept;
        // The median is among the kept squares (kept > n / 2).
        let middle = n / 2;
        let median = if middle == kept - 1 {
            largest_kept
        } else {
            *smaller.select_nth_unstable_by(middle, f64::total_cmp).1
        };
        Self {
            mm: (total / (2.0 * kept as f64)).sqrt(),
            dof: 2.0 * kept as f64,
            median_mm: (median / (2.0 * std::f64::consts::LN_2)).sqrt(),
        }
    }

    /// Never below `floor_mm`; a floor that is used is given, not measured.
    pub(super) fn floored(self, floor_mm: f64) -> Self {
        let noise = if self.mm >= floor_mm {
            self
        } else {
            Self::known(floor_mm)
        };
        Self {
            median_mm: self.median_mm.max(floor_mm),
            ..noise
        }
    }
}

/// The quantile of F(k, m) at standard normal quantile `z` (Paulson's normal approximation, Wilson-Hilferty's for
/// both chi-squares; m infinite gives chi-square(k) / k, a noise known exactly).
pub fn f_quantile(k: f64, m: f64, z: f64) -> f64 {
    let (c, d) = (2.0 / (9.0 * m), 2.0 / (9.0 * k));
    let (a, b) = (1.0 - c, 1.0 - d);
    // (a u - b)^2 = z^2 (c u^2 + d) with u = F^(1/3), the larger root (the upper tail).
    let quadratic = a * a - z * z * c;
    let half_linear = a * b;
    let constant = b * b - z * z * d;
    let discriminant = half_linear * half_linear - quadratic * constant;
    if !(quadratic > 0.0 && discriminant >= 0.0) {
        // So few degrees of freedom in the noise that the approximation has no upper quantile: no threshold.
        return f64::INFINITY;
    }
    let u = (half_linear + discriminant.sqrt()) / quadratic;
    u.max(0.0).powi(3)
}

/// Upper tail probability of F(k, m) at `x` (Paulson; m infinite: chi-square(k) / k).
pub fn f_upper_tail(k: f64, m: f64, x: f64) -> f64 {
    if !(x > 0.0) {
        return 1.0;
    }
    let (c, d) = (2.0 / (9.0 * m), 2.0 / (9.0 * k));
    let u = x.cbrt();
    let z = ((1.0 - c) * u - (1.0 - d)) / (c * u * u + d).sqrt();
    0.5 * libm::erfc(z / std::f64::consts::SQRT_2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inverse::test_support::pseudo_gauss;

    /// The censored scatter's degrees of freedom are those of its spread over many frames: 20,000 frames of 60
    /// corners, their squared residuals drawn as 2 sigma^2 times an exponential (the spread's standard error about
    /// 1 %). The median of the same squares was as precise as 2 n ln^2 2 = 57.7 squares.
    #[test]
    fn the_censored_scatter_is_unbiased_and_as_precise_as_its_degrees_of_freedom_say() {
        let sigma = 0.002;
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut exponential = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            -(((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64).ln()
        };
        let estimates: Vec<NoiseEstimate> = (0..20_000)
            .map(|_| {
                let mut squares: Vec<f64> = (0..60).map(|_| 2.0 * sigma * sigma * exponential()).collect();
                NoiseEstimate::censored_of(&mut squares)
            })
            .collect();
        let dof = estimates[0].dof;
        assert_eq!(dof, 90.0, "45 corners kept of 60");
        let variances: Vec<f64> = estimates.iter().map(|e| e.mm * e.mm).collect();
        let mean = variances.iter().sum::<f64>() / variances.len() as f64;
        let spread = variances.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (variances.len() - 1) as f64;
        assert!((mean / (sigma * sigma) - 1.0).abs() < 0.005, "{mean}");
        let measured_dof = 2.0 * mean * mean / spread;
        assert!((measured_dof / dof - 1.0).abs() < 0.04, "{measured_dof} against {dof}");
    }

    /// Corners that a contact or the tracker moves far, fewer than the share censored, raise the scatter only by the
    /// rest that they crowd out of it, however far they move: a tenth of them 11 % (the median 8 %).
    #[test]
    fn far_corners_raise_the_censored_scatter_only_by_the_rest_they_crowd_out() {
        let mut gauss = pseudo_gauss(29);
        let mut squares: Vec<f64> = (0..1000).map(|_| 1e-6 * (gauss().powi(2) + gauss().powi(2))).collect();
        let still = NoiseEstimate::censored_of(&mut squares.clone());
        for far in squares.iter_mut().take(100) {
            *far += 1.0;
        }
        let moved = NoiseEstimate::censored_of(&mut squares);
        assert!((moved.mm / still.mm - 1.11).abs() < 0.03, "{moved:?} against {still:?}");
        assert!(
            (moved.median_mm / still.median_mm - 1.08).abs() < 0.03,
            "{moved:?} against {still:?}"
        );
    }

    #[test]
    fn quantiles_match_tables() {
        assert!((normal_quantile(0.975) - 1.959_964).abs() < 1e-6);
        assert!((normal_quantile(1.0 - 1e-6) - 4.753_424).abs() < 1e-5);
        // An infinite second dof is chi-square(k) / k: chi-square(10) at 95 % is 18.307.
        assert!((10.0 * f_quantile(10.0, f64::INFINITY, normal_quantile(0.95)) - 18.307).abs() < 0.05);
        assert!((f_upper_tail(10.0, f64::INFINITY, 18.307 / 10.0) - 0.05).abs() < 0.003);
        // F(10, 20) and F(300, 150) at 95 % and 1 - 1e-6 (tables; Paulson's approximation is within 1 %).
        for (k, m, p, table) in [
            (10.0, 20.0, 0.95, 2.348),
            (300.0, 150.0, 0.95, 1.2693),
            (300.0, 150.0, 1.0 - 1e-6, 2.0289),
        ] {
            let q = f_quantile(k, m, normal_quantile(p));
            assert!(
                (q / table - 1.0).abs() < 0.01,
                "F({k}, {m}) at {p}: {q} against {table}"
            );
            assert!(
                (f_upper_tail(k, m, q) - (1.0 - p)).abs() < 1e-3 * (1.0 - p).max(1e-3),
                "tail at {q}"
            );
        }
    }
}
