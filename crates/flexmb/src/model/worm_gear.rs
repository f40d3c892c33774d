//! A crossed-axis worm gear pair with friction in the mesh and, optionally, at the worm's
//! thrust washer: what a model file's `[[worm_gear]]` declares. The mechanics, the
//! efficiencies and the torque bias ratio of a Torsen-type differential built from such
//! meshes are in [`crate::elements::worm_gear`].

use super::{Model, NodeId};
use flexmb_lie::{Frame, Mat3, Vec3};

/// A worm (node A) meshing with a worm wheel (node B) about perpendicular axes.
///
/// The frames are built by [`Model::add_worm_gear`]: the worm frame has its origin on the
/// worm axis at the foot of the common perpendicular of the two axes, z along the worm axis
/// and x along the common perpendicular towards the wheel axis; the wheel frame has its origin
/// on the wheel axis at the other foot (the distance between the origins is the centre
/// distance `a_0`), x towards the worm axis and z = (worm z) x (worm x), so that the wheel's
/// y axis is the worm axis. Either node may be the ground (the frame is then inertial).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct WormGear {
    pub name: String,
    /// Node of the worm (`None`: fixed to the ground).
    pub node_a: Option<NodeId>,
    /// Node of the worm wheel.
    pub node_b: Option<NodeId>,
    /// Worm frame on node A (above).
    pub frame_a: Frame,
    /// Wheel frame on node B (above).
    pub frame_b: Frame,
    /// Number of threads (starts) z_1 of the worm, >= 1.
    pub starts: u32,
    /// Number of teeth z_2 of the wheel, >= 1.
    pub teeth: u32,
    /// Pitch radius r_1 of the worm \[m\], in (0, a_0).
    pub worm_radius: f64,
    /// Centre distance a_0 at t = 0 \[m\] (derived from the frames); the wheel's pitch radius
    /// is `r_2 = a_0 - r_1`.
    pub center_distance: f64,
    /// Normal pressure angle alpha_n \[rad\], in (0, pi/2).
    pub pressure_angle: f64,
    /// Left-handed thread (the lead angle's sign; right-handed by default).
    pub left_hand: bool,
    /// Mesh stiffness k along the thread normal \[N/m\], > 0.
    pub mesh_stiffness: f64,
    /// Mesh damping c along the thread normal \[N s/m\], >= 0 (in contact only).
    pub damping: f64,
    /// Coulomb friction coefficient mu of the flanks and of the thrust washer, >= 0.
    pub friction: f64,
    /// Stiction velocity v_s of the regularized friction \[m/s\], > 0.
    pub stiction_velocity: f64,
    /// Mean friction radius r_w of the worm's thrust washer \[m\], >= 0 (0: no washer).
    pub washer_radius: f64,
}

impl WormGear {
    /// Pitch radius of the wheel `r_2 = a_0 - r_1` \[m\].
    pub fn wheel_radius(&self) -> f64 {
        self.center_distance - self.worm_radius
    }

    /// Lead angle `lambda` of the worm at its pitch radius, `tan(lambda) = z_1 r_2 / (z_2
    /// r_1)` (the axial advance of the thread per worm turn is a wheel pitch per start), \[rad\],
    /// positive: the hand is [`WormGear::left_hand`].
    pub fn lead_angle(&self) -> f64 {
        (self.starts as f64 * self.wheel_radius() / (self.teeth as f64 * self.worm_radius)).atan()
    }

    /// Speed ratio `omega_worm / omega_wheel = z_2 / z_1` (magnitudes, relative to the axes).
    pub fn ratio(&self) -> f64 {
        self.teeth as f64 / self.starts as f64
    }
}

impl Model {
    /// Adds a worm gear pair ([`WormGear`]): the worm on `nodes[0]` turning about
    /// `axes[0]` through `centers[0]`, the wheel on `nodes[1]` turning about `axes[1]`
    /// (perpendicular to the worm axis; the caller checks) through `centers[1]` (inertial,
    /// t = 0), with `starts` threads, `teeth` teeth, the worm pitch radius `worm_radius`
    /// and the mesh stiffness `k`, a pressure angle of 20 deg, no damping, friction or washer
    /// (set those fields after); returns its index in [`Model::worm_gears`].
    pub fn add_worm_gear(
        &mut self,
        name: &str,
        nodes: [Option<NodeId>; 2],
        centers: [Vec3; 2],
        axes: [Vec3; 2],
        (starts, teeth, worm_radius): (u32, u32, f64),
        k: f64,
    ) -> usize {
        let (e1, e2) = (axes[0].normalize(), axes[1].normalize());
        let d = centers[1] - centers[0];
        // the common perpendicular and its feet on the two axes
        let across = d - e1 * e1.dot(&d) - e2 * e2.dot(&d);
        let x = if across.norm() > 0.0 {
            across.normalize()
        } else {
            super::frame_from_axis(&e1, None).column(0).into_owned()
        };
        let foot_a = centers[0] + e1 * e1.dot(&d);
        let foot_b = centers[1] - e2 * e2.dot(&d);
        let y = e1.cross(&x);
        let worm = Frame::new(foot_a, Mat3::from_columns(&[x, y, e1]));
        let wheel = Frame::new(foot_b, Mat3::from_columns(&[-x, e1, y]));
        let local = |n: Option<NodeId>, g: Frame| match n {
            Some(id) => self.nodes[id.0].frame.inverse().compose(&g),
            None => g,
        };
        let gear = WormGear {
            name: name.to_string(),
            node_a: nodes[0],
            node_b: nodes[1],
            frame_a: local(nodes[0], worm),
            frame_b: local(nodes[1], wheel),
            starts,
            teeth,
            worm_radius,
            center_distance: across.norm(),
            pressure_angle: 20f64.to_radians(),
            left_hand: false,
            mesh_stiffness: k,
            damping: 0.0,
            friction: 0.0,
            stiction_velocity: 1e-3,
            washer_radius: 0.0,
        };
        self.worm_gears.push(gear);
        self.worm_gears.len() - 1
    }
}
