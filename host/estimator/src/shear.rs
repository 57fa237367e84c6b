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
}

/// Samples of both surfaces.
#[derive(Clone, Debug, PartialEq)]
pub struct ShearSamples {
    /// Reference surface samples, paper px.
    pub reference: Vec<Point2>,
    /// s - s_ref, paper px.
    pub displacement: Vec<Point2>,
    /// Whether the sample rests only on valid corners.
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
    pub fn new(rows: usize, cols: usize, surface: &SurfaceConfig) -> Result<Self, SurfaceError> {
        let basis = SampleBasis::for_net(rows, cols, surface.degree_u, surface.degree_v, surface.uv_step)?;
        Ok(Self { rows, cols, degree_u: surface.degree_u, degree_v: surface.degree_v, basis })
    }

    /// Both nets hold `rows x cols` corners in paper px; `valid` masks both.
    pub fn sample(
        &self,
        reference: &[Point2],
        current: &[Point2],
        valid: &[bool],
    ) -> Result<ShearSamples, SurfaceError> {
        let surface = |points: &[Point2]| -> Result<BSplineSurface, SurfaceError> {
            let net = ControlNet::new(self.rows, self.cols, points.to_vec(), valid.to_vec())?;
            BSplineSurface::new(net, self.degree_u, self.degree_v)
        };
        let reference = surface(reference)?.sample_on(&self.basis);
        let current = surface(current)?.sample_on(&self.basis);
        let displacement = current
            .points
            .iter()
            .zip(&reference.points)
            .map(|(c, r)| [c[0] - r[0], c[1] - r[1]])
            .collect();
        Ok(ShearSamples { reference: reference.points, displacement, valid: reference.rests_on_valid })
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
            .map(|(d, _)| d[0].hypot(d[1]))
            .sum::<f64>()
}
