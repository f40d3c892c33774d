//! Time functions of time functions (`bump`, `smooth_step`, `delay`, `window`, `sum`,
//! `scaled`) in a model file: a half car whose rear wheel sees the front wheel's road bump
//! later reads, runs, and has the nested amplitudes as parameters (by the same paths as
//! `--set`, with derivatives matching central differences); bad nested fields are reported
//! at their line with their path, and `Model::validate` checks the same rules.

use crate::common;

use flexmb::elements::{evaluate_owned, Context, ElementKernel, ElementRef, Local, NodeState};
use flexmb::input::{parse_model_str, Analysis, ModelFile};
use flexmb::joints;
use flexmb::model::parameters::{JointParam, LoadParam};
use flexmb::model::{Model, ParamKind, Parameters, TimeFunction};
use flexmb::parameter_derivatives::{residual_derivative, Columns, Point};
use flexmb_lie::{Frame, Mat6};

/// A half car (chassis pitching and heaving in the x-z plane, two wheels on struts, tyre
/// springs to road patches) over a bump: the road under each wheel is a driven prismatic
/// joint, the rear one the front one's bump delayed by 0.26 s. Two loads on the chassis use
/// nested functions, one written inline, one as subtables.
const HALF_CAR: &str = r#"flexmb = 1
title = "Half car over a bump"

[model]
group = "R3xSO3"
gravity = [0.0, 0.0, 0.0]

[solver]
analysis = "dynamic"
t_end = 0.8
h = 1e-3
output_interval = 1e-2

[[body]]
name = "chassis"
position = [0.0, 0.0, 0.6]
mass = 600.0
inertia = [200.0, 800.0, 900.0]

[[body]]
name = "wheel_front"
position = [1.2, 0.0, 0.3]
mass = 40.0
inertia = [1.0, 1.0, 1.0]

[[body]]
name = "wheel_rear"
position = [-1.4, 0.0, 0.3]
mass = 40.0
inertia = [1.0, 1.0, 1.0]

[[body]]
name = "patch_front"
position = [1.2, 0.0, 0.0]
mass = 1.0
inertia = [0.01, 0.01, 0.01]

[[body]]
name = "patch_rear"
position = [-1.4, 0.0, 0.0]
mass = 1.0
inertia = [0.01, 0.01, 0.01]

[[joint]]
name = "pitch_plane"
type = "planar"
node_b = "chassis"
position = [0.0, 0.0, 0.6]
axis = [0.0, 1.0, 0.0]

[[joint]]
name = "strut_front"
type = "prismatic"
node_a = "chassis"
node_b = "wheel_front"
position = [1.2, 0.0, 0.3]
axis = [0.0, 0.0, 1.0]

[[joint]]
name = "strut_rear"
type = "prismatic"
node_a = "chassis"
node_b = "wheel_rear"
position = [-1.4, 0.0, 0.3]
axis = [0.0, 0.0, 1.0]

[[joint]]
name = "road_front"
type = "prismatic"
node_b = "patch_front"
position = [1.2, 0.0, 0.0]
axis = [0.0, 0.0, 1.0]
drive = { type = "bump", height = 0.05, start = 0.1, duration = 0.1 }

[[joint]]
name = "road_rear"
type = "prismatic"
node_b = "patch_rear"
position = [-1.4, 0.0, 0.0]
axis = [0.0, 0.0, 1.0]
drive = { type = "delay", delay = 0.26, function = { type = "bump", height = 0.05, start = 0.1, duration = 0.1 } }

[[spring]]
name = "suspension_front"
node_a = "chassis"
node_b = "wheel_front"
point_a = [1.2, 0.0, 0.6]
point_b = [1.2, 0.0, 0.3]
stiffness = 30000.0
damping = 2000.0

[[spring]]
name = "suspension_rear"
node_a = "chassis"
node_b = "wheel_rear"
point_a = [-1.4, 0.0, 0.6]
point_b = [-1.4, 0.0, 0.3]
stiffness = 30000.0
damping = 2000.0

[[spring]]
name = "tyre_front"
node_a = "wheel_front"
node_b = "patch_front"
point_a = [1.2, 0.0, 0.3]
point_b = [1.2, 0.0, 0.0]
stiffness = 200000.0
damping = 100.0

[[spring]]
name = "tyre_rear"
node_a = "wheel_rear"
node_b = "patch_rear"
point_a = [-1.4, 0.0, 0.3]
point_b = [-1.4, 0.0, 0.0]
stiffness = 200000.0
damping = 100.0

[[load]]
name = "road"
node = "chassis"
force = [0.0, 0.0, 200.0]
function = { type = "delay", delay = 0.3, function = { type = "bump", height = 1.0, duration = 0.2 } }

[[load]]
name = "kick"
node = "chassis"
force = [0.0, 0.0, 100.0]

[load.function]
type = "scaled"
factor = 0.5

[load.function.function]
type = "sum"

[[load.function.function.functions]]
type = "delay"
delay = 0.3
function = { type = "bump", height = 1.0, start = 0.0, duration = 0.2 }

[[load.function.function.functions]]
type = "window"
start = 0.5
end = 0.7
function = { type = "smooth_step", value = -1.0, start = 0.5, duration = 0.1 }

[[sensor]]
name = "road_front"
type = "joint_coordinate"
joint = "road_front"

[[sensor]]
name = "road_rear"
type = "joint_coordinate"
joint = "road_rear"

[[sensor]]
name = "wheel_front_z"
type = "position"
node = "wheel_front"
component = "z"

[[sensor]]
name = "wheel_rear_z"
type = "position"
node = "wheel_rear"
component = "z"

[[sensor]]
name = "chassis_z"
type = "position"
node = "chassis"
component = "z"
"#;

fn bump(height: f64, start: f64, duration: f64) -> TimeFunction {
    TimeFunction::Bump {
        height,
        start,
        duration,
    }
}

fn read(text: &str, overrides: &[&str]) -> Result<ModelFile, flexmb::input::InputError> {
    let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    parse_model_str(text, "half_car.toml", &overrides)
}

fn half_car(overrides: &[&str]) -> Model {
    read(HALF_CAR, overrides)
        .unwrap_or_else(|e| panic!("{e}"))
        .model
}

#[test]
fn nested_functions_read_from_inline_tables_and_subtables() {
    let m = half_car(&[]);
    let joint = |name: &str| m.joints.iter().find(|j| j.name == name).unwrap();
    assert_eq!(joint("road_front").drive, Some(bump(0.05, 0.1, 0.1)));
    assert_eq!(
        joint("road_rear").drive,
        Some(TimeFunction::Delay {
            delay: 0.26,
            function: Box::new(bump(0.05, 0.1, 0.1)),
        })
    );
    assert_eq!(
        m.loads[0].function,
        TimeFunction::Delay {
            delay: 0.3,
            function: Box::new(bump(1.0, 0.0, 0.2)),
        }
    );
    assert_eq!(
        m.loads[1].function,
        TimeFunction::Scaled {
            factor: 0.5,
            function: Box::new(TimeFunction::Sum {
                functions: vec![
                    TimeFunction::Delay {
                        delay: 0.3,
                        function: Box::new(bump(1.0, 0.0, 0.2)),
                    },
                    TimeFunction::Window {
                        start: 0.5,
                        end: 0.7,
                        function: Box::new(TimeFunction::SmoothStep {
                            value: -1.0,
                            start: 0.5,
                            duration: 0.1,
                        }),
                    },
                ],
            }),
        }
    );
    // The rear road is the front road 0.26 s later.
    let (front, rear) = (
        joint("road_front").drive.as_ref().unwrap(),
        joint("road_rear").drive.as_ref().unwrap(),
    );
    for t in [0.0, 0.12, 0.15, 0.19, 0.3] {
        let (a, b) = (rear.eval(t + 0.26), front.eval(t));
        assert!(
            (a.0 - b.0).abs() < 1e-15 && (a.1 - b.1).abs() < 1e-12,
            "at {t}"
        );
        assert!((a.2 - b.2).abs() < 1e-9 * b.2.abs().max(1.0), "at {t}");
    }
}

#[test]
fn half_car_rear_wheel_sees_the_bump_later() {
    let file = read(HALF_CAR, &[]).unwrap();
    let Analysis::Dynamic(settings) = file.analysis else {
        panic!("dynamic")
    };
    let h = common::run_model(&file.model, settings).unwrap_or_else(|e| panic!("{e}"));
    // The drives hold: the road coordinates are the bump, the rear one 0.26 s later.
    for (t, _) in h.series("road_front") {
        let front = bump(0.05, 0.1, 0.1).value(t);
        assert!((h.at("road_front", t) - front).abs() < 1e-9, "front at {t}");
        let rear = bump(0.05, 0.36, 0.1).value(t);
        assert!((h.at("road_rear", t) - rear).abs() < 1e-9, "rear at {t}");
    }
    assert!((h.at("road_front", 0.15) - 0.05).abs() < 1e-9);
    // Each wheel rises with its road (stiff tyres), the rear one 0.26 s after the front one.
    let peak = |name: &str| {
        h.series(name)
            .into_iter()
            .map(|(t, z)| (t, z - 0.3))
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap()
    };
    let (tf, zf) = peak("wheel_front_z");
    let (tr, zr) = peak("wheel_rear_z");
    println!("front wheel peak {zf:.4} m at {tf}, rear {zr:.4} m at {tr}");
    assert!((0.13..=0.2).contains(&tf), "front peak at {tf}");
    assert!((tr - tf - 0.26).abs() <= 0.03, "rear peak at {tr}");
    assert!(zf > 0.03 && zf < 0.07 && zr > 0.03 && zr < 0.07);
    // Before the rear bump the rear wheel has barely moved.
    assert!((h.at("wheel_rear_z", 0.3) - 0.3).abs() < 0.5 * zf);
}

/// The amplitudes of the nested functions are parameters whose paths are `--set` paths: the
/// registry's `set` gives the model `--set` gives.
#[test]
fn nested_amplitudes_are_parameters_with_set_paths() {
    let model = half_car(&[]);
    let params = Parameters::new(&model);
    let cases: &[(&str, f64)] = &[
        ("joint.road_front.drive.height", 0.07),
        ("joint.road_rear.drive.function.height", 0.08),
        ("load.road.function.function.height", 2.5),
        ("load.kick.function.factor", -0.75),
        (
            "load.kick.function.function.functions.0.function.height",
            3.0,
        ),
        (
            "load.kick.function.function.functions.1.function.value",
            0.4,
        ),
    ];
    for &(path, value) in cases {
        let id = params.id(path).unwrap_or_else(|e| panic!("{e}"));
        let expected = half_car(&[&format!("{path}={value}")]);
        let mut m = model.clone();
        params.set(&mut m, id, value);
        assert_eq!(m, expected, "{path}");
        assert_eq!(params.value(&m, id), value, "{path}");
    }
    // delay + bump: the rear bump's height moves the rear road only, and by the bump's shape.
    let id = params.id("joint.road_rear.drive.function.height").unwrap();
    assert!(matches!(
        params.kind(id),
        ParamKind::Joint(_, JointParam::Drive(0))
    ));
    let mut m = model.clone();
    params.set(&mut m, id, 0.1);
    let rear = m.joint_id("road_rear").unwrap();
    let drive = m.joints[rear.0].drive.as_ref().unwrap();
    assert!((drive.value(0.41) - 0.1).abs() < 1e-15);
    // f is linear in the height: df/dheight = f/height.
    let (d, f) = (drive.amplitude_derivative(0, 0.41), drive.eval(0.41));
    assert_eq!(d.0, 1.0);
    assert!((0.1 * d.2 - f.2).abs() < 1e-12 * f.2.abs());
    // Times are not parameters.
    for path in [
        "joint.road_rear.drive.delay",
        "joint.road_rear.drive.function.duration",
        "load.kick.function.function.functions.1.start",
    ] {
        assert!(params.id(path).is_err(), "{path}");
    }
    // A bad value given by --set on a nested field is reported with the override.
    let e = read(HALF_CAR, &["load.road.function.function.duration=-1"])
        .unwrap_err()
        .to_string();
    assert_contains(
        &e,
        &[
            &format!(
                "half_car.toml:{}:",
                line_of(HALF_CAR, "type = \"delay\", delay = 0.3")
            ),
            "field 'load[0].function.function.duration'",
            "must be positive",
            "(value set by --set 'load.road.function.function.duration=-1')",
        ],
    );
}

/// The equations of the loads and joints of `model` (the other elements do not depend on
/// time-function amplitudes): the nodal residual, `Phi` and `B v + Phi_t`.
fn load_and_joint_equations(model: &Model, at: &Point) -> Vec<f64> {
    let ctx = Context::at(model, at.t, at.load_factor);
    let mut r = vec![0.0; 6 * model.nodes.len()];
    for i in 0..model.loads.len() {
        let element = ElementRef::Load(i);
        let kernel = element.kernel(model);
        let node = kernel.node(0).unwrap();
        let slot = [at.nodes[node.0]];
        let local = Local::nodes(&slot);
        let (local, _) = evaluate_owned(&kernel, &ctx, &local, None);
        for k in 0..6 {
            r[6 * node.0 + k] += local[k];
        }
    }
    let (mut phi, mut psi) = (vec![], vec![]);
    let mut start = 0;
    for joint in &model.joints {
        let rows = joints::rows(joint);
        let state = |n: Option<flexmb::model::NodeId>| {
            n.map_or(NodeState::ground(Frame::identity()), |n| at.nodes[n.0])
        };
        let nodes = [state(joint.node_a), state(joint.node_b)];
        let lambda = &at.lambda[start..start + rows.len()];
        let jv = joints::evaluate_joint(model.group, joint, &rows, &nodes, at.t, lambda, None);
        for i in 0..rows.len() {
            let v = [&nodes[0].v, &nodes[1].v];
            let bv = jv.b[i].fixed_rows::<6>(0).dot(v[0]) + jv.b[i].fixed_rows::<6>(6).dot(v[1]);
            phi.push(jv.phi[i]);
            psi.push(bv + jv.phi_t[i]);
            for (k, n) in [joint.node_a, joint.node_b].iter().enumerate() {
                if let Some(n) = n {
                    for c in 0..6 {
                        r[6 * n.0 + c] += jv.b[i][6 * k + c] * lambda[i];
                    }
                }
            }
        }
        start += rows.len();
    }
    [r, phi, psi].concat()
}

/// The derivatives with respect to every amplitude of the nested functions (the load's
/// `factor` too, which multiplies the amplitudes of its function) match central differences
/// through `Parameters::set`, in the bumps, the window and outside them.
#[test]
fn nested_amplitude_derivatives_match_differences() {
    let model = half_car(&[]);
    let params = Parameters::new(&model);
    let n_rows: usize = model.joints.iter().map(|j| joints::rows(j).len()).sum();
    let mut rng = common::Lcg(3);
    let nodes: Vec<NodeState> = model
        .nodes
        .iter()
        .map(|n| NodeState {
            q: model.group.integrate(&n.frame, &rng.v6(0.1)),
            v: rng.v6(1.0),
            vdot: rng.v6(1.0),
            t: Mat6::identity(),
        })
        .collect();
    let lambda: Vec<f64> = (0..n_rows).map(|_| 10.0 * rng.next()).collect();
    let amplitudes: Vec<_> = params
        .ids()
        .filter(|&id| {
            matches!(
                params.kind(id),
                ParamKind::Load(_, LoadParam::Amplitude(_))
                    | ParamKind::Joint(_, JointParam::Drive(_))
            )
        })
        .collect();
    assert_eq!(amplitudes.len(), 6, "the amplitudes of the half car");
    let mut nonzero = 0;
    for t in [0.05, 0.15, 0.42, 0.55, 0.62] {
        let at = Point {
            nodes: &nodes,
            x: &[],
            xdot: &[],
            t,
            lambda: &lambda,
            load_factor: 1.0,
            inputs: None,
        };
        for &id in &amplitudes {
            let path = params.path(id);
            let nd = 6 * model.nodes.len();
            let (mut dr, mut dphi, mut dpsi) =
                (vec![0.0; nd], vec![0.0; n_rows], vec![0.0; n_rows]);
            let columns = Columns {
                dr: &mut dr,
                dphi: &mut dphi,
                dpsi: &mut dpsi,
                de: &mut [],
            };
            residual_derivative(&model, &params, id, &at, columns);
            let analytic = [dr, dphi, dpsi].concat();
            let p = params.value(&model, id);
            let e = 1e-6 * (1.0 + p.abs());
            let eval = |v: f64| {
                let mut m = model.clone();
                params.set(&mut m, id, v);
                load_and_joint_equations(&m, &at)
            };
            let (plus, minus) = (eval(p + e), eval(p - e));
            let scale = plus
                .iter()
                .chain(&minus)
                .fold(1e-300f64, |m, x| m.max(x.abs()));
            for (i, (a, (x, y))) in analytic.iter().zip(plus.iter().zip(&minus)).enumerate() {
                let fd = (x - y) / (2.0 * e);
                assert!(
                    (a - fd).abs() <= 1e-7 * (1.0 + scale),
                    "{path} at t = {t}, entry {i}: {a} vs {fd}"
                );
            }
            if analytic.iter().any(|a| a.abs() > 1e-9) {
                nonzero += 1;
            }
        }
    }
    // Every amplitude matters somewhere (factor: wherever its function is not 0).
    assert!(nonzero >= 8, "{nonzero} non-zero derivative columns");
}

fn assert_contains(message: &str, parts: &[&str]) {
    for p in parts {
        assert!(message.contains(p), "error message lacks {p:?}:\n{message}");
    }
}

/// 1-based line of the first line holding `needle`.
fn line_of(text: &str, needle: &str) -> usize {
    1 + text
        .lines()
        .position(|l| l.contains(needle))
        .unwrap_or_else(|| panic!("{needle:?} not found"))
}

/// The error for `HALF_CAR` with `from` replaced by `to`, which names `field` at the line of
/// `at` in the edited text (`to` when `at` is empty).
fn check(from: &str, to: &str, at: &str, field: &str, more: &[&str]) {
    assert!(HALF_CAR.contains(from), "{from:?} not in the model");
    let text = HALF_CAR.replacen(from, to, 1);
    let e = match read(&text, &[]) {
        Ok(_) => panic!("accepted with {to:?}"),
        Err(e) => e.to_string(),
    };
    println!("{e}");
    let line = line_of(&text, if at.is_empty() { to } else { at });
    assert_contains(
        &e,
        &[
            &format!("half_car.toml:{line}:"),
            &format!("field '{field}'"),
        ],
    );
    assert_contains(&e, more);
}

#[test]
fn bad_nested_fields_name_their_line_and_path() {
    let kick = "load[1].function.function";
    // A value out of range, in an inline table in a subtable of an array of subtables.
    check(
        "height = 1.0, start = 0.0, duration = 0.2",
        "height = 1.0, start = 0.0, duration = -0.2",
        "",
        &format!("{kick}.functions[0].function.duration"),
        &["(load 'kick')", "must be positive, got -0.2"],
    );
    // An unknown key, and a misspelt type, in a subtable.
    check(
        "value = -1.0, start = 0.5",
        "vaule = -1.0, start = 0.5",
        "",
        &format!("{kick}.functions[1].function.vaule"),
        &["unknown key 'vaule'", "did you mean 'value'"],
    );
    check(
        "type = \"window\"",
        "type = \"windw\"",
        "",
        &format!("{kick}.functions[1].type"),
        &["did you mean 'window'"],
    );
    check(
        "type = \"scaled\"\nfactor = 0.5",
        "type = \"scaled\"\nfactor = \"half\"",
        "factor = \"half\"",
        "load[1].function.factor",
        &["expected a number"],
    );
    // A window that closes before it opens.
    check(
        "start = 0.5\nend = 0.7",
        "start = 0.5\nend = 0.4",
        "end = 0.4",
        &format!("{kick}.functions[1].end"),
        &["must exceed start = 0.5"],
    );
    // A missing inner function: at the line of the table that lacks it.
    check(
        "type = \"delay\"\ndelay = 0.3\nfunction = { type = \"bump\", height = 1.0, start = 0.0, duration = 0.2 }",
        "type = \"delay\"\ndelay = 0.3",
        "[[load.function.function.functions]]",
        &format!("{kick}.functions[0].function"),
        &["required but missing"],
    );
    // A delay of the wrong type, inline.
    check(
        "delay = 0.26,",
        "delay = \"late\",",
        "",
        "joint[4].drive.delay",
        &["(joint 'road_rear')", "expected a number"],
    );
    // Sums of no function and of too many.
    let road = "function = { type = \"delay\", delay = 0.3, function = { type = \"bump\", height = 1.0, duration = 0.2 } }";
    check(
        road,
        "function = { type = \"sum\", functions = [] }",
        "",
        "load[0].function.functions",
        &["must hold 1 to 64 functions, got 0"],
    );
    let many = vec!["{ type = \"constant\", value = 1.0 }"; 65].join(", ");
    check(
        road,
        &format!("function = {{ type = \"sum\", functions = [{many}] }}"),
        "",
        "load[0].function.functions",
        &["must hold 1 to 64 functions, got 65"],
    );
    // Nested scaled factors whose product is out of range: at the inner factor.
    check(
        road,
        "function = { type = \"scaled\", factor = 1e20, function = { type = \"scaled\", factor = -1e20, function = { type = \"constant\", value = 1.0 } } }",
        "",
        "load[0].function.function.factor",
        &["multiply to 1e40"],
    );
    // Nine levels of functions: the ninth is reported.
    let mut deep = "{ type = \"constant\", value = 1.0 }".to_string();
    for _ in 0..8 {
        deep = format!("{{ type = \"delay\", delay = 0.01, function = {deep} }}");
    }
    let ninth = format!("load[0]{}", ".function".repeat(9));
    check(
        road,
        &format!("function = {deep}"),
        "",
        &ninth,
        &["nested more than 8 levels deep"],
    );
    // Eight levels are fine.
    let mut eight = "{ type = \"constant\", value = 1.0 }".to_string();
    for _ in 0..7 {
        eight = format!("{{ type = \"delay\", delay = 0.01, function = {eight} }}");
    }
    let text = HALF_CAR.replacen(road, &format!("function = {eight}"), 1);
    let m = read(&text, &[]).unwrap_or_else(|e| panic!("{e}")).model;
    let path = format!("load.road{}.value", ".function".repeat(8));
    assert!(Parameters::new(&m).id(&path).is_ok(), "{path}");
}

/// `Model::validate` checks a model built in Rust by the same rules, naming the nested
/// field in its message.
#[test]
fn validate_checks_nested_functions() {
    let with = |f: TimeFunction| {
        let mut m = half_car(&[]);
        m.loads[0].function = f;
        m.validate().map_err(|e| e.to_string())
    };
    let delayed = |g: TimeFunction| TimeFunction::Delay {
        delay: 0.1,
        function: Box::new(g),
    };
    assert!(with(delayed(bump(1.0, 0.0, 0.2))).is_ok());
    let e = with(delayed(bump(1.0, 0.0, 0.0))).unwrap_err();
    assert_contains(
        &e,
        &["load", "function", "function.duration must be between"],
    );
    let e = with(TimeFunction::Sum {
        functions: vec![bump(1.0, 0.0, 0.2), bump(f64::NAN, 0.0, 0.2)],
    })
    .unwrap_err();
    assert_contains(&e, &["functions[1].height must be between", "NaN"]);
    let e = with(TimeFunction::Sum { functions: vec![] }).unwrap_err();
    assert_contains(&e, &["1 to 64 functions, got 0"]);
    let e = with(TimeFunction::Window {
        start: 1.0,
        end: 1.0,
        function: Box::new(bump(1.0, 0.0, 0.2)),
    })
    .unwrap_err();
    assert_contains(&e, &["end = 1 must exceed start = 1"]);
    let scaled = |factor: f64, g: TimeFunction| TimeFunction::Scaled {
        factor,
        function: Box::new(g),
    };
    let e = with(scaled(1e20, scaled(-1e20, bump(1.0, 0.0, 0.2)))).unwrap_err();
    assert_contains(
        &e,
        &[
            "function.factor -100000000000000000000 makes the factors",
            "multiply to 1e40",
        ],
    );
    assert!(with(scaled(1e20, scaled(1e-5, bump(1.0, 0.0, 0.2)))).is_ok());
    let mut f = bump(1.0, 0.0, 0.2);
    for _ in 0..7 {
        f = delayed(f);
    }
    assert!(with(f.clone()).is_ok(), "8 levels");
    let e = with(delayed(f)).unwrap_err();
    assert_contains(&e, &["nested more than 8 levels deep"]);
    // A deeply nested function is refused without recursing through it.
    let mut f = bump(1.0, 0.0, 0.2);
    for _ in 0..1000 {
        f = delayed(f);
    }
    let e = with(f).unwrap_err();
    assert_contains(&e, &["nested more than 8 levels deep"]);
}
