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

use crate::data::{active_slots, Data, Layout};
use crate::elements::{
    Coefficients, Context, ElementKernel, LocalBuffers, Mat12, NodeState, Vec12,
};
use crate::joints::{self, ConstraintKernel};
use crate::model::{Model, NodeId};

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
    /// ([`crate::Data::nodal_mass`]) [1/s]: used by pseudo-dynamic static analysis.
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
/// iterate `it`.
pub fn assemble(model: &Model, data: &mut Data, it: &Iterate, sc: &Scaling, matrix: bool) {
    let Data {
        layout,
        values,
        residual,
        phi,
        b_rows,
        nodal_mass,
        local,
        ..
    } = data;
    let out = Outputs {
        residual,
        phi,
        b_rows,
    };
    if matrix {
        let mut sink = Values { values, pos: 0 };
        traverse(model, layout, nodal_mass, it, sc, out, local, &mut sink);
        debug_assert_eq!(
            sink.pos,
            sink.values.len(),
            "assembly order differs from the pattern"
        );
    } else {
        traverse(model, layout, nodal_mass, it, sc, out, local, &mut NoMatrix);
    }
}

/// The sparsity pattern of the iteration matrix of `layout`: the traversal of [`assemble`]
/// with no kernel evaluated.
pub fn pattern(model: &Model, layout: &Layout) -> Vec<(usize, usize)> {
    let mut p = Vec::new();
    let it = Iterate {
        nodes: &[],
        t: 0.0,
        lambda: &[],
        b_start: &[],
        x: &[],
        xdot: &[],
    };
    let out = Outputs {
        residual: &mut [],
        phi: &mut [],
        b_rows: &mut [],
    };
    traverse(
        model,
        layout,
        &[],
        &it,
        &Scaling::NONE,
        out,
        &mut LocalBuffers::default(),
        &mut Pattern(&mut p),
    );
    p
}

/// One pass over elements and joints: residual and `Phi` (when `S::EVALUATE`) and the matrix
/// entries in a fixed order (when `S::MATRIX`): for each element its node-node blocks; for
/// each joint its node-node blocks, then for each active row the row `B T` (row x node dofs)
/// and the column `B^T` (node dofs x row), interleaved; in the stabilized formulation the
/// velocity-level rows `B` and the block `B B_n^T` of the position rows against the
/// stabilization unknowns; last the diagonal of every unknown (nodal damping, and `-epsilon`
/// on the constraint block).
fn traverse<S: Sink>(
    model: &Model,
    layout: &Layout,
    nodal_mass: &[flexmb_lie::Vec6],
    it: &Iterate,
    sc: &Scaling,
    out: Outputs,
    buffers: &mut LocalBuffers,
    sink: &mut S,
) {
    let Outputs {
        residual,
        phi,
        b_rows,
    } = out;
    let ctx = Context::at(model, it.t, sc.load_factor);
    let ground = [NodeState::ground(Default::default()); 2];
    residual.iter_mut().for_each(|r| *r = 0.0);
    let mut s = Mat12::zeros();
    let n_dofs = layout.n_dofs;
    let state_offset = layout.state_offset();
    for (e, &x_start) in layout.elements.iter().zip(&layout.state_start) {
        let kernel = e.kernel(model);
        let (n_slots, n_states) = (kernel.n_slots(), kernel.n_states());
        let dof = |k: usize| layout.dof(kernel.node(k));
        if S::EVALUATE {
            buffers.gather(&kernel, it.nodes, (it.x, it.xdot, x_start));
        }
        let (local, mut r, mut se) = buffers.split(kernel.n_local(), it.nodes);
        if S::EVALUATE {
            let matrix = S::MATRIX.then_some((&sc.coef, &mut se));
            kernel.evaluate(&ctx, &local, &mut r, matrix);
            for k in 0..n_slots {
                if let Some(a) = dof(k) {
                    for i in 0..6 {
                        residual[a + i] += sc.row_scale * r[6 * k + i];
                    }
                }
            }
            for i in 0..n_states {
                residual[state_offset + x_start + i] = sc.state_scale * r[6 * n_slots + i];
            }
        }
        if S::MATRIX {
            scatter_blocks(sink, n_slots, dof, |i, j| se.get(i, j));
            if n_states > 0 {
                let ratio = sc.state_scale / sc.row_scale;
                let xs = state_offset + x_start;
                scatter_states(sink, (n_slots, n_states), dof, xs, ratio, &se);
            }
        }
    }
    if S::EVALUATE && sc.nodal_damping > 0.0 {
        for (i, node) in it.nodes.iter().enumerate() {
            for k in 0..6 {
                residual[6 * i + k] +=
                    sc.row_scale * sc.nodal_damping * nodal_mass[i][k] * node.v[k];
            }
        }
    }
    let mut jv = joints::JointValues {
        n_rows: 0,
        phi: [0.0; joints::MAX_ROWS],
        b: [Vec12::zeros(); joints::MAX_ROWS],
        phi_t: [0.0; joints::MAX_ROWS],
    };
    for (j, joint) in model.joints.iter().enumerate() {
        let slots = [joint.node_a, joint.node_b];
        let dofs = [layout.dof(slots[0]), layout.dof(slots[1])];
        let start = layout.joint_row_start[j];
        let rows = &layout.joint_rows[j];
        let nodes = if S::EVALUATE {
            gather(it.nodes, slots, &ground)
        } else {
            ground
        };
        if S::EVALUATE {
            let active = [dofs[0].is_some(), dofs[1].is_some()];
            let lam = &it.lambda[start..start + rows.len()];
            let mut k = Mat12::zeros();
            jv = joint.evaluate(
                model.group,
                rows,
                &nodes,
                it.t,
                lam,
                S::MATRIX.then_some(&mut k),
            );
            for ri in 0..rows.len() {
                phi[start + ri] = jv.phi[ri];
                b_rows[start + ri] = jv.b[ri];
                if layout.row_unknown[start + ri].is_some() {
                    for (ka, a) in active_slots(dofs) {
                        for i in 0..6 {
                            residual[a + i] += sc.row_scale * jv.b[ri][6 * ka + i] * lam[ri];
                        }
                    }
                }
            }
            if S::MATRIX {
                // c_k K_c T, column block by column block
                s = k * sc.coef.k;
                crate::elements::physical::apply_tangent_full(
                    &nodes, &active, &mut s, &sc.coef, &k,
                );
            }
        }
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
            let c = n_dofs + k;
            let b = &jv.b[ri];
            if S::EVALUATE {
                if layout.stabilized {
                    residual[layout.zeta(k)] = (b.dot(&vloc) + jv.phi_t[ri]) * sc.velocity_scale;
                }
                residual[c] = match sc.constraint_rhs {
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
    if S::MATRIX && layout.stabilized {
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
                        let b2 = it.b_start[r2].fixed_rows::<6>(6 * s2);
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
    if S::MATRIX {
        // Every diagonal entry is in the pattern (nodes without elements, zero blocks).
        for k in 0..n_dofs {
            let v = if S::EVALUATE {
                sc.coef.c * sc.nodal_damping * nodal_mass[k / 6][k % 6]
            } else {
                0.0
            };
            sink.entry(k, k, v);
        }
        for k in n_dofs..state_offset {
            sink.entry(k, k, -sc.regularization);
        }
        for k in state_offset..layout.n_unknowns() {
            sink.entry(k, k, 0.0);
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
