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

use super::newton::{
    NewtonError, NewtonPolicy, NewtonSettings, NewtonSolver, NonlinearSystem, Norms,
};
use crate::assembly::{assemble, ConstraintRhs, Iterate, Scaling};
use crate::data::{Block, Data, Layout};
use crate::elements::{Coefficients, NodeState};
use crate::error::SolveError;
use crate::joints;
use crate::model::Model;
use crate::state::State;
use flexmb_lie::Frame;
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

/// Layout of the unknowns with redundant constraint rows removed; also returns a note for
/// the user naming them (`None` when no row is redundant). Redundant rows are expected of a
/// closed loop built with spatial joints (a planar four-bar of revolutes has three per
/// loop): information, not a warning.
pub fn prepare_layout(model: &Model) -> (Layout, Option<String>) {
    let mut layout = Layout::new(model);
    if layout.n_rows == 0 || !has_closed_loop(model) {
        return (layout, None);
    }
    let q0: Vec<Frame> = model.nodes.iter().map(|n| n.frame).collect();
    let (order, rank) = row_order(model, &layout, &q0);
    if rank == layout.n_rows {
        return (layout, None);
    }
    // The first `rank` rows of the pivot order are independent.
    let redundant = &order[rank..];
    let rows: Vec<String> = redundant
        .iter()
        .map(|&row| layout.describe_row(model, row))
        .collect();
    let note = format!(
        "closed loops: {} of the {} constraint rows are redundant and were left out, their reactions carried by the other joints of the loops (the reactions along them are not determined by the equations; flexmb gives the ones with these rows at zero): {}",
        redundant.len(),
        layout.n_rows,
        rows.join("; ")
    );
    layout.deactivate_rows(model, redundant);
    (layout, Some(note))
}

/// Which rows to remove as redundant at the configuration `q`, keeping their number: the
/// last of the pivot order of `row_order`; `None` when that is the set removed already.
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
    (redundant != layout.redundant_rows()).then_some(redundant)
}

/// The consistent initial accelerations as a (linear) system for [`NewtonSolver`]:
/// `[M B^T; B 0] [vdot0; mu0] = -[s r(q0, v0, 0); v0^T H v0 + 2 B_t v0 + Phi_tt]`, with
/// the equilibrium rows divided by the largest nodal mass (multipliers solved for as
/// `mu = lambda / m`): mass and constraint blocks are then both O(1), and a model of heavy
/// bodies is not mistaken for a singular one by the relative pivot test.
struct Accelerations<'a> {
    model: &'a Model,
    nodes: &'a [NodeState],
    /// The elements' initial states, and zero rates.
    states: (&'a [f64], &'a [f64]),
    t: f64,
    sc: Scaling,
    zeros: &'a [f64],
    /// The solution `[vdot0; mu0]` (`n_unknowns`).
    x: Vec<f64>,
}

impl NonlinearSystem for Accelerations<'_> {
    fn assemble(&mut self, data: &mut Data, matrix: bool, _: f64) {
        let it = Iterate {
            nodes: self.nodes,
            t: self.t,
            lambda: self.zeros,
            b_start: &[],
            x: self.states.0,
            xdot: self.states.1,
            inputs: None,
        };
        assemble(self.model, data, &it, &self.sc, matrix);
    }

    fn apply(&mut self, data: &Data) {
        self.x.clone_from(&data.correction);
    }

    /// The system is linear: one exact correction leaves no error.
    fn norms(&self, _: &Data) -> Norms {
        Norms {
            n: 1,
            ..Norms::default()
        }
    }
}

/// The scaling of the system for the initial accelerations (see [`Accelerations`]): rows
/// divided by the largest nodal mass `m`, the matrix `[M B^T 0; B 0 0; E_vd 0 E_xd] / m`,
/// acceleration-level constraint rows.
pub(crate) fn acceleration_scaling(model: &Model, load_factor: f64) -> Scaling {
    let s = 1.0 / mass_scale(model);
    Scaling {
        row_scale: s,
        coef: Coefficients {
            m: s,
            c: 0.0,
            k: 0.0,
            x: 0.0,
            xdot: s,
            y: s,
        },
        constraint_rhs: ConstraintRhs::Acceleration,
        load_factor,
        regularization: 0.0,
        velocity_scale: 1.0,
        nodal_damping: 0.0,
        state_scale: s,
    }
}

/// Checks the initial conditions and computes consistent `vdot0`, `a0 = vdot0` and `lambda0`,
/// and the rates of the element states `xdot0`, `w0 = xdot0` (their equations solved with
/// the accelerations: `[M B^T 0; B 0 0; E_vd 0 E_xd] [vdot0; mu0; xdot0] = -[...]`).
pub fn initial_accelerations(
    model: &Model,
    data: &mut Data,
    state: &mut State,
    load_factor: f64,
) -> Result<(), SolveError> {
    let mut nodes = crate::sensors::node_states(state);
    for n in nodes.iter_mut() {
        n.vdot.fill(0.0);
    }
    let zeros = vec![0.0; data.layout.n_rows];
    let no_rates = vec![0.0; data.layout.n_states];
    let mut sc = acceleration_scaling(model, load_factor);
    let s = sc.row_scale;
    sc.constraint_rhs = ConstraintRhs::Position;
    let mut it = Iterate {
        nodes: &nodes,
        t: state.t,
        lambda: &zeros,
        b_start: &[],
        x: &state.x,
        xdot: &no_rates,
        inputs: None,
    };
    assemble(model, data, &it, &sc, false);
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
    it.nodes = &nodes;
    assemble(model, data, &it, &sc, false);
    let nd = data.layout.n_dofs;
    if let Some((k, v)) = worst(&data.residual[data.layout.block(Block::Multipliers)]) {
        if v > VELOCITY_TOLERANCE {
            let desc = data.layout.describe_unknown(model, nd + k);
            return Err(SolveError::InconsistentInitialConditions(format!(
                "initial velocities violate {desc} by {v:.3e} (velocity-level constraint B v + Phi_t, tolerance {VELOCITY_TOLERANCE:e})"
            )));
        }
    }
    sc.constraint_rhs = ConstraintRhs::Acceleration;
    let mut system = Accelerations {
        model,
        nodes: &nodes,
        states: (&state.x, &no_rates),
        t: state.t,
        sc,
        zeros: &zeros,
        x: Vec::new(),
    };
    let mut newton = NewtonSolver::new(
        NewtonPolicy {
            settings: NewtonSettings {
                max_iterations: 1,
                reuse_jacobian: false,
                ..NewtonSettings::default()
            },
            regularized_solves: 0,
            divergence_rate: f64::INFINITY,
            diverge_after: 1,
            exact_by_size: false,
        },
        false,
    );
    if let Err(failure) = newton.solve(&mut system, data, 0.0) {
        return Err(initial_failure(model, data, state.t, failure.error));
    }
    let x = system.x;
    for i in 0..data.layout.n_nodes {
        let acc = flexmb_lie::Vec6::from_column_slice(&x[6 * i..6 * i + 6]);
        state.vdot[i] = acc;
        state.a[i] = acc;
    }
    for (row, slot) in data.layout.row_unknown.iter().enumerate() {
        state.lambda[row] = slot.map_or(0.0, |k| x[nd + k] / s);
    }
    let solved = &x[data.layout.block(Block::States)];
    for (i, (&v, &algebraic)) in solved.iter().zip(&data.layout.algebraic).enumerate() {
        if algebraic {
            // the value's correction from its initial guess; no rate
            state.x[i] += v;
            state.xdot[i] = 0.0;
            state.w[i] = 0.0;
        } else {
            state.xdot[i] = v;
            state.w[i] = v;
        }
    }
    Ok(())
}

/// The diagnosis of a failed solve for the initial accelerations: for a singular
/// `[M B^T; B 0]`, a node without mass is named only when the unknown blamed belongs to a
/// node whose nodal mass or inertia is zero.
fn initial_failure(model: &Model, data: &Data, t: f64, error: NewtonError) -> SolveError {
    let unknown = error.unknown();
    let message = match (&error, unknown) {
        (NewtonError::Singular { .. }, Some(c)) if c < data.layout.n_dofs && data.nodal_mass[c / 6][c % 6] == 0.0 => format!(
            "the mass/constraint matrix [M B^T; B 0] is singular: node '{}' has no {} and nothing else determines its motion in {} ({error})",
            model.nodes[c / 6].name,
            if c % 6 < 3 { "mass" } else { "rotational inertia" },
            data.layout.describe_unknown(model, c)
        ),
        (NewtonError::Singular { .. }, Some(c)) => format!(
            "the mass/constraint matrix [M B^T; B 0] is singular: the motion of the model is not determined near {}: a node without mass, or constraints that are redundant or contradict each other there ({error})",
            data.layout.describe_unknown(model, c)
        ),
        (NewtonError::Singular { .. }, None) => format!(
            "the mass/constraint matrix [M B^T; B 0] is singular; no unknown can be blamed ({error})"
        ),
        _ => format!("the initial accelerations are not finite ({error})"),
    };
    SolveError::InitialAccelerations {
        t,
        unknown: unknown.map(|i| data.layout.unknown(i)),
        message,
    }
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

/// A located reason why the control diagram of `model` cannot be solved at its initial
/// state: an algebraic loop whose outputs' Newton iteration fails there
/// ([`crate::error::SolveError::InitialStates`]: no convergence, a loop without a
/// solution), or whose equations are singular there (e.g. a loop gain of 1), as the index of
/// a block on it and a message. `None` when every loop can be solved.
pub fn unsolvable_loop(model: &Model) -> Option<(usize, String)> {
    use crate::elements::control::{algebraic_loops, singular_loop, unsolvable, SINGULAR};
    use crate::elements::{ElementRef, Kernel, LocalBuffers};
    let system = &model.control;
    let loops = algebraic_loops(system);
    if loops.is_empty() {
        return None;
    }
    // the initial state of the model: node kinematics, the blocks' states and outputs
    let layout = Layout::new(model);
    let state = match State::initial(model, &layout) {
        Ok(state) => state,
        Err(SolveError::InitialStates {
            error,
            unknown,
            worst_equation,
        }) => {
            // the loop of the output blamed
            let blamed = match unknown {
                Some(crate::error::UnknownId::State { index, .. }) => {
                    Some(system.owner(usize::from(index)))
                }
                _ => None,
            };
            let blocks = loops
                .iter()
                .find(|l| blamed.is_some_and(|b| l.contains(&b)))
                .unwrap_or(&loops[0]);
            return Some(match *error {
                crate::error::NewtonError::Singular { .. } => unsolvable(system, blocks, SINGULAR),
                error => unsolvable(
                    system,
                    blocks,
                    &format!("Newton's method on the outputs at t = 0 fails: {error}; worst equation: {worst_equation}"),
                ),
            });
        }
        Err(e) => return Some((loops[0][0], e.to_string())),
    };
    let control = layout
        .elements
        .iter()
        .position(|e| matches!(e, ElementRef::Control(_)))?;
    let kernel = layout.elements[control].kernel(model);
    let mut buffers = LocalBuffers::default();
    let all = crate::sensors::node_states(&state);
    buffers.gather(
        &kernel,
        &all,
        (&state.x, &state.xdot, layout.state_start[control]),
        &state.lambda,
    );
    let local = buffers.local(&all);
    let Kernel::Control(element) = kernel else {
        return None;
    };
    singular_loop(model, &element, &local, &loops)
}
