//! 6-DOF bushing on SE(3): a linear stiffness and damping on the relative configuration of
//! two frames, exact for large relative rotations.
//!
//! ```text
//!   node A                 node B
//!     o--[F_a]~~~~~~~~~~[F_b]--o       H_A = Q_a F_a,  H_B = Q_b F_b   (bushing frames)
//! ```
//!
//! With the bushing frames `H_A`, `H_B` (node configurations `Q` composed with the constant
//! offsets `F`; a ground slot is the identity, its offset the frame in space), the
//! deformation is the SE(3) logarithm of the relative configuration (translation first),
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
//! The element needs SE(3) nodes (the variations and velocities above are SE(3)'s); on
//! R3xSO(3) the model is rejected, like a beam.
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
use crate::model::{Bushing, NodeId};
use flexmb_lie::{se3, Frame, Mat6, Vec6};
use nalgebra::SMatrix;

/// The deformation of a bushing and what it derives from it.
pub struct BushingState {
    /// `d = log(H_A^-1 H_B)` (translation, rotation).
    pub d: Vec6,
    /// Its rate `P v`.
    pub ddot: Vec6,
    /// Stress resultants `K d + C ddot` (forces, then moments; bushing frame).
    pub sigma: Vec6,
    /// `P` (6 x 12).
    p: SMatrix<f64, 6, 12>,
    /// `Ad(F_a^-1)`, `Ad(F_b^-1)`.
    maps: [Mat6; 2],
}

impl Bushing {
    /// The deformation at the slots' kinematics (a ground slot at rest at the identity).
    pub fn state(&self, nodes: &[NodeState]) -> BushingState {
        let ha = nodes[0].q.compose(&self.frame_a);
        let hb = nodes[1].q.compose(&self.frame_b);
        let d = se3::log(&ha.inverse().compose(&hb));
        let maps = [offset(&self.frame_a), offset(&self.frame_b)];
        let mut p = SMatrix::<f64, 6, 12>::zeros();
        p.fixed_view_mut::<6, 6>(0, 0)
            .copy_from(&(-se3::tangent_inv(&(-d)) * maps[0]));
        p.fixed_view_mut::<6, 6>(0, 6)
            .copy_from(&(se3::tangent_inv(&d) * maps[1]));
        let ddot = p * velocities(nodes);
        BushingState {
            d,
            ddot,
            sigma: self.stiffness * d + self.damping * ddot,
            p,
            maps,
        }
    }

    fn active(&self) -> [bool; 2] {
        [self.node_a.is_some(), self.node_b.is_some()]
    }
}

/// `Ad(F^-1)`: a node's SE(3) variation to its bushing frame's.
fn offset(f: &Frame) -> Mat6 {
    se3::big_ad(&f.inverse())
}

/// `[v_a; v_b]`.
fn velocities(nodes: &[NodeState]) -> Vec12 {
    let mut v = Vec12::zeros();
    for (a, n) in nodes.iter().enumerate() {
        v.fixed_rows_mut::<6>(6 * a).copy_from(&n.v);
    }
    v
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
        _ctx: &Context,
        local: &Local,
        r: &mut LocalVector,
        s: Option<(&Coefficients, &mut LocalMatrix)>,
    ) {
        let nodes = local.nodes;
        let st = self.state(nodes);
        let p = &st.p;
        r.fixed_rows_mut::<12>(0)
            .copy_from(&(p.transpose() * st.sigma));
        let Some((coef, s)) = s else {
            return;
        };
        let [aa, ab] = &st.maps;
        let mut geometric = SMatrix::<f64, 12, 6>::zeros();
        geometric.fixed_view_mut::<6, 6>(0, 0).copy_from(
            &(aa.transpose() * se3::tangent_inv_transpose_derivative(&(-st.d), &st.sigma)),
        );
        geometric
            .fixed_view_mut::<6, 6>(6, 0)
            .copy_from(&(ab.transpose() * se3::tangent_inv_transpose_derivative(&st.d, &st.sigma)));
        let v = velocities(nodes);
        let va = aa * v.fixed_rows::<6>(0);
        let vb = ab * v.fixed_rows::<6>(6);
        // d(P v)/dd at fixed v
        let dd = tangent_inv_derivative(&(-st.d), &va) + tangent_inv_derivative(&st.d, &vb);
        let pt = p.transpose();
        let k: Mat12 = pt * self.stiffness * p + geometric * p + pt * self.damping * dd * p;
        let c: Mat12 = pt * self.damping * p;
        let mut s = s.fixed::<12>();
        s.copy_from(&(c * coef.c + k * coef.k));
        physical::apply_tangent_full(nodes, &self.active(), &mut s, coef, &k);
    }

    fn potential_energy(&self, _ctx: &Context, local: &Local) -> f64 {
        let d = self.state(local.nodes).d;
        0.5 * d.dot(&(self.stiffness * d))
    }
}

impl ElementParameters for Bushing {
    type Param = BushingParam;

    fn parameter_derivative(
        &self,
        _ctx: &Context,
        p: BushingParam,
        local: &Local,
        dr: &mut LocalVector,
    ) -> DerivativeMethod {
        let st = self.state(local.nodes);
        let dsigma = match p {
            BushingParam::Stiffness(i, j) => unit_symmetric::<6>(i, j) * st.d,
            BushingParam::Damping(i, j) => unit_symmetric::<6>(i, j) * st.ddot,
        };
        dr.fixed_rows_mut::<12>(0)
            .copy_from(&(st.p.transpose() * dsigma));
        DerivativeMethod::Analytic
    }
}
