//! First-order element states integrated with the mechanics: a mass on a standard linear
//! solid (a spring in parallel with a Maxwell branch, whose damper elongation is the element's
//! state), along the spring's axis so that the problem is exactly linear. Against the exact
//! solution `y(t) = exp(A t) y_0` of `y = (u, udot, z)`,
//!
//! ```text
//! m u'' = -k u - c u' - k_m (u - z),     c_m z' = k_m (u - z),
//! ```
//!
//! with second-order convergence in `h` of the coupled scheme (mechanical generalized-alpha,
//! first-order generalized-alpha for `z`; Brüls & Golinval 2008); and the static equilibrium,
//! where the branch has relaxed.

use crate::common;

use flexmb::model::{Model, Relaxation, SpringDamper};
use flexmb::solve::Statics;
use flexmb::{DynamicSettings, Simulation};
use flexmb_lie::{Frame, Group, Mat3, Vec3};
use nalgebra::{Matrix3, Vector3};

const M: f64 = 1.0;
const K: f64 = 1.0;
const C: f64 = 0.1;
const KM: f64 = 2.0;
const CM: f64 = 0.5;
const U0: f64 = 0.01;

fn model(group: Group) -> Model {
    let mut m = Model::new(group);
    let n = m.add_node(
        "mass",
        Frame::new(Vec3::new(U0, 0.0, 0.0), Mat3::identity()),
    );
    m.add_body("mass", n, M, Vec3::zeros(), Mat3::identity() * 1e-3);
    m.springs.push(SpringDamper {
        name: "solid".into(),
        node_a: None,
        node_b: Some(n),
        point_a: Vec3::new(-1.0, 0.0, 0.0),
        point_b: Vec3::zeros(),
        stiffness: K,
        damping: C,
        rest_length: 1.0,
        relaxation: Some(Relaxation {
            stiffness: KM,
            damping: CM,
        }),
    });
    m
}

/// `(u, z)` at `t_end` with step `h`.
fn simulate(group: Group, rho_inf: f64, h: f64, t_end: f64) -> (f64, f64) {
    let mut s = DynamicSettings::new(t_end, h);
    s.rho_inf = rho_inf;
    s.newton.rtol = 1e-12;
    s.newton.atol = 1e-15;
    let mut sim = Simulation::new(model(group), s).expect("starts");
    sim.run(&mut |_: &flexmb::observe::Sample| Ok(()))
        .expect("runs");
    (sim.state.q[0].x.x, sim.state.x[0])
}

/// The exact `(u, udot, z)` at `t`: the branch unstressed at the start (`z_0 = u_0`), at
/// rest.
fn exact_state(t: f64) -> Vector3<f64> {
    let a = Matrix3::new(
        0.0,
        1.0,
        0.0,
        -(K + KM) / M,
        -C / M,
        KM / M,
        KM / CM,
        0.0,
        -KM / CM,
    );
    (a * t).exp() * Vector3::new(U0, 0.0, U0)
}

/// The exact `(u, z)` at `t`.
fn exact(t: f64) -> (f64, f64) {
    let y = exact_state(t);
    (y[0], y[2])
}

#[test]
fn viscoelastic_mount_example_follows_the_exact_solution() {
    // examples/viscoelastic_mount.toml is the model above, through the model file: its
    // sensors (position, the spring force with the branch's, the total energy) at every
    // output time against y(t) = exp(A t) y(0).
    let file = flexmb::input::read_model_file(&common::example("viscoelastic_mount.toml"), &[])
        .expect("reads");
    let flexmb::input::Analysis::Dynamic(settings) = file.analysis else {
        panic!("a dynamic analysis")
    };
    let mut sim = Simulation::new(file.model.clone(), settings).expect("starts");
    let mut sensors = flexmb::sensors::SensorEvaluator::new(&file.model);
    let (mut worst_u, mut worst_force, mut outputs) = (0.0f64, 0.0f64, 0);
    sim.run(&mut |s: &flexmb::observe::Sample| {
        let values = sensors.evaluate(s.model, s.data, s.state);
        let y = exact_state(s.state.t);
        let force = K * y[0] + C * y[1] + KM * (y[0] - y[2]);
        worst_u = worst_u.max((values[0] - y[0]).abs() / U0);
        worst_force = worst_force.max((values[1] - force).abs() / (K + KM) / U0);
        outputs += 1;
        Ok(())
    })
    .expect("runs");
    println!("{outputs} outputs: u within {worst_u:.2e}, force within {worst_force:.2e}");
    assert_eq!(outputs, 201);
    assert!(
        worst_u < 2e-5 && worst_force < 2e-5,
        "{worst_u:e} {worst_force:e}"
    );
}

#[test]
fn standard_linear_solid_matches_the_exact_solution_to_second_order() {
    let t_end = 3.0;
    let (u_ref, z_ref) = exact(t_end);
    for group in [Group::SE3, Group::R3xSO3] {
        for rho_inf in [0.6, 0.9] {
            let error = |h: f64| {
                let (u, z) = simulate(group, rho_inf, h, t_end);
                ((u - u_ref).abs().max((z - z_ref).abs())) / U0
            };
            let (e1, e2) = (error(0.02), error(0.01));
            let order = (e1 / e2).log2();
            assert!(
                e2 < 2e-4 && (order - 2.0).abs() < 0.15,
                "{group:?}, rho_inf {rho_inf}: errors {e1:e}, {e2:e} (order {order:.3})"
            );
        }
    }
}

#[test]
fn static_equilibrium_relaxes_the_maxwell_branch() {
    // At rest the branch carries no force (c_m zdot = k_m (u - z) = 0): the spring alone
    // balances the load, u = F / k, and z = u. The mass slides on a prismatic joint along
    // the spring's axis; load control and arc length, on both groups.
    use flexmb::solve::StaticMethod;
    let force = 0.3;
    for group in [Group::SE3, Group::R3xSO3] {
        for method in [StaticMethod::LoadControl, StaticMethod::ArcLength] {
            let m = pulled(group, force);
            let mut settings = flexmb::solve::StaticSettings {
                method,
                ..Default::default()
            };
            settings.arc_length = 0.05;
            let mut statics = Statics::new(m, settings).expect("starts");
            statics
                .run(&mut |_: &flexmb::observe::Sample| Ok(()))
                .expect("converges");
            let (u, z) = (statics.state.q[0].x.x, statics.state.x[0]);
            assert!(
                (u - force / K).abs() < 1e-9 && (z - u).abs() < 1e-9,
                "{group:?}, {method:?}: u = {u}, z = {z}, expected {}",
                force / K
            );
        }
    }
}

/// The model above on a prismatic joint along the spring, pulled by `force` along it.
fn pulled(group: Group, force: f64) -> Model {
    use flexmb::model::{JointKind, Load, LoadFrame, TimeFunction};
    let mut m = model(group);
    let z_to_x = Mat3::new(0.0, 0.0, 1.0, 0.0, 1.0, 0.0, -1.0, 0.0, 0.0);
    let node = flexmb::model::NodeId(0);
    let at = Vec3::new(U0, 0.0, 0.0);
    m.add_joint(
        "slide",
        JointKind::Prismatic,
        None,
        Some(node),
        at,
        z_to_x,
        None,
    );
    m.loads.push(Load {
        name: "pull".into(),
        node,
        force: Vec3::new(force, 0.0, 0.0),
        torque: Vec3::zeros(),
        frame: LoadFrame::Inertial,
        function: TimeFunction::Constant { value: 1.0 },
        input: None,
    });
    m
}

#[test]
fn pseudo_dynamic_statics_warns_when_the_branch_has_not_relaxed() {
    // The pseudo-dynamic method settles the nodes within pseudo_time; a branch that relaxes
    // in c_m / k_m = 2e6 s has not: the run says so instead of returning a state away from
    // the equilibrium silently. With a branch of 0.25 s it settles on u = F / k.
    use flexmb::solve::StaticMethod;
    let force = 0.3;
    for (branch_damping, settled) in [(2e8, false), (0.5 * 100.0 / 2.0, true)] {
        let mut m = pulled(Group::SE3, force);
        m.springs[0].relaxation = Some(Relaxation {
            stiffness: 100.0,
            damping: branch_damping,
        });
        let settings = flexmb::solve::StaticSettings {
            method: StaticMethod::PseudoDynamic,
            pseudo_time: 200.0,
            pseudo_damping: 2.0,
            initial_increment: 0.002,
            ..Default::default()
        };
        let mut statics = Statics::new(m, settings).expect("starts");
        statics
            .run(&mut |_: &flexmb::observe::Sample| Ok(()))
            .expect("runs");
        let u = statics.state.q[0].x.x;
        let warned = statics
            .warnings
            .iter()
            .any(|w| w.contains("from the static equilibrium"));
        assert_eq!(
            warned, !settled,
            "c_m = {branch_damping}: {:?}",
            statics.warnings
        );
        if settled {
            assert!((u - force / K).abs() < 1e-4, "u = {u}");
        } else {
            assert!((u - force / K).abs() > 1e-2, "u = {u}");
        }
    }
}
