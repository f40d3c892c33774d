//! Geometrically exact beam on SE(3), two nodes (Sonneville, Cardona & Brüls 2014, CMAME 268,
//! 451-474, Sects. 3-4).
//!
//! ```text
//!   node a                                   node b
//!     o======================================o        H(s) = H_a exp((s/L) tilde(d)),
//!   H_a = (x_a, R_a O_a)                   H_b         s in [0, L]
//! ```
//!
//! The section frames at the ends are the node frames composed with constant rotations
//! `O_a`, `O_b` (identity unless members of different directions share a node). With
//! `d = log(H_a^-1 H_b)` (translation, rotation) the strain is constant along the element,
//!
//! ```text
//! epsilon = (d - d_0) / L,        sigma = C epsilon           (Eqs. (31)-(33))
//! delta d = P [w_a; w_b],         P = [ -T^-1(-d) A_a,  T^-1(d) A_b ],   A = blockdiag(O^T, O^T)
//! f_int   = P^T sigma                                          (Eq. (40))
//! K_t     = P^T (C / L) P + [ A_a^T G(-d, sigma) ; A_b^T G(d, sigma) ] P
//! ```
//!
//! where `G(d, sigma) = d(T^-1(d)^T sigma)/dd` ([`flexmb_lie::se3::tangent_inv_transpose_derivative`]).
//! `K_t` depends on the relative motion only: it is invariant under a superimposed rigid
//! motion, and the element is free of shear locking (the strain is exactly constant).
//!
//! Rayleigh damping (optional): stiffness-proportional stress resultants
//! `sigma_d = beta C (P v) / L` (`P v` is the rate of `d`), giving `f_d = P^T sigma_d`,
//! `C_t = beta P^T C P / L` and, in `K_t`, the derivatives of `P` at fixed `v`
//! (`H(x, y) = d(T^-1(x) y)/dx`, obtained from `G` by `H_ij = y . G(x, e_i)_{:,j}`);
//! mass-proportional forces `alpha M v` on the lumped nodal masses.
//!
//! The interpolation is the SE(3) geodesic between the two end frames (the paper's
//! two-node interpolation); a higher-order element needs another interpolation and is not
//! provided. Refinement is by more elements (the strain is exact for constant curvature, as
//! in the roll-up, and converges at second order otherwise).
//!
//! Inertia is lumped: each node carries half the element's mass `rho A L / 2` and rotary
//! inertia `J L / 2` as a rigid body at the node (SE(3) form of [`super::rigid_body`]),
//! including gravity. Beams need SE(3) nodes: on R3xSO(3) the model is rejected with a clear
//! error (the relative motion `d` and its tangent operator are those of SE(3)).

use super::{Coefficients, Context, ElementKernel, Mat12, NodeState, Vec12};
use crate::model::{Beam, NodeId, RigidBody};
use flexmb_lie::{se3, Frame, Mat3, Mat6, Vec6};
use nalgebra::SMatrix;

/// Length of the element axis for a reference relative motion `d_0` (the translation part,
/// which the SE(3) interpolation travels at constant speed).
pub fn arc_length(d0: &Vec6) -> f64 {
    d0.fixed_rows::<3>(0).norm()
}

/// `blockdiag(O^T, O^T)`: maps a node variation to a section-frame variation.
fn offset_map(o: &Mat3) -> Mat6 {
    let mut a = Mat6::zeros();
    a.fixed_view_mut::<3, 3>(0, 0).copy_from(&o.transpose());
    a.fixed_view_mut::<3, 3>(3, 3).copy_from(&o.transpose());
    a
}

/// `H(x, y) = d(T^-1(x) y)/dx` from the transposed derivative `G`:
/// `e_i . T^-1(x) y = (T^-1(x)^T e_i) . y`, so row `i` of `H` is `y^T G(x, e_i)`.
fn tangent_inv_derivative(x: &Vec6, y: &Vec6) -> Mat6 {
    let mut h = Mat6::zeros();
    for i in 0..6 {
        let mut e = Vec6::zeros();
        e[i] = 1.0;
        let row = y.transpose() * se3::tangent_inv_transpose_derivative(x, &e);
        h.set_row(i, &row);
    }
    h
}

/// Kinematic and static quantities of one element state.
pub struct BeamState {
    /// Relative motion `d = log(H_a^-1 H_b)`.
    pub d: Vec6,
    /// Strain `(d - d_0) / L`.
    pub strain: Vec6,
    /// Stress resultants `C epsilon` (forces, then moments, section frame).
    pub stress: Vec6,
}

impl Beam {
    /// Section frames of the element ends.
    fn end_frames(&self, nodes: &[NodeState; 2]) -> (Frame, Frame) {
        let (a, b) = (&nodes[0].q, &nodes[1].q);
        (
            Frame::new(a.x, a.r * self.offset_a),
            Frame::new(b.x, b.r * self.offset_b),
        )
    }

    /// Relative motion, strain and stress at the current configuration.
    pub fn state(&self, nodes: &[NodeState; 2]) -> BeamState {
        let (ha, hb) = self.end_frames(nodes);
        let d = se3::log(&ha.inverse().compose(&hb));
        let strain = (d - self.d0) / self.length;
        BeamState {
            d,
            strain,
            stress: self.section.stiffness * strain,
        }
    }

    /// Lumped inertia at one end as a rigid body on the node.
    fn lumped(&self, end: usize) -> RigidBody {
        let o = if end == 0 {
            &self.offset_a
        } else {
            &self.offset_b
        };
        let half = 0.5 * self.length;
        RigidBody {
            name: self.name.clone(),
            node: self.nodes[end],
            mass: self.section.mass_per_length * half,
            com: flexmb_lie::Vec3::zeros(),
            inertia: o * self.section.rotary_inertia * o.transpose() * half,
        }
    }
}

impl ElementKernel for Beam {
    fn nodes(&self) -> [Option<NodeId>; 2] {
        [Some(self.nodes[0]), Some(self.nodes[1])]
    }

    fn evaluate(
        &self,
        ctx: &Context,
        nodes: &[NodeState; 2],
        r: &mut Vec12,
        s: Option<(&Coefficients, &mut Mat12)>,
    ) {
        let st = self.state(nodes);
        let (aa, ab) = (offset_map(&self.offset_a), offset_map(&self.offset_b));
        let mut p = SMatrix::<f64, 6, 12>::zeros();
        p.fixed_view_mut::<6, 6>(0, 0)
            .copy_from(&(-se3::tangent_inv(&(-st.d)) * aa));
        p.fixed_view_mut::<6, 6>(0, 6)
            .copy_from(&(se3::tangent_inv(&st.d) * ab));
        let (alpha, beta) = (self.section.damping_mass, self.section.damping_stiffness);
        let mut v = Vec12::zeros();
        v.fixed_rows_mut::<6>(0).copy_from(&nodes[0].v);
        v.fixed_rows_mut::<6>(6).copy_from(&nodes[1].v);
        let c_over_l = self.section.stiffness / self.length;
        // total stress resultants: elastic plus stiffness-proportional damping
        let sigma = if beta > 0.0 {
            st.stress + c_over_l * (p * v) * beta
        } else {
            st.stress
        };
        *r = p.transpose() * sigma;
        if alpha > 0.0 {
            for end in 0..2 {
                let mm = self.lumped(end).mass_matrix_se3();
                let mut re = r.fixed_rows_mut::<6>(6 * end);
                re += mm * v.fixed_rows::<6>(6 * end) * alpha;
            }
        }
        let mut blocks = [(Vec6::zeros(), Mat6::zeros(), Mat6::zeros(), Mat6::zeros()); 2];
        for (end, blk) in blocks.iter_mut().enumerate() {
            let body = self.lumped(end);
            *blk = if s.is_some() {
                body.local(ctx, &nodes[end], false)
            } else {
                (
                    body.residual(ctx, &nodes[end]),
                    Mat6::zeros(),
                    Mat6::zeros(),
                    Mat6::zeros(),
                )
            };
            let mut re = r.fixed_rows_mut::<6>(6 * end);
            re += blk.0;
        }
        let Some((coef, s)) = s else {
            return;
        };
        let mut geometric = SMatrix::<f64, 12, 6>::zeros();
        geometric
            .fixed_view_mut::<6, 6>(0, 0)
            .copy_from(&(aa.transpose() * se3::tangent_inv_transpose_derivative(&(-st.d), &sigma)));
        geometric
            .fixed_view_mut::<6, 6>(6, 0)
            .copy_from(&(ab.transpose() * se3::tangent_inv_transpose_derivative(&st.d, &sigma)));
        let mut k = p.transpose() * c_over_l * p + geometric * p;
        let mut c_t = Mat12::zeros();
        if beta > 0.0 {
            // d(P v)/dd at fixed v, then through P to the node variations
            let va = aa * v.fixed_rows::<6>(0);
            let vb = ab * v.fixed_rows::<6>(6);
            let ddot = tangent_inv_derivative(&(-st.d), &va) + tangent_inv_derivative(&st.d, &vb);
            k += p.transpose() * c_over_l * beta * ddot * p;
            c_t += p.transpose() * c_over_l * beta * p;
        }
        if alpha > 0.0 {
            for end in 0..2 {
                let mm = self.lumped(end).mass_matrix_se3();
                let mut cb = c_t.fixed_view_mut::<6, 6>(6 * end, 6 * end);
                cb += mm * alpha;
            }
        }
        for (end, blk) in blocks.iter().enumerate() {
            let mut kb = k.fixed_view_mut::<6, 6>(6 * end, 6 * end);
            kb += blk.3;
        }
        s.fill(0.0);
        for (end, blk) in blocks.iter().enumerate() {
            let mut sb = s.fixed_view_mut::<6, 6>(6 * end, 6 * end);
            sb += blk.1 * coef.m + blk.2 * coef.c;
        }
        *s += k * coef.k + c_t * coef.c;
        super::physical::apply_tangent_full(nodes, [true, true], s, coef, &k);
    }

    fn kinetic_energy(&self, ctx: &Context, nodes: &[NodeState; 2]) -> f64 {
        (0..2)
            .map(|e| self.lumped(e).kinetic_energy(ctx, &[nodes[e], nodes[e]]))
            .sum()
    }

    fn potential_energy(&self, ctx: &Context, nodes: &[NodeState; 2]) -> f64 {
        let st = self.state(nodes);
        let gravity: f64 = (0..2)
            .map(|e| self.lumped(e).potential_energy(ctx, &[nodes[e], nodes[e]]))
            .sum();
        0.5 * self.length * st.strain.dot(&st.stress) + gravity
    }
}
