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
//! **Maxwell branch** ([`crate::model::Relaxation`], viscoelastic relaxation; the standard
//! linear solid when the spring is there too): a spring `k_m` in series with a damper
//! `c_m`. The damper's elongation `z` is the element's one state, with its own equation
//!
//! ```text
//! T = k (l - l0) + c ldot + k_m (l - l0 - z),     e = zdot - (k_m / c_m) (l - l0 - z) = 0,
//! dr_p/dz = -k_m g,   de/dw_p = -(k_m / c_m) g^T,   de/dz = k_m / c_m,   de/dzdot = 1,
//! ```
//!
//! and `k + k_m` in place of `k` in `K_p`. At the start the branch is unstressed
//! (`z_0 = l(q_0) - l0`).
//!
//! **Parameter derivatives** ([`SpringParam`]): `dr_p/dk = (l - l0) g`, `dr_p/dc = ldot g`,
//! `dr_p/dl0 = -(k + k_m) g` (`de/dl0 = k_m / c_m`), `dr_p/dk_m = (l - l0 - z) g`
//! (`de/dk_m = -(l - l0 - z) / c_m`), `de/dc_m = k_m (l - l0 - z) / c_m^2`; the attachment
//! points by the finite-difference default ([`super::central_difference`]).

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

/// The length `l = |P_b - P_a|` of the segment between the points `p_a` of node `na` and
/// `p_b` of node `nb` (node frames), its gradient `g = dl/dw_p` and the derivative `H` of
/// the gradient (module documentation), in the physical coordinates of the two nodes.
pub(super) fn segment(na: &NodeState, pa: &Vec3, nb: &NodeState, pb: &Vec3) -> (f64, Vec12, Mat12) {
    let d = nb.q.point(pb) - na.q.point(pa);
    let l = d.norm().max(1e-300);
    let n = d / l;
    let mut dm = SMatrix::<f64, 3, 12>::zeros();
    dm.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(-Mat3::identity()));
    dm.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&(na.q.r * hat(pa)));
    dm.fixed_view_mut::<3, 3>(0, 6).copy_from(&Mat3::identity());
    dm.fixed_view_mut::<3, 3>(0, 9)
        .copy_from(&(-nb.q.r * hat(pb)));
    let g = dm.transpose() * n;
    let proj = (Mat3::identity() - n * n.transpose()) / l;
    let mut h = dm.transpose() * proj * dm;
    let na_b: Vec3 = na.q.r.transpose() * n;
    let nb_b: Vec3 = nb.q.r.transpose() * n;
    let mut blk = h.fixed_view_mut::<3, 3>(3, 3);
    blk -= hat(pa) * hat(&na_b);
    let mut blk = h.fixed_view_mut::<3, 3>(9, 9);
    blk += hat(pb) * hat(&nb_b);
    (l, g, h)
}

impl SpringDamper {
    fn geometry(&self, ctx: &Context, nodes: &[NodeState]) -> Geometry {
        let (l, g, h) = segment(&nodes[0], &self.point_a, &nodes[1], &self.point_b);
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

    /// The tension `T` (module documentation), the branch included \[N\].
    pub fn tension(&self, ctx: &Context, local: &Local) -> f64 {
        let geo = self.geometry(ctx, local.nodes);
        self.tension_and_stiffness(&geo, self.branch(&geo, local)).0
    }

    /// `T` and the stiffness `k + k_m` along the line.
    fn tension_and_stiffness(&self, geo: &Geometry, branch: Option<(f64, f64, f64)>) -> (f64, f64) {
        let mut tension = self.stiffness * (geo.l - self.rest_length) + self.damping * geo.ldot;
        let mut stiffness = self.stiffness;
        if let Some((km, _, stretch)) = branch {
            tension += km * stretch;
            stiffness += km;
        }
        (tension, stiffness)
    }

    /// `(k_m, c_m, l - l0 - z)` of the Maxwell branch, if any.
    fn branch(&self, geo: &Geometry, local: &Local) -> Option<(f64, f64, f64)> {
        self.relaxation.map(|m| {
            (
                m.stiffness,
                m.damping,
                geo.l - self.rest_length - local.x[0],
            )
        })
    }
}

impl ElementKernel for SpringDamper {
    fn n_slots(&self) -> usize {
        2
    }

    fn node(&self, slot: usize) -> Option<NodeId> {
        [self.node_a, self.node_b][slot]
    }

    fn n_states(&self) -> usize {
        self.relaxation.is_some() as usize
    }

    fn initial_states(&self, ctx: &Context, local: &Local, x: &mut [f64]) {
        if self.relaxation.is_some() {
            x[0] = self.geometry(ctx, local.nodes).l - self.rest_length;
        }
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
        let branch = self.branch(&geo, local);
        let (tension, stiffness) = self.tension_and_stiffness(&geo, branch);
        let r_p = geo.g * tension;
        let dt = geo.g * stiffness + geo.h.transpose() * geo.v_p * self.damping;
        let k_p = geo.g * dt.transpose() + geo.h * tension;
        let c_p = geo.g * geo.g.transpose() * self.damping;
        let active = self.active();
        let mut s = s;
        let matrix = s.as_mut().map(|(coef, m)| (*coef, &mut **m));
        physical::to_group(
            ctx.group,
            nodes,
            &active,
            &r_p,
            Some(&k_p),
            Some(&c_p),
            r,
            matrix,
        );
        let Some((km, cm, stretch)) = branch else {
            return;
        };
        r[12] = local.xdot[0] - km / cm * stretch;
        let Some((coef, s)) = s else {
            return;
        };
        // dl/dw in group coordinates, like a residual
        let mut g = geo.g;
        physical::translations_to_group(ctx.group, nodes, &active, &mut g);
        let mut s = s.view();
        for a in 0..2 {
            let row = if active[a] {
                nodes[a].t.transpose() * g.fixed_rows::<6>(6 * a) * (-km / cm * coef.k)
            } else {
                flexmb_lie::Vec6::zeros()
            };
            for i in 0..6 {
                s[(6 * a + i, 12)] = -km * g[6 * a + i] * coef.x;
                s[(12, 6 * a + i)] = row[i];
            }
        }
        s[(12, 12)] = km / cm * coef.x + coef.xdot;
    }

    fn potential_energy(&self, ctx: &Context, local: &Local) -> f64 {
        let geo = self.geometry(ctx, local.nodes);
        let e = geo.l - self.rest_length;
        let branch = self
            .branch(&geo, local)
            .map_or(0.0, |(km, _, s)| 0.5 * km * s * s);
        0.5 * self.stiffness * e * e + branch
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
        let branch = self.branch(&geo, local);
        let (km, cm, stretch) = branch.unwrap_or((0.0, 1.0, 0.0));
        // (dT/dp, de/dp)
        let (dt, de) = match p {
            SpringParam::Stiffness => (geo.l - self.rest_length, 0.0),
            SpringParam::Damping => (geo.ldot, 0.0),
            SpringParam::RestLength => (-self.stiffness - km, km / cm),
            SpringParam::RelaxationStiffness => (stretch, -stretch / cm),
            SpringParam::RelaxationDamping => (0.0, km * stretch / (cm * cm)),
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
        physical::to_group(ctx.group, nodes, &self.active(), &r_p, None, None, dr, None);
        if branch.is_some() {
            dr[12] = de;
        }
        DerivativeMethod::Analytic
    }
}
