//! Control blocks coupled to the mechanics (`[[block]]`, `flexmb::elements::control`):
//! closed loops against the exact solutions of their linear ODEs, the order of the coupled
//! generalized-alpha scheme, its spectral radius at infinity, and the examples.

use crate::common;

use nalgebra::{DMatrix, DVector};

/// `exp(A t) z0`, by scaling and squaring of the Taylor series (the test's reference; `A`
/// small and dense).
fn expm_apply(a: &DMatrix<f64>, t: f64, z0: &DVector<f64>) -> DVector<f64> {
    let norm = (a * t).abs().max() * a.nrows() as f64;
    let squarings = (norm.max(1.0).log2().ceil() as i32 + 4).max(0);
    let at = a * (t / 2f64.powi(squarings));
    let n = a.nrows();
    let mut e = DMatrix::identity(n, n);
    let mut term = DMatrix::identity(n, n);
    for k in 1..30 {
        term = &term * &at / k as f64;
        e += &term;
    }
    for _ in 0..squarings {
        e = &e * &e;
    }
    e * z0
}

/// The PID loop of `examples/pid_mass_spring.toml` as `z' = A z`, `z = (x, x', x_i, x_f, r)`.
fn pid_loop() -> DMatrix<f64> {
    let (m, k, c) = (2.0, 50.0, 1.0);
    let (kp, ki, kd, tf) = (200.0, 400.0, 20.0, 0.01);
    // e = r - x; F = kp e + ki x_i + kd (e - x_f) / tf
    let f_row = [-(kp + kd / tf), 0.0, ki, -kd / tf, kp + kd / tf];
    let mut a = DMatrix::zeros(5, 5);
    a[(0, 1)] = 1.0;
    for j in 0..5 {
        a[(1, j)] = f_row[j] / m;
    }
    a[(1, 0)] -= k / m;
    a[(1, 1)] -= c / m;
    a[(2, 0)] = -1.0;
    a[(2, 4)] = 1.0;
    a[(3, 0)] = -1.0 / tf;
    a[(3, 3)] = -1.0 / tf;
    a[(3, 4)] = 1.0 / tf;
    a
}

/// Runs a model given as text (`file`: its name, the base of relative paths in it).
fn run_text(text: &str, file: &str) -> common::History {
    let f = flexmb::input::parse_model_str(text, file, &[]).expect("model");
    let flexmb::input::Analysis::Dynamic(settings) = f.analysis else {
        panic!("{file} is a dynamic analysis")
    };
    common::run_model(&f.model, settings).expect("runs")
}

/// Largest error of the sensor `x` against the exact closed-loop response, over the run.
fn pid_error(h: f64) -> (f64, common::History) {
    let hist = common::run("pid_mass_spring.toml", &[&format!("solver.h={h}")]);
    let a = pid_loop();
    let z0 = DVector::from_vec(vec![0.0, 0.0, 0.0, 0.0, 0.1]);
    let err = hist
        .series("x")
        .iter()
        .map(|&(t, x)| (x - expm_apply(&a, t, &z0)[0]).abs())
        .fold(0.0, f64::max);
    (err, hist)
}

#[test]
fn pid_mass_spring_follows_the_exact_closed_loop_at_second_order() {
    let hs = [2e-3, 1e-3, 5e-4];
    let mut errs = Vec::new();
    for &h in &hs {
        let (err, hist) = pid_error(h);
        if h == 1e-3 {
            // the force at t = 0: the PID's proportional and filtered-derivative kick
            let f0 = hist.series("force")[0].1;
            assert!(
                (f0 - (200.0 + 20.0 / 0.01) * 0.1).abs() < 1e-9,
                "F(0) = {f0}"
            );
        }
        errs.push(err);
    }
    let order = common::order(&hs, &errs);
    eprintln!("PID loop: errors {errs:?}, order {order:.3}");
    assert!(errs[1] < 1e-5, "error at h = 1e-3: {:.3e}", errs[1]);
    assert!((order - 2.0).abs() < 0.15, "order {order}");
}

/// A stiff closed loop (all its modes far beyond the step's resolution) for the spectral
/// radius at infinity: a mass on a stiff spring (omega h = 1000) whose position a fast lag
/// (h / T = 1000) feeds back as a force; the spring is a gain block too, so that the whole
/// loop is linear.
fn stiff_loop(rho_inf: f64) -> Vec<(f64, f64, f64)> {
    let text = format!(
        r#"flexmb = 1
[model]
group = "R3xSO3"
[solver]
analysis = "dynamic"
t_end = 2000.0
h = 10.0
rho_inf = {rho_inf}
rtol = 1e-12
atol = 1e-30
[[body]]
name = "mass"
mass = 1.0
inertia = [1.0, 1.0, 1.0]
position = [0.01, 0.0, 0.0]
[[joint]]
name = "guide"
type = "prismatic"
node_b = "mass"
position = [0.01, 0.0, 0.0]
axis = [1.0, 0.0, 0.0]
[[block]]
name = "x"
type = "measure"
quantity = "position"
node = "mass"
component = "x"
[[block]]
name = "filter"
type = "lag"
input = "x"
time_constant = 1e-2
gain = -3e3
[[block]]
name = "spring"
type = "gain"
input = "x"
gain = -1e4
[[block]]
name = "force"
type = "sum"
inputs = ["spring", "filter"]
[[block]]
name = "push"
type = "actuator"
input = "force"
target = "force"
node = "mass"
component = "x"
[[sensor]]
name = "x"
type = "position"
node = "mass"
component = "x"
[[sensor]]
name = "filter"
type = "block"
block = "filter"
"#
    );
    let h = run_text(&text, "stiff.toml");
    h.rows.iter().map(|(t, v)| (*t, v[0], v[1])).collect()
}

#[test]
fn coupled_scheme_damps_unresolved_modes_at_rho_inf() {
    // Brüls & Golinval 2008: the coupled scheme (Lie group generalized-alpha for
    // the mechanics, its first-order form for the block states, both from rho_inf) has the
    // spectral radius rho_inf for modes far beyond the step's resolution. The loop is
    // linear, so its solution is z_n = G^n z_0: the decay over steps 100 to 200 gives the
    // spectral radius of G (a Jordan block of size k biases it by (200/100)^((k - 1)/100),
    // under 1.5 % for k <= 3).
    let norm = |rows: &[(f64, f64, f64)], n: usize| {
        let f0 = rows.iter().fold(0.0f64, |m, r| m.max(r.2.abs()));
        rows[n..n + 10]
            .iter()
            .fold(0.0f64, |m, r| m.max(r.1.abs() / 0.01 + r.2.abs() / f0))
    };
    for rho in [0.5, 0.8, 0.9] {
        let rows = stiff_loop(rho);
        let radius = (norm(&rows, 190) / norm(&rows, 90)).powf(1.0 / 100.0);
        eprintln!("rho_inf {rho}: measured spectral radius {radius:.4}");
        assert!((radius - rho).abs() < 0.015, "rho_inf {rho}: {radius}");
    }
    // rho_inf = 0 annihilates them: 12 orders of magnitude in 10 steps
    let rows = stiff_loop(0.0);
    let decay = norm(&rows, 10) / norm(&rows, 0);
    eprintln!("rho_inf 0: decay over 10 steps {decay:.2e}");
    assert!(decay < 1e-12, "{decay}");
}

#[test]
fn zero_order_hold_samples_a_csv_signal_on_its_period() {
    // A signal read from a CSV file (t, value: a ramp of slope 2), sampled by a zero-order
    // hold of period 0.05 s while the steps are 0.013 s: the step control lands on every
    // sample, and the held value is the signal at the last sample, to round-off.
    let dir = std::env::temp_dir().join(format!("flexmb_hold_{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    std::fs::write(dir.join("signal.csv"), "t, u\n0.0, 0.0\n1.0, 2.0\n").expect("csv");
    let text = r#"flexmb = 1
[model]
group = "R3xSO3"
[solver]
analysis = "dynamic"
t_end = 0.5
h = 0.013
[[body]]
name = "mass"
mass = 1.0
inertia = [1.0, 1.0, 1.0]
[[block]]
name = "signal"
type = "source"
file = "signal.csv"
column = "u"
[[block]]
name = "held"
type = "hold"
input = "signal"
period = 0.05
[[sensor]]
name = "held"
type = "block"
block = "held"
[[sensor]]
name = "signal"
type = "block"
block = "signal"
"#;
    let file = dir.join("hold.toml");
    let h = run_text(text, file.to_str().expect("path"));
    let mut samples = 0;
    for (t, v) in &h.rows {
        let (held, signal) = (v[0], v[1]);
        assert!((signal - 2.0 * t).abs() < 1e-12, "signal at {t}: {signal}");
        // the last sample at or before t
        let k = ((t + 1e-9) / 0.05).floor();
        assert!(
            (held - 2.0 * 0.05 * k).abs() < 1e-12,
            "held at {t}: {held}, expected {}",
            0.1 * k
        );
        if ((t / 0.05).round() * 0.05 - t).abs() < 1e-12 {
            samples += 1;
        }
    }
    // every sample instant is an output point (the steps land on it)
    assert_eq!(samples, 11, "sample instants among the outputs");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn servo_constraint_gives_the_inverse_dynamics_input_of_a_mass_spring_mass() {
    // examples/servo_mass_spring_mass.toml (its header derives the exact solution): cart 1
    // prescribed, x1 = A (1 - cos(w t)); cart 2 on the spring, y = x2 - 1 from
    // m2 y'' + k y = k x1; the input u = m1 x1'' - k (y - x1).
    let (a, w, m1, m2, k): (f64, f64, f64, f64, f64) = (0.1, std::f64::consts::PI, 1.0, 0.5, 100.0);
    let big = (k / m2).sqrt();
    let c = a * big * big / (big * big - w * w);
    let x1 = |t: f64| a * (1.0 - (w * t).cos());
    let y = |t: f64| a - c * (w * t).cos() + (c - a) * (big * t).cos();
    let u = |t: f64| m1 * a * w * w * (w * t).cos() - k * (y(t) - x1(t));
    let mut errors = Vec::new();
    let hs = [2e-3, 1e-3, 5e-4];
    for h in hs {
        let hist = common::run("servo_mass_spring_mass.toml", &[&format!("solver.h={h}")]);
        let on_path = hist
            .series("x1")
            .iter()
            .map(|&(t, x)| (x - x1(t)).abs())
            .fold(0.0, f64::max);
        assert!(on_path < 1e-10, "x1 off its trajectory by {on_path:e}");
        let err = hist
            .series("force")
            .iter()
            .map(|&(t, f)| (f - u(t)).abs())
            .fold(0.0, f64::max);
        let err_x2 = hist
            .series("x2")
            .iter()
            .map(|&(t, x)| (x - 1.0 - y(t)).abs())
            .fold(0.0, f64::max);
        eprintln!("h {h}: input error {err:.3e}, x2 error {err_x2:.3e}");
        errors.push(err);
    }
    let order = common::order(&hs, &errors);
    eprintln!("servo input: errors {errors:?}, order {order:.2}");
    // |u| up to about 3 N
    assert!(errors[1] < 1e-3, "input error at h = 1e-3: {:e}", errors[1]);
    assert!((order - 2.0).abs() < 0.2, "order {order}");
}

#[test]
fn noncollocated_servo_gives_the_inverse_dynamics_input_of_a_mass_spring_mass() {
    // examples/servo_noncollocated.toml (its header derives the exact solution): the force u
    // on cart 1 makes cart 2 follow x2 = 1 + A (1 - cos(w t)) through the spring k, a
    // relative degree 4, index-5 problem; x1 = x2 - 1 + m2 x2''/k and
    // u = (m1 + m2) x2'' + (m1 m2 / k) x2''''. rho_inf = 0 (the example's): rho_inf = 0.5
    // and 0.9 leave errors of 0.1 N and 8 N in u at h = 1e-3 (docs/model-format.md).
    let (a, w, m1, m2, k): (f64, f64, f64, f64, f64) = (0.1, std::f64::consts::PI, 1.0, 0.5, 100.0);
    let x2dd = |t: f64| a * w * w * (w * t).cos();
    let x2 = |t: f64| 1.0 + a * (1.0 - (w * t).cos());
    let x1 = |t: f64| x2(t) - 1.0 + m2 * x2dd(t) / k;
    // x2'''' = -w^2 x2''
    let u = |t: f64| (m1 + m2) * x2dd(t) - m1 * m2 / k * w * w * x2dd(t);
    let hs = [8e-3, 4e-3, 2e-3];
    let (mut errors, mut errors_x1) = (Vec::new(), Vec::new());
    for h in hs {
        let hist = common::run(
            "servo_noncollocated.toml",
            &[&format!("solver.h={h}"), "solver.output_interval=0"],
        );
        let on_path = hist
            .series("x2")
            .iter()
            .map(|&(t, x)| (x - x2(t)).abs())
            .fold(0.0, f64::max);
        assert!(on_path < 1e-12, "x2 off its trajectory by {on_path:e}");
        // The first five steps are a start-up layer: the scheme starts from a_0 = vdot_0,
        // which the index-5 problem turns into an error of u of 0.04 N whatever h, gone
        // after five steps (rho_inf = 0); the error after it is measured apart.
        let (mut start, mut err) = (0.0f64, 0.0f64);
        for &(t, f) in &hist.series("force") {
            let e = (f - u(t)).abs();
            if t < 5.5 * h {
                start = start.max(e);
            } else {
                err = err.max(e);
            }
        }
        let err_x1 = hist
            .series("x1")
            .iter()
            .map(|&(t, x)| (x - x1(t)).abs())
            .fold(0.0, f64::max);
        eprintln!(
            "h {h}: input error {err:.3e} (first five steps {start:.3e}), x1 error {err_x1:.3e}"
        );
        assert!(start < 0.05, "start-up error of u at h = {h}: {start:e}");
        errors.push(err);
        errors_x1.push(err_x1);
    }
    let order = common::order(&hs, &errors);
    let order_x1 = common::order(&hs, &errors_x1);
    eprintln!(
        "non-collocated servo: input errors {errors:?}, order {order:.2}; x1 order {order_x1:.2}"
    );
    // |u| up to 1.43 N
    assert!(errors[2] < 1e-4, "input error at h = 2e-3: {:e}", errors[2]);
    assert!(
        errors_x1[2] < 3e-7,
        "x1 error at h = 2e-3: {:e}",
        errors_x1[2]
    );
    assert!((order - 2.0).abs() < 0.2, "order {order}");
    assert!((order_x1 - 2.0).abs() < 0.1, "x1 order {order_x1}");
}

#[test]
fn diagnoses_name_blocks() {
    // The unknowns of the diagram in words (what a Newton failure or a singular matrix
    // reports): the block and its state or output, not an index.
    let f = flexmb::input::read_model_file(&common::example("pid_mass_spring.toml"), &[])
        .expect("model");
    let layout = flexmb::data::Layout::new(&f.model);
    let words: Vec<String> = (0..layout.n_states)
        .map(|k| layout.describe_unknown(&f.model, layout.state_offset() + k))
        .collect();
    // reference (output), position (output), error (output), pid (2 states, output)
    assert!(
        words[0].contains("output 0 of block 'reference'"),
        "{words:?}"
    );
    assert!(words[3].contains("state 0 of block 'pid'"), "{words:?}");
    assert!(words[4].contains("state 1 of block 'pid'"), "{words:?}");
    assert!(words[5].contains("output 0 of block 'pid'"), "{words:?}");
}

/// examples/pid_mass_spring.toml with more blocks before its PID: `blocks` (TOML).
fn pid_with_blocks(blocks: &str) -> String {
    let text = std::fs::read_to_string(common::example("pid_mass_spring.toml")).unwrap();
    let pid = "[[block]]\nname = \"pid\"";
    assert!(text.contains(pid));
    text.replace(pid, &format!("{blocks}\n\n{pid}"))
}

/// The outputs at t = 0 are solved at the initial kinematics by the diagram's own Newton
/// iteration, which fails as the solver's do (a `NewtonError` in
/// `SolveError::InitialStates`, the output blamed in words). An algebraic loop without a
/// solution, `y = y^2 + 1` (Newton cycles between 0 and 1), is refused with the model file
/// on its block (it was taken as it stood: `y = 1` written at t = 0, then the first step
/// failed); a loop of gain 1, `y = y + e` (the reader refuses it too), set through the Rust
/// API fails `Simulation::new` on its singular matrix (it was diagnosed as a singular mass
/// matrix).
#[test]
fn outputs_that_cannot_be_solved_at_the_start_are_diagnosed_on_their_block() {
    let no_root = pid_with_blocks(
        "[[block]]\nname = \"one\"\ntype = \"source\"\nfunction = { type = \"constant\", value = 1.0 }\n\n[[block]]\nname = \"square\"\ntype = \"product\"\ninputs = [\"loop\", \"loop\"]\n\n[[block]]\nname = \"loop\"\ntype = \"sum\"\ninputs = [\"square\", \"one\"]",
    );
    let e = flexmb::input::parse_model_str(&no_root, "no_root.toml", &[])
        .expect_err("y = y^2 + 1 has no solution");
    let e = e.to_string();
    for part in [
        "no_root.toml:",
        "field 'block[4].inputs' (block 'square')",
        "the algebraic loop through blocks 'square', 'loop' cannot be solved",
        "no convergence in 30 iterations",
        "the equation of output 0 of block 'square' (control blocks)",
    ] {
        assert!(e.contains(part), "{part}: {e}");
    }
    let gain = |g: f64| {
        pid_with_blocks(&format!(
            "[[block]]\nname = \"echo\"\ntype = \"gain\"\ninput = \"loop\"\ngain = {g}\n\n[[block]]\nname = \"loop\"\ntype = \"sum\"\ninputs = [\"echo\", \"error\"]"
        ))
    };
    let file = flexmb::input::parse_model_str(&gain(0.5), "loop.toml", &[]).expect("gain 1/2");
    let flexmb::input::Analysis::Dynamic(settings) = file.analysis else {
        panic!("dynamic")
    };
    let mut model = file.model;
    let echo = model.control.find("echo").unwrap();
    let k = model.control.blocks[echo]
        .kind
        .param_names()
        .iter()
        .position(|n| n == "gain")
        .unwrap();
    model.control.blocks[echo].set_param(k, 1.0);
    let e = flexmb::Simulation::new(model, settings)
        .map(|_| ())
        .expect_err("a singular loop");
    let flexmb::SolveError::InitialStates {
        error,
        worst_equation,
        ..
    } = &e
    else {
        panic!("{e}")
    };
    assert!(
        matches!(**error, flexmb::solve::NewtonError::Singular { .. }),
        "{e}"
    );
    assert!(worst_equation.contains("of block '"), "{e}");
}

#[test]
fn transfer_function_realizes_its_ratio() {
    // (s + 2) / (s^2 + 3 s + 2) = 1 / (s + 1): its unit step response is 1 - exp(-t); the
    // lag block T = 1 gives the same (both integrated by the same scheme, so they agree to
    // the Newton tolerance, and both to the exact response at second order in h).
    let text = r#"flexmb = 1
[model]
group = "R3xSO3"
[solver]
analysis = "dynamic"
t_end = 3.0
h = 1e-3
rtol = 1e-12
atol = 1e-14
[[body]]
name = "mass"
mass = 1.0
inertia = [1.0, 1.0, 1.0]
[[block]]
name = "step"
type = "source"
function = { type = "constant", value = 1.0 }
[[block]]
name = "tf"
type = "transfer_function"
input = "step"
numerator = [1.0, 2.0]
denominator = [1.0, 3.0, 2.0]
[[block]]
name = "lag"
type = "lag"
input = "step"
time_constant = 1.0
[[sensor]]
name = "tf"
type = "block"
block = "tf"
[[sensor]]
name = "lag"
type = "block"
block = "lag"
"#;
    let h = run_text(text, "tf.toml");
    let (mut exact, mut lag) = (0.0f64, 0.0f64);
    for (t, v) in &h.rows {
        exact = exact.max((v[0] - (1.0 - (-t).exp())).abs());
        lag = lag.max((v[0] - v[1]).abs());
    }
    eprintln!("transfer function: {exact:.2e} from 1 - exp(-t), {lag:.2e} from the lag");
    assert!(exact < 1e-6, "{exact}");
    assert!(lag < 1e-6, "{lag}");
}

#[test]
fn a_measured_constraint_force_is_the_joints_reaction() {
    // A pendulum (2 kg, centre of mass 0.5 m below the pivot) starts at the bottom with
    // 3 rad/s; its revolute joint's force on the bob is measured by a block and fed back as
    // a small torque about the pivot (so the multipliers' columns are in the loop). At the
    // bottom the reaction is vertical, m (g + L omega^2) = 28.62 N; throughout, the measured
    // force equals the `joint_force` sensor (the reaction computed apart from the blocks).
    let text = r#"flexmb = 1
[model]
group = "R3xSO3"
gravity = [0.0, -9.81, 0.0]
[solver]
analysis = "dynamic"
t_end = 1.0
h = 2e-3
output_interval = 0.02
[[body]]
name = "bob"
position = [0.0, 0.0, 0.0]
mass = 2.0
com = [0.0, -0.5, 0.0]
inertia = [0.01, 0.01, 0.01]
angular_velocity = [0.0, 0.0, 3.0]
[[joint]]
name = "pivot"
type = "revolute"
node_b = "bob"
position = [0.0, 0.0, 0.0]
axis = [0.0, 0.0, 1.0]
[[block]]
name = "fy"
type = "measure"
quantity = "constraint_force"
joint = "pivot"
component = "y"
[[block]]
name = "fx"
type = "measure"
quantity = "constraint_force"
joint = "pivot"
axis = [1.0, 0.0, 0.0]
[[block]]
name = "feedback"
type = "gain"
input = "fx"
gain = 0.02
[[block]]
name = "torque"
type = "actuator"
target = "joint"
joint = "pivot"
input = "feedback"
[[sensor]]
name = "fy"
type = "block"
block = "fy"
[[sensor]]
name = "fx"
type = "block"
block = "fx"
[[sensor]]
name = "reaction_y"
type = "joint_force"
joint = "pivot"
component = "y"
[[sensor]]
name = "reaction_x"
type = "joint_force"
joint = "pivot"
component = "x"
"#;
    let h = run_text(text, "constraint_force.toml");
    let (fy0, exact) = (h.rows[0].1[0], 2.0 * (9.81 + 0.5 * 9.0));
    assert!(
        (fy0 - exact).abs() < 1e-9 * exact,
        "reaction at the bottom {fy0} N, m (g + L w^2) = {exact} N"
    );
    let mut worst: f64 = 0.0;
    for (t, v) in &h.rows {
        let (fy, fx, ry, rx) = (v[0], v[1], v[2], v[3]);
        worst = worst.max((fy - ry).abs()).max((fx - rx).abs());
        assert!(
            (fy - ry).abs() < 1e-8 * exact && (fx - rx).abs() < 1e-8 * exact,
            "t = {t}: measured ({fx}, {fy}) against the reaction ({rx}, {ry})"
        );
    }
    // the exact coupling terms: Newton converges as without the feedback
    let per_step = h.stats.newton_iterations as f64 / h.stats.steps as f64;
    assert!(per_step < 4.0, "{per_step} Newton iterations per step");
    println!(
        "measured against the reaction: worst {worst:.2e} N, {per_step:.2} iterations/step, at t = 0.5 s: {:?}",
        h.rows[25]
    );
}

#[test]
fn a_measured_section_force_is_the_cantilevers_bending_moment() {
    // A cantilever (1 m, 4 elements along x, clamped at the root) under a tip force of
    // -2 N along y, statics: the bending moment of the root element is the force's moment
    // about its midpoint, M = F (L - L/8) = 1.75 N m (small deflection: EI = 1e4 N m^2), the
    // clamp's reaction on the root node +2 N along y and +2 N m about z (about the joint
    // point); the measurements feed a block (a sum), as a controller would read them.
    let text = r#"flexmb = 1
[model]
group = "SE3"
gravity = [0.0, 0.0, 0.0]
[solver]
analysis = "static"
load_factor = 1.0
increment = 0.5
[[beam]]
name = "arm"
start = [0.0, 0.0, 0.0]
end = [1.0, 0.0, 0.0]
elements = 4
orientation = [0.0, 0.0, 1.0]
section = { EA = 1e8, GA2 = 1e8, GA3 = 1e8, GJ = 1e4, EI2 = 1e4, EI3 = 1e4, rhoA = 1.0, rhoJ = 0.01, rhoI2 = 0.01, rhoI3 = 0.01 }
[[joint]]
name = "clamp"
type = "fixed"
node_b = "arm.0"
position = [0.0, 0.0, 0.0]
[[load]]
name = "tip"
node = "arm.4"
force = [0.0, -2.0, 0.0]
[[block]]
name = "bending"
type = "measure"
quantity = "section_force"
beam = "arm[0]"
component = "bending_3"
[[block]]
name = "reaction"
type = "measure"
quantity = "constraint_force"
joint = "clamp"
component = "y"
[[block]]
name = "reaction_moment"
type = "measure"
quantity = "constraint_moment"
joint = "clamp"
component = "z"
[[block]]
name = "both"
type = "sum"
inputs = ["bending", "reaction"]
signs = [1.0, 1.0]
[[sensor]]
name = "bending"
type = "block"
block = "bending"
[[sensor]]
name = "stress"
type = "beam_stress"
beam = "arm[0]"
component = "bending_3"
[[sensor]]
name = "reaction"
type = "block"
block = "reaction"
[[sensor]]
name = "reaction_moment"
type = "block"
block = "reaction_moment"
[[sensor]]
name = "both"
type = "block"
block = "both"
"#;
    let f = flexmb::input::parse_model_str(text, "section_force.toml", &[]).expect("model");
    let flexmb::input::Analysis::Static(settings) = f.analysis else {
        panic!("a static analysis")
    };
    let mut statics = flexmb::solve::Statics::new(&f.model, settings).expect("statics");
    let mut sensors = flexmb::sensors::SensorEvaluator::new(&f.model);
    let mut last = Vec::new();
    statics
        .run(&mut |s: &flexmb::observe::Sample| {
            last = sensors.evaluate(s.model, s.data, s.state);
            Ok(())
        })
        .expect("converges");
    let (bending, stress, reaction, moment, both) = (last[0], last[1], last[2], last[3], last[4]);
    assert!(
        (bending - stress).abs() < 1e-10,
        "measured {bending} against the beam_stress sensor {stress}"
    );
    // the sign of a section's bending moment: a tip force along -y bends the arm down
    assert!(
        (bending.abs() - 1.75).abs() < 1e-3 * 1.75,
        "root element's bending moment {bending} N m, F (L - L/8) = 1.75"
    );
    assert!((reaction - 2.0).abs() < 1e-8, "clamp force {reaction} N");
    assert!(
        (moment - 2.0).abs() < 1e-3 * 2.0,
        "clamp moment {moment} N m"
    );
    assert!(
        (both - bending - reaction).abs() < 1e-10,
        "the sum reads them"
    );
}

#[test]
fn a_measured_contact_force_is_the_contacts_normal_force() {
    // The dropped ball of examples/ball_drop.toml (4.11 kg, Lankarani-Nikravesh, e = 0.8,
    // 0.1 m free fall) with its contact force along z measured by a block, every step an
    // output: through the impacts (resolved by the step control) the measurement equals the
    // contact's normal force (the `contact` sensor, computed apart from the blocks), and once
    // the ball rests (the bounces die out geometrically: 0.8^2 of the height each time) it
    // carries the weight, m g = 40.32 N.
    let text = r#"flexmb = 1
[model]
group = "R3xSO3"
gravity = [0.0, 0.0, -9.81]
[solver]
analysis = "dynamic"
t_end = 2.5
h = 1e-2
rho_inf = 0.9
output_interval = 0
rtol = 1e-10
atol = 1e-14
[[body]]
name = "ball"
mass = 4.11
position = [0.0, 0.0, 0.15]
inertia = [4.11e-3, 4.11e-3, 4.11e-3]
[[contact]]
name = "floor"
node_b = "ball"
a = { shape = "plane", point = [0.0, 0.0, 0.0], normal = [0.0, 0.0, 1.0] }
b = { shape = "sphere", center = [0.0, 0.0, 0.15], radius = 0.05 }
law = "lankarani_nikravesh"
hertz = { young = [210e9, 210e9], poisson = [0.3, 0.3] }
restitution = 0.8
[[block]]
name = "fz"
type = "measure"
quantity = "contact_force"
contact = "floor"
component = "z"
[[sensor]]
name = "fz"
type = "block"
block = "fz"
[[sensor]]
name = "normal_force"
type = "contact"
contact = "floor"
component = "normal_force"
"#;
    let h = run_text(text, "contact_force.toml");
    // The measurement is the force the step applied. The sensor evaluates the contact after
    // the step, when the impact velocity of a contact that closed in it has been stored
    // (the damping term then changes): the two agree on the steps that start closed.
    let (mut peak, mut worst, mut compared) = (0.0f64, 0.0f64, 0);
    for pair in h.rows.windows(2) {
        let (t, v) = &pair[1];
        let (fz, normal) = (v[0], v[1]);
        peak = peak.max(fz);
        if pair[0].1[1] > 0.0 {
            compared += 1;
            worst = worst.max((fz - normal).abs() / (1.0 + normal.abs()));
            assert!(
                (fz - normal).abs() <= 1e-8 * (1.0 + normal.abs()),
                "t = {t}: measured {fz} N against the normal force {normal} N"
            );
        }
    }
    assert!(compared > 100, "{compared} steps in contact compared");
    println!(
        "measured against the normal force: worst relative {worst:.1e} over {compared} steps, peak {peak:.0} N"
    );
    let weight = 4.11 * 9.81;
    let last = h.rows.last().expect("outputs").1[0];
    assert!(
        (last - weight).abs() < 1e-3 * weight,
        "at rest the contact carries the weight: {last} N against {weight} N"
    );
    // every step is an output: the impacts' peaks are among them
    assert!(peak > 10.0 * weight, "impacts: peak {peak} N");
}
