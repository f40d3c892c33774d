//! Static large-rotation beam problems against analytic and published references.

use flexmb::model::{BeamSection, Load, LoadFrame, Model, TimeFunction};
use flexmb::solve::{StaticSettings, Statics};
use flexmb_lie::{Frame, Group, Mat3, Vec3};
use std::f64::consts::PI;

/// Straight cantilever along x of length `l` with `n` elements, clamped at the origin.
fn cantilever(l: f64, n: usize, section: &BeamSection) -> (Model, flexmb::model::NodeId) {
    let mut m = Model::new(Group::SE3);
    let root = m.add_node("root", Frame::identity());
    let ids = m.add_straight_beam(
        "beam",
        root,
        Vec3::new(l, 0.0, 0.0),
        None,
        n,
        &Vec3::z(),
        section,
    );
    m.add_joint(
        "clamp",
        flexmb::model::JointKind::Fixed,
        None,
        Some(root),
        Vec3::zeros(),
        Mat3::identity(),
        None,
    );
    (m, *ids.last().expect("tip"))
}

/// Roll-up of a cantilever by an end moment M = 2 pi EI / L (Simo & Vu-Quoc 1986; exact
/// solution: a circle of radius EI/M, benchmarks.md Sect. 4.1). The two-node SE(3) element
/// represents constant curvature exactly, so the discrete solution is exact for any mesh.
#[test]
fn cantilever_rolls_up_into_a_full_circle() {
    let (l, ei) = (1.0, 2.0);
    let section = BeamSection::diagonal([1e4, 1e4, 1e4, 2.0, ei, ei], 1.0, [0.1, 0.05, 0.05]);
    let (mut model, tip) = cantilever(l, 10, &section);
    let m = 2.0 * PI * ei / l;
    model.loads.push(Load {
        name: "moment".into(),
        node: tip,
        force: Vec3::zeros(),
        torque: Vec3::new(0.0, -m, 0.0),
        frame: LoadFrame::Body,
        function: TimeFunction::Constant { value: 1.0 },
    });
    let mut settings = StaticSettings::new();
    settings.initial_increment = 0.25;
    let mut statics = Statics::new(&model, settings).expect("starts");
    let mut checked = 0;
    statics
        .run(&mut |s| {
            let lam = s.load_factor;
            let x = s.state.q[tip.0].x;
            let (ex, ez) = if lam == 0.0 {
                (l, 0.0)
            } else {
                let rho = l / (2.0 * PI * lam);
                (
                    rho * (2.0 * PI * lam).sin(),
                    rho * (1.0 - (2.0 * PI * lam).cos()),
                )
            };
            assert!(
                (x.x - ex).abs() < 1e-8 && (x.z - ez).abs() < 1e-8 && x.y.abs() < 1e-10,
                "lambda {lam}: tip {x:?} vs ({ex}, {ez})"
            );
            checked += 1;
            Ok(())
        })
        .expect("converges");
    assert!((statics.load_factor - 1.0).abs() < 1e-12);
    let tip_q = statics.state.q[tip.0];
    assert!(tip_q.x.norm() < 1e-8, "tip back at the root: {:?}", tip_q.x);
    assert!(
        (tip_q.r - Mat3::identity()).norm() < 1e-8,
        "tip rotation 2 pi"
    );
    assert!(checked >= 5);
    println!(
        "roll-up: {} steps, {} Newton iterations",
        statics.stats.steps, statics.stats.newton_iterations
    );
}

/// 45 degree bend (Bathe & Bolourchi 1979): arc of radius 100 in the x-y plane, tip force
/// in z. Continuum reference (variant A: EA = 1e7, EI = 833 333, GJ = 833 333, GA = 5e6),
/// benchmarks.md Sect. 4.2: tip at P = 600 (47.1504, 15.6848, 53.4749).
#[test]
fn bathe_bolourchi_bend_matches_continuum_reference() {
    let section = BeamSection::diagonal(
        [1e7, 5e6, 5e6, 833_333.0, 833_333.0, 833_333.0],
        1.0,
        [1.0, 0.5, 0.5],
    );
    let (r, n) = (100.0, 32);
    let mut m = Model::new(Group::SE3);
    let frame = |phi: f64| {
        let x = Vec3::new(phi.cos(), phi.sin(), 0.0);
        let z = Vec3::z();
        Mat3::from_columns(&[x, z.cross(&x), z])
    };
    let point = |phi: f64| Vec3::new(r * phi.sin(), r * (1.0 - phi.cos()), 0.0);
    let mut ids = vec![];
    for i in 0..=n {
        let phi = PI / 4.0 * i as f64 / n as f64;
        ids.push(m.add_node(&format!("n{i}"), Frame::new(point(phi), frame(phi))));
    }
    for i in 0..n {
        let (p0, p1) = (
            PI / 4.0 * i as f64 / n as f64,
            PI / 4.0 * (i + 1) as f64 / n as f64,
        );
        m.add_beam(
            &format!("e{i}"),
            [ids[i], ids[i + 1]],
            section.clone(),
            [frame(p0), frame(p1)],
        );
    }
    m.add_joint(
        "clamp",
        flexmb::model::JointKind::Fixed,
        None,
        Some(ids[0]),
        Vec3::zeros(),
        Mat3::identity(),
        None,
    );
    let tip = ids[n];
    m.loads.push(Load {
        name: "p".into(),
        node: tip,
        force: Vec3::new(0.0, 0.0, 600.0),
        torque: Vec3::zeros(),
        frame: LoadFrame::Inertial,
        function: TimeFunction::Constant { value: 1.0 },
    });
    let mut settings = StaticSettings::new();
    settings.initial_increment = 0.1;
    let mut statics = Statics::new(&m, settings).expect("starts");
    let mut at = vec![];
    statics
        .run(&mut |s| {
            at.push((s.load_factor, s.state.q[tip.0].x));
            Ok(())
        })
        .expect("converges");
    let x = statics.state.q[tip.0].x;
    let reference = Vec3::new(47.1504, 15.6848, 53.4749);
    println!("bend: tip {x:?}, error {:.3e}", (x - reference).norm());
    assert!((x - reference).norm() < 0.05, "tip {x:?} vs {reference:?}");
}
