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
        // 1 - cos p = sin^2 p/(1 + cos p) avoids the cancellation at small angles.
        let b = if c > 0.0 {
            s * s / (p2 * (1.0 + c))
        } else {
            (1.0 - c) / p2
        };
        // p - sin p cancels up to moderate angles: series below p = 1.5.
        let d = if p2 < SERIES_MAX {
            horner(&SIN_DEFECT, p2)
        } else {
            (p - s) / (p2 * p)
        };
        (s / p, b, d)
    }
}

/// Below this squared angle, `(p - sin p)/p^3` and the `T^-1` coefficient use their series.
pub(crate) const SERIES_MAX: f64 = 2.25;

/// Taylor coefficients (in `p^2`) of `(p - sin p)/p^3 = sum (-1)^k p^2k/(2k+3)!`; ten terms
/// reach round-off up to `p = 2`.
pub(crate) const SIN_DEFECT: [f64; 10] = [
    1.0 / 6.0,
    -1.0 / 120.0,
    1.0 / 5040.0,
    -1.0 / 362880.0,
    1.0 / 39916800.0,
    -1.0 / 6227020800.0,
    1.0 / 1307674368000.0,
    -1.0 / 355687428096000.0,
    1.0 / 121645100408832000.0,
    -1.0 / 51090942171709440000.0,
];

/// Polynomial `sum_k c_k s^k` (Horner).
#[inline]
pub(crate) fn horner<const N: usize>(c: &[f64; N], s: f64) -> f64 {
    c.iter().rev().fold(0.0, |acc, &ck| acc * s + ck)
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
    // The closed form loses relative accuracy in `d` for small p, but `d` multiplies
    // `tilde(x)^2 ~ p^2`, so the absolute error of `T^-1` stays at round-off level.
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

/// Taylor coefficients of `eta(s) = (1 - (p/2) cot(p/2))/p^2`, `s = p^2`:
/// `eta(s) = sum_{k>=1} c_k s^(k-1)` with `c_k = |B_2k|/(2k)! = 2 zeta(2k)/(2 pi)^(2k)`
/// (`1/12, 1/720, 1/30240, 1/1209600, ...`; Bernoulli numbers `B_2k`). Radius of convergence
/// `s = 4 pi^2`, so 15 terms reach round-off at `s = 2.25`.
const ETA: [f64; 15] = [
    0.08333333333333333,
    0.001388888888888889,
    3.306878306878307e-05,
    8.267195767195768e-07,
    2.08767569878681e-08,
    5.284190138687493e-10,
    1.3382536530684679e-11,
    3.3896802963225827e-13,
    8.586062056277845e-15,
    2.174868698558062e-16,
    5.5090028283602295e-18,
    1.3954464685812522e-19,
    3.534707039629467e-21,
    8.953517427037546e-23,
    2.267952452337683e-24,
];
/// Taylor coefficients of `d eta/ds`: `k c_(k+1)`, `k >= 1`.
const ETA_1: [f64; 15] = [
    0.001388888888888889,
    6.613756613756614e-05,
    2.48015873015873e-06,
    8.35070279514724e-08,
    2.6420950693437467e-09,
    8.029521918410807e-11,
    2.372776207425808e-12,
    6.868849645022276e-14,
    1.9573818287022555e-15,
    5.5090028283602297e-17,
    1.5349911154393775e-18,
    4.241648447555361e-20,
    1.163957265514881e-21,
    3.1751334332727565e-23,
    8.617186003308303e-25,
];
/// Taylor coefficients of `d^2 eta/ds^2`: `k (k+1) c_(k+2)`, `k >= 1`.
const ETA_2: [f64; 15] = [
    6.613756613756614e-05,
    4.96031746031746e-06,
    2.505210838544172e-07,
    1.0568380277374987e-08,
    4.0147609592054037e-10,
    1.4236657244554848e-11,
    4.808194751515593e-13,
    1.5659054629618044e-14,
    4.958102545524207e-16,
    1.5349911154393774e-17,
    4.665813292310897e-19,
    1.3967487186178574e-20,
    4.127673463254583e-22,
    1.2064060404631625e-23,
    3.492413941475676e-25,
];

/// `(eta, eta', eta'')`: the `tilde(x)^2` coefficient of `T^-1(x)`,
/// `eta(s) = (1 - (p/2) cot(p/2))/s`, `s = p^2 = |x|^2`, and its first two derivatives with
/// respect to `s`.
///
/// Series below `s = 2.25` (two terms below `s = 1e-8`); above, the closed form for `eta`
/// and, for the derivatives, the Riccati equation of `q = (p/2) cot(p/2)`
/// (`2 s q' = q - q^2 - s/4`, i.e. with `q = 1 - s eta`):
///
/// ```text
/// eta'  = (1/4 - 3 eta + s eta^2) / (2 s)
/// eta'' = (eta^2 - 5 eta' + 2 s eta eta') / (2 s)
/// ```
///
/// Relative accuracy (against 50-digit arithmetic) better than `1e-15, 2e-14, 4e-13` for
/// `eta, eta', eta''` on `p in [0, 3.1]`. Singular at `p = 2 pi`.
#[inline]
pub(crate) fn eta_derivatives(s: f64) -> (f64, f64, f64) {
    if s < SMALL * SMALL {
        // Two terms each: truncation below 1e-18 relative.
        (
            ETA[0] + ETA[1] * s,
            ETA_1[0] + ETA_1[1] * s,
            ETA_2[0] + ETA_2[1] * s,
        )
    } else if s < SERIES_MAX {
        (horner(&ETA, s), horner(&ETA_1, s), horner(&ETA_2, s))
    } else {
        let p = s.sqrt();
        let eta = (1.0 - 0.5 * p / (0.5 * p).tan()) / s;
        let eta1 = (0.25 - 3.0 * eta + s * eta * eta) / (2.0 * s);
        let eta2 = (eta * eta - 5.0 * eta1 + 2.0 * s * eta * eta1) / (2.0 * s);
        (eta, eta1, eta2)
    }
}

/// `G(x, m) = d/dx [ T^-1(x)^T m ]`, given `(eta, eta')` of [`eta_derivatives`].
#[inline]
pub(crate) fn tangent_inv_transpose_derivative_with(
    x: &Vec3,
    m: &Vec3,
    eta: f64,
    eta1: f64,
) -> Mat3 {
    let a = x.dot(m);
    let v = x * a - m * x.norm_squared(); // tilde(x)^2 m
    let mut g = hat(m) * 0.5
        + (x * m.transpose() - m * x.transpose() * 2.0) * eta
        + v * x.transpose() * (2.0 * eta1);
    g[(0, 0)] += eta * a;
    g[(1, 1)] += eta * a;
    g[(2, 2)] += eta * a;
    g
}

/// Derivative of the transposed inverse tangent operator applied to a fixed vector:
/// `G(x, m) = d/dx [ T^-1(x)^T m ]` (3 x 3), with `T^-1` of [`tangent_inv`]
/// (right-trivialized, `exp(x + dx) = exp(x) exp(T(x) dx)`).
///
/// From `T^-1(x)^T m = m - 1/2 x cross m + eta(s) tilde(x)^2 m`, `s = |x|^2`,
/// `eta(s) = (1 - (p/2) cot(p/2))/s`:
///
/// ```text
/// G(x, m) = 1/2 tilde(m) + eta ( (x.m) I + x m^T - 2 m x^T ) + 2 eta' (tilde(x)^2 m) x^T
/// ```
///
/// with `eta' = d eta/ds` (series below `|x| = 1.5`, so `x = 0` gives `1/2 tilde(m)` exactly).
/// For the derivative of `T^-1(-x)^T m` with respect to `x` use `-G(-x, m)` (chain rule).
/// `T^-1` is the one of Géradin & Cardona 2001, Ch. 4 (Brüls & Cardona 2010, Eq. (22));
/// the derivative is derived here. Singular at `|x| = 2 pi`.
pub fn tangent_inv_transpose_derivative(x: &Vec3, m: &Vec3) -> Mat3 {
    let (eta, eta1, _) = eta_derivatives(x.norm_squared());
    tangent_inv_transpose_derivative_with(x, m, eta, eta1)
}

/// Taylor coefficients (in `p^2`) of the tangent operator's derivative coefficients
/// `b'/p = (sin p / p - 2 b)/p^2 = sum_{k>=1} (-1)^k 2k p^(2k-2) / (2k+2)!` and
/// `c'/p = (b - 3 c)/p^2 = sum_{k>=1} (-1)^k 2k p^(2k-2) / (2k+3)!`
/// (`b = (1 - cos p)/p^2`, `c = (p - sin p)/p^3`); twelve terms reach round-off below
/// [`SERIES_MAX`].
const fn rate_series(offset: usize) -> [f64; 12] {
    let mut out = [0.0; 12];
    let mut k = 1;
    while k <= 12 {
        let mut f = 1.0;
        let mut i = 2;
        while i <= 2 * k + offset {
            f *= i as f64;
            i += 1;
        }
        let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
        out[k - 1] = sign * (2 * k) as f64 / f;
        k += 1;
    }
    out
}
const B_RATE: [f64; 12] = rate_series(2);
const C_RATE: [f64; 12] = rate_series(3);

/// `d/dt [T(theta(t))] x` along `theta' = x` (see [`crate::Group::tangent_rate`]):
/// with `T = I - b tilde(theta) + c tilde(theta)^2` and `p' = theta . x / p`,
/// `(theta . x) (-(b'/p) theta x x + (c'/p) theta x (theta x x)) + c x x (theta x x)`.
pub fn tangent_rate(theta: &Vec3, x: &Vec3) -> Vec3 {
    let p2 = theta.norm_squared();
    let (_, b, c) = coefficients(p2);
    let (db, dc) = if p2 < SERIES_MAX {
        (horner(&B_RATE, p2), horner(&C_RATE, p2))
    } else {
        let (a, _, _) = coefficients(p2);
        ((a - 2.0 * b) / p2, (b - 3.0 * c) / p2)
    };
    let tx = theta.cross(x);
    let s = theta.dot(x);
    (tx * -db + theta.cross(&tx) * dc) * s + x.cross(&tx) * c
}
