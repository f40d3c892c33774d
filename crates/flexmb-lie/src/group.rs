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

    /// Name used in model files and outputs.
    pub fn name(self) -> &'static str {
        match self {
            Group::R3xSO3 => "R3xSO3",
            Group::SE3 => "SE3",
        }
    }
}
