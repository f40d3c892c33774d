//! Start of an analysis: redundant constraints, consistency of the initial conditions and
//! consistent initial accelerations.
//!
//! * Redundant rows: in a model whose joint graph has a closed loop, the rows of `B(q0)` are
//!   tested for linear dependence by a QR factorization with column pivoting of `B^T`;
//!   dependent rows are removed from the unknowns (their multipliers stay 0). A mechanism such
//!   as Bricard's, whose constraints are redundant at every configuration, then runs.
//! * Consistency: `|Phi(q0, 0)|` and `|B v0 + Phi_t|` must vanish within a tolerance;
//!   otherwise the joint and row are named.
//! * Accelerations: `[M B^T; B 0] [vdot0; lambda0] = -[r(q0, v0, 0); v0^T H v0 + 2 B_t v0 + Phi_tt]`
//!   (Arnold & Brüls 2007, Sect. 3: the generalized-alpha scheme starts from `a0 = vdot0`).

use crate::assembly::{assemble, ConstraintRhs, Scaling};
use crate::data::{Data, Layout};
use crate::elements::{Coefficients, NodeState};
use crate::error::SolveError;
use crate::joints;
use crate::model::Model;
use crate::state::State;
use flexmb_lie::Mat6;
use nalgebra::DMatrix;

/// Position-level tolerance of the initial configuration [m, or dimensionless for angles].
pub const POSITION_TOLERANCE: f64 = 1e-6;
/// Velocity-level tolerance of the initial velocities [m/s or rad/s].
pub const VELOCITY_TOLERANCE: f64 = 1e-6;
/// Relative size of a pivot below which a constraint row counts as redundant.
pub const RANK_TOLERANCE: f64 = 1e-9;

/// Whether the joints (with the ground as one vertex) close a loop.
fn has_closed_loop(model: &Model) -> bool {
    let n = model.nodes.len() + 1;
    let ground = n - 1;
    let mut parent: Vec<usize> = (0..n).collect();
    fn find(p: &mut [usize], mut i: usize) -> usize {
        while p[i] != i {
            p[i] = p[p[i]];
            i = p[i];
        }
        i
    }
    for j in &model.joints {
        let a = j.node_a.map_or(ground, |x| x.0);
        let b = j.node_b.map_or(ground, |x| x.0);
        let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
        if ra == rb {
            return true;
        }
        parent[ra] = rb;
    }
    false
}

/// Dense constraint matrix `B(q)` (`n_rows x n_dofs`) at the model's initial configuration.
fn constraint_matrix(model: &Model, layout: &Layout) -> DMatrix<f64> {
    let mut b = DMatrix::zeros(layout.n_rows, layout.n_dofs);
    let nodes: Vec<NodeState> = model
        .nodes
        .iter()
        .map(|n| NodeState::ground(n.frame))
        .collect();
    for (j, joint) in model.joints.iter().enumerate() {
        let slots = [joint.node_a, joint.node_b];
        let pair = [
            slots[0].map_or(NodeState::ground(Default::default()), |n| nodes[n.0]),
            slots[1].map_or(NodeState::ground(Default::default()), |n| nodes[n.0]),
        ];
        for (r, row) in layout.joint_rows[j].iter().enumerate() {
            let rv = joints::evaluate_row(model.group, joint, *row, &pair, 0.0);
            for (k, slot) in slots.iter().enumerate() {
                if let Some(n) = slot {
                    for i in 0..6 {
                        b[(layout.joint_row_start[j] + r, 6 * n.0 + i)] += rv.b[6 * k + i];
                    }
                }
            }
        }
    }
    b
}

/// Layout of the unknowns with redundant constraint rows removed; also returns a warning
/// per removed row.
pub fn prepare_layout(model: &Model) -> (Layout, Vec<String>) {
    let mut layout = Layout::new(model);
    let mut warnings = Vec::new();
    if layout.n_rows == 0 || !has_closed_loop(model) {
        return (layout, warnings);
    }
    let b = constraint_matrix(model, &layout);
    let qr = b.transpose().col_piv_qr();
    let r = qr.r();
    let k = r.nrows().min(r.ncols());
    let scale = (0..k).map(|i| r[(i, i)].abs()).fold(0.0, f64::max);
    let rank = (0..k)
        .take_while(|&i| r[(i, i)].abs() > RANK_TOLERANCE * scale)
        .count();
    if rank == layout.n_rows {
        return (layout, warnings);
    }
    // Order of the rows after pivoting: the first `rank` are independent.
    let mut order = DMatrix::from_fn(1, layout.n_rows, |_, j| j as f64);
    qr.p().permute_columns(&mut order);
    let redundant: Vec<usize> = (rank..layout.n_rows)
        .map(|i| order[(0, i)] as usize)
        .collect();
    for &row in &redundant {
        let (j, r) = locate_row(&layout, row);
        warnings.push(format!(
            "joint '{}' ({}): constraint row {} ({:?}) is redundant and was removed; its reaction is carried by the other joints of the loop",
            model.joints[j].name,
            model.joints[j].kind.name(),
            r + 1,
            layout.joint_rows[j][r]
        ));
    }
    layout.deactivate_rows(model, &redundant);
    (layout, warnings)
}

/// `(joint, row within joint)` of a global row index.
pub fn locate_row(layout: &Layout, row: usize) -> (usize, usize) {
    let j = layout.joint_row_start.partition_point(|&s| s <= row) - 1;
    (j, row - layout.joint_row_start[j])
}

/// Loads a state into the node kinematics of `data` (tangent operators set to identity).
pub fn load_nodes(state: &State, data: &mut Data) {
    for (i, n) in data.nodes.iter_mut().enumerate() {
        n.q = state.q[i];
        n.v = state.v[i];
        n.vdot = state.vdot[i];
        n.t = Mat6::identity();
    }
}

/// Checks the initial conditions and computes consistent `vdot0`, `a0 = vdot0` and `lambda0`.
pub fn initial_accelerations(
    model: &Model,
    data: &mut Data,
    state: &mut State,
    load_factor: f64,
) -> Result<(), SolveError> {
    load_nodes(state, data);
    for n in data.nodes.iter_mut() {
        n.vdot.fill(0.0);
    }
    let zeros = vec![0.0; data.layout.n_rows];
    let mut sc = Scaling {
        row_scale: 1.0,
        coef: Coefficients::MASS,
        constraint_rhs: ConstraintRhs::Position,
        load_factor,
        regularization: 0.0,
        velocity_scale: 1.0,
        nodal_damping: 0.0,
    };
    assemble(model, data, state.t, &zeros, &sc, false);
    if let Some((row, v)) = worst(&data.phi) {
        if v > POSITION_TOLERANCE {
            let (j, r) = locate_row(&data.layout, row);
            return Err(SolveError::InconsistentInitialConditions(format!(
                "joint '{}' ({}) is violated by {v:.3e} in its row {} ({:?}) at t = {}: the initial positions/orientations of its nodes do not satisfy it (tolerance {POSITION_TOLERANCE:e})",
                model.joints[j].name,
                model.joints[j].kind.name(),
                r + 1,
                data.layout.joint_rows[j][r],
                state.t
            )));
        }
    }
    sc.constraint_rhs = ConstraintRhs::Velocity;
    assemble(model, data, state.t, &zeros, &sc, false);
    let nd = data.layout.n_dofs;
    if let Some((k, v)) = worst(&data.residual[nd..]) {
        if v > VELOCITY_TOLERANCE {
            let desc = data.layout.describe_unknown(model, nd + k);
            return Err(SolveError::InconsistentInitialConditions(format!(
                "initial velocities violate {desc} by {v:.3e} (velocity-level constraint B v + Phi_t, tolerance {VELOCITY_TOLERANCE:e})"
            )));
        }
    }
    sc.constraint_rhs = ConstraintRhs::Acceleration;
    assemble(model, data, state.t, &zeros, &sc, true);
    data.solver.factorize(&data.values).map_err(|e| {
        let col = match e {
            crate::solve::linear::LinearError::Singular { column: Some(c) } => {
                format!("; near {}", data.layout.describe_unknown(model, c))
            }
            _ => String::new(),
        };
        SolveError::Model(format!(
            "the mass/constraint matrix [M B^T; B 0] is singular at t = {}: a node without mass or constraint, or redundant constraints{col} ({e})",
            state.t
        ))
    })?;
    let mut x: Vec<f64> = data.residual.iter().map(|r| -r).collect();
    data.solver.solve_in_place(&mut x);
    if x.iter().any(|v| !v.is_finite()) {
        return Err(SolveError::Model(
            "initial accelerations are not finite".into(),
        ));
    }
    for i in 0..data.layout.n_nodes {
        let acc = flexmb_lie::Vec6::from_column_slice(&x[6 * i..6 * i + 6]);
        state.vdot[i] = acc;
        state.a[i] = acc;
    }
    for (row, slot) in data.layout.row_unknown.iter().enumerate() {
        state.lambda[row] = slot.map_or(0.0, |k| x[nd + k]);
    }
    load_nodes(state, data);
    Ok(())
}

fn worst(v: &[f64]) -> Option<(usize, f64)> {
    v.iter()
        .map(|x| x.abs())
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(&b.1))
}
