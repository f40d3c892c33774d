//! Conversion of element contributions from physical to group coordinates.
//!
//! Physical coordinates of a node variation: `(dx, theta)`, `dx` the inertial translation of
//! the node origin and `theta` the body-frame rotation (`R -> R exp(tilde(theta))`). On
//! R3xSO(3) these are the group's coordinates. On SE(3) the translation part is in the body
//! frame, `dx = R dU`, so with `P = blockdiag(R, I)` per node:
//!
//! ```text
//! r_g = P^T r_p,
//! K_g = P^T K_p P + blockdiag( [[0, tilde(R^T f_p)], [0, 0]] ) + P^T C_p dv_p/dw,
//! C_g = P^T C_p P,      M_g = P^T M_p P,
//! ```
//!
//! where `f_p` is the translational part of the node's physical residual (the middle term is
//! the derivative of `R^T` at fixed `f_p`) and `v_p = (R U, Omega)` is the physical velocity
//! (its derivative `dv_p/dtheta = -R tilde(U)` gives the last term).

use super::{Coefficients, LocalMatrix, LocalVector, NodeState};
use flexmb_lie::{so3::hat, Group, Mat3, Mat6, Vec3};
use nalgebra::allocator::Allocator;
use nalgebra::{
    DMatrix, DMatrixView, DVectorView, DefaultAllocator, Dim, Matrix, Storage, StorageMut, U6,
};

/// Physical velocity `(xdot, Omega)` of a node.
pub fn velocity(group: Group, n: &NodeState) -> (Vec3, Vec3) {
    let u = n.v.fixed_rows::<3>(0).into_owned();
    let om = n.v.fixed_rows::<3>(3).into_owned();
    match group {
        Group::R3xSO3 => (u, om),
        Group::SE3 => (n.q.r * u, om),
    }
}

/// Converts a physical residual and, optionally, physical `K_p` and `C_p` (column-major,
/// `6 n` square for the `n` slots of `nodes`) into the group's residual and iteration matrix
/// `S = c.c C + c.k K T` (no mass term: these elements have none), written to the first
/// `6 n` rows (and columns) of `r` and `s`. `active` tells which slots are nodes (ground
/// slots are skipped).
pub fn to_group(
    group: Group,
    nodes: &[NodeState],
    active: &[bool],
    r_p: &[f64],
    k_p: Option<&[f64]>,
    c_p: Option<&[f64]>,
    r: &mut LocalVector,
    s: Option<(&Coefficients, &mut LocalMatrix)>,
) {
    let n = 6 * nodes.len();
    let r_p = DVectorView::from_slice(r_p, n);
    let k_p = k_p.map(|k| DMatrixView::from_slice(k, n, n));
    let c_p = c_p.map(|c| DMatrixView::from_slice(c, n, n));
    let mut r = r.rows_mut(0, n);
    match group {
        Group::R3xSO3 => {
            r.copy_from(&r_p);
            if let Some((coef, s)) = s {
                let mut whole = s.view();
                let mut s = whole.view_mut((0, 0), (n, n));
                s.fill(0.0);
                if let Some(k) = &k_p {
                    s += k * coef.k;
                }
                if let Some(c) = &c_p {
                    s += c * coef.c;
                }
                if let Some(k) = &k_p {
                    apply_tangent_full(nodes, active, &mut s, coef, k);
                }
            }
        }
        Group::SE3 => {
            // P = blockdiag(R_a, I, R_b, I, ...)
            let mut p = DMatrix::<f64>::identity(n, n);
            for a in 0..nodes.len() {
                if active[a] {
                    p.fixed_view_mut::<3, 3>(6 * a, 6 * a)
                        .copy_from(&nodes[a].q.r);
                }
            }
            r.copy_from(&(p.transpose() * r_p));
            if let Some((coef, s)) = s {
                let mut k = match &k_p {
                    Some(k) => p.transpose() * k * &p,
                    None => DMatrix::zeros(n, n),
                };
                for a in 0..nodes.len() {
                    if !active[a] {
                        continue;
                    }
                    let f = r.fixed_rows::<3>(6 * a).into_owned();
                    let mut blk = k.fixed_view_mut::<3, 3>(6 * a, 6 * a + 3);
                    blk += hat(&f);
                }
                let mut whole = s.view();
                let mut s = whole.view_mut((0, 0), (n, n));
                s.fill(0.0);
                if let Some(c) = &c_p {
                    let cg = p.transpose() * c * &p;
                    s += cg * coef.c;
                    // dv_p/dw: translation velocity R U depends on the rotation.
                    let mut dv = DMatrix::zeros(n, n);
                    for a in 0..nodes.len() {
                        if active[a] {
                            let u = nodes[a].v.fixed_rows::<3>(0).into_owned();
                            let blk: Mat3 = -nodes[a].q.r * hat(&u);
                            dv.fixed_view_mut::<3, 3>(6 * a, 6 * a + 3).copy_from(&blk);
                        }
                    }
                    k += p.transpose() * c * dv;
                }
                s += &k * coef.k;
                apply_tangent_full(nodes, active, &mut s, coef, &k);
            }
        }
    }
}

/// `s += c.k K (T - I)` column block by column block, which turns `c.k K` into `c.k K T`
/// (`nodes` and `active` one per slot; the first `6 n` columns of `s` and `k`).
pub fn apply_tangent_full<R1, C1, S1, R2, C2, S2>(
    nodes: &[NodeState],
    active: &[bool],
    s: &mut Matrix<f64, R1, C1, S1>,
    coef: &Coefficients,
    k: &Matrix<f64, R2, C2, S2>,
) where
    R1: Dim,
    C1: Dim,
    S1: StorageMut<f64, R1, C1>,
    R2: Dim,
    C2: Dim,
    S2: Storage<f64, R2, C2>,
    DefaultAllocator: Allocator<R2, U6> + Allocator<U6, U6>,
    nalgebra::constraint::ShapeConstraint: nalgebra::constraint::SameNumberOfRows<R1, R2>,
{
    if coef.k == 0.0 {
        return;
    }
    for b in 0..nodes.len() {
        if !active[b] {
            continue;
        }
        let t = &nodes[b].t;
        if *t == Mat6::identity() {
            continue;
        }
        let tm = t - Mat6::identity();
        let cols = k.fixed_columns::<6>(6 * b) * tm * coef.k;
        let mut target = s.fixed_columns_mut::<6>(6 * b);
        target += cols;
    }
}
