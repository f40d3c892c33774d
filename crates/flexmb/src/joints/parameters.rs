//! Derivatives of a joint's rows with respect to its parameters ([`JointParam`]): the
//! position-level rows `Phi`, the velocity-level rows `psi = B v + Phi_t` (12-vector `v` of
//! the two nodes' velocities) and the generalized forces `B^T lambda`.
//!
//! **Drive amplitudes** (analytic). With `a` an amplitude of the drive, `theta_a = df/da` and
//! `thetadot_a = df'/da` ([`crate::model::TimeFunction::amplitude_derivative`]), the driven
//! rotation row `Phi = cos(theta) p_1 - sin(theta) p_2` (`p_1 = y_a.x_b`, `p_2 = x_a.x_b`,
//! gradients `g_1`, `g_2`; [`super`]) gives
//!
//! ```text
//! dPhi/da   = (-sin(theta) p_1 - cos(theta) p_2) theta_a
//! dB/da     = (-sin(theta) g_1 - cos(theta) g_2) theta_a
//! dPhi_t/da = (-cos(theta) p_1 + sin(theta) p_2) thetadot theta_a + (-sin(theta) p_1 - cos(theta) p_2) thetadot_a
//! ```
//!
//! and the driven translation row `Phi = z_a.d - s(t)`: `dPhi/da = -s_a`,
//! `dPhi_t/da = -sdot_a`, `dB/da = 0`. Every other row is independent of the drive.
//!
//! **Joint position** (finite-difference default). Central difference on two copies of the
//! joint with the point moved by `+-h` ([`JointParam::set`], which places both joint frames'
//! points), `h = FD_STEP max(|p_k|, L, 1)` with `L` the largest distance of the joint's
//! nodes from the point at t = 0 (a node at the point within round-off must not make the
//! step vanish). `Phi` and `B` are linear in the
//! point, so the difference is exact up to round-off.

use super::primitives::dot1_into;
use super::{evaluate_joint, node_frames, Row, MAX_ROWS};
use crate::kernel::{DerivativeMethod, NodeState, Vec12, FD_STEP};
use crate::model::parameters::JointParam;
use crate::model::{Joint, Model};
use flexmb_lie::{Frame, Group};

/// Derivatives of a joint's rows with respect to one parameter (`n_rows` entries used).
#[derive(Clone, Copy, Debug)]
pub struct JointDerivative {
    pub n_rows: usize,
    /// `dPhi/dp` per row.
    pub dphi: [f64; MAX_ROWS],
    /// `d(B v + Phi_t)/dp` per row.
    pub dpsi: [f64; MAX_ROWS],
    /// `d(B^T lambda)/dp` (12, group coordinates, node A then node B).
    pub dforce: Vec12,
}

impl JointDerivative {
    /// All zero, for `n_rows` rows.
    pub fn zeros(n_rows: usize) -> Self {
        Self {
            n_rows,
            dphi: [0.0; MAX_ROWS],
            dpsi: [0.0; MAX_ROWS],
            dforce: Vec12::zeros(),
        }
    }
}

/// The parameter-derivative capability of a constraint, mirroring
/// [`crate::elements::ElementParameters`].
pub trait ConstraintParameters {
    /// Derivatives of the rows `rows` with respect to `p` at node kinematics `nodes` (velocities
    /// used by `psi`), time `t` and multipliers `lambda` (one per row). `model` gives the
    /// nodes' initial frames, in which joint points are stored.
    fn parameter_derivative(
        &self,
        model: &Model,
        rows: &[Row],
        p: JointParam,
        nodes: &[NodeState; 2],
        t: f64,
        lambda: &[f64],
    ) -> (JointDerivative, DerivativeMethod);
}

/// Velocities of the joint's two nodes, `[v_a; v_b]` (zero for the ground).
fn velocities(joint: &Joint, nodes: &[NodeState; 2]) -> Vec12 {
    let mut v = Vec12::zeros();
    for (slot, node) in [joint.node_a, joint.node_b].iter().enumerate() {
        if node.is_some() {
            v.fixed_rows_mut::<6>(6 * slot).copy_from(&nodes[slot].v);
        }
    }
    v
}

/// A gradient in physical coordinates in the group's (see [`super::evaluate_joint`]).
fn to_group(group: Group, joint: &Joint, frames: [&Frame; 2], g: &Vec12) -> Vec12 {
    let mut out = *g;
    for (slot, node) in [joint.node_a, joint.node_b].iter().enumerate() {
        if node.is_none() {
            out.fixed_rows_mut::<6>(6 * slot).fill(0.0);
        } else if group == Group::SE3 {
            let x = frames[slot].r.transpose() * g.fixed_rows::<3>(6 * slot);
            out.fixed_rows_mut::<3>(6 * slot).copy_from(&x);
        }
    }
    out
}

impl ConstraintParameters for Joint {
    fn parameter_derivative(
        &self,
        model: &Model,
        rows: &[Row],
        p: JointParam,
        nodes: &[NodeState; 2],
        t: f64,
        lambda: &[f64],
    ) -> (JointDerivative, DerivativeMethod) {
        match p {
            JointParam::Drive(a) => {
                let d = self.drive_derivative(model.group, rows, a, nodes, t, lambda);
                (d, DerivativeMethod::Analytic)
            }
            JointParam::Position(k) => {
                let point = match self.node_a {
                    Some(n) => model.nodes[n.0].frame.point(&self.frame_a.x),
                    None => self.frame_a.x,
                };
                let at = point[k];
                let reach = [self.node_a, self.node_b]
                    .iter()
                    .flatten()
                    .map(|n| (model.nodes[n.0].frame.x - point).norm())
                    .fold(0.0, f64::max);
                // Phi and B are linear in the point: the step need not be small, only not
                // lost in round-off (nodes at the point give a reach of round-off size).
                let h = FD_STEP * at.abs().max(reach).max(1.0);
                let v = velocities(self, nodes);
                let rows_at = |value: f64| {
                    let mut copy = self.clone();
                    p.set(&mut copy, &model.nodes, value);
                    evaluate_joint(model.group, &copy, rows, nodes, t, lambda, None)
                };
                let (plus, minus) = (rows_at(at + h), rows_at(at - h));
                let mut out = JointDerivative::zeros(rows.len());
                for r in 0..rows.len() {
                    let psi = |jv: &super::JointValues| jv.b[r].dot(&v) + jv.phi_t[r];
                    out.dphi[r] = (plus.phi[r] - minus.phi[r]) / (2.0 * h);
                    out.dpsi[r] = (psi(&plus) - psi(&minus)) / (2.0 * h);
                    out.dforce += (plus.b[r] - minus.b[r]) * (lambda[r] / (2.0 * h));
                }
                (out, DerivativeMethod::FiniteDifference)
            }
        }
    }
}

impl Joint {
    /// Derivatives with respect to amplitude `a` of the drive (module documentation).
    fn drive_derivative(
        &self,
        group: Group,
        rows: &[Row],
        a: usize,
        nodes: &[NodeState; 2],
        t: f64,
        lambda: &[f64],
    ) -> JointDerivative {
        let mut out = JointDerivative::zeros(rows.len());
        let Some(drive) = &self.drive else {
            return out;
        };
        let (th, thd, _) = drive.eval(t);
        let (th_a, thd_a, _) = drive.amplitude_derivative(a, t);
        let (fa, fb) = node_frames(self, nodes);
        let v = velocities(self, nodes);
        let axis_a = |i: usize| self.frame_a.r.column(i).into_owned();
        let axis_b = |i: usize| self.frame_b.r.column(i).into_owned();
        for (r, row) in rows.iter().enumerate() {
            match row {
                Row::DriveAngle => {
                    let (p1, g1) = dot1_into(&fa, &axis_a(1), &fb, &axis_b(0), 1.0, None);
                    let (p2, g2) = dot1_into(&fa, &axis_a(0), &fb, &axis_b(0), 1.0, None);
                    let (s, c) = th.sin_cos();
                    let dphi_dth = -s * p1 - c * p2;
                    let db = to_group(group, self, [&fa, &fb], &(g1 * (-s) - g2 * c)) * th_a;
                    let dphi_t = (-c * p1 + s * p2) * thd * th_a + dphi_dth * thd_a;
                    out.dphi[r] = dphi_dth * th_a;
                    out.dpsi[r] = db.dot(&v) + dphi_t;
                    out.dforce += db * lambda[r];
                }
                Row::DriveSlide => {
                    out.dphi[r] = -th_a;
                    out.dpsi[r] = -thd_a;
                }
                Row::Dot1 { .. } | Row::Dot2 { .. } | Row::Gear => {}
            }
        }
        out
    }
}
