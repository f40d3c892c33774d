//! Results in memory: what a run collects.

use flexmb_results::Results;
use std::path::Path;

fn model(name: &str) -> flexmb::input::ModelFile {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples")
        .join(name);
    flexmb::input::read_model_file(&path, &[]).expect("the example reads")
}

#[test]
fn heavy_top_snapshots_hold_every_output_step_and_its_unit_quaternions() {
    let mut file = model("heavy_top.toml");
    file.analysis = match file.analysis {
        flexmb::input::Analysis::Dynamic(mut s) => {
            s.t_end = 0.05;
            flexmb::input::Analysis::Dynamic(s)
        }
        a => a,
    };
    let (r, error) = Results::collect(&file);
    assert!(error.is_none());
    assert_eq!(r.info.nodes.len(), 1);
    assert!(r.snapshots.len() > 2);
    assert!(!r.steps.is_empty());
    for s in &r.snapshots {
        let q = s.orientation[0];
        let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
        assert!((n - 1.0).abs() < 1e-12);
        assert_eq!(s.sensors.len(), r.info.sensors.len());
    }
    // The file's shapes: the disc, the rod, the marker.
    let kinds: Vec<&str> = r.info.shapes.iter().map(|s| s.kind.as_str()).collect();
    assert_eq!(kinds, ["cylinder", "cylinder", "box"]);
    assert_eq!(r.info.shapes[0].size, [0.5, 0.5, 0.03]);
}

#[test]
fn a_body_without_shapes_is_drawn_as_its_inertia_box_at_its_centre_of_mass() {
    // The four-bar's links: homogeneous bars, their inertia boxes are the bars.
    let file = model("four_bar.toml");
    let info = flexmb_results::ModelInfo::of(&file.model, "dynamic");
    assert_eq!(info.shapes.len(), file.model.bodies.len());
    for (s, b) in info.shapes.iter().zip(&file.model.bodies) {
        assert_eq!(s.node, b.node.0);
        assert_eq!(s.position, <[f64; 3]>::from(b.com));
        // The homogeneous box of the body's mass and principal moments, I_k = m (a_i^2 +
        // a_j^2) / 12, so a_k^2 = 6 (I_i + I_j - I_k) / m; sides at least 1 % of the model's
        // size (the extent of its nodes, 2 m here) so that the bars show.
        let i: Vec<f64> = b.inertia.symmetric_eigenvalues().iter().copied().collect();
        let mut expected: Vec<f64> = (0..3)
            .map(|k| (6.0 * (i[(k + 1) % 3] + i[(k + 2) % 3] - i[k]) / b.mass).sqrt())
            .map(|a| a.max(0.01 * file.model.extent()))
            .collect();
        expected.sort_by(f64::total_cmp);
        let mut sides = s.size;
        sides.sort_by(f64::total_cmp);
        for (a, e) in sides.iter().zip(&expected) {
            assert!((a - e).abs() <= 1e-9, "{sides:?} against {expected:?}");
        }
        assert!(
            (sides[2] - 1.0).abs() < 1e-5,
            "a link is 1 m long: {sides:?}"
        );
    }
}
