//! Scalar constraint primitives from which every joint is built (Haug 1989, Sect. 3.3).
//!
//! Both act between node frames `(x_a, R_a)` and `(x_b, R_b)`; vectors with a `0` are fixed
//! in a node frame. Each returns the value `phi`, its gradient `g = dphi/dw_p` and the
//! derivative of that gradient `H = dg/dw_p`, in physical coordinates
//! `w_p = (dx_a, theta_a, dx_b, theta_b)` (inertial translation, body rotation, see
//! [`crate::elements::physical`]). `H` is what `d(B^T lambda)/dq` and the convective term
//! `v^T H v` of the acceleration-level constraint need.
//!
//! ```text
//! dot-1:  phi = (R_a a0) . (R_b b0)
//!         g_theta_a = a0 x (R_a^T b),   g_theta_b = b0 x (R_b^T a)
//! dot-2:  phi = (R_a a0) . d,   d = x_b + R_b p_b - x_a - R_a p_a,   r = x_b + R_b p_b - x_a
//!         g = ( -a, a0 x R_a^T r, a, p_b x R_b^T a )
//! ```

use crate::elements::{Mat12, Vec12};
use flexmb_lie::{so3::hat, Frame, Mat3, Vec3};

/// Value, gradient and gradient derivative of a scalar constraint.
#[derive(Clone, Copy, Debug)]
pub struct Primitive {
    pub phi: f64,
    pub g: Vec12,
    pub h: Mat12,
}

fn put(h: &mut Mat12, i: usize, j: usize, m: &Mat3) {
    h.fixed_view_mut::<3, 3>(i, j).copy_from(m);
}

/// Dot-1: `phi = (R_a a0) . (R_b b0)`.
pub fn dot1(fa: &Frame, a0: &Vec3, fb: &Frame, b0: &Vec3) -> Primitive {
    let (ra, rb) = (&fa.r, &fb.r);
    let a = ra * a0;
    let b = rb * b0;
    let (at, bt) = (hat(a0), hat(b0));
    let b_in_a = ra.transpose() * b;
    let a_in_b = rb.transpose() * a;
    let mut g = Vec12::zeros();
    g.fixed_rows_mut::<3>(3).copy_from(&a0.cross(&b_in_a));
    g.fixed_rows_mut::<3>(9).copy_from(&b0.cross(&a_in_b));
    let mut h = Mat12::zeros();
    let rab = ra.transpose() * rb;
    put(&mut h, 3, 3, &(at * hat(&b_in_a)));
    put(&mut h, 3, 9, &(-at * rab * bt));
    put(&mut h, 9, 9, &(bt * hat(&a_in_b)));
    put(&mut h, 9, 3, &(-bt * rab.transpose() * at));
    Primitive {
        phi: a.dot(&b),
        g,
        h,
    }
}

/// Dot-2: `phi = (R_a a0) . (x_b + R_b p_b - x_a - R_a p_a)`.
pub fn dot2(fa: &Frame, a0: &Vec3, pa: &Vec3, fb: &Frame, pb: &Vec3) -> Primitive {
    let (ra, rb) = (&fa.r, &fb.r);
    let a = ra * a0;
    let r = fb.x + rb * pb - fa.x;
    let d = r - ra * pa;
    let at = hat(a0);
    let pbt = hat(pb);
    let rat = ra.transpose();
    let mut g = Vec12::zeros();
    g.fixed_rows_mut::<3>(0).copy_from(&(-a));
    g.fixed_rows_mut::<3>(3).copy_from(&a0.cross(&(rat * r)));
    g.fixed_rows_mut::<3>(6).copy_from(&a);
    g.fixed_rows_mut::<3>(9)
        .copy_from(&pb.cross(&(rb.transpose() * a)));
    let mut h = Mat12::zeros();
    put(&mut h, 0, 3, &(ra * at));
    put(&mut h, 3, 0, &(-at * rat));
    put(&mut h, 3, 3, &(at * hat(&(rat * r))));
    put(&mut h, 3, 6, &(at * rat));
    put(&mut h, 3, 9, &(-at * rat * rb * pbt));
    put(&mut h, 6, 3, &(-ra * at));
    put(&mut h, 9, 3, &(-pbt * rb.transpose() * ra * at));
    put(&mut h, 9, 9, &(pbt * hat(&(rb.transpose() * a))));
    Primitive {
        phi: a.dot(&d),
        g,
        h,
    }
}
