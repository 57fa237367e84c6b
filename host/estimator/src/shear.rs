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
        let displacement: Vec<Point2> = current
            .iter()
            .zip(&self.reference_net)
            .zip(valid)
            .map(|((c, r), &ok)| if ok { [c[0] - r[0], c[1] - r[1]] } else { [0.0, 0.0] })
            .collect();
        let net = ControlNet::new(self.rows, self.cols, displacement, valid.to_vec())?;
        let grid = BSplineSurface::new(net, self.degree_u, self.degree_v)?.sample_on(&self.basis);
        Ok(ShearSamples {
            displacement: grid.points,
            valid: grid.rests_on_valid,
        })
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
