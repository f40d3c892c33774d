//! Spring-damper between two points `P_a = x_a + R_a p_a`, `P_b = x_b + R_b p_b`, linear or
//! with a nonlinear law ([`crate::model::SpringLaw`], [`ForceLaw`]).
//!
//! With `d = P_b - P_a`, `l = |d|`, `n = d / l`, tension `T(l, ldot)` (linear:
//! `T = k (l - l0) + c ldot`), `k_t = dT/dl`, `c_t = dT/dldot`:
//!
//! ```text
//! r_p = T g,     g = dl/dw_p = D^T n,   D = [ -I, R_a tilde(p_a), I, -R_b tilde(p_b) ]
//! H   = dg/dw_p = D^T (I - n n^T)/l D + blockdiag(0, -tilde(p_a) tilde(R_a^T n), 0, tilde(p_b) tilde(R_b^T n))
//! K_p = g (k_t g + c_t H^T v_p)^T + T H,      C_p = c_t g g^T,     ldot = g . v_p
//! ```
//! (physical coordinates, see [`super::physical`]). Géradin & Cardona 2001, Sect. 6.3: the
//! element is written there for any force law `T(l, ldot)`; only `k_t` and `c_t` change.
//!
//! **Nonlinear law** ([`ForceLaw`]): with the elongation `e = l - l0` (`l0` the free
//! length) and the preload `P` (the tension at the free length),
//!
//! ```text
//! T = P + k e + F(e) + c ldot,     k_t = k + F'(e),     c_t = c,
//! ```
//!
//! `F` the force curve of the side of `e` ([`ForceCurve`]: a piecewise-linear table, or a
//! polynomial `sum_j a_j e^j`). A **one-sided** spring (a stop, [`SpringSide`]) acts only on
//! its side: compression, `T` as above while `e < 0` and `T < 0`, else `T = 0`; extension,
//! while `e >= 0` and `T >= 0`. The law is continuous at a stop's onset only without
//! preload, and its derivative jumps at a table point and at the onset: there `k_t` is the
//! derivative from the side of larger `e` (the table segment to the right of a point; at
//! `e = 0` a compression stop is off), the same one-sided choice everywhere, so that the
//! iteration matrix is the exact derivative of the residual along every direction that
//! increases `e`. Energy: `V = P e + k e^2 / 2 + integral_0^e F` on the active side, 0 off
//! it (exact while the stop's elastic force keeps the sign of its side).
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
//! `dr_p/dl0 = -(k_t + k_m) g` (`de/dl0 = k_m / c_m`), `dr_p/dk_m = (l - l0 - z) g`
//! (`de/dk_m = -(l - l0 - z) / c_m`), `de/dc_m = k_m (l - l0 - z) / c_m^2`; of the law
//! ([`SpringLawParam`]) `dr_p/dP = g`, `dr_p/da_j = e^j g`, `dr_p/dF_i = w_i(e) g` (`w_i` the
//! interpolation weight of table point `i` at `e`), all zero where a stop is off; the
//! attachment points by the finite-difference default ([`super::central_difference`]).
//! A Maxwell branch is not combined with a one-sided law (validation rejects it).

use super::{
    central_difference, physical, Coefficients, Context, DerivativeMethod, ElementKernel,
    ElementParameters, InitialStates, Local, LocalMatrix, LocalVector, Mat12, NodeState, Vec12,
};
use crate::model::parameters::{SpringLawParam, SpringParam};
use crate::model::{ForceCurve, ForceLaw, Model, NodeId, SpringDamper, SpringSide};
use flexmb_lie::{so3::hat, Mat3, Vec3};
use nalgebra::SMatrix;
use std::borrow::Cow;

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

/// The force of the element and its derivatives: tension `T`, `k_t = dT/dl`,
/// `c_t = dT/dldot` (all zero where a stop is off), and whether the element acts.
#[derive(Clone, Copy, Debug)]
pub(super) struct Force {
    pub(super) t: f64,
    pub(super) kt: f64,
    pub(super) ct: f64,
    pub(super) active: bool,
}

impl Force {
    /// `T`, `k_t`, `c_t` if the element acts, else zeros.
    pub(super) fn of(active: bool, t: f64, kt: f64, ct: f64) -> Self {
        if active {
            Force { t, kt, ct, active }
        } else {
            Force {
                t: 0.0,
                kt: 0.0,
                ct: 0.0,
                active,
            }
        }
    }
}

impl ForceLaw {
    /// The law's part of the force beyond `k e + c edot` at `e`, `P + F(e)`, and its
    /// derivative `F'(e)` (from the side of larger `e` at a table point).
    pub fn elastic(&self, e: f64) -> (f64, f64) {
        match self.curve_at(e) {
            Some(curve) => {
                let (f, df) = curve.eval(e);
                (self.preload + f, df)
            }
            None => (self.preload, 0.0),
        }
    }

    /// Whether `e` is on the side where the law acts (always for a two-sided law).
    pub fn on_side(&self, e: f64) -> bool {
        match self.acts {
            SpringSide::Both => true,
            SpringSide::Compression => e < 0.0,
            SpringSide::Extension => e >= 0.0,
        }
    }

    /// Whether the total force `t` at `e` acts: a stop acts on its side and while its force
    /// pushes (compression) or pulls (extension).
    pub fn acts_at(&self, e: f64, t: f64) -> bool {
        self.on_side(e)
            && match self.acts {
                SpringSide::Both => true,
                SpringSide::Compression => t < 0.0,
                SpringSide::Extension => t >= 0.0,
            }
    }

    /// The energy of the law's part, `P e + integral_0^e F` \[J\] (on its side).
    pub fn energy(&self, e: f64) -> f64 {
        self.preload * e + self.curve_at(e).map_or(0.0, |c| c.integral(e))
    }

    /// `d(P + F(e))/dp` for a parameter of the law at `e`.
    pub fn parameter_derivative(&self, p: SpringLawParam, e: f64) -> f64 {
        match p {
            SpringLawParam::Preload => 1.0,
            SpringLawParam::Polynomial(key, j) | SpringLawParam::TableForce(key, j) => {
                // the parameter's curve acts at e only if it is the side's curve
                match (key.curve(self), self.curve_at(e)) {
                    (Some(c), Some(used)) if std::ptr::eq(c, used) => c.weight(j, e),
                    _ => 0.0,
                }
            }
        }
    }
}

impl ForceCurve {
    /// `(F(e), dF/de)`, the slope from the side of larger `e` at a table point.
    pub fn eval(&self, e: f64) -> (f64, f64) {
        match self {
            ForceCurve::Table(points) => {
                let i = table_segment(points, e);
                let ((e0, f0), (e1, f1)) = (points[i], points[i + 1]);
                let slope = (f1 - f0) / (e1 - e0);
                (f0 + slope * (e - e0), slope)
            }
            ForceCurve::Polynomial(a) => {
                // Horner on sum_j a_j e^j (j from 1) and its derivative
                let (mut f, mut df) = (0.0, 0.0);
                for (j, aj) in a.iter().enumerate().rev() {
                    df = df * e + (j + 1) as f64 * aj;
                    f = f * e + aj;
                }
                (f * e, df)
            }
        }
    }

    /// `dF/dp_j` at `e`: `e^(j+1)` for coefficient `j` of a polynomial, the interpolation
    /// weight of point `j` for a table.
    pub fn weight(&self, j: usize, e: f64) -> f64 {
        match self {
            ForceCurve::Table(points) => {
                let i = table_segment(points, e);
                let s = (e - points[i].0) / (points[i + 1].0 - points[i].0);
                if j == i {
                    1.0 - s
                } else if j == i + 1 {
                    s
                } else {
                    0.0
                }
            }
            ForceCurve::Polynomial(_) => e.powi(j as i32 + 1),
        }
    }

    /// `integral_0^e F(s) ds` \[J\].
    pub fn integral(&self, e: f64) -> f64 {
        match self {
            ForceCurve::Table(points) => {
                // exact: F is linear between consecutive breakpoints
                let (lo, hi) = if e < 0.0 { (e, 0.0) } else { (0.0, e) };
                let mut cuts = vec![lo];
                cuts.extend(points.iter().map(|p| p.0).filter(|&x| x > lo && x < hi));
                cuts.push(hi);
                let area: f64 = cuts
                    .windows(2)
                    .map(|w| 0.5 * (w[1] - w[0]) * (self.eval(w[0]).0 + self.eval(w[1]).0))
                    .sum();
                if e < 0.0 {
                    -area
                } else {
                    area
                }
            }
            ForceCurve::Polynomial(a) => a
                .iter()
                .enumerate()
                .map(|(j, aj)| aj * e.powi(j as i32 + 2) / (j + 2) as f64)
                .sum(),
        }
    }
}

/// The segment `[e_i, e_{i+1})` of a table that holds `e` (the first or last one beyond the
/// ends).
fn table_segment(points: &[(f64, f64)], e: f64) -> usize {
    points
        .partition_point(|p| p.0 <= e)
        .saturating_sub(1)
        .min(points.len() - 2)
}

/// A spring-damper with its nonlinear law, if it has one: the element as the assembly sees
/// it. The spring-damper is borrowed (or owned by a copy whose parameter a finite difference
/// moved).
#[derive(Clone, Debug)]
pub struct SpringElement<'m> {
    pub spring: Cow<'m, SpringDamper>,
    pub law: Option<&'m ForceLaw>,
}

/// A parameter of a [`SpringElement`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpringElementParam {
    Spring(SpringParam),
    Law(SpringLawParam),
}

impl<'m> SpringElement<'m> {
    /// Spring `i` of `model` with its law.
    pub fn of(model: &'m Model, i: usize) -> Self {
        Self {
            spring: Cow::Borrowed(&model.springs[i]),
            law: model.spring_law(i).map(|l| &l.law),
        }
    }

    /// The linear spring-damper `spring`.
    pub fn linear(spring: &'m SpringDamper) -> Self {
        Self {
            spring: Cow::Borrowed(spring),
            law: None,
        }
    }

    fn geometry(&self, ctx: &Context, nodes: &[NodeState]) -> Geometry {
        let s = &self.spring;
        let (l, g, h) = segment(&nodes[0], &s.point_a, &nodes[1], &s.point_b);
        let mut v_p = Vec12::zeros();
        for (a, node) in nodes.iter().enumerate() {
            let (xd, om) = physical::velocity(ctx.group, node);
            v_p.fixed_rows_mut::<3>(6 * a).copy_from(&xd);
            v_p.fixed_rows_mut::<3>(6 * a + 3).copy_from(&om);
        }
        let ldot = g.dot(&v_p);
        Geometry { l, ldot, g, h, v_p }
    }

    fn active_slots(&self) -> [bool; 2] {
        [self.spring.node_a.is_some(), self.spring.node_b.is_some()]
    }

    /// The tension `T` (module documentation), the branch included \[N\].
    pub fn tension(&self, ctx: &Context, local: &Local) -> f64 {
        let geo = self.geometry(ctx, local.nodes);
        self.force(&geo, self.branch(&geo, local)).t
    }

    /// `T`, `k_t` and `c_t`, the branch included.
    fn force(&self, geo: &Geometry, branch: Option<(f64, f64, f64)>) -> Force {
        let s = &self.spring;
        let e = geo.l - s.rest_length;
        let mut t = s.stiffness * e + s.damping * geo.ldot;
        let mut kt = s.stiffness;
        if let Some(law) = self.law {
            let (f, df) = law.elastic(e);
            t += f;
            kt += df;
        }
        if let Some((km, _, stretch)) = branch {
            t += km * stretch;
            kt += km;
        }
        let active = self.law.is_none_or(|law| law.acts_at(e, t));
        Force::of(active, t, kt, s.damping)
    }

    /// `(k_m, c_m, l - l0 - z)` of the Maxwell branch, if any.
    fn branch(&self, geo: &Geometry, local: &Local) -> Option<(f64, f64, f64)> {
        self.spring.relaxation.map(|m| {
            (
                m.stiffness,
                m.damping,
                geo.l - self.spring.rest_length - local.x[0],
            )
        })
    }
}

/// A force `T` along a scalar coordinate `c(q)` of two slots (a spring's length, a joint's
/// angle), with the gradient `g = dc/dw_p`, its derivative `H = dg/dw_p`, the physical
/// velocity `v_p` and `(T, dT/dc, dT/dcdot)`: the residual `r_p = T g` and the iteration
/// matrix from `K_p = g (dT/dc g + dT/dcdot H^T v_p)^T + T H`, `C_p = dT/dcdot g g^T`, in
/// group coordinates ([`physical::to_group`]).
pub(super) fn coordinate_force(
    ctx: &Context,
    nodes: &[NodeState],
    active: &[bool],
    (g, h, v_p): (&Vec12, &Mat12, &Vec12),
    (t, kt, ct): (f64, f64, f64),
    r: &mut LocalVector,
    s: &mut Option<(&Coefficients, &mut LocalMatrix)>,
) {
    let r_p = g * t;
    let dt = g * kt + h.transpose() * v_p * ct;
    let k_p = g * dt.transpose() + h * t;
    let c_p = g * g.transpose() * ct;
    let matrix = s.as_mut().map(|(coef, m)| (*coef, &mut **m));
    physical::to_group(
        ctx.group,
        nodes,
        active,
        &r_p,
        Some(&k_p),
        Some(&c_p),
        r,
        matrix,
    );
}

impl SpringDamper {
    /// The tension `T` of the linear spring-damper (module documentation), the branch
    /// included \[N\] (a spring with a nonlinear law: [`SpringElement::tension`]).
    pub fn tension(&self, ctx: &Context, local: &Local) -> f64 {
        SpringElement::linear(self).tension(ctx, local)
    }
}

impl ElementKernel for SpringElement<'_> {
    fn n_slots(&self) -> usize {
        2
    }

    fn node(&self, slot: usize) -> Option<NodeId> {
        [self.spring.node_a, self.spring.node_b][slot]
    }

    fn n_states(&self) -> usize {
        self.spring.relaxation.is_some() as usize
    }

    fn initial_states(&self, ctx: &Context, local: &Local, x: &mut [f64]) -> InitialStates {
        if self.spring.relaxation.is_some() {
            x[0] = self.geometry(ctx, local.nodes).l - self.spring.rest_length;
        }
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
        let geo = self.geometry(ctx, nodes);
        let branch = self.branch(&geo, local);
        let force = self.force(&geo, branch);
        let active = self.active_slots();
        let mut s = s;
        let coordinate = (&geo.g, &geo.h, &geo.v_p);
        let tension = (force.t, force.kt, force.ct);
        coordinate_force(ctx, nodes, &active, coordinate, tension, r, &mut s);
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
        // the branch force acts only with the element (always, but for a one-sided law,
        // which validation keeps apart from a branch)
        let on = if force.active { 1.0 } else { 0.0 };
        for a in 0..2 {
            let row = if active[a] {
                nodes[a].t.transpose() * g.fixed_rows::<6>(6 * a) * (-km / cm * coef.k)
            } else {
                flexmb_lie::Vec6::zeros()
            };
            for i in 0..6 {
                s[(6 * a + i, 12)] = -km * g[6 * a + i] * coef.x * on;
                s[(12, 6 * a + i)] = row[i];
            }
        }
        s[(12, 12)] = km / cm * coef.x + coef.xdot;
    }

    fn potential_energy(&self, ctx: &Context, local: &Local) -> f64 {
        let geo = self.geometry(ctx, local.nodes);
        let sp = &self.spring;
        let e = geo.l - sp.rest_length;
        let branch = self
            .branch(&geo, local)
            .map_or(0.0, |(km, _, s)| 0.5 * km * s * s);
        let Some(law) = self.law else {
            return 0.5 * sp.stiffness * e * e + branch;
        };
        if !law.on_side(e) {
            return 0.0;
        }
        law.energy(e) + 0.5 * sp.stiffness * e * e + branch
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

    fn initial_states(&self, ctx: &Context, local: &Local, x: &mut [f64]) -> InitialStates {
        SpringElement::linear(self).initial_states(ctx, local, x)
    }

    fn evaluate(
        &self,
        ctx: &Context,
        local: &Local,
        r: &mut LocalVector,
        s: Option<(&Coefficients, &mut LocalMatrix)>,
    ) {
        SpringElement::linear(self).evaluate(ctx, local, r, s)
    }

    fn potential_energy(&self, ctx: &Context, local: &Local) -> f64 {
        SpringElement::linear(self).potential_energy(ctx, local)
    }
}

impl ElementParameters for SpringElement<'_> {
    type Param = SpringElementParam;

    fn parameter_derivative(
        &self,
        ctx: &Context,
        p: SpringElementParam,
        local: &Local,
        dr: &mut LocalVector,
    ) -> DerivativeMethod {
        let nodes = local.nodes;
        let geo = self.geometry(ctx, nodes);
        let branch = self.branch(&geo, local);
        let force = self.force(&geo, branch);
        let on = if force.active { 1.0 } else { 0.0 };
        let (km, cm, stretch) = branch.unwrap_or((0.0, 1.0, 0.0));
        let sp = &self.spring;
        let e = geo.l - sp.rest_length;
        // (dT/dp, de/dp); dT/dp zero where a stop is off
        let (dt, de) = match p {
            SpringElementParam::Spring(q) => match q {
                SpringParam::Stiffness => (e * on, 0.0),
                SpringParam::Damping => (geo.ldot * on, 0.0),
                // k_t holds k_m already
                SpringParam::RestLength => (-force.kt, km / cm),
                SpringParam::RelaxationStiffness => (stretch * on, -stretch / cm),
                SpringParam::RelaxationDamping => (0.0, km * stretch / (cm * cm)),
                SpringParam::PointA(_) | SpringParam::PointB(_) => {
                    let model_nodes = &ctx.model.nodes;
                    let at = q.get(sp, model_nodes);
                    // a typical length: the spring's, or the point's distance from the origin
                    let scale = sp.rest_length.max(geo.l).max(at.abs());
                    let scale = if scale > 1e-300 { scale } else { 1.0 };
                    let set =
                        |s: &mut SpringElement, v: f64| q.set(s.spring.to_mut(), model_nodes, v);
                    return central_difference(self, ctx, local, (at, scale), set, dr);
                }
            },
            SpringElementParam::Law(q) => {
                let law = self.law.expect("a law parameter of a spring with a law");
                (law.parameter_derivative(q, e) * on, 0.0)
            }
        };
        let r_p = geo.g * dt;
        let active = self.active_slots();
        physical::to_group(ctx.group, nodes, &active, &r_p, None, None, dr, None);
        if branch.is_some() {
            dr[12] = de;
        }
        DerivativeMethod::Analytic
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
        let element = SpringElement::linear(self);
        element.parameter_derivative(ctx, SpringElementParam::Spring(p), local, dr)
    }
}
