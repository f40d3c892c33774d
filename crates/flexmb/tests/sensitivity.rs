//! Sensitivity analysis through the Rust API (`flexmb::sensitivity`): direct differentiation
//! and the discrete adjoint agree to round-off on the paths the CLI tests do not reach (the
//! stabilized index-2 step with joint parameters, element states with their initial values,
//! closed loops, the adjoint's checkpoints), and with central finite differences; the
//! acceleration sensors that criteria use are the time derivatives of the velocity sensors.

use flexmb::input::read_model_file;
use flexmb::sensitivity::{self, CriteriaSet, Criterion, CriterionKind, Gradients, Problem};
use std::sync::Arc;

fn problem(
    file: &str,
    set: &[&str],
    design: &[&str],
    criteria: &[(&str, CriterionKind, &str)],
) -> Problem {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples")
        .join(file);
    let set: Vec<String> = set.iter().map(|s| s.to_string()).collect();
    let f = read_model_file(&path, &set).expect("model");
    let model = Arc::new(f.model);
    let params = flexmb::model::Parameters::new(&model);
    let design = design
        .iter()
        .map(|p| params.id(p).expect("parameter"))
        .collect();
    let criteria = criteria
        .iter()
        .map(|(n, k, t)| Criterion::new(&model, &[], n, *k, t).expect("criterion"))
        .collect();
    let criteria = CriteriaSet::new(&model, Vec::new(), criteria);
    Problem::new(model, f.analysis, design, criteria)
}

/// Largest difference of two gradient tables relative to the largest gradient of each
/// criterion (at least `floor`).
fn difference(a: &Gradients, b: &Gradients, floor: f64) -> f64 {
    a.gradients
        .iter()
        .zip(&b.gradients)
        .map(|(x, y)| {
            let scale = x.iter().fold(floor, |m, v| m.max(v.abs()));
            x.iter()
                .zip(y)
                .fold(0.0f64, |m, (p, q)| m.max((p - q).abs() / scale))
        })
        .fold(0.0, f64::max)
}

/// Direct and adjoint within `exact`, the adjoint and central differences (relative step
/// `1e-5`) within `fd`, relative to each criterion's largest gradient.
fn agree(name: &str, p: &Problem, exact: f64, fd: f64) -> Gradients {
    let d = sensitivity::direct(p).expect("direct");
    let a = sensitivity::adjoint(p, &mut |_, _| {}).expect("adjoint");
    let f = sensitivity::finite_differences(p, 1e-5).expect("fd");
    let (e1, e2) = (difference(&d, &a, 1e-300), difference(&a, &f, 1e-300));
    println!("{name}: direct-adjoint {e1:.2e}, adjoint-fd {e2:.2e}");
    assert!(
        e1 < exact,
        "{name}: direct and adjoint differ by {e1:e}\n{d:?}\n{a:?}"
    );
    assert!(
        e2 < fd,
        "{name}: adjoint and finite differences differ by {e2:e}\n{a:?}\n{f:?}"
    );
    a
}

const TIGHT: [&str; 2] = ["solver.rtol=1e-12", "solver.atol=1e-14"];

#[test]
fn stabilized_index_2_step() {
    // rho_inf = 1 selects the stabilized index-2 form: the configuration update
    // q_n exp(dq + B(q_n)^T zeta) depends on the start. (Its dependence on a joint's position
    // is checked step by step in step_jacobians.rs: moving a joint makes the initial
    // conditions of a run inconsistent, so a run cannot be differenced along it.)
    for group in ["SE3", "R3xSO3"] {
        let g = format!("model.group={group}");
        let p = problem(
            "heavy_top_sensitivity.toml",
            &[
                "solver.rtol=1e-10",
                "solver.t_end=0.1",
                "solver.rho_inf=1.0",
                &g,
            ],
            &[
                "body.top.mass",
                "body.top.inertia.0",
                "node.top.angular_velocity_body.1",
                "body.top.com.1",
            ],
            &[
                ("x", CriterionKind::Terminal, "com_x + 0.3 * com_z"),
                ("reaction", CriterionKind::Integral, "sq(reaction_z)"),
            ],
        );
        assert!(
            p.dynamic().unwrap().stabilized(),
            "rho_inf = 1 is the stabilized form"
        );
        agree(&format!("stabilized top {group}"), &p, 1e-9, 1e-5);
    }
}

#[test]
fn element_states_and_their_initial_values() {
    // The Maxwell branch starts unstressed, z_0 = l(q_0) - l0: its initial state depends
    // on the rest length (dz_0/dp), the relaxation parameters enter its state equation.
    let p = problem(
        "viscoelastic_mount.toml",
        &["solver.t_end=2.0", "solver.h=0.01"],
        &[
            "spring.mount.rest_length",
            "spring.mount.stiffness",
            "spring.mount.relaxation_stiffness",
            "spring.mount.relaxation_damping",
            "body.mass.mass",
            "node.mass.velocity.0",
        ],
        &[
            ("u_end", CriterionKind::Terminal, "u"),
            ("force", CriterionKind::Integral, "sq(force)"),
        ],
    );
    agree("viscoelastic mount", &p, 1e-9, 1e-5);
}

/// The problem of an example's text with `extra` appended (sensors the example lacks).
fn problem_with(
    file: &str,
    extra: &str,
    set: &[&str],
    design: &[&str],
    criteria: &[(&str, CriterionKind, &str)],
) -> Problem {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples")
        .join(file);
    let text = std::fs::read_to_string(&path).expect("example") + extra;
    let dir = std::env::temp_dir().join(format!("flexmb-sens-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let copy = dir.join(file);
    std::fs::write(&copy, text).expect("copy");
    problem(copy.to_str().expect("utf-8"), set, design, criteria)
}

const ACCELERATIONS: &str = r#"
[[sensor]]
name = "acc_y"
type = "acceleration"
node = "coupler0"
point = [1.0, 0.5, 0.0]
component = "y"

[[sensor]]
name = "vel_y"
type = "velocity"
node = "coupler0"
point = [1.0, 0.5, 0.0]
component = "y"

[[sensor]]
name = "alpha_z"
type = "angular_acceleration"
node = "crank1"
component = "z"

[[sensor]]
name = "omega_z"
type = "angular_velocity"
node = "crank1"
component = "z"
"#;

#[test]
fn closed_loop_with_acceleration_criteria() {
    // The double four-bar (closed loops, redundant rows left out) with criteria on point and
    // angular accelerations, from the step's own vdot.
    let p = problem_with(
        "four_bar.toml",
        ACCELERATIONS,
        &[TIGHT[0], TIGHT[1], "solver.t_end=0.3", "solver.h=1e-3"],
        &[
            "body.crank0.mass",
            "body.coupler0.mass",
            "body.coupler1.mass",
            "model.gravity.1",
        ],
        &[
            (
                "acc",
                CriterionKind::Integral,
                "sq(acc_y) + 0.1 * sq(alpha_z)",
            ),
            ("end", CriterionKind::Terminal, "vel_y"),
        ],
    );
    agree("four-bar accelerations", &p, 1e-9, 1e-5);
}

#[test]
fn acceleration_sensors_are_the_rates_of_the_velocity_sensors() {
    // A central difference in time of the velocity sensors against the acceleration
    // sensors, every step of a run with small steps (error O(h^2) of both).
    let p = problem_with(
        "four_bar.toml",
        ACCELERATIONS,
        &[
            "solver.t_end=0.2",
            "solver.h=1e-4",
            "solver.output_interval=1e-4",
        ],
        &[],
        &[],
    );
    let mut sim =
        flexmb::Simulation::new(Arc::clone(&p.model), *p.dynamic().unwrap()).expect("sim");
    let k = |name: &str| p.model.sensors.iter().position(|s| s.name == name).unwrap();
    let (a, v, alpha, om) = (k("acc_y"), k("vel_y"), k("alpha_z"), k("omega_z"));
    let mut rows: Vec<(f64, Vec<f64>)> = Vec::new();
    let mut eval = flexmb::sensors::SensorEvaluator::new(&p.model);
    let mut record = |s: &flexmb::observe::Sample| {
        rows.push((s.at, eval.evaluate(s.model, s.data, s.state)));
        Ok(())
    };
    sim.run(&mut record).expect("run");
    let mut worst = 0.0f64;
    // After the start: the generalized-alpha accelerations carry an O(h) transient over the
    // first steps (Arnold & Brüls 2007, Sect. 4), not the rates' error.
    for w in rows.windows(3).filter(|w| w[0].0 > 0.01) {
        let dt = w[2].0 - w[0].0;
        for (rate, of) in [(a, v), (alpha, om)] {
            let fd = (w[2].1[of] - w[0].1[of]) / dt;
            let scale = w[1].1[rate].abs().max(1.0);
            worst = worst.max((fd - w[1].1[rate]).abs() / scale);
        }
    }
    println!("acceleration sensors against d/dt of velocity sensors: {worst:.2e}");
    assert!(worst < 1e-4, "{worst:e}");
}

#[test]
fn checkpointed_adjoint_gives_the_same_gradients() {
    let mut p = problem(
        "heavy_top_sensitivity.toml",
        &["solver.t_end=0.2"],
        &[
            "body.top.mass",
            "body.top.inertia.0",
            "node.top.angular_velocity_body.1",
        ],
        &[
            ("x", CriterionKind::Terminal, "com_x"),
            ("nutation", CriterionKind::Integral, "sq(com_z)"),
        ],
    );
    let all = sensitivity::adjoint(&p, &mut |_, _| {}).expect("in memory");
    assert_eq!(all.stats.checkpoints, 0);
    p.memory_budget = 40_000;
    let mut calls = 0;
    let some = sensitivity::adjoint(&p, &mut |done, total| {
        calls += 1;
        assert!(done <= total);
    })
    .expect("checkpoints");
    assert!(some.stats.checkpoints > 1, "{:?}", some.stats);
    assert!(some.stats.trajectory_bytes <= 40_000, "{:?}", some.stats);
    assert_eq!(calls, some.stats.steps);
    assert_eq!(
        all.gradients, some.gradients,
        "a restored run takes the same steps"
    );
    assert_eq!(all.values, some.values);
}

#[test]
fn variable_step_sizes() {
    // t_end = 0.2045 with h = 1e-2: the step control shortens steps to land on the output
    // times (every 0.0275 s) and on t_end, so the grid is not uniform; every step's own h
    // enters its step function and the trapezoidal weights.
    let p = problem(
        "heavy_top_sensitivity.toml",
        &[
            TIGHT[0],
            TIGHT[1],
            "solver.t_end=0.2045",
            "solver.h=1e-2",
            "solver.output_interval=0.0275",
        ],
        &[
            "body.top.mass",
            "body.top.inertia.1",
            "node.top.angular_velocity_body.1",
        ],
        &[
            ("x", CriterionKind::Terminal, "com_x"),
            ("nutation", CriterionKind::Integral, "sq(com_z) + t"),
        ],
    );
    let a = agree("variable steps", &p, 1e-9, 1e-5);
    assert!(
        a.stats.steps > 21,
        "the grid has extra steps: {}",
        a.stats.steps
    );
    // The integral of t alone is exact under the trapezoidal rule: t_end^2 / 2.
    let t_only = problem(
        "heavy_top_sensitivity.toml",
        &[
            "solver.t_end=0.2045",
            "solver.h=1e-2",
            "solver.output_interval=0.0275",
        ],
        &["body.top.mass"],
        &[("t", CriterionKind::Integral, "t")],
    );
    let g = sensitivity::direct(&t_only).expect("direct");
    assert!(
        (g.values[0] - 0.2045f64.powi(2) / 2.0).abs() < 1e-14,
        "{}",
        g.values[0]
    );
    assert_eq!(g.gradients[0][0], 0.0);
}
