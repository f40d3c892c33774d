//! The input is checked where it enters: numbers finite and in range (with the field that
//! caused a bad derived value, e.g. a step whose square underflows), degenerate items
//! rejected, file size and message length bounded (reading time: BENCHMARKS.md).
//! The same checks hold for a model built with the Rust API (`Model::validate`).

use crate::common;

use flexmb::input::{parse_model_str, read_model_file, InputError};
use flexmb::model::{JointKind, Model, Sensor, SensorKind, SpringDamper};
use flexmb_lie::{Frame, Group, Mat3, Vec3};
use std::path::PathBuf;

/// The text of an example model file.
fn example(name: &str) -> String {
    std::fs::read_to_string(common::example(name)).unwrap()
}

/// The error of reading `text` with `overrides`; it must name `line` (if given) and `field`.
fn error(text: &str, overrides: &[&str], line: Option<u32>, field: &str, more: &[&str]) -> String {
    let set: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    let e = match parse_model_str(text, "m.toml", &set) {
        Ok(_) => panic!("accepted with {overrides:?}"),
        Err(e) => e,
    };
    let message = e.to_string();
    println!("{message}");
    let location = e.location().expect("a location");
    if let Some(line) = line {
        assert_eq!(location.line, line, "{message}");
    }
    assert_eq!(e.field(), Some(field), "{message}");
    assert!(message.starts_with(&format!("m.toml:{}:", location.line)));
    for part in more {
        assert!(message.contains(part), "{message} lacks {part:?}");
    }
    message
}

const TOP: &str = "heavy_top.toml";

/// The first line that starts with `start`.
fn line_of(text: &str, start: &str) -> u32 {
    text.lines()
        .position(|l| l.starts_with(start))
        .expect(start) as u32
        + 1
}

#[test]
fn huge_rotations_are_rejected_at_the_orientation() {
    let top = example(TOP);
    error(
        &top,
        &["body.top.orientation={ rotation_vector = [1e200, 0, 0] }"],
        None,
        "body[0].orientation.rotation_vector[0]",
        &["1e6", "--set"],
    );
    error(
        &top,
        &["body.top.orientation={ rotation_vector = [8e5, 8e5, 0] }"],
        None,
        "body[0].orientation.rotation_vector",
        &["angle", "1e-10"],
    );
    error(
        &top,
        &["body.top.orientation={ axis = [1, 0, 0], angle_deg = 1e308 }"],
        None,
        "body[0].orientation.angle_deg",
        &["1e6"],
    );
    // A large but precise angle is fine.
    let set = ["body.top.orientation={ axis = [1, 0, 0], angle_deg = 7200 }".to_string()];
    parse_model_str(&top, "m.toml", &set).unwrap();
}

#[test]
fn masses_inertias_and_tiny_beams_out_of_range_are_located_errors() {
    let top = example(TOP);
    let mass_line = line_of(&top, "mass = ");
    error(
        &top,
        &["body.top.mass=1e300"],
        Some(mass_line),
        "body[0].mass",
        &["1e30"],
    );
    error(
        &top,
        &["body.top.mass=5e-324"],
        Some(mass_line),
        "body[0].mass",
        &["1e-30"],
    );
    error(
        &top,
        &["body.top.inertia=[1e99, 1e99, 1e99]"],
        None,
        "body[0].inertia",
        &["1e30"],
    );
    error(
        &top,
        &["body.top.com=[0, 1e300, 0]"],
        None,
        "body[0].com[1]",
        &["1e9"],
    );
    // A beam element of 1e-12 m in a model of metres: degenerate, at the beam's end point.
    let beams = r#"flexmb = 1
[model]
group = "SE3"
[solver]
analysis = "static"
[[beam]]
name = "long"
start = [0.0, 0.0, 0.0]
end = [2.0, 0.0, 0.0]
elements = 2
orientation = [0.0, 0.0, 1.0]
section = { EA = 1e6, GA2 = 1e6, GA3 = 1e6, GJ = 1e3, EI2 = 1e3, EI3 = 1e3, rhoA = 1.0, rhoJ = 2.0, rhoI2 = 1.0, rhoI3 = 1.0 }
[[beam]]
name = "short"
start_node = "long.2"
end = [2.0, 1.0, 0.0]
elements = 1
orientation = [0.0, 0.0, 1.0]
section = { EA = 1e6, GA2 = 1e6, GA3 = 1e6, GJ = 1e3, EI2 = 1e3, EI3 = 1e3, rhoA = 1.0, rhoJ = 2.0, rhoI2 = 1.0, rhoI3 = 1.0 }
"#;
    parse_model_str(beams, "m.toml", &[]).unwrap();
    error(
        beams,
        &["beam.short.end=[2.0, 1e-12, 0.0]"],
        Some(16),
        "beam[1].end",
        &["degenerate", "extent of the model"],
    );
}

#[test]
fn a_lone_tiny_beam_is_degenerate_against_its_own_section() {
    let text = r#"flexmb = 1
[model]
group = "SE3"
[solver]
analysis = "static"
[[beam]]
name = "speck"
start = [0.0, 0.0, 0.0]
end = [1e-12, 0.0, 0.0]
elements = 1
orientation = [0.0, 0.0, 1.0]
section = { EA = 1e6, GA2 = 1e6, GA3 = 1e6, GJ = 1e3, EI2 = 1e3, EI3 = 1e3, rhoA = 1.0, rhoJ = 2.0, rhoI2 = 1.0, rhoI3 = 1.0 }
"#;
    error(text, &[], Some(9), "beam[0].end", &["radius of gyration"]);
}

#[test]
fn steps_whose_derived_values_underflow_are_rejected_at_their_field() {
    let top = example(TOP);
    let h_line = line_of(&top, "h = ");
    error(
        &top,
        &["solver.h=1e-320"],
        Some(h_line),
        "solver.h",
        &["1e-12"],
    );
    // t_end / h steps: time would no longer advance.
    error(
        &top,
        &["solver.t_end=1e12"],
        None,
        "solver.t_end",
        &["steps", "--set 'solver.t_end=1e12'"],
    );
    error(
        &top,
        &["solver.h=1e-11"],
        Some(h_line),
        "solver.h",
        &["steps"],
    );
    error(
        &top,
        &["solver.h_min=5e-324"],
        None,
        "solver.h_min",
        &["1e-12 h"],
    );
    error(
        &top,
        &["solver.output_interval=5e-324"],
        None,
        "solver.output_interval",
        &["1e-12"],
    );
    error(
        &top,
        &["solver.output_interval=1e-11"],
        None,
        "solver.output_interval",
        &["outputs"],
    );
    let lee = example("lee_frame.toml");
    let arc_line = line_of(&lee, "arc_length = ");
    error(
        &lee,
        &["solver.arc_length=5e-324"],
        Some(arc_line),
        "solver.arc_length",
        &["1e-9"],
    );
    error(
        &lee,
        &["solver.load_factor=1e-320"],
        None,
        "solver.load_factor",
        &["1e-12"],
    );
    let roll = example("roll_up.toml");
    error(
        &roll,
        &["solver.min_increment=5e-324"],
        None,
        "solver.min_increment",
        &["1e-12"],
    );
    // The smallest increment must move a large load factor.
    error(
        &roll,
        &["solver.load_factor=1e9", "solver.min_increment=1e-6"],
        None,
        "solver.min_increment",
        &["would not advance"],
    );
    // Pseudo-dynamic: the step increment x pseudo_time.
    error(
        &roll,
        &[
            "solver.method=pseudo_dynamic",
            "solver.pseudo_time=1e-12",
            "solver.min_increment=1e-6",
        ],
        None,
        "solver.pseudo_time",
        &["pseudo-dynamic step"],
    );
}

#[test]
fn time_functions_with_extreme_numbers_are_rejected_at_their_field() {
    let crank = r#"flexmb = 1
[model]
group = "SE3"
[solver]
analysis = "dynamic"
t_end = 1.0
h = 1e-3
[[body]]
name = "hub"
mass = 1.0
inertia = [1.0, 1.0, 1.0]
[[joint]]
name = "crank"
type = "revolute"
node_b = "hub"
position = [0.0, 0.0, 0.0]
axis = [0.0, 0.0, 1.0]
drive = { type = "ramp", t0 = 0.0, t1 = 1.0, value = 1.0 }
"#;
    parse_model_str(crank, "m.toml", &[]).unwrap();
    error(
        crank,
        &["joint.crank.drive.t1=1e-300"],
        None,
        "joint[0].drive.t1",
        &["exceed t0"],
    );
    error(
        crank,
        &["joint.crank.drive.value=1e300"],
        None,
        "joint[0].drive.value",
        &["1e30"],
    );
    error(
        crank,
        &["joint.crank.drive={ type = \"sine\", amplitude = 1.0, frequency = 1e300 }"],
        None,
        "joint[0].drive.frequency",
        &["1e9"],
    );
    error(
        crank,
        &["joint.crank.drive={ type = \"spin_up\", omega = 1.0, duration = 5e-324 }"],
        None,
        "joint[0].drive.duration",
        &["1e-12"],
    );
    error(
        crank,
        &["joint.crank.drive={ type = \"table\", points = [[0, 0], [1e-300, 1]] }"],
        None,
        "joint[0].drive.points[1]",
        &["increasing"],
    );
}

#[test]
fn degenerate_springs_are_rejected_at_their_field() {
    let spring = |extra: &str| {
        format!(
            r#"flexmb = 1
[model]
group = "SE3"
[solver]
analysis = "dynamic"
t_end = 1.0
h = 1e-3
[[body]]
name = "a"
mass = 1.0
inertia = [1.0, 1.0, 1.0]
[[body]]
name = "b"
position = [1.0, 0.0, 0.0]
mass = 1.0
inertia = [1.0, 1.0, 1.0]
[[spring]]
name = "s"
stiffness = 10.0
{extra}
"#
        )
    };
    let ok = spring("node_a = \"a\"\nnode_b = \"b\"\npoint_a = [0, 0, 0]\npoint_b = [1, 0, 0]");
    parse_model_str(&ok, "m.toml", &[]).unwrap();
    let node_b = line_of(&ok, "node_b");
    error(
        &spring("node_a = \"a\"\nnode_b = \"a\"\npoint_a = [0, 0, 0]\npoint_b = [1, 0, 0]"),
        &[],
        Some(node_b),
        "spring[0].node_b",
        &["to itself"],
    );
    error(
        &spring("node_b = \"ground\"\npoint_a = [0, 0, 0]\npoint_b = [1, 0, 0]"),
        &[],
        Some(node_b - 1),
        "spring[0].node_b",
        &["ground to the ground"],
    );
    error(
        &spring("node_a = \"a\"\nnode_b = \"b\"\npoint_a = [1, 0, 0]\npoint_b = [1, 0, 0]\nrest_length = 0.5"),
        &[],
        Some(node_b + 3),
        "spring[0].rest_length",
        &["coincide", "undefined"],
    );
    // Coincident end points with rest length 0 are a zero-length spring: fine.
    let zero = spring("node_a = \"a\"\nnode_b = \"b\"\npoint_a = [1, 0, 0]\npoint_b = [1, 0, 0]");
    parse_model_str(&zero, "m.toml", &[]).unwrap();
}

#[test]
fn sensor_names_that_break_the_csv_header_are_rejected() {
    let top = example(TOP);
    let line = line_of(&top, "name = \"com_x\"");
    for name in ["time", "load_factor"] {
        error(
            &top,
            &[&format!("sensor.com_x.name={name}")],
            Some(line),
            "sensor[0].name",
            &["first column"],
        );
    }
    for name in ["\"a,b\"", "\"a\\\"b\"", "\"a\\nb\"", "\"a\\u0007b\""] {
        error(
            &top,
            &[&format!("sensor.com_x.name={name}")],
            Some(line),
            "sensor[0].name",
            &["must not contain"],
        );
    }
    let energy = top[..top.find("name = \"energy\"").unwrap()]
        .matches("[[sensor]]")
        .count()
        - 1;
    error(
        &top,
        &["sensor.com_x.name=energy"],
        None,
        &format!("sensor[{energy}].name"),
        &["duplicate sensor name"],
    );
}

#[test]
fn error_messages_stay_short_for_huge_names_and_values() {
    let top = example(TOP);
    let huge = "n".repeat(10_000_000);
    let cases = [
        top.replace("node_b = \"top\"", &format!("node_b = \"{huge}\"")),
        top.replace("mass = 15.0", &format!("{huge} = 15.0")),
        top.replace("type = \"spherical\"", &format!("type = \"{huge}\"")),
        top.replace("name = \"top\"", &format!("name = \"{huge}\"\nmass = -1")),
    ];
    for text in &cases {
        let e = parse_model_str(text, "m.toml", &[]).unwrap_err();
        assert!(e.location().is_some());
        assert!(e.to_string().len() < 2000, "{} bytes", e.to_string().len());
    }
    let set = [format!("body.{huge}.mass=1"), format!("solver.h={huge}")];
    for s in set {
        let e = parse_model_str(&top, "m.toml", &[s]).unwrap_err();
        assert!(e.to_string().len() < 2000, "{} bytes", e.to_string().len());
    }
}

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("flexmb-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn a_model_file_over_the_size_limit_is_refused_without_reading_it() {
    let dir = temp_dir("size");
    let path = dir.join("huge.toml");
    // A sparse file: no disk space, but 300 MiB long.
    let f = std::fs::File::create(&path).unwrap();
    f.set_len(300 << 20).unwrap();
    let e = read_model_file(&path, &[]).unwrap_err();
    assert!(matches!(e, InputError::Io { .. }), "{e}");
    assert!(e.to_string().contains("256 MiB"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[cfg(unix)]
#[test]
fn devices_are_refused_and_pipes_are_read() {
    let e = read_model_file("/dev/zero".as_ref(), &[]).unwrap_err();
    assert!(e.to_string().contains("not a model file"), "{e}");
    // A named pipe is read as its writer writes it.
    let dir = temp_dir("fifo");
    let fifo = dir.join("model.fifo");
    let made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .expect("mkfifo runs");
    assert!(made.success());
    let text = example(TOP);
    let writer = {
        let (fifo, text) = (fifo.clone(), text.clone());
        std::thread::spawn(move || std::fs::write(&fifo, text).expect("writes the pipe"))
    };
    let file = read_model_file(&fifo, &[]).expect("reads the pipe");
    writer.join().unwrap();
    assert_eq!(file.model.nodes.len(), 1);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_file_with_nul_bytes_is_not_text() {
    let dir = temp_dir("nul");
    let path = dir.join("zeros.toml");
    std::fs::write(&path, b"flexmb = 1\n\0\0\0").unwrap();
    let e = read_model_file(&path, &[]).unwrap_err();
    assert!(e.to_string().contains("NUL byte at byte 11"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A Rust API model: one body on a spherical joint, a spring to the ground and a sensor.
fn api_model() -> Model {
    let mut m = Model::new(Group::SE3);
    let a = m.add_node("a", Frame::identity());
    m.add_body("a", a, 1.0, Vec3::new(0.0, 1.0, 0.0), Mat3::identity());
    m.add_joint(
        "pivot",
        JointKind::Spherical,
        None,
        Some(a),
        Vec3::zeros(),
        Mat3::identity(),
        None,
    );
    m.springs.push(SpringDamper {
        name: "s".into(),
        node_a: None,
        node_b: Some(a),
        point_a: Vec3::new(0.0, 2.0, 0.0),
        point_b: Vec3::new(0.0, 1.0, 0.0),
        stiffness: 1.0,
        damping: 0.0,
        rest_length: 1.0,
        relaxation: None,
    });
    m.sensors.push(Sensor {
        name: "y".into(),
        kind: SensorKind::Position {
            node: a,
            point: Vec3::zeros(),
            component: 1,
        },
    });
    m
}

/// `Model::validate` of `api_model()` changed by `edit` fails at `table`/`field`.
fn api_error(edit: impl FnOnce(&mut Model), table: &str, field: &str, more: &str) {
    let mut m = api_model();
    edit(&mut m);
    let e = m.validate().expect_err("accepted");
    println!("{e}");
    assert_eq!((e.item().table, e.item().field), (table, field), "{e}");
    assert!(e.to_string().contains(more), "{e}");
}

#[test]
fn the_rust_api_rejects_non_finite_and_out_of_range_data() {
    api_model().validate().unwrap();
    api_error(
        |m| m.nodes[0].frame.x.x = f64::NAN,
        "node",
        "position",
        "non-finite",
    );
    api_error(|m| m.nodes[0].velocity.y = 1e300, "node", "velocity", "1e9");
    api_error(|m| m.bodies[0].mass = 1e300, "body", "mass", "1e30");
    api_error(|m| m.bodies[0].inertia *= 1e99, "body", "inertia", "1e30");
    api_error(
        |m| m.bodies[0].com.z = f64::INFINITY,
        "body",
        "com",
        "non-finite",
    );
    api_error(|m| m.gravity.z = f64::NAN, "model", "gravity", "non-finite");
    api_error(
        |m| m.joints[0].frame_b.r *= 2.0,
        "joint",
        "position",
        "rotation",
    );
    api_error(
        |m| m.springs[0].stiffness = f64::NAN,
        "spring",
        "stiffness",
        "NaN",
    );
    api_error(
        |m| {
            m.joints[0].kind = JointKind::Revolute;
            m.joints[0].drive = Some(flexmb::model::TimeFunction::Constant { value: f64::NAN });
        },
        "joint",
        "drive",
        "NaN",
    );
    api_error(
        |m| {
            m.sensors[0].kind = SensorKind::JointCoordinate {
                joint: flexmb::model::JointId(0),
            }
        },
        "sensor",
        "joint",
        "spherical",
    );
    api_error(
        |m| {
            m.sensors[0].kind = SensorKind::BeamStrain {
                beam: 3,
                component: 0,
            }
        },
        "sensor",
        "beam",
        "does not exist",
    );
    api_error(
        |m| {
            m.sensors[0].kind = SensorKind::Quaternion {
                node: flexmb::model::NodeId(0),
                component: 4,
            }
        },
        "sensor",
        "component",
        "0 to 3",
    );
}

#[test]
fn the_rust_api_rejects_degenerate_springs_and_sensor_names() {
    api_error(|m| m.springs[0].node_b = None, "spring", "node_b", "ground");
    api_error(
        |m| m.springs[0].node_a = m.springs[0].node_b,
        "spring",
        "node_b",
        "itself",
    );
    api_error(
        |m| m.springs[0].point_a = Vec3::new(0.0, 1.0, 0.0),
        "spring",
        "rest_length",
        "coincide",
    );
    api_error(
        |m| m.sensors[0].name = "time".into(),
        "sensor",
        "name",
        "first column",
    );
    api_error(
        |m| m.sensors[0].name = "a\tb".into(),
        "sensor",
        "name",
        "control",
    );
    api_error(
        |m| m.sensors.push(m.sensors[0].clone()),
        "sensor",
        "name",
        "duplicate",
    );
    api_error(
        |m| {
            let id = m.add_node("a", Frame::identity());
            m.add_body("b", id, 1.0, Vec3::zeros(), Mat3::identity());
        },
        "node",
        "name",
        "duplicate",
    );
}

/// A vector is bounded by its length, which no rotation changes: an inertial angular
/// velocity (1e9, 1e9, 0) has components in range but a length of 1.4e9, and is rejected at
/// the key the file gives (a bound on components let the reader accept it and the model's
/// check refuse its rotated node-frame copy, (1.4e9, 0, 0), a number nobody wrote).
#[test]
fn vectors_are_bounded_by_their_length_at_their_key() {
    let top = example(TOP);
    error(
        &top,
        &[
            "body.top.orientation={ axis = [0, 0, 1], angle_deg = 45 }",
            "body.top.angular_velocity=[1e9, 1e9, 0]",
        ],
        None,
        "body[0].angular_velocity",
        &["length", "1e9"],
    );
}
