//! A rope through `n >= 2` points ([`crate::model::Rope`]): an element on `n` node slots, one
//! per point (a node may carry several points; a ground slot is fixed in space). The
//! intermediate points are frictionless eyelets or pulleys, so one tension acts along the
//! whole length
//!
//! ```text
//! L = sum_s l_s,    l_s = |P_{s+1} - P_s|,    P_s = x_s + R_s p_s,
//! T = k (L - L0) + c Ldot   while L > L0 and T > 0,    T = 0 when slack,
//! r_p = T g,   g = dL/dw_p = sum_s L_s^T g_s,   H = dg/dw_p = sum_s L_s^T H_s L_s,
//! K_p = g (k g + c H^T v_p)^T + T H,   C_p = c g g^T,   Ldot = g . v_p
//! ```
//!
//! in the physical coordinates of the slots ([`super::physical`]), `g_s`, `H_s` the gradient
//! of one segment's length and its derivative ([`super::spring`], Géradin & Cardona 2001,
//! Sect. 6.3) and `L_s` the selection of the segment's two slots. When the rope is slack
//! (or its damping would push) the force and its derivatives are zero.
//!
//! **Parameter derivatives** ([`RopeParam`]): `dr_p/dk = (L - L0) g`, `dr_p/dc = Ldot g`,
//! `dr_p/dL0 = -k g` while taut (zero when slack); the points by the finite-difference default
//! ([`super::central_difference`]).

use super::spring::segment;
use super::{
    central_difference, physical, Coefficients, Context, DerivativeMethod, ElementKernel,
    ElementParameters, Local, LocalMatrix, LocalVector, NodeState,
};
use crate::model::parameters::RopeParam;
use crate::model::{NodeId, Rope};
use nalgebra::{DMatrix, DVector};

/// The rope's length, rate, gradient and its derivative, and the physical slot velocities.
struct Geometry {
    l: f64,
    ldot: f64,
    g: DVector<f64>,
    h: DMatrix<f64>,
    v_p: DVector<f64>,
}

impl Rope {
    fn geometry(&self, ctx: &Context, nodes: &[NodeState]) -> Geometry {
        let n = 6 * nodes.len();
        let (mut l, mut g, mut h) = (0.0, DVector::zeros(n), DMatrix::zeros(n, n));
        for s in 0..self.points.len() - 1 {
            let (a, b) = (&self.points[s], &self.points[s + 1]);
            let (ls, gs, hs) = segment(&nodes[s], &a.point, &nodes[s + 1], &b.point);
            l += ls;
            let mut gv = g.rows_mut(6 * s, 12);
            gv += gs;
            let mut hv = h.view_mut((6 * s, 6 * s), (12, 12));
            hv += hs;
        }
        let mut v_p = DVector::zeros(n);
        for (a, node) in nodes.iter().enumerate() {
            let (xd, om) = physical::velocity(ctx.group, node);
            v_p.fixed_rows_mut::<3>(6 * a).copy_from(&xd);
            v_p.fixed_rows_mut::<3>(6 * a + 3).copy_from(&om);
        }
        let ldot = g.dot(&v_p);
        Geometry { l, ldot, g, h, v_p }
    }

    /// The tension: `k (L - L0) + c Ldot` while taut and pulling, else 0.
    fn tension(&self, geo: &Geometry) -> f64 {
        if geo.l <= self.rest_length {
            return 0.0;
        }
        (self.stiffness * (geo.l - self.rest_length) + self.damping * geo.ldot).max(0.0)
    }

    /// The tension of the rope at `local` \[N\].
    pub fn force(&self, ctx: &Context, local: &Local) -> f64 {
        self.tension(&self.geometry(ctx, local.nodes))
    }

    fn active(&self) -> Vec<bool> {
        self.points.iter().map(|p| p.node.is_some()).collect()
    }
}

impl ElementKernel for Rope {
    fn n_slots(&self) -> usize {
        self.points.len()
    }

    fn node(&self, slot: usize) -> Option<NodeId> {
        self.points[slot].node
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
        let tension = self.tension(&geo);
        let r_p = &geo.g * tension;
        let active = self.active();
        // The tangents only when asked for and taut (a slack rope has none).
        let (k_p, c_p) = match &s {
            Some(_) if tension > 0.0 => {
                let dt = &geo.g * self.stiffness + geo.h.transpose() * &geo.v_p * self.damping;
                let k_p = &geo.g * dt.transpose() + &geo.h * tension;
                let c_p = &geo.g * geo.g.transpose() * self.damping;
                (Some(k_p), Some(c_p))
            }
            _ => (None, None),
        };
        let (k, c) = (k_p.as_ref(), c_p.as_ref());
        physical::to_group(ctx.group, nodes, &active, &r_p, k, c, r, s);
    }

    fn potential_energy(&self, ctx: &Context, local: &Local) -> f64 {
        let e = (self.geometry(ctx, local.nodes).l - self.rest_length).max(0.0);
        0.5 * self.stiffness * e * e
    }
}

impl ElementParameters for Rope {
    type Param = RopeParam;

    fn parameter_derivative(
        &self,
        ctx: &Context,
        p: RopeParam,
        local: &Local,
        dr: &mut LocalVector,
    ) -> DerivativeMethod {
        let nodes = local.nodes;
        let geo = self.geometry(ctx, nodes);
        let dt = match p {
            RopeParam::Stiffness => geo.l - self.rest_length,
            RopeParam::Damping => geo.ldot,
            RopeParam::RestLength => -self.stiffness,
            RopeParam::Point(..) => {
                let model_nodes = &ctx.model.nodes;
                let at = p.get(self, model_nodes);
                // a typical length: the rope's, or the point's distance from the origin
                let scale = self.rest_length.max(geo.l).max(at.abs());
                let scale = if scale > 1e-300 { scale } else { 1.0 };
                let set = |rope: &mut Rope, v: f64| p.set(rope, model_nodes, v);
                return central_difference(self, ctx, local, (at, scale), set, dr);
            }
        };
        // a slack rope pulls nothing, whatever its parameters
        let dt = if self.tension(&geo) > 0.0 { dt } else { 0.0 };
        let r_p = &geo.g * dt;
        let active = self.active();
        physical::to_group(ctx.group, nodes, &active, &r_p, None, None, dr, None);
        DerivativeMethod::Analytic
    }
}
