//! Applied force and torque at a node, dead (inertial) or follower (body frame), scaled by
//! a time function `f(t)`. Physical residual (the load enters with a minus sign):
//!
//! ```text
//! inertial:  r_x = -f F,        r_theta = -f R^T M,   K_theta,theta = -f tilde(R^T M)
//! follower:  r_x = -f R F_b,    r_theta = -f M_b,     K_x,theta = f R tilde(F_b)
//! ```
//! converted to group coordinates by [`super::physical::to_group`].
//! Géradin & Cardona 2001, Sect. 6.4 (follower loads).
//!
//! **Parameter derivatives** ([`LoadParam`]): `r` is linear in `F`, `M` and `f`, so `dr/dF_k`
//! is `r` with `F = e_k, M = 0`, `dr/dM_k` is `r` with `F = 0, M = e_k`, and the derivative
//! with respect to an amplitude `a` of the time function is `r` with `f` replaced by
//! `df/da` ([`crate::model::TimeFunction::amplitude_derivative`]).
//!
//! **Inputs** ([`crate::model::Input`]): the load of an input takes `f = u_k`, the step's
//! input value (its function's at `t` in a run), and `dr/du_k` is `r` with `f` the load
//! factor alone (1 in dynamics).

use super::{
    physical, Coefficients, Context, DerivativeMethod, ElementKernel, ElementParameters, Local,
    LocalMatrix, LocalVector, NodeState,
};
use crate::model::parameters::LoadParam;
use crate::model::{Load, LoadFrame, NodeId};
use flexmb_lie::{so3::hat, Mat6, Vec3, Vec6};

impl Load {
    /// Physical residual of force `force` and torque `torque` scaled by `f` (module
    /// documentation).
    fn physical_residual(&self, force: &Vec3, torque: &Vec3, f: f64, n: &NodeState) -> Vec6 {
        let rot = n.q.r;
        let (rf, rm) = match self.frame {
            LoadFrame::Inertial => (-force * f, -(rot.transpose() * torque) * f),
            LoadFrame::Body => (-(rot * force) * f, -torque * f),
        };
        let mut r_p = Vec6::zeros();
        r_p.fixed_rows_mut::<3>(0).copy_from(&rf);
        r_p.fixed_rows_mut::<3>(3).copy_from(&rm);
        r_p
    }
}

impl Load {
    /// The scale of the load in `ctx`: its input's value (the step's, [`Context::input`]) or
    /// its function's, times the load factor.
    fn scale(&self, ctx: &Context) -> f64 {
        let f = match self.input {
            Some(k) => ctx.input(k),
            None => self.function.value(ctx.t),
        };
        f * ctx.load_scale
    }
}

impl ElementKernel for Load {
    fn n_slots(&self) -> usize {
        1
    }

    fn node(&self, _slot: usize) -> Option<NodeId> {
        Some(self.node)
    }

    fn evaluate(
        &self,
        ctx: &Context,
        local: &Local,
        r: &mut LocalVector,
        s: Option<(&Coefficients, &mut LocalMatrix)>,
    ) {
        let nodes = local.nodes;
        let f = self.scale(ctx);
        let rot = nodes[0].q.r;
        let mut r_p = Vec6::zeros();
        let mut k_p = Mat6::zeros();
        match self.frame {
            LoadFrame::Inertial => {
                let mb = rot.transpose() * self.torque;
                r_p.fixed_rows_mut::<3>(0).copy_from(&(-self.force * f));
                r_p.fixed_rows_mut::<3>(3).copy_from(&(-mb * f));
                k_p.fixed_view_mut::<3, 3>(3, 3).copy_from(&(-hat(&mb) * f));
            }
            LoadFrame::Body => {
                r_p.fixed_rows_mut::<3>(0)
                    .copy_from(&(-(rot * self.force) * f));
                r_p.fixed_rows_mut::<3>(3).copy_from(&(-self.torque * f));
                k_p.fixed_view_mut::<3, 3>(0, 3)
                    .copy_from(&(rot * hat(&self.force) * f));
            }
        }
        physical::to_group(ctx.group, nodes, &[true], &r_p, Some(&k_p), None, r, s);
    }
}

impl ElementParameters for Load {
    type Param = LoadParam;

    fn parameter_derivative(
        &self,
        ctx: &Context,
        p: LoadParam,
        local: &Local,
        dr: &mut LocalVector,
    ) -> DerivativeMethod {
        let nodes = local.nodes;
        let f = self.scale(ctx);
        let unit = |k: usize| {
            let mut e = Vec3::zeros();
            e[k] = 1.0;
            e
        };
        let zero = Vec3::zeros();
        let r_p = match p {
            LoadParam::Force(k) => self.physical_residual(&unit(k), &zero, f, &nodes[0]),
            LoadParam::Torque(k) => self.physical_residual(&zero, &unit(k), f, &nodes[0]),
            LoadParam::Amplitude(a) => {
                // An input given to the step does not move with its function.
                let given = self.input.is_some() && ctx.inputs.is_some();
                let d = if given {
                    0.0
                } else {
                    self.function.amplitude_derivative(a, ctx.t).0
                };
                let df = d * ctx.load_scale;
                self.physical_residual(&self.force, &self.torque, df, &nodes[0])
            }
        };
        physical::to_group(ctx.group, nodes, &[true], &r_p, None, None, dr, None);
        DerivativeMethod::Analytic
    }

    fn input_derivative(&self, ctx: &Context, local: &Local, dr: &mut LocalVector) {
        // r is linear in the input: dr/du is r at u = 1.
        let nodes = local.nodes;
        let scale = if self.input.is_some() {
            ctx.load_scale
        } else {
            0.0
        };
        let r_p = self.physical_residual(&self.force, &self.torque, scale, &nodes[0]);
        physical::to_group(ctx.group, nodes, &[true], &r_p, None, None, dr, None);
    }
}
