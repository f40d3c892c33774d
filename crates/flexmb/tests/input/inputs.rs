//! `[[input]]`: the model's inputs `u` (the engine issue, item 3), an actuator torque or force
//! per unit of `u_k` at a node. A run applies each input's `function`, exactly as a `[[load]]`
//! of the same data would; a step can be given the input vector instead
//! (`StepFunction::with_inputs`), and `dR/du` is exact (`tests/derivatives`, step Jacobians).

use crate::common::{example, run_model};
use flexmb::input::read_model_file;
use flexmb::model::Parameters;
use flexmb::solve::Analysis;

/// The pendulum example driven by a torque about its pivot's axis, as an `[[input]]` or as a
/// `[[load]]` (`table`), written to a file of its own.
fn pendulum_with(table: &str, extra: &str) -> std::path::PathBuf {
    let base = std::fs::read_to_string(example("pendulum.toml")).unwrap();
    let text = format!(
        "{base}\n[[{table}]]\nname = \"motor\"\nnode = \"pendulum\"\ntorque = [0.0, 0.0, 2.0]\n{extra}"
    );
    let dir = std::env::temp_dir().join(format!("flexmb-inputs-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(format!("{table}-{}.toml", extra.len()));
    std::fs::write(&path, text).unwrap();
    path
}

const SHORT: &str = "solver.t_end=0.5";

#[test]
fn an_input_runs_as_the_load_of_its_function() {
    let function =
        "function = { type = \"table\", points = [[0.0, 0.0], [0.2, 1.5], [0.5, -0.5]] }\n";
    let history = |table: &str| {
        let file = read_model_file(&pendulum_with(table, function), &[SHORT.into()]).unwrap();
        let Analysis::Dynamic(settings) = file.analysis else {
            panic!("dynamic")
        };
        (
            file.model.inputs.len(),
            run_model(&file.model, settings).unwrap(),
        )
    };
    let ((n_input, input), (n_load, load)) = (history("input"), history("load"));
    assert_eq!((n_input, n_load), (1, 0));
    assert_eq!(
        input.rows, load.rows,
        "the same steps and sensors, bit for bit"
    );
    // and the torque acts: against the free pendulum
    let free = crate::common::run("pendulum.toml", &[SHORT]);
    let (a, b) = (input.last("angle"), free.last("angle"));
    assert!(
        (a - b).abs() > 1e-3,
        "angle {a} against {b} without the torque"
    );
}

#[test]
fn an_input_without_values_applies_nothing_and_is_addressed_as_an_input() {
    let file = read_model_file(&pendulum_with("input", ""), &[SHORT.into()]).unwrap();
    let Analysis::Dynamic(settings) = file.analysis else {
        panic!("dynamic")
    };
    let with = run_model(&file.model, settings).unwrap();
    let free = crate::common::run("pendulum.toml", &[SHORT]);
    assert_eq!(with.rows, free.rows, "u = 0 without a function");
    let params = Parameters::new(&file.model);
    assert!(params.id("input.motor.torque.2").is_ok());
    assert!(params.id("load.motor.torque.2").is_err());
}

#[test]
fn input_errors_name_the_file_line_and_field() {
    let cases = [
        (
            "torque = [0.0, 0.0, 0.0]\n",
            "input[0].force",
            "needs a `force` or a `torque`",
        ),
        ("frame = \"sideways\"\n", "input[0].frame", "sideways"),
        ("values = 1.0\n", "input[0]", "values"),
    ];
    for (extra, field, message) in cases {
        let path = pendulum_with("input", extra);
        // the torque written by `pendulum_with` comes first; a second one replaces nothing:
        // a duplicated key is itself an error, so the zero torque case rewrites the file
        let text = std::fs::read_to_string(&path).unwrap();
        let text = if extra.starts_with("torque") {
            text.replace("torque = [0.0, 0.0, 2.0]\n", "")
        } else {
            text
        };
        std::fs::write(&path, text).unwrap();
        let e = read_model_file(&path, &[])
            .expect_err("refused")
            .to_string();
        assert!(e.contains(field) && e.contains(message), "{extra}: {e}");
        assert!(e.contains(".toml:"), "{extra}: the file and line: {e}");
    }
    // an input may not take the name of a [[load]]
    let base = std::fs::read_to_string(example("pendulum.toml")).unwrap();
    let text = format!(
        "{base}\n[[load]]\nname = \"motor\"\nnode = \"pendulum\"\ntorque = [0.0, 0.0, 1.0]\n\n[[input]]\nname = \"motor\"\nnode = \"pendulum\"\ntorque = [0.0, 0.0, 1.0]\n"
    );
    let path = pendulum_with("input", "# clash\n");
    std::fs::write(&path, text).unwrap();
    let e = read_model_file(&path, &[])
        .expect_err("refused")
        .to_string();
    assert!(e.contains("input[0].name") && e.contains("[[load]]"), "{e}");
}

#[test]
fn an_input_whose_name_is_not_a_path_segment_takes_its_index_among_the_inputs() {
    // a [[load]] before it: the fallback is the input's own index, not the load's
    let text = std::fs::read_to_string(pendulum_with("load", "")).unwrap()
        + "\n[[input]]\nname = \"7\"\nnode = \"pendulum\"\nforce = [1.0, 0.0, 0.0]\n";
    let path = pendulum_with("input", "# numeric name\n");
    std::fs::write(&path, text).unwrap();
    let model = read_model_file(&path, &[]).unwrap().model;
    let params = Parameters::new(&model);
    assert!(params.id("input.0.force.0").is_ok());
    assert!(params.id("load.motor.torque.2").is_ok());
}
