//! Assembly of the Newton system from element and joint contributions.
//!
//! The scaled system of one Newton iteration (Brüls & Cardona 2010, Eq. (48); scaling of
//! Bottasso, Bauchau & Cardona 2008) is
//!
//! ```text
//! [ c_m M + c_c C_t + c_k (K_t + K_c) T    B^T ] [ dx  ]     [ s (r + B^T lambda) ]
//! [ B T                                    0   ] [ dmu ] = - [ Phi                ]
//! ```
//!
//! with `s` the row scale (`1/(beta' m)` in dynamics, `m` the largest nodal mass, so that
//! every block stays O(1) as `h -> 0` and whatever the unit of mass), `mu = s lambda` the
//! scaled multipliers, `c_m = s beta'`, `c_c = s gamma'`, `c_k = s`, and
//! `K_c = d(B^T lambda)/dq`. The same routine serves the consistent initial accelerations
//! (`c_m = s = 1/m`, `c_c = c_k = 0`, right-hand side the convective terms) and statics
//! (`c_m = c_c = 0`).
//!
//! **Threads, and why the bits do not depend on them.** With one thread
//! ([`crate::parallel::Threads::sequential`], the setting `threads = 1` or a model below
//! [`crate::parallel::MIN_PARALLEL_ITEMS`] items) one loop visits the elements, then the
//! joints, and adds each contribution to the residual as it comes; rayon is not used. With
//! more, the elements and the joints are cut into leaves of a fixed number of items and
//! evaluated in parallel, each item writing only what is its own:
//!
//! * its matrix entries, into its own range of `Data::values` (the pattern gives every item
//!   a fixed, contiguous range: no sum is made there, the linear solver sums duplicates in
//!   pattern order as before);
//! * its local vector (an element), or its rows of `Phi` and `B` and the right-hand sides of
//!   its constraint equations (a joint), into per-item storage ([`ParallelScratch`]).
//!
//! The only floating-point sums shared between items, the nodes' equations, are then made
//! node by node (in parallel too: a node's sum is its own), each from zero over the node's
//! terms in the order of the sequential loop (its elements in element order, the nodal
//! damping, its joints' rows in joint order) and with the same operations as
//! `add_element`, `add_nodal_damping` and `add_joint`. No sum depends on how the work
//! is cut. Every number is therefore the same bits with 1, 2 or any number of threads
//! (`tests/physics/threads.rs`), and a run keeps its bits when its thread count changes (a resumed
//! checkpoint may use another).

use crate::data::{active_slots, nodal_mass, Data, Layout};
use crate::elements::{
    Coefficients, Context, ElementKernel, Kernel, LocalBuffers, Mat12, NodeState, Vec12,
};
use crate::joints::{self, ConstraintKernel};
use crate::linear::{LinearError, LinearSolver};
use crate::model::{Model, NodeId};
use rayon::prelude::*;

/// What the constraint rows of the right-hand side hold.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ConstraintRhs {
    /// `Phi(q, t)` (position level: time integration, statics).
    Position,
    /// `v^T H v + 2 B_t v + Phi_tt` (acceleration level: consistent initial accelerations).
    Acceleration,
    /// `B v + Phi_t` (velocity level: consistency check of initial velocities).
    Velocity,
}

/// Scaling and coefficients of one assembly.
#[derive(Clone, Copy, Debug)]
pub struct Scaling {
    /// Factor `s` on the equilibrium rows.
    pub row_scale: f64,
    /// Coefficients of the element iteration matrices (scale included).
    pub coef: Coefficients,
    pub constraint_rhs: ConstraintRhs,
    /// Load factor on gravity and applied loads (statics); 1 in dynamics.
    pub load_factor: f64,
    /// `epsilon >= 0` put as `-epsilon` on the diagonal of the constraint block. It makes the
    /// iteration matrix regular at a singular configuration (a transient rank loss of `B`, as
    /// in a four-bar passing its dead point) and tends to the least-norm multipliers; the
    /// residual is unchanged, so a converged solution is exact.
    pub regularization: f64,
    /// Factor on the velocity-level rows of the stabilized formulation (`1/gamma'`).
    pub velocity_scale: f64,
    /// Nodal viscous damping `alpha D v` with `D` the nodal masses and inertias
    /// ([`crate::data::Data::nodal_mass`]) [1/s]: used by pseudo-dynamic static analysis.
    pub nodal_damping: f64,
    /// Factor on the elements' state equations (`h` in dynamics: a state equation written
    /// as a rate then weighs like an increment; `row_scale` elsewhere). The element matrices
    /// come with `row_scale` in their coefficients; their state rows are rescaled.
    pub state_scale: f64,
}

/// The point at which the equations are assembled: every input is explicit, nothing is read
/// from a copy kept elsewhere.
#[derive(Clone, Copy, Debug)]
pub struct Iterate<'a> {
    /// Node kinematics `q, v, vdot` and the tangent operator `T` of each node's increment
    /// (`n_nodes`; `T = I` outside a Newton iteration).
    pub nodes: &'a [NodeState],
    /// Time (the load factor in statics).
    pub t: f64,
    /// Multipliers, unscaled (`n_rows`; redundant rows are ignored).
    pub lambda: &'a [f64],
    /// Rows of `B(q_n)` at the start of the step (`n_rows`): the stabilized formulation's
    /// block of the position rows against the stabilization unknowns. Unused otherwise.
    pub b_start: &'a [Vec12],
    /// The elements' states `x` and rates `xdot` (`n_states` each).
    pub x: &'a [f64],
    pub xdot: &'a [f64],
    /// The input vector `u` ([`crate::model::Input`]) given to the step, or `None`: each
    /// input from its function at `t`.
    pub inputs: Option<&'a [f64]>,
}

/// Where the entries of the iteration matrix go. The same traversal of elements and joints
/// records the sparsity pattern ([`Pattern`]) and writes the values ([`Values`]), so the two
/// cannot disagree on the order of the entries.
pub trait Sink {
    /// Whether element and joint kernels are evaluated (values and residual): `false` when only
    /// the positions of the entries are recorded.
    const EVALUATE: bool;
    /// Whether matrix entries are emitted at all (`false`: residual only).
    const MATRIX: bool;
    /// The entry `(i, j)` with value `v` (in emission order; duplicates are summed).
    fn entry(&mut self, i: usize, j: usize, v: f64);
}

/// Records the positions of the entries.
pub struct Pattern<'a>(pub &'a mut Vec<(usize, usize)>);

impl Sink for Pattern<'_> {
    const EVALUATE: bool = false;
    const MATRIX: bool = true;
    #[inline]
    fn entry(&mut self, i: usize, j: usize, _: f64) {
        self.0.push((i, j));
    }
}

/// Writes values in the order of the pattern recorded by [`Pattern`].
pub struct Values<'a> {
    pub values: &'a mut [f64],
    pub pos: usize,
}

impl Sink for Values<'_> {
    const EVALUATE: bool = true;
    const MATRIX: bool = true;
    #[inline]
    fn entry(&mut self, _: usize, _: usize, v: f64) {
        self.values[self.pos] = v;
        self.pos += 1;
    }
}

/// Entries summed into other positions: entry `e` of the traversal goes to `out[dest[e]]`,
/// or nowhere where `dest[e]` is [`Selected::NONE`] (a selection of the matrix's entries on
/// another matrix's positions).
pub struct Selected<'a> {
    pub dest: &'a [u32],
    pub out: &'a mut [f64],
    pub pos: usize,
}

impl Selected<'_> {
    /// The destination of an entry left out.
    pub const NONE: u32 = u32::MAX;
}

impl Sink for Selected<'_> {
    const EVALUATE: bool = true;
    const MATRIX: bool = true;
    #[inline]
    fn entry(&mut self, _: usize, _: usize, v: f64) {
        let d = self.dest[self.pos];
        if d != Self::NONE {
            self.out[d as usize] += v;
        }
        self.pos += 1;
    }
}

/// Residual only.
pub struct NoMatrix;

impl Sink for NoMatrix {
    const EVALUATE: bool = true;
    const MATRIX: bool = false;
    #[inline]
    fn entry(&mut self, _: usize, _: usize, _: f64) {}
}

/// Outputs of a traversal besides the matrix: the residual (`n_unknowns`), `Phi` and the rows
/// of `B` at the iterate (`n_rows`).
pub struct Outputs<'a> {
    pub residual: &'a mut [f64],
    pub phi: &'a mut [f64],
    pub b_rows: &'a mut [Vec12],
}

impl Scaling {
    /// Unit row scale, no coefficient, no load: the scaling of a traversal that records the
    /// sparsity pattern only.
    pub const NONE: Scaling = Scaling {
        row_scale: 1.0,
        coef: Coefficients {
            m: 0.0,
            c: 0.0,
            k: 0.0,
            x: 0.0,
            xdot: 0.0,
            y: 0.0,
        },
        constraint_rhs: ConstraintRhs::Position,
        load_factor: 1.0,
        regularization: 0.0,
        velocity_scale: 1.0,
        nodal_damping: 0.0,
        state_scale: 1.0,
    };
}

fn gather(
    nodes: &[NodeState],
    slots: [Option<NodeId>; 2],
    ground: &[NodeState; 2],
) -> [NodeState; 2] {
    [
        slots[0].map_or(ground[0], |n| nodes[n.0]),
        slots[1].map_or(ground[1], |n| nodes[n.0]),
    ]
}

/// Fills `data.residual` (and `data.values` if `matrix`), `data.phi` and `data.b_rows` at the
/// iterate `it`, on the threads of `data.threads` (the same bits whatever their number).
pub fn assemble(model: &Model, data: &mut Data, it: &Iterate, sc: &Scaling, matrix: bool) {
    let Data {
        layout,
        values,
        residual,
        phi,
        b_rows,
        nodal_mass,
        local,
        threads,
        derived,
        ..
    } = data;
    let layout: &Layout = layout;
    let pass = Pass::new(model, layout, it, sc);
    let out = Outputs {
        residual,
        phi,
        b_rows,
    };
    if let Some(pool) = threads.pool() {
        let scratch = derived.get_or_insert_with(|| ParallelScratch::new(model, layout));
        let values = matrix.then_some(&mut values[..]);
        traverse_parallel(&pass, nodal_mass, out, scratch, values, pool);
    } else if matrix {
        let mut sink = Values { values, pos: 0 };
        traverse(&pass, nodal_mass, out, local, &mut sink);
        debug_assert_eq!(
            sink.pos,
            sink.values.len(),
            "assembly order differs from the pattern"
        );
    } else {
        traverse(&pass, nodal_mass, out, local, &mut NoMatrix);
    }
}

/// The matrix of the elements alone, once per coefficient set: `sinks[s]` gets every
/// element's entries with the coefficients `coefs[s]` (the other fields of `sc` shared) and
/// the last entries of [`assemble`] (nodal damping, diagonal and, in the stabilized
/// formulation, the velocity-level rows `B` of the last [`assemble`] at the same iterate,
/// kept in `data`), not the joints'. Where the joints have no terms (the matrices of
/// velocities, accelerations and element states: `K_c` comes with the stiffness
/// coefficient, `B` has none), this is the full matrix at the cost of the elements: the step
/// Jacobian's partial derivatives. Sequential; the residual of `data` is left as it was.
pub fn assemble_elements(
    model: &Model,
    data: &mut Data,
    it: &Iterate,
    sc: &Scaling,
    coefs: &[Coefficients],
    sinks: &mut [Selected],
) {
    let n = data.values.len();
    let Data {
        layout,
        b_rows,
        nodal_mass,
        local,
        ..
    } = data;
    let layout: &Layout = layout;
    // where the tail's entries start (the same for every coefficient set)
    let mut count = Count(0);
    tail(
        &Pass::new(model, layout, it, sc),
        nodal_mass,
        b_rows,
        &mut count,
    );
    let tail_start = n - count.0;
    for (&coef, sink) in coefs.iter().zip(sinks.iter_mut()) {
        let pass = Pass::new(model, layout, it, &Scaling { coef, ..*sc });
        sink.pos = 0;
        for e in 0..layout.elements.len() {
            element(&pass, e, local, sink);
        }
        sink.pos = tail_start;
        tail(&pass, nodal_mass, b_rows, sink);
    }
}

impl Data {
    /// Builds the workspaces of `layout`: its sparsity pattern (an assembly pass,
    /// [`pattern`]) and the linear solver on it.
    pub fn new(model: &Model, layout: Layout) -> Result<Self, LinearError> {
        let pattern = pattern(model, &layout);
        let n = layout.n_unknowns();
        let solver = LinearSolver::with_groups(n, &pattern, &layout.groups())?;
        let diagonal_slots = pattern
            .iter()
            .enumerate()
            .filter(|(_, (i, j))| i == j)
            .map(|(k, &(i, _))| (i, k))
            .collect();
        // The solver keeps what it needs of the pattern ([`Data::pattern`]): freed before the
        // values are allocated, it does not add to the peak memory.
        let len = pattern.len();
        drop(pattern);
        Ok(Self {
            values: vec![0.0; len],
            diagonal_slots,
            diagonal: vec![0.0; n],
            residual: vec![0.0; n],
            correction: vec![0.0; n],
            phi: vec![0.0; layout.n_rows],
            nodal_mass: nodal_mass(model),
            b_rows: vec![Vec12::zeros(); layout.n_rows],
            local: Default::default(),
            threads: Default::default(),
            solver,
            layout,
            derived: Default::default(),
        })
    }
}

/// The sparsity pattern of the iteration matrix of `layout`: the traversal of [`assemble`]
/// with no kernel evaluated.
pub fn pattern(model: &Model, layout: &Layout) -> Vec<(usize, usize)> {
    let it = Iterate::NONE;
    let pass = Pass::new(model, layout, &it, &Scaling::NONE);
    let (mut phi, mut b_rows) = (
        vec![0.0; layout.n_rows],
        vec![Vec12::zeros(); layout.n_rows],
    );
    let out = Outputs {
        residual: &mut [],
        phi: &mut phi,
        b_rows: &mut b_rows,
    };
    // Counted first and allocated once (on a 100 000-link chain the pattern is 500 MB).
    let mut count = Count(0);
    let mut buffers = LocalBuffers::default();
    traverse(&pass, &[], out, &mut buffers, &mut count);
    let mut p = Vec::with_capacity(count.0);
    let out = Outputs {
        residual: &mut [],
        phi: &mut phi,
        b_rows: &mut b_rows,
    };
    traverse(&pass, &[], out, &mut buffers, &mut Pattern(&mut p));
    p
}

impl Iterate<'static> {
    /// No kinematics at all: the iterate of a traversal that evaluates nothing.
    const NONE: Self = Iterate {
        nodes: &[],
        t: 0.0,
        lambda: &[],
        b_start: &[],
        x: &[],
        xdot: &[],
        inputs: None,
    };
}

/// What every item of one traversal reads.
struct Pass<'a> {
    model: &'a Model,
    layout: &'a Layout,
    it: Iterate<'a>,
    sc: Scaling,
    ctx: Context<'a>,
    ground: [NodeState; 2],
}

impl<'a> Pass<'a> {
    fn new(model: &'a Model, layout: &'a Layout, it: &Iterate<'a>, sc: &Scaling) -> Self {
        Self {
            model,
            layout,
            it: *it,
            sc: *sc,
            ctx: Context {
                acceleration_level: sc.constraint_rhs == ConstraintRhs::Acceleration,
                inputs: it.inputs,
                ..Context::at(model, it.t, sc.load_factor)
            },
            ground: [NodeState::ground(Default::default()); 2],
        }
    }
}

/// One pass over elements and joints: residual and `Phi` (when `S::EVALUATE`) and the matrix
/// entries in a fixed order (when `S::MATRIX`): for each element its node-node blocks (and
/// its state blocks); for each joint its node-node blocks, then for each active row the row
/// `B T` (row x node dofs) and the column `B^T` (node dofs x row), interleaved; then
/// ([`tail`]) in the stabilized formulation the velocity-level rows `B` and the block
/// `B B_n^T` of the position rows against the stabilization unknowns; last the diagonal of
/// every unknown (nodal damping, and `-epsilon` on the constraint block).
///
/// The residual of a node sums its elements' contributions in the order of the elements,
/// then the nodal damping, then its joints' `B^T lambda` in the order of the joints:
/// [`traverse_parallel`] sums in that order too.
fn traverse<S: Sink>(
    p: &Pass,
    nodal_mass: &[flexmb_lie::Vec6],
    out: Outputs,
    buffers: &mut LocalBuffers,
    sink: &mut S,
) {
    let Outputs {
        residual,
        phi,
        b_rows,
    } = out;
    let layout = p.layout;
    residual.iter_mut().for_each(|r| *r = 0.0);
    for e in 0..layout.elements.len() {
        let kernel = element(p, e, buffers, sink);
        if S::EVALUATE {
            let r = buffers.vector(kernel.n_local());
            add_element(p, &kernel, layout.state_start[e], r, residual);
        }
    }
    if S::EVALUATE {
        add_nodal_damping(p, nodal_mass, residual);
    }
    let (mut rhs, mut vel) = ([0.0; joints::MAX_ROWS], [0.0; joints::MAX_ROWS]);
    for j in 0..p.model.joints.len() {
        let start = layout.joint_row_start[j];
        let n = layout.joint_rows[j].len();
        let rows = start..start + n;
        let out = JointRows {
            phi: &mut phi[rows.clone()],
            b: &mut b_rows[rows.clone()],
            rhs: &mut rhs[..n],
            vel: &mut vel[..n],
        };
        joint(p, j, out, sink);
        if S::EVALUATE {
            add_joint(p, j, &b_rows[rows], &rhs[..n], &vel[..n], residual);
        }
    }
    if S::MATRIX {
        tail(p, nodal_mass, b_rows, sink);
    }
}

/// Element `e` (index in [`Layout::elements`]): evaluated (when `S::EVALUATE`) into
/// `buffers`, where its local vector stays ([`LocalBuffers::vector`]), and its matrix
/// entries emitted (when `S::MATRIX`). Returns its kernel.
#[inline]
fn element<'m, S: Sink>(
    p: &Pass<'m>,
    e: usize,
    buffers: &mut LocalBuffers,
    sink: &mut S,
) -> Kernel<'m> {
    let layout = p.layout;
    let kernel = layout.elements[e].kernel(p.model);
    let x_start = layout.state_start[e];
    let (n_slots, n_states) = (kernel.n_slots(), kernel.n_states());
    let dof = |k: usize| layout.dof(kernel.node(k));
    let it = &p.it;
    if S::EVALUATE {
        buffers.gather(&kernel, it.nodes, (it.x, it.xdot, x_start), it.lambda);
    }
    let (local, mut r, mut se) = buffers.split(kernel.n_local(), it.nodes);
    if S::EVALUATE {
        let matrix = S::MATRIX.then_some((&p.sc.coef, &mut se));
        kernel.evaluate(&p.ctx, &local, &mut r, matrix);
    }
    if S::MATRIX {
        scatter_blocks(sink, n_slots, dof, |i, j| se.get(i, j));
        let ratio = p.sc.state_scale / p.sc.row_scale;
        let xs = layout.state_offset() + x_start;
        if n_states > 0 {
            scatter_states(sink, (n_slots, n_states), dof, xs, ratio, &se);
        }
        // the columns of what it reads (no equations of its own): local column `j` to
        // unknown `c`, on its slots' and states' rows
        let n6 = 6 * n_slots;
        let mut column = |c: usize, j: usize| {
            for ka in 0..n_slots {
                let Some(a) = dof(ka) else { continue };
                for i in 0..6 {
                    sink.entry(a + i, c, se.get(6 * ka + i, j));
                }
            }
            for i in 0..n_states {
                sink.entry(xs + i, c, se.get(n6 + i, j) * ratio);
            }
        };
        // the multipliers of the active rows, then the other elements' states
        let rows = kernel.multiplier_rows();
        for (m, &row) in rows.iter().enumerate() {
            if let Some(k) = layout.row_unknown[row] {
                column(layout.n_dofs + k, n6 + n_states + m);
            }
        }
        let first = n6 + n_states + rows.len();
        for (m, &g) in kernel.state_reads().iter().enumerate() {
            column(layout.state_offset() + g, first + m);
        }
    }
    kernel
}

/// Adds an element's local vector `r` to the residual: its slots' rows times the row scale
/// to its nodes' equations, its state rows times the state scale to its state equations.
#[inline]
fn add_element(p: &Pass, kernel: &Kernel, x_start: usize, r: &[f64], residual: &mut [f64]) {
    let n_slots = kernel.n_slots();
    for k in 0..n_slots {
        if let Some(a) = p.layout.dof(kernel.node(k)) {
            for i in 0..6 {
                residual[a + i] += p.sc.row_scale * r[6 * k + i];
            }
        }
    }
    let xs = p.layout.state_offset() + x_start;
    for i in 0..kernel.n_states() {
        residual[xs + i] = p.sc.state_scale * r[6 * n_slots + i];
    }
}

/// Nodal viscous damping `s alpha D v` added to the nodes' equations.
fn add_nodal_damping(p: &Pass, nodal_mass: &[flexmb_lie::Vec6], residual: &mut [f64]) {
    let sc = &p.sc;
    if sc.nodal_damping > 0.0 {
        for (i, node) in p.it.nodes.iter().enumerate() {
            for k in 0..6 {
                residual[6 * i + k] +=
                    sc.row_scale * sc.nodal_damping * nodal_mass[i][k] * node.v[k];
            }
        }
    }
}

/// A joint's outputs, its rows only: `Phi` and the rows of `B` (every row), and for each
/// active row the right-hand side of its constraint equation and, in the stabilized
/// formulation, of its velocity-level equation (scaled).
struct JointRows<'o> {
    phi: &'o mut [f64],
    b: &'o mut [Vec12],
    rhs: &'o mut [f64],
    vel: &'o mut [f64],
}

/// Joint `j`: evaluated into `out` (when `S::EVALUATE`), its matrix entries emitted (when
/// `S::MATRIX`). Its part of the residual is added by [`add_joint`].
#[inline]
fn joint<S: Sink>(p: &Pass, j: usize, out: JointRows, sink: &mut S) {
    let (model, layout, it, sc) = (p.model, p.layout, &p.it, &p.sc);
    let joint = &model.joints[j];
    let slots = [joint.node_a, joint.node_b];
    let dofs = [layout.dof(slots[0]), layout.dof(slots[1])];
    let start = layout.joint_row_start[j];
    let rows = &layout.joint_rows[j];
    let nodes = if S::EVALUATE {
        gather(it.nodes, slots, &p.ground)
    } else {
        p.ground
    };
    let mut s = Mat12::zeros();
    let jv = if S::EVALUATE {
        let active = [dofs[0].is_some(), dofs[1].is_some()];
        let lam = &it.lambda[start..start + rows.len()];
        let mut k = Mat12::zeros();
        // `K_c` enters the matrix only through the stiffness coefficient: a matrix of
        // masses or velocities alone (initial accelerations, the step Jacobian's
        // partials) needs the rows `B` but not the joint's second derivatives.
        let stiffness = S::MATRIX && sc.coef.k != 0.0;
        let jv = joint.evaluate(
            model.group,
            rows,
            &nodes,
            it.t,
            lam,
            stiffness.then_some(&mut k),
        );
        out.phi.copy_from_slice(&jv.phi[..rows.len()]);
        out.b.copy_from_slice(&jv.b[..rows.len()]);
        if stiffness {
            // c_k K_c T, column block by column block
            s = k * sc.coef.k;
            crate::elements::physical::apply_tangent_full(&nodes, &active, &mut s, &sc.coef, &k);
        }
        jv
    } else {
        joints::JointValues {
            n_rows: 0,
            phi: [0.0; joints::MAX_ROWS],
            b: [Vec12::zeros(); joints::MAX_ROWS],
            phi_t: [0.0; joints::MAX_ROWS],
        }
    };
    if S::MATRIX {
        scatter_blocks(sink, 2, |k| dofs[k], |i, j| s[(i, j)]);
    }
    let mut vloc = Vec12::zeros();
    if S::EVALUATE {
        for (ka, _) in active_slots(dofs) {
            vloc.fixed_rows_mut::<6>(6 * ka).copy_from(&nodes[ka].v);
        }
    }
    for ri in 0..rows.len() {
        let Some(k) = layout.row_unknown[start + ri] else {
            continue;
        };
        let c = layout.n_dofs + k;
        let b = &jv.b[ri];
        if S::EVALUATE {
            if layout.stabilized {
                out.vel[ri] = (b.dot(&vloc) + jv.phi_t[ri]) * sc.velocity_scale;
            }
            out.rhs[ri] = match sc.constraint_rhs {
                ConstraintRhs::Position => jv.phi[ri],
                ConstraintRhs::Acceleration => {
                    joints::evaluate_row(model.group, joint, rows[ri], &nodes, it.t)
                        .convective(&vloc)
                }
                ConstraintRhs::Velocity => b.dot(&vloc) + jv.phi_t[ri],
            };
        }
        if S::MATRIX {
            for (ka, a) in active_slots(dofs) {
                let bt = nodes[ka].t.transpose() * b.fixed_rows::<6>(6 * ka);
                for i in 0..6 {
                    sink.entry(c, a + i, bt[i]);
                    sink.entry(a + i, c, b[6 * ka + i]);
                }
            }
        }
    }
}

/// Adds joint `j`'s part of the residual from its rows' outputs ([`JointRows`]): `s B^T
/// lambda` to its nodes' equations (row by row), and its constraint equations.
#[inline]
fn add_joint(p: &Pass, j: usize, b: &[Vec12], rhs: &[f64], vel: &[f64], residual: &mut [f64]) {
    let (layout, sc) = (p.layout, &p.sc);
    let joint = &p.model.joints[j];
    let dofs = [layout.dof(joint.node_a), layout.dof(joint.node_b)];
    let start = layout.joint_row_start[j];
    let lam = &p.it.lambda[start..start + b.len()];
    for ri in 0..b.len() {
        let Some(k) = layout.row_unknown[start + ri] else {
            continue;
        };
        for (ka, a) in active_slots(dofs) {
            for i in 0..6 {
                residual[a + i] += sc.row_scale * b[ri][6 * ka + i] * lam[ri];
            }
        }
        residual[layout.n_dofs + k] = rhs[ri];
        if layout.stabilized {
            residual[layout.zeta(k)] = vel[ri];
        }
    }
}

/// The entries after the joints' (see [`traverse`]): in the stabilized formulation the
/// velocity-level rows `B` and the block `B B_n^T`, then every diagonal entry.
fn tail<S: Sink>(p: &Pass, nodal_mass: &[flexmb_lie::Vec6], b_rows: &[Vec12], sink: &mut S) {
    let (model, layout, sc) = (p.model, p.layout, &p.sc);
    let n_dofs = layout.n_dofs;
    if layout.stabilized {
        // Velocity-level rows: B.
        for (j, joint) in model.joints.iter().enumerate() {
            let dofs = [layout.dof(joint.node_a), layout.dof(joint.node_b)];
            let start = layout.joint_row_start[j];
            for ri in 0..layout.joint_rows[j].len() {
                let Some(k) = layout.row_unknown[start + ri] else {
                    continue;
                };
                for (ka, a) in active_slots(dofs) {
                    for i in 0..6 {
                        let v = if S::EVALUATE {
                            b_rows[start + ri][6 * ka + i]
                        } else {
                            0.0
                        };
                        sink.entry(layout.zeta(k), a + i, v);
                    }
                }
            }
        }
        // Position rows against the stabilization unknowns: B B_n^T, node by node.
        for rows in &layout.node_rows {
            for &(r1, s1) in rows {
                for &(r2, s2) in rows {
                    let v = if S::EVALUATE {
                        let b1 = b_rows[r1].fixed_rows::<6>(6 * s1);
                        let b2 = p.it.b_start[r2].fixed_rows::<6>(6 * s2);
                        b1.dot(&b2)
                    } else {
                        0.0
                    };
                    let (k1, k2) = (
                        layout.row_unknown[r1].expect("active row"),
                        layout.row_unknown[r2].expect("active row"),
                    );
                    sink.entry(n_dofs + k1, layout.zeta(k2), v);
                }
            }
        }
    }
    // Every diagonal entry is in the pattern (nodes without elements, zero blocks).
    for k in 0..n_dofs {
        let v = if S::EVALUATE {
            sc.coef.c * sc.nodal_damping * nodal_mass[k / 6][k % 6]
        } else {
            0.0
        };
        sink.entry(k, k, v);
    }
    let state_offset = layout.state_offset();
    for k in n_dofs..state_offset {
        sink.entry(k, k, -sc.regularization);
    }
    for k in state_offset..layout.n_unknowns() {
        sink.entry(k, k, 0.0);
    }
}

/// Items per leaf of the parallel traversal: the unit of work a thread takes (some tens of
/// microseconds of beam elements). Fixed, so the work is cut the same way whatever the
/// number of threads.
const LEAF: usize = 64;

/// Counts the entries of a traversal.
struct Count(usize);

impl Sink for Count {
    const EVALUATE: bool = false;
    const MATRIX: bool = true;
    #[inline]
    fn entry(&mut self, _: usize, _: usize, _: f64) {
        self.0 += 1;
    }
}

/// Where each item's results go in a parallel assembly, and the storage of the results that
/// are summed afterwards: built for one layout, on the first parallel assembly of a
/// [`Data`].
pub struct ParallelScratch {
    /// Position in `values` of each element's first entry (`n_elements + 1`).
    element_pos: Vec<usize>,
    /// Position in `values` of each joint's first entry (`n_joints + 1`).
    joint_pos: Vec<usize>,
    /// Start of each element's local vector in `element_r` (`n_elements + 1`).
    element_r_start: Vec<usize>,
    /// The elements' local vectors, one after the other.
    element_r: Vec<f64>,
    /// Right-hand sides of the constraint equations of the active rows (`n_rows`).
    rhs: Vec<f64>,
    /// Right-hand sides of their velocity-level equations (`n_rows`; stabilized form).
    vel: Vec<f64>,
    /// One [`LocalBuffers`] per leaf of elements.
    buffers: Vec<LocalBuffers>,
    /// The terms of each node's equations, in the order [`traverse`] adds them (node `n`:
    /// `terms[terms_start[n]..terms_start[n + 1]]`, then its joints' from `joint_terms`).
    terms_start: Vec<usize>,
    /// Elements' terms: the start of the slot's 6 rows in `element_r`.
    terms: Vec<usize>,
    /// Joints' terms of node `n`: `joint_terms[joint_terms_start[n]..]`, as `(row, slot)`.
    joint_terms_start: Vec<usize>,
    joint_terms: Vec<(usize, usize)>,
    /// The elements that own states.
    with_states: Vec<usize>,
}

impl ParallelScratch {
    fn new(model: &Model, layout: &Layout) -> Self {
        let it = Iterate::NONE;
        let pass = Pass::new(model, layout, &it, &Scaling::NONE);
        let mut buffers = LocalBuffers::default();
        let mut count = Count(0);
        let n_elements = layout.elements.len();
        let mut element_pos = Vec::with_capacity(n_elements + 1);
        let mut element_r_start = Vec::with_capacity(n_elements + 1);
        let mut n_r = 0;
        for e in 0..n_elements {
            element_pos.push(count.0);
            element_r_start.push(n_r);
            n_r += element(&pass, e, &mut buffers, &mut count).n_local();
        }
        element_pos.push(count.0);
        element_r_start.push(n_r);
        let mut joint_pos = Vec::with_capacity(model.joints.len() + 1);
        let mut phi = [0.0; joints::MAX_ROWS];
        let mut b = [Vec12::zeros(); joints::MAX_ROWS];
        let (mut rhs, mut vel) = ([0.0; joints::MAX_ROWS], [0.0; joints::MAX_ROWS]);
        for j in 0..model.joints.len() {
            joint_pos.push(count.0);
            let n = layout.joint_rows[j].len();
            let out = JointRows {
                phi: &mut phi[..n],
                b: &mut b[..n],
                rhs: &mut rhs[..n],
                vel: &mut vel[..n],
            };
            joint(&pass, j, out, &mut count);
        }
        joint_pos.push(count.0);
        // Each node's terms, element after element (slot after slot), then joint after
        // joint (active row after row, slot after slot): the order of `traverse`.
        let mut by_node = vec![Vec::new(); layout.n_nodes];
        let mut with_states = Vec::new();
        for (e, element) in layout.elements.iter().enumerate() {
            let kernel = element.kernel(model);
            for k in 0..kernel.n_slots() {
                if let Some(node) = kernel.node(k) {
                    by_node[node.0].push(element_r_start[e] + 6 * k);
                }
            }
            if kernel.n_states() > 0 {
                with_states.push(e);
            }
        }
        let mut by_node_joints = vec![Vec::new(); layout.n_nodes];
        for (j, joint) in model.joints.iter().enumerate() {
            let start = layout.joint_row_start[j];
            for row in start..start + layout.joint_rows[j].len() {
                if layout.row_unknown[row].is_none() {
                    continue;
                }
                for (slot, node) in [joint.node_a, joint.node_b].into_iter().enumerate() {
                    if let Some(node) = node {
                        by_node_joints[node.0].push((row, slot));
                    }
                }
            }
        }
        let (terms_start, terms) = flatten(by_node);
        let (joint_terms_start, joint_terms) = flatten(by_node_joints);
        Self {
            element_pos,
            joint_pos,
            element_r_start,
            element_r: vec![0.0; n_r],
            rhs: vec![0.0; layout.n_rows],
            vel: vec![0.0; layout.n_rows],
            buffers: vec![LocalBuffers::default(); n_elements.div_ceil(LEAF)],
            terms_start,
            terms,
            joint_terms_start,
            joint_terms,
            with_states,
        }
    }
}

/// Lists one after the other, and where each starts (`lists.len() + 1`).
fn flatten<T>(lists: Vec<Vec<T>>) -> (Vec<usize>, Vec<T>) {
    let mut starts = vec![0];
    let mut all = Vec::new();
    for list in lists {
        all.extend(list);
        starts.push(all.len());
    }
    (starts, all)
}

/// [`traverse`] on the threads of `pool`: the elements and the joints are evaluated in
/// parallel, each writing its own entries of `values` (positions fixed by the pattern) and
/// its own results (local vector, rows of `Phi` and `B`, right-hand sides) into per-item
/// storage; then the nodes' equations are summed node by node ([`NodeSums`]), each node's
/// terms in the order of [`traverse`] and with the same operations: the same bits whatever
/// the number of threads, and the same as [`traverse`]. `values` is `None` for the
/// residual only.
fn traverse_parallel(
    p: &Pass,
    nodal_mass: &[flexmb_lie::Vec6],
    out: Outputs,
    scratch: &mut ParallelScratch,
    values: Option<&mut [f64]>,
    pool: &rayon::ThreadPool,
) {
    let Outputs {
        residual,
        phi,
        b_rows,
    } = out;
    let layout = p.layout;
    let matrix = values.is_some();
    let values = values.unwrap_or_default();
    let ParallelScratch {
        element_pos,
        joint_pos,
        element_r_start,
        element_r,
        rhs,
        vel,
        buffers,
        terms_start,
        terms,
        joint_terms_start,
        joint_terms,
        with_states,
    } = scratch;
    let (element_values, rest) = values.split_at_mut(if matrix { joint_pos[0] } else { 0 });
    let n_joint_values = joint_pos[joint_pos.len() - 1] - joint_pos[0];
    let (joint_values, tail_values) = rest.split_at_mut(if matrix { n_joint_values } else { 0 });
    let element_work = ElementWork {
        pos: element_pos,
        r_start: element_r_start,
    };
    let joint_work = JointWork { pos: joint_pos };
    let n_element_leaves = layout.elements.len().div_ceil(LEAF);
    let n_joint_leaves = p.model.joints.len().div_ceil(LEAF);
    let (nodes_residual, others) = residual.split_at_mut(layout.n_dofs);
    // One call into the pool (waking its threads is the cost that matters on small models).
    pool.install(|| {
        let joint_out = JointRows {
            phi,
            b: &mut *b_rows,
            rhs: &mut rhs[..],
            vel: &mut vel[..],
        };
        rayon::join(
            || {
                let out = (&mut element_r[..], &mut buffers[..]);
                run_leaves(
                    &element_work,
                    p,
                    0..n_element_leaves,
                    matrix,
                    element_values,
                    out,
                )
            },
            || {
                run_leaves(
                    &joint_work,
                    p,
                    0..n_joint_leaves,
                    matrix,
                    joint_values,
                    joint_out,
                )
            },
        );
        // The nodes' equations, node by node in parallel, each summing its terms in the
        // order of `traverse` with the same operations.
        let sums = NodeSums {
            terms_start,
            terms,
            joint_terms_start,
            joint_terms,
            element_r,
            b_rows,
            nodal_mass,
        };
        nodes_residual
            .par_chunks_mut(6 * LEAF)
            .enumerate()
            .for_each(|(leaf, chunk)| sums.leaf(p, leaf * LEAF, chunk));
    });
    // The other equations are copied.
    others.iter_mut().for_each(|r| *r = 0.0);
    let state_offset = layout.state_offset();
    for &e in with_states.iter() {
        let kernel = layout.elements[e].kernel(p.model);
        let (n_slots, n_states) = (kernel.n_slots(), kernel.n_states());
        let r = &element_r[element_r_start[e] + 6 * n_slots..];
        let xs = state_offset + layout.state_start[e];
        for i in 0..n_states {
            residual[xs + i] = p.sc.state_scale * r[i];
        }
    }
    for (k, &row) in layout.active_rows.iter().enumerate() {
        residual[layout.n_dofs + k] = rhs[row];
        if layout.stabilized {
            residual[layout.zeta(k)] = vel[row];
        }
    }
    if matrix {
        let mut sink = Values {
            values: tail_values,
            pos: 0,
        };
        tail(p, nodal_mass, b_rows, &mut sink);
        debug_assert_eq!(
            sink.pos,
            sink.values.len(),
            "assembly order differs from the pattern"
        );
    }
}

/// The sums of the nodes' equations in [`traverse_parallel`].
struct NodeSums<'s> {
    terms_start: &'s [usize],
    terms: &'s [usize],
    joint_terms_start: &'s [usize],
    joint_terms: &'s [(usize, usize)],
    element_r: &'s [f64],
    b_rows: &'s [Vec12],
    nodal_mass: &'s [flexmb_lie::Vec6],
}

impl NodeSums<'_> {
    /// The equations of the nodes from `first` on (`chunk`: 6 per node): from zero, `s r` of
    /// each element (as [`add_element`]), the nodal damping (as [`add_nodal_damping`]),
    /// `s b lambda` of each joint row (as [`add_joint`]), in that order.
    fn leaf(&self, p: &Pass, first: usize, chunk: &mut [f64]) {
        let sc = &p.sc;
        for (n, out) in (first..).zip(chunk.chunks_exact_mut(6)) {
            out.iter_mut().for_each(|r| *r = 0.0);
            for &at in &self.terms[self.terms_start[n]..self.terms_start[n + 1]] {
                for i in 0..6 {
                    out[i] += sc.row_scale * self.element_r[at + i];
                }
            }
            if sc.nodal_damping > 0.0 {
                let v = &p.it.nodes[n].v;
                for i in 0..6 {
                    out[i] += sc.row_scale * sc.nodal_damping * self.nodal_mass[n][i] * v[i];
                }
            }
            let joints =
                &self.joint_terms[self.joint_terms_start[n]..self.joint_terms_start[n + 1]];
            for &(row, slot) in joints {
                let lam = p.it.lambda[row];
                for i in 0..6 {
                    out[i] += sc.row_scale * self.b_rows[row][6 * slot + i] * lam;
                }
            }
        }
    }
}

/// One kind of item of [`traverse_parallel`] (elements, joints): what each item writes
/// besides its matrix entries, and how a run of items is evaluated.
trait Items: Sync {
    /// The items' own outputs, for a run of consecutive items.
    type Out<'o>: Send;
    /// Position of each item's first matrix entry (one more entry than items).
    fn pos(&self) -> &[usize];
    /// Number of items.
    fn count(&self, p: &Pass) -> usize;
    /// Splits the outputs of items `first..` at item `at`; `leaves` is the number of leaves
    /// of the first part.
    fn split<'o>(
        &self,
        p: &Pass,
        out: Self::Out<'o>,
        first: usize,
        at: usize,
        leaves: usize,
    ) -> (Self::Out<'o>, Self::Out<'o>);
    /// Evaluates `items` in order into `out` and `sink`.
    fn leaf<S: Sink>(
        &self,
        p: &Pass,
        items: std::ops::Range<usize>,
        out: Self::Out<'_>,
        sink: &mut S,
    );
}

/// Evaluates the items of `leaves` (leaf `k`: items `k LEAF ..`) into `values` (their
/// entries; empty without matrix) and `out`, splitting the leaves in halves that run in
/// parallel. Every item writes only its own places, so the cut does not change the results.
fn run_leaves<W: Items>(
    w: &W,
    p: &Pass,
    leaves: std::ops::Range<usize>,
    matrix: bool,
    values: &mut [f64],
    out: W::Out<'_>,
) {
    let first = leaves.start * LEAF;
    if leaves.is_empty() {
        return;
    }
    if leaves.len() == 1 {
        let items = first..(leaves.end * LEAF).min(w.count(p));
        if matrix {
            let mut sink = Values { values, pos: 0 };
            w.leaf(p, items, out, &mut sink);
            debug_assert_eq!(sink.pos, sink.values.len());
        } else {
            w.leaf(p, items, out, &mut NoMatrix);
        }
        return;
    }
    let mid = (leaves.start + leaves.end) / 2;
    let at = mid * LEAF;
    let split = if matrix {
        w.pos()[at] - w.pos()[first]
    } else {
        0
    };
    let (v1, v2) = values.split_at_mut(split);
    let (o1, o2) = w.split(p, out, first, at, mid - leaves.start);
    rayon::join(
        || run_leaves(w, p, leaves.start..mid, matrix, v1, o1),
        || run_leaves(w, p, mid..leaves.end, matrix, v2, o2),
    );
}

/// The elements' part of [`traverse_parallel`]: their local vectors (at `r_start`) and one
/// set of buffers per leaf.
struct ElementWork<'s> {
    pos: &'s [usize],
    r_start: &'s [usize],
}

impl Items for ElementWork<'_> {
    type Out<'o> = (&'o mut [f64], &'o mut [LocalBuffers]);

    fn pos(&self) -> &[usize] {
        self.pos
    }

    fn count(&self, p: &Pass) -> usize {
        p.layout.elements.len()
    }

    fn split<'o>(
        &self,
        _: &Pass,
        (r, buffers): Self::Out<'o>,
        first: usize,
        at: usize,
        leaves: usize,
    ) -> (Self::Out<'o>, Self::Out<'o>) {
        let (r1, r2) = r.split_at_mut(self.r_start[at] - self.r_start[first]);
        let (b1, b2) = buffers.split_at_mut(leaves);
        ((r1, b1), (r2, b2))
    }

    fn leaf<S: Sink>(
        &self,
        p: &Pass,
        items: std::ops::Range<usize>,
        (r, buffers): Self::Out<'_>,
        sink: &mut S,
    ) {
        let buffers = &mut buffers[0];
        let base = self.r_start[items.start];
        for e in items {
            let n = element(p, e, buffers, sink).n_local();
            let at = self.r_start[e] - base;
            r[at..at + n].copy_from_slice(buffers.vector(n));
        }
    }
}

/// The joints' part of [`traverse_parallel`]: their rows.
struct JointWork<'s> {
    pos: &'s [usize],
}

impl Items for JointWork<'_> {
    type Out<'o> = JointRows<'o>;

    fn pos(&self) -> &[usize] {
        self.pos
    }

    fn count(&self, p: &Pass) -> usize {
        p.model.joints.len()
    }

    fn split<'o>(
        &self,
        p: &Pass,
        out: Self::Out<'o>,
        first: usize,
        at: usize,
        _: usize,
    ) -> (Self::Out<'o>, Self::Out<'o>) {
        let rows = p.layout.joint_row_start[at] - p.layout.joint_row_start[first];
        let (phi1, phi2) = out.phi.split_at_mut(rows);
        let (b1, b2) = out.b.split_at_mut(rows);
        let (rhs1, rhs2) = out.rhs.split_at_mut(rows);
        let (vel1, vel2) = out.vel.split_at_mut(rows);
        (
            JointRows {
                phi: phi1,
                b: b1,
                rhs: rhs1,
                vel: vel1,
            },
            JointRows {
                phi: phi2,
                b: b2,
                rhs: rhs2,
                vel: vel2,
            },
        )
    }

    fn leaf<S: Sink>(
        &self,
        p: &Pass,
        items: std::ops::Range<usize>,
        out: Self::Out<'_>,
        sink: &mut S,
    ) {
        let layout = p.layout;
        let base = layout
            .joint_row_start
            .get(items.start)
            .copied()
            .unwrap_or(0);
        for j in items {
            let start = layout.joint_row_start[j] - base;
            let rows = start..start + layout.joint_rows[j].len();
            let rows_out = JointRows {
                phi: &mut out.phi[rows.clone()],
                b: &mut out.b[rows.clone()],
                rhs: &mut out.rhs[rows.clone()],
                vel: &mut out.vel[rows],
            };
            joint(p, j, rows_out, sink);
        }
    }
}

/// Emits the node-node blocks of a local matrix (`value(i, j)`, local indices) on `n_slots`
/// slots (`dof`: a slot's first global unknown, `None` for the ground), column block by column
/// block.
#[inline]
fn scatter_blocks<S: Sink>(
    sink: &mut S,
    n_slots: usize,
    dof: impl Fn(usize) -> Option<usize>,
    value: impl Fn(usize, usize) -> f64,
) {
    for kb in 0..n_slots {
        let Some(b) = dof(kb) else { continue };
        for ka in 0..n_slots {
            let Some(a) = dof(ka) else { continue };
            for j in 0..6 {
                for i in 0..6 {
                    sink.entry(a + i, b + j, value(6 * ka + i, 6 * kb + j));
                }
            }
        }
    }
}

/// Emits the blocks of an element's local matrix that involve its states (`n_slots` node
/// slots, then `n_states` states, the first of which is unknown `xs`): the node rows against
/// the state columns, then the state rows (times `ratio`) against the node columns and the
/// state columns.
#[inline]
fn scatter_states<S: Sink>(
    sink: &mut S,
    (n_slots, n_states): (usize, usize),
    dof: impl Fn(usize) -> Option<usize>,
    xs: usize,
    ratio: f64,
    se: &crate::elements::LocalMatrix,
) {
    let n6 = 6 * n_slots;
    for j in 0..n_states {
        for ka in 0..n_slots {
            let Some(a) = dof(ka) else { continue };
            for i in 0..6 {
                sink.entry(a + i, xs + j, se.get(6 * ka + i, n6 + j));
            }
        }
    }
    for i in 0..n_states {
        for kb in 0..n_slots {
            let Some(b) = dof(kb) else { continue };
            for j in 0..6 {
                sink.entry(xs + i, b + j, se.get(n6 + i, 6 * kb + j) * ratio);
            }
        }
        for j in 0..n_states {
            sink.entry(xs + i, xs + j, se.get(n6 + i, n6 + j) * ratio);
        }
    }
}

/// Rows of `B(q)` at the node configurations `nodes` (`n_rows`, group coordinates, tangent
/// operators ignored): `B(q_n)` for the stabilized formulation.
pub fn constraint_rows(
    model: &Model,
    layout: &Layout,
    nodes: &[NodeState],
    t: f64,
    out: &mut [Vec12],
) {
    let ground = [NodeState::ground(Default::default()); 2];
    let zeros = [0.0; joints::MAX_ROWS];
    for (j, joint) in model.joints.iter().enumerate() {
        let pair = gather(nodes, [joint.node_a, joint.node_b], &ground);
        let start = layout.joint_row_start[j];
        let rows = &layout.joint_rows[j];
        let jv = joint.evaluate(model.group, rows, &pair, t, &zeros[..rows.len()], None);
        out[start..start + rows.len()].copy_from_slice(&jv.b[..rows.len()]);
    }
}
