//! Force elements: rigid bodies (inertia and gravity), geometrically exact beams on SE(3)
//! (two nodes, [`beam`]), applied loads, spring-dampers.
//!
//! Every element contributes to the equations of motion of Brüls & Cardona (2010), Eq. (37),
//!
//! ```text
//! r(q, v, vdot, t) = M vdot - hat(v)^T M v + g_int(q, v) - g_ext(q, t),
//! ```
//!
//! written in the Lie algebra of the model's group (6 components per node: translation, then
//! rotation; see [`flexmb_lie::Group`]). For the Newton iteration of the generalized-alpha
//! scheme an element also returns its block of the iteration matrix
//!
//! ```text
//! S = c_m M + c_c C_t + c_k K_t T,     M = dr/dvdot, C_t = dr/dv, K_t = dr/dw (q -> q exp(w)),
//! ```
//!
//! where `T` is the tangent operator of each node's increment. One trait, [`ElementKernel`],
//! serves the dynamic step, statics, the initial accelerations and the step function of
//! [`crate::solve::step`]; a second, [`ElementParameters`], gives the derivatives `dr/dp` with
//! respect to the element's own parameters ([`crate::model::parameters`]) that sensitivity
//! analysis needs ([`crate::parameter_derivatives`]).
//!
//! Elements written most naturally in "physical" coordinates (inertial translation
//! variation, body rotation variation) are converted to the group's coordinates by
//! [`physical`].

pub mod beam;
pub mod load;
pub mod physical;
pub mod rigid_body;
pub mod spring;

use crate::model::{Model, NodeId};
use flexmb_lie::{Frame, Group, Mat6, Vec3, Vec6};
use nalgebra::{SMatrix, SVector};
use std::sync::Arc;

/// Local vector of a two-node element: `[node a (6), node b (6)]`.
pub type Vec12 = SVector<f64, 12>;
/// Local matrix of a two-node element, rows and columns ordered like [`Vec12`].
pub type Mat12 = SMatrix<f64, 12, 12>;

/// Kinematics of one node as an element sees it.
#[derive(Clone, Copy, Debug)]
pub struct NodeState {
    /// Configuration `q` (position, rotation).
    pub q: Frame,
    /// Velocity `v` in the group's convention (SE(3): body frame; R3xSO(3): inertial translation).
    pub v: Vec6,
    /// Acceleration `vdot`, same convention.
    pub vdot: Vec6,
    /// Tangent operator `T(h dq)` of the current increment (identity outside Newton).
    pub t: Mat6,
}

impl NodeState {
    /// A node fixed in space (the ground).
    pub fn ground(frame: Frame) -> Self {
        Self {
            q: frame,
            v: Vec6::zeros(),
            vdot: Vec6::zeros(),
            t: Mat6::identity(),
        }
    }
}

/// Coefficients of the iteration matrix `S = m M + c C_t + k K_t T`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Coefficients {
    pub m: f64,
    pub c: f64,
    pub k: f64,
}

impl Coefficients {
    /// Only the mass matrix (consistent initial accelerations).
    pub const MASS: Coefficients = Coefficients {
        m: 1.0,
        c: 0.0,
        k: 0.0,
    };
    /// Only the tangent stiffness (statics).
    pub const STIFFNESS: Coefficients = Coefficients {
        m: 0.0,
        c: 0.0,
        k: 1.0,
    };
}

/// Everything an element evaluation reads besides its own data.
#[derive(Clone, Copy, Debug)]
pub struct Context<'a> {
    pub model: &'a Model,
    pub group: Group,
    pub t: f64,
    /// Gravity is multiplied by this factor (load factor in statics, 1 in dynamics).
    pub gravity_scale: f64,
    /// Applied loads are multiplied by this factor (load factor in statics, 1 in dynamics).
    pub load_scale: f64,
}

/// The built-in force elements (enum dispatch), each with what it derives from the model
/// once: a beam element carries its mass matrix (computed from its section by
/// [`beam::mass_matrix`]), so that a [`Model`] holds no derived data. Built by
/// [`ElementRef::all`] with the [`crate::data::Layout`]: it belongs to that model as it was
/// then.
#[derive(Clone, Debug, PartialEq)]
pub enum ElementRef {
    Body(usize),
    /// Index in [`Model::beams`] and the element's mass matrix.
    Beam(usize, Arc<Mat12>),
    Load(usize),
    Spring(usize),
}

/// One small capability set shared by every force element.
pub trait ElementKernel {
    /// The nodes the element connects (`None` = ground), in local order.
    fn nodes(&self) -> [Option<NodeId>; 2];
    /// Residual `r` (12 entries, only the first 6 used by one-node elements) and, if asked,
    /// the iteration matrix `S = m M + c C_t + k K_t T` (group coordinates).
    fn evaluate(
        &self,
        ctx: &Context,
        nodes: &[NodeState; 2],
        r: &mut Vec12,
        s: Option<(&Coefficients, &mut Mat12)>,
    );
    /// Kinetic energy \[J\].
    fn kinetic_energy(&self, _ctx: &Context, _nodes: &[NodeState; 2]) -> f64 {
        0.0
    }
    /// Potential energy \[J\] (gravity, elastic).
    fn potential_energy(&self, _ctx: &Context, _nodes: &[NodeState; 2]) -> f64 {
        0.0
    }
}

impl ElementRef {
    /// All force elements of a model (beam mass matrices computed here).
    pub fn all(model: &Model) -> Vec<ElementRef> {
        let mut out: Vec<ElementRef> = (0..model.bodies.len()).map(ElementRef::Body).collect();
        let beams = model.beams.iter().enumerate();
        out.extend(beams.map(|(i, b)| ElementRef::Beam(i, Arc::new(beam::mass_matrix(b)))));
        out.extend((0..model.loads.len()).map(ElementRef::Load));
        out.extend((0..model.springs.len()).map(ElementRef::Spring));
        out
    }

    /// The kernel of this element.
    pub fn kernel<'m>(&'m self, model: &'m Model) -> Kernel<'m> {
        match self {
            ElementRef::Body(i) => Kernel::Body(&model.bodies[*i]),
            ElementRef::Beam(i, mass) => Kernel::Beam(beam::BeamElement {
                beam: &model.beams[*i],
                mass,
            }),
            ElementRef::Load(i) => Kernel::Load(&model.loads[*i]),
            ElementRef::Spring(i) => Kernel::Spring(&model.springs[*i]),
        }
    }

    /// Name for diagnostics, e.g. `body 'crank'`.
    pub fn describe(&self, model: &Model) -> String {
        match self {
            ElementRef::Body(i) => format!("body '{}'", model.bodies[*i].name),
            ElementRef::Beam(i, _) => format!("beam element '{}'", model.beams[*i].name),
            ElementRef::Load(i) => format!("load '{}'", model.loads[*i].name),
            ElementRef::Spring(i) => format!("spring '{}'", model.springs[*i].name),
        }
    }
}

/// Borrowed kernel of a built-in element.
pub enum Kernel<'m> {
    Body(&'m crate::model::RigidBody),
    Beam(beam::BeamElement<'m>),
    Load(&'m crate::model::Load),
    Spring(&'m crate::model::SpringDamper),
}

macro_rules! dispatch {
    ($self:ident, $k:ident => $e:expr) => {
        match $self {
            Kernel::Body($k) => $e,
            Kernel::Beam($k) => $e,
            Kernel::Load($k) => $e,
            Kernel::Spring($k) => $e,
        }
    };
}

impl ElementKernel for Kernel<'_> {
    fn nodes(&self) -> [Option<NodeId>; 2] {
        dispatch!(self, k => k.nodes())
    }
    fn evaluate(
        &self,
        ctx: &Context,
        nodes: &[NodeState; 2],
        r: &mut Vec12,
        s: Option<(&Coefficients, &mut Mat12)>,
    ) {
        dispatch!(self, k => k.evaluate(ctx, nodes, r, s))
    }
    fn kinetic_energy(&self, ctx: &Context, nodes: &[NodeState; 2]) -> f64 {
        dispatch!(self, k => k.kinetic_energy(ctx, nodes))
    }
    fn potential_energy(&self, ctx: &Context, nodes: &[NodeState; 2]) -> f64 {
        dispatch!(self, k => k.potential_energy(ctx, nodes))
    }
}

/// Inertial velocity of the point `p` (node frame) of a node, and of its origin.
pub fn point_velocity(group: Group, node: &NodeState, p: &Vec3) -> Vec3 {
    let (u, om) = flexmb_lie::split(&node.v);
    let origin = match group {
        Group::R3xSO3 => u,
        Group::SE3 => node.q.r * u,
    };
    origin + node.q.r * om.cross(p)
}

/// How a parameter derivative was obtained.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DerivativeMethod {
    /// From the formula (exact up to round-off).
    Analytic,
    /// Central difference on a perturbed copy of one element or joint
    /// ([`central_difference`], [`crate::joints::parameters`]).
    FiniteDifference,
}

/// The parameter-derivative capability of a force element: `dr/dp` for the element's own
/// parameters ([`crate::model::parameters`]) and for gravity, at given node kinematics.
/// Analytic where the element implements it, otherwise the [`central_difference`] default.
pub trait ElementParameters: ElementKernel {
    /// The element's parameters.
    type Param: Copy;
    /// `dr/dp` (12 entries like the residual, group coordinates, overwritten).
    fn parameter_derivative(
        &self,
        ctx: &Context,
        p: Self::Param,
        nodes: &[NodeState; 2],
        dr: &mut Vec12,
    ) -> DerivativeMethod;
    /// `dr/dg_k`, component `k` of gravity (overwritten; zero for massless elements).
    fn gravity_derivative(
        &self,
        _ctx: &Context,
        _k: usize,
        _nodes: &[NodeState; 2],
        dr: &mut Vec12,
    ) {
        dr.fill(0.0);
    }
}

/// Relative step of [`central_difference`]: about the cube root of the machine epsilon,
/// which balances the round-off error (`eps / h`) against the `O(h^2)` truncation error of a
/// central difference.
pub const FD_STEP: f64 = 6e-6;

/// The finite-difference default of [`ElementParameters::parameter_derivative`]:
/// `dr/dp = (r(p + h) - r(p - h)) / 2h` on two copies of `element` with the parameter set by
/// `set`, `h = FD_STEP max(|p|, scale)` (`scale`: a typical magnitude of the parameter).
pub fn central_difference<E: ElementKernel + Clone>(
    element: &E,
    ctx: &Context,
    nodes: &[NodeState; 2],
    (value, scale): (f64, f64),
    set: impl Fn(&mut E, f64),
    dr: &mut Vec12,
) -> DerivativeMethod {
    let h = FD_STEP * value.abs().max(scale);
    let r = |v: f64| {
        let mut copy = element.clone();
        set(&mut copy, v);
        let mut out = Vec12::zeros();
        copy.evaluate(ctx, nodes, &mut out, None);
        out
    };
    *dr = (r(value + h) - r(value - h)) / (2.0 * h);
    DerivativeMethod::FiniteDifference
}
