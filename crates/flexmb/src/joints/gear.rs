//! The ideal gear constraint: one row holding the kinematic ratio of two wheels, at the
//! position level and on the Lie group, for when the mesh dynamics do not matter (the gear
//! pair element [`crate::elements::gear`] is its compliant counterpart, with the same
//! kinematics).
//!
//! With `phi_a`, `phi_b` the angles of the line of centres seen from wheels A and B
//! (dot-2 primitives composed through `atan2`, [`centerline_angles`]),
//! `z_a`, `z_b` the teeth and `sigma = +1` for an external pair, `-1` for an internal one
//! (wheel B a ring gear), rolling without slip of the pitch (or base) circles is
//! `psi = z_a phi_a + sigma z_b phi_b = 0`, which holds modulo `2 pi` because the teeth are
//! whole numbers. The row is
//!
//! ```text
//! Phi = sin(psi) / z_a,
//! B   = cos(psi) grad(psi) / z_a,
//! H   = (cos(psi) H_psi - sin(psi) grad(psi) grad(psi)^T) / z_a,
//! ```
//!
//! smooth everywhere (like the driven revolute row `sin(theta - theta_d)` of [`super`]), with
//! `Phi ~ (phi_a - phi_a0) + sigma (z_b / z_a) (phi_b - phi_b0)` near the solution branch of
//! the initial configuration: its multiplier is the torque on wheel A \[N m\] and the torque on
//! wheel B is `sigma z_b / z_a` times it. Both angles are measured from the line of centres,
//! so the row holds for moving axes (a planet on its carrier obeys Willis' formula
//! `z_a (omega_a - omega_c) = -sigma z_b (omega_b - omega_c)`), and without a carrier node: the
//! two wheel centres are the carrier.
//!
//! The row has no continuous parameter (the teeth are whole numbers; the wheel centres are
//! the nodes' geometry): no `joint.<j>.position.<k>` is registered for a gear joint.
//!
//! # References
//! - A. Cardona, "Flexible three dimensional gear modelling", Eur. J. Mech. A/Solids, 1997
//!   (gear pair kinematics on the line of centres).
//! - E. J. Haug, "Computer-Aided Kinematics and Dynamics of Mechanical Systems", 1989,
//!   Sect. 3.3 (the dot-2 primitive).

use super::primitives::{dot2, Primitive};
use crate::kernel::{Mat12, Vec12};
use crate::model::{Joint, JointKind};
use flexmb_lie::{Frame, Vec3};

/// The gear row of `joint` (a [`JointKind::Gear`]) between node frames `fa` and `fb`, in
/// physical coordinates.
pub fn row(joint: &Joint, fa: &Frame, fb: &Frame) -> Primitive {
    let JointKind::Gear {
        teeth_a,
        teeth_b,
        internal,
    } = joint.kind
    else {
        panic!("joint '{}' is not a gear joint", joint.name);
    };
    let (psi, _) = mesh_angle(
        [fa, fb],
        [&joint.frame_a, &joint.frame_b],
        (teeth_a, teeth_b, internal),
    );
    let z = teeth_a as f64;
    let (s, c) = psi.v.sin_cos();
    Primitive {
        phi: s / z,
        g: psi.g * (c / z),
        h: (psi.h * c - psi.g * psi.g.transpose() * s) / z,
    }
}

/// A scalar function of the two nodes' configurations with its gradient `g = df/dw_p` and
/// the derivative of that gradient `H = dg/dw_p` (physical coordinates of both nodes).
#[derive(Clone, Copy, Debug)]
pub struct Scalar {
    pub v: f64,
    pub g: Vec12,
    pub h: Mat12,
}

impl From<Primitive> for Scalar {
    fn from(p: Primitive) -> Self {
        Self {
            v: p.phi,
            g: p.g,
            h: p.h,
        }
    }
}

impl Scalar {
    /// The same function of the nodes in the order (b, a): its blocks swapped.
    pub(crate) fn swapped(&self) -> Self {
        let perm = |i: usize| (i + 6) % 12;
        let g = Vec12::from_fn(|i, _| self.g[perm(i)]);
        let h = Mat12::from_fn(|i, j| self.h[(perm(i), perm(j))]);
        Self { v: self.v, g, h }
    }

    /// `a self + b other`.
    pub(crate) fn lin(&self, a: f64, other: &Scalar, b: f64) -> Self {
        Self {
            v: a * self.v + b * other.v,
            g: self.g * a + other.g * b,
            h: self.h * a + other.h * b,
        }
    }

    /// `a self`.
    pub(crate) fn scale(&self, a: f64) -> Self {
        Self {
            v: a * self.v,
            g: self.g * a,
            h: self.h * a,
        }
    }

    /// `f(self)` from the value `f`, first `df` and second `ddf` derivatives of `f`.
    pub(crate) fn map(&self, f: f64, df: f64, ddf: f64) -> Self {
        Self {
            v: f,
            g: self.g * df,
            h: self.h * df + self.g * self.g.transpose() * ddf,
        }
    }
}

/// `atan2(w, u)` of two scalar functions, by the chain rule.
fn atan2(w: &Scalar, u: &Scalar) -> Scalar {
    let r2 = u.v * u.v + w.v * w.v;
    let r4 = r2 * r2;
    let (fu, fw) = (-w.v / r2, u.v / r2);
    let (fuu, fww, fuw) = (
        2.0 * u.v * w.v / r4,
        -2.0 * u.v * w.v / r4,
        (w.v * w.v - u.v * u.v) / r4,
    );
    let gu = &u.g;
    let gw = &w.g;
    Scalar {
        v: w.v.atan2(u.v),
        g: gu * fu + gw * fw,
        h: u.h * fu
            + w.h * fw
            + gu * (gu * fuu + gw * fuw).transpose()
            + gw * (gu * fuw + gw * fww).transpose(),
    }
}

/// The angles `phi_a`, `phi_b` of the line of centres seen from wheels A and B (module
/// documentation): `fa`, `fb` the node frames, `wa`, `wb` the wheel frames on them.
pub fn centerline_angles(fa: &Frame, wa: &Frame, fb: &Frame, wb: &Frame) -> [Scalar; 2] {
    let axis = |w: &Frame, i: usize| -> Vec3 { w.r.column(i).into_owned() };
    let u = Scalar::from(dot2(fa, &axis(wa, 0), &wa.x, fb, &wb.x));
    let w = Scalar::from(dot2(fa, &axis(wa, 1), &wa.x, fb, &wb.x));
    let phi_a = atan2(&w, &u);
    let u = Scalar::from(dot2(fb, &axis(wb, 0), &wb.x, fa, &wa.x)).swapped();
    let w = Scalar::from(dot2(fb, &axis(wb, 1), &wb.x, fa, &wa.x)).swapped();
    let phi_b = atan2(&w, &u);
    [phi_a, phi_b]
}

/// The mesh angle `psi = z_a phi_a + sigma z_b phi_b` (module documentation), not wrapped.
pub fn mesh_angle(
    frames: [&Frame; 2],
    wheels: [&Frame; 2],
    (teeth_a, teeth_b, internal): (u32, u32, bool),
) -> (Scalar, Scalar) {
    let [pa, pb] = centerline_angles(frames[0], wheels[0], frames[1], wheels[1]);
    let sigma = if internal { -1.0 } else { 1.0 };
    (pa.lin(teeth_a as f64, &pb, sigma * teeth_b as f64), pa)
}
