//! The validation set of issue 12: frames the estimator has never seen, made by a sensor that shares none of its
//! assumptions ([`SensorModel::validation`]: another lens and pose, a layered pad solved independently of any
//! estimator kernel, refraction and parallax, glare, vignetting, shot noise, JPEG), with ground truth for every
//! frame.
//!
//! A [`ValidationSet`] is a list of [`Case`]s, deterministic for a profile and a seed; a [`ValidationRenderer`] per
//! frame size renders the rest frame every case is measured against and each case's frame with its
//! [`CaseTruth`]. Cases come in [`CaseKind`]s, one per question the benchmark asks; the calibration cases are
//! apart, so that a force calibration fitted on them is scored on the others.

use image::RgbImage;
use nusense_geometry::{Point2, Similarity};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::model::{ModelError, PadPose, SensorModel, NOMINAL_LED_CURRENT_MA};
use crate::render::{RenderError, Renderer};
use crate::scene::{Contact, Damage, Scene};
use crate::truth::GroundTruth;

/// How many frames: `Quick` for tests and CI (1024 x 768, a few per kind), `Full` for the documented numbers
/// (2048 x 1536, many per kind).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Profile {
    Quick,
    Full,
}

/// What a case asks of the estimator.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CaseKind {
    /// Sphere presses of 1-8 N near the centre: the one force calibration is fitted on these only.
    Calibration,
    /// Presses of 1-8 N anywhere on the pad with spheres (3, 5, 8 mm) and flat tips (1.5, 3 mm).
    Press,
    /// Light presses (0.2-2 N) at several positions: the detection floor.
    Floor,
    /// An edge (20 mm x 1 mm) at many angles.
    Edge,
    /// Light edges (20 mm x 1 mm, 0.2-2 N) at 0, 45, 90 and 135 degrees and several positions: the detection floor
    /// of a long contact, whose load spreads over a line of cells rather than a round patch.
    EdgeFloor,
    /// Two spheres 10 mm apart.
    TwoContacts,
    /// A press with a tangential push in a random direction.
    Tangential,
    /// A press with a twist about the normal and no net tangential force.
    Twist,
    /// No contact: LED drift, noise, JPEG, and camera motion up to 5 degrees.
    Rest,
    /// Presses seen by a camera rotated up to 5 degrees and shifted against the rest frame.
    CameraMotion,
    /// Presses on a pad with ink missing or smeared.
    Damaged,
    /// Presses at other frame sizes.
    Resolution,
    /// Pushes near the centre with a known tangential force, as a force/torque log records them: what a calibration
    /// of the model's shear against its pressure is fitted on (`nusense calibrate`'s tangential scale).
    CalibrationPush,
    /// Twists near the centre with a known torque, as a force/torque log records them: what a calibration of the
    /// model's torque is fitted on (`nusense calibrate`'s torque scale).
    CalibrationTwist,
}

impl CaseKind {
    pub const ALL: [CaseKind; 14] = [
        CaseKind::Calibration,
        CaseKind::Press,
        CaseKind::Floor,
        CaseKind::Edge,
        CaseKind::EdgeFloor,
        CaseKind::TwoContacts,
        CaseKind::Tangential,
        CaseKind::Twist,
        CaseKind::Rest,
        CaseKind::CameraMotion,
        CaseKind::Damaged,
        CaseKind::Resolution,
        CaseKind::CalibrationPush,
        CaseKind::CalibrationTwist,
    ];
}

/// The camera moved against the pad between the rest frame and this frame: added to the pad's pose.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraMotion {
    /// About the camera's x, y and z (optical) axes, degrees.
    pub rotation_deg: [f64; 3],
    /// In the pad's plane, mm.
    pub shift_mm: [f64; 2],
}

impl CameraMotion {
    /// The pad's pose as the moved camera sees it.
    pub fn applied_to(&self, pose: PadPose) -> PadPose {
        PadPose {
            distance_mm: pose.distance_mm,
            shift_mm: [pose.shift_mm[0] + self.shift_mm[0], pose.shift_mm[1] + self.shift_mm[1]],
            rotation_deg: std::array::from_fn(|k| pose.rotation_deg[k] + self.rotation_deg[k]),
        }
    }
}

/// The camera's motion as the image shows it: the similarity transform that best maps the rest lattice's raw px
/// before the motion onto the same material points after it (least squares over the interior corners). The shift
/// is that of the lattice's centroid; the rotation and scale are about it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImageMotion {
    /// From +x towards +y (clockwise on screen), degrees.
    pub rotation_deg: f64,
    pub shift_px: [f64; 2],
    pub scale: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Case {
    pub name: String,
    pub kind: CaseKind,
    pub size: (u32, u32),
    pub scene: Scene,
    pub camera_motion: Option<CameraMotion>,
    /// The LEDs' effective currents for this frame (drift against the rest frame's nominal currents).
    pub led_currents_ma: [f32; 4],
    pub seed: u64,
}

impl Case {
    /// A case under the LEDs' nominal currents with the camera where the rest frame saw it: one effect at a time, as
    /// the tests and benches that are not about the light or the mount need (set `camera_motion` or
    /// `led_currents_ma` on it for one that is).
    pub fn still(name: impl Into<String>, kind: CaseKind, size: (u32, u32), scene: Scene, seed: u64) -> Self {
        Self {
            name: name.into(),
            kind,
            size,
            scene,
            camera_motion: None,
            led_currents_ma: [NOMINAL_LED_CURRENT_MA; 4],
            seed,
        }
    }
}

/// Everything true about one case's frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CaseTruth {
    pub frame: GroundTruth,
    /// The motion given to the camera, and what it does in the image.
    pub camera_motion: Option<(CameraMotion, ImageMotion)>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ValidationSet {
    pub profile: Profile,
    pub seed: u64,
    pub cases: Vec<Case>,
}

/// Largest |x| and |y| of a press centre, mm: the whole pattern (53 x 40 mm) less a margin that keeps the largest
/// tip on the pad.
const REACH_MM: [f64; 2] = [23.0, 17.0];
/// LED drift of a frame against its rest frame: each side's output within +-3 % (+-8 % on drift rest frames).
const DRIFT: f32 = 0.03;
const REST_DRIFT: f32 = 0.08;
/// Largest camera rotation about the optical axis, degrees, and tilt about the others.
const MAX_ROLL_DEG: f64 = 5.0;
const MAX_TILT_DEG: f64 = 1.0;
const MAX_CAMERA_SHIFT_MM: f64 = 1.0;
pub const TWO_CONTACT_SEPARATION_MM: f64 = 10.0;
/// Heaviest press of the small tips (3 mm sphere, 1.5 mm flat tip), N. With these, no case sinks the pattern more
/// than about 2 mm towards the camera, three quarters of the 2.7 mm of elastomer below it (the larger tips and the
/// edge stay under that at 8 N); heavier small-tip presses leave the linear model's reach altogether.
const SMALL_SPHERE_MAX_N: f64 = 3.0;
const SMALL_FLAT_MAX_N: f64 = 2.0;
/// Forces of the detection-floor cases, N.
pub const FLOOR_FORCES_N: [f64; 7] = [0.2, 0.3, 0.5, 0.75, 1.0, 1.5, 2.0];
/// Angles of the edge detection-floor cases, degrees.
pub const EDGE_FLOOR_ANGLES_DEG: [f64; 4] = [0.0, 45.0, 90.0, 135.0];
/// Largest |x| and |y| of an edge's centre, mm: its 20 mm stays on the pattern at any angle.
const EDGE_REACH_MM: [f64; 2] = [12.0, 8.0];

impl ValidationSet {
    pub fn new(profile: Profile, seed: u64) -> Self {
        let mut draw = Draw {
            rng: ChaCha8Rng::seed_from_u64(seed),
            seed,
            quick: profile == Profile::Quick,
            main: match profile {
                Profile::Quick => (1024, 768),
                Profile::Full => (2048, 1536),
            },
            cases: Vec::new(),
        };
        draw.calibration_presses();
        draw.presses();
        draw.floor_presses();
        draw.edges();
        draw.two_contacts();
        draw.pushes(
            CaseKind::Tangential,
            -15.0..=15.0,
            -10.0..=10.0,
            DRIFT,
            draw.many(8, 24),
        );
        draw.twists(CaseKind::Twist, -10.0..=10.0, -6.0..=6.0, DRIFT, draw.many(4, 12));
        draw.rests();
        draw.camera_motions();
        draw.damaged();
        draw.other_sizes(match profile {
            Profile::Quick => &[(640, 480)],
            Profile::Full => &[(640, 480), (1280, 960), (1600, 1200)],
        });
        // Last, so that adding them left every earlier case (and its draws) as it was.
        draw.edge_floor();
        // After the edges' floor, for the same reason. Where and how hard as the calibration presses, the push a
        // fifth to a half of the load, as the tangential cases.
        draw.pushes(CaseKind::CalibrationPush, -8.0..=8.0, -6.0..=6.0, 0.0, draw.many(4, 8));
        // After the calibration pushes, for the same reason. Where and how hard as the twists, nearer the centre.
        draw.twists(CaseKind::CalibrationTwist, -8.0..=8.0, -6.0..=6.0, 0.0, draw.many(4, 8));
        Self {
            profile,
            seed,
            cases: draw.cases,
        }
    }

    /// The frame sizes the cases use, the main one first.
    pub fn sizes(&self) -> Vec<(u32, u32)> {
        let mut sizes: Vec<(u32, u32)> = Vec::new();
        for case in &self.cases {
            if !sizes.contains(&case.size) {
                sizes.push(case.size);
            }
        }
        sizes
    }

    pub fn of_kind(&self, kind: CaseKind) -> impl Iterator<Item = &Case> {
        self.cases.iter().filter(move |c| c.kind == kind)
    }
}

/// The set's cases as they are drawn: one seeded generator whose draws follow the cases' order, so that a kind added
/// last leaves every earlier case as it was.
struct Draw {
    rng: ChaCha8Rng,
    seed: u64,
    quick: bool,
    /// The main size, px.
    main: (u32, u32),
    cases: Vec<Case>,
}

impl Draw {
    /// `quick` cases in the quick profile, `full` in the full one.
    fn many(&self, quick: usize, full: usize) -> usize {
        if self.quick {
            quick
        } else {
            full
        }
    }

    /// Adds a case, its LED currents each drawn within `drift` of the nominal current.
    fn push(
        &mut self,
        kind: CaseKind,
        size: (u32, u32),
        scene: Scene,
        camera_motion: Option<CameraMotion>,
        drift: f32,
    ) {
        let rng = &mut self.rng;
        let led_currents_ma = std::array::from_fn(|_| NOMINAL_LED_CURRENT_MA * (1.0 + rng.gen_range(-drift..=drift)));
        let index = self.cases.len();
        self.cases.push(Case {
            name: format!("{}_{index:03}", kind_name(kind)),
            kind,
            size,
            scene,
            camera_motion,
            led_currents_ma,
            seed: self.seed.wrapping_mul(1_000_003).wrapping_add(index as u64 + 1),
        });
    }

    fn anywhere(&mut self) -> Point2 {
        [
            self.rng.gen_range(-REACH_MM[0]..=REACH_MM[0]),
            self.rng.gen_range(-REACH_MM[1]..=REACH_MM[1]),
        ]
    }

    /// Anywhere an edge fits.
    fn edge_anywhere(&mut self) -> Point2 {
        [
            self.rng.gen_range(-EDGE_REACH_MM[0]..=EDGE_REACH_MM[0]),
            self.rng.gen_range(-EDGE_REACH_MM[1]..=EDGE_REACH_MM[1]),
        ]
    }

    /// One of the five tips at `at`. The small tips only up to the force at which the linear pad still holds: a
    /// 1.5 mm flat tip at 6 N would push the pattern further towards the camera than the 2.7 mm of elastomer below
    /// it.
    fn any_tip(&mut self, at: Point2) -> Contact {
        let rng = &mut self.rng;
        match rng.gen_range(0..5) {
            0 => Contact::sphere(3.0, at, rng.gen_range(1.0..=SMALL_SPHERE_MAX_N)),
            1 => Contact::sphere(5.0, at, rng.gen_range(1.0..=8.0)),
            2 => Contact::sphere(8.0, at, rng.gen_range(1.0..=8.0)),
            3 => Contact::flat_punch(1.5, at, rng.gen_range(1.0..=SMALL_FLAT_MAX_N)),
            _ => Contact::flat_punch(3.0, at, rng.gen_range(1.0..=8.0)),
        }
    }

    fn calibration_presses(&mut self) {
        let forces = self.many(8, 16);
        for i in 0..forces {
            let force = 1.0 + 7.0 * i as f64 / (forces - 1) as f64;
            let at = [self.rng.gen_range(-8.0..=8.0), self.rng.gen_range(-6.0..=6.0)];
            let scene = Scene::with_contact(Contact::sphere(5.0, at, force));
            self.push(CaseKind::Calibration, self.main, scene, None, 0.0);
        }
    }

    fn presses(&mut self) {
        for _ in 0..self.many(24, 80) {
            let at = self.anywhere();
            let scene = Scene::with_contact(self.any_tip(at));
            self.push(CaseKind::Press, self.main, scene, None, DRIFT);
        }
    }

    fn floor_presses(&mut self) {
        for force in FLOOR_FORCES_N {
            for k in 0..self.many(3, 8) {
                let at = self.anywhere();
                let tip = if k % 2 == 0 {
                    Contact::sphere(5.0, at, force)
                } else {
                    Contact::flat_punch(3.0, at, force)
                };
                self.push(CaseKind::Floor, self.main, Scene::with_contact(tip), None, DRIFT);
            }
        }
    }

    fn edges(&mut self) {
        let edges = self.many(8, 24);
        for k in 0..edges {
            let angle = 180.0 * k as f64 / edges as f64 + self.rng.gen_range(0.0..180.0 / edges as f64);
            let at = self.edge_anywhere();
            let force = self.rng.gen_range(3.0..=8.0);
            let scene = Scene::with_contact(Contact::edge(20.0, 1.0, angle, at, force));
            self.push(CaseKind::Edge, self.main, scene, None, DRIFT);
        }
    }

    fn two_contacts(&mut self) {
        for _ in 0..self.many(6, 16) {
            let rng = &mut self.rng;
            let mid = [rng.gen_range(-14.0..=14.0), rng.gen_range(-9.0..=9.0)];
            let direction = rng.gen_range(0.0..std::f64::consts::PI);
            let half = [
                0.5 * TWO_CONTACT_SEPARATION_MM * direction.cos(),
                0.5 * TWO_CONTACT_SEPARATION_MM * direction.sin(),
            ];
            let a = Contact::sphere(4.0, [mid[0] - half[0], mid[1] - half[1]], rng.gen_range(2.0..=6.0));
            let b = Contact::sphere(4.0, [mid[0] + half[0], mid[1] + half[1]], rng.gen_range(2.0..=6.0));
            let scene = Scene {
                contacts: vec![a, b],
                ..Scene::default()
            };
            self.push(CaseKind::TwoContacts, self.main, scene, None, DRIFT);
        }
    }

    /// `count` spheres pushed sideways (see [`sphere_with_push`]) within `x` and `y` (mm), as cases of `kind`.
    fn pushes(
        &mut self,
        kind: CaseKind,
        x: std::ops::RangeInclusive<f64>,
        y: std::ops::RangeInclusive<f64>,
        drift: f32,
        count: usize,
    ) {
        for _ in 0..count {
            let at = [self.rng.gen_range(x.clone()), self.rng.gen_range(y.clone())];
            let scene = Scene::with_contact(sphere_with_push(&mut self.rng, at));
            self.push(kind, self.main, scene, None, drift);
        }
    }

    /// `count` 8 mm spheres of 4-6 N within `x`, `y` (mm), twisted by 5-20 N mm, alternately each way.
    fn twists(
        &mut self,
        kind: CaseKind,
        x: std::ops::RangeInclusive<f64>,
        y: std::ops::RangeInclusive<f64>,
        drift: f32,
        count: usize,
    ) {
        for k in 0..count {
            let rng = &mut self.rng;
            let at = [rng.gen_range(x.clone()), rng.gen_range(y.clone())];
            let mut contact = Contact::sphere(8.0, at, rng.gen_range(4.0..=6.0));
            let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
            contact.torsion_nmm = sign * rng.gen_range(5.0..=20.0);
            self.push(kind, self.main, Scene::with_contact(contact), None, drift);
        }
    }

    fn rests(&mut self) {
        for k in 0..self.many(6, 16) {
            // Half under LED drift alone, half with the camera moved as well.
            let motion = (k % 2 == 1).then(|| camera_motion(&mut self.rng));
            self.push(CaseKind::Rest, self.main, Scene::rest(), motion, REST_DRIFT);
        }
    }

    fn camera_motions(&mut self) {
        for _ in 0..self.many(8, 24) {
            let (at, force) = (self.anywhere(), self.rng.gen_range(1.0..=8.0));
            let scene = Scene::with_contact(Contact::sphere(5.0, at, force));
            let motion = Some(camera_motion(&mut self.rng));
            self.push(CaseKind::CameraMotion, self.main, scene, motion, DRIFT);
        }
    }

    fn damaged(&mut self) {
        for k in 0..self.many(3, 8) {
            let (at, force) = (self.anywhere(), self.rng.gen_range(2.0..=8.0));
            let mut scene = Scene::with_contact(Contact::sphere(5.0, at, force));
            let centre = self.anywhere();
            scene.damage.push(if k % 2 == 0 {
                Damage::Missing {
                    centre_mm: centre,
                    radius_mm: self.rng.gen_range(2.0..=5.0),
                }
            } else {
                Damage::Smeared {
                    centre_mm: centre,
                    radius_mm: self.rng.gen_range(3.0..=6.0),
                    smear_mm: 0.5,
                }
            });
            self.push(CaseKind::Damaged, self.main, scene, None, DRIFT);
        }
    }

    fn other_sizes(&mut self, sizes: &[(u32, u32)]) {
        for &size in sizes {
            for _ in 0..4 {
                let (at, force) = (self.anywhere(), self.rng.gen_range(1.0..=8.0));
                let scene = Scene::with_contact(Contact::sphere(5.0, at, force));
                self.push(CaseKind::Resolution, size, scene, None, DRIFT);
            }
        }
    }

    fn edge_floor(&mut self) {
        for force in FLOOR_FORCES_N {
            for k in 0..self.many(2, 4) {
                for angle in EDGE_FLOOR_ANGLES_DEG {
                    // Near the centre on the first round, anywhere the edge fits on the others.
                    let at = if k == 0 {
                        [self.rng.gen_range(-3.0..=3.0), self.rng.gen_range(-3.0..=3.0)]
                    } else {
                        self.edge_anywhere()
                    };
                    let scene = Scene::with_contact(Contact::edge(20.0, 1.0, angle, at, force));
                    self.push(CaseKind::EdgeFloor, self.main, scene, None, DRIFT);
                }
            }
        }
    }
}

fn kind_name(kind: CaseKind) -> &'static str {
    match kind {
        CaseKind::Calibration => "calibration",
        CaseKind::Press => "press",
        CaseKind::Floor => "floor",
        CaseKind::Edge => "edge",
        CaseKind::EdgeFloor => "edge_floor",
        CaseKind::TwoContacts => "two_contacts",
        CaseKind::Tangential => "tangential",
        CaseKind::Twist => "twist",
        CaseKind::Rest => "rest",
        CaseKind::CameraMotion => "camera_motion",
        CaseKind::Damaged => "damaged",
        CaseKind::Resolution => "resolution",
        CaseKind::CalibrationPush => "calibration_push",
        CaseKind::CalibrationTwist => "calibration_twist",
    }
}

/// A 5 mm sphere pressing 3-6 N at `at`, pushed sideways by a fifth to a half of that in a random direction.
fn sphere_with_push(rng: &mut ChaCha8Rng, at: Point2) -> Contact {
    let normal = rng.gen_range(3.0..=6.0);
    let (magnitude, direction) = (
        normal * rng.gen_range(0.2..=0.5),
        rng.gen_range(0.0..std::f64::consts::TAU),
    );
    let mut contact = Contact::sphere(5.0, at, normal);
    contact.tangential_force_n = [magnitude * direction.cos(), magnitude * direction.sin()];
    contact
}

fn camera_motion(rng: &mut ChaCha8Rng) -> CameraMotion {
    let sign = if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
    CameraMotion {
        rotation_deg: [
            rng.gen_range(-MAX_TILT_DEG..=MAX_TILT_DEG),
            rng.gen_range(-MAX_TILT_DEG..=MAX_TILT_DEG),
            sign * rng.gen_range(0.5..=MAX_ROLL_DEG),
        ],
        shift_mm: [
            rng.gen_range(-MAX_CAMERA_SHIFT_MM..=MAX_CAMERA_SHIFT_MM),
            rng.gen_range(-MAX_CAMERA_SHIFT_MM..=MAX_CAMERA_SHIFT_MM),
        ],
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ValidationError {
    #[error("the validation sensor: {0}")]
    Model(#[from] ModelError),
    #[error("rendering a validation frame: {0}")]
    Render(#[from] RenderError),
    #[error("case {case} is {found:?} but this renderer makes {expected:?} frames")]
    WrongSize {
        case: String,
        found: (u32, u32),
        expected: (u32, u32),
    },
}

/// The validation sensor at one frame size.
pub struct ValidationRenderer {
    renderer: Renderer,
}

impl ValidationRenderer {
    pub fn new(size: (u32, u32)) -> Result<Self, ValidationError> {
        Ok(Self {
            renderer: Renderer::new(SensorModel::validation(size.0, size.1))?,
        })
    }

    pub fn renderer(&self) -> &Renderer {
        &self.renderer
    }

    /// The rest frame every case of this size is measured against: nominal LEDs, the camera where it was
    /// mounted.
    pub fn reference(&self, set_seed: u64) -> Result<RgbImage, ValidationError> {
        Ok(self
            .renderer
            .render(&Scene::rest(), [NOMINAL_LED_CURRENT_MA; 4], set_seed)?
            .0)
    }

    pub fn render(&self, case: &Case) -> Result<(RgbImage, CaseTruth), ValidationError> {
        let expected = (self.renderer.model().width, self.renderer.model().height);
        if case.size != expected {
            return Err(ValidationError::WrongSize {
                case: case.name.clone(),
                found: case.size,
                expected,
            });
        }
        match case.camera_motion {
            None => {
                let (image, frame) = self.renderer.render(&case.scene, case.led_currents_ma, case.seed)?;
                Ok((
                    image,
                    CaseTruth {
                        frame,
                        camera_motion: None,
                    },
                ))
            }
            Some(motion) => {
                let moved = self.renderer.with_pose(motion.applied_to(self.renderer.model().pose))?;
                let (image, frame) = moved.render(&case.scene, case.led_currents_ma, case.seed)?;
                let before = self
                    .renderer
                    .ground_truth(&Scene::rest(), case.led_currents_ma, case.seed)?;
                let after = moved.ground_truth(&Scene::rest(), case.led_currents_ma, case.seed)?;
                let pairs: Vec<(Point2, Point2)> = before
                    .corners
                    .iter()
                    .zip(&after.corners)
                    .map(|(a, b)| (a.rest_px, b.rest_px))
                    .collect();
                Ok((
                    image,
                    CaseTruth {
                        frame,
                        camera_motion: Some((motion, similarity(&pairs))),
                    },
                ))
            }
        }
    }
}

/// Least-squares similarity a -> b: rotation and scale about the centroid of a, and the centroid's motion.
pub fn similarity(pairs: &[(Point2, Point2)]) -> ImageMotion {
    match Similarity::fit(pairs.iter()) {
        Some(fit) => ImageMotion {
            rotation_deg: fit.rotation.to_degrees(),
            shift_px: fit.shift(),
            scale: fit.scale,
        },
        None => ImageMotion {
            rotation_deg: 0.0,
            shift_px: [0.0, 0.0],
            scale: 0.0,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_set_is_deterministic_valid_and_covers_every_kind() {
        let a = ValidationSet::new(Profile::Quick, 3);
        assert_eq!(a, ValidationSet::new(Profile::Quick, 3));
        assert_ne!(a, ValidationSet::new(Profile::Quick, 4));
        let pad = nusense_geometry::PadGeometry::default();
        for case in &a.cases {
            case.scene.validate(&pad).unwrap();
        }
        for kind in CaseKind::ALL {
            assert!(a.of_kind(kind).count() >= 3, "{kind:?}");
        }
        let full = ValidationSet::new(Profile::Full, 3);
        assert!(full.cases.len() > 2 * a.cases.len());
        assert_eq!(full.sizes()[0], (2048, 1536));
        // Two contacts are 10 mm apart; twists carry no net tangential force; camera rolls reach up to 5 degrees.
        for case in full.of_kind(CaseKind::TwoContacts) {
            let (p, q) = (case.scene.contacts[0].position_mm, case.scene.contacts[1].position_mm);
            assert!(((p[0] - q[0]).hypot(p[1] - q[1]) - TWO_CONTACT_SEPARATION_MM).abs() < 1e-12);
        }
        for case in full.of_kind(CaseKind::Twist) {
            assert_eq!(case.scene.contacts[0].tangential_force_n, [0.0, 0.0]);
        }
        let largest_roll = full
            .of_kind(CaseKind::CameraMotion)
            .map(|c| c.camera_motion.unwrap().rotation_deg[2].abs())
            .fold(0.0, f64::max);
        assert!(largest_roll > 4.0 && largest_roll <= MAX_ROLL_DEG, "{largest_roll}");
    }

    #[test]
    fn every_case_stays_within_the_linear_pad() {
        // Every case has its ground truth, and no press sinks the pattern through most of the elastomer under it.
        // The frame size changes only pixels, not mechanics: a small renderer is enough.
        let renderer = ValidationRenderer::new((160, 120)).unwrap();
        let elastomer_mm = 2.7;
        let set = ValidationSet::new(Profile::Quick, 7);
        let mut deepest: f64 = 0.0;
        for case in &set.cases {
            let truth = renderer
                .renderer()
                .ground_truth(&case.scene, case.led_currents_ma, case.seed)
                .unwrap_or_else(|e| panic!("{}: {e}", case.name));
            let sink = truth
                .corners
                .iter()
                .map(|c| c.normal_displacement_mm)
                .fold(0.0, f64::max);
            assert!(sink < 0.75 * elastomer_mm, "{}: the pattern sinks {sink} mm", case.name);
            deepest = deepest.max(sink);
        }
        // The set does press hard: the deepest case sinks over a millimetre (measured: 1.8 mm).
        assert!(deepest > 1.0, "{deepest}");
    }

    #[test]
    fn the_similarity_fit_recovers_a_known_motion() {
        let (angle, scale, shift) = (3f64.to_radians(), 1.01, [4.0, -2.5]);
        let pairs: Vec<(Point2, Point2)> = (0..20)
            .map(|i| {
                let a = [f64::from(i % 5) * 30.0 + 100.0, f64::from(i / 5) * 25.0 + 80.0];
                let c = [160.0, 117.5];
                let (dx, dy) = (a[0] - c[0], a[1] - c[1]);
                let b = [
                    c[0] + shift[0] + scale * (angle.cos() * dx - angle.sin() * dy),
                    c[1] + shift[1] + scale * (angle.sin() * dx + angle.cos() * dy),
                ];
                (a, b)
            })
            .collect();
        let m = similarity(&pairs);
        assert!((m.rotation_deg - 3.0).abs() < 1e-12, "{m:?}");
        assert!(
            (m.scale - 1.01).abs() < 1e-12 && (m.shift_px[0] - 4.0).abs() < 1e-9 && (m.shift_px[1] + 2.5).abs() < 1e-9
        );
    }

    #[test]
    fn a_rolled_camera_turns_the_image_by_about_its_roll() {
        let renderer = ValidationRenderer::new((320, 240)).unwrap();
        let case = Case {
            camera_motion: Some(CameraMotion {
                rotation_deg: [0.0, 0.0, 4.0],
                shift_mm: [0.0, 0.0],
            }),
            ..Case::still("roll", CaseKind::Rest, (320, 240), Scene::rest(), 1)
        };
        let (_, truth) = renderer.render(&case).unwrap();
        let (_, image) = truth.camera_motion.unwrap();
        // The pad turns by the roll in camera coordinates; the fisheye, tilt and refraction bend it a little.
        assert!((image.rotation_deg - 4.0).abs() < 0.3, "{image:?}");
        assert!(truth.frame.contacts.is_empty() && truth.frame.force_vector_n == [0.0; 3]);
    }
}
