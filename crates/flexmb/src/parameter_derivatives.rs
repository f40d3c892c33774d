//! Derivatives of the equations with respect to model parameters ([`Parameters`]).
//!
//! At a [`Point`]: node kinematics `(q, v, vdot)` (one [`NodeState`] per model node, tangent
//! operators identity), the element states `x` and rates `xdot`, time `t`, multipliers
//! `lambda` (one per constraint row, unscaled) and load factor, the unscaled equations of the
//! time step and of statics are (Brüls & Cardona 2010, Eq. (37); velocity level: Arnold,
//! Brüls & Cardona 2015, Sect. 3)
//!
//! ```text
//! R(p)   = r(q, v, vdot, x, xdot, t; p) + B(q; p)^T lambda   6 per node: equilibrium
//! Phi(p) = Phi(q, t; p)                                n_rows: position level
//! psi(p) = B(q; p) v + Phi_t(q, t; p)                  n_rows: velocity level (stabilized index 2)
//! E(p)   = e(q, v, vdot, x, xdot, t; p)                n_states: the elements' state equations
//! ```
//!
//! with `r = M vdot - hat(v)^T M v + g_int(q, v) - g_ext(q, t)` the sum of the force elements'
//! residuals (gravity and applied loads times the load factor) and the constraint rows in the
//! order of [`crate::joints::rows`], joint after joint (the rows of
//! `crate::data::Layout::joint_row_start`). Each is a sum of local terms,
//!
//! ```text
//! dR/dp   = sum_e L_e^T dr_e/dp + sum_j L_j^T d(B_j^T lambda_j)/dp,
//! dPhi/dp = [ dPhi_j/dp ]_j,     dpsi/dp = [ dB_j/dp v_j + dPhi_t,j/dp ]_j,
//! ```
//!
//! `L_e` gathering an element's two nodes: a parameter reaches only its own item (a body, the
//! elements of a beam, a spring, a load, a joint), except gravity, which reaches every body
//! and beam element. The local derivatives are the capabilities
//! [`ElementParameters`] and [`ConstraintParameters`]: analytic for body mass, centre of mass
//! and inertia, spring stiffness, damping and rest length, every beam section quantity, load
//! components and amplitudes, drive amplitudes and gravity; a central difference on a
//! perturbed copy of the one element or joint for spring attachment points and joint
//! positions ([`DerivativeMethod`] says which). Node velocities
//! ([`crate::model::ParamRole::InitialState`]) enter the initial state only: their
//! derivatives here are zero.
//!
//! [`residual_derivative`] gives the columns of `dR/dp` one parameter at a time;
//! [`residual_derivative_transpose`] the products `J_p^T w` for every parameter at once (what
//! an adjoint needs); [`constraint_force_derivative`] the term `d(B^T w)/dp` alone (the
//! configuration update `q_n exp(dq + B(q_n)^T zeta)` of the stabilized step has it).
//!
//! # References
//! - O. Brüls, A. Cardona, On the use of Lie group time integrators in multibody dynamics,
//!   J. Comput. Nonlinear Dyn. 5 (2010), Eq. (37).
//! - M. Arnold, O. Brüls, A. Cardona, Error analysis of generalized-alpha Lie group time
//!   integration methods for constrained mechanical systems, Numer. Math. 129 (2015), Sect. 3.

use crate::elements::rotational_spring::RotationalSpringElement;
use crate::elements::spring::{SpringElement, SpringElementParam};
use crate::elements::{
    Context, DerivativeMethod, ElementItem, ElementKernel, ElementParameters, LocalBuffers,
    NodeState,
};
use crate::joints::parameters::{ConstraintParameters, JointDerivative};
use crate::joints::{self, Row};
use crate::model::parameters::{ControlWrt, SectionParam};
use crate::model::{Model, NodeId, ParamId, ParamKind, Parameters};
use nalgebra::DVector;

/// One local term of a derivative.
enum Piece<'a> {
    /// `d[r_e; e_e]/dp` of an element on its node slots (6 entries per slot), then its states
    /// (the first of which is state `.1` of the model).
    Element(&'a [Option<NodeId>], usize, &'a [f64]),
    /// The derivatives of joint `j`'s rows.
    Joint(usize, &'a JointDerivative),
}

/// Where the derivatives are taken (module documentation).
#[derive(Clone, Copy, Debug)]
pub struct Point<'a> {
    /// Node kinematics (one per model node, tangent operators identity).
    pub nodes: &'a [NodeState],
    /// The element states and their rates (`n_states` each).
    pub x: &'a [f64],
    pub xdot: &'a [f64],
    /// Time (the load factor in statics).
    pub t: f64,
    /// Multipliers, unscaled (`n_rows`; rows left out as redundant carry 0).
    pub lambda: &'a [f64],
    /// Factor on gravity and loads (1 in dynamics).
    pub load_factor: f64,
    /// The input vector `u` given to the step, or `None` (each input from its function at
    /// `t`; [`crate::elements::Context::inputs`]).
    pub inputs: Option<&'a [f64]>,
}

/// A model and a point.
struct At<'a> {
    model: &'a Model,
    point: &'a Point<'a>,
}

impl At<'_> {
    fn context(&self) -> Context<'_> {
        Context {
            inputs: self.point.inputs,
            ..Context::at(self.model, self.point.t, self.point.load_factor)
        }
    }

    /// The kinematics of two node slots (identity frame at rest for the ground).
    fn pair(&self, slots: [Option<NodeId>; 2]) -> [NodeState; 2] {
        let ground = NodeState::ground(Default::default());
        slots.map(|s| s.map_or(ground, |n| self.point.nodes[n.0]))
    }
}

/// What an element's derivative is taken with respect to.
enum Wrt<P> {
    /// One of its own parameters.
    Own(P),
    /// Component `k` of gravity.
    Gravity(usize),
    /// The value of the input it reads ([`ElementParameters::input_derivative`]).
    Input,
}

/// One element's term (the element and which it is): its derivative at the kinematics of its
/// nodes and its states, to `sink`.
fn element_term<E: ElementParameters>(
    at: &At,
    (e, item): (&E, ElementItem),
    wrt: Wrt<E::Param>,
    sink: &mut dyn FnMut(Piece),
) -> DerivativeMethod {
    let ctx = at.context();
    let slots: Vec<_> = (0..e.n_slots()).map(|k| e.node(k)).collect();
    let mut buffers = LocalBuffers::default();
    let p = at.point;
    let state_start = item.state_start(at.model);
    buffers.gather(e, p.nodes, (p.x, p.xdot, state_start), p.lambda);
    let local = buffers.local(p.nodes);
    let mut d = DVector::zeros(e.n_local());
    let mut dv = d.as_view_mut();
    let method = match wrt {
        Wrt::Own(p) => e.parameter_derivative(&ctx, p, &local, &mut dv),
        Wrt::Gravity(k) => {
            e.gravity_derivative(&ctx, k, &local, &mut dv);
            DerivativeMethod::Analytic
        }
        Wrt::Input => {
            e.input_derivative(&ctx, &local, &mut dv);
            DerivativeMethod::Analytic
        }
    };
    // (no equations for the multipliers an element reads)
    let n = 6 * slots.len() + e.n_states();
    sink(Piece::Element(&slots, state_start, &d.as_slice()[..n]));
    method
}

/// The block diagram's term: the derivative with respect to a block's parameter, or to a
/// parameter of a joint, beam element or contact it measures or acts along. None in a point
/// without states (the constraint forces alone, [`constraint_force_derivative`]).
fn control_term(at: &At, wrt: ControlWrt, sink: &mut dyn FnMut(Piece)) -> DerivativeMethod {
    if at.point.x.is_empty() {
        return DerivativeMethod::Analytic;
    }
    let slots = crate::elements::control::slots(at.model);
    let element = crate::elements::control::ControlElement::new(at.model, &slots);
    element_term(at, (&element, ElementItem::Control), Wrt::Own(wrt), sink)
}

/// Visits the local terms of the derivative with respect to `id`. `rows` and `starts` as
/// from [`joints::row_table`] (may be empty if `id` is not a joint parameter).
fn visit(
    at: &At,
    params: &Parameters,
    id: ParamId,
    (rows, starts): (&[Vec<Row>], &[usize]),
    sink: &mut dyn FnMut(Piece),
) -> DerivativeMethod {
    let model = at.model;
    match params.kind(id) {
        ParamKind::Gravity(k) => {
            for (i, b) in model.bodies.iter().enumerate() {
                element_term(at, (b, ElementItem::Body(i)), Wrt::Gravity(k), sink);
            }
            for (i, b) in model.beams.iter().enumerate() {
                element_term(at, (b, ElementItem::Beam(i)), Wrt::Gravity(k), sink);
            }
            DerivativeMethod::Analytic
        }
        ParamKind::Node(..) => DerivativeMethod::Analytic,
        ParamKind::Body(i, p) => element_term(
            at,
            (&model.bodies[i], ElementItem::Body(i)),
            Wrt::Own(p),
            sink,
        ),
        ParamKind::Beam(item, p) => {
            let mut method = DerivativeMethod::Analytic;
            for &e in params.beam_elements(item) {
                let beam = (&model.beams[e], ElementItem::Beam(e));
                method = element_term(at, beam, Wrt::Own(p), sink);
                // the block diagram measuring the element's section forces
                if model.control.uses_beam(e) {
                    control_term(at, ControlWrt::Section(e, p), sink);
                }
            }
            method
        }
        ParamKind::Load(i, p) => element_term(
            at,
            (&model.loads[i], ElementItem::Load(i)),
            Wrt::Own(p),
            sink,
        ),
        ParamKind::Spring(i, p) if model.spring_law(i).is_some() => element_term(
            at,
            (&SpringElement::of(model, i), ElementItem::Spring(i)),
            Wrt::Own(SpringElementParam::Spring(p)),
            sink,
        ),
        ParamKind::Spring(i, p) => element_term(
            at,
            (&model.springs[i], ElementItem::Spring(i)),
            Wrt::Own(p),
            sink,
        ),
        ParamKind::Rope(i, p) => element_term(
            at,
            (&model.ropes[i], ElementItem::Rope(i)),
            Wrt::Own(p),
            sink,
        ),
        ParamKind::Contact(i, p) => {
            let c = &model.contacts[i];
            let element = crate::elements::contact::ContactElement {
                contact: c,
                effective_mass: crate::elements::contact::effective_mass(model, c.node_a, c.node_b),
            };
            let method = element_term(at, (&element, ElementItem::Contact(i)), Wrt::Own(p), sink);
            // the block diagram measuring the contact's force
            if model.control.uses_contact(i) {
                control_term(at, ControlWrt::Contact(i, p), sink);
            }
            method
        }
        ParamKind::Joint(j, p) => {
            let joint = &model.joints[j.0];
            let (rows, start) = (&rows[j.0], starts[j.0]);
            let nodes = at.pair([joint.node_a, joint.node_b]);
            let (t, lambda) = (at.point.t, &at.point.lambda[start..start + rows.len()]);
            let (d, method) = joint.parameter_derivative(model, rows, p, &nodes, t, lambda);
            sink(Piece::Joint(j.0, &d));
            // the block diagram along the joint
            if model.control.uses_joint(j) {
                control_term(at, ControlWrt::Joint(j, p), sink);
            }
            method
        }
        ParamKind::Gear(i, p) => element_term(
            at,
            (&model.gears[i], ElementItem::Gear(i)),
            Wrt::Own(p),
            sink,
        ),
        ParamKind::SpringLaw(i, p) => element_term(
            at,
            (&SpringElement::of(model, i), ElementItem::Spring(i)),
            Wrt::Own(SpringElementParam::Law(p)),
            sink,
        ),
        ParamKind::RotationalSpring(i, p) => element_term(
            at,
            (
                &RotationalSpringElement::of(model, i),
                ElementItem::RotationalSpring(i),
            ),
            Wrt::Own(p),
            sink,
        ),
        ParamKind::Bushing(i, p) => element_term(
            at,
            (&model.bushings[i], ElementItem::Bushing(i)),
            Wrt::Own(p),
            sink,
        ),
        ParamKind::WormGear(i, p) => element_term(
            at,
            (&model.worm_gears[i], ElementItem::WormGear(i)),
            Wrt::Own(p),
            sink,
        ),
        ParamKind::Control(p) => control_term(at, ControlWrt::Block(p), sink),
    }
}

/// The columns of [`residual_derivative`], overwritten: `dr` (6 per node: equilibrium rows
/// `r + B^T lambda`), `dphi` (`n_rows`: position-level `Phi`), `dpsi` (`n_rows`:
/// velocity-level `B v + Phi_t`; may be empty, then not computed) and `de` (`n_states`: the
/// elements' state equations; may be empty, then not computed).
pub struct Columns<'a> {
    pub dr: &'a mut [f64],
    pub dphi: &'a mut [f64],
    pub dpsi: &'a mut [f64],
    pub de: &'a mut [f64],
}

/// `dR/du_k` of the unscaled equilibrium rows (6 per node, into `dr`) for input `k` of the
/// model ([`crate::model::Input`]) at `point`: the derivative of the load it scales with
/// respect to its value (the residual is linear in it).
pub fn input_derivative(model: &Model, point: &Point, k: usize, dr: &mut [f64]) {
    assert_eq!(dr.len(), 6 * model.nodes.len(), "dr: 6 per node");
    dr.fill(0.0);
    let i = model.inputs[k].load;
    let at = At { model, point };
    let mut sink = |piece: Piece| {
        if let Piece::Element(slots, _, d) = piece {
            scatter(dr, slots, &d[..6 * slots.len()]);
        }
    };
    let item = (&model.loads[i], ElementItem::Load(i));
    element_term(&at, item, Wrt::Input, &mut sink);
}

/// `dR/dp` of the unscaled equations (module documentation) for one parameter at `point`,
/// into `out`. Returns how the local derivatives were obtained.
pub fn residual_derivative(
    model: &Model,
    params: &Parameters,
    id: ParamId,
    point: &Point,
    out: Columns,
) -> DerivativeMethod {
    let Columns { dr, dphi, dpsi, de } = out;
    assert_eq!(dr.len(), 6 * model.nodes.len(), "dr: 6 per node");
    let (rows, starts, n_rows) = match params.kind(id) {
        ParamKind::Joint(..) => joints::row_table(model),
        _ => (Vec::new(), Vec::new(), dphi.len()),
    };
    assert_eq!(dphi.len(), n_rows, "dphi: one per constraint row");
    assert!(
        dpsi.is_empty() || dpsi.len() == n_rows,
        "dpsi: one per constraint row, or none"
    );
    dr.fill(0.0);
    dphi.fill(0.0);
    dpsi.fill(0.0);
    de.fill(0.0);
    let at = At { model, point };
    let mut sink = |piece: Piece| match piece {
        Piece::Element(slots, x_start, d) => {
            scatter(dr, slots, d);
            let states = &d[6 * slots.len()..];
            if !de.is_empty() {
                // (added: the diagram may have a term for each beam element it measures)
                let out = &mut de[x_start..x_start + states.len()];
                out.iter_mut().zip(states).for_each(|(o, s)| *o += s);
            }
        }
        Piece::Joint(j, d) => {
            let joint = &model.joints[j];
            scatter(dr, &[joint.node_a, joint.node_b], d.dforce.as_slice());
            let s = starts[j];
            dphi[s..s + d.n_rows].copy_from_slice(&d.dphi[..d.n_rows]);
            if !dpsi.is_empty() {
                dpsi[s..s + d.n_rows].copy_from_slice(&d.dpsi[..d.n_rows]);
            }
        }
    };
    visit(&at, params, id, (&rows, &starts), &mut sink)
}

/// `d(B(q; p)^T w)/dp` (6 per node, overwritten) for one parameter at the configurations of
/// `nodes` and time `t`, `w` one weight per constraint row: the constraint forces alone.
pub fn constraint_force_derivative(
    model: &Model,
    params: &Parameters,
    id: ParamId,
    nodes: &[NodeState],
    t: f64,
    w: &[f64],
    dforce: &mut [f64],
) {
    assert_eq!(dforce.len(), 6 * model.nodes.len(), "dforce: 6 per node");
    dforce.fill(0.0);
    if !matches!(params.kind(id), ParamKind::Joint(..)) {
        return;
    }
    let (rows, starts, _) = joints::row_table(model);
    let point = Point {
        nodes,
        x: &[],
        xdot: &[],
        t,
        lambda: w,
        load_factor: 1.0,
        inputs: None,
    };
    let at = At {
        model,
        point: &point,
    };
    let mut sink = |piece: Piece| {
        if let Piece::Joint(j, d) = piece {
            let joint = &model.joints[j];
            scatter(dforce, &[joint.node_a, joint.node_b], d.dforce.as_slice());
        }
    };
    visit(&at, params, id, (&rows, &starts), &mut sink);
}

/// The weights of [`residual_derivative_transpose`]: `r` 6 per node, `phi` and `psi` one per
/// constraint row (`psi` may be empty: no velocity-level rows), `e` one per element state
/// (may be empty: no state rows).
#[derive(Clone, Copy, Debug)]
pub struct Weights<'a> {
    pub r: &'a [f64],
    pub phi: &'a [f64],
    pub psi: &'a [f64],
    pub e: &'a [f64],
}

/// `J_p^T w` for every parameter: `grad[k] = w.r . dR/dp_k + w.phi . dPhi/dp_k + w.psi .
/// dpsi/dp_k + w.e . dE/dp_k` (`grad`: one per parameter, overwritten) at `point`. Costs one
/// local derivative per parameter and item, never a dense column.
pub fn residual_derivative_transpose(
    model: &Model,
    params: &Parameters,
    point: &Point,
    w: Weights,
    grad: &mut [f64],
) {
    let ids: Vec<ParamId> = params.ids().collect();
    residual_derivative_transpose_for(model, params, &ids, point, w, grad);
}

/// [`residual_derivative_transpose`] for the parameters `ids` only: `grad[k]` written for
/// them, the other entries left as they are.
pub fn residual_derivative_transpose_for(
    model: &Model,
    params: &Parameters,
    ids: &[ParamId],
    point: &Point,
    w: Weights,
    grad: &mut [f64],
) {
    let (rows, starts, n_rows) = joints::row_table(model);
    assert_eq!(w.r.len(), 6 * model.nodes.len(), "w.r: 6 per node");
    assert_eq!(w.phi.len(), n_rows, "w.phi: one per constraint row");
    assert!(
        w.psi.is_empty() || w.psi.len() == n_rows,
        "w.psi: one per row, or none"
    );
    assert_eq!(grad.len(), params.len(), "grad: one per parameter");
    let at = At { model, point };
    // A beam's section parameters, batched element by element ([`beam_section_vjp`]).
    let (sections, ids) = beam_sections(model, params, ids);
    for (item, ps) in &sections {
        beam_section_vjp(&at, params, (*item, ps), w.r, grad);
    }
    for &id in &ids {
        let mut sum = 0.0;
        let mut sink = |piece: Piece| match piece {
            Piece::Element(slots, x_start, d) => {
                sum += gather_dot(w.r, slots, d);
                if !w.e.is_empty() {
                    let states = &d[6 * slots.len()..];
                    let we = &w.e[x_start..x_start + states.len()];
                    sum += we.iter().zip(states).map(|(a, b)| a * b).sum::<f64>();
                }
            }
            Piece::Joint(j, d) => {
                let joint = &model.joints[j];
                sum += gather_dot(w.r, &[joint.node_a, joint.node_b], d.dforce.as_slice());
                let s = starts[j];
                for r in 0..d.n_rows {
                    sum += w.phi[s + r] * d.dphi[r];
                    if !w.psi.is_empty() {
                        sum += w.psi[s + r] * d.dpsi[r];
                    }
                }
            }
        };
        visit(&at, params, id, (&rows, &starts), &mut sink);
        grad[id.0 as usize] = sum;
    }
}

/// A beam (its index among the beams of [`Parameters`]) and some of its section parameters.
type SectionGroup = (usize, Vec<(SectionParam, ParamId)>);

/// The section parameters of `ids` grouped by beam (those of a beam whose elements a control
/// block measures excepted), and the other parameters.
fn beam_sections(
    model: &Model,
    params: &Parameters,
    ids: &[ParamId],
) -> (Vec<SectionGroup>, Vec<ParamId>) {
    let mut sections: Vec<SectionGroup> = Vec::new();
    let mut rest = Vec::new();
    for &id in ids {
        match params.kind(id) {
            ParamKind::Beam(item, p)
                if !params
                    .beam_elements(item)
                    .iter()
                    .any(|&e| model.control.uses_beam(e)) =>
            {
                match sections.iter_mut().find(|(i, _)| *i == item) {
                    Some((_, ps)) => ps.push((p, id)),
                    None => sections.push((item, vec![(p, id)])),
                }
            }
            _ => rest.push(id),
        }
    }
    (sections, rest)
}

/// `grad[id] = w_r . dR/dp` for section parameters `ps` of beam `item`: each element's
/// kinematics gathered once and its derivatives taken together
/// ([`ElementParameters::parameter_vjp`]).
fn beam_section_vjp(
    at: &At,
    params: &Parameters,
    (item, ps): (usize, &[(SectionParam, ParamId)]),
    w_r: &[f64],
    grad: &mut [f64],
) {
    let ctx = at.context();
    let p = at.point;
    let which: Vec<SectionParam> = ps.iter().map(|&(s, _)| s).collect();
    let mut buffers = LocalBuffers::default();
    let mut out = vec![0.0; ps.len()];
    for &id in ps.iter().map(|(_, id)| id) {
        grad[id.0 as usize] = 0.0;
    }
    for &e in params.beam_elements(item) {
        let beam = &at.model.beams[e];
        let state_start = ElementItem::Beam(e).state_start(at.model);
        buffers.gather(beam, p.nodes, (p.x, p.xdot, state_start), p.lambda);
        let local = buffers.local(p.nodes);
        let mut w = [0.0; 12];
        for (k, slot) in [beam.node(0), beam.node(1)].iter().enumerate() {
            if let Some(n) = slot {
                w[6 * k..6 * k + 6].copy_from_slice(&w_r[6 * n.0..6 * n.0 + 6]);
            }
        }
        beam.parameter_vjp(&ctx, &which, &local, &w, &mut out);
        for (&(_, id), o) in ps.iter().zip(&out) {
            grad[id.0 as usize] += o;
        }
    }
}

/// `dD/dp`: the derivative of the diagonal nodal masses and inertias `D`
/// ([`crate::data::Data::nodal_mass`]: bodies' masses and mean inertias about their nodes, the
/// lumped halves of beam elements) with respect to one parameter, as `(node, dD_node)`
/// pairs (none for a parameter that does not change `D`). The nodal damping `alpha D v` of
/// pseudo-dynamic statics depends on the parameters through it.
pub fn nodal_mass_derivative(
    model: &Model,
    params: &Parameters,
    id: ParamId,
) -> Vec<(NodeId, flexmb_lie::Vec6)> {
    use crate::model::parameters::BodyParam;
    use flexmb_lie::Vec6;
    let split = |m: f64, j: f64| Vec6::new(m, m, m, j, j, j);
    match params.kind(id) {
        ParamKind::Body(i, p) => {
            let b = &model.bodies[i];
            let d = match p {
                // j_o = tr(J) / 3 + m |c|^2 2 / 3
                BodyParam::Mass => split(1.0, b.com.norm_squared() * 2.0 / 3.0),
                BodyParam::Inertia(k) if k < 3 => split(0.0, 1.0 / 3.0),
                BodyParam::Inertia(_) => return Vec::new(),
                BodyParam::Com(k) => split(0.0, b.mass * 4.0 / 3.0 * b.com[k]),
            };
            vec![(b.node, d)]
        }
        ParamKind::Beam(item, p) => {
            let per_length = |b: &crate::model::Beam| match p {
                SectionParam::MassPerLength => Some(split(0.5 * b.length, 0.0)),
                SectionParam::RotaryInertia(i, j) if i == j => {
                    Some(split(0.0, 0.5 * b.length / 3.0))
                }
                _ => None,
            };
            let mut out = Vec::new();
            for &e in params.beam_elements(item) {
                let b = &model.beams[e];
                if let Some(d) = per_length(b) {
                    out.extend(b.nodes.iter().map(|&n| (n, d)));
                }
            }
            out
        }
        _ => Vec::new(),
    }
}

/// Adds a local vector (6 entries per slot) to the rows of its node slots.
fn scatter(out: &mut [f64], slots: &[Option<NodeId>], d: &[f64]) {
    for (k, slot) in slots.iter().enumerate() {
        if let Some(n) = slot {
            for i in 0..6 {
                out[6 * n.0 + i] += d[6 * k + i];
            }
        }
    }
}

/// `w . L^T d` for a local vector on its node slots.
fn gather_dot(w: &[f64], slots: &[Option<NodeId>], d: &[f64]) -> f64 {
    let mut sum = 0.0;
    for (k, slot) in slots.iter().enumerate() {
        if let Some(n) = slot {
            for i in 0..6 {
                sum += w[6 * n.0 + i] * d[6 * k + i];
            }
        }
    }
    sum
}
