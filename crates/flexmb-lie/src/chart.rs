//! Local coordinates of a configuration near a point `q_n`: `q = q_n o C(Theta)`, and how
//! velocities and accelerations read in them.
//!
//! Along a curve `Theta(t)`, the body velocity and its rate are
//!
//! ```text
//! v    = M(Theta) Theta'
//! vdot = M(Theta) Theta'' + N(Theta, Theta')
//! ```
//!
//! with `M` the right-trivialized differential of `C` (`q_n C(Theta + d) =
//! q_n C(Theta) exp(M(Theta) d)` to first order) and `N` what the motion of `M` adds.
//!
//! * [`Chart::Exponential`]: `C = exp` of the group, `M = T(Theta)` its tangent operator and
//!   `N = (d/dt T) Theta'` ([`Group::tangent_rate`]); `M(0) = I`, `N(0, X) = 0`.
//! * [`Chart::TranslationRotation`] on SE(3): `C(Theta) = (Theta_u, exp(Theta_w))`, the
//!   translation in the frame of `q_n` and the rotation vector apart (R3xSO(3)'s
//!   exponential composed on SE(3)): `M = diag(exp(Theta_w)^T, T(Theta_w))` and, with
//!   `Omega = T(Theta_w) Theta_w'` and `U = exp(Theta_w)^T Theta_u'` the body velocities,
//!   `N = (-Omega x U, (d/dt T) Theta_w')`. `M(0) = I` but `N(0, X) = (-X_w x X_u, 0)`: the
//!   translation coordinates' second derivative is the acceleration of the point in the
//!   frame of `q_n`, not the body-frame `Udot`.

use crate::{join, so3, split, Frame, Group, Mat6, Vec6};

/// Local coordinates near a configuration (module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Chart {
    /// `q_n exp(Theta)` on the group.
    Exponential(Group),
    /// SE(3) only: `q_n o (Theta_u, exp(Theta_w))`.
    TranslationRotation,
}

impl Chart {
    /// `q_n o C(theta)`.
    pub fn point(self, q_n: &Frame, theta: &Vec6) -> Frame {
        match self {
            Chart::Exponential(group) => group.integrate(q_n, theta),
            Chart::TranslationRotation => {
                let (u, w) = split(theta);
                q_n.compose(&Frame::new(u, so3::exp(&w)))
            }
        }
    }

    /// `M(theta)`: `v = M Theta'`.
    pub fn map(self, theta: &Vec6) -> Mat6 {
        match self {
            Chart::Exponential(group) => group.tangent(theta),
            Chart::TranslationRotation => {
                let (_, w) = split(theta);
                blocks(&so3::exp(&w).transpose(), &so3::tangent(&w))
            }
        }
    }

    /// `M(theta)^-1`.
    pub fn inverse_map(self, theta: &Vec6) -> Mat6 {
        match self {
            Chart::Exponential(group) => group.tangent_inv(theta),
            Chart::TranslationRotation => {
                let (_, w) = split(theta);
                blocks(&so3::exp(&w), &so3::tangent_inv(&w))
            }
        }
    }

    /// `N(theta, x)`: `vdot = M Theta'' + N` along `Theta' = x`.
    pub fn rate(self, theta: &Vec6, x: &Vec6) -> Vec6 {
        match self {
            Chart::Exponential(group) => group.tangent_rate(theta, x),
            Chart::TranslationRotation => {
                let ((_, w), (xu, xw)) = (split(theta), split(x));
                let omega = so3::tangent(&w) * xw;
                let u = so3::exp(&w).transpose() * xu;
                join(&-omega.cross(&u), &so3::tangent_rate(&w, &xw))
            }
        }
    }
}

/// `diag(a, b)` of two 3 x 3 blocks.
fn blocks(a: &crate::Mat3, b: &crate::Mat3) -> Mat6 {
    let mut m = Mat6::zeros();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(a);
    m.fixed_view_mut::<3, 3>(3, 3).copy_from(b);
    m
}
