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
use crate::solve::linear::LinearError;
use crate::state::State;
use flexmb_lie::{Frame, Mat6};
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

/// Dense constraint matrix `B(q)` (`n_rows x n_dofs`) at the node configurations `q`.
fn constraint_matrix(model: &Model, layout: &Layout, q: &[Frame]) -> DMatrix<f64> {
    let mut b = DMatrix::zeros(layout.n_rows, layout.n_dofs);
    let ground = NodeState::ground(Default::default());
    for (j, joint) in model.joints.iter().enumerate() {
        let slots = [joint.node_a, joint.node_b];
        let pair = slots.map(|s| s.map_or(ground, |n| NodeState::ground(q[n.0])));
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

/// The constraint rows ordered from the most to the least independent by a QR factorization
/// with column pivoting of `B(q)^T` (Businger & Golub 1965), and the numerical rank of `B`.
fn row_order(model: &Model, layout: &Layout, q: &[Frame]) -> (Vec<usize>, usize) {
    let b = constraint_matrix(model, layout, q);
    let qr = b.transpose().col_piv_qr();
    let r = qr.r();
    let k = r.nrows().min(r.ncols());
    let scale = (0..k).map(|i| r[(i, i)].abs()).fold(0.0, f64::max);
    let rank = (0..k)
        .take_while(|&i| r[(i, i)].abs() > RANK_TOLERANCE * scale)
        .count();
    let mut order = DMatrix::from_fn(1, layout.n_rows, |_, j| j as f64);
    qr.p().permute_columns(&mut order);
    (
        (0..layout.n_rows).map(|i| order[(0, i)] as usize).collect(),
        rank,
    )
}

/// Layout of the unknowns with redundant constraint rows removed; also returns a warning
/// per removed row.
pub fn prepare_layout(model: &Model) -> (Layout, Vec<String>) {
    let mut layout = Layout::new(model);
    let mut warnings = Vec::new();
    if layout.n_rows == 0 || !has_closed_loop(model) {
        return (layout, warnings);
    }
    let q0: Vec<Frame> = model.nodes.iter().map(|n| n.frame).collect();
    let (order, rank) = row_order(model, &layout, &q0);
    if rank == layout.n_rows {
        return (layout, warnings);
    }
    // The first `rank` rows of the pivot order are independent.
    let redundant = &order[rank..];
    for &row in redundant {
        warnings.push(format!(
            "{} is redundant and was removed; its reaction is carried by the other joints of the loop",
            layout.describe_row(model, row)
        ));
    }
    layout.deactivate_rows(model, redundant);
    (layout, warnings)
}

/// Which rows to remove as redundant at the configuration `q`, keeping their number: the
/// last of the pivot order of [`row_order`]; `None` when that is the set removed already.
///
/// The rows found redundant at the start are independent of the others at the start only:
/// as a closed loop moves, the self-stress of the loop (the left null vector of `B`) can
/// lose its component along a removed row, and the kept rows then lose rank although `B`
/// does not (the Bricard mechanism at the lowest point of P3 when each rod's node sits at
/// its first joint). Choosing the rows again at the current configuration keeps the kept
/// rows a well-conditioned basis for the whole motion.
pub fn reselect_redundant_rows(model: &Model, layout: &Layout, q: &[Frame]) -> Option<Vec<usize>> {
    let count = layout.n_rows - layout.n_active;
    if count == 0 {
        return None;
    }
    let (order, _) = row_order(model, layout, q);
    let mut redundant = order[layout.n_rows - count..].to_vec();
    redundant.sort_unstable();
    let current: Vec<usize> = (0..layout.n_rows)
        .filter(|&r| layout.row_unknown[r].is_none())
        .collect();
    (redundant != current).then_some(redundant)
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
    // Equilibrium rows divided by the largest nodal mass (multipliers solved for as
    // `lambda / m`): mass and constraint blocks are then both O(1), and a model of heavy
    // bodies is not mistaken for a singular one by the relative pivot test.
    let s = 1.0 / mass_scale(model);
    let mut sc = Scaling {
        row_scale: s,
        coef: Coefficients {
            m: s,
            c: 0.0,
            k: 0.0,
        },
        constraint_rhs: ConstraintRhs::Position,
        load_factor,
        regularization: 0.0,
        velocity_scale: 1.0,
        nodal_damping: 0.0,
    };
    assemble(model, data, state.t, &zeros, &sc, false);
    if let Some((row, v)) = worst(&data.phi) {
        if v > POSITION_TOLERANCE {
            return Err(SolveError::InconsistentInitialConditions(format!(
                "{} is violated by {v:.3e} at t = {}: the initial positions/orientations of its nodes do not satisfy it (tolerance {POSITION_TOLERANCE:e})",
                data.layout.describe_row(model, row),
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
    data.solver
        .factorize(&data.values)
        .map_err(|e| singular_mass_matrix(model, data, state.t, e))?;
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
        state.lambda[row] = slot.map_or(0.0, |k| x[nd + k] / s);
    }
    load_nodes(state, data);
    Ok(())
}

/// The diagnosis of a singular `[M B^T; B 0]`: a node without mass is named only when the
/// unknown blamed belongs to a node whose nodal mass or inertia is zero.
fn singular_mass_matrix(model: &Model, data: &Data, t: f64, e: LinearError) -> SolveError {
    let column = match e {
        LinearError::Singular { column } => column,
        LinearError::Factorization(_) => None,
    };
    let nd = data.layout.n_dofs;
    let cause = match column {
        Some(c) if c < nd && data.nodal_mass[c / 6][c % 6] == 0.0 => format!(
            "node '{}' has no {} and nothing else determines its motion in {}",
            model.nodes[c / 6].name,
            if c % 6 < 3 { "mass" } else { "rotational inertia" },
            data.layout.describe_unknown(model, c)
        ),
        Some(c) => format!(
            "the motion of the model is not determined near {}: a node without mass, or constraints that are redundant or contradict each other there",
            data.layout.describe_unknown(model, c)
        ),
        None => "no unknown can be blamed".into(),
    };
    SolveError::Model(format!(
        "the mass/constraint matrix [M B^T; B 0] is singular at t = {t}: {cause} ({e})"
    ))
}

/// Largest nodal mass of the model [kg] (1 if there is none): the scale of the mass block,
/// for scaling the equations and for the regularization of singular iteration matrices.
pub(crate) fn mass_scale(model: &Model) -> f64 {
    let bodies = model.bodies.iter().map(|b| b.mass);
    let beams = model
        .beams
        .iter()
        .map(|b| 0.5 * b.section.mass_per_length * b.length);
    let m = bodies.chain(beams).fold(0.0, f64::max);
    if m > 0.0 {
        m
    } else {
        1.0
    }
}

fn worst(v: &[f64]) -> Option<(usize, f64)> {
    v.iter()
        .map(|x| x.abs())
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(&b.1))
}
