//! Gradients and events (`flexmb::sensitivity`, module documentation, "Events"): a run in
//! which a contact or a gear flank closes or opens is refused by the direct and adjoint
//! methods and by the optimizer, naming the element and the time of the run's first event;
//! the same elements in runs where the event does not happen, and steps cut for output
//! times, keep gradients that agree with the analytic ones and with central differences; the
//! finite differences run through events; a hold's samples, at fixed times, are followed
//! exactly, and the engine reports them, and a bounce's closing and opening, as events.

use flexmb::input::parse_model_str;
use flexmb::sensitivity::optimize::{optimize, Evaluator};
use flexmb::sensitivity::{self, Gradients, Problem, SensitivityError, Setup};
use flexmb::solve::StepEvent;
use std::sync::Arc;

/// An example's text with `extra` appended (its sensitivity sections).
fn example(file: &str, extra: &str) -> String {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples")
        .join(file);
    std::fs::read_to_string(path).expect("example") + extra
}

/// The sensitivity problem of a model text with the overrides `set`, and its setup.
fn problem(text: &str, set: &[&str]) -> (Problem, Setup) {
    let set: Vec<String> = set.iter().map(|s| s.to_string()).collect();
    let mut file = parse_model_str(text, "model.toml", &set).expect("model");
    let setup = file.sensitivity.take().expect("a sensitivity setup");
    let problem = setup.problem(Arc::new(file.model), file.analysis);
    (problem, setup)
}

/// The event that `result` was refused for: what happened and when.
fn refused(result: Result<Gradients, SensitivityError>) -> (String, f64) {
    match result {
        Err(SensitivityError::Event { what, t }) => (what, t),
        other => panic!("not refused for an event: {other:?}"),
    }
}

/// Direct and adjoint agree to round-off and with central differences (relative step
/// `1e-6`) within `fd` of each criterion's largest gradient; the adjoint's gradients.
fn agree(name: &str, p: &Problem, fd: f64) -> Gradients {
    let d = sensitivity::direct(p).expect("direct");
    let a = sensitivity::adjoint(p, &mut |_, _| {}).expect("adjoint");
    let f = sensitivity::finite_differences(p, 1e-6).expect("fd");
    for (c, ((ga, gd), gf)) in a
        .gradients
        .iter()
        .zip(&d.gradients)
        .zip(&f.gradients)
        .enumerate()
    {
        let largest = ga.iter().fold(1e-300f64, |m, v| m.max(v.abs()));
        for (k, ((x, y), z)) in ga.iter().zip(gd).zip(gf).enumerate() {
            assert!(
                (x - y).abs() <= 1e-9 * largest,
                "{name} [{c}][{k}]: adjoint {x:e}, direct {y:e}"
            );
            assert!(
                (x - z).abs() <= fd * largest,
                "{name} [{c}][{k}]: adjoint {x:e}, central differences {z:e}"
            );
        }
    }
    a
}

/// The ball of `examples/ball_drop.toml` (released at rest 0.1 m above the plane: the
/// contact closes at t = sqrt(2 0.1 / 9.81) = 0.142784 s) with its height at the end as the
/// criterion.
fn ball() -> String {
    let sections = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/ball_drop_sensitivity.toml");
    example(
        "ball_drop.toml",
        &std::fs::read_to_string(sections).expect("sections"),
    )
}

/// The events the engine reports in a run of `p` (`Simulation::last_step_event` after each
/// step).
fn events(p: &Problem) -> Vec<StepEvent> {
    let settings = *p.analysis.dynamic().expect("dynamic");
    let mut sim = flexmb::Simulation::new(Arc::clone(&p.model), settings).expect("simulation");
    let mut events = Vec::new();
    while sim.state.t < settings.t_end {
        sim.step().expect("step");
        events.extend(sim.last_step_event());
    }
    events
}

#[test]
fn a_ball_through_its_impact_is_refused_naming_the_contact_and_the_time() {
    // Before: adjoint d height / d restitution = -132 at h = 1e-2 (+210 at 1e-4, -93.6 at
    // 2e-5) with exit code 0, where central differences with a step of 1e-2 give +0.48.
    let (p, setup) = problem(&ball(), &[]);
    let onset = (2.0f64 * 0.1 / 9.81).sqrt();
    for (what, t) in [
        refused(sensitivity::adjoint(&p, &mut |_, _| {})),
        refused(sensitivity::direct(&p)),
    ] {
        assert_eq!(what, "contact 'floor' closes");
        // The step that closes the contact is located on the gap (penetration below a
        // micrometre at 1.4 m/s).
        assert!((t - onset).abs() < 1e-4, "t = {t}, onset {onset}");
    }
    let e = sensitivity::adjoint(&p, &mut |_, _| {}).expect_err("refused");
    assert!(e.is_refusal());
    let text = e.to_string();
    assert!(
        text.contains("contact 'floor' closes")
            && text.contains("t = 1.4279")
            && text.contains("--method fd"),
        "{text}"
    );
    // The optimizer's first evaluation is the same adjoint run: refused, nothing found.
    let stopped = optimize(
        &mut Evaluator::new(p.clone()),
        &setup.design,
        0,
        5,
        &mut |_| {},
    )
    .expect_err("refused");
    assert!(matches!(stopped.error, SensitivityError::Event { .. }));
    assert!(stopped.history.is_empty());
    // The finite differences go through the impacts: with a step above the events' noise they
    // estimate the gradient (+0.48 for the restitution at 1e-2).
    let f = sensitivity::finite_differences(&p, 1e-2).expect("fd");
    assert!((0.3..0.7).contains(&f.gradients[0][0]), "{:?}", f.gradients);
}

#[test]
fn a_ball_before_its_impact_has_exact_gradients_on_steps_cut_for_outputs() {
    // To t = 0.135 s the ball falls free (gap 1.1 cm at the end), the step control shortens
    // the steps as the gap closes, and output times every 0.015 s cut the 1e-2 s steps: no
    // event. Free fall: height = z0 + v0 t + g t^2 / 2, integrated exactly by the scheme.
    let t_end = 0.135;
    let (p, _) = problem(
        &ball(),
        &["solver.t_end=0.135", "solver.output_interval=0.015"],
    );
    let a = agree("ball before impact", &p, 1e-6);
    assert!(
        a.stats.steps > 15,
        "steps cut for outputs and the approach: {}",
        a.stats.steps
    );
    let exact = [0.0, t_end, t_end * t_end / 2.0];
    for (g, e) in a.gradients[0].iter().zip(exact) {
        assert!(
            (g - e).abs() < 1e-12,
            "{:?} against {exact:?}",
            a.gradients[0]
        );
    }
}

#[test]
fn an_optimizer_that_reaches_an_event_stops_with_what_it_found() {
    // Lowering the height at t = 0.13 s over the gravity, bounded in [-30, -1]: from
    // g = -9.81 (no contact) the line search tries stronger gravity, which brings the ball
    // onto the plane within the run: that evaluation is refused, and the improvements found
    // before it are kept.
    let (p, setup) = problem(&ball(), &["solver.t_end=0.13"]);
    let stopped = optimize(&mut Evaluator::new(p), &setup.design, 0, 20, &mut |_| {})
        .expect_err("stopped at an event");
    match &stopped.error {
        SensitivityError::Event { what, .. } => assert_eq!(what, "contact 'floor' closes"),
        e => panic!("{e}"),
    }
    assert!(!stopped.history.is_empty(), "the start is an improvement");
    assert!(stopped.runs > stopped.history.len() - 1);
}

/// The spur gear stage of `examples/gear_rattle.toml` at `h = 1e-4` with `edits` to its
/// text, differentiated with respect to the mesh's damping and stiffness and the driving
/// torque: the wheel's speed at the end and the integral of the squared transmission
/// error.
fn gears(edits: &[(&str, &str)]) -> String {
    let mut text = example(
        "gear_rattle.toml",
        r#"
[[design_parameter]]
path = "gear.mesh.damping"
scale = 900.0

[[design_parameter]]
path = "gear.mesh.mesh_stiffness"
scale = 4e8

[[design_parameter]]
path = "load.drive.torque.2"
scale = 5.0

[[criterion]]
name = "wheel_speed"
terminal = "omega_wheel"

[[criterion]]
name = "dte_squared"
integral = "sq(dte)"
"#,
    );
    for (from, to) in edits {
        assert!(text.contains(from), "{from}");
        text = text.replacen(from, to, 1);
    }
    text
}

const STEADY: (&str, &str) = (
    "function = { type = \"sine\", amplitude = 1.0, frequency = 20.0 }",
    "function = { type = \"constant\", value = 1.0 }",
);
const NO_BACKLASH: (&str, &str) = ("backlash = 1e-4\n", "\n");
const COARSE: [&str; 3] = [
    "solver.h=1e-4",
    "solver.output_interval=0",
    "solver.t_end=0.01",
];

#[test]
fn a_gear_pair_that_keeps_its_flank_has_exact_gradients() {
    // Without backlash (the damper acts on the flank in contact only: a flank change would
    // switch it) and under a steady torque, the drive flank stays in contact.
    let (p, _) = problem(&gears(&[STEADY, NO_BACKLASH]), &COARSE);
    agree("gear pair in mesh", &p, 1e-5);
    // With backlash, to before the teeth cross it (0.38 ms at 5 N m), no flank closes.
    let (p, _) = problem(
        &gears(&[STEADY]),
        &[
            "solver.h=2e-5",
            "solver.output_interval=0",
            "solver.t_end=3e-4",
        ],
    );
    agree("gear pair in its backlash", &p, 1e-5);
}

#[test]
fn a_gear_pair_whose_flank_closes_or_opens_is_refused() {
    // Before: on the rattle (0.04 s) `--check` reported a largest relative difference of
    // 1.03, signs wrong, with exit code 0.
    let (p, _) = problem(&gears(&[STEADY]), &COARSE);
    let (what, t) = refused(sensitivity::adjoint(&p, &mut |_, _| {}));
    assert_eq!(what, "gear pair 'mesh': its drive flank closes");
    assert!(t > 3e-4 && t < 5e-4, "the backlash crossed at t = {t}");
    // Without backlash, the reversing torque turns the load onto the coast flank (the drive
    // flank, touching at the start, closes at once: not an event).
    let (p, _) = problem(
        &gears(&[NO_BACKLASH]),
        &[
            "solver.h=1e-4",
            "solver.output_interval=0",
            "solver.t_end=0.04",
        ],
    );
    let (what, t) = refused(sensitivity::direct(&p));
    assert_eq!(what, "gear pair 'mesh': its drive flank opens");
    assert!(
        t > 0.02 && t < 0.03,
        "the torque reverses at t = 0.025: {t}"
    );
}

/// `examples/pid_mass_spring.toml` with a zero-order hold of period 0.1 s between the PID
/// and the motor, differentiated with respect to the proportional gain.
fn held() -> String {
    let text = example(
        "pid_mass_spring.toml",
        r#"
[[block]]
name = "zoh"
type = "hold"
input = "pid"
period = 0.1

[[design_parameter]]
path = "control.pid.kp"
scale = 200.0

[[criterion]]
name = "x_end"
terminal = "x"
"#,
    );
    let motor = "name = \"motor\"\ntype = \"actuator\"\ninput = \"pid\"";
    assert!(text.contains(motor));
    text.replacen(
        motor,
        "name = \"motor\"\ntype = \"actuator\"\ninput = \"zoh\"",
        1,
    )
}

#[test]
fn gradients_go_through_the_samples_of_a_hold() {
    // A sample at fixed times sets the held value and the hold's output to the input's: the
    // step's end through it is that copy (ElementKernel::event_map), so the direct and
    // adjoint methods follow it. Before: refused, and without the refusal the held value's
    // derivative decayed like e^-t from the start (0.0951 against 0.1 at t = 0.05 s: the
    // statics' diagonal of a hold leaked into the step's dE/dx).
    let text = held().replace(
        "terminal = \"x\"\n",
        "terminal = \"x\"\n\n[[sensor]]\nname = \"held\"\ntype = \"block\"\nblock = \"zoh\"\n\n[[criterion]]\nname = \"held_end\"\nterminal = \"held\"\n\n[[design_parameter]]\npath = \"control.pid.kd\"\n\n[[design_parameter]]\npath = \"spring.spring.stiffness\"\n",
    );
    for t_end in ["0.05", "0.35"] {
        let (p, _) = problem(&text, &[&format!("solver.t_end={t_end}")]);
        let a = agree(&format!("hold to {t_end} s"), &p, 1e-6);
        if t_end == "0.05" {
            // before the first sample: the value held from t = 0, kp e(0) + ..., e(0) = 0.1
            let kp = p.params.id("control.pid.kp").unwrap();
            let k = p.design.iter().position(|&d| d == kp).unwrap();
            assert!(
                (a.gradients[1][k] - 0.1).abs() < 1e-9,
                "{:?}",
                a.gradients[1]
            );
        }
    }
    // and with the adjoint's steps recomputed from checkpoints
    let (mut p, _) = problem(&text, &["solver.t_end=0.35"]);
    let full = sensitivity::adjoint(&p, &mut |_, _| {}).expect("adjoint");
    p.memory_budget = 120_000;
    let checkpointed = sensitivity::adjoint(&p, &mut |_, _| {}).expect("adjoint");
    assert_eq!(full.gradients, checkpointed.gradients);
    assert!(
        checkpointed.stats.recomputed_steps > 0,
        "{:?}",
        checkpointed.stats
    );
    // The engine reports the samples as events, and nothing between them.
    let (p, _) = problem(&held(), &["solver.t_end=0.25"]);
    let events = events(&p);
    let times: Vec<f64> = events.iter().map(|e| e.t).collect();
    assert!(
        events
            .iter()
            .all(|e| e.what == "hold 'zoh' samples" && e.held.is_some()),
        "{events:?}"
    );
    assert_eq!(times.len(), 2, "{times:?}");
    assert!(
        (times[0] - 0.1).abs() < 1e-12 && (times[1] - 0.2).abs() < 1e-12,
        "{times:?}"
    );
}

#[test]
fn the_engine_reports_a_bounce_as_a_closing_and_an_opening() {
    // The ball's first impact lasts about 0.3 ms: the contact closes at the onset and opens
    // at the release, and nothing happens in free flight.
    let (p, _) = problem(&ball(), &["solver.t_end=0.2"]);
    let events = events(&p);
    let what: Vec<&str> = events.iter().map(|e| e.what.as_str()).collect();
    assert_eq!(what, ["contact 'floor' closes", "contact 'floor' opens"]);
    let contact = events[1].t - events[0].t;
    assert!(
        contact > 1e-4 && contact < 1e-3,
        "in contact for {contact} s"
    );
}

#[test]
fn a_step_that_leaves_a_parameter_unchanged_is_an_error() {
    // Before: a relative step of 1e-20 gave every gradient as 0.
    let (p, _) = problem(&ball(), &["solver.t_end=0.05"]);
    match sensitivity::finite_differences(&p, 1e-20) {
        Err(e @ SensitivityError::FiniteDifference { failed: None, .. }) => {
            assert!(e.is_refusal());
            assert!(e.to_string().contains("unchanged"), "{e}");
        }
        other => panic!("{other:?}"),
    }
}
