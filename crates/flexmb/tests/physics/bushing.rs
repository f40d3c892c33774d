//! The 6-DOF bushing against analytic solutions: the static deflection of a bushing-mounted
//! body under a force (`u = K^-1 F`) and under a large torque about a principal axis
//! (`phi = M / k`, exact for the SE(3)-logarithm law at any angle below pi), and the six
//! natural frequencies of a rigid body on a bushing with a diagonal stiffness at its centre
//! of mass (`sqrt(k_i / m)`, `sqrt(k_(3+i) / J_i)`); the example `engine_mount.toml`.

use flexmb::model::{Bushing, BushingForm, Load, LoadFrame, Model, TimeFunction};
use flexmb::solve::{StaticSettings, Statics};
use flexmb::{DynamicSettings, Simulation};
use flexmb_lie::{so3, Frame, Group, Mat3, Mat6, Vec3, Vec6};
use std::f64::consts::PI;

use crate::common;

const K: [f64; 6] = [2e4, 3e4, 5e4, 800.0, 1500.0, 2800.0];

/// A body of mass 10 kg and inertia diag(0.2, 0.3, 0.5) kg m^2 on a bushing (`form`) from
/// the ground at its centre of mass (frames aligned with the body), loaded at its centre by
/// `force` and `torque` (in `frame`), without gravity.
fn mounted(form: BushingForm, force: Vec3, torque: Vec3, frame: LoadFrame) -> Model {
    mounted_on(Group::SE3, form, force, torque, frame)
}

/// [`mounted`] on `group`.
fn mounted_on(
    group: Group,
    form: BushingForm,
    force: Vec3,
    torque: Vec3,
    frame: LoadFrame,
) -> Model {
    let mut m = Model::new(group);
    let at = Frame::new(
        Vec3::new(0.3, -0.2, 1.0),
        so3::exp(&Vec3::new(0.2, 0.5, -0.4)),
    );
    let n = m.add_node("block", at);
    let inertia = Mat3::from_diagonal(&Vec3::new(0.2, 0.3, 0.5));
    m.add_body("block", n, 10.0, Vec3::zeros(), inertia);
    m.bushings.push(Bushing {
        name: "mount".into(),
        node_a: None,
        node_b: Some(n),
        frame_a: at,
        frame_b: Frame::identity(),
        stiffness: Mat6::from_diagonal(&Vec6::from_column_slice(&K)),
        damping: Mat6::zeros(),
        form,
    });
    m.loads.push(Load {
        name: "load".into(),
        node: n,
        force,
        torque,
        frame,
        function: TimeFunction::Constant { value: 1.0 },
        input: None,
    });
    m
}

/// The static configuration of the block of `mounted`, relative to its initial frame
/// (`A^-1 H`, `A` the bushing frame on the ground).
fn static_deflection(model: &Model) -> Frame {
    let mut settings = StaticSettings::new();
    settings.initial_increment = 0.1;
    settings.newton.rtol = 1e-12;
    settings.newton.atol = 1e-14;
    let mut statics = Statics::new(model, settings).expect("starts");
    statics
        .run(&mut |_: &flexmb::observe::Sample| Ok(()))
        .expect("converges");
    model.nodes[0].frame.inverse().compose(&statics.state.q[0])
}

#[test]
fn static_deflection_under_a_force_is_k_inverse_f() {
    // A pure translation d = (u, 0) of the SE(3)-logarithm law: T^-1(u, 0) =
    // [[I, tilde(u)/2], [0, I]] (Sonneville, Cardona & Brüls 2014, Appendix A, at theta = 0),
    // so the residual of node B, T^-1(d)^T K d, is the force K u and the moment
    // -u x (K u) / 2 (body frame): the law's elastic centre is midway between the frames. Under
    // that force and moment (follower loads), u = K^-1 F exactly, at any size; the moment is
    // of second order in u (a pure force gives K^-1 F to first order).
    let f = Vec3::new(400.0, -900.0, 2500.0);
    let expected = Vec3::new(f.x / K[0], f.y / K[1], f.z / K[2]);
    let moment = -expected.cross(&f) * 0.5;
    let large = BushingForm::LargeRotation;
    let rel = static_deflection(&mounted(large, f, moment, LoadFrame::Body));
    println!("translation {:?} vs K^-1 F {:?}", rel.x, expected);
    assert!((rel.x - expected).norm() < 1e-10 * expected.norm());
    assert!(so3::log(&rel.r).norm() < 1e-12);
    // The small-rotation form's elastic centre is frame B's origin: the force alone holds
    // u = K^-1 F (its delta u = R_rel U_B, and R_rel = I).
    let small = BushingForm::SmallRotation;
    let rel = static_deflection(&mounted(small, f, Vec3::zeros(), LoadFrame::Body));
    println!("small-rotation form: translation {:?}", rel.x);
    assert!((rel.x - expected).norm() < 1e-10 * expected.norm());
    assert!(so3::log(&rel.r).norm() < 1e-12);
}

#[test]
fn static_rotation_under_a_large_torque_is_m_over_k() {
    // A torque M about the bushing's z axis (dead or follower: about z both stay on z): the
    // deformation is d = (0, phi e_z) and T^-1(d)^T K d = K d (T(theta) theta = theta), so
    // phi = M / k_rz exactly, here 2 rad (115 degrees). The same about x (1.2 rad) and y
    // (2.8 rad, 160 degrees).
    // The small-rotation form gives the same (T^-1(phi)^T phi = phi on SO(3) as well).
    let forms = [BushingForm::LargeRotation, BushingForm::SmallRotation];
    for (form, (axis, k, phi)) in forms
        .into_iter()
        .flat_map(|f| [(2, K[5], 2.0), (0, K[3], 1.2), (1, K[4], 2.8)].map(|c| (f, c)))
    {
        let mut torque = Vec3::zeros();
        torque[axis] = k * phi;
        let rel = static_deflection(&mounted(form, Vec3::zeros(), torque, LoadFrame::Body));
        let rotation = so3::log(&rel.r);
        let mut expected = Vec3::zeros();
        expected[axis] = phi;
        println!(
            "axis {axis}: rotation {rotation:?} vs M/k {expected:?}, translation {:?}",
            rel.x
        );
        assert!(
            (rotation - expected).norm() < 1e-10,
            "rotation {rotation:?}"
        );
        assert!(rel.x.norm() < 1e-12, "translation {:?}", rel.x);
    }
}

/// Upward zero crossings of a sampled signal.
fn upward_crossings(t: &[f64], x: &[f64]) -> Vec<f64> {
    (1..x.len())
        .filter(|&i| x[i - 1] < 0.0 && x[i] >= 0.0)
        .map(|i| t[i - 1] + (-x[i - 1]) / (x[i] - x[i - 1]) * (t[i] - t[i - 1]))
        .collect()
}

#[test]
fn bushing_mounted_body_has_the_six_natural_frequencies() {
    // Diagonal K at the centre of mass, bushing frame along the principal axes: six decoupled
    // oscillators, omega_i = sqrt(k_i / m) (translations) and sqrt(k_(3+i) / J_i)
    // (rotations) (a rigid body on a linear 6x6 mount: the eigenvalues of M^-1 K with
    // M = diag(m, m, m, J1, J2, J3); e.g. Harris' Shock and Vibration Handbook, the chapter on
    // vibration isolation of rigid bodies on resilient supports). Each mode is excited alone
    // by a small initial velocity (amplitude about 1e-5 m or rad: the coupling of finite
    // rotations is far below the tolerance) and its period measured from the response.
    let (m, j) = (10.0, [0.2, 0.3, 0.5]);
    let mass = [m, m, m, j[0], j[1], j[2]];
    let cases = [
        (Group::SE3, BushingForm::LargeRotation),
        (Group::SE3, BushingForm::SmallRotation),
        (Group::R3xSO3, BushingForm::LargeRotation),
        (Group::R3xSO3, BushingForm::SmallRotation),
    ];
    for ((group, form), mode) in cases.into_iter().flat_map(|c| (0..6).map(move |m| (c, m))) {
        let omega = (K[mode] / mass[mode]).sqrt();
        let zero = Vec3::zeros();
        let mut model = mounted_on(group, form, zero, zero, LoadFrame::Body);
        let r = model.nodes[0].frame.r;
        if mode < 3 {
            model.nodes[0].velocity = r.column(mode) * (1e-5 * omega);
        } else {
            model.nodes[0].angular_velocity[mode - 3] = 1e-5 * omega;
        }
        let period = 2.0 * PI / omega;
        let h = period / 400.0;
        let mut s = DynamicSettings::new(6.0 * period, h);
        s.rho_inf = 1.0;
        s.newton.rtol = 1e-12;
        s.newton.atol = 1e-16;
        let mut sim = Simulation::new(&model, s).expect("starts");
        let (mut t, mut x) = (vec![], vec![]);
        let start = model.nodes[0].frame;
        sim.run(&mut |s: &flexmb::observe::Sample| {
            let rel = start.inverse().compose(&s.state.q[0]);
            let value = if mode < 3 {
                rel.x[mode]
            } else {
                so3::log(&rel.r)[mode - 3]
            };
            t.push(s.state.t);
            x.push(value);
            Ok(())
        })
        .expect("runs");
        let c = upward_crossings(&t, &x);
        let measured = (c[c.len() - 1] - c[0]) / (c.len() - 1) as f64;
        // generalized-alpha with rho_inf = 1 (trapezoidal) lengthens the period by
        // (omega h)^2 / 12 (Chung & Hulbert 1993)
        let expected = period * (1.0 + (omega * h).powi(2) / 12.0);
        println!(
            "{group:?}, {form:?}, mode {mode}: period {measured:.8} s vs {expected:.8} s (2 pi / omega = {period:.8}), error {:.2e}",
            measured / expected - 1.0
        );
        assert!(
            (measured / expected - 1.0).abs() < 1e-5,
            "{group:?} {form:?}, mode {mode}"
        );
    }
}

#[test]
fn engine_on_four_mounts_settles_at_the_static_sag() {
    // examples/engine_mount.toml: by symmetry each mount deflects in pure vertical
    // translation, where the law is exactly K d: sag m g / (4 k_z), mount force -m g / 4.
    let h = common::run("engine_mount.toml", &[]);
    let sag = 0.5 - h.last("z");
    let expected = 150.0 * 9.81 / (4.0 * 3e5);
    let force = h.last("mount_fz");
    println!(
        "sag {sag:.7e} m vs {expected:.7e}; mount force {force:.3} N vs {:.3}",
        -150.0 * 9.81 / 4.0
    );
    assert!((sag / expected - 1.0).abs() < 1e-4, "sag {sag}");
    assert!(
        (force / (-150.0 * 9.81 / 4.0) - 1.0).abs() < 1e-4,
        "force {force}"
    );
}
