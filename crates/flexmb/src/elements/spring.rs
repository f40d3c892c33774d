//! Linear spring-damper between two points `P_a = x_a + R_a p_a`, `P_b = x_b + R_b p_b`.
//!
//! With `d = P_b - P_a`, `l = |d|`, `n = d / l`, tension `T = k (l - l0) + c ldot`:
//!
//! ```text
//! r_p = T g,     g = dl/dw_p = D^T n,   D = [ -I, R_a tilde(p_a), I, -R_b tilde(p_b) ]
//! H   = dg/dw_p = D^T (I - n n^T)/l D + blockdiag(0, -tilde(p_a) tilde(R_a^T n), 0, tilde(p_b) tilde(R_b^T n))
//! K_p = g (k g + c H^T v_p)^T + T H,      C_p = c g g^T,     ldot = g . v_p
//! ```
//! (physical coordinates, see [`super::physical`]). Géradin & Cardona 2001, Sect. 6.3.
//!
//! **Parameter derivatives** ([`SpringParam`]): `dr_p/dk = (l - l0) g`, `dr_p/dc = ldot g`,
//! `dr_p/dl0 = -k g`; the attachment points by the finite-difference default
//! ([`super::central_difference`]).

use super::{
    central_difference, physical, Coefficients, Context, DerivativeMethod, ElementKernel,
    ElementParameters, Local, LocalMatrix, LocalVector, Mat12, NodeState, Vec12,
};
use crate::model::parameters::SpringParam;
use crate::model::{NodeId, SpringDamper};
use flexmb_lie::{so3::hat, Mat3, Vec3};
use nalgebra::SMatrix;

struct Geometry {
    l: f64,
    ldot: f64,
    g: Vec12,
    h: Mat12,
    v_p: Vec12,
}

impl SpringDamper {
    fn geometry(&self, ctx: &Context, nodes: &[NodeState]) -> Geometry {
        let (na, nb) = (&nodes[0], &nodes[1]);
        let pa = na.q.point(&self.point_a);
        let pb = nb.q.point(&self.point_b);
        let d = pb - pa;
        let l = d.norm().max(1e-300);
        let n = d / l;
        let mut dm = SMatrix::<f64, 3, 12>::zeros();
        dm.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(-Mat3::identity()));
        dm.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&(na.q.r * hat(&self.point_a)));
        dm.fixed_view_mut::<3, 3>(0, 6).copy_from(&Mat3::identity());
        dm.fixed_view_mut::<3, 3>(0, 9)
            .copy_from(&(-nb.q.r * hat(&self.point_b)));
        let g = dm.transpose() * n;
        let proj = (Mat3::identity() - n * n.transpose()) / l;
        let mut h = dm.transpose() * proj * dm;
        let na_b: Vec3 = na.q.r.transpose() * n;
        let nb_b: Vec3 = nb.q.r.transpose() * n;
        let mut blk = h.fixed_view_mut::<3, 3>(3, 3);
        blk -= hat(&self.point_a) * hat(&na_b);
        let mut blk = h.fixed_view_mut::<3, 3>(9, 9);
        blk += hat(&self.point_b) * hat(&nb_b);
        let mut v_p = Vec12::zeros();
        for (a, node) in nodes.iter().enumerate() {
            let (xd, om) = physical::velocity(ctx.group, node);
            v_p.fixed_rows_mut::<3>(6 * a).copy_from(&xd);
            v_p.fixed_rows_mut::<3>(6 * a + 3).copy_from(&om);
        }
        let ldot = g.dot(&v_p);
        Geometry { l, ldot, g, h, v_p }
    }

    fn active(&self) -> [bool; 2] {
        [self.node_a.is_some(), self.node_b.is_some()]
    }
}

impl ElementKernel for SpringDamper {
    fn n_slots(&self) -> usize {
        2
    }

    fn node(&self, slot: usize) -> Option<NodeId> {
        [self.node_a, self.node_b][slot]
    }

    fn evaluate(
        &self,
        ctx: &Context,
        local: &Local,
        r: &mut LocalVector,
        s: Option<(&Coefficients, &mut LocalMatrix)>,
    ) {
        let nodes = local.nodes;
        let geo = self.geometry(ctx, nodes);
        let tension = self.stiffness * (geo.l - self.rest_length) + self.damping * geo.ldot;
        let r_p = geo.g * tension;
        let dt = geo.g * self.stiffness + geo.h.transpose() * geo.v_p * self.damping;
        let k_p = geo.g * dt.transpose() + geo.h * tension;
        let c_p = geo.g * geo.g.transpose() * self.damping;
        let (r_p, k_p, c_p) = (r_p.as_slice(), k_p.as_slice(), c_p.as_slice());
        physical::to_group(
            ctx.group,
            nodes,
            &self.active(),
            r_p,
            Some(k_p),
            Some(c_p),
            r,
            s,
        );
    }

    fn potential_energy(&self, ctx: &Context, local: &Local) -> f64 {
        let e = self.geometry(ctx, local.nodes).l - self.rest_length;
        0.5 * self.stiffness * e * e
    }
}

impl ElementParameters for SpringDamper {
    type Param = SpringParam;

    fn parameter_derivative(
        &self,
        ctx: &Context,
        p: SpringParam,
        local: &Local,
        dr: &mut LocalVector,
    ) -> DerivativeMethod {
        let nodes = local.nodes;
        let geo = self.geometry(ctx, nodes);
        let dt = match p {
            SpringParam::Stiffness => geo.l - self.rest_length,
            SpringParam::Damping => geo.ldot,
            SpringParam::RestLength => -self.stiffness,
            SpringParam::PointA(_) | SpringParam::PointB(_) => {
                let model_nodes = &ctx.model.nodes;
                let at = p.get(self, model_nodes);
                // a typical length: the spring's, or the point's distance from the origin
                let scale = self.rest_length.max(geo.l).max(at.abs());
                let scale = if scale > 1e-300 { scale } else { 1.0 };
                let set = |s: &mut SpringDamper, v: f64| p.set(s, model_nodes, v);
                return central_difference(self, ctx, local, (at, scale), set, dr);
            }
        };
        let r_p = geo.g * dt;
        physical::to_group(
            ctx.group,
            nodes,
            &self.active(),
            r_p.as_slice(),
            None,
            None,
            dr,
            None,
        );
        DerivativeMethod::Analytic
    }
}
