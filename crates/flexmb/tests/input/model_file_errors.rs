//! The TOML model file front end: a good file builds the same `Model` as the Rust API,
//! overrides work, and every kind of bad input gives an error naming file, line and field.

use flexmb::input::{parse_model_str, read_model_file, Analysis, InputError, ModelFile};
use flexmb::model::{
    box_inertia, frame_from_axis, rotation_from_vector, BeamMass, JointKind, Model, NodeId, Sensor,
    SensorKind, SpringDamper, TimeFunction,
};
use flexmb::solve::{StaticMethod, StaticSettings};
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
        relaxation: None,
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
        Analysis::Static(_) => panic!("not a dynamic analysis"),
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

#[test]
fn threads_read_and_checked_at_their_key() {
    assert_eq!(
        dynamic(&good(&[]).unwrap()).threads,
        0,
        "all cores by default"
    );
    assert_eq!(dynamic(&good(&["solver.threads=2"]).unwrap()).threads, 2);
    for (value, says) in [
        ("-1", "must be 0 (all cores) or a number of threads, got -1"),
        ("5000", "must be between 0 (all cores) and 1024, got 5000"),
        ("1.5", "solver.threads"),
    ] {
        let e = good(&[&format!("solver.threads={value}")])
            .err()
            .unwrap_or_else(|| panic!("threads = {value} was accepted"))
            .to_string();
        println!("{e}");
        assert_contains(&e, &["good.toml:9:", "field 'solver.threads'", says]);
    }
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
    // Unknown parent table: created by the override, then refused by the reader's key
    // check, at the parent table, naming the override.
    let e = set("solver.newton.rtol=1e-8");
    assert_contains(
        &e,
        &[
            &format!("{f}:8:"),
            "field 'solver.newton'",
            "unknown key 'newton'",
            "--set 'solver.newton.rtol=1e-8'",
        ],
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
    let bend = files
        .iter()
        .find(|f| f.model.title == "45-degree bend")
        .expect("the bend example");
    assert!(matches!(bend.analysis, Analysis::Static(_)));
    assert_eq!(bend.model.nodes.len(), 9);
    assert_eq!(bend.model.beams.len(), 8);
    let tip = bend.model.nodes[8].frame.x;
    let c = std::f64::consts::FRAC_1_SQRT_2;
    assert!((tip - Vec3::new(100.0 * c, 100.0 * (1.0 - c), 0.0)).norm() < 1e-10);
    let frame = files
        .iter()
        .find(|f| f.model.title == "L frame")
        .expect("the frame example");
    assert_eq!(frame.model.nodes.len(), 7);
    assert_eq!(frame.model.beams.len(), 6);
    assert_eq!(
        frame.model.bodies[0].node,
        frame.model.node_id("arm.2").unwrap()
    );
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
        let file = parse_model_str(block, "model-format.md", &[]).unwrap();
        if let Analysis::Static(settings) = file.analysis {
            let mut statics = flexmb::solve::Statics::new(&file.model, settings)
                .unwrap_or_else(|e| panic!("{}: {e}", file.model.title));
            statics
                .run(&mut |_: &flexmb::observe::Sample| Ok(()))
                .unwrap_or_else(|e| panic!("{}: {e}", file.model.title));
            assert!((statics.load_factor - settings.load_factor).abs() < 1e-9);
            if file.model.title == "45-degree bend" {
                // Close to the reference tip position (Simo & Vu-Quoc 1986).
                let tip = statics.state.q[8].x;
                let reference = Vec3::new(47.23, 15.79, 53.37);
                assert!(
                    (tip - reference).norm() < 0.02 * reference.norm(),
                    "{tip:?}"
                );
            }
            continue;
        }
        let file =
            parse_model_str(block, "model-format.md", &["solver.t_end=0.02".to_string()]).unwrap();
        let mut sim = flexmb::Simulation::new(&file.model, dynamic(&file))
            .unwrap_or_else(|e| panic!("{}: {e}", file.model.title));
        let stats = sim
            .run(&mut |_: &flexmb::observe::Sample| Ok(()))
            .unwrap_or_else(|e| panic!("{}: {e}", file.model.title));
        assert!(stats.steps >= 20, "{stats:?}");
    }
}

const BEAMS: &str = r#"flexmb = 1
title = "Beams"

[model]
group = "SE3"
gravity = [0.0, 0.0, -9.81]

[solver]
analysis = "static"
load_factor = 2.0
increment = 0.05
rtol = 1e-9

[[beam]]
name = "a"
start = [0.0, 0.0, 0.0]
end = [4.0, 0.0, 0.0]
elements = 4
orientation = [0.0, 0.0, 1.0]
section = { EA = 1e6, GA2 = 1e6, GA3 = 1e6, GJ = 1e3, EI2 = 1e3, EI3 = 1e3, rhoA = 1.0, rhoJ = 20.0, rhoI2 = 10.0, rhoI3 = 10.0 }

[[beam]]
name = "b"
start_node = "a.4"
end = [4.0, 2.0, 0.0]
elements = 2
orientation = [0.0, 0.0, 5.0]
section = { E = 2.1e11, nu = 0.3, A = 1e-4, I2 = 1e-8, I3 = 2e-8, J = 3e-8, rho = 7800.0 }

[[beam]]
name = "ring"
start = [10.0, 0.0, 0.0]
arc = { center = [0.0, 0.0, 0.0], axis = [0.0, 0.0, 1.0], angle_deg = 90.0 }
elements = 3
orientation = [0.0, 0.0, 1.0]
section = { stiffness = [[1e6, 0, 0, 0, 0, 0], [0, 1e6, 0, 0, 0, 0], [0, 0, 1e6, 0, 0, 0], [0, 0, 0, 1e3, 0, 0], [0, 0, 0, 0, 1e3, 0], [0, 0, 0, 0, 0, 1e3]], mass_per_length = 1.0, rotary_inertia = [20.0, 10.0, 10.0] }

[[joint]]
name = "clamp"
type = "fixed"
node_b = "a.0"
position = [0.0, 0.0, 0.0]

[[load]]
name = "tip"
node = "b.2"
force = [0.0, 0.0, -10.0]

[[sensor]]
name = "root_moment"
type = "beam_stress"
beam = "a[0]"
component = "bending_2"

[[sensor]]
name = "ring_strain"
type = "beam_strain"
beam = "ring[2]"
component = "axial"

[[body]]
name = "weight"
node = "b.2"
mass = 2.0
inertia = [0.1, 0.1, 0.1]
"#;

fn beams_with(from: &str, to: &str) -> String {
    assert!(BEAMS.contains(from), "{from:?} not in BEAMS");
    match parse_model_str(&BEAMS.replacen(from, to, 1), "beams.toml", &[]) {
        Ok(_) => panic!("accepted with {to:?}"),
        Err(e) => {
            println!("{e}");
            e.to_string()
        }
    }
}

fn close(a: &Mat3, b: &Mat3) -> bool {
    (a - b).norm() < 1e-12
}

#[test]
fn beams_are_meshed() {
    let file = parse_model_str(BEAMS, "beams.toml", &[]).unwrap();
    let m = &file.model;
    let names: Vec<&str> = m.nodes.iter().map(|n| n.name.as_str()).collect();
    assert_eq!(
        names,
        ["a.0", "a.1", "a.2", "a.3", "a.4", "b.1", "b.2", "ring.0", "ring.1", "ring.2", "ring.3"]
    );
    let elements: Vec<&str> = m.beams.iter().map(|b| b.name.as_str()).collect();
    assert_eq!(
        elements,
        ["a[0]", "a[1]", "a[2]", "a[3]", "b[0]", "b[1]", "ring[0]", "ring[1]", "ring[2]"]
    );
    let id = |name: &str| m.node_id(name).unwrap();
    // Straight beams: equal spacing, section frame x along the beam, z along orientation.
    for i in 0..=4 {
        let n = &m.nodes[id(&format!("a.{i}")).0];
        assert!((n.frame.x - Vec3::new(i as f64, 0.0, 0.0)).norm() < 1e-14);
        assert!(close(&n.frame.r, &Mat3::identity()));
        assert_eq!(n.velocity, Vec3::zeros());
    }
    let b2 = &m.nodes[id("b.2").0];
    assert!((b2.frame.x - Vec3::new(4.0, 2.0, 0.0)).norm() < 1e-14);
    let quarter = rotation_from_vector(&(Vec3::z() * std::f64::consts::FRAC_PI_2));
    assert!(close(&b2.frame.r, &quarter));
    assert!((m.nodes[id("b.1").0].frame.x - Vec3::new(4.0, 1.0, 0.0)).norm() < 1e-14);
    // The shared node keeps the frame of beam a; beam b's section there is turned by 90 deg.
    let (a3, b0) = (&m.beams[3], &m.beams[4]);
    assert_eq!(a3.nodes, [id("a.3"), id("a.4")]);
    assert_eq!(b0.nodes, [id("a.4"), id("b.1")]);
    assert!(close(&a3.offset_b, &Mat3::identity()));
    assert!(close(&b0.offset_a, &quarter));
    assert!(close(&b0.offset_b, &Mat3::identity()));
    for b in &m.beams[..6] {
        assert!((b.length - 1.0).abs() < 1e-12, "{}: {}", b.name, b.length);
    }
    // Material form: EA = E A, GA = G A with G = E / (2 (1 + nu)), rhoJ = rho (I2 + I3).
    let s = &b0.section;
    let g = 2.1e11 / 2.6;
    let expected = [2.1e7, g * 1e-4, g * 1e-4, g * 3e-8, 2.1e3, 4.2e3];
    for (k, e) in expected.iter().enumerate() {
        assert!((s.stiffness[(k, k)] - e).abs() < 1e-9 * e, "C[{k}]");
    }
    assert!((s.mass_per_length - 0.78).abs() < 1e-12);
    assert!((s.rotary_inertia[(0, 0)] - 7800.0 * 3e-8).abs() < 1e-15);
    // Arc: nodes on the circle, x tangent, z along the arc's axis, arc-length elements.
    for i in 0..=3 {
        let phi = (30.0 * i as f64).to_radians();
        let n = &m.nodes[id(&format!("ring.{i}")).0];
        let p = Vec3::new(10.0 * phi.cos(), 10.0 * phi.sin(), 0.0);
        assert!((n.frame.x - p).norm() < 1e-12, "{}", n.name);
        let x = n.frame.r.column(0).into_owned();
        assert!((x - Vec3::new(-phi.sin(), phi.cos(), 0.0)).norm() < 1e-12);
        assert!((n.frame.r.column(2) - Vec3::z()).norm() < 1e-12);
        assert!((n.frame.r.determinant() - 1.0).abs() < 1e-12);
    }
    for b in &m.beams[6..] {
        assert!((b.length - 10.0 * 30f64.to_radians()).abs() < 1e-9);
        assert!(close(&b.offset_a, &Mat3::identity()));
    }
    assert_eq!(m.beams[6].section.stiffness[(3, 3)], 1e3);
    // Joints and loads refer to beam nodes by name; beam sensors to elements.
    assert_eq!(m.joints[0].node_b, Some(id("a.0")));
    assert_eq!(m.loads[0].node, id("b.2"));
    assert_eq!(m.bodies[0].node, id("b.2"));
    assert_eq!(
        m.sensors[0].kind,
        SensorKind::BeamStress {
            beam: 0,
            component: 4
        }
    );
    assert_eq!(
        m.sensors[1].kind,
        SensorKind::BeamStrain {
            beam: 8,
            component: 0
        }
    );
    // Static analysis.
    let Analysis::Static(s) = file.analysis else {
        panic!("not static")
    };
    let mut expected = StaticSettings::new();
    expected.load_factor = 2.0;
    expected.initial_increment = 0.05;
    expected.newton.rtol = 1e-9;
    assert_eq!(s, expected);
    assert_eq!(s.method, StaticMethod::LoadControl);
}

#[test]
fn beam_initial_velocity_is_a_rigid_motion() {
    // v(p) = velocity + angular_velocity x (p - start) on every generated node, angular
    // velocity in the node (section) frame; mass_matrix reaches the elements.
    let text = BEAMS.replacen(
        "elements = 2\n",
        "elements = 2\nvelocity = [1.0, 0.0, 0.5]\nangular_velocity = [0.0, 0.0, 3.0]\nmass_matrix = \"consistent\"\n",
        1,
    );
    let file = parse_model_str(&text, "beams.toml", &[]).unwrap_or_else(|e| panic!("{e}"));
    let m = &file.model;
    let node = |name: &str| &m.nodes[m.node_id(name).unwrap().0];
    // b starts at the existing node a.4 = (4, 0, 0), which keeps its own (zero) velocity
    assert_eq!(node("a.4").velocity, Vec3::zeros());
    for (name, y) in [("b.1", 1.0), ("b.2", 2.0)] {
        let n = node(name);
        let expected =
            Vec3::new(1.0, 0.0, 0.5) + Vec3::new(0.0, 0.0, 3.0).cross(&Vec3::new(0.0, y, 0.0));
        assert!(
            (n.velocity - expected).norm() < 1e-14,
            "{name}: {}",
            n.velocity
        );
        assert!((n.frame.r * n.angular_velocity - Vec3::new(0.0, 0.0, 3.0)).norm() < 1e-14);
    }
    let kinds: Vec<BeamMass> = m.beams.iter().map(|b| b.mass_kind).collect();
    assert_eq!(kinds[3], BeamMass::Lumped);
    assert_eq!(kinds[4], BeamMass::Consistent);
    assert_eq!(kinds[5], BeamMass::Consistent);
    let coupling = |e: usize| {
        let mass = flexmb::elements::beam::mass_matrix(&m.beams[e]);
        mass.fixed_view::<6, 6>(0, 6).norm()
    };
    assert!(coupling(4) > 0.1, "the consistent mass couples the nodes");
    assert_eq!(coupling(3), 0.0);
}

#[test]
fn beam_end_node_and_negative_arc() {
    // An arc turning clockwise, ending at an existing node; a beam between two nodes.
    let text = BEAMS
        .replace(
            "[[beam]]\nname = \"ring\"",
            "[[node]]\nname = \"rim\"\nposition = [0.0, -10.0, 0.0]\n\n[[beam]]\nname = \"ring\"",
        )
        .replace("angle_deg = 90.0 }", "angle_deg = -90.0 }\nend_node = \"rim\"")
        .replace(
            "\n[[joint]]",
            "\n[[beam]]\nname = \"tie\"\nstart_node = \"b.2\"\nend = [0.0, -10.0, 0.0]\nend_node = \"rim\"\nelements = 1\norientation = [0, 0, 1]\nsection = { E = 1e9, G = 4e8, A = 1e-3, I2 = 1e-6, I3 = 1e-6, J = 2e-6, rho = 1000, k2 = 0.8, k3 = 0.9 }\n\n[[joint]]",
        );
    let file = parse_model_str(&text, "beams.toml", &[]).unwrap_or_else(|e| panic!("{e}"));
    // The tie creates no node: an initial velocity field on it would do nothing.
    let e = parse_model_str(
        &text.replace(
            "end_node = \"rim\"\nelements = 1\n",
            "end_node = \"rim\"\nelements = 1\nvelocity = [1, 0, 0]\n",
        ),
        "beams.toml",
        &[],
    )
    .unwrap_err()
    .to_string();
    assert_contains(
        &e,
        &["field 'beam[3].velocity' (beam 'tie')", "creates no node"],
    );
    let m = &file.model;
    let rim = m.node_id("rim").unwrap();
    assert_eq!(m.node_id("ring.3"), None);
    let ring2 = &m.nodes[m.node_id("ring.2").unwrap().0];
    assert!((ring2.frame.x - Vec3::new(5.0, -5.0 * 3f64.sqrt(), 0.0)).norm() < 1e-12);
    // Clockwise: the tangent is -z x r.
    let x = ring2.frame.r.column(0).into_owned();
    assert!((x - Vec3::new(-3f64.sqrt() / 2.0, -0.5, 0.0)).norm() < 1e-12);
    let last = m.beams.iter().find(|b| b.name == "ring[2]").unwrap();
    assert_eq!(last.nodes[1], rim);
    // The rim node has the identity orientation: the offset is the section frame there.
    let frame = Mat3::from_columns(&[-Vec3::x(), -Vec3::y(), Vec3::z()]);
    assert!(close(&last.offset_b, &frame));
    let tie = m.beams.iter().find(|b| b.name == "tie[0]").unwrap();
    assert_eq!(tie.nodes, [m.node_id("b.2").unwrap(), rim]);
    let s = &tie.section;
    assert!((s.stiffness[(1, 1)] - 0.8 * 4e8 * 1e-3).abs() < 1e-6);
    assert!((s.stiffness[(2, 2)] - 0.9 * 4e8 * 1e-3).abs() < 1e-6);
    assert!((tie.length - (4.0f64.powi(2) + 12.0f64.powi(2)).sqrt()).abs() < 1e-12);
}

#[test]
fn beam_errors_name_their_field() {
    let sec = "section = { EA = 1e6,";
    // Sectional properties must be positive.
    let e = beams_with("GJ = 1e3", "GJ = -1");
    assert_contains(
        &e,
        &[
            "beams.toml:20:",
            "field 'beam[0].section.GJ' (beam 'a')",
            "must be positive",
        ],
    );
    // Mixed forms.
    let e = beams_with(sec, "section = { E = 1.0, EA = 1e6,");
    assert_contains(&e, &["field 'beam[0].section.EA'", "use one form"]);
    let e = beams_with("mass_per_length = 1.0, ", "");
    assert_contains(&e, &["field 'beam[2].section.mass_per_length'", "required"]);
    let e = beams_with("nu = 0.3", "G = 1e10, nu = 0.3");
    assert_contains(&e, &["field 'beam[1].section.nu'", "either G or nu"]);
    // A stiffness matrix that is symmetric but not positive definite: Model::validate, at the
    // section's line, naming the element.
    let e = beams_with(
        "[[1e6, 0, 0, 0, 0, 0], [0, 1e6,",
        "[[1e6, 2e6, 0, 0, 0, 0], [2e6, 1e6,",
    );
    assert_contains(
        &e,
        &[
            "beams.toml:36:",
            "field 'beam[2].section' (beam 'ring')",
            "element 'ring[0]'",
            "positive definite",
        ],
    );
    let e = beams_with("[0, 1e6, 0, 0, 0, 0]", "[1, 1e6, 0, 0, 0, 0]");
    assert_contains(&e, &["field 'beam[2].section.stiffness'", "symmetric"]);
    // Geometry.
    let e = beams_with("end = [4.0, 2.0, 0.0]", "end = [4.0, 0.0, 0.0]");
    assert_contains(
        &e,
        &["field 'beam[1].end'", "must differ from the start point"],
    );
    let e = beams_with("elements = 4", "elements = 4\nmass_matrix = \"diagonal\"");
    assert_contains(
        &e,
        &["field 'beam[0].mass_matrix'", "\"lumped\", \"consistent\""],
    );
    let e = beams_with("elements = 4", "elements = 4\nvelocity = [1, 2]");
    assert_contains(&e, &["field 'beam[0].velocity'"]);
    let e = beams_with("elements = 4", "elements = 0");
    assert_contains(&e, &["field 'beam[0].elements'", "between 1 and"]);
    let e = beams_with("angle_deg = 90.0", "angle_deg = 400.0");
    assert_contains(&e, &["field 'beam[2].arc.angle_deg'", "360"]);
    let e = beams_with(
        "angle_deg = 90.0 }\nelements = 3",
        "angle_deg = 270.0 }\nelements = 1",
    );
    assert_contains(
        &e,
        &["field 'beam[2].arc.angle_deg'", "less than 180 degrees"],
    );
    let e = beams_with("center = [0.0, 0.0, 0.0]", "center = [10.0, 0.0, -1.0]");
    assert_contains(&e, &["field 'beam[2].arc.center'", "on the arc's axis"]);
    // In-plane orientation: parallel to the tangent in the middle of the arc (at 45 deg).
    let e = beams_with(
        "elements = 3\norientation = [0.0, 0.0, 1.0]",
        "elements = 3\norientation = [-1.0, 1.0, 0.0]",
    );
    assert_contains(
        &e,
        &[
            "beams.toml:35:",
            "field 'beam[2].orientation'",
            "parallel",
            "at [7.07",
        ],
    );
    let e = beams_with(
        "start_node = \"a.4\"",
        "start_node = \"a.4\"\nstart = [0, 0, 0]",
    );
    assert_contains(&e, &["field 'beam[1].start_node'", "not both"]);
    // A beam starting at a later beam's node.
    let e = beams_with("start_node = \"a.4\"", "start_node = \"ring.0\"");
    assert_contains(&e, &["field 'beam[1].start_node'", "unknown node 'ring.0'"]);
    // Generated node names must not clash with other nodes.
    let e = beams_with(
        "[[beam]]\nname = \"a\"",
        "[[node]]\nname = \"a.2\"\n\n[[beam]]\nname = \"a\"",
    );
    assert_contains(
        &e,
        &[
            "field 'beam[0].name'",
            "creates a node named 'a.2'",
            "node[0]",
        ],
    );
    let e = beams_with("name = \"b\"", "name = \"a\"");
    assert_contains(&e, &["field 'beam[1].name'", "duplicate beam name 'a'"]);
    // Beam sensors.
    let e = beams_with("beam = \"a[0]\"", "beam = \"a\"");
    assert_contains(
        &e,
        &["field 'sensor[0].beam'", "4 elements", "'a[0]' to 'a[3]'"],
    );
    let e = beams_with("beam = \"a[0]\"", "beam = \"a[4]\"");
    assert_contains(
        &e,
        &[
            "field 'sensor[0].beam'",
            "unknown beam element 'a[4]'",
            "did you mean",
        ],
    );
    let e = beams_with("component = \"bending_2\"", "component = \"bending_y\"");
    assert_contains(&e, &["field 'sensor[0].component'", "\"bending_2\""]);
    let e = beams_with(
        "component = \"axial\"",
        "component = \"axial\"\nnode = \"a.1\"",
    );
    assert_contains(&e, &["field 'sensor[1].node'", "beam_strain"]);
    // Static settings.
    let e = beams_with("increment = 0.05", "increment = 0.05\nh = 1e-3");
    assert_contains(
        &e,
        &[
            "beams.toml:12:",
            "field 'solver.h'",
            "dynamic analysis",
            "analysis = \"static\"",
        ],
    );
    let e = beams_with("increment = 0.05", "increment = -0.05");
    assert_contains(&e, &["field 'solver.increment'", "must be positive"]);
    let e = beams_with("increment = 0.05", "increment = 0.05\narc_length = 0.2");
    assert_contains(
        &e,
        &["field 'solver.arc_length'", "method = \"arc_length\""],
    );
    let e = beams_with("increment = 0.05", "increment = 0.05\nmethod = \"riks\"");
    assert_contains(&e, &["field 'solver.method'", "\"arc_length\""]);
    let e = beams_with("increment = 0.05", "increment = 0.05\nmin_increment = 0.1");
    assert_contains(&e, &["field 'solver.increment'", "below min_increment"]);
}

#[test]
fn static_solver_settings() {
    let file = parse_model_str(
        BEAMS,
        "beams.toml",
        &[
            "solver.method=arc_length".into(),
            "solver.arc_length=0.5".into(),
            "solver.max_steps=50".into(),
            "solver.target_iterations=4".into(),
            "solver.max_iterations=40".into(),
            "solver.min_increment=1e-4".into(),
            "solver.max_increment=0.5".into(),
            "solver.atol=1e-12".into(),
        ],
    )
    .unwrap();
    let Analysis::Static(s) = file.analysis else {
        panic!("not static")
    };
    assert_eq!(s.method, StaticMethod::ArcLength);
    assert_eq!(s.arc_length, 0.5);
    assert_eq!(s.max_steps, 50);
    assert_eq!(s.target_iterations, 4);
    assert_eq!(s.newton.max_iterations, 40);
    assert_eq!(s.newton.atol, 1e-12);
    assert_eq!(s.min_increment, 1e-4);
    assert_eq!(s.max_increment, 0.5);
    assert_eq!(s.load_factor, 2.0);
    // Overrides reach beams like any item.
    let file = parse_model_str(
        BEAMS,
        "beams.toml",
        &[
            "beam.a.elements=8".into(),
            "beam.ring.arc.angle_deg=-60".into(),
        ],
    )
    .unwrap();
    let m = &file.model;
    assert_eq!(
        m.beams.iter().filter(|b| b.name.starts_with("a[")).count(),
        8
    );
    let end = m.nodes[m.node_id("ring.3").unwrap().0].frame.x;
    assert!((end - Vec3::new(5.0, -5.0 * 3f64.sqrt(), 0.0)).norm() < 1e-12);
}

/// Byte mutations of the beam file give errors, never panics.
#[test]
fn no_panic_on_damaged_beam_input() {
    let mut seed = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    };
    let alphabet = b"0-.e[]{}=\"',\n axyz_19";
    for _ in 0..3000 {
        let mut bytes = BEAMS.as_bytes().to_vec();
        for _ in 0..1 + next() % 3 {
            let i = (next() % bytes.len() as u64) as usize;
            bytes[i] = alphabet[(next() % alphabet.len() as u64) as usize];
        }
        if let Ok(text) = String::from_utf8(bytes) {
            let _ = parse_model_str(&text, "t.toml", &[]);
        }
    }
}

#[test]
fn beam_end_and_arc() {
    check(
        "beam_end_and_arc",
        21,
        "beam[0].arc",
        &["(beam 'leg')", "either end", "not both"],
    );
}

#[test]
fn beam_unknown_section_key() {
    check(
        "beam_unknown_section_key",
        23,
        "beam[0].section.EIy",
        &["unknown key 'EIy'", "did you mean 'EI2'", "(beam 'leg')"],
    );
}

#[test]
fn beam_nonpositive_ea() {
    check(
        "beam_nonpositive_ea",
        23,
        "beam[0].section.EA",
        &["must be positive, got 0"],
    );
}

#[test]
fn beam_orientation_parallel_to_axis() {
    check(
        "beam_orientation_parallel",
        22,
        "beam[0].orientation",
        &["parallel to the beam's axis"],
    );
}

#[test]
fn beam_dangling_start_node() {
    check(
        "beam_dangling_start_node",
        19,
        "beam[0].start_node",
        &["unknown node 'tpi'", "did you mean 'tip'"],
    );
}

#[test]
fn beam_end_node_not_at_end_point() {
    check(
        "beam_end_node_off",
        21,
        "beam[0].end_node",
        &["node 'tip'", "not at the end point"],
    );
}

#[test]
fn beam_needs_se3() {
    check(
        "beam_group",
        18,
        "beam[0].name",
        &["(beam 'leg')", "SE(3)", "\"SE3\""],
    );
}

#[test]
fn static_key_in_dynamic_solver() {
    check(
        "static_key_in_dynamic",
        13,
        "solver.load_factor",
        &["static analysis", "analysis = \"dynamic\""],
    );
}

const BEAM_LOAD: &str = r#"flexmb = 1
[model]
group = "SE3"
[solver]
analysis = "static"
[[beam]]
name = "b"
start = [0.0, 0.0, 0.0]
end = [3.0, 0.0, 0.0]
elements = 3
orientation = [0.0, 0.0, 1.0]
section = { EA = 1e6, GA2 = 1e6, GA3 = 1e6, GJ = 1e3, EI2 = 1e3, EI3 = 1e3, rhoA = 1.0, rhoJ = 1.0, rhoI2 = 0.5, rhoI3 = 0.5 }
[[load]]
name = "q"
beam = "b"
force_per_length = [0.0, 0.0, -2.0]
"#;

#[test]
fn distributed_beam_load_is_lumped_to_the_beam_nodes() {
    let file = parse_model_str(BEAM_LOAD, "beam_load.toml", &[]).unwrap();
    let loads = &file.model.loads;
    assert_eq!(loads.len(), 4, "one load per node of the 3-element beam");
    let total: f64 = loads.iter().map(|l| l.force.z).sum();
    assert!((total + 6.0).abs() < 1e-12);
    assert!((loads[0].force.z + 1.0).abs() < 1e-12 && (loads[1].force.z + 2.0).abs() < 1e-12);
    assert_eq!(loads[0].name, "q@b.0");
    let bad = BEAM_LOAD.replace("beam = \"b\"", "beam = \"b\"\nnode = \"b.1\"");
    let e = parse_model_str(&bad, "beam_load.toml", &[])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("beam_load.toml:16:") && e.contains("node"),
        "{e}"
    );
    let bad = BEAM_LOAD.replace("beam = \"b\"", "beam = \"nope\"");
    let e = parse_model_str(&bad, "beam_load.toml", &[])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("beam_load.toml:15:") && e.contains("nope"),
        "{e}"
    );
}

#[test]
fn a_changed_beam_section_needs_no_refresh() {
    // The model holds no derived mass matrix: the elements compute theirs from the section.
    let file = parse_model_str(BEAMS, "beams.toml", &[]).unwrap();
    let mut model = file.model;
    let before = flexmb::elements::beam::mass_matrix(&model.beams[2]);
    model.beams[2].section.mass_per_length *= 2.0;
    model.validate().expect("valid after a change of section");
    let after = flexmb::elements::beam::mass_matrix(&model.beams[2]);
    let translation = |m: &flexmb::elements::Mat12| m[(0, 0)];
    assert!((translation(&after) - 2.0 * translation(&before)).abs() < 1e-12 * translation(&after));
}

#[test]
fn spring_maxwell_branch_and_spring_force_sensor() {
    let text = GOOD.replace(
        "stiffness = 100\n",
        "stiffness = 100\nrelaxation_stiffness = 500\nrelaxation_damping = 20\n",
    ) + "\n[[sensor]]\nname = \"F\"\ntype = \"spring_force\"\nspring = \"s\"\n";
    let file = parse_model_str(&text, "maxwell.toml", &[]).expect("reads");
    assert_eq!(
        file.model.springs[0].relaxation,
        Some(flexmb::model::Relaxation {
            stiffness: 500.0,
            damping: 20.0
        })
    );
    assert_eq!(
        file.model.sensors[3].kind,
        SensorKind::SpringForce { spring: 0 }
    );
    // The parameters of the branch have paths.
    let params = flexmb::model::Parameters::new(&file.model);
    assert!(params.id("spring.s.relaxation_damping").is_ok());
    // One key without the other is an error at that key.
    let half = GOOD.replace(
        "stiffness = 100\n",
        "stiffness = 100\nrelaxation_damping = 20\n",
    );
    let e = parse_model_str(&half, "half.toml", &[])
        .map(|_| ())
        .expect_err("refused")
        .to_string();
    assert_contains(
        &e,
        &[
            "half.toml:53:",
            "relaxation_damping",
            "needs both relaxation_stiffness and relaxation_damping",
        ],
    );
    let negative = GOOD.replace(
        "stiffness = 100\n",
        "stiffness = 100\nrelaxation_stiffness = -5\nrelaxation_damping = 20\n",
    );
    let e = parse_model_str(&negative, "negative.toml", &[])
        .map(|_| ())
        .expect_err("refused")
        .to_string();
    assert_contains(
        &e,
        &["negative.toml:53:", "relaxation_stiffness", "positive"],
    );
    let unknown =
        GOOD.to_string() + "\n[[sensor]]\nname = \"F\"\ntype = \"spring_force\"\nspring = \"t\"\n";
    let e = parse_model_str(&unknown, "unknown.toml", &[])
        .map(|_| ())
        .expect_err("refused")
        .to_string();
    assert_contains(&e, &["unknown spring 't'"]);
}

#[test]
fn rope_errors_name_the_key() {
    let rope = |points: &str| {
        GOOD.to_string() + &format!("\n[[rope]]\nname = \"r\"\npoints = {points}\nstiffness = 10\n")
    };
    let read = |text: String| {
        parse_model_str(&text, "rope.toml", &[])
            .map(|_| ())
            .expect_err("refused")
            .to_string()
    };
    let ok = rope("[{ point = [0, 0, 3] }, { node = \"top\", point = [1, 0, 0] }]");
    let file = parse_model_str(&ok, "rope.toml", &[]).expect("reads");
    assert_eq!(file.model.ropes[0].points.len(), 2);
    assert!((file.model.ropes[0].rest_length - 10f64.sqrt()).abs() < 1e-12);
    assert_contains(
        &read(rope(
            "[{ node = \"tpo\", point = [1, 0, 0] }, { point = [0, 0, 3] }]",
        )),
        &["rope.toml:", "rope[0].points[0].node", "unknown node 'tpo'"],
    );
    assert_contains(
        &read(rope("[{ node = \"top\", point = [1, 0, 0] }]")),
        &["field 'rope[0].points'", "2 to 64 points"],
    );
    assert_contains(
        &read(rope("[{ point = [0, 0, 3] }, { point = [1, 0, 0] }]")),
        &["field 'rope[0].points'", "every point is on the ground"],
    );
    assert_contains(
        &read(rope(
            "[{ point = [1, 0, 0] }, { node = \"top\", point = [1, 0, 0] }]",
        )),
        &["field 'rope[0].points'", "points 1 and 2 coincide"],
    );
    assert_contains(
        &read(rope(
            "[{ point = [0, 0, 3], nod = \"top\" }, { point = [1, 0, 0] }]",
        )),
        &["unknown key 'nod'"],
    );
}

#[test]
fn lie_update_is_read_and_checked_at_its_key() {
    use flexmb::solve::LieUpdate;
    assert_eq!(
        dynamic(&good(&[]).unwrap()).lie_update,
        LieUpdate::BrulsCardona
    );
    let s = dynamic(&good(&["solver.lie_update=commutator"]).unwrap());
    assert_eq!(s.lie_update, LieUpdate::Commutator { sigma: 1.0 / 12.0 });
    let s = dynamic(
        &good(&[
            "solver.lie_update=commutator",
            "solver.lie_update_sigma=0.2",
        ])
        .unwrap(),
    );
    assert_eq!(s.lie_update, LieUpdate::Commutator { sigma: 0.2 });
    let e = good(&["solver.lie_update=magnus"]).unwrap_err().to_string();
    assert_contains(&e, &["lie_update", "bruls_cardona", "commutator"]);
    let e = good(&["solver.lie_update_sigma=0.2"])
        .unwrap_err()
        .to_string();
    assert_contains(&e, &["lie_update_sigma", "only allowed"]);
    let e = good(&["solver.lie_update=commutator", "solver.lie_update_sigma=2"])
        .unwrap_err()
        .to_string();
    assert_contains(&e, &["lie_update_sigma"]);
}

/// Bad `[[contact]]` input in `examples/ball_drop.toml`: located errors.
#[test]
fn contact_errors_are_located() {
    let path: PathBuf = [env!("CARGO_MANIFEST_DIR"), "../../examples/ball_drop.toml"]
        .iter()
        .collect();
    let good = std::fs::read_to_string(&path).expect("example");
    let edit = |from: &str, to: &str| {
        assert!(good.contains(from), "{from}");
        match parse_model_str(&good.replace(from, to), "ball.toml", &[]) {
            Ok(_) => panic!("accepted: {to}"),
            Err(e) => e.to_string(),
        }
    };
    let hertz = "hertz = { young = [210e9, 210e9], poisson = [0.3, 0.3] }";
    for (from, to, parts) in [
        (
            "restitution = 0.8",
            "restitution = 1.5",
            &["ball.toml:41:", "field 'contact[0].restitution'", "(0, 1]"][..],
        ),
        (
            "restitution = 0.8",
            "restitution = 0.0",
            &["field 'contact[0].restitution'", "(0, 1]"],
        ),
        (
            hertz,
            "stiffness = -3e10",
            &["ball.toml:40:", "field 'contact[0].stiffness'", "positive"],
        ),
        (
            hertz,
            "hertz = { young = [210e9, -1.0], poisson = [0.3, 0.3] }",
            &["field 'contact[0].hertz'", "Young's modulus"],
        ),
        (
            "node_b = \"ball\"",
            "node_b = \"bal\"",
            &["field 'contact[0].node_b'", "unknown node 'bal'"],
        ),
        (
            "b = { shape = \"sphere\", center = [0.0, 0.0, 0.15], radius = 0.05 }\nlaw",
            "b = { shape = \"plane\", point = [0.0, 0.0, 0.15], normal = [0.0, 0.0, 1.0] }\nlaw",
            &["field 'contact[0].hertz'", "for a sphere B"],
        ),
        (
            "radius = 0.05 }",
            "radius = nan }",
            &["field 'contact[0].b.radius'", "finite"],
        ),
        (
            "normal = [0.0, 0.0, 1.0] }",
            "normal = [0.0, 0.0, 0.0] }",
            &["field 'contact[0].a.normal'", "non-zero"],
        ),
        (
            "restitution = 0.8",
            "restitution = 0.8\nfriction = { coefficient = -0.2 }",
            &["field 'contact[0].friction.coefficient'", ">= 0"],
        ),
        (
            "law = \"lankarani_nikravesh\"",
            "law = \"hertz\"",
            &["field 'contact[0].law'", "\"flores\""],
        ),
        (
            "law = \"lankarani_nikravesh\"",
            "law = \"hertz\"",
            &["field 'contact[0].law'", "\"exact_restitution\""],
        ),
        (
            "restitution = 0.8",
            "restitution = 0.8\nstiffnes = 1.0",
            &["contact[0]", "stiffnes"],
        ),
    ] {
        assert_contains(&edit(from, to), parts);
    }
    // The law of the exact restitution keeps the located error on e (and takes e = 1).
    let exact = good.replace(
        "law = \"lankarani_nikravesh\"",
        "law = \"exact_restitution\"",
    );
    for bad in ["0.0", "1.01", "-0.5", "nan"] {
        let text = exact.replace("restitution = 0.8", &format!("restitution = {bad}"));
        let e = parse_model_str(&text, "ball.toml", &[]).expect_err(bad);
        assert_contains(
            &e.to_string(),
            &["ball.toml:41:", "field 'contact[0].restitution'"],
        );
    }
    let text = exact.replace("restitution = 0.8", "restitution = 1.0");
    let file = parse_model_str(&text, "ball.toml", &[]).expect("e = 1");
    let law = &file.model.contacts[0].law;
    assert_eq!(
        law.dissipation.factor(law.restitution),
        0.0,
        "e = 1: no dissipation"
    );
    let good = good.replace(hertz, "stiffness = 3e10");
    let plane_b = good.replace(
        "b = { shape = \"sphere\", center = [0.0, 0.0, 0.15], radius = 0.05 }",
        "b = { shape = \"plane\", point = [0.0, 0.0, 0.15], normal = [0.0, 0.0, 1.0] }",
    );
    let e = parse_model_str(&plane_b, "ball.toml", &[]).expect_err("a plane B");
    assert_contains(
        &e.to_string(),
        &["ball.toml:38:", "field 'contact[0].b'", "cannot be a plane"],
    );
}

/// The example `example` with `from` replaced by `to` (once), read as the file `name` with
/// the overrides `set`: the error, and the line of `line_of` in the edited text (1-based).
fn example_with(
    (example, name): (&str, &str),
    (from, to): (&str, &str),
    line_of: &str,
    set: &[String],
) -> (String, usize) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples")
        .join(example);
    let text = std::fs::read_to_string(path).expect("example");
    assert!(text.contains(from), "{from:?} not in the example");
    let edited = text.replacen(from, to, 1);
    let line = edited
        .lines()
        .position(|l| l.contains(line_of))
        .expect("the key")
        + 1;
    match parse_model_str(&edited, name, set) {
        Ok(_) => panic!("accepted with {to:?} and {set:?}"),
        Err(e) => (e.to_string(), line),
    }
}

/// The example gear stage with `from` replaced by `to` (once): the error, and the line of
/// `line_of` in the edited text (1-based).
fn gears_with(from: &str, to: &str, line_of: &str) -> (String, usize) {
    example_with(("gear_rattle.toml", "gears.toml"), (from, to), line_of, &[])
}
/// `GOOD` with `extra` lines after the spring's `stiffness = 100` (replaced by `stiffness`
/// when given), and the line of the first extra line.
fn spring_with(stiffness: Option<&str>, extra: &str) -> (String, usize) {
    let line = GOOD
        .lines()
        .position(|l| l == "stiffness = 100")
        .expect("the spring's stiffness")
        + 1;
    let head = stiffness.map_or(String::new(), |s| format!("{s}\n"));
    let text = GOOD.replacen("stiffness = 100\n", &format!("{head}{extra}\n"), 1);
    (text, line + usize::from(stiffness.is_some()))
}

#[test]
fn spring_laws_are_read_with_their_parameters() {
    use flexmb::model::{ForceCurve, SpringSide};
    let (text, _) = spring_with(
        Some("stiffness = 100"),
        "rest_length = 0.8\npreload = -10\nacts = \"compression\"\nforce_table = [[-0.1, -50], [0, 0]]",
    );
    let file = parse_model_str(&text, "law.toml", &[]).expect("reads");
    let law = &file.model.spring_laws[0];
    assert_eq!(law.spring, 0);
    assert_eq!(law.law.preload, -10.0);
    assert_eq!(law.law.acts, SpringSide::Compression);
    assert_eq!(
        law.law.curve,
        Some(ForceCurve::Table(vec![(-0.1, -50.0), (0.0, 0.0)]))
    );
    assert_eq!(file.model.springs[0].stiffness, 100.0);
    let params = flexmb::model::Parameters::new(&file.model);
    for path in ["spring.s.preload", "spring.s.force_table.1"] {
        assert!(params.id(path).is_ok(), "{path}");
    }
    // per side, without a linear part; overrides reach the curves
    let (text, _) = spring_with(
        None,
        "compression = { polynomial = [100, 0, 1e4] }\nextension = { force_table = [[0, 0], [0.1, 20]] }",
    );
    let file = parse_model_str(
        &text,
        "sides.toml",
        &["spring.s.compression.polynomial.2=2e4".to_string()],
    )
    .expect("reads");
    let law = &file.model.spring_laws[0];
    assert_eq!(file.model.springs[0].stiffness, 0.0);
    assert_eq!(law.law.acts, SpringSide::Both);
    assert_eq!(
        law.law.compression,
        Some(ForceCurve::Polynomial(vec![100.0, 0.0, 2e4]))
    );
    let params = flexmb::model::Parameters::new(&file.model);
    for path in [
        "spring.s.compression.polynomial.2",
        "spring.s.extension.force_table.0",
    ] {
        assert!(params.id(path).is_ok(), "{path}");
    }
    // a linear spring has no law
    let file = good(&[]).expect("reads");
    assert!(file.model.spring_laws.is_empty());
}

#[test]
fn bad_spring_laws_name_their_field() {
    let cases: [(Option<&str>, &str, usize, &str, &str); 10] = [
        (
            Some("stiffness = -100"),
            "",
            0,
            "spring[0].stiffness",
            ">= 0",
        ),
        (
            None,
            "force_table = [[0, 0], [0.2, 10], [0.1, 20]]",
            0,
            "spring[0].force_table[2]",
            "not sorted in elongation",
        ),
        (
            None,
            "force_table = [[0, 0]]",
            0,
            "spring[0].force_table",
            "at least 2",
        ),
        (
            None,
            "force_table = [[0, 0], [1, 1]]\npolynomial = [1]",
            1,
            "spring[0].polynomial",
            "not both",
        ),
        (
            None,
            "polynomial = []",
            0,
            "spring[0].polynomial",
            "1 to 16",
        ),
        (
            Some("stiffness = 100"),
            "acts = \"both_sides\"",
            0,
            "spring[0].acts",
            "must be one of",
        ),
        (
            None,
            "compression = { force_table = [[0, 0], [0, 1]] }",
            0,
            "spring[0].compression.force_table[1]",
            "not sorted",
        ),
        (
            None,
            "extension = { }",
            0,
            "spring[0].extension",
            "the side's curve",
        ),
        (
            Some("stiffness = 100"),
            "acts = \"extension\"\nrelaxation_stiffness = 5\nrelaxation_damping = 1",
            0,
            "spring[0].acts",
            "Maxwell branch",
        ),
        (
            Some("stiffness = 100"),
            "preload = 1e40",
            0,
            "spring[0].preload",
            "",
        ),
    ];
    for (stiffness, extra, offset, field, says) in cases {
        let (text, line) = spring_with(stiffness, extra);
        let line = if stiffness.is_some() && extra.is_empty() {
            line - 1
        } else {
            line
        } + offset;
        let e = parse_model_str(&text, "law.toml", &[])
            .map(|_| ())
            .expect_err(extra)
            .to_string();
        println!("{e}");
        assert_contains(
            &e,
            &[
                &format!("law.toml:{line}:"),
                &format!("field '{field}'"),
                says,
            ],
        );
    }
    // an unknown node and a law-less spring without stiffness, as before
    let e = parse_model_str(
        &GOOD.replace("node_b = \"top\"\npoint_a", "node_b = \"nowhere\"\npoint_a"),
        "law.toml",
        &[],
    )
    .map(|_| ())
    .expect_err("unknown node")
    .to_string();
    assert_contains(&e, &["field 'spring[0].node_b'", "nowhere"]);
    let (text, _) = spring_with(None, "damping = 1");
    let e = parse_model_str(&text, "law.toml", &[])
        .map(|_| ())
        .expect_err("no stiffness")
        .to_string();
    assert_contains(&e, &["spring[0]", "stiffness"]);
}

/// `GOOD` with a revolute joint "hinge" between the hub and the top, and `extra` appended
/// (a `[[rotational_spring]]`); the line of the first line of `extra`.
fn with_rotational_spring(extra: &str) -> (String, usize) {
    let joint = "\n[[joint]]\nname = \"hinge\"\ntype = \"cylindrical\"\nnode_a = \"hub\"\nnode_b = \"top\"\nposition = [1, 0, 0]\naxis = [0, 0, 1]\n";
    let text = GOOD.replacen("\n[[joint]]\nname = \"pin\"\ntype = \"spherical\"\nnode_a = \"hub\"\nnode_b = \"top\"\nposition = [1, 0, 0]\n", joint, 1);
    assert_ne!(text, GOOD, "the pin joint replaced");
    let line = text.lines().count() + 1;
    (format!("{text}{extra}\n"), line)
}

#[test]
fn rotational_springs_are_read_with_their_sensor_and_parameters() {
    let (text, _) = with_rotational_spring(
        "[[rotational_spring]]\nname = \"clock\"\njoint = \"hinge\"\nstiffness = 0.8\ndamping = 0.01\nangle_deg = -720\npreload = 0.1\n\n[[sensor]]\nname = \"T\"\ntype = \"rotational_spring_torque\"\nspring = \"clock\"\n",
    );
    let file = parse_model_str(&text, "clock.toml", &[]).expect("reads");
    let s = &file.model.rotational_springs[0];
    assert_eq!(s.joint, file.model.joint_id("hinge").unwrap());
    assert_eq!((s.stiffness, s.damping), (0.8, 0.01));
    assert!((s.angle + 4.0 * std::f64::consts::PI).abs() < 1e-12);
    assert_eq!(s.law.preload, 0.1);
    assert_eq!(
        file.model.sensors.last().unwrap().kind,
        SensorKind::RotationalSpringTorque { spring: 0 }
    );
    let params = flexmb::model::Parameters::new(&file.model);
    for path in [
        "rotational_spring.clock.angle",
        "rotational_spring.clock.preload",
    ] {
        assert!(params.id(path).is_ok(), "{path}");
    }
}

#[test]
fn gear_errors_name_the_key() {
    let at = |line: usize| format!("gears.toml:{line}:");
    for (from, to, key, field, message) in [
        (
            "mesh_stiffness = 4e8",
            "mesh_stiffness = -4e8",
            "mesh_stiffness =",
            "gear[0].mesh_stiffness",
            "must be positive",
        ),
        (
            "backlash = 1e-4",
            "backlash = -1e-4",
            "backlash =",
            "gear[0].backlash",
            "must be >= 0",
        ),
        (
            "backlash = 1e-4",
            "backlash = 1e-4\nlocate_impacts = 1",
            "locate_impacts =",
            "gear[0].locate_impacts",
            "a boolean",
        ),
        (
            "module = 0.003",
            "module = 0",
            "module =",
            "gear[0].module",
            "must be positive",
        ),
        (
            "teeth_a = 20",
            "teeth_a = 0",
            "teeth_a =",
            "gear[0].teeth_a",
            "whole number of teeth",
        ),
        (
            "node_b = \"wheel\"\naxis",
            "node_b = \"whee\"\naxis",
            "\"whee\"",
            "gear[0].node_b",
            "unknown node 'whee'",
        ),
        (
            "damping = 900.0",
            "damping = -1.0",
            "damping =",
            "gear[0].damping",
            "must be >= 0",
        ),
    ] {
        let (e, line) = gears_with(from, to, key);
        assert_contains(&e, &[&at(line), &format!("field '{field}'"), message]);
    }
    // Found by Model::validate, mapped back to the key.
    let (e, line) = gears_with("backlash = 1e-4", "backlash = 0.005", "backlash =");
    assert_contains(
        &e,
        &[&at(line), "field 'gear[0].backlash'", "half the base pitch"],
    );
    let (e, line) = gears_with(
        "teeth_b = 40\nmodule",
        "teeth_b = 40\ncenter_b = [0.08, 0.0, 0.0]\nmodule",
        "center_b",
    );
    assert_contains(
        &e,
        &[
            &at(line),
            "field 'gear[0].center_b'",
            "must exceed the sum of the base radii",
        ],
    );
    let (e, line) = gears_with(
        "backlash = 1e-4",
        "backlash = 1e-4\nstiffness_variation = [[1.2, 0.0]]",
        "stiffness_variation",
    );
    assert_contains(&e, &[&at(line), "gear[0].stiffness_variation[0][0]"]);
    let (e, line) = gears_with(
        "backlash = 1e-4",
        "backlash = 1e-4\nstiffness_variation = [[0.6, 0.0], [0.5, 1.0]]",
        "stiffness_variation",
    );
    assert_contains(
        &e,
        &[
            &at(line),
            "field 'gear[0].stiffness_variation'",
            "less than 1",
        ],
    );
    let (e, line) = gears_with(
        "backlash = 1e-4",
        "backlash = 1e-4\nstiffness_table = [[0.0, 1.2], [1.2, 0.8]]",
        "stiffness_table",
    );
    assert_contains(
        &e,
        &[
            &at(line),
            "field 'gear[0].stiffness_table'",
            "point 2",
            "within [0, 1)",
        ],
    );
    let (e, line) = gears_with(
        "backlash = 1e-4",
        "backlash = 1e-4\ninternal = \"yes\"",
        "internal",
    );
    assert_contains(&e, &[&at(line), "field 'gear[0].internal'", "boolean"]);
    let (e, line) = gears_with("gear = \"mesh\"", "gear = \"mash\"", "\"mash\"");
    assert_contains(&e, &[&at(line), "unknown gear pair 'mash'"]);
    // The gear joint.
    let joint = "[[joint]]\nname = \"ratio\"\ntype = \"gear\"\nnode_a = \"pinion\"\nnode_b = \"wheel\"\naxis = [0.0, 0.0, 1.0]\nteeth_a = 20\nteeth_b = 40\n\n[[gear]]";
    let with_joint =
        |from: &str, to: &str, key: &str| gears_with("[[gear]]", &joint.replacen(from, to, 1), key);
    let (e, line) = with_joint("teeth_b = 40", "teeth_b = -3", "teeth_b = -3");
    assert_contains(
        &e,
        &[
            &at(line),
            "field 'joint[2].teeth_b'",
            "whole number of teeth",
        ],
    );
    let (e, _) = with_joint(
        "node_b = \"wheel\"",
        "node_b = \"pinion\"",
        "name = \"ratio\"",
    );
    assert_contains(&e, &["field 'joint[2].node_b'", "joins a node to itself"]);
    let (e, line) = with_joint(
        "axis = [0.0, 0.0, 1.0]\n",
        "axis = [0.0, 0.0, 1.0]\nposition = [0.0, 0.0, 0.0]\n",
        "name = \"ratio\"",
    );
    assert!(line > 0);
    assert_contains(&e, &["joint[2]", "position"]);
    let (e, line) = with_joint(
        "node_a = \"pinion\"\n",
        "node_a = \"ground\"\n",
        "node_a = \"ground\"",
    );
    assert!(line > 0);
    assert_contains(
        &e,
        &[
            "field 'joint[2].center_a'",
            "required for a wheel on the ground",
        ],
    );
}

#[test]
fn bad_rotational_springs_name_their_field() {
    let head = "[[rotational_spring]]\nname = \"clock\"\n";
    let cases = [
        (
            "joint = \"hinge\"\nstiffness = -1",
            3,
            "rotational_spring[0].stiffness",
            ">= 0",
        ),
        (
            "joint = \"hinj\"\nstiffness = 1",
            2,
            "rotational_spring[0].joint",
            "unknown joint 'hinj'",
        ),
        (
            "joint = \"pin2\"\nstiffness = 1",
            2,
            "rotational_spring[0].joint",
            "unknown joint",
        ),
        (
            "joint = \"crank\"\nstiffness = 1\nangle = 1\nangle_deg = 5",
            5,
            "rotational_spring[0].angle_deg",
            "not both",
        ),
        (
            "joint = \"hinge\"\nforce_table = [[1, 0], [0, 1]]",
            3,
            "rotational_spring[0].force_table[1]",
            "not sorted",
        ),
        (
            "joint = \"hinge\"\nstiffness = 1\nacts = \"sideways\"",
            4,
            "rotational_spring[0].acts",
            "must be one of",
        ),
        (
            "joint = \"hinge\"",
            0,
            "rotational_spring[0].stiffness",
            "missing",
        ),
    ];
    for (body, offset, field, says) in cases {
        let (text, line) = with_rotational_spring(&format!("{head}{body}"));
        let e = parse_model_str(&text, "rot.toml", &[])
            .map(|_| ())
            .expect_err(body)
            .to_string();
        println!("{e}");
        assert_contains(
            &e,
            &[
                &format!("rot.toml:{}:", line + offset),
                &format!("field '{field}'"),
                says,
            ],
        );
    }
    // a joint that is neither revolute nor cylindrical: the spherical pin of GOOD
    let text = format!("{GOOD}\n{head}joint = \"pin\"\nstiffness = 1\n");
    let e = parse_model_str(&text, "rot.toml", &[])
        .map(|_| ())
        .expect_err("spherical")
        .to_string();
    println!("{e}");
    assert_contains(
        &e,
        &[
            "field 'rotational_spring[0].joint'",
            "spherical",
            "revolute or cylindrical",
        ],
    );
}

#[test]
fn bushings_are_read_and_bad_matrices_are_located() {
    let base = "\n[[bushing]]\nname = \"mount\"\nnode_b = \"top\"\nposition = [1, 0, 0]\n";
    let text = format!(
        "{GOOD}{base}stiffness = [1e4, 1e4, 2e4, 100, 100, 200]\ndamping = [[10, 1, 0, 0, 0, 0], [1, 10, 0, 0, 0, 0], [0, 0, 10, 0, 0, 0], [0, 0, 0, 1, 0, 0], [0, 0, 0, 0, 1, 0], [0, 0, 0, 0, 0, 1]]\n\n[[sensor]]\nname = \"mz\"\ntype = \"bushing_force\"\nbushing = \"mount\"\ncomponent = \"mz\"\n"
    );
    let file = parse_model_str(&text, "mount.toml", &[]).expect("reads");
    let b = &file.model.bushings[0];
    assert_eq!(b.node_a, None);
    assert_eq!(b.stiffness[(2, 2)], 2e4);
    assert_eq!(b.damping[(0, 1)], 1.0);
    // the two frames coincide at t = 0, at the given point
    let top = &file.model.nodes[b.node_b.unwrap().0].frame;
    let (fa, fb) = (b.frame_a, top.compose(&b.frame_b));
    assert!((fa.x - Vec3::new(1.0, 0.0, 0.0)).norm() < 1e-12);
    assert!((fb.x - fa.x).norm() < 1e-12 && (fb.r - fa.r).norm() < 1e-12);
    assert_eq!(
        file.model.sensors.last().unwrap().kind,
        SensorKind::BushingForce {
            bushing: 0,
            component: 5
        }
    );
    let params = flexmb::model::Parameters::new(&file.model);
    assert!(params.id("bushing.mount.stiffness.2.5").is_ok());
    let line = GOOD.lines().count() + 6;
    let cases = [
        (
            "stiffness = [[1, 2, 0, 0, 0, 0], [0, 1, 0, 0, 0, 0], [0, 0, 1, 0, 0, 0], [0, 0, 0, 1, 0, 0], [0, 0, 0, 0, 1, 0], [0, 0, 0, 0, 0, 1]]",
            "bushing[0].stiffness",
            "not symmetric",
        ),
        (
            "stiffness = [1, 1, -1, 1, 1, 1]",
            "bushing[0].stiffness",
            "not positive semidefinite",
        ),
        (
            "stiffness = [1, 1, 1, 1, 1, 1]\ndamping = [[1, 2, 0, 0, 0, 0], [2, 1, 0, 0, 0, 0], [0, 0, 1, 0, 0, 0], [0, 0, 0, 1, 0, 0], [0, 0, 0, 0, 1, 0], [0, 0, 0, 0, 0, 1]]",
            "bushing[0].damping",
            "not positive semidefinite",
        ),
        (
            "stiffness = [1, 1, 1]",
            "bushing[0].stiffness",
            "6 numbers",
        ),
    ];
    for (extra, field, says) in cases {
        let text = format!("{GOOD}{base}{extra}\n");
        let e = parse_model_str(&text, "mount.toml", &[])
            .map(|_| ())
            .expect_err(extra)
            .to_string();
        println!("{e}");
        let at = line + usize::from(field.ends_with("damping"));
        assert_contains(
            &e,
            &[
                &format!("mount.toml:{at}:"),
                &format!("field '{field}'"),
                says,
            ],
        );
    }
    // an unknown node; the R3xSO(3) group reads (the element converts its coordinates)
    let text = format!(
        "{GOOD}{}stiffness = [1, 1, 1, 1, 1, 1]\n",
        base.replace("\"top\"", "\"tpo\"")
    );
    let e = parse_model_str(&text, "mount.toml", &[])
        .map(|_| ())
        .expect_err("node")
        .to_string();
    assert_contains(&e, &["field 'bushing[0].node_b'", "unknown node 'tpo'"]);
    let text = format!("{GOOD}{base}stiffness = [1, 1, 1, 1, 1, 1]\n")
        .replace("group = \"SE3\"", "group = \"R3xSO3\"");
    let file = parse_model_str(&text, "mount.toml", &[]).expect("reads on R3xSO(3)");
    assert_eq!(file.model.group, Group::R3xSO3);
}

#[test]
fn worm_gear_errors_name_the_key() {
    let at = |line: usize| format!("torsen.toml:{line}:");
    let torsen = ("torsen.toml", "torsen.toml");
    for (from, to, key, field, message) in [
        (
            "mesh_stiffness = 1e8",
            "mesh_stiffness = -1e8",
            "mesh_stiffness = -",
            "worm_gear[0].mesh_stiffness",
            "must be positive",
        ),
        (
            "friction = 0.1",
            "friction = -0.1",
            "friction = -",
            "worm_gear[0].friction",
            "must be >= 0",
        ),
        (
            "node_a = \"side_left\"",
            "node_a = \"side_lef\"",
            "\"side_lef\"",
            "worm_gear[0].node_a",
            "unknown node 'side_lef'",
        ),
        (
            "axis_b = [0.0, 1.0, 0.0]",
            "axis_b = [0.1, 1.0, 0.0]",
            "axis_b = [0.1",
            "worm_gear[0].axis_b",
            "perpendicular to axis_a",
        ),
        (
            "washer_radius = 0.0095",
            "washer_radius = -0.0095",
            "washer_radius = -",
            "worm_gear[0].washer_radius",
            "must be >= 0",
        ),
        // found by Model::validate, mapped back to the key
        (
            "worm_radius = 0.02",
            "worm_radius = 0.04",
            "worm_radius = 0.04",
            "worm_gear[0].worm_radius",
            "below the centre distance",
        ),
    ] {
        let (e, line) = example_with(torsen, (from, to), key, &[]);
        assert_contains(&e, &[&at(line), &format!("field '{field}'"), message]);
    }
    // an override of the second worm gear's friction, located at its key
    let set = ["worm_gear.right.friction=-0.2".to_string()];
    let (e, _) = example_with(torsen, ("title", "title"), "title", &set);
    assert_contains(&e, &["field 'worm_gear[1].friction'", "must be >= 0"]);
    // a model built in Rust: the same check by Model::validate
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../examples/torsen.toml");
    let mut model = flexmb::input::read_model_file(&path, &[])
        .expect("example")
        .model;
    model.worm_gears[1].friction = -0.1;
    let e = model.validate().expect_err("negative friction").to_string();
    assert_contains(&e, &["worm_gear", "right", "friction", "-0.1"]);
}

/// Bad `[[block]]` input in `examples/pid_mass_spring.toml`: wiring and parameters, located.
#[test]
fn control_block_errors_are_located() {
    let path: PathBuf = [
        env!("CARGO_MANIFEST_DIR"),
        "../../examples/pid_mass_spring.toml",
    ]
    .iter()
    .collect();
    let good = std::fs::read_to_string(&path).expect("example");
    parse_model_str(&good, "pid.toml", &[]).expect("the example reads");
    let edit = |from: &str, to: &str| {
        assert!(good.contains(from), "{from}");
        match parse_model_str(&good.replace(from, to), "pid.toml", &[]) {
            Ok(_) => panic!("accepted: {to}"),
            Err(e) => e.to_string(),
        }
    };
    for (from, to, parts) in [
        (
            "input = \"error\"",
            "input = \"eror\"",
            &[
                "pid.toml:",
                "field 'block[3].input'",
                "unknown signal 'eror'",
                "'error'",
            ][..],
        ),
        (
            "inputs = [\"reference\", \"position\"]",
            "inputs = [\"reference\"]",
            &["field 'block[2].signs'", "one sign per input (1)"],
        ),
        (
            "inputs = [\"reference\", \"position\"]\nsigns = [1.0, -1.0]",
            "inputs = [\"reference\", \"position[1]\"]\nsigns = [1.0, -1.0]",
            &["field 'block[2].inputs[1]'", "'position' has 1 output"],
        ),
        (
            "input = \"pid\"\ntarget",
            "inputs = [\"pid\", \"error\"]\ntarget",
            &["field 'block[4].inputs'", "takes 1 input, got 2"],
        ),
        (
            "\ntf = 0.01\n",
            "\ntf = -0.01\n",
            &["field 'block[3].tf'", "positive"],
        ),
        (
            "\ntf = 0.01\n",
            "\ntf = 0.01\nlower = 5.0\nupper = -5.0\n",
            &["field 'block[3].upper'", ">= lower"],
        ),
        (
            "node = \"mass\"\ncomponent = \"x\"\n\n[[block]]\nname = \"error\"",
            "node = \"mas\"\ncomponent = \"x\"\n\n[[block]]\nname = \"error\"",
            &["field 'block[1].node'", "unknown node 'mas'"],
        ),
        (
            "quantity = \"position\"",
            "quantity = \"joint_coordinate\"\njoint = \"spring\"",
            &["field 'block[1].joint'", "unknown joint 'spring'"],
        ),
        (
            "quantity = \"position\"",
            "quantity = \"section_force\"\nbeam = \"guide[0]\"",
            &["field 'block[1].beam'", "unknown beam element 'guide[0]'"],
        ),
        (
            "quantity = \"position\"",
            "quantity = \"constraint_force\"\njoint = \"guide\"\naxis = [0.0, 0.0, 0.0]",
            &["block[1]", "axis"],
        ),
        (
            "quantity = \"position\"",
            "quantity = \"contact_force\"\ncontact = \"floor\"",
            &["field 'block[1].contact'", "unknown contact 'floor'"],
        ),
        (
            "type = \"pid\"",
            "type = \"pdi\"",
            &["field 'block[3].type'", "\"pid\""],
        ),
        ("kd = 20.0", "kd = 20.0\nkk = 1.0", &["block[3]", "kk"]),
    ] {
        assert_contains(&edit(from, to), parts);
    }
    // A force measured on a joint whose node B is the ground: located on the block's joint
    // (the check of the model, mapped to the file).
    let grounded = good
        .replace(
            "node_b = \"mass\"\nposition",
            "node_a = \"mass\"\nnode_b = \"ground\"\nposition",
        )
        .replace(
            "quantity = \"position\"",
            "quantity = \"constraint_force\"\njoint = \"guide\"",
        );
    let e = parse_model_str(&grounded, "pid.toml", &[]).expect_err("node B is the ground");
    assert_contains(
        &e.to_string(),
        &[
            "pid.toml:",
            "field 'block[1].joint'",
            "joint 'guide' has the ground as its node B",
        ],
    );
    // An algebraic loop whose gain is 1 (e = r - x, x = x + e: singular) is located on it;
    // one of gain 1/2 is solved.
    let with_loop = |gain: &str| {
        good.replace(
            "[[block]]\nname = \"pid\"",
            &format!("[[block]]\nname = \"echo\"\ntype = \"gain\"\ninput = \"loop\"\ngain = {gain}\n\n[[block]]\nname = \"loop\"\ntype = \"sum\"\ninputs = [\"echo\", \"error\"]\n\n[[block]]\nname = \"pid\""),
        )
    };
    let e = parse_model_str(&with_loop("1.0"), "pid.toml", &[]).expect_err("singular loop");
    assert_contains(
        &e.to_string(),
        &[
            "block[3]",
            "algebraic loop through blocks 'echo', 'loop'",
            "cannot be solved",
        ],
    );
    parse_model_str(&with_loop("0.5"), "pid.toml", &[]).expect("a loop of gain 1/2");
    // --set overrides are checked like the file.
    let e = parse_model_str(&good, "pid.toml", &["block.3.tf=0".to_string()]).expect_err("tf = 0");
    assert_contains(&e.to_string(), &["tf", "positive"]);
}
