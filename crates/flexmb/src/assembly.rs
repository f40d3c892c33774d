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

use crate::data::{active_slots, Data};
use crate::elements::{Coefficients, Context, ElementKernel, Mat12, NodeState, Vec12};
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
}

fn gather(data: &Data, slots: [Option<NodeId>; 2], ground: &[NodeState; 2]) -> [NodeState; 2] {
    [
        slots[0].map_or(ground[0], |n| data.nodes[n.0]),
        slots[1].map_or(ground[1], |n| data.nodes[n.0]),
    ]
}

/// Fills `data.residual` (and `data.values` if `matrix`) at time `t` from `data.nodes` and the
/// multipliers `lambda` (unscaled, `n_rows`); also `data.phi`.
pub fn assemble(
    model: &Model,
    data: &mut Data,
    t: f64,
    lambda: &[f64],
    sc: &Scaling,
    matrix: bool,
) {
    let ctx = Context {
        model,
        group: model.group,
        t,
        gravity_scale: sc.load_factor,
        load_scale: sc.load_factor,
    };
    let ground = [NodeState::ground(Default::default()); 2];
    data.residual.iter_mut().for_each(|r| *r = 0.0);
    let mut pos = 0;
    let mut r = Vec12::zeros();
    let mut s = Mat12::zeros();
    let layout = &data.layout;
    let n_dofs = layout.n_dofs;
    for e in &layout.elements {
        let kernel = e.kernel(model);
        let slots = kernel.nodes();
        let nodes = gather(data, slots, &ground);
        kernel.evaluate(&ctx, &nodes, &mut r, matrix.then_some((&sc.coef, &mut s)));
        let dofs = [layout.dof(slots[0]), layout.dof(slots[1])];
        for (ka, a) in active_slots(dofs) {
            for i in 0..6 {
                data.residual[a + i] += sc.row_scale * r[6 * ka + i];
            }
        }
        if matrix {
            pos = scatter_blocks(&mut data.values, pos, dofs, &s);
        }
    }
    if sc.nodal_damping > 0.0 {
        for (i, node) in data.nodes.iter().enumerate() {
            for k in 0..6 {
                data.residual[6 * i + k] +=
                    sc.row_scale * sc.nodal_damping * data.nodal_mass[i][k] * node.v[k];
            }
        }
    }
    let needs_h = sc.constraint_rhs == ConstraintRhs::Acceleration;
    for (j, joint) in model.joints.iter().enumerate() {
        let slots = [joint.node_a, joint.node_b];
        let nodes = gather(data, slots, &ground);
        let dofs = [layout.dof(slots[0]), layout.dof(slots[1])];
        let active = [dofs[0].is_some(), dofs[1].is_some()];
        let start = layout.joint_row_start[j];
        let rows = &layout.joint_rows[j];
        let lam = &lambda[start..start + rows.len()];
        let mut k = Mat12::zeros();
        let jv = joint.evaluate(model.group, rows, &nodes, t, lam, matrix.then_some(&mut k));
        let mut vloc = Vec12::zeros();
        for (ka, _) in active_slots(dofs) {
            vloc.fixed_rows_mut::<6>(6 * ka).copy_from(&nodes[ka].v);
        }
        for ri in 0..rows.len() {
            data.phi[start + ri] = jv.phi[ri];
            if layout.row_unknown[start + ri].is_some() {
                for (ka, a) in active_slots(dofs) {
                    for i in 0..6 {
                        data.residual[a + i] += sc.row_scale * jv.b[ri][6 * ka + i] * lam[ri];
                    }
                }
            }
        }
        if matrix {
            // c_k K_c T, column block by column block
            let mut kt = k * sc.coef.k;
            crate::elements::physical::apply_tangent_full(&nodes, active, &mut kt, &sc.coef, &k);
            pos = scatter_blocks(&mut data.values, pos, dofs, &kt);
        }
        for ri in 0..rows.len() {
            data.b_rows[start + ri] = jv.b[ri];
            let Some(k) = layout.row_unknown[start + ri] else {
                continue;
            };
            if layout.stabilized {
                data.residual[layout.zeta(k)] =
                    (jv.b[ri].dot(&vloc) + jv.phi_t[ri]) * sc.velocity_scale;
            }
            let c = n_dofs + k;
            let b = &jv.b[ri];
            data.residual[c] = match sc.constraint_rhs {
                ConstraintRhs::Position => jv.phi[ri],
                ConstraintRhs::Acceleration if needs_h => {
                    joints::evaluate_row(model.group, joint, rows[ri], &nodes, t).convective(&vloc)
                }
                ConstraintRhs::Acceleration => unreachable!(),
                ConstraintRhs::Velocity => b.dot(&vloc) + jv.phi_t[ri],
            };
            if matrix {
                for (ka, _) in active_slots(dofs) {
                    let bt = nodes[ka].t.transpose() * b.fixed_rows::<6>(6 * ka);
                    for i in 0..6 {
                        data.values[pos] = bt[i];
                        data.values[pos + 1] = b[6 * ka + i];
                        pos += 2;
                    }
                }
            }
        }
    }
    if matrix && layout.stabilized {
        // Velocity-level rows: B.
        for (j, joint) in model.joints.iter().enumerate() {
            let dofs = [layout.dof(joint.node_a), layout.dof(joint.node_b)];
            let start = layout.joint_row_start[j];
            for ri in 0..layout.joint_rows[j].len() {
                if layout.row_unknown[start + ri].is_none() {
                    continue;
                }
                for (ka, _) in active_slots(dofs) {
                    for i in 0..6 {
                        data.values[pos] = data.b_rows[start + ri][6 * ka + i];
                        pos += 1;
                    }
                }
            }
        }
        // Position rows against the stabilization unknowns: B B_n^T, node by node.
        for rows in &layout.node_rows {
            for &(r1, s1) in rows {
                for &(r2, s2) in rows {
                    let b1 = data.b_rows[r1].fixed_rows::<6>(6 * s1);
                    let b2 = data.b_start[r2].fixed_rows::<6>(6 * s2);
                    data.values[pos] = b1.dot(&b2);
                    pos += 1;
                }
            }
        }
    }
    if matrix {
        // Diagonal entries come last in the pattern, one per unknown.
        let n = layout.n_unknowns();
        for (k, v) in data.values[pos..pos + n_dofs].iter_mut().enumerate() {
            *v = sc.coef.c * sc.nodal_damping * data.nodal_mass[k / 6][k % 6];
        }
        for v in &mut data.values[pos + n_dofs..pos + n] {
            *v = -sc.regularization;
        }
        debug_assert_eq!(
            pos + n,
            data.values.len(),
            "assembly order differs from the pattern"
        );
    }
}

/// Writes the node-node blocks of a local matrix in pattern order; returns the new position.
fn scatter_blocks(
    values: &mut [f64],
    mut pos: usize,
    dofs: [Option<usize>; 2],
    s: &Mat12,
) -> usize {
    for (kb, _) in active_slots(dofs) {
        for (ka, _) in active_slots(dofs) {
            for j in 0..6 {
                for i in 0..6 {
                    values[pos] = s[(6 * ka + i, 6 * kb + j)];
                    pos += 1;
                }
            }
        }
    }
    pos
}

/// Rows of `B(q)` at the configuration in `data.nodes` into `data.b_rows` (group coordinates,
/// tangent operators ignored): `B(q_n)` for the stabilized formulation.
pub fn constraint_rows(model: &Model, data: &mut Data, t: f64) {
    let ground = [NodeState::ground(Default::default()); 2];
    let zeros = [0.0; joints::MAX_ROWS];
    for (j, joint) in model.joints.iter().enumerate() {
        let nodes = gather(data, [joint.node_a, joint.node_b], &ground);
        let start = data.layout.joint_row_start[j];
        let rows = &data.layout.joint_rows[j];
        let jv = joint.evaluate(model.group, rows, &nodes, t, &zeros[..rows.len()], None);
        data.b_rows[start..start + rows.len()].copy_from_slice(&jv.b[..rows.len()]);
    }
}
