//! The model: the immutable description of a multibody system.
//!
//! A [`Model`] holds what a user writes in a model file (nodes, bodies, beam elements, joints, loads, springs,
//! sensors) and never changes during a run. Everything that changes lives in
//! [`crate::state::State`]; everything derived, and all scratch memory, in [`crate::data::Data`].
//! Items refer to each other through typed ids ([`NodeId`], [`JointId`]); joints, loads and
//! sensors attach to frames fixed on nodes, never to degree-of-freedom numbers.
//! [`Parameters`] names every numeric parameter of a model by a path and sets it.
//!
//! Units are SI throughout (m, kg, s, N, rad) unless a model chooses consistent others.

pub mod contact;
pub mod control;
pub mod display;
pub mod error;
pub mod limits;
pub mod parameters;
mod time_function;
mod validate;
pub mod worm_gear;

pub use error::{ModelError, SettingsError};
pub use parameters::{ParamId, ParamKind, ParamRole, Parameters};
pub use time_function::TimeFunction;
pub(crate) use validate::{clip, QUOTED};
pub use worm_gear::WormGear;

use flexmb_lie::{so3, Frame, Group, Mat3, Vec3};

/// Index of a node in [`Model::nodes`].
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
pub struct NodeId(pub usize);

/// Index of a joint in [`Model::joints`].
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
pub struct JointId(pub usize);

/// A node: a frame whose configuration is an unknown on the model's Lie group.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Node {
    pub name: String,
    /// Initial configuration (position in m, rotation body-to-inertial).
    pub frame: Frame,
    /// Initial velocity of the node origin, inertial frame [m/s].
    pub velocity: Vec3,
    /// Initial angular velocity, body frame [rad/s].
    pub angular_velocity: Vec3,
}

/// A rigid body attached to a node (the node is the body's reference frame).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RigidBody {
    pub name: String,
    pub node: NodeId,
    /// Mass m \[kg\], > 0.
    pub mass: f64,
    /// Centre of mass X in the node frame \[m\].
    pub com: Vec3,
    /// Inertia tensor J_c about the centre of mass, node axes [kg m^2], symmetric positive definite.
    pub inertia: Mat3,
}

/// Kinds of kinematic joints. All but `Fixed` and `Spherical` use the joint frame's z axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum JointKind {
    /// All six relative motions blocked (clamp).
    Fixed,
    /// Relative translation blocked, rotation free.
    Spherical,
    /// Rotation about z free (the joint coordinate), all else blocked.
    Revolute,
    /// Translation along z free (the joint coordinate), all else blocked.
    Prismatic,
    /// Rotation about and translation along z free.
    Cylindrical,
    /// Cardan joint: translation blocked, z of frame A stays perpendicular to z of frame B.
    Universal,
    /// Motion in the plane normal to z: translation along z and rotation about x, y blocked.
    Planar,
    /// Ideal gear ratio between two wheels (one row, [`crate::joints::gear`]): frame A is
    /// wheel A's centre and axes on node A (z the wheel axis, x towards wheel B's centre at
    /// t = 0), frame B likewise on node B (x towards wheel A's centre). `teeth_b / teeth_a`
    /// is the ratio; an internal pair (B a ring gear) turns both wheels the same way.
    Gear {
        teeth_a: u32,
        teeth_b: u32,
        internal: bool,
    },
}

impl JointKind {
    pub fn name(self) -> &'static str {
        match self {
            JointKind::Fixed => "fixed",
            JointKind::Spherical => "spherical",
            JointKind::Revolute => "revolute",
            JointKind::Prismatic => "prismatic",
            JointKind::Cylindrical => "cylindrical",
            JointKind::Universal => "universal",
            JointKind::Planar => "planar",
            JointKind::Gear { .. } => "gear",
        }
    }
}

/// A holonomic joint between frame A (on `node_a`, or fixed in space when `None`) and frame B
/// (on `node_b`). The joint frames coincide in the initial configuration, except for a
/// universal joint, whose two z axes are perpendicular.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Joint {
    pub name: String,
    pub kind: JointKind,
    /// `None` is the ground.
    pub node_a: Option<NodeId>,
    pub node_b: Option<NodeId>,
    /// Joint frame A in the frame of node A (in the inertial frame if A is the ground).
    pub frame_a: Frame,
    /// Joint frame B in the frame of node B (in the inertial frame if B is the ground).
    pub frame_b: Frame,
    /// Prescribed joint coordinate (rad for revolute, m for prismatic) as a function of time,
    /// measured from the initial configuration.
    pub drive: Option<TimeFunction>,
}

/// Frame in which an applied load is given.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum LoadFrame {
    /// Fixed direction in space (dead load).
    Inertial,
    /// Direction fixed in the node frame (follower load).
    Body,
}

/// A force and torque applied at a node, scaled by a time function, or by an input of the
/// model ([`Input`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Load {
    pub name: String,
    pub node: NodeId,
    /// Force at the node origin \[N\] (per unit of the input for an input's load).
    pub force: Vec3,
    /// Torque [N m] (likewise).
    pub torque: Vec3,
    pub frame: LoadFrame,
    /// The scale `f(t)`; for an input's load, the input's values in a run.
    pub function: TimeFunction,
    /// The index in [`Model::inputs`] of the input that scales this load in place of
    /// `function` when a step is given input values ([`crate::elements::Context::inputs`]).
    #[serde(default)]
    pub input: Option<usize>,
}

/// An input of the model, `u_k`: one entry of the input vector `u_n` of each step (an
/// actuator force or torque, `[[input]]`), which the step residual reads in place of a time
/// function (`R(x; s_n, u_{n+1}, p)`, [`crate::solve::step::StepFunction::input_jacobian`]).
/// In a run, `u(t)` is the function of its load.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Input {
    pub name: String,
    /// The index in [`Model::loads`] of the load it scales.
    pub load: usize,
}

/// A linear spring-damper between two points, acting along the line joining them.
/// `f = k (l - l0) + c l'` (tension positive).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SpringDamper {
    pub name: String,
    pub node_a: Option<NodeId>,
    pub node_b: Option<NodeId>,
    /// Attachment point on A, in the frame of node A (inertial if A is the ground) \[m\].
    pub point_a: Vec3,
    /// Attachment point on B, in the frame of node B (inertial if B is the ground) \[m\].
    pub point_b: Vec3,
    /// Stiffness k [N/m], >= 0.
    pub stiffness: f64,
    /// Damping c [N s/m], >= 0.
    pub damping: f64,
    /// Rest length l0 \[m\], >= 0.
    pub rest_length: f64,
    /// A Maxwell branch in parallel (viscoelastic relaxation), or none.
    #[serde(default)]
    pub relaxation: Option<Relaxation>,
}

/// A Maxwell branch: a spring `k_m` in series with a damper `c_m`, between the same points
/// as the spring-damper it belongs to. Its internal variable is the damper's elongation `z`
/// (one element state): branch force `k_m (l - l0 - z)`, `c_m zdot = k_m (l - l0 - z)`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Relaxation {
    /// Branch stiffness k_m [N/m], > 0.
    pub stiffness: f64,
    /// Branch damping c_m [N s/m], > 0 (relaxation time `c_m / k_m`).
    pub damping: f64,
}

/// A force-elongation curve `F(e)` \[N\] of a nonlinear spring, `e = l - l0` the elongation
/// \[m\] (tension positive). See [`crate::elements::spring`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum ForceCurve {
    /// Piecewise linear through the points `(e_i, F_i)` (at least two, `e_i` strictly
    /// increasing), continued beyond the first and the last point with the slopes of the end
    /// segments. At a point `e_i` the slope is that of the segment to its right.
    Table(Vec<(f64, f64)>),
    /// `F = a_1 e + a_2 e^2 + ...`: the coefficients `[a_1, a_2, ...]` (no constant term: that
    /// is the preload).
    Polynomial(Vec<f64>),
}

/// On which side of its free length a spring acts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum SpringSide {
    /// Always (an ordinary spring).
    #[default]
    Both,
    /// Only while compressed (`e < 0`) and pushing (`T < 0`): a bump stop, engaged when the
    /// points come closer than the free length.
    Compression,
    /// Only while extended (`e >= 0`) and pulling (`T >= 0`): a rebound stop, a strap.
    Extension,
}

/// A nonlinear force law, of a spring-damper ([`SpringLaw`]) or of a rotational spring
/// ([`RotationalSpring`]): with `e` the elongation (or the rotation angle from the neutral one),
///
/// ```text
/// T = P + k e + F(e) + c edot,
/// ```
///
/// `k`, `c` the element's linear stiffness and damping, `P` the preload (the force at
/// `e = 0`), `F` the curve of the side of `e` (`compression` for `e < 0`, `extension` for
/// `e >= 0`, each falling back to `curve`, none = 0); with `acts` a one-sided spring (a stop)
/// whose force is zero off its side.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ForceLaw {
    /// Preload `P` \[N or N m\], the force at `e = 0` (negative: pushing).
    pub preload: f64,
    /// Curve for both sides (unless a side has its own).
    pub curve: Option<ForceCurve>,
    /// Curve for `e < 0`.
    pub compression: Option<ForceCurve>,
    /// Curve for `e >= 0`.
    pub extension: Option<ForceCurve>,
    pub acts: SpringSide,
}

impl ForceLaw {
    /// Whether the law has a force curve (on either side).
    pub fn has_curve(&self) -> bool {
        self.curve.is_some() || self.compression.is_some() || self.extension.is_some()
    }

    /// The curve that acts at `e`, if any.
    pub fn curve_at(&self, e: f64) -> Option<&ForceCurve> {
        let side = if e < 0.0 {
            &self.compression
        } else {
            &self.extension
        };
        side.as_ref().or(self.curve.as_ref())
    }
}

/// The nonlinear law of the spring-damper `Model::springs[spring]`: tension
/// `T = P + k e + F(e) + c ldot` (plus the Maxwell branch), `e = l - l0`, `k`, `c`, `l0` (free
/// length) those of the spring-damper ([`ForceLaw`]). Kept apart from [`SpringDamper`] so
/// that the linear spring-damper, which users and tests build field by field, keeps its
/// fields.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SpringLaw {
    /// Index of the spring-damper in [`Model::springs`] (at most one law per spring).
    pub spring: usize,
    pub law: ForceLaw,
}

impl SpringLaw {
    /// A law with no curve, no preload, acting on both sides (the linear spring) for
    /// `Model::springs[spring]`.
    pub fn new(spring: usize) -> Self {
        Self {
            spring,
            law: ForceLaw::default(),
        }
    }
}

/// A rotational spring-damper about the axis of a revolute or cylindrical joint, between the
/// joint's two nodes: with `theta` the relative rotation angle about the joint's z axis
/// (frame B's x axis in frame A, measured from the initial configuration, continuous over
/// any number of turns) and `e = theta - theta0`, the spring's torque
/// `T = P + k e + F(e) + c edot` (the law of [`ForceLaw`], `P` its preload) acts on node B
/// as the moment `-T` about the axis and on node A as `+T`. See
/// [`crate::elements::rotational_spring`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RotationalSpring {
    pub name: String,
    /// The revolute or cylindrical joint whose axis and nodes the spring uses.
    pub joint: JointId,
    /// Stiffness k [N m/rad], >= 0.
    pub stiffness: f64,
    /// Damping c [N m s/rad], >= 0.
    pub damping: f64,
    /// Neutral angle theta0 \[rad\], from the initial configuration.
    pub angle: f64,
    /// Nonlinear part of the law, preload and stops (none: linear).
    pub law: ForceLaw,
}

/// A 6-DOF bushing between a frame on node A and a frame on node B (either may be the
/// ground): with `d` the relative configuration of the two frames ([`BushingForm`]: the SE(3)
/// logarithm `log(H_A^-1 H_B)`, or the position and rotation vector of B in A; translation,
/// then rotation; 0 where the frames coincide), the bushing's stress resultants are
/// `sigma = K d + C ddot` in the bushing frame. See [`crate::elements::bushing`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Bushing {
    pub name: String,
    /// `None` is the ground.
    pub node_a: Option<NodeId>,
    pub node_b: Option<NodeId>,
    /// Bushing frame A in the frame of node A (in the inertial frame if A is the ground).
    pub frame_a: Frame,
    /// Bushing frame B in the frame of node B (in the inertial frame if B is the ground).
    pub frame_b: Frame,
    /// Stiffness K (6 x 6, symmetric positive semidefinite): blocks [N/m, N/rad; N m/m,
    /// N m/rad], ordered (translation x, y, z, rotation x, y, z) of the bushing frame.
    pub stiffness: flexmb_lie::Mat6,
    /// Damping C (6 x 6, symmetric positive semidefinite), the same order [N s/m ...].
    pub damping: flexmb_lie::Mat6,
    /// The deformation measure.
    pub form: BushingForm,
}

/// The deformation measure `d` of a [`Bushing`] (both coincide to first order).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum BushingForm {
    /// The SE(3) logarithm of the relative configuration `log(H_A^-1 H_B)`: objective for
    /// large relative rotations, the elastic centre midway between the frames.
    #[default]
    LargeRotation,
    /// The R3 x SO(3) logarithm: the position of frame B in frame A and the rotation vector
    /// of the relative rotation, `(R_A^T (x_B - x_A), log(R_A^T R_B))`: the usual bushing,
    /// the elastic centre at frame B's origin; for small relative rotations.
    SmallRotation,
}

/// A point a rope passes through: fixed on a node (node frame) or on the ground (inertial).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RopePoint {
    pub node: Option<NodeId>,
    /// The point, in the frame of `node` (inertial for the ground) \[m\].
    pub point: Vec3,
}

/// A rope (cable, belt) through `n >= 2` points, the intermediate ones frictionless eyelets
/// or pulleys: one tension along its whole length `L` (the sum of the straight segments),
/// `T = k (L - L0) + c dL/dt` while taut, and no force when slack (`L <= L0`, or a
/// damping force that would push). An element on `n` node slots ([`crate::elements::rope`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Rope {
    pub name: String,
    pub points: Vec<RopePoint>,
    /// Axial stiffness of the whole rope k [N/m], >= 0.
    pub stiffness: f64,
    /// Damping c [N s/m], >= 0.
    pub damping: f64,
    /// Unstretched length L0 \[m\], >= 0.
    pub rest_length: f64,
}

/// One harmonic of a periodic function of the mesh position `s` (one period per tooth
/// pitch): `amplitude cos(n s + phase)` for the `n`-th entry of a list (`n = 1, 2, ...`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Harmonic {
    /// Amplitude (unit of the function).
    pub amplitude: f64,
    /// Phase \[rad\].
    pub phase: f64,
}

/// Involute tooth geometry of a gear pair (ISO 21771 notation: normal module `m_n`, normal
/// pressure angle `alpha_n`, helix angle `beta`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GearGeometry {
    /// Teeth of wheel A, >= 1.
    pub teeth_a: u32,
    /// Teeth of wheel B, >= 1 (of the ring gear for an internal pair).
    pub teeth_b: u32,
    /// Normal module m_n \[m\], > 0.
    pub module: f64,
    /// Normal pressure angle alpha_n \[rad\], in (0, pi/2).
    pub pressure_angle: f64,
    /// Helix angle beta \[rad\], |beta| < pi/2 (0: spur; its sign is the hand of wheel A).
    pub helix_angle: f64,
    /// Wheel B is a ring gear (internal teeth).
    pub internal: bool,
}

impl GearGeometry {
    /// Transverse pressure angle `alpha_t = atan(tan alpha_n / cos beta)` \[rad\].
    pub fn transverse_pressure_angle(&self) -> f64 {
        (self.pressure_angle.tan() / self.helix_angle.cos()).atan()
    }

    /// Base radii `r_b = z m_n cos(alpha_t) / (2 cos beta)` of wheels A and B \[m\].
    pub fn base_radii(&self) -> [f64; 2] {
        let k =
            self.module * self.transverse_pressure_angle().cos() / (2.0 * self.helix_angle.cos());
        [self.teeth_a as f64 * k, self.teeth_b as f64 * k]
    }

    /// Pitch radii `r = z m_n / (2 cos beta)` \[m\].
    pub fn pitch_radii(&self) -> [f64; 2] {
        let k = self.module / (2.0 * self.helix_angle.cos());
        [self.teeth_a as f64 * k, self.teeth_b as f64 * k]
    }

    /// Base helix angle `beta_b`, `tan beta_b = tan beta cos alpha_t` \[rad\] (signed).
    pub fn base_helix_angle(&self) -> f64 {
        (self.helix_angle.tan() * self.transverse_pressure_angle().cos()).atan()
    }

    /// `+1` for an external pair, `-1` for an internal one.
    pub fn sigma(&self) -> f64 {
        if self.internal {
            -1.0
        } else {
            1.0
        }
    }

    /// Transmission ratio `omega_a / omega_b = -sigma z_b / z_a` (negative: opposite senses).
    pub fn ratio(&self) -> f64 {
        -self.sigma() * self.teeth_b as f64 / self.teeth_a as f64
    }
}

/// A gear pair: two wheels meshing through a spring and a damper along the line of action,
/// with a mesh stiffness that varies with the mesh position, backlash, static transmission
/// error and the effect of the centre distance (see [`crate::elements::gear`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GearPair {
    pub name: String,
    /// Node of wheel A (`None`: a wheel fixed to the ground).
    pub node_a: Option<NodeId>,
    /// Node of wheel B.
    pub node_b: Option<NodeId>,
    /// Wheel A's frame on node A: origin at the wheel centre, z along the wheel axis, x
    /// towards wheel B's centre at t = 0 (inertial if A is the ground).
    pub frame_a: Frame,
    /// Wheel B's frame on node B: origin at its centre, z along its axis (parallel to and in
    /// the sense of wheel A's), x towards wheel A's centre at t = 0.
    pub frame_b: Frame,
    pub geometry: GearGeometry,
    /// Mean mesh stiffness k_m along the line of action [N/m], > 0.
    pub mesh_stiffness: f64,
    /// Relative fluctuation of the mesh stiffness: `k(s) = k_m (kappa(s) + sum_n eps_n cos(n s
    /// + phi_n))`, one harmonic per entry (amplitudes eps_n dimensionless, `sum |eps_n|`
    /// below the smallest `kappa`, 1 without a table).
    pub stiffness_variation: Vec<Harmonic>,
    /// Mesh damping c along the line of action [N s/m], >= 0 (acts in contact only).
    pub damping: f64,
    /// The mesh stiffness over one mesh period as a table of `(position, factor)`: position
    /// `s / 2 pi` in `[0, 1)`, strictly increasing, factor > 0; `k(s) = k_m (kappa(s) +
    /// sum_n eps_n cos(n s + phi_n))` with `kappa` interpolated linearly and periodically
    /// (`kappa = 1` for an empty table). E.g. the alternating single and double tooth contact of ISO
    /// 6336-1 (a stiffness `c'` per tooth pair): a factor near 1 / contact ratio where one
    /// pair meshes, near twice that where two do.
    #[serde(default)]
    pub stiffness_table: Vec<(f64, f64)>,
    /// Backlash b: total clearance along the line of action \[m\], >= 0.
    pub backlash: f64,
    /// Static transmission error `e(s) = sum_n e_n cos(n s + phi_n)` along the line of
    /// action \[m\].
    pub transmission_error: Vec<Harmonic>,
    /// Mesh position at t = 0 \[rad\] (one mesh period is 2 pi).
    pub mesh_phase: f64,
    /// Centre distance at t = 0 \[m\] (derived from the frames).
    pub center_distance: f64,
    /// Axial offset `z_a . (C_b - C_a)` at t = 0 \[m\] (derived from the frames).
    pub axial_offset: f64,
    /// With backlash, the dynamic step control locates the impacts of the flanks
    /// ([`crate::elements::impact`]); `false` leaves the step to the nominal size and Newton.
    #[serde(default = "locate_impacts_default")]
    pub locate_impacts: bool,
}

fn locate_impacts_default() -> bool {
    true
}

/// Cross-section properties of a beam, in the section frame (x along the beam axis, y and z
/// the section's principal axes). Strain components are ordered
/// `(epsilon_1, gamma_2, gamma_3, kappa_1, kappa_2, kappa_3)`: axial strain, two shear
/// strains, torsion and two bending curvatures; the stiffness is then
/// `diag(EA, GA_2, GA_3, GJ, EI_2, EI_3)` in the common case.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BeamSection {
    /// Sectional stiffness C (6 x 6, symmetric positive definite) [N, N m^2 blocks].
    pub stiffness: flexmb_lie::Mat6,
    /// Mass per unit length rho A [kg/m], > 0.
    pub mass_per_length: f64,
    /// Sectional rotary inertia per unit length diag(rho J, rho I_2, rho I_3) or full [kg m].
    pub rotary_inertia: Mat3,
    /// Rayleigh damping, mass-proportional coefficient alpha [1/s]: nodal forces
    /// `alpha M v` (this also damps rigid motion, as Rayleigh damping does).
    pub damping_mass: f64,
    /// Rayleigh damping, stiffness-proportional coefficient beta \[s\]: stress resultants
    /// `beta C depsilon/dt` (objective: no force under rigid motion).
    pub damping_stiffness: f64,
}

impl BeamSection {
    /// The common case: diagonal stiffness and rotary inertia.
    pub fn diagonal(stiffness: [f64; 6], mass_per_length: f64, rotary_inertia: [f64; 3]) -> Self {
        Self {
            stiffness: flexmb_lie::Mat6::from_diagonal(&flexmb_lie::Vec6::from_column_slice(
                &stiffness,
            )),
            mass_per_length,
            rotary_inertia: Mat3::from_diagonal(&Vec3::from_column_slice(&rotary_inertia)),
            damping_mass: 0.0,
            damping_stiffness: 0.0,
        }
    }

    /// The same section with Rayleigh damping coefficients `alpha` (mass) and `beta`
    /// (stiffness).
    pub fn with_damping(mut self, alpha: f64, beta: f64) -> Self {
        self.damping_mass = alpha;
        self.damping_stiffness = beta;
        self
    }
}

/// A two-node geometrically exact beam element on SE(3) (see [`crate::elements::beam`]).
///
/// The element's section frames at its ends are the node frames composed with constant
/// rotations `offset_a`, `offset_b` (identity when a node's frame already has x along the
/// element), so nodes shared by members of different directions (an elbow) need no joint.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Beam {
    pub name: String,
    pub nodes: [NodeId; 2],
    pub section: BeamSection,
    /// Section frame at end A relative to node A (rotation).
    pub offset_a: Mat3,
    /// Section frame at end B relative to node B (rotation).
    pub offset_b: Mat3,
    /// Relative motion of the end frames in the reference configuration,
    /// `d_0 = log(H_a0^-1 H_b0)` (translation, rotation).
    pub d0: flexmb_lie::Vec6,
    /// Reference length \[m\] (length of the element's axis, `|translation of d_0|` for a
    /// straight element).
    pub length: f64,
    /// How the inertia is distributed over the nodes.
    pub mass_kind: BeamMass,
}

/// Distribution of a beam element's inertia (see [`crate::elements::beam`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum BeamMass {
    /// Half of the element's mass and rotary inertia on each node, no coupling (the
    /// default: block-diagonal, cheaper, as accurate for this element).
    #[default]
    Lumped,
    /// The mass matrix of the element's own interpolation: exact kinetic energy for rigid
    /// motions and small deformations of the reference shape; couples the two nodes.
    Consistent,
}

impl Beam {
    /// A beam element between `nodes` whose section frames at the ends are the node frames
    /// rotated by `offset_a`, `offset_b`, with reference relative motion `d0`; the length
    /// follows.
    pub fn new(
        name: &str,
        nodes: [NodeId; 2],
        section: BeamSection,
        [offset_a, offset_b]: [Mat3; 2],
        d0: flexmb_lie::Vec6,
        mass_kind: BeamMass,
    ) -> Self {
        Self {
            name: name.to_string(),
            nodes,
            section,
            offset_a,
            offset_b,
            d0,
            // the SE(3) interpolation travels the translation part of d_0 at constant speed
            length: d0.fixed_rows::<3>(0).norm(),
            mass_kind,
        }
    }
}

/// Frame in which a vector sensor reports its components.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum SensorFrame {
    Inertial,
    Body,
}

/// What a sensor measures; each sensor gives one column of `sensors.csv`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum SensorKind {
    /// Position component of a point fixed on a node (point in the node frame) \[m\].
    Position {
        node: NodeId,
        point: Vec3,
        component: usize,
    },
    /// Velocity component of a point fixed on a node, inertial frame [m/s].
    Velocity {
        node: NodeId,
        point: Vec3,
        component: usize,
    },
    /// Acceleration component of a point fixed on a node, inertial frame [m/s^2] (from the
    /// step's own `vdot`).
    Acceleration {
        node: NodeId,
        point: Vec3,
        component: usize,
    },
    /// Angular acceleration component [rad/s^2] (from the step's own `vdot`).
    AngularAcceleration {
        node: NodeId,
        frame: SensorFrame,
        component: usize,
    },
    /// Component of the node's unit quaternion, scalar first (0 = w, 1..3 = x, y, z).
    Quaternion {
        node: NodeId,
        component: usize,
    },
    /// Angular velocity component [rad/s].
    AngularVelocity {
        node: NodeId,
        frame: SensorFrame,
        component: usize,
    },
    /// Revolute/prismatic/cylindrical joint coordinate (unwrapped angle \[rad\] or slide \[m\]).
    JointCoordinate {
        joint: JointId,
    },
    /// Force exerted by the joint on its node B, inertial frame \[N\].
    JointForce {
        joint: JointId,
        component: usize,
    },
    /// Torque exerted by the joint on its node B about the joint point, inertial frame [N m].
    JointTorque {
        joint: JointId,
        component: usize,
    },
    /// Tension of a spring-damper, its Maxwell branch included \[N\] (index in
    /// [`Model::springs`]).
    SpringForce {
        spring: usize,
    },
    /// Tension of a rope \[N\] (index in [`Model::ropes`]).
    RopeForce {
        rope: usize,
    },
    /// A quantity of a contact (index in [`Model::contacts`]; [`CONTACT_QUANTITIES`]).
    Contact {
        contact: usize,
        quantity: usize,
    },
    KineticEnergy,
    PotentialEnergy,
    TotalEnergy,
    /// Largest |Phi| over all constraint equations.
    ConstraintViolation,
    /// Strain component of a beam element (0..6: axial, shear 2, shear 3, torsion,
    /// curvature 2, curvature 3), constant along the element.
    BeamStrain {
        beam: usize,
        component: usize,
    },
    /// Stress resultant of a beam element (0..6: axial force, shear forces 2 and 3 \[N\],
    /// torque, bending moments 2 and 3 [N m]), section frame.
    BeamStress {
        beam: usize,
        component: usize,
    },
    /// Normal mesh force of a gear pair \[N\] (index in [`Model::gears`]): positive on the
    /// drive flank (wheel A driving), negative on the coast flank, zero in the backlash.
    GearForce {
        gear: usize,
    },
    /// Dynamic transmission error of a gear pair along the line of action \[m\] (index in
    /// [`Model::gears`]): `r_ba alpha_a + sigma r_bb alpha_b`.
    GearTransmissionError {
        gear: usize,
    },
    /// Torque `T` of a rotational spring-damper, positive when it resists a positive
    /// rotation (the moment on the joint's node B about the axis is `-T`) [N m] (index in
    /// [`Model::rotational_springs`]).
    RotationalSpringTorque {
        spring: usize,
    },
    /// Component of the stress resultants `sigma = K d + C ddot` of a bushing (0..3: forces
    /// \[N\], 3..6: moments [N m], bushing frame) (index in [`Model::bushings`]).
    BushingForce {
        bushing: usize,
        component: usize,
    },
    /// Output `output` of control block `block` (index in [`Model::control`]'s blocks), in
    /// the signal's own unit.
    Block {
        block: usize,
        output: usize,
    },
}

/// The quantities a contact sensor measures, in the order of
/// [`SensorKind::Contact::quantity`]: the normal force \[N\], the penetration \[m\] (0 when
/// open), the signed gap \[m\], the slip speed [m/s], the magnitude of the friction force
/// \[N\], and whether it sticks (1 when closed and slipping slower than the stiction
/// velocity, else 0).
pub const CONTACT_QUANTITIES: [&str; 6] = [
    "normal_force",
    "penetration",
    "gap",
    "slip_velocity",
    "friction_force",
    "stick",
];

/// A named output channel.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Sensor {
    pub name: String,
    pub kind: SensorKind,
}

/// The immutable description of a multibody system.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Model {
    pub title: String,
    /// Lie group of every node configuration.
    pub group: Group,
    /// Gravitational acceleration, inertial frame [m/s^2].
    pub gravity: Vec3,
    pub nodes: Vec<Node>,
    pub bodies: Vec<RigidBody>,
    pub joints: Vec<Joint>,
    pub loads: Vec<Load>,
    /// The model's inputs, in the order of the input vector `u`.
    #[serde(default)]
    pub inputs: Vec<Input>,
    pub springs: Vec<SpringDamper>,
    #[serde(default)]
    pub ropes: Vec<Rope>,
    /// Unilateral contacts with impact and friction.
    #[serde(default)]
    pub contacts: Vec<contact::Contact>,
    pub beams: Vec<Beam>,
    pub sensors: Vec<Sensor>,
    /// What the bodies and beams look like in the results (no effect on the mechanics).
    #[serde(default)]
    pub display: display::Display,
    /// Gear pairs ([`crate::elements::gear`]).
    #[serde(default)]
    pub gears: Vec<GearPair>,
    /// Nonlinear laws of spring-dampers (at most one per spring; a spring without one is
    /// linear).
    #[serde(default)]
    pub spring_laws: Vec<SpringLaw>,
    /// Rotational spring-dampers about joint axes.
    #[serde(default)]
    pub rotational_springs: Vec<RotationalSpring>,
    /// 6-DOF bushings.
    #[serde(default)]
    pub bushings: Vec<Bushing>,
    /// Worm gear pairs with mesh friction ([`crate::elements::worm_gear`]).
    #[serde(default)]
    pub worm_gears: Vec<WormGear>,
    /// Control blocks coupled to the mechanics ([`crate::elements::control`]).
    #[serde(default)]
    pub control: control::ControlSystem,
}

/// Reference to one item of a model and one of its fields, for error messages.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ItemRef {
    /// Table name in the model file: "node", "body", "beam", "joint", "load", "spring", "sensor".
    pub table: &'static str,
    pub index: usize,
    pub name: String,
    pub field: &'static str,
}

impl Model {
    /// Length scale of the model: the diagonal of the box around its nodes' initial
    /// positions (0 without nodes).
    pub fn extent(&self) -> f64 {
        let (lo, hi) = self.nodes.iter().fold(
            (Vec3::repeat(f64::INFINITY), Vec3::repeat(f64::NEG_INFINITY)),
            |(lo, hi), n| (lo.inf(&n.frame.x), hi.sup(&n.frame.x)),
        );
        if self.nodes.is_empty() {
            0.0
        } else {
            (hi - lo).norm()
        }
    }

    /// An empty model on the given group, without gravity.
    pub fn new(group: Group) -> Self {
        Self {
            title: String::new(),
            group,
            gravity: Vec3::zeros(),
            nodes: Vec::new(),
            bodies: Vec::new(),
            joints: Vec::new(),
            loads: Vec::new(),
            inputs: Vec::new(),
            springs: Vec::new(),
            ropes: Vec::new(),
            contacts: Vec::new(),
            beams: Vec::new(),
            sensors: Vec::new(),
            display: display::Display::default(),
            gears: Vec::new(),
            spring_laws: Vec::new(),
            rotational_springs: Vec::new(),
            bushings: Vec::new(),
            worm_gears: Vec::new(),
            control: control::ControlSystem::default(),
        }
    }

    /// Adds a beam element between two nodes, with the section frames at both ends given as
    /// rotations in the inertial frame at t = 0 (x along the element axis) and the default
    /// (lumped) mass; returns its index.
    pub fn add_beam(
        &mut self,
        name: &str,
        nodes: [NodeId; 2],
        section: BeamSection,
        frames: [Mat3; 2],
    ) -> usize {
        self.add_beam_with_mass(name, nodes, section, frames, BeamMass::default())
    }

    /// [`Model::add_beam`] with a choice of mass matrix.
    pub fn add_beam_with_mass(
        &mut self,
        name: &str,
        nodes: [NodeId; 2],
        section: BeamSection,
        frames: [Mat3; 2],
        mass_kind: BeamMass,
    ) -> usize {
        let (na, nb) = (&self.nodes[nodes[0].0].frame, &self.nodes[nodes[1].0].frame);
        let offset_a = na.r.transpose() * frames[0];
        let offset_b = nb.r.transpose() * frames[1];
        let ha = Frame::new(na.x, frames[0]);
        let hb = Frame::new(nb.x, frames[1]);
        let d0 = flexmb_lie::se3::log(&ha.inverse().compose(&hb));
        self.beams.push(Beam::new(
            name,
            nodes,
            section,
            [offset_a, offset_b],
            d0,
            mass_kind,
        ));
        self.beams.len() - 1
    }

    /// Adds a load distributed along beam elements (per unit length of their reference
    /// axis), lumped to their nodes: each element gives half of `f L` to each of its two
    /// nodes (consistent for a uniform load on two-node elements up to O(L^2) in the
    /// moments). One [`Load`] is added per loaded node, named `<name>@<node>`; returns how
    /// many. In the `Body` frame the per-length force and torque are given in each node's
    /// frame (the section frame of generated beam nodes).
    pub fn add_beam_load(
        &mut self,
        name: &str,
        elements: &[usize],
        force_per_length: Vec3,
        torque_per_length: Vec3,
        frame: LoadFrame,
        function: TimeFunction,
    ) -> usize {
        // Nodes in order of first appearance, with the length they carry.
        let mut share: Vec<(NodeId, f64)> = Vec::new();
        let mut slot: std::collections::HashMap<NodeId, usize> = Default::default();
        for &e in elements {
            let b = &self.beams[e];
            for node in b.nodes {
                let k = *slot.entry(node).or_insert_with(|| {
                    share.push((node, 0.0));
                    share.len() - 1
                });
                share[k].1 += 0.5 * b.length;
            }
        }
        for (node, length) in &share {
            let node_name = self.nodes[node.0].name.clone();
            self.loads.push(Load {
                name: format!("{name}@{node_name}"),
                node: *node,
                force: force_per_length * *length,
                torque: torque_per_length * *length,
                frame,
                function: function.clone(),
                input: None,
            });
        }
        share.len()
    }

    /// Adds `n` beam elements along the straight segment from node `a` to a new node at
    /// `end` (plus `n - 1` intermediate nodes named `<name>.<i>`, and the end node
    /// `<name>.<n>` unless `end_node` is an existing node there). The section's z axis is
    /// `z_axis` projected on the plane normal to the segment. Returns the node ids, `a` first.
    pub fn add_straight_beam(
        &mut self,
        name: &str,
        a: NodeId,
        end: Vec3,
        end_node: Option<NodeId>,
        n: usize,
        z_axis: &Vec3,
        section: &BeamSection,
    ) -> Vec<NodeId> {
        let start = self.nodes[a.0].frame.x;
        let r = section_frame(&(end - start), z_axis);
        let mut ids = vec![a];
        for i in 1..=n {
            let id = match end_node {
                Some(id) if i == n => id,
                _ => {
                    let p = start + (end - start) * (i as f64 / n as f64);
                    self.add_node(&format!("{name}.{i}"), Frame::new(p, r))
                }
            };
            ids.push(id);
        }
        for i in 0..n {
            self.add_beam(
                &format!("{name}[{i}]"),
                [ids[i], ids[i + 1]],
                section.clone(),
                [r, r],
            );
        }
        ids
    }

    /// Adds a node at rest; returns its id.
    pub fn add_node(&mut self, name: &str, frame: Frame) -> NodeId {
        self.nodes.push(Node {
            name: name.to_string(),
            frame,
            velocity: Vec3::zeros(),
            angular_velocity: Vec3::zeros(),
        });
        NodeId(self.nodes.len() - 1)
    }

    /// Adds a rigid body on a node.
    pub fn add_body(&mut self, name: &str, node: NodeId, mass: f64, com: Vec3, inertia: Mat3) {
        self.bodies.push(RigidBody {
            name: name.to_string(),
            node,
            mass,
            com,
            inertia,
        });
    }

    /// Adds a joint whose frame is given in the inertial frame at the initial configuration
    /// (`position`, rotation `orientation`), and returns its id. For a universal joint,
    /// `orientation_b` gives frame B (its z axis is the second cross axis).
    pub fn add_joint(
        &mut self,
        name: &str,
        kind: JointKind,
        node_a: Option<NodeId>,
        node_b: Option<NodeId>,
        position: Vec3,
        orientation: Mat3,
        orientation_b: Option<Mat3>,
    ) -> JointId {
        let global = Frame::new(position, orientation);
        let global_b = Frame::new(position, orientation_b.unwrap_or(orientation));
        let local = |n: Option<NodeId>, g: &Frame| match n {
            Some(id) => self.nodes[id.0].frame.inverse().compose(g),
            None => *g,
        };
        let joint = Joint {
            name: name.to_string(),
            kind,
            node_a,
            node_b,
            frame_a: local(node_a, &global),
            frame_b: local(node_b, &global_b),
            drive: None,
        };
        self.joints.push(joint);
        JointId(self.joints.len() - 1)
    }

    /// The frames of two meshing wheels on their nodes (inertial for the ground): origins at
    /// the centres `center_a`, `center_b` (inertial, t = 0), z along `axis`, x of each
    /// towards the other wheel's centre (projected on the plane normal to the axis). The
    /// centres must not lie on one line along the axis.
    pub fn gear_frames(
        &self,
        [node_a, node_b]: [Option<NodeId>; 2],
        [center_a, center_b]: [Vec3; 2],
        axis: &Vec3,
    ) -> [Frame; 2] {
        let d = center_b - center_a;
        let local = |n: Option<NodeId>, g: Frame| match n {
            Some(id) => self.nodes[id.0].frame.inverse().compose(&g),
            None => g,
        };
        [
            local(
                node_a,
                Frame::new(center_a, frame_from_axis(axis, Some(&d))),
            ),
            local(
                node_b,
                Frame::new(center_b, frame_from_axis(axis, Some(&-d))),
            ),
        ]
    }

    /// Adds an ideal gear constraint ([`JointKind::Gear`]) between the wheels on `nodes`
    /// centred at `centers` (inertial, t = 0) turning about `axis`; returns its id.
    pub fn add_gear_joint(
        &mut self,
        name: &str,
        nodes: [Option<NodeId>; 2],
        centers: [Vec3; 2],
        axis: &Vec3,
        (teeth_a, teeth_b, internal): (u32, u32, bool),
    ) -> JointId {
        let [frame_a, frame_b] = self.gear_frames(nodes, centers, axis);
        self.joints.push(Joint {
            name: name.to_string(),
            kind: JointKind::Gear {
                teeth_a,
                teeth_b,
                internal,
            },
            node_a: nodes[0],
            node_b: nodes[1],
            frame_a,
            frame_b,
            drive: None,
        });
        JointId(self.joints.len() - 1)
    }

    /// Adds a gear pair ([`GearPair`]) between the wheels on `nodes` centred at `centers`
    /// (inertial, t = 0) turning about `axis`, with mesh stiffness `k` [N/m] and no
    /// damping, backlash, fluctuation or transmission error (set those fields after);
    /// returns its index in [`Model::gears`].
    pub fn add_gear_pair(
        &mut self,
        name: &str,
        nodes: [Option<NodeId>; 2],
        centers: [Vec3; 2],
        axis: &Vec3,
        geometry: GearGeometry,
        k: f64,
    ) -> usize {
        let [frame_a, frame_b] = self.gear_frames(nodes, centers, axis);
        let d = centers[1] - centers[0];
        self.gears.push(GearPair {
            name: name.to_string(),
            node_a: nodes[0],
            node_b: nodes[1],
            frame_a,
            frame_b,
            geometry,
            mesh_stiffness: k,
            stiffness_variation: Vec::new(),
            damping: 0.0,
            stiffness_table: Vec::new(),
            backlash: 0.0,
            transmission_error: Vec::new(),
            mesh_phase: 0.0,
            center_distance: d.norm(),
            axial_offset: axis.normalize().dot(&d),
            locate_impacts: true,
        });
        self.gears.len() - 1
    }

    /// Adds a fixed joint from the ground to `node` at the node's initial frame (a clamp)
    /// and returns its id.
    pub fn add_clamp(&mut self, name: &str, node: NodeId) -> JointId {
        let at = self.nodes[node.0].frame;
        self.add_joint(name, JointKind::Fixed, None, Some(node), at.x, at.r, None)
    }

    /// Finds a node by name (the first of that name).
    pub fn node_id(&self, name: &str) -> Option<NodeId> {
        self.nodes.iter().position(|n| n.name == name).map(NodeId)
    }

    /// The nonlinear law of spring `spring` (index in [`Model::springs`]), if it has one.
    pub fn spring_law(&self, spring: usize) -> Option<&SpringLaw> {
        self.spring_laws.iter().find(|l| l.spring == spring)
    }

    /// The nonlinear law of spring `spring`, to change it.
    pub fn spring_law_mut(&mut self, spring: usize) -> Option<&mut SpringLaw> {
        self.spring_laws.iter_mut().find(|l| l.spring == spring)
    }

    /// Finds a joint by name (the first of that name).
    pub fn joint_id(&self, name: &str) -> Option<JointId> {
        self.joints.iter().position(|j| j.name == name).map(JointId)
    }
}

/// Rotation matrix whose z axis is `axis` (normalized), with x chosen perpendicular to it
/// (`reference` projected, or a global axis when `reference` is `None` or parallel).
pub fn frame_from_axis(axis: &Vec3, reference: Option<&Vec3>) -> Mat3 {
    let z = axis.normalize();
    let pick = |r: &Vec3| {
        let x = r - z * z.dot(r);
        (x.norm() > 1e-6).then(|| x.normalize())
    };
    let x = reference
        .and_then(pick)
        .or_else(|| pick(&Vec3::x()))
        .or_else(|| pick(&Vec3::y()))
        .expect("x or y is not parallel to z");
    let y = z.cross(&x);
    Mat3::from_columns(&[x, y, z])
}

/// Section frame of a beam: x along `axis`, z along `z_axis` projected on the plane normal to
/// x, y = z cross x. `z_axis` must not be parallel to `axis`.
pub fn section_frame(axis: &Vec3, z_axis: &Vec3) -> Mat3 {
    let x = axis.normalize();
    let z = (z_axis - x * x.dot(z_axis)).normalize();
    Mat3::from_columns(&[x, z.cross(&x), z])
}

/// Inertia of a homogeneous box of mass `m` and side lengths `a`, about its centre, box axes.
pub fn box_inertia(m: f64, a: &Vec3) -> Mat3 {
    Mat3::from_diagonal(&Vec3::new(
        m * (a.y * a.y + a.z * a.z) / 12.0,
        m * (a.x * a.x + a.z * a.z) / 12.0,
        m * (a.x * a.x + a.y * a.y) / 12.0,
    ))
}

/// Rotation from a rotation vector (axis times angle \[rad\]).
pub fn rotation_from_vector(v: &Vec3) -> Mat3 {
    so3::exp(v)
}
