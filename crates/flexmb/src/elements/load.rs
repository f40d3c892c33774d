//! Applied force and torque at a node, dead (inertial) or follower (body frame), scaled by
//! a time function `f(t)`. Physical residual (the load enters with a minus sign):
//!
//! ```text
//! inertial:  r_x = -f F,        r_theta = -f R^T M,   K_theta,theta = -f tilde(R^T M)
//! follower:  r_x = -f R F_b,    r_theta = -f M_b,     K_x,theta = f R tilde(F_b)
//! ```
//! converted to group coordinates by [`super::physical::to_group`].
//! Géradin & Cardona 2001, Sect. 6.4 (follower loads).

use super::{physical, Coefficients, Context, ElementKernel, Mat12, NodeState, Vec12};
use crate::model::{Load, LoadFrame, NodeId};
use flexmb_lie::so3::hat;

impl ElementKernel for Load {
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
        let f = self.function.value(ctx.t) * ctx.load_scale;
        let rot = nodes[0].q.r;
        let mut r_p = Vec12::zeros();
        let mut k_p = Mat12::zeros();
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
        physical::to_group(
            ctx.group,
            nodes,
            [true, false],
            &r_p,
            Some(&k_p),
            None,
            r,
            s,
        );
    }
}
