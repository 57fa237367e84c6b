//! What really happened in a simulated frame, for scoring the estimator.

use nusense_geometry::CornerIndex;
use serde::{Deserialize, Serialize};

use crate::scene::Indenter;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ContactTruth {
    pub indenter: Indenter,
    /// Contact centre in pad mm.
    pub centre_mm: [f64; 2],
    /// The colour layer's point below the contact centre, in raw px of this frame.
    pub centre_px: [f64; 2],
    pub normal_force_n: f64,
    pub tangential_force_n: [f64; 2],
    pub torsion_nmm: f64,
    /// Radius of the loaded area (sphere: Hertz radius at this force; punch: its radius; edge: half its width).
    pub contact_radius_mm: f64,
    /// The loaded area (disc, or the edge's strip), mm^2.
    pub area_mm2: f64,
    /// The edge's direction in pad mm, in [0, 180), for edge contacts.
    pub edge_angle_deg: Option<f64>,
    /// The same direction as it appears in the raw frame around the contact centre, in [0, 180).
    pub edge_angle_px_deg: Option<f64>,
}

/// One interior corner of the checkerboard.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CornerTruth {
    pub index: CornerIndex,
    pub rest_mm: [f64; 2],
    pub displaced_mm: [f64; 2],
    /// Displacement into the gel (the camera sees it only as a tiny change of scale).
    pub normal_displacement_mm: f64,
    pub rest_px: [f64; 2],
    pub displaced_px: [f64; 2],
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GroundTruth {
    pub width: u32,
    pub height: u32,
    pub seed: u64,
    /// Top, Right, Bottom, Left.
    pub led_currents_ma: [f32; 4],
    pub contacts: Vec<ContactTruth>,
    /// Sum of the contacts' normal forces, N.
    pub total_force_n: f64,
    /// Sum of the contacts' forces [fx, fy, fz] in the pad frame (x right, y down, z into the pad), N.
    pub force_vector_n: [f64; 3],
    /// Moment of the contacts' forces about the pad's normal through the pad centre (twists included), N mm,
    /// positive from +x towards +y.
    pub torque_nmm: f64,
    /// Row-major over the pad's interior corners (`PadGeometry::corner_slot` order).
    pub corners: Vec<CornerTruth>,
}

impl GroundTruth {
    /// Largest in-plane corner displacement, mm.
    pub fn max_corner_displacement_mm(&self) -> f64 {
        self.corners
            .iter()
            .map(|c| (c.displaced_mm[0] - c.rest_mm[0]).hypot(c.displaced_mm[1] - c.rest_mm[1]))
            .fold(0.0, f64::max)
    }
}
