//! A contact's shape: the second moments of its pressure, whose major axis is its edge direction.

use nusense_geometry::Point2;

use super::{InverseModel, Region};

/// Whether a contact is elongated is judged on its core, each cell weighted by its pressure above this fraction of
/// the contact's peak: the solve leaves a low ring of pressure around every contact (its noise, kept positive by
/// p >= 0) whose shape is the noise's, and with it a round 3 mm press measures 14 mm by 11. Above the floor the
/// weights still vary smoothly with the pressure, so no cell enters or leaves abruptly. (The direction itself
/// comes from all of the contact's pressure: cutting the map at a level bends the axis towards the grid's.)
pub(super) const MOMENT_FLOOR_FRACTION: f64 = 0.3;
/// A contact has a direction only when its core is longer than wide by more than this many grid pitches: the
/// smallest contact the node unknowns can show covers 2 x 2 to 3 x 3 cells depending on where it falls on the grid,
/// so a round contact can look up to about a pitch longer one way than the other.
pub(super) const ROUND_EXTENT_PITCHES: f64 = 2.0;

/// Second moments of a pressure distribution.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Moments {
    /// Degrees from +x towards +y, in [0, 180); `None` when round (confidence below the minimum, or not longer
    /// than wide by more than the grid can fake).
    pub angle_deg: Option<f64>,
    /// 1 - minor / major.
    pub confidence: f64,
    /// Length and width (mm) of the contact's core: the uniform strip with its second moments.
    pub length_mm: f64,
    pub width_mm: f64,
}

pub(super) struct SecondMoments {
    pub(super) centre: Point2,
    xx: f64,
    yy: f64,
    xy: f64,
}

impl SecondMoments {
    /// Variances along the major and minor axes.
    pub(super) fn axes(&self) -> (f64, f64) {
        let half_trace = 0.5 * (self.xx + self.yy);
        let root = (0.25 * (self.xx - self.yy).powi(2) + self.xy * self.xy).sqrt();
        (half_trace + root, (half_trace - root).max(0.0))
    }

    /// The major axis, degrees from +x towards +y in [0, 180).
    pub(super) fn angle_deg(&self) -> f64 {
        let angle = (0.5 * (2.0 * self.xy).atan2(self.xx - self.yy))
            .to_degrees()
            .rem_euclid(180.0);
        // rem_euclid can return exactly 180.0 for tiny negative angles.
        if angle >= 180.0 {
            0.0
        } else {
            angle
        }
    }
}

impl InverseModel {
    /// The edge direction of a region: the major axis of its pressure's second moments, and their contrast as the
    /// confidence. Round (no direction) below `min_confidence`, or when the contact's core, its pressure above
    /// `MOMENT_FLOOR_FRACTION` of the peak, is longer than wide by no more than `ROUND_EXTENT_PITCHES`.
    pub fn moments(&self, region: &Region, min_confidence: f64) -> Moments {
        let none = Moments {
            angle_deg: None,
            confidence: 0.0,
            length_mm: 0.0,
            width_mm: 0.0,
        };
        let Some(all) = self.second_moments(region, 0.0) else {
            return none;
        };
        let Some(core) = self.second_moments(region, MOMENT_FLOOR_FRACTION) else {
            return none;
        };
        let (major, minor) = all.axes();
        if !(major > 0.0) {
            return none;
        }
        let confidence = (1.0 - minor / major).clamp(0.0, 1.0);
        let (core_major, core_minor) = core.axes();
        let (length_mm, width_mm) = ((12.0 * core_major).sqrt(), (12.0 * core_minor).sqrt());
        let elongated = length_mm - width_mm > ROUND_EXTENT_PITCHES * self.pad.pitch_x_mm().max(self.pad.pitch_y_mm());
        Moments {
            angle_deg: (confidence >= min_confidence && elongated).then(|| all.angle_deg()),
            confidence,
            length_mm,
            width_mm,
        }
    }

    /// Second moments (mm^2) of a region's pressure above `fraction` of its peak, each cell weighted by its pressure
    /// less that floor and spread over its own area.
    pub(super) fn second_moments(&self, region: &Region, fraction: f64) -> Option<SecondMoments> {
        let floor = fraction * region.cells.iter().map(|c| c.1[2]).fold(0.0, f64::max);
        let above: Vec<(Point2, f64)> = region
            .cells
            .iter()
            .filter(|c| c.1[2] > floor)
            .map(|(j, f)| (self.cells[*j].centre_mm, f[2] - floor))
            .collect();
        let weight: f64 = above.iter().map(|a| a.1).sum();
        if !(weight > 0.0) {
            return None;
        }
        let centre = [
            above.iter().map(|(p, w)| w * p[0]).sum::<f64>() / weight,
            above.iter().map(|(p, w)| w * p[1]).sum::<f64>() / weight,
        ];
        let (mut xx, mut yy, mut xy) = (0.0, 0.0, 0.0);
        for (p, w) in &above {
            let (dx, dy) = (p[0] - centre[0], p[1] - centre[1]);
            xx += w * dx * dx;
            yy += w * dy * dy;
            xy += w * dx * dy;
        }
        Some(SecondMoments {
            centre,
            xx: xx / weight + self.pad.pitch_x_mm().powi(2) / 12.0,
            yy: yy / weight + self.pad.pitch_y_mm().powi(2) / 12.0,
            xy: xy / weight,
        })
    }
}

#[cfg(test)]
mod tests {
    use crate::inverse::test_support::{field, model, node_at, node_press};
    use crate::inverse::MOTION_PARAMETERS;

    #[test]
    fn round_presses_have_no_direction_wherever_they_fall_on_the_grid() {
        // A force at one node, and the same force shared by two and by four neighbouring nodes (the press centred
        // on a cell's edge and on its centre): all round, whatever the grid makes of them.
        let model = model();
        let valid = vec![true; model.observations / 2];
        let (row, col) = node_at(&model, [3.0, 2.0]);
        let presses: [Vec<(usize, [f64; 3])>; 3] = [
            node_press(&model, row, col, [0.0, 0.0, 4.0]),
            [(row, col), (row, col + 1)]
                .iter()
                .flat_map(|&(r, c)| node_press(&model, r, c, [0.0, 0.0, 2.0]))
                .collect(),
            [(row, col), (row, col + 1), (row + 1, col), (row + 1, col + 1)]
                .iter()
                .flat_map(|&(r, c)| node_press(&model, r, c, [0.0, 0.0, 1.0]))
                .collect(),
        ];
        for press in presses {
            let d = field(&model, &press, [0.0; MOTION_PARAMETERS]);
            let stage = model.stage1(&d, &valid);
            let stage2 = model.stage2(&d, &valid, &stage, 0.002, 0.1);
            assert_eq!(stage2.regions.len(), 1, "{:?}", stage2.regions);
            let moments = model.moments(stage2.edge_region.as_ref().expect("a contact"), 0.35);
            assert_eq!(moments.angle_deg, None, "{moments:?}");
            assert!(
                (stage2.regions[0].force_vector_n[2] - 4.0).abs() < 0.1,
                "{:?}",
                stage2.regions
            );
        }
    }
}
