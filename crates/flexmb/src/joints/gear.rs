//! The ideal gear constraint: one row holding the kinematic ratio of two wheels, at the
//! position level and on the Lie group, for when the mesh dynamics do not matter (the gear
//! pair element [`crate::elements::gear`] is its compliant counterpart, with the same
//! kinematics).
//!
//! With `phi_a`, `phi_b` the angles of the line of centres seen from wheels A and B
//! (dot-2 primitives composed through `atan2`, [`crate::elements::gear::centerline_angles`]),
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

use super::primitives::Primitive;
use crate::elements::gear::mesh_angle;
use crate::model::{Joint, JointKind};
use flexmb_lie::Frame;

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
