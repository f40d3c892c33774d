//! Lie groups for flexible multibody dynamics: SO(3), SE(3) and R3xSO(3).
//!
//! Node configurations in flexmb live on one of two groups, chosen per model:
//!
//! * R3xSO(3): `q = (x, R)`, composition `(x1, R1) o (x2, R2) = (x1 + x2, R1 R2)`,
//!   velocity `v = (u, Omega)` with `x' = u` (inertial frame) and `R' = R tilde(Omega)`;
//! * SE(3): `q = [[R, x], [0, 1]]`, composition is the product of homogeneous matrices,
//!   velocity `v = (U, Omega)` with `x' = R U` (body frame) and `R' = R tilde(Omega)`.
//!
//! Both store the same data, a [`Frame`] (position and rotation matrix); they differ in how a
//! tangent vector `w` (translation part first, then rotation) moves a configuration:
//! `q exp(tilde(w))`. Everything a solver needs is in [`Group`]: `integrate`, `difference`,
//! the tangent operator `T` (`exp(w + dw) = exp(w) exp(T(w) dw)`) and its inverse, and the
//! derivative `d/dw [T^-1(w)^T sigma]` that the tangent stiffness of the SE(3) beam needs
//! ([`tangent_inv_transpose_derivative`], [`tangent_inv_transpose_derivative_so3`]).
//!
//! Formulas are closed form with Taylor series near zero rotation; the logarithm goes through
//! a quaternion and is robust up to and including a rotation of pi.
//!
//! # References
//! * O. Brüls, A. Cardona, "On the use of Lie group time integrators in multibody dynamics",
//!   J. Comput. Nonlinear Dyn. 5 (2010) 031002, Sect. 2 (R3xSO(3) and SE(3) operators).
//! * V. Sonneville, A. Cardona, O. Brüls, "Geometrically exact beam finite element formulated
//!   on the special Euclidean group SE(3)", CMAME 268 (2014) 451-474, Sect. 2 and Appendix
//!   (tangent operator of SE(3)).
//! * T. D. Barfoot, "State Estimation for Robotics", 2017, Sect. 7.1 (closed forms of the
//!   SE(3) Jacobians, used here in the right-trivialized form).

mod chart;
mod frame;
mod group;
pub mod se3;
pub mod so3;

pub use chart::Chart;
pub use frame::Frame;
pub use group::Group;
pub use se3::tangent_inv_transpose_derivative;
pub use so3::tangent_inv_transpose_derivative as tangent_inv_transpose_derivative_so3;

/// 3-vector.
pub type Vec3 = nalgebra::Vector3<f64>;
/// 6-vector: translation part first, then rotation part.
pub type Vec6 = nalgebra::Vector6<f64>;
/// 3 x 3 matrix.
pub type Mat3 = nalgebra::Matrix3<f64>;
/// 6 x 6 matrix, blocks ordered (translation, rotation).
pub type Mat6 = nalgebra::Matrix6<f64>;

/// Splits a 6-vector into its translation and rotation parts.
#[inline]
pub fn split(w: &Vec6) -> (Vec3, Vec3) {
    (
        w.fixed_rows::<3>(0).into_owned(),
        w.fixed_rows::<3>(3).into_owned(),
    )
}

/// Joins translation and rotation parts into a 6-vector.
#[inline]
pub fn join(u: &Vec3, theta: &Vec3) -> Vec6 {
    Vec6::new(u.x, u.y, u.z, theta.x, theta.y, theta.z)
}
