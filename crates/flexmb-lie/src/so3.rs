//! The rotation group SO(3): hat/vee, exponential, logarithm and tangent operator.
//!
//! Conventions: `exp(tilde(theta))` is the rotation by `|theta|` about `theta`
//! (Rodrigues' formula); the tangent operator is right-trivialized,
//! `exp(theta + dtheta) = exp(theta) exp(tilde(T(theta) dtheta))`, with
//!
//! ```text
//! T(x)    = I - (1 - cos p)/p^2 tilde(x) + (p - sin p)/p^3 tilde(x)^2,   p = |x|
//! T^-1(x) = I + 1/2 tilde(x) + (1 - (p/2) cot(p/2))/p^2 tilde(x)^2
//! ```
//!
//! # References
//! Brüls & Cardona 2010, J. Comput. Nonlinear Dyn. 5, 031002, Eqs. (20)-(22);
//! Géradin & Cardona 2001, "Flexible multibody dynamics", Ch. 4.

use crate::{Mat3, Vec3};

/// Below this angle the closed forms are replaced by their Taylor series.
const SMALL: f64 = 1e-4;

/// `tilde(v)`: the skew matrix with `tilde(v) a = v x a`.
#[inline]
pub fn hat(v: &Vec3) -> Mat3 {
    Mat3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// Inverse of [`hat`]; takes the skew part of a general matrix.
#[inline]
pub fn vee(m: &Mat3) -> Vec3 {
    Vec3::new(
        0.5 * (m[(2, 1)] - m[(1, 2)]),
        0.5 * (m[(0, 2)] - m[(2, 0)]),
        0.5 * (m[(1, 0)] - m[(0, 1)]),
    )
}

/// Coefficients `(sin p / p, (1 - cos p)/p^2, (p - sin p)/p^3)` with series near 0.
#[inline]
pub(crate) fn coefficients(p2: f64) -> (f64, f64, f64) {
    if p2 < SMALL * SMALL {
        (
            1.0 - p2 / 6.0 + p2 * p2 / 120.0,
            0.5 - p2 / 24.0 + p2 * p2 / 720.0,
            1.0 / 6.0 - p2 / 120.0 + p2 * p2 / 5040.0,
        )
    } else {
        let p = p2.sqrt();
        let (s, c) = p.sin_cos();
        (s / p, (1.0 - c) / p2, (p - s) / (p2 * p))
    }
}

/// Exponential map (Rodrigues): `R = I + sin p/p tilde(x) + (1 - cos p)/p^2 tilde(x)^2`.
pub fn exp(x: &Vec3) -> Mat3 {
    let (a, b, _) = coefficients(x.norm_squared());
    let k = hat(x);
    Mat3::identity() + k * a + k * k * b
}

/// Unit quaternion `(w, x, y, z)` (scalar first, `w >= 0`) of a rotation matrix (Shepperd's method).
pub fn to_quaternion(r: &Mat3) -> [f64; 4] {
    let tr = r.trace();
    let d = [r[(0, 0)], r[(1, 1)], r[(2, 2)]];
    let mut q = if tr >= d[0] && tr >= d[1] && tr >= d[2] {
        let s = 2.0 * (1.0 + tr).sqrt();
        [
            0.25 * s,
            (r[(2, 1)] - r[(1, 2)]) / s,
            (r[(0, 2)] - r[(2, 0)]) / s,
            (r[(1, 0)] - r[(0, 1)]) / s,
        ]
    } else if d[0] >= d[1] && d[0] >= d[2] {
        let s = 2.0 * (1.0 + d[0] - d[1] - d[2]).sqrt();
        [
            (r[(2, 1)] - r[(1, 2)]) / s,
            0.25 * s,
            (r[(0, 1)] + r[(1, 0)]) / s,
            (r[(0, 2)] + r[(2, 0)]) / s,
        ]
    } else if d[1] >= d[2] {
        let s = 2.0 * (1.0 + d[1] - d[0] - d[2]).sqrt();
        [
            (r[(0, 2)] - r[(2, 0)]) / s,
            (r[(0, 1)] + r[(1, 0)]) / s,
            0.25 * s,
            (r[(1, 2)] + r[(2, 1)]) / s,
        ]
    } else {
        let s = 2.0 * (1.0 + d[2] - d[0] - d[1]).sqrt();
        [
            (r[(1, 0)] - r[(0, 1)]) / s,
            (r[(0, 2)] + r[(2, 0)]) / s,
            (r[(1, 2)] + r[(2, 1)]) / s,
            0.25 * s,
        ]
    };
    if q[0] < 0.0 {
        q.iter_mut().for_each(|c| *c = -*c);
    }
    let n = q.iter().map(|c| c * c).sum::<f64>().sqrt();
    q.iter_mut().for_each(|c| *c /= n);
    q
}

/// Rotation matrix of a quaternion `(w, x, y, z)` (normalized here).
pub fn from_quaternion(q: [f64; 4]) -> Mat3 {
    let n = q.iter().map(|c| c * c).sum::<f64>().sqrt();
    let [w, x, y, z] = q.map(|c| c / n);
    Mat3::new(
        1.0 - 2.0 * (y * y + z * z),
        2.0 * (x * y - w * z),
        2.0 * (x * z + w * y),
        2.0 * (x * y + w * z),
        1.0 - 2.0 * (x * x + z * z),
        2.0 * (y * z - w * x),
        2.0 * (x * z - w * y),
        2.0 * (y * z + w * x),
        1.0 - 2.0 * (x * x + y * y),
    )
}

/// Logarithm: the rotation vector of `R`, with angle in `[0, pi]`. Computed from the
/// quaternion, `theta = 2 atan2(|q_v|, q_0) q_v/|q_v|`, which is accurate near 0 and near pi.
pub fn log(r: &Mat3) -> Vec3 {
    let q = to_quaternion(r);
    let qv = Vec3::new(q[1], q[2], q[3]);
    let s = qv.norm();
    if s < 1e-300 {
        return Vec3::zeros();
    }
    let angle = 2.0 * s.atan2(q[0]);
    // angle/s -> 2 as s -> 0 (q0 -> 1); the ratio is well conditioned.
    let ratio = if s < 1e-8 { 2.0 / q[0] } else { angle / s };
    qv * ratio
}

/// Tangent operator `T(x)` with `exp(x + dx) = exp(x) exp(T(x) dx)`.
pub fn tangent(x: &Vec3) -> Mat3 {
    let (_, b, c) = coefficients(x.norm_squared());
    let k = hat(x);
    Mat3::identity() - k * b + k * k * c
}

/// Inverse tangent operator `T^-1(x) = I + 1/2 tilde(x) + (1 - (p/2) cot(p/2))/p^2 tilde(x)^2`.
/// Singular at `p = 2 pi`.
pub fn tangent_inv(x: &Vec3) -> Mat3 {
    let p2 = x.norm_squared();
    let d = if p2 < SMALL * SMALL {
        1.0 / 12.0 + p2 / 720.0 + p2 * p2 / 30240.0
    } else {
        let p = p2.sqrt();
        (1.0 - 0.5 * p / (0.5 * p).tan()) / p2
    };
    let k = hat(x);
    Mat3::identity() + k * 0.5 + k * k * d
}

/// Re-orthonormalizes a rotation matrix that drifted by round-off (through its quaternion).
pub fn orthonormalize(r: &Mat3) -> Mat3 {
    from_quaternion(to_quaternion(r))
}
