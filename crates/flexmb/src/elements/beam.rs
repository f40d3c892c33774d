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
//! mass-proportional forces `alpha M v` with the element's mass matrix `M` (below).
//!
//! The interpolation is the SE(3) geodesic between the two end frames (the paper's
//! two-node interpolation); a higher-order element needs another interpolation and is not
//! provided. Refinement is by more elements (the strain is exact for constant curvature, as
//! in the roll-up, and converges at second order otherwise).
//!
//! **Inertia.** The element's configuration field is `H(xi) = H_a exp(xi d)`, `xi = s / L`
//! (section frames). Its body velocity follows from `d/dt exp(x) = exp(x) tilde(T(x) xdot)`
//! and `ddot = P [v_a; v_b]`:
//!
//! ```text
//! eta(xi) = Ad(exp(-xi d)) A_a v_a + xi T(xi d) ddot
//!         = [ (Ad(exp(-xi d)) - xi T(xi d) T^-1(-d)) A_a ,  xi T(xi d) T^-1(d) A_b ] [v_a; v_b]
//!         = N(xi; d) [v_a; v_b],
//! ```
//!
//! which gives `v_a` at `xi = 0`, `v_b` at `xi = 1` (`T(d) T^-1(-d) = Ad(exp(-d))`) and the
//! rigid velocity field for every rigid motion (`ddot = 0`). The consistent mass matrix is
//! `M = L int_0^1 N^T M_s N dxi`, `M_s = blockdiag(rho A I, J)`, with `N` evaluated at the
//! reference `d_0` (5-point Gauss; exact for straight elements): the kinetic energy is then
//! exact for rigid motions of the reference shape and for the element's small deformations
//! about it, and `M` is constant like a rigid body's on SE(3) (Brüls & Cardona 2010,
//! Sect. 5.2), the error of freezing `d` at `d_0` being of the order of the element's
//! strains and change of curvature times `L`. `T = 1/2 v^T M v` is a left-invariant metric
//! on the two nodes, so the Euler-Poincaré equations give the inertia forces and tangents
//!
//! ```text
//! f_ine = M vdot - [ ad(v_a)^T p_a ; ad(v_b)^T p_b ],   p = M v,
//! C_t   = -blockdiag(ad(v_a)^T, ad(v_b)^T) M - blockdiag(Q(p_a), Q(p_b)),   K_t = 0,
//! ```
//!
//! with `Q` of [`super::rigid_body`] (the rigid body's equations with a coupled mass matrix).
//!
//! The default ([`crate::model::BeamMass`]) is the lumped mass: half of the element's mass
//! and rotary inertia on each node (block-diagonal `M`, the same equations). For this
//! element the choice hardly matters for accuracy: the first bending frequency of a
//! pinned-pinned rod with 16 elements is 0.16 % too high with either mass (the element's
//! stiffness dominates; BENCHMARKS.md, slider-crank), and the lumped mass is cheaper.
//!
//! Gravity acts on half of the element's mass at each node (exact resultant; the moments
//! differ by `O(L^2)`), on both mass models. Mass-proportional damping uses the same `M`.
//! Beams need SE(3) nodes: on R3xSO(3) the model is rejected with a clear error (the relative
//! motion `d` and its tangent operator are those of SE(3)).
//!
//! The mass matrix is not part of the model: [`mass_matrix`] computes it from the section,
//! and the assembly evaluates a [`BeamElement`], the element with the matrix computed once
//! (see [`super::ElementRef`]); evaluating a [`Beam`] alone computes it on the way.
//!
//! **Parameter derivatives** ([`SectionParam`]). `r` is linear in every section parameter:
//! with `sigma_tot = C (epsilon + beta P v / L)` and `E` the unit symmetric matrix of the
//! entry `(i, j)`,
//!
//! ```text
//! dr/dC_ij   = P^T E (epsilon + beta P v / L)
//! dr/drho A  = f_ine(M_A) - [ R_a^T g L/2 ; 0 ; R_b^T g L/2 ; 0 ]    M_A = M(rho A = 1, J = 0)
//! dr/dJ_ij   = f_ine(M_J)                                              M_J = M(rho A = 0, J = E)
//! dr/dalpha  = M v,      dr/dbeta = P^T C P v / L
//! dr/dg_k    = -[ R_a^T e_k ; 0 ; R_b^T e_k ; 0 ] rho A L / 2
//! ```
//!
//! with `f_ine(M) = M vdot + alpha M v - [ ad(v_a)^T (M v)_a ; ad(v_b)^T (M v)_b ]` (gravity
//! and the applied-load terms times the load factor). The damping terms are evaluated only
//! for `alpha > 0`, `beta > 0`: at 0 these are the derivatives from above.

use super::rigid_body::momentum_jacobian;
use super::{
    Coefficients, Context, DerivativeMethod, ElementKernel, ElementParameters, Local, LocalMatrix,
    LocalVector, Mat12, NodeState, Vec12,
};
use crate::model::parameters::SectionParam;
use crate::model::{Beam, BeamMass, NodeId};
use flexmb_lie::{se3, so3::hat, Frame, Mat3, Mat6, Vec3, Vec6};
use nalgebra::{DVector, SMatrix, SVector};

/// `blockdiag(O^T, O^T)`: maps a node variation to a section-frame variation.
fn offset_map(o: &Mat3) -> Mat6 {
    let mut a = Mat6::zeros();
    a.fixed_view_mut::<3, 3>(0, 0).copy_from(&o.transpose());
    a.fixed_view_mut::<3, 3>(3, 3).copy_from(&o.transpose());
    a
}

/// Gauss-Legendre points and weights on [0, 1], 5 points (exact to degree 9).
const GAUSS5: [(f64, f64); 5] = [
    (0.046_910_077_030_668, 0.118_463_442_528_095),
    (0.230_765_344_947_158, 0.239_314_335_249_683),
    (0.5, 0.284_444_444_444_444),
    (0.769_234_655_052_842, 0.239_314_335_249_683),
    (0.953_089_922_969_332, 0.118_463_442_528_095),
];

/// Element mass matrix in the nodes' body velocities `[v_a; v_b]` (12 x 12, see the module
/// documentation), from the section, the geometry and `mass_kind`.
pub fn mass_matrix(beam: &Beam) -> Mat12 {
    let sec = &beam.section;
    mass_matrix_with(beam, sec.mass_per_length, &sec.rotary_inertia)
}

/// [`mass_matrix`] with the mass per length and the rotary inertia given (it is linear in
/// them).
pub fn mass_matrix_with(beam: &Beam, mass_per_length: f64, rotary_inertia: &Mat3) -> Mat12 {
    let mut ms = Mat6::zeros();
    ms.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(Mat3::identity() * mass_per_length));
    ms.fixed_view_mut::<3, 3>(3, 3).copy_from(rotary_inertia);
    let (aa, ab) = (offset_map(&beam.offset_a), offset_map(&beam.offset_b));
    let l = beam.length;
    let mut m = Mat12::zeros();
    match beam.mass_kind {
        BeamMass::Lumped => {
            m.fixed_view_mut::<6, 6>(0, 0)
                .copy_from(&(aa.transpose() * ms * aa * (0.5 * l)));
            m.fixed_view_mut::<6, 6>(6, 6)
                .copy_from(&(ab.transpose() * ms * ab * (0.5 * l)));
        }
        BeamMass::Consistent => {
            let d0 = &beam.d0;
            let (pa, pb) = (se3::tangent_inv(&(-d0)), se3::tangent_inv(d0));
            for (xi, w) in GAUSS5 {
                let t = se3::tangent(&(xi * d0)) * xi;
                let mut n = SMatrix::<f64, 6, 12>::zeros();
                n.fixed_view_mut::<6, 6>(0, 0)
                    .copy_from(&((se3::big_ad(&se3::exp(&(-xi * d0))) - t * pa) * aa));
                n.fixed_view_mut::<6, 6>(0, 6).copy_from(&(t * pb * ab));
                m += n.transpose() * ms * n * (w * l);
            }
            // symmetric up to round-off; make it exactly so
            m = (m + m.transpose()) * 0.5;
        }
    }
    m
}

/// `H(x, y) = d(T^-1(x) y)/dx` from the transposed derivative `G`:
/// `e_i . T^-1(x) y = (T^-1(x)^T e_i) . y`, so row `i` of `H` is `y^T G(x, e_i)`.
pub(super) fn tangent_inv_derivative(x: &Vec6, y: &Vec6) -> Mat6 {
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

    /// [`Beam::state`] and the derivative of its stress resultants `C epsilon` with
    /// respect to the nodes' variations `[w_a; w_b]` (group coordinates, tangent operators
    /// not applied): `C P / L` (6 x 12).
    pub fn stress_derivative(&self, nodes: &[NodeState; 2]) -> (BeamState, SMatrix<f64, 6, 12>) {
        let st = self.state(nodes);
        let (aa, ab) = (offset_map(&self.offset_a), offset_map(&self.offset_b));
        let p = self.projection(&st.d, &aa, &ab);
        (st, self.section.stiffness * p / self.length)
    }

    /// Gravity force on half of the element's mass at node `end` (body frame of the node).
    fn half_weight(&self, ctx: &Context, n: &NodeState) -> Vec3 {
        n.q.r.transpose()
            * ctx.model.gravity
            * (0.5 * self.length * self.section.mass_per_length * ctx.gravity_scale)
    }

    /// `P = [ -T^-1(-d) A_a, T^-1(d) A_b ]` (6 x 12): `delta d = P [w_a; w_b]`.
    fn projection(&self, d: &Vec6, aa: &Mat6, ab: &Mat6) -> SMatrix<f64, 6, 12> {
        let mut p = SMatrix::<f64, 6, 12>::zeros();
        p.fixed_view_mut::<6, 6>(0, 0)
            .copy_from(&(-se3::tangent_inv(&(-d)) * aa));
        p.fixed_view_mut::<6, 6>(0, 6)
            .copy_from(&(se3::tangent_inv(d) * ab));
        p
    }
}

/// Velocities (`what = 'v'`) or accelerations of both nodes, `[node a; node b]`.
fn stack(nodes: &[NodeState; 2], what: char) -> Vec12 {
    let mut out = Vec12::zeros();
    for (end, n) in nodes.iter().enumerate() {
        let x = if what == 'v' { &n.v } else { &n.vdot };
        out.fixed_rows_mut::<6>(6 * end).copy_from(x);
    }
    out
}

/// A beam element with its mass matrix (12 x 12, in the nodes' body velocities), as the
/// assembly evaluates it.
#[derive(Clone, Copy, Debug)]
pub struct BeamElement<'m> {
    pub beam: &'m Beam,
    /// [`mass_matrix`] of `beam`.
    pub mass: &'m Mat12,
}

/// The two slots of a beam's [`Local`].
fn pair<'a>(local: &Local<'a>) -> &'a [NodeState; 2] {
    local
        .nodes
        .try_into()
        .expect("a beam element has two node slots")
}

impl ElementKernel for BeamElement<'_> {
    fn n_slots(&self) -> usize {
        2
    }

    fn node(&self, slot: usize) -> Option<NodeId> {
        Some(self.beam.nodes[slot])
    }

    fn evaluate(
        &self,
        ctx: &Context,
        local: &Local,
        r_out: &mut LocalVector,
        s: Option<(&Coefficients, &mut LocalMatrix)>,
    ) {
        let nodes = pair(local);
        let b = self.beam;
        let st = b.state(nodes);
        let (aa, ab) = (offset_map(&b.offset_a), offset_map(&b.offset_b));
        let p = b.projection(&st.d, &aa, &ab);
        let (alpha, beta) = (b.section.damping_mass, b.section.damping_stiffness);
        let v = stack(nodes, 'v');
        let c_over_l = b.section.stiffness / b.length;
        // total stress resultants: elastic plus stiffness-proportional damping
        let sigma = if beta > 0.0 {
            st.stress + c_over_l * (p * v) * beta
        } else {
            st.stress
        };
        let mut r = p.transpose() * sigma;

        // Inertia and gravity (module documentation).
        let vdot = stack(nodes, 'a');
        let mm = self.mass;
        let momentum = mm * v;
        r += mm * vdot;
        if alpha > 0.0 {
            r += momentum * alpha;
        }
        let mut weights = [Vec3::zeros(); 2];
        for end in 0..2 {
            let pe = momentum.fixed_rows::<6>(6 * end).into_owned();
            let we = b.half_weight(ctx, &nodes[end]);
            weights[end] = we;
            let mut re = r.fixed_rows_mut::<6>(6 * end);
            re -= se3::ad(&nodes[end].v).transpose() * pe;
            let mut rf = re.fixed_rows_mut::<3>(0);
            rf -= we;
        }
        r_out.fixed_rows_mut::<12>(0).copy_from(&r);
        let Some((coef, s)) = s else {
            return;
        };
        // (each part only when its coefficient asks for it: the step Jacobian's partial
        // derivatives take them one at a time)
        let mut k = Mat12::zeros();
        if coef.k != 0.0 {
            let mut geometric = SMatrix::<f64, 12, 6>::zeros();
            geometric.fixed_view_mut::<6, 6>(0, 0).copy_from(
                &(aa.transpose() * se3::tangent_inv_transpose_derivative(&(-st.d), &sigma)),
            );
            geometric.fixed_view_mut::<6, 6>(6, 0).copy_from(
                &(ab.transpose() * se3::tangent_inv_transpose_derivative(&st.d, &sigma)),
            );
            k = p.transpose() * c_over_l * p + geometric * p;
            if beta > 0.0 {
                // d(P v)/dd at fixed v, then through P to the node variations
                let va = aa * v.fixed_rows::<6>(0);
                let vb = ab * v.fixed_rows::<6>(6);
                let ddot =
                    tangent_inv_derivative(&(-st.d), &va) + tangent_inv_derivative(&st.d, &vb);
                k += p.transpose() * c_over_l * beta * ddot * p;
            }
            for end in 0..2 {
                // gravity in the node frame turns with the node: d(-R^T w)/dtheta = -tilde(R^T w)
                let mut kb = k.fixed_view_mut::<3, 3>(6 * end, 6 * end + 3);
                kb -= hat(&weights[end]);
            }
        }
        let mut c_t = Mat12::zeros();
        if coef.c != 0.0 {
            c_t = mm * alpha;
            if beta > 0.0 {
                c_t += p.transpose() * c_over_l * beta * p;
            }
            for end in 0..2 {
                let adt = se3::ad(&nodes[end].v).transpose();
                let rows = adt * mm.fixed_rows::<6>(6 * end);
                let mut cr = c_t.fixed_rows_mut::<6>(6 * end);
                cr -= rows;
                let pe = momentum.fixed_rows::<6>(6 * end).into_owned();
                let mut cb = c_t.fixed_view_mut::<6, 6>(6 * end, 6 * end);
                cb -= momentum_jacobian(&pe);
            }
        }
        let mut s = s.fixed::<12>();
        s.copy_from(&(mm * coef.m + c_t * coef.c + k * coef.k));
        super::physical::apply_tangent_full(nodes, &[true, true], &mut s, coef, &k);
    }

    fn kinetic_energy(&self, _ctx: &Context, local: &Local) -> f64 {
        let v = stack(pair(local), 'v');
        0.5 * v.dot(&(self.mass * v))
    }

    fn potential_energy(&self, ctx: &Context, local: &Local) -> f64 {
        self.beam.potential_energy(ctx, local)
    }
}

/// A beam alone: the [`BeamElement`] with the mass matrix computed at each call.
impl ElementKernel for Beam {
    fn n_slots(&self) -> usize {
        2
    }

    fn node(&self, slot: usize) -> Option<NodeId> {
        Some(self.nodes[slot])
    }

    fn evaluate(
        &self,
        ctx: &Context,
        local: &Local,
        r: &mut LocalVector,
        s: Option<(&Coefficients, &mut LocalMatrix)>,
    ) {
        let mass = mass_matrix(self);
        BeamElement {
            beam: self,
            mass: &mass,
        }
        .evaluate(ctx, local, r, s);
    }

    fn kinetic_energy(&self, ctx: &Context, local: &Local) -> f64 {
        let mass = mass_matrix(self);
        BeamElement {
            beam: self,
            mass: &mass,
        }
        .kinetic_energy(ctx, local)
    }

    fn potential_energy(&self, ctx: &Context, local: &Local) -> f64 {
        let nodes = pair(local);
        let st = self.state(nodes);
        let half_mass = 0.5 * self.length * self.section.mass_per_length * ctx.gravity_scale;
        let gravity: f64 = nodes
            .iter()
            .map(|n| -half_mass * ctx.model.gravity.dot(&n.q.x))
            .sum();
        0.5 * self.length * st.strain.dot(&st.stress) + gravity
    }
}

/// Inertia forces of a mass matrix `mm` with mass-proportional damping `alpha`:
/// `M vdot + alpha M v - [ ad(v_a)^T (M v)_a ; ad(v_b)^T (M v)_b ]`.
fn inertia_forces(mm: &Mat12, alpha: f64, nodes: &[NodeState; 2]) -> Vec12 {
    let momentum = mm * stack(nodes, 'v');
    let mut f = mm * stack(nodes, 'a');
    if alpha > 0.0 {
        f += momentum * alpha;
    }
    for end in 0..2 {
        let pe = momentum.fixed_rows::<6>(6 * end).into_owned();
        let mut fe = f.fixed_rows_mut::<6>(6 * end);
        fe -= se3::ad(&nodes[end].v).transpose() * pe;
    }
    f
}

/// The unit symmetric matrix of entry `(i, j)`.
pub(super) fn unit_symmetric<const N: usize>(i: usize, j: usize) -> SMatrix<f64, N, N> {
    let mut e = SMatrix::<f64, N, N>::zeros();
    e[(i, j)] = 1.0;
    e[(j, i)] = 1.0;
    e
}

impl ElementParameters for Beam {
    type Param = SectionParam;

    fn parameter_derivative(
        &self,
        ctx: &Context,
        p: SectionParam,
        local: &Local,
        dr: &mut LocalVector,
    ) -> DerivativeMethod {
        let nodes = pair(local);
        let sec = &self.section;
        let (alpha, beta) = (sec.damping_mass, sec.damping_stiffness);
        // P v / L and P, when the stiffness terms need them
        let rate = || {
            let st = self.state(nodes);
            let (aa, ab) = (offset_map(&self.offset_a), offset_map(&self.offset_b));
            let p = self.projection(&st.d, &aa, &ab);
            let pv = p * stack(nodes, 'v') / self.length;
            (st, p, pv)
        };
        let d = match p {
            SectionParam::Stiffness(i, j) => {
                let (st, p, pv) = rate();
                let e = unit_symmetric::<6>(i, j);
                let strain = if beta > 0.0 {
                    st.strain + pv * beta
                } else {
                    st.strain
                };
                p.transpose() * (e * strain)
            }
            SectionParam::DampingStiffness => {
                let (_, p, pv) = rate();
                p.transpose() * (sec.stiffness * pv)
            }
            SectionParam::MassPerLength => {
                let m = mass_matrix_with(self, 1.0, &Mat3::zeros());
                let mut f = inertia_forces(&m, alpha, nodes);
                for end in 0..2 {
                    let w = nodes[end].q.r.transpose()
                        * ctx.model.gravity
                        * (0.5 * self.length * ctx.gravity_scale);
                    let mut fe = f.fixed_rows_mut::<3>(6 * end);
                    fe -= w;
                }
                f
            }
            SectionParam::RotaryInertia(i, j) => {
                let m = mass_matrix_with(self, 0.0, &unit_symmetric::<3>(i, j));
                inertia_forces(&m, alpha, nodes)
            }
            SectionParam::DampingMass => mass_matrix(self) * stack(nodes, 'v'),
        };
        dr.copy_from(&d);
        DerivativeMethod::Analytic
    }

    /// The stiffness entries share the strain and the projection `P`: with
    /// `dr/dC_ij = P^T E_ij eps` (`E_ij` the unit symmetric matrix, `eps` the strain plus
    /// `beta P v / L` with stiffness-proportional damping), `w . dr/dC_ij = (P w)_i eps_j +
    /// (P w)_j eps_i` (one term for `i = j`); the other parameters one at a time.
    fn parameter_vjp(
        &self,
        ctx: &Context,
        ps: &[SectionParam],
        local: &Local,
        w: &[f64],
        out: &mut [f64],
    ) {
        let nodes = pair(local);
        let mut shared: Option<(Vec6, Vec6)> = None;
        let mut d = DVector::zeros(self.n_local());
        for (&p, o) in ps.iter().zip(out) {
            let SectionParam::Stiffness(i, j) = p else {
                *o = super::parameter_dot(self, ctx, p, local, w, &mut d);
                continue;
            };
            let (pw, eps) = shared.get_or_insert_with(|| {
                let st = self.state(nodes);
                let (aa, ab) = (offset_map(&self.offset_a), offset_map(&self.offset_b));
                let pm = self.projection(&st.d, &aa, &ab);
                let beta = self.section.damping_stiffness;
                let eps = if beta > 0.0 {
                    st.strain + pm * stack(nodes, 'v') * (beta / self.length)
                } else {
                    st.strain
                };
                (pm * SVector::<f64, 12>::from_column_slice(&w[..12]), eps)
            });
            *o = if i == j {
                pw[i] * eps[i]
            } else {
                pw[i] * eps[j] + pw[j] * eps[i]
            };
        }
    }

    fn gravity_derivative(&self, ctx: &Context, k: usize, local: &Local, dr: &mut LocalVector) {
        let nodes = pair(local);
        let mut e = Vec3::zeros();
        e[k] = -0.5 * self.length * self.section.mass_per_length * ctx.gravity_scale;
        dr.fill(0.0);
        for end in 0..2 {
            let w = nodes[end].q.r.transpose() * e;
            dr.fixed_rows_mut::<3>(6 * end).copy_from(&w);
        }
    }
}
