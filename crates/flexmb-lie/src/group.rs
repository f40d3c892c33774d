//! The two node groups behind one vocabulary: `integrate`, `difference`, `tangent`.

use crate::{join, se3, so3, split, Frame, Mat6, Vec6};

/// The Lie group a node configuration lives on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum Group {
    /// `R3 x SO(3)`: translation velocity in the inertial frame, rotation in the body frame.
    R3xSO3,
    /// `SE(3)`: both velocity parts in the body frame.
    SE3,
}

impl Group {
    /// Group exponential of a tangent vector (translation first).
    pub fn exp(self, w: &Vec6) -> Frame {
        match self {
            Group::R3xSO3 => {
                let (u, theta) = split(w);
                Frame::new(u, so3::exp(&theta))
            }
            Group::SE3 => se3::exp(w),
        }
    }

    /// Group logarithm (inverse of [`Group::exp`], rotation angle in `[0, pi]`).
    pub fn log(self, h: &Frame) -> Vec6 {
        match self {
            Group::R3xSO3 => join(&h.x, &so3::log(&h.r)),
            Group::SE3 => se3::log(h),
        }
    }

    /// Group product `a o b`.
    pub fn compose(self, a: &Frame, b: &Frame) -> Frame {
        match self {
            Group::R3xSO3 => Frame::new(a.x + b.x, a.r * b.r),
            Group::SE3 => a.compose(b),
        }
    }

    /// Group inverse.
    pub fn inverse(self, a: &Frame) -> Frame {
        match self {
            Group::R3xSO3 => Frame::new(-a.x, a.r.transpose()),
            Group::SE3 => a.inverse(),
        }
    }

    /// `q exp(tilde(w))`: the only way a configuration moves.
    pub fn integrate(self, q: &Frame, w: &Vec6) -> Frame {
        self.compose(q, &self.exp(w))
    }

    /// `log(a^-1 b)`: the tangent vector taking `a` to `b`.
    pub fn difference(self, a: &Frame, b: &Frame) -> Vec6 {
        self.log(&self.compose(&self.inverse(a), b))
    }

    /// Adjoint `Ad(h)`: `h exp(w) h^-1 = exp(Ad(h) w)` (R3xSO(3): the translation part is
    /// unchanged, the rotation part rotated by `h.r`).
    pub fn adjoint(self, h: &Frame) -> Mat6 {
        match self {
            Group::R3xSO3 => {
                let mut m = Mat6::identity();
                m.fixed_view_mut::<3, 3>(3, 3).copy_from(&h.r);
                m
            }
            Group::SE3 => se3::big_ad(h),
        }
    }

    /// Small adjoint `ad(v)`: `ad(a) b = [a, b]`, the Lie bracket of the algebra (R3xSO(3):
    /// the rotation parts only, `[a, b] = (0, omega_a x omega_b)`; SE(3): [`se3::ad`]).
    pub fn ad(self, v: &Vec6) -> Mat6 {
        match self {
            Group::R3xSO3 => {
                let (_, omega) = split(v);
                let mut m = Mat6::zeros();
                m.fixed_view_mut::<3, 3>(3, 3).copy_from(&so3::hat(&omega));
                m
            }
            Group::SE3 => se3::ad(v),
        }
    }

    /// Tangent operator `T(w)`: `exp(w + dw) = exp(w) exp(T(w) dw)`.
    pub fn tangent(self, w: &Vec6) -> Mat6 {
        match self {
            Group::R3xSO3 => {
                let (_, theta) = split(w);
                let mut m = Mat6::identity();
                m.fixed_view_mut::<3, 3>(3, 3)
                    .copy_from(&so3::tangent(&theta));
                m
            }
            Group::SE3 => se3::tangent(w),
        }
    }

    /// Inverse tangent operator.
    pub fn tangent_inv(self, w: &Vec6) -> Mat6 {
        match self {
            Group::R3xSO3 => {
                let (_, theta) = split(w);
                let mut m = Mat6::identity();
                m.fixed_view_mut::<3, 3>(3, 3)
                    .copy_from(&so3::tangent_inv(&theta));
                m
            }
            Group::SE3 => se3::tangent_inv(w),
        }
    }

    /// `d/dw [ T^-1(w)^T sigma ]` at fixed `sigma` (see
    /// [`se3::tangent_inv_transpose_derivative`]). For R3xSO(3) only the rotation block,
    /// [`so3::tangent_inv_transpose_derivative`], is nonzero.
    pub fn tangent_inv_transpose_derivative(self, w: &Vec6, sigma: &Vec6) -> Mat6 {
        match self {
            Group::R3xSO3 => {
                let (_, theta) = split(w);
                let (_, m) = split(sigma);
                let mut g = Mat6::zeros();
                g.fixed_view_mut::<3, 3>(3, 3)
                    .copy_from(&so3::tangent_inv_transpose_derivative(&theta, &m));
                g
            }
            Group::SE3 => se3::tangent_inv_transpose_derivative(w, sigma),
        }
    }

    /// `d/dt [T(w(t))] x` along `w' = x`: the derivative of the tangent operator in the
    /// direction `x` applied to `x`, what `v = T(w) w'` adds to `vdot = T(w) w''` when `w`
    /// moves with velocity `x`. R3xSO(3): the rotation part's closed form,
    /// [`so3::tangent_rate`]. SE(3): from the series `T(w) = sum_k (-1)^k / (k+1)! ad(w)^k`
    /// (`dexp_{-w}`), whose derivative is `sum_k c_k sum_{j<k} ad(w)^j ad(x) ad(w)^{k-1-j}`:
    /// with `y_i = ad(x) ad(w)^i x` it is `sum_j ad(w)^j g_j`, `g_j = sum_i c_{i+j+1} y_i`,
    /// summed by Horner's rule. The series is truncated where its remainder is below
    /// round-off relative to its first term (`|w|` up to a few radians; step increments
    /// are far below).
    pub fn tangent_rate(self, w: &Vec6, x: &Vec6) -> Vec6 {
        if self == Group::R3xSO3 {
            let ((_, theta), (_, omega)) = (split(w), split(x));
            return join(&crate::Vec3::zeros(), &so3::tangent_rate(&theta, &omega));
        }
        const MAX: usize = 40;
        let a = self.ad(w);
        let norm = w.norm();
        // c_k = (-1)^k / (k+1)!, and the terms k = 1..=n: the k-th is bounded by
        // |w|^(k-1) k / (k+1)! |x|^2, relative to the first nonzero one (k = 2,
        // |w| |x|^2 / 6) by r_k = 6 k |w|^(k-2) / (k+1)!; n is the last k with r_k above
        // round-off.
        let mut c = [0.0; MAX + 1];
        c[0] = 1.0;
        let mut n = 2;
        let mut p = 1.0 / 6.0; // |w|^(k-2) / (k+1)! at k = 2
        for k in 1..=MAX {
            c[k] = -c[k - 1] / (k + 1) as f64;
            if k > 2 {
                p *= norm / (k + 1) as f64;
                if 6.0 * k as f64 * p < 1e-17 {
                    break;
                }
                n = k;
            }
        }
        let ax = self.ad(x);
        let mut y = [Vec6::zeros(); MAX];
        let mut u = *x;
        for yi in y.iter_mut().take(n) {
            *yi = ax * u;
            u = a * u;
        }
        let mut sum = Vec6::zeros();
        for j in (0..n).rev() {
            let g: Vec6 = (0..n - j).fold(Vec6::zeros(), |g, i| g + y[i] * c[i + j + 1]);
            sum = a * sum + g;
        }
        sum
    }

    /// Name used in model files and outputs.
    pub fn name(self) -> &'static str {
        match self {
            Group::R3xSO3 => "R3xSO3",
            Group::SE3 => "SE3",
        }
    }
}
