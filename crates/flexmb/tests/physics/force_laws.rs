//! Force elements with nonlinear laws against analytic solutions: a mass bouncing on a bump
//! stop (the period of a piecewise-linear oscillator), the static deflection of a mass
//! under a load on a table and on a polynomial spring (the inverse of the law); the example
//! `bump_stop.toml`.

use flexmb::model::{
    ForceCurve, Load, LoadFrame, Model, NodeId, SpringDamper, SpringLaw, SpringSide, TimeFunction,
};
use flexmb::solve::{StaticSettings, Statics};
use flexmb::{DynamicSettings, Simulation};
use flexmb_lie::{Frame, Group, Mat3, Vec3};
use std::f64::consts::PI;

use crate::common;

/// A spring from the ground point `(-1, 0, 0)` to the origin of node `n`, along x.
fn spring_along_x(name: &str, n: NodeId, stiffness: f64, rest_length: f64) -> SpringDamper {
    SpringDamper {
        name: name.into(),
        node_a: None,
        node_b: Some(n),
        point_a: Vec3::new(-1.0, 0.0, 0.0),
        point_b: Vec3::zeros(),
        stiffness,
        damping: 0.0,
        rest_length,
        relaxation: None,
    }
}

/// Upward zero crossings of `x(t)`, linearly interpolated.
fn upward_crossings(history: &[(f64, f64)]) -> Vec<f64> {
    history
        .windows(2)
        .filter(|w| w[0].1 < 0.0 && w[1].1 >= 0.0)
        .map(|w| w[0].0 + (-w[0].1) / (w[1].1 - w[0].1) * (w[1].0 - w[0].0))
        .collect()
}

#[test]
fn mass_on_a_bump_stop_has_the_piecewise_linear_period() {
    // A mass m on a spring k1 (free length 1, x = 0 at rest) and a bump stop k2 that engages
    // after a gap delta (a one-sided spring of free length 1 - delta), released at rest from
    // x = A > delta. Reference (the piecewise-linear oscillator: two harmonic arcs matched at
    // the contact, e.g. Den Hartog, Mechanical Vibrations, the chapter on systems with
    // nonlinear springs; derived here): above x = -delta the motion is x = A cos(w1 t),
    // w1 = sqrt(k1/m), reaching -delta at speed w1 sqrt(A^2 - delta^2) after
    // acos(-delta/A)/w1; below, harmonic with w2 = sqrt((k1+k2)/m) about
    // x_e = -k2 delta/(k1+k2), entering at y0 = -delta - x_e with amplitude
    // B = sqrt(y0^2 + (v/w2)^2) and leaving after (2 pi - 2 acos(y0/B))/w2. So
    //   T = 2 acos(-delta/A)/w1 + 2 (pi - acos(y0/B))/w2.
    let (m, k1, k2, delta, a): (f64, f64, f64, f64, f64) = (1.0, 100.0, 900.0, 0.05, 0.1);
    let (w1, w2) = ((k1 / m).sqrt(), ((k1 + k2) / m).sqrt());
    let v = w1 * (a * a - delta * delta).sqrt();
    let xe = -k2 * delta / (k1 + k2);
    let y0 = -delta - xe;
    let b = (y0 * y0 + (v / w2) * (v / w2)).sqrt();
    let period = 2.0 * (-delta / a).acos() / w1 + 2.0 * (PI - (y0 / b).acos()) / w2;

    for group in [Group::SE3, Group::R3xSO3] {
        let mut model = Model::new(group);
        let n = model.add_node("mass", Frame::new(Vec3::new(a, 0.0, 0.0), Mat3::identity()));
        model.add_body("mass", n, m, Vec3::zeros(), Mat3::identity() * 1e-3);
        model.springs.push(spring_along_x("spring", n, k1, 1.0));
        model
            .springs
            .push(spring_along_x("bump", n, k2, 1.0 - delta));
        let mut law = SpringLaw::new(1);
        law.law.acts = SpringSide::Compression;
        model.spring_laws.push(law);
        let mut s = DynamicSettings::new(4.0 * period, 2e-4);
        s.newton.rtol = 1e-12;
        s.newton.atol = 1e-15;
        let mut sim = Simulation::new(&model, s).expect("starts");
        let mut x = vec![];
        sim.run(&mut |s: &flexmb::observe::Sample| {
            x.push((s.state.t, s.state.q[0].x.x));
            Ok(())
        })
        .expect("runs");
        let c = upward_crossings(&x);
        let measured = (c[c.len() - 1] - c[0]) / (c.len() - 1) as f64;
        let lowest = x.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
        println!(
            "{group:?}: bump-stop period {measured:.6} s vs {period:.6} s (error {:.2e}); lowest x {lowest:.5} vs {:.5}",
            measured / period - 1.0,
            xe - b
        );
        assert!(
            (measured / period - 1.0).abs() < 1e-4,
            "period {measured} vs {period}"
        );
        assert!(
            (lowest - (xe - b)).abs() < 1e-4 * a,
            "lowest point {lowest} vs {}",
            xe - b
        );
    }
}

/// The static position of a mass pulled along x by `force` on a spring of free length 1 with
/// the law `law` (spring 0).
fn static_elongation(law: SpringLaw, force: f64) -> f64 {
    let mut model = Model::new(Group::SE3);
    let n = model.add_node("mass", Frame::identity());
    model.add_body("mass", n, 1.0, Vec3::zeros(), Mat3::identity() * 1e-3);
    model.springs.push(spring_along_x("spring", n, 0.0, 1.0));
    model.spring_laws.push(law);
    // only the translation along x is free
    let along_x = flexmb::model::frame_from_axis(&Vec3::x(), None);
    let prismatic = flexmb::model::JointKind::Prismatic;
    model.add_joint(
        "slide",
        prismatic,
        None,
        Some(n),
        Vec3::zeros(),
        along_x,
        None,
    );
    model.loads.push(Load {
        name: "pull".into(),
        node: n,
        force: Vec3::new(force, 0.0, 0.0),
        torque: Vec3::zeros(),
        frame: LoadFrame::Inertial,
        function: TimeFunction::Constant { value: 1.0 },
        input: None,
    });
    let mut settings = StaticSettings::new();
    settings.initial_increment = 0.25;
    settings.newton.rtol = 1e-12;
    settings.newton.atol = 1e-14;
    let mut statics = Statics::new(&model, settings).expect("starts");
    statics
        .run(&mut |_: &flexmb::observe::Sample| Ok(()))
        .expect("converges");
    statics.state.q[0].x.x
}

#[test]
fn static_elongation_inverts_the_table_and_the_polynomial_law() {
    // Table: T(e) piecewise linear through (0, 0), (0.01, 100), (0.03, 1100) N, preload 20 N:
    // under 620 N, 620 - 20 = 600 N lies on the second segment (slope 5e4 N/m):
    // e = 0.01 + (600 - 100) / 5e4 = 0.02 m.
    let mut law = SpringLaw::new(0);
    law.law.preload = 20.0;
    law.law.curve = Some(ForceCurve::Table(vec![
        (0.0, 0.0),
        (0.01, 100.0),
        (0.03, 1100.0),
    ]));
    let e = static_elongation(law, 620.0);
    println!("table: e = {e:.12} (0.02)");
    assert!((e - 0.02).abs() < 1e-10, "table: e = {e}");
    // Polynomial in extension T = 1000 e + 2e5 e^3 (a hardening spring), a linear one of
    // 500 N/m in compression: under 300 N, e = 0.1 m (1000 * 0.1 + 2e5 * 0.1^3 = 300, the
    // only real root: T is increasing).
    let mut law = SpringLaw::new(0);
    law.law.extension = Some(ForceCurve::Polynomial(vec![1000.0, 0.0, 2e5]));
    law.law.compression = Some(ForceCurve::Polynomial(vec![500.0]));
    let e = static_elongation(law.clone(), 300.0);
    println!("polynomial, extension: e = {e:.12} (0.1)");
    assert!((e - 0.1).abs() < 1e-10, "polynomial: e = {e}");
    // and the compression side under -50 N: 500 e = -50, e = -0.1 m
    let e = static_elongation(law, -50.0);
    println!("polynomial, compression: e = {e:.12} (-0.1)");
    assert!(
        (e + 0.1).abs() < 1e-10,
        "polynomial in compression: e = {e}"
    );
}

#[test]
fn bump_stop_example_contacts_within_the_energy_bound_and_settles_at_the_free_length() {
    let h = common::run("bump_stop.toml", &[]);
    let (z, bump) = (h.series("z"), h.series("bump_force"));
    // The stop pushes only while the points are closer than its free length, 0.25 m.
    for (&(t, zi), &(_, f)) in z.iter().zip(&bump) {
        assert!(f <= 0.0, "t = {t}: the stop pulls ({f} N)");
        if zi > 0.25 {
            assert_eq!(f, 0.0, "t = {t}: force {f} N off contact (z = {zi})");
        }
    }
    let lowest = z.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
    assert!(lowest < 0.25, "the stop is reached: lowest z {lowest}");
    // Without damping the lowest point would be at the depth d where the kinetic energy
    // 0.5 * 300 * 1.5^2 = 337.5 J is stored: the coil's preload cancels the weight's work, so
    // 1.5e4 d^2 + 1e4 s^2 + 1.25e7 s^4 = 337.5 with s = d - 0.05 (the stop's
    // integral_0^e F for F = 2e4 e + 5e7 e^3). With damping the mass stops higher.
    let energy = |d: f64| {
        let s = (d - 0.05).max(0.0);
        1.5e4 * d * d + 1e4 * s * s + 1.25e7 * s.powi(4) - 337.5
    };
    let (mut lo, mut hi) = (0.0, 0.15);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if energy(mid) > 0.0 {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    println!(
        "lowest z {lowest:.4} m, above the undamped bound {:.4} m",
        0.3 - lo
    );
    assert!(
        lowest > 0.3 - lo,
        "lowest z {lowest} below the energy bound {}",
        0.3 - lo
    );
    // Settled at the free length, the coil holding the weight.
    let (z_end, coil) = (h.last("z"), h.last("coil_force"));
    println!("end: z {z_end:.6} m, coil force {coil:.2} N");
    assert!((z_end - 0.3).abs() < 1e-4, "z {z_end}");
    assert!((coil + 2943.0).abs() < 5.0, "coil force {coil}");
}

/// The angle of a node's x axis about the inertial z axis, unwrapped along a history.
fn unwrapped_angles(history: &[(f64, Mat3)]) -> Vec<(f64, f64)> {
    let mut out: Vec<(f64, f64)> = Vec::new();
    for (t, r) in history {
        let raw = r[(1, 0)].atan2(r[(0, 0)]);
        let angle = match out.last() {
            Some(&(_, last)) => last + (raw - last + PI).rem_euclid(2.0 * PI) - PI,
            None => raw,
        };
        out.push((*t, angle));
    }
    out
}

#[test]
fn torsional_pendulum_wound_over_turns_has_frequency_sqrt_k_over_j() {
    // A disk of polar moment J on a revolute joint to the ground with a rotational spring k
    // about its axis: J theta'' + k theta = 0, omega = sqrt(k / J) at any amplitude (the
    // torsional pendulum, e.g. S. S. Rao, Mechanical Vibrations, the torsional system of one
    // degree of freedom). Started at theta = 0 with theta' = 20 rad/s, it swings to
    // +-theta' / omega = +-10 rad, more than a turn and a half each way: the spring must
    // follow the angle over the turns (the element's state), not its value in (-pi, pi].
    use flexmb::model::{frame_from_axis, ForceLaw, JointKind, RotationalSpring};
    let (k, j, spin): (f64, f64, f64) = (2.0, 0.5, 20.0);
    let omega = (k / j).sqrt();
    for group in [Group::SE3, Group::R3xSO3] {
        let mut model = Model::new(group);
        let n = model.add_node("disk", Frame::identity());
        model.nodes[n.0].angular_velocity = Vec3::new(0.0, 0.0, spin);
        let inertia = Mat3::from_diagonal(&Vec3::new(0.3, 0.3, j));
        model.add_body("disk", n, 2.0, Vec3::zeros(), inertia);
        let axis = frame_from_axis(&Vec3::z(), None);
        let hinge = model.add_joint(
            "hinge",
            JointKind::Revolute,
            None,
            Some(n),
            Vec3::zeros(),
            axis,
            None,
        );
        model.rotational_springs.push(RotationalSpring {
            name: "torsion".into(),
            joint: hinge,
            stiffness: k,
            damping: 0.0,
            angle: 0.0,
            law: ForceLaw::default(),
        });
        let period = 2.0 * PI / omega;
        let mut s = DynamicSettings::new(5.0 * period, 1e-3);
        s.newton.rtol = 1e-12;
        s.newton.atol = 1e-14;
        let mut sim = Simulation::new(&model, s).expect("starts");
        let mut history = vec![];
        sim.run(&mut |s: &flexmb::observe::Sample| {
            history.push((s.state.t, s.state.q[0].r));
            Ok(())
        })
        .expect("runs");
        let theta = unwrapped_angles(&history);
        let c = upward_crossings(&theta);
        let measured = (c[c.len() - 1] - c[0]) / (c.len() - 1) as f64;
        let highest = theta.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max);
        let lowest = theta.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
        println!(
            "{group:?}: period {measured:.7} s vs 2 pi sqrt(J/k) = {period:.7} s (error {:.2e}); swing {lowest:.5} .. {highest:.5} rad vs +-{:.5}",
            measured / period - 1.0,
            spin / omega
        );
        assert!(
            (measured / period - 1.0).abs() < 1e-5,
            "period {measured} vs {period}"
        );
        for extreme in [highest, -lowest] {
            assert!(
                (extreme - spin / omega).abs() < 1e-4 * spin / omega,
                "amplitude {extreme}"
            );
        }
    }
}

#[test]
fn torsion_pendulum_example_follows_the_turns_and_conserves_energy() {
    // examples/torsion_pendulum.toml: k = 2 N m/rad, J = 0.5 kg m^2, theta'(0) = 20 rad/s:
    // amplitude 10 rad, energy 1/2 J theta'^2 = 100 J; the torque sensor is k theta over the
    // turns (the joint_coordinate sensor unwraps the angle on its own, independently of the
    // element's state).
    let h = common::run("torsion_pendulum.toml", &[]);
    let (angle, torque, energy) = (h.series("angle"), h.series("torque"), h.series("energy"));
    let highest = angle.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max);
    let lowest = angle.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
    println!("swing {lowest:.6} .. {highest:.6} rad");
    // the outputs every 0.01 s sample the turning points within 1 - cos(0.01) = 5e-5
    assert!((highest - 10.0).abs() < 1e-3 && (lowest + 10.0).abs() < 1e-3);
    for (&(t, a), &(_, m)) in angle.iter().zip(&torque) {
        assert!(
            (m - 2.0 * a).abs() < 1e-9,
            "t = {t}: torque {m} vs k theta {}",
            2.0 * a
        );
    }
    let drift = energy
        .iter()
        .map(|p| (p.1 - 100.0).abs())
        .fold(0.0, f64::max);
    println!("largest energy error {drift:.3e} J");
    assert!(drift < 1e-5, "energy drift {drift}");
}
