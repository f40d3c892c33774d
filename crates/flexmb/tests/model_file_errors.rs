//! The TOML model file front end: a good file builds the same `Model` as the Rust API,
//! overrides work, and every kind of bad input gives an error naming file, line and field.

use flexmb::input::{parse_model_str, read_model_file, Analysis, InputError, ModelFile};
use flexmb::model::{
    box_inertia, frame_from_axis, rotation_from_vector, JointKind, Model, NodeId, Sensor,
    SensorKind, SpringDamper, TimeFunction,
};
use flexmb::DynamicSettings;
use flexmb_lie::{Frame, Group, Mat3, Vec3};
use std::path::PathBuf;

const GOOD: &str = r#"flexmb = 1
title = "Driven crank"
description = "A hub driven by a revolute joint, a box pinned to it, a spring."

[model]
group = "SE3"
gravity = [0.0, 0.0, -9.81]

[solver]
analysis = "dynamic"
t_end = 1.0
h = 1e-3

[[node]]
name = "hub"

[[body]]
name = "hub_body"
node = "hub"
mass = 2.0
inertia = [0.1, 0.1, 0.1]

[[body]]
name = "top"
position = [1.0, 0.0, 0.0]
orientation = { axis = [0, 0, 1], angle_deg = 90 }
angular_velocity = [0.0, 0.0, 1.0]
mass = 3.0
com = [0.5, 0, 0]
inertia = { box = [1.0, 0.1, 0.2] }

[[joint]]
name = "crank"
type = "revolute"
node_b = "hub"
position = [0, 0, 0]
axis = [0, 0, 1]
drive = { type = "linear", slope = 0.6 }

[[joint]]
name = "pin"
type = "spherical"
node_a = "hub"
node_b = "top"
position = [1, 0, 0]

[[spring]]
name = "s"
node_b = "top"
point_a = [0, 0, 1]
point_b = [1, 0, 0]
stiffness = 100

[[sensor]]
name = "tip_x"
type = "position"
node = "top"
point = [1, 1, 0]
component = "x"

[[sensor]]
name = "angle"
type = "joint_coordinate"
joint = "crank"

[[sensor]]
name = "E"
type = "total_energy"
"#;

/// The model of `GOOD`, built by hand with the Rust API.
fn expected_model() -> Model {
    let mut m = Model::new(Group::SE3);
    m.title = "Driven crank".into();
    m.gravity = Vec3::new(0.0, 0.0, -9.81);
    let hub = m.add_node("hub", Frame::identity());
    let r = rotation_from_vector(&(Vec3::z() * 90f64.to_radians()));
    let top = m.add_node("top", Frame::new(Vec3::new(1.0, 0.0, 0.0), r));
    m.nodes[top.0].angular_velocity = r.transpose() * Vec3::z();
    m.add_body(
        "hub_body",
        hub,
        2.0,
        Vec3::zeros(),
        Mat3::from_diagonal(&Vec3::repeat(0.1)),
    );
    let inertia = box_inertia(3.0, &Vec3::new(1.0, 0.1, 0.2));
    m.add_body("top", top, 3.0, Vec3::new(0.5, 0.0, 0.0), inertia);
    let crank = m.add_joint(
        "crank",
        JointKind::Revolute,
        None,
        Some(hub),
        Vec3::zeros(),
        frame_from_axis(&Vec3::z(), None),
        None,
    );
    m.joints[crank.0].drive = Some(TimeFunction::Linear {
        slope: 0.6,
        start: 0.0,
        offset: 0.0,
    });
    m.add_joint(
        "pin",
        JointKind::Spherical,
        Some(hub),
        Some(top),
        Vec3::x(),
        Mat3::identity(),
        None,
    );
    let to_top = |p: Vec3| m.nodes[top.0].frame.inverse().point(&p);
    m.springs.push(SpringDamper {
        name: "s".into(),
        node_a: None,
        node_b: Some(top),
        point_a: Vec3::z(),
        point_b: to_top(Vec3::x()),
        stiffness: 100.0,
        damping: 0.0,
        rest_length: 2f64.sqrt(),
    });
    let tip = to_top(Vec3::new(1.0, 1.0, 0.0));
    m.sensors.push(Sensor {
        name: "tip_x".into(),
        kind: SensorKind::Position {
            node: top,
            point: tip,
            component: 0,
        },
    });
    m.sensors.push(Sensor {
        name: "angle".into(),
        kind: SensorKind::JointCoordinate { joint: crank },
    });
    m.sensors.push(Sensor {
        name: "E".into(),
        kind: SensorKind::TotalEnergy,
    });
    m
}

fn good(overrides: &[&str]) -> Result<ModelFile, InputError> {
    let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    parse_model_str(GOOD, "good.toml", &overrides)
}

fn dynamic(file: &ModelFile) -> DynamicSettings {
    match file.analysis {
        Analysis::Dynamic(s) => s,
    }
}

#[test]
fn good_file_builds_the_model_of_the_rust_api() {
    let file = good(&[]).unwrap();
    assert_eq!(file.model, expected_model());
    assert_eq!(dynamic(&file), DynamicSettings::new(1.0, 1e-3));
    assert!(file.description.starts_with("A hub driven"));
    // Sanity of the conversions the expected model relies on.
    let m = &file.model;
    assert!((m.springs[0].point_b).norm() < 1e-15);
    match m.sensors[0].kind {
        SensorKind::Position { point, .. } => assert!((point - Vec3::x()).norm() < 1e-12),
        _ => unreachable!(),
    }
    assert!((m.nodes[1].angular_velocity - Vec3::z()).norm() < 1e-12);
    assert_eq!(m.bodies[1].node, NodeId(1));
}

#[test]
fn overrides_replace_and_insert_values() {
    let file = good(&[
        "solver.h=0.0005",
        "body.top.mass=2",
        "body.0.mass = 5",
        "solver.rtol=1e-8",
        "model.gravity.2=-1.62",
        "model.group=R3xSO3",
        "sensor.tip_x.component=y",
    ])
    .unwrap();
    let s = dynamic(&file);
    assert_eq!(s.h, 0.0005);
    assert_eq!(s.h_min, 0.0005 * 1e-4);
    assert_eq!(s.newton.rtol, 1e-8);
    let m = &file.model;
    assert_eq!(m.bodies[1].mass, 2.0);
    assert_eq!(
        m.bodies[1].inertia,
        box_inertia(2.0, &Vec3::new(1.0, 0.1, 0.2))
    );
    assert_eq!(m.bodies[0].mass, 5.0);
    assert_eq!(m.gravity, Vec3::new(0.0, 0.0, -1.62));
    assert_eq!(m.group, Group::R3xSO3);
    assert!(matches!(
        m.sensors[0].kind,
        SensorKind::Position { component: 1, .. }
    ));

    // An override's value is checked like the file's, at the line of the value it replaced.
    let e = good(&["body.top.mass=-1"]).unwrap_err().to_string();
    assert_contains(
        &e,
        &[
            "good.toml:28:",
            "field 'body[1].mass'",
            "(body 'top')",
            "must be positive",
            "--set 'body.top.mass=-1'",
        ],
    );
    let e = good(&["solver.h=fast"]).unwrap_err().to_string();
    assert_contains(
        &e,
        &["good.toml:12:", "field 'solver.h'", "string \"fast\""],
    );
    let e = good(&["solver.hh=1"]).unwrap_err().to_string();
    assert_contains(
        &e,
        &[
            "good.toml:9:",
            "field 'solver.hh'",
            "unknown key",
            "did you mean 'h'",
        ],
    );
}

fn bad(name: &str) -> String {
    let path: PathBuf = [env!("CARGO_MANIFEST_DIR"), "tests", "data", "bad", name]
        .iter()
        .collect();
    match read_model_file(&path, &[]) {
        Ok(_) => panic!("{name} was accepted"),
        Err(e) => e.to_string(),
    }
}

fn assert_contains(message: &str, parts: &[&str]) {
    for p in parts {
        assert!(message.contains(p), "error message lacks {p:?}:\n{message}");
    }
}

/// The error of `bad/{name}.toml` names the file, the line and the field.
fn check(name: &str, line: usize, field: &str, more: &[&str]) {
    let e = bad(&format!("{name}.toml"));
    println!("{e}");
    assert_contains(
        &e,
        &[&format!("{name}.toml:{line}:"), &format!("field '{field}'")],
    );
    assert_contains(&e, more);
}

#[test]
fn syntax_error() {
    let e = bad("syntax_error.toml");
    println!("{e}");
    assert_contains(&e, &["syntax_error.toml:16:", "TOML syntax error"]);
}

#[test]
fn unknown_key() {
    check(
        "unknown_key",
        16,
        "body[0].mas",
        &["unknown key 'mas'", "did you mean 'mass'", "(body 'top')"],
    );
}

#[test]
fn unknown_key_in_inline_table() {
    check(
        "unknown_key_inline",
        25,
        "joint[0].drive.slop",
        &["unknown key 'slop'", "(joint 'pivot')"],
    );
}

#[test]
fn missing_field() {
    check("missing_field", 19, "joint[0].node_b", &["required"]);
}

#[test]
fn wrong_type() {
    check(
        "wrong_type",
        16,
        "body[0].mass",
        &["expected a number", "\"heavy\""],
    );
}

#[test]
fn wrong_array_length() {
    check(
        "wrong_length",
        6,
        "model.gravity",
        &["3 numbers", "2 elements"],
    );
}

#[test]
fn non_positive_mass() {
    check(
        "nonpositive_mass",
        16,
        "body[0].mass",
        &["(body 'top')", "must be positive, got -1"],
    );
}

#[test]
fn inertia_not_positive_definite() {
    check(
        "inertia_not_pd",
        17,
        "body[0].inertia",
        &["positive definite"],
    );
}

#[test]
fn inertia_not_symmetric() {
    check(
        "inertia_not_symmetric",
        17,
        "body[0].inertia",
        &["must be symmetric", "row 1 column 2 is 0.5"],
    );
}

#[test]
fn dangling_node_reference() {
    check(
        "dangling_node",
        22,
        "joint[0].node_b",
        &["unknown node 'tpo'", "did you mean 'top'"],
    );
}

#[test]
fn duplicate_name() {
    check(
        "duplicate_name",
        20,
        "body[1].name",
        &["duplicate body name 'top'", "body[0]"],
    );
}

#[test]
fn bad_enum_value() {
    check(
        "bad_enum",
        21,
        "joint[0].type",
        &["\"hinge\"", "\"revolute\"", "\"universal\""],
    );
}

#[test]
fn bad_sensor_component() {
    check(
        "bad_component",
        29,
        "sensor[0].component",
        &["\"u\"", "\"x\", \"y\", \"z\""],
    );
}

#[test]
fn universal_axes_not_perpendicular() {
    check("universal_axes", 25, "joint[0].axis_b", &["perpendicular"]);
}

#[test]
fn malformed_overrides() {
    let path: PathBuf = [
        env!("CARGO_MANIFEST_DIR"),
        "tests",
        "data",
        "bad",
        "malformed_override.toml",
    ]
    .iter()
    .collect();
    let set = |o: &str| match read_model_file(&path, &[o.to_string()]) {
        Ok(_) => panic!("override {o} was accepted"),
        Err(e) => {
            println!("{e}");
            e.to_string()
        }
    };
    assert!(
        read_model_file(&path, &[]).is_ok(),
        "the base file is valid"
    );
    let f = "malformed_override.toml";
    // Unknown item: the error is at the [[body]] array.
    let e = set("body.nosuch.mass=2");
    assert_contains(
        &e,
        &[
            &format!("{f}:13:"),
            "field 'body.nosuch'",
            "--set 'body.nosuch.mass=2'",
            "'top'",
        ],
    );
    // Index out of range.
    let e = set("body.3.mass=2");
    assert_contains(&e, &[&format!("{f}:13:"), "field 'body.3'", "out of range"]);
    // Unknown parent table.
    let e = set("solver.newton.rtol=1e-8");
    assert_contains(
        &e,
        &[&format!("{f}:8:"), "field 'solver.newton'", "cannot be set"],
    );
    // A scalar has no children.
    let e = set("solver.h.x=1");
    assert_contains(
        &e,
        &[&format!("{f}:11:"), "field 'solver.h'", "not a table"],
    );
    // Not KEY=VALUE, and not a TOML value.
    let e = set("solver.h");
    assert_contains(
        &e,
        &[&format!("{f}:11:"), "field 'solver.h'", "KEY.PATH=VALUE"],
    );
    let e = set("model.gravity=[0, 0");
    assert_contains(
        &e,
        &[
            &format!("{f}:6:"),
            "field 'model.gravity'",
            "not a valid TOML value",
        ],
    );
}

#[test]
fn unreadable_file_is_an_error() {
    let e = read_model_file("no/such/file.toml".as_ref(), &[]).unwrap_err();
    assert!(e.to_string().contains("no/such/file.toml"));
}

/// Truncations and byte mutations of a good file give errors, never panics.
#[test]
fn no_panic_on_damaged_input() {
    for end in 0..GOOD.len() {
        if GOOD.is_char_boundary(end) {
            let _ = parse_model_str(&GOOD[..end], "t.toml", &[]);
        }
    }
    let lines: Vec<&str> = GOOD.lines().collect();
    for skip in 0..lines.len() {
        let text: Vec<&str> = lines
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != skip)
            .map(|(_, l)| *l)
            .collect();
        let _ = parse_model_str(&text.join("\n"), "t.toml", &[]);
    }
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let mut next = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    };
    let alphabet = b"0-.e[]{}=\"',\n axyz_ground1";
    for _ in 0..3000 {
        let mut bytes = GOOD.as_bytes().to_vec();
        for _ in 0..1 + next() % 3 {
            let i = (next() % bytes.len() as u64) as usize;
            bytes[i] = alphabet[(next() % alphabet.len() as u64) as usize];
        }
        if let Ok(text) = String::from_utf8(bytes) {
            let _ = parse_model_str(&text, "t.toml", &[]);
        }
    }
}

/// The error for `GOOD` with `from` replaced by `to`.
fn good_with(from: &str, to: &str) -> String {
    assert!(GOOD.contains(from), "{from:?} not in GOOD");
    match parse_model_str(&GOOD.replacen(from, to, 1), "edited.toml", &[]) {
        Ok(_) => panic!("accepted with {to:?}"),
        Err(e) => {
            println!("{e}");
            e.to_string()
        }
    }
}

#[test]
fn more_errors_name_their_field() {
    let pin = "type = \"spherical\"\n";
    let e = good_with(
        pin,
        "type = \"spherical\"\ndrive = { type = \"constant\", value = 1.0 }\n",
    );
    assert_contains(
        &e,
        &[
            "edited.toml:43:",
            "field 'joint[1].drive' (joint 'pin')",
            "only revolute and prismatic",
        ],
    );
    let e = good_with("node = \"hub\"\n", "node = \"hub\"\nposition = [1, 2, 3]\n");
    assert_contains(
        &e,
        &[
            "edited.toml:20:",
            "field 'body[0].position'",
            "not allowed when 'node' is given",
        ],
    );
    let e = good_with("angle_deg = 90", "angle = 90");
    assert_contains(
        &e,
        &[
            "edited.toml:26:",
            "field 'body[1].orientation.angle'",
            "did you mean 'angle_deg'",
        ],
    );
    let e = good_with(
        "{ axis = [0, 0, 1], angle_deg = 90 }",
        "{ quaternion = [1, 0, 0, 0.1] }",
    );
    assert_contains(
        &e,
        &["field 'body[1].orientation.quaternion'", "unit quaternion"],
    );
    let e = good_with(
        "angular_velocity = [",
        "angular_velocity_body = [1, 0, 0]\nangular_velocity = [",
    );
    assert_contains(&e, &["field 'body[1].angular_velocity_body'", "not both"]);
    let e = good_with("joint = \"crank\"", "joint = \"crank2\"");
    assert_contains(
        &e,
        &[
            "field 'sensor[1].joint'",
            "unknown joint 'crank2'",
            "did you mean 'crank'",
        ],
    );
    let e = good_with("joint = \"crank\"", "joint = \"pin\"");
    assert_contains(&e, &["field 'sensor[1].joint'", "spherical"]);
    let e = good_with("h = 1e-3", "h = -1e-3");
    assert_contains(
        &e,
        &[
            "edited.toml:12:",
            "field 'solver.h'",
            "must be positive, got -0.001",
        ],
    );
    let e = good_with("flexmb = 1", "flexmb = 2");
    assert_contains(&e, &["edited.toml:1:", "field 'flexmb'", "version 2"]);
    let e = good_with(
        "{ type = \"linear\", slope = 0.6 }",
        "{ type = \"table\", points = [[0, 0], [1, 1], [1, 2]] }",
    );
    assert_contains(
        &e,
        &["field 'joint[0].drive.points[2]'", "strictly increasing"],
    );
    let e = good_with(
        "node_a = \"hub\"\nnode_b = \"top\"",
        "node_a = \"top\"\nnode_b = \"top\"",
    );
    assert_contains(&e, &["field 'joint[1].node_b'", "itself"]);
    let e = good_with("name = \"E\"", "name = \"tip_x\"");
    assert_contains(
        &e,
        &["field 'sensor[2].name'", "duplicate sensor name 'tip_x'"],
    );
    let e = good_with("[[node]]\nname = \"hub\"", "[[node]]\nname = \"top\"");
    assert_contains(&e, &["field 'body[1].name'", "already used by node[0]"]);
    let e = good_with("axis = [0, 0, 1]\ndrive", "drive");
    assert_contains(
        &e,
        &["edited.toml:32:", "field 'joint[0].axis'", "required"],
    );
    let e = good_with(
        "position = [1, 0, 0]\n",
        "position = [1, 0, 0]\naxis = [1, 0, 0]\n",
    );
    assert_contains(
        &e,
        &["field 'joint[1].axis'", "not allowed for a spherical joint"],
    );
    let e = good_with("stiffness = 100", "stiffness = -100");
    assert_contains(&e, &["field 'spring[0].stiffness'", "must be >= 0"]);
    let e = good_with("group = \"SE3\"", "group = \"se3\"");
    assert_contains(
        &e,
        &[
            "edited.toml:6:",
            "field 'model.group'",
            "\"SE3\", \"R3xSO3\"",
        ],
    );
    let e = good_with("gravity = [0.0, 0.0, -9.81]", "gravity = [0.0, 0.0, nan]");
    assert_contains(&e, &["field 'model.gravity[2]'", "finite"]);
}

/// The complete examples of docs/model-format.md (TOML blocks starting with `flexmb = 1`)
/// are valid; the heavy top is the engine's benchmark model.
#[test]
fn documented_examples_are_valid() {
    let path: PathBuf = [
        env!("CARGO_MANIFEST_DIR"),
        "..",
        "..",
        "docs",
        "model-format.md",
    ]
    .iter()
    .collect();
    let doc = std::fs::read_to_string(&path).unwrap();
    let blocks: Vec<&str> = doc
        .split("```toml\n")
        .skip(1)
        .filter_map(|b| b.split("```").next())
        .filter(|b| b.starts_with("flexmb = 1"))
        .collect();
    assert!(blocks.len() >= 2, "complete examples not found");
    let files: Vec<ModelFile> = blocks
        .iter()
        .map(|b| parse_model_str(b, "model-format.md", &[]).unwrap_or_else(|e| panic!("{e}")))
        .collect();
    let top = &files[0].model;
    assert_eq!(top.title, "Heavy top");
    assert_eq!(
        top.nodes[0].angular_velocity,
        Vec3::new(0.0, 150.0, -4.61538)
    );
    assert_eq!(top.bodies[0].com, Vec3::new(0.0, 1.0, 0.0));
    assert_eq!(top.joints[0].kind, JointKind::Spherical);
    assert_eq!(top.sensors.len(), 3);
    let crank = &files[1].model;
    assert_eq!(crank.joints[1].kind, JointKind::Universal);
    // Frame B of the universal joint has its z axis along axis_b.
    let zb = crank.nodes[1].frame.r * crank.joints[1].frame_b.r.column(2);
    assert!((zb - Vec3::y()).norm() < 1e-12);
}

/// The documented examples start: consistent initial conditions and a few steps.
#[test]
fn documented_examples_run() {
    let path: PathBuf = [
        env!("CARGO_MANIFEST_DIR"),
        "..",
        "..",
        "docs",
        "model-format.md",
    ]
    .iter()
    .collect();
    let doc = std::fs::read_to_string(&path).unwrap();
    for block in doc
        .split("```toml\n")
        .skip(1)
        .filter_map(|b| b.split("```").next())
    {
        if !block.starts_with("flexmb = 1") {
            continue;
        }
        let file =
            parse_model_str(block, "model-format.md", &["solver.t_end=0.02".to_string()]).unwrap();
        let mut sim = flexmb::Simulation::new(&file.model, dynamic(&file))
            .unwrap_or_else(|e| panic!("{}: {e}", file.model.title));
        let stats = sim
            .run(&mut |_| Ok(()))
            .unwrap_or_else(|e| panic!("{}: {e}", file.model.title));
        assert!(stats.steps >= 20, "{stats:?}");
    }
}
