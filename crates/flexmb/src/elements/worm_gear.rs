//! Worm gear pair with Coulomb friction in the mesh and at the worm's thrust washer
//! ([`crate::model::WormGear`]): a worm (node A, `z_1` threads, pitch radius `r_1`) and a worm
//! wheel (node B, `z_2` teeth, pitch radius `r_2 = a_0 - r_1`) on perpendicular axes, the
//! friction-carrying mesh of a Torsen-type limited-slip differential.
//!
//! ```text
//!          wheel axis e_2 (= y)             worm axis e_1 (= z)
//!               |                               ^
//!        wheel  o--- x_B ---  P  --- x ---o worm       P = c_1 + r_1 x: the pitch point
//!          c_2            (r_2)     (r_1)    c_1        on the common perpendicular x
//! ```
//!
//! **Mesh kinematics without rotation parameters** (as the gear pair, [`super::gear`]). The
//! common perpendicular of the two axes, `x = (e_2 x e_1) / |e_2 x e_1|`, depends on the two
//! rotations only. Each member's angle about its own axis is measured from it,
//!
//! ```text
//! phi_1 = atan2(j_A . x, i_A . x),     phi_2 = atan2(-j_B . x, -i_B . x),
//! ```
//!
//! (`i, j` the frame axes normal to the member's axis, [`crate::model::WormGear`]), both 0 at
//! t = 0, so a rigid rotation of the whole pair (a carrier turning about the worm axis)
//! leaves them unchanged. A worm rotation `alpha_1` advances the thread axially by
//! `r_1 tan(lambda) alpha_1`, `tan(lambda) = z_1 r_2 / (z_2 r_1)` (lead angle `lambda`, its
//! sign `h = +1` right, `-1` left hand: `lambda_s = h lambda`), and the wheel's pitch circle,
//! which moves along `e_1` at P, follows it when `z_1 alpha_1 + h z_2 alpha_2 = 0`. Since
//! `phi = -alpha`, the mesh angle
//!
//! ```text
//! psi = z_1 phi_1 + h z_2 phi_2
//! ```
//!
//! is zero for an ideal mesh and, with whole numbers of threads and teeth, defined modulo
//! `2 pi` by the node rotations alone (`wrap` to `(-pi, pi]`; no angle is tracked).
//!
//! **Deflection along the thread normal.** In the pitch plane at P (spanned by `y = e_1 x x`
//! and `z = e_1`) the thread runs along `t = cos(lambda) y + sin(lambda_s) z` and its
//! in-plane normal is `n_t = -sin(lambda_s) y + cos(lambda) z`. The relative displacement of
//! the wheel's tooth against the thread along `n_t`, from the rotations and from the relative
//! position `d = c_2 - c_1` of the two frame origins (`d = a_0 x` at t = 0), is
//!
//! ```text
//! delta = -(r_1 sin(lambda_s) / z_1) wrap(psi) + n_t . d
//! ```
//!
//! (a wheel rotation alone gives `r_2 cos(lambda) alpha_2`, a worm rotation
//! `r_1 sin(lambda_s) alpha_1`). The flanks' normals are inclined by the normal pressure angle
//! `alpha_n` out of the pitch plane, `n_f = f cos(alpha_n) n_t - sin(alpha_n) x`
//! (`f = +1`, `-1` the two flanks), and their penetrations are
//!
//! ```text
//! y_f = f cos(alpha_n) delta - sin(alpha_n) (x . d - a_0),
//! ```
//!
//! so that separating the axes opens both flanks. A flank in contact (`y_f > 0`) carries the
//! normal force `F_f = max(0, k y_f + c ydot_f)`, `ydot_f = n_f . v_rel`, with
//! `v_rel = v_B(P) - v_A(P)` the relative velocity of the two material points at P (the rate
//! of `y_f` up to terms of the order of the deflection times the rotation of the axes);
//! the damper acts in contact only and never pulls. There is no backlash.
//!
//! **Friction.** The flanks slide along the thread at `v_s = t . v_rel` (at the ideal mesh
//! `|v_s| = r_1 omega_1 / cos(lambda)`, relative to the axes). On the wheel, at P,
//!
//! ```text
//! F_B = sum_f -F_f (n_f + mu g(v_s) t),      g(v) = v / max(|v|, v_e)   (regularized Coulomb,
//! ```
//!
//! as the contact's friction, [`super::contact`], `v_e` the stiction velocity), and `-F_B`
//! on the worm at P. **Thrust washer**: the axial thrust of the mesh on the worm,
//! `F_ax = -F_B . e_1`, presses it against its washer, of mean friction radius `r_w`, which
//! brakes the worm's spin relative to the wheel's node about `e_1` (in a differential the
//! wheel turns on the carrier about an axis normal to `e_1`, so that relative spin is the
//! worm's relative to the carrier), `omega_r = (omega_A - omega_B) . e_1`, with the torque
//! `M_w = -mu r_w |F_ax| g(r_w omega_r) e_1` on the worm and `-M_w` on the wheel's node
//! (carried by its bearing to the carrier). The washer's friction coefficient is the
//! flanks'.
//!
//! **Efficiency by direction** (the standard result for a worm gear with Coulomb friction on
//! the flanks, Niemann & Winter, Maschinenelemente III, Sect. 24 on worm gears; Dudley's Gear
//! Handbook, 2nd ed., Ch. 3): with the friction angle `phi' = atan(mu / cos(alpha_n))`,
//! the torques of one mesh without washer satisfy, per unit normal force and in the
//! direction of the slip, worm torque `r_1 (cos(alpha_n) sin(lambda) + mu cos(lambda))` and
//! wheel torque `r_2 (cos(alpha_n) cos(lambda) - mu sin(lambda))`, hence
//!
//! ```text
//! worm driving:   eta  = T_2 omega_2 / (T_1 omega_1) = tan(lambda) / tan(lambda + phi'),
//! wheel driving:  eta' = T_1 omega_1 / (T_2 omega_2) = tan(lambda - phi') / tan(lambda)
//! ```
//!
//! (self-locking when `phi' >= lambda`): [`efficiencies`].
//!
//! **Torque bias ratio of a Torsen (type I) differential** ([`torque_bias_ratio`]). The case
//! (carrier) carries element gears (worm wheels) meshing with the worms of the two side
//! shafts; the element gears of the two sides are coupled by ideal 1:1 spur gears, so the two
//! worms turn at `omega_c + Delta` and `omega_c - Delta` relative to the case `omega_c`.
//! Quasi-statically, in the case's frame (where the input torque does no work) with the
//! element gears' torque `T_e` (the same on both sides through the spur coupling),
//! `i = z_2 / z_1`, the worm of the slow side drives its element gear (power flows from the
//! slow shaft's relative motion to the fast one's) and the fast side's element gear drives
//! its worm:
//!
//! ```text
//! slow:  T_e omega_e = eta (M_s Delta)     ->  M_s = T_e / (eta i),
//! fast:  M_f Delta = eta' (T_e omega_e)    ->  M_f = eta' T_e / i,
//! ```
//!
//! `M` the mesh torques on the worms. The washers' thrust is the wheel's tangential force,
//! `|F_ax| = T_e / r_2`, and their torque `mu r_w T_e / r_2` opposes each worm's relative
//! spin: it adds to the slow shaft's torque and takes from the fast one's. The output torques
//! are `T_slow = M_s + mu r_w T_e / r_2`, `T_fast = M_f - mu r_w T_e / r_2`, and
//!
//! ```text
//! TBR = T_slow / T_fast = (1 / eta + w) / (eta' - w),      w = mu r_w / (r_1 tan(lambda)),
//! ```
//!
//! `= tan(lambda + phi') / tan(lambda - phi')` without washers; 1 at `mu = 0` (the ideal
//! open differential), infinite (locked) once `eta' <= w`. Inertia, the element gears'
//! journal friction and the spur gears' losses are left out. The derivation is this module's
//! own (a power balance in the case's frame with the efficiencies above); the Torsen's
//! principle and its bias ratio of about 2.5 to 5 are described by Chocholek (1988), and
//! the talk `talk-direct-to-inverse-fmbd` ("Torsen limited slip differential") reports a TDR
//! of 3.90 computed and 4.02 measured for a detailed model.
//!
//! **Residual and iteration matrix.** With `F_B` at P on the wheel and `-F_B` on the worm,
//! the washer moment `M_w`, in physical coordinates ([`super::physical`])
//! `r_X = -[F_X; (R_X^T (P - x_X)) x (R_X^T F_X) + R_X^T M_X]`. Its exact derivatives
//! `K_p = dr/dw`, `C_p = dr/dv` are computed by forward automatic differentiation (`num-dual`)
//! of the same function of the two poses ([`super::pose`]), exact to round-off (one-sided at
//! the kinks: flank onset, `F_f = 0`, `|v_s| = v_e`, `F_ax = 0`); the wrap's whole number of
//! turns is taken from the undifferentiated evaluation. The parameter derivatives
//! ([`WormGearParam`]) are forward derivatives of the same function in the parameter.
//!
//! The section numbers of the books cited could not be checked here (no copy at hand); the
//! equations above are written out in full so that they stand on their own.
//!
//! # References
//! - G. Niemann, H. Winter, "Maschinenelemente, Band III: Schraubrad-, Kegelrad-, Schnecken-,
//!   Ketten-, Riemen-, Reibradgetriebe, Kupplungen, Bremsen, Freiläufe", Springer, 1983
//!   (worm gear efficiency `tan(gamma) / tan(gamma + rho')`, `tan(rho') = mu / cos(alpha_n)`).
//! - D. P. Townsend (ed.), "Dudley's Gear Handbook", 2nd ed., McGraw-Hill, 1991 (worm gear
//!   efficiency driving and back-driving, self-locking).
//! - S. E. Chocholek, "The development of a differential for the improvement of traction
//!   control", IMechE Conference Publication C368/88, 1988 (the Torsen differential).
//! - A. Cardona, "Flexible three dimensional gear modelling", Eur. J. Mech. A/Solids, 1997,
//!   as presented in the talk `talk-direct-to-inverse-fmbd`.

use super::pose::{c, lift, perturbed, pose, Dv, Pose, D1};
use super::{
    physical, Coefficients, Context, DerivativeMethod, ElementKernel, ElementParameters, Local,
    LocalMatrix, LocalVector, Vec12,
};
use crate::model::parameters::WormGearParam;
use crate::model::{NodeId, WormGear};
use nalgebra::{RealField, SMatrix, SVector, Vector3};
use std::f64::consts::PI;

/// The differentiated parameters ([`WormGearParam`], in its order).
#[derive(Clone, Copy, Debug)]
struct Law<T> {
    stiffness: T,
    damping: T,
    friction: T,
    washer_radius: T,
}

/// What one evaluation finds, for the tests and the analyses of a differential.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MeshState {
    /// Deflection `delta` along the thread's in-plane normal \[m\].
    pub deflection: f64,
    /// Normal force `F_+ - F_-` \[N\] (positive on the flank `f = +1`).
    pub normal_force: f64,
    /// Sliding velocity `v_s` along the thread \[m/s\].
    pub slip_velocity: f64,
    /// Washer torque on the worm about its axis \[N m\].
    pub washer_torque: f64,
    /// Elastic energy `k y_f^2 / 2` of the flanks in contact \[J\].
    pub elastic_energy: f64,
}

/// Worm-driving and wheel-driving efficiencies `(eta, eta')` of a worm gear of lead angle
/// `lambda` and normal pressure angle `alpha_n` with the friction coefficient `mu` (module
/// documentation); `eta'` is negative when the pair is self-locking.
pub fn efficiencies(lambda: f64, alpha_n: f64, mu: f64) -> (f64, f64) {
    let phi = (mu / alpha_n.cos()).atan();
    (
        lambda.tan() / (lambda + phi).tan(),
        (lambda - phi).tan() / lambda.tan(),
    )
}

/// The torque bias ratio `T_slow / T_fast` of a Torsen type I differential whose two sides
/// are the worm gear `g` (module documentation), at its friction coefficient; infinite when
/// it locks.
pub fn torque_bias_ratio(g: &WormGear) -> f64 {
    let lambda = g.lead_angle();
    let (eta, eta_back) = efficiencies(lambda, g.pressure_angle, g.friction);
    let w = g.friction * g.washer_radius / (g.worm_radius * lambda.tan());
    if eta_back <= w {
        f64::INFINITY
    } else {
        (1.0 / eta + w) / (eta_back - w)
    }
}

impl WormGear {
    fn law<T: RealField + Copy>(&self) -> Law<T> {
        Law {
            stiffness: c(self.mesh_stiffness),
            damping: c(self.damping),
            friction: c(self.friction),
            washer_radius: c(self.washer_radius),
        }
    }

    fn active(&self) -> [bool; 2] {
        [self.node_a.is_some(), self.node_b.is_some()]
    }

    /// The common perpendicular `x` (unnormalized) and the mesh angle `psi`, not wrapped.
    fn mesh_angle<T: RealField + Copy>(&self, a: &Pose<T>, b: &Pose<T>) -> (Vector3<T>, T) {
        let col =
            |p: &Pose<T>, f: &flexmb_lie::Frame, i: usize| p.direction(&f.r.column(i).into_owned());
        let (ia, ja, e1) = (
            col(a, &self.frame_a, 0),
            col(a, &self.frame_a, 1),
            col(a, &self.frame_a, 2),
        );
        let (ib, jb, e2) = (
            col(b, &self.frame_b, 0),
            col(b, &self.frame_b, 1),
            col(b, &self.frame_b, 2),
        );
        let x = e2.cross(&e1);
        let phi_1 = ja.dot(&x).atan2(ia.dot(&x));
        let phi_2 = (-jb.dot(&x)).atan2(-ib.dot(&x));
        let hand = if self.left_hand { -1.0 } else { 1.0 };
        let psi = phi_1 * c(self.starts as f64) + phi_2 * c(hand * self.teeth as f64);
        (x, psi)
    }

    /// The whole number of turns `round(psi / 2 pi)` that the wrap of `psi` removes.
    fn turns(&self, a: &Pose<f64>, b: &Pose<f64>) -> f64 {
        (self.mesh_angle(a, b).1 / (2.0 * PI)).round()
    }

    /// The physical residual (12: worm, wheel) at the poses `a`, `b` and what the evaluation
    /// found, with `turns` from [`WormGear::turns`] and the parameters `law`.
    fn residual<T: RealField + Copy>(
        &self,
        a: &Pose<T>,
        b: &Pose<T>,
        turns: f64,
        law: &Law<T>,
    ) -> ([T; 12], [T; 5]) {
        let zero = T::zero();
        let (x, psi) = self.mesh_angle(a, b);
        let x = x / x.norm();
        let e1 = a.direction(&self.frame_a.r.column(2).into_owned());
        let y = e1.cross(&x);
        let lambda = self.lead_angle();
        let hand = if self.left_hand { -1.0 } else { 1.0 };
        let (sl, cl) = ((hand * lambda).sin(), lambda.cos());
        let n_t = y * c::<T>(-sl) + e1 * c::<T>(cl);
        let t = y * c::<T>(cl) + e1 * c::<T>(sl);
        let (c1, c2) = (a.point(&self.frame_a.x), b.point(&self.frame_b.x));
        let d = c2 - c1;
        let wrapped = psi - c(2.0 * PI * turns);
        let delta = wrapped * c::<T>(-self.worm_radius * sl / self.starts as f64) + n_t.dot(&d);
        let radial = x.dot(&d) - c(self.center_distance);
        let p = c1 + x * c::<T>(self.worm_radius);
        let v_rel = b.velocity_at(&p) - a.velocity_at(&p);
        let v_s = t.dot(&v_rel);
        let v_e: T = c(self.stiction_velocity);
        let slip = v_s / v_s.abs().max(v_e);
        let (sa, ca) = self.pressure_angle.sin_cos();
        let mut f_b = Vector3::zeros();
        let (mut signed, mut energy) = (zero, zero);
        for f in [1.0, -1.0] {
            let n_f = n_t * c::<T>(f * ca) - x * c::<T>(sa);
            let y_f = delta * c::<T>(f * ca) - radial * c::<T>(sa);
            if y_f <= zero {
                continue;
            }
            let force = (law.stiffness * y_f + law.damping * n_f.dot(&v_rel)).max(zero);
            f_b -= (n_f + t * (law.friction * slip)) * force;
            signed += force * c::<T>(f);
            energy += law.stiffness * y_f * y_f * c(0.5);
        }
        // the washer: the worm's axial thrust against it, braking its relative spin
        let thrust = -f_b.dot(&e1);
        let spin = (a.angular_velocity() - b.angular_velocity()).dot(&e1);
        let rim = law.washer_radius * spin;
        let washer = -law.friction * law.washer_radius * thrust.abs() * (rim / rim.abs().max(v_e));
        let m_a = e1 * washer;
        let mut out = [zero; 12];
        let (fa, ma) = (
            a.generalized(&f_b, &p, 1.0),
            a.generalized_moment(&m_a, -1.0),
        );
        let (fb, mb) = (
            b.generalized(&f_b, &p, -1.0),
            b.generalized_moment(&m_a, 1.0),
        );
        for i in 0..6 {
            out[i] = fa[i] + ma[i];
            out[6 + i] = fb[i] + mb[i];
        }
        (out, [delta, signed, v_s, washer, energy])
    }

    /// What the mesh finds at the kinematics of `local`.
    pub fn state(&self, ctx: &Context, local: &Local) -> MeshState {
        let (a, b) = (
            pose(ctx.group, &local.nodes[0]),
            pose(ctx.group, &local.nodes[1]),
        );
        let turns = self.turns(&a, &b);
        let (_, f) = self.residual(&a, &b, turns, &self.law());
        MeshState {
            deflection: f[0],
            normal_force: f[1],
            slip_velocity: f[2],
            washer_torque: f[3],
            elastic_energy: f[4],
        }
    }
}

/// Variables of the automatic differentiation: the two slots' configuration variations (12),
/// then their velocities (12).
const N_VARIABLES: usize = 24;

impl ElementKernel for WormGear {
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
        let (group, nodes) = (ctx.group, local.nodes);
        let (a, b) = (pose(group, &nodes[0]), pose(group, &nodes[1]));
        let turns = self.turns(&a, &b);
        let Some(s) = s else {
            let rp = Vec12::from(self.residual(&a, &b, turns, &self.law()).0);
            physical::to_group(group, nodes, &self.active(), &rp, None, None, r, None);
            return;
        };
        let law = self.law();
        let (rp, jac): (Vec12, SMatrix<f64, 12, N_VARIABLES>) = num_dual::jacobian(
            |w: SVector<Dv<N_VARIABLES>, N_VARIABLES>| {
                let a = perturbed(group, &nodes[0], &w, 0);
                let b = perturbed(group, &nodes[1], &w, 1);
                SVector::from(self.residual(&a, &b, turns, &law).0)
            },
            &SVector::zeros(),
        );
        let k_p: SMatrix<f64, 12, 12> = jac.fixed_view::<12, 12>(0, 0).into_owned();
        let c_p: SMatrix<f64, 12, 12> = jac.fixed_view::<12, 12>(0, 12).into_owned();
        physical::to_group(
            group,
            nodes,
            &self.active(),
            &rp,
            Some(&k_p),
            Some(&c_p),
            r,
            Some(s),
        );
    }

    fn potential_energy(&self, ctx: &Context, local: &Local) -> f64 {
        self.state(ctx, local).elastic_energy
    }
}

impl ElementParameters for WormGear {
    type Param = WormGearParam;

    fn parameter_derivative(
        &self,
        ctx: &Context,
        p: WormGearParam,
        local: &Local,
        dr: &mut LocalVector,
    ) -> DerivativeMethod {
        let (group, nodes) = (ctx.group, local.nodes);
        let (a, b) = (pose(group, &nodes[0]), pose(group, &nodes[1]));
        let turns = self.turns(&a, &b);
        let mut law = self.law::<D1>();
        let parameter = match p {
            WormGearParam::MeshStiffness => &mut law.stiffness,
            WormGearParam::Damping => &mut law.damping,
            WormGearParam::Friction => &mut law.friction,
            WormGearParam::WasherRadius => &mut law.washer_radius,
        };
        parameter.eps = 1.0;
        let (out, _) = self.residual(&lift(&a), &lift(&b), turns, &law);
        let d = Vec12::from_fn(|i, _| out[i].eps);
        physical::to_group(group, nodes, &self.active(), &d, None, None, dr, None);
        DerivativeMethod::Analytic
    }
}
