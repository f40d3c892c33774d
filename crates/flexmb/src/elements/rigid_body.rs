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

use super::{Coefficients, Context, ElementKernel, Mat12, NodeState, Parameter, Vec12};
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

impl RigidBody {
    /// Mass matrix about the node, SE(3) form (constant).
    pub fn mass_matrix_se3(&self) -> Mat6 {
        let m = self.mass;
        let xt = hat(&self.com);
        let mut mm = Mat6::zeros();
        mm.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(Mat3::identity() * m));
        mm.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-xt * m));
        mm.fixed_view_mut::<3, 3>(3, 0).copy_from(&(xt * m));
        mm.fixed_view_mut::<3, 3>(3, 3)
            .copy_from(&(self.inertia - xt * xt * m));
        mm
    }

    /// Inertial position of the centre of mass.
    pub fn com_position(&self, n: &NodeState) -> Vec3 {
        n.q.point(&self.com)
    }

    /// Inertial velocity of the centre of mass.
    pub fn com_velocity(&self, group: Group, n: &NodeState) -> Vec3 {
        super::point_velocity(group, n, &self.com)
    }

    fn residual_se3(
        &self,
        ctx: &Context,
        n: &NodeState,
        unit_mass: bool,
    ) -> (Vec6, Mat6, Mat6, Mat6) {
        let mut mm = self.mass_matrix_se3();
        if unit_mass {
            // d/dm of everything: inertia tensor does not scale with m here (J_c given).
            let xt = hat(&self.com);
            mm.fill(0.0);
            mm.fixed_view_mut::<3, 3>(0, 0).copy_from(&Mat3::identity());
            mm.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-xt));
            mm.fixed_view_mut::<3, 3>(3, 0).copy_from(&xt);
            mm.fixed_view_mut::<3, 3>(3, 3).copy_from(&(-xt * xt));
        }
        let m = if unit_mass { 1.0 } else { self.mass };
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

    fn residual_r3so3(
        &self,
        ctx: &Context,
        n: &NodeState,
        unit_mass: bool,
    ) -> (Vec6, Mat6, Mat6, Mat6) {
        let m = if unit_mass { 1.0 } else { self.mass };
        let jc = if unit_mass {
            Mat3::zeros()
        } else {
            self.inertia
        };
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
        let m = self.mass;
        let g = ctx.model.gravity * (m * ctx.gravity_scale);
        let xt = hat(&self.com);
        match ctx.group {
            Group::SE3 => {
                let mm = self.mass_matrix_se3();
                let wg = n.q.r.transpose() * g;
                mm * n.vdot
                    - se3::ad(&n.v).transpose() * (mm * n.v)
                    - flexmb_lie::join(&wg, &(xt * wg))
            }
            Group::R3xSO3 => {
                let (ud, omd) = split(&n.vdot);
                let om = n.v.fixed_rows::<3>(3).into_owned();
                let omt = hat(&om);
                let c = -xt * omd + omt * (omt * self.com);
                let f_g = (ud + n.q.r * c) * m - g;
                let b = n.q.r.transpose() * f_g;
                let jc = self.inertia;
                flexmb_lie::join(&f_g, &(xt * b + jc * omd + omt * (jc * om)))
            }
        }
    }

    /// Residual, mass matrix, C_t and K_t of the body (unit mass: their derivative wrt m).
    pub(crate) fn local(
        &self,
        ctx: &Context,
        n: &NodeState,
        unit_mass: bool,
    ) -> (Vec6, Mat6, Mat6, Mat6) {
        match ctx.group {
            Group::SE3 => self.residual_se3(ctx, n, unit_mass),
            Group::R3xSO3 => self.residual_r3so3(ctx, n, unit_mass),
        }
    }
}

impl ElementKernel for RigidBody {
    fn nodes(&self) -> [Option<NodeId>; 2] {
        [Some(self.node), None]
    }

    fn evaluate(
        &self,
        ctx: &Context,
        nodes: &[NodeState; 2],
        r: &mut Vec12,
        s: Option<(&Coefficients, &mut Mat12)>,
    ) {
        let n = &nodes[0];
        r.fill(0.0);
        if s.is_none() {
            r.fixed_rows_mut::<6>(0).copy_from(&self.residual(ctx, n));
            return;
        }
        let (res, mm, c, k) = self.local(ctx, n, false);
        r.fixed_rows_mut::<6>(0).copy_from(&res);
        if let Some((coef, s)) = s {
            s.fill(0.0);
            let blk = mm * coef.m + c * coef.c + k * n.t * coef.k;
            s.fixed_view_mut::<6, 6>(0, 0).copy_from(&blk);
        }
    }

    fn parameter_derivative(
        &self,
        ctx: &Context,
        param: &Parameter,
        nodes: &[NodeState; 2],
        dr: &mut Vec12,
    ) -> bool {
        match param {
            Parameter::BodyMass(name) if *name == self.name => {
                let (res, ..) = self.local(ctx, &nodes[0], true);
                dr.fill(0.0);
                dr.fixed_rows_mut::<6>(0).copy_from(&res);
                true
            }
            _ => false,
        }
    }

    fn kinetic_energy(&self, ctx: &Context, nodes: &[NodeState; 2]) -> f64 {
        let n = &nodes[0];
        let om = n.v.fixed_rows::<3>(3).into_owned();
        let vg = self.com_velocity(ctx.group, n);
        0.5 * self.mass * vg.norm_squared() + 0.5 * om.dot(&(self.inertia * om))
    }

    fn potential_energy(&self, ctx: &Context, nodes: &[NodeState; 2]) -> f64 {
        -self.mass * ctx.gravity_scale * ctx.model.gravity.dot(&self.com_position(&nodes[0]))
    }
}
