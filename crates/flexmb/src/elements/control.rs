//! Block diagrams coupled monolithically to the mechanics ([`crate::model::control`]).
//!
//! The talk's integrated approach (Brüls & Golinval 2008; Arnold & Brüls 2007) adds to the equations of motion first-order states `x` and outputs `y`,
//!
//! ```text
//! M vdot - hat(v)^T M v + g(q, v, t) - L(q) y + B^T lambda = 0,
//! xdot = f(q, v, vdot, x, y, t),
//! y = h(q, v, vdot, x, y, t),
//! ```
//!
//! and integrates all of them in one Newton loop: the mechanical unknowns by the Lie group
//! generalized-alpha scheme, the states by its first-order counterpart with the same
//! `rho_inf` ([`crate::solve::FirstOrderParameters`], Jansen, Whiting & Hulbert 2000,
//! Eq. (27)), the outputs as algebraic unknowns ([`ElementKernel::is_algebraic`]).
//! All the blocks of a model form one element whose states are, block after block, the
//! block's states and then its outputs ([`ControlSystem`]); its slots are the nodes its
//! measurement and actuator blocks touch. Its equations, for block `b` with inputs `u_b`
//! (outputs of other blocks: `y` may depend on `y`, an algebraic loop, solved by the same
//! Newton iteration):
//!
//! ```text
//! states:  e = xdot_b - f_b(x_b, u_b, t)      (a hold: e = xdot_b, set between steps;
//!                                             a lag, the PID's filter and a motor's
//!                                             current: e = T xdot_b - T f_b, times their
//!                                             time constant or inductance, for scaling)
//! outputs: e = y_b - h_b(x_b, u_b, t)         (a measurement: y_b - m(q, v, vdot))
//! nodes:   r = -L(q) u                        (an actuator: u along its target)
//! ```
//!
//! with, per block kind ([`BlockKind`]):
//!
//! ```text
//! source          y = f(t)
//! gain            y = K u                  sum   y = sum s_i u_i     product  y = prod u_i
//! integrator      xdot = k u, y = x        lag   xdot = (K u - x) / T, y = x
//! pid             v = kp u + ki x_i + kd (u - x_f) / tf,  y = sat(v),
//!                 xdot_i = u + kb (y - v) (back-calculation anti-windup),  xdot_f = (u - x_f) / tf
//! state space     xdot = A x + B u, y = C x + D u
//! transfer fn.    b(s) / a(s) in controllable canonical form (e.g. Ogata, Modern Control
//!                 Engineering), a and b divided by a_0, b padded to degree n:
//!                 xdot_k = x_{k+1}, xdot_{n-1} = u - sum a_{n-k} x_k,
//!                 y = sum (b_{n-k} - a_{n-k} b_0) x_k + b_0 u
//! saturation      y = min(max(u, lower), upper)     dead zone, lookup: piecewise linear in u
//! rate limiter    xdot = min(max((u - x) / T, -falling), rising), y = x
//! hold            xdot = 0, x = u(t_k) set at the samples t_k = k period, y = x
//! dc motor        L xdot = V - R x - k_e omega (x the current), y = k_t x
//! ```
//!
//! **Measurements** (inertial components along a unit `axis`; `x, R` a node's
//! configuration, `xdot, omega` its physical velocity, `xddot, omegadot` its acceleration):
//! `axis . (x + R p)`, its rate `axis . (xdot + R (omega x p))` and acceleration, `axis .
//! (R omega)`, and a joint's coordinate and rate (the angle of frame B's x axis in frame A's
//! xy plane, `atan2`, as [`crate::joints::coordinate`]; a prismatic joint's slide `a_z .
//! (p_B - p_A)`). The angle is continuous over turns: its output equation is `e = y -
//! theta_g - 2 pi k`, `k` the whole number of turns nearest `(y - theta_g) / 2 pi` at the
//! iterate, so the branch follows the output itself (no extra state).
//!
//! **Reactions** read more than kinematics: a joint's constraint force on its node B (the
//! `joint_force` sensor's `-B_B^T lambda`, the moment about the joint point) depends on the
//! joint's multipliers, which the element reads ([`ElementKernel::multiplier_rows`]) so that
//! the measurement's row has its columns `-a . d(B^T lambda)/dlambda` next to the node
//! columns `-a . K_c` from the joint's own kernel (`K_c = sum_r lambda_r dB_r^T/dw`, the
//! joint's geometric stiffness); a beam element's stress resultant `C epsilon` has the node
//! columns `C P / L` ([`crate::elements::beam`]); a contact's force on its node B is minus
//! its residual rows there, whose derivatives, node columns and the columns of the
//! contact's states (read like the multipliers, [`ElementKernel::state_reads`]), come from
//! the contact's own iteration matrix with the same coefficients. These rows are computed
//! in `f64` by the joint's, beam's and contact's kernels, not by the diagram's automatic
//! differentiation.
//!
//! **Actuators**: a force `u a` at a node's point `P`, `r = -[u a; (R^T (P - x)) x (R^T u
//! a)]`; a moment `r_theta = -R^T u a`; a joint torque `u` about a revolute joint's axis `a =
//! R_A a_z` (on node B, `-u a` on A), a force along a prismatic joint's axis at B's joint
//! point (its reaction on A at the same point). `follower`: `a` turns with the node.
//!
//! **Servo constraints** (Blajer & Kołodziejczyk 2004): the output `u` of a servo block is
//! the input along its target that makes a position-level quantity `c(q)` (a node's
//! position along an axis, a joint coordinate) follow `f(t)`:
//!
//! ```text
//! nodes:   r = -L(q) u                 (u along the target, as an actuator's)
//! output:  e = c(q) - f(t)             (position level, like a joint's Phi, times h as
//!                                       every state row)
//! ```
//!
//! The index of these equations is the relative degree `r` of `c` with respect to `u`
//! plus one. A collocated servo (the target acts along `c`) has `r = 2`: index 3, like a
//! joint's drive, and the consistent initial accelerations write its row at acceleration
//! level, `c'' - f'' = 0`, which gives `u(0)`. A non-collocated servo reaches `c` through
//! other bodies; on two carts joined by a spring `k`, the force on cart 1 and `c = x2`,
//! `m2 x2'' = k (x1 - x2 + l)` and `m1 x1'' = u - k (x1 - x2 + l)` give `r = 4`, index 5,
//! and the input `u = (m1 + m2) x2'' + (m1 m2 / k) x2''''` (the two-car example, Altmann &
//! Heiland 2017). Its row is the same position-level row, discretized as it stands (no
//! index reduction); in the initial accelerations it reads `u = initial` (the user's
//! `u(0)`), since `u` appears only in the fourth derivative of `c`. The consequences,
//! measured on `examples/servo_noncollocated.toml` (`tests/control/control.rs`, docs/model-format.md
//! "Servo constraints"):
//!
//! * the pivot of `u` in the iteration matrix is `h^5` of its largest entry (the equilibrium
//!   rows are scaled by `1/(beta' m)`, the spring enters them `h^2` below the masses, the
//!   row weighs `h`) but `h^3` of its own column: the linear solver's singularity rule is
//!   relative to the column ([`crate::linear`]), which partial pivoting makes
//!   invariant to the unit of `u`. No further scaling of the row or of `u` is needed at the
//!   step sizes where round-off allows the problem at all (below);
//! * `rho_inf = 0` (the error of `u` at `h = 1e-3`: 7e-5 N, against 0.1 N at `rho_inf =
//!   0.5` and 8 N at 0.9, |u| <= 1.43 N);
//! * after a start-up layer of five steps (an error of 0.04 N whatever `h`, from the start
//!   `a_0 = vdot_0`), `u` and the motion converge at second order; round-off, amplified by
//!   negative powers of `h`, bounds the accuracy of `u` from below (7e-5 N at `h = 1e-3`,
//!   growing below), and its Newton corrections (3e-10 N at `h = 1e-3`, as `h^-7`): the
//!   step's Newton judges a servo's force with the joints' multipliers, whose corrections
//!   that stop halving after the configuration has converged are taken for round-off
//!   ([`crate::solve::dynamics`]);
//! * inconsistent initial conditions (the hidden constraints `c^(k)(0) = f^(k)(0)`,
//!   `k < r`, and `u(0)`) are not checked: `rho_inf = 0` corrects them within five steps
//!   by impulses of `u`.
//!
//! Seifried & Blajer (2013) analyse the servo-constraint problems of underactuated
//! multibody systems, flat and non-flat, and their numerical solution strategies.
//!
//! **Iteration matrix and parameter derivatives.** The residual is one function, generic
//! over the scalar type, of the slots' physical variations (configuration `x + dx`, `R (I +
//! tilde(theta))`, velocities and accelerations), the states and their rates. Its
//! derivatives are taken by forward automatic differentiation (num-dual), one pass per
//! variable the element has (the diagrams are small), and converted to group coordinates
//! like every element's ([`super::physical`]; on SE(3) the physical velocity `R U` and
//! acceleration `R (Udot + Omega x U)` also turn with the rotation). The parameters of the
//! blocks ([`crate::model::parameters::ControlParam`]) are differentiated the same way.
//! The kinks (saturation limits, dead-zone edges, lookup breakpoints) get one-sided
//! derivatives.
//!
//! **Initial values.** States start at their `initial` parameters (0 otherwise); the
//! outputs and the held values are solved for at `t = 0` by a Newton iteration on their
//! equations at the initial kinematics (zero accelerations), and again with the initial
//! accelerations by the consistent-initial-conditions solve, where the outputs are
//! unknowns in place of rates.
//!
//! # References
//! - O. Brüls, J.-C. Golinval, On the numerical damping of time integrators for coupled
//!   mechatronic systems, Comput. Methods Appl. Mech. Engrg. 197 (2008) 577-588.
//! - M. Arnold, O. Brüls, Convergence of the generalized-alpha scheme for constrained
//!   mechanical systems, Multibody Syst. Dyn. 18 (2007) 185-202.
//! - K. E. Jansen, C. H. Whiting, G. M. Hulbert, A generalized-alpha method for integrating
//!   the filtered Navier-Stokes equations with a stabilized finite element method, Comput.
//!   Methods Appl. Mech. Engrg. 190 (2000) 305-319.
//! - K. J. Åström, T. Hägglund, Advanced PID Control, ISA, 2006 (filtered derivative,
//!   anti-windup by back-calculation).
//! - W. Blajer, K. Kołodziejczyk, A geometric approach to solving problems of control
//!   constraints, Multibody Syst. Dyn. 11 (2004).
//! - R. Seifried, W. Blajer, Analysis of servo-constraint problems for underactuated
//!   multibody systems, Mech. Sci. 4 (2013) 113-129.
//! - R. Altmann, J. Heiland, Simulation of multibody systems with servo constraints through
//!   optimal control, Multibody Syst. Dyn. 40 (2017) 75-98.

use super::pose::{c, pose, Pose};
use super::{
    physical, Coefficients, Context, DerivativeMethod, ElementKernel, ElementParameters,
    HeldStates, InitialStates, Local, LocalMatrix, LocalVector, Mat12, StepLimit,
};
use crate::error::NewtonError;
use crate::linear::LinearError;
use crate::model::control::{BlockKind, ControlSystem, Quantity, Target};
use crate::model::parameters::{ControlWrt, SectionParam};
use crate::model::{Joint, JointId, JointKind, Model, NodeId};
use flexmb_lie::Vec3;
use nalgebra::{DMatrix, DVector, Matrix3, RealField, RowVector6, SMatrix, Vector3};

/// A row over the 12 variations of two nodes.
type RowVector12 = SMatrix<f64, 1, 12>;
use num_dual::Dual64;
use std::f64::consts::PI;

/// Most Newton iterations for the outputs at the initial state
/// ([`ControlElement::solve_outputs`]).
const OUTPUTS_ITERATIONS: usize = 30;
/// Relative size of the last correction at which the outputs at the initial state have
/// converged (a few units of round-off).
const OUTPUTS_TOLERANCE: f64 = 1e-14;

/// The block diagram of a model as the assembly sees it: the system, its slots and the
/// constraint rows it reads.
#[derive(Clone, Copy, Debug)]
pub struct ControlElement<'m> {
    pub system: &'m ControlSystem,
    pub model: &'m Model,
    /// The nodes the measurements and actuators touch (`None`: the ground side of a joint).
    pub slots: &'m [Option<NodeId>],
    /// The constraint rows whose multipliers the measurements of constraint forces read
    /// ([`ElementKernel::multiplier_rows`]), joint after joint, and where each joint's
    /// rows start among them.
    pub rows: &'m [usize],
    pub joint_rows: &'m [(JointId, usize)],
    /// The contacts' states that the measurements of contact forces read
    /// ([`ElementKernel::state_reads`]), contact after contact, and for each contact where
    /// its states start among them and its effective mass.
    pub states: &'m [usize],
    pub contacts: &'m [(usize, usize, f64)],
}

/// What the diagram of a model touches ([`slots`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Slots {
    /// Every node a measurement or actuator touches, in the order of first use (both sides
    /// of a joint, the ground as `None`).
    pub nodes: Vec<Option<NodeId>>,
    /// The rows of the joints whose constraint forces are measured (indices in
    /// `State::lambda`), joint after joint.
    pub rows: Vec<usize>,
    /// Those joints, each with the position of its first row in `rows`.
    pub joint_rows: Vec<(JointId, usize)>,
    /// The states (indices in `State::x`) of the contacts whose forces are measured.
    pub states: Vec<usize>,
    /// Those contacts: index, position of the first state in `states`, effective mass.
    pub contacts: Vec<(usize, usize, f64)>,
}

impl<'m> ControlElement<'m> {
    /// The diagram of `model` on its [`slots`].
    pub fn new(model: &'m Model, slots: &'m Slots) -> Self {
        Self {
            system: &model.control,
            model,
            slots: &slots.nodes,
            rows: &slots.rows,
            joint_rows: &slots.joint_rows,
            states: &slots.states,
            contacts: &slots.contacts,
        }
    }
}

/// The slots of a model's diagram and the constraint rows it reads.
pub fn slots(model: &Model) -> Slots {
    let mut out: Vec<Option<NodeId>> = Vec::new();
    let mut add = |n: Option<NodeId>| {
        if !out.contains(&n) {
            out.push(n);
        }
    };
    let (mut rows, mut joint_rows) = (Vec::new(), Vec::<(JointId, usize)>::new());
    let (mut states, mut contacts) = (Vec::new(), Vec::<(usize, usize, f64)>::new());
    for b in &model.control.blocks {
        let (quantity, target) = match &b.kind {
            BlockKind::Measure(q) => (Some(q), None),
            BlockKind::Actuator(t) => (None, Some(t)),
            BlockKind::Servo {
                quantity, target, ..
            } => (Some(quantity), Some(target)),
            _ => (None, None),
        };
        if let Some(q) = quantity {
            match q {
                Quantity::Position { node, .. }
                | Quantity::Velocity { node, .. }
                | Quantity::Acceleration { node, .. }
                | Quantity::AngularVelocity { node, .. } => add(Some(*node)),
                Quantity::JointCoordinate { joint } | Quantity::JointRate { joint } => {
                    let j = &model.joints[joint.0];
                    add(j.node_a);
                    add(j.node_b);
                }
                Quantity::ConstraintForce { joint, .. } => {
                    let j = &model.joints[joint.0];
                    add(j.node_a);
                    add(j.node_b);
                    if !joint_rows.iter().any(|(k, _)| k == joint) {
                        let (table, starts, _) = crate::joints::row_table(model);
                        let first = starts[joint.0];
                        joint_rows.push((*joint, rows.len()));
                        rows.extend(first..first + table[joint.0].len());
                    }
                }
                Quantity::SectionForce { beam, .. } => {
                    let b = &model.beams[*beam];
                    add(Some(b.nodes[0]));
                    add(Some(b.nodes[1]));
                }
                Quantity::ContactForce { contact, .. } => {
                    let c = &model.contacts[*contact];
                    add(c.node_a);
                    add(c.node_b);
                    if !contacts.iter().any(|(k, ..)| k == contact) {
                        let first = super::ElementItem::Contact(*contact).state_start(model);
                        let mass = super::contact::effective_mass(model, c.node_a, c.node_b);
                        contacts.push((*contact, states.len(), mass));
                        states.extend(first..first + c.n_states());
                    }
                }
            }
        }
        if let Some(t) = target {
            match t {
                Target::Force { node, .. } | Target::Moment { node, .. } => add(Some(*node)),
                Target::Joint { joint } => {
                    let j = &model.joints[joint.0];
                    add(j.node_a);
                    add(j.node_b);
                }
            }
        }
    }
    Slots {
        nodes: out,
        rows,
        joint_rows,
        states,
        contacts,
    }
}

/// The inputs of a measured contact's element, taken from the diagram's.
struct ContactInputs<'a> {
    nodes: [super::NodeState; 2],
    x: &'a [f64],
    xdot: &'a [f64],
}

impl ContactInputs<'_> {
    fn local(&self) -> Local<'_> {
        Local {
            x: self.x,
            xdot: self.xdot,
            ..Local::nodes(&self.nodes)
        }
    }
}

/// The scalars the residual is evaluated in: `f64`, and dual numbers for its derivatives.
trait Scalar: RealField + Copy {
    /// The real part.
    fn value(&self) -> f64;
}

impl Scalar for f64 {
    fn value(&self) -> f64 {
        *self
    }
}

impl Scalar for Dual64 {
    fn value(&self) -> f64 {
        self.re
    }
}

/// `v` as a vector of the scalar type `T`.
fn vector<T: RealField + Copy>(v: &Vec3) -> Vector3<T> {
    v.map(c)
}

/// `r -= g`: a generalized force ([`Pose::generalized`]) on a slot's residual rows.
fn subtract<T: RealField + Copy>(r: &mut [T], g: [T; 6]) {
    for (ri, gi) in r.iter_mut().zip(g) {
        *ri -= gi;
    }
}

/// Variables of the automatic differentiation per slot: `dx, theta, dxdot, domega,
/// dxddot, domegadot`.
const PER_SLOT: usize = 18;

/// The pose of a slot perturbed by the variables `w[18 k..18 k + 18]`.
fn perturbed<T: RealField + Copy>(p: &Pose<f64>, w: &[T]) -> Pose<T> {
    let v = |i: usize| Vector3::new(w[i], w[i + 1], w[i + 2]);
    let r = p.r.map(c::<T>) * (Matrix3::identity() + v(3).cross_matrix());
    Pose {
        x: vector(&p.x) + v(0),
        r,
        xdot: vector(&p.xdot) + v(6),
        om: vector(&p.om) + v(9),
        xddot: vector(&p.xddot) + v(12),
        omdot: vector(&p.omdot) + v(15),
    }
}

/// A joint's frames in inertial coordinates from its two slots' poses: `(p_A, A, p_B, B)`.
fn joint_frames<T: RealField + Copy>(
    joint: &Joint,
    a: &Pose<T>,
    b: &Pose<T>,
) -> (Vector3<T>, Matrix3<T>, Vector3<T>, Matrix3<T>) {
    let ra = a.r * joint.frame_a.r.map(c::<T>);
    let rb = b.r * joint.frame_b.r.map(c::<T>);
    (a.point(&joint.frame_a.x), ra, b.point(&joint.frame_b.x), rb)
}

fn is_angle(joint: &Joint) -> bool {
    matches!(joint.kind, JointKind::Revolute | JointKind::Cylindrical)
}

/// `min(max(v, lo), hi)`.
fn clamp<T: RealField + Copy>(v: T, lo: T, hi: T) -> T {
    if v < lo {
        lo
    } else if v > hi {
        hi
    } else {
        v
    }
}

/// Piecewise-linear interpolation through `(xs[i], ys[i])`, constant outside.
fn interpolate<T: RealField + Copy>(xs: &[f64], ys: &[T], u: T) -> T {
    let n = xs.len();
    if u <= c(xs[0]) {
        return ys[0];
    }
    if u >= c(xs[n - 1]) {
        return ys[n - 1];
    }
    let k = xs.partition_point(|&x| c::<T>(x) <= u).clamp(1, n - 1);
    let s = (u - c(xs[k - 1])) / c(xs[k] - xs[k - 1]);
    ys[k - 1] + (ys[k] - ys[k - 1]) * s
}

/// Where the residual is evaluated: during the run, or for the initial outputs and held
/// values (a hold's row then reads `x - u`).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Phase {
    Run,
    Initial,
    /// The consistent initial accelerations ([`Context::acceleration_level`]).
    Accelerations,
}

impl Phase {
    fn of(ctx: &Context) -> Self {
        if ctx.acceleration_level {
            Phase::Accelerations
        } else {
            Phase::Run
        }
    }
}

impl ControlElement<'_> {
    /// The slot of a node.
    fn slot(&self, node: Option<NodeId>) -> usize {
        self.slots
            .iter()
            .position(|&s| s == node)
            .expect("control slot")
    }

    /// Number of variables of the automatic differentiation.
    fn n_variables(&self) -> usize {
        PER_SLOT * self.slots.len() + 2 * self.system.n_unknowns
    }

    /// The value of a measurement (`reaction`: the value of a measurement that is not a
    /// function of the poses, [`Quantity::is_reaction`], from [`ControlElement::reaction`]).
    fn measure<T: Scalar>(&self, q: &Quantity, poses: &[Pose<T>], y: T, reaction: f64) -> T {
        let node = |n: NodeId| &poses[self.slot(Some(n))];
        match q {
            Quantity::Position {
                node: n,
                point,
                axis,
            } => node(*n).point(point).dot(&vector(axis)),
            Quantity::Velocity {
                node: n,
                point,
                axis,
            } => {
                let p = node(*n);
                (p.xdot + p.r * p.om.cross(&vector(point))).dot(&vector(axis))
            }
            Quantity::Acceleration {
                node: n,
                point,
                axis,
            } => {
                let p = node(*n);
                let pt = vector(point);
                let a = p.xddot + p.r * (p.omdot.cross(&pt) + p.om.cross(&p.om.cross(&pt)));
                a.dot(&vector(axis))
            }
            Quantity::AngularVelocity { node: n, axis } => {
                let p = node(*n);
                (p.r * p.om).dot(&vector(axis))
            }
            Quantity::JointCoordinate { joint } | Quantity::JointRate { joint } => {
                let j = &self.model.joints[joint.0];
                let (a, b) = (&poses[self.slot(j.node_a)], &poses[self.slot(j.node_b)]);
                let (pa, fa, pb, fb) = joint_frames(j, a, b);
                let axis = fa.column(2).into_owned();
                let rate = matches!(q, Quantity::JointRate { .. });
                match (is_angle(j), rate) {
                    (true, false) => {
                        let xb = fb.column(0);
                        let g = xb.dot(&fa.column(1)).atan2(xb.dot(&fa.column(0)));
                        let turns = ((y.value() - g.value()) / (2.0 * PI)).round();
                        g + c::<T>(2.0 * PI * turns)
                    }
                    (true, true) => (b.r * b.om - a.r * a.om).dot(&axis),
                    (false, false) => axis.dot(&(pb - pa)),
                    (false, true) => {
                        let axis_dot = (a.r * a.om).cross(&axis);
                        let rel = b.velocity_at(&pb) - a.velocity_at(&pa);
                        axis_dot.dot(&(pb - pa)) + axis.dot(&rel)
                    }
                }
            }
            Quantity::ConstraintForce { .. }
            | Quantity::SectionForce { .. }
            | Quantity::ContactForce { .. } => c(reaction),
        }
    }

    /// A measurement of a constraint, section or contact force ([`Quantity::is_reaction`]):
    /// its value and, with `coef`, its derivative in the element's local columns (node
    /// columns in group coordinates, times the coefficients and the tangent operators;
    /// multiplier columns without coefficient, [`ElementKernel::multiplier_rows`]; the
    /// columns of the states read, [`ElementKernel::state_reads`]).
    ///
    /// A constraint force is `-B^T lambda` on the measured node, the joint's own rows `B`
    /// and `K_c = sum_r lambda_r dB_r^T/dw` giving its derivatives; its components in the
    /// node's frame (the rotational ones, and on SE(3) the translational ones too) turn to
    /// inertial ones by `R`, whose variation `R tilde(theta)` adds `(R^T a) x g` on the
    /// node's rotation columns. A section force is the beam's `C epsilon`, of derivative
    /// `C P / L` ([`crate::elements::beam::Beam::stress_derivative`]). A contact force is
    /// minus the contact's residual rows of node B, differentiated by the contact's own
    /// iteration matrix with the same coefficients (and the same turn of its components).
    fn reaction(
        &self,
        ctx: &Context,
        local: &Local,
        q: &Quantity,
        coef: Option<&Coefficients>,
    ) -> (f64, Option<DVector<f64>>) {
        let n6 = 6 * self.slots.len();
        let mut row = coef.map(|_| DVector::zeros(self.n_local()));
        // the 12 node columns of a pair of slots, times c_k and the tangent operators
        let nodes_row = |row: &mut DVector<f64>, slots: [usize; 2], d: &RowVector12, k: f64| {
            for (end, &slot) in slots.iter().enumerate() {
                if self.slots[slot].is_some() {
                    let block = d.fixed_columns::<6>(6 * end) * local.nodes[slot].t * k;
                    let mut out = row.rows_mut(6 * slot, 6);
                    out += block.transpose();
                }
            }
        };
        match q {
            Quantity::ConstraintForce {
                joint,
                axis,
                moment,
            } => {
                let j = &self.model.joints[joint.0];
                let slots = [self.slot(j.node_a), self.slot(j.node_b)];
                let pair = [local.nodes[slots[0]], local.nodes[slots[1]]];
                let rows = crate::joints::rows(j);
                let first = self
                    .joint_rows
                    .iter()
                    .find(|(k, _)| k == joint)
                    .map_or(0, |&(_, f)| f);
                let lam = &local.lambda[first..first + rows.len()];
                let mut k = Mat12::zeros();
                let jv = crate::joints::ConstraintKernel::evaluate(
                    j,
                    ctx.group,
                    &rows,
                    &pair,
                    ctx.t,
                    lam,
                    row.as_ref().map(|_| &mut k),
                );
                let rb = pair[1].q.r;
                let mut d = RowVector12::zeros();
                let mut dl = vec![0.0; rows.len()];
                // `a . f` for f the force (at = 6) or moment about B's origin (at = 9) of
                // `-B^T lambda` on node B, inertial; `g` the node's generalized force part
                let part = |at: usize| -> Vec3 {
                    (0..rows.len()).fold(Vec3::zeros(), |acc, r| {
                        acc + jv.b[r].fixed_rows::<3>(at) * lam[r]
                    })
                };
                // components in the node's frame turn with it
                let turns = |at: usize| at == 9 || ctx.group == flexmb_lie::Group::SE3;
                let mut along = |at: usize, a: &Vec3, d: &mut RowVector12| {
                    let g = part(at);
                    let turns = turns(at);
                    let w = if turns { rb.transpose() * a } else { *a };
                    for c in 0..12 {
                        d[c] -= (0..3).map(|i| w[i] * k[(at + i, c)]).sum::<f64>();
                    }
                    if turns {
                        let extra = w.cross(&g);
                        for i in 0..3 {
                            d[9 + i] += extra[i];
                        }
                    }
                    for (r, dl) in dl.iter_mut().enumerate() {
                        *dl -= w.dot(&jv.b[r].fixed_rows::<3>(at));
                    }
                    -w.dot(&g)
                };
                let value = if *moment {
                    // about the joint point P = x_B + R_B p: m_P = m_O - (R_B p) x f, so
                    // a . m_P = a . m_O + ((R_B p) x a) . f, and the variation of R_B p
                    // adds p x (R_B^T (a x f)) on B's rotation columns
                    let p = j.frame_b.x;
                    let r = rb * p;
                    let f = if turns(6) { rb * part(6) } else { part(6) } * -1.0;
                    let extra = p.cross(&(rb.transpose() * axis.cross(&f)));
                    for i in 0..3 {
                        d[9 + i] += extra[i];
                    }
                    along(9, axis, &mut d) + along(6, &r.cross(axis), &mut d)
                } else {
                    along(6, axis, &mut d)
                };
                if let (Some(row), Some(coef)) = (row.as_mut(), coef) {
                    nodes_row(row, slots, &d, coef.k);
                    let m0 = n6 + self.system.n_unknowns + first;
                    row.rows_mut(m0, rows.len()).copy_from_slice(&dl);
                }
                (value, row)
            }
            Quantity::SectionForce { beam, component } => {
                let b = &self.model.beams[*beam];
                let slots = [self.slot(Some(b.nodes[0])), self.slot(Some(b.nodes[1]))];
                let (st, d) = b.stress_derivative(&self.beam_pair(b, local));
                if let (Some(row), Some(coef)) = (row.as_mut(), coef) {
                    nodes_row(row, slots, &d.row(*component).into_owned(), coef.k);
                }
                (st.stress[*component], row)
            }
            Quantity::ContactForce { contact, axis } => {
                let (element, local_c, slots, first) = self.contact_local(*contact, local);
                let (r, sc) = super::evaluate_owned(&element, ctx, &local_c.local(), coef);
                let rb = local_c.nodes[1].q.r;
                let g = Vec3::new(r[6], r[7], r[8]);
                let turns = ctx.group == flexmb_lie::Group::SE3;
                let w = if turns { rb.transpose() * axis } else { *axis };
                if let (Some(row), Some(coef)) = (row.as_mut(), coef) {
                    // the contact's own rows of node B (coefficients and tangents applied)
                    let d = |c: usize| -(0..3).map(|i| w[i] * sc[(6 + i, c)]).sum::<f64>();
                    let extra = w.cross(&g) * coef.k;
                    for (end, &slot) in slots.iter().enumerate() {
                        if self.slots[slot].is_some() {
                            for c in 0..6 {
                                row[6 * slot + c] += d(6 * end + c);
                            }
                        }
                    }
                    if turns {
                        let t = local_c.nodes[1].t.fixed_view::<3, 6>(3, 0).into_owned();
                        let mut out = row.rows_mut(6 * slots[1], 6);
                        out += (extra.transpose() * t).transpose();
                    }
                    let s0 = n6 + self.system.n_unknowns + self.rows.len() + first;
                    for i in 0..element.n_states() {
                        row[s0 + i] = d(12 + i);
                    }
                }
                (-w.dot(&g), row)
            }
            _ => (0.0, row),
        }
    }

    /// The contact element of a measured contact force, its inputs from the diagram's
    /// (its nodes' slots, its states among the states read), the two slots and the position
    /// of its states among those read.
    fn contact_local<'l>(
        &self,
        contact: usize,
        local: &Local<'l>,
    ) -> (
        super::contact::ContactElement<'_>,
        ContactInputs<'l>,
        [usize; 2],
        usize,
    ) {
        let c = &self.model.contacts[contact];
        let &(_, first, effective_mass) = self
            .contacts
            .iter()
            .find(|(k, ..)| *k == contact)
            .expect("a measured contact has its states among those read");
        let slots = [self.slot(c.node_a), self.slot(c.node_b)];
        let n = c.n_states();
        let inputs = ContactInputs {
            nodes: slots.map(|k| local.nodes[k]),
            x: &local.read_x[first..first + n],
            xdot: &local.read_xdot[first..first + n],
        };
        let element = super::contact::ContactElement {
            contact: c,
            effective_mass,
        };
        (element, inputs, slots, first)
    }

    /// The kinematics of a beam element's two nodes (both are slots).
    fn beam_pair(&self, b: &crate::model::Beam, local: &Local) -> [super::NodeState; 2] {
        b.nodes.map(|n| local.nodes[self.slot(Some(n))])
    }

    /// The values of the diagram's [`ControlElement::reaction`] measurements, per block (0
    /// for the others).
    fn reactions(&self, ctx: &Context, local: &Local) -> Vec<f64> {
        self.system
            .blocks
            .iter()
            .map(|b| match &b.kind {
                BlockKind::Measure(q) if q.is_reaction() => self.reaction(ctx, local, q, None).0,
                _ => 0.0,
            })
            .collect()
    }

    /// The second time derivative of a position-level quantity (a node's position along an
    /// axis, a joint coordinate), from the slots' accelerations.
    fn second_derivative<T: Scalar>(&self, q: &Quantity, poses: &[Pose<T>]) -> T {
        match q {
            Quantity::Position { node, point, axis } => {
                let acceleration = Quantity::Acceleration {
                    node: *node,
                    point: *point,
                    axis: *axis,
                };
                self.measure(&acceleration, poses, c(0.0), 0.0)
            }
            Quantity::JointCoordinate { joint } => {
                let j = &self.model.joints[joint.0];
                let (a, b) = (&poses[self.slot(j.node_a)], &poses[self.slot(j.node_b)]);
                let (pa, fa, pb, _) = joint_frames(j, a, b);
                let axis = fa.column(2).into_owned();
                let (wa, wb) = (a.r * a.om, b.r * b.om);
                let (aa, ab) = (a.r * a.omdot, b.r * b.omdot);
                let axis_dot = wa.cross(&axis);
                if is_angle(j) {
                    axis.dot(&(ab - aa)) + axis_dot.dot(&(wb - wa))
                } else {
                    // material accelerations of the joint points
                    let acc = |p: &Pose<T>, w: &Vector3<T>, al: &Vector3<T>, at: &Vector3<T>| {
                        let r = at - p.x;
                        p.xddot + al.cross(&r) + w.cross(&w.cross(&r))
                    };
                    let axis_ddot = aa.cross(&axis) + wa.cross(&axis_dot);
                    let d = pb - pa;
                    let d_dot = b.velocity_at(&pb) - a.velocity_at(&pa);
                    let d_ddot = acc(b, &wb, &ab, &pb) - acc(a, &wa, &aa, &pa);
                    axis_ddot.dot(&d) + axis_dot.dot(&d_dot) * c(2.0) + axis.dot(&d_ddot)
                }
            }
            _ => unreachable!("a servo follows a position-level quantity"),
        }
    }

    /// Adds the generalized force of actuator input `u` on `target` to the node rows.
    fn actuate<T: RealField + Copy>(&self, target: &Target, poses: &[Pose<T>], u: T, r: &mut [T]) {
        // the slot of a node and `u` times a direction fixed in space or turning with it
        let along = |node: &NodeId, axis: &Vec3, follower: bool| {
            let k = self.slot(Some(*node));
            let p = &poses[k];
            let dir = if follower {
                p.r * vector(axis)
            } else {
                vector(axis)
            };
            (k, p, dir * u)
        };
        match target {
            Target::Force {
                node,
                point,
                axis,
                follower,
            } => {
                let (k, p, f) = along(node, axis, *follower);
                subtract(
                    &mut r[6 * k..6 * k + 6],
                    p.generalized(&f, &p.point(point), 1.0),
                );
            }
            Target::Moment {
                node,
                axis,
                follower,
            } => {
                let (k, p, m) = along(node, axis, *follower);
                subtract(&mut r[6 * k..6 * k + 6], p.generalized_moment(&m, 1.0));
            }
            Target::Joint { joint } => {
                let j = &self.model.joints[joint.0];
                let (ka, kb) = (self.slot(j.node_a), self.slot(j.node_b));
                let (a, b) = (&poses[ka], &poses[kb]);
                let (_, fa, pb, _) = joint_frames(j, a, b);
                let axis = fa.column(2).into_owned() * u;
                if is_angle(j) {
                    subtract(&mut r[6 * kb..6 * kb + 6], b.generalized_moment(&axis, 1.0));
                    subtract(
                        &mut r[6 * ka..6 * ka + 6],
                        a.generalized_moment(&axis, -1.0),
                    );
                } else {
                    subtract(&mut r[6 * kb..6 * kb + 6], b.generalized(&axis, &pb, 1.0));
                    subtract(&mut r[6 * ka..6 * ka + 6], a.generalized(&axis, &pb, -1.0));
                }
            }
        }
    }

    /// The physical residual `[r (6 per slot); e (one per unknown)]` at the poses, states
    /// `x`, rates `xdot`, time `t`, with the blocks' parameters from `param(block, k)`.
    fn residual<T: Scalar>(
        &self,
        poses: &[Pose<T>],
        (x, xdot): (&[T], &[T]),
        (t, reactions): (f64, &[f64]),
        param: &dyn Fn(usize, usize) -> T,
        phase: Phase,
    ) -> Vec<T> {
        let sys = self.system;
        let ns = 6 * self.slots.len();
        let zero = c::<T>(0.0);
        let mut out = vec![zero; ns + sys.n_unknowns];
        let (nodes, e) = out.split_at_mut(ns);
        for (b, block) in sys.blocks.iter().enumerate() {
            let p = |k: usize| param(b, k);
            // input i: the output of another block (no copy: read in place)
            let u = |i: usize| x[sys.unknown(block.inputs[i])];
            let (s0, y0) = (sys.state_start[b], sys.output_start[b]);
            let xs = &x[s0..y0];
            let xd = &xdot[s0..y0];
            let ys = &x[y0..y0 + block.kind.n_outputs()];
            // Rows: e[s0 + k] for states (rate minus f), e[y0 + k] for outputs (y minus h).
            macro_rules! state {
                ($k:expr, $f:expr) => {{
                    let f = $f;
                    e[s0 + $k] = xd[$k] - f;
                }};
                // `T xdot = f`, written multiplied by the time constant `T` (a row of
                // entries T, 1 rather than 1, 1/T: well scaled for a fast filter)
                ($k:expr, $f:expr, $t:expr) => {{
                    let f = $f;
                    e[s0 + $k] = $t * xd[$k] - f;
                }};
            }
            match &block.kind {
                BlockKind::Source(f) => {
                    // f(t) is linear in its amplitudes (the parameters): their derivative
                    let value = (0..f.amplitude_count()).fold(c::<T>(f.eval(t).0), |v, k| {
                        let g = f.amplitude_derivative(k, t).0;
                        v + (p(k) - c(block.value(k))) * c(g)
                    });
                    e[y0] = ys[0] - value;
                }
                BlockKind::Gain { rows, cols } => {
                    for i in 0..*rows {
                        let h = (0..*cols).fold(zero, |acc, j| acc + p(i * cols + j) * u(j));
                        e[y0 + i] = ys[i] - h;
                    }
                }
                BlockKind::Sum { signs } => {
                    let h = signs
                        .iter()
                        .enumerate()
                        .fold(zero, |acc, (i, &s)| acc + u(i) * c(s));
                    e[y0] = ys[0] - h;
                }
                BlockKind::Product { .. } => {
                    e[y0] = ys[0] - (0..block.inputs.len()).fold(c(1.0), |acc, i| acc * u(i));
                }
                BlockKind::Integrator => {
                    state!(0, p(0) * u(0));
                    e[y0] = ys[0] - xs[0];
                }
                BlockKind::Lag => {
                    state!(0, p(0) * u(0) - xs[0], p(1));
                    e[y0] = ys[0] - xs[0];
                }
                BlockKind::Pid => {
                    let (kp, ki, kd, tf) = (p(0), p(1), p(2), p(3));
                    let v = kp * u(0) + ki * xs[0] + kd * (u(0) - xs[1]) / tf;
                    let sat = clamp(v, p(4), p(5));
                    state!(0, u(0) + p(6) * (sat - v));
                    state!(1, u(0) - xs[1], tf);
                    e[y0] = ys[0] - sat;
                }
                BlockKind::StateSpace {
                    states: n,
                    inputs: m,
                    outputs: q,
                } => {
                    let (n, m, q) = (*n, *m, *q);
                    let (a, bm, cm, d) = (0, n * n, n * n + n * m, n * n + n * m + q * n);
                    for i in 0..n {
                        let f = (0..n).fold(zero, |acc, j| acc + p(a + i * n + j) * xs[j])
                            + (0..m).fold(zero, |acc, j| acc + p(bm + i * m + j) * u(j));
                        state!(i, f);
                    }
                    for i in 0..q {
                        let h = (0..n).fold(zero, |acc, j| acc + p(cm + i * n + j) * xs[j])
                            + (0..m).fold(zero, |acc, j| acc + p(d + i * m + j) * u(j));
                        e[y0 + i] = ys[i] - h;
                    }
                }
                BlockKind::TransferFunction { num, den } => {
                    let n = den - 1;
                    let a0 = p(*num);
                    let a = |k: usize| p(num + k) / a0;
                    // numerator padded to degree n: b_k for k = 0..=n
                    let b = |k: usize| {
                        if k + num > n {
                            p(k + num - n - 1) / a0
                        } else {
                            zero
                        }
                    };
                    for k in 0..n {
                        let f = if k + 1 < n {
                            xs[k + 1]
                        } else {
                            u(0) - (0..n).fold(zero, |acc, j| acc + a(n - j) * xs[j])
                        };
                        state!(k, f);
                    }
                    let h = (0..n).fold(b(0) * u(0), |acc, j| {
                        acc + (b(n - j) - a(n - j) * b(0)) * xs[j]
                    });
                    e[y0] = ys[0] - h;
                }
                BlockKind::Saturation => e[y0] = ys[0] - clamp(u(0), p(0), p(1)),
                BlockKind::DeadZone => {
                    let h = if u(0) > p(1) {
                        u(0) - p(1)
                    } else if u(0) < p(0) {
                        u(0) - p(0)
                    } else {
                        zero
                    };
                    e[y0] = ys[0] - h;
                }
                BlockKind::RateLimiter => {
                    state!(0, clamp((u(0) - xs[0]) / p(2), -p(1), p(0)));
                    e[y0] = ys[0] - xs[0];
                }
                BlockKind::Lookup { breakpoints } => {
                    let values: Vec<T> = (0..breakpoints.len()).map(p).collect();
                    e[y0] = ys[0] - interpolate(breakpoints, &values, u(0));
                }
                BlockKind::Hold { .. } => {
                    e[s0] = match phase {
                        Phase::Initial => xs[0] - u(0),
                        _ => xd[0],
                    };
                    e[y0] = ys[0] - xs[0];
                }
                BlockKind::DcMotor => {
                    let (r, l, kt, ke) = (p(0), p(1), p(2), p(3));
                    state!(0, u(0) - r * xs[0] - ke * u(1), l);
                    e[y0] = ys[0] - kt * xs[0];
                }
                BlockKind::Measure(q) => {
                    e[y0] = ys[0] - self.measure(q, poses, ys[0], reactions[b]);
                }
                BlockKind::Actuator(target) => self.actuate(target, poses, u(0), nodes),
                BlockKind::Servo {
                    quantity,
                    target,
                    function,
                } => {
                    // f(t) and f''(t), linear in the amplitudes (the first parameters)
                    let n = function.amplitude_count();
                    let (f0, _, f2) = function.eval(t);
                    let (mut f, mut fdd) = (c::<T>(f0), c::<T>(f2));
                    for k in 0..n {
                        let (g, _, g2) = function.amplitude_derivative(k, t);
                        let dp = p(k) - c(block.value(k));
                        f += dp * c(g);
                        fdd += dp * c(g2);
                    }
                    // position level; for the consistent initial accelerations, acceleration
                    // level where the input enters it (collocated), else u = initial
                    e[y0] = match phase {
                        Phase::Accelerations if ControlSystem::collocated(quantity, target) => {
                            self.second_derivative(quantity, poses) - fdd
                        }
                        Phase::Accelerations => ys[0] - p(n),
                        _ => self.measure(quantity, poses, f, 0.0) - f,
                    };
                    self.actuate(target, poses, ys[0], nodes);
                }
            }
        }
        out
    }

    /// The blocks' parameters as `f64`.
    fn param_f64(&self) -> impl Fn(usize, usize) -> f64 + '_ {
        |b, k| self.system.blocks[b].value(k)
    }

    /// The residual at `f64` and its Jacobian with respect to the variables
    /// (`[18 per slot; x; xdot]`), by one forward pass per variable (`None` columns: the
    /// slot is the ground).
    /// `reactions`: the values of [`ControlElement::reactions`].
    fn jacobian(
        &self,
        ctx: &Context,
        local: &Local,
        phase: Phase,
        reactions: &[f64],
    ) -> (DVector<f64>, DMatrix<f64>) {
        let poses: Vec<Pose<f64>> = local.nodes.iter().map(|n| pose(ctx.group, n)).collect();
        let nv = self.n_variables();
        let n = self.system.n_unknowns;
        let nrows = 6 * self.slots.len() + n;
        let ns = PER_SLOT * self.slots.len();
        let mut jac = DMatrix::zeros(nrows, nv);
        let params = |b: usize, k: usize| Dual64::from_re(self.system.blocks[b].value(k));
        let mut w = vec![Dual64::from_re(0.0); nv];
        for i in 0..n {
            w[ns + i] = Dual64::from_re(local.x[i]);
            w[ns + n + i] = Dual64::from_re(local.xdot[i]);
        }
        let mut value = DVector::zeros(nrows);
        let mut filled = false;
        for j in 0..nv {
            if j < ns && self.slots[j / PER_SLOT].is_none() {
                continue;
            }
            w[j].eps = 1.0;
            let dual: Vec<Pose<Dual64>> = poses
                .iter()
                .enumerate()
                .map(|(k, p)| perturbed(p, &w[PER_SLOT * k..PER_SLOT * (k + 1)]))
                .collect();
            let out = self.residual(
                &dual,
                (&w[ns..ns + n], &w[ns + n..]),
                (ctx.t, reactions),
                &params,
                phase,
            );
            w[j].eps = 0.0;
            for (i, o) in out.iter().enumerate() {
                jac[(i, j)] = o.eps;
                value[i] = o.re;
            }
            filled = true;
        }
        if !filled {
            let out = self.residual(
                &poses,
                (local.x, local.xdot),
                (ctx.t, reactions),
                &self.param_f64(),
                phase,
            );
            value = DVector::from_vec(out);
        }
        (value, jac)
    }

    /// Which slots are nodes.
    fn active(&self) -> Vec<bool> {
        self.slots.iter().map(Option::is_some).collect()
    }

    /// Outputs and held values at `t` from the states in `x` (the outputs' and holds' entries
    /// are the starting guess), by Newton's method on their equations at fixed kinematics,
    /// converged when the largest correction is at most `OUTPUTS_TOLERANCE (1 + |e|)`, `e`
    /// the equations' values before it. Fails as the solver's Newton iterations do, blaming
    /// an output by its index in `x`: a singular matrix (an algebraic loop of gain 1), a
    /// value that is not finite, or no convergence in `OUTPUTS_ITERATIONS` iterations (an
    /// algebraic loop without a solution there).
    fn solve_outputs(
        &self,
        ctx: &Context,
        local: &Local,
        x: &mut [f64],
    ) -> Result<(), NewtonError> {
        let sys = self.system;
        let unknowns: Vec<usize> = (0..sys.n_unknowns)
            .filter(|&i| {
                let b = sys.owner(i);
                match sys.blocks[b].kind {
                    // (its input follows from the mechanics: the initial accelerations)
                    BlockKind::Servo { .. } => false,
                    BlockKind::Hold { .. } => true,
                    _ => sys.is_output(i),
                }
            })
            .collect();
        if unknowns.is_empty() {
            return Ok(());
        }
        let ns = PER_SLOT * self.slots.len();
        let rows = 6 * self.slots.len();
        // the weighted correction of the last iteration and its largest entry
        let mut last = (0.0, 0);
        for _ in 0..OUTPUTS_ITERATIONS {
            let here = Local { x: &*x, ..*local };
            let reactions = self.reactions(ctx, &here);
            let (value, jac) = self.jacobian(ctx, &here, Phase::Initial, &reactions);
            let m = unknowns.len();
            let a = DMatrix::from_fn(m, m, |i, j| jac[(rows + unknowns[i], ns + unknowns[j])]);
            let r = DVector::from_fn(m, |i, _| value[rows + unknowns[i]]);
            if let Some(k) = r.iter().position(|v| !v.is_finite()) {
                return Err(NewtonError::NonFiniteResidual {
                    unknown: unknowns[k],
                });
            }
            let lu = a.lu();
            let Some(dx) = lu.solve(&r) else {
                // (partial pivoting permutes rows only: a zero pivot is in its column)
                let u = lu.u();
                let column = (0..m).find(|&k| u[(k, k)] == 0.0);
                return Err(NewtonError::Singular {
                    unknown: column.map(|k| unknowns[k]),
                    source: LinearError::Singular { column: None },
                });
            };
            if let Some(k) = dx.iter().position(|v| !v.is_finite()) {
                return Err(NewtonError::NonFiniteCorrection {
                    unknown: unknowns[k],
                });
            }
            for (k, &i) in unknowns.iter().enumerate() {
                x[i] -= dx[k];
            }
            let tolerance = OUTPUTS_TOLERANCE * (1.0 + r.amax());
            if dx.amax() <= tolerance {
                return Ok(());
            }
            last = (dx.amax() / tolerance, dx.iamax());
        }
        Err(NewtonError::MaxIterations {
            iterations: OUTPUTS_ITERATIONS,
            error: last.0,
            unknown: unknowns[last.1],
        })
    }
}

/// The blocks on cycles of direct feedthrough (algebraic loops), each cycle once, in the
/// order of the blocks (depth-first search over the feedthrough edges `input -> block`).
pub fn algebraic_loops(system: &ControlSystem) -> Vec<Vec<usize>> {
    let n = system.blocks.len();
    // successors: the feedthrough blocks that read each block
    let mut next = vec![Vec::new(); n];
    for (b, block) in system.blocks.iter().enumerate() {
        if block.kind.feedthrough() {
            for s in &block.inputs {
                next[s.block].push(b);
            }
        }
    }
    let mut loops: Vec<Vec<usize>> = Vec::new();
    // Tarjan's strongly connected components, iteratively
    let (mut index, mut low, mut on) = (vec![usize::MAX; n], vec![0; n], vec![false; n]);
    let (mut stack, mut count) = (Vec::new(), 0);
    for root in 0..n {
        if index[root] != usize::MAX {
            continue;
        }
        let mut work = vec![(root, 0usize)];
        while let Some((v, k)) = work.pop() {
            if k == 0 {
                index[v] = count;
                low[v] = count;
                count += 1;
                stack.push(v);
                on[v] = true;
            }
            if let Some(&w) = next[v].get(k) {
                work.push((v, k + 1));
                if index[w] == usize::MAX {
                    work.push((w, 0));
                } else if on[w] {
                    low[v] = low[v].min(index[w]);
                }
                continue;
            }
            if let Some(&(parent, _)) = work.last() {
                low[parent] = low[parent].min(low[v]);
            }
            if low[v] == index[v] {
                let mut component = Vec::new();
                while let Some(w) = stack.pop() {
                    on[w] = false;
                    component.push(w);
                    if w == v {
                        break;
                    }
                }
                let cyclic = component.len() > 1 || next[v].contains(&v);
                if cyclic {
                    component.sort_unstable();
                    loops.push(component);
                }
            }
        }
    }
    loops.sort();
    loops
}

/// The located reason why the algebraic loop `blocks` of `system` cannot be solved: its
/// first block, and a message naming the loop's blocks, `why`, and what breaks it.
pub fn unsolvable(system: &ControlSystem, blocks: &[usize], why: &str) -> (usize, String) {
    let names: Vec<String> = blocks
        .iter()
        .map(|&b| format!("'{}'", system.blocks[b].name))
        .collect();
    (
        blocks[0],
        format!(
            "the algebraic loop through blocks {} cannot be solved: {why}; break it with a block that has a state (integrator, lag)",
            names.join(", ")
        ),
    )
}

/// Why a loop whose output equations are singular cannot be solved ([`unsolvable`]).
pub const SINGULAR: &str = "its output equations are singular at t = 0 (a loop gain of 1?)";

/// The first of the algebraic `loops` of `model`'s diagram whose output equations are
/// singular at `local` (the control element's local values at the initial state), located
/// as by [`unsolvable`]; `None` when none is. `crate::solve::initial::unsolvable_loop` builds
/// the initial state and calls it.
pub fn singular_loop(
    model: &Model,
    element: &ControlElement,
    local: &Local,
    loops: &[Vec<usize>],
) -> Option<(usize, String)> {
    let system = &model.control;
    let ctx = Context::at(model, 0.0, 1.0);
    let reactions = element.reactions(&ctx, local);
    let (_, jac) = element.jacobian(&ctx, local, Phase::Initial, &reactions);
    let (rows, ns) = (6 * element.slots.len(), PER_SLOT * element.slots.len());
    for blocks in loops {
        let outputs: Vec<usize> = blocks
            .iter()
            .flat_map(|&b| {
                let y0 = system.output_start[b];
                y0..y0 + system.blocks[b].kind.n_outputs()
            })
            .collect();
        let m = outputs.len();
        let a = DMatrix::from_fn(m, m, |i, j| jac[(rows + outputs[i], ns + outputs[j])]);
        let svd = a.singular_values();
        let (smax, smin) = (svd.max(), svd.min());
        // (a NaN singular value counts as singular)
        if smin.is_nan() || smin <= 1e-10 * smax.max(1.0) {
            return Some(unsolvable(system, blocks, SINGULAR));
        }
    }
    None
}

impl ElementKernel for ControlElement<'_> {
    fn n_slots(&self) -> usize {
        self.slots.len()
    }

    fn node(&self, k: usize) -> Option<NodeId> {
        // (a diagram without measurements or actuators has no slots)
        self.slots.get(k).copied().flatten()
    }

    fn n_states(&self) -> usize {
        self.system.n_unknowns
    }

    fn is_algebraic(&self, i: usize) -> bool {
        self.system.is_output(i)
    }

    fn multiplier_rows(&self) -> &[usize] {
        self.rows
    }

    fn state_reads(&self) -> &[usize] {
        self.states
    }

    fn initial_states(&self, ctx: &Context, local: &Local, x: &mut [f64]) -> InitialStates {
        let sys = self.system;
        for (b, block) in sys.blocks.iter().enumerate() {
            let s0 = sys.state_start[b];
            let initial = |name: &str| block.param(name).unwrap_or(0.0);
            match &block.kind {
                BlockKind::Integrator | BlockKind::Lag => x[s0] = initial("initial"),
                BlockKind::StateSpace { states, .. } => {
                    for k in 0..*states {
                        x[s0 + k] = initial(&format!("x0[{k}]"));
                    }
                }
                BlockKind::Servo { .. } => x[sys.output_start[b]] = initial("initial"),
                _ => {}
            }
        }
        // Measured angles start on the branch of the geometric angle.
        self.solve_outputs(ctx, local, x)
    }

    fn evaluate(
        &self,
        ctx: &Context,
        local: &Local,
        r: &mut LocalVector,
        s: Option<(&Coefficients, &mut LocalMatrix)>,
    ) {
        let group = ctx.group;
        let nslots = self.slots.len();
        let (rows, n) = (6 * nslots, self.system.n_unknowns);
        let active = self.active();
        let Some((coef, s)) = s else {
            let poses: Vec<Pose<f64>> = local.nodes.iter().map(|n| pose(group, n)).collect();
            let out = self.residual(
                &poses,
                (local.x, local.xdot),
                (ctx.t, &self.reactions(ctx, local)),
                &self.param_f64(),
                Phase::of(ctx),
            );
            let rp = DVector::from_column_slice(&out[..rows]);
            physical::to_group(group, local.nodes, &active, &rp, None, None, r, None);
            r.rows_mut(rows, n).copy_from_slice(&out[rows..]);
            r.rows_mut(rows + n, self.rows.len() + self.states.len())
                .fill(0.0);
            return;
        };
        // the measured constraint and section forces: values and derivative rows
        let mut reactions = vec![0.0; self.system.blocks.len()];
        let mut reaction_rows = Vec::new();
        for (b, block) in self.system.blocks.iter().enumerate() {
            if let BlockKind::Measure(q) = &block.kind {
                if q.is_reaction() {
                    let (value, d) = self.reaction(ctx, local, q, Some(coef));
                    reactions[b] = value;
                    reaction_rows.extend(d.map(|d| (self.system.output_start[b], d)));
                }
            }
        }
        let (value, jac) = self.jacobian(ctx, local, Phase::of(ctx), &reactions);
        let ns = PER_SLOT * nslots;
        let rp = value.rows(0, rows).into_owned();
        let node_block = |offset: usize| {
            DMatrix::from_fn(rows, rows, |i, j| {
                jac[(i, PER_SLOT * (j / 6) + offset + j % 6)]
            })
        };
        let k_p = node_block(0);
        physical::to_group(
            group,
            local.nodes,
            &active,
            &rp,
            Some(&k_p),
            None,
            r,
            Some((coef, s)),
        );
        r.rows_mut(rows, n).copy_from(&value.rows(rows, n));
        let mut s = s.view();
        // State columns: x dr/dx (outputs: y dr/dy) + xdot dr/dxdot, node rows in group
        // coordinates.
        let column_factor = |j: usize| {
            if self.system.is_output(j) {
                coef.y
            } else {
                coef.x
            }
        };
        for j in 0..n {
            let (fx, fxd) = (column_factor(j), coef.xdot);
            let mut col = DVector::from_fn(rows + n, |i, _| {
                jac[(i, ns + j)] * fx + jac[(i, ns + n + j)] * fxd
            });
            physical::translations_to_group(
                group,
                local.nodes,
                &active,
                &mut col.rows_mut(0, rows),
            );
            s.view_mut((0, rows + j), (rows + n, 1)).copy_from(&col);
        }
        // State rows, node columns.
        for i in 0..n {
            for k in 0..nslots {
                let block = if active[k] {
                    let part = |o: usize| {
                        RowVector6::from_fn(|_, m| jac[(rows + i, PER_SLOT * k + o + m)])
                    };
                    physical::row_to_group(
                        group,
                        &local.nodes[k],
                        (part(0), part(6), part(12)),
                        coef,
                    )
                } else {
                    RowVector6::zeros()
                };
                s.view_mut((rows + i, 6 * k), (1, 6)).copy_from(&block);
            }
        }
        // The columns and rows of the multipliers and other states read: zero but for the
        // measured reactions', whose output rows (e = y - m) take -dm from the joint's,
        // beam's or contact's own kernel.
        let nm = self.rows.len() + self.states.len();
        r.rows_mut(rows + n, nm).fill(0.0);
        s.columns_mut(rows + n, nm).fill(0.0);
        s.rows_mut(rows + n, nm).fill(0.0);
        for (i, d) in &reaction_rows {
            let mut out = s.row_mut(rows + i);
            out -= d.transpose();
        }
        // A hold keeps its value in statics ([`Coefficients::holds_states`]).
        if coef.holds_states() {
            for (b, block) in self.system.blocks.iter().enumerate() {
                if matches!(block.kind, BlockKind::Hold { .. }) {
                    let i = rows + self.system.state_start[b];
                    s[(i, i)] = coef.x;
                }
            }
        }
    }

    fn update_states(&self, ctx: &Context, start: &Local, end: &Local, x: &mut [f64]) {
        // the copies whose derivatives the sensitivities follow, from the end's values
        for (target, source) in self.event_map(ctx, start, end).unwrap_or_default() {
            x[target] = end.x[source];
        }
    }

    fn event_map(&self, ctx: &Context, _start: &Local, _end: &Local) -> Option<HeldStates> {
        // A hold's sample (its only event, at fixed times): the held value and the output
        // that equals it take the input's ([`ElementKernel::update_states`]).
        let sys = self.system;
        let mut map = HeldStates::new();
        for (b, block) in sys.blocks.iter().enumerate() {
            if let BlockKind::Hold { period } = block.kind {
                if on_sample(ctx.t, period) {
                    let u = sys.unknown(block.inputs[0]);
                    map.extend([(sys.state_start[b], u), (sys.output_start[b], u)]);
                }
            }
        }
        Some(map)
    }

    fn event(&self, ctx: &Context, _start: &Local, _end: &Local) -> Option<String> {
        self.system
            .blocks
            .iter()
            .find_map(|block| match block.kind {
                BlockKind::Hold { period } if on_sample(ctx.t, period) => {
                    Some(format!("hold '{}' samples", block.name))
                }
                _ => None,
            })
    }

    fn step_limit(&self, ctx: &Context, _start: &Local, _end: &Local, h: f64) -> Option<StepLimit> {
        let (t0, t1) = (ctx.t - h, ctx.t);
        let mut limit: Option<StepLimit> = None;
        for block in &self.system.blocks {
            let BlockKind::Hold { period } = block.kind else {
                continue;
            };
            let tol = SAMPLE_TOLERANCE * period;
            // the first sample after the start of the step
            let next = ((t0 + tol) / period).floor() * period + period;
            let this = if t1 > next + tol {
                StepLimit::Retry(next - t0)
            } else {
                let after = if on_sample(t1, period) {
                    period
                } else {
                    next - t1
                };
                StepLimit::Next(after)
            };
            limit = StepLimit::stricter(limit, Some(this));
        }
        limit
    }
}

/// Relative tolerance (of the period) within which a time is a sample instant.
const SAMPLE_TOLERANCE: f64 = 1e-9;

/// Whether `t` is a sample instant of a hold with `period`.
fn on_sample(t: f64, period: f64) -> bool {
    let k = (t / period).round();
    (t - k * period).abs() <= SAMPLE_TOLERANCE * period
}

impl ElementParameters for ControlElement<'_> {
    type Param = ControlWrt;

    fn parameter_derivative(
        &self,
        ctx: &Context,
        wrt: ControlWrt,
        local: &Local,
        dr: &mut LocalVector,
    ) -> DerivativeMethod {
        let p = match wrt {
            ControlWrt::Block(p) => p,
            ControlWrt::Section(e, sp) => {
                // sigma = C epsilon is linear in the stiffness entries: d sigma = E epsilon,
                // E the unit symmetric matrix of the entry; the other section parameters
                // (mass, damping) do not enter the elastic stress resultants
                dr.fill(0.0);
                if let SectionParam::Stiffness(i, j) = sp {
                    let beam = &self.model.beams[e];
                    let b = self.beam_pair(beam, local);
                    let eps = beam.state(&b).strain;
                    let rows = 6 * self.slots.len();
                    for (k, block) in self.system.blocks.iter().enumerate() {
                        if let BlockKind::Measure(Quantity::SectionForce { beam, component }) =
                            block.kind
                        {
                            if beam == e {
                                let mut d = if component == i { eps[j] } else { 0.0 };
                                if component == j && i != j {
                                    d += eps[i];
                                }
                                dr[rows + self.system.output_start[k]] = -d;
                            }
                        }
                    }
                }
                return DerivativeMethod::Analytic;
            }
            ControlWrt::Contact(i, cp) => {
                // the contact's own derivative of its force on node B, along each measuring
                // block's direction (dm/dp = -a . dg/dp, so de/dp = a . dg/dp)
                dr.fill(0.0);
                let (element, inputs, ..) = self.contact_local(i, local);
                let mut d = DVector::zeros(element.n_local());
                let method =
                    element.parameter_derivative(ctx, cp, &inputs.local(), &mut d.as_view_mut());
                let dg = Vec3::new(d[6], d[7], d[8]);
                let rb = inputs.nodes[1].q.r;
                let rows = 6 * self.slots.len();
                for (k, block) in self.system.blocks.iter().enumerate() {
                    if let BlockKind::Measure(Quantity::ContactForce { contact, axis }) =
                        &block.kind
                    {
                        if *contact == i {
                            let w = match ctx.group {
                                flexmb_lie::Group::SE3 => rb.transpose() * axis,
                                flexmb_lie::Group::R3xSO3 => *axis,
                            };
                            dr[rows + self.system.output_start[k]] = w.dot(&dg);
                        }
                    }
                }
                return method;
            }
            ControlWrt::Joint(j, jp) => {
                // the joint's frames enter the measurements and actuators along it: central
                // difference on copies of the model
                let value = jp.get(&self.model.joints[j.0], &self.model.nodes);
                let h = super::FD_STEP * value.abs().max(self.model.extent().max(1.0));
                let r = |v: f64| {
                    let mut model = self.model.clone();
                    jp.set(&mut model.joints[j.0], &self.model.nodes, v);
                    let moved = ControlElement {
                        model: &model,
                        ..*self
                    };
                    super::evaluate_owned(&moved, ctx, local, None).0
                };
                dr.copy_from(&((r(value + h) - r(value - h)) / (2.0 * h)));
                return DerivativeMethod::FiniteDifference;
            }
        };
        let poses: Vec<Pose<Dual64>> = local
            .nodes
            .iter()
            .map(|n| {
                let p = pose(ctx.group, n);
                perturbed(&p, &[Dual64::from_re(0.0); PER_SLOT])
            })
            .collect();
        let x: Vec<Dual64> = local.x.iter().map(|&v| Dual64::from_re(v)).collect();
        let xdot: Vec<Dual64> = local.xdot.iter().map(|&v| Dual64::from_re(v)).collect();
        let params = |b: usize, k: usize| {
            let v = Dual64::from_re(self.system.blocks[b].value(k));
            if (b, k) == (p.block, p.index) {
                Dual64::new(v.re, 1.0)
            } else {
                v
            }
        };
        let reactions = self.reactions(ctx, local);
        let out = self.residual(
            &poses,
            (&x, &xdot),
            (ctx.t, &reactions),
            &params,
            Phase::of(ctx),
        );
        let rows = 6 * self.slots.len();
        let d = DVector::from_fn(rows, |i, _| out[i].eps);
        physical::to_group(
            ctx.group,
            local.nodes,
            &self.active(),
            &d,
            None,
            None,
            dr,
            None,
        );
        for (i, o) in out[rows..].iter().enumerate() {
            dr[rows + i] = o.eps;
        }
        DerivativeMethod::Analytic
    }
}
