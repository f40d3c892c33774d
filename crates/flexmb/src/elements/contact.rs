//! Unilateral contact with a continuous (compliant) impact law and regularized Coulomb
//! friction ([`crate::model::contact::Contact`]).
//!
//! **Gap.** Shape A is fixed on node A, shape B on node B (either may be the ground). With
//! `c_B` the centre of B (a sphere's centre, a point, or the reference point of a circle's
//! axis) and `rho_B` its radius, the signed gap `g` and the unit normal `n` (the direction
//! the contact pushes B) are
//!
//! ```text
//! plane (point p, normal m) - sphere:   n = R_A m,         g = n . (c_B - x_A - R_A p) - rho_B
//! sphere (centre c_A) - sphere:          d = c_B - c_A
//! cylinder (axis e through a) - sphere
//!   or circle (parallel axis):           d = (I - e e^T)(c_B - a),   e = R_A e_A
//!   outside:  n = d / |d|,  g = |d| - rho_A - rho_B;     inside:  n = -d / |d|,  g = rho_A - rho_B - |d|
//! ```
//!
//! The penetration is `delta = -g`; both bodies are loaded at the point
//! `P = c_B - (rho_B - delta / 2) n` halfway between the two surfaces, and the relative
//! velocity there is `v_rel = v_B(P) - v_A(P)` (material points of the two bodies), so that
//! `deltadot = -n . v_rel` and the slip velocity is `v_t = (I - n n^T) v_rel`.
//!
//! **Normal force** (Lankarani & Nikravesh 1994, Nonlinear Dyn. 5, Eq. (10); Hunt & Crossley
//! 1975, J. Appl. Mech. 42; Flores, Machado, Silva & Martins 2011, Multibody Syst. Dyn. 25,
//! Eq. (28)): for `delta > 0`,
//!
//! ```text
//! F_n = max(0, K delta^n (1 + chi(e) deltadot / v_imp)),
//! chi = 3 (1 - e^2) / 4 (Lankarani-Nikravesh),   3 (1 - e) / 2 (Hunt-Crossley),
//!       8 (1 - e) / (5 e) (Flores),
//!       the root in (0, 1/e) of chi (1 + e) = ln((1 + chi) / (1 - chi e)) (exact restitution),
//! ```
//!
//! `K` the Hertz stiffness (`4/3 E* sqrt(R*)` for two spheres, `1/E* = (1 - nu_1^2)/E_1 +
//! (1 - nu_2^2)/E_2`), `n` its exponent (3/2), `e` the coefficient of restitution and `v_imp`
//! the approach speed at the onset of the contact. The hysteresis loop of Lankarani &
//! Nikravesh dissipates, along the elastic path, `Delta E = 2/3 chi m* v_imp^2 =
//! m* v_imp^2 (1 - e^2) / 2`, the kinetic energy an impact of restitution `e` loses; the
//! approximation holds for `e` near 1 (the law's true restitution is higher for small `e`;
//! Flores et al. 2011 derive their `chi` for the whole range).
//!
//! **Exact restitution.** In an isolated impact (`m* deltaddot = -F`, onset at `deltadot =
//! v_imp`), with `w = delta^(n+1) / (n + 1)` and `s = deltadot / v_imp`, the law reads
//! `s ds / (1 + chi s) = -K / (m* v_imp^2) dw`: `w` returns to 0 at the release, so the
//! integral of the left side from `s = 1` to `s = -R` vanishes, and the law's own
//! restitution `R` solves
//!
//! ```text
//! chi (1 + R) = ln((1 + chi) / (1 - chi R)),     0 < chi R < 1,
//! ```
//!
//! independent of `K`, `m*`, `v_imp` and `n` (the force is never clipped: `1 + chi s > 0`
//! from `s = 1` down to `-R`). `law = "exact_restitution"` takes for `chi(e)` the root of
//! this equation with `R = e` ([`crate::model::contact::exact_restitution_factor`]:
//! safeguarded Newton iterations in the bracket `(0, 1/e)`, `dchi/de` by the implicit
//! function theorem, exact). Its `chi` (1.4328, 0.37315, 0.07893 for e = 0.5, 0.8, 0.95)
//! lies between Hunt & Crossley's and Flores et al.'s for these `e`; `tests/physics/contact.rs`
//! checks that the law restitutes `e` by integrating the impact numerically. This is Hunt &
//! Crossley's form with `chi` chosen for the exact restitution, and the relation is derived
//! here as stated: the published work on exact restitution for this form could not be
//! consulted to check what it proposes, so none is cited. An impact in a model rebounds at
//! `e` up to what the isolated impact leaves out (gravity and other forces during the
//! contact, the approach speed of the step that closes it).
//!
//! **Impact velocity.** `v_imp` is the element's one state `x`, a held value: its equation is
//! `e = xdot = 0` (in statics, where rates are absent, `x` keeps its value), and between
//! steps ([`ElementKernel::update_states`]) it is set, while the contact is open, to the
//! approach speed `deltadot` (at least `min_impact_velocity`), and after the step in which
//! it closes, to the approach speed at the onset (gap and rate interpolated linearly over
//! that step). The step that closes the contact is damped with the approach speed at its
//! start; the step control keeps its penetration small.
//!
//! **Friction** (regularized Coulomb with a viscous term): on B,
//!
//! ```text
//! F_t = -(mu F_n / max(|v_t|, v_s) + c_v) v_t,
//! ```
//!
//! equal to Coulomb's `mu F_n` above the stiction velocity `v_s` and linear below it: a body
//! held by friction creeps at most at `v_s F_t / (mu F_n)`.
//!
//! **Bristles** (LuGre: Canudas de Wit, Olsson, Åström & Lischinsky 1995, IEEE Trans. Autom.
//! Control 40(3), Eqs. (1)-(4), per unit normal force): three more element states, the mean
//! bristle deflection `z` (inertial components), with
//!
//! ```text
//! e_z = zdot - v_t + sigma_0 |v_t| z / g(|v_t|) = 0,    g(v) = mu + (mu_s - mu) exp(-(v/v_s)^2),
//! F_t = -F_n (I - n n^T)(sigma_0 z + sigma_1 zdot) - c_v v_t,
//! ```
//!
//! in place of the regularization: at rest the bristles hold the load like a spring, without
//! creep, and break away at `mu_s F_n`. The deflection equation holds whether the contact is
//! open or closed (continuous across the onset; open, the force is zero), with `|v_t|`
//! smoothed at `1e-6 v_s` for its derivative.
//!
//! **Residual and iteration matrix.** The force `F = F_n n + F_t` acts on B at `P` and `-F`
//! on A, so in physical coordinates ([`super::physical`])
//!
//! ```text
//! r_X = -s_X [ F ; (R_X^T (P - x_X)) x (R_X^T F) ],    s_B = 1, s_A = -1.
//! ```
//!
//! Its exact derivatives `K_p = dr/dw` (configuration `R -> R exp(tilde(theta))`, `x -> x +
//! dx`), `C_p = dr/dv`, those with respect to the states and their rates, and those of the
//! bristles' equations, are computed by forward automatic differentiation (`num-dual`) of
//! the same function, exact to round-off (one-sided at the kinks: the onset `delta = 0`,
//! `F_n = 0`, `|v_t| = v_s`); so are the parameter derivatives. In the iteration matrix of
//! statics (stiffness without a rate term: the rates are absent) the states are held: their
//! rows read `x = x_start` (friction acts in dynamics only).
//!
//! **Step control around impacts** ([`ElementKernel::step_limit`]): the contact's gap `g`,
//! its rate, the law's `K` and `n`, the effective mass `m*` of the two nodes' bodies and the
//! held impact velocity go to the step control shared with the gear pairs' backlash
//! ([`super::impact`]): the steps shrink geometrically as the gap closes, a step that closes
//! it deeper than `delta* / 12` (`delta*` the largest penetration of the impact) is repeated
//! to the time the gap reaches half that much (event location on the gap), one that closes
//! and opens it within itself is shortened, about 35 steps resolve the impact, and after the
//! contact opens the step grows back (doubling every 4 accepted steps).

use super::impact::{crossing, Gap, ImpactLaw};
use super::pose::{c, lift, perturbed, pose, Dv, Pose, D1};
use super::{
    physical, Coefficients, Context, DerivativeMethod, ElementKernel, ElementParameters,
    InitialStates, Local, LocalMatrix, LocalVector, StepLimit, Vec12,
};
use crate::model::contact::{Contact, ContactShape};
use crate::model::parameters::ContactParam;
use crate::model::{Model, NodeId};
use flexmb_lie::Group;
use nalgebra::{RealField, SMatrix, SVector, Vector3};

/// A contact pair with the effective mass `m*` of its two nodes' bodies (for the step
/// control; infinite when neither node carries a body).
#[derive(Clone, Copy, Debug)]
pub struct ContactElement<'m> {
    pub contact: &'m Contact,
    pub effective_mass: f64,
}

/// The parameters of a contact's law that are differentiated ([`ContactParam`], in its
/// order): stiffness, exponent, restitution, friction coefficient, viscous coefficient.
#[derive(Clone, Copy, Debug)]
struct Law<T> {
    stiffness: T,
    exponent: T,
    restitution: T,
    friction: T,
    viscous: T,
    /// The hysteresis factor `chi(e)` (a function of the restitution).
    chi: T,
}

/// What one evaluation finds, for the residual and the sensors.
#[derive(Clone, Copy, Debug, Default)]
pub struct ContactState {
    /// Signed gap g \[m\] (negative: penetration).
    pub gap: f64,
    /// Its rate gdot \[m/s\].
    pub gap_rate: f64,
    /// Normal force F_n \[N\].
    pub normal_force: f64,
    /// Magnitude of the friction force \[N\].
    pub friction_force: f64,
    /// Slip speed |v_t| \[m/s\].
    pub slip_velocity: f64,
}

impl Contact {
    /// Gap `g`, normal `n` and centre `c_B` (module documentation).
    fn gap<T: RealField + Copy>(&self, a: &Pose<T>, b: &Pose<T>) -> (T, Vector3<T>, Vector3<T>) {
        let rho_b: T = c(self.shape_b.radius());
        let c_b = match self.shape_b {
            ContactShape::Sphere { center, .. } => b.point(&center),
            ContactShape::Cylinder { point, .. } => b.point(&point),
            ContactShape::Plane { .. } => unreachable!("validated: shape B is not a plane"),
        };
        let d = match self.shape_a {
            ContactShape::Plane { point, normal } => {
                let n = a.direction(&normal);
                let g = n.dot(&(c_b - a.point(&point))) - rho_b;
                return (g, n, c_b);
            }
            ContactShape::Sphere { center, .. } => c_b - a.point(&center),
            ContactShape::Cylinder { point, axis, .. } => {
                let e = a.direction(&axis);
                let d0 = c_b - a.point(&point);
                d0 - e * e.dot(&d0)
            }
        };
        let dist = d.norm().max(c(1e-300));
        let rho_a: T = c(self.shape_a.radius());
        if self.shape_a.inside() {
            (rho_a - rho_b - dist, -d / dist, c_b)
        } else {
            (dist - rho_a - rho_b, d / dist, c_b)
        }
    }

    /// The physical residual (12: slot A, slot B) and the bristles' equations (3; zero
    /// without bristles) at the poses `a`, `b` with the states `x` (impact velocity, then
    /// the bristles' deflection) and their rates `xdot`, with the law's parameters `law`;
    /// and what the evaluation found (gap, its rate, normal force, friction force, slip
    /// speed).
    fn residual<T: RealField + Copy>(
        &self,
        a: &Pose<T>,
        b: &Pose<T>,
        (x, xdot): (&[T], &[T]),
        law: &Law<T>,
    ) -> ([T; 15], [T; 5]) {
        let zero = T::zero();
        let mut out = [zero; 15];
        let (g, n, c_b) = self.gap(a, b);
        let delta = -g;
        let rho_b: T = c(self.shape_b.radius());
        let p = c_b - n * (rho_b - delta * c(0.5));
        let v_rel = b.velocity_at(&p) - a.velocity_at(&p);
        let gdot = n.dot(&v_rel);
        let v_t = v_rel - n * gdot;
        let mut found = [g, gdot, zero, zero, zero];
        let bristles = self.friction.and_then(|f| f.bristles.map(|b| (f, b)));
        let mut z_and_rate = None;
        if let Some((f, br)) = bristles {
            // LuGre's deflection equation, open or closed (continuous across the onset; the
            // friction force it gives is zero while the contact is open). |v_t| is smoothed
            // at 0 (1e-6 v_s) for its derivative.
            let z = Vector3::new(x[1], x[2], x[3]);
            let zdot = Vector3::new(xdot[1], xdot[2], xdot[3]);
            let vs: T = c(f.stiction_velocity);
            let s = (v_t.norm_squared() + vs * vs * c(1e-12)).sqrt();
            let mu_s: T = c(br.static_coefficient);
            let stribeck = law.friction + (mu_s - law.friction) * (-(s / vs).powi(2)).exp();
            let e = zdot - v_t + z * (c::<T>(br.stiffness) * s / stribeck);
            out[12..].copy_from_slice(e.as_slice());
            z_and_rate = Some((z, zdot, s));
        }
        if delta <= zero {
            return (out, found);
        }
        let chi = law.chi;
        let elastic = delta.powf(law.exponent) * law.stiffness;
        let f_n = (elastic * (T::one() - chi * gdot / x[0])).max(zero);
        let mut f = n * f_n;
        found[2] = f_n;
        if let Some(fr) = &self.friction {
            let f_t = match bristles {
                None => {
                    let s = v_t.norm();
                    let vs: T = c(fr.stiction_velocity);
                    found[4] = s;
                    v_t * -(f_n * law.friction / s.max(vs) + law.viscous)
                }
                Some((_, br)) => {
                    let (z, zdot, s) = z_and_rate.expect("bristle states");
                    found[4] = s;
                    let (sigma0, sigma1): (T, T) = (c(br.stiffness), c(br.damping));
                    let tangential = |v: Vector3<T>| v - n * n.dot(&v);
                    -(tangential(z * sigma0 + zdot * sigma1) * f_n) - v_t * law.viscous
                }
            };
            found[3] = f_t.norm();
            f += f_t;
        }
        let ra = a.generalized(&f, &p, 1.0);
        let rb = b.generalized(&f, &p, -1.0);
        out[..6].copy_from_slice(&ra);
        out[6..12].copy_from_slice(&rb);
        (out, found)
    }

    /// The law's parameters ([`ContactParam`]) as `T`.
    fn law<T: RealField + Copy>(&self) -> Law<T> {
        let friction = self.friction.as_ref();
        let e = c(self.law.restitution);
        Law {
            stiffness: c(self.law.stiffness),
            exponent: c(self.law.exponent),
            restitution: e,
            friction: c(friction.map_or(0.0, |f| f.coefficient)),
            viscous: c(friction.map_or(0.0, |f| f.viscous)),
            chi: self.law.dissipation.factor(e),
        }
    }

    /// Whether slots A and B are nodes.
    fn active(&self) -> [bool; 2] {
        [self.node_a.is_some(), self.node_b.is_some()]
    }
}

/// Variables of the automatic differentiation of [`ElementKernel::evaluate`]: node
/// variations (12), velocities (12), the impact velocity, and with bristles their deflection
/// (3) and its rate (3).
const N_PLAIN: usize = 25;
const N_BRISTLES: usize = 31;
impl ContactElement<'_> {
    /// The residual `[r (12); e_z (3)]` and its Jacobian with respect to the `N` variables
    /// ([`N_PLAIN`] without bristles, [`N_BRISTLES`] with), by forward AD.
    fn jacobian<const N: usize>(
        &self,
        group: Group,
        local: &Local,
    ) -> (SVector<f64, 15>, SMatrix<f64, 15, N>) {
        let nodes = local.nodes;
        let ns = self.n_states();
        let mut w0 = SVector::<f64, N>::zeros();
        w0.rows_mut(24, ns).copy_from_slice(local.x);
        if ns > 1 {
            w0.rows_mut(28, ns - 1).copy_from_slice(&local.xdot[1..]);
        }
        let law = self.contact.law();
        num_dual::jacobian(
            |w: SVector<Dv<N>, N>| {
                let a = perturbed(group, &nodes[0], &w, 0);
                let b = perturbed(group, &nodes[1], &w, 1);
                let zero = w[24] * 0.0;
                let at = |i: usize| if i < N { w[i] } else { zero };
                let x = [w[24], at(25), at(26), at(27)];
                let xdot = [zero, at(28), at(29), at(30)];
                SVector::<Dv<N>, 15>::from(self.contact.residual(&a, &b, (&x, &xdot), &law).0)
            },
            &w0,
        )
    }

    /// What the contact finds at the kinematics of `local` (sensors, step control).
    pub fn state(&self, ctx: &Context, local: &Local) -> ContactState {
        let (a, b) = (
            pose(ctx.group, &local.nodes[0]),
            pose(ctx.group, &local.nodes[1]),
        );
        let (_, f) = self
            .contact
            .residual(&a, &b, (local.x, local.xdot), &self.contact.law());
        ContactState {
            gap: f[0],
            gap_rate: f[1],
            normal_force: f[2],
            friction_force: f[3],
            slip_velocity: f[4],
        }
    }

    /// The impact velocity a contact that closes from these kinematics is damped with.
    fn approach_speed(&self, state: &ContactState) -> f64 {
        (-state.gap_rate).max(self.contact.law.min_impact_velocity)
    }

    /// The elastic part of the law with the effective mass, for the step control.
    fn impact_law(&self) -> ImpactLaw {
        let law = &self.contact.law;
        ImpactLaw {
            stiffness: law.stiffness,
            exponent: law.exponent,
            effective_mass: self.effective_mass,
        }
    }
}

/// The effective mass `m*` of the bodies on nodes `a` and `b` (`1/m* = 1/m_a + 1/m_b`; the
/// ground and nodes without bodies count as infinite).
pub fn effective_mass(model: &Model, a: Option<NodeId>, b: Option<NodeId>) -> f64 {
    let mass = |n: Option<NodeId>| {
        n.map_or(0.0, |n| {
            model
                .bodies
                .iter()
                .filter(|body| body.node == n)
                .map(|body| body.mass)
                .sum()
        })
    };
    let inverse: f64 = [mass(a), mass(b)]
        .iter()
        .filter(|&&m| m > 0.0)
        .map(|m| 1.0 / m)
        .sum();
    if inverse > 0.0 {
        1.0 / inverse
    } else {
        f64::INFINITY
    }
}

impl ElementKernel for ContactElement<'_> {
    fn n_slots(&self) -> usize {
        2
    }

    fn node(&self, slot: usize) -> Option<NodeId> {
        [self.contact.node_a, self.contact.node_b][slot]
    }

    fn n_states(&self) -> usize {
        self.contact.n_states()
    }

    fn initial_states(&self, ctx: &Context, local: &Local, x: &mut [f64]) -> InitialStates {
        let held = [1.0, 0.0, 0.0, 0.0];
        let local = Local {
            x: &held[..x.len()],
            xdot: &[0.0; 4][..x.len()],
            ..*local
        };
        x[0] = self.approach_speed(&self.state(ctx, &local));
        Ok(())
    }

    fn update_states(&self, ctx: &Context, start: &Local, end: &Local, x: &mut [f64]) {
        let s1 = self.state(ctx, end);
        if s1.gap >= 0.0 {
            x[0] = self.approach_speed(&s1);
            return;
        }
        let s0 = self.state(ctx, start);
        if s0.gap >= 0.0 {
            // Closed in this step: the approach speed at the onset, the gap and its rate
            // interpolated linearly.
            let s = s0.gap / (s0.gap - s1.gap);
            let rate = s0.gap_rate + s * (s1.gap_rate - s0.gap_rate);
            x[0] = (-rate).max(self.contact.law.min_impact_velocity);
        }
    }

    fn step_limit(&self, ctx: &Context, start: &Local, end: &Local, h: f64) -> Option<StepLimit> {
        let (s0, s1) = (self.state(ctx, start), self.state(ctx, end));
        let gap = |s: &ContactState| Gap {
            gap: s.gap,
            rate: s.gap_rate,
        };
        let impact_speed = start.x[0].max(end.x[0]);
        self.impact_law()
            .step_limit(gap(&s0), gap(&s1), Some(impact_speed), h)
    }

    fn event(&self, ctx: &Context, start: &Local, end: &Local) -> Option<String> {
        let gap = |local: &Local| self.state(ctx, local).gap;
        let what = crossing(gap(start), gap(end))?;
        Some(format!("contact '{}' {what}", self.contact.name))
    }

    fn evaluate(
        &self,
        ctx: &Context,
        local: &Local,
        r: &mut LocalVector,
        s: Option<(&Coefficients, &mut LocalMatrix)>,
    ) {
        let nodes = local.nodes;
        let group = ctx.group;
        let active = self.contact.active();
        let ns = self.n_states();
        r[12] = local.xdot[0];
        let Some((coef, s)) = s else {
            let (a, b) = (pose(group, &nodes[0]), pose(group, &nodes[1]));
            let law = self.contact.law();
            let (out, _) = self.contact.residual(&a, &b, (local.x, local.xdot), &law);
            let rp = Vec12::from_column_slice(&out[..12]);
            physical::to_group(group, nodes, &active, &rp, None, None, r, None);
            for i in 1..ns {
                r[12 + i] = out[11 + i];
            }
            return;
        };
        if ns == 1 && self.state(ctx, local).gap > 0.0 {
            // Open, without bristles: no force, and none nearby (the gap is continuous).
            r.rows_mut(0, 12).fill(0.0);
            let mut s = s.view();
            s.fill(0.0);
            // (the impact velocity's equation `xdot = 0`; held in statics, below)
            s[(12, 12)] = if coef.holds_states() {
                coef.x
            } else {
                coef.xdot
            };
            return;
        }
        let (out, jac) = if ns == 1 {
            let (out, jac) = self.jacobian::<N_PLAIN>(group, local);
            let mut full = SMatrix::<f64, 15, N_BRISTLES>::zeros();
            full.fixed_columns_mut::<N_PLAIN>(0).copy_from(&jac);
            (out, full)
        } else {
            self.jacobian::<N_BRISTLES>(group, local)
        };
        let rp = Vec12::from_column_slice(&out.as_slice()[..12]);
        for i in 1..ns {
            r[12 + i] = out[11 + i];
        }
        let k_p: SMatrix<f64, 12, 12> = jac.fixed_view::<12, 12>(0, 0).into_owned();
        let c_p: SMatrix<f64, 12, 12> = jac.fixed_view::<12, 12>(0, 12).into_owned();
        physical::to_group(
            group,
            nodes,
            &active,
            &rp,
            Some(&k_p),
            Some(&c_p),
            r,
            Some((coef, s)),
        );
        let mut s = s.view();
        // State columns of the mechanical rows (group coordinates, like a residual):
        // x dr/dx + xdot dr/dxdot (the impact velocity has no rate in r).
        for k in 0..ns {
            let mut col = Vec12::from_column_slice(&jac.column(24 + k).as_slice()[..12]) * coef.x;
            if k > 0 {
                col += Vec12::from_column_slice(&jac.column(27 + k).as_slice()[..12]) * coef.xdot;
            }
            physical::translations_to_group(group, nodes, &active, &mut col);
            s.view_mut((0, 12 + k), (12, 1)).copy_from(&col);
        }
        // The held impact velocity's row.
        s.view_mut((12, 0), (1, 12 + ns)).fill(0.0);
        // The bristles' rows: node columns in group coordinates, state columns.
        for i in 1..ns {
            let row = 11 + i;
            for a in 0..2 {
                let block = if active[a] {
                    let de_dw = jac.fixed_view::<1, 6>(row, 6 * a).into_owned();
                    let de_dv = jac.fixed_view::<1, 6>(row, 12 + 6 * a).into_owned();
                    physical::row_to_group(
                        group,
                        &nodes[a],
                        (de_dw, de_dv, nalgebra::RowVector6::zeros()),
                        coef,
                    )
                } else {
                    nalgebra::RowVector6::zeros()
                };
                s.view_mut((12 + i, 6 * a), (1, 6)).copy_from(&block);
            }
            s[(12 + i, 12)] = jac[(row, 24)] * coef.x;
            for k in 1..ns {
                s[(12 + i, 12 + k)] = jac[(row, 24 + k)] * coef.x + jac[(row, 27 + k)] * coef.xdot;
            }
        }
        // The states are held in statics ([`Coefficients::holds_states`]); elsewhere the
        // impact velocity's equation is `xdot = 0` (its rate's column).
        let statics = coef.holds_states();
        for k in 0..ns {
            if statics {
                s[(12 + k, 12 + k)] = coef.x;
            } else if k == 0 && coef.xdot != 0.0 {
                s[(12, 12)] = coef.xdot;
            }
        }
    }

    fn potential_energy(&self, ctx: &Context, local: &Local) -> f64 {
        let delta = -self.state(ctx, local).gap;
        if delta <= 0.0 {
            return 0.0;
        }
        let law = &self.contact.law;
        law.stiffness * delta.powf(law.exponent + 1.0) / (law.exponent + 1.0)
    }
}

impl ElementParameters for ContactElement<'_> {
    type Param = ContactParam;

    fn parameter_derivative(
        &self,
        ctx: &Context,
        p: ContactParam,
        local: &Local,
        dr: &mut LocalVector,
    ) -> DerivativeMethod {
        // Forward automatic differentiation of the same residual in the law's parameter
        // (the held state's equation does not depend on it).
        let nodes = local.nodes;
        let group = ctx.group;
        let (a, b) = (pose(group, &nodes[0]), pose(group, &nodes[1]));
        let mut law = self.contact.law::<D1>();
        let parameter = match p {
            ContactParam::Stiffness => &mut law.stiffness,
            ContactParam::Exponent => &mut law.exponent,
            ContactParam::Restitution => &mut law.restitution,
            ContactParam::Friction => &mut law.friction,
            ContactParam::ViscousFriction => &mut law.viscous,
        };
        parameter.eps = 1.0;
        // chi follows the restitution
        law.chi = self.contact.law.dissipation.factor(law.restitution);
        let x: Vec<D1> = local.x.iter().map(|&v| D1::from_re(v)).collect();
        let xdot: Vec<D1> = local.xdot.iter().map(|&v| D1::from_re(v)).collect();
        let (out, _) = self
            .contact
            .residual(&lift(&a), &lift(&b), (&x, &xdot), &law);
        let d = Vec12::from_fn(|i, _| out[i].eps);
        physical::to_group(
            group,
            nodes,
            &self.contact.active(),
            &d,
            None,
            None,
            dr,
            None,
        );
        dr[12] = 0.0;
        for i in 1..self.n_states() {
            dr[12 + i] = out[11 + i].eps;
        }
        DerivativeMethod::Analytic
    }
}
