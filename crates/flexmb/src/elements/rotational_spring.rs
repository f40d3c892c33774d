//! Rotational spring-damper about the axis of a revolute or cylindrical joint.
//!
//! ```text
//!        node A                      node B
//!   (frame a_x, a_y, a_z = axis)   (frame b_x, ...)
//!           \__ theta: b_x seen in (a_x, a_y), about a_z __/
//! ```
//!
//! The element refers to a joint by name ([`RotationalSpring::joint`]) rather than carrying
//! two nodes and an axis of its own: the joint already holds the two nodes and the frames
//! whose z axes are the hinge axis, the same angle is what the `joint_coordinate` sensor
//! reports, and the spring cannot be put on an axis other than the hinge's by mistake.
//!
//! **Angle.** With the joint frames `A = R_a a`, `B = R_b b` (columns `a_x, a_y, a_z`, node
//! rotations `R_a`, `R_b`), the angle of `B`'s x axis in `A`'s xy plane is
//!
//! ```text
//! theta_g = atan2(s, c),   s = (R_a a_y) . (R_b b_x),   c = (R_a a_x) . (R_b b_x)
//! ```
//!
//! in `(-pi, pi]` (Haug 1989, Sect. 3.3, the dot-1 primitives of [`crate::joints::primitives`],
//! as the revolute joint's drive row uses them). For a spring wound over several turns the
//! element tracks the continuous angle with one element state `x`, the angle integrated
//! along the motion,
//!
//! ```text
//! e_x = xdot - thetadot = 0,   thetadot = g . v_p,     theta = x + wrap(theta_g - x),
//! ```
//!
//! `wrap` to `(-pi, pi]`: `theta` is the geometric angle on the branch nearest `x`, so the
//! force is a function of the configuration alone (the integration error of `x` only chooses
//! the turn, and would have to reach pi to matter), and `dtheta/dx = 0`. At the start
//! `x_0 = theta_g(q_0)` (0 for a joint read from a model file: its frames coincide there).
//!
//! **Gradient.** With `g_s`, `g_c`, `H_s`, `H_c` the gradients and their derivatives of the
//! dot-1 primitives (physical coordinates `w_p = (dx_a, theta_a, dx_b, theta_b)`, rotation
//! entries only), `D = s^2 + c^2`:
//!
//! ```text
//! g = (c g_s - s g_c) / D,
//! H = dg/dw_p = (g_s g_c^T - g_c g_s^T + c H_s - s H_c) / D - 2 g (s g_s + c g_c)^T / D.
//! ```
//!
//! **Law.** `e = theta - theta0`, `T = P + k e + F(e) + c edot` ([`ForceLaw`]: preload,
//! curves, stops; `edot = thetadot`), `k_t = k + F'(e)`, `c_t = c`; then exactly as for the
//! point-to-point spring ([`super::spring`], Géradin & Cardona 2001, Sect. 6.3, with the
//! length replaced by the angle):
//!
//! ```text
//! r_p = T g,    K_p = g (k_t g + c_t H^T v_p)^T + T H,    C_p = c_t g g^T,
//! de_x/dv = -g^T,   de_x/dw = -(H^T v_p)^T,   de_x/dxdot = 1,   de_x/dx = 0,
//! ```
//!
//! converted to the group's coordinates by [`super::physical`] (the gradient has rotation
//! entries only, which are the same in both groups). `T` is the torque the spring resists a
//! positive rotation with: the moment on node B about the axis is `-T`. Energy
//! `V = P e + k e^2 / 2 + integral_0^e F` on the law's side.
//!
//! **Parameter derivatives** ([`RotationalSpringParam`]): `dr_p/dk = e g`, `dr_p/dc = edot g`,
//! `dr_p/dtheta0 = -k_t g`, and those of the law ([`ForceLaw::parameter_derivative`]), zero
//! where a stop is off.
//!
//! # References
//! - E. J. Haug, Computer-Aided Kinematics and Dynamics of Mechanical Systems, Allyn and
//!   Bacon, 1989, Sect. 3.3 (dot-1 constraint and its derivatives).
//! - M. Géradin, A. Cardona, Flexible Multibody Dynamics: A Finite Element Approach, Wiley,
//!   2001, Sect. 6.3 (spring-damper elements).

use super::spring::Force;
use super::{
    physical, Coefficients, Context, DerivativeMethod, ElementKernel, ElementParameters,
    InitialStates, Local, LocalMatrix, LocalVector, Mat12, NodeState, Vec12,
};
use crate::joints::primitives::dot1;
use crate::model::parameters::RotationalSpringParam;
use crate::model::{ForceLaw, Joint, Model, NodeId, RotationalSpring};
use std::f64::consts::PI;

/// A rotational spring with its joint: the element as the assembly sees it.
#[derive(Clone, Copy, Debug)]
pub struct RotationalSpringElement<'m> {
    pub spring: &'m RotationalSpring,
    pub joint: &'m Joint,
}

/// The angle, its gradient and the gradient's derivative (physical coordinates), and the
/// physical velocity of the two slots.
struct Geometry {
    theta: f64,
    thetadot: f64,
    g: Vec12,
    h: Mat12,
    v_p: Vec12,
}

/// `a - 2 pi n`, the representative of `a` in `(-pi, pi]`.
fn wrap(a: f64) -> f64 {
    let w = a - 2.0 * PI * (a / (2.0 * PI)).round();
    if w <= -PI {
        w + 2.0 * PI
    } else {
        w
    }
}

/// The angle `theta_g` in `(-pi, pi]` of the joint's frame B about its frame A's z axis, with
/// its gradient and the gradient's derivative (module documentation), at the slots' frames
/// (identity for a ground slot).
pub fn joint_angle(joint: &Joint, nodes: &[NodeState]) -> (f64, Vec12, Mat12) {
    let (fa, fb) = (&nodes[0].q, &nodes[1].q);
    let (ra, rb) = (&joint.frame_a.r, &joint.frame_b.r);
    let bx = rb.column(0).into_owned();
    let ps = dot1(fa, &ra.column(1).into_owned(), fb, &bx);
    let pc = dot1(fa, &ra.column(0).into_owned(), fb, &bx);
    let (s, c) = (ps.phi, pc.phi);
    let d = s * s + c * c;
    let g = (ps.g * c - pc.g * s) / d;
    let h = (ps.g * pc.g.transpose() - pc.g * ps.g.transpose() + ps.h * c - pc.h * s) / d
        - g * (ps.g * s + pc.g * c).transpose() * (2.0 / d);
    (s.atan2(c), g, h)
}

impl<'m> RotationalSpringElement<'m> {
    /// Rotational spring `i` of `model` with its joint.
    pub fn of(model: &'m Model, i: usize) -> Self {
        let spring = &model.rotational_springs[i];
        Self {
            spring,
            joint: &model.joints[spring.joint.0],
        }
    }

    fn geometry(&self, ctx: &Context, local: &Local) -> Geometry {
        let (theta_g, g, h) = joint_angle(self.joint, local.nodes);
        let x = local.x[0];
        let theta = x + wrap(theta_g - x);
        let mut v_p = Vec12::zeros();
        for (a, node) in local.nodes.iter().enumerate() {
            let (xd, om) = physical::velocity(ctx.group, node);
            v_p.fixed_rows_mut::<3>(6 * a).copy_from(&xd);
            v_p.fixed_rows_mut::<3>(6 * a + 3).copy_from(&om);
        }
        Geometry {
            theta,
            thetadot: g.dot(&v_p),
            g,
            h,
            v_p,
        }
    }

    fn law(&self) -> &ForceLaw {
        &self.spring.law
    }

    fn force(&self, geo: &Geometry) -> Force {
        let s = self.spring;
        let e = geo.theta - s.angle;
        let (f, df) = self.law().elastic(e);
        let t = f + s.stiffness * e + s.damping * geo.thetadot;
        let active = self.law().acts_at(e, t);
        Force::of(active, t, s.stiffness + df, s.damping)
    }

    /// The continuous angle `theta` \[rad\] (module documentation).
    pub fn angle(&self, ctx: &Context, local: &Local) -> f64 {
        self.geometry(ctx, local).theta
    }

    /// The spring's torque `T` [N m] (module documentation: the moment on node B about the
    /// axis is `-T`).
    pub fn torque(&self, ctx: &Context, local: &Local) -> f64 {
        self.force(&self.geometry(ctx, local)).t
    }

    fn active_slots(&self) -> [bool; 2] {
        [self.joint.node_a.is_some(), self.joint.node_b.is_some()]
    }
}

impl ElementKernel for RotationalSpringElement<'_> {
    fn n_slots(&self) -> usize {
        2
    }

    fn node(&self, slot: usize) -> Option<NodeId> {
        [self.joint.node_a, self.joint.node_b][slot]
    }

    fn n_states(&self) -> usize {
        1
    }

    fn initial_states(&self, _ctx: &Context, local: &Local, x: &mut [f64]) -> InitialStates {
        x[0] = joint_angle(self.joint, local.nodes).0;
        Ok(())
    }

    fn evaluate(
        &self,
        ctx: &Context,
        local: &Local,
        r: &mut LocalVector,
        s: Option<(&Coefficients, &mut LocalMatrix)>,
    ) {
        let nodes = local.nodes;
        let geo = self.geometry(ctx, local);
        let force = self.force(&geo);
        let active = self.active_slots();
        let mut s = s;
        let coordinate = (&geo.g, &geo.h, &geo.v_p);
        let torque = (force.t, force.kt, force.ct);
        super::spring::coordinate_force(ctx, nodes, &active, coordinate, torque, r, &mut s);
        let hv = geo.h.transpose() * geo.v_p;
        r[12] = local.xdot[0] - geo.thetadot;
        let Some((coef, s)) = s else {
            return;
        };
        // the state row: -g^T on the velocities, -(H^T v_p)^T T on the configuration (the
        // rotation entries, the same in both groups); the state's own column: dr/dx = 0
        let mut s = s.view();
        for a in 0..2 {
            let row = if active[a] {
                let t = nodes[a].t.transpose();
                -(t * hv.fixed_rows::<6>(6 * a)) * coef.k - geo.g.fixed_rows::<6>(6 * a) * coef.c
            } else {
                flexmb_lie::Vec6::zeros()
            };
            for i in 0..6 {
                s[(12, 6 * a + i)] = row[i];
                s[(6 * a + i, 12)] = 0.0;
            }
        }
        s[(12, 12)] = coef.xdot;
    }

    fn potential_energy(&self, ctx: &Context, local: &Local) -> f64 {
        let geo = self.geometry(ctx, local);
        let e = geo.theta - self.spring.angle;
        if !self.law().on_side(e) {
            return 0.0;
        }
        self.law().energy(e) + 0.5 * self.spring.stiffness * e * e
    }
}

impl ElementParameters for RotationalSpringElement<'_> {
    type Param = RotationalSpringParam;

    fn parameter_derivative(
        &self,
        ctx: &Context,
        p: RotationalSpringParam,
        local: &Local,
        dr: &mut LocalVector,
    ) -> DerivativeMethod {
        let geo = self.geometry(ctx, local);
        let force = self.force(&geo);
        let on = if force.active { 1.0 } else { 0.0 };
        let e = geo.theta - self.spring.angle;
        let dt = match p {
            RotationalSpringParam::Stiffness => e * on,
            RotationalSpringParam::Damping => geo.thetadot * on,
            RotationalSpringParam::Angle => -force.kt,
            RotationalSpringParam::Law(q) => self.law().parameter_derivative(q, e) * on,
        };
        let r_p = geo.g * dt;
        let active = self.active_slots();
        physical::to_group(ctx.group, local.nodes, &active, &r_p, None, None, dr, None);
        dr[12] = 0.0;
        DerivativeMethod::Analytic
    }
}
