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

use crate::kernel::{Mat12, Vec12};
use flexmb_lie::{so3::hat, Frame, Mat3, Vec3};

/// Value, gradient and gradient derivative of a scalar constraint.
#[derive(Clone, Copy, Debug)]
pub struct Primitive {
    pub phi: f64,
    pub g: Vec12,
    pub h: Mat12,
}

fn add(h: &mut Mat12, i: usize, j: usize, m: &Mat3) {
    let mut blk = h.fixed_view_mut::<3, 3>(i, j);
    blk += m;
}

/// Dot-1: `phi = (R_a a0) . (R_b b0)`.
pub fn dot1(fa: &Frame, a0: &Vec3, fb: &Frame, b0: &Vec3) -> Primitive {
    let mut h = Mat12::zeros();
    let (phi, g) = dot1_into(fa, a0, fb, b0, 1.0, Some(&mut h));
    Primitive { phi, g, h }
}

/// Dot-1 value and gradient; adds `w H` to `h` when given (no allocation, no full matrix).
pub fn dot1_into(
    fa: &Frame,
    a0: &Vec3,
    fb: &Frame,
    b0: &Vec3,
    w: f64,
    h: Option<&mut Mat12>,
) -> (f64, Vec12) {
    let (ra, rb) = (&fa.r, &fb.r);
    let a = ra * a0;
    let b = rb * b0;
    let b_in_a = ra.transpose() * b;
    let a_in_b = rb.transpose() * a;
    let mut g = Vec12::zeros();
    g.fixed_rows_mut::<3>(3).copy_from(&a0.cross(&b_in_a));
    g.fixed_rows_mut::<3>(9).copy_from(&b0.cross(&a_in_b));
    if let Some(h) = h {
        let (at, bt) = (hat(a0) * w, hat(b0));
        let rab = ra.transpose() * rb;
        add(h, 3, 3, &(at * hat(&b_in_a)));
        add(h, 3, 9, &(-at * rab * bt));
        add(h, 9, 9, &(bt * hat(&a_in_b) * w));
        add(h, 9, 3, &(-bt * rab.transpose() * at));
    }
    (a.dot(&b), g)
}

/// Dot-2: `phi = (R_a a0) . (x_b + R_b p_b - x_a - R_a p_a)`.
pub fn dot2(fa: &Frame, a0: &Vec3, pa: &Vec3, fb: &Frame, pb: &Vec3) -> Primitive {
    let mut h = Mat12::zeros();
    let (phi, g) = dot2_into(fa, a0, pa, fb, pb, 1.0, Some(&mut h));
    Primitive { phi, g, h }
}

/// Dot-2 value and gradient; adds `w H` to `h` when given.
pub fn dot2_into(
    fa: &Frame,
    a0: &Vec3,
    pa: &Vec3,
    fb: &Frame,
    pb: &Vec3,
    w: f64,
    h: Option<&mut Mat12>,
) -> (f64, Vec12) {
    let (ra, rb) = (&fa.r, &fb.r);
    let a = ra * a0;
    let r = fb.x + rb * pb - fa.x;
    let d = r - ra * pa;
    let rat = ra.transpose();
    let a_in_b = rb.transpose() * a;
    let r_in_a = rat * r;
    let mut g = Vec12::zeros();
    g.fixed_rows_mut::<3>(0).copy_from(&(-a));
    g.fixed_rows_mut::<3>(3).copy_from(&a0.cross(&r_in_a));
    g.fixed_rows_mut::<3>(6).copy_from(&a);
    g.fixed_rows_mut::<3>(9).copy_from(&pb.cross(&a_in_b));
    if let Some(h) = h {
        let at = hat(a0) * w;
        let pbt = hat(pb);
        let ra_at = ra * at;
        let at_rat = at * rat;
        add(h, 0, 3, &ra_at);
        add(h, 3, 0, &(-at_rat));
        add(h, 3, 3, &(at * hat(&r_in_a)));
        add(h, 3, 6, &at_rat);
        add(h, 3, 9, &(-at_rat * rb * pbt));
        add(h, 6, 3, &(-ra_at));
        add(h, 9, 3, &(-pbt * rb.transpose() * ra_at));
        add(h, 9, 9, &(pbt * hat(&a_in_b) * w));
    }
    (a.dot(&d), g)
}
