//! Rigid body: inertia forces and gravity of a body whose reference frame is a node.
//!
//! Notation: node frame `(x, R)`, centre of mass `X` in the node frame, mass `m`, inertia
//! `J_c` about the centre of mass, gravity `g` (inertial), velocity `v = (u, Omega)`.
//!
//! **SE(3)** (Brüls & Cardona 2010, Sect. 5.2; Sonneville & Brüls 2014, Eq. (9)): the mass
//! matrix about the node is constant,
//!
//! ```text
//! M = [[ m I, -m tilde(X) ], [ m tilde(X), J_O ]],   J_O = J_c - m tilde(X)^2,
//! r = M vdot - ad(v)^T M v - [ R^T m g ; tilde(X) R^T m g ],
//! C_t = -( ad(v)^T M + Q(M v) ),   Q((f, mu)) = [[0, tilde(f)], [tilde(f), tilde(mu)]],
//! K_t = -[[0, tilde(R^T m g)], [0, tilde(X) tilde(R^T m g)]].
//! ```
//!
//! **R3xSO(3)** (Brüls & Cardona 2010, Sect. 5.1, extended to an offset centre of mass):
//! with `c = -tilde(X) Omegadot + tilde(Omega)^2 X` the centre-of-mass acceleration is
//! `a_G = udot + R c`, and with `f_G = m a_G - m g`, `b = R^T f_G`:
//!
//! ```text
//! r = [ f_G ; tilde(X) b + J_c Omegadot + tilde(Omega) J_c Omega ],
//! M = [[ m I, -m R tilde(X) ], [ m tilde(X) R^T, J_O ]],
//! C_t = [[0, m R D], [0, m tilde(X) D + tilde(Omega) J_c - tilde(J_c Omega)]],
//!       D = -tilde(tilde(Omega) X) - tilde(Omega) tilde(X),
//! K_t = [[0, -m R tilde(c)], [0, tilde(X) (tilde(b) - m tilde(c))]].
//! ```
//! With `X = 0` both reduce to the classical Newton-Euler equations.
//!
//! **Parameter derivatives** ([`BodyParam`]). `r` is linear in `(m, J_c)` jointly (gravity
//! included), so `dr/dm` is `r` with `m = 1, J_c = 0` and `dr/dJ_c` (entry `(i, j)` and
//! `(j, i)`, `E = e_i e_j^T + e_j e_i^T`, or `e_i e_i^T`) is `r` with `m = 0, J_c = E`. With
//! `E_k = tilde(e_k)`, the derivative with respect to the centre of mass `X_k` is, on SE(3),
//!
//! ```text
//! dr/dX_k = M_X vdot - ad(v)^T M_X v - [ 0 ; E_k R^T m g ],
//! M_X = [[ 0, -m E_k ], [ m E_k, -m (E_k tilde(X) + tilde(X) E_k) ]],
//! ```
//!
//! and on R3xSO(3), with `c_X = -E_k Omegadot + tilde(Omega)^2 e_k`,
//! `dr/dX_k = [ m R c_X ; E_k b + tilde(X) R^T m R c_X ]`. Gravity:
//! `dr/dg_k = -[ R^T e_k m ; tilde(X) R^T e_k m ]` (SE(3)),
//! `-[ e_k m ; tilde(X) R^T e_k m ]` (R3xSO(3)), times the load factor.

use super::{
    Coefficients, Context, DerivativeMethod, ElementKernel, ElementParameters, Local, LocalMatrix,
    LocalVector, NodeState,
};
use crate::model::parameters::{BodyParam, VOIGT};
use crate::model::{NodeId, RigidBody};
use flexmb_lie::{se3, so3::hat, split, Group, Mat3, Mat6, Vec3, Vec6};

/// `Q(p) = d(ad(v)^T p)/dv` at fixed momentum `p = (f, mu)`:
/// `[[0, tilde(f)], [tilde(f), tilde(mu)]]` (SE(3), translation first).
pub(crate) fn momentum_jacobian(p: &Vec6) -> Mat6 {
    let (f, mu) = split(p);
    let mut q = Mat6::zeros();
    q.fixed_view_mut::<3, 3>(0, 3).copy_from(&hat(&f));
    q.fixed_view_mut::<3, 3>(3, 0).copy_from(&hat(&f));
    q.fixed_view_mut::<3, 3>(3, 3).copy_from(&hat(&mu));
    q
}

/// Mass matrix about the node, SE(3) form, of mass `m`, centre of mass `com` and inertia `jc`.
fn mass_matrix_se3(m: f64, com: &Vec3, jc: &Mat3) -> Mat6 {
    let xt = hat(com);
    let mut mm = Mat6::zeros();
    mm.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(Mat3::identity() * m));
    mm.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-xt * m));
    mm.fixed_view_mut::<3, 3>(3, 0).copy_from(&(xt * m));
    mm.fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&(jc - xt * xt * m));
    mm
}

/// Residual of a body of mass `m`, centre of mass `com` and inertia `jc` on node `n`.
fn residual_of(ctx: &Context, n: &NodeState, m: f64, com: &Vec3, jc: &Mat3) -> Vec6 {
    let g = ctx.model.gravity * (m * ctx.gravity_scale);
    let xt = hat(com);
    match ctx.group {
        Group::SE3 => {
            let mm = mass_matrix_se3(m, com, jc);
            let wg = n.q.r.transpose() * g;
            mm * n.vdot - se3::ad(&n.v).transpose() * (mm * n.v) - flexmb_lie::join(&wg, &(xt * wg))
        }
        Group::R3xSO3 => {
            let (ud, omd) = split(&n.vdot);
            let om = n.v.fixed_rows::<3>(3).into_owned();
            let omt = hat(&om);
            let c = -xt * omd + omt * (omt * com);
            let f_g = (ud + n.q.r * c) * m - g;
            let b = n.q.r.transpose() * f_g;
            flexmb_lie::join(&f_g, &(xt * b + jc * omd + omt * (jc * om)))
        }
    }
}

impl RigidBody {
    /// Mass matrix about the node, SE(3) form (constant).
    pub fn mass_matrix_se3(&self) -> Mat6 {
        mass_matrix_se3(self.mass, &self.com, &self.inertia)
    }

    /// Inertial position of the centre of mass.
    pub fn com_position(&self, n: &NodeState) -> Vec3 {
        n.q.point(&self.com)
    }

    /// Inertial velocity of the centre of mass.
    pub fn com_velocity(&self, group: Group, n: &NodeState) -> Vec3 {
        super::point_velocity(group, n, &self.com)
    }

    fn residual_se3(&self, ctx: &Context, n: &NodeState) -> (Vec6, Mat6, Mat6, Mat6) {
        let mm = self.mass_matrix_se3();
        let m = self.mass;
        let v = &n.v;
        let p = mm * v;
        let adt = se3::ad(v).transpose();
        let wg = n.q.r.transpose() * ctx.model.gravity * (m * ctx.gravity_scale);
        let xt = hat(&self.com);
        let fg = flexmb_lie::join(&wg, &(xt * wg));
        let r = mm * n.vdot - adt * p - fg;
        let c = -(adt * mm + momentum_jacobian(&p));
        let mut k = Mat6::zeros();
        let wgt = hat(&wg);
        k.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-wgt));
        k.fixed_view_mut::<3, 3>(3, 3).copy_from(&(-xt * wgt));
        (r, mm, c, k)
    }

    fn residual_r3so3(&self, ctx: &Context, n: &NodeState) -> (Vec6, Mat6, Mat6, Mat6) {
        let m = self.mass;
        let jc = self.inertia;
        let (ud, omd) = split(&n.vdot);
        let (_, om) = split(&n.v);
        let r_mat = n.q.r;
        let x = self.com;
        let xt = hat(&x);
        let omt = hat(&om);
        let c = -xt * omd + omt * (omt * x);
        let f_g = (ud + r_mat * c) * m - ctx.model.gravity * (m * ctx.gravity_scale);
        let b = r_mat.transpose() * f_g;
        let r_th = xt * b + jc * omd + omt * (jc * om);
        let r = flexmb_lie::join(&f_g, &r_th);
        let mut mm = Mat6::zeros();
        mm.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(Mat3::identity() * m));
        mm.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&(-r_mat * xt * m));
        mm.fixed_view_mut::<3, 3>(3, 0)
            .copy_from(&(xt * r_mat.transpose() * m));
        mm.fixed_view_mut::<3, 3>(3, 3)
            .copy_from(&(jc - xt * xt * m));
        let d = -hat(&(omt * x)) - omt * xt;
        let mut cm = Mat6::zeros();
        cm.fixed_view_mut::<3, 3>(0, 3).copy_from(&(r_mat * d * m));
        cm.fixed_view_mut::<3, 3>(3, 3)
            .copy_from(&(xt * d * m + omt * jc - hat(&(jc * om))));
        let mut k = Mat6::zeros();
        let ct = hat(&c);
        k.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-r_mat * ct * m));
        k.fixed_view_mut::<3, 3>(3, 3)
            .copy_from(&(xt * (hat(&b) - ct * m)));
        (r, mm, cm, k)
    }

    /// Residual only (the hot path of iterations that reuse the iteration matrix).
    pub fn residual(&self, ctx: &Context, n: &NodeState) -> Vec6 {
        residual_of(ctx, n, self.mass, &self.com, &self.inertia)
    }

    /// Residual, mass matrix, C_t and K_t of the body.
    pub(crate) fn local(&self, ctx: &Context, n: &NodeState) -> (Vec6, Mat6, Mat6, Mat6) {
        match ctx.group {
            Group::SE3 => self.residual_se3(ctx, n),
            Group::R3xSO3 => self.residual_r3so3(ctx, n),
        }
    }

    /// `dr/dX_k` (module documentation).
    fn com_derivative(&self, ctx: &Context, n: &NodeState, k: usize) -> Vec6 {
        let m = self.mass;
        let mut e = Vec3::zeros();
        e[k] = 1.0;
        let (ek, xt) = (hat(&e), hat(&self.com));
        match ctx.group {
            Group::SE3 => {
                let mut mx = Mat6::zeros();
                mx.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-ek * m));
                mx.fixed_view_mut::<3, 3>(3, 0).copy_from(&(ek * m));
                mx.fixed_view_mut::<3, 3>(3, 3)
                    .copy_from(&(-(ek * xt + xt * ek) * m));
                let wg = n.q.r.transpose() * ctx.model.gravity * (m * ctx.gravity_scale);
                let f = flexmb_lie::join(&Vec3::zeros(), &(ek * wg));
                mx * n.vdot - se3::ad(&n.v).transpose() * (mx * n.v) - f
            }
            Group::R3xSO3 => {
                let (ud, omd) = split(&n.vdot);
                let om = n.v.fixed_rows::<3>(3).into_owned();
                let omt = hat(&om);
                let c = -xt * omd + omt * (omt * self.com);
                let f_g = (ud + n.q.r * c) * m - ctx.model.gravity * (m * ctx.gravity_scale);
                let b = n.q.r.transpose() * f_g;
                let c_x = -ek * omd + omt * (omt * e);
                let f_x = n.q.r * c_x * m;
                flexmb_lie::join(&f_x, &(ek * b + xt * (n.q.r.transpose() * f_x)))
            }
        }
    }
}

impl ElementKernel for RigidBody {
    fn n_slots(&self) -> usize {
        1
    }

    fn node(&self, _slot: usize) -> Option<NodeId> {
        Some(self.node)
    }

    #[inline]
    fn evaluate(
        &self,
        ctx: &Context,
        local: &Local,
        r: &mut LocalVector,
        s: Option<(&Coefficients, &mut LocalMatrix)>,
    ) {
        let n = &local.nodes[0];
        let Some((coef, s)) = s else {
            r.fixed_rows_mut::<6>(0).copy_from(&self.residual(ctx, n));
            return;
        };
        let (res, mm, c, k) = self.local(ctx, n);
        r.fixed_rows_mut::<6>(0).copy_from(&res);
        let blk = mm * coef.m + c * coef.c + k * n.t * coef.k;
        s.fixed::<6>().copy_from(&blk);
    }

    fn kinetic_energy(&self, ctx: &Context, local: &Local) -> f64 {
        let n = &local.nodes[0];
        let om = n.v.fixed_rows::<3>(3).into_owned();
        let vg = self.com_velocity(ctx.group, n);
        0.5 * self.mass * vg.norm_squared() + 0.5 * om.dot(&(self.inertia * om))
    }

    fn potential_energy(&self, ctx: &Context, local: &Local) -> f64 {
        -self.mass * ctx.gravity_scale * ctx.model.gravity.dot(&self.com_position(&local.nodes[0]))
    }
}

impl ElementParameters for RigidBody {
    type Param = BodyParam;

    fn parameter_derivative(
        &self,
        ctx: &Context,
        p: BodyParam,
        local: &Local,
        dr: &mut LocalVector,
    ) -> DerivativeMethod {
        let n = &local.nodes[0];
        let d = match p {
            BodyParam::Mass => residual_of(ctx, n, 1.0, &self.com, &Mat3::zeros()),
            BodyParam::Inertia(k) => {
                let (i, j) = VOIGT[k];
                let mut e = Mat3::zeros();
                e[(i, j)] = 1.0;
                e[(j, i)] = 1.0;
                residual_of(ctx, n, 0.0, &self.com, &e)
            }
            BodyParam::Com(k) => self.com_derivative(ctx, n, k),
        };
        dr.fixed_rows_mut::<6>(0).copy_from(&d);
        DerivativeMethod::Analytic
    }

    fn gravity_derivative(&self, ctx: &Context, k: usize, local: &Local, dr: &mut LocalVector) {
        let n = &local.nodes[0];
        let mut w = Vec3::zeros();
        w[k] = -self.mass * ctx.gravity_scale;
        let wb = n.q.r.transpose() * w;
        let xt = hat(&self.com);
        let force = match ctx.group {
            Group::SE3 => wb,
            Group::R3xSO3 => w,
        };
        dr.fixed_rows_mut::<3>(0).copy_from(&force);
        dr.fixed_rows_mut::<3>(3).copy_from(&(xt * wb));
    }
}
