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

use super::{Coefficients, Mat12, NodeState, Vec12};
use flexmb_lie::{so3::hat, Group, Mat3, Vec3};

/// Physical velocity `(xdot, Omega)` of a node.
pub fn velocity(group: Group, n: &NodeState) -> (Vec3, Vec3) {
    let u = n.v.fixed_rows::<3>(0).into_owned();
    let om = n.v.fixed_rows::<3>(3).into_owned();
    match group {
        Group::R3xSO3 => (u, om),
        Group::SE3 => (n.q.r * u, om),
    }
}

/// Converts a physical residual and, optionally, physical `K_p` and `C_p` into the group's
/// residual and iteration matrix `S = c.c C + c.k K T` (no mass term: these elements have
/// none). `active` tells which of the two node slots exist (ground slots are skipped).
pub fn to_group(
    group: Group,
    nodes: &[NodeState; 2],
    active: [bool; 2],
    r_p: &Vec12,
    k_p: Option<&Mat12>,
    c_p: Option<&Mat12>,
    r: &mut Vec12,
    s: Option<(&Coefficients, &mut Mat12)>,
) {
    match group {
        Group::R3xSO3 => {
            *r = *r_p;
            if let Some((coef, s)) = s {
                s.fill(0.0);
                if let Some(k) = k_p {
                    *s += k * coef.k;
                }
                if let Some(c) = c_p {
                    *s += c * coef.c;
                }
                if let Some(k) = k_p {
                    apply_tangent_full(nodes, active, s, coef, k);
                }
            }
        }
        Group::SE3 => {
            // P = blockdiag(R_a, I, R_b, I)
            let mut p = Mat12::identity();
            for a in 0..2 {
                if active[a] {
                    p.fixed_view_mut::<3, 3>(6 * a, 6 * a)
                        .copy_from(&nodes[a].q.r);
                }
            }
            *r = p.transpose() * r_p;
            if let Some((coef, s)) = s {
                let mut k = match k_p {
                    Some(k) => p.transpose() * k * p,
                    None => Mat12::zeros(),
                };
                for a in 0..2 {
                    if !active[a] {
                        continue;
                    }
                    let f = r.fixed_rows::<3>(6 * a).into_owned();
                    let mut blk = k.fixed_view_mut::<3, 3>(6 * a, 6 * a + 3);
                    blk += hat(&f);
                }
                s.fill(0.0);
                if let Some(c) = c_p {
                    let cg = p.transpose() * c * p;
                    *s += cg * coef.c;
                    // dv_p/dw: translation velocity R U depends on the rotation.
                    let mut dv = Mat12::zeros();
                    for a in 0..2 {
                        if active[a] {
                            let u = nodes[a].v.fixed_rows::<3>(0).into_owned();
                            let blk: Mat3 = -nodes[a].q.r * hat(&u);
                            dv.fixed_view_mut::<3, 3>(6 * a, 6 * a + 3).copy_from(&blk);
                        }
                    }
                    k += p.transpose() * c * dv;
                }
                *s += k * coef.k;
                apply_tangent_full(nodes, active, s, coef, &k);
            }
        }
    }
}

/// `s += c.k K (T - I)` column block by column block, which turns `c.k K` into `c.k K T`.
pub fn apply_tangent_full(
    nodes: &[NodeState; 2],
    active: [bool; 2],
    s: &mut Mat12,
    coef: &Coefficients,
    k: &Mat12,
) {
    if coef.k == 0.0 {
        return;
    }
    for b in 0..2 {
        if !active[b] {
            continue;
        }
        let t = &nodes[b].t;
        if *t == flexmb_lie::Mat6::identity() {
            continue;
        }
        let tm = t - flexmb_lie::Mat6::identity();
        let cols = k.fixed_columns::<6>(6 * b) * tm * coef.k;
        let mut target = s.fixed_columns_mut::<6>(6 * b);
        target += cols;
    }
}
