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

use crate::so3::{self, hat, horner, SIN_DEFECT as B1};
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

/// Taylor coefficients of `b2 = (p^2 + 2 cos p - 2)/(2 p^4) = sum (-1)^k p^2k/(2k+4)!`.
const B2: [f64; 10] = [
    1.0 / 24.0,
    -1.0 / 720.0,
    1.0 / 40320.0,
    -1.0 / 3628800.0,
    1.0 / 479001600.0,
    -1.0 / 87178291200.0,
    1.0 / 20922789888000.0,
    -1.0 / 6402373705728000.0,
    1.0 / 2432902008176640000.0,
    -1.0 / 1124000727777607680000.0,
];
/// Taylor coefficients of `b3 = (2p - 3 sin p + p cos p)/(2 p^5)
/// = sum_(j>=2) (-1)^j (j - 1) p^(2j-4)/(2j+1)!`.
const B3: [f64; 10] = [
    1.0 / 120.0,
    -1.0 / 2520.0,
    1.0 / 120960.0,
    -1.0 / 9979200.0,
    1.0 / 1245404160.0,
    -1.0 / 217945728000.0,
    1.0 / 50812489728000.0,
    -1.0 / 15205637551104000.0,
    1.0 / 5676771352412160000.0,
    -1.0 / 2585201673888497664000.0,
];

/// Coupling block `T_Ut(u, theta)` of the SE(3) tangent operator (equal to the directional
/// derivative `D T_SO3(theta)[u]`).
///
/// The closed forms of `b2`, `b3` cancel catastrophically for small angles (relative error
/// `~1e-3` at `p = 1e-3`), so the series is used up to `p = 1.5`; both branches are then
/// accurate to a few ulps.
fn coupling(w: &Vec6) -> Mat3 {
    let (u, theta) = split(w);
    let p2 = theta.norm_squared();
    let (b1, b2, b3) = if p2 < 1e-8 {
        (B1[0] + B1[1] * p2, B2[0] + B2[1] * p2, B3[0] + B3[1] * p2)
    } else if p2 < so3::SERIES_MAX {
        (horner(&B1, p2), horner(&B2, p2), horner(&B3, p2))
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

/// `G(d, sigma) = d/dd [ T^-1(d)^T sigma ]` (6 x 6): derivative with respect to `d`, at fixed
/// `sigma`, of the transposed inverse tangent operator ([`tangent_inv`]) applied to `sigma`.
///
/// # Use in the SE(3) beam
/// With `d = log(H_A^-1 H_B)` and `H_A -> H_A exp(w_A)`, `H_B -> H_B exp(w_B)`,
/// `delta d = P(d) [w_A; w_B]`, `P(d) = [ -T^-1(-d), T^-1(d) ]` (6 x 12). The internal force
/// `f = P(d)^T sigma` has, at fixed `sigma`, `d f/dd = [ G(-d, sigma); G(d, sigma) ]` (12 x 6),
/// since `d/dd [ T^-1(-d)^T sigma ] = -G(-d, sigma)` (chain rule). The tangent stiffness is
/// `K = P^T (d sigma/dd) P + [ G(-d, sigma); G(d, sigma) ] P`.
///
/// # Formula
/// Write `d = (u, theta)`, `sigma = (n, m)` (translation first). Since
/// `T^-1(x) = sum_k B_k/k! (-ad(x))^k` (Bernoulli numbers, `B_1 = -1/2`) and
/// `ad(u, theta) = [[tilde(theta), tilde(u)], [0, tilde(theta)]]` is block triangular with equal
/// diagonal blocks, the off-diagonal block of `ad^k` is `d/de (tilde(theta) + e tilde(u))^k`, so
/// the coupling block of `T^-1` is the directional derivative of the SO(3) operator:
/// `T^-1(d) = [[ T^-1(theta), D T^-1(theta)[u] ], [ 0, T^-1(theta) ]]` (the same block
/// structure as Sonneville, Cardona & Brüls 2014, Appendix A, where the coupling block is
/// written in closed form). Hence
/// `T^-1(d)^T sigma = ( T^-1(theta)^T n ;  g(theta, n) u + T^-1(theta)^T m )` and
///
/// ```text
/// G(d, sigma) = [[ 0,         g(theta, n)                              ],
///                [ g(theta, n), g(theta, m) + D_theta g(theta, n)[u]   ]]
/// ```
///
/// with `g = so3::tangent_inv_transpose_derivative`,
/// `g(theta, n) = 1/2 tilde(n) + eta M + 2 eta' v theta^T`, `M = a I + theta n^T - 2 n theta^T`,
/// `v = tilde(theta)^2 n = a theta - s n`, `a = theta.n`, `s = |theta|^2`,
/// `eta(s) = (1 - (p/2) cot(p/2))/s`, and, with `b = theta.u`, `c = u.n`,
///
/// ```text
/// D_theta g(theta, n)[u] = 2 eta' b M + eta (c I + u n^T - 2 n u^T) + 4 eta'' b v theta^T
///                        + 2 eta' ( (a u + c theta - 2 b n) theta^T + v u^T )
/// ```
///
/// `eta, eta', eta''` (derivatives in `s`) use a Bernoulli-number series below
/// `|theta| = 1.5` (exact at `theta = 0`) and closed forms above; accurate for any `u` and
/// `|theta|` up to `pi` and beyond, singular at `|theta| = 2 pi`. The derivation is ours
/// (differentiation of the Sonneville-Cardona-Brüls operator); tests check it against finite
/// differences of [`tangent_inv`] and of `log(exp(-w_A) H_A^-1 H_B exp(w_B))`.
pub fn tangent_inv_transpose_derivative(d: &Vec6, sigma: &Vec6) -> Mat6 {
    let (u, theta) = split(d);
    let (n, m) = split(sigma);
    let s = theta.norm_squared();
    let (eta, eta1, eta2) = so3::eta_derivatives(s);
    let gn = so3::tangent_inv_transpose_derivative_with(&theta, &n, eta, eta1);
    let gm = so3::tangent_inv_transpose_derivative_with(&theta, &m, eta, eta1);

    let a = theta.dot(&n);
    let b = theta.dot(&u);
    let c = u.dot(&n);
    let v = theta * a - n * s;
    let mm = theta * n.transpose() - n * theta.transpose() * 2.0;
    let w = u * a + theta * c - n * (2.0 * b);
    let mut k = mm * (2.0 * eta1 * b)
        + (u * n.transpose() - n * u.transpose() * 2.0) * eta
        + v * theta.transpose() * (4.0 * eta2 * b)
        + (w * theta.transpose() + v * u.transpose()) * (2.0 * eta1);
    let diag = 2.0 * eta1 * b * a + eta * c;
    k[(0, 0)] += diag;
    k[(1, 1)] += diag;
    k[(2, 2)] += diag;

    let mut out = Mat6::zeros();
    out.fixed_view_mut::<3, 3>(0, 3).copy_from(&gn);
    out.fixed_view_mut::<3, 3>(3, 0).copy_from(&gn);
    out.fixed_view_mut::<3, 3>(3, 3).copy_from(&(gm + k));
    out
}
