//! Newton with a reused iteration matrix gives the solution of full Newton (a fresh matrix at
//! every iteration) to within the Newton tolerance: on the free-body reproducer of the trust
//! issue across groups, centre-of-mass offsets and rho_inf, near the intermediate axis over
//! 20 s, and on every example; and every accepted step passes the verify mode (a fresh-matrix
//! re-check of the accepted iterate, estimated error at most 1 in units of the tolerance).
//!
//! Before the acceptance test bounded the error of the accepted iterate (the size of one
//! correction from a stale matrix was taken for the error), the reproducer took 1.00
//! iteration per step and ended 1.4e-4 rad/s away from full Newton, 300 times its
//! integration error.

mod common;
use common::example;
use flexmb::input::{parse_model_str, read_model_file, Analysis};
use flexmb::sensors::SensorEvaluator;
use flexmb::solve::newton::KAPPA;
use flexmb::solve::{Statics, Verification};
use flexmb::{DynamicSettings, Model, Simulation, State};

/// The trust issue's reproducer: a free body (no joints, no gravity) whose centre of mass
/// is off its node, spinning close to its intermediate principal axis.
fn free_body(group: &str, com: [f64; 3], rho_inf: f64, t_end: f64) -> (Model, DynamicSettings) {
    let text = format!(
        r#"flexmb = 1
[model]
group = "{group}"
[solver]
analysis = "dynamic"
t_end = {t_end}
h = 2.5e-3
rho_inf = {rho_inf}
[[body]]
name = "b"
mass = 3.0
com = [{}, {}, {}]
inertia = [1.0, 2.0, 3.0]
angular_velocity_body = [0.05, 4.0, 0.02]
"#,
        com[0], com[1], com[2]
    );
    let file = parse_model_str(&text, "free_body.toml", &[]).expect("valid model");
    let Analysis::Dynamic(settings) = file.analysis else {
        unreachable!()
    };
    (file.model, settings)
}

/// Every state of a run (one per step) and what verify found.
fn trajectory(model: &Model, mut settings: DynamicSettings, reuse: bool) -> Run {
    settings.newton.reuse_jacobian = reuse;
    settings.verify = true;
    let mut sim = Simulation::new(model, settings).expect("starts");
    let mut states = Vec::new();
    sim.run(&mut |s: &flexmb::observe::Sample| {
        states.push(s.state.clone());
        Ok(())
    })
    .expect("runs");
    Run {
        states,
        verification: sim.verification.clone().expect("verify was on"),
        iterations_per_step: sim.stats.newton_iterations as f64 / sim.stats.steps as f64,
    }
}

struct Run {
    states: Vec<State>,
    verification: Verification,
    iterations_per_step: f64,
}

/// Largest difference over the run between two trajectories with the same steps:
/// positions [m], velocities (6 per node) and multipliers, each relative to the largest
/// magnitude of that quantity over the run.
fn largest_differences(a: &[State], b: &[State]) -> [f64; 3] {
    assert_eq!(a.len(), b.len(), "same steps");
    let mut diff = [0.0f64; 3];
    let mut size = [0.0f64; 3];
    for (sa, sb) in a.iter().zip(b) {
        assert_eq!(sa.t, sb.t);
        for (qa, qb) in sa.q.iter().zip(&sb.q) {
            diff[0] = diff[0].max((qa.x - qb.x).norm());
            size[0] = size[0].max(qa.x.norm());
        }
        for (va, vb) in sa.v.iter().zip(&sb.v) {
            diff[1] = diff[1].max((va - vb).amax());
            size[1] = size[1].max(va.amax());
        }
        for (la, lb) in sa.lambda.iter().zip(&sb.lambda) {
            diff[2] = diff[2].max((la - lb).abs());
            size[2] = size[2].max(la.abs());
        }
    }
    // (A floor on the size: a node that stays at the origin differs by round-off.)
    [0, 1, 2].map(|k| diff[k] / size[k].max(1e-6))
}

#[test]
fn free_body_with_a_reused_matrix_matches_full_newton() {
    for group in ["R3xSO3", "SE3"] {
        for com in [[0.0; 3], [0.2, -0.1, 0.3]] {
            for rho_inf in [0.0, 0.5, 0.9, 1.0] {
                let (model, settings) = free_body(group, com, rho_inf, 1.0);
                let reused = trajectory(&model, settings, true);
                let fresh = trajectory(&model, settings, false);
                let d = largest_differences(&reused.states, &fresh.states);
                let case = format!("{group} com {com:?} rho_inf {rho_inf}");
                println!(
                    "{case}: differences q {:.2e} v {:.2e}; verify {:.2e} / {:.2e}; iterations/step {:.2} / {:.2}",
                    d[0], d[1], reused.verification.max_error, fresh.verification.max_error,
                    reused.iterations_per_step, fresh.iterations_per_step
                );
                assert!(
                    reused.verification.max_error <= 1.0,
                    "{case}: {:?}",
                    reused.verification
                );
                assert!(
                    fresh.verification.max_error <= 1.0,
                    "{case}: {:?}",
                    fresh.verification
                );
                // Each step may differ by up to KAPPA times the tolerance (see
                // flexmb::solve::newton): at most 400 KAPPA rtol = 4e-6 over the 400 steps if
                // nothing amplifies it. Before the fix: 3.6e-5 (and 2e-5 with the contraction
                // estimate but no safety factor).
                let bound = 400.0 * KAPPA * settings.newton.rtol;
                assert!(d[0] < bound && d[1] < bound, "{case}: {d:?}");
                // Two or more corrections with a reused matrix (its rate is measured); the
                // first step has no matrix to reuse.
                assert!(reused.iterations_per_step > 1.9, "{case}");
            }
        }
    }
}

/// Times at which the body-frame angular velocity about the intermediate axis changes
/// sign (the body flips).
fn flip_times(run: &Run) -> Vec<f64> {
    let w = |s: &State| s.v[0][4];
    run.states
        .windows(2)
        .filter(|p| w(&p[0]) * w(&p[1]) < 0.0)
        .map(|p| p[1].t)
        .collect()
}

/// Near the intermediate axis the motion amplifies any per-step error: with the old
/// acceptance test the flips came at 7.84, 12.275 and 16.605 s instead of full Newton's
/// 8.2875, 13.5675 and 18.845 s (18.844375 s at h / 4: the integration error is about 1 ms).
/// A reused matrix stays within 0.03 s with the default tolerances (22.5 ms observed at the
/// fourth flip: errors below the tolerance, amplified by the separatrix) and within 1 ms with
/// tight ones.
#[test]
fn intermediate_axis_flips_on_time_with_a_reused_matrix() {
    let (model, mut settings) = free_body("R3xSO3", [0.2, -0.1, 0.3], 0.9, 20.0);
    let fresh = flip_times(&trajectory(&model, settings, false));
    let reused = flip_times(&trajectory(&model, settings, true));
    println!("flips: full Newton {fresh:?}, reused matrix {reused:?}");
    assert!(fresh.len() >= 4 && reused.len() == fresh.len());
    for (a, b) in fresh.iter().zip(&reused) {
        assert!((a - b).abs() < 0.03, "flip at {b} s instead of {a} s");
    }
    settings.newton.rtol = 1e-10;
    settings.newton.atol = 1e-12;
    let tight = flip_times(&trajectory(&model, settings, true));
    for (a, b) in fresh.iter().zip(&tight) {
        assert!(
            (a - b).abs() < 1e-3,
            "tight tolerances: flip at {b} s instead of {a} s"
        );
    }
}

/// Every example, shortened (400 steps; the chains of 100 and 1000 links 100 and 5): with
/// the reused matrix (the default), verify finds every accepted step within the tolerance,
/// and the states agree with full Newton.
#[test]
fn every_example_passes_verify_and_matches_full_newton() {
    let mut names: Vec<String> = std::fs::read_dir(example(""))
        .expect("examples/")
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| n.ends_with(".toml"))
        .collect();
    names.sort();
    assert!(names.len() >= 16, "{names:?}");
    for name in names {
        let file = read_model_file(&example(&name), &[]).expect("example reads");
        match file.analysis {
            Analysis::Dynamic(settings) => {
                let steps = match name.as_str() {
                    "chain_1000.toml" => 5.0,
                    "chain_100.toml" => 100.0,
                    _ => 400.0,
                };
                let mut s = settings;
                s.t_end = s.t_end.min(steps * s.h);
                s.output_interval = 0.0;
                let reused = trajectory(&file.model, s, true);
                let fresh = trajectory(&file.model, s, false);
                // Steps that the step control cuts around impacts (contacts, gear pairs with
                // backlash) follow the solution, which the two runs have to the Newton
                // tolerance: compare their ends only.
                let impacts = !file.model.contacts.is_empty()
                    || file.model.gears.iter().any(|g| g.has_events());
                let ends = |run: &Run| run.states[run.states.len() - 1..].to_vec();
                let d = if !impacts {
                    largest_differences(&reused.states, &fresh.states)
                } else {
                    largest_differences(&ends(&reused), &ends(&fresh))
                };
                println!(
                    "{name}: differences q {:.2e} v {:.2e} lambda {:.2e}; verify {:.2e} / {:.2e}",
                    d[0], d[1], d[2], reused.verification.max_error, fresh.verification.max_error
                );
                for run in [&reused, &fresh] {
                    assert!(
                        run.verification.max_error <= 1.0,
                        "{name}: {:?}",
                        run.verification
                    );
                }
                // (Repeated impacts amplify the differences within the Newton tolerance.)
                let bound = if impacts { 100.0 } else { 1.0 };
                assert!(
                    d[0] < 1e-6 * bound && d[1] < 1e-5 * bound && d[2] < 1e-3,
                    "{name}: {d:?}"
                );
            }
            Analysis::Static(mut settings) => {
                settings.verify = true;
                let mut statics = Statics::new(&file.model, settings).expect("starts");
                let mut sensors = SensorEvaluator::new(&file.model);
                statics
                    .run(&mut |s: &flexmb::observe::Sample| {
                        sensors.evaluate(s.model, s.data, s.state);
                        Ok(())
                    })
                    .expect("runs");
                let v = statics.verification.expect("verify was on");
                println!(
                    "{name}: verify {:.2e} over {} load steps",
                    v.max_error, v.steps
                );
                assert!(v.max_error <= 1.0, "{name}: {v:?}");
            }
        }
    }
}

/// The heavy top on R3xSO(3) (examples/heavy_top_r3so3.toml, rho_inf = 0.6, h = 1.25e-4,
/// 0.1 s) with `extra` settings, run with verify on.
fn heavy_top_verified(extra: &[&str]) -> Simulation {
    let set: Vec<String> = ["solver.h=1.25e-4", "solver.rho_inf=0.6", "solver.t_end=0.1"]
        .iter()
        .chain(extra)
        .map(|s| s.to_string())
        .collect();
    let file = read_model_file(&example("heavy_top_r3so3.toml"), &set).expect("example reads");
    let Analysis::Dynamic(mut settings) = file.analysis else {
        unreachable!()
    };
    settings.verify = true;
    let mut sim = Simulation::new(&file.model, settings).expect("starts");
    sim.run(&mut |_: &flexmb::observe::Sample| Ok(()))
        .expect("runs");
    sim
}

/// The heavy top on R3xSO(3) (examples/heavy_top_r3so3.toml, rho_inf = 0.6, h = 1.25e-4,
/// 0.1 s): its multipliers, extrapolated from smooth values, start within the tolerance,
/// and their next correction (moved by the increments' through the coupling) once made the
/// dense matrix look stale and rebuilt it at every step (800 factorizations in 800 steps).
/// The reuse test judges a matrix on the blocks the predictor left outside the tolerance
/// (`Convergence::matrix_rate`): far fewer rebuilds, and verify still finds every step within
/// the tolerance.
#[test]
fn heavy_top_keeps_its_matrix_when_its_multipliers_start_within_the_tolerance() {
    let sim = heavy_top_verified(&[]);
    let stats = sim.stats;
    let verify = sim.verification.clone().expect("verify was on");
    println!(
        "{} steps, {} factorizations, {:.2} iterations per step; verify {:.2e}",
        stats.steps,
        stats.factorizations,
        stats.newton_iterations as f64 / stats.steps as f64,
        verify.max_error
    );
    assert_eq!(stats.steps, 800);
    assert!(stats.factorizations < stats.steps / 2, "{stats:?}");
    assert!(verify.max_error <= 1.0, "{verify:?}");
}

/// The adaptive predictor (`[solver] predictor = "adaptive"`): on the heavy top, whose
/// accelerations and multipliers are smooth over three steps, it takes both quadratic and
/// saves Newton iterations (2.49 per step against 3.00 with the linear one, which has 2.4
/// times the factorizations), and the steps stay within the tolerance of full Newton.
#[test]
fn adaptive_predictor_saves_iterations_on_the_heavy_top() {
    let run = |predictor: &str| {
        let sim = heavy_top_verified(&[predictor]);
        let verify = sim.verification.clone().expect("verify was on");
        assert!(verify.max_error <= 1.0, "{predictor}: {verify:?}");
        let s = sim.stats;
        println!(
            "{predictor}: {:.2} iterations per step, {} factorizations",
            s.newton_iterations as f64 / s.steps as f64,
            s.factorizations
        );
        (s.newton_iterations as f64 / s.steps as f64, sim.state)
    };
    let (linear, end_linear) = run("solver.predictor=linear");
    let (adaptive, end_adaptive) = run("solver.predictor=adaptive");
    assert!(adaptive < linear - 0.3, "{adaptive} against {linear}");
    // Both within the tolerance of the same solution (rtol 1e-6 on the increments).
    let moved = (end_linear.q[0].x - end_adaptive.q[0].x).norm();
    assert!(moved < 1e-6, "end positions {moved:e} apart");
}

/// The predictor's extrapolation weights reproduce polynomials of their order exactly on
/// uneven steps: linear through two points, quadratic through three.
#[test]
fn extrapolation_weights_are_exact_for_their_order() {
    use flexmb::solve::step::Extrapolation;
    let (h, h1, h2) = (0.3, 0.5, 0.2);
    let (t1, t0, t_1, t_2) = (h, 0.0, -h1, -h1 - h2);
    let quadratic = |t: f64| 1.5 - 2.0 * t + 0.7 * t * t;
    let linear = |t: f64| 1.5 - 2.0 * t;
    let q = Extrapolation::weights(h, h1, h2);
    let l = Extrapolation::weights(h, h1, 0.0);
    let at = |w: [f64; 3], f: &dyn Fn(f64) -> f64| w[0] * f(t0) + w[1] * f(t_1) + w[2] * f(t_2);
    assert!((at(q, &quadratic) - quadratic(t1)).abs() < 1e-14);
    assert!((at(l, &linear) - linear(t1)).abs() < 1e-14);
    assert_eq!(l[2], 0.0);
    // Equal steps: 3, -3, 1 and 2, -1.
    let e = Extrapolation::weights(1.0, 1.0, 1.0);
    assert!((e[0] - 3.0).abs() < 1e-15 && (e[1] + 3.0).abs() < 1e-15 && (e[2] - 1.0).abs() < 1e-15);
    assert_eq!(Extrapolation::weights(1.0, 1.0, 0.0), [2.0, -1.0, 0.0]);
}
