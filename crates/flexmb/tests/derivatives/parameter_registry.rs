//! The parameter registry (`flexmb::model::Parameters`): every path names one parameter,
//! `set` then `value` returns the value, unknown paths are reported with the paths near
//! them, and a path set through the registry gives the same model as the same `--set` on the
//! model file.

use crate::common;

use flexmb::input::read_model_file;
use flexmb::model::{
    BeamSection, JointKind, Model, ParamKind, ParamRole, Parameters, TimeFunction,
};
use flexmb_lie::{Frame, Group, Mat3, Vec3};

const EXAMPLES: &[&str] = &[
    "andrews.toml",
    "bend_45.toml",
    "bricard.toml",
    "chain_10.toml",
    "flexible_four_bar.toml",
    "four_bar.toml",
    "heavy_top.toml",
    "heavy_top_r3so3.toml",
    "lee_frame.toml",
    "pendulum.toml",
    "right_angle_cantilever.toml",
    "roll_up.toml",
    "slider_crank.toml",
    "spin_up.toml",
    "viscoelastic_mount.toml",
    "block_and_tackle.toml",
];

fn read(name: &str, overrides: &[&str]) -> Model {
    let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    read_model_file(&common::example(name), &overrides)
        .unwrap_or_else(|e| panic!("{e}"))
        .model
}

/// Parameters stored in a node frame and read back in the inertial frame: `value` after
/// `set` is exact up to the round trip through the frame.
fn through_a_frame(kind: ParamKind) -> bool {
    use flexmb::model::parameters::{JointParam, SpringParam};
    matches!(
        kind,
        ParamKind::Joint(_, JointParam::Position(_))
            | ParamKind::Spring(_, SpringParam::PointA(_) | SpringParam::PointB(_))
    )
}

/// A model built in Rust with awkward names: shared, empty and numeric names, and beam
/// elements of one name whose sections differ.
fn awkward_model() -> Model {
    let mut m = Model::new(Group::SE3);
    let a = m.add_node("a", Frame::identity());
    let b = m.add_node("", Frame::new(Vec3::new(1.0, 0.0, 0.0), Mat3::identity()));
    m.add_body("twin", a, 1.0, Vec3::zeros(), Mat3::identity());
    m.add_body("twin", b, 2.0, Vec3::zeros(), Mat3::identity());
    m.add_body("42", b, 3.0, Vec3::zeros(), Mat3::identity());
    let section = BeamSection::diagonal([1e3; 6], 1.0, [0.1; 3]);
    let c = m.add_node("c", Frame::new(Vec3::new(2.0, 0.0, 0.0), Mat3::identity()));
    m.add_beam("rod[0]", [a, b], section.clone(), [Mat3::identity(); 2]);
    m.add_beam(
        "rod[1]",
        [b, c],
        section.with_damping(0.1, 0.0),
        [Mat3::identity(); 2],
    );
    m.add_beam(
        "link",
        [a, c],
        BeamSection::diagonal([1e3; 6], 1.0, [0.1; 3]),
        [Mat3::identity(); 2],
    );
    let j = m.add_joint(
        "hinge",
        JointKind::Revolute,
        None,
        Some(a),
        Vec3::zeros(),
        Mat3::identity(),
        None,
    );
    m.joints[j.0].drive = Some(TimeFunction::Table {
        points: vec![(0.0, 0.0), (1.0, 1.0)],
    });
    m
}

#[test]
fn parameter_paths_round_trip_and_set_then_value_returns_the_value() {
    let mut models: Vec<(String, Model)> = EXAMPLES
        .iter()
        .map(|n| (n.to_string(), read(n, &[])))
        .collect();
    models.push(("awkward".into(), awkward_model()));
    let mut count = 0;
    for (name, model) in &models {
        let params = Parameters::new(model);
        for id in params.ids() {
            let path = params.path(id);
            assert_eq!(params.id(path), Ok(id), "{name}: {path}");
            let role = params.role(id);
            assert_eq!(
                role == ParamRole::InitialState,
                matches!(params.kind(id), ParamKind::Node(..)),
                "{name}: {path}"
            );
            let old = params.value(model, id);
            let new = 1.5 * old + 0.25;
            let mut copy = model.clone();
            params.set(&mut copy, id, new);
            let got = params.value(&copy, id);
            if through_a_frame(params.kind(id)) {
                assert!(
                    (got - new).abs() <= 1e-14 * (1.0 + new.abs()),
                    "{name}: {path}: {got} vs {new}"
                );
            } else {
                assert_eq!(got, new, "{name}: {path}");
            }
            // setting the old value back gives the model (up to frames' round-off)
            params.set(&mut copy, id, old);
            if !through_a_frame(params.kind(id)) {
                assert_eq!(&copy, model, "{name}: {path}");
            }
            count += 1;
        }
    }
    println!("{count} parameters of {} models", models.len());

    // The names a model built in Rust gets (module documentation of `parameters`).
    let m = awkward_model();
    let params = Parameters::new(&m);
    for path in [
        "node.a.velocity.0",
        "node.1.angular_velocity_body.2",
        "body.0.mass",
        "body.1.inertia.5",
        "body.2.com.1",
        "beam.rod.element.0.section.EA",
        "beam.rod.element.1.damping.mass",
        "beam.link.section.rhoA",
        "joint.hinge.position.2",
        "joint.hinge.drive.points.1.1",
    ] {
        assert!(
            params.id(path).is_ok(),
            "{path}: {}",
            params.id(path).unwrap_err()
        );
    }
    for path in ["body.twin.mass", "body.42.mass", "beam.rod.section.EA"] {
        assert!(
            params.id(path).is_err(),
            "{path} is ambiguous and not a path"
        );
    }
    // one parameter drives every element of a file-level beam
    let m = read("right_angle_cantilever.toml", &[]);
    let params = Parameters::new(&m);
    let id = params.id("beam.leg1.section.EI2").unwrap();
    let ParamKind::Beam(item, _) = params.kind(id) else {
        panic!("a beam parameter")
    };
    let elements = params.beam_elements(item);
    assert_eq!(elements.len(), 10, "leg1 has 10 elements");
    let mut copy = m.clone();
    params.set(&mut copy, id, 7.0);
    for &e in elements {
        assert_eq!(copy.beams[e].section.stiffness[(4, 4)], 7.0);
    }
    assert_eq!(
        copy.beams
            .iter()
            .filter(|b| b.section.stiffness[(4, 4)] == 7.0)
            .count(),
        10
    );
}

#[test]
fn unknown_parameter_paths_name_near_paths() {
    let model = read("heavy_top.toml", &[]);
    let params = Parameters::new(&model);
    for (path, near) in [
        ("body.top.mas", "body.top.mass"),
        ("body.tpo.mass", "body.top.mass"),
        ("model.gravity.3", "model.gravity.2"),
        ("joint.pivot.position", "joint.pivot.position.0"),
        ("body.top.inertia.xx", "body.top.inertia.0"),
    ] {
        let e = params.id(path).unwrap_err();
        assert_eq!(e.path, path);
        assert!(e.near.iter().any(|p| p == near), "{path}: {:?}", e.near);
        let message = e.to_string();
        assert!(
            message.contains(&format!("unknown parameter '{path}'"))
                && message.contains(&format!("'{near}'")),
            "{message}"
        );
    }
}

#[test]
fn parameter_set_matches_set_override_on_example_files() {
    // (file, the --set override, the registry path, the value)
    let cases: &[(&str, &str, &str, f64)] = &[
        ("heavy_top.toml", "body.top.mass=2", "body.top.mass", 2.0),
        (
            "heavy_top.toml",
            "body.top.inertia.0=0.3",
            "body.top.inertia.0",
            0.3,
        ),
        (
            "heavy_top.toml",
            "model.gravity.2=-1.62",
            "model.gravity.2",
            -1.62,
        ),
        (
            "heavy_top.toml",
            "joint.pivot.position.0=0.25",
            "joint.pivot.position.0",
            0.25,
        ),
        // the file has no com: --set inserts the vector
        (
            "heavy_top.toml",
            "body.top.com=[0.0, 0.8, 0.0]",
            "body.top.com.1",
            0.8,
        ),
        // a body's own node: the file sets its state on the body
        (
            "heavy_top.toml",
            "body.top.angular_velocity_body.1=140",
            "node.top.angular_velocity_body.1",
            140.0,
        ),
        (
            "heavy_top.toml",
            "body.top.velocity.0=4",
            "node.top.velocity.0",
            4.0,
        ),
        (
            "andrews.toml",
            "spring.spring.stiffness=4000",
            "spring.spring.stiffness",
            4000.0,
        ),
        (
            "andrews.toml",
            "spring.spring.rest_length=0.08",
            "spring.spring.rest_length",
            0.08,
        ),
        (
            "andrews.toml",
            "spring.spring.point_a.1=0.07",
            "spring.spring.point_a.1",
            0.07,
        ),
        (
            "andrews.toml",
            "load.drive.torque.2=0.05",
            "load.drive.torque.2",
            0.05,
        ),
        (
            "bend_45.toml",
            "beam.arc.section.EA=2e7",
            "beam.arc.section.EA",
            2e7,
        ),
        (
            "bend_45.toml",
            "beam.arc.section.rhoI3=0.1",
            "beam.arc.section.rhoI3",
            0.1,
        ),
        (
            "bend_45.toml",
            "load.tip_force.force.2=300",
            "load.tip_force.force.2",
            300.0,
        ),
        (
            "right_angle_cantilever.toml",
            "load.impulse.function.points.1.1=40",
            "load.impulse.function.points.1.1",
            40.0,
        ),
        (
            "spin_up.toml",
            "joint.hub.drive.omega=4",
            "joint.hub.drive.omega",
            4.0,
        ),
        (
            "slider_crank.toml",
            "joint.motor.drive.slope=140",
            "joint.motor.drive.slope",
            140.0,
        ),
        (
            "viscoelastic_mount.toml",
            "spring.mount.relaxation_stiffness=3",
            "spring.mount.relaxation_stiffness",
            3.0,
        ),
        (
            "block_and_tackle.toml",
            "rope.rope.points.2.point.0=0.6",
            "rope.rope.points.2.point.0",
            0.6,
        ),
        (
            "block_and_tackle.toml",
            "rope.rope.stiffness=1200",
            "rope.rope.stiffness",
            1200.0,
        ),
        (
            "viscoelastic_mount.toml",
            "spring.mount.relaxation_damping=0.7",
            "spring.mount.relaxation_damping",
            0.7,
        ),
    ];
    for &(file, set, path, value) in cases {
        let expected = read(file, &[set]);
        let mut model = read(file, &[]);
        let params = Parameters::new(&model);
        let id = params.id(path).unwrap_or_else(|e| panic!("{file}: {e}"));
        params.set(&mut model, id, value);
        assert_eq!(model, expected, "{file}: {path}");
    }
}

/// Beam elements of one name (not `<r>[<i>]`) whose sections differ have no common path:
/// each is a beam of its own, named by its index in `Model::beams` (the rule of the
/// module documentation), so that every element keeps parameters.
#[test]
fn beam_elements_of_one_name_and_other_sections_are_named_by_index() {
    let mut m = Model::new(Group::SE3);
    let a = m.add_node("a", Frame::identity());
    let b = m.add_node("b", Frame::new(Vec3::new(1.0, 0.0, 0.0), Mat3::identity()));
    let c = m.add_node("c", Frame::new(Vec3::new(2.0, 0.0, 0.0), Mat3::identity()));
    let section = BeamSection::diagonal([1e3; 6], 1.0, [0.1; 3]);
    m.add_beam("strut", [a, b], section.clone(), [Mat3::identity(); 2]);
    m.add_beam(
        "strut",
        [b, c],
        section.clone().with_damping(0.1, 0.0),
        [Mat3::identity(); 2],
    );
    let params = Parameters::new(&m);
    assert!(params.id("beam.strut.section.EA").is_err());
    assert!(params.id("beam.strut.element.0.section.EA").is_err());
    for e in 0..2 {
        let id = params.id(&format!("beam.{e}.damping.mass")).unwrap();
        assert_eq!(params.value(&m, id), [0.0, 0.1][e]);
    }
    // with one section they are one beam
    m.beams[1].section = section;
    let params = Parameters::new(&m);
    let id = params.id("beam.strut.section.EA").unwrap();
    let ParamKind::Beam(item, _) = params.kind(id) else {
        panic!("a beam parameter")
    };
    assert_eq!(params.beam_elements(item), [0, 1]);
}
