//! Edge direction of an elongated contact: the principal axis of the most-sheared samples' positions on the
//! pad. The confidence is the eigenvalue contrast 1 - minor/major: 0 for a round contact (no direction exists,
//! so none is reported), towards 1 for a long edge.

use nusense_geometry::Point2;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EdgeEstimate {
    /// Degrees from +x towards +y on the pad, in [0, 180); `None` when the contact is round.
    pub angle_deg: Option<f64>,
    pub confidence: f64,
    /// Centre and reach (mm) of the samples the direction came from.
    pub region_centre_mm: Point2,
    pub region_radius_mm: f64,
}

impl EdgeEstimate {
    pub const NONE: Self = Self {
        angle_deg: None,
        confidence: 0.0,
        region_centre_mm: [0.0, 0.0],
        region_radius_mm: 0.0,
    };

    /// Scales the confidence by the fraction of the region that was actually seen; a partly seen region can
    /// look elongated only because of its holes, so below `min_coverage` no direction is claimed.
    pub fn with_coverage(self, coverage: f64, min_coverage: f64, min_confidence: f64) -> Self {
        let confidence = self.confidence * coverage.clamp(0.0, 1.0);
        let keep = coverage >= min_coverage && confidence >= min_confidence;
        Self {
            angle_deg: self.angle_deg.filter(|_| keep),
            confidence,
            ..self
        }
    }
}

/// `samples`: (position on the pad in mm, shear magnitude). Samples of at least `fraction` of the peak shear
/// take part, weighted by their shear.
pub fn edge_direction(samples: &[(Point2, f64)], fraction: f64, min_confidence: f64) -> EdgeEstimate {
    let peak = samples.iter().map(|s| s.1).fold(0.0, f64::max);
    if !(peak > 0.0) {
        return EdgeEstimate::NONE;
    }
    let chosen: Vec<&(Point2, f64)> = samples.iter().filter(|s| s.1 >= fraction * peak).collect();
    if chosen.len() < 3 {
        return EdgeEstimate::NONE;
    }
    let sw: f64 = chosen.iter().map(|s| s.1).sum();
    let mx = chosen.iter().map(|s| s.1 * s.0[0]).sum::<f64>() / sw;
    let my = chosen.iter().map(|s| s.1 * s.0[1]).sum::<f64>() / sw;
    let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
    for s in &chosen {
        let (dx, dy) = (s.0[0] - mx, s.0[1] - my);
        sxx += s.1 * dx * dx;
        syy += s.1 * dy * dy;
        sxy += s.1 * dx * dy;
    }
    let (sxx, syy, sxy) = (sxx / sw, syy / sw, sxy / sw);
    let half_trace = (sxx + syy) / 2.0;
    let root = (((sxx - syy) / 2.0).powi(2) + sxy * sxy).sqrt();
    let (major, minor) = (half_trace + root, half_trace - root);
    if !(major > 0.0) {
        return EdgeEstimate::NONE;
    }
    let confidence = (1.0 - minor.max(0.0) / major).clamp(0.0, 1.0);
    let region_radius_mm = chosen
        .iter()
        .map(|s| (s.0[0] - mx).hypot(s.0[1] - my))
        .fold(0.0, f64::max);
    let region = EdgeEstimate {
        angle_deg: None,
        confidence,
        region_centre_mm: [mx, my],
        region_radius_mm,
    };
    if confidence < min_confidence {
        return region;
    }
    let angle = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    let degrees = angle.to_degrees().rem_euclid(180.0);
    // rem_euclid can return exactly 180.0 for tiny negative angles.
    let degrees = if degrees >= 180.0 { 0.0 } else { degrees };
    EdgeEstimate {
        angle_deg: Some(degrees),
        ..region
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_line_of_shear_has_its_direction_and_a_disc_has_none() {
        let line: Vec<(Point2, f64)> = (0..50)
            .map(|i| {
                let t = i as f64 / 5.0 - 5.0;
                let a = 30f64.to_radians();
                ([t * a.cos(), t * a.sin()], 1.0)
            })
            .collect();
        let e = edge_direction(&line, 0.5, 0.35);
        assert!((e.angle_deg.unwrap() - 30.0).abs() < 1e-6, "{e:?}");
        assert!(e.confidence > 0.99);
        let ring: Vec<(Point2, f64)> = (0..72)
            .map(|i| {
                let a = (i as f64 * 5.0).to_radians();
                ([3.0 * a.cos(), 3.0 * a.sin()], 1.0)
            })
            .collect();
        let e = edge_direction(&ring, 0.5, 0.35);
        assert_eq!(e.angle_deg, None);
        assert!(e.confidence < 0.05);
    }
}
