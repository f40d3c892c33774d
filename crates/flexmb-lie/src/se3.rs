//! The special Euclidean group SE(3), vectors ordered (translation U, rotation Omega).
//!
//! ```text
//! exp(u, theta) = ( R = exp_SO3(theta),  x = T_SO3(theta)^T u )
//! T_SE3(u, theta) = [[ T(theta), T_Ut(u, theta) ], [ 0, T(theta) ]]
//! ad(U, Omega)  = [[ tilde(Omega), tilde(U) ], [ 0, tilde(Omega) ]]
//! Ad(R, x)      = [[ R, tilde(x) R ], [ 0, R ]]
//! ```
//! `T_Ut` is the coupling block of the right-trivialized tangent operator.
//!
//! # References
//! Sonneville, Cardona & Brüls 2014, CMAME 268, Sect. 2.2 and Appendix A (Eqs. (A.1)-(A.5));
//! Barfoot 2017, Sect. 7.1.5 (the same operator written for the left Jacobian, Eq. (7.86)).

use crate::so3::{self, hat};
use crate::{join, split, Frame, Mat3, Mat6, Vec6};

/// Exponential map of SE(3).
pub fn exp(w: &Vec6) -> Frame {
    let (u, theta) = split(w);
    Frame {
        x: so3::tangent(&theta).transpose() * u,
        r: so3::exp(&theta),
    }
}

/// Logarithm of SE(3): the inverse of [`exp`] with rotation angle in `[0, pi]`.
pub fn log(h: &Frame) -> Vec6 {
    let theta = so3::log(&h.r);
    let u = so3::tangent_inv(&theta).transpose() * h.x;
    join(&u, &theta)
}

/// Coupling block `T_Ut(u, theta)` of the SE(3) tangent operator.
fn coupling(w: &Vec6) -> Mat3 {
    let (u, theta) = split(w);
    let p2 = theta.norm_squared();
    let (b1, b2, b3) = if p2 < 1e-8 {
        (
            1.0 / 6.0 - p2 / 120.0,
            1.0 / 24.0 - p2 / 720.0,
            1.0 / 120.0 - p2 / 2520.0,
        )
    } else {
        let p = p2.sqrt();
        let (s, c) = p.sin_cos();
        (
            (p - s) / (p2 * p),
            (p2 + 2.0 * c - 2.0) / (2.0 * p2 * p2),
            (2.0 * p - 3.0 * s + p * c) / (2.0 * p2 * p2 * p),
        )
    };
    let t = hat(&theta);
    let uu = hat(&u);
    let tut = t * uu * t;
    -uu * 0.5 + (t * uu + uu * t - tut) * b1 - (t * t * uu + uu * t * t - tut * 3.0) * b2
        + (tut * t + t * tut) * b3
}

/// Tangent operator: `exp(w + dw) = exp(w) exp(T(w) dw)`.
pub fn tangent(w: &Vec6) -> Mat6 {
    let (_, theta) = split(w);
    let t = so3::tangent(&theta);
    let mut m = Mat6::zeros();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&t);
    m.fixed_view_mut::<3, 3>(3, 3).copy_from(&t);
    m.fixed_view_mut::<3, 3>(0, 3).copy_from(&coupling(w));
    m
}

/// Inverse tangent operator `[[T^-1, -T^-1 T_Ut T^-1], [0, T^-1]]`.
pub fn tangent_inv(w: &Vec6) -> Mat6 {
    let (_, theta) = split(w);
    let ti = so3::tangent_inv(&theta);
    let mut m = Mat6::zeros();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&ti);
    m.fixed_view_mut::<3, 3>(3, 3).copy_from(&ti);
    m.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&(-ti * coupling(w) * ti));
    m
}

/// Small adjoint `ad(v)`: `ad(a) b = [a, b]` (the Lie bracket of se(3)).
pub fn ad(v: &Vec6) -> Mat6 {
    let (u, om) = split(v);
    let mut m = Mat6::zeros();
    let o = hat(&om);
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&o);
    m.fixed_view_mut::<3, 3>(3, 3).copy_from(&o);
    m.fixed_view_mut::<3, 3>(0, 3).copy_from(&hat(&u));
    m
}

/// Adjoint `Ad(H)`: `H exp(tilde(w)) H^-1 = exp(tilde(Ad(H) w))`.
pub fn big_ad(h: &Frame) -> Mat6 {
    let mut m = Mat6::zeros();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(&h.r);
    m.fixed_view_mut::<3, 3>(3, 3).copy_from(&h.r);
    m.fixed_view_mut::<3, 3>(0, 3).copy_from(&(hat(&h.x) * h.r));
    m
}
