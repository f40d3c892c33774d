//! Unilateral contact between two shapes fixed on nodes (or the ground): what a model file's
//! `[[contact]]` declares. The mechanics are in [`crate::elements::contact`].

use super::NodeId;
use flexmb_lie::Vec3;

/// A contact pair: shape A on node A, shape B on node B (either node may be the ground, whose
/// shape is then given in the inertial frame), a normal force law and, optionally, friction.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Contact {
    pub name: String,
    pub node_a: Option<NodeId>,
    pub node_b: Option<NodeId>,
    /// Shape on A, in the frame of node A: a plane, a sphere or a cylinder.
    pub shape_a: ContactShape,
    /// Shape on B, in the frame of node B: a sphere (a point if its radius is 0), or a
    /// cylinder whose axis is parallel to a cylinder A (planar circles).
    pub shape_b: ContactShape,
    pub law: ContactLaw,
    #[serde(default)]
    pub friction: Option<Friction>,
}

impl Contact {
    /// The element's states: the impact velocity, and the bristles' deflection (3) if any.
    pub fn n_states(&self) -> usize {
        1 + 3 * self.friction.is_some_and(|f| f.bristles.is_some()) as usize
    }
}

/// A contact surface in its node's frame.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum ContactShape {
    /// The plane through `point` with the unit outward `normal` (a half-space behind it).
    Plane { point: Vec3, normal: Vec3 },
    /// A sphere (radius 0: a point). `inside`: the other shape is inside this one (a ball in
    /// a spherical socket), allowed on shape A.
    Sphere {
        center: Vec3,
        radius: f64,
        inside: bool,
    },
    /// An infinite circular cylinder of unit `axis` through `point` (a circle in the plane
    /// normal to the axis, for planar cams). `inside`: the other shape is inside this one (a
    /// pin in a hole), allowed on shape A.
    Cylinder {
        point: Vec3,
        axis: Vec3,
        radius: f64,
        inside: bool,
    },
}

impl ContactShape {
    /// The shape's radius (0 for a plane).
    pub fn radius(&self) -> f64 {
        match *self {
            ContactShape::Plane { .. } => 0.0,
            ContactShape::Sphere { radius, .. } | ContactShape::Cylinder { radius, .. } => radius,
        }
    }

    /// Whether the other shape is inside this one.
    pub fn inside(&self) -> bool {
        match *self {
            ContactShape::Plane { .. } => false,
            ContactShape::Sphere { inside, .. } | ContactShape::Cylinder { inside, .. } => inside,
        }
    }

    /// The shape's name in the model file.
    pub fn keyword(&self) -> &'static str {
        match self {
            ContactShape::Plane { .. } => "plane",
            ContactShape::Sphere { .. } => "sphere",
            ContactShape::Cylinder { .. } => "cylinder",
        }
    }
}

/// How the hysteresis damping of the normal force depends on the restitution coefficient
/// `e` (module documentation of [`crate::elements::contact`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Dissipation {
    /// Lankarani & Nikravesh (1990, 1994): `chi = 3 (1 - e^2) / 4`.
    LankaraniNikravesh,
    /// Hunt & Crossley (1975): `chi = 3 (1 - e) / 2`.
    HuntCrossley,
    /// Flores, Machado, Silva & Martins (2011): `chi = 8 (1 - e) / (5 e)`.
    Flores,
    /// `chi(e)` such that the law's own restitution is `e`: the root in `(0, 1/e)` of
    /// `chi (1 + e) = ln((1 + chi) / (1 - chi e))` ([`exact_restitution_factor`]).
    ExactRestitution,
}

impl Dissipation {
    /// The factor `chi(e)` of `F = K delta^n (1 + chi deltadot / v_impact)` (generic: the
    /// contact differentiates it by forward automatic differentiation).
    pub fn factor<T: nalgebra::RealField + Copy>(self, e: T) -> T {
        let k = |v: f64| -> T { nalgebra::convert(v) };
        match self {
            Dissipation::LankaraniNikravesh => k(0.75) * (T::one() - e * e),
            Dissipation::HuntCrossley => k(1.5) * (T::one() - e),
            Dissipation::Flores => k(1.6) * (T::one() - e) / e,
            Dissipation::ExactRestitution => {
                // the root at e's value, and its exact first derivative for forward AD
                let e0: f64 = e.to_subset_unchecked();
                let (chi, dchi_de) = exact_restitution_factor(e0);
                k(chi) + (e - k(e0)) * k(dchi_de)
            }
        }
    }

    /// The law's name in the model file.
    pub fn keyword(self) -> &'static str {
        match self {
            Dissipation::LankaraniNikravesh => "lankarani_nikravesh",
            Dissipation::HuntCrossley => "hunt_crossley",
            Dissipation::Flores => "flores",
            Dissipation::ExactRestitution => "exact_restitution",
        }
    }
}

/// The hysteresis factor `chi` for which the law `F = K delta^n (1 + chi deltadot / v) >= 0`
/// restitutes exactly `e` in an isolated impact at speed `v`, and `dchi/de`.
///
/// With `w = delta^(n+1) / (n + 1)` the impact `m* deltaddot = -F` reads `m* deltadot
/// d(deltadot)/dw = -K (1 + chi deltadot / v)`, independent of `n`; integrated from
/// `deltadot = v` at `w = 0` (onset) back to `w = 0` (release, `deltadot = -e v`), and `1 + chi
/// deltadot / v > 0` throughout (so the force is never clipped), it gives
///
/// ```text
/// G(chi, e) = chi (1 + e) - ln(1 + chi) + ln(1 - chi e) = 0,    0 < chi < 1 / e,
/// ```
///
/// (`chi = 0` is a root for every `e` and is not the one: `G ~ chi^2 (1 - e^2) / 2` near
/// it). The root is bracketed in `(0, 1/e)` (`G > 0` below it, `G -> -inf` at `1/e`) and found
/// by safeguarded Newton iterations; `dchi/de = -G_e / G_chi`, `G_e = -chi^2 e / (1 - chi e)`,
/// `G_chi = 1 + e - 1 / (1 + chi) - e / (1 - chi e)`. At `e = 1`, `chi = 0` and `dchi/de =
/// -3/2` (the limit: Hunt & Crossley's `3 (1 - e) / 2` to first order). `e` in `(0, 1]`.
pub fn exact_restitution_factor(e: f64) -> (f64, f64) {
    if e >= 1.0 {
        return (0.0, -1.5);
    }
    // G = phi(chi) - phi(-chi e), phi(x) = x - ln(1 + x), by its series for small |x| (the
    // two terms nearly cancel when e is near 1)
    let phi = |x: f64| {
        if x.abs() < 0.05 {
            (2..20)
                .rev()
                .fold(0.0, |acc, k| x * (acc + (-1.0f64).powi(k) / k as f64))
                * x
        } else {
            x - x.ln_1p()
        }
    };
    let g = |x: f64| phi(x) - phi(-x * e);
    let g_chi = |x: f64| x / (1.0 + x) - e * e * x / (1.0 - x * e);
    let (mut lo, mut hi) = (0.0f64, 1.0 / e);
    // start from Flores et al.'s factor, inside the bracket
    let mut x = (1.6 * (1.0 - e) / e).min(0.5 / e);
    for _ in 0..200 {
        let value = g(x);
        if value > 0.0 {
            lo = x;
        } else {
            hi = x;
        }
        let newton = x - value / g_chi(x);
        let next = if newton > lo && newton < hi {
            newton
        } else {
            0.5 * (lo + hi)
        };
        let done = (next - x).abs() <= 1e-15 * x || hi - lo <= 1e-15 * hi;
        x = next;
        if done {
            break;
        }
    }
    let g_e = -x * x * e / (1.0 - x * e);
    (x, -g_e / g_chi(x))
}

/// The normal force law `F = K delta^n (1 + chi(e) deltadot / v_impact)`, `F >= 0`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ContactLaw {
    pub dissipation: Dissipation,
    /// Contact stiffness K [N/m^n], > 0 (Hertz: `4/3 E* sqrt(R*)`).
    pub stiffness: f64,
    /// Exponent n, >= 1 (Hertz: 3/2).
    pub exponent: f64,
    /// Coefficient of restitution e, in (0, 1].
    pub restitution: f64,
    /// Smallest impact velocity the damping is scaled by [m/s], > 0: a contact that closes
    /// slower (a body set down, resting contact) is damped as if it hit at this speed.
    pub min_impact_velocity: f64,
}

/// Regularized Coulomb friction with a viscous term: the tangential force opposes the slip
/// velocity `v_t` at the contact point with magnitude `mu F_n min(|v_t| / v_s, 1) + c_v |v_t|`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Friction {
    /// Coulomb coefficient mu, >= 0.
    pub coefficient: f64,
    /// Stiction velocity v_s [m/s], > 0: below it the force grows linearly with the slip.
    pub stiction_velocity: f64,
    /// Viscous coefficient c_v [N s/m], >= 0.
    pub viscous: f64,
    /// Bristles (LuGre): stick-slip with an internal state instead of the regularization.
    #[serde(default)]
    pub bristles: Option<Bristles>,
}

/// The LuGre friction model (Canudas de Wit, Olsson, Åström & Lischinsky 1995, IEEE Trans.
/// Autom. Control 40, Eqs. (1)-(4)), per unit normal force: the mean bristle deflection `z`
/// (three element states, in the tangent plane), `zdot = v_t - sigma_0 |v_t| z / g(|v_t|)`,
/// `g(v) = mu + (mu_s - mu) exp(-(v / v_s)^2)`, friction `-F_n (sigma_0 z + sigma_1 zdot) -
/// c_v v_t` (`mu`, `v_s`, `c_v` those of [`Friction`]).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Bristles {
    /// Bristle stiffness sigma_0 [1/m] (per unit normal force), > 0.
    pub stiffness: f64,
    /// Bristle damping sigma_1 [s/m] (per unit normal force), >= 0.
    pub damping: f64,
    /// Static coefficient mu_s >= mu (Stribeck: the friction at rest before it breaks away).
    pub static_coefficient: f64,
}
