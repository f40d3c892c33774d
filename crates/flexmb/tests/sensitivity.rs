//! Sensitivity analysis: direct differentiation, the discrete adjoint and central finite
//! differences agree on the criteria of small models.

use flexmb::input::read_model_file;
use flexmb::sensitivity::{self, Criterion, CriterionKind, Problem};
use std::sync::Arc;

fn problem(
    file: &str,
    set: &[&str],
    design: &[&str],
    criteria: &[(&str, CriterionKind, &str)],
) -> Problem {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples")
        .join(file);
    let set: Vec<String> = set.iter().map(|s| s.to_string()).collect();
    let f = read_model_file(&path, &set).expect("model");
    let settings = *f.analysis.dynamic().expect("dynamic");
    let model = Arc::new(f.model);
    let params = flexmb::model::Parameters::new(&model);
    let design = design
        .iter()
        .map(|p| params.id(p).expect("parameter"))
        .collect();
    let criteria = criteria
        .iter()
        .map(|(n, k, t)| Criterion::new(&model, &[], n, *k, t).expect("criterion"))
        .collect();
    let criteria = sensitivity::CriteriaSet::new(&model, Vec::new(), criteria);
    Problem::new(model, settings, design, criteria)
}

#[test]
fn heavy_top_gradients_agree() {
    for group in ["SE3", "R3xSO3"] {
        let group_set = format!("model.group={group}");
        let p = problem(
            "heavy_top.toml",
            &[
                &group_set,
                "body.top.inertia=[0.234375, 0.45, 0.234375]",
                "solver.t_end=0.05",
                "solver.h=1e-3",
                "solver.rtol=1e-12",
                "solver.atol=1e-14",
            ],
            &[
                "body.top.mass",
                "body.top.inertia.0",
                "body.top.inertia.1",
                "node.top.angular_velocity_body.1",
                "body.top.com.0",
            ],
            &[
                ("x", CriterionKind::Terminal, "com_x"),
                ("z", CriterionKind::Terminal, "com_z"),
                ("w1sq", CriterionKind::Integral, "sq(omega_1)"),
                ("rz", CriterionKind::Integral, "reaction_z"),
            ],
        );
        let d = sensitivity::direct(&p).expect("direct");
        let a = sensitivity::adjoint(&p, &mut |_, _| {}).expect("adjoint");
        let f = sensitivity::finite_differences(&p, 1e-6).expect("fd");
        println!("{group}: values {:?}", d.values);
        for c in 0..d.values.len() {
            println!("  direct  {:?}", d.gradients[c]);
            println!("  adjoint {:?}", a.gradients[c]);
            println!("  fd      {:?}", f.gradients[c]);
        }
    }
}
