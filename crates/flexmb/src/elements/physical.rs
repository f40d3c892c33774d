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
use nalgebra::RowVector6;
use nalgebra::{DefaultAllocator, Dim, Matrix, OMatrix, OVector, Storage, StorageMut, U3, U6};

/// Physical velocity `(xdot, Omega)` of a node.
pub fn velocity(group: Group, n: &NodeState) -> (Vec3, Vec3) {
    let u = n.v.fixed_rows::<3>(0).into_owned();
    let om = n.v.fixed_rows::<3>(3).into_owned();
    match group {
        Group::R3xSO3 => (u, om),
        Group::SE3 => (n.q.r * u, om),
    }
}

/// Converts a physical residual and, optionally, physical `K_p` and `C_p` (`6 n` for the `n`
/// slots of `nodes`; a fixed size for an element of static size, no allocation) into the
/// group's residual and iteration matrix `S = c.c C + c.k K T` (no mass term: these elements
/// have none), written to the first `6 n` rows (and columns) of `r` and `s`. `active` tells
/// which slots are nodes (ground slots are skipped). `P` is block-diagonal: it is applied by
/// rotating the translation rows and columns of each slot in place.
pub fn to_group<D: Dim>(
    group: Group,
    nodes: &[NodeState],
    active: &[bool],
    r_p: &OVector<f64, D>,
    k_p: Option<&OMatrix<f64, D, D>>,
    c_p: Option<&OMatrix<f64, D, D>>,
    r: &mut LocalVector,
    s: Option<(&Coefficients, &mut LocalMatrix)>,
) where
    DefaultAllocator:
        Allocator<D> + Allocator<D, D> + Allocator<D, U3> + Allocator<D, U6> + Allocator<U6, U6>,
{
    let (d, n) = (r_p.shape_generic().0, r_p.nrows());
    let zeros = || OMatrix::<f64, D, D>::zeros_generic(d, d);
    match group {
        Group::R3xSO3 => {
            r.rows_mut(0, n).copy_from_slice(r_p.as_slice());
            if let Some((coef, s)) = s {
                let mut sg = zeros();
                if let Some(k) = k_p {
                    sg += k * coef.k;
                }
                if let Some(c) = c_p {
                    sg += c * coef.c;
                }
                if let Some(k) = k_p {
                    apply_tangent_full(nodes, active, &mut sg, coef, k);
                }
                s.view()
                    .view_mut((0, 0), (n, n))
                    .copy_from_slice(sg.as_slice());
            }
        }
        Group::SE3 => {
            let mut rg = r_p.clone();
            translations_to_group(group, nodes, active, &mut rg);
            r.rows_mut(0, n).copy_from_slice(rg.as_slice());
            let Some((coef, s)) = s else {
                return;
            };
            // P^T K P, and the derivative of R^T at fixed f_p
            let mut k = k_p.cloned().unwrap_or_else(zeros);
            rotate_rows(&mut k, nodes, active);
            rotate_columns(&mut k, nodes, active);
            for a in (0..nodes.len()).filter(|&a| active[a]) {
                let f = rg.fixed_rows::<3>(6 * a).into_owned();
                let mut blk = k.fixed_view_mut::<3, 3>(6 * a, 6 * a + 3);
                blk += hat(&f);
            }
            let mut sg = zeros();
            if let Some(c) = c_p {
                let mut ptc = c.clone();
                rotate_rows(&mut ptc, nodes, active);
                let mut cg = ptc.clone();
                rotate_columns(&mut cg, nodes, active);
                sg += cg * coef.c;
                // P^T C dv_p/dw: the translation velocity R U depends on the rotation.
                for a in (0..nodes.len()).filter(|&a| active[a]) {
                    let u = nodes[a].v.fixed_rows::<3>(0).into_owned();
                    let dv: Mat3 = -nodes[a].q.r * hat(&u);
                    let cols = ptc.fixed_columns::<3>(6 * a) * dv;
                    let mut target = k.fixed_columns_mut::<3>(6 * a + 3);
                    target += cols;
                }
            }
            sg += &k * coef.k;
            apply_tangent_full(nodes, active, &mut sg, coef, &k);
            s.view()
                .view_mut((0, 0), (n, n))
                .copy_from_slice(sg.as_slice());
        }
    }
}

/// `v <- P^T v`: a residual-like vector (or the rows of a matrix) in group coordinates. On
/// SE(3) the translation rows of each active slot are turned by `R^T`; on R3xSO(3) `P = I`.
pub fn translations_to_group<C: Dim, S: StorageMut<f64, D, C>, D: Dim>(
    group: Group,
    nodes: &[NodeState],
    active: &[bool],
    v: &mut Matrix<f64, D, C, S>,
) {
    if group == Group::SE3 {
        rotate_rows(v, nodes, active);
    }
}

/// `m <- P^T m` on SE(3): the translation rows of each active slot turned by `R^T`.
fn rotate_rows<C: Dim, S: StorageMut<f64, D, C>, D: Dim>(
    m: &mut Matrix<f64, D, C, S>,
    nodes: &[NodeState],
    active: &[bool],
) {
    for a in (0..nodes.len()).filter(|&a| active[a]) {
        let rt = nodes[a].q.r.transpose();
        for j in 0..m.ncols() {
            let col = rt * m.fixed_view::<3, 1>(6 * a, j);
            m.fixed_view_mut::<3, 1>(6 * a, j).copy_from(&col);
        }
    }
}

/// `m <- m P` on SE(3): the translation columns of each active slot turned by `R`.
fn rotate_columns<R: Dim, S: StorageMut<f64, R, D>, D: Dim>(
    m: &mut Matrix<f64, R, D, S>,
    nodes: &[NodeState],
    active: &[bool],
) {
    for b in (0..nodes.len()).filter(|&b| active[b]) {
        let rot = nodes[b].q.r;
        for i in 0..m.nrows() {
            let row = m.fixed_view::<1, 3>(i, 6 * b) * rot;
            m.fixed_view_mut::<1, 3>(i, 6 * b).copy_from(&row);
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

/// A row of an element's state equations: its physical derivatives `(de/dw_p, de/dv_p,
/// de/dvdot_p)` at a node as its row of the iteration matrix in group coordinates,
/// `k de/dw T + c de/dv + m de/dvdot` (contact bristles, control blocks). On SE(3)
/// (`P = blockdiag(R, I)`) the physical velocity `R U` and acceleration `R (Udot + Omega x U)`
/// depend on the rotation and on `U`, `Omega`.
pub fn row_to_group(
    group: Group,
    node: &NodeState,
    (dw, dv, da): (RowVector6<f64>, RowVector6<f64>, RowVector6<f64>),
    coef: &Coefficients,
) -> RowVector6<f64> {
    let (mut gw, mut gv, mut ga) = (dw, dv, da);
    if group == Group::SE3 {
        let r = node.q.r;
        let (u, om) = flexmb_lie::split(&node.v);
        let (ud, _) = flexmb_lie::split(&node.vdot);
        let t = |m: &RowVector6<f64>| m.fixed_columns::<3>(0).into_owned();
        let (dw_t, dv_t, da_t) = (t(&dw), t(&dv), t(&da));
        gw.fixed_columns_mut::<3>(0).copy_from(&(dw_t * r));
        let turn: nalgebra::RowVector3<f64> =
            dv_t * (-r * hat(&u)) + da_t * (-r * hat(&(ud + om.cross(&u))));
        let mut rot = gw.fixed_columns_mut::<3>(3);
        rot += turn;
        gv.fixed_columns_mut::<3>(0)
            .copy_from(&(dv_t * r + da_t * (r * hat(&om))));
        let mut gv_rot = gv.fixed_columns_mut::<3>(3);
        gv_rot += da_t * (-r * hat(&u));
        ga.fixed_columns_mut::<3>(0).copy_from(&(da_t * r));
    }
    gw * node.t * coef.k + gv * coef.c + ga * coef.m
}
