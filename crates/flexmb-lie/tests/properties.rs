//! Property tests of the Lie group operators: exp/log round trips (including near 0 and pi),
//! the tangent operator against central differences of exp, group axioms, adjoint identities.

use flexmb_lie::{se3, so3, Chart, Frame, Group, Mat3, Mat6, Vec3, Vec6};

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

/// Rotation angles at which the beam evaluates `G`: exact zero, the series range, both sides
/// of the series/closed-form switch (|theta| = 1.5) and large angles.
const G_ANGLES: [f64; 10] = [0.0, 1e-9, 1e-5, 1e-3, 0.5, 1.4999, 1.5, 1.5001, 2.8, 3.1];

fn rotation(rng: &mut Lcg, angle: f64) -> Vec3 {
    rng.vec3(1.0).normalize() * angle
}

#[test]
fn so3_tangent_inv_transpose_derivative_matches_central_differences() {
    let mut rng = Lcg(21);
    let eps = 1e-6;
    for &angle in &G_ANGLES {
        for _ in 0..5 {
            let x = rotation(&mut rng, angle);
            let m = rng.vec3(3.0);
            let g = flexmb_lie::tangent_inv_transpose_derivative_so3(&x, &m);
            assert!(g.iter().all(|v| v.is_finite()));
            let f = |y: &Vec3| so3::tangent_inv(y).transpose() * m;
            let mut fd = Mat3::zeros();
            for k in 0..3 {
                let mut e = Vec3::zeros();
                e[k] = eps;
                fd.set_column(k, &((f(&(x + e)) - f(&(x - e))) / (2.0 * eps)));
            }
            assert!(
                (g - fd).norm() < 1e-7 * g.norm().max(1.0),
                "angle {angle}: {g} vs {fd}"
            );
        }
    }
    // Exactly at zero: G(0, m) = 1/2 tilde(m).
    let m = Vec3::new(1.0, -2.0, 0.5);
    let g0 = so3::tangent_inv_transpose_derivative(&Vec3::zeros(), &m);
    assert_eq!(g0, so3::hat(&m) * 0.5);
}

#[test]
fn se3_tangent_inv_transpose_derivative_matches_central_differences() {
    let mut rng = Lcg(23);
    let eps = 1e-6;
    for g in groups() {
        for &angle in &G_ANGLES {
            for _ in 0..6 {
                let theta = rotation(&mut rng, angle);
                let u = rng.vec3(3.0);
                let d = Vec6::new(u.x, u.y, u.z, theta.x, theta.y, theta.z);
                let sigma = rng.vec6(5.0, 2.0);
                let gd = g.tangent_inv_transpose_derivative(&d, &sigma);
                assert!(gd.iter().all(|v| v.is_finite()), "{g:?} angle {angle}");
                if g == Group::SE3 {
                    assert_eq!(gd, se3::tangent_inv_transpose_derivative(&d, &sigma));
                }
                let f = |y: &Vec6| g.tangent_inv(y).transpose() * sigma;
                let mut fd = Mat6::zeros();
                for k in 0..6 {
                    let mut e = Vec6::zeros();
                    e[k] = eps;
                    fd.set_column(k, &((f(&(d + e)) - f(&(d - e))) / (2.0 * eps)));
                }
                let err = (gd - fd).norm() / gd.norm().max(1.0);
                assert!(
                    err < 1e-7,
                    "{g:?} angle {angle}: rel err {err:e}\n{gd}\n{fd}"
                );
            }
        }
    }
}

/// `d(eps) = log((H_A exp(eps_1 a_1) exp(eps_2 a_2))^-1 H_B exp(eps_1 b_1) exp(eps_2 b_2))`,
/// with `z_i = [a_i; b_i]` (12-vectors, node A first).
fn beam_relative_motion(ha: &Frame, hb: &Frame, z: &[(f64, [f64; 12])]) -> Vec6 {
    let (mut a, mut b) = (*ha, *hb);
    for (e, zi) in z {
        let wa = Vec6::from_column_slice(&zi[..6]) * *e;
        let wb = Vec6::from_column_slice(&zi[6..]) * *e;
        a = a.compose(&se3::exp(&wa));
        b = b.compose(&se3::exp(&wb));
    }
    se3::log(&a.inverse().compose(&b))
}

fn beam_p(d: &Vec6) -> nalgebra::SMatrix<f64, 6, 12> {
    let mut p = nalgebra::SMatrix::<f64, 6, 12>::zeros();
    p.fixed_view_mut::<6, 6>(0, 0)
        .copy_from(&(-se3::tangent_inv(&(-d))));
    p.fixed_view_mut::<6, 6>(0, 6)
        .copy_from(&se3::tangent_inv(d));
    p
}

fn unit12(k: usize) -> [f64; 12] {
    let mut z = [0.0; 12];
    z[k] = 1.0;
    z
}

/// Nodes `H_A` (random) and `H_B = H_A exp(d)` with the rotation of `d` of a given angle.
fn beam_nodes(rng: &mut Lcg, angle: f64) -> (Frame, Frame, Vec6) {
    let ha = se3::exp(&rng.vec6(2.0, 2.0));
    let theta = rotation(rng, angle);
    let u = rng.vec3(2.0);
    let d = Vec6::new(u.x, u.y, u.z, theta.x, theta.y, theta.z);
    let hb = ha.compose(&se3::exp(&d));
    let d = se3::log(&ha.inverse().compose(&hb)); // what the beam actually sees
    (ha, hb, d)
}

#[test]
fn beam_relative_motion_variation_is_p_of_d() {
    // delta log(H_A^-1 H_B) = [-T^-1(-d), T^-1(d)] [w_A; w_B].
    let mut rng = Lcg(29);
    let eps = 1e-6;
    for &angle in &G_ANGLES {
        for _ in 0..4 {
            let (ha, hb, d) = beam_nodes(&mut rng, angle);
            let p = beam_p(&d);
            for k in 0..12 {
                let plus = beam_relative_motion(&ha, &hb, &[(eps, unit12(k))]);
                let minus = beam_relative_motion(&ha, &hb, &[(-eps, unit12(k))]);
                let col = (plus - minus) / (2.0 * eps);
                assert!(
                    (col - p.column(k)).norm() < 1e-7 * (1.0 + d.norm()),
                    "angle {angle} k {k}: {col:?} vs {:?}",
                    p.column(k)
                );
            }
        }
    }
}

#[test]
fn beam_geometric_stiffness_matches_second_derivative_of_log() {
    // f(e1, e2) = sigma . d(e1, e2) with the ordered perturbation of `beam_relative_motion`:
    // d f/d e2 at e2 = 0 is sigma^T P(d(e1, 0)) z_2 exactly, so
    // d^2 f/(d e1 d e2) = z_2^T [G(-d, sigma); G(d, sigma)] P(d) z_1.
    let mut rng = Lcg(31);
    let h = 2e-4;
    for &angle in &G_ANGLES {
        for _ in 0..2 {
            let (ha, hb, d) = beam_nodes(&mut rng, angle);
            let sigma = rng.vec6(3.0, 2.0);
            let mut gs = nalgebra::SMatrix::<f64, 12, 6>::zeros();
            gs.fixed_view_mut::<6, 6>(0, 0)
                .copy_from(&se3::tangent_inv_transpose_derivative(&(-d), &sigma));
            gs.fixed_view_mut::<6, 6>(6, 0)
                .copy_from(&se3::tangent_inv_transpose_derivative(&d, &sigma));
            let kg = gs * beam_p(&d);
            let f = |e1: f64, e2: f64, i: usize, j: usize| {
                sigma.dot(&beam_relative_motion(
                    &ha,
                    &hb,
                    &[(e1, unit12(j)), (e2, unit12(i))],
                ))
            };
            let mut fd = nalgebra::SMatrix::<f64, 12, 12>::zeros();
            for i in 0..12 {
                for j in 0..12 {
                    fd[(i, j)] = (f(h, h, i, j) - f(h, -h, i, j) - f(-h, h, i, j)
                        + f(-h, -h, i, j))
                        / (4.0 * h * h);
                }
            }
            let err = (kg - fd).norm() / kg.norm().max(1.0);
            assert!(err < 1e-5, "angle {angle}: rel err {err:e}\n{kg}\n{fd}");
        }
    }
}

#[test]
fn se3_tangent_matches_its_power_series_at_all_angles() {
    // T(x) = sum_k (-ad(x))^k/(k+1)!: an independent reference for the closed forms, in
    // particular for the coupling block in the small-angle range where they cancel.
    let mut rng = Lcg(37);
    for &angle in &[
        0.0, 1e-9, 1.1e-4, 3e-4, 1e-3, 1e-2, 0.3, 1.4999, 1.5001, 2.8, 3.1,
    ] {
        for _ in 0..4 {
            let theta = rotation(&mut rng, angle);
            let u = rng.vec3(2.0);
            let w = Vec6::new(u.x, u.y, u.z, theta.x, theta.y, theta.z);
            let a = -se3::ad(&w);
            let (mut term, mut sum) = (Mat6::identity(), Mat6::identity());
            for k in 1..60 {
                term = term * a / (k as f64 + 1.0);
                sum += term;
            }
            let t = se3::tangent(&w);
            assert!(
                (t - sum).norm() < 1e-14 * (1.0 + w.norm()).powi(2),
                "angle {angle}: {:e}",
                (t - sum).norm()
            );
        }
    }
}

#[test]
fn tangent_rate_matches_central_differences_of_the_tangent() {
    // d/ds [T(w + s x) x] at s = 0, on both groups, from increments of a step (1e-3) to
    // large angles, translations of metres.
    let mut rng = Lcg(41);
    let eps = 1e-6;
    for g in groups() {
        for &angle in &[0.0, 1e-8, 1e-3, 0.02, 0.3, 1.0, 1.49, 1.51, 2.5] {
            for _ in 0..6 {
                let theta = rotation(&mut rng, angle);
                let u = rng.vec3(2.0);
                let w = flexmb_lie::join(&u, &theta);
                let x = rng.vec6(3.0, 5.0);
                let rate = g.tangent_rate(&w, &x);
                let fd =
                    (g.tangent(&(w + x * eps)) * x - g.tangent(&(w - x * eps)) * x) / (2.0 * eps);
                let err = (rate - fd).norm();
                assert!(
                    err < 1e-7 * x.norm_squared(),
                    "{g:?} angle {angle}: {rate:?} against {fd:?} ({err:e})"
                );
            }
        }
        // T(0) = I and dT/dt at 0 along x applied to x is -ad(x) x / 2 = 0.
        let x = rng.vec6(1.0, 1.0);
        assert!(g.tangent_rate(&Vec6::zeros(), &x).norm() < 1e-16);
    }
}

/// Every chart with the group it is used on.
const CHARTS: [(Chart, Group); 3] = [
    (Chart::Exponential(Group::R3xSO3), Group::R3xSO3),
    (Chart::Exponential(Group::SE3), Group::SE3),
    (Chart::TranslationRotation, Group::SE3),
];

#[test]
fn charts_read_velocities_and_accelerations_as_their_maps_say() {
    // For each chart C around q_n: M(theta) is the right-trivialized differential of
    // q_n o C (central differences of log((q_n o C(theta))^-1 q_n o C(theta + e d)) / e),
    // inverse_map inverts it, and along the straight line theta + s x (Theta'' = 0) the
    // body velocity M x changes at the rate N(theta, x).
    let mut rng = Lcg(43);
    let eps = 1e-6;
    for (chart, group) in CHARTS {
        for &angle in &[0.0, 1e-3, 0.05, 0.8, 2.0] {
            for _ in 0..5 {
                let q_n = Frame::new(rng.vec3(2.0), so3::exp(&rng.vec3(1.5)));
                let w = rotation(&mut rng, angle);
                let u = rng.vec3(1.0);
                let theta = flexmb_lie::join(&u, &w);
                let (d, x) = (rng.vec6(1.0, 1.0), rng.vec6(3.0, 5.0));
                let p = chart.point(&q_n, &theta);
                let moved = |e: f64| group.difference(&p, &chart.point(&q_n, &(theta + d * e)));
                let fd = (moved(eps) - moved(-eps)) / (2.0 * eps);
                let m = chart.map(&theta);
                assert!((m * d - fd).norm() < 1e-7, "{chart:?} angle {angle}: M");
                assert!((chart.inverse_map(&theta) * m - Mat6::identity()).norm() < 1e-12);
                let v = |s: f64| chart.map(&(theta + x * s)) * x;
                let rate = (v(eps) - v(-eps)) / (2.0 * eps);
                let n = chart.rate(&theta, &x);
                assert!(
                    (n - rate).norm() < 1e-7 * x.norm_squared(),
                    "{chart:?} angle {angle}: N {n:?} against {rate:?}"
                );
            }
        }
        let q_n = Frame::new(rng.vec3(1.0), so3::exp(&rng.vec3(1.0)));
        assert!(frame_close(&chart.point(&q_n, &Vec6::zeros()), &q_n, 1e-15));
        assert_eq!(chart.map(&Vec6::zeros()), Mat6::identity());
    }
}

#[test]
fn chart_jacobians_match_central_differences_of_the_maps() {
    // Chart::jacobians (dual numbers through the maps' series) against central differences
    // of the closed forms Chart::map and Chart::rate: d(M y)/dtheta, dN/dtheta, dN/dx, from
    // a step's increments to large angles; the transport G and dN(0, x)/dx likewise.
    let mut rng = Lcg(47);
    let eps = 1e-6;
    for (chart, group) in CHARTS {
        for &angle in &[0.0, 1e-3, 0.05, 0.8, 2.0] {
            for _ in 0..4 {
                let theta = flexmb_lie::join(&rng.vec3(1.0), &rotation(&mut rng, angle));
                let x = rng.vec6(3.0, 5.0);
                let ys = [x, rng.vec6(2.0, 4.0), rng.vec6(1.0, 3.0)];
                let j = chart.jacobians(&theta, &x, &ys);
                assert_eq!(j.m, chart.map(&theta));
                let d = rng.vec6(1.0, 1.0);
                let along = |f: &dyn Fn(&Vec6) -> Vec6| {
                    (f(&(theta + d * eps)) - f(&(theta - d * eps))) / (2.0 * eps)
                };
                let scale = 1.0 + x.norm_squared();
                for (k, y) in ys.iter().enumerate() {
                    let fd = along(&|t| chart.map(t) * y);
                    let err = (j.m_theta[k] * d - fd).norm();
                    assert!(
                        err < 1e-7 * scale,
                        "{chart:?} angle {angle}: d(M y)/dtheta {err:e}"
                    );
                }
                let fd = along(&|t| chart.rate(t, &x));
                let err = (j.n_theta * d - fd).norm();
                assert!(
                    err < 1e-7 * scale,
                    "{chart:?} angle {angle}: dN/dtheta {err:e}"
                );
                let fd = (chart.rate(&theta, &(x + d * eps)) - chart.rate(&theta, &(x - d * eps)))
                    / (2.0 * eps);
                let err = (j.n_x * d - fd).norm();
                assert!(err < 1e-7 * scale, "{chart:?} angle {angle}: dN/dx {err:e}");
                // q_n exp(e d) o C(theta) = q_n o C(theta) exp(e G d)
                let q_n = Frame::new(rng.vec3(2.0), so3::exp(&rng.vec3(1.5)));
                let p = chart.point(&q_n, &theta);
                let moved = |e: f64| {
                    group.difference(&p, &chart.point(&group.integrate(&q_n, &(d * e)), &theta))
                };
                let fd = (moved(eps) - moved(-eps)) / (2.0 * eps);
                let err = (chart.transport(group, &theta) * d - fd).norm();
                assert!(err < 1e-7, "{chart:?} angle {angle}: transport {err:e}");
            }
        }
        let x = rng.vec6(2.0, 3.0);
        let d = rng.vec6(1.0, 1.0);
        let n0 = |x: &Vec6| chart.rate(&Vec6::zeros(), x);
        let fd = (n0(&(x + d * eps)) - n0(&(x - d * eps))) / (2.0 * eps);
        assert!((chart.start_rate_derivative(&x) * d - fd).norm() < 1e-8);
    }
}
