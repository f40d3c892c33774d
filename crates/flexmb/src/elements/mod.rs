//! Force elements: rigid bodies (inertia and gravity), geometrically exact beams on SE(3)
//! (two nodes, [`beam`]), applied loads, spring-dampers (with an optional Maxwell branch,
//! [`spring`], nonlinear laws and stops included), rotational spring-dampers about a joint's
//! axis ([`rotational_spring`]), 6-DOF bushings ([`bushing`]), ropes through any number of
//! points ([`rope`]), unilateral contacts with impact and friction ([`contact`]), gear
//! pairs ([`gear`]), worm gear pairs with mesh friction ([`worm_gear`]), and the blocks of a
//! control diagram coupled to the mechanics ([`control`]).
//!
//! Every element contributes to the equations of motion of Brüls & Cardona (2010), Eq. (37),
//!
//! ```text
//! r(q, v, vdot, x, xdot, t) = M vdot - hat(v)^T M v + g_int(q, v, x) - g_ext(q, t),
//! ```
//!
//! written in the Lie algebra of the model's group (6 components per node slot: translation,
//! then rotation; see [`flexmb_lie::Group`]), and, if it owns first-order states `x`, to their
//! equations `e(q, v, vdot, x, xdot, t) = 0` (one per state, after the slots' rows). For the
//! Newton iteration of the generalized-alpha scheme an element also returns its block of the
//! iteration matrix
//!
//! ```text
//! S = c_m M + c_c C_t + c_k K_t T     (node columns; M = dr/dvdot, C_t = dr/dv,
//!                                      K_t = dr/dw for q -> q exp(w))
//! S_x = c_x d/dx + c_xdot d/dxdot     (state columns)
//! ```
//!
//! for its rows of `r` and of `e` alike, where `T` is the tangent operator of each node's
//! increment. One trait, [`ElementKernel`], serves the dynamic step, statics, the initial
//! accelerations and the step function of [`crate::solve::step`]; a second,
//! [`ElementParameters`], gives the derivatives `d[r; e]/dp` with respect to the element's own
//! parameters ([`crate::model::parameters`]) that sensitivity analysis needs
//! ([`crate::parameter_derivatives`]).
//!
//! Elements written most naturally in "physical" coordinates (inertial translation
//! variation, body rotation variation) are converted to the group's coordinates by
//! [`physical`].

pub mod beam;
pub mod bushing;
pub mod contact;
pub mod control;
pub mod gear;
pub mod impact;
pub mod load;
pub mod physical;
pub mod pose;
pub mod rigid_body;
pub mod rope;
pub mod rotational_spring;
pub mod spring;
pub mod worm_gear;

pub use crate::kernel::{DerivativeMethod, Mat12, NodeState, Vec12, FD_STEP};
use crate::model::{Model, NodeId};
use flexmb_lie::{Frame, Group, Vec3};
use nalgebra::{DMatrix, DMatrixViewMut, DVector, DVectorViewMut};
use std::sync::Arc;

/// An element's local vector: 6 entries per node slot (Lie algebra: translation, then
/// rotation), then one per element state ([`ElementKernel::n_states`]).
pub type LocalVector<'a> = DVectorViewMut<'a, f64>;
/// An element's local matrix, rows and columns ordered like [`LocalVector`]: `n x n`,
/// column-major in contiguous storage, seen as a fixed-size matrix by an element whose
/// size is static ([`LocalMatrix::fixed`]: the arithmetic of fixed-size matrices) and as a
/// dynamic one otherwise ([`LocalMatrix::view`]).
pub struct LocalMatrix<'a> {
    data: &'a mut [f64],
    n: usize,
}

impl<'a> LocalMatrix<'a> {
    /// The `n x n` matrix stored column-major in `data` (at least `n^2` entries).
    pub fn new(data: &'a mut [f64], n: usize) -> Self {
        Self {
            data: &mut data[..n * n],
            n,
        }
    }

    /// Entry `(i, j)`.
    #[inline]
    pub fn get(&self, i: usize, j: usize) -> f64 {
        self.data[i + j * self.n]
    }

    /// The whole matrix as a dynamic view.
    pub fn view(&mut self) -> DMatrixViewMut<'_, f64> {
        DMatrixViewMut::from_slice(self.data, self.n, self.n)
    }

    /// The whole matrix as an `N x N` view (`N` must be its size).
    #[inline]
    pub fn fixed<const N: usize>(&mut self) -> nalgebra::SMatrixViewMut<'_, f64, N, N> {
        assert_eq!(self.n, N, "local matrix of size {} seen as {N}", self.n);
        nalgebra::SMatrixViewMut::<f64, N, N>::from_slice(self.data)
    }
}

/// Coefficients of the iteration matrix: on the node columns `S = m M + c C_t + k K_t T`,
/// on the columns of the element's states `S_x = x dr/dx + xdot dr/dxdot`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Coefficients {
    pub m: f64,
    pub c: f64,
    pub k: f64,
    /// Factor on `dr/dx` (element states).
    pub x: f64,
    /// Factor on `dr/dxdot` (element state rates).
    pub xdot: f64,
    /// Factor on `dr/dx` of the algebraic states ([`ElementKernel::is_algebraic`]: the
    /// outputs of control blocks), whose values are unknowns even where the other states'
    /// rates are (the initial accelerations).
    pub y: f64,
}

impl Coefficients {
    /// Only the mass matrix, and on the states only `dr/dxdot`: the matrix of the
    /// accelerations and state rates (consistent initial conditions).
    pub const MASS: Coefficients = Coefficients {
        m: 1.0,
        c: 0.0,
        k: 0.0,
        x: 0.0,
        xdot: 1.0,
        y: 1.0,
    };
    /// Only the tangent stiffness, and on the states only `dr/dx` (statics).
    pub const STIFFNESS: Coefficients = Coefficients {
        m: 0.0,
        c: 0.0,
        k: 1.0,
        x: 1.0,
        xdot: 0.0,
        y: 1.0,
    };

    /// Whether these are the coefficients of statics (stiffness without a rate term: the
    /// rates are absent), where states that only an event changes (a hold's value, a
    /// contact's impact velocity, friction's bristles) are held, their equations reading
    /// `x = x_start`. Not a partial derivative taken one coefficient at a time (the step
    /// function's `dE/dx`, the initial tangents' `dG/dx_0`: no stiffness with it), where
    /// such rows have no term in `x`.
    pub fn holds_states(&self) -> bool {
        self.xdot == 0.0 && self.k != 0.0
    }
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
    /// The system of the consistent initial accelerations is assembled: position-level
    /// equations of elements (a servo constraint) are written at acceleration level there,
    /// like the joints' rows.
    pub acceleration_level: bool,
    /// The input vector `u` at `t` given to the step ([`crate::model::Input`]); `None` reads
    /// each input from its function at `t` (a run).
    pub inputs: Option<&'a [f64]>,
}

impl<'a> Context<'a> {
    /// The context of `model` at time `t` with gravity and loads times `load_factor`.
    pub fn at(model: &'a Model, t: f64, load_factor: f64) -> Self {
        Self {
            model,
            group: model.group,
            t,
            gravity_scale: load_factor,
            load_scale: load_factor,
            acceleration_level: false,
            inputs: None,
        }
    }

    /// The value of input `k` (index in [`Model::inputs`]): the step's, or its function's at
    /// `t`.
    pub fn input(&self, k: usize) -> f64 {
        match self.inputs {
            Some(u) => u[k],
            None => self.model.loads[self.model.inputs[k].load]
                .function
                .value(self.t),
        }
    }
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
    Rope(usize),
    /// Index in [`Model::contacts`] and the effective mass of its nodes' bodies.
    Contact(usize, f64),
    Gear(usize),
    /// A spring-damper with a nonlinear law: indices in [`Model::springs`] and
    /// [`Model::spring_laws`] (its place in [`ElementItem::all`] is that of
    /// [`ElementItem::Spring`]).
    NonlinearSpring(usize, usize),
    /// Index in [`Model::rotational_springs`].
    RotationalSpring(usize),
    /// Index in [`Model::bushings`].
    Bushing(usize),
    /// Index in [`Model::worm_gears`].
    WormGear(usize),
    /// The model's block diagram ([`Model::control`]) and its slots ([`control::slots`]).
    Control(Arc<control::Slots>),
}

/// What an element sees besides its own data: the kinematics of its node slots (the
/// ground's, at rest, for a slot without a node) and its own states and their rates.
#[derive(Clone, Copy, Debug)]
pub struct Local<'a> {
    /// One per slot ([`ElementKernel::n_slots`]).
    pub nodes: &'a [NodeState],
    /// The element's states `x` ([`ElementKernel::n_states`]).
    pub x: &'a [f64],
    /// Their rates `xdot`.
    pub xdot: &'a [f64],
    /// The multipliers the element reads ([`ElementKernel::multiplier_rows`]), unscaled.
    pub lambda: &'a [f64],
    /// The other elements' states the element reads ([`ElementKernel::state_reads`]) and
    /// their rates.
    pub read_x: &'a [f64],
    pub read_xdot: &'a [f64],
}

impl<'a> Local<'a> {
    /// Node kinematics only (an element without states).
    pub fn nodes(nodes: &'a [NodeState]) -> Self {
        Self {
            nodes,
            x: &[],
            xdot: &[],
            lambda: &[],
            read_x: &[],
            read_xdot: &[],
        }
    }
}

/// What [`ElementKernel::initial_states`] returns: a failure of the Newton iterations that
/// solve for states, as [`crate::error::NewtonError`], the unknown blamed being the index of
/// the state in the element's `x`.
pub type InitialStates = Result<(), crate::error::NewtonError>;

/// Copies `(target, source)` among an element's states (local indices) that an event sets
/// ([`ElementKernel::event_map`]); global state indices in [`crate::solve::StepEvent`].
pub type HeldStates = Vec<(usize, usize)>;

/// One small capability set shared by every force element.
///
/// An element connects `n_slots` node slots (any number; a slot may be the ground) and may
/// own `n_states` first-order states `x` with as many equations `e(q, v, vdot, x, xdot, t) =
/// 0` of its own (an internal variable: a damper's elongation, a friction model's bristle
/// deflection). Its local vector is `[r (6 per slot); e (one per state)]`.
pub trait ElementKernel {
    /// Number of node slots.
    fn n_slots(&self) -> usize;
    /// The node of slot `k` (`None` = the ground).
    fn node(&self, k: usize) -> Option<NodeId>;
    /// Number of states the element owns.
    fn n_states(&self) -> usize {
        0
    }
    /// Whether state `i` is algebraic: its equation has no rate in it, and the value is the
    /// unknown where the other states' rates are (the initial accelerations; matrix factor
    /// [`Coefficients::y`]). The outputs of control blocks are.
    fn is_algebraic(&self, _i: usize) -> bool {
        false
    }
    /// Constraint rows (indices in `State::lambda`) whose multipliers the element reads: a
    /// control block measuring a joint's reaction. Their values are in [`Local::lambda`]
    /// and their columns follow the states' in the local matrix, `dr/dlambda` with no
    /// coefficient (the multiplier unknowns are `s lambda`, `s` the row scale that the
    /// element's rows carry). The element has no equations for them: their entries of the
    /// local vector and their rows of the local matrix are zero.
    fn multiplier_rows(&self) -> &[usize] {
        &[]
    }
    /// Other elements' states (indices in `State::x`) that the element reads: a control
    /// block measuring a contact's force reads the contact's impact velocity and bristles.
    /// Their values and rates are in [`Local::read_x`], [`Local::read_xdot`]; their columns
    /// follow the multipliers' in the local matrix, with the coefficients of state columns
    /// (`x dr/dx + xdot dr/dxdot`; none is algebraic). No equations, as for the multipliers.
    fn state_reads(&self) -> &[usize] {
        &[]
    }
    /// Size of the local vector: `6 n_slots + n_states + n_multipliers + n_state_reads`.
    fn n_local(&self) -> usize {
        6 * self.n_slots()
            + self.n_states()
            + self.multiplier_rows().len()
            + self.state_reads().len()
    }
    /// Residual `[r; e]` (every entry written) and, if asked, the iteration matrix (every
    /// entry written): on node columns `m M + c C_t + k K_t T`, on state columns
    /// `x dr/dx + xdot dr/dxdot`, for the rows of `r` and of `e` alike (group coordinates).
    fn evaluate(
        &self,
        ctx: &Context,
        local: &Local,
        r: &mut LocalVector,
        s: Option<(&Coefficients, &mut LocalMatrix)>,
    );
    /// The element's states at the start of a run, from the initial kinematics in `local`
    /// (its `x` and `xdot` zero); `x` is zero on entry. States found by solving equations
    /// (the outputs of control blocks) report a failure as the Newton iterations of the
    /// solver do ([`InitialStates`]).
    fn initial_states(&self, _ctx: &Context, _local: &Local, _x: &mut [f64]) -> InitialStates {
        Ok(())
    }
    /// Kinetic energy \[J\].
    fn kinetic_energy(&self, _ctx: &Context, _local: &Local) -> f64 {
        0.0
    }
    /// Potential energy \[J\] (gravity, elastic).
    fn potential_energy(&self, _ctx: &Context, _local: &Local) -> f64 {
        0.0
    }
    /// After an accepted time step from `start` to `end` (kinematics and states): the element
    /// may set states that are held constant during steps (their equation `xdot = 0`), e.g.
    /// a contact's impact velocity. `x` holds the end's states on entry.
    fn update_states(&self, _ctx: &Context, _start: &Local, _end: &Local, _x: &mut [f64]) {}
    /// Step-size control for elements with events (a contact's onset): what the element
    /// asks of a step of size `h` whose Newton iteration converged, from `start` to `end`.
    /// `None`: nothing.
    fn step_limit(
        &self,
        _ctx: &Context,
        _start: &Local,
        _end: &Local,
        _h: f64,
    ) -> Option<StepLimit> {
        None
    }
    /// The event of an accepted step from `start` to `end`, in words (e.g. `contact 'floor'
    /// closes`), if the element has one in it: a change of its law's branch that the step's
    /// equations do not carry smoothly (a contact or a gear flank that closes or opens, a
    /// hold that samples). Elements that can have one are those of
    /// [`ElementRef::can_switch`]; a run's derivatives are not followed through it
    /// ([`crate::sensitivity`], "Events").
    fn event(&self, _ctx: &Context, _start: &Local, _end: &Local) -> Option<String> {
        None
    }
    /// The held states an accepted step with an event ([`ElementKernel::event`]) sets, as
    /// copies among the element's own states, `(target, source)` in local indices (the
    /// sources read before any target is set), when the event's time does not depend on the
    /// motion (a hold's sample, at fixed times): the derivative of the step's end through
    /// the event is then the same copies ([`crate::sensitivity`], "Events"). `None`, the
    /// default: the event is placed by the motion, or its held values come from the
    /// kinematics (a contact's impact velocity, a gear flank), and a run's derivatives are
    /// not followed through it.
    fn event_map(&self, _ctx: &Context, _start: &Local, _end: &Local) -> Option<HeldStates> {
        None
    }
}

/// What an element with events asks of a converged step ([`ElementKernel::step_limit`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum StepLimit {
    /// Reject the step and repeat it with this size.
    Retry(f64),
    /// Accept it, and make the following steps at most this long.
    Next(f64),
}

impl StepLimit {
    /// The stricter of two requests: a retry before any limit on the next steps, the
    /// shorter of two of a kind.
    pub fn stricter(a: Option<StepLimit>, b: Option<StepLimit>) -> Option<StepLimit> {
        use StepLimit::{Next, Retry};
        match (a, b) {
            (Some(Retry(x)), Some(Retry(y))) => Some(Retry(x.min(y))),
            (Some(Retry(x)), _) | (_, Some(Retry(x))) => Some(Retry(x)),
            (Some(Next(x)), Some(Next(y))) => Some(Next(x.min(y))),
            (l, None) | (None, l) => l,
        }
    }
}

/// Reused storage for one element's [`Local`] inputs and its local vector and matrix.
#[derive(Clone, Debug)]
pub struct LocalBuffers {
    /// The kinematics of a ground slot (built once).
    ground: NodeState,
    /// The slots' kinematics are those of consecutive nodes: read them in place.
    in_place: Option<std::ops::Range<usize>>,
    /// Otherwise, their copy.
    nodes: Vec<NodeState>,
    x: Vec<f64>,
    xdot: Vec<f64>,
    lambda: Vec<f64>,
    read_x: Vec<f64>,
    read_xdot: Vec<f64>,
    r: Vec<f64>,
    s: Vec<f64>,
}

impl Default for LocalBuffers {
    fn default() -> Self {
        Self {
            ground: NodeState::ground(Frame::identity()),
            in_place: None,
            nodes: Vec::new(),
            x: Vec::new(),
            xdot: Vec::new(),
            lambda: Vec::new(),
            read_x: Vec::new(),
            read_xdot: Vec::new(),
            r: Vec::new(),
            s: Vec::new(),
        }
    }
}

impl LocalBuffers {
    /// Gathers the inputs of `kernel` from the kinematics of all nodes, from the states
    /// and rates of all elements (`x`, `xdot`, the element's own starting at `state_start`)
    /// and from the multipliers of all constraint rows (`lambda`, unscaled; empty: all zero).
    /// Slots that are consecutive nodes (a body, most beam elements) are not copied: the
    /// element reads them in `nodes`, which [`LocalBuffers::split`] and
    /// [`LocalBuffers::local`] take again.
    #[inline]
    pub fn gather<K: ElementKernel + ?Sized>(
        &mut self,
        kernel: &K,
        nodes: &[NodeState],
        (x, xdot, state_start): (&[f64], &[f64], usize),
        lambda: &[f64],
    ) {
        let n = kernel.n_slots();
        self.in_place = match kernel.node(0) {
            Some(first) if (1..n).all(|k| kernel.node(k) == Some(NodeId(first.0 + k))) => {
                Some(first.0..first.0 + n)
            }
            _ => None,
        };
        self.nodes.clear();
        if self.in_place.is_none() {
            for k in 0..n {
                let node = kernel.node(k).map_or(&self.ground, |n| &nodes[n.0]);
                self.nodes.push(*node);
            }
        }
        let ns = kernel.n_states();
        self.x.clear();
        self.xdot.clear();
        if ns > 0 {
            self.x.extend_from_slice(&x[state_start..state_start + ns]);
            self.xdot
                .extend_from_slice(&xdot[state_start..state_start + ns]);
        }
        self.lambda.clear();
        let rows = kernel.multiplier_rows();
        self.lambda
            .extend(rows.iter().map(|&r| lambda.get(r).copied().unwrap_or(0.0)));
        let reads = kernel.state_reads();
        self.read_x.clear();
        self.read_xdot.clear();
        self.read_x.extend(reads.iter().map(|&i| x[i]));
        self.read_xdot.extend(reads.iter().map(|&i| xdot[i]));
    }

    /// The gathered inputs (`nodes`: those given to [`LocalBuffers::gather`]) and the local
    /// vector and matrix (`n` = [`ElementKernel::n_local`]) to write.
    #[inline]
    pub fn split<'s>(
        &'s mut self,
        n: usize,
        nodes: &'s [NodeState],
    ) -> (Local<'s>, LocalVector<'s>, LocalMatrix<'s>) {
        if self.r.len() < n {
            self.r.resize(n, 0.0);
        }
        if self.s.len() < n * n {
            self.s.resize(n * n, 0.0);
        }
        let local = Local {
            nodes: slot_kinematics(&self.in_place, &self.nodes, nodes),
            x: &self.x,
            xdot: &self.xdot,
            lambda: &self.lambda,
            read_x: &self.read_x,
            read_xdot: &self.read_xdot,
        };
        (
            local,
            LocalVector::from_slice(&mut self.r[..n], n),
            LocalMatrix::new(&mut self.s, n),
        )
    }

    /// The first `n` entries of the local vector of [`LocalBuffers::split`]: what the last
    /// evaluation wrote there.
    #[inline]
    pub fn vector(&self, n: usize) -> &[f64] {
        &self.r[..n]
    }

    /// The gathered inputs (`nodes`: those given to [`LocalBuffers::gather`]).
    pub fn local<'s>(&'s self, nodes: &'s [NodeState]) -> Local<'s> {
        Local {
            nodes: slot_kinematics(&self.in_place, &self.nodes, nodes),
            x: &self.x,
            xdot: &self.xdot,
            lambda: &self.lambda,
            read_x: &self.read_x,
            read_xdot: &self.read_xdot,
        }
    }
}

/// The slots' kinematics: a range of all the nodes' (`in_place`), or their copy.
#[inline]
fn slot_kinematics<'s>(
    in_place: &Option<std::ops::Range<usize>>,
    copy: &'s [NodeState],
    nodes: &'s [NodeState],
) -> &'s [NodeState] {
    match in_place {
        Some(range) => &nodes[range.clone()],
        None => copy,
    }
}

/// The local residual of `kernel` and, with `coef`, its local matrix, as owned values (tests
/// and derivative code; assembly writes into [`LocalBuffers`] instead).
pub fn evaluate_owned<K: ElementKernel + ?Sized>(
    kernel: &K,
    ctx: &Context,
    local: &Local,
    coef: Option<&Coefficients>,
) -> (DVector<f64>, DMatrix<f64>) {
    let n = kernel.n_local();
    let mut r = DVector::zeros(n);
    let mut s = DMatrix::zeros(n, n);
    let mut rv = r.as_view_mut();
    let mut sv = LocalMatrix::new(s.as_mut_slice(), n);
    kernel.evaluate(ctx, local, &mut rv, coef.map(|c| (c, &mut sv)));
    (r, s)
}

impl ElementRef {
    /// All force elements of a model (beam mass matrices computed here), in the order of
    /// [`ElementItem::all`].
    pub fn all(model: &Model) -> Vec<ElementRef> {
        let mut laws = vec![None; model.springs.len()];
        // (the first law of a spring, like `Model::spring_law`; validation allows one)
        for (k, law) in model.spring_laws.iter().enumerate().rev() {
            if let Some(slot) = laws.get_mut(law.spring) {
                *slot = Some(k);
            }
        }
        ElementItem::all(model)
            .map(|item| match item {
                ElementItem::Body(i) => ElementRef::Body(i),
                ElementItem::Beam(i) => {
                    ElementRef::Beam(i, Arc::new(beam::mass_matrix(&model.beams[i])))
                }
                ElementItem::Load(i) => ElementRef::Load(i),
                ElementItem::Spring(i) => match laws[i] {
                    Some(k) => ElementRef::NonlinearSpring(i, k),
                    None => ElementRef::Spring(i),
                },
                ElementItem::Rope(i) => ElementRef::Rope(i),
                ElementItem::Contact(i) => {
                    let c = &model.contacts[i];
                    ElementRef::Contact(i, contact::effective_mass(model, c.node_a, c.node_b))
                }
                ElementItem::Gear(i) => ElementRef::Gear(i),
                ElementItem::RotationalSpring(i) => ElementRef::RotationalSpring(i),
                ElementItem::Bushing(i) => ElementRef::Bushing(i),
                ElementItem::WormGear(i) => ElementRef::WormGear(i),
                ElementItem::Control => ElementRef::Control(Arc::new(control::slots(model))),
            })
            .collect()
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
            ElementRef::Rope(i) => Kernel::Rope(&model.ropes[*i]),
            ElementRef::Contact(i, m) => Kernel::Contact(contact::ContactElement {
                contact: &model.contacts[*i],
                effective_mass: *m,
            }),
            ElementRef::Gear(i) => Kernel::Gear(&model.gears[*i]),
            ElementRef::NonlinearSpring(i, k) => Kernel::NonlinearSpring(spring::SpringElement {
                spring: std::borrow::Cow::Borrowed(&model.springs[*i]),
                law: Some(&model.spring_laws[*k].law),
            }),
            ElementRef::RotationalSpring(i) => {
                Kernel::RotationalSpring(rotational_spring::RotationalSpringElement::of(model, *i))
            }
            ElementRef::Bushing(i) => Kernel::Bushing(&model.bushings[*i]),
            ElementRef::WormGear(i) => Kernel::WormGear(&model.worm_gears[*i]),
            ElementRef::Control(slots) => {
                Kernel::Control(control::ControlElement::new(model, slots))
            }
        }
    }

    /// Whether the element has events: the dynamic step asks it for a step limit
    /// ([`ElementKernel::step_limit`]) and lets it update its held states between steps
    /// ([`ElementKernel::update_states`]).
    pub fn has_events(&self, model: &Model) -> bool {
        match self {
            ElementRef::Contact(..) => true,
            ElementRef::Gear(i) => model.gears[*i].has_events(),
            ElementRef::Control(_) => model.control.has_holds(),
            _ => false,
        }
    }

    /// Whether the element's law can switch in a way a step does not carry smoothly
    /// ([`ElementKernel::event`]): contacts (closing, opening), gear pairs whose flanks' laws
    /// differ (backlash or damping: without either, the force is the same spring on both
    /// sides of a flank change) and the holds of a control diagram (their samples).
    pub fn can_switch(&self, model: &Model) -> bool {
        match self {
            ElementRef::Contact(..) => true,
            ElementRef::Gear(i) => model.gears[*i].can_switch(),
            ElementRef::Control(_) => model.control.has_holds(),
            _ => false,
        }
    }

    /// Name for diagnostics, e.g. `body 'crank'`.
    pub fn describe(&self, model: &Model) -> String {
        match self {
            ElementRef::Body(i) => format!("body '{}'", model.bodies[*i].name),
            ElementRef::Beam(i, _) => format!("beam element '{}'", model.beams[*i].name),
            ElementRef::Load(i) => format!("load '{}'", model.loads[*i].name),
            ElementRef::Spring(i) => format!("spring '{}'", model.springs[*i].name),
            ElementRef::Rope(i) => format!("rope '{}'", model.ropes[*i].name),
            ElementRef::Contact(i, _) => format!("contact '{}'", model.contacts[*i].name),
            ElementRef::Gear(i) => format!("gear pair '{}'", model.gears[*i].name),
            ElementRef::NonlinearSpring(i, _) => format!("spring '{}'", model.springs[*i].name),
            ElementRef::RotationalSpring(i) => {
                format!("rotational spring '{}'", model.rotational_springs[*i].name)
            }
            ElementRef::Bushing(i) => format!("bushing '{}'", model.bushings[*i].name),
            ElementRef::WormGear(i) => format!("worm gear '{}'", model.worm_gears[*i].name),
            ElementRef::Control(_) => "the control blocks".into(),
        }
    }
}

/// A force element by its kind and index in the model's list: the order of the elements
/// ([`ElementItem::all`]), hence of their states in `State::x`, in one place.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ElementItem {
    Body(usize),
    Beam(usize),
    Load(usize),
    Spring(usize),
    Rope(usize),
    Contact(usize),
    Gear(usize),
    RotationalSpring(usize),
    Bushing(usize),
    WormGear(usize),
    /// The block diagram, one element (when the model has blocks).
    Control,
}

impl ElementItem {
    /// Every force element of `model`: bodies, beam elements, loads, springs, ropes,
    /// contacts, gear pairs, rotational springs, bushings, worm gear pairs.
    pub fn all(model: &Model) -> impl Iterator<Item = ElementItem> {
        (0..model.bodies.len())
            .map(ElementItem::Body)
            .chain((0..model.beams.len()).map(ElementItem::Beam))
            .chain((0..model.loads.len()).map(ElementItem::Load))
            .chain((0..model.springs.len()).map(ElementItem::Spring))
            .chain((0..model.ropes.len()).map(ElementItem::Rope))
            .chain((0..model.contacts.len()).map(ElementItem::Contact))
            .chain((0..model.gears.len()).map(ElementItem::Gear))
            .chain((0..model.rotational_springs.len()).map(ElementItem::RotationalSpring))
            .chain((0..model.bushings.len()).map(ElementItem::Bushing))
            .chain((0..model.worm_gears.len()).map(ElementItem::WormGear))
            .chain((!model.control.is_empty()).then_some(ElementItem::Control))
    }

    /// The number of states the element owns.
    pub fn n_states(self, model: &Model) -> usize {
        match self {
            ElementItem::Body(i) => model.bodies[i].n_states(),
            ElementItem::Beam(i) => model.beams[i].n_states(),
            ElementItem::Load(i) => model.loads[i].n_states(),
            ElementItem::Spring(i) => model.springs[i].n_states(),
            ElementItem::Rope(i) => model.ropes[i].n_states(),
            ElementItem::Contact(i) => model.contacts[i].n_states(),
            ElementItem::Gear(i) => model.gears[i].n_states(),
            ElementItem::RotationalSpring(_) => 1,
            ElementItem::Bushing(i) => model.bushings[i].n_states(),
            ElementItem::WormGear(_) => 0,
            ElementItem::Control => model.control.n_unknowns,
        }
    }

    /// The index of the element's first state in `State::x` (the states of the elements
    /// before it; [`crate::data::Layout::state_start`] of the element), 0 for an element
    /// without states (it reads none). Walks the elements before it, only when it has states.
    pub fn state_start(self, model: &Model) -> usize {
        if self.n_states(model) == 0 {
            return 0;
        }
        ElementItem::all(model)
            .take_while(|&item| item != self)
            .map(|item| item.n_states(model))
            .sum()
    }
}

/// Borrowed kernel of a built-in element.
pub enum Kernel<'m> {
    Body(&'m crate::model::RigidBody),
    Beam(beam::BeamElement<'m>),
    Load(&'m crate::model::Load),
    Spring(&'m crate::model::SpringDamper),
    Rope(&'m crate::model::Rope),
    Contact(contact::ContactElement<'m>),
    Gear(&'m crate::model::GearPair),
    NonlinearSpring(spring::SpringElement<'m>),
    RotationalSpring(rotational_spring::RotationalSpringElement<'m>),
    Bushing(&'m crate::model::Bushing),
    WormGear(&'m crate::model::WormGear),
    Control(control::ControlElement<'m>),
}

macro_rules! dispatch {
    ($self:ident, $k:ident => $e:expr) => {
        match $self {
            Kernel::Body($k) => $e,
            Kernel::Beam($k) => $e,
            Kernel::Load($k) => $e,
            Kernel::Spring($k) => $e,
            Kernel::Rope($k) => $e,
            Kernel::Contact($k) => $e,
            Kernel::Gear($k) => $e,
            Kernel::NonlinearSpring($k) => $e,
            Kernel::RotationalSpring($k) => $e,
            Kernel::Bushing($k) => $e,
            Kernel::WormGear($k) => $e,
            Kernel::Control($k) => $e,
        }
    };
}

impl ElementKernel for Kernel<'_> {
    #[inline]
    fn n_slots(&self) -> usize {
        dispatch!(self, k => k.n_slots())
    }
    #[inline]
    fn node(&self, slot: usize) -> Option<NodeId> {
        dispatch!(self, k => k.node(slot))
    }
    #[inline]
    fn n_states(&self) -> usize {
        dispatch!(self, k => k.n_states())
    }
    #[inline]
    fn is_algebraic(&self, i: usize) -> bool {
        dispatch!(self, k => k.is_algebraic(i))
    }
    #[inline]
    fn multiplier_rows(&self) -> &[usize] {
        dispatch!(self, k => k.multiplier_rows())
    }
    #[inline]
    fn state_reads(&self) -> &[usize] {
        dispatch!(self, k => k.state_reads())
    }
    #[inline]
    fn evaluate(
        &self,
        ctx: &Context,
        local: &Local,
        r: &mut LocalVector,
        s: Option<(&Coefficients, &mut LocalMatrix)>,
    ) {
        dispatch!(self, k => k.evaluate(ctx, local, r, s))
    }
    fn initial_states(&self, ctx: &Context, local: &Local, x: &mut [f64]) -> InitialStates {
        dispatch!(self, k => k.initial_states(ctx, local, x))
    }
    fn kinetic_energy(&self, ctx: &Context, local: &Local) -> f64 {
        dispatch!(self, k => k.kinetic_energy(ctx, local))
    }
    fn potential_energy(&self, ctx: &Context, local: &Local) -> f64 {
        dispatch!(self, k => k.potential_energy(ctx, local))
    }
    fn update_states(&self, ctx: &Context, start: &Local, end: &Local, x: &mut [f64]) {
        dispatch!(self, k => k.update_states(ctx, start, end, x))
    }
    fn step_limit(&self, ctx: &Context, start: &Local, end: &Local, h: f64) -> Option<StepLimit> {
        dispatch!(self, k => k.step_limit(ctx, start, end, h))
    }
    fn event(&self, ctx: &Context, start: &Local, end: &Local) -> Option<String> {
        dispatch!(self, k => k.event(ctx, start, end))
    }
    fn event_map(&self, ctx: &Context, start: &Local, end: &Local) -> Option<HeldStates> {
        dispatch!(self, k => k.event_map(ctx, start, end))
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

/// Inertial acceleration of the point `p` (node frame) of a node: on SE(3) `v = (R^T xdot,
/// omega)`, so `xddot = R (udot + omega x u)`; on R3xSO(3) `xddot = udot`; plus
/// `R (omegadot x p + omega x (omega x p))`.
pub fn point_acceleration(group: Group, node: &NodeState, p: &Vec3) -> Vec3 {
    let (u, om) = flexmb_lie::split(&node.v);
    let (ud, omd) = flexmb_lie::split(&node.vdot);
    let origin = match group {
        Group::R3xSO3 => ud,
        Group::SE3 => node.q.r * (ud + om.cross(&u)),
    };
    origin + node.q.r * (omd.cross(p) + om.cross(&om.cross(p)))
}

/// The parameter-derivative capability of a force element: `dr/dp` for the element's own
/// parameters ([`crate::model::parameters`]) and for gravity, at given node kinematics.
/// Analytic where the element implements it, otherwise the [`central_difference`] default.
pub trait ElementParameters: ElementKernel {
    /// The element's parameters.
    type Param: Copy;
    /// `d[r; e]/dp` (like the residual, group coordinates, every entry written).
    fn parameter_derivative(
        &self,
        ctx: &Context,
        p: Self::Param,
        local: &Local,
        dr: &mut LocalVector,
    ) -> DerivativeMethod;
    /// `d[r; e]/du` of the input the element reads, if it reads one (every entry written;
    /// zero for the others): the column of `dR/du` ([`crate::model::Input`]).
    fn input_derivative(&self, _ctx: &Context, _local: &Local, dr: &mut LocalVector) {
        dr.fill(0.0);
    }
    /// `d[r; e]/dg_k`, component `k` of gravity (every entry written; zero for massless
    /// elements).
    fn gravity_derivative(&self, _ctx: &Context, _k: usize, _local: &Local, dr: &mut LocalVector) {
        dr.fill(0.0);
    }
    /// `out[k] = w . d[r; e]/dp_k` for the parameters `ps` (`w`: the local weights, 6 per
    /// slot then one per state): the transposed products of an adjoint. The default takes
    /// the derivatives one at a time; an element whose derivatives share work overrides it.
    fn parameter_vjp(
        &self,
        ctx: &Context,
        ps: &[Self::Param],
        local: &Local,
        w: &[f64],
        out: &mut [f64],
    ) {
        let mut d = DVector::zeros(self.n_local());
        for (&p, o) in ps.iter().zip(out) {
            *o = parameter_dot(self, ctx, p, local, w, &mut d);
        }
    }
}

/// `w . d[r; e]/dp` of one parameter (`d`: scratch of the element's local size), the
/// entries past `w` (the multipliers an element reads: no equations) left out.
pub fn parameter_dot<E: ElementParameters + ?Sized>(
    element: &E,
    ctx: &Context,
    p: E::Param,
    local: &Local,
    w: &[f64],
    d: &mut DVector<f64>,
) -> f64 {
    element.parameter_derivative(ctx, p, local, &mut d.as_view_mut());
    w.iter().zip(d.iter()).map(|(a, b)| a * b).sum()
}

/// The finite-difference default of [`ElementParameters::parameter_derivative`]:
/// `dr/dp = (r(p + h) - r(p - h)) / 2h` on two copies of `element` with the parameter set by
/// `set`, `h = FD_STEP max(|p|, scale)` (`scale`: a typical magnitude of the parameter).
pub fn central_difference<E: ElementKernel + Clone>(
    element: &E,
    ctx: &Context,
    local: &Local,
    (value, scale): (f64, f64),
    set: impl Fn(&mut E, f64),
    dr: &mut LocalVector,
) -> DerivativeMethod {
    let h = FD_STEP * value.abs().max(scale);
    let r = |v: f64| {
        let mut copy = element.clone();
        set(&mut copy, v);
        evaluate_owned(&copy, ctx, local, None).0
    };
    dr.copy_from(&((r(value + h) - r(value - h)) / (2.0 * h)));
    DerivativeMethod::FiniteDifference
}
