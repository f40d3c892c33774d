//! Property tests of the Lie group operators: exp/log round trips (including near 0 and pi),
//! the tangent operator against central differences of exp, group axioms, adjoint identities.

use flexmb_lie::{se3, so3, Frame, Group, Mat3, Mat6, Vec3, Vec6};

/// Deterministic pseudo-random numbers in [-1, 1) (no external crate needed).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }
    fn vec3(&mut self, scale: f64) -> Vec3 {
        Vec3::new(self.next(), self.next(), self.next()) * scale
    }
    fn vec6(&mut self, st: f64, sr: f64) -> Vec6 {
        let (u, t) = (self.vec3(st), self.vec3(sr));
        Vec6::new(u.x, u.y, u.z, t.x, t.y, t.z)
    }
}

/// Rotation vectors spanning tiny, moderate and near-pi angles.
fn rotation_samples() -> Vec<Vec3> {
    let mut rng = Lcg(7);
    let mut out = vec![Vec3::zeros()];
    for &angle in &[
        1e-12,
        1e-7,
        1e-5,
        1e-3,
        0.3,
        1.0,
        2.5,
        3.0,
        3.1,
        std::f64::consts::PI - 1e-9,
    ] {
        for _ in 0..4 {
            let axis = rng.vec3(1.0).normalize();
            out.push(axis * angle);
        }
    }
    out
}

#[test]
fn so3_exp_is_orthonormal_and_log_inverts_it() {
    for theta in rotation_samples() {
        let r = so3::exp(&theta);
        assert!((r.transpose() * r - Mat3::identity()).norm() < 1e-14);
        assert!((r.determinant() - 1.0).abs() < 1e-14);
        let back = so3::log(&r);
        assert!(
            (back - theta).norm() < 1e-9 * (1.0 + theta.norm()),
            "{theta:?} -> {back:?}"
        );
        // log(exp) reproduces the rotation even where the vector is ambiguous (pi).
        assert!((so3::exp(&back) - r).norm() < 1e-13);
    }
}

#[test]
fn so3_log_is_accurate_at_exactly_pi() {
    for axis in [
        Vec3::x(),
        Vec3::y(),
        Vec3::z(),
        Vec3::new(1.0, 1.0, 1.0).normalize(),
    ] {
        let r = so3::exp(&(axis * std::f64::consts::PI));
        let t = so3::log(&r);
        assert!((t.norm() - std::f64::consts::PI).abs() < 1e-12);
        assert!((so3::exp(&t) - r).norm() < 1e-12);
    }
}

#[test]
fn so3_tangent_matches_central_differences_of_exp() {
    let eps = 1e-6;
    for theta in rotation_samples() {
        if theta.norm() > 3.0 {
            continue;
        }
        let r = so3::exp(&theta);
        let t = so3::tangent(&theta);
        for k in 0..3 {
            let mut e = Vec3::zeros();
            e[k] = eps;
            // exp(theta)^T exp(theta + d) = exp(T d)  =>  column k of T by differences.
            let plus = so3::log(&(r.transpose() * so3::exp(&(theta + e))));
            let minus = so3::log(&(r.transpose() * so3::exp(&(theta - e))));
            let col = (plus - minus) / (2.0 * eps);
            assert!((col - t.column(k)).norm() < 1e-8, "theta {theta:?} k {k}");
        }
        let ti = so3::tangent_inv(&theta);
        assert!((t * ti - Mat3::identity()).norm() < 1e-11);
    }
}

#[test]
fn so3_quaternion_round_trip() {
    for theta in rotation_samples() {
        let r = so3::exp(&theta);
        let q = so3::to_quaternion(&r);
        assert!((so3::from_quaternion(q) - r).norm() < 1e-14);
        assert!(q[0] >= 0.0);
    }
}

fn groups() -> [Group; 2] {
    [Group::R3xSO3, Group::SE3]
}

fn frame_close(a: &Frame, b: &Frame, tol: f64) -> bool {
    (a.x - b.x).norm() < tol && (a.r - b.r).norm() < tol
}

#[test]
fn group_exp_log_round_trip() {
    let mut rng = Lcg(11);
    for g in groups() {
        for theta in rotation_samples() {
            let u = rng.vec3(2.0);
            let w = Vec6::new(u.x, u.y, u.z, theta.x, theta.y, theta.z);
            let h = g.exp(&w);
            let back = g.log(&h);
            assert!(
                (back - w).norm() < 1e-8 * (1.0 + w.norm()),
                "{g:?} {w:?} {back:?}"
            );
        }
    }
}

#[test]
fn group_axioms_hold() {
    let mut rng = Lcg(3);
    for g in groups() {
        for _ in 0..50 {
            let a = g.exp(&rng.vec6(2.0, 3.0));
            let b = g.exp(&rng.vec6(2.0, 3.0));
            let c = g.exp(&rng.vec6(2.0, 3.0));
            // associativity
            let l = g.compose(&g.compose(&a, &b), &c);
            let r = g.compose(&a, &g.compose(&b, &c));
            assert!(frame_close(&l, &r, 1e-12));
            // identity and inverse
            assert!(frame_close(&g.compose(&a, &Frame::identity()), &a, 1e-15));
            assert!(frame_close(
                &g.compose(&a, &g.inverse(&a)),
                &Frame::identity(),
                1e-13
            ));
            // difference / integrate are inverse operations
            let d = g.difference(&a, &b);
            assert!(frame_close(&g.integrate(&a, &d), &b, 1e-12));
            // exp(s w) exp(t w) = exp((s + t) w): one-parameter subgroups
            let w = rng.vec6(1.0, 1.0);
            let lhs = g.compose(&g.exp(&(w * 0.3)), &g.exp(&(w * 0.5)));
            assert!(frame_close(&lhs, &g.exp(&(w * 0.8)), 1e-13));
        }
    }
}

#[test]
fn group_tangent_matches_central_differences_of_exp() {
    let mut rng = Lcg(5);
    let eps = 1e-6;
    for g in groups() {
        let mut samples: Vec<Vec6> = (0..20).map(|_| rng.vec6(2.0, 1.5)).collect();
        samples.push(Vec6::zeros());
        samples.push(Vec6::new(0.3, -0.2, 0.5, 1e-9, 2e-9, -1e-9));
        samples.push(Vec6::new(0.3, -0.2, 0.5, 1e-5, 2e-5, -1e-5));
        samples.push(Vec6::new(1.0, 2.0, 3.0, 0.0, 0.0, 2.9));
        for w in samples {
            let h = g.exp(&w);
            let t = g.tangent(&w);
            for k in 0..6 {
                let mut e = Vec6::zeros();
                e[k] = eps;
                let plus = g.difference(&h, &g.exp(&(w + e)));
                let minus = g.difference(&h, &g.exp(&(w - e)));
                let col = (plus - minus) / (2.0 * eps);
                assert!(
                    (col - t.column(k)).norm() < 1e-7 * (1.0 + w.norm()),
                    "{g:?} w {w:?} k {k}: fd {col:?} vs {:?}",
                    t.column(k)
                );
            }
            let ti = g.tangent_inv(&w);
            assert!((t * ti - Mat6::identity()).norm() < 1e-10);
        }
    }
}

#[test]
fn se3_adjoint_identities() {
    let mut rng = Lcg(9);
    for _ in 0..30 {
        let h = se3::exp(&rng.vec6(2.0, 2.0));
        let w = rng.vec6(0.5, 0.5);
        // H exp(w) H^-1 = exp(Ad(H) w)
        let lhs = h.compose(&se3::exp(&w)).compose(&h.inverse());
        let rhs = se3::exp(&(se3::big_ad(&h) * w));
        assert!(frame_close(&lhs, &rhs, 1e-12));
        // ad(a) a = 0 and antisymmetry of the bracket
        let a = rng.vec6(1.0, 1.0);
        let b = rng.vec6(1.0, 1.0);
        assert!((se3::ad(&a) * a).norm() < 1e-15);
        assert!((se3::ad(&a) * b + se3::ad(&b) * a).norm() < 1e-14);
        // T(w) w = w (the tangent operator leaves the generator unchanged)
        assert!((se3::tangent(&a) * a - a).norm() < 1e-14);
    }
}
