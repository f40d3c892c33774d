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

/// The derivatives of the chart's relations `v = M(theta) x`, `vdot = M(theta) y + N(theta, x)`
/// at one point ([`Chart::jacobians`]): what an exact step Jacobian of the Lie algebra
/// updates needs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChartJacobians {
    /// `M(theta)`.
    pub m: Mat6,
    /// `d(M(theta) y_k)/dtheta` for the vectors `y_k` given.
    pub m_theta: [Mat6; 3],
    /// `dN(theta, x)/dtheta`.
    pub n_theta: Mat6,
    /// `dN(theta, x)/dx`.
    pub n_x: Mat6,
}

impl Chart {
    /// `M(theta)`, the derivatives of `M(theta) y_k` (`k = 0, 1, 2`) and of `N(theta, x)`
    /// with respect to `theta`, and of `N` with respect to `x`. Forward automatic
    /// differentiation (`num-dual`) of the series of the maps in the algebra's bracket,
    /// truncated where a term's derivative is below round-off ([`Group::tangent_rate`]'s
    /// series for `N`; `M` of the exponential chart `sum_k (-1)^k/(k+1)! ad(theta)^k`, the
    /// rotation `exp(theta_w)^T = sum_k (-tilde(theta_w))^k/k!`): the closed forms
    /// [`Chart::map`] and [`Chart::rate`] agree with them to round-off.
    pub fn jacobians(self, theta: &Vec6, x: &Vec6, ys: &[Vec6; 3]) -> ChartJacobians {
        let lift = |v: &Vec6| dual::Pair::constant(v);
        let (x_c, ys_c) = (lift(x), ys.map(|y| lift(&y)));
        let (_, in_theta) = num_dual::jacobian(
            |t: nalgebra::SVector<dual::D, 6>| {
                let t = dual::Pair::from_vector(&t);
                let mut out = nalgebra::SVector::<dual::D, 24>::zeros();
                for (k, y) in ys_c.iter().enumerate() {
                    dual::map(self, &t, y).write(&mut out, 6 * k);
                }
                dual::rate(self, &t, &x_c).write(&mut out, 18);
                out
            },
            theta,
        );
        let theta_c = lift(theta);
        let (_, n_x) = num_dual::jacobian(
            |x: nalgebra::SVector<dual::D, 6>| {
                dual::rate(self, &theta_c, &dual::Pair::from_vector(&x)).to_vector()
            },
            x,
        );
        let block = |k: usize| -> Mat6 { in_theta.fixed_view::<6, 6>(6 * k, 0).into_owned() };
        ChartJacobians {
            m: self.map(theta),
            m_theta: [block(0), block(1), block(2)],
            n_theta: block(3),
            n_x,
        }
    }

    /// `dN(0, x)/dx`: how the start of a step in the chart, `vdot_n - N(0, v_n)`, moves with
    /// `v_n` (zero for the exponential chart; `N(0, x) = (-x_w x x_u, 0)` for
    /// [`Chart::TranslationRotation`]).
    pub fn start_rate_derivative(self, x: &Vec6) -> Mat6 {
        let mut d = Mat6::zeros();
        if self == Chart::TranslationRotation {
            let (u, w) = split(x);
            d.fixed_view_mut::<3, 3>(0, 0).copy_from(&-so3::hat(&w));
            d.fixed_view_mut::<3, 3>(0, 3).copy_from(&so3::hat(&u));
        }
        d
    }

    /// The transport of a start perturbation: `q_n exp(d) o C(theta) = q_n o C(theta)
    /// exp(G d)` with `G = Ad(C(theta)^-1)` on `group`.
    pub fn transport(self, group: Group, theta: &Vec6) -> Mat6 {
        let c = self.point(&Frame::identity(), theta);
        group.adjoint(&group.inverse(&c))
    }
}

/// The maps of [`Chart`] in dual numbers, as series in the algebra's bracket.
mod dual {
    use super::{Chart, Group, Vec6};
    use nalgebra::{SVector, Vector3};

    /// Dual numbers with six derivative directions.
    pub type D = num_dual::DualSVec64<6>;
    type V3 = Vector3<D>;

    /// A 6-vector as its translation and rotation parts.
    #[derive(Clone, Copy)]
    pub struct Pair(pub V3, pub V3);

    impl Pair {
        pub fn constant(v: &Vec6) -> Self {
            let c = |i: usize| V3::new(v[i].into(), v[i + 1].into(), v[i + 2].into());
            Pair(c(0), c(3))
        }
        pub fn from_vector(v: &SVector<D, 6>) -> Self {
            Pair(V3::new(v[0], v[1], v[2]), V3::new(v[3], v[4], v[5]))
        }
        pub fn to_vector(self) -> SVector<D, 6> {
            let mut out = SVector::<D, 6>::zeros();
            self.write(&mut out, 0);
            out
        }
        pub fn write<const N: usize>(&self, out: &mut SVector<D, N>, at: usize) {
            for i in 0..3 {
                out[at + i] = self.0[i];
                out[at + 3 + i] = self.1[i];
            }
        }
        fn zero() -> Self {
            Pair(V3::zeros(), V3::zeros())
        }
        fn add(self, o: Self) -> Self {
            Pair(self.0 + o.0, self.1 + o.1)
        }
        fn scale(self, c: f64) -> Self {
            let c = D::from(c);
            Pair(self.0 * c, self.1 * c)
        }
        fn real_norm(&self) -> f64 {
            let s: f64 = (self.0.iter().chain(self.1.iter()))
                .map(|d| d.re * d.re)
                .sum();
            s.sqrt()
        }
    }

    /// `ad(a) b = [a, b]` on `group` (R3xSO(3): the rotation parts only).
    fn bracket(group: Group, a: &Pair, b: &Pair) -> Pair {
        match group {
            Group::R3xSO3 => Pair(V3::zeros(), a.1.cross(&b.1)),
            Group::SE3 => Pair(a.1.cross(&b.0) + a.0.cross(&b.1), a.1.cross(&b.1)),
        }
    }

    /// Terms `k = 0..n` of a series whose `k`-th term is bounded by `r^k k / k!` (a term's
    /// derivative included), `n` the last above round-off relative to the first.
    fn terms(r: f64) -> usize {
        const MAX: usize = 60;
        let mut bound = 1.0;
        for k in 1..MAX {
            bound *= r / k as f64;
            if bound * (k + 1) as f64 <= 1e-18 {
                return k;
            }
        }
        MAX
    }

    /// `T(theta) y = sum_k (-1)^k/(k+1)! ad(theta)^k y` on `group`.
    fn tangent(group: Group, theta: &Pair, y: &Pair) -> Pair {
        let n = terms(theta.real_norm());
        let (mut term, mut sum) = (*y, *y);
        for k in 1..=n {
            term = bracket(group, theta, &term).scale(-1.0 / (k + 1) as f64);
            sum = sum.add(term);
        }
        sum
    }

    /// `N(theta, x) = (d/ds T(theta + s x))|_0 x`: `sum_k c_k sum_{j<k} ad(theta)^j ad(x)
    /// ad(theta)^(k-1-j) x`, `c_k = (-1)^k/(k+1)!` ([`Group::tangent_rate`]'s series).
    fn tangent_rate(group: Group, theta: &Pair, x: &Pair) -> Pair {
        let n = terms(theta.real_norm()) + 1;
        let mut c = vec![1.0; n + 1];
        for k in 1..=n {
            c[k] = -c[k - 1] / (k + 1) as f64;
        }
        // y_i = ad(x) ad(theta)^i x, i < n
        let mut y = Vec::with_capacity(n);
        let mut u = *x;
        for _ in 0..n {
            y.push(bracket(group, x, &u));
            u = bracket(group, theta, &u);
        }
        let mut sum = Pair::zero();
        for j in (0..n).rev() {
            let g = (0..n - j).fold(Pair::zero(), |g, i| g.add(y[i].scale(c[i + j + 1])));
            sum = bracket(group, theta, &sum).add(g);
        }
        sum
    }

    /// `exp(w)^T y = sum_k (-tilde(w))^k / k! y` (rotation part of a pair).
    fn rotation_transposed(w: &V3, y: &V3) -> V3 {
        let n = terms(w.iter().map(|d| d.re * d.re).sum::<f64>().sqrt());
        let (mut term, mut sum) = (*y, *y);
        for k in 1..=n {
            term = term.cross(w) * D::from(1.0 / k as f64);
            sum += term;
        }
        sum
    }

    /// `M(theta) y` of `chart`.
    pub fn map(chart: Chart, theta: &Pair, y: &Pair) -> Pair {
        match chart {
            Chart::Exponential(group) => tangent(group, theta, y),
            Chart::TranslationRotation => {
                let rotation = Pair(V3::zeros(), theta.1);
                let w = tangent(Group::R3xSO3, &rotation, &Pair(V3::zeros(), y.1)).1;
                Pair(rotation_transposed(&theta.1, &y.0), w)
            }
        }
    }

    /// `N(theta, x)` of `chart`.
    pub fn rate(chart: Chart, theta: &Pair, x: &Pair) -> Pair {
        match chart {
            Chart::Exponential(group) => tangent_rate(group, theta, x),
            Chart::TranslationRotation => {
                let rotation = Pair(V3::zeros(), theta.1);
                let xw = Pair(V3::zeros(), x.1);
                let omega = tangent(Group::R3xSO3, &rotation, &xw).1;
                let u = rotation_transposed(&theta.1, &x.0);
                let rate = tangent_rate(Group::R3xSO3, &rotation, &xw).1;
                Pair(-omega.cross(&u), rate)
            }
        }
    }
}
