//! 6-DOF bushing on SE(3): a linear stiffness and damping on the relative configuration of
//! two frames, in a large-rotation form (the SE(3) logarithm) and a small-rotation form
//! (position and rotation vector).
//!
//! ```text
//!   node A                 node B
//!     o--[F_a]~~~~~~~~~~[F_b]--o       H_A = Q_a F_a,  H_B = Q_b F_b   (bushing frames)
//! ```
//!
//! With the bushing frames `H_A`, `H_B` (node configurations `Q` composed with the constant
//! offsets `F`; a ground slot is the identity, its offset the frame in space), the
//! deformation of the **large-rotation form** ([`BushingForm::LargeRotation`]) is the SE(3)
//! logarithm of the relative configuration (translation first),
//!
//! ```text
//! d = log(H_A^-1 H_B),     sigma = K d + C ddot,
//! delta d = P [w_a; w_b],  P = [ -T^-1(-d) A_a,  T^-1(d) A_b ],   A = Ad(F^-1),
//! r       = P^T sigma,     ddot = P [v_a; v_b],
//! K_t     = P^T K P + [ A_a^T G(-d, sigma) ; A_b^T G(d, sigma) ] P + P^T C (H(-d, A_a v_a) + H(d, A_b v_b)) P,
//! C_t     = P^T C P,
//! ```
//!
//! `w`, `v` the nodes' SE(3) variations and body velocities, `A = Ad(F^-1)` the map from a
//! node's to its bushing frame's, `T^-1` the inverse tangent operator of SE(3),
//! `G(x, y) = d(T^-1(x)^T y)/dx` ([`flexmb_lie::se3::tangent_inv_transpose_derivative`]),
//! `H(x, y) = d(T^-1(x) y)/dx`. This is the two-node SE(3) beam of Sonneville, Cardona &
//! Brüls (2014), Sects. 3-4, Eqs. (31)-(40) ([`super::beam`]), with the sectional stiffness
//! over the length `C / L` replaced by the bushing's `K`, the stiffness-proportional damping
//! by the bushing's `C`, no reference deformation (the frames coincide when the bushing is
//! unstressed) and no inertia: the element has the beam's properties, an internal force that
//! depends on the relative motion only (objective: invariant under a superimposed rigid
//! motion, whatever the size of the relative rotation) and exact tangents. For small relative
//! motion `d` is the displacement of frame B in frame A and the rotation vector of their
//! relative rotation, so `K` and `C` have the meaning of the usual small-rotation bushing.
//! The law's elastic centre is midway between the two frames (as a beam's stress resultants
//! act along the element): for a pure translation `d = (u, 0)`,
//! `T^-1(d) = [[I, tilde(u)/2], [0, I]]`, so holding it takes the force `K u` and the moment
//! `-u x (K u) / 2` on node B, a moment of second order in the deflection.
//! `sigma` holds the bushing's forces and moments; the wrench the bushing exerts on node B is
//! `-T^-1(d)^T sigma` in the bushing frame B (its residual), on node A
//! `T^-1(-d)^T sigma` in frame A. Energy `V = d^T K d / 2`.
//!
//! **Small-rotation form** ([`BushingForm::SmallRotation`]): `d = (u, phi)`, the position of
//! frame B's origin in frame A and the rotation vector of the relative rotation,
//! `u = R_A^T (x_B - x_A)`, `phi = log(R_rel)`, `R_rel = R_A^T R_B` (the logarithm of
//! R3 x SO(3)). With the frames' SE(3) variations `w = (U_A, theta_A, U_B, theta_B)`,
//! `T^-1` now SO(3)'s,
//!
//! ```text
//! delta u   = -U_A + tilde(u) theta_A + R_rel U_B,
//! delta phi = T^-1(phi) (theta_B - R_rel^T theta_A),
//! ```
//!
//! which is `P` (then times `blockdiag(A_a, A_b)`); with `sigma = (n, m)`,
//! `y = T^-1(phi)^T m` and `G = d(T^-1(phi)^T m)/dphi` (SO(3)), the derivative of `P^T sigma`
//! at fixed `sigma` has the rows
//!
//! ```text
//! theta_A: tilde(n) delta u - tilde(R_rel y) theta_A + R_rel tilde(y) theta_B - R_rel G delta phi
//! U_B:     -R_rel^T tilde(n) theta_A + tilde(R_rel^T n) theta_B
//! theta_B: G delta phi          (U_A: 0),
//! ```
//!
//! and that of `P z` at fixed frame velocities `z = (z_UA, z_tA, z_UB, z_tB)`, with
//! `q = z_tB - R_rel^T z_tA` and `H = d(T^-1(phi) q)/dphi`,
//!
//! ```text
//! u:   -tilde(z_tA) delta u + tilde(R_rel z_UB) theta_A - R_rel tilde(z_UB) theta_B
//! phi: H delta phi + T^-1(phi) (R_rel^T tilde(z_tA) theta_A - tilde(R_rel^T z_tA) theta_B).
//! ```
//!
//! The elastic centre is then frame B's origin (a force there holds a pure deflection
//! `u = K^-1 F`), the rotation measure is singular at a relative rotation of `2 pi` and the
//! law depends on which node is A: the usual small-rotation bushing, for relative rotations
//! of a few degrees; the large-rotation form for more.
//!
//! The variations and velocities above are SE(3)'s. On R3xSO(3), whose node variations and
//! velocities are `(dx, theta)` and `(xdot, Omega)` (inertial translation), the element is
//! evaluated in the nodes' SE(3) body coordinates `w_s = P^T w`, `v_s = P^T v`,
//! `P = blockdiag(R, I)` per node, and converted: `r = P r_s`,
//! `K = P K_s P^T - [R tilde(f_u)] + P C_s [tilde(U)]`, `C = P C_s P^T`, the second term the
//! derivative of `R` at fixed `r_s` (translation rows, rotation columns; `f_u` the
//! translation part of `r_s`), the third that of `v_s = (R^T xdot, Omega)` at fixed `xdot`
//! (`U = R^T xdot`).
//!
//! **Parameter derivatives** ([`BushingParam`]): with `E` the unit symmetric matrix of the
//! entry `(i, j)`, `dr/dK_ij = P^T E d`, `dr/dC_ij = P^T E ddot`.
//!
//! # References
//! - V. Sonneville, A. Cardona, O. Brüls, Geometrically exact beam finite element formulated
//!   on the special Euclidean group SE(3), Comput. Methods Appl. Mech. Engrg. 268 (2014)
//!   451-474, Sects. 3-4 and Appendix A (the tangent operator of SE(3)).

use super::beam::{tangent_inv_derivative, unit_symmetric};
use super::{
    physical, Coefficients, Context, DerivativeMethod, ElementKernel, ElementParameters, Local,
    LocalMatrix, LocalVector, Mat12, NodeState, Vec12,
};
use crate::model::parameters::BushingParam;
use crate::model::{Bushing, BushingForm, NodeId};
use flexmb_lie::so3::{self, hat};
use flexmb_lie::{se3, Frame, Group, Mat3, Mat6, Vec3, Vec6};
use nalgebra::SMatrix;

/// The deformation of a bushing and what it derives from it.
pub struct BushingState {
    /// `d = log(H_A^-1 H_B)` (translation, rotation).
    pub d: Vec6,
    /// Its rate `P v`.
    pub ddot: Vec6,
    /// Stress resultants `K d + C ddot` (forces, then moments; bushing frame).
    pub sigma: Vec6,
    /// `P` (6 x 12), in the nodes' variations.
    p: SMatrix<f64, 6, 12>,
    /// `P` in the frames' variations (`P = P_f blockdiag(A_a, A_b)`).
    pf: SMatrix<f64, 6, 12>,
    /// `Ad(F_a^-1)`, `Ad(F_b^-1)`.
    maps: [Mat6; 2],
    /// The relative configuration `H_A^-1 H_B`.
    rel: Frame,
}

impl Bushing {
    /// The deformation at the slots' kinematics (a ground slot at rest at the identity) on
    /// the model's `group`.
    pub fn state(&self, group: Group, nodes: &[NodeState]) -> BushingState {
        let ha = nodes[0].q.compose(&self.frame_a);
        let hb = nodes[1].q.compose(&self.frame_b);
        let rel = ha.inverse().compose(&hb);
        let maps = [offset(&self.frame_a), offset(&self.frame_b)];
        let mut pf = SMatrix::<f64, 6, 12>::zeros();
        let d = match self.form {
            BushingForm::LargeRotation => {
                let d = se3::log(&rel);
                pf.fixed_view_mut::<6, 6>(0, 0)
                    .copy_from(&(-se3::tangent_inv(&(-d))));
                pf.fixed_view_mut::<6, 6>(0, 6)
                    .copy_from(&se3::tangent_inv(&d));
                d
            }
            BushingForm::SmallRotation => {
                let (u, phi) = (rel.x, so3::log(&rel.r));
                let ti = so3::tangent_inv(&phi);
                pf.fixed_view_mut::<3, 3>(0, 0)
                    .copy_from(&(-Mat3::identity()));
                pf.fixed_view_mut::<3, 3>(0, 3).copy_from(&hat(&u));
                pf.fixed_view_mut::<3, 3>(0, 6).copy_from(&rel.r);
                pf.fixed_view_mut::<3, 3>(3, 3)
                    .copy_from(&(-ti * rel.r.transpose()));
                pf.fixed_view_mut::<3, 3>(3, 9).copy_from(&ti);
                flexmb_lie::join(&u, &phi)
            }
        };
        let mut p = pf;
        for (a, map) in maps.iter().enumerate() {
            let cols = pf.fixed_columns::<6>(6 * a) * map;
            p.fixed_columns_mut::<6>(6 * a).copy_from(&cols);
        }
        let ddot = p * velocities(group, nodes);
        BushingState {
            d,
            ddot,
            sigma: self.stiffness * d + self.damping * ddot,
            p,
            pf,
            maps,
            rel,
        }
    }

    fn active(&self) -> [bool; 2] {
        [self.node_a.is_some(), self.node_b.is_some()]
    }

    /// `d(P^T sigma)/dw` at fixed `sigma` (12 x 12) and `d(P v)/dw` at fixed node velocities
    /// `v` (6 x 12), `w` the nodes' variations (module documentation).
    fn derivatives(&self, st: &BushingState, v: &Vec12) -> (Mat12, SMatrix<f64, 6, 12>) {
        let [aa, ab] = &st.maps;
        let mut big_a = Mat12::zeros();
        big_a.fixed_view_mut::<6, 6>(0, 0).copy_from(aa);
        big_a.fixed_view_mut::<6, 6>(6, 6).copy_from(ab);
        // frame velocities
        let z = big_a * v;
        match self.form {
            BushingForm::LargeRotation => {
                let mut geometric = SMatrix::<f64, 12, 6>::zeros();
                geometric.fixed_view_mut::<6, 6>(0, 0).copy_from(
                    &(aa.transpose() * se3::tangent_inv_transpose_derivative(&(-st.d), &st.sigma)),
                );
                geometric.fixed_view_mut::<6, 6>(6, 0).copy_from(
                    &(ab.transpose() * se3::tangent_inv_transpose_derivative(&st.d, &st.sigma)),
                );
                let (za, zb) = (
                    z.fixed_rows::<6>(0).into_owned(),
                    z.fixed_rows::<6>(6).into_owned(),
                );
                let dd = tangent_inv_derivative(&(-st.d), &za) + tangent_inv_derivative(&st.d, &zb);
                (geometric * st.p, dd * st.p)
            }
            BushingForm::SmallRotation => {
                let phi = st.d.fixed_rows::<3>(3).into_owned();
                let (n, m) = flexmb_lie::split(&st.sigma);
                let r = st.rel.r;
                let ti = so3::tangent_inv(&phi);
                let y = ti.transpose() * m;
                let g = so3::tangent_inv_transpose_derivative(&phi, &m);
                // rows of P in frame variations: delta u, delta phi
                let pf_u: SMatrix<f64, 3, 12> = st.pf.fixed_rows::<3>(0).into_owned();
                let pf_phi: SMatrix<f64, 3, 12> = st.pf.fixed_rows::<3>(3).into_owned();
                // geometric, frame variations (blocks: U_A 0, theta_A 3, U_B 6, theta_B 9)
                let mut kf = Mat12::zeros();
                let mut rows = kf.fixed_rows_mut::<3>(3);
                rows += hat(&n) * pf_u - r * g * pf_phi;
                let mut blk = kf.fixed_view_mut::<3, 3>(3, 3);
                blk -= hat(&(r * y));
                let mut blk = kf.fixed_view_mut::<3, 3>(3, 9);
                blk += r * hat(&y);
                let mut blk = kf.fixed_view_mut::<3, 3>(6, 3);
                blk -= r.transpose() * hat(&n);
                let mut blk = kf.fixed_view_mut::<3, 3>(6, 9);
                blk += hat(&(r.transpose() * n));
                let mut rows = kf.fixed_rows_mut::<3>(9);
                rows += g * pf_phi;
                // rate: d(P z)/dw, frame variations
                let z_ta: Vec3 = z.fixed_rows::<3>(3).into_owned();
                let z_ub: Vec3 = z.fixed_rows::<3>(6).into_owned();
                let z_tb: Vec3 = z.fixed_rows::<3>(9).into_owned();
                let q: Vec3 = z_tb - r.transpose() * z_ta;
                let h = so3_tangent_inv_derivative(&phi, &q);
                let mut df = SMatrix::<f64, 6, 12>::zeros();
                let mut rows = df.fixed_rows_mut::<3>(0);
                rows -= hat(&z_ta) * pf_u;
                let mut blk = df.fixed_view_mut::<3, 3>(0, 3);
                blk += hat(&(r * z_ub));
                let mut blk = df.fixed_view_mut::<3, 3>(0, 9);
                blk -= r * hat(&z_ub);
                let mut rows = df.fixed_rows_mut::<3>(3);
                rows += h * pf_phi;
                let mut blk = df.fixed_view_mut::<3, 3>(3, 3);
                blk += ti * r.transpose() * hat(&z_ta);
                let mut blk = df.fixed_view_mut::<3, 3>(3, 9);
                blk -= ti * hat(&(r.transpose() * z_ta));
                (big_a.transpose() * kf * big_a, df * big_a)
            }
        }
    }
}

/// `H(x, q) = d(T^-1(x) q)/dx` on SO(3), from the transposed derivative `G`: row `i` of `H`
/// is `q^T G(x, e_i)`.
fn so3_tangent_inv_derivative(x: &Vec3, q: &Vec3) -> Mat3 {
    let mut h = Mat3::zeros();
    for i in 0..3 {
        let row = q.transpose() * so3::tangent_inv_transpose_derivative(x, &Vec3::ith(i, 1.0));
        h.set_row(i, &row);
    }
    h
}

/// `Ad(F^-1)`: a node's SE(3) variation to its bushing frame's.
fn offset(f: &Frame) -> Mat6 {
    se3::big_ad(&f.inverse())
}

/// `[v_a; v_b]`, the nodes' SE(3) body velocities (`(R^T xdot, Omega)` on R3xSO(3)).
fn velocities(group: Group, nodes: &[NodeState]) -> Vec12 {
    let mut v = Vec12::zeros();
    for (a, n) in nodes.iter().enumerate() {
        v.fixed_rows_mut::<6>(6 * a).copy_from(&n.v);
        if group == Group::R3xSO3 {
            let u = n.q.r.transpose() * n.v.fixed_rows::<3>(0);
            v.fixed_rows_mut::<3>(6 * a).copy_from(&u);
        }
    }
    v
}

/// On R3xSO(3), the residual, tangent stiffness and damping in the nodes' SE(3) body
/// coordinates `(r_s, K_s, C_s)` to the group's (physical) coordinates (module
/// documentation): `r = P r_s`, `K = P K_s P^T - [R tilde(f_u)] + P C_s [tilde(U)]`,
/// `C = P C_s P^T`, `P = blockdiag(R, I)` per node.
fn se3_to_r3so3(nodes: &[NodeState], r: &mut Vec12, k: &mut Mat12, c: &mut Mat12) {
    let mut p = Mat12::identity();
    for (a, n) in nodes.iter().enumerate() {
        p.fixed_view_mut::<3, 3>(6 * a, 6 * a).copy_from(&n.q.r);
    }
    // the body velocity (R^T xdot, Omega) turns with R at fixed xdot: d(R^T xdot)/dtheta
    let mut dv = Mat12::zeros();
    for (a, n) in nodes.iter().enumerate() {
        let u = n.q.r.transpose() * n.v.fixed_rows::<3>(0);
        dv.fixed_view_mut::<3, 3>(6 * a, 6 * a + 3)
            .copy_from(&hat(&u));
    }
    let mut kp = p * *k * p.transpose() + p * *c * dv;
    for (a, n) in nodes.iter().enumerate() {
        let f = r.fixed_rows::<3>(6 * a).into_owned();
        let mut blk = kp.fixed_view_mut::<3, 3>(6 * a, 6 * a + 3);
        blk -= n.q.r * hat(&f);
    }
    *k = kp;
    *c = p * *c * p.transpose();
    *r = p * *r;
}

impl ElementKernel for Bushing {
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
        r_out: &mut LocalVector,
        s: Option<(&Coefficients, &mut LocalMatrix)>,
    ) {
        let nodes = local.nodes;
        let st = self.state(ctx.group, nodes);
        let p = &st.p;
        let mut r: Vec12 = p.transpose() * st.sigma;
        if s.is_none() {
            if ctx.group == Group::R3xSO3 {
                for (a, n) in nodes.iter().enumerate() {
                    let f = n.q.r * r.fixed_rows::<3>(6 * a);
                    r.fixed_rows_mut::<3>(6 * a).copy_from(&f);
                }
            }
            r_out.fixed_rows_mut::<12>(0).copy_from(&r);
            return;
        }
        let Some((coef, s)) = s else {
            return;
        };
        let v = velocities(ctx.group, nodes);
        let (geometric, rate) = self.derivatives(&st, &v);
        let pt = p.transpose();
        let mut k: Mat12 = pt * self.stiffness * p + geometric + pt * self.damping * rate;
        let mut c: Mat12 = pt * self.damping * p;
        if ctx.group == Group::R3xSO3 {
            se3_to_r3so3(nodes, &mut r, &mut k, &mut c);
        }
        r_out.fixed_rows_mut::<12>(0).copy_from(&r);
        let mut s = s.fixed::<12>();
        s.copy_from(&(c * coef.c + k * coef.k));
        physical::apply_tangent_full(nodes, &self.active(), &mut s, coef, &k);
    }

    fn potential_energy(&self, ctx: &Context, local: &Local) -> f64 {
        let d = self.state(ctx.group, local.nodes).d;
        0.5 * d.dot(&(self.stiffness * d))
    }
}

impl ElementParameters for Bushing {
    type Param = BushingParam;

    fn parameter_derivative(
        &self,
        ctx: &Context,
        p: BushingParam,
        local: &Local,
        dr: &mut LocalVector,
    ) -> DerivativeMethod {
        let st = self.state(ctx.group, local.nodes);
        let dsigma = match p {
            BushingParam::Stiffness(i, j) => unit_symmetric::<6>(i, j) * st.d,
            BushingParam::Damping(i, j) => unit_symmetric::<6>(i, j) * st.ddot,
        };
        let mut d: Vec12 = st.p.transpose() * dsigma;
        if ctx.group == Group::R3xSO3 {
            for (a, n) in local.nodes.iter().enumerate() {
                let f = n.q.r * d.fixed_rows::<3>(6 * a);
                d.fixed_rows_mut::<3>(6 * a).copy_from(&f);
            }
        }
        dr.fixed_rows_mut::<12>(0).copy_from(&d);
        DerivativeMethod::Analytic
    }
}
