//! Gear pair between two rotating nodes: a spring `k(s)` and a damper `c` along the line of
//! action, with backlash, static transmission error and the effect of the centre distance
//! (Cardona 1997; the talk's "gear pair element": local flexibility, ISO 6336 mesh stiffness
//! fluctuation, backlash, transmission error, misalignment). The same kinematics give the ideal gear constraint
//! ([`crate::joints::gear`]).
//!
//! ```text
//!            wheel A (node A)                 wheel B (node B)
//!              z_a (axis)                        z_b (parallel to z_a)
//!               |     x_a  ----- d ----->  <---- x_b
//!              C_a ==========================  C_b
//!                    (line of centres d = C_b - C_a; the mesh is on it)
//! ```
//!
//! **Mesh kinematics on the group, without a rotation parameterization.** Each wheel carries
//! a frame (centre `C`, axes `i, j, k`, `k` the wheel axis) whose `i` points at the other
//! wheel's centre at t = 0. The angle of the line of centres seen from each wheel,
//!
//! ```text
//! phi_a = atan2(j_a . d, i_a . d),     phi_b = atan2(-j_b . d, -i_b . d),
//! ```
//!
//! is a smooth function of the two node configurations (both arguments are dot-2 primitives
//! of Haug 1989, Sect. 3.3, [`crate::joints::primitives`]) and zero at t = 0. A rotation
//! `alpha` of a wheel about its axis relative to the line of centres gives `phi = -alpha`,
//! so rolling without slip of the base circles (radii `r_ba`, `r_bb`), `r_ba alpha_a' =
//! -sigma r_bb alpha_b'` (`sigma = +1` external, `-1` internal), is `psi = 0` with
//!
//! ```text
//! psi = z_a phi_a + sigma z_b phi_b        (z_a, z_b the teeth; r_bb / r_ba = z_b / z_a).
//! ```
//!
//! Measuring both rotations from the line of centres makes the relation hold for moving
//! axes too (a planet on its carrier: Willis' formula) and makes the mesh insensitive to the
//! centre distance, as an involute mesh is (Litvin & Fuentes 2004). Because the
//! teeth are whole numbers, `psi` is defined modulo `2 pi` by the node rotations alone: one
//! turn of either wheel moves it by a whole number of base pitches. No angle is tracked.
//!
//! **Mesh deflection and transmission error.** Along the transverse line of action
//! (Cardona 1997; Kahraman & Singh 1990) the dynamic transmission error
//! is
//!
//! ```text
//! delta_t = r_ba alpha_a + sigma r_bb alpha_b = -(p_bt / 2 pi) wrap(psi),   p_bt = 2 pi r_ba / z_a,
//! ```
//!
//! (`wrap` to `(-pi, pi]`: the deflection is far below half a base pitch `p_bt`), and along
//! the normal line of action of a helical pair, with base helix angle `beta_b` and the
//! relative axial displacement `u = k_a . d - u_0`,
//! `delta_n = cos(beta_b) delta_t + sin(beta_b) u`. The mesh position is `s = z_a alpha_a +
//! s_0` (one mesh period per `2 pi`).
//!
//! **Contact on either flank.** With the static transmission error
//! `e(s) = sum_n e_n cos(n s + phi_n)` (Özgüven & Houser 1988), the backlash `b` (total
//! clearance along the normal line of action) and the centre distance `a = |d|` (its change
//! opens the backlash by `2 (a - a_0) sin(alpha_wt) cos(beta_b)` for an external pair and
//! closes it for an internal one: the involute relation of ISO/TR 10064-2 between centre
//! distance and backlash), flank `f = +1` (drive: wheel A pushes) and `f = -1` (coast) have
//! the penetrations
//!
//! ```text
//! y_f = f (delta_n - e(s)) - sigma sin(alpha_wt) cos(beta_b) (a - a_0) - b / 2,
//! cos(alpha_wt) = |r_ba + sigma r_bb| / a_0,
//! ```
//!
//! and carry the force (the clearance function of Kahraman & Singh 1990; here the damper
//! acts in contact only and never pulls, so there is no force inside the backlash)
//!
//! ```text
//! F_f = max(0, k(s) y_f + c y_f')  if y_f > 0,  else 0,
//! k(s) = k_m (kappa(s) + sum_n eps_n cos(n s + phi_n))  (ISO 6336-1: c_gamma, c'),
//! ```
//!
//! (`kappa` the stiffness table over one mesh period, linearly interpolated and periodic; 1
//! without a table), whose generalized force is `r_p = sum_f F_f grad(y_f)` (physical coordinates, see
//! [`super::physical`]). Exact iteration matrix, per flank in contact:
//!
//! ```text
//! K_p = g (k g + y k'(s) grad(s) + c H^T v_p)^T + F H,    C_p = c g g^T,
//! g = grad(y_f),  H = d g / d w_p,
//! ```
//!
//! with the gradients of `y_f` composed from those of the primitives by the chain rule
//! (`atan2`, `sin`, the cosine series). The force is continuous at contact onset when
//! `c = 0` and one-sided differentiable there.
//!
//! **Impacts of the flanks located by the step control** ([`ElementKernel::step_limit`]).
//! With backlash (`b > 0`, unless `locate_impacts` is off) each flank is a gap `g = -y_f` with
//! rate `-y_f'` for the step control the contacts use ([`super::impact`], the same code): the
//! elastic law `k(s) y_f` (`n = 1`) and the effective mass of the mesh along the normal line
//! of action,
//!
//! ```text
//! 1 / m* = cos^2(beta_b) (r_ba^2 / J_a + r_bb^2 / J_b),
//! ```
//!
//! `J_a`, `J_b` the inertias of the bodies on the wheels' nodes about the wheel axes (a node
//! without a body counts as infinitely heavy; the translation of the wheels on their
//! bearings is left out: `m*` only sizes the steps). A mesh impact lasts about `pi
//! sqrt(m* / k)`; the steps shrink as a flank closes, a step that closes it deeper than
//! `delta* / 12` is repeated to the time its gap reaches half that much (event location on
//! the gap), one that closes and opens it within itself is shortened, and the step grows back
//! once the flank opens or the mesh rests (vibration below 1 % of the deflection). Without
//! backlash one flank is always in contact and the force is continuous across the flank
//! change: no event.
//!
//! **Parameter derivatives** ([`GearParam`]): `dr_p/dk_m = sum_f (k / k_m) y_f g_f`,
//! `dr_p/dc = sum_f y_f' g_f`, `dr_p/db = -sum_f (k / 2) g_f`, `dr_p/deps_n = sum_f k_m
//! cos(n s + phi_n) y_f g_f` (flanks in contact); the transmission error's amplitudes by the
//! finite-difference default ([`super::central_difference`]).
//!
//! The section and equation numbers of the papers below could not be checked here (no copy
//! at hand); the equations above are written out in full so that they stand on their own.
//!
//! # References
//! - A. Cardona, "Flexible three dimensional gear modelling", Eur. J. Mech. A/Solids, 1997
//!   (the gear pair element between rigid or flexible wheels: base circles, line of action,
//!   backlash, transmission error), as presented in the talk
//!   `talk-direct-to-inverse-fmbd` ("Gear pair element").
//! - A. Kahraman, R. Singh, "Non-linear dynamics of a spur gear pair", J. Sound Vib. 142(1),
//!   1990, 49-75 (single-mesh torsional model with backlash and a clearance function).
//! - H. N. Özgüven, D. R. Houser, "Mathematical models used in gear dynamics - a review",
//!   J. Sound Vib. 121(3), 1988, 383-411 (static transmission error, mesh stiffness).
//! - ISO 6336-1:2019 (single stiffness c' and mesh stiffness c_gamma); ISO/TR 10064-2
//!   (backlash).
//! - F. L. Litvin, A. Fuentes, "Gear Geometry and Applied Theory", 2nd ed., 2004.

use super::impact::{crossing, Gap, ImpactLaw};
use super::{
    central_difference, physical, spring, Coefficients, Context, DerivativeMethod, ElementKernel,
    ElementParameters, Local, LocalMatrix, LocalVector, Mat12, NodeState, StepLimit, Vec12,
};
use crate::joints::gear::{mesh_angle, Scalar};
use crate::joints::primitives::dot2;
use crate::model::parameters::GearParam;
use crate::model::{GearPair, Harmonic, Model, NodeId};
use flexmb_lie::{Frame, Vec3};
use std::f64::consts::PI;

/// `x - 2 pi round(x / 2 pi)`, in `[-pi, pi]`.
fn wrap(x: f64) -> f64 {
    x - 2.0 * PI * (x / (2.0 * PI)).round()
}

/// `(sum_n a_n cos(n s + phi_n), its first and second derivatives in s)`.
fn series(harmonics: &[Harmonic], s: f64) -> (f64, f64, f64) {
    let mut out = (0.0, 0.0, 0.0);
    for (i, h) in harmonics.iter().enumerate() {
        let n = (i + 1) as f64;
        let (sn, cs) = (n * s + h.phase).sin_cos();
        out.0 += h.amplitude * cs;
        out.1 -= h.amplitude * n * sn;
        out.2 -= h.amplitude * n * n * cs;
    }
    out
}

/// `(f(s), df/ds)` of a periodic table of `(s / 2 pi, f)` (linear interpolation; `(1, 0)`
/// for an empty table).
fn periodic_table(table: &[(f64, f64)], s: f64) -> (f64, f64) {
    let (Some(first), Some(last)) = (table.first(), table.last()) else {
        return (1.0, 0.0);
    };
    let u = (s / (2.0 * PI)).rem_euclid(1.0);
    // the segment [u0, u1] holding u, the last one wrapping round to the first point
    let k = table.partition_point(|p| p.0 <= u);
    let ((u0, f0), (u1, f1)) = match k {
        0 => ((last.0 - 1.0, last.1), *first),
        k if k == table.len() => (*last, (first.0 + 1.0, first.1)),
        k => (table[k - 1], table[k]),
    };
    let slope = (f1 - f0) / (u1 - u0);
    (f0 + slope * (u - u0), slope / (2.0 * PI))
}

/// The mesh state of a gear pair at given node kinematics.
struct Mesh {
    /// Dynamic transmission error `delta_t` \[m\].
    dte: f64,
    /// Mesh position `s`.
    s: Scalar,
    /// Mesh stiffness `k(s)` and `dk/ds`.
    k: (f64, f64),
    /// Penetrations `y_f` of the drive (`+1`) and coast (`-1`) flanks.
    y: [Scalar; 2],
    /// Physical velocities of the two slots.
    v_p: Vec12,
}

/// A flank in contact: its sign, penetration, its rate and the force.
struct Contact<'m> {
    sign: f64,
    y: &'m Scalar,
    ydot: f64,
    force: f64,
}

impl GearPair {
    fn active(&self) -> [bool; 2] {
        [self.node_a.is_some(), self.node_b.is_some()]
    }

    /// `sigma sin(alpha_wt) cos(beta_b)`: how much the centre distance closes each flank.
    fn radial_factor(&self) -> f64 {
        let g = &self.geometry;
        let [ra, rb] = g.base_radii();
        let cos_w = ((ra + g.sigma() * rb).abs() / self.center_distance).min(1.0);
        g.sigma() * (1.0 - cos_w * cos_w).sqrt() * g.base_helix_angle().cos()
    }

    fn mesh(&self, ctx: &Context, nodes: &[NodeState]) -> Mesh {
        let g = &self.geometry;
        let (fa, fb) = (&nodes[0].q, &nodes[1].q);
        let (mut psi, phi_a) = mesh_angle(
            [fa, fb],
            [&self.frame_a, &self.frame_b],
            (g.teeth_a, g.teeth_b, g.internal),
        );
        psi.v = wrap(psi.v);
        let [ra, _] = g.base_radii();
        let delta_t = psi.scale(-ra / g.teeth_a as f64);
        let beta_b = g.base_helix_angle();
        let axis = self.frame_a.r.column(2).into_owned();
        let mut u = Scalar::from(dot2(fa, &axis, &self.frame_a.x, fb, &self.frame_b.x));
        u.v -= self.axial_offset;
        let delta_n = delta_t.lin(beta_b.cos(), &u, beta_b.sin());
        let mut s = phi_a.scale(-(g.teeth_a as f64));
        s.v += self.mesh_phase;
        let (e, de, dde) = series(&self.transmission_error, s.v);
        let x = delta_n.lin(1.0, &s.map(e, de, dde), -1.0);
        let (l, gl, hl) = spring::segment(&nodes[0], &self.frame_a.x, &nodes[1], &self.frame_b.x);
        let radial = Scalar {
            v: l - self.center_distance,
            g: gl,
            h: hl,
        }
        .scale(self.radial_factor());
        let flank = |f: f64| {
            let mut y = x.lin(f, &radial, -1.0);
            y.v -= 0.5 * self.backlash;
            y
        };
        let (eps, deps, _) = series(&self.stiffness_variation, s.v);
        let (f, df) = periodic_table(&self.stiffness_table, s.v);
        let mut v_p = Vec12::zeros();
        for (a, node) in nodes.iter().enumerate().take(2) {
            let (xd, om) = physical::velocity(ctx.group, node);
            v_p.fixed_rows_mut::<3>(6 * a).copy_from(&xd);
            v_p.fixed_rows_mut::<3>(6 * a + 3).copy_from(&om);
        }
        Mesh {
            dte: delta_t.v,
            s,
            k: (
                self.mesh_stiffness * (f + eps),
                self.mesh_stiffness * (df + deps),
            ),
            y: [flank(1.0), flank(-1.0)],
            v_p,
        }
    }

    /// The flanks in contact (penetration positive and a compressive force).
    fn contacts<'m>(&self, mesh: &'m Mesh) -> impl Iterator<Item = Contact<'m>> + 'm {
        let (k, c) = (mesh.k.0, self.damping);
        mesh.y.iter().zip([1.0, -1.0]).filter_map(move |(y, sign)| {
            let ydot = y.g.dot(&mesh.v_p);
            let force = k * y.v + c * ydot;
            (y.v > 0.0 && force > 0.0).then_some(Contact {
                sign,
                y,
                ydot,
                force,
            })
        })
    }

    /// Normal mesh force \[N\]: positive on the drive flank, negative on the coast flank.
    pub fn mesh_force(&self, ctx: &Context, local: &Local) -> f64 {
        let mesh = self.mesh(ctx, local.nodes);
        self.contacts(&mesh).map(|c| c.sign * c.force).sum()
    }

    /// Dynamic transmission error `delta_t = r_ba alpha_a + sigma r_bb alpha_b` \[m\].
    pub fn transmission_error(&self, ctx: &Context, local: &Local) -> f64 {
        self.mesh(ctx, local.nodes).dte
    }

    /// Whether the step control locates the flanks' impacts: with backlash, unless
    /// `locate_impacts` is off.
    pub fn has_events(&self) -> bool {
        self.backlash > 0.0 && self.locate_impacts
    }

    /// Whether a flank that closes or opens is an event ([`ElementKernel::event`]): with
    /// backlash (located or not), or with damping, which acts on a flank in contact only
    /// (`c y_f'` starts at once when a flank closes). Without either the two flanks carry the
    /// same spring across a flank change, and the force is continuous.
    pub fn can_switch(&self) -> bool {
        self.backlash > 0.0 || self.damping > 0.0
    }

    /// The effective mass `m*` of the mesh along the normal line of action (module
    /// documentation), from the inertias of the bodies on the wheels' nodes about the wheel
    /// axes (infinite when neither node carries a body).
    pub fn mesh_mass(&self, model: &Model) -> f64 {
        let inertia = |node: Option<NodeId>, wheel: &Frame| -> f64 {
            let Some(n) = node else { return 0.0 };
            let k: Vec3 = wheel.r.column(2).into_owned();
            model
                .bodies
                .iter()
                .filter(|b| b.node == n)
                .map(|b| {
                    k.dot(&(b.inertia * k)) + b.mass * k.cross(&(b.com - wheel.x)).norm_squared()
                })
                .sum()
        };
        let [ra, rb] = self.geometry.base_radii();
        let cos_b = self.geometry.base_helix_angle().cos();
        let inverse: f64 = [
            (inertia(self.node_a, &self.frame_a), ra),
            (inertia(self.node_b, &self.frame_b), rb),
        ]
        .iter()
        .filter(|(j, _)| *j > 0.0)
        .map(|(j, r)| (r * cos_b).powi(2) / j)
        .sum();
        if inverse > 0.0 {
            1.0 / inverse
        } else {
            f64::INFINITY
        }
    }
}

impl ElementKernel for GearPair {
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
        r: &mut LocalVector,
        s: Option<(&Coefficients, &mut LocalMatrix)>,
    ) {
        let nodes = local.nodes;
        let mesh = self.mesh(ctx, nodes);
        let (k, dk) = mesh.k;
        let c = self.damping;
        let mut r_p = Vec12::zeros();
        let mut k_p = Mat12::zeros();
        let mut c_p = Mat12::zeros();
        for contact in self.contacts(&mesh) {
            let y = contact.y;
            r_p += y.g * contact.force;
            if s.is_some() {
                let df = y.g * k + mesh.s.g * (y.v * dk) + y.h.transpose() * mesh.v_p * c;
                k_p += y.g * df.transpose() + y.h * contact.force;
                c_p += y.g * y.g.transpose() * c;
            }
        }
        physical::to_group(
            ctx.group,
            nodes,
            &self.active(),
            &r_p,
            Some(&k_p),
            Some(&c_p),
            r,
            s,
        );
    }

    fn step_limit(&self, ctx: &Context, start: &Local, end: &Local, h: f64) -> Option<StepLimit> {
        // Each flank's penetration y_f is a gap g = -y_f for the step control shared with
        // the contacts, with the elastic law k(s) y_f (n = 1) and the mesh's effective mass.
        let (m0, m1) = (self.mesh(ctx, start.nodes), self.mesh(ctx, end.nodes));
        let law = ImpactLaw {
            stiffness: m0.k.0.max(m1.k.0),
            exponent: 1.0,
            effective_mass: self.mesh_mass(ctx.model),
        };
        let gap = |m: &Mesh, f: usize| Gap {
            gap: -m.y[f].v,
            rate: -m.y[f].g.dot(&m.v_p),
        };
        (0..2)
            .map(|f| law.step_limit(gap(&m0, f), gap(&m1, f), None, h))
            .fold(None, StepLimit::stricter)
    }

    fn event(&self, ctx: &Context, start: &Local, end: &Local) -> Option<String> {
        // Each flank's gap is -y_f.
        let (m0, m1) = (self.mesh(ctx, start.nodes), self.mesh(ctx, end.nodes));
        (0..2).find_map(|f| {
            let what = crossing(-m0.y[f].v, -m1.y[f].v)?;
            let flank = ["drive", "coast"][f];
            Some(format!(
                "gear pair '{}': its {flank} flank {what}",
                self.name
            ))
        })
    }

    fn potential_energy(&self, ctx: &Context, local: &Local) -> f64 {
        let mesh = self.mesh(ctx, local.nodes);
        mesh.y
            .iter()
            .filter(|y| y.v > 0.0)
            .map(|y| 0.5 * mesh.k.0 * y.v * y.v)
            .sum()
    }
}

impl ElementParameters for GearPair {
    type Param = GearParam;

    fn parameter_derivative(
        &self,
        ctx: &Context,
        p: GearParam,
        local: &Local,
        dr: &mut LocalVector,
    ) -> DerivativeMethod {
        let nodes = local.nodes;
        let mesh = self.mesh(ctx, nodes);
        let harmonic = |n: usize| {
            let h = self.stiffness_variation[n];
            ((n + 1) as f64 * mesh.s.v + h.phase).cos()
        };
        let dforce = |c: &Contact| match p {
            GearParam::MeshStiffness => mesh.k.0 / self.mesh_stiffness * c.y.v,
            GearParam::Damping => c.ydot,
            GearParam::Backlash => -0.5 * mesh.k.0,
            GearParam::StiffnessVariation(n) => self.mesh_stiffness * harmonic(n) * c.y.v,
            GearParam::TransmissionError(_) => 0.0,
        };
        if let GearParam::TransmissionError(_) = p {
            let at = p.get(self);
            // a typical amplitude: a thousandth of the base pitch
            let scale = self.geometry.base_radii()[0] / self.geometry.teeth_a as f64 * 1e-3;
            let set = |g: &mut GearPair, v: f64| p.set(g, v);
            return central_difference(self, ctx, local, (at, scale), set, dr);
        }
        let mut r_p = Vec12::zeros();
        for c in self.contacts(&mesh) {
            r_p += c.y.g * dforce(&c);
        }
        physical::to_group(ctx.group, nodes, &self.active(), &r_p, None, None, dr, None);
        DerivativeMethod::Analytic
    }
}
