//! The derivative of the initial state `s_0` with respect to the parameters.
//!
//! The configuration `q_0` is the model's and depends on no parameter. The velocity `v_0` is
//! the nodes' initial velocities (parameters of role
//! [`crate::model::ParamRole::InitialState`]: on SE(3) the translational part is
//! `R_0^T xdot_0`). The element states `x_0` are [`crate::elements::ElementKernel::initial_states`]
//! of the model (e.g. a Maxwell branch starts unstressed). The accelerations, multipliers
//! and state rates `y = (vdot_0, mu_0, xdot_0)` (for an algebraic state, a control block's
//! output, its value `x_0` in place of its rate) solve the linear system of
//! [`crate::solve::initial_accelerations`] (Arnold & Brüls 2007, Sect. 3),
//!
//! ```text
//! G(y; v_0, x_0, p) = [ s (M vdot_0 + r(q_0, v_0, x_0, xdot_0) + B^T lambda_0) ]
//!                     [ B vdot_0 + v_0^T H v_0 + 2 B_t v_0 + Phi_tt          ] = A y + g = 0,
//!                     [ s e(q_0, v_0, x_0, xdot_0)                           ]
//! ```
//!
//! so that, with `a_0 = vdot_0` and `w_0 = xdot_0`,
//!
//! ```text
//! dy/dp = -A^-1 (dG/dp + dG/dv_0 dv_0/dp + dG/dx_0 dx_0/dp)      at the solution y.
//! ```
//!
//! `dG/dp` of the equilibrium and state rows is [`crate::parameter_derivatives`]; of the
//! acceleration-level constraint rows (joint parameters only) a fourth-order central
//! difference on a copy of the joint. `dG/dv_0` is `s C_t` on the equilibrium and state rows
//! (the assembled damping matrix) and `(H + H^T) v_0 + 2 b_t` on the constraint rows
//! ([`crate::joints::evaluate_row`]); `dG/dx_0` the assembled state columns. `dx_0/dp` is a
//! fourth-order central difference of the initial states of a copy of the model.

use crate::assembly::{assemble, Iterate};
use crate::data::{Block, Data, Layout};
use crate::elements::{Coefficients, NodeState, Vec12};
use crate::joints;
use crate::model::parameters::NodeParam;
use crate::model::{Model, ParamId, ParamKind, ParamRole, Parameters};
use crate::parameter_derivatives::{residual_derivative, Columns, Point};
use crate::solve::step::StateTangent;
use crate::state::State;
use flexmb_lie::{Group, Vec6};

use super::SensitivityError;

/// `ds_0/dp` for each parameter of `ids`, at the consistent initial state `s0` of `model`
/// (rows left out as redundant: `redundant`), loads at `load_factor`.
pub fn initial_tangents(
    model: &Model,
    params: &Parameters,
    ids: &[ParamId],
    s0: &State,
    redundant: &[usize],
    load_factor: f64,
) -> Result<Vec<StateTangent>, SensitivityError> {
    let layout = Layout::with_rows(model, false, redundant);
    let mut data = Data::new(model, layout.clone()).map_err(crate::error::SolveError::from)?;
    let (nd, so) = (layout.n_dofs, layout.state_offset());
    let mut sc = crate::solve::initial::acceleration_scaling(model, load_factor);
    let s = sc.row_scale;
    // The point of the solution: v_0, vdot_0, lambda_0, x_0, xdot_0.
    let nodes = crate::sensors::node_states(s0);
    let it = Iterate {
        nodes: &nodes,
        t: s0.t,
        lambda: &s0.lambda,
        b_start: &[],
        x: &s0.x,
        xdot: &s0.xdot,
        inputs: None,
    };
    // A = dG/dy.
    assemble(model, &mut data, &it, &sc, true);
    let a_values = data.values.clone();
    // dG/dv_0 and dG/dx_0 on the equilibrium and state rows: s C_t on node columns, s dr/dx
    // on state columns.
    sc.coef = Coefficients {
        m: 0.0,
        c: s,
        k: 0.0,
        x: s,
        xdot: 0.0,
        y: 0.0,
    };
    assemble(model, &mut data, &it, &sc, true);
    let element_rows = |i: usize| i < nd || i >= so;
    let rate_columns: Vec<(usize, usize, f64)> = data
        .pattern()
        .into_iter()
        .zip(&data.values)
        .filter(|((i, j), v)| **v != 0.0 && element_rows(*i) && element_rows(*j))
        .map(|((i, j), &v)| (i, j, v))
        .collect();
    data.solver.factorize(&a_values).map_err(|e| {
        SensitivityError::Singular(format!(
            "the matrix of the initial accelerations [M B^T; B 0] ({e})"
        ))
    })?;
    let convective = convective_gradients(model, &layout, &nodes, s0.t);
    let mut out = Vec::with_capacity(ids.len());
    let n_rows = layout.n_rows;
    let mut dr = vec![0.0; nd];
    let (mut dphi, mut de) = (vec![0.0; n_rows], vec![0.0; layout.n_states]);
    let mut dpsi = vec![0.0; n_rows];
    for &id in ids {
        let mut ds = StateTangent::zeros_of(&layout);
        initial_velocity(model, params, id, &mut ds.v);
        if layout.n_states > 0 && params.role(id) == ParamRole::Residual {
            ds.x = initial_states_derivative(model, params, id, &layout)?;
            // the algebraic states are unknowns of the solve, not inputs
            for (d, &algebraic) in ds.x.iter_mut().zip(&layout.algebraic) {
                if algebraic {
                    *d = 0.0;
                }
            }
        }
        let mut g = vec![0.0; layout.n_unknowns()];
        if params.role(id) == ParamRole::Residual {
            let point = Point {
                nodes: &nodes,
                x: &s0.x,
                xdot: &s0.xdot,
                t: s0.t,
                lambda: &s0.lambda,
                load_factor,
                inputs: None,
            };
            let columns = Columns {
                dr: &mut dr,
                dphi: &mut dphi,
                dpsi: &mut dpsi,
                de: &mut de,
            };
            residual_derivative(model, params, id, &point, columns);
            consistent(model, &layout, params, id, &dphi, &dpsi)?;
            for i in 0..nd {
                g[i] += s * dr[i];
            }
            for (i, e) in de.iter().enumerate() {
                g[so + i] += s * e;
            }
            if let ParamKind::Joint(j, _) = params.kind(id) {
                acceleration_rows_derivative(model, params, id, &layout, j.0, &nodes, s0.t, &mut g);
            }
        }
        for &(i, j, v) in &rate_columns {
            let d = if j < nd {
                ds.v[j / 6][j % 6]
            } else {
                ds.x[j - so]
            };
            g[i] += v * d;
        }
        for (k, &row) in layout.active_rows.iter().enumerate() {
            let (slots, grad) = &convective[row];
            g[nd + k] += slots
                .iter()
                .enumerate()
                .filter_map(|(a, n)| n.map(|n| (a, n)))
                .map(|(a, n)| (0..6).map(|c| grad[6 * a + c] * ds.v[n][c]).sum::<f64>())
                .sum::<f64>();
        }
        data.solver.solve_in_place(&mut g);
        for i in 0..layout.n_nodes {
            let d = -Vec6::from_column_slice(&g[6 * i..6 * i + 6]);
            ds.vdot[i] = d;
            ds.a[i] = d;
        }
        for (k, &row) in layout.active_rows.iter().enumerate() {
            ds.lambda[row] = -g[nd + k] / s;
        }
        for (i, d) in g[layout.block(Block::States)].iter().enumerate() {
            if layout.algebraic[i] {
                ds.x[i] = -d;
            } else {
                ds.xdot[i] = -d;
                ds.w[i] = -d;
            }
        }
        out.push(ds);
    }
    Ok(out)
}

/// The initial configuration and velocities do not move with the parameters, so a
/// parameter that changes `Phi(q_0)` or `B v_0 + Phi_t` at t = 0 (a joint's position across
/// its constrained directions, a drive's amplitude with `f(0)` or `f'(0)` nonzero) would make
/// the perturbed initial conditions inconsistent: its derivative is refused.
fn consistent(
    model: &Model,
    layout: &Layout,
    params: &Parameters,
    id: ParamId,
    dphi: &[f64],
    dpsi: &[f64],
) -> Result<(), SensitivityError> {
    let active = |d: &[f64]| {
        layout
            .active_rows
            .iter()
            .map(|&r| (r, d[r].abs()))
            .fold((0, 0.0f64), |w, (r, v)| if v > w.1 { (r, v) } else { w })
    };
    for (d, what) in [(dphi, "position"), (dpsi, "velocity")] {
        let (row, v) = active(d);
        if v > 1e-9 {
            return Err(SensitivityError::Unsupported(format!(
                "parameter '{}' moves the {what}-level constraint {} at t = 0 (by {v:.3e} per unit): the initial conditions, which do not move with it, would become inconsistent; its derivative is not defined",
                params.path(id),
                layout.describe_row(model, row)
            )));
        }
    }
    Ok(())
}

/// `dv_0/dp` of an initial-velocity parameter (zero for the others).
fn initial_velocity(model: &Model, params: &Parameters, id: ParamId, dv: &mut [Vec6]) {
    if let ParamKind::Node(node, p) = params.kind(id) {
        match p {
            NodeParam::Velocity(k) => {
                let e = flexmb_lie::Vec3::ith(k, 1.0);
                let u = match model.group {
                    Group::R3xSO3 => e,
                    Group::SE3 => model.nodes[node.0].frame.r.transpose() * e,
                };
                dv[node.0].fixed_rows_mut::<3>(0).copy_from(&u);
            }
            NodeParam::AngularVelocity(k) => dv[node.0][3 + k] = 1.0,
        }
    }
}

/// `dx_0/dp`: the initial element states of a copy of the model with `id` moved; fails
/// where a moved copy's states cannot be solved.
fn initial_states_derivative(
    model: &Model,
    params: &Parameters,
    id: ParamId,
    layout: &Layout,
) -> Result<Vec<f64>, crate::error::SolveError> {
    let value = params.value(model, id);
    let mut copy = model.clone();
    let eps = 1e-4 * value.abs().max(1e-3);
    let mut failure = None;
    let d = super::fourth_order_difference(eps, &mut |e| {
        params.set(&mut copy, id, value + e);
        match State::initial(&copy, layout) {
            Ok(state) => state.x,
            Err(error) => {
                failure.get_or_insert(error);
                vec![0.0; layout.n_states]
            }
        }
    });
    match failure {
        Some(error) => Err(error),
        None => Ok(d),
    }
}

/// A constraint row's slots (node indices, `None` for the ground) and a gradient on them.
type RowGradient = ([Option<usize>; 2], Vec12);

/// Per constraint row: the slots' nodes and `d(v^T H v + 2 b_t . v)/dv = (H + H^T) v + 2 b_t`
/// (12: node A, node B).
fn convective_gradients(
    model: &Model,
    layout: &Layout,
    nodes: &[NodeState],
    t: f64,
) -> Vec<RowGradient> {
    let ground = NodeState::ground(Default::default());
    let mut out = Vec::with_capacity(layout.n_rows);
    for (j, joint) in model.joints.iter().enumerate() {
        let slots = [joint.node_a.map(|n| n.0), joint.node_b.map(|n| n.0)];
        let pair = slots.map(|s| s.map_or(ground, |n| nodes[n]));
        let mut v = Vec12::zeros();
        for (a, n) in slots.iter().enumerate() {
            if n.is_some() {
                v.fixed_rows_mut::<6>(6 * a).copy_from(&pair[a].v);
            }
        }
        for &row in &layout.joint_rows[j] {
            let value = joints::evaluate_row(model.group, joint, row, &pair, t);
            let grad = (value.h + value.h.transpose()) * v + value.b_t * 2.0;
            out.push((slots, grad));
        }
    }
    out
}

/// Adds `dG/dp` of the acceleration-level rows of joint `j` (scaled rows of the initial
/// system: unscaled) to `g`, for a parameter of that joint: fourth-order central difference
/// of `b . vdot + v^T H v + 2 b_t . v + Phi_tt` on a copy of the joint.
fn acceleration_rows_derivative(
    model: &Model,
    params: &Parameters,
    id: ParamId,
    layout: &Layout,
    j: usize,
    nodes: &[NodeState],
    t: f64,
    g: &mut [f64],
) {
    let ParamKind::Joint(_, p) = params.kind(id) else {
        return;
    };
    let joint = &model.joints[j];
    let ground = NodeState::ground(Default::default());
    let pair = [joint.node_a, joint.node_b].map(|s| s.map_or(ground, |n| nodes[n.0]));
    let (mut v, mut vd) = (Vec12::zeros(), Vec12::zeros());
    for (a, n) in [joint.node_a, joint.node_b].iter().enumerate() {
        if n.is_some() {
            v.fixed_rows_mut::<6>(6 * a).copy_from(&pair[a].v);
            vd.fixed_rows_mut::<6>(6 * a).copy_from(&pair[a].vdot);
        }
    }
    let value = p.get(joint, &model.nodes);
    let eps = 1e-4 * value.abs().max(super::length_scale(model));
    let mut copy = joint.clone();
    let rows = &layout.joint_rows[j];
    let d = super::fourth_order_difference(eps, &mut |e| {
        p.set(&mut copy, &model.nodes, value + e);
        rows.iter()
            .map(|&row| {
                let r = joints::evaluate_row(model.group, &copy, row, &pair, t);
                r.b.dot(&vd) + r.convective(&v)
            })
            .collect()
    });
    let start = layout.joint_row_start[j];
    for (r, dv) in d.iter().enumerate() {
        if let Some(k) = layout.row_unknown[start + r] {
            g[layout.n_dofs + k] += dv;
        }
    }
}
