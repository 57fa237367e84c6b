//! The shear measure: B-spline surfaces of the reference and current corner nets (paper px, see
//! [`crate::pad_map`]), sampled on the same uv grid, and gamma = alpha * sum ||s - s_ref|| over the samples
//! that rest only on corners valid in both frames.

use nusense_geometry::Point2;

use crate::config::SurfaceConfig;
use crate::surface::{BSplineSurface, ControlNet, SampleBasis, SurfaceError};

#[derive(Clone, Debug)]
pub struct ShearSampler {
    rows: usize,
    cols: usize,
    degree_u: usize,
    degree_v: usize,
    basis: SampleBasis,
    reference_net: Vec<Point2>,
    /// The reference surface's samples never change: computed once.
    reference_samples: Vec<Point2>,
}

/// The shear of one frame at every sample.
#[derive(Clone, Debug, PartialEq)]
pub struct ShearSamples {
    /// s - s_ref, paper px.
    pub displacement: Vec<Point2>,
    /// Whether the sample rests only on corners valid in both frames.
    pub valid: Vec<bool>,
}

impl ShearSamples {
    pub fn used(&self) -> usize {
        self.valid.iter().filter(|&&v| v).count()
    }

    pub fn total(&self) -> usize {
        self.valid.len()
    }
}

impl ShearSampler {
    /// `reference` holds the rest frame's `rows x cols` corners in paper px; `reference_valid` masks them.
    pub fn new(
        rows: usize,
        cols: usize,
        surface: &SurfaceConfig,
        reference: &[Point2],
        reference_valid: &[bool],
    ) -> Result<Self, SurfaceError> {
        let basis = SampleBasis::for_net(rows, cols, surface.degree_u, surface.degree_v, surface.uv_step)?;
        let net = ControlNet::new(rows, cols, reference.to_vec(), reference_valid.to_vec())?;
        let reference_samples = BSplineSurface::new(net, surface.degree_u, surface.degree_v)?
            .sample_on(&basis)
            .points;
        Ok(Self {
            rows,
            cols,
            degree_u: surface.degree_u,
            degree_v: surface.degree_v,
            basis,
            reference_net: reference.to_vec(),
            reference_samples,
        })
    }

    /// Samples of the reference surface, paper px (meaningful where a frame's samples are valid).
    pub fn reference_samples(&self) -> &[Point2] {
        &self.reference_samples
    }

    /// `current` holds the frame's corners in paper px; `valid` marks the corners valid in both frames.
    /// By linearity s - s_ref is the surface of the corners' displacements, so one surface is evaluated.
    pub fn sample(&self, current: &[Point2], valid: &[bool]) -> Result<ShearSamples, SurfaceError> {
        let net = self.displacement_net(current, valid)?;
        let grid = BSplineSurface::new(net, self.degree_u, self.degree_v)?.sample_on(&self.basis);
        Ok(ShearSamples {
            displacement: grid.points,
            valid: grid.rests_on_valid,
        })
    }

    /// [`Self::sample`] of `current`, with the [`gamma`] of those samples and of `other`'s (the same frame's corners
    /// otherwise placed, over the same `valid`), each bit for bit: one pass over the sample basis for both, and
    /// `other`'s samples are summed, never stored (a frame's compensated and uncompensated gamma).
    pub fn sample_with_gammas(
        &self,
        current: &[Point2],
        other: &[Point2],
        valid: &[bool],
        alpha: f64,
    ) -> Result<(ShearSamples, f64, f64), SurfaceError> {
        let (net, other_net) = (
            self.displacement_net(current, valid)?,
            self.displacement_net(other, valid)?,
        );
        let mut samples = ShearSamples {
            displacement: Vec::with_capacity(self.basis.len()),
            valid: Vec::with_capacity(self.basis.len()),
        };
        // Summed as `gamma` sums: in sample order, from the empty sum.
        let (mut sum, mut other_sum): (f64, f64) = (std::iter::empty::<f64>().sum(), std::iter::empty::<f64>().sum());
        self.basis.for_each_pair(&net, &other_net, |d, e, ok| {
            if ok {
                sum += length(&d);
                other_sum += length(&e);
            }
            samples.displacement.push(d);
            samples.valid.push(ok);
        });
        Ok((samples, alpha * sum, alpha * other_sum))
    }

    /// The net of the corners' displacements from the reference (zero where not `valid`).
    fn displacement_net(&self, current: &[Point2], valid: &[bool]) -> Result<ControlNet, SurfaceError> {
        let displacement: Vec<Point2> = current
            .iter()
            .zip(&self.reference_net)
            .zip(valid)
            .map(|((c, r), &ok)| if ok { [c[0] - r[0], c[1] - r[1]] } else { [0.0, 0.0] })
            .collect();
        ControlNet::new(self.rows, self.cols, displacement, valid.to_vec())
    }
}

/// gamma = alpha * sum over valid samples of ||s - s_ref|| (paper px).
pub fn gamma(samples: &ShearSamples, alpha: f64) -> f64 {
    alpha
        * samples
            .displacement
            .iter()
            .zip(&samples.valid)
            .filter(|(_, &ok)| ok)
            .map(|(d, _)| length(d))
            .sum::<f64>()
}

/// A sample's shear length, the one both sums above add. Plain `sqrt(dx^2 + dy^2)`, not `hypot`: the samples are
/// displacements in paper px (a pixel scale), whose squares lie far from where f64 overflows or underflows (about
/// 1e+-150 before squaring), so the sums differ from `hypot`'s only in their last bits (every reading of the quick
/// validation the same to its printed digits), while `hypot`'s library call, which guards those ranges, took 2.6 % of
/// the inverse's instructions per frame (two per valid sample, some 9000 a frame).
#[inline]
fn length(d: &Point2) -> f64 {
    (d[0] * d[0] + d[1] * d[1]).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gammas_in_one_pass_are_those_of_two_samplings_bit_for_bit() {
        let (rows, cols) = (5, 6);
        let reference: Vec<Point2> = (0..rows * cols)
            .map(|i| [(i % cols) as f64 * 31.7, (i / cols) as f64 * 29.3])
            .collect();
        let mut valid = vec![true; rows * cols];
        valid[7] = false;
        valid[20] = false;
        let moved = |k: f64| -> Vec<Point2> {
            reference
                .iter()
                .enumerate()
                .map(|(i, r)| [r[0] + (i as f64 * k).sin() * 0.37, r[1] + (i as f64 * k).cos() * 0.21])
                .collect()
        };
        let (current, other) = (moved(0.7), moved(1.3));
        let surface = SurfaceConfig {
            degree_u: 2,
            degree_v: 1,
            uv_step: 0.03,
        };
        let sampler = ShearSampler::new(rows, cols, &surface, &reference, &vec![true; rows * cols]).unwrap();
        let (samples, g, g_other) = sampler.sample_with_gammas(&current, &other, &valid, 0.25).unwrap();
        let expected = sampler.sample(&current, &valid).unwrap();
        assert_eq!(samples, expected);
        assert_eq!(g.to_bits(), gamma(&expected, 0.25).to_bits());
        let expected_other = gamma(&sampler.sample(&other, &valid).unwrap(), 0.25);
        assert_eq!(g_other.to_bits(), expected_other.to_bits());
        assert!(g > 0.0 && g_other > 0.0);
    }
}
