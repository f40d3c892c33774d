//! The pose of a node slot as a generic scalar type, for the elements whose residual is one
//! function of the two slots' poses differentiated by forward automatic differentiation
//! (`num-dual`): contacts ([`super::contact`]), worm gear meshes ([`super::worm_gear`]) and
//! the block diagram ([`super::control`]).
//!
//! A slot's pose is its position `x`, rotation `R`, physical velocity (`xdot` inertial,
//! `Omega` in the body frame, [`super::physical::velocity`]) and acceleration (`xddot`
//! inertial, `Omegadot`; the measurements of control blocks, [`super::control`], read it). The variations the iteration
//! matrix needs, in physical coordinates ([`super::physical`]), are `x -> x + dx`,
//! `R -> R (I + tilde(theta))` (exact to first order, which is all a forward derivative
//! sees), `xdot -> xdot + dxdot`, `Omega -> Omega + dOmega`: [`perturbed`] lifts a pose to
//! dual numbers carrying those 12 variations per slot (24 for two slots, in the order slot
//! A configuration, slot B configuration, slot A velocity, slot B velocity).

use super::{physical, NodeState};
use flexmb_lie::{Group, Vec3};
use nalgebra::{Matrix3, RealField, SVector, Vector3};

/// Configuration, physical velocity and acceleration of one slot: `(x, R, xdot, Omega,
/// xddot, Omegadot)`.
#[derive(Clone, Copy, Debug)]
pub struct Pose<T: RealField + Copy> {
    pub x: Vector3<T>,
    pub r: Matrix3<T>,
    pub xdot: Vector3<T>,
    pub om: Vector3<T>,
    pub xddot: Vector3<T>,
    pub omdot: Vector3<T>,
}

impl<T: RealField + Copy> Pose<T> {
    /// The material point `p` (node frame) in inertial coordinates.
    pub fn point(&self, p: &Vec3) -> Vector3<T> {
        self.x + self.r * p.map(c)
    }
    /// The direction `d` (node frame) in inertial coordinates.
    pub fn direction(&self, d: &Vec3) -> Vector3<T> {
        self.r * d.map(c)
    }
    /// Velocity of the material point at the inertial position `p`.
    pub fn velocity_at(&self, p: &Vector3<T>) -> Vector3<T> {
        self.xdot + (self.r * self.om).cross(&(p - self.x))
    }
    /// Inertial angular velocity `R Omega`.
    pub fn angular_velocity(&self) -> Vector3<T> {
        self.r * self.om
    }
    /// `[F; (R^T (P - x)) x (R^T F)]` times `sign`: the generalized force of `F` at `P`.
    pub fn generalized(&self, f: &Vector3<T>, p: &Vector3<T>, sign: f64) -> [T; 6] {
        let rt = self.r.transpose();
        let m = (rt * (p - self.x)).cross(&(rt * f));
        let s: T = c(sign);
        [f[0] * s, f[1] * s, f[2] * s, m[0] * s, m[1] * s, m[2] * s]
    }
    /// `[0; R^T M]` times `sign`: the generalized force of the inertial moment `M`.
    pub fn generalized_moment(&self, m: &Vector3<T>, sign: f64) -> [T; 6] {
        let b = self.r.transpose() * m;
        let (z, s): (T, T) = (T::zero(), c(sign));
        [z, z, z, b[0] * s, b[1] * s, b[2] * s]
    }
}

/// `v` as the scalar type `T`.
pub fn c<T: RealField + Copy>(v: f64) -> T {
    nalgebra::convert(v)
}

/// The pose of a slot in `f64`.
pub fn pose(group: Group, node: &NodeState) -> Pose<f64> {
    let (xdot, om) = physical::velocity(group, node);
    Pose {
        x: node.q.x,
        r: node.q.r,
        xdot,
        om,
        xddot: super::point_acceleration(group, node, &Vec3::zeros()),
        omdot: node.vdot.fixed_rows::<3>(3).into_owned(),
    }
}

/// A pose in `f64` as dual numbers of zero derivative (for a parameter derivative).
pub fn lift(p: &Pose<f64>) -> Pose<D1> {
    Pose {
        x: p.x.map(D1::from_re),
        r: p.r.map(D1::from_re),
        xdot: p.xdot.map(D1::from_re),
        om: p.om.map(D1::from_re),
        xddot: p.xddot.map(D1::from_re),
        omdot: p.omdot.map(D1::from_re),
    }
}

/// Dual numbers with `N` derivative directions.
pub type Dv<const N: usize> = num_dual::DualSVec64<N>;
/// Dual numbers with one derivative direction.
pub type D1 = num_dual::Dual64;

/// The pose of slot `k` perturbed by the variables `w[6 k..6 k + 6]` (configuration:
/// `x + dx`, `R (I + tilde(theta))`, exact to first order) and `w[12 + 6 k..]` (velocity).
pub fn perturbed<const N: usize>(
    group: Group,
    node: &NodeState,
    w: &SVector<Dv<N>, N>,
    k: usize,
) -> Pose<Dv<N>> {
    let p = pose(group, node);
    let var = |i: usize| -> Vector3<Dv<N>> { Vector3::new(w[i], w[i + 1], w[i + 2]) };
    let theta = var(6 * k + 3);
    let r = p.r.map(Dv::from_re) * (Matrix3::identity() + theta.cross_matrix());
    Pose {
        x: p.x.map(Dv::from_re) + var(6 * k),
        r,
        xdot: p.xdot.map(Dv::from_re) + var(12 + 6 * k),
        om: p.om.map(Dv::from_re) + var(12 + 6 * k + 3),
        xddot: p.xddot.map(Dv::from_re),
        omdot: p.omdot.map(Dv::from_re),
    }
}
