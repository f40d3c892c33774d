//! Parameters by path: every numeric model parameter has one dense id ([`ParamId`]) and one
//! path, built once from a [`Model`] by [`Parameters::new`].
//!
//! A path is what a user writes with `--set` on the model file for the same quantity
//! (`body.top.mass`, `model.gravity.2`; see docs/model-format.md, "Overrides"), where the
//! file holds the quantity the model stores. Where the model stores it in other terms, the
//! path is named after the model's quantity and the table says so.
//!
//! | item | path | quantity \[unit\] | file `--set` |
//! |---|---|---|---|
//! | model | `model.gravity.<k>` | gravity `g_k`, inertial [m/s^2] | same |
//! | node | `node.<n>.velocity.<k>` | initial velocity of the origin, inertial [m/s] | same for a `[[node]]` |
//! | node | `node.<n>.angular_velocity_body.<k>` | initial angular velocity, node frame [rad/s] | same for a `[[node]]` (the model stores the node-frame value) |
//! | body | `body.<b>.mass` | `m` \[kg\] | same |
//! | body | `body.<b>.com.<k>` | centre of mass, node frame \[m\] | same |
//! | body | `body.<b>.inertia.<k>` | `J_c`, Voigt order: 0 `Ixx`, 1 `Iyy`, 2 `Izz`, 3 `Iyz`, 4 `Ixz`, 5 `Ixy` [kg m^2]; a product sets both symmetric entries | 0 to 2 as `inertia = [Ixx, Iyy, Izz]` |
//! | beam | `beam.<r>.section.{EA, GA2, GA3, GJ, EI2, EI3}` | diagonal of the sectional stiffness `C` | same with the sectional-property form |
//! | beam | `beam.<r>.section.stiffness.<i>.<j>`, `i < j` | coupling `C_ij = C_ji` | the matrix form (sets one entry there) |
//! | beam | `beam.<r>.section.rhoA` | mass per length [kg/m] | same with the sectional-property form |
//! | beam | `beam.<r>.section.{rhoJ, rhoI2, rhoI3}` | diagonal of the rotary inertia per length [kg m] | same with the sectional-property form |
//! | beam | `beam.<r>.section.rotary_inertia.<i>.<j>`, `i < j` | coupling `J_ij = J_ji` | the matrix form |
//! | beam | `beam.<r>.damping.{mass, stiffness}` | Rayleigh `alpha` \[1/s\], `beta` \[s\] | same |
//! | beam element | `beam.<r>.element.<k>.` then any of the beam's paths after `beam.<r>.` | the same quantity of element `k` (from 0) alone | `element.<k>` of the `[[beam]]` |
//! | joint | `joint.<j>.position.<k>` | joint point at t = 0, inertial \[m\]; sets both joint frames' points | same |
//! | joint | `joint.<j>.drive.<a>` | drive amplitude `a` ([`super::TimeFunction::amplitude_keys`]) | same |
//! | load | `load.<l>.force.<k>`, `load.<l>.torque.<k>` | force \[N\], torque [N m], in the load's frame | same |
//! | load | `load.<l>.function.<a>` | amplitude `a` of the load's time function | same |
//! | input | `input.<i>.force.<k>`, `input.<i>.torque.<k>`, `input.<i>.function.<a>` | per unit of the input, and the amplitudes of its values in a run ([`super::Input`]) | same |
//! | spring | `spring.<s>.stiffness`, `.damping`, `.rest_length` | `k` [N/m], `c` [N s/m], `l0` \[m\] | same |
//! | spring | `spring.<s>.point_a.<k>`, `spring.<s>.point_b.<k>` | attachment point at t = 0, inertial \[m\] | same |
//! | spring | `spring.<s>.relaxation_stiffness`, `.relaxation_damping` | Maxwell branch `k_m` [N/m], `c_m` [N s/m] (springs that have one) | same |
//! | spring | `spring.<s>.preload` | preload `P` \[N\] (springs with a nonlinear law) | same |
//! | spring | `spring.<s>.polynomial.<j>`, `spring.<s>.force_table.<i>` | coefficient `a_{j+1}` of a polynomial curve, force `F_i` of point `i` of a table curve \[N\] | same (the table's elongations are not parameters) |
//! | spring | `spring.<s>.{compression, extension}.{polynomial.<j>, force_table.<i>}` | the same for a side's own curve | same |
//! | rotational spring | `rotational_spring.<s>.stiffness`, `.damping`, `.angle` | `k` [N m/rad], `c` [N m s/rad], `theta0` \[rad\] | same |
//! | rotational spring | `rotational_spring.<s>.preload`, `.polynomial.<j>`, `.force_table.<i>`, `.{compression, extension}.{...}` | its law, as for a spring [N m] | same |
//! | bushing | `bushing.<b>.stiffness.<i>.<j>`, `bushing.<b>.damping.<i>.<j>`, `i <= j` | entry `K_ij = K_ji`, `C_ij = C_ji` (order: translation x, y, z, rotation x, y, z) | the matrix form (sets one entry there) |
//! | rope | `rope.<r>.stiffness`, `.damping`, `.rest_length` | `k` [N/m], `c` [N s/m], `L0` \[m\] | same |
//! | rope | `rope.<r>.points.<i>.point.<k>` | point `i` at t = 0, inertial \[m\] | same |
//! | gear | `gear.<g>.mesh_stiffness`, `.damping`, `.backlash` | `k_m` [N/m], `c` [N s/m], `b` \[m\] | same |
//! | gear | `gear.<g>.stiffness_variation.<n>` | relative amplitude `eps_n` of harmonic `n` (0-based) of the mesh stiffness | the first number of entry `n` |
//! | gear | `gear.<g>.transmission_error.<n>` | amplitude `e_n` of harmonic `n` (0-based) of the static transmission error \[m\] | the first number of entry `n` |
//! | worm gear | `worm_gear.<g>.mesh_stiffness`, `.damping`, `.friction`, `.washer_radius` | `k` [N/m], `c` [N s/m], `mu`, `r_w` \[m\] | same |
//!
//! Components `<k>` are 0, 1, 2 (x, y, z); matrix indices follow the strain order
//! `(axial, shear 2, shear 3, torsion, bending 2, bending 3)` for `C` and `(x, y, z)` for `J`.
//! An amplitude of a function nested in a time function has the path of its field:
//! `load.road.function.function.height` (the bump of a `delay`),
//! `joint.hub.drive.functions.1.value` (a term of a `sum`), `load.l.function.factor` (of a
//! `scaled`). Time-like fields of time functions (`t0`, `frequency`, `phase`, `delay`, ...),
//! node positions and orientations, joint axes, and the geometry of beams are not parameters.
//!
//! **Names.** An item is named by its name when that name is non-empty, not all digits and
//! unique among the items of its kind; otherwise by its 0-based index in the model's list
//! (`body.3.mass`), which for items read from a file in file order is also what `--set`
//! accepts. Beam elements named `<r>[<i>]` (how a file-level `[[beam]]` `r`, or
//! [`Model::add_straight_beam`], names its elements) form the beam `r`, whose parameters
//! drive all of its elements while they all have the same section; each of them also has
//! its own, `beam.<r>.element.<k>. ...` with `k` its position among them from 0, whatever
//! the sections of the others (one design variable per element). Elements with other names
//! are beams of their own, named by the element's name, or by its index in
//! [`Model::beams`] under the rule above. Distributed beam loads are the nodal loads the
//! model holds (`load.snow@roof.3`).
//!
//! **Roles.** Node velocities enter only the initial state ([`ParamRole::InitialState`]);
//! every other parameter enters the residual of the equations of motion or the constraints
//! ([`ParamRole::Residual`]).

use super::contact::Contact;
use super::{BeamSection, JointId};
use super::{GearPair, Joint, Load, Model, Node, NodeId, RigidBody, Rope, SpringDamper, WormGear};
use flexmb_lie::Vec3;
use std::collections::HashMap;

/// Dense index of a parameter in [`Parameters`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ParamId(pub u32);

/// Where a parameter enters the equations.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamRole {
    /// The residual of the equations of motion or of the constraints.
    Residual,
    /// Only the initial state (initial velocities).
    InitialState,
}

/// Symmetric 3 x 3 components in Voigt order.
pub const VOIGT: [(usize, usize); 6] = [(0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1)];
/// File keys of the diagonal of the sectional stiffness.
const STIFFNESS_KEYS: [&str; 6] = ["EA", "GA2", "GA3", "GJ", "EI2", "EI3"];
/// File keys of the diagonal of the sectional rotary inertia.
const ROTARY_KEYS: [&str; 3] = ["rhoJ", "rhoI2", "rhoI3"];

/// A parameter of a node (initial state only).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NodeParam {
    /// Component of the initial velocity, inertial [m/s].
    Velocity(usize),
    /// Component of the initial angular velocity, node frame [rad/s].
    AngularVelocity(usize),
}

/// A parameter of a rigid body.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BodyParam {
    /// Mass \[kg\].
    Mass,
    /// Component of the centre of mass, node frame \[m\].
    Com(usize),
    /// Component of the inertia about the centre of mass in Voigt order ([`VOIGT`]) [kg m^2].
    Inertia(usize),
}

/// A parameter of a beam section (all elements of a beam share it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SectionParam {
    /// Sectional stiffness entry `(i, j)`, `i <= j` (both symmetric entries).
    Stiffness(usize, usize),
    /// Mass per length [kg/m].
    MassPerLength,
    /// Rotary inertia per length, entry `(i, j)`, `i <= j` [kg m].
    RotaryInertia(usize, usize),
    /// Rayleigh mass-proportional coefficient `alpha` \[1/s\].
    DampingMass,
    /// Rayleigh stiffness-proportional coefficient `beta` \[s\].
    DampingStiffness,
}

/// A parameter of a joint.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JointParam {
    /// Component of the joint point at t = 0, inertial \[m\].
    Position(usize),
    /// Amplitude of the drive ([`super::TimeFunction::amplitude_keys`]).
    Drive(usize),
}

/// A parameter of an applied load.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LoadParam {
    /// Force component \[N\], in the load's frame.
    Force(usize),
    /// Torque component [N m], in the load's frame.
    Torque(usize),
    /// Amplitude of the time function ([`super::TimeFunction::amplitude_keys`]).
    Amplitude(usize),
}

/// A parameter of a spring-damper.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpringParam {
    /// Stiffness [N/m].
    Stiffness,
    /// Damping [N s/m].
    Damping,
    /// Rest length \[m\].
    RestLength,
    /// Component of attachment point A at t = 0, inertial \[m\].
    PointA(usize),
    /// Component of attachment point B at t = 0, inertial \[m\].
    PointB(usize),
    /// Stiffness of the Maxwell branch [N/m].
    RelaxationStiffness,
    /// Damping of the Maxwell branch [N s/m].
    RelaxationDamping,
}

/// A parameter of a contact ([`super::contact::Contact`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ContactParam {
    /// Contact stiffness K [N/m^n].
    Stiffness,
    /// Exponent n.
    Exponent,
    /// Coefficient of restitution e.
    Restitution,
    /// Coulomb friction coefficient mu.
    Friction,
    /// Viscous friction coefficient c_v [N s/m].
    ViscousFriction,
}

impl ContactParam {
    /// The value.
    pub fn get(self, c: &Contact) -> f64 {
        let friction = |f: fn(&super::contact::Friction) -> f64| c.friction.as_ref().map_or(0.0, f);
        match self {
            ContactParam::Stiffness => c.law.stiffness,
            ContactParam::Exponent => c.law.exponent,
            ContactParam::Restitution => c.law.restitution,
            ContactParam::Friction => friction(|f| f.coefficient),
            ContactParam::ViscousFriction => friction(|f| f.viscous),
        }
    }

    /// Sets the value.
    pub fn set(self, c: &mut Contact, value: f64) {
        match self {
            ContactParam::Stiffness => c.law.stiffness = value,
            ContactParam::Exponent => c.law.exponent = value,
            ContactParam::Restitution => c.law.restitution = value,
            ContactParam::Friction => {
                if let Some(f) = &mut c.friction {
                    f.coefficient = value;
                }
            }
            ContactParam::ViscousFriction => {
                if let Some(f) = &mut c.friction {
                    f.viscous = value;
                }
            }
        }
    }
}

/// A parameter of a control block ([`super::control::Block::params`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ControlParam {
    /// Index in [`super::control::ControlSystem::blocks`].
    pub block: usize,
    /// Index in the block's parameters.
    pub index: usize,
}

/// What the block diagram's equations are differentiated with respect to: a block's own
/// parameter, a parameter of a joint its measurements or actuators act along, or a section
/// parameter of a beam element (index in `Model::beams`) whose section forces it measures, or
/// of a contact whose force it measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ControlWrt {
    Block(ControlParam),
    Joint(JointId, JointParam),
    Section(usize, SectionParam),
    /// A law parameter of a contact (index in `Model::contacts`) whose force it measures.
    Contact(usize, ContactParam),
}

/// Which curve of a nonlinear force law ([`super::ForceLaw`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CurveKey {
    /// `curve`, both sides.
    Both,
    /// `compression`.
    Compression,
    /// `extension`.
    Extension,
}

impl CurveKey {
    /// The path segment (empty for `Both`: the curve's keys sit on the spring itself).
    pub fn key(self) -> &'static str {
        match self {
            CurveKey::Both => "",
            CurveKey::Compression => "compression.",
            CurveKey::Extension => "extension.",
        }
    }

    /// The curve of `law` this key names.
    pub fn curve(self, law: &super::ForceLaw) -> Option<&super::ForceCurve> {
        match self {
            CurveKey::Both => law.curve.as_ref(),
            CurveKey::Compression => law.compression.as_ref(),
            CurveKey::Extension => law.extension.as_ref(),
        }
    }

    fn curve_mut(self, law: &mut super::ForceLaw) -> Option<&mut super::ForceCurve> {
        match self {
            CurveKey::Both => law.curve.as_mut(),
            CurveKey::Compression => law.compression.as_mut(),
            CurveKey::Extension => law.extension.as_mut(),
        }
    }
}

/// A parameter of a nonlinear force law ([`super::ForceLaw`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpringLawParam {
    /// Preload \[N\].
    Preload,
    /// Coefficient `a_{j+1}` (of `e^{j+1}`) of a polynomial curve [N/m^(j+1)].
    Polynomial(CurveKey, usize),
    /// Force `F_i` of point `i` of a table curve \[N\].
    TableForce(CurveKey, usize),
}

impl SpringLawParam {
    /// Every parameter of `law`, in registry order, with the path after the spring's name.
    pub fn all(law: &super::ForceLaw) -> Vec<(String, SpringLawParam)> {
        let mut out = vec![("preload".to_string(), SpringLawParam::Preload)];
        for key in [CurveKey::Both, CurveKey::Compression, CurveKey::Extension] {
            match key.curve(law) {
                Some(super::ForceCurve::Polynomial(a)) => out.extend((0..a.len()).map(|j| {
                    let path = format!("{}polynomial.{j}", key.key());
                    (path, SpringLawParam::Polynomial(key, j))
                })),
                Some(super::ForceCurve::Table(points)) => out.extend((0..points.len()).map(|i| {
                    let path = format!("{}force_table.{i}", key.key());
                    (path, SpringLawParam::TableForce(key, i))
                })),
                None => {}
            }
        }
        out
    }

    pub fn get(self, law: &super::ForceLaw) -> f64 {
        match self {
            SpringLawParam::Preload => law.preload,
            SpringLawParam::Polynomial(key, j) => match key.curve(law) {
                Some(super::ForceCurve::Polynomial(a)) => a[j],
                _ => 0.0,
            },
            SpringLawParam::TableForce(key, i) => match key.curve(law) {
                Some(super::ForceCurve::Table(p)) => p[i].1,
                _ => 0.0,
            },
        }
    }

    pub fn set(self, law: &mut super::ForceLaw, value: f64) {
        match self {
            SpringLawParam::Preload => law.preload = value,
            SpringLawParam::Polynomial(key, j) => {
                if let Some(super::ForceCurve::Polynomial(a)) = key.curve_mut(law) {
                    a[j] = value;
                }
            }
            SpringLawParam::TableForce(key, i) => {
                if let Some(super::ForceCurve::Table(p)) = key.curve_mut(law) {
                    p[i].1 = value;
                }
            }
        }
    }
}

/// A parameter of a rotational spring-damper.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RotationalSpringParam {
    /// Stiffness [N m/rad].
    Stiffness,
    /// Damping [N m s/rad].
    Damping,
    /// Neutral angle \[rad\].
    Angle,
    /// A parameter of its law (preload [N m], curves).
    Law(SpringLawParam),
}

impl RotationalSpringParam {
    pub fn get(self, s: &super::RotationalSpring) -> f64 {
        match self {
            RotationalSpringParam::Stiffness => s.stiffness,
            RotationalSpringParam::Damping => s.damping,
            RotationalSpringParam::Angle => s.angle,
            RotationalSpringParam::Law(p) => p.get(&s.law),
        }
    }

    pub fn set(self, s: &mut super::RotationalSpring, value: f64) {
        match self {
            RotationalSpringParam::Stiffness => s.stiffness = value,
            RotationalSpringParam::Damping => s.damping = value,
            RotationalSpringParam::Angle => s.angle = value,
            RotationalSpringParam::Law(p) => p.set(&mut s.law, value),
        }
    }
}

/// A parameter of a bushing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BushingParam {
    /// Stiffness entry `(i, j)`, `i <= j` (both symmetric entries).
    Stiffness(usize, usize),
    /// Damping entry `(i, j)`, `i <= j` (both symmetric entries).
    Damping(usize, usize),
}

impl BushingParam {
    /// Every parameter of a bushing, in registry order, with its path after the name.
    pub fn all() -> Vec<(String, BushingParam)> {
        let mut out = Vec::new();
        for (key, make) in [
            (
                "stiffness",
                BushingParam::Stiffness as fn(usize, usize) -> BushingParam,
            ),
            ("damping", BushingParam::Damping),
        ] {
            for i in 0..6 {
                for j in i..6 {
                    out.push((format!("{key}.{i}.{j}"), make(i, j)));
                }
            }
        }
        out
    }

    pub fn get(self, b: &super::Bushing) -> f64 {
        match self {
            BushingParam::Stiffness(i, j) => b.stiffness[(i, j)],
            BushingParam::Damping(i, j) => b.damping[(i, j)],
        }
    }

    pub fn set(self, b: &mut super::Bushing, value: f64) {
        let (m, i, j) = match self {
            BushingParam::Stiffness(i, j) => (&mut b.stiffness, i, j),
            BushingParam::Damping(i, j) => (&mut b.damping, i, j),
        };
        m[(i, j)] = value;
        m[(j, i)] = value;
    }
}

/// Parameters of a rope.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RopeParam {
    /// Stiffness [N/m].
    Stiffness,
    /// Damping [N s/m].
    Damping,
    /// Unstretched length \[m\].
    RestLength,
    /// Component `k` of point `i` at t = 0, inertial \[m\].
    Point(usize, usize),
}

/// A parameter of a gear pair.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GearParam {
    /// Mean mesh stiffness `k_m` [N/m].
    MeshStiffness,
    /// Mesh damping `c` [N s/m].
    Damping,
    /// Backlash `b` \[m\].
    Backlash,
    /// Relative amplitude of harmonic `n` (0-based) of the mesh stiffness.
    StiffnessVariation(usize),
    /// Amplitude of harmonic `n` (0-based) of the static transmission error \[m\].
    TransmissionError(usize),
}

impl GearParam {
    /// The value.
    pub fn get(self, gear: &GearPair) -> f64 {
        match self {
            GearParam::MeshStiffness => gear.mesh_stiffness,
            GearParam::Damping => gear.damping,
            GearParam::Backlash => gear.backlash,
            GearParam::StiffnessVariation(n) => gear.stiffness_variation[n].amplitude,
            GearParam::TransmissionError(n) => gear.transmission_error[n].amplitude,
        }
    }

    /// Sets the value.
    pub fn set(self, gear: &mut GearPair, value: f64) {
        match self {
            GearParam::MeshStiffness => gear.mesh_stiffness = value,
            GearParam::Damping => gear.damping = value,
            GearParam::Backlash => gear.backlash = value,
            GearParam::StiffnessVariation(n) => gear.stiffness_variation[n].amplitude = value,
            GearParam::TransmissionError(n) => gear.transmission_error[n].amplitude = value,
        }
    }
}

/// A parameter of a worm gear pair ([`WormGear`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WormGearParam {
    /// Mesh stiffness `k` [N/m].
    MeshStiffness,
    /// Mesh damping `c` [N s/m].
    Damping,
    /// Friction coefficient `mu` of the flanks and the washer.
    Friction,
    /// Friction radius `r_w` of the thrust washer \[m\].
    WasherRadius,
}

impl WormGearParam {
    /// Every parameter with its key.
    pub const ALL: [(&'static str, WormGearParam); 4] = [
        ("mesh_stiffness", WormGearParam::MeshStiffness),
        ("damping", WormGearParam::Damping),
        ("friction", WormGearParam::Friction),
        ("washer_radius", WormGearParam::WasherRadius),
    ];

    /// The value.
    pub fn get(self, g: &WormGear) -> f64 {
        match self {
            WormGearParam::MeshStiffness => g.mesh_stiffness,
            WormGearParam::Damping => g.damping,
            WormGearParam::Friction => g.friction,
            WormGearParam::WasherRadius => g.washer_radius,
        }
    }

    /// Sets the value.
    pub fn set(self, g: &mut WormGear, value: f64) {
        match self {
            WormGearParam::MeshStiffness => g.mesh_stiffness = value,
            WormGearParam::Damping => g.damping = value,
            WormGearParam::Friction => g.friction = value,
            WormGearParam::WasherRadius => g.washer_radius = value,
        }
    }
}

/// What a parameter is: its item and which of the item's quantities.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamKind {
    /// Component of gravity [m/s^2].
    Gravity(usize),
    Node(NodeId, NodeParam),
    /// Index in [`Model::bodies`].
    Body(usize, BodyParam),
    /// A beam of [`Parameters::beam_elements`].
    Beam(usize, SectionParam),
    Joint(JointId, JointParam),
    /// Index in [`Model::loads`].
    Load(usize, LoadParam),
    /// Index in [`Model::springs`].
    Spring(usize, SpringParam),
    /// Index in [`Model::ropes`].
    Rope(usize, RopeParam),
    /// Index in [`Model::contacts`].
    Contact(usize, ContactParam),
    /// Index in [`Model::gears`].
    Gear(usize, GearParam),
    /// The nonlinear law of a spring-damper (index in [`Model::springs`]).
    SpringLaw(usize, SpringLawParam),
    /// Index in [`Model::rotational_springs`].
    RotationalSpring(usize, RotationalSpringParam),
    /// Index in [`Model::bushings`].
    Bushing(usize, BushingParam),
    /// Index in [`Model::worm_gears`].
    WormGear(usize, WormGearParam),
    Control(ControlParam),
}

/// A path that names no parameter.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown parameter '{path}'{}", near_list(.near))]
pub struct UnknownParameter {
    pub path: String,
    /// The closest paths of the registry (by edit distance, else by common prefix).
    pub near: Vec<String>,
}

fn near_list(near: &[String]) -> String {
    if near.is_empty() {
        " (the model has no parameters)".into()
    } else {
        let quoted: Vec<String> = near.iter().map(|p| format!("'{p}'")).collect();
        format!(" (near: {})", quoted.join(", "))
    }
}

/// The registry of a model's parameters (see the module documentation).
#[derive(Clone, Debug)]
pub struct Parameters {
    /// Path and kind of each parameter, by id.
    entries: Vec<(String, ParamKind)>,
    by_path: HashMap<String, ParamId>,
    /// Elements of each beam (indices in [`Model::beams`]).
    beams: Vec<Vec<usize>>,
}

impl Parameters {
    /// The registry of `model`'s parameters, in the order gravity, nodes, bodies, beams,
    /// joints, loads, springs.
    pub fn new(model: &Model) -> Self {
        let mut reg = Self {
            entries: Vec::new(),
            by_path: HashMap::new(),
            beams: Vec::new(),
        };
        for k in 0..3 {
            reg.push(format!("model.gravity.{k}"), ParamKind::Gravity(k));
        }
        let names = segments(model.nodes.iter().map(|n| n.name.as_str()));
        for (i, name) in names.iter().enumerate() {
            let node = NodeId(i);
            for k in 0..3 {
                let p = NodeParam::Velocity(k);
                reg.push(
                    format!("node.{name}.velocity.{k}"),
                    ParamKind::Node(node, p),
                );
            }
            for k in 0..3 {
                let p = NodeParam::AngularVelocity(k);
                let path = format!("node.{name}.angular_velocity_body.{k}");
                reg.push(path, ParamKind::Node(node, p));
            }
        }
        let names = segments(model.bodies.iter().map(|b| b.name.as_str()));
        for (i, name) in names.iter().enumerate() {
            let mut add =
                |key: String, p| reg.push(format!("body.{name}.{key}"), ParamKind::Body(i, p));
            add("mass".into(), BodyParam::Mass);
            for k in 0..3 {
                add(format!("com.{k}"), BodyParam::Com(k));
            }
            for k in 0..6 {
                add(format!("inertia.{k}"), BodyParam::Inertia(k));
            }
        }
        for beam in beam_items(model) {
            if beam.uniform {
                let item = reg.beams.len();
                reg.beams.push(beam.elements.clone());
                for p in SectionParam::all() {
                    let path = format!("beam.{}.{}", beam.name, p.key());
                    reg.push(path, ParamKind::Beam(item, p));
                }
            }
            if beam.meshed {
                for (k, &e) in beam.elements.iter().enumerate() {
                    let item = reg.beams.len();
                    reg.beams.push(vec![e]);
                    for p in SectionParam::all() {
                        let path = format!("beam.{}.element.{k}.{}", beam.name, p.key());
                        reg.push(path, ParamKind::Beam(item, p));
                    }
                }
            }
        }
        let names = segments(model.joints.iter().map(|j| j.name.as_str()));
        for (i, name) in names.iter().enumerate() {
            let joint = JointId(i);
            // a gear joint has no continuous parameter (crate::joints::gear)
            let positions = if matches!(model.joints[i].kind, super::JointKind::Gear { .. }) {
                0
            } else {
                3
            };
            for k in 0..positions {
                let p = JointParam::Position(k);
                reg.push(
                    format!("joint.{name}.position.{k}"),
                    ParamKind::Joint(joint, p),
                );
            }
            if let Some(f) = &model.joints[i].drive {
                for (a, key) in f.amplitude_keys().into_iter().enumerate() {
                    let p = ParamKind::Joint(joint, JointParam::Drive(a));
                    reg.push(format!("joint.{name}.drive.{key}"), p);
                }
            }
        }
        // An input's load is addressed as the input (`input.NAME...`, its function the
        // values of a run).
        let names = segments(model.loads.iter().map(|l| l.name.as_str()));
        let input_names = segments(model.inputs.iter().map(|u| u.name.as_str()));
        for (i, name) in names.iter().enumerate() {
            // (a name that is not a path segment falls back to the index among its own kind)
            let (table, name) = match model.loads[i].input {
                Some(k) => ("input", &input_names[k]),
                None => ("load", name),
            };
            for k in 0..3 {
                let p = ParamKind::Load(i, LoadParam::Force(k));
                reg.push(format!("{table}.{name}.force.{k}"), p);
            }
            for k in 0..3 {
                let p = ParamKind::Load(i, LoadParam::Torque(k));
                reg.push(format!("{table}.{name}.torque.{k}"), p);
            }
            let keys = model.loads[i].function.amplitude_keys();
            for (a, key) in keys.into_iter().enumerate() {
                let p = ParamKind::Load(i, LoadParam::Amplitude(a));
                reg.push(format!("{table}.{name}.function.{key}"), p);
            }
        }
        let names = segments(model.springs.iter().map(|s| s.name.as_str()));
        for (i, name) in names.iter().enumerate() {
            let mut add = |key: String, p| {
                reg.push(format!("spring.{name}.{key}"), ParamKind::Spring(i, p));
            };
            add("stiffness".into(), SpringParam::Stiffness);
            add("damping".into(), SpringParam::Damping);
            add("rest_length".into(), SpringParam::RestLength);
            for k in 0..3 {
                add(format!("point_a.{k}"), SpringParam::PointA(k));
            }
            for k in 0..3 {
                add(format!("point_b.{k}"), SpringParam::PointB(k));
            }
            if model.springs[i].relaxation.is_some() {
                add(
                    "relaxation_stiffness".into(),
                    SpringParam::RelaxationStiffness,
                );
                add("relaxation_damping".into(), SpringParam::RelaxationDamping);
            }
            if let Some(law) = model.spring_law(i) {
                for (key, p) in SpringLawParam::all(&law.law) {
                    reg.push(format!("spring.{name}.{key}"), ParamKind::SpringLaw(i, p));
                }
            }
        }
        let names = segments(model.ropes.iter().map(|r| r.name.as_str()));
        for (i, name) in names.iter().enumerate() {
            let mut add = |key: String, p| {
                reg.push(format!("rope.{name}.{key}"), ParamKind::Rope(i, p));
            };
            add("stiffness".into(), RopeParam::Stiffness);
            add("damping".into(), RopeParam::Damping);
            add("rest_length".into(), RopeParam::RestLength);
            for j in 0..model.ropes[i].points.len() {
                for k in 0..3 {
                    add(format!("points.{j}.point.{k}"), RopeParam::Point(j, k));
                }
            }
        }
        let names = segments(model.contacts.iter().map(|c| c.name.as_str()));
        for (i, name) in names.iter().enumerate() {
            let mut add = |key: &str, p| {
                reg.push(format!("contact.{name}.{key}"), ParamKind::Contact(i, p));
            };
            add("stiffness", ContactParam::Stiffness);
            add("exponent", ContactParam::Exponent);
            add("restitution", ContactParam::Restitution);
            if model.contacts[i].friction.is_some() {
                add("friction.coefficient", ContactParam::Friction);
                add("friction.viscous", ContactParam::ViscousFriction);
            }
        }
        let names = segments(model.gears.iter().map(|g| g.name.as_str()));
        for (i, name) in names.iter().enumerate() {
            let mut add = |key: String, p| {
                reg.push(format!("gear.{name}.{key}"), ParamKind::Gear(i, p));
            };
            add("mesh_stiffness".into(), GearParam::MeshStiffness);
            add("damping".into(), GearParam::Damping);
            add("backlash".into(), GearParam::Backlash);
            for n in 0..model.gears[i].stiffness_variation.len() {
                add(
                    format!("stiffness_variation.{n}"),
                    GearParam::StiffnessVariation(n),
                );
            }
            for n in 0..model.gears[i].transmission_error.len() {
                add(
                    format!("transmission_error.{n}"),
                    GearParam::TransmissionError(n),
                );
            }
        }
        let names = segments(model.rotational_springs.iter().map(|s| s.name.as_str()));
        for (i, name) in names.iter().enumerate() {
            let mut add = |key: &str, p| {
                let kind = ParamKind::RotationalSpring(i, p);
                reg.push(format!("rotational_spring.{name}.{key}"), kind);
            };
            add("stiffness", RotationalSpringParam::Stiffness);
            add("damping", RotationalSpringParam::Damping);
            add("angle", RotationalSpringParam::Angle);
            for (key, p) in SpringLawParam::all(&model.rotational_springs[i].law) {
                add(&key, RotationalSpringParam::Law(p));
            }
        }
        let names = segments(model.bushings.iter().map(|b| b.name.as_str()));
        for (i, name) in names.iter().enumerate() {
            for (key, p) in BushingParam::all() {
                reg.push(format!("bushing.{name}.{key}"), ParamKind::Bushing(i, p));
            }
        }
        let names = segments(model.worm_gears.iter().map(|g| g.name.as_str()));
        for (i, name) in names.iter().enumerate() {
            for (key, p) in WormGearParam::ALL {
                reg.push(format!("worm_gear.{name}.{key}"), ParamKind::WormGear(i, p));
            }
        }
        let blocks = &model.control.blocks;
        let names = segments(blocks.iter().map(|b| b.name.as_str()));
        for (block, name) in names.iter().enumerate() {
            for (index, key) in blocks[block].kind.param_names().iter().enumerate() {
                let p = ControlParam { block, index };
                reg.push(format!("control.{name}.{key}"), ParamKind::Control(p));
            }
        }
        reg
    }

    fn push(&mut self, path: String, kind: ParamKind) {
        let id = ParamId(self.entries.len() as u32);
        let previous = self.by_path.insert(path.clone(), id);
        debug_assert!(previous.is_none(), "two parameters named '{path}'");
        self.entries.push((path, kind));
    }

    /// Number of parameters.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether there is no parameter (never for a model: gravity is always one).
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Every id, in order.
    pub fn ids(&self) -> impl Iterator<Item = ParamId> {
        (0..self.entries.len() as u32).map(ParamId)
    }

    /// The parameter of a path; an unknown path's error names the closest paths.
    pub fn id(&self, path: &str) -> Result<ParamId, UnknownParameter> {
        self.by_path
            .get(path)
            .copied()
            .ok_or_else(|| UnknownParameter {
                path: path.to_string(),
                near: self.near(path),
            })
    }

    /// The path of a parameter.
    pub fn path(&self, id: ParamId) -> &str {
        &self.entries[id.0 as usize].0
    }

    /// What a parameter is.
    pub fn kind(&self, id: ParamId) -> ParamKind {
        self.entries[id.0 as usize].1
    }

    /// Where a parameter enters the equations.
    pub fn role(&self, id: ParamId) -> ParamRole {
        match self.kind(id) {
            ParamKind::Node(..) => ParamRole::InitialState,
            _ => ParamRole::Residual,
        }
    }

    /// The elements (indices in [`Model::beams`]) of beam `item` of [`ParamKind::Beam`].
    pub fn beam_elements(&self, item: usize) -> &[usize] {
        &self.beams[item]
    }

    /// The value of a parameter in `model` (of a beam: that of its first element, which all
    /// share).
    pub fn value(&self, model: &Model, id: ParamId) -> f64 {
        match self.kind(id) {
            ParamKind::Gravity(k) => model.gravity[k],
            ParamKind::Node(n, p) => p.get(&model.nodes[n.0]),
            ParamKind::Body(i, p) => p.get(&model.bodies[i]),
            ParamKind::Beam(item, p) => p.get(&model.beams[self.beams[item][0]].section),
            ParamKind::Joint(j, p) => p.get(&model.joints[j.0], &model.nodes),
            ParamKind::Load(i, p) => p.get(&model.loads[i]),
            ParamKind::Spring(i, p) => p.get(&model.springs[i], &model.nodes),
            ParamKind::Rope(i, p) => p.get(&model.ropes[i], &model.nodes),
            ParamKind::Contact(i, p) => p.get(&model.contacts[i]),
            ParamKind::Gear(i, p) => p.get(&model.gears[i]),
            ParamKind::SpringLaw(i, p) => model.spring_law(i).map_or(0.0, |law| p.get(&law.law)),
            ParamKind::RotationalSpring(i, p) => p.get(&model.rotational_springs[i]),
            ParamKind::Bushing(i, p) => p.get(&model.bushings[i]),
            ParamKind::WormGear(i, p) => p.get(&model.worm_gears[i]),
            ParamKind::Control(p) => model.control.blocks[p.block].value(p.index),
        }
    }

    /// Sets a parameter in `model`, keeping it consistent: both symmetric entries of a
    /// coupling, every element of a beam, both joint frames, points converted to their node's
    /// frame. `model` must be the model the registry was built from (or a copy of it). The
    /// value is not checked: [`Model::validate`] does.
    pub fn set(&self, model: &mut Model, id: ParamId, value: f64) {
        match self.kind(id) {
            ParamKind::Gravity(k) => model.gravity[k] = value,
            ParamKind::Node(n, p) => p.set(&mut model.nodes[n.0], value),
            ParamKind::Body(i, p) => p.set(&mut model.bodies[i], value),
            ParamKind::Beam(item, p) => {
                for &e in &self.beams[item] {
                    p.set(&mut model.beams[e].section, value);
                }
            }
            ParamKind::Joint(j, p) => p.set(&mut model.joints[j.0], &model.nodes, value),
            ParamKind::Load(i, p) => p.set(&mut model.loads[i], value),
            ParamKind::Spring(i, p) => p.set(&mut model.springs[i], &model.nodes, value),
            ParamKind::Rope(i, p) => p.set(&mut model.ropes[i], &model.nodes, value),
            ParamKind::Contact(i, p) => p.set(&mut model.contacts[i], value),
            ParamKind::Gear(i, p) => p.set(&mut model.gears[i], value),
            ParamKind::SpringLaw(i, p) => {
                if let Some(law) = model.spring_law_mut(i) {
                    p.set(&mut law.law, value);
                }
            }
            ParamKind::RotationalSpring(i, p) => p.set(&mut model.rotational_springs[i], value),
            ParamKind::Bushing(i, p) => p.set(&mut model.bushings[i], value),
            ParamKind::WormGear(i, p) => p.set(&mut model.worm_gears[i], value),
            ParamKind::Control(p) => model.control.blocks[p.block].set_param(p.index, value),
        }
    }

    /// Up to 3 paths within a small edit distance of `path`, else up to 5 sharing its
    /// longest prefix.
    fn near(&self, path: &str) -> Vec<String> {
        let bound = (path.len() / 5).clamp(2, 4);
        let mut close: Vec<(usize, &str)> = self
            .entries
            .iter()
            .filter_map(|(p, _)| edit_distance(path, p, bound).map(|d| (d, p.as_str())))
            .collect();
        close.sort();
        if !close.is_empty() {
            return close.iter().take(3).map(|(_, p)| p.to_string()).collect();
        }
        let common = |p: &str| {
            path.bytes()
                .zip(p.bytes())
                .take_while(|(a, b)| a == b)
                .count()
        };
        let best = self
            .entries
            .iter()
            .map(|(p, _)| common(p))
            .max()
            .unwrap_or(0);
        self.entries
            .iter()
            .filter(|(p, _)| common(p) == best)
            .take(5)
            .map(|(p, _)| p.clone())
            .collect()
    }
}

/// Levenshtein distance of `a` and `b` if at most `bound` (by bytes).
fn edit_distance(a: &str, b: &str, bound: usize) -> Option<usize> {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    if a.len().abs_diff(b.len()) > bound {
        return None;
    }
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.iter().enumerate() {
        let mut diag = row[0];
        row[0] = i + 1;
        let mut smallest = row[0];
        for (j, cb) in b.iter().enumerate() {
            let next = (diag + usize::from(ca != cb))
                .min(row[j] + 1)
                .min(row[j + 1] + 1);
            diag = row[j + 1];
            row[j + 1] = next;
            smallest = smallest.min(next);
        }
        if smallest > bound {
            return None;
        }
    }
    (row[b.len()] <= bound).then_some(row[b.len()])
}

/// The path segment of each item: its name if non-empty, not all digits and unique among
/// `names`, else its index.
fn segments<'a>(names: impl Iterator<Item = &'a str> + Clone) -> Vec<String> {
    let mut count: HashMap<&str, usize> = HashMap::new();
    for n in names.clone() {
        *count.entry(n).or_default() += 1;
    }
    names
        .enumerate()
        .map(|(i, n)| {
            if plain_name(n) && count[n] == 1 {
                n.to_string()
            } else {
                i.to_string()
            }
        })
        .collect()
}

fn plain_name(name: &str) -> bool {
    !name.is_empty() && !name.bytes().all(|c| c.is_ascii_digit())
}

/// `r` for an element named `r[i]`, the whole name otherwise.
fn beam_key(name: &str) -> &str {
    let Some(body) = name.strip_suffix(']') else {
        return name;
    };
    match body.rsplit_once('[') {
        Some((prefix, digits))
            if plain_name(prefix)
                && !digits.is_empty()
                && digits.bytes().all(|c| c.is_ascii_digit()) =>
        {
            prefix
        }
        _ => name,
    }
}

/// A beam of the registry ([`beam_items`]).
struct BeamItem {
    /// The path segment after `beam.`.
    name: String,
    /// Its elements (indices in [`Model::beams`]), in order.
    elements: Vec<usize>,
    /// Its elements share one section: the beam's paths drive them all.
    uniform: bool,
    /// Its elements are named `<r>[<i>]`: each also has the paths `beam.<r>.element.<k>. ...`
    /// (`k` its position among them, from 0), whatever the sections of the others.
    meshed: bool,
}

/// The beams of the registry, in order of first element.
fn beam_items(model: &Model) -> Vec<BeamItem> {
    let mut groups: Vec<(&str, Vec<usize>)> = Vec::new();
    let mut slot: HashMap<&str, usize> = HashMap::new();
    for (e, b) in model.beams.iter().enumerate() {
        let key = beam_key(&b.name);
        let k = *slot.entry(key).or_insert_with(|| {
            groups.push((key, Vec::new()));
            groups.len() - 1
        });
        groups[k].1.push(e);
    }
    // A name that is not plain, or elements of one name whose sections differ: one beam per
    // element, named by its index.
    let mut out = Vec::new();
    for (key, elements) in groups {
        let first = &model.beams[elements[0]].section;
        let uniform = elements.iter().all(|&e| model.beams[e].section == *first);
        let meshed = model.beams[elements[0]].name != key;
        if plain_name(key) && (uniform || meshed) {
            out.push(BeamItem {
                name: key.to_string(),
                elements,
                uniform,
                meshed,
            });
        } else {
            out.extend(elements.into_iter().map(|e| BeamItem {
                name: e.to_string(),
                elements: vec![e],
                uniform: true,
                meshed: false,
            }));
        }
    }
    out
}

impl NodeParam {
    pub fn get(self, node: &Node) -> f64 {
        match self {
            NodeParam::Velocity(k) => node.velocity[k],
            NodeParam::AngularVelocity(k) => node.angular_velocity[k],
        }
    }

    pub fn set(self, node: &mut Node, value: f64) {
        match self {
            NodeParam::Velocity(k) => node.velocity[k] = value,
            NodeParam::AngularVelocity(k) => node.angular_velocity[k] = value,
        }
    }
}

impl BodyParam {
    pub fn get(self, body: &RigidBody) -> f64 {
        match self {
            BodyParam::Mass => body.mass,
            BodyParam::Com(k) => body.com[k],
            BodyParam::Inertia(k) => body.inertia[VOIGT[k]],
        }
    }

    pub fn set(self, body: &mut RigidBody, value: f64) {
        match self {
            BodyParam::Mass => body.mass = value,
            BodyParam::Com(k) => body.com[k] = value,
            BodyParam::Inertia(k) => {
                let (i, j) = VOIGT[k];
                body.inertia[(i, j)] = value;
                body.inertia[(j, i)] = value;
            }
        }
    }
}

impl SectionParam {
    /// Every section parameter, in registry order.
    pub fn all() -> Vec<SectionParam> {
        let mut out: Vec<SectionParam> = (0..6).map(|i| SectionParam::Stiffness(i, i)).collect();
        for i in 0..6 {
            for j in i + 1..6 {
                out.push(SectionParam::Stiffness(i, j));
            }
        }
        out.push(SectionParam::MassPerLength);
        out.extend((0..3).map(|i| SectionParam::RotaryInertia(i, i)));
        out.extend([(1, 2), (0, 2), (0, 1)].map(|(i, j)| SectionParam::RotaryInertia(i, j)));
        out.push(SectionParam::DampingMass);
        out.push(SectionParam::DampingStiffness);
        out
    }

    /// The path after the beam's name.
    pub fn key(self) -> String {
        match self {
            SectionParam::Stiffness(i, j) if i == j => format!("section.{}", STIFFNESS_KEYS[i]),
            SectionParam::Stiffness(i, j) => format!("section.stiffness.{i}.{j}"),
            SectionParam::MassPerLength => "section.rhoA".into(),
            SectionParam::RotaryInertia(i, j) if i == j => {
                format!("section.{}", ROTARY_KEYS[i])
            }
            SectionParam::RotaryInertia(i, j) => format!("section.rotary_inertia.{i}.{j}"),
            SectionParam::DampingMass => "damping.mass".into(),
            SectionParam::DampingStiffness => "damping.stiffness".into(),
        }
    }

    pub fn get(self, s: &BeamSection) -> f64 {
        match self {
            SectionParam::Stiffness(i, j) => s.stiffness[(i, j)],
            SectionParam::MassPerLength => s.mass_per_length,
            SectionParam::RotaryInertia(i, j) => s.rotary_inertia[(i, j)],
            SectionParam::DampingMass => s.damping_mass,
            SectionParam::DampingStiffness => s.damping_stiffness,
        }
    }

    pub fn set(self, s: &mut BeamSection, value: f64) {
        match self {
            SectionParam::Stiffness(i, j) => {
                s.stiffness[(i, j)] = value;
                s.stiffness[(j, i)] = value;
            }
            SectionParam::MassPerLength => s.mass_per_length = value,
            SectionParam::RotaryInertia(i, j) => {
                s.rotary_inertia[(i, j)] = value;
                s.rotary_inertia[(j, i)] = value;
            }
            SectionParam::DampingMass => s.damping_mass = value,
            SectionParam::DampingStiffness => s.damping_stiffness = value,
        }
    }
}

/// A point given in the frame of `node` (inertial for the ground), in inertial coordinates
/// at t = 0.
fn to_inertial(nodes: &[Node], node: Option<NodeId>, p: &Vec3) -> Vec3 {
    match node {
        Some(n) => nodes[n.0].frame.point(p),
        None => *p,
    }
}

/// An inertial point at t = 0 in the frame of `node` (as the model-file reader converts it).
fn to_node_frame(nodes: &[Node], node: Option<NodeId>, p: &Vec3) -> Vec3 {
    match node {
        Some(n) => nodes[n.0].frame.inverse().point(p),
        None => *p,
    }
}

impl RopeParam {
    /// The value; `nodes` are the model's nodes (their initial frames).
    pub fn get(self, rope: &Rope, nodes: &[Node]) -> f64 {
        match self {
            RopeParam::Stiffness => rope.stiffness,
            RopeParam::Damping => rope.damping,
            RopeParam::RestLength => rope.rest_length,
            RopeParam::Point(i, k) => {
                let p = &rope.points[i];
                to_inertial(nodes, p.node, &p.point)[k]
            }
        }
    }

    /// Sets the value (points converted to their node's frame).
    pub fn set(self, rope: &mut Rope, nodes: &[Node], value: f64) {
        match self {
            RopeParam::Stiffness => rope.stiffness = value,
            RopeParam::Damping => rope.damping = value,
            RopeParam::RestLength => rope.rest_length = value,
            RopeParam::Point(i, k) => {
                let p = &mut rope.points[i];
                let mut x = to_inertial(nodes, p.node, &p.point);
                x[k] = value;
                p.point = to_node_frame(nodes, p.node, &x);
            }
        }
    }
}

impl JointParam {
    /// The value; `nodes` are the model's nodes (their initial frames).
    pub fn get(self, joint: &Joint, nodes: &[Node]) -> f64 {
        match self {
            JointParam::Position(k) => to_inertial(nodes, joint.node_a, &joint.frame_a.x)[k],
            JointParam::Drive(a) => joint.drive.as_ref().map_or(0.0, |f| f.amplitude(a)),
        }
    }

    /// Sets the value: a position places both joint frames' points at the new point (the
    /// joint frames coincide at t = 0), in their nodes' frames.
    pub fn set(self, joint: &mut Joint, nodes: &[Node], value: f64) {
        match self {
            JointParam::Position(k) => {
                let mut p = to_inertial(nodes, joint.node_a, &joint.frame_a.x);
                p[k] = value;
                joint.frame_a.x = to_node_frame(nodes, joint.node_a, &p);
                joint.frame_b.x = to_node_frame(nodes, joint.node_b, &p);
            }
            JointParam::Drive(a) => {
                if let Some(f) = &mut joint.drive {
                    f.set_amplitude(a, value);
                }
            }
        }
    }
}

impl LoadParam {
    pub fn get(self, load: &Load) -> f64 {
        match self {
            LoadParam::Force(k) => load.force[k],
            LoadParam::Torque(k) => load.torque[k],
            LoadParam::Amplitude(a) => load.function.amplitude(a),
        }
    }

    pub fn set(self, load: &mut Load, value: f64) {
        match self {
            LoadParam::Force(k) => load.force[k] = value,
            LoadParam::Torque(k) => load.torque[k] = value,
            LoadParam::Amplitude(a) => load.function.set_amplitude(a, value),
        }
    }
}

impl SpringParam {
    /// The value; `nodes` are the model's nodes (their initial frames).
    pub fn get(self, spring: &SpringDamper, nodes: &[Node]) -> f64 {
        match self {
            SpringParam::Stiffness => spring.stiffness,
            SpringParam::Damping => spring.damping,
            SpringParam::RestLength => spring.rest_length,
            SpringParam::PointA(k) => to_inertial(nodes, spring.node_a, &spring.point_a)[k],
            SpringParam::PointB(k) => to_inertial(nodes, spring.node_b, &spring.point_b)[k],
            SpringParam::RelaxationStiffness => spring.relaxation.map_or(0.0, |m| m.stiffness),
            SpringParam::RelaxationDamping => spring.relaxation.map_or(0.0, |m| m.damping),
        }
    }

    /// Sets the value (points converted to their node's frame).
    pub fn set(self, spring: &mut SpringDamper, nodes: &[Node], value: f64) {
        let point = |node, p: &mut Vec3, k: usize| {
            let mut x = to_inertial(nodes, node, p);
            x[k] = value;
            *p = to_node_frame(nodes, node, &x);
        };
        match self {
            SpringParam::Stiffness => spring.stiffness = value,
            SpringParam::Damping => spring.damping = value,
            SpringParam::RestLength => spring.rest_length = value,
            SpringParam::PointA(k) => point(spring.node_a, &mut spring.point_a, k),
            SpringParam::PointB(k) => point(spring.node_b, &mut spring.point_b, k),
            SpringParam::RelaxationStiffness => {
                if let Some(m) = &mut spring.relaxation {
                    m.stiffness = value;
                }
            }
            SpringParam::RelaxationDamping => {
                if let Some(m) = &mut spring.relaxation {
                    m.damping = value;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn beam_keys_strip_the_element_index_only() {
        assert_eq!(beam_key("rod[12]"), "rod");
        assert_eq!(beam_key("a[b][3]"), "a[b]");
        assert_eq!(beam_key("rod"), "rod");
        assert_eq!(beam_key("rod[]"), "rod[]");
        assert_eq!(beam_key("[3]"), "[3]");
        assert_eq!(beam_key("7[3]"), "7[3]");
        assert_eq!(beam_key("rod[x]"), "rod[x]");
    }

    #[test]
    fn edit_distance_is_bounded() {
        assert_eq!(edit_distance("body.top.mas", "body.top.mass", 2), Some(1));
        assert_eq!(edit_distance("body.tpo.mass", "body.top.mass", 2), Some(2));
        assert_eq!(edit_distance("abc", "xyz", 2), None);
        assert_eq!(edit_distance("", "ab", 2), Some(2));
    }

    #[test]
    fn names_fall_back_to_indices() {
        let s = segments(["a", "", "12", "b", "a", "c"].into_iter());
        assert_eq!(s, ["0", "1", "2", "b", "4", "c"]);
    }
}
