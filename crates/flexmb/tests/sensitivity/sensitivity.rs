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

/// The heavy top of `heavy_top_sensitivity.toml` to 0.1 s at rtol 1e-10 on `group`, with
/// the settings `set`: its mass, first inertia, initial spin and (`com`) its centre of
/// mass against a terminal criterion on the centre of mass and the integral of the squared
/// vertical reaction.
fn top(group: &str, set: &[&str], com: bool) -> Problem {
    let g = format!("model.group={group}");
    let mut set = set.to_vec();
    set.extend(["solver.rtol=1e-10", "solver.t_end=0.1", &g]);
    let mut design = vec![
        "body.top.mass",
        "body.top.inertia.0",
        "node.top.angular_velocity_body.1",
    ];
    if com {
        design.push("body.top.com.1");
    }
    problem(
        "heavy_top_sensitivity.toml",
        &set,
        &design,
        &[
            ("x", CriterionKind::Terminal, "com_x + 0.3 * com_z"),
            ("reaction", CriterionKind::Integral, "sq(reaction_z)"),
        ],
    )
}

#[test]
fn stabilized_index_2_step() {
    // rho_inf = 1 selects the stabilized index-2 form: the configuration update
    // q_n exp(dq + B(q_n)^T zeta) depends on the start. (Its dependence on a joint's position
    // is checked step by step in step_jacobians.rs: moving a joint makes the initial
    // conditions of a run inconsistent, so a run cannot be differenced along it.)
    for group in ["SE3", "R3xSO3"] {
        let p = top(group, &["solver.rho_inf=1.0"], true);
        assert!(
            p.dynamic().unwrap().stabilized(),
            "rho_inf = 1 is the stabilized form"
        );
        agree(&format!("stabilized top {group}"), &p, 1e-9, 1e-5);
    }
}

#[test]
fn commutator_configuration_update() {
    // q_{n+1} = q_n exp(dq + sigma h^3 [v_n, a_n]): the update depends on v_n and a_n.
    for group in ["SE3", "R3xSO3"] {
        let set = [
            "solver.lie_update=commutator",
            "solver.lie_update_sigma=0.5",
            "solver.rho_inf=0.6",
        ];
        let p = top(group, &set, false);
        agree(&format!("commutator update {group}"), &p, 1e-9, 1e-5);
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
    p.memory_budget = 60_000;
    let mut calls = 0;
    let some = sensitivity::adjoint(&p, &mut |done, total| {
        calls += 1;
        assert!(done <= total);
    })
    .expect("checkpoints");
    assert!(some.stats.checkpoints > 1, "{:?}", some.stats);
    assert!(some.stats.trajectory_bytes <= 60_000, "{:?}", some.stats);
    assert_eq!(calls, some.stats.steps);
    assert_eq!(
        all.gradients, some.gradients,
        "a restored run takes the same steps"
    );
    assert_eq!(all.values, some.values);
}

/// The adjoint with a workspace kept from earlier calls (an optimizer's: its trajectory
/// storage overwritten in place) gives the gradients of a fresh one, bit for bit, whether
/// the earlier run took more steps, fewer, or had other parameter values.
#[test]
fn a_kept_workspace_gives_the_gradients_of_a_fresh_one() {
    let design = ["body.top.mass", "node.top.angular_velocity_body.1"];
    let criteria = [
        ("x", CriterionKind::Terminal, "com_x"),
        ("nutation", CriterionKind::Integral, "sq(com_z)"),
    ];
    let run = |t_end: &str| problem("heavy_top_sensitivity.toml", &[t_end], &design, &criteria);
    let (long, short) = (run("solver.t_end=0.2"), run("solver.t_end=0.1"));
    let heavier = short.with_values(&[16.0, 140.0]);
    let mut workspace = sensitivity::Workspace::default();
    for p in [&long, &short, &heavier, &long] {
        let kept = sensitivity::adjoint_in(p, &mut workspace, &mut |_, _| {}).expect("kept");
        let fresh = sensitivity::adjoint(p, &mut |_, _| {}).expect("fresh");
        assert_eq!(kept.values, fresh.values);
        assert_eq!(kept.gradients, fresh.gradients);
        assert_eq!(kept.stats.steps, fresh.stats.steps);
    }
    assert_ne!(
        sensitivity::adjoint(&short, &mut |_, _| {})
            .expect("short")
            .gradients,
        sensitivity::adjoint(&heavier, &mut |_, _| {})
            .expect("heavier")
            .gradients,
        "the parameter values matter"
    );
}

/// Both methods with their steps' Jacobians prepared on two threads give the gradients of
/// the sequential methods, bit for bit (the same operations in the same order); the adjoint
/// with a fresh workspace, with one kept from an earlier call, and from checkpoints.
#[test]
fn jacobians_on_two_threads_give_the_gradients_of_one_thread() {
    let design = [
        "body.link1.mass",
        "body.link5.inertia.2",
        "joint.j3.position.0",
    ];
    let criteria = [
        ("tip", CriterionKind::Terminal, "tip_x"),
        ("energy", CriterionKind::Integral, "sq(tip_y)"),
    ];
    let on = |threads: usize| {
        let set = [
            "solver.t_end=0.05".to_string(),
            format!("solver.threads={threads}"),
        ];
        let set: Vec<&str> = set.iter().map(String::as_str).collect();
        problem("chain_10.toml", &set, &design, &criteria)
    };
    let sequential = sensitivity::adjoint(&on(1), &mut |_, _| {}).expect("one thread");
    assert_eq!(sequential.stats.jacobian_threads, 1);
    let p = on(2);
    let mut workspace = sensitivity::Workspace::default();
    for call in 0..2 {
        let mut done = 0;
        let parallel = sensitivity::adjoint_in(&p, &mut workspace, &mut |d, n| {
            assert_eq!(d, done + 1, "the steps reported in order");
            assert!(d <= n);
            done = d;
        })
        .expect("two threads");
        assert_eq!(done, parallel.stats.steps);
        assert_eq!(parallel.stats.jacobian_threads, 2, "call {call}");
        assert_eq!(parallel.gradients, sequential.gradients, "call {call}");
        assert_eq!(parallel.values, sequential.values);
    }
    // From checkpoints: each recomputed segment swept on the threads.
    let mut tight = on(2);
    tight.memory_budget = 240_000;
    let segments = sensitivity::adjoint(&tight, &mut |_, _| {}).expect("checkpoints");
    assert!(segments.stats.checkpoints > 1, "{:?}", segments.stats);
    assert_eq!(segments.stats.jacobian_threads, 2);
    assert_eq!(segments.gradients, sequential.gradients);
    let direct = sensitivity::direct(&on(1)).expect("direct, one thread");
    assert_eq!(direct.stats.jacobian_threads, 1);
    assert!(difference(&direct, &sequential, 1e-300) < 1e-8);
    let parallel = sensitivity::direct(&p).expect("direct, two threads");
    assert_eq!(parallel.stats.jacobian_threads, 2);
    assert_eq!(parallel.gradients, direct.gradients);
    assert_eq!(parallel.values, direct.values);
    assert_eq!(parallel.stats.steps, direct.stats.steps);
}

/// A run that fails while the direct method's tangents are carried on other threads (its
/// first step, with one Newton iteration allowed) stops them and reports the run's error,
/// as on one thread.
#[test]
fn a_run_that_fails_stops_the_threads_with_its_error() {
    let failing = |threads: usize| {
        let set = [
            "solver.t_end=0.05".to_string(),
            "solver.max_iterations=1".to_string(),
            format!("solver.threads={threads}"),
        ];
        let set: Vec<&str> = set.iter().map(String::as_str).collect();
        let p = problem(
            "chain_10.toml",
            &set,
            &["body.link1.mass"],
            &[("tip", CriterionKind::Terminal, "tip_x")],
        );
        sensitivity::direct(&p)
            .expect_err("one Newton iteration per step")
            .to_string()
    };
    let (one, two) = (failing(1), failing(2));
    assert_eq!(one, two);
    assert!(one.contains("Newton failed at step 1"), "{one}");
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

/// The error of reading `file` from the examples with `from` replaced by `to` (each must be
/// in the file).
fn read_error(file: &str, edits: &[(&str, &str)]) -> String {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples")
        .join(file);
    let mut text = std::fs::read_to_string(&path).expect("example");
    for (from, to) in edits {
        assert!(text.contains(from), "{from}");
        text = text.replacen(from, to, 1);
    }
    flexmb::input::parse_model_str(&text, file, &[])
        .expect_err("an error")
        .to_string()
}

/// An example, the edits of its text and what the error must say.
type Case<'a> = (&'a str, &'a [(&'a str, &'a str)], &'a [&'a str]);

#[test]
fn sensitivity_sections_are_checked_with_file_line_and_field() {
    let cases: &[Case] = &[
        // a static analysis: terminal criteria only, no initial velocities
        (
            "bend_45_sensitivity.toml",
            &[("terminal = \"tip_x\"", "integral = \"tip_x\"")],
            &["bend_45_sensitivity.toml:", "criterion[0].integral", "terminal criteria only"],
        ),
        (
            "bend_45_sensitivity.toml",
            &[("path = \"load.tip_force.force.2\"", "path = \"node.arc.32.velocity.0\"")],
            &["design_parameter[3].path", "initial velocity"],
        ),
        // bounds must contain the value (the optimizer starts there)
        (
            "half_car.toml",
            &[("lower = 100.0", "lower = 2000.0")],
            &["half_car.toml:", "design_parameter[0].lower", "must contain the parameter's value 2000"],
        ),
        // reversed or equal bounds say so (before: "must contain the value strictly")
        (
            "half_car.toml",
            &[("lower = 100.0\nupper = 20000.0", "lower = 2000.0\nupper = 100.0")],
            &["design_parameter[0].lower", "the bounds are reversed: lower = 2000 is above upper = 100"],
        ),
        (
            "half_car.toml",
            &[("lower = 100.0\nupper = 20000.0", "lower = 2000.0\nupper = 2000.0")],
            &["design_parameter[0].lower", "lower and upper are equal (2000)"],
        ),
        (
            "half_car.toml",
            &[("upper = 20000.0\n", "\n")],
            &["design_parameter[0].upper", "is required with lower"],
        ),
        // names: not the built-ins, no commas
        (
            "half_car.toml",
            &[("name = \"comfort\"", "name = \"t\"")],
            &["criterion[0].name", "built-in"],
        ),
        (
            "half_car.toml",
            &[("name = \"comfort\"", "name = \"a,b\"")],
            &["criterion[0].name", "commas"],
        ),
        // unknown parameter path, unknown sensor, energy sensors
        (
            "half_car.toml",
            &[("path = \"spring.suspension_front.damping\"", "path = \"spring.suspension_front.dampng\"")],
            &["design_parameter[0].path", "unknown parameter", "spring.suspension_front.damping"],
        ),
        (
            "heavy_top_sensitivity.toml",
            &[("terminal = \"com_x\"", "terminal = \"energy + 1\"")],
            &["criterion[0].terminal", "'energy' (total_energy) has no derivative"],
        ),
        (
            "heavy_top_sensitivity.toml",
            &[("terminal = \"com_x\"", "terminal = \"sq(com_x\"")],
            &["criterion[0].terminal", "at character"],
        ),
        // a reference file that is not there
        (
            "half_car.toml",
            &[("[[criterion]]\nname = \"comfort\"", "[[reference]]\nname = \"target\"\nfile = \"no_such.csv\"\ncolumn = \"z\"\n\n[[criterion]]\nname = \"comfort\"")],
            &["reference[0].file", "no_such.csv"],
        ),
    ];
    for (file, edits, expected) in cases {
        let e = read_error(file, edits);
        for x in *expected {
            assert!(e.contains(x), "{file} {edits:?}: '{x}' not in: {e}");
        }
    }
}

#[test]
fn a_parameter_that_breaks_the_initial_conditions_is_refused() {
    // Moving the heavy top's pivot across its constrained directions makes the initial
    // velocities inconsistent: the derivative is refused, naming the parameter.
    let p = problem(
        "heavy_top_sensitivity.toml",
        &["solver.t_end=0.01"],
        &["joint.pivot.position.0"],
        &[("x", CriterionKind::Terminal, "com_x")],
    );
    let e = sensitivity::direct(&p).expect_err("refused").to_string();
    assert!(
        e.contains("joint.pivot.position.0") && e.contains("inconsistent"),
        "{e}"
    );
}

#[test]
fn lie_algebra_updates() {
    // q_{n+1} = q_n o C(Theta), v = M(Theta) Theta', vdot = M Theta'' + N: the step
    // function's exact Jacobian follows the chart (solve::step, "Lie algebra updates"), on
    // the heavy top of both groups with each chart.
    for update in ["lie_algebra", "lie_algebra_r3xso3"] {
        for group in ["SE3", "R3xSO3"] {
            let u = format!("solver.lie_update={update}");
            let p = top(group, &["solver.rho_inf=0.6", &u], true);
            agree(&format!("{update} update, {group}"), &p, 1e-8, 1e-5);
        }
    }
    // The half car of the talk (ride comfort against the suspension): rigid bodies on
    // driven, prismatic and planar joints, with the exponential chart on both groups.
    // (R3xSO(3)'s chart on SE(3) gives it the same exact gradients, but central differences
    // of its runs scatter by percents: BENCHMARKS.md, "The Lie algebra update".)
    for group in ["SE3", "R3xSO3"] {
        let g = format!("model.group={group}");
        let p = problem(
            "half_car.toml",
            &[
                "solver.rtol=1e-10",
                "solver.t_end=0.3",
                "solver.lie_update=lie_algebra",
                &g,
            ],
            &[
                "spring.suspension_front.damping",
                "spring.suspension_rear.stiffness",
                "spring.tyre_front.stiffness",
            ],
            &[
                ("comfort", CriterionKind::Integral, "sq(heave_acc)"),
                ("seat", CriterionKind::Integral, "sq(seat_acc)"),
            ],
        );
        agree(
            &format!("half car, lie_algebra update, {group}"),
            &p,
            1e-8,
            1e-5,
        );
    }
}

#[test]
fn references_from_csv_enter_criteria() {
    // A reference signal r(t) = 2 t read from a CSV file: the integral of (t - r)^2 over
    // [0, T] is T^3 / 3 exactly under the trapezoidal rule only at the samples, so check it
    // against the rule itself with the run's steps, and that it carries no gradient.
    let dir = std::env::temp_dir().join(format!("flexmb-ref-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("r.csv"), "# a ramp\nt,r\n0,0\n1,2\n").unwrap();
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples/heavy_top_sensitivity.toml");
    let text = std::fs::read_to_string(path).unwrap().replace(
        "[[criterion]]\nname = \"x_G\"",
        "[[reference]]\nname = \"ramp\"\nfile = \"r.csv\"\ncolumn = \"r\"\n\n[[criterion]]\nname = \"gap\"\nintegral = \"sq(t - ramp)\"\n\n[[criterion]]\nname = \"x_G\"",
    );
    let file = dir.join("top.toml");
    std::fs::write(&file, text).unwrap();
    let f = read_model_file(&file, &["solver.t_end=0.1".to_string()]).expect("model");
    let setup = f.sensitivity.clone().expect("sensitivity");
    let p = setup.problem(Arc::new(f.model.clone()), f.analysis.clone());
    let g = sensitivity::adjoint(&p, &mut |_, _| {}).expect("adjoint");
    // (t - 2t)^2 = t^2; trapezoidal with h = 1e-3 on [0, 0.1]: T^3/3 + h^2 T / 6.
    let (t, h) = (0.1f64, 1e-3f64);
    let exact = t.powi(3) / 3.0 + h * h * t / 6.0;
    assert!(
        (g.values[0] - exact).abs() < 1e-15,
        "{} against {exact}",
        g.values[0]
    );
    assert!(g.gradients[0].iter().all(|&v| v == 0.0));
}

#[test]
fn adjoint_memory_stays_within_budgets_when_the_run_takes_more_steps() {
    // The adjoint sizes its memory from t_end / h; this grid takes more steps (shortened to
    // land on output times), so with some budgets the steps kept overflow and the sweep goes
    // through the checkpoints instead. Every budget gives the in-memory gradients, or says
    // it is too small.
    let mut p = problem(
        "heavy_top_sensitivity.toml",
        &[
            "solver.t_end=0.2045",
            "solver.h=1e-2",
            "solver.output_interval=0.0275",
        ],
        &["body.top.mass", "node.top.angular_velocity_body.1"],
        &[("nutation", CriterionKind::Integral, "sq(com_z)")],
    );
    let all = sensitivity::adjoint(&p, &mut |_, _| {}).expect("in memory");
    let mut fallbacks = 0;
    for budget in (4_000..60_000).step_by(1_000) {
        p.memory_budget = budget;
        match sensitivity::adjoint(&p, &mut |_, _| {}) {
            Ok(g) => {
                assert_eq!(g.gradients, all.gradients, "budget {budget}");
                assert!(
                    g.stats.trajectory_bytes <= budget,
                    "{budget}: {:?}",
                    g.stats
                );
                fallbacks += usize::from(g.stats.checkpoints > 0);
            }
            Err(e) => assert!(e.to_string().contains("too small"), "{e}"),
        }
    }
    assert!(fallbacks > 0, "some budget sweeps from checkpoints");
}

#[test]
fn closed_loop_gains_and_plant() {
    // The PID loop of pid_mass_spring.toml: the gains and filter constant enter the
    // block equations, the plant's stiffness and mass the mechanics; the outputs of the
    // blocks are algebraic unknowns (their initial values solved with the accelerations).
    let p = problem(
        "pid_mass_spring.toml",
        &[
            "solver.t_end=0.5",
            "solver.h=2e-3",
            "solver.rtol=1e-11",
            "solver.atol=1e-14",
        ],
        &[
            "control.pid.kp",
            "control.pid.ki",
            "control.pid.kd",
            "control.pid.tf",
            "control.reference.function.value",
            "spring.spring.stiffness",
            "body.mass.mass",
        ],
        &[
            ("x_end", CriterionKind::Terminal, "x"),
            ("effort", CriterionKind::Integral, "sq(force)"),
        ],
    );
    agree("PID loop", &p, 1e-9, 1e-5);
}
