//! One element of a meshed beam addressed on its own: `element.<k>` in a `[[beam]]` (and by
//! `--set beam.<r>.element.<k>. ...`) changes that element's section, and its parameters
//! keep the paths `beam.<r>.element.<k>. ...` whatever the sections of the others (the
//! engine issue, item 5: what topology optimization needs, one design variable per element).

use crate::common::{example, run};
use flexmb::input::read_model_file;
use flexmb::model::{ParamKind, Parameters};

/// The right-angle cantilever with element 3 of its first member stiffer in bending.
const STIFF_ELEMENT: &str = "beam.leg1.element.3.section.EI2=3000";

#[test]
fn an_element_of_a_meshed_beam_gets_its_own_section_from_the_command_line() {
    let path = example("right_angle_cantilever.toml");
    let base = read_model_file(&path, &[]).unwrap().model;
    let changed = read_model_file(&path, &[STIFF_ELEMENT.to_string()])
        .unwrap()
        .model;
    // only leg1[3] changes, and only its EI2 (the diagonal entry of C for bending 2)
    let mut differ = Vec::new();
    for (a, b) in base.beams.iter().zip(&changed.beams) {
        if a.section != b.section {
            differ.push(b.name.clone());
            let mut expected = a.section.clone();
            expected.stiffness[(4, 4)] = 3000.0;
            assert_eq!(b.section, expected, "{}", b.name);
        }
    }
    assert_eq!(differ, ["leg1[3]"]);

    // and the motion changes: the tip under the impulse at t = 2 s (the end of the load)
    let t_end = ["solver.t_end=2.0"];
    let before = run("right_angle_cantilever.toml", &t_end);
    let after = run("right_angle_cantilever.toml", &[t_end[0], STIFF_ELEMENT]);
    let (w0, w1) = (before.last("tip_w"), after.last("tip_w"));
    assert!(
        (w0 - w1).abs() > 1e-3 * w0.abs(),
        "tip deflection {w0} vs {w1} with one element stiffer"
    );
}

#[test]
fn element_paths_stay_when_the_sections_of_a_beam_differ() {
    let path = example("right_angle_cantilever.toml");
    for overrides in [vec![], vec![STIFF_ELEMENT.to_string()]] {
        let model = read_model_file(&path, &overrides).unwrap().model;
        let params = Parameters::new(&model);
        let uniform = overrides.is_empty();
        // the beam's own path exists while its elements share one section
        assert_eq!(params.id("beam.leg1.section.EI2").is_ok(), uniform);
        assert!(params.id("beam.leg2.section.EI2").is_ok());
        for k in 0..10 {
            let id = params
                .id(&format!("beam.leg1.element.{k}.section.EI2"))
                .unwrap();
            let ParamKind::Beam(item, _) = params.kind(id) else {
                panic!("a beam parameter")
            };
            let [e] = params.beam_elements(item) else {
                panic!("one element")
            };
            assert_eq!(model.beams[*e].name, format!("leg1[{k}]"));
            let expected = if k == 3 && !uniform { 3000.0 } else { 1e3 };
            assert_eq!(params.value(&model, id), expected);
            // setting it changes that element alone
            let mut copy = model.clone();
            params.set(&mut copy, id, 42.0);
            let changed: Vec<usize> = (0..model.beams.len())
                .filter(|&i| copy.beams[i].section != model.beams[i].section)
                .collect();
            assert_eq!(changed, [*e]);
        }
        assert!(params.id("beam.leg1.element.10.section.EI2").is_err());
    }
}

#[test]
fn element_tables_in_the_file_read_like_the_command_line() {
    let text = std::fs::read_to_string(example("right_angle_cantilever.toml")).unwrap();
    // the first [[beam]]'s table, with dotted keys for element 3 and a coupling of element 0
    let edited = text.replacen(
        "elements = 10\n",
        "elements = 10\nelement.3.section.EI2 = 3000.0\nelement.0.section.stiffness.3.4 = 5.0\nelement.0.damping.stiffness = 0.01\n",
        1,
    );
    assert_ne!(edited, text);
    let dir = std::env::temp_dir().join(format!("flexmb-beam-elements-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("model.toml");
    std::fs::write(&file, &edited).unwrap();
    let from_file = read_model_file(&file, &[]).unwrap().model;
    let e0 = &from_file.beams[0].section;
    assert_eq!((e0.stiffness[(3, 4)], e0.stiffness[(4, 3)]), (5.0, 5.0));
    assert_eq!(e0.damping_stiffness, 0.01);
    let set = [
        "beam.leg1.element.3.section.EI2=3000.0".to_string(),
        "beam.leg1.element.0.section.stiffness.3.4=5.0".to_string(),
        "beam.leg1.element.0.damping.stiffness=0.01".to_string(),
    ];
    let by_set = read_model_file(&example("right_angle_cantilever.toml"), &set)
        .unwrap()
        .model;
    assert_eq!(from_file.beams, by_set.beams);

    // located errors: an element the beam does not have, a key a section does not have, a
    // coupling that is a diagonal entry
    for (bad, expect) in [
        (
            "element.10.section.EI2 = 1.0",
            "must be an element number from 0 to 9",
        ),
        ("element.3.section.EIy = 1.0", "unknown key 'EIy'"),
        (
            "element.3.section.stiffness.4.4 = 1.0",
            "allowed keys here: 5",
        ),
        ("element.3.section.EI2 = -1.0", "must be positive"),
    ] {
        let edited = text.replacen("elements = 10\n", &format!("elements = 10\n{bad}\n"), 1);
        std::fs::write(&file, &edited).unwrap();
        let e = read_model_file(&file, &[]).unwrap_err().to_string();
        assert!(
            e.contains("model.toml:") && e.contains("beam 'leg1'") && e.contains(expect),
            "{bad}: {e}"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}
